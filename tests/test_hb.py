"""Harmonic balance: Jacobians, the Duffing backbone, NNM 2 against its exact relation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2
from reduced.periodic.backbones import hb_backbones, nnm_branch
from reduced.periodic.hb import (
    CubicForce,
    HarmonicBalance,
    NewtonError,
    NNMResidual,
    default_samples,
    newton,
)

P = DiscreteParams()
SYS = P.system()


def _fd_jacobian(fun, y, rel=1e-7):
    """Central differences, column i stepped by h_i = rel max(1, |y_i|): (J, h)."""
    R0 = fun(y)[0]
    J = np.zeros((R0.size, y.size))
    h = rel * np.maximum(1.0, np.abs(y))
    for i in range(y.size):
        e = np.zeros(y.size)
        e[i] = h[i]
        J[:, i] = (fun(y + e)[0] - fun(y - e)[0]) / (2 * h[i])
    return J, h


def _roundoff_bound(J, y, R, h):
    """Bound on |central difference - J| from round-off alone, per column: each evaluation of R errs
    by about eps times the largest term it sums, max(|R|, |J| |y|) (the force is piecewise linear in
    X, so that is the size of the terms), and the difference divides two such errors by 2 h. The
    factor 4 covers the few roundings per term."""
    size = max(float(np.max(np.abs(R))), float(np.max(np.abs(J) @ np.abs(y))))
    return np.broadcast_to(4.0 * np.finfo(float).eps * size / h, J.shape)


def _stop_samples(hb, X):
    """(N, m) m: the stop coordinates B x at the AFT samples, minus each stop's offset (its kink)."""
    return (hb.E @ hb.unpack(X)) @ SYS.B.T - SYS.offset


@pytest.mark.parametrize("H", [1, 3, 7])
def test_residual_jacobian_matches_finite_differences(H):
    # a generic point in contact: random coefficients of a few gaps, well off every kink
    rng = np.random.default_rng(H)
    hb = HarmonicBalance.for_system(SYS, H)
    X = 5 * P.gap * rng.standard_normal(hb.size) / np.arange(1, hb.size + 1)
    omega = 900.0
    R, J, dRdw = hb.residual(X, omega)
    y = np.append(X, omega)
    Jf, h = _fd_jacobian(lambda z: (hb.residual(z[:-1], z[-1])[0], None), y, rel=1e-9)
    Ja = np.column_stack([J, dRdw])
    # the AFT force is piecewise linear in X, so the central difference has no truncation error unless
    # a sample crosses a kink within the step. A step h moves a sample by at most h (|E| <= 1, B selects
    # a DOF): the nearest sample lies 3e-7 m from its kink (H = 7) against h = 1e-9 m, so every entry
    # must agree to round-off. Measured: at most 0.054 of the bound (the bound is 2e-10 to 3e-9 of max |J|).
    assert np.min(np.abs(_stop_samples(hb, X))) > 100 * np.max(h[:-1])
    err = np.abs(Ja - Jf)
    bound = _roundoff_bound(Ja, y, R, h)
    worst = np.unravel_index(np.argmax(err / bound), err.shape)
    assert np.all(err <= bound), f"entry {worst}: {err[worst]:.3g} > bound {bound[worst]:.3g}"


def test_nnm_residual_jacobian_matches_finite_differences():
    hb = HarmonicBalance.for_system(SYS, 5)
    lin = linear_modes(SYS)
    res = NNMResidual(hb, float(lin.omega[1]), 0)
    rng = np.random.default_rng(1)
    y = res.start(lin.phi[:, 1], float(lin.omega[1]) * 3.0, math.log10(0.01))
    y[:-3] += 0.05 * rng.standard_normal(hb.size)
    y[-2] = 0.01
    R, J = res(y)
    Jf, h = _fd_jacobian(res, y, rel=1e-8)
    # X = a Psi with a = 10^y[-1] = 0.01: a step moves a sample by at most a h (a Psi column) or
    # ln(10) h max|x| (the log a column), ~1e-9 m, against 3.8e-6 m from the nearest sample to its kink.
    # Off the kinks R is smooth in y (omega^2, 10^y): the truncation h^2 R''' / 6 is ~1e-16 of R,
    # below round-off. Measured: every entry within 0.16 of the bound (the bound is 1e-7 of max |J|).
    Psi, _, _, a = res.split(y)
    s = _stop_samples(hb, a * Psi)
    moved = a * np.max(h[:-3]) + math.log(10) * h[-1] * np.max(np.abs(s + SYS.offset))
    assert np.min(np.abs(s)) > 100 * moved
    err = np.abs(J - Jf)
    bound = _roundoff_bound(J, y, R, h)
    worst = np.unravel_index(np.argmax(err / bound), err.shape)
    assert np.all(err <= bound), f"entry {worst}: {err[worst]:.3g} > bound {bound[worst]:.3g}"


