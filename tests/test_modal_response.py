"""fem.modal_response: the closed-form reference of the linear check, against independent methods.

The half-sine response of a non-proportionally damped 5-mode system against DOP853 restarted at
the pulse's kinks; the resonant undamped mode (omega = pi/d) and its neighbours against the SDOF
convolution written in a form without 0/0; free rigid modes against the repeated integral of the
force; the pole-residue FRF against a direct complex solve; the FRF against the ratio of DFTs
of the time response and the force; defective systems and bad input refused.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from fem.modal_response import QUANTITIES, ModalModel, half_sine_laplace

P, D, T0 = 100.0, 1e-3, 2e-3  # N, s, s: the pulse of the brief
A = np.pi / D  # rad/s, the pulse's half-period frequency


def random_system(seed: int = 7, m: int = 5) -> tuple[ModalModel, np.ndarray, np.ndarray]:
    """m modes 40-400 Hz, Cm = alpha I + c u u^T (coupled), b and 3 output rows random."""
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.sort(rng.uniform(40.0, 400.0, m))
    u = rng.standard_normal(m)
    Cm = 6.0 * np.eye(m) + 15.0 * np.outer(u, u) / (u @ u)  # 1/s: zeta 1e-3 .. 4e-2
    b = rng.standard_normal(m)
    R = rng.standard_normal((3, m))
    return ModalModel(omega=omega, Cm=Cm), b, R


def rigid_system() -> tuple[ModalModel, np.ndarray, np.ndarray]:
    """Two zero-frequency modes, one elastic; Cm = c u u^T damps (q1 + q2) and couples it to q3,
    leaves (q1 - q2) free: the general split of the zero-frequency subspace."""
    u = np.array([1.0, 1.0, 0.5])
    model = ModalModel(omega=np.array([0.0, 0.0, 2 * np.pi * 150.0]), Cm=3.0 * np.outer(u, u))
    return model, np.array([0.8, -0.3, 1.1]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.4, -0.7, 1.2]])


def dop853_reference(model: ModalModel, b, R, t):
    """R q, R q', R q'' by DOP853 (rtol 1e-12) over [0, t0], [t0, t0 + d], [t0 + d, T]: the
    right-hand side is smooth inside each segment, so the error control sees no kink."""
    omega2, Cm, m = model.omega**2, model.Cm, model.m

    def force(tt):
        tau = tt - T0
        return np.where((tau >= 0) & (tau < D), P * np.sin(A * np.clip(tau, 0.0, D)), 0.0)

    def rhs(tt, z, on):
        f = P * np.sin(A * (tt - T0)) if on else 0.0
        return np.concatenate([z[m:], b * f - Cm @ z[m:] - omega2 * z[:m]])

    edges = [0.0, T0, T0 + D, t[-1]]
    z0 = np.zeros(2 * m)
    Z = np.zeros((2 * m, t.size))
    for k in range(3):
        lo, hi = edges[k], edges[k + 1]
        sel = (t > lo) & (t <= hi) if k else (t >= lo) & (t <= hi)
        sol = solve_ivp(rhs, (lo, hi), z0, method="DOP853", rtol=1e-12, atol=1e-20,
                        t_eval=np.unique(np.concatenate([t[sel], [hi]])), args=(k == 1,))
        assert sol.success, sol.message
        Z[:, sel] = sol.y[:, :sel.sum()]
        z0 = sol.y[:, -1]
    f = force(t)
    acc = b[:, None] * f[None, :] - Cm @ Z[m:] - omega2[:, None] * Z[:m]
    return R @ Z[:m], R @ Z[m:], R @ acc


@pytest.mark.parametrize("system", [random_system, rigid_system])
def test_half_sine_against_dop853(system):
    model, b, R = system()
    if system is random_system:  # the premise: light, non-proportional damping
        zeta = np.diag(model.Cm) / (2 * model.omega)
        assert 1e-3 <= zeta.min() and zeta.max() <= 5e-2, zeta
        off = np.abs(model.Cm - np.diag(np.diag(model.Cm))).max()
        assert off >= 0.2 * np.diag(model.Cm).min(), "Cm would be nearly diagonal"
    else:
        assert model.poles().n_rigid == 1
    t = np.linspace(0.0, 0.2, 400)
    res = model.half_sine_response(t, b, R, P, D, T0)
    ref = dop853_reference(model, b, R, t)
    # DOP853 at rtol 1e-12 keeps a global error of ~1e-10 of the signal over ~80 periods; the
    # closed form is exact to ~cond(V) eps: 1e-8 leaves margin for the integrator only
    for name, exact, num in zip(QUANTITIES, (res.displacement, res.velocity, res.acceleration), ref, strict=True):
        err = np.abs(exact - num).max() / np.abs(num).max()
        assert err <= 1e-8, f"{name}: max error {err:.2e} of the signal's max"
    assert res.imag_rel <= 1e-12, res.imag_rel  # conjugate pairs cancel to round-off
    assert np.all(res.displacement[:, t < T0] == 0.0)  # at rest before the pulse


def sdof_undamped(omega: float, b: float, t: np.ndarray):
    """q, q', q'' of q'' + omega^2 q = b f for the half-sine, from the convolution
    q = (b P / omega) int_0^tau sin(omega (tau - v)) sin(a v) dv, written with product-to-sum
    and sin(x)/x so that omega = a (delta = omega - a = 0) needs no limit:
    int = [(sin(omega tau) + sin(a tau)) / (omega + a) - tau cos((omega + a) tau / 2) sinc(delta tau / 2)] / 2,
    q' = b P [tau sin(omega tau - delta tau / 2) sinc(delta tau / 2) + (cos(omega tau) - cos(a tau)) / (omega + a)] / 2;
    after the pulse, free vibration from (q(d), q'(d))."""
    def sinc(x):
        return np.sinc(x / np.pi)

    dl = omega - A
    tau = t - T0
    th = np.clip(tau, 0.0, D)
    q = b * P / omega * 0.5 * ((np.sin(omega * th) + np.sin(A * th)) / (omega + A)
                               - th * np.cos((omega + A) * th / 2) * sinc(dl * th / 2))
    v = b * P * 0.5 * (th * np.sin(omega * th - dl * th / 2) * sinc(dl * th / 2)
                       + (np.cos(omega * th) - np.cos(A * th)) / (omega + A))
    after = tau > D
    s = np.maximum(tau - D, 0.0)
    qd, vd = q[after][0], v[after][0]  # th = d there
    q = np.where(after, qd * np.cos(omega * s) + vd / omega * np.sin(omega * s), q)
    v = np.where(after, -omega * qd * np.sin(omega * s) + vd * np.cos(omega * s), v)
    on = (tau >= 0) & (tau < D)
    f = np.where(on, P * np.sin(A * th), 0.0)
    return q, v, b * f - omega**2 * q


@pytest.mark.parametrize("rel", [0.0, 1e-12, 1e-8, 1e-4, -1e-3, 0.3, 2.0])
def test_resonant_and_near_resonant_single_mode(rel):
    """omega = a (1 + rel): rel = 0 is the resonant double root of the kernel's denominator,
    small rel the 0/0 the divided-difference branch exists for, 2.0 the direct branch."""
    omega = A * (1.0 + rel)
    b = 0.7
    t = np.concatenate([np.linspace(0.0, 4 * D, 301), np.linspace(4 * D, 0.05, 200)])
    res = ModalModel(omega=np.array([omega]), Cm=np.zeros((1, 1))).half_sine_response(
        t, np.array([b]), np.array([[1.3]]), P, D, T0)
    if rel == 0.0:  # q(d) = b P d / (2 a), q'(d) = 0 at exact resonance
        assert np.isclose(sdof_undamped(omega, b, np.array([T0 + D, T0 + 2 * D]))[0][1],
                          b * P * D / (2 * A) * np.cos(A * D), rtol=1e-14)
    # both sides are accurate to ~1e-14 of the peak: 1e-10 catches a wrong term, a lost
    # factor or the 1e-8-level loss of the direct formula at rel = 1e-8
    for name, exact, mine in zip(QUANTITIES, sdof_undamped(omega, b, t),
                                 (res.displacement, res.velocity, res.acceleration), strict=True):
        err = np.abs(1.3 * exact - mine[0]).max() / np.abs(1.3 * exact).max()
        assert err <= 1e-10, f"{name} at omega = a (1 + {rel}): relative error {err:.2e}"


def test_free_rigid_mode_is_the_double_integral():
    """omega = 0, no damping coupling: q(t) = int_0^t (t - u) b f(u) du (Cauchy's repeated
    integral, by quad), q' = int_0^t b f, q'' = b f; an elastic mode alongside stays untouched."""
    model = ModalModel(omega=np.array([0.0, 2 * np.pi * 80.0]), Cm=np.diag([0.0, 5.0]))
    assert model.poles().n_rigid == 1 and model.poles().lam.size == 2
    b = np.array([0.6, 1.0])
    t = np.linspace(0.0, 0.01, 41)
    res = model.half_sine_response(t, b, np.array([[1.0, 0.0]]), P, D, T0)

    def f(u):
        return P * np.sin(A * (u - T0)) if T0 <= u < T0 + D else 0.0

    pts = [T0, T0 + D]
    q = np.array([quad(lambda u, tt=tt: (tt - u) * f(u), 0.0, tt, points=pts, epsabs=0, epsrel=1e-13)[0]
                  if tt > 0 else 0.0 for tt in t]) * b[0]
    v = np.array([quad(f, 0.0, tt, points=pts, epsabs=0, epsrel=1e-13)[0] if tt > 0 else 0.0 for tt in t]) * b[0]
    # quad is accurate to ~1e-13 here; 1e-11 of the peak catches any wrong term of F1, F2
    assert np.abs(res.displacement[0] - q).max() <= 1e-11 * np.abs(q).max()
    assert np.abs(res.velocity[0] - v).max() <= 1e-11 * np.abs(v).max()
    assert np.allclose(res.acceleration[0], b[0] * np.array([f(tt) for tt in t]), rtol=0, atol=1e-12 * P)
    assert v[-1] == pytest.approx(b[0] * 2 * P / A, rel=1e-12)  # the impulse 2 P d / pi


def direct_frf(model: ModalModel, freq_hz, b, R, quantity):
    k = QUANTITIES.index(quantity)
    out = []
    for f in freq_hz:
        s = 2j * np.pi * f
        out.append(s**k * (R @ np.linalg.solve(s * s * np.eye(model.m) + s * model.Cm + np.diag(model.omega**2), b)))
    return np.array(out).T


@pytest.mark.parametrize("system", [random_system, rigid_system])
@pytest.mark.parametrize("quantity", QUANTITIES)
def test_frf_pole_residue_equals_direct_solve(system, quantity):
    model, b, R = system()
    freq_hz = np.concatenate([np.linspace(0.5, 1000.0, 997), model.omega[model.omega > 0] / (2 * np.pi)])
    H = model.frf(freq_hz, b, R, quantity)
    H_ref = direct_frf(model, freq_hz, b, R, quantity)
    # both are exact up to ~cond * eps; the pole-residue sum of 2m terms has absolute error
    # ~eps * max|H| (the residues are of the peak's size), so compare with each row's peak
    err = (np.abs(H - H_ref).max(axis=1) / np.abs(H_ref).max(axis=1)).max()
    assert err <= 1e-10, f"{quantity}: pole-residue vs direct, {err:.2e} of the peak"


def test_frf_is_the_ratio_of_dfts_of_the_time_response():
    """Y(f) / F(f) from the DFT of the sampled, fully decayed acceleration and force equals
    H(i 2 pi f) below the pulse's first spectral zero (1.5 / d)."""
    rng = np.random.default_rng(3)
    omega = 2 * np.pi * np.array([220.0, 480.0, 850.0])
    u = rng.standard_normal(3)
    model = ModalModel(omega=omega, Cm=np.diag(2 * 0.03 * omega) + 20.0 * np.outer(u, u) / (u @ u))
    b, R = rng.standard_normal(3), rng.standard_normal((2, 3))
    decay = -model.poles().lam.real.max()
    fs = 2e5  # Hz
    n = int(np.ceil(25.0 / decay * fs))  # e^{-25} ~ 1e-11 left at the end: no leakage
    t = np.arange(n) / fs
    res = model.half_sine_response(t, b, R, P, D, 0.0)
    Y = np.fft.rfft(res.acceleration, axis=1) / fs
    F = np.fft.rfft(res.force) / fs
    freq = np.fft.rfftfreq(n, 1 / fs)
    band = (freq > 0) & (freq < 1.2 / D)
    H = model.frf(freq[band], b, R, "acceleration")
    # the DFT of a sampled signal is its Fourier transform plus aliases F(f + k fs); the pulse's
    # spectrum falls as (a / 2 pi f)^2, so aliases are ~3 (a / 2 pi fs)^2 ~ 2e-5 of F in the band
    # (and H -> R b at high frequency); 1.7e-5 is measured, 2e-4 of the FRF's peak leaves 10x
    err = np.abs(Y[:, band] / F[band] - H).max() / np.abs(H).max()
    assert err <= 2e-4, f"DFT ratio vs FRF: {err:.2e} of the peak"
    F_exact = half_sine_laplace(2j * np.pi * freq[band], P, D, 0.0)
    assert np.abs(F[band] - F_exact).max() <= 1e-4 * np.abs(F_exact).max()  # the same aliases, 2e-5


def test_half_sine_laplace_is_finite_at_the_pulse_frequency():
    """F(+-i a) = -+i P d e^{-+i a t0} / 2 (l'Hopital; int_0^d sin(a t) e^{-i a t} dt = d / (2 i));
    just beside it the same value to O(ds)."""
    s = 1j * A * np.array([1.0, -1.0, 1.0 + 1e-9])
    F = half_sine_laplace(s, P, D, T0)
    assert np.allclose(F[:2], np.array([-1j, 1j]) * P * D / 2 * np.exp(-s[:2] * T0), rtol=1e-14)
    assert abs(F[2] - F[0]) <= 1e-7 * abs(F[0])
    # against the direct quotient where it is well conditioned
    s_far = 2j * np.pi * np.array([10.0, 700.0, 3000.0])
    F_direct = P * A * np.exp(-s_far * T0) * (1 + np.exp(-s_far * D)) / (s_far**2 + A**2)
    assert np.allclose(half_sine_laplace(s_far, P, D, T0), F_direct, rtol=1e-13)


def test_critically_damped_mode_is_refused():
    model = ModalModel(omega=np.array([100.0, 300.0]), Cm=np.diag([200.0, 6.0]))  # c = 2 omega on mode 1
    with pytest.raises(ValueError, match="defective") as e:
        model.poles()
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="defective"):
        model.half_sine_response([0.0], [1.0, 1.0], [[1.0, 0.0]], P, D)


