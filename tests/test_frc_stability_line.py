"""frc.md's stability line: Hill's method against the monodromy at the checked points, every disagreement named."""

from __future__ import annotations

import math

from bearingshaft.stages.frc_files import _stability_line
from bearingshaft.stages.frc_results import PointCheck


def _check(f, mono, hill=math.nan, shoot=math.nan):
    return PointCheck(0, True, not math.isnan(shoot), f, mono, mono <= 1.0, hill,
                      None if math.isnan(hill) else hill <= 1.0, shoot,
                      None if math.isnan(shoot) else shoot <= 1.0, None, "")


def test_the_line_counts_and_names_the_disagreements():
    checks = [_check(10.0, 0.79, 0.79, 0.79), _check(18.37, 399.0, 0.88, 3.1), _check(20.0, 1.5, 1.5 * 1.01),
              _check(30.0, 0.9)]
    line = _stability_line(checks, 15)
    assert "at 4 checked points" in line and "Hill's method at 3 gives the monodromy's verdict at 2" in line
    assert "within 0.001 (relative) of the monodromy's at 1" in line  # 20 Hz agrees in verdict, not in |mu|
    assert "18.37 Hz (Hill 0.88, monodromy 399)" in line and "20 Hz" not in line.split("differ at")[1]
    assert "Shooting found the exact orbit at 2 of them; its verdict differs from the HB monodromy's at 0" in line


def test_no_hill_no_line():
    assert _stability_line([_check(30.0, 0.9)], 15) == ""
