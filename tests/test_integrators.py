"""Ringdown integrators against closed forms, each other, and their invariants."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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
    assert force[i_peak] == pytest.approx(9950.37, abs=0.01)  # REFERENCES: 9950.37 N at 0.015630 s
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
    p = replace(P, m2=P.m1, m3=P.m1, g=1e-2, c=4.0)
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


@pytest.mark.parametrize("method", ["exact", "explicit", "dop853"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_initial_state_refused(method, bad):
    with pytest.raises(ValueError, match="x0 must be finite"):
        ringdown(P.system(), np.array([bad, 0, 0]), np.zeros(3), 0.01, 1000.0, method)


def test_grazing_touch_is_not_missed():
    # Start 1e-9 gaps inside the stop: the contact lasts ~1e-5 of a period. A missed event
    # would leave the stop force off and change the period by ~1e-6 relative.
    from reduced.periodic import nnm2

    x0 = P.g * (1 + 1e-9)
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
    p = replace(P, g=gap, k_g=k_g, c=c)
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
    p = replace(P, m2=P.m1, m3=P.m1, g=1e4, c=max(c, 0.0))
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
    # the exact flow gives its largest multiplier, ln|mu| / T = 400 /s, independently of two runs
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
    assert floquet == pytest.approx(400.0, rel=0.01)
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
