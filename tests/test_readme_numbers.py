"""The README's numbers that come from results, checked against the files they come from (issue 24).

Each claim is a pattern in README.md with named groups and the function that computes what those
groups must say from the committed results (or the code: stage counts, disk use). A stale number fails
its test with the file it comes from; ``python tests/test_readme_numbers.py --write`` rewrites every
claim from the results, for after they are regenerated. Numbers that no file records (test counts,
the suite's run time) are not in the README.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "results"


def _rows(path: str) -> list[dict]:
    with open(RESULTS / path, newline="") as fh:
        return list(csv.DictReader(fh))


def _main_job() -> dict[tuple[str, str], float]:
    return {(r["scene"], r["stage"]): float(r["wall_s"]) for r in _rows("performance/main_job.csv")}


def _scene_wall(scene: str) -> str:
    return f"{max(w for (s, _), w in _main_job().items() if s == scene):.0f}"


LONGEST = ("rom-fep", "rom-frc", "discrete-frc", "discrete-symmetric", "hammer-test", "discrete-fep", "hammer-friction")


def _stage_counts() -> dict[str, str]:
    from bearingshaft.registry import stages_of
    from bearingshaft.scenes import builtin_names, load_scene

    names = builtin_names()
    return {"stages": str(sum(len(stages_of(load_scene(n))) for n in names)), "scenes": str(len(names))}


def _main_job_total() -> dict[str, str]:
    job = _main_job()
    assert len(job) == int(_stage_counts()["stages"]), "main_job.csv does not time every stage of the main job"
    return {"minutes": f"{sum(job.values()) / 60:.1f}"}


def _main_job_wall() -> dict[str, str]:
    (row,) = _rows("performance/main_job_wall.csv")
    assert row["stages"] == _stage_counts()["stages"], "main_job_wall.csv is not of the whole main job"
    return {"minutes": f"{float(row['wall_s']) / 60:.1f}"}


def _others() -> dict[str, str]:
    rest = [w for (s, st), w in _main_job().items() if s not in LONGEST]
    return {"lo": f"{min(rest):.0f}", "hi": f"{max(rest):.0f}"}


def _hammer() -> dict[str, str]:
    stats = json.loads((RESULTS / "discrete-hammer/provenance.json").read_text())["stages"]["ringdown"]["stats"]
    return {"work": f"{stats['work_of_loads_J_max']:.3g}", "events": str(stats["n_events"]),
            "balance": f"{stats['energy_balance_error']:.2g}"}


def _table2() -> dict[str, str]:
    return {"pct": f"{max(abs(float(r['error_pct'])) for r in _rows('assembly-modal/frequencies.csv')):.2f}"}


def _suite() -> dict[str, str]:
    """The suite's test count, wall and CPU seconds and verdict, as job_times.py recorded them."""
    row = next(r for r in _rows("performance/job_headline.csv") if r["what"].startswith("test suite"))
    machine = {r["key"]: r["value"] for r in _rows("performance/job_machine.csv")}
    cpu = re.search(r"CPU ([\d.]+) s", machine["suite ours"])[1]
    return {"passed": re.search(r"\((\d+) passed", row["what"])[1], "wall": f"{float(row['ours_s']):.0f}",
            "cpu": f"{float(cpu):.0f}", "met": "met" if row["met"] == "True" else "not met"}


def _modal_speed() -> dict[str, str]:
    wall, cpu = _rows("performance/modal_headline.csv")[:2]
    dofs = re.search(r"([\d,]+) DOFs", wall["what"])[1]
    return {"dofs": dofs, "ours": f"{float(wall['ours_s']):.1f}", "ratio": f"{float(wall['ratio']):.1f}",
            "cpu": f"{float(cpu['ratio']):.1f}", "base": f"{float(wall['baseline_s']):.1f}"}


def _long_disk() -> dict[str, str]:
    from reduced.transient.integrate import ringdown_disk_bytes

    return {"gb": f"{ringdown_disk_bytes(3, 1e4, 20000.0) / 1e9:.1f}"}


def _case_disk() -> dict[str, str]:
    from reduced.transient.integrate import ringdown_disk_bytes

    case = ringdown_disk_bytes(3, 4.0, 5000.0)  # sweep-gap-kg: 4 s at 5 kHz
    return {"mb": f"{case / 1e6:.1f}", "gb": f"{55_000 * case / 1e9:.0f}"}  # 55 000 cases an hour (README)


def _eq13() -> dict[str, str]:
    first = _rows("discrete-fep/nnm2_check.csv")[0]  # just above grazing
    return {"pct": f"{100 * float(first['rel_err_paper']):.1f}"}


def _sweep_cases(scene: str) -> dict[str, str]:
    rows = _rows(f"{scene}/sweep/sweep.csv")
    return {"cases": str(len(rows))}


def _late_freqs() -> dict[str, str]:
    late = [float(r["freq_late_hz"]) for r in _rows("sweep-gap-kg/sweep/sweep.csv")]
    nnm1 = [f for f in late if abs(f - 17.98) < 0.5]  # the two open-gap modes, 17.98 and 25.43 Hz
    nnm2 = [f for f in late if abs(f - 25.43) < 0.5]
    assert len(nnm1) + len(nnm2) == len(late), "a late frequency that is neither open-gap mode"
    return {"n1": str(len(nnm1)), "n2": str(len(nnm2))}


