"""The fast paths of the ringdown integrators (issue 14) against the code they replaced and against
independent references: no crossing missed, the same bits where the arithmetic was kept.

- the exact integrator's free segments (:mod:`reduced.transient._modal`: conjugate-pair modal form,
  one march for all stops with quadratic, cubic and amplitude bounds) find the same first crossing
  as the single-stop march of :func:`reduced.transient.exact._first_root` on the full 2n-term series,
  from random states of random systems;
- densely sampled runs keep the energy balance E(0) = E(t) + W(t) at every sample: a contact the
  march stepped over would leave its penalty energy unaccounted for while it lasts;
- DOP853 restarted at every crossing sees a contact entered and left inside one of its steps;
- the central-difference kernel gives the bits of the row-by-row recurrence it replaced.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.models.loads import HalfSine, Loads
from reduced.studies import relative_error
from reduced.transient import _exact_kernels as exk
from reduced.transient import _modal
from reduced.transient import exact as ex
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.explicit import _damping_factor, integrate_explicit
from reduced.transient.integrate import ringdown

P = DiscreteParams()
IMPULSE = (np.zeros(3), np.array([0.0, 0.0, 200.0]))


def chain(n: int, c: float, seed: int) -> GapSystem:
    """n masses on springs to ground and between neighbours (random, seeded), two-sided clearances at
    the first and the last mass (0.2 mm, 3.5e7 N/m), damping c at every mass."""
    rng = np.random.default_rng(seed)
    m = rng.uniform(0.5, 2.0, n)
    kg = rng.uniform(2e3, 2e4, n)
    kc = rng.uniform(1e4, 1e5, n - 1)
    K = np.diag(kg)
    for i, k in enumerate(kc):
        K[i:i + 2, i:i + 2] += k * np.array([[1.0, -1.0], [-1.0, 1.0]])
    rows = np.zeros((2, n))
    rows[0, 0] = rows[1, -1] = 1.0
    stops = two_sided_stops(rows, 3.5e7, 2e-4, ("a", "b"))
    return GapSystem(M=np.diag(m), C=c * np.eye(n), K=K, dof_names=tuple(f"x{i}" for i in range(n)), **stops)


def first_crossing_both_ways(system: GapSystem, y: np.ndarray, active: np.ndarray, tau_limit: float):
    """(tau, j) of the first crossing from (y, active) by the joint march of _modal and by the
    single-stop march of exact._first_root over every stop (the code the joint march replaced)."""
    table = ex.state_table(system)
    mt = ex.modal_table(system, table)
    (nK, lam, alam, UT, Uinv, aUinv, yp, BU, aBU, Byp, *_) = mt
    n, m = system.n, system.m
    N, Kmax = 2 * n, lam.shape[1]
    s = int(np.sum(active * (1 << np.arange(m))))
    hmin = ex.HMIN_PERIODS / system.omega_max()
    floor = 0.0
    K = int(nK[s])
    w, werr = np.empty(Kmax, complex), np.empty(Kmax)
    coef, lc, l2c = (np.empty((m, Kmax), complex) for _ in range(3))
    a0 = np.empty((m, Kmax))
    const, qtol, dnoise, hprev, hnext = (np.empty(m) for _ in range(5))
    live = np.empty(m, bool)
    n_live = _modal._start(s, K, y, Uinv, aUinv, yp, BU, aBU, Byp, lam, alam, system.offset, system.side, active,
                           floor, w, werr, coef, lc, l2c, a0, const, qtol, dnoise, live, np.empty(N), np.empty(N))
    tau_new, j_new, _ = _modal._march(s, K, lam, alam, const, coef, lc, l2c, a0, qtol, dnoise, live, n_live,
                                      tau_limit, hmin, np.empty(Kmax, complex), np.empty(Kmax), hprev, hnext,
                                      np.empty((m, _modal.MARCH_COLS)), np.ones(Kmax))
    X, werr2 = np.empty((N, N), complex), np.empty(N)
    exk._modal_start(table.V[s], table.Vinv[s], y, table.yp[s], X, werr2)
    tau_old, j_old = tau_limit, -1
    cf = np.empty(N, complex)
    for j in range(m):
        sgn = -system.side[j] if active[j] else system.side[j]
        const_j = exk._stop_series(system.B, j, sgn, system.offset[j], table.yp[s], X, cf)
        pv = system.B[j] @ table.V[s, :n]
        qn = float(np.sum(np.abs(pv) * werr2))
        dn = float(np.sum(np.abs(pv) * np.abs(table.lam[s]) * werr2))
        tj, _ = exk._first_root(const_j, cf, table.lam[s], tau_old, hmin, qn, dn, floor)
        if tj < tau_old:
            tau_old, j_old = tj, j
    return (tau_new, j_new), (tau_old, j_old)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.sampled_from([2, 3, 5]), c=st.sampled_from([0.0, 0.5, 20.0]),
       state=st.integers(0, 8), speed=st.floats(1e-3, 10.0))
def test_joint_march_finds_the_single_stop_marches_first_crossing(seed, n, c, state, speed):
    # both marches are rigorous (no root stepped over), so they must agree on which stop crosses
    # first and when: to round-off, or to the single-stop march's step floor hmin, which can carry it
    # past a steep crossing by up to hmin (1.7e-13 s past a root the joint march puts within 1e-22 s)
    system = chain(n, c, seed)
    feasible = system.feasible_states()
    active = feasible[state % len(feasible)]
    rng = np.random.default_rng(seed + 1)
    x = rng.uniform(-3e-4, 3e-4, n)
    v = speed * rng.standard_normal(n)
    for tip, dof in ((0, 0), (1, n - 1)):  # the tips' positions consistent with the contact state
        upper, lower = active[2 * tip], active[2 * tip + 1]
        x[dof] = 2.1e-4 if upper else -2.1e-4 if lower else 0.5 * x[dof]
    y = np.concatenate([x, v])
    tau_limit = 20.0 * 2 * math.pi / system.omega_max()
    (tau_new, j_new), (tau_old, j_old) = first_crossing_both_ways(system, y, active, tau_limit)
    assert j_new == j_old, f"first stop {j_new} (joint) vs {j_old} (single-stop) at {tau_new:.17g} / {tau_old:.17g}"
    if j_new >= 0:
        hmin = ex.HMIN_PERIODS / system.omega_max()
        assert tau_new == pytest.approx(tau_old, rel=1e-12, abs=2.0 * hmin)


@pytest.mark.parametrize("case", ["impulse", "graze", "soft-damped", "chain"])
def test_densely_sampled_runs_keep_the_energy_balance_at_every_sample(case):
    # at 1 MHz every contact longer than 1 us has samples inside it; a stepped-over crossing would
    # leave 1/2 k pen^2 of penalty energy out of E(t) there (1e-4 of E(0) and more here). The graze's
    # contacts (~1e-7 s) fall between samples: there the event count says none was stepped over
    T, fs = 0.01, 1e6
    if case == "impulse":
        system, x0, v0 = P.system(), *IMPULSE
    elif case == "graze":  # the antisymmetric NNM just above grazing: contacts of ~1e-5 of a period
        p = replace(P, c=0.0)
        x0 = P.gap * (1 + 1e-9)
        system, x0, v0 = p.system(), np.array([x0, 0.0, -x0]), np.zeros(3)
        T, fs = 0.08, 2e5  # 4 half periods: enter and leave at both tips in each
    elif case == "soft-damped":
        system, x0, v0 = replace(P, c=40.0, k_g=1e6).system(), *IMPULSE
    else:
        system = chain(5, 0.5, 7)
        x0, v0 = np.zeros(5), np.array([0.0, 3.0, -2.0, 1.0, 0.0])
    res = ringdown(system, x0, v0, T, fs, "exact")
    assert res.stats["n_events"] >= (16 if case == "graze" else 4)
    assert res.energy_balance_error < 1e-11


def test_two_second_impulse_ringdown_keeps_its_accuracy():
    # the run issue 14 times: the balance holds to round-off over ~12,500 events
    res = ringdown(P.system(), *IMPULSE, 2.0, 20000.0, "exact")
    assert res.stats["n_events"] > 10_000
    assert res.energy_balance_error < 5e-12


def test_exact_matches_the_dop853_reference_over_the_first_tenth_of_a_second():
    # DOP853 at rtol 1e-12 restarted at every crossing: independent of the closed form and of the
    # march; over 0.05 s (~470 events) its own error is ~1e-10 (chaotic growth of its tolerance)
    sys = P.system()
    a = ringdown(sys, *IMPULSE, 0.05, 20000.0, "exact")
    b = integrate_dop853(sys, *IMPULSE, 0.05, 20000.0, rtol=1e-12, events=True)
    assert a.stats["n_events"] == b.stats["n_events"]
    assert relative_error(a.x, b.x) < 1e-8


def one_dof_graze(depth: float) -> tuple[GapSystem, np.ndarray, np.ndarray]:
    """A mass on a spring (omega = 100 rad/s) swinging to depth x its 1 mm gap past a stiff stop."""
    system = GapSystem(M=np.eye(1), C=np.zeros((1, 1)), K=np.array([[1e4]]), B=np.eye(1), k=np.array([1e8]),
                       offset=np.array([1e-3]), side=np.array([1.0]), tip=np.array([0]), dof_names=("x",),
                       stop_names=("stop",))
    return system, np.array([1e-3 * (1 + depth)]), np.zeros(1)


def test_dop853_reference_sees_a_contact_entered_and_left_inside_one_step():
    # started 1e-4 of the gap inside the stop: a contact of ~3e-4 of a period, far shorter than a
    # DOP853 step at rtol 1e-6; the end-point test alone misses it and the motion never reflects
    system, x0, v0 = one_dof_graze(1e-4)
    T = 0.2
    a = ringdown(system, np.array([-x0[0]]), v0, T, 5000.0, "exact")
    b = integrate_dop853(system, np.array([-x0[0]]), v0, T, 5000.0, rtol=1e-6, events=True)
    assert a.stats["n_events"] >= 2
    assert b.stats["n_events"] == a.stats["n_events"]
    assert relative_error(b.x, a.x) < 1e-3  # rtol 1e-6 over three periods and six contacts


def test_forced_run_after_the_blow_is_the_free_run_from_its_state():
    # where every load is zero the forced run goes through the free kernel; started from the state the
    # blow left, a free run must agree to round-off (the piece grids differ, so not bit for bit)
    sys = P.system()
    blow = HalfSine(peak_N=500.0, duration_s=1e-3, start_s=0.0)
    loads = Loads(np.array([[0.0, 1.0, 0.0]]), (blow,), ("x2",))
    fs = 20000.0
    forced = ringdown(sys, np.zeros(3), np.zeros(3), 0.02, fs, "exact", loads=loads)
    k = int(round(blow.end_s * fs))  # the sample at the blow's end
    free = ringdown(sys, forced.x[k], forced.v[k], 0.02 - k / fs, fs, "exact")
    assert forced.stats["n_events"] > 0
    assert relative_error(free.x, forced.x[k:]) < 1e-9
    assert forced.energy_balance_error < 1e-11


def row_by_row_cd(system: GapSystem, x0, v0, dt: float, n_steps: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The central-difference recurrence as the kernel computed it before issue 14, in plain Python
    floats (IEEE: the same bits for the same operations): rows summed c = 0 .. n - 1."""
    n, m = system.n, system.m
    M, C, K = system.M, system.C, system.K
    G = np.linalg.inv(M + 0.5 * dt * C)
    A = (G @ (M - 0.5 * dt * C)).tolist()
    dtGK = (dt * (G @ K)).tolist()
    dtGB = (dt * (G @ system.B.T)).tolist()
    L = _damping_factor(C).tolist()
    B, off, side, kk = system.B.tolist(), system.offset.tolist(), system.side.tolist(), system.k.tolist()
    x = [float(v) for v in x0]
    a0 = np.linalg.solve(M, -(K @ x0) - system.contact_force(x0) - C @ v0)
    vh = [float(v) for v in v0 + 0.5 * dt * a0]
    r = len(L[0]) if L else 0
    pw = sum(sum(L[i][q] * float(v0[i]) for i in range(n)) ** 2 for q in range(r)) if r else 0.0
    W = 0.0
    for _ in range(n_steps):
        for i in range(n):
            x[i] += dt * vh[i]
        f = []
        for j in range(m):
            s = -off[j]
            for i in range(n):
                s += B[j][i] * x[i]
            f.append(kk[j] * s if side[j] * s > 0.0 else 0.0)
        vnew = []
        for i in range(n):
            acc = 0.0
            for c in range(n):
                acc += A[i][c] * vh[c] - dtGK[i][c] * x[c]
            for j in range(m):
                acc -= dtGB[i][j] * f[j]
            vnew.append(acc)
        v_int = [0.5 * (vh[i] + vnew[i]) for i in range(n)]
        vh = vnew
        pw_new = 0.0
        for q in range(r):
            s = 0.0
            for i in range(n):
                s += L[i][q] * v_int[i]
            pw_new += s * s
        W += 0.5 * dt * (pw + pw_new)
        pw = pw_new
    return np.array(x), np.array(v_int), W


