"""The two jobs a user runs, timed whole: the main job (``bearingshaft run``) on Dask against the same
job one stage after the other, and the test suite (the README's ``python -m pytest``) against the
same suite in one process.

    PYTHONPATH=. python benchmarks/job_times.py [--what job suite] [--no-baseline] [--cold] [--runs 1]
        [--out results/performance]

With ``--runs`` N (odd) ours runs N times, one after the other, and each row is that of the run with the median
wall time, all N walls and CPU times in its ``what`` (this machine's cores switch between two speed states,
benchmarks/machine_speed.py, so one run is one draw).

Each command runs as a child process, timed from outside (wall time around it, CPU time and peak
resident memory of its process tree from ``os.wait4``), in this order: ours, then the baseline, in
the same session, so the load is alike (the 1-minute load average at each start is recorded):

- main job: ``bearingshaft run --out TMP --no-progress`` (a LocalCluster of one worker per core)
  against ``... --workers 1`` (every stage in order in one process, the behaviour before issue 28);
  the files of the two runs are compared byte for byte (``provenance.json`` holds finishing times
  and is left out): the speed-up must not change a file. Both use the user's reduced-model cache
  unless ``--cold`` gives each its own empty one (a fresh clone: the reductions are built); after a change to the
  code that builds them (its source hash keys the cache) fill it first with ``benchmarks/warm_cache.py``;
- suite: ``python -m pytest`` (pytest-xdist, ``-n auto --dist loadfile`` from pyproject.toml)
  against ``python -m pytest -n 0``; the 15 slowest tests of ours are listed.

Writes ``job_headline.csv`` (the rows of the performance table, targets of issue 28: main job under
6 min, suite under 4 min, on 2 cores), ``job_machine.csv``, ``job_durations.csv`` and, from the main job's own
stage lines (:func:`main_job_cost.from_log`), ``main_job.csv`` and ``main_job_wall.csv``.
"""

from __future__ import annotations

import argparse
import csv
import filecmp
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import write_rows  # noqa: E402

JOB_TARGET_S, SUITE_TARGET_S = 360.0, 240.0
CLI = [sys.executable, "-m", "bearingshaft.cli"]


def timed(argv: list[str], log: Path, env: dict | None = None) -> dict:
    """Run ``argv`` from the checkout: wall s, CPU s and peak MB of its process tree, exit code, load, and the
    fraction of the run the host's cores spent in their fast state (``host_fast``, sampled every 2 s by
    ``benchmarks/machine_speed.py --watch`` beside it, ~0.4 % of the CPU; its own CPU is not counted)."""
    load = os.getloadavg()[0]
    states = log.with_suffix(".states.csv")
    watch = subprocess.Popen([sys.executable, str(ROOT / "benchmarks" / "machine_speed.py"), "--watch", str(states)],
                             cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    t0 = time.perf_counter()
    with open(log, "wb") as fh:
        proc = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    watch.terminate()
    watch.wait()
    from machine_speed import watched_fast_fraction

    fast, samples = watched_fast_fraction(states)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "peak_mb": usage.ru_maxrss / 1024.0,
            "exit_code": proc.returncode, "load_1min": load, "host_fast": fast, "host_samples": samples}


