"""The reduced model against the full 3-D model through impacts (issue 22).

The full system is the beam-grounded 3-D model on ALL its DOFs (hex8, the coarsest mesh the
builders allow: one element across each beam sub-block, ``section_layers = 1``, 270 DOFs) with
the two-sided tip stops on the real gap rows (:func:`fem.contact.contact_rows`) and the reduced
model's damping mapped back: dashpots ``c_points`` on the three point rows plus ``alpha`` M.
The Craig-Bampton model that keeps every fixed-interface mode is an exact change of coordinates
u = V q, V = [Psi Phi], so V^T M V, V^T C V, V^T K V and R V are the reduced model's matrices and
stop rows, and the exact (event-driven, closed-form) integrator must give the same motion on both
from u0 = V q0, to round-off: the same contact events at the same times. A truncated model
(the first k fixed-interface modes, as ``craig_bampton(n_modes=k)`` keeps them) converges toward it.

Size: the exact integrator tabulates 2^4 contact states of 2n x 2n complex eigenvectors (V, V^-1)
and a dense 2n eigen-decomposition of each distinct state (O(n^3)). At n = 270 a run takes about
2 s of CPU; the two-layer hex8 mesh (729 DOFs, tests/test_rom.py's small model) agrees as well (9.1e-9)
but takes about 35 s of CPU a run and 2.4 GB, too much for the default suite. The ringdown and
the flow of one system share its tables (:func:`shared_tables`). The one-layer hex8 beam is
shear-locked (first bending 2.8 kHz against 731 Hz with hex20): this mesh checks the reduction
and the integrator, not the beam's physics.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla

from fem.contact import contact_pairs, contact_rows, point_rows
from fem.model import AssemblyModel, build_system
from fem.rig import sensor_rows
from geometry.build import build_mesh
from reduced._blas import single_thread_blas
from reduced.models.craig_bampton import craig_bampton
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.models.initial import initial_state
from reduced.models.rom import POINTS, RomSpec, build_rom
from reduced.transient import exact
from reduced.transient import flow as flow_module
from reduced.transient.flow import Flow
from reduced.transient.integrate import ringdown

EPS = np.finfo(float).eps
DURATION = 0.01  # s
RATE = 100e3  # Hz: 1001 samples, 10 a contact half-period (~1 kHz)
V0_POINTS = (0.0, 0.0, 1.0)  # m/s at x1, x2, x3: x3 closes its gap (0.254 mm) in 0.3 ms
# 4 N s/m at each point, 2 1/s x M; no modal damping (it lives on the reduced modes: the full model has none)
SPEC = RomSpec(planar=False, element="hex8", c_points=4.0, alpha=2.0, modal_damping=(0.0,))


@pytest.fixture(scope="module")
def models():
    model = AssemblyModel(layout="beam-grounded", element="hex8")
    fe = build_system(model, mesh=build_mesh(replace(model.geometry(), section_layers=1)))
    rom = build_rom(replace(SPEC, n_modes=fe.n_dofs - 2), fe=fe)[0]  # every fixed-interface mode
    R = contact_rows(contact_pairs(fe, gap=SPEC.gap, k_g=SPEC.k_g))
    prow = point_rows(fe)
    rows = np.vstack([prow[p] for p in POINTS])
    M = fe.M.toarray()
    K = fe.K.toarray()
    K = 0.5 * (K + K.T)  # assembly leaves 3e-17 relative asymmetry; the reduction symmetrizes V^T K V too
    C = SPEC.c_points * rows.T @ rows + SPEC.alpha * M  # what RomSpec's damping is on the full DOFs
    full = GapSystem(M=M, C=C, K=K, dof_names=tuple(f"u{i}" for i in range(fe.n_dofs)),
                     **two_sided_stops(R, SPEC.k_g, SPEC.gap, ("x1", "x3")))
    red = rom.system()
    V = np.hstack([rom.Psi, rom.Phi])
    x0, v0 = initial_state(red.M, red.K, rom.P, (0.0, 0.0, 0.0), V0_POINTS)
    return {"fe": fe, "rom": rom, "full": full, "red": red, "V": V, "R": R, "rows": rows, "q0": (x0, v0)}


@contextmanager
def shared_tables():
    """The ringdown and the flow of one system decompose its contact states once (the state and
    modal tables are functions of the system alone; at 2n = 540 they are most of the run time)."""
    memo: dict = {}

    def cached(name, fn):
        def wrapper(system, *args):
            key = (name, id(system))
            if key not in memo:
                memo[key] = (system, fn(system, *args))  # the system is kept: its id stays unique
            return memo[key][1]
        return wrapper

    with pytest.MonkeyPatch.context() as mp:
        for fn in (exact.state_table, exact.modal_table):
            wrapper = cached(fn.__name__, fn)
            mp.setattr(exact, fn.__name__, wrapper)
            mp.setattr(flow_module, fn.__name__, wrapper)
        yield


@pytest.fixture(scope="module")
def runs(models):
    """The exact ringdown of the full and the all-mode model from the same state, and their events
    (times, contact states, and the speed of the gap that crosses) from the exact flow."""
    full, red, V = models["full"], models["red"], models["V"]
    x0, v0 = models["q0"]
    out = {}
    with single_thread_blas(), shared_tables():
        for name, system, y0 in (("full", full, (V @ x0, V @ v0)), ("red", red, (x0, v0))):
            res = ringdown(system, *y0, DURATION, RATE)
            flow = Flow(system)
            states, tau = flow(*y0, DURATION).segments
            t_ev = np.cumsum(tau)[:-1]
            stop = np.log2(states[1:] ^ states[:-1]).astype(int)  # one stop switches at each event
            speed = np.array([abs(system.B[j] @ flow(*y0, t).y[system.n:]) for j, t in zip(stop, t_ev, strict=True)])
            out[name] = {"res": res, "states": states, "t_events": t_ev, "speed": speed}
    return out


def round_off(runs) -> float:
    """Relative round-off bound of the two runs: the closed form restarts at every event and every
    piece boundary, and each restart loses cond(V_s) eps of the state's size (V_s the eigenvectors
    of a contact state: the integrator's own ``tolerance`` is this times the amplitude)."""
    stats = [runs[k]["res"].stats for k in ("full", "red")]
    restarts = stats[1]["n_events"] + stats[1]["n_pieces"]
    return restarts * max(s["cond_V"] for s in stats) * EPS


