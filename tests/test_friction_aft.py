"""Friction in the forced harmonic balance (issue 27): the Jenkins element by AFT against closed forms, finite
differences and the exact integrator's settled orbits.

The system of the HB-versus-time checks is the Coulomb oscillator of tests/test_friction.py: a mass on a spring
rubbing on a contact pressed into its stop, so the normal force N_REST is held by the stop (and stays: nothing
loads the normal coordinate), and Den Hartog's closed form applies with F = mu N_REST.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_friction import K_X, M_X, N_REST, Z_REST, coulomb

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteFrictionParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.forced_stability import forced_hill
from reduced.periodic.frc import harmonic_amplitudes, max_abs_over_period, solution_at_frequency
from reduced.periodic.friction_aft import (
    OPEN,
    SLIP,
    STICK,
    FrictionBalance,
    den_hartog_amplitude,
    friction_frc,
    jenkins_describing_function,
    jenkins_loop,
)
from reduced.periodic.hb import _phases, _projection_matrix, newton
from reduced.periodic.stability import HILL_TOL
from reduced.transient.friction import integrate_exact_friction

B_X = np.array([1.0, 0.0])  # the load along the tangential coordinate x


def solve(fb: FrictionBalance, omega: float, x_ref: float = 1e-4) -> np.ndarray:
    """z of the balance at omega, by Newton from the linear response (the normal coordinate at rest)."""
    z = fb.linear_z(omega)
    z[1] = Z_REST  # the constant harmonic of z: pressed into its stop

    def fun(v):
        R, J, _ = fb.residual(v * x_ref, omega)
        return R / x_ref, J

    with single_thread_blas():
        return newton(fun, z / x_ref, tol=1e-12, max_iter=100).y * x_ref


# -- the element in time ---------------------------------------------------------------------------
def _jenkins_loop_python(t, N, k_t, mu):
    """The Python loop jenkins_loop ran before its numba kernel (session 13), kept as the bit-for-bit reference."""
    OPEN_, STICK_, SLIP_ = 0, 1, 2
    Ns = t.size
    tt, NN = [float(v) for v in t], [float(v) for v in N]
    f_out, state, anchor, sign = np.zeros(Ns), np.zeros(Ns, np.int64), np.arange(Ns), np.zeros(Ns)
    f, a, s_a = 0.0, 0, 0.0
    for n in range(2 * Ns):
        i = n % Ns
        limit = mu * NN[i]
        if limit <= 0.0:
            f, a, s_a, st, s = 0.0, i, 0.0, OPEN_, 0.0
        else:
            trial = f + k_t * (tt[i] - tt[i - 1]) if n > 0 else 0.0
            if abs(trial) < limit:
                f, st, s = trial, STICK_, s_a
            else:
                s = 1.0 if trial > 0.0 else -1.0
                f, a, s_a, st = s * limit, i, s, SLIP_
        if n >= Ns:
            f_out[i], state[i], sign[i] = f, st, s
            anchor[i] = a if st == STICK_ else i
    return f_out, state, anchor, sign


@pytest.mark.parametrize("seed", range(6))
def test_jenkins_loop_kernel_is_the_python_loop_bit_for_bit(seed):
    """The numba return map gives the Python loop's force, states, anchors and signs to the bit: random
    harmonic inputs whose normal force opens part of the period (open, stick and slip all visited), on a
    strided column as the balance passes it."""
    rng = np.random.default_rng(seed)
    Ns = int(rng.choice([16, 64, 256]))
    tau = 2 * np.pi * np.arange(Ns) / Ns
    H = 5
    c = rng.standard_normal((2 * H + 1, 2)) / (1.0 + np.arange(2 * H + 1))[:, None]
    E = np.column_stack([np.ones(Ns)] + [f(k * tau) for k in range(1, H + 1) for f in (np.cos, np.sin)])
    qs = E @ c  # (Ns, 2): column 0 the tangential motion, column 1 the normal one
    k_t, mu = float(rng.uniform(5.0, 50.0)), float(rng.uniform(0.1, 0.6))
    N = 20.0 * (qs[:, 1] - 0.2 * float(seed % 3))
    loop = jenkins_loop(qs[:, 0], N, k_t, mu)
    ref = _jenkins_loop_python(qs[:, 0], N, k_t, mu)
    assert {int(v) for v in loop.state} >= ({1, 2} if seed % 3 == 0 else {2})  # the cases are visited
    for got, want in zip((loop.f, loop.state, loop.anchor, loop.sign), ref, strict=True):
        assert got.dtype == want.dtype and np.array_equal(got, want)
        assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("a", [0.02, 0.05, 0.08, 0.3, 3.0])
def test_jenkins_loop_fundamental_is_the_describing_function(a):
    # t = a cos(tau) under a constant slip force: the fundamental of the AFT loop against the closed form
    # (full stick for k_t a <= f_s). Tolerance: the stick-slip switch falls between samples, an O(1/Ns^2)
    # error in the coefficients (measured 4e-7 k_t a at Ns = 4096)
    k_t, f_s, Ns = 10.0, 0.5, 4096
    tau = _phases(Ns)
    loop = jenkins_loop(a * np.cos(tau), np.full(Ns, 1.0), k_t, f_s)
    c = _projection_matrix(1, tau) @ loop.f
    a1, b1 = jenkins_describing_function(a, k_t, f_s)
    assert abs(c[1] - a1) < 1e-5 * k_t * a and abs(c[2] - b1) < 1e-5 * k_t * a, (c, a1, b1)
    if k_t * a > f_s:  # a slipping loop is half-wave symmetric: no mean force (a stuck one keeps f(0) = 0)
        assert abs(c[0]) < 1e-12 * k_t * a


def test_describing_function_limits():
    # large amplitude: Coulomb's -4 f_s / pi in quadrature, the in-phase part ~ k_t a beta^3 (2/3) / pi -> 0
    a1, b1 = jenkins_describing_function(1e6, 10.0, 0.5)
    assert b1 == pytest.approx(-4 * 0.5 / math.pi, rel=1e-6) and abs(a1) < 1e-3 * abs(b1)
    assert jenkins_describing_function(0.04, 10.0, 0.5) == (0.4, 0.0)  # stuck: the spring k_t


def test_jenkins_loop_derivatives_match_finite_differences():
    # df_i / dt_j and df_i / dN_j of the two-period march against central differences, on a loop that opens,
    # sticks and slips both ways; 1e-7 relative (a smooth branch of the map: the steps move no sample across
    # a switch)
    Ns = 96
    tau = _phases(Ns)
    t = 1e-3 * (np.cos(tau) + 0.3 * np.sin(3 * tau))
    N = 40.0 * (np.cos(2 * tau) + 0.3)  # <= 0: open (no sample at N = 0 exactly, a switch)
    k_t, mu = 1e5, 0.3
    loop = jenkins_loop(t, N, k_t, mu)
    assert set(loop.state.tolist()) == {0, STICK, SLIP}
    G, Hn = loop.derivatives(k_t, mu)
    h_t, h_n = 1e-10, 1e-7
    Gfd = np.empty_like(G)
    Hfd = np.empty_like(Hn)
    for j in range(Ns):
        e = np.zeros(Ns)
        e[j] = 1.0
        Gfd[:, j] = (jenkins_loop(t + h_t * e, N, k_t, mu).f - jenkins_loop(t - h_t * e, N, k_t, mu).f) / (2 * h_t)
        Hfd[:, j] = (jenkins_loop(t, N + h_n * e, k_t, mu).f - jenkins_loop(t, N - h_n * e, k_t, mu).f) / (2 * h_n)
    assert np.max(np.abs(G - Gfd)) < 1e-7 * k_t
    assert np.max(np.abs(Hn - Hfd)) < 1e-7 * mu


# -- the balance -----------------------------------------------------------------------------------
def test_balance_jacobian_matches_finite_differences():
    # the discrete friction model driven vertically and axially, at a state whose tips open, stick and slip:
    # dR/dz and dR/dOmega (exact stop projection + AFT sliders) against central differences, 1e-7 relative
    s = DiscreteFrictionParams().system()
    fb = FrictionBalance(s, np.array([0.0, 1.0, 0.0, 0.5]), 2.0, 0.0, 5, 64, False, None, 256)
    w = 2 * np.pi * 16.0
    rng = np.random.default_rng(1)
    z = 1.5 * fb.linear_z(w) + 1e-6 * rng.standard_normal(fb.size)
    states = fb.slider_state(z)
    assert np.all(states > 0.0), states  # open, stick and slip on both sliders
    with single_thread_blas():
        R, J, dRdw = fb.residual(z, w)
        h = 1e-7 * np.max(np.abs(z))
        Jfd = np.empty_like(J)
        for i in range(fb.size):
            e = np.zeros(fb.size)
            e[i] = h
            Jfd[:, i] = (fb.residual(z + e, w)[0] - fb.residual(z - e, w)[0]) / (2 * h)
        dw = 1e-6 * w
        dfd = (fb.residual(z, w + dw)[0] - fb.residual(z, w - dw)[0]) / (2 * dw)
    assert np.max(np.abs(J - Jfd)) < 1e-7 * np.max(np.abs(J))
    assert np.max(np.abs(dRdw - dfd)) < 1e-7 * np.max(np.abs(dRdw))


def test_full_stick_is_the_linear_system_with_the_tangential_spring():
    # mu N far above any force: the slider never slips, the fundamental is that of k + k_t (exact up to
    # round-off: a linear spring's AFT is exact)
    kt, P, c = 1e5, 1.0, 2.0
    s = coulomb(mu=1e3, kt=kt, c=c)
    fb = FrictionBalance(s, B_X, P, 0.0, 3, 64, False, None, 128)
    w = 2 * np.pi * 30.0
    X = fb.response(solve(fb, w), w)
    amp = harmonic_amplitudes(X, np.eye(2))[0, 1]
    assert amp == pytest.approx(P / abs(K_X + kt - M_X * w**2 + 1j * w * c), rel=1e-10)


@pytest.mark.parametrize("r", [0.7, 1.4])
def test_den_hartog_steady_response(r):
    # continuous slip (F / P = 0.3): the amplitude against Den Hartog's closed form. Tolerance 1.5%: the
    # Jenkins element's compliance (k_t = 1e3 k) and H = 15 odd-and-even harmonics of a sign-like force
    # (measured -0.4% at r = 0.7 and +0.7% at r = 1.4; the frictionless amplitude is 3.9% and 10% away)
    mu, P = 0.3, 10.0
    F = mu * N_REST
    s = coulomb(mu=mu, kt=1e3 * K_X)
    w = r * math.sqrt(K_X / M_X)
    ref = den_hartog_amplitude(M_X, K_X, P, F, w)
    assert abs(P / K_X / abs(1 - r * r) / ref - 1.0) > 0.03
    fb = FrictionBalance(s, B_X, P, 0.0, 15, 64, False, None, 8192)
    z = solve(fb, w)
    amp = max_abs_over_period(fb.response(z, w), np.eye(2))[0]
    assert abs(amp / ref - 1.0) < 0.015, (amp, ref)
    # the same with the normal load given as a constant: the stop's N is exactly N_REST
    fc = FrictionBalance(s, B_X, P, 0.0, 15, 64, False, N_REST, 8192)
    with single_thread_blas():
        R, _, _ = fc.residual(z, w)
    assert np.max(np.abs(R)) < 1e-9 * np.max(np.abs(z))


@pytest.mark.parametrize("freq_hz", [12.0, 20.0])
def test_hb_matches_the_exact_settled_orbit_through_stick_slip(freq_hz):
    # P = 4 N against F = 2.97 N: the mass sticks for part of each period (asserted). The HB amplitude
    # (H = 31) against the exact integrator's orbit settled from rest (40 periods, the last one sampled at
    # 2000 points a period); 0.5%: the H truncation of the force's kinks (H = 15 errs by 1.3% at 12 Hz) and the
    # AFT sampling of the switches; the orbit it settles on is stable by Hill's method on the AFT Jacobian
    P, spp, periods = 4.0, 2000, 40
    s = coulomb(mu=0.3, kt=1e6, c=2.0)
    w = 2 * np.pi * freq_hz
    fb = FrictionBalance(s, B_X, P, 0.0, 31, 64, False, None, 2048)
    z = solve(fb, w)
    stick = fb.slider_state(z)[0, 1]
    assert 0.02 < stick < 0.5, stick
    amp = max_abs_over_period(fb.response(z, w), np.eye(2))[0]
    run = integrate_exact_friction(s, np.array([0.0, Z_REST]), np.zeros(2), periods / freq_hz, spp * freq_hz,
                                   loads=Loads(B_X[None, :], (Harmonic(P, freq_hz),)))
    last = np.abs(run.x[-spp - 1:, 0]).max()
    before = np.abs(run.x[-2 * spp - 1:-spp, 0]).max()
    assert abs(last / before - 1.0) < 1e-6  # settled
    assert abs(amp / last - 1.0) < 5e-3, (amp, last)
    with single_thread_blas():
        assert np.max(np.abs(forced_hill(fb, z, w))) <= 1.0 + HILL_TOL


def test_friction_frc_continues_through_stick_slip():
    # the continued curve (H = 9, coarse for speed) over 17-26 Hz at 4 N: it crosses the band, every point is
    # stable by Hill's method (the exact runs settle on them: test above), and at 18 and 25 Hz it is within 6%
    # of the exact settled orbits (3.2457e-4 m and 7.8484e-5 m, from the test above and
    # results/friction-frc/friction_frc_checks.csv): H = 9 truncates the stick-slip kinks (4.8% and 2.9%
    # measured; 7e-4 at H = 31)
    s = coulomb(mu=0.3, kt=1e6, c=2.0)
    br = friction_frc(s, B_X, 4.0, 17.0, 26.0, 9, samples=512, x_ref=1e-4)
    assert br.status == "stop" and br.freq_hz.max() > 25.0  # left the band (its last point past 26 Hz dropped)
    assert np.all(br.stable) and br.bifurcations == []
    for f, exact in ((18.0, 3.2457e-4), (25.0, 7.8484e-5)):
        amp, _, _ = solution_at_frequency(br, f)
        assert abs(amp[0] / exact - 1.0) < 0.06, (f, amp[0], exact)
        stick = br.balance.slider_state(br.z[np.argmin(np.abs(br.freq_hz - f))])[0, 1]
        assert 0.0 < stick < 1.0  # the point sticks and slips


def test_slider_state_is_kept_per_point_and_equal_to_the_loops():
    # slider_state is read several times a point by the stage (bands, frc.csv, frc.md, frc.png): it is worked out
    # once for each z and given as a copy; against the loops' states counted directly, at points that differ
    # (a kept state of another z would fail), and a caller's change to the copy does not reach the next call
    s = DiscreteFrictionParams().system()
    fb = FrictionBalance(s, np.array([0.0, 1.0, 0.0, 0.5]), 2.0, 0.0, 5, 64, False, None, 256)
    w = 2 * np.pi * 16.0
    rng = np.random.default_rng(1)
    zs = [c * fb.linear_z(w) + 1e-6 * rng.standard_normal(fb.size) for c in (0.2, 1.0, 1.5)]
    for _ in range(2):
        for z in zs:
            direct = np.array([[np.mean(lp.state == k) for k in (OPEN, STICK, SLIP)]
                               for lp in fb.loops(fb.full_q(z))])
            got = fb.slider_state(z)
            assert np.array_equal(got, direct)
            got[:] = -1.0
    assert len(fb._states) == 3
    assert not np.array_equal(fb.slider_state(zs[0]), fb.slider_state(zs[2]))


def _contact_every_term(fb, q):
    """FrictionBalance.contact as first written: every slider's projections summed, zeros included."""
    h, u, ug = 2 * fb.H + 1, fb.u, fb._gap.u
    phi, dphi = np.zeros((h, u)), np.zeros((u, h, u, h))
    pg, dpg, _ = fb._gap.contact(q[:, :ug])
    phi[:, :ug] = pg
    for r in range(ug):
        dphi[r, :, r, :] = dpg[r]
    fr, E, P = fb.system.friction, fb._E, fb._P
    qs = E @ q
    for k in range(fr.p):
        rt = fb.trow[k]
        N, terms = fb.normal_force(qs, k)
        loop = jenkins_loop(qs[:, rt], N, fr.k_t[k], fr.mu[k])
        GE, c, j = loop.synthesised(E, fr.k_t[k], fr.mu[k])
        phi[:, rt] += P @ loop.f
        dphi[rt, :, rt, :] += P @ GE
        for r, dN in terms:
            dphi[rt, :, r, :] += P @ ((c * dN[j])[:, None] * E[j])
    return phi, dphi


def test_contact_without_the_zero_terms_is_every_terms_bits():
    # contact skips a slider open over the whole period and a stop that never engages it: the same bits (to the
    # sign of every zero: int64 views) as summing their zero projections, at points open, in contact on one stop
    # of a tip, and through stick-slip
    s = DiscreteFrictionParams().system()
    fb = FrictionBalance(s, np.array([0.0, 1.0, 0.0, 0.5]), 2.0, 0.0, 5, 64, False, None, 256)
    w = 2 * np.pi * 16.0
    rng = np.random.default_rng(1)
    skipped = 0
    with single_thread_blas():
        for c in (0.05, 0.3, 1.0, 1.5, 3.0):
            z = c * fb.linear_z(w) + 1e-6 * c * rng.standard_normal(fb.size)
            q = fb.full_q(z)
            phi, dphi, _ = fb.contact(q)
            phi0, dphi0 = _contact_every_term(fb, q)
            assert np.array_equal(phi.view(np.int64), phi0.view(np.int64))
            assert np.array_equal(dphi.view(np.int64), dphi0.view(np.int64))
            skipped += sum(not lp.state.any() for lp in fb.loops(q))
    assert skipped > 0  # an open point was among them
