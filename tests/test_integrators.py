"""Ringdown integrators against closed forms, each other, and their invariants."""

from __future__ import annotations

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
