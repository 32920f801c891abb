"""Memory estimates against measured peaks: every stage of every built-in scene, and the whole job.

    PYTHONPATH=. python benchmarks/memory_estimates.py [--scenes NAME ...] [--out results/memory]
        [--no-job] [--reestimate]

**Stages.** Every stage of every built-in scene (or of ``--scenes``) is run in the order
``bearingshaft run`` runs them, each in its own process
``python -m bearingshaft.cli STAGE --scene NAME --out TMP/NAME --no-progress``, so that its peak
is its own: the peak resident set size of that process (``ru_maxrss`` from ``os.wait4``, what
``/usr/bin/time -v`` calls "Maximum resident set size"), beside the stage's estimate
(:func:`bearingshaft.budget.stage_bytes`, counted from the scene alone). A stage that compiled
numba kernels (the cache files next to the sources grew) is run a second time, warm: the row
keeps the warm peak, and ``compiling_peak_bytes`` the first (a fresh clone pays it once).

**Baseline.** A process that only imports what the stages import (numpy, scipy, numba,
matplotlib, gmsh, scikit-fem, pyvista and the package): every peak includes it, so every
estimate does (:data:`bearingshaft.estimates.BASELINE_BYTES`).

**Whole job.** Then (unless ``--no-job``) the same stages run one after another in one process,
as ``bearingshaft run`` runs them: before each stage the process's peak is reset
(``/proc/self/clear_refs``, Linux), after it the stage's peak in the job (``VmHWM``) and what it
left resident (``VmRSS``) are read. The job's peak is compared with
:func:`bearingshaft.budget.job_bytes`.

Writes, in ``--out``: ``estimates.csv`` (scene, stage, estimate_bytes, peak_bytes, ratio =
estimate / peak, compiling_peak_bytes, wall_s, exit_code), ``baseline.csv``, ``job.csv`` (per stage:
rss_before_bytes, peak_in_job_bytes, rss_after_bytes, alone_peak_bytes), ``job_summary.csv`` and
``estimates.png``. ``--reestimate`` recomputes the estimate columns of the CSV files already
written (after a change of an estimate) without running anything.

Measured on the 2-core machine: the stage pass takes about as long as the main job (13-20 min,
more under load), the job pass as long again.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.budget import job_bytes, stage_bytes  # noqa: E402
from bearingshaft.registry import stages_of  # noqa: E402
from bearingshaft.scenes import builtin_names, load_scene  # noqa: E402

FIELDS = ["scene", "stage", "estimate_bytes", "peak_bytes", "ratio", "compiling_peak_bytes", "wall_s", "exit_code"]
JOB_FIELDS = ["scene", "stage", "rss_before_bytes", "peak_in_job_bytes", "rss_after_bytes", "alone_peak_bytes",
              "estimate_bytes"]
BASELINE_IMPORTS = ("numpy", "scipy.sparse.linalg", "scipy.linalg", "numba", "matplotlib.pyplot", "gmsh", "skfem",
                    "pyvista", "bearingshaft.cli")
RATIO_MAX = 1.3  # the bound: estimate / peak in [1, RATIO_MAX]


def numba_cache_files() -> int:
    """numba's cache index files next to the sources (they grow when a stage compiles a kernel)."""
    return sum(1 for d in ("reduced", "bearingshaft", "fem") for _ in (ROOT / d).rglob("*.nbi"))


def child_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["MPLBACKEND"] = "Agg"
    return env


def run_measured(argv: list[str], log: Path) -> tuple[int, float, int]:
    """Run ``argv`` to completion in ROOT: (peak RSS bytes of it and its children, wall s, exit code)."""
    t0 = time.perf_counter()
    with open(log, "wb") as fh:
        proc = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, env=child_env(), cwd=ROOT)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: keep Popen from waiting again
    return usage.ru_maxrss * 1024, time.perf_counter() - t0, proc.returncode  # ru_maxrss: KiB on Linux


def measure_baseline(tmp: Path) -> dict:
    code = "import importlib\nfor m in %r: importlib.import_module(m)" % (BASELINE_IMPORTS,)
    peak, wall, rc = run_measured([sys.executable, "-c", code], tmp / "baseline.log")
    return {"what": "imports: " + " ".join(BASELINE_IMPORTS), "peak_bytes": peak, "wall_s": round(wall, 1),
            "exit_code": rc}


