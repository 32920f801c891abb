"""Ringdown integrators against closed forms, each other, and their invariants."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import eigh as scipy_eigh

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.modes import linear_modes
from reduced.studies import fit_order, relative_error
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.explicit import StepTooLargeError, stability_limit
from reduced.transient.integrate import ringdown

P = DiscreteParams()
IMPULSE = (np.zeros(3), np.array([0.0, 0.0, 200.0]))


def one_dof_stop(m=100.0, k=1e4, kc=1e6) -> GapSystem:
    """code_aster SDND101: a mass on a spring against a one-sided stop at zero gap."""
    return GapSystem(
        M=np.array([[m]]), C=np.zeros((1, 1)), K=np.array([[k]]), B=np.array([[1.0]]), k=np.array([kc]),
        offset=np.array([0.0]), side=np.array([1.0]), tip=np.array([0]), dof_names=("x",), stop_names=("stop",),
    )


def sdnd101_closed_form(t: np.ndarray, m=100.0, k=1e4, kc=1e6, v0=1.0) -> np.ndarray:
    """x(t) of SDND101: half-sines in contact (omega_c) and free flight (omega) alternating."""
    wc, w = np.sqrt((k + kc) / m), np.sqrt(k / m)
    tc, tf = np.pi / wc, np.pi / w
    phase = np.mod(t, tc + tf)
    return np.where(phase < tc, v0 / wc * np.sin(wc * phase), -v0 / w * np.sin(w * (phase - tc)))


def test_exact_matches_dop853_with_events():
    # DOP853 at rtol 1e-13 restarted at each crossing is independent of the closed form;
    # over ~190 events in 0.03 s its own error is ~1e-11, so 1e-9 leaves a margin of 100.
    sys = P.system()
    a = ringdown(sys, *IMPULSE, 0.03, 20000.0, "exact")
    b = integrate_dop853(sys, *IMPULSE, 0.03, 20000.0, rtol=1e-13, events=True)
    assert a.stats["n_events"] > 100
    assert relative_error(a.x, b.x) < 1e-9
    assert relative_error(a.v, b.v) < 1e-9


def test_exact_sdnd101_closed_form():
    sys = one_dof_stop()
    res = ringdown(sys, np.zeros(1), np.ones(1), 0.4, 1e5, "exact")
    x_ref = sdnd101_closed_form(res.t)
    assert np.max(np.abs(res.x[:, 0] - x_ref)) < 1e-12 * np.max(np.abs(x_ref))
    force = sys.stop_force(res.x)[:, 0]
    first = res.t < 0.05
    i_peak = np.argmax(force * first)
    assert force[i_peak] == pytest.approx(9950.37, abs=0.01)  # code_aster SDND101: 9950.37 N at 0.015630 s
    assert res.t[i_peak] == pytest.approx(0.015630, abs=1e-5)
    impulse = np.trapezoid(force[first], res.t[first])
    assert impulse == pytest.approx(198.02, abs=0.01)  # N s
    i_rebound = np.searchsorted(res.t, 0.031260) + 1  # just after the contact ends
    assert res.v[i_rebound, 0] == pytest.approx(-1.0, abs=1e-3)  # free flight barely slows it
    second = (res.t > 0.2)
    assert res.t[np.argmax(force * second)] == pytest.approx(0.361049, abs=1e-5)
    assert res.stats["n_events"] == 4  # enter at t = 0 (x = 0, moving in), leave, enter, leave


@pytest.mark.parametrize("mode", [0, 1, 2])
def test_exact_pure_mode_is_a_damped_cosine(mode):
    # Equal masses make C = c I mass-proportional, so modes decouple; a wide gap keeps it linear.
    p = replace(P, m2=P.m1, m3=P.m1, gap=1e-2, c=4.0)
    sys = p.system()
    lm = linear_modes(sys, "open")
    phi, w = lm.phi[:, mode], lm.omega[mode]
    amp = 1e-4 / np.max(np.abs(phi))
    res = ringdown(sys, amp * phi, np.zeros(3), 0.5, 5000.0, "exact")
    zeta = p.c / p.m1 / (2 * w)
    wd = w * np.sqrt(1 - zeta**2)
    q = amp * np.exp(-zeta * w * res.t) * (np.cos(wd * res.t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * res.t))
    assert res.stats["n_events"] == 0
    # the closed form loses cond(V) eps ~ 8e3 x 2.2e-16 = 2e-12 relative: allow 1e-11
    assert np.max(np.abs(res.x - np.outer(q, phi))) < 1e-11 * amp * np.max(np.abs(phi))


def test_explicit_order_from_refinement():
    sys = P.system()
    ref = ringdown(sys, *IMPULSE, 0.01, 20000.0, "exact")
    steps, errs = [], []
    for wdt in (0.2, 0.1, 0.05, 0.025, 0.0125):
        r = ringdown(sys, *IMPULSE, 0.01, 20000.0, "explicit", omega_dt=wdt)
        steps.append(r.stats["dt"])
        errs.append(relative_error(r.x, ref.x))
    order = fit_order(steps, errs, lo=1e-300, hi=1.0)  # every point: all are in the asymptotic range
    assert 1.85 < order < 2.15, f"observed order {order:.3f}, errors {errs}"
    assert errs[-1] < 1e-3


@pytest.mark.parametrize(
    "method, kw, tol",
    [("exact", {}, 1e-11),  # closed-form work integral: round-off only
     ("explicit", {"omega_dt": 0.05}, 5e-3),  # O(dt^2) energy error of central difference
     ("dop853", {"rtol": 1e-10}, 1e-6)],
)
def test_energy_balance_through_contact(method, kw, tol):
    res = ringdown(P.system(), *IMPULSE, 0.05, 20000.0, method, **kw)
    assert res.dissipated[-1] > 0.01 * res.energy[0]  # damping did measurable work
    assert res.energy_balance_error < tol


@pytest.mark.parametrize("method", ["exact", "explicit", "dop853"])
def test_odd_symmetry_bit_for_bit(method):
    sys = P.system()
    x0 = np.array([0.0254, 0.0, -0.02])
    v0 = np.array([3.0, -50.0, 200.0])
    a = ringdown(sys, x0, v0, 0.02, 20000.0, method)
    b = ringdown(sys, -x0, -v0, 0.02, 20000.0, method)
    assert np.array_equal(a.x, -b.x)
    assert np.array_equal(a.v, -b.v)


def test_explicit_refuses_unstable_step():
    sys = P.system()
    omega, dt_crit = stability_limit(sys)
    assert omega == pytest.approx(8184.87, rel=1e-5)
    with pytest.raises(StepTooLargeError, match="exceeds the stable step"):
        ringdown(sys, *IMPULSE, 0.01, 20000.0, "explicit", dt=0.9 * dt_crit)
    ringdown(sys, *IMPULSE, 0.01, 20000.0, "explicit", dt=0.5 * dt_crit)  # accepted


def _cd_unchecked(monkeypatch, system: GapSystem, x0: np.ndarray, dt: float, n_steps: int) -> np.ndarray:
    """x at every step of the explicit integrator's central difference with step dt, its stability
    refusal bypassed (stability_limit patched to allow any step); the production kernel runs as is."""
    import reduced.transient.explicit as explicit

    monkeypatch.setattr(explicit, "stability_limit", lambda s: (1.0, math.inf))
    # one sample a step: sample_rate_hz = 1/dt makes the run take exactly dt
    res = ringdown(system, x0, np.zeros(system.n), n_steps * dt, 1.0 / dt, "explicit", dt=dt)
    assert res.stats["dt"] == pytest.approx(dt, rel=1e-12) and res.stats["n_steps"] == n_steps
    return res.x


def _cd_growth_per_step(omega_dt: float, xi: float = 0.0) -> float:
    """ln |z|max of central difference on one mode: (1 + xi W) z^2 - (2 - W^2) z + (1 - xi W) = 0, W = omega dt
    (M (x+ - 2x + x-)/dt^2 + C (x+ - x-)/(2 dt) + K x = 0, the scheme of explicit._cd_kernel)."""
    W = omega_dt
    return float(np.log(np.abs(np.roots([1 + xi * W, -(2 - W * W), 1 - xi * W])).max()))


def _cd_closed_form(omega_dt: float, xi: float, x0: float, n_steps: int) -> np.ndarray:
    """x_0 .. x_n of central difference on one mode from rest, in closed form: x_n = c1 z1^n + c2 z2^n with
    z the roots of (1 + xi W) z^2 - (2 - W^2) z + (1 - xi W) = 0, W = omega dt (the recurrence
    M (x+ - 2x + x-)/dt^2 + C (x+ - x-)/(2 dt) + K x = 0 of explicit._cd_kernel) and x_1 = x0 (1 - W^2/2)
    (its start: v_{1/2} = v0 + dt/2 a0)."""
    W = omega_dt
    z = np.roots([1 + xi * W, -(2 - W * W), 1 - xi * W]).astype(complex)
    c = np.linalg.solve(np.array([[1.0, 1.0], z]), np.array([x0, x0 * (1 - W * W / 2)]))
    n = np.arange(n_steps + 1)
    return (c[0] * z[0] ** n + c[1] * z[1] ** n).real


@pytest.mark.parametrize("c", [0.0, 4.0])
def test_central_difference_diverges_just_above_2_over_omega_max_with_the_gaps_closed(monkeypatch, c):
    # The 3-DOF model with the stops of x1 and x3 held closed (offset -1 mm: a preload keeps each in
    # contact, penetration 4.6e-7 m at equilibrium), so the system is linear in its stiffest state,
    # omega_max = 8184.87 rad/s, and the kernel runs its contact terms. From the equilibrium plus some of
    # the top closed-gap mode (every stop checked closed at every step):
    # - dt = 1.01 x 2/omega_max, from 1e-12 m: |x - x_eq| grows each step by the closed-form root of the CD recurrence,
    #   ln|z| = 0.2826 (undamped; 0.2818 with c = 4, top-mode xi = 3.8e-4), 1e-12 to 4e-8 m in 40 steps.
    #   Measured over steps 20-40 (the other root, |z2/z1|^20 ~ 1e-5, nearly gone): 2.2e-6 from the closed
    #   form; 1e-4 allowed (c = 4 couples the modes slightly: C is not proportional to M);
    # - dt = 0.99 x 2/omega_max, from 1e-9 m of the top mode: bounded over 20,000 steps. Undamped, CD's
    #   discrete solution of one mode from rest is x0 cos(n theta), cos theta = 1 - (omega dt)^2 / 2, so
    #   |x - x_eq| never exceeds its start but by round-off (x_eq is solved to ~1e-15 m, cond(K) ~ 5e3:
    #   measured 1 + 1.3e-8 of the start); with c = 4 it decays. 1e-6 allowed.
    s = DiscreteParams(c=c).system()
    held = s.side > 0
    sys = GapSystem(M=s.M, C=s.C, K=s.K, B=s.B[held], k=s.k[held], offset=np.full(held.sum(), -1e-3),
                    side=s.side[held], tip=s.tip[held], dof_names=s.dof_names,
                    stop_names=tuple(np.array(s.stop_names)[held]))
    Kc = sys.closed_stiffness()
    assert np.allclose(Kc, s.closed_stiffness(), rtol=1e-15)  # the discrete model's stiffest state
    lam, phi = scipy_eigh(Kc, sys.M)
    omega = math.sqrt(lam[-1])
    assert omega == pytest.approx(8184.87, rel=1e-5)
    xi = float(phi[:, -1] @ sys.C @ phi[:, -1]) / (2 * omega)
    x_eq = np.linalg.solve(Kc, sys.B.T @ (sys.k * sys.offset))  # K x + B^T k (B x - offset) = 0
    top = phi[:, -1] / np.abs(phi[:, -1]).max()

    def run(dt, n_steps, size):
        x = _cd_unchecked(monkeypatch, sys, x_eq + size * top, dt, n_steps)
        assert np.all(sys.side * (x @ sys.B.T - sys.offset) > 0), "a stop opened: no longer linear"
        return np.abs(x - x_eq).max(axis=1)

    dt = 1.01 * 2.0 / omega
    d = run(dt, 40, 1e-12)
    rate = np.log(d[40] / d[20]) / 20
    assert rate == pytest.approx(_cd_growth_per_step(omega * dt, xi), rel=1e-4)
    assert d[-1] > 1e4 * d[0]

    d = run(0.99 * 2.0 / omega, 20_000, 1e-9)
    assert d.max() <= (1 + 1e-6) * d[0], d.max() / d[0]


def test_central_difference_damped_limit_is_2_over_omega_for_this_scheme(monkeypatch):
    # A 1-DOF oscillator with xi = 0.3. Belytschko, Liu & Moran (Nonlinear Finite Elements for Continua and
    # Structures, 2000, Sec. 6.2) give dt <= (2/omega)(sqrt(1 + xi^2) - xi) = 1.488/omega
    # for central difference with damping; that bound belongs to the variant with the damping force at the
    # lagged velocity v_{n-1/2}. The kernel here takes it at (v_{n-1/2} + v_{n+1/2}) / 2 (G = (M + dt/2 C)^-1,
    # Newmark gamma = 1/2, beta = 0), whose recurrence (1 + xi W) z^2 - (2 - W^2) z + (1 - xi W) = 0 is stable
    # for W = omega dt < 2 whatever xi (Schur-Cohn: |2 - W^2| < 2). So stability_limit's damped dt_crit is
    # conservative for this kernel (the refusal errs on the safe side), and the limit is 2/omega: at
    # W = 1.9 and 1.99 (above 1.488) the response decays, at W = 2.02 it grows, as the closed form
    # x_n = c1 z1^n + c2 z2^n says, sample by sample (measured: 2.8e-12 of the envelope r^n |x0| at most; 1e-9 allowed).
    omega, xi = 1e3, 0.3
    sys = GapSystem(M=np.eye(1), C=np.array([[2 * xi * omega]]), K=np.array([[omega**2]]), B=np.eye(1),
                    k=np.zeros(1), offset=np.ones(1), side=np.ones(1), tip=np.zeros(1, int), dof_names=("x",),
                    stop_names=("never",))  # no contact: a linear oscillator
    _, dt_crit = stability_limit(sys)
    assert omega * dt_crit == pytest.approx(2 * (math.sqrt(1 + xi**2) - xi), rel=1e-12)  # the damped textbook bound
    for W in (1.9, 1.99, 2.02):
        x = _cd_unchecked(monkeypatch, sys, np.array([1e-3]), W / omega, 400)[:, 0]
        ref = _cd_closed_form(W, xi, 1e-3, 400)
        envelope = 1e-3 * np.exp(_cd_growth_per_step(W, xi) * np.arange(401))
        assert np.max(np.abs(x - ref) / envelope) < 1e-9, (W, np.max(np.abs(x - ref) / envelope))
        assert (envelope[-1] > 1e3 * envelope[0]) == (W > 2.0), W  # grows only past 2/omega


@pytest.mark.parametrize("method", ["exact", "explicit", "dop853"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_initial_state_refused(method, bad):
    with pytest.raises(ValueError, match="x0 must be finite"):
        ringdown(P.system(), np.array([bad, 0, 0]), np.zeros(3), 0.01, 1000.0, method)


def test_grazing_touch_is_not_missed():
    # Start 1e-9 gaps inside the stop: the contact lasts ~1e-5 of a period. A missed event
    # would leave the stop force off and change the period by ~1e-6 relative.
    from reduced.periodic import nnm2

    x0 = P.gap * (1 + 1e-9)
    p = replace(P, c=0.0)
    T = nnm2.period_from_amplitude(p, x0)
    res = ringdown(p.system(), np.array([x0, 0, -x0]), np.zeros(3), 3 * T, 2000.0, "exact")
    assert res.stats["n_events"] >= 4 * 3  # enter/leave at both tips each half period
    assert res.energy_balance_error < 1e-12


@settings(max_examples=25, deadline=None)
@given(
    speed=st.floats(1e-3, 3e3),
    gap=st.sampled_from([0.0, 1e-6, 2.54e-4, 1e-2]),
    k_g=st.sampled_from([1e5, 3.502e7, 1e10]),
    c=st.sampled_from([0.0, 4.0]),
)
def test_exact_energy_balance_any_velocity(speed, gap, k_g, c):
    # A crossing stepped over would leave penalty energy unpaid for: E(0) != E(t) + W(t).
    p = replace(P, gap=gap, k_g=k_g, c=c)
    res = ringdown(p.system(), np.zeros(3), np.array([0.0, 0.0, speed]), 0.01, 20000.0, "exact")
    assert res.energy_balance_error < 1e-9


# -- DOP853 driven as solve_ivp drives it ----------------------------------------------------------
def test_dop853_stream_is_solve_ivp_bit_for_bit():
    # the stepper loop replaces solve_ivp so that a run can live across chunks; on its own
    # terms (one call, t_eval = the samples) solve_ivp must give the same bits
    from scipy.integrate import solve_ivp

    from reduced.transient.dop853 import _rhs_factory

    sys = P.system()
    res = ringdown(sys, *IMPULSE, 0.003, 20000.0, "dop853", rtol=1e-9)
    z0 = np.concatenate([*IMPULSE, [0.0]])
    sol = solve_ivp(_rhs_factory(sys), (0.0, res.t[-1]), z0, method="DOP853", t_eval=res.t, rtol=1e-9,
                    atol=1e-9 * 1e-3)  # the default: rtol x max(gap, 1 mm)
    assert np.array_equal(sol.y[:3].T, res.x) and np.array_equal(sol.y[3:6].T, res.v)
    assert np.array_equal(sol.y[6], res.dissipated)
    assert res.stats["nfev"] == sol.nfev


def test_dop853_compiled_rhs_is_the_numpy_expression_to_round_off():
    # the free leg's compiled right-hand side against the numpy expression it replaced, on states with
    # many combinations of stops open and closed (the 3-DOF model, and the same with full mass and damping
    # matrices, so that every product has off-diagonal terms). The two differ only in the order of the sums
    # (OpenBLAS's 3 x 3 products against the compiled loops): a few eps of the sum of the magnitudes that
    # enter each component (measured 2 eps; 8 eps allowed)
    from reduced.transient.dop853 import _rhs_factory

    rng = np.random.default_rng(3)
    base = P.system()
    R = rng.standard_normal((3, 3))
    full = replace(base, M=base.M + 0.1 * (R @ R.T), C=base.C + 0.5 * (R + R.T))
    for sys in (base, full):
        _check_compiled_rhs(sys, _rhs_factory(sys), rng)


def _check_compiled_rhs(sys, rhs, rng):
    n, Minv, eps = sys.n, np.linalg.inv(sys.M), np.finfo(float).eps
    closed = set()
    for _ in range(2000):
        x = rng.standard_normal(n) * 2 * float(np.max(np.abs(sys.offset)))
        v = rng.standard_normal(n) * 100.0
        z = np.concatenate([x, v, [0.0]])
        f = sys.contact_force(x)
        ref = np.concatenate([v, Minv @ (-(sys.K @ x) - sys.C @ v - f), [v @ sys.C @ v]])
        out = rhs(0.0, z)
        scale = np.abs(Minv) @ (np.abs(sys.K) @ np.abs(x) + np.abs(sys.C) @ np.abs(v) + np.abs(f))
        assert np.array_equal(out[:n], v)
        assert np.all(np.abs(out[n:2 * n] - ref[n:2 * n]) <= 8 * eps * scale)
        assert abs(out[-1] - ref[-1]) <= 8 * eps * (np.abs(v) @ np.abs(sys.C) @ np.abs(v))
        closed.add(tuple(sys.penetration(x) > 0))
    assert len(closed) >= 8  # open and closed stops in many combinations were seen


def test_dop853_events_restart_at_every_crossing_as_solve_ivp():
    # the reference mode, leg by leg with solve_ivp's terminal events (the code this replaced)
    from scipy.integrate import solve_ivp

    sys = P.system()
    n, fs, T = 3, 20000.0, 0.004
    res = integrate_dop853(sys, *IMPULSE, T, fs, rtol=1e-11, events=True)
    ts = np.arange(res.n_samples) / fs
    Minv = np.linalg.inv(sys.M)
    z, t0, i, active = np.concatenate([*IMPULSE, [0.0]]), 0.0, 0, sys.penetration(IMPULSE[0]) > 0
    Z = np.empty((ts.size, 2 * n + 1))
    while True:
        Ks, Fs = sys.state_matrices(active)

        def leg(t, zz, Ks=Ks, Fs=Fs):
            x, v = zz[:n], zz[n:2 * n]
            return np.concatenate([v, Minv @ (Fs - Ks @ x - sys.C @ v), [v @ sys.C @ v]])

        sol = solve_ivp(leg, (t0, ts[-1]), z, method="DOP853", t_eval=ts[i:], rtol=1e-11,
                        atol=1e-11 * 1e-3, events=sys.crossing_events(active))
        k = len(sol.t)  # a leg between two samples returns none (and lists)
        if k:
            Z[i:i + k] = np.asarray(sol.y).T
        i += k
        if sol.status != 1:
            break
        je = int(np.argmin([e[0] if e.size else np.inf for e in sol.t_events]))
        t0, z = float(sol.t_events[je][0]), sol.y_events[je][0].copy()
        active = sys.state_after_crossing(active, je, z[:n], z[n:2 * n], 1e-9 * 1e-3)
    assert res.stats["n_events"] > 20
    assert np.array_equal(Z[:, :n], res.x) and np.array_equal(Z[:, 2 * n], res.dissipated)


# -- spectrogram against SciPy's ShortTimeFFT ---------------------------------------------------------
@pytest.mark.parametrize("n, window_s, overlap", [(40001, 0.05, 0.9), (1234, 0.01, 0.5), (101, 4e-4, 0.6)])
def test_spectrogram_is_shorttimefft_inside_the_record(n, window_s, overlap):
    from scipy.signal import ShortTimeFFT
    from scipy.signal.windows import hann

    from reduced.transient.spectrogram import spectrogram, spectrogram_chunks

    fs = 20000.0
    t = 0.3 + np.arange(n) / fs
    y = np.sin(2 * np.pi * 700 * t) + 0.1 * np.random.default_rng(1).standard_normal(n) + 0.5
    nwin = max(8, round(window_s * fs))
    stft = ShortTimeFFT(hann(nwin, sym=False), hop=max(1, round(nwin * (1 - overlap))), fs=fs, scale_to="psd")
    S = stft.spectrogram(y - y.mean())  # frames p_min .. p_max - 1
    lo, hi = stft.lower_border_end[1] - stft.p_min, stft.upper_border_begin(n)[1] - stft.p_min
    ref = S[:, lo:hi]
    ours = spectrogram(t, y, window_s, overlap)
    assert ours.power.shape == ref.shape
    assert np.allclose(ours.t, stft.t(n)[lo:hi] + t[0], rtol=0, atol=1e-12)
    assert np.max(np.abs(ours.power - ref)) < 1e-12 * np.max(ref)  # one FFT each: round-off
    # fed in chunks of 333 samples: the same frames
    chunked = spectrogram_chunks(((i, y[i:i + 333]) for i in range(0, n, 333)), n, fs, window_s, overlap,
                                 mean=float(y.mean()), t0=0.3, max_frames=None)
    assert np.max(np.abs(chunked.power - ours.power)) < 1e-12 * np.max(ref)


def test_spectrogram_of_a_long_record_keeps_every_kth_frame():
    from reduced.transient.spectrogram import spectrogram

    fs, n = 20000.0, 40001
    t = np.arange(n) / fs
    y = np.sin(2 * np.pi * (300 + 200 * t) * t)
    full = spectrogram(t, y, 0.05, 0.9)
    thin = spectrogram(t, y, 0.05, 0.9, max_frames=50, fmax_hz=1500.0)
    assert thin.power.shape[1] <= 50 and thin.hop % full.hop == 0
    k = thin.hop // full.hop
    first = int(np.argmin(np.abs(full.t - thin.t[0])))
    assert np.array_equal(full.t[first::k][: thin.t.size], thin.t)
    assert np.allclose(full.power[: thin.power.shape[0], first::k][:, : thin.t.size], thin.power, rtol=1e-12)
    assert thin.freq_hz[-1] <= 1500.0
    # the chirp's dominant frequency 300 + 400 t is found frame by frame to one bin (20 Hz)
    assert np.max(np.abs(thin.dominant_freq_hz() - (300 + 400 * thin.t))) <= 20.0


# -- largest Lyapunov exponent against known exponents ------------------------------------------------
def _linear(c: float):
    # equal masses and C = c I: every mode decays at c / (2 m); a 10 km gap is never reached
    p = replace(P, m2=P.m1, m3=P.m1, gap=1e4, c=max(c, 0.0))
    sys = p.system()
    if c < 0:
        sys = replace(sys, C=c * np.eye(3))
    return sys, np.array([1e-4, 0.0, -2e-4]), np.array([0.0, 0.1, 0.0])


@pytest.mark.parametrize("c, method", [(4.0, "exact"), (0.0, "exact"), (-20.0, "explicit"), (-20.0, "dop853")])
def test_lyapunov_exponent_of_a_linear_system_is_its_decay_rate(c, method):
    from reduced.transient.compare import largest_lyapunov

    sys, x0, v0 = _linear(c)
    kw = {"rtol": 1e-10, "atol": 1e-20} if method == "dop853" else {}  # atol far below the 1e-13 m separation
    est = largest_lyapunov(sys, x0, v0, 1.0, 5000.0, method, window_s=0.01, **kw)
    rate = -c / (2 * P.m1)  # 1/s: -3.18 (damped), 0, +15.9 (negative damping)
    # measured: 1e-5 relative (decaying), 3e-6 /s (undamped), 0.1 % (growing: fitted only after the
    # 100-fold onset at 0.29 s, on window maxima that ripple with the 18 Hz mode)
    assert est.exponent_per_s == pytest.approx(rate, abs=0.005 * abs(rate) + 1e-4)
    assert est.chaotic == (c < 0)  # only the growing one separates 100-fold
    assert math.isinf(est.saturation_s)  # D/|y| stays delta in a linear system


def test_lyapunov_exponent_on_an_unstable_periodic_orbit_is_its_floquet_exponent():
    # NNM 2 of the undamped model at 2.6 J: the antisymmetric orbit x(0) = [a, 0, -a] is periodic
    # (its period in closed form, reduced.periodic.nnm2) and unstable; the monodromy matrix of
    # the exact flow gives its largest multiplier, ln|mu| / T = 400 /s, checked against finite
    # differences of DOP853 and against the divergence of two nearby runs
    from scipy.optimize import brentq

    from reduced.periodic import nnm2
    from reduced.transient.compare import largest_lyapunov
    from reduced.transient.flow import Flow

    p = replace(P, c=0.0)
    sys = p.system()
    a = brentq(lambda a: float(sys.energy(np.array([a, 0.0, -a]), np.zeros(3))) - 2.6, 1e-6, 1e-1)
    T = float(nnm2.period_from_amplitude(p, a))
    x0 = np.array([a, 0.0, -a])
    flow = Flow(sys)(x0, np.zeros(3), T, jacobian=True)
    assert np.max(np.abs(flow.y[:3] - x0)) < 1e-12 * a  # periodic
    floquet = np.log(np.max(np.abs(np.linalg.eigvals(flow.jacobian)))) / T
    assert floquet == pytest.approx(400.0, rel=0.01)  # regression guard only (the value when written: 399.97)
    # independent of the closed-form segments: the monodromy by central differences of SciPy's DOP853
    # (rtol 1e-12, crossings located) over one period, steps of 1e-5 of a and of a omega. Measured: the
    # matrices agree to 2.8e-8 of the largest entry (truncation h^2 and DOP853's 1e-12 / h noise), the
    # exponents to 6e-10; 1e-6 and 1e-7 allowed.
    y0, step = np.concatenate([x0, np.zeros(3)]), np.r_[np.full(3, 1e-5 * a), np.full(3, 1e-5 * a * 2 * np.pi / T)]
    J = np.empty((6, 6))
    for j in range(6):
        ends = []
        for sign in (1.0, -1.0):
            y = y0.copy()
            y[j] += sign * step[j]
            r = integrate_dop853(sys, y[:3], y[3:], T, 1.0 / T, rtol=1e-12, events=True)  # samples at 0 and T
            ends.append(np.r_[r.x[-1], r.v[-1]])
        J[:, j] = (ends[0] - ends[1]) / (2 * step[j])
    assert np.abs(J - flow.jacobian).max() < 1e-6 * np.abs(flow.jacobian).max()
    assert np.log(np.max(np.abs(np.linalg.eigvals(J)))) / T == pytest.approx(floquet, rel=1e-7)
    for seed in (0, 1):
        est = largest_lyapunov(sys, x0, np.zeros(3), 200 * T, 100 / T, window_s=T, seed=seed)
        assert est.chaotic and est.saturation_s < 30 * T
        assert est.exponent_per_s == pytest.approx(floquet, rel=0.02)


def test_compare_runs_of_a_run_with_itself_and_stop_closures():
    from reduced.transient.compare import compare_runs

    sys = one_dof_stop()
    res = ringdown(sys, np.zeros(1), np.ones(1), 0.4, 1e5, "exact")
    c = compare_runs(sys, res.chunks(1000), res.chunks(777), res.n_samples, 1e5, np.eye(1), windows_s=(0.05, 0.4),
                     window_s=0.02)
    assert c.pointwise_error == (0.0, 0.0) and c.energy_envelope_error == 0.0
    assert c.freq_agreement == 1.0 and c.freq_median_diff_hz == 0.0
    # SDND101: the mass enters the stop at t = 0+ and again at 0.3299 s (contact tc + flight tf)
    assert c.closures_run == c.closures_ref == 2