@pytest.mark.parametrize("model", ["discrete", "chain"])
def test_central_difference_kernel_gives_the_row_by_row_bits(model):
    system = P.system() if model == "discrete" else chain(6, 0.5, 3)
    x0 = np.zeros(system.n)
    v0 = np.zeros(system.n)
    v0[-1] = 200.0 if model == "discrete" else 5.0
    fs, steps = 20000.0, 400
    res = integrate_explicit(system, x0, v0, steps / fs, fs, dt=1.0 / fs / 4)  # 4 steps a sample
    x, v, W = row_by_row_cd(system, x0, v0, res.stats["dt"], 4 * steps)
    assert res.stats["n_steps"] == 4 * steps
    assert np.array_equal(res.x[-1], x) and np.array_equal(res.v[-1], v) and res.dissipated[-1] == W


@pytest.mark.parametrize("c", [400.0, 2000.0])
def test_overdamped_states_match_the_dop853_reference(c):
    # heavy damping makes some modes overdamped (real eigenvalues, kept once instead of as a conjugate
    # pair), so the states have different numbers of terms (5, 4 and 3 here): padded terms add nothing
    p = replace(P, c=c)
    system = p.system()
    table = ex.state_table(system)
    nK = ex.modal_table(system, table)[0][table.valid]
    assert len(set(nK.tolist())) > 1
    a = ringdown(system, *IMPULSE, 0.02, 20000.0, "exact")
    b = integrate_dop853(system, *IMPULSE, 0.02, 20000.0, rtol=1e-12, events=True)
    assert a.stats["n_events"] == b.stats["n_events"] > 10
    assert relative_error(a.x, b.x) < 1e-9
    assert a.energy_balance_error < 1e-12
