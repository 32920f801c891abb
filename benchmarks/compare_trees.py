"""Two results trees compared file by file: the science files must be byte-identical.

Used to show that a change of the code's structure changed no result (issue 23): run the main
job before and after into two folders, then

    python benchmarks/compare_trees.py BEFORE AFTER [--csv results/performance/tree_compare.csv]

Every file under either tree is compared by content. Files that hold run times or the run's
own provenance (``provenance.json``, ``*timing*``) are reported but not judged: they change with
machine load on every run. Exit status 1 if a science file differs, is missing on one side or
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
            status = "same" if a.stat().st_size == b.stat().st_size and _digest(a) == _digest(b) else "differs"
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