def test_all_mode_reduction_is_the_full_model_in_other_coordinates(models):
    full, red, V, rom = models["full"], models["red"], models["V"], models["rom"]
    scale = lambda A: np.abs(A).max()  # noqa: E731
    # each product V^T A V sums ~n terms: n eps relative of its largest entry
    tol = full.n * EPS
    assert scale(V.T @ full.M @ V - red.M) < tol * scale(red.M)
    assert scale(V.T @ full.K @ V - red.K) < tol * scale(red.K)
    assert scale(V.T @ full.C @ V - red.C) < tol * scale(red.C)  # the same damping, c_points and alpha
    assert scale(full.B @ V - red.B) < tol  # the stops act on the same gap coordinates
    assert np.array_equal(full.offset, red.offset) and np.array_equal(full.k, red.k)
    assert rom.n == full.n == 270


def test_full_and_all_mode_models_agree_to_round_off_through_impacts(models, runs):
    V = models["V"]
    rf, rr = runs["full"]["res"], runs["red"]["res"]
    # several impacts, on both sides of both tips, and the same number on both models
    n_ev = rr.stats["n_events"]
    assert rf.stats["n_events"] == n_ev >= 20, (rf.stats, rr.stats)
    force = rr.system.stop_force(rr.x).max(axis=0)  # (4,) N, peak force in each stop
    assert np.all(force > 1e3), force  # measured 1.6 to 5.2 kN
    # cond(V_s) is 1e7 here (the spectrum spans 10 Hz to 490 kHz): a bound of 1.7e-7 relative
    rel = round_off(runs)
    assert rel < 1e-6  # far below the truncated models' errors (1.8e-5 with 160 of 268 modes)
    gap_full = rf.x @ models["R"].T
    gap_red = rr.x[:, :2]
    err = np.abs(gap_full - gap_red).max() / np.abs(gap_red).max()
    assert err < rel, f"gap error {err:.3g} relative against the round-off bound {rel:.3g}"  # measured 9e-9
    # physical DOFs through V: the beam's six accelerometers (x, y, z) and the mid-span point x2
    dofs = np.array(list(sensor_rows(models["fe"], ("beam",)).values()))
    u_red = rr.x @ V[dofs].T
    err_u = np.abs(rf.x[:, dofs] - u_red).max() / np.abs(u_red).max()
    assert err_u < rel, f"sensor error {err_u:.3g} relative against {rel:.3g}"  # measured 1e-8
    x2_full = rf.x @ models["rows"][1]
    x2_red = rr.x @ models["rom"].P[1]
    assert np.abs(x2_full - x2_red).max() < rel * np.abs(x2_red).max()  # measured 6e-9
    err_v = np.abs(rf.v @ models["R"].T - rr.v[:, :2]).max() / np.abs(rr.v[:, :2]).max()
    assert err_v < rel, err_v  # measured 4e-8
    # the closed form keeps E(0) = E(t) + W(t) (damping c_points and alpha) on both
    assert rf.energy_balance_error < 1e-9 and rr.energy_balance_error < 1e-9