def test_blocked_evaluation_matches_one_block(monkeypatch):
    """Times (response) and frequencies (FRF) cut into blocks of a few entries give the numbers
    of one block: the blocking only bounds memory."""
    import fem.modal_response as mr

    model, b, R = rigid_system()
    t, freq_hz = np.linspace(0.0, 0.05, 1001), np.linspace(1.0, 500.0, 301)
    whole, H = model.half_sine_response(t, b, R, P, D, T0), model.frf(freq_hz, b, R, "velocity")
    monkeypatch.setattr(mr, "CHUNK_ELEMENTS", 37)
    parts, H_parts = model.half_sine_response(t, b, R, P, D, T0), model.frf(freq_hz, b, R, "velocity")
    for x, y in ((whole.acceleration, parts.acceleration), (whole.displacement, parts.displacement), (H, H_parts)):
        assert np.abs(x - y).max() <= 1e-14 * np.abs(x).max()  # same arithmetic, maybe other BLAS paths


def test_poles_diagonalise_the_first_order_form():
    """A V = V diag(lam) and V^-1 V = I for A = [[0, I], [-Omega^2, -Cm]]; conjugate pairs, Re <= 0."""
    model, _, _ = random_system()
    p, m = model.poles(), model.m
    A_ = np.block([[np.zeros((m, m)), np.eye(m)], [-np.diag(model.omega**2), -model.Cm]])
    scale = np.abs(A_).max()
    assert np.abs(A_ @ p.V - p.V * p.lam[None, :]).max() <= 1e-12 * scale * np.abs(p.V).max()
    assert np.abs(p.V_inv @ p.V - np.eye(2 * m)).max() <= 1e-12
    assert np.allclose(np.sort_complex(p.lam), np.sort_complex(p.lam.conj()), rtol=1e-12)
    assert p.lam.real.max() < 0.0 and p.n_rigid == 0 and p.cond_V < 10.0