@dataclass(frozen=True)
class Claim:
    """A README pattern whose named groups must read what ``source()`` computes."""

    name: str
    pattern: str
    source: Callable[[], dict[str, str]]


CLAIMS = [
    Claim("main job size", r"It runs the (?P<stages>\d+) stages of the (?P<scenes>\d+) built-in scenes", _stage_counts),
    Claim("main job time", r"stages' own times sum to\s+(?P<minutes>[\d.]+) min on the 2-core machine",
          _main_job_total),
    Claim("main job wall", r"on Dask, (?P<minutes>[\d.]+) min of wall time", _main_job_wall),
    *[Claim(f"{scene} wall time", rf"\| `{scene}` [^|\n]*\| (?P<s>\d+) s \|",
            lambda scene=scene: {"s": _scene_wall(scene)}) for scene in LONGEST],
    Claim("apparatus reduction", r"its apparatus reduction takes another (?P<s>\d+) s",
          lambda: {"s": f"{_main_job()[('hammer-test', 'reduce')]:.0f}"}),
    Claim("other stages", r"Every other stage takes (?P<lo>\d+)-(?P<hi>\d+) s", _others),
    Claim("discrete-hammer", r"puts (?P<work>[\d.]+) J into the model, (?P<events>\d+) contact events follow in the "
          r"1 s\s+run, and the balance holds to (?P<balance>[\d.e+-]+) of the largest energy", _hammer),
    Claim("suite time", r"The default suite \((?P<passed>\d+) tests passed, [^)]*\) took (?P<wall>\d+) s "
          r"\((?P<cpu>\d+) s of CPU\) on a quiet 2-core machine: the 4-minute target is (?P<met>met|not met)", _suite),
    Claim("Table 2", r"Calibrated defaults put all six modes within (?P<pct>[\d.]+) % of\s+Table 2", _table2),
    Claim("modal speed", r"(?P<dofs>[\d,]+) DOFs, 16 modes, in (?P<ours>[\d.]+) s on a (?:quiet|loaded)"
          r"\s+2-core machine[^,]*, "
          r"(?P<ratio>[\d.]+)x faster \((?P<cpu>[\d.]+)x in CPU time\)[^(]*\((?P<base>[\d.]+) s;", _modal_speed),
    Claim("long ringdown disk", r"(?P<gb>[\d.]+) GB at 20 kHz for\s+1e4 s", _long_disk),
    Claim("sweep case disk", r"a `sweep-gap-kg` case writes\s+(?P<mb>[\d.]+) MB \(`ringdown.npz` at 5 kHz for 4 s\), "
          r"(?P<gb>\d+) GB an hour on one node", _case_disk),
    Claim("Eq. 13", r"grazing limit: (?P<pct>[\d.]+) % too high a frequency just above grazing", _eq13),
    Claim("sweep-gap-kg cases", r"\| `sweep-gap-kg` \| (?P<cases>\d+) \|", lambda: _sweep_cases("sweep-gap-kg")),
    Claim("sweep-energy cases", r"\| `sweep-energy` \| (?P<cases>\d+) \|", lambda: _sweep_cases("sweep-energy")),
    Claim("late frequencies", r"17\.98 Hz \(NNM 1, (?P<n1>\d+) cases\) or 25\.43 Hz \(NNM 2, (?P<n2>\d+)\)",
          _late_freqs),
]


def _check(claim: Claim, text: str) -> list[str]:
    """What differs: '<group>: README says X, <source> gives Y' lines."""
    m = re.search(claim.pattern, text)
    assert m, f"{claim.name}: the README no longer has {claim.pattern!r}; update the claim or the README"
    want = claim.source()
    return [f"{g}: README says {m[g]}, the results give {v}" for g, v in want.items() if m[g] != v]


@pytest.mark.parametrize("claim", CLAIMS, ids=[c.name for c in CLAIMS])
def test_readme_number_matches_its_results(claim):
    wrong = _check(claim, README.read_text())
    assert not wrong, (f"{claim.name}: " + "; ".join(wrong)
                       + " (python tests/test_readme_numbers.py --write updates the README)")


def test_no_unrecorded_counts():
    """The README states no number that no file records: the test count and the suite's time go stale."""
    text = README.read_text()
    assert not re.search(r"\(\d+ tests\)", text)


def write() -> int:
    """Rewrite every claim's numbers in README.md from the results; the number of claims changed."""
    text = README.read_text()
    changed = 0
    for claim in CLAIMS:
        m = re.search(claim.pattern, text)
        if m is None:
            print(f"not found: {claim.name}", file=sys.stderr)
            continue
        want = claim.source()
        spans = sorted(((m.span(g), v) for g, v in want.items()), reverse=True)
        new = m[0]
        for (a, b), v in spans:
            new = new[: a - m.start()] + v + new[b - m.start():]
        if new != m[0]:
            text = text[: m.start()] + new + text[m.end():]
            changed += 1
    README.write_text(text)
    return changed


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/test_readme_numbers.py --write")
    print(f"{write()} claims rewritten in {README}")