def test_same_events_at_the_same_times(runs):
    f, r = runs["full"], runs["red"]
    assert np.array_equal(f["states"], r["states"])  # the same sequence of contact states
    for run in (f, r):  # the flow and the ringdown see the same events
        assert len(run["t_events"]) == run["res"].stats["n_events"]
    # an error dx in the gap moves a crossing by dx / |s'|: the round-off bound of the gap over the
    # speed of the crossing gap (0.12 to 0.96 m/s here: no grazing event)
    dx = round_off(runs) * np.abs(r["res"].x[:, :2]).max()
    dt = np.abs(f["t_events"] - r["t_events"])
    bound = dx / np.minimum(f["speed"], r["speed"])
    assert np.all(dt < bound), np.column_stack([dt, bound])  # measured at most 0.1 of it, 2e-11 s


def test_truncated_models_converge_toward_the_all_mode_model(models, runs):
    red, rom = models["red"], models["rom"]
    x0, v0 = models["q0"]
    ref = runs["red"]["res"]
    peak = np.abs(ref.x[:, :2]).max()
    # A dropped fixed-interface mode j, driven by the interface through M_qb,j, answers quasi-statically
    # (omega_j far above the contact's ~1 kHz), q_j = -M_qb,j x_b'' / omega_j^2, so the interface
    # misses the force M_bq,j q_j'': the truncation error goes as the omitted modes' interface mass
    # over omega^2, S(k) = sum_{j > k} |M_bq,j|^2 / omega_j^2 (the constraint modes carry their
    # static part exactly). Each k below adds modes the tips couple to; 10 (the first three such
    # modes) is not enough to keep the sequence of impacts.
    counts = (20, 31, 44, 64, 80, 128, 160)
    mass_w2 = np.sum(rom.M[:2, 2:] ** 2, axis=0) / rom.omega_fixed**2  # |M_bq,j|^2 / omega_j^2
    errors, tails = [], []
    with single_thread_blas():
        for k in counts:
            sl = slice(0, 2 + k)
            sys_k = replace(red, M=red.M[sl, sl], C=red.C[sl, sl], K=red.K[sl, sl], B=red.B[:, sl],
                            dof_names=red.dof_names[sl])
            # the same initial state, its modal content above the cut dropped
            res = ringdown(sys_k, x0[sl], v0[sl], DURATION, RATE)
            assert res.stats["n_events"] == ref.stats["n_events"], (k, res.stats)
            errors.append(np.abs(res.x[:, :2] - ref.x[:, :2]).max() / peak)
            tails.append(mass_w2[k:].sum())
    errors, tails = np.array(errors), np.array(tails)
    assert np.all(np.diff(errors) < 0), dict(zip(counts, errors, strict=True))  # 1.5e-2 .. 1.8e-5
    # error = c S(k): fit the exponent of S, and the constant within a factor 1.5 over three decades
    slope = np.polyfit(np.log(tails), np.log(errors), 1)[0]
    ratio = errors / tails
    msg = f"slope {slope:.3f}, error / S(k) {ratio}, errors {errors}"
    assert 0.9 < slope < 1.1, msg  # measured 0.999
    assert np.all(np.abs(np.log(ratio / np.median(ratio))) < np.log(1.5)), msg  # measured 0.73 .. 1.2
    assert errors[-1] < 1e-4
    # the slice is what the reduction itself keeps with n_modes = k
    k = counts[0]
    cb = craig_bampton(models["fe"].K, models["fe"].M, models["R"], n_modes=k)
    # a change of basis within the same subspace: the eigenvalues agree to the dense solvers'
    # backward error, eps max|lambda| absolute (here max|lambda| = (2 pi 490 kHz)^2)
    w_all = sla.eigh(red.K[:2 + k, :2 + k], red.M[:2 + k, :2 + k], eigvals_only=True)
    w_cb = sla.eigh(cb.K, cb.M, eigvals_only=True)
    assert np.max(np.abs(w_all - w_cb)) < 10 * EPS * rom.omega_fixed[-1] ** 2