def measure_stages(names: list[str], tmp: Path) -> list[dict]:
    rows = []
    for name in names:
        scene = load_scene(name)
        for stage in stages_of(scene):
            argv = [sys.executable, "-m", "bearingshaft.cli", stage, "--scene", name, "--out", str(tmp / name),
                    "--no-progress"]
            log = tmp / f"{name}.{stage}.log"
            before = numba_cache_files()
            peak, wall, rc = run_measured(argv, log)
            compiling = ""
            if rc == 0 and numba_cache_files() > before:  # it compiled kernels: measure it warm as well
                compiling = peak
                peak, wall, rc = run_measured(argv, log)
            est = stage_bytes(scene, stage)
            rows.append({"scene": name, "stage": stage, "estimate_bytes": est, "peak_bytes": peak,
                         "ratio": round(est / peak, 3), "compiling_peak_bytes": compiling, "wall_s": round(wall, 1),
                         "exit_code": rc})
            print(f"{name:24s} {stage:9s} peak {peak / 2**20:7.0f} MiB  estimate {est / 2**20:7.0f} MiB  "
                  f"ratio {est / peak:5.2f}  {wall:6.1f} s{'  (compiled: ' + str(compiling // 2**20) + ' MiB)' if compiling else ''}"
                  f"{'  EXIT ' + str(rc) if rc else ''}", flush=True)
            if rc:
                print(log.read_text(errors="replace")[-2000:], file=sys.stderr)
    return rows


def _status(key: str) -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    raise KeyError(key)


def job_child(names: list[str], out: Path) -> int:
    """In this process, as ``bearingshaft run NAMES --out OUT``: one JSON line per stage on stdout."""
    from bearingshaft import pipeline

    for name in names:
        scene = load_scene(name)
        for stage in stages_of(scene):
            before = _status("VmRSS")
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")  # reset VmHWM to the current RSS (Linux >= 4.0)
            pipeline.run_stage(scene, stage, out / name, progress=False)
            print("JOB " + json.dumps({"scene": name, "stage": stage, "rss_before_bytes": before,
                                       "peak_in_job_bytes": _status("VmHWM"), "rss_after_bytes": _status("VmRSS")}),
                  flush=True)
    return 0


