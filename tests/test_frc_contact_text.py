"""The level's statement about its contact band in frc.md (bearingshaft.stages.frc_contact): on a constructed
level whose answer is known by construction, which family covers which HB points in contact, and what the
verdicts and the response map found in the band no family from the HB curve reaches."""

from types import SimpleNamespace as NS

import numpy as np

from bearingshaft.stages.frc_contact import contact_statement, owners


def _family(kind, f, stable=False):
    f = np.asarray(f, float)
    return NS(kind=kind, freq_hz=f, segment=np.zeros(f.size, int), stable=np.full(f.size, stable),
              pieces=lambda: [np.arange(f.size)])


def _verdict(f, verdict, band, family=-1, defect=np.nan, segments=32):
    return NS(freq_hz=f, verdict=verdict, band_hz=band, family=family, defect=defect, segments=segments)


def _level():
    # contact HB points at 10..20 Hz (1 Hz apart); family 0 (main) holds 14-20 Hz, family 1 (asymmetric) 16-17 Hz
    # (inside 0's: credited to 0); the band 10-13 Hz was judged: an orbit at 11 Hz started family 2 (10.5-11.5 Hz),
    # 12 and 13 Hz no orbit (defects 0.02 and 0.004)
    band = (10.0, 13.0)
    fams = [_family("main", np.linspace(13.5, 20.5, 30), True), _family("asymmetric", [16.0, 17.0]),
            _family("isolated", [10.5, 11.0, 11.5])]
    verdicts = [_verdict(10.0, "not_judged", band, segments=0), _verdict(11.0, "orbit", band, 2, 1e-9),
                _verdict(12.0, "no_orbit", band, defect=0.02), _verdict(13.0, "no_orbit", band, defect=0.004)]
    ex = NS(cover_freqs_hz=np.arange(10.0, 21.0), families=fams, verdicts=verdicts, uncovered_bands=lambda: [])
    pts = [NS(regime="chaotic", period_k=0, contact=True)] * 4 + [NS(regime="periodic", period_k=1, contact=True)]
    lvl = NS(sweeps={"up": NS(freq_hz=np.array([10.0, 11.0, 12.0, 13.0, 14.0]), points=pts)})
    return ex, lvl


def test_owners_credit_the_lowest_numbered_family():
    ex, _ = _level()
    own = owners(ex.families, ex.cover_freqs_hz)
    # 10 Hz: in no family; 11 Hz: family 2 only; 12-13 Hz: none; 14-20 Hz: family 0 (family 1's 16-17 Hz inside it)
    assert own.tolist() == [-1, 2, -1, -1, 0, 0, 0, 0, 0, 0, 0]


def test_one_statement_names_families_verdicts_and_the_stepped_sine():
    ex, lvl = _level()
    text = contact_statement(ex, lvl, None, 4)
    assert text.startswith("Contact band (11 HB points in contact, 10-20 Hz): covered by family 0 (main) at 7 "
                           "points, 14-20 Hz. No family from the HB curve reaches 10-13 Hz (4 HB points): ")
    assert "family 1" not in text  # credited to family 0, not listed twice
    assert "judged by shooting at 3" in text
    assert "exact orbits that start family 2 (isolated, 10.5-11.5 Hz, unstable) at 11 Hz" in text
    # the best (smallest) defect of the two points with no orbit
    assert "no orbit of the exact flow near the HB points judged at 12, 13 Hz (best defect 0.004)" in text
    assert "covered now by a family: 1 of 4; by none: 10 Hz, 12-13 Hz" in text
    # the stepped sine counted over the band only (14 Hz is outside it)
    assert text.endswith("the stepped sine there (response_map.csv): chaotic at 4 (up).")


def test_every_point_covered_and_not_judged():
    ex, _ = _level()
    ex.verdicts = []
    ex.families[2] = _family("isolated", [9.0, 13.2])
    assert contact_statement(ex, None, None, 4) == ("Contact band (11 HB points in contact, 10-20 Hz): covered by "
                                                    "family 2 (isolated) at 4 points, 10-13 Hz; family 0 (main) at 7 "
                                                    "points, 14-20 Hz; every point is covered.")
    ex.families.pop()
    ex.uncovered_bands = lambda: [(10.0, 13.0, 4)]
    text = contact_statement(ex, None, None, 0)
    assert "reaches 10-13 Hz (4 HB points): not judged (`[frc] verdict_points = 0`); covered now by a family: 0 of 4" \
        in text


# -- the committed results ---------------------------------------------------------------------------------------
def _csv(path):
    import csv

    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_committed_results_every_map_frequency_in_one_band_and_one_statement_per_level():
    from pathlib import Path

    import pytest

    for scene in ("discrete-frc", "rom-frc"):
        root = Path(__file__).resolve().parents[1] / "results" / scene
        if not (root / "frc_regimes.csv").exists():
            pytest.skip(f"{scene}: no committed frc_regimes.csv")
        rows, bands = _csv(root / "response_map.csv"), _csv(root / "frc_regimes.csv")
        for key in {(r["level"], r["direction"]) for r in rows}:
            swept = [float(r["freq_hz"]) for r in rows if (r["level"], r["direction"]) == key]
            mine = [b for b in bands if (b["level"], b["direction"]) == key]
            # each frequency of the sweep (in sweep order) lies in exactly one band: the bands tile the sweep
            hits = [sum(min(float(b["freq_from_hz"]), float(b["freq_to_hz"])) <= f <=
                        max(float(b["freq_from_hz"]), float(b["freq_to_hz"])) for b in mine) for f in swept]
            assert sum(int(b["points"]) for b in mine) == len(swept), (scene, key)
            assert all(h == 1 for h in hits), (scene, key)
            assert float(mine[0]["freq_from_hz"]) == swept[0] and float(mine[-1]["freq_to_hz"]) == swept[-1]
        # one statement per level: every level with HB points in contact states its contact band once, and
        # each band judged (frc_cover.csv) is in that statement
        text = (root / "frc.md").read_text("utf-8")
        cover = _csv(root / "frc_cover.csv")
        assert "Uncovered band" not in text
        for level in {r["level"] for r in cover}:
            part = text.split(f"## {float(level):g} N")[1].split("\n## ")[0]
            assert part.count("Contact band (") == 1, (scene, level)
            for lo in {float(r["band_lo_hz"]) for r in cover if r["level"] == level}:
                assert f"reaches {lo:.5g}-" in part or f") {lo:.5g}-" in part, (scene, level, lo)
