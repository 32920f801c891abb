"""Two results trees compared file by file: the science files must be byte-identical.

Used to show that a change of the code's structure changed no result (issue 23): run the main
job before and after into two folders, then

    python benchmarks/compare_trees.py BEFORE AFTER [--csv results/performance/tree_compare.csv]

Every file under either tree is compared by content. Files that hold run times or the run's
own provenance (``provenance.json``, ``*timing*``) are reported but not judged: they change with
machine load on every run. An ``.npz`` archive is compared array by array, and the JSON it
carries (``rom.npz``'s ``info_json``) without its run records (times, dates, commit, source
hash). Exit status 1 if a science file differs, is missing on one side or
is extra on the other; 0 otherwise.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import sys
from pathlib import Path

NOT_JUDGED = ("provenance.json",)  # the run's commit, date and wall times
NOT_JUDGED_PARTS = ("timing",)  # study_timing.md, *_timing.csv: wall-clock times
RUN_RECORD_KEYS = ("time", "timing", "wall", "utc", "commit", "hash", "created")  # in a JSON key: a record of the run
# (and keys ending in _s: durations in seconds)


def _without_run_records(obj):
    """A JSON value with the keys that record the run (times, dates, commit, source hash) dropped.

    >>> _without_run_records({"n": 10, "static_s": 1.2, "provenance": {"git_commit": "abc"}, "k": [{"timing": 3}]})
    {'n': 10, 'provenance': {}, 'k': [{}]}
    """
    if isinstance(obj, dict):
        return {k: _without_run_records(v) for k, v in obj.items()
                if not (k.lower().endswith("_s") or any(r in k.lower() for r in RUN_RECORD_KEYS))}
    if isinstance(obj, list):
        return [_without_run_records(v) for v in obj]
    return obj


def _same_npz(a: Path, b: Path) -> bool:
    """Same arrays (bit for bit, NaN equal to NaN) and the same JSON less its run records."""
    import json

    import numpy as np

    with np.load(a, allow_pickle=False) as x, np.load(b, allow_pickle=False) as y:
        if sorted(x.files) != sorted(y.files):
            return False
        for k in x.files:
            u, v = x[k], y[k]
            if k.endswith("_json"):
                if _without_run_records(json.loads(str(u))) != _without_run_records(json.loads(str(v))):
                    return False
            elif u.dtype != v.dtype or u.shape != v.shape or u.tobytes() != v.tobytes():
                return False
    return True


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def judged(rel: str) -> bool:
    """Whether a file is a science file (compared byte for byte) rather than a record of the run.

    >>> judged("discrete-fep/fep.csv"), judged("a/provenance.json"), judged("x/study_timing.md")
    (True, False, False)
    """
    name = rel.rsplit("/", 1)[-1]
    return name not in NOT_JUDGED and not any(p in name for p in NOT_JUDGED_PARTS)


def compare(before: Path, after: Path) -> list[dict]:
    """One row per file of either tree: ``file``, ``status`` (same, differs, missing, extra) and ``judged``."""
    files = sorted({p.relative_to(before).as_posix() for p in before.rglob("*") if p.is_file()}
                   | {p.relative_to(after).as_posix() for p in after.rglob("*") if p.is_file()})
    rows = []
    for rel in files:
        a, b = before / rel, after / rel
        if not b.exists():
            status = "missing"
        elif not a.exists():
            status = "extra"
        else:
            same = a.stat().st_size == b.stat().st_size and _digest(a) == _digest(b)
            if not same and a.suffix == ".npz":
                same = _same_npz(a, b)
            status = "same" if same else "differs"
        rows.append({"file": rel, "status": status, "judged": judged(rel)})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--csv", type=Path, help="write every file's row here")
    args = ap.parse_args(argv)
    rows = compare(args.before, args.after)
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=["file", "status", "judged"])
            w.writeheader()
            w.writerows(rows)
    bad = [r for r in rows if r["judged"] and r["status"] != "same"]
    same = sum(r["status"] == "same" for r in rows if r["judged"])
    for r in bad:
        print(f"{r['status']:8s} {r['file']}")
    print(f"{same} science files byte-identical, {len(bad)} not; "
          f"{sum(not r['judged'] for r in rows)} run records (provenance, timings) not judged")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
