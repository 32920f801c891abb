"""Exact friction orbits on a frequency grid (reduced/periodic/friction_sweep.py, issue 27): Newton at fixed
frequencies with the exact Jacobian, against Den Hartog's closed form."""

from __future__ import annotations

import numpy as np
from test_friction import K_X, M_X, coulomb, den_hartog
from test_friction_continuation import FN, MU, F, P, start

from reduced.periodic.friction_sweep import sweep_friction


def test_the_grid_follows_den_hartog():
    # Den Hartog's X(beta) (continuous slip, undamped) at every grid frequency beta = 0.62 .. 0.78 (step 0.04), each
    # orbit from the previous one (extrapolated): the Jenkins slider (kt = 1e10 N/m) differs from Den Hartog by
    # 1e-4 .. 2e-4 X (as the continuation's test), 3e-4 allowed; every orbit converged from the previous one, stable
    # (the undamped normal pair on the circle), defect <= 1e-10.
    s = coulomb(MU, 1e10)
    r = start(s, 0.6)
    sw = sweep_friction(r, 0.62 * FN, 0.785 * FN, 0.04 * FN, point_rows=np.array([[1.0, 0.0]]))
    assert len(sw.freq_hz) == 5 and np.all(sw.converged), (sw.freq_hz, sw.defect)
    assert np.all(sw.start == "previous") and np.max(sw.defect) < 1e-10 and np.all(sw.stable)
    assert np.all(np.abs(np.diff(sw.freq_hz) - 0.04 * FN) < 1e-12)
    X = np.array([den_hartog(P, F, K_X, M_X, f / FN)[0] for f in sw.freq_hz])
    err = np.abs(sw.amplitude_m[:, 0] / X - 1.0)
    assert np.max(err) < 3e-4, err


def test_a_sweep_without_orbits_near_its_starts_ends_after_max_fail():
    # From a start far from every orbit (the amplitude x 100) with no second start, Newton does not converge in its
    # steps; the sweep ends after 2 frequencies in a row (max_fail), the second twice as far as the step.
    s = coulomb(MU, 1e10)
    r = start(s, 0.6)
    bad = r.nodes * 100.0
    sw = sweep_friction(r, 0.62 * FN, 0.9 * FN, 0.02 * FN, first=bad, max_fail=2, max_iter=1)
    assert not np.any(sw.converged) and len(sw.freq_hz) == 2
    assert abs(sw.freq_hz[1] - sw.freq_hz[0] - 0.04 * FN) < 1e-12