GOOD_OMEGA, GOOD_CM = np.array([10.0, 20.0]), np.diag([0.1, 0.2])


@pytest.mark.parametrize("make, field", [
    (lambda: ModalModel(np.array([[10.0, 20.0]]), GOOD_CM), "omega"),
    (lambda: ModalModel(np.array([10.0, np.nan]), GOOD_CM), "omega"),
    (lambda: ModalModel(np.array([10.0, -1.0]), GOOD_CM), "omega"),
    (lambda: ModalModel(GOOD_OMEGA, np.eye(3)), "Cm"),
    (lambda: ModalModel(GOOD_OMEGA, np.array([[1.0, np.inf], [np.inf, 1.0]])), "Cm"),
    (lambda: ModalModel(GOOD_OMEGA, np.array([[1.0, 0.5], [0.0, 1.0]])), "Cm"),
    (lambda: ModalModel(GOOD_OMEGA, np.diag([1.0, -1.0])), "Cm"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([0.0], [1.0], [[1.0, 0.0]], P, D), "b"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([0.0], [1.0, 0.0], [1.0, 0.0], P, D), "R"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([0.0], [1.0, 0.0], [[1.0, 0.0]], P, 0.0),
     "duration_s"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([0.0], [1.0, 0.0], [[1.0, 0.0]], P, -D),
     "duration_s"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([0.0], [1.0, 0.0], [[1.0, 0.0]], np.nan, D),
     "peak_N"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).half_sine_response([[0.0]], [1.0, 0.0], [[1.0, 0.0]], P, D), "t"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).frf([1.0], [1.0, 0.0], [[1.0, 0.0]], "jerk"), "quantity"),
    (lambda: ModalModel(GOOD_OMEGA, GOOD_CM).frf([np.nan], [1.0, 0.0], [[1.0, 0.0]]), "freq_hz"),
])
def test_bad_input_refused_naming_the_field(make, field):
    with pytest.raises(ValueError) as e:
        make()
    msg = str(e.value)
    assert msg.startswith(field + " ") or msg.startswith(field + ","), msg
    assert "\n" not in msg
