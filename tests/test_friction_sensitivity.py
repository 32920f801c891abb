"""The exact sensitivity of the friction flow (reduced/periodic/friction_sensitivity.py, issue 27): state transition
matrices and saltation matrices against central differences of the exact integrator."""

from __future__ import annotations

import numpy as np
from test_friction_continuation import MU, P, coulomb, start

from reduced.periodic.friction_sensitivity import FlowSensitivity
from reduced.periodic.friction_shooting import flow


def test_the_segment_sensitivity_matches_central_differences_of_the_flow():
    # The Coulomb oscillator's continuous-slip orbit (k_t = 1e7 N/m), 8 segments. Central differences of the exact
    # flow, step 1e-6 of the scale D, in z = [x; v; d] (d = x - w the stretch, as Newton's unknowns): at a fixed w a
    # step in x moves a slipping slider off its cone one way and into it the other (a kink of the map); at a fixed d
    # both sides agree to first order. Within a state the flow is affine (no truncation) and an event time moves by
    # O(step), so the difference is exact to O(step) (a step in N moves the cone: on one side the slider sticks for
    # a time O(step) with a force O(step) short of mu N, an O(step^2) change) + round-off eps / 1e-6 ~ 1e-10.
    # Measured up to 1.2e-6 of the largest entry (the normal column). Not compared: nodes 0 and 4, at the slip
    # reversals (the map has a kink there: one-sided derivatives differ, a central difference averages
    # them), and the d column of a slipping slider (a d off its cone is projected back by the integrator: a kink
    # too; its exact column is 0 in x and v, checked). 1e-5 allowed (a wrong saltation or a missed projection
    # gives 1e-2 .. 1).
    system = coulomb(MU, 1e7)
    r = start(system)
    f, T, D = r.freq_hz, 1.0 / r.freq_hz, np.abs(r.scale)
    sens = FlowSensitivity(system, [1.0, 0.0], P, f, r.phase_deg)
    scale = D[None, :] / D[:, None]
    Tz = np.eye(5)  # y = [x, z, vx, vz, w] -> [x, z, vx, vz, d = x - w] (its own inverse)
    Tz[4, 0], Tz[4, 4] = 1.0, -1.0
    worst = 0.0
    for k in (1, 2, 3, 5, 6, 7):
        y, t0, h = r.nodes[k], k * T / 8, T / 8
        end, Phi = sens.segment(y, t0, h)
        assert np.allclose(end, flow(system, [1.0, 0.0], P, f, y, t0, h, 1, r.phase_deg)[-1], rtol=0, atol=1e-12)
        Phi = Tz @ Phi @ Tz
        for j in range(4):
            dy = np.zeros(y.size)
            dy[j] = 1e-6 * D[j]
            dy[4] = dy[0]  # at a fixed stretch d = x - w
            col = (flow(system, [1.0, 0.0], P, f, y + dy, t0, h, 1, r.phase_deg)[-1]
                   - flow(system, [1.0, 0.0], P, f, y - dy, t0, h, 1, r.phase_deg)[-1]) / (2 * dy[j])
            col = Tz @ col
            err = np.max(np.abs((Phi[:, j] - col) * scale[:, j])) / np.max(np.abs(Phi * scale))
            worst = max(worst, err)
            assert err < 1e-5, (k, j, err)
        assert np.max(np.abs(Phi[:4, 4] * scale[:4, 4])) < 1e-9 * np.max(np.abs(Phi * scale))  # d acts on nothing
    print(f"worst {worst:.2e}")