def measure_job(names: list[str], tmp: Path) -> tuple[list[dict], int]:
    argv = [sys.executable, str(Path(__file__).resolve()), "--job-child", "--out", str(tmp / "job"),
            "--scenes", *names]
    log = tmp / "job.log"
    peak, wall, rc = run_measured(argv, log)
    rows = [json.loads(line[4:]) for line in log.read_text(errors="replace").splitlines() if line.startswith("JOB ")]
    if rc:
        print(log.read_text(errors="replace")[-3000:], file=sys.stderr)
    print(f"job: {len(rows)} stages in one process, peak {peak / 2**20:.0f} MiB, {wall:.0f} s, exit {rc}", flush=True)
    return rows, peak


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def write_csv(path: Path, fields: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def reestimate(out: Path) -> None:
    """The estimate columns of the files in ``out`` recomputed from the scenes (nothing is run)."""
    rows = read_csv(out / "estimates.csv")
    for r in rows:
        r["estimate_bytes"] = stage_bytes(load_scene(r["scene"]), r["stage"])
        r["ratio"] = round(r["estimate_bytes"] / int(r["peak_bytes"]), 3)
    write_csv(out / "estimates.csv", FIELDS, rows)
    if (out / "job.csv").exists():
        job = read_csv(out / "job.csv")
        for r in job:
            r["estimate_bytes"] = stage_bytes(load_scene(r["scene"]), r["stage"])
        write_csv(out / "job.csv", JOB_FIELDS, job)
        summary = read_csv(out / "job_summary.csv")[0]
        write_job_summary(out, job, int(summary["job_peak_bytes"]), float(summary["wall_s"]))


def write_job_summary(out: Path, job: list[dict], peak: int, wall: float) -> None:
    pairs = [(load_scene(r["scene"]), r["stage"]) for r in job]
    est = job_bytes(pairs)
    largest = max(int(r["alone_peak_bytes"]) for r in job if r["alone_peak_bytes"] not in ("", None))
    write_csv(out / "job_summary.csv", ["stages", "job_peak_bytes", "largest_alone_peak_bytes", "estimate_bytes",
                                        "ratio", "wall_s"],
              [{"stages": len(job), "job_peak_bytes": peak, "largest_alone_peak_bytes": largest,
                "estimate_bytes": est, "ratio": round(est / peak, 3), "wall_s": round(wall, 1)}])


def plot(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_csv(out / "estimates.csv")
    base = read_csv(out / "baseline.csv")[0] if (out / "baseline.csv").exists() else None
    labels = [f"{r['scene']} {r['stage']}" for r in rows]
    peak = [int(r["peak_bytes"]) / 2**30 for r in rows]
    est = [float(r["estimate_bytes"]) / 2**30 for r in rows]
    ratio = [float(r["ratio"]) for r in rows]
    y = range(len(rows))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 0.28 * len(rows) + 1.8), sharey=True,
                                  gridspec_kw={"width_ratios": [3, 1.3]})
    ax.barh([i + 0.2 for i in y], peak, height=0.4, color="tab:blue", label="measured peak (own process)")
    ax.barh([i - 0.2 for i in y], est, height=0.4, color="tab:orange", label="estimate (from the scene)")
    if base:
        ax.axvline(int(base["peak_bytes"]) / 2**30, color="0.3", ls=":", label="baseline: the imports alone")
    ax.set_yticks(list(y), labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("peak resident memory [GiB]")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.6 / (0.28 * len(rows) + 1.8) * 4), ncol=3, fontsize=8)
    ax2.scatter(ratio, list(y), color="k", s=12)
    ax2.axvspan(1.0, RATIO_MAX, color="tab:green", alpha=0.15, label=f"1 to {RATIO_MAX}")
    ax2.set_xlabel("estimate / peak")
    ax2.set_xlim(min(0.5, min(ratio) - 0.05), max(1.5, max(ratio) + 0.05))
    ax2.legend(loc="upper center", bbox_to_anchor=(0.5, -0.6 / (0.28 * len(rows) + 1.8) * 4), fontsize=8)
    ax2.grid(axis="x", alpha=0.3)
    fig.suptitle("Memory estimate against the measured peak, each stage in its own process")
    fig.tight_layout()
    fig.savefig(out / "estimates.png", dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=None, help="scenes to run (default: every built-in one)")
    ap.add_argument("--out", default=str(ROOT / "results" / "memory"), help="folder of the CSV files and plot")
    ap.add_argument("--no-job", action="store_true", help="skip the whole job in one process")
    ap.add_argument("--reestimate", action="store_true", help="recompute the estimates of the CSV files in --out")
    ap.add_argument("--job-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    names = args.scenes or builtin_names()
    out = Path(args.out)
    if args.job_child:
        return job_child(names, out)
    if args.reestimate:
        reestimate(out)
        plot(out)
        return 0
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="memory_estimates-") as tmp_name:
        tmp = Path(tmp_name)
        base = measure_baseline(tmp)
        write_csv(out / "baseline.csv", ["what", "peak_bytes", "wall_s", "exit_code"], [base])
        print(f"baseline (imports alone): {base['peak_bytes'] / 2**20:.0f} MiB", flush=True)
        rows = measure_stages(names, tmp)
        write_csv(out / "estimates.csv", FIELDS, rows)
        t_stages = time.perf_counter() - t0
        if not args.no_job:
            job, peak = measure_job(names, tmp)
            alone = {(r["scene"], r["stage"]): r["peak_bytes"] for r in rows}
            for r in job:
                r["alone_peak_bytes"] = alone.get((r["scene"], r["stage"]), "")
                r["estimate_bytes"] = stage_bytes(load_scene(r["scene"]), r["stage"])
            write_csv(out / "job.csv", JOB_FIELDS, job)
            write_job_summary(out, job, peak, time.perf_counter() - t0 - t_stages)
    plot(out)
    bad = [r for r in rows if not 1.0 <= r["ratio"] <= RATIO_MAX]
    print(f"{len(rows)} stages in {t_stages / 60:.1f} min (total {(time.perf_counter() - t0) / 60:.1f} min); "
          f"{len(bad)} estimates outside [1, {RATIO_MAX}] x the peak; written {out}")
    return 0 if all(r["exit_code"] == 0 for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
