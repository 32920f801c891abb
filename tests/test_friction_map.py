"""The response map with friction (reduced/periodic/friction_map.py, issues 25 and 27): the period map of the exact
friction flow and its exact tangent (state transition matrices between events, saltation at every gap, stick and
slip event, the sliders that are not stuck slaved to x) against finite differences, Floquet's exponent of a stable
orbit against the multipliers of the friction shooting, and mu = 0 against the frictionless map."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from test_friction import K_X, M_X, N_REST, Z_REST, coulomb

from reduced.models.gaps import GapSystem
from reduced.periodic.friction_map import FrictionPeriodMap, friction_response_map
from reduced.periodic.friction_shooting import shoot_friction
from reduced.periodic.response_map import MapOptions, classify, response_map
from reduced.periodic.stepped_sine import slowest_decay_rate
from reduced.transient.friction import initial_friction_state

P = 2.0  # N, the discrete-friction-frc scene's level: contact from ~14 Hz on


@functools.lru_cache(maxsize=1)
def scene_system():
    """(system, b, rows, names) of the discrete-friction-frc scene (the 3-DOF model with u and two sliders)."""
    from bearingshaft.scenes import load_scene
    from bearingshaft.stages.frc_friction import load_vector
    from bearingshaft.systems import model_system

    sc = load_scene("discrete-friction-frc")
    system, rows = model_system(sc.model, False)
    rows = np.asarray(rows, float)
    names = tuple(sc.model.point_names)
    return system, load_vector(sc.frc, rows, names), rows, names


def test_the_tangent_matches_central_differences_of_the_flow_through_stick_slip_and_gap_events():
    # At 22 Hz in contact (the tips close, their sliders stick, slip and reopen about 10 times a period; the
    # response chaotic, lambda ~ 80 1/s, a growth of ~40 a period), 1 and 2 periods from a state of the run from
    # rest. A perturbation consistent with the start's state (a slider open or slipping has its w slaved to x: P_s d)
    # by central differences of the flow, step 1e-7 of |y| in the norm D: the flow is affine within a state and each
    # event time moves by O(step), so the difference is exact to O(step) + round-off times the growth (|dF d| 270-4700
    # here); measured 7e-9 .. 2.4e-8 of |dF d| over 1 period, 7e-8 .. 7.3e-7 over 2. The saltation left out (Sal = DR)
    # gives 0.07 and 0.14. Compared after P_end (the slaved w at the end do not act).
    system, b, rows, _ = scene_system()
    pm = FrictionPeriodMap(system, b, P, 22.0, rows=rows)
    N = 2 * system.n + system.p
    y = pm.run(np.zeros(N), 40, samples_per_period=0).y
    st = pm.states
    rng = np.random.default_rng(3)
    kinds = set()
    for K in (1, 2):
        run = pm.jacobian(y, K)
        kinds |= set(st.flows.events.kind[:len(st.flows.events)].tolist())
        table = st.flows.events.table
        P0 = st.projection(table, initial_friction_state(system, table, y[:system.n], y[2 * system.n:]))
        end = run.y
        P1 = st.projection(table, initial_friction_state(system, table, end[:system.n], end[2 * system.n:]))
        for _ in range(3):
            d = P0 @ np.linalg.solve(pm.norm_matrix, rng.standard_normal(N))
            d /= pm.norm(d)
            h = 1e-7 * pm.norm(y)
            fd = (pm.run(y + h * d, K, samples_per_period=0).y - pm.run(y - h * d, K, samples_per_period=0).y) / (2 * h)
            exact = run.tangent @ d
            assert pm.norm(P1 @ fd - exact) <= 1e-5 * pm.norm(exact)
    assert kinds == {"gap", "stick", "slip+", "slip-"}, kinds  # every kind of event crossed


def damped_coulomb():
    """The Coulomb oscillator of tests/test_friction.py (x tangential, its slider k_t = 1e7 N/m, mu = 0.3; z normal,
    pressed into its stop) with both motions damped (c = 1 and 20 N s/m: the normal pair inside the circle)."""
    s0 = coulomb(0.3, 1e7)
    return GapSystem(M=s0.M, C=np.diag([1.0, 20.0]), K=s0.K, B=s0.B, k=s0.k, offset=s0.offset, side=s0.side,
                     tip=s0.tip, dof_names=s0.dof_names, stop_names=s0.stop_names, friction=s0.friction)


def test_the_exponent_of_a_stable_orbit_is_floquets_from_the_friction_shooting():
    # The damped Coulomb oscillator under P = 4 mu N at 0.6 of its natural frequency (Den Hartog's continuous slip:
    # each reversal a slip -> stick -> slip pair of events), classified from rest: periodic, finished by Newton on
    # P J P with lambda = f ln max |mu|. Against the multipliers of the shooting with the sliders (8 nodes, the
    # monodromy by central differences: independent of the tangent) at the orbit's nodes: measured 1e-9 apart. And
    # the tangent's time average over 250 periods on the orbit (Benettin), whose finite-time error is O(log(cond) /
    # K) (measured 0.2 %), within 2 %. The slaved direction (the slider's w while it slips) has the multiplier 0
    # in both (shooting: 6e-20), not 1.
    system = damped_coulomb()
    F = 0.3 * N_REST
    f = 0.6 * math.sqrt(K_X / M_X) / (2 * math.pi)
    pm = FrictionPeriodMap(system, [1.0, 0.0], 4 * F, f)
    y0 = np.array([0.0, Z_REST, 0.0, 0.0, 0.0])
    pt = classify(pm, y0, slowest_decay_rate(system.with_friction(None), [1.0, 0.0]),
                  MapOptions(n_transient=32, n_record=32), rng=np.random.default_rng(0))
    assert pt.regime == "periodic" and pt.period_k == 1 and pt.settled and pt.contact
    y = pt.state
    kinds = set(pm.states.flows.events.kind[:len(pm.states.flows.events)].tolist())
    assert {"stick", "slip+", "slip-"} <= kinds, kinds
    mu = np.sort(np.abs(np.linalg.eigvals(pm.jacobian(y, 1).tangent)))[::-1]
    assert mu[0] < 1.0 and mu[-1] < 1e-12
    nodes = np.array([pm.states.flows(f, y, 0.0, 1.0 / f, 8)[k] for k in range(8)])
    shot = shoot_friction(system, [1.0, 0.0], 4 * F, f, nodes)
    assert shot.converged and shot.defect < 1e-8
    floquet = f * math.log(shot.max_abs_multiplier)
    assert abs(mu[0] - shot.max_abs_multiplier) <= 1e-6 * mu[0]
    assert abs(pt.lyapunov_per_s - floquet) <= 1e-6 * abs(floquet)
    assert abs(pt.max_abs_mu - shot.max_abs_multiplier) <= 1e-6 * shot.max_abs_multiplier
    W = np.linalg.solve(pm.norm_matrix, np.random.default_rng(1).standard_normal((y.size, 1)))
    run = pm.run(y, 250, tangent=W, samples_per_period=0)
    lam = float(run.log_growth[50:, 0].mean()) * f
    assert abs(lam - floquet) <= 0.02 * abs(floquet)


def test_mu_zero_gives_the_frictionless_map():
    # With mu = 0 the sliders carry no force (they slip at once, slaved to x): the same motion as the frictionless
    # model. Out of contact (12 Hz) the same periodic orbit to round-off, and its exponent; in contact both maps
    # chaotic (the kicks differ in dimension, so the chaotic runs differ in detail, not in kind). Measured:
    # 12 Hz exponents equal to 1e-14, 16 and 22 Hz chaotic in both with exponents 20 / 22 and 74 / 77 1/s.
    system, b, rows, names = scene_system()
    s0 = system.with_friction(dataclasses.replace(system.friction, mu=np.zeros(system.p)))
    freqs = np.array([12.0, 16.0, 22.0])
    opts = MapOptions(n_transient=8, n_record=32)
    a = friction_response_map(s0, b, P, freqs, point_rows=rows, point_names=names, options=opts)
    c = response_map(system.with_friction(None), b, P, freqs, point_rows=rows, point_names=names, options=opts)
    assert a.regime == c.regime == ["periodic", "chaotic", "chaotic"]
    p, q = a.points[0], c.points[0]
    assert abs(p.lyapunov_per_s - q.lyapunov_per_s) <= 1e-9 * abs(q.lyapunov_per_s)
    assert np.allclose(p.peak, q.peak, rtol=1e-6, atol=0)
    assert abs(p.max_abs_mu - q.max_abs_mu) <= 1e-9
    for p, q in zip(a.points[1:], c.points[1:], strict=True):
        assert p.lyapunov_per_s > p.lyapunov_tol and q.lyapunov_per_s > q.lyapunov_tol
        assert 0.5 < p.lyapunov_per_s / q.lyapunov_per_s < 2.0
