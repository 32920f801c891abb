"""Friction at the tips (issue 27): the exact, explicit and reference integrators against closed forms.

The workhorse is the Coulomb oscillator built from the gap system's own parts: a mass m on a spring k
(x, tangential) rubbing on a contact whose normal coordinate z (mass mz, spring kz) is pressed into a
stop of stiffness kg with an interference delta, so that the normal force is N = kg kz delta / (kg + kz)
at rest and stays so (the friction force acts along x only, and loads nothing along z). With the slider's
tangential stiffness kt, F = mu N is the friction force, and kt -> infinity is Coulomb's law.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import MINDLIN_RATIO, DiscreteFrictionParams, DiscreteParams
from reduced.models.gaps import Friction, GapSystem
from reduced.models.loads import Harmonic, Loads, Tabulated
from reduced.transient.explicit import stability_limit
from reduced.transient.friction import clear_tables, integrate_exact_friction, reference_dop853
from reduced.transient.integrate import ringdown
from reduced.transient.store import RingdownFile

M_X, K_X, M_Z, K_Z, K_G, DELTA = 1.0, 1.0e4, 0.5, 1.0e5, 1.0e7, 1.0e-4
Z_REST = -K_G * DELTA / (K_G + K_Z)  # m, the normal coordinate at rest, pressed into its stop
N_REST = K_G * (Z_REST + DELTA)  # N, the normal force there (9.90 N)


def coulomb(mu: float = 0.3, kt: float = 1e7, c: float = 0.0, k: float = K_X, m: float = M_X) -> GapSystem:
    """The Coulomb oscillator of the module docstring: x tangential, z normal."""
    return GapSystem(M=np.diag([m, M_Z]), C=np.diag([c, 0.0]), K=np.diag([k, K_Z]), B=np.array([[0.0, 1.0]]),
                     k=np.array([K_G]), offset=np.array([-DELTA]), side=np.array([1.0]), tip=np.array([0]),
                     dof_names=("x", "z"), stop_names=("n",),
                     friction=Friction(Bt=np.array([[1.0, 0.0]]), tip=[0], k_t=kt, mu=mu, names=("t",)))


def merged(events) -> tuple[np.ndarray, np.ndarray]:
    """(times, kinds) of a run's events with those at one instant taken as one (the first): the exact
    integrator logs a closing and the slip that starts at once as two, the reference decides both at once."""
    keep = np.r_[True, np.diff(events.t) > 1e-12] if len(events) else np.zeros(0, bool)
    return events.t[keep], events.kind[keep]


def coulomb_turning_points(x0: float, F: float, k: float, kt: float, m: float, n: int) -> tuple[list, list]:
    """(turning points, their times) of the Coulomb oscillator with the slider's stiffness kt, from rest at x0
    with the slider unloaded, in closed form (each phase is linear):

    - stick: from a turning point x_a (slider force s F after a slip in direction s; at the start 0) the
      block oscillates at Omega = sqrt((k + kt) / m) about x_c = kt w / (k + kt) and the force runs to -s F
      at x_b = x_a - 2 s F / kt (x_0 - F / kt at the start), after arccos((x_b - x_c) / (x_a - x_c)) / Omega,
      if it gets there (|x_b - x_c| <= |x_a - x_c|); the spring energy F^2 / (2 kt) is the same at both
      ends, so m v_b^2 = k (x_a^2 - x_b^2) (minus F^2 / kt at the start);
    - slip in direction -s: m x'' + k x = s F, x - c = (x_b - c) cos(w t) + v_b / w sin(w t) about c = s F / k,
      w = sqrt(k / m): the next turning point c - s sqrt(m v_b^2 / k + (x_b - c)^2), where the phase
      atan2(-v_b / w, x_b - c) + w t first reaches a multiple of pi.
    """
    pts, times, xa, s, first, t = [], [], x0, 0.0, True, 0.0
    Om, om = math.sqrt((k + kt) / m), math.sqrt(k / m)
    while len(pts) < n:
        s_new = -1.0 if xa > 0 else 1.0  # the spring pulls back toward 0
        w = xa if first else xa - s * F / kt
        xb = xa - F / kt * (1.0 if first else 2.0) * (-s_new)
        xc = kt * w / (k + kt)
        if abs(xb - xc) > abs(xa - xc):
            break  # sticks for good
        t += math.acos((xb - xc) / (xa - xc)) / Om
        mv2 = k * (xa * xa - xb * xb) - (F * F / kt if first else 0.0)
        vb = s_new * math.sqrt(mv2 / m)
        c = -s_new * F / k
        t += ((-math.atan2(-vb / om, xb - c)) % math.pi) / om
        xa = c + s_new * math.sqrt(m * mv2 / k + (xb - c) ** 2)
        pts.append(xa)
        times.append(t)
        s, first = s_new, False
    return pts, times


# -- the Coulomb oscillator's free decay ----------------------------------------------------------------------
def test_coulomb_free_decay_closed_form():
    # Turning points (the slip -> stick events, where x' = 0) against the closed form with the slider's own
    # stiffness: the exact integrator is exact, so they agree to round-off (cond(V) eps x0 ~ 1e-12 x0; 1e-10 x0
    # allowed). Coulomb's rule then holds to the penalty's size: the amplitude falls by 2 F / k a half cycle
    # (4 F / k a cycle) up to the stick phase at each reversal, whose effect on the amplitude is within
    # 8 F / kt here (the closed form's stick terms: x_b - x_a = 2 F / kt and the energy it shifts); the
    # turning points' times are the closed form's to round-off (1e-12 s), the half period pi sqrt(m / k) to
    # the stick phase's share (it grows as the amplitude falls, 1e-5 s allowed over the amplitudes above
    # 3 F / k); and the motion stops in the band |x| <= F / k (+ 2 F / kt, the slider's give).
    # Undamped, the last stick oscillates for good and its force returns exactly to the cone once a period:
    # within round-off the march takes that touch for a crossing, and the slider slips for ~1e-10 s at
    # ~1e-10 m/s (events, no motion: below 1e-9 m/s and 1e-15 J each); the turning points are the ends of
    # the slips that last (longer than 1 ms: a half period is 31 ms).
    mu, kt, x0 = 0.3, 1e9, 0.01
    F = mu * N_REST
    r = integrate_exact_friction(coulomb(mu, kt), [x0, Z_REST], [0.0, 0.0], 0.6, 2000.0, log_events=1000)
    assert r.energy_balance_error < 1e-12, r.energy_balance_error
    ev = r.events
    ends = np.flatnonzero(ev.kind == "stick")
    lasted = np.diff(np.r_[0.0, ev.t])[ends] > 1e-3
    stick = ends[lasted]
    micro = ends[~lasted]
    assert np.all(np.abs(ev.y[micro - 1, 2]) < 1e-9)  # the touches' slips: no motion
    tp = ev.y[stick, 0]
    ref, times = coulomb_turning_points(x0, F, K_X, kt, M_X, 100)
    assert len(tp) == len(ref) == 17, (len(tp), len(ref))  # ceil((x0 - F/k) / (2 F/k)) = ceil(16.3) half cycles
    assert np.max(np.abs(tp - ref)) < 1e-10 * x0, np.max(np.abs(tp - ref))
    amp = np.abs(np.r_[x0, tp])
    big = amp[1:] > 3 * F / K_X
    loss = (amp[:-1] - amp[1:])[big]
    assert np.max(np.abs(loss - 2 * F / K_X)) < 8 * F / kt, np.max(np.abs(loss - 2 * F / K_X)) / (F / kt)
    assert np.max(np.abs(ev.t[stick] - times)) < 1e-12, np.max(np.abs(ev.t[stick] - times))
    half = np.diff(np.r_[0.0, ev.t[stick]])[big]
    assert np.max(np.abs(half - math.pi * math.sqrt(M_X / K_X))) < 1e-5, half
    assert abs(tp[-1]) <= F / K_X + 2 * F / kt
    after = r.t > ev.t[stick][-1]
    assert np.all(np.abs(r.x[after, 0]) <= F / K_X + 2 * F / kt)
    last = r.t > ev.t[stick][-1] + 1e-3
    assert np.ptp(r.friction[last]) < 1e-12 * r.energy0  # the touches dissipate nothing that counts
    # the friction work is the energy lost: 1/2 k (x0^2 - x_end^2) less the spring's, to round-off
    assert r.friction[-1] == pytest.approx(r.energy0 - r.energy[-1], rel=1e-12)


def test_stick_slip_at_grazing_is_not_missed():
    # Sticking from x = 0 with a velocity, the slider's force oscillates with amplitude kt v0 / Omega
    # (Omega = sqrt((k + kt) / m)); set it to (1 +- 1e-6) F: just above, the force crosses the cone for
    # 2 sqrt(2e-6) / Omega ~ 1e-7 s at t = pi / (2 Omega), a slip that a march stepping over it would miss;
    # just below, it touches nothing. The exact integrator finds the first and no event in the second.
    mu, kt = 0.3, 1e7
    F = mu * N_REST
    Omega = math.sqrt((K_X + kt) / M_X)
    for delta, slips in ((1e-6, True), (-1e-6, False)):
        v0 = (1 + delta) * F / kt * Omega
        r = integrate_exact_friction(coulomb(mu, kt), [0.0, Z_REST], [v0, 0.0], 2 * math.pi / Omega, 1e5,
                                     log_events=10)
        kinds = list(r.events.kind)
        assert (kinds[:1] == ["slip+"]) == slips, (delta, kinds)
        if slips:
            assert r.events.t[0] == pytest.approx(math.pi / (2 * Omega), rel=2e-3)  # the crossing is sqrt(delta) wide
            assert kinds[1] == "stick"
        else:
            assert kinds == []
        assert r.energy_balance_error < 1e-12


def test_a_slip_reversal_inside_one_output_interval_is_not_missed():
    # A fast Coulomb oscillator (k = 1e6 N/m: 159 Hz) sampled at 20 Hz: a whole cycle, two reversals, falls
    # between two samples. The events do not depend on the sampling (the same bits at 20 Hz and 20 kHz),
    # and they are those of DOP853 restarted at every state change (same kinds, times to 1e-9 s: the
    # reference's event location after its Newton refinement).
    sys = coulomb(0.3, 1e8, k=1e6)
    args = ([2e-4, Z_REST], [0.0, 0.0], 0.05)
    a = integrate_exact_friction(sys, *args, 20.0, log_events=1000)
    b = integrate_exact_friction(sys, *args, 20000.0, log_events=1000)
    assert len(a.events) > 20 and np.array_equal(a.events.t, b.events.t) and np.array_equal(a.events.y, b.events.y)
    assert np.array_equal(a.x, b.x[::1000])
    d = reference_dop853(sys, *args, 20.0)
    ta, ka = merged(a.events)
    td, kd = merged(d.events)
    assert list(ka) == list(kd)
    assert np.max(np.abs(ta - td)) < 1e-9
    assert a.energy_balance_error < 1e-12 and d.energy_balance_error < 1e-8


# -- forced: Den Hartog and the moving belt ------------------------------------------------------------------
def den_hartog(P: float, F: float, k: float, m: float, beta: float):
    """Den Hartog's steady response of m x'' + k x + F sign(x') = P cos(w t + psi), continuous slip, from
    x(0) = -X at rest (derived here: four conditions on a half period, x(t + pi / w) = -x(t)):

        a = P / (k (1 - beta^2)),  U = sin(pi / beta) / (beta (1 + cos(pi / beta))),
        a sin(psi) = F U / k,  X = -a cos(psi) = sqrt(a^2 - (F U / k)^2),

    x = A cos(wn t) + B sin(wn t) + a cos(w t + psi) - F / k on the first half period, B = a beta sin(psi),
    A = B (1 + cos(pi / beta)) / sin(pi / beta). Returns (X, psi, x(t))."""
    wn = math.sqrt(k / m)
    w = beta * wn
    th = math.pi / beta
    U = math.sin(th) / (beta * (1 + math.cos(th)))
    a = P / (k * (1 - beta**2))
    psi = math.pi - math.asin(F * U / (k * a))  # cos(psi) < 0: X > 0 below resonance
    X = -a * math.cos(psi)
    Bc = a * beta * math.sin(psi)
    A = Bc * (1 + math.cos(th)) / math.sin(th)

    def x(t):
        h = math.pi / w
        kh = np.floor(np.asarray(t) / h)
        tau = t - kh * h
        xx = A * np.cos(wn * tau) + Bc * np.sin(wn * tau) + a * np.cos(w * tau + psi) - F / k
        return np.where(kh % 2 == 0, xx, -xx)

    return X, psi, x


def test_den_hartog_forced_coulomb_oscillator():
    # Forced at beta = 0.6 of resonance with P = 4 F, started on Den Hartog's orbit (the slider on the cone).
    # With the slider's stiffness kt each reversal sticks for a quarter period of the stiff stick oscillation,
    # a delay ~ sqrt(m / kt), so the exact integrator's motion converges to Den Hartog's as kt^(-1/2): the
    # fitted rate over kt = 1e8 .. 1e10 is -0.500 (asserted within 0.02), the error 2.9e-4 X at 1e10 (4e-4
    # allowed), and it stays bounded over the ten periods run (the orbit is stable). The stick time itself
    # is the closed form arccos((-F/kt - u_eq) / (F/kt - u_eq)) / Omega of the spring u = x - w released from
    # F / kt about u_eq = (P(t) - k w) / (k + kt) (P(t) held at its value at the stick's start: the load moves
    # by w t_s ~ 2e-3 of a radian meanwhile, 1e-2 relative allowed); and DOP853 restarted at every state
    # change agrees to 1e-7 X (measured 3e-8: DOP853's own accuracy through the stiff stick phases).
    mu, beta = 0.3, 0.6
    F = mu * N_REST
    P = 4 * F
    X, psi, xdh = den_hartog(P, F, K_X, M_X, beta)
    w = beta * math.sqrt(K_X / M_X)
    loads = Loads(b=np.array([[1.0, 0.0]]),
                  signals=(Harmonic(amplitude_N=P, freq_hz=w / (2 * math.pi), phase_deg=math.degrees(psi)),))
    T, fs = 10 * 2 * math.pi / w, 100 * w / (2 * math.pi)
    errs = []
    for kt in (1e8, 1e9, 1e10):
        r = integrate_exact_friction(coulomb(mu, kt), [-X, Z_REST], [0.0, 0.0], T, fs, loads=loads,
                                     w0=[-X - F / kt], log_events=200)
        assert r.energy_balance_error < 1e-12, r.energy_balance_error
        errs.append(np.max(np.abs(r.x[:, 0] - xdh(r.t))) / X)
        if kt == 1e9:
            ev, Omega = r.events, math.sqrt((K_X + kt) / M_X)
            starts = np.flatnonzero(ev.kind == "stick")
            assert len(starts) >= 19 and np.all(ev.kind[starts[:-1] + 1] != "stick")  # two reversals a period
            for i in starts[:-1]:
                t0, xw = ev.t[i], ev.y[i]
                s = 1.0 if xw[0] - xw[4] > 0 else -1.0  # the slider's force s F at the stick's start
                u_eq = (P * math.cos(w * t0 + psi) - K_X * xw[4]) / (K_X + kt)
                ts = math.acos((-s * F / kt - u_eq) / (s * F / kt - u_eq)) / Omega
                assert ev.t[i + 1] - t0 == pytest.approx(ts, rel=1e-2)
            d = reference_dop853(coulomb(mu, kt), [-X, Z_REST], [0.0, 0.0], T / 5, fs, loads=loads, w0=[-X - F / kt])
            assert np.max(np.abs(d.x - r.x[:d.x.shape[0]])) < 1e-7 * X  # DOP853 through the stiff sticks: 3e-8
            assert d.energy_balance_error < 1e-8
    rate = np.polyfit(np.log([1e8, 1e9, 1e10]), np.log(errs), 1)[0]
    assert rate == pytest.approx(-0.5, abs=0.02), (rate, errs)
    assert errs[-1] < 4e-4, errs


def belt(t: np.ndarray, F: float, k: float, m: float, V: float) -> np.ndarray:
    """The block on the belt (lab frame, spring to a wall, belt at V, from rest at 0), in closed form:
    slip x = F/k (1 - cos w t) until x' = V at t1 (sin w t1 = V k / (F w)); stick x = x1 + V (t - t1) until
    k x = F at t2; then the slip that returns to the belt's speed tangentially, x = F/k + V/w sin(w (t - t2))
    (its relative velocity V (cos - 1) touches zero every period without crossing: a graze)."""
    w = math.sqrt(k / m)
    t1 = math.asin(V * k / (F * w)) / w
    x1 = F / k * (1 - math.cos(w * t1))
    t2 = t1 + (F / k - x1) / V
    return np.where(t < t1, F / k * (1 - np.cos(w * t)),
                    np.where(t < t2, x1 + V * (t - t1), F / k + V / w * np.sin(w * (t - t2)))), t1, t2


def test_stick_slip_on_a_moving_belt():
    # In the belt's frame X = x - V t the block is the Coulomb oscillator under the load -k V t (a ramp: a
    # tabulated load, piecewise linear), rubbing on a still surface; from rest in the lab, X'(0) = -V. The
    # exact integrator gives the closed form's phases: the first slip ends (the block catches the belt) at t1
    # (to the penalty's stick transient, ~sqrt(m / kt) = 3e-5 s at kt = 1e9; 1e-4 s allowed), the block then
    # rides the belt, |X'| within the stick oscillation's 2 Omega F / kt, until t2, where the long slip of the
    # limit cycle starts (1e-4 s allowed), and x follows the closed form to 2e-3 of F / k (measured 4e-5).
    # With a finite kt the sticking is a sequence of brief slips: the ramp moves the stick oscillation's
    # centre, so its force comes back past the cone once a stick period (2e-4 s), a genuine crossing each
    # time: one a stick period 2 pi / Omega over [t1, t2] (55), every one found though the late ones exceed the
    # cone by ~1e-15 m for ~1e-7 s. The limit cycle's tangential returns to the belt's speed (grazes: the
    # relative velocity touches zero once a period) pass without an event. DOP853 restarted at every state
    # change agrees to 1e-9 F / k up to t1 + 1 ms (its sign test at the step ends misses the later brief slips,
    # shorter than its steps), and the energy balances to round-off.
    mu, kt, V = 0.3, 1e9, 0.02
    F = mu * N_REST
    w, Om = math.sqrt(K_X / M_X), math.sqrt((K_X + kt) / M_X)
    assert F * w / K_X > V  # the block catches up with the belt: there is a first stick
    T = 6 * 2 * math.pi / w
    loads = Loads(b=np.array([[1.0, 0.0]]), signals=(Tabulated(t_s=np.array([0.0, 2 * T]),
                                                              force_N=np.array([0.0, -K_X * V * 2 * T])),))
    fs = 20000.0
    r = integrate_exact_friction(coulomb(mu, kt), [0.0, Z_REST], [-V, 0.0], T, fs, loads=loads, log_events=1000)
    assert r.energy_balance_error < 1e-12, r.energy_balance_error
    x = r.x[:, 0] + V * r.t
    ref, t1, t2 = belt(r.t, F, K_X, M_X, V)
    assert np.max(np.abs(x - ref)) < 2e-3 * F / K_X, np.max(np.abs(x - ref)) / (F / K_X)
    ev = r.events
    assert list(ev.kind[:2]) == ["slip-", "stick"] and ev.t[1] == pytest.approx(t1, abs=1e-4)
    gaps = np.diff(np.r_[ev.t, T])
    long_slip = np.flatnonzero((ev.kind == "slip-") & (gaps > 1e-3))[1:]  # after the first, from t = 0
    assert long_slip.size == 1 and ev.t[long_slip[0]] == pytest.approx(t2, abs=1e-4)
    riding = (r.t > ev.t[1]) & (r.t < ev.t[long_slip[0]])
    assert np.max(np.abs(r.v[riding, 0])) < 2 * Om * F / kt
    brief = np.count_nonzero((ev.kind == "slip-") & (ev.t > ev.t[1]) & (ev.t < ev.t[long_slip[0]]))
    periods = (ev.t[long_slip[0]] - ev.t[1]) * Om / (2 * math.pi)  # stick periods while riding
    assert abs(brief + 1 - periods) < 0.5, (brief, periods)  # the last touch is the long slip's start
    assert len(ev) == long_slip[0] + 1  # the grazes of the limit cycle: no event after the long slip starts
    d = reference_dop853(coulomb(mu, kt), [0.0, Z_REST], [-V, 0.0], t1 + 1e-3, fs, loads=loads)
    assert np.max(np.abs(d.x[:, 0] - r.x[:d.x.shape[0], 0])) < 1e-9 * F / K_X
    assert d.energy_balance_error < 1e-8


def test_a_slip_end_under_a_moving_load_sticks_without_toggling():
    # The damped Coulomb oscillator (c = 20 N s/m) with a stiff slider (kt = 1e10: the stick oscillation at
    # Omega = 1e5 rad/s, cond(V) = 1.4e5) under a harmonic load P = 1.5 F at 3 x its natural frequency, from
    # rest: the block mostly sticks, and the moving load brings the stick force back past the cone once a
    # stick period, each time a brief slip whose end (w' = 0, the force rate kt t' = mu N' exactly there) is
    # followed by a stick whose cone function has q = q' = 0: decided by q'' < 0. The re-expanded state's
    # round-off put q' above the march's band, and the code before this fix switched the slider back and forth
    # at such an instant until it stopped ("contact state flips back and forth" at t = 0.0172 s). Now no slider
    # switches back at the instant it switched, and the energy balances to round-off (1e-12: measured 3e-14).
    # Checks: the brief slips recur once a stick period 2 pi / Omega (the moving centre's closed form, as on
    # the belt: the median spacing to 2e-3, measured 1.0e-3), and central difference with the return
    # mapping (independent of the events) converges to the exact motion at its second order: errors 1.7e-5
    # and 1.5e-6 of the motion at omega_max dt = 0.1 and 0.03 (2e-5 and 2e-6 allowed; their ratio 11.3 against
    # (0.1 / 0.03)^2 = 11.1, 20 % allowed), its friction work to 1e-7 of the exact (measured 1.5e-8).
    # DOP853 restarted at every state change misses these slips (shorter than its steps; see the belt).
    mu, kt, beta = 0.3, 1e10, 3.0
    F = mu * N_REST
    w = beta * math.sqrt(K_X / M_X)
    loads = Loads(b=np.array([[1.0, 0.0]]), signals=(Harmonic(amplitude_N=1.5 * F, freq_hz=w / (2 * math.pi)),))
    sys = coulomb(mu, kt, c=20.0)
    args = ([0.0, Z_REST], [0.0, 0.0], 4 * 2 * math.pi / w, 2000.0)
    r = integrate_exact_friction(sys, *args, loads=loads, log_events=5000)
    assert r.energy_balance_error < 1e-12, r.energy_balance_error
    ev = r.events
    assert len(ev) > 300 and ev.t[-1] > 0.05
    assert not np.any((np.diff(ev.t) < 1e-12) & (ev.slot[1:] == ev.slot[:-1]))
    Omega = math.sqrt((K_X + kt) / M_X)
    slips = np.diff(ev.t[ev.kind == "slip-"])
    assert np.median(slips) == pytest.approx(2 * math.pi / Omega, rel=2e-3)
    scale = np.max(np.abs(r.x[:, 0]))
    errs = []
    for od in (0.1, 0.03):
        e = ringdown(sys, *args, "explicit", loads=loads, omega_dt=od)
        errs.append(np.max(np.abs(e.x[:, 0] - r.x[:, 0])) / scale)
    assert errs[0] < 2e-5 and errs[1] < 2e-6, errs
    assert errs[0] / errs[1] == pytest.approx((0.1 / 0.03) ** 2, rel=0.2)
    assert abs(e.friction[-1] - r.friction[-1]) < 1e-7 * r.friction[-1]


# -- the exact integrator against DOP853 restarted at every state change -----------------------------------------
@pytest.mark.parametrize("case", ["coulomb-damped", "discrete"])
def test_exact_matches_dop853_restarted_at_every_state_change(case):
    # The same events (merged at an instant, see merged()) in the same order at the same times, and the same
    # motion: to 1e-9 s and 1e-9 of the motion for the damped Coulomb oscillator (DOP853 at rtol 1e-12 with its
    # events refined on the steps: measured 3e-9 of the motion, 1e-8 allowed); the discrete model with friction
    # is chaotic (its impacts amplify every difference), so over its first 20 ms (37 events) 1e-7 of the motion
    # and 1e-8 s. Both balance their energy: the exact to round-off, DOP853 to its tolerance.
    if case == "coulomb-damped":
        sys, x0, v0, T, tol_x, tol_t = coulomb(0.3, 1e6, c=2.0), [0.01, Z_REST], [0.0, 0.0], 0.3, 1e-8, 1e-9
    else:
        sys, x0, v0 = DiscreteFrictionParams().system(), np.zeros(4), [0, 0, 0.3, 0.2]
        T, tol_x, tol_t = 0.02, 1e-7, 1e-8
    r = integrate_exact_friction(sys, x0, v0, T, 20000.0, log_events=10000)
    d = reference_dop853(sys, x0, v0, T, 20000.0)
    tr, kr = merged(r.events)
    td, kd = merged(d.events)
    assert list(kr) == list(kd) and len(kr) > 10
    assert np.max(np.abs(tr - td)) < tol_t
    scale = np.max(np.abs(r.x))
    assert np.max(np.abs(r.x - d.x)) < tol_x * scale
    assert np.max(np.abs(r.w - d.w)) < tol_x * scale
    assert r.energy_balance_error < 1e-11 and d.energy_balance_error < 1e-8


def test_zero_friction_is_the_frictionless_motion():
    # mu = 0: every closing sticks with a zero cone and slips at once, with zero force: the motion is that of
    # the system without friction, to the round-off of the two closed forms as the impacts amplify it (the
    # motion is chaotic: measured 2.4e-13 of the motion after 25 ms, 1.5e-11 after 30 ms; 1e-11 allowed at 25 ms).
    p = DiscreteFrictionParams()
    sys = p.system()
    free = sys.with_friction(None)
    zero = sys.with_friction(Friction(Bt=sys.friction.Bt, tip=sys.friction.tip, k_t=sys.friction.k_t, mu=0.0,
                                      names=sys.friction.names))
    args = (np.zeros(4), [0, 0, 0.3, 0.2], 0.025, 20000.0)
    a, b = ringdown(free, *args), ringdown(zero, *args)
    assert b.stats["n_events"] > a.stats["n_events"] > 10
    assert np.max(np.abs(a.x - b.x)) < 1e-11 * np.max(np.abs(a.x))
    assert np.max(np.abs(b.friction)) < 1e-20 * b.energy0  # the sliders' zero force does no work


# -- energy balance on every run --------------------------------------------------------------------------
@pytest.mark.parametrize("method, tol", [("exact", 1e-11), ("explicit", 2e-3), ("dop853", 1e-8)])
@pytest.mark.parametrize("forced", [False, True])
def test_energy_balance_every_method(method, tol, forced):
    # E(t) = E(0) + W_ext(t) - W_viscous(t) - W_friction(t): the exact integrator to round-off, DOP853 restarted
    # to its tolerance (rtol 1e-10 in ringdown), central difference to its scheme's error (measured 1e-4 to
    # 5e-4 at its default step: its return mapping is backward Euler on the slider).
    sys = DiscreteFrictionParams().system()
    loads = Loads(b=np.array([[0.0, 1.0, 0.0, 0.3]]), signals=(Harmonic(amplitude_N=40.0, freq_hz=30.0),)) \
        if forced else None
    r = ringdown(sys, np.zeros(4), [0, 0, 0.3, 0.2], 0.05, 20000.0, method, loads=loads)
    assert r.energy_balance_error < tol, r.energy_balance_error
    assert r.friction[-1] > 1e-3 * r.energy0  # friction did work
    assert np.all(np.diff(r.friction) >= -1e-12 * r.energy0)  # and never gave energy back


# -- the explicit integrator ----------------------------------------------------------------------------------
def test_explicit_converges_to_the_exact_motion():
    # The damped Coulomb oscillator over 0.1 s (3 reversals): central difference with the return mapping
    # against the exact run, at omega_max dt = 0.2, 0.1, 0.05. The displacement error falls with the step at a
    # fitted rate of at least 1 (the stick-slip transitions are decided at the steps, first order; the smooth
    # phases are second order: measured 2.8 over these three steps, irregularly; asserted >= 0.9), below 1e-4
    # of the motion at the finest step; the friction work to 1e-3.
    sys = coulomb(0.3, 1e6, c=2.0)
    args = ([0.01, Z_REST], [0.0, 0.0], 0.1, 10000.0)
    ref = ringdown(sys, *args)
    errs, wf = [], []
    for od in (0.2, 0.1, 0.05):
        e = ringdown(sys, *args, "explicit", omega_dt=od)
        errs.append(np.max(np.abs(e.x - ref.x)) / 0.01)
        wf.append(abs(e.friction[-1] - ref.friction[-1]) / ref.friction[-1])
    rate = np.polyfit(np.log([0.2, 0.1, 0.05]), np.log(errs), 1)[0]
    assert rate >= 0.9, (rate, errs)
    assert errs[-1] < 1e-4 and wf[-1] < 1e-3, (errs, wf)


def _cd_stick_run(monkeypatch, sys: GapSystem, dt: float, n_steps: int, size: float) -> np.ndarray:
    """x of central difference with friction from the sticking equilibrium plus ``size`` of the stick mode
    (its refusal bypassed, as tests/test_integrators.py does for the frictionless kernel)."""
    import reduced.transient.explicit as explicit
    from reduced.transient import stepper
    from reduced.transient.friction import ExplicitFrictionOptions, FrictionExplicitStepper

    monkeypatch.setattr(explicit, "stability_limit", lambda s: (1.0, math.inf))
    # the slider at 0: the sticking equilibrium is x = 0, and x(0) = size is all stick mode
    res = stepper.run(FrictionExplicitStepper, sys, [size, Z_REST], [0.0, 0.0], n_steps * dt, 1.0 / dt,
                      ExplicitFrictionOptions(dt=dt, w0=(0.0,))).collect()
    assert res.stats["n_steps"] == n_steps
    F = sys.friction.mu[0] * N_REST
    assert np.all(np.abs(sys.friction.force(res.x, res.w)) < F), "the slider slipped: no longer linear"
    return np.abs(res.x[:, 0])


def test_central_difference_stability_limit_with_kt(monkeypatch):
    # With the contact closed and the slider sticking, the tangential motion is a linear oscillator of
    # stiffness k + kt: omega_max = sqrt((k + kt) / m) = 31624 rad/s (kt = 1e9 above the normal contact's
    # 4494 rad/s), which stability_limit reports (closed_stiffness counts the sticking sliders). Central
    # difference grows past omega_max dt = 2 (1.01 x 2 / omega: from 1e-15 m, the root ln|z| = 0.2826 of its
    # recurrence, measured over steps 20 - 40 to 1e-4) and stays bounded below it (0.99 x: 20,000 steps, never
    # above its start but by round-off). The amplitudes keep the slider's force far inside the cone
    # (F / kt = 3e-9 m), so the run stays in the sticking state.
    kt = 1e9
    sys = coulomb(0.3, kt)
    omega, _ = stability_limit(sys)
    assert omega == pytest.approx(math.sqrt((K_X + kt) / M_X), rel=1e-12)
    dt = 1.01 * 2 / omega
    d = _cd_stick_run(monkeypatch, sys, dt, 40, 1e-15)
    W = omega * dt
    expected = float(np.log(np.abs(np.roots([1.0, -(2 - W * W), 1.0])).max()))
    assert np.log(d[40] / d[20]) / 20 == pytest.approx(expected, rel=1e-4)
    d = _cd_stick_run(monkeypatch, sys, 0.99 * 2 / omega, 20_000, 1e-12)
    assert d.max() <= (1 + 1e-6) * d[0]


# -- the model ------------------------------------------------------------------------------------------------
def test_discrete_friction_model():
    # The vertical part is the paper's model (the same M, K, C and stops), the axial one a rigid beam of
    # m1 + m2 + m3 at 10.92 Hz (Table 2's longitudinal mode), the tangential stiffness Mindlin's
    # 2 (1 - nu) / (2 - nu) k_g, and mu = 0 is no friction.
    p = DiscreteFrictionParams()
    s, s3 = p.system(), DiscreteParams().system()
    assert np.array_equal(s.M[:3, :3], s3.M) and np.array_equal(s.K[:3, :3], s3.K)
    assert np.array_equal(s.B[:, :3], s3.B) and np.array_equal(s.k, s3.k) and np.array_equal(s.offset, s3.offset)
    w2 = np.linalg.eigvals(np.linalg.solve(s.M, s.K))
    assert np.any(np.isclose(np.sqrt(w2.real) / (2 * math.pi), 10.92, rtol=1e-12))
    assert MINDLIN_RATIO == pytest.approx(0.7 / 0.85 * 1.0, rel=1e-15)  # 2 (1 - 0.3) / (2 - 0.3)
    assert np.all(s.friction.k_t == MINDLIN_RATIO * p.k_g) and np.all(s.friction.mu == 0.3)
    assert DiscreteFrictionParams(mu=0.0).system().friction is None
    assert np.all(DiscreteFrictionParams(k_t=1e6).system().friction.k_t == 1e6)
    with pytest.raises(ValueError, match="k_t must be > 0"):
        DiscreteFrictionParams(k_t=0.0)


def test_friction_damps_the_longitudinal_mode_when_the_tips_touch():
    # The scene discrete-friction's start: without friction the axial motion u is a damped cosine of its own
    # (u is decoupled: u = v0 / w_d e^{-zeta w t} sin(w_d t), matched to 1e-9 of its amplitude: the exact closed
    # form); with mu = 0.3 the impacts lock and brake it, and 0.5 s later it is below 1e-4 of that.
    v0 = [0.0, 0.0, 0.3, 0.2]
    free = DiscreteFrictionParams(mu=0.0)
    r0 = ringdown(free.system(), np.zeros(4), v0, 0.6, 2000.0)
    w = 2 * math.pi * free.f_long_hz
    zeta = free.c / (2 * free.m_beam * w)
    wd = w * math.sqrt(1 - zeta**2)
    u = 0.2 / wd * np.exp(-zeta * w * r0.t) * np.sin(wd * r0.t)
    assert np.max(np.abs(r0.x[:, 3] - u)) < 1e-9 * 0.2 / w
    r = ringdown(DiscreteFrictionParams().system(), np.zeros(4), v0, 0.6, 2000.0)
    late = r.t >= 0.5
    assert np.max(np.abs(r.x[late, 3])) < 1e-4 * np.max(np.abs(r0.x[late, 3]))
    assert r.energy_balance_error < 1e-11


def flutter_system() -> GapSystem:
    """Mode coupling: a tangential-normal coupling kc in K and the slip's nonsymmetric term sigma mu kg make a
    slip state's stiffness have complex eigenvalues (k1 = k2 + kg, kc (kc + sigma mu kg) < 0): slip - grows
    at Re lam = 110 /s (friction-induced flutter, as the 3-D apparatus's pitch makes at its tips)."""
    kc = 1e5
    return GapSystem(M=np.eye(2), C=np.zeros((2, 2)), K=np.array([[K_G + K_Z, kc], [kc, K_Z]]),
                     B=np.array([[0.0, 1.0]]), k=np.array([K_G]), offset=np.array([-DELTA]), side=np.array([1.0]),
                     tip=np.array([0]), dof_names=("x", "z"), stop_names=("n",),
                     friction=Friction(Bt=np.array([[1.0, 0.0]]), tip=[0], k_t=1e7, mu=0.5, names=("t",)))


def test_a_fluttering_slip_state_is_integrated_exactly(monkeypatch):
    # The growing state is solved like any other, its growing terms bounded over segments of at most
    # ln 2 / Re lam (6.3 ms here). Against DOP853 restarted at every state change: the same events at the
    # same times, the motion to 1e-9 (measured 6e-12); the energy balance to round-off.
    from reduced.transient import friction_tables as ft_module

    sys = flutter_system()
    table = ft_module.friction_table(sys, sys.omega_max())
    slip_down = table.states.index([True], [-1])
    # slip -: K_s = [[k, kc - mu kg], [kc, k]] (k = kg + kz, M = I), omega^2 = k +- i sqrt(kc (mu kg - kc)), so
    # lam = i omega has Re lam = Im sqrt(k + i sqrt(kc (mu kg - kc))) > 0 (the modes' own 1e-16 aside)
    kc, k = 1e5, K_G + K_Z
    growth = np.sqrt(complex(k, math.sqrt(kc * (0.5 * K_G - kc)))).imag
    assert table.lam[slip_down].real.max() == pytest.approx(growth, rel=1e-9)  # 110.06 /s
    args = ([0.0, 0.0], [1.0, 0.0], 0.05, 20000.0)
    r = integrate_exact_friction(sys, *args, log_events=100)
    ref = reference_dop853(sys, *args)
    t_r, k_r = merged(r.events)
    t_d, k_d = merged(ref.events)
    assert list(k_r) == list(k_d) and "slip-" in k_r
    assert np.max(np.abs(t_r - t_d)) < 1e-9
    assert np.max(np.abs(r.x - ref.x)) < 1e-9 * np.max(np.abs(r.x))
    assert r.energy_balance_error < 1e-12
    # the segments cut 600 times shorter (10 us, each slip - in ~27 pieces): the closed form restarts at
    # each cut from the state there, so the motion changes only by the round-off of the restarts
    monkeypatch.setattr(ft_module, "GROWTH_SEGMENT", math.log(2.0) / 600)
    clear_tables()  # the tables of this system are kept from the run above
    short = integrate_exact_friction(sys, *args, log_events=100)
    assert short.stats["n_events"] == r.stats["n_events"]
    assert np.max(np.abs(short.x - r.x)) < 1e-11 * np.max(np.abs(r.x))
    assert short.energy_balance_error < 1e-12


def test_a_slider_given_outside_the_cone_starts_on_it():
    # w0 pulling harder than mu N: the run starts slipping, the slider on the cone (w = t - mu N / kt).
    kt = 1e7
    F = 0.3 * N_REST
    r = integrate_exact_friction(coulomb(0.3, kt), [0.0, Z_REST], [0.0, 0.0], 0.01, 1000.0, w0=[-1e-3])
    assert r.w[0, 0] == pytest.approx(-F / kt, rel=1e-12)


def test_ringdown_file_keeps_the_sliders(tmp_path):
    # streamed to disk and read back: w and the friction work are histories of the file, the energy
    # (with the sliders' springs) is stored, and the balance is kept.
    sys = DiscreteFrictionParams().system()
    f = ringdown(sys, np.zeros(4), [0, 0, 0.3, 0.2], 0.05, 20000.0, out=tmp_path / "r.npz", chunk_samples=300)
    r = ringdown(sys, np.zeros(4), [0, 0, 0.3, 0.2], 0.05, 20000.0)
    assert isinstance(f, RingdownFile)
    assert np.array_equal(f.w, r.w) and np.array_equal(f.friction, r.friction)
    assert np.array_equal(np.asarray(f.energy), r.energy)
    assert f.energy_balance_error == pytest.approx(r.energy_balance_error, rel=1e-12)
    (c,) = list(f.chunks(10_000, fields=("w",)))
    assert np.array_equal(c.w, r.w)


def test_stored_accelerations_carry_the_friction_forces(tmp_path):
    # ringdown.npz's a = M^-1 (... - Bt^T k_t (Bt x - w)): on the axial coordinate u, at the samples where a
    # slider carries force, central differences of v agree with the stored a to their O(dt^2) error away from
    # the stick-slip kinks (median 0.093 m/s^2 of a peak 2300, measured), while the formula without the
    # friction term misses by the friction force itself (median 108 m/s^2)
    from reduced.transient.result import accelerations

    sys = DiscreteFrictionParams().system()
    f = ringdown(sys, np.zeros(4), [0.0, 0.0, 200.0, 0.5], 0.1, 100000.0, out=tmp_path / "r.npz")
    t, x, v, w, a = (np.asarray(getattr(f, k)) for k in ("t", "x", "v", "w", "a"))
    fd = (v[2:] - v[:-2]) / (t[2:] - t[:-2])[:, None]
    fr = sys.friction
    force = np.abs((x @ fr.Bt.T - w) * fr.k_t)[1:-1].max(axis=1)
    acting = force > 1e-3 * force.max()
    assert acting.sum() > 100  # the tips touch and the sliders work in this run
    u = 3  # the axial coordinate
    err = np.median(np.abs(a[1:-1, u] - fd[:, u])[acting])
    err_without = np.median(np.abs(accelerations(sys, t, x, v)[1:-1, u] - fd[:, u])[acting])
    assert err < 1e-3 * np.max(np.abs(a[:, u])) and err_without > 100 * err
    assert np.array_equal(a, accelerations(sys, t, x, v, None, w))


def test_what_does_not_treat_friction_refuses_it():
    # harmonic balance and the flow map (shooting) would drop the friction silently: refused by name, as the
    # scene tables that run them are on the friction model; the scene itself parses, with its keys.
    from bearingshaft.scenes import SceneError, load_scene, parse_scene
    from reduced._checks import InvalidArgument
    from reduced.periodic.hb import HarmonicBalance
    from reduced.transient.flow import Flow

    s = DiscreteFrictionParams().system()
    for build in (lambda: HarmonicBalance.for_system(s, 3), lambda: Flow(s)):
        with pytest.raises(InvalidArgument, match="friction"):
            build()
    scene = load_scene("discrete-friction")
    assert scene.model_kind == "discrete_friction" and scene.model.mu == 0.3 and scene.model.k_t is None
    text = ('[model]\nkind = "discrete_friction"\nmu = 0.5\nk_t = 1e7\n[initial]\nx0_m = [0.0, 0.0, 0.0, 0.0]\n'
            'v0_m_s = [0.0, 0.0, 1.0, 0.1]\n'
            '[ringdown]\nduration_s = 0.1\nsample_rate_hz = 1000.0\n')
    assert parse_scene(text, "t", "t.toml").model.k_t == 1e7
    with pytest.raises(SceneError, match=r"\[nnm\] does not treat friction"):
        parse_scene(text + "[nnm]\n", "t", "t.toml")
    with pytest.raises(SceneError, match="needs 4 values"):
        parse_scene(text.replace("[0.0, 0.0, 1.0, 0.1]", "[0.0, 0.0, 1.0]"), "t", "t.toml")
