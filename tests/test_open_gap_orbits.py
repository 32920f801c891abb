"""The open-gap system's harmonic orbits (reduced.periodic.frc.open_gap_orbits): where they close no stop
they are exact periodic orbits of the gap system, drawn beside the exact families (bearingshaft.stages.frc)."""

from __future__ import annotations

import numpy as np

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.frc import linear_frf, open_gap_orbits
from reduced.transient.exact import integrate_exact

B2 = np.array([0.0, 1.0, 0.0])  # the load at x2


def test_the_penetration_and_amplitude_are_those_of_the_sampled_orbit():
    """|r X| and max_j |B_j X| - side_j o_j against the orbit sampled at 4000 points of a period (the
    sampled maximum of a sinusoid falls short of the true one by at most 1 - cos(pi / 4000) ~ 3e-7)."""
    s = DiscreteParams().system()
    f = np.array([12.0, 18.0, 40.0])
    amp, pen, stable = open_gap_orbits(s, B2, 1.0, f, np.eye(3))
    assert stable
    assert np.allclose(amp, linear_frf(s, B2, 1.0, f), rtol=1e-14, atol=0.0)
    for k, fk in enumerate(f):
        w = 2 * np.pi * fk
        X = np.linalg.solve(s.K - w**2 * s.M + 1j * w * s.C, B2)
        t = np.linspace(0.0, 1.0 / fk, 4000, endpoint=False)
        x = np.real(np.outer(np.exp(1j * w * t), X))
        sampled = np.max(s.penetration(x))
        assert abs(sampled - pen[k]) <= 1e-6 * np.max(np.abs(s.B @ X)), (fk, sampled, pen[k])
    assert pen[1] > 0.0 > pen[0]  # 1 N at x2: the open orbit touches near the 18 Hz mode, not at 12 Hz


def test_an_open_orbit_that_closes_no_stop_is_an_orbit_of_the_exact_flow():
    """Started on the open orbit at 40 Hz, 1 N (pen < 0), the exact integrator with the stops comes back to
    the start after 20 periods to round-off (the orbit touches nothing: the flow is linear along it), while
    at 18 Hz (pen > 0) the same start leaves the open orbit (a stop closes)."""
    s = DiscreteParams().system()
    for fk, on in ((40.0, True), (18.0, False)):
        amp, pen, _ = open_gap_orbits(s, B2, 1.0, np.array([fk]), np.eye(3))
        assert (pen[0] < 0.0) == on
        w = 2 * np.pi * fk
        X = np.linalg.solve(s.K - w**2 * s.M + 1j * w * s.C, B2)
        x0, v0 = X.real, (1j * w * X).real
        T = 1.0 / fk
        r = integrate_exact(s, x0, v0, 20 * T, 200 / T, loads=Loads(B2[None, :], (Harmonic(1.0, fk),)), work=False)
        drift = np.max(np.abs(r.x[-1] - x0)) / np.max(np.abs(X))
        if on:
            assert drift < 1e-9, drift
        else:
            assert drift > 1e-3, drift
