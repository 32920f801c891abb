"""The response map's part of the frc stage with friction (bearingshaft/stages/frc_friction_map.py): the files'
side only (no solver): the stretches of one regime frc.md lists, and the state the checks start from."""

from __future__ import annotations

from types import SimpleNamespace as N

import numpy as np

from bearingshaft.stages.frc_friction_map import markdown, state_at, stretches
from bearingshaft.stages.frc_results import MapLevel


def point(regime, period, lam, peak, settled=True):
    return N(regime=regime, period_k=period, lyapunov_per_s=lam, settled=settled,
             peak=np.array([[peak, 0.0], [2 * peak, 0.0]]), state=np.full(3, peak))


def sweep():
    pts = [point("periodic", 1, -1.0, 1e-5), point("periodic", 1, -0.5, 2e-5), point("chaotic", 0, 20.0, 1e-4),
           point("chaotic", 0, 30.0, 2e-4), point("subharmonic", 3, -0.1, 5e-5, settled=False)]
    f = np.array([10.0, 10.1, 10.2, 10.3, 10.4])
    return N(freq_hz=f, points=pts, jump_hz=np.array([10.2]), wall_s=np.ones(5))


def test_the_stretches_group_consecutive_frequencies_of_one_regime_with_their_exponents_and_envelope():
    got = stretches(sweep(), 0)
    assert [(a, b, lab) for a, b, lab, _, _ in got] == [
        (10.0, 10.1, "periodic"), (10.2, 10.3, "chaotic"), (10.4, 10.4, "subharmonic 3 (not settled)")]
    assert got[1][3].tolist() == [20.0, 30.0]
    assert got[1][4].tolist() == [[1e-4, 2e-4], [2e-4, 4e-4]]  # per-period max |x1| min and max at each


def test_the_checks_start_from_the_map_state_at_their_frequency_only():
    lvl = MapLevel(2.0, [(10.0, 10.4)], {"up": sweep(), "down": sweep()}, 1.0)
    pt, y = state_at(lvl, 10.3 + 1e-12)
    assert pt.regime == "chaotic" and y.tolist() == [2e-4] * 3
    assert state_at(lvl, 10.25) is None and state_at(None, 10.3) is None


def test_frc_md_lists_each_sweep_and_its_stretches():
    lvl = MapLevel(2.0, [(10.0, 10.4)], {"up": sweep()}, 1.0)
    spec = N(map_step_hz=0.1, map_coarse_points=12, map_periods=32)
    md = "\n".join(markdown(N(response_maps={2.0: lvl}, names=("x1", "x2"), scene=N(frc=spec))))
    assert "2 N, sweep up: 5 frequencies, 2 periodic, 1 subharmonic, 2 chaotic; jumps at 10.2 Hz" in md
    assert "10.2 -> 10.3 Hz: chaotic, exponent 20 .. 30 1/s, per-period max |x1| 0.0001 .. 0.0004 m" in md
    assert markdown(N(response_maps={}, names=("x1",), scene=N(frc=spec))) == []
