"""The sweep over the friction coefficient (scene sweep-mu, issue 27): its cases, and its mu = 0 row as the
frictionless run."""

from __future__ import annotations

import math

import numpy as np

from bearingshaft.scenes import load_scene
from bearingshaft.sweep import build_plan
from bearingshaft.sweep.run import run_case
from reduced.models.discrete import DiscreteFrictionParams
from reduced.transient.integrate import ringdown
from reduced.transient.store import RingdownFile

MUS = [0.0, 0.05, 0.1, 0.2, 0.3, 0.5]


def test_sweep_mu_cases():
    # the [sweep] table addresses model.mu: six cases, every one validated, the base case's blow in each
    scene = load_scene("sweep-mu")
    plan = build_plan(scene, scene.sweep, "sweep-mu [sweep]")
    assert [dict(c.values)["model.mu"] for c in plan.cases] == MUS
    assert len({c.case_id for c in plan.cases}) == len(MUS)


def test_sweep_mu_zero_row_is_the_frictionless_run(tmp_path):
    # mu = 0 builds no sliders: the case's run is the frictionless 4-DOF model's, bit for bit; its vertical
    # motion is the paper's 3-DOF model's to round-off while that lasts (1e-12 of the motion over the first
    # 5 ms: the impacts amplify the round-off of the two closed forms, which part at 1e-12 near 8 ms, as in
    # tests/test_friction.py), and its axial motion u rings alone on its suspension, the damped oscillator's
    # closed form to 1e-12 of its amplitude over the 2 s (measured 1.7e-14); no friction work, and the
    # energy does not fall to 1 % within the 2 s (the axial mode, damped by c alone, e^(-1.6 t) in energy, holds
    # 64 % of it): decay_time_s is NaN.
    scene = load_scene("sweep-mu")
    plan = build_plan(scene, scene.sweep, "sweep-mu [sweep]")
    case = next(c for c in plan.cases if dict(c.values)["model.mu"] == 0.0)
    row = run_case(case, str(tmp_path))
    assert row["status"] == "ok", row["message"]
    p = DiscreteFrictionParams(mu=0.0)
    system = p.system()
    assert system.friction is None
    f = RingdownFile(tmp_path / case.case_id / "ringdown.npz", system)
    x = f.read("x", 0, f.n_samples)
    x0, v0 = np.zeros(4), [0.0, 0.0, 0.3, 0.2]
    direct = ringdown(system, x0, v0, 2.0, 20000.0, "exact")
    assert np.array_equal(direct.x, x)
    assert row["impacts"] > 10 and row["energy_balance_error"] < 1e-11
    assert math.isnan(row["decay_time_s"])
    k = 100  # 5 ms
    paper = ringdown(p.vertical.system(), np.zeros(3), v0[:3], k / 20000.0, 20000.0, "exact")
    assert np.max(np.abs(x[:k + 1, :3] - paper.x)) < 1e-12 * np.max(np.abs(paper.x))
    t = np.arange(f.n_samples) / 20000.0
    sig = p.c / (2.0 * p.m_beam)
    wd = math.sqrt(p.k_u / p.m_beam - sig**2)
    amp = v0[3] / wd
    assert np.max(np.abs(x[:, 3] - amp * np.exp(-sig * t) * np.sin(wd * t))) < 1e-12 * amp
    assert row["friction_work_J"] == 0.0 and row["friction_work_fraction"] == 0.0


def test_sweep_mu_friction_work_against_the_energy_it_leaves(tmp_path):
    # the friction_work_J column against the energy balance done independently from the samples:
    # E0 - E(T) - int c |v|^2 dt (the viscous work by the trapezoidal rule over the 20 kHz samples,
    # whose error ~ dt^2 |d2/dt2 (c v^2)| T / 12 is below 1e-3 of it here: the motion's fastest part,
    # the contacts' ~1 kHz, is resolved by 20 samples a period); allowed 1 % of the initial energy
    scene = load_scene("sweep-mu")
    plan = build_plan(scene, scene.sweep, "sweep-mu [sweep]")
    case = next(c for c in plan.cases if dict(c.values)["model.mu"] == 0.3)
    row = run_case(case, str(tmp_path))
    assert row["status"] == "ok", row["message"]
    p = DiscreteFrictionParams(mu=0.3)
    f = RingdownFile(tmp_path / case.case_id / "ringdown.npz", p.system())
    v = f.read("v", 0, f.n_samples)
    e = f.read("energy", 0, f.n_samples)
    power = p.c * np.sum(v**2, axis=1)  # C = c I on every coordinate
    w_visc = float(np.sum(0.5 * (power[1:] + power[:-1])) / f.sample_rate_hz)
    expected = e[0] - e[-1] - w_visc
    assert expected > 0.1 * e[0]  # friction takes a real share: the check is not of zeros
    assert abs(row["friction_work_J"] - expected) < 1e-2 * e[0]
    assert row["friction_work_fraction"] == row["friction_work_J"] / row["energy_J_initial"]
