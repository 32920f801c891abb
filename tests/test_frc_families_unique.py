"""The committed forced-response results list each exact family once.

A family switched onto at a branch point that a retraced parent passes twice used to be followed and
listed twice (session 12's rom-frc at 10 N: families 11 and 12 repeated 1 and 3, the same kind, period,
extent to 1e-9 Hz and amplitude to 1e-9 m). ``reduced.periodic.exact_frc._known`` now also shoots a
known family's point nearest a new first orbit (``NEAR_ORBIT_TOL``); this checks the files it wrote.
Two distinct families of one level may share a kind and period, but not their extent and their largest
amplitude to the digits written: that is one orbit set found twice.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results"
REL = 1e-7  # frequencies and amplitudes are written to 10 digits; a repeat agrees to ~1e-9 (above)


def _same(a: dict, b: dict) -> bool:
    if (a["level"], a["kind"], a["period_k"]) != (b["level"], b["kind"], b["period_k"]):
        return False
    keys = ("freq_min_hz", "freq_max_hz", "max_amplitude_m")
    return all(abs(float(a[k]) - float(b[k])) <= REL * abs(float(a[k])) for k in keys)


def repeats(rows: list[dict]) -> list[tuple[str, str, str]]:
    """(level, family, family it repeats) for every family listed again.

    Parameters
    ----------
    rows : frc_families.csv's rows

    Returns
    -------
    list of (level, family, earlier family)
    """
    out = []
    for i, b in enumerate(rows):
        for a in rows[:i]:
            if _same(a, b):
                out.append((b["level"], b["family"], a["family"]))
                break
    return out


@pytest.mark.parametrize("scene", ["discrete-frc", "rom-frc"])
def test_no_family_is_listed_twice(scene):
    with open(RESULTS / scene / "frc_families.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) > 10  # the families are there
    assert repeats(rows) == []


def test_the_check_finds_session_12s_repeats():
    """The rows of session 12's rom-frc at 10 N (families 1, 3 and their repeats 11, 12) are caught."""
    base = {"level": "10.0", "period_k": "1"}
    rows = [
        {**base, "family": "1", "kind": "asymmetric_half_wave", "freq_min_hz": "47.40099296",
         "freq_max_hz": "49.60157633", "max_amplitude_m": "0.0002871515885"},
        {**base, "family": "3", "kind": "half_wave_broken", "freq_min_hz": "46.10931794",
         "freq_max_hz": "49.02371516", "max_amplitude_m": "0.0002883461447"},
        {**base, "family": "11", "kind": "asymmetric_half_wave", "freq_min_hz": "47.40099296",
         "freq_max_hz": "49.60157634", "max_amplitude_m": "0.0002871515885"},
        {**base, "family": "12", "kind": "half_wave_broken", "freq_min_hz": "46.10931795",
         "freq_max_hz": "49.02371509", "max_amplitude_m": "0.0002883461444"},
    ]
    assert repeats(rows) == [("10.0", "11", "1"), ("10.0", "12", "3")]
