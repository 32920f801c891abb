"""Lyapunov exponents by the exact flow's tangent (reduced.transient.lyapunov), against closed forms and
independent methods: the saltation matrix of a penalty stop is I (and the formula is right where it is
not), the tangent equals finite differences of the exact flow across crossings, the exponents sum to
-tr(M^-1 C) (Liouville), the two-run method (no tangent) agrees in chaos, and a linear system's largest
exponent is its slowest decay rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.transient.lyapunov import (
    PeriodMap,
    crossing_saltation,
    lyapunov_exponents,
    lyapunov_two_runs,
    saltation_matrix,
)

PARAMS = DiscreteParams()
SYSTEM = PARAMS.system()
LOAD = PARAMS.point_rows[1]  # x2, as discrete-frc


@pytest.fixture(scope="module")
def chaos():
    """The 1 N, 19 Hz map on its chaotic attractor (a stepped sine up lands there: response map)."""
    pm = PeriodMap(SYSTEM, LOAD, 1.0, 19.0)
    y = np.zeros(6)
    y[0] = y[2] = 2.6e-4  # a contact start; the attractor is reached in ~100 periods
    y = pm.run(y, 200, samples_per_period=0, inner_samples=0).y
    return pm, y


def test_saltation_formula_on_a_force_step():
    # x'' = 0 for x < 0, a for x > 0, crossed upward at speed v0: the flow's derivative in closed form,
    # x(t) = 1/2 a (t - t_c)^2 + v0 (t - t_c) with t_c = -x0 / v0, so dv/dx0 = a / v0 after the crossing;
    # S = I + (f+ - f-) n^T / (n^T f-) must carry the same (Leine & Nijmeijer 2004)
    a, v0 = 3.0, 0.5

    def flow(x0, v):  # from (x0 < 0, v) over t = 1 (crossing inside)
        tc = -x0 / v
        s = 1.0 - tc
        return np.array([0.5 * a * s * s + v * s, v + a * s])

    h = 1e-7
    J_fd = np.column_stack([(flow(-0.1 + h, v0) - flow(-0.1 - h, v0)) / (2 * h),
                            (flow(-0.1, v0 + h) - flow(-0.1, v0 - h)) / (2 * h)])
    # the flow = (after the crossing) o S o (before); before and after are x += v t, v += a t
    tc = 0.1 / v0
    before = np.array([[1.0, tc], [0.0, 1.0]])
    after = np.array([[1.0, 1.0 - tc], [0.0, 1.0]])
    S = saltation_matrix([v0, 0.0], [v0, a], [1.0, 0.0])
    assert np.allclose(after @ S @ before, J_fd, rtol=0, atol=1e-7), (after @ S @ before, J_fd)  # FD error ~h^2
    assert not np.allclose(S, np.eye(2))


def test_saltation_of_a_penalty_stop_is_the_identity():
    # on the surface s = o the stop force k (s - o) is 0 on both sides: f+ = f-, S = I exactly
    g = PARAMS.gap
    for j, (x, v) in enumerate([([g, 1e-4, 0.0], [0.3, 0.1, 0.0]), ([g, 0.0, 0.0], [-0.2, 0.0, 0.0]),
                                ([0.0, 0.0, -g], [0.0, 0.1, -0.1])]):
        stop = [0, 0, 3][j]
        S = crossing_saltation(SYSTEM, np.concatenate([x, v]), stop, force_N=LOAD * 0.7)
        assert np.array_equal(S, np.eye(6)), np.abs(S - np.eye(6)).max()


def test_the_tangent_is_the_derivative_of_the_exact_flow_across_crossings(chaos):
    pm, y = chaos
    run = pm.jacobian(y, 1)
    assert run.n_events >= 2  # the period crosses stops
    J = run.tangent
    scale = np.abs(pm.norm_matrix.diagonal())  # steps of equal energy in each coordinate
    J_fd = np.empty_like(J)
    for c in range(6):
        h = 1e-7 * pm.norm(y) / scale[c]
        e = np.zeros(6)
        e[c] = h
        J_fd[:, c] = (pm.run(y + e, 1, samples_per_period=0, inner_samples=0).y
                      - pm.run(y - e, 1, samples_per_period=0, inner_samples=0).y) / (2 * h)
    D = pm.norm_matrix
    err = np.linalg.norm(D @ (J - J_fd) @ np.linalg.inv(D), 2) / np.linalg.norm(D @ J @ np.linalg.inv(D), 2)
    # central differences with steps 1e-7 of the state: 3e-8 here (1e-6 at 1e-9: round-off / h grows);
    # the flow is C^1 across crossings, so a step straddling one adds O(h) at most
    assert err < 1e-6, err


def test_exponents_sum_to_minus_the_trace_of_the_damping(chaos):
    # Liouville: div f = -tr(M^-1 C) in every contact state, and det S = 1 at every crossing
    pm, y = chaos
    lam = lyapunov_exponents(pm, y, 60, n_exponents=6).exponents
    target = -np.trace(np.linalg.solve(SYSTEM.M, SYSTEM.C))
    assert abs(lam.sum() - target) < 1e-8 * abs(target), (lam.sum(), target)  # round-off of 60 QR steps
    assert lam[0] > 10.0  # chaos (response map: ~50 1/s here)


def test_tangent_and_two_runs_agree_in_chaos(chaos):
    # two independent methods: the QR of the tangent, and the divergence of two exact runs 1e-8 apart
    # renormalised each period (Benettin 1980), from different random directions; both averaged over the
    # same 300 periods after 30 that align them
    pm, y = chaos
    a = lyapunov_exponents(pm, y, 300, n_transient=30, seed=1)
    b = lyapunov_two_runs(pm, y, 300, n_transient=30, seed=2)
    # the same trajectory, so the same finite-time average up to the alignment of the vectors (a few
    # periods of log-growth, ~1/300 of the sum) and the two-run method's finite separation
    assert abs(a.largest - b.largest) < 0.02 * a.largest, (a.largest, b.largest)
    assert a.largest > 10.0


def test_a_linear_systems_exponent_is_its_slowest_decay_rate():
    # a gap far beyond the motion: the map is exp(A T) plus a constant, lambda_i = Re(eig A), each twice
    # (a pair per mode); the largest is minus the slowest decay rate
    sy = DiscreteParams(gap=1.0).system()
    n = sy.n
    Minv = np.linalg.inv(sy.M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ sy.K, -Minv @ sy.C]])
    re = np.sort(np.linalg.eigvals(A).real)[::-1]
    pm = PeriodMap(sy, LOAD, 0.1, 40.0)
    res = lyapunov_exponents(pm, np.zeros(6), 4000, n_transient=100, n_exponents=6)
    # finite time: the growth of a vector in the energy norm, where the undamped modes are orthogonal,
    # deviates from exp(-sigma t) by the damping's mode coupling, a factor bounded over the run:
    # log(bound) / (K T) with K T = 100 s
    assert np.allclose(res.exponents, re, rtol=0, atol=0.01), (res.exponents, re)
    assert math.isclose(res.largest, re[0], abs_tol=2e-3), (res.largest, re[0])
