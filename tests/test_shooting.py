"""Shooting on the exact flow: closure, periods, monodromy."""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2
from reduced.periodic.shooting import conservative, shoot
from reduced.transient.exact import integrate_exact
from reduced.transient.flow import Flow

P = DiscreteParams()
SYS = conservative(P.system())
FLOW = Flow(SYS)


def test_monodromy_matches_finite_differences():
    x0 = np.array([7.0 * P.gap, 0.3 * P.gap, -5.0 * P.gap])
    v0 = np.array([0.1, -0.2, 0.05])
    T = 0.0123
    r = FLOW(x0, v0, T, jacobian=True)
    assert r.n_events > 4
    h = np.concatenate([np.full(3, 1e-6 * P.gap), np.full(3, 1e-6)])
    Jf = np.zeros((6, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = h[i]
        Jf[:, i] = (FLOW(x0 + e[:3], v0 + e[3:], T).y - FLOW(x0 - e[:3], v0 - e[3:], T).y) / (2 * h[i])
    # central differences of a C^1, piecewise-C^inf flow: truncation ~h^2 |y'''| plus
    # round-off ~eps |y| / h, both ~1e-8 relative here
    assert np.abs(Jf - r.jacobian).max() / np.abs(r.jacobian).max() < 1e-6


def test_flow_agrees_with_exact_integrator():
    x0 = np.array([3.0 * P.gap, 0.0, -0.5 * P.gap])  # generic: no stop touched at t = 0
    v0 = np.array([0.0, 0.5, 0.0])
    res = integrate_exact(SYS, x0, v0, 0.01, 1e4)
    r = FLOW(x0, v0, float(res.t[-1]))
    assert np.allclose(r.y[:3], res.x[-1], rtol=0, atol=1e-11 * np.abs(res.x).max())  # 60 events, round-off


@pytest.mark.parametrize("chi", [1.5, 10.0, 300.0])
def test_nnm2_shooting_matches_exact_period(chi):
    x0 = chi * P.gap
    E = float(nnm2.energy_from_amplitude(P, x0))
    T_exact = float(nnm2.period_from_amplitude(P, x0))
    # start 3 % off in period and 1 % in shape: Gauss-Newton must find the orbit
    orb = shoot(FLOW, np.array([x0, 0.001 * x0, -0.99 * x0]), np.zeros(3), 1.03 * T_exact, E)
    assert orb.closure < 1e-12
    assert orb.period_s == pytest.approx(T_exact, rel=1e-12)
    assert orb.energy_J == pytest.approx(E, rel=1e-13)
    # and the period agrees with a ringdown of the exact integrator over that orbit
    res = integrate_exact(SYS, orb.x0, orb.v0, 3 * orb.period_s, 1.0 / orb.period_s)
    assert np.allclose(res.x[-1], orb.x0, atol=1e-10 * x0)


def test_linear_orbits_have_unit_multipliers():
    lin = linear_modes(SYS)
    for k in range(3):
        x0 = 0.2 * P.gap * lin.phi[:, k] / np.abs(lin.phi[:, k]).max()
        E = float(SYS.energy(x0, np.zeros(3)))
        orb = shoot(FLOW, x0, np.zeros(3), 1.0 / lin.freq_hz[k], E)
        assert orb.freq_hz == pytest.approx(lin.freq_hz[k], rel=1e-13)
        assert np.allclose(np.abs(orb.multipliers), 1.0, atol=1e-9)


@pytest.mark.parametrize("E", [1.1e-3, 3.17e-3, 1.3e-2])
def test_multiple_shooting_near_grazing(E):
    # just above grazing NNM 2 is violently unstable (|mu| ~ 50-150): multiple shooting
    # from the H = 15 HB orbit converges to the exact orbit
    from reduced.periodic.backbones import nnm_branch
    from reduced.periodic.shooting import shoot_multiple

    b = nnm_branch(SYS, 1, H=15, energy_max_J=0.1)
    i = int(np.argmin(np.abs(np.log(b.energy_J / E))))
    x, v = b.residual.hb.time_series(b.X[i], b.omega[i], N=8)
    orb = shoot_multiple(FLOW, np.hstack([x, v]), 2 * np.pi / b.omega[i], b.energy_J[i])
    assert orb.freq_hz == pytest.approx(float(nnm2.frequency_from_energy(P, orb.energy_J)), rel=1e-12)
    assert orb.max_multiplier > 10.0