def test_projection_inverts_synthesis():
    hb = HarmonicBalance.for_system(SYS, 4, 9)  # the minimal N = 2H + 1
    assert np.allclose(hb.P @ hb.E, np.eye(9), atol=1e-13)
    with pytest.raises(ValueError):
        HarmonicBalance.for_system(SYS, 4, 8)


@pytest.mark.parametrize(("H", "N"), [(1, 3), (4, 9), (4, 10), (7, 17), (15, 1024), (50, 4096)])
def test_weighted_gram_by_fft_is_the_product(H, N):
    # G = P diag(w) E from one FFT (trig product identities) against the O(N H^2) product, for
    # random weights and gap-like ones (a stiffness on a short contact arc, zero elsewhere);
    # the tolerance is round-off summed over N samples as a random walk (100 eps sqrt(N) |w|_inf);
    # a wrong index or sign in the identities errs by O(|w|_inf)
    hb = HarmonicBalance.for_system(SYS, H, N)
    rng = np.random.default_rng(H * N)
    arc = np.zeros(N)
    arc[N // 7 : N // 7 + max(N // 20, 1)] = 3.5e7
    for w in (rng.standard_normal(N), arc):
        direct = (hb.P * w) @ hb.E
        G = hb.weighted_gram(w)
        assert np.max(np.abs(G - direct)) <= 100 * np.finfo(float).eps * np.sqrt(N) * np.max(np.abs(w))
    assert not np.any(hb.weighted_gram(np.zeros(N)))


def test_default_samples_grow_with_harmonics():
    assert default_samples(1) >= 96 and default_samples(50) >= 32 * 101
    assert all(default_samples(h) > 4 * h + 1 for h in (1, 5, 25, 50))


def _duffing_at_amplitude(H, A, N=None):
    """omega of x'' + x + x^3 = 0 with x(0) = A by HB (H harmonics)."""
    hb = HarmonicBalance(np.eye(1), np.eye(1), CubicForce(np.ones(1)), H, N or (4 * H + 1))
    nX = hb.size
    DM = np.kron(hb.Nab, hb.M)
    xs0 = hb.E[0]  # synthesis row at tau = 0

    def fun(y):
        X, w, d = y[:nX], y[nX], y[nX + 1]
        R, J, dw = hb.residual(X, w)
        Rf = np.concatenate([R - d * w * (DM @ X), [X[2] if H else 0.0], [xs0 @ X - A]])
        Jf = np.zeros((nX + 2, nX + 2))
        Jf[:nX, :nX] = J - d * w * DM
        Jf[:nX, nX] = dw - d * (DM @ X)
        Jf[:nX, nX + 1] = -w * (DM @ X)
        Jf[nX, 2] = 1.0
        Jf[nX + 1, :nX] = xs0
        return Rf, Jf

    y = np.zeros(nX + 2)
    y[1] = A
    y[nX] = math.sqrt(1 + 0.75 * A * A)
    return newton(fun, y, tol=1e-13).y[nX]


@pytest.mark.parametrize("A", [0.5, 1.0, 2.0])
def test_duffing_one_harmonic_is_the_textbook_backbone(A):
    # with one harmonic and N >= 4H + 1 the AFT projection of x^3 is exact, so
    # omega^2 = omega_0^2 + 3/4 gamma A^2 holds to round-off
    w = _duffing_at_amplitude(1, A)
    assert w == pytest.approx(math.sqrt(1 + 0.75 * A * A), rel=1e-13)


@pytest.mark.parametrize("A, exact", [(0.5, 1.0891581788), (1.0, 1.3177760650), (2.0, 1.9760163641)])
def test_duffing_converged_matches_elliptic_integral(A, exact):
    m = A * A / (2 * (1 + A * A))
    assert exact == pytest.approx(math.pi * math.sqrt(1 + A * A) / (2 * ellipk(m)), abs=1e-10)
    # the harmonics of the Duffing solution decay geometrically (H = 9 is still 5e-8 off
    # at A = 2, H = 15 is converged to 3e-11): compare at the 1e-10 of the printed values
    w = _duffing_at_amplitude(15, A)
    assert w == pytest.approx(exact, abs=1e-10)


def test_newton_raises_named_error():
    with pytest.raises(NewtonError):
        newton(lambda y: (np.array([y[0] ** 2 + 1.0]), np.array([[2 * y[0]]])), np.array([0.3]), max_iter=15)


def test_newton_keeps_the_residual_of_the_step_it_takes():
    # an uphill "Jacobian" (the sign of f' flipped): no trial dy, dy/2, ..., dy/32 lowers |R|, so
    # the iteration takes the last one, dy/32, and the next iteration must start from the residual
    # and Jacobian of exactly that point (the bug: it moved by dy/64 and kept dy/32's R and J)
    seen = []

    def fun(y):
        seen.append(float(y[0]))
        return np.array([y[0] ** 2 + 1.0]), np.array([[-2.0 * y[0]]])

    with pytest.raises(NewtonError):
        newton(fun, np.array([0.3]), max_iter=2)
    y0 = 0.3
    dy = (y0**2 + 1.0) / (2.0 * y0)  # -R / J with J = -2 y
    assert seen[1:7] == pytest.approx([y0 + dy / 2**k for k in range(6)], rel=1e-15)
    y1 = y0 + dy / 32.0  # where the first iteration ended
    dy1 = (y1**2 + 1.0) / (2.0 * y1)  # the second step, from y1's own R and J
    assert seen[7] == pytest.approx(y1 + dy1, rel=1e-15)


def test_linear_system_returns_linear_modes_at_every_energy():
    # no stop can ever close (gap 1 m): every NNM is its linear mode, at any energy
    s0 = SYS
    s = GapSystem(s0.M, s0.C, s0.K, s0.B, s0.k, s0.offset * 1e6, s0.side, s0.tip, s0.dof_names, s0.stop_names)
    lin = linear_modes(s)
    for mode in range(3):
        b = nnm_branch(s, mode, H=3, energy_max_J=1e3, energy_start_J=1e-3)
        assert b.energy_J[-1] >= 1e3 and b.energy_J[0] < 1e-2
        assert np.allclose(b.freq_hz, lin.freq_hz[mode], rtol=1e-12, atol=0.0)


def test_nnm2_one_harmonic_tracks_exact_relation():
    b = nnm_branch(SYS, 1, H=1)
    assert b.status == "stop" and b.energy_J[-1] >= 1e5
    exact = nnm2.frequency_from_energy(P, b.energy_J)
    err = np.abs(b.freq_hz / exact - 1.0)
    # below grazing the mode is linear: HB is exact
    low = b.energy_J < 0.99 * P.grazing_energy_nnm2
    assert np.max(err[low]) < 1e-12
    # one harmonic: about 12 % off just above grazing (short contact pulses), < 1 % at 1e4 J
    assert np.max(err) < 0.15
    assert np.max(err[b.energy_J > 1e4]) < 0.01


def test_nnm2_converges_with_harmonics():
    errs = []
    for H in (1, 5, 15):
        b = nnm_branch(SYS, 1, H=H, energy_max_J=1e2)
        exact = nnm2.frequency_from_energy(P, b.energy_J)
        errs.append(np.max(np.abs(b.freq_hz / exact - 1.0)[b.energy_J > 2 * P.grazing_energy_nnm2]))
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[2] < 0.2 * errs[0], errs


def test_hb_backbones_fig2():
    bb = hb_backbones(SYS, harmonics=1, energy_max_J=1e5)
    assert list(bb) == ["NNM 1", "NNM 2", "NNM 3"]
    lo = linear_modes(SYS, "open").freq_hz
    hi = linear_modes(SYS, "closed").freq_hz
    for i, (E, f) in enumerate(bb.values()):
        assert np.all(np.diff(E) >= 0) and E[-1] >= 1e5
        assert f[0] == pytest.approx(lo[i], rel=1e-12)
        # saturates toward the closed-gap frequency (within 0.5 % at 1e5 J)
        assert f[-1] == pytest.approx(hi[i], rel=5e-3)
        assert np.all(f <= hi[i] * (1 + 1e-9)) and np.all(f >= lo[i] * (1 - 1e-9))


def test_energy_gradient_matches_finite_differences():
    hb = HarmonicBalance.for_system(SYS, 5)
    lin = linear_modes(SYS)
    res = NNMResidual(hb, float(lin.omega[0]), 0)
    rng = np.random.default_rng(3)
    y = res.start(lin.phi[:, 0], float(lin.omega[0]) * 4.0, math.log10(0.02))
    y[:-3] += 0.05 * rng.standard_normal(hb.size)
    g = res.energy_gradient(y)
    gf = np.array(
        [
            (res.energy(y + e) - res.energy(y - e)) / (2 * 1e-7 * max(1, abs(y[i])))
            for i, e in enumerate(np.eye(y.size) * (1e-7 * np.maximum(1, np.abs(y))))
        ]
    )
    assert np.allclose(g, gf, rtol=1e-5, atol=1e-7 * np.abs(g).max())
    # the energy computed alongside the gradient is energy() to round-off (other summation order)
    E, g2 = res.energy_and_gradient(y)
    assert E == pytest.approx(res.energy(y), rel=1e-13)
    assert np.array_equal(g2, g)