def same_files(a: Path, b: Path) -> tuple[int, list[str]]:
    """(files compared, those that differ or exist in one run only), provenance.json left out."""
    names = {p.relative_to(a) for p in a.rglob("*") if p.is_file()} | \
            {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    names = {n for n in names if n.name != "provenance.json"}
    differ = [str(n) for n in sorted(names) if not ((a / n).is_file() and (b / n).is_file()
                                                      and filecmp.cmp(a / n, b / n, shallow=False))]
    return len(names), differ


def median_run(rows: list[dict]) -> tuple[dict, str]:
    """The run of ``rows`` (labels ``ours``, ``ours-2``, ...) with the median wall time, and a text of all of
    them (an odd number; the machine's cores switch between two speed states, benchmarks/machine_speed.py).

    Parameters
    ----------
    rows : list of dict
        Runs of :func:`timed` with a ``label``.

    Returns
    -------
    tuple of (dict, str)
    """
    mine = sorted((r for r in rows if r["label"].startswith("ours")), key=lambda r: r["wall_s"])
    mid = mine[len(mine) // 2]
    if len(mine) == 1:
        return mid, ""
    walls = ", ".join(f"{r['wall_s']:.0f}" for r in rows if r["label"].startswith("ours"))
    cpus = ", ".join(f"{r['cpu_s']:.0f}" for r in rows if r["label"].startswith("ours"))
    fast = ", ".join(f"{100 * r['host_fast']:.0f}" for r in rows if r["label"].startswith("ours") and "host_fast" in r)
    fast = f"; host's fast state % {fast}" if fast else ""
    return mid, f"; the median of {len(mine)} runs one after the other (wall s {walls}; CPU s {cpus}{fast})"


def _labels(runs: int) -> list[str]:
    return ["ours"] + [f"ours-{k}" for k in range(2, runs + 1)]


def main_job(work: Path, baseline: bool, cold: bool, out: Path | None = None, runs: int = 1) -> list[dict]:
    rows = []
    todo = [(label, []) for label in _labels(runs)] + ([("baseline", ["--workers", "1"])] if baseline else [])
    for label, extra in todo:
        env = dict(os.environ)
        if cold:
            env["BEARINGSHAFT_CACHE"] = str(work / f"cache-{label}")
        r = timed([*CLI, "run", "--out", str(work / label), "--no-progress", *extra], work / f"job-{label}.log", env)
        print(f"main job, {label}: {r['wall_s']:.0f} s wall, {r['cpu_s']:.0f} s CPU, exit {r['exit_code']}, "
              f"load {r['load_1min']:.2f}, host fast {100 * r['host_fast']:.0f} %", flush=True)
        rows.append({"label": label, **r})
    ours, several = median_run(rows)
    log = work / f"job-{ours['label']}.log"
    if ours["exit_code"] == 0 and out is not None:  # each stage's own wall time, read from the run's lines
        from main_job_cost import from_log

        from_log(log, out)
    total = re.search(r"run: (\d+) stages of (\d+) scenes", log.read_text())
    what = (f"main job, bearingshaft run ({total[1]} stages of {total[2]} scenes"
            f"{', reductions built' if cold else ', reductions and full 3-D reference modes cached'}), "
            f"on a LocalCluster of one worker per core{several}"
            if total else f"main job, bearingshaft run{several}")
    ok = all(r["exit_code"] == 0 for r in rows if r["label"].startswith("ours"))
    row = {"what": what, "ours_s": round(ours["wall_s"], 1), "target": f"<= {JOB_TARGET_S:.0f} s",
           "met": ok and ours["wall_s"] <= JOB_TARGET_S}
    if baseline:
        base = rows[-1]
        n, differ = same_files(work / "ours", work / "baseline")
        row.update(baseline="bearingshaft run --workers 1 (every stage in order, one process), same session",
                   baseline_s=round(base["wall_s"], 1), ratio=round(base["wall_s"] / ours["wall_s"], 2),
                   error=(f"{n - len(differ)} of {n} files identical to the in-order run"
                          + (f"; differ: {', '.join(differ[:5])}" if differ else "")))
    return [row, {"what": "main job, CPU seconds of the process tree", "ours_s": round(ours["cpu_s"], 1),
                  **({"baseline": "the same, --workers 1", "baseline_s": round(rows[-1]["cpu_s"], 1),
                      "ratio": round(rows[-1]["cpu_s"] / ours["cpu_s"], 2)} if baseline else {})}], rows


def suite(work: Path, baseline: bool, durations_path: Path, runs: int = 1) -> list[dict]:
    rows = []
    todo = [(label, ["--durations=15"]) for label in _labels(runs)] + ([("baseline", ["-n", "0"])] if baseline
                                                                       else [])
    for label, extra in todo:
        r = timed([sys.executable, "-m", "pytest", "-q", *extra], work / f"suite-{label}.log")
        print(f"suite, {label}: {r['wall_s']:.0f} s wall, {r['cpu_s']:.0f} s CPU, exit {r['exit_code']}, "
              f"load {r['load_1min']:.2f}, host fast {100 * r['host_fast']:.0f} %", flush=True)
        rows.append({"label": label, **r})
    ours, several = median_run(rows)
    log = (work / f"suite-{ours['label']}.log").read_text(errors="replace")
    slow = [{"seconds": float(m[1]), "phase": m[2], "test": m[3]}
            for m in re.finditer(r"^([\d.]+)s (call|setup|teardown)\s+(\S+)", log, re.M)]
    write_rows(durations_path, slow)
    passed = re.search(r"(\d+) passed", log)
    ok = all(r["exit_code"] == 0 for r in rows if r["label"].startswith("ours"))
    row = {"what": f"test suite, python -m pytest ({passed[1] if passed else '?'} passed; pytest-xdist, "
                   f"-n auto --dist loadfile){several}", "ours_s": round(ours["wall_s"], 1),
           "target": f"<= {SUITE_TARGET_S:.0f} s", "met": ok and ours["wall_s"] <= SUITE_TARGET_S}
    if baseline:
        base = rows[-1]
        row.update(baseline="python -m pytest -n 0 (one process), same session", baseline_s=round(base["wall_s"], 1),
                   ratio=round(base["wall_s"] / ours["wall_s"], 2))
    return [row], rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--what", nargs="+", choices=("job", "suite"), default=["job", "suite"])
    ap.add_argument("--no-baseline", action="store_true", help="time ours only")
    ap.add_argument("--cold", action="store_true", help="main job: each run with its own empty model cache")
    ap.add_argument("--runs", type=int, default=1,
                    help="runs of ours, one after the other; the row is the median run's (odd)")
    ap.add_argument("--out", default=str(ROOT / "results" / "performance"))
    args = ap.parse_args(argv)
    if args.runs < 1 or args.runs % 2 == 0:
        ap.error("--runs must be odd and >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    headline, raw = [], []
    with tempfile.TemporaryDirectory(prefix="job_times-") as tmp:
        work = Path(tmp)
        if "job" in args.what:
            h, r = main_job(work, not args.no_baseline, args.cold, out, args.runs)
            headline += h
            raw += [{"job": "main job", **x} for x in r]
        if "suite" in args.what:
            h, r = suite(work, not args.no_baseline, out / "job_durations.csv", args.runs)
            headline += h
            raw += [{"job": "suite", **x} for x in r]
    previous = []
    if (out / "job_headline.csv").exists():  # keep the rows of the job not measured now
        with open(out / "job_headline.csv", newline="") as f:
            kept = ("main job",) if "job" not in args.what else ("test suite",) if "suite" not in args.what else ()
            previous = [r for r in csv.DictReader(f) if r["what"].startswith(kept)] if kept else []
    fields = ["what", "ours_s", "baseline", "baseline_s", "ratio", "error", "target", "met"]
    write_rows(out / "job_headline.csv", [{k: r.get(k, "") for k in fields} for r in previous + headline])
    import platform

    machine = [{"key": "cpu", "value": platform.processor() or platform.machine()},
               {"key": "cores", "value": len(os.sched_getaffinity(0))},
               {"key": "python", "value": platform.python_version()},
               {"key": "git_commit", "value": subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT,
                                                             capture_output=True, text=True).stdout.strip()},
               {"key": "date_utc", "value": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}]
    machine += [{"key": f"{r['job']} {r['label']}",
                 "value": f"wall {r['wall_s']:.1f} s, CPU {r['cpu_s']:.1f} s, peak {r['peak_mb']:.0f} MB, "
                          f"load {r['load_1min']:.2f}, exit {r['exit_code']}, host fast "
                          f"{100 * r['host_fast']:.0f} % of {r['host_samples']} samples"} for r in raw]
    if (out / "job_machine.csv").exists():  # keep the run lines of the job not measured now
        with open(out / "job_machine.csv", newline="") as f:
            gone = ("main job",) if "job" in args.what else ()
            gone += ("suite",) if "suite" in args.what else ()
            machine += [r for r in csv.DictReader(f) if r["key"].startswith(("main job", "suite"))
                        and not r["key"].startswith(gone)]
    write_rows(out / "job_machine.csv", machine)
    return 0 if all(r["exit_code"] == 0 for r in raw) else 1


if __name__ == "__main__":
    raise SystemExit(main())
