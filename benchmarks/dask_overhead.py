"""What Dask's own monitoring costs on the LocalCluster of ``bearingshaft run`` and ``sweep``: Dask's defaults
against :data:`bearingshaft.sweep.run.QUIET_CLUSTER`, interleaved, in child processes timed from outside.

    PYTHONPATH=. python benchmarks/dask_overhead.py [--idle 40] [--busy 300000] [--job SCENE ...]
        [--repeats 2] [--out /tmp/DIR]

Each variant runs as its own process; the CPU time of its process tree (client, scheduler, nannies, workers;
``os.wait4``) is the number compared, since wall time on a shared machine is noise:

- ``idle``: LocalCluster(2) started, each worker sleeping ``--idle`` s, closed: the monitoring alone;
- ``busy``: four tasks of fixed pure-Python work at a stack 40 frames deep (the statistical profiler's cost
  grows with the depth of the running task's stack);
- ``job``: ``bearingshaft run SCENE ... --out DIR --no-progress`` (the real stages on LocalCluster(2)); the files
  of the two variants are compared byte for byte (``TIMESTAMPED`` and ``*_timing*`` files, which hold times, left
  out): the configuration must not change a result.

Prints one line a run and the medians; writes ``dask_overhead.csv`` under ``--out``.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import write_rows  # noqa: E402

CHILD = r"""
import logging, sys, time
import dask
from distributed import Client, LocalCluster
import bearingshaft.sweep.run as run

def deep(d, n):
    if d:
        return deep(d - 1, n)
    s = 0.0
    for i in range(n):
        s += i * 1e-9
    return s

def work(n):
    for _ in range(20):
        deep(40, n)
    return n

variant, what, arg = sys.argv[1], sys.argv[2], sys.argv[3]
if variant == "default":
    run.QUIET_CLUSTER.clear()
if what == "job":
    from bearingshaft.cli import main
    sys.exit(main(["run", *sys.argv[4:], "--out", arg, "--no-progress"]))
with run.dask_client(workers=2) as (client, _):
    if what == "idle":
        client.gather([client.submit(time.sleep, float(arg), pure=False) for _ in range(2)])
    else:
        client.gather([client.submit(work, int(arg), pure=False) for _ in range(4)])
"""


def tree(argv: list[str], log: Path) -> tuple[float, float, int]:
    """(wall s, CPU s of the process tree, exit code) of ``argv`` run from the checkout, its output in ``log``."""
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open(log, "wb") as fh:
        proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime, os.waitstatus_to_exitcode(status)


# files that hold the time they were written: provenance.json, the report (its run's folder and time) and rom.npz
# (the model with its provenance, in a zip whose members are stamped; git ignores it)
TIMESTAMPED = ("provenance.json", "reproduction.md", "rom.npz")


def differing(a: Path, b: Path) -> list[str]:
    """Files of two runs that differ or exist in one only (:data:`TIMESTAMPED` and timing files left out)."""
    names = {p.relative_to(a) for p in a.rglob("*") if p.is_file()} | \
            {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    names = {n for n in names if n.name not in TIMESTAMPED and "_timing" not in n.name}
    return [str(n) for n in sorted(names) if not ((a / n).is_file() and (b / n).is_file()
                                                   and filecmp.cmp(a / n, b / n, shallow=False))]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--idle", type=float, default=40.0, help="s each worker sleeps (0: skip)")
    ap.add_argument("--busy", type=int, default=300000, help="work of each busy task (0: skip)")
    ap.add_argument("--job", nargs="*", default=[], help="scenes of a real run on LocalCluster(2)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="dask_overhead-") as tmp:
        cases = ([("idle", str(args.idle))] if args.idle else []) + ([("busy", str(args.busy))] if args.busy else [])
        cases += [("job", "")] if args.job else []
        for what, arg in cases:
            for rep in range(args.repeats):
                for variant in ("default", "quiet"):
                    folder = Path(tmp) / f"{variant}-{rep}"
                    extra = [str(folder), *args.job] if what == "job" else [arg]
                    load = os.getloadavg()[0]
                    log = Path(tmp) / f"{what}-{variant}-{rep}.log"
                    wall, cpu, code = tree([sys.executable, "-c", CHILD, variant, what, *extra], log)
                    row = {"what": what, "variant": variant, "repeat": rep, "wall_s": round(wall, 2),
                           "cpu_s": round(cpu, 2), "exit_code": code, "load_1min": round(load, 2)}
                    if what == "job":  # the run's own check against the committed results/
                        row["reproduction"] = next((line for line in log.read_text().splitlines()
                                                    if line.startswith("reproduction:")), "")
                    if what == "job" and variant == "quiet":
                        row["files_differing"] = len(differing(Path(tmp) / f"default-{rep}", folder))
                    print(row, flush=True)
                    rows.append(row)
            for variant in ("default", "quiet"):
                cpu = [r["cpu_s"] for r in rows if r["what"] == what and r["variant"] == variant]
                print(f"{what} {variant}: median CPU {statistics.median(cpu):.2f} s over {len(cpu)}", flush=True)
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        write_rows(Path(args.out) / "dask_overhead.csv", rows)
    return 0 if all(r["exit_code"] in (0,) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
