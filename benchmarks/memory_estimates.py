"""Memory estimates against measured peaks: every stage of every built-in scene, and the whole job.

    PYTHONPATH=. python benchmarks/memory_estimates.py [--peaks results/performance/main_job.csv]
        [--measure [--scenes NAME ...] | --reuse ESTIMATES.csv] [--job] [--out results/memory-estimates]

**Stages.** For each stage of each built-in scene, its estimate (:func:`bearingshaft.budget.stage_peak`,
counted from the scene alone, with the model cache as it was when the stage ran) beside its measured peak
resident memory, the stage run in a process of its own:

- by default the peaks of ``benchmarks/main_job_cost.py`` (``--peaks``, its ``main_job.csv``: ``ru_maxrss``
  of each stage's process; a stage during which the cache gained an entry built its reduced model);
- with ``--measure``, measured again here: each stage as
  ``python -c "...cli.main([STAGE, --scene, NAME, --out, TMP, --no-progress])"``, whose peak is the
  ``VmHWM`` it reads from ``/proc/self/status`` as it ends (``ru_maxrss`` of a child started by
  ``subprocess`` counts the parent's pages shared before ``exec``: a large parent would inflate it). The
  cache state before each stage is the user's cache (``$BEARINGSHAFT_CACHE``) as the stages leave it;
- with ``--reuse FILE``, the measured peaks and cache states of an ``estimates.csv`` written before (after a
  change of the estimates: nothing is run), a stage it lacks from ``--peaks``.

**Whole job** (``--job``): the stages of every built-in scene run one after another in one process, as
``bearingshaft run`` runs them; before each stage the process's high-water mark is reset
(``/proc/self/clear_refs``, Linux) and after it the stage's peak in the job (``VmHWM``) and what it left
resident (``VmRSS``) are read. The job's peak is compared with :func:`bearingshaft.budget.job_bytes`.

Writes, in ``--out``: ``estimates.csv`` (scene, stage, estimate_mb, measured_mb, ratio = estimate / measured,
cached: the scene's reduced model was in the cache as the stage started, builds_model, source),
``estimates.png`` and, with ``--job``, ``job.csv`` (per stage: rss_before_mb, peak_in_job_mb, rss_after_mb,
estimate_mb) and ``job_summary.csv``. MB are MiB (2**20 bytes).
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

from bearingshaft.budget import job_bytes, job_peaks, rom_cached, stage_peak  # noqa: E402
from bearingshaft.registry import stages_of  # noqa: E402
from bearingshaft.scenes import builtin_names, load_scene  # noqa: E402

MIB = 2**20
FIELDS = ["scene", "stage", "estimate_mb", "measured_mb", "ratio", "cached", "builds_model", "source"]
JOB_FIELDS = ["scene", "stage", "rss_before_mb", "peak_in_job_mb", "rss_after_mb", "estimate_mb"]
RATIO_MAX = 1.3  # the bound: estimate / measured peak in [1, RATIO_MAX]
PEAK_CODE = ("import sys\nfrom bearingshaft.cli import main\nrc = main(sys.argv[1:])\n"
             "hwm = [line.split()[1] for line in open('/proc/self/status') if line.startswith('VmHWM:')][0]\n"
             "print('VMHWM_KIB', hwm, flush=True)\nsys.exit(rc)\n")


def child_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["MPLBACKEND"] = "Agg"
    return env


def stage_peak_measured(scene: str, stage: str, out: Path, env: dict | None = None) -> tuple[int, float, int]:
    """Run ``stage`` of ``scene`` in a process of its own: (its VmHWM in bytes, wall s, exit code).

    Parameters
    ----------
    scene, stage : str
        What to run.
    out : Path
        Its results folder.
    env : dict, optional
        The child's environment (default: this one, with the checkout first on PYTHONPATH).

    Returns
    -------
    tuple
        (bytes, s, exit code); bytes is 0 if the stage failed before printing its peak.
    """
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", PEAK_CODE, stage, "--scene", scene, "--out", str(out),
                           "--no-progress"], capture_output=True, text=True, env=env or child_env(), cwd=ROOT)
    wall = time.perf_counter() - t0
    hwm = [int(line.split()[1]) for line in proc.stdout.splitlines() if line.startswith("VMHWM_KIB ")]
    if proc.returncode:
        print((proc.stdout + proc.stderr)[-2000:], file=sys.stderr)
    return (hwm[0] * 1024 if hwm else 0), wall, proc.returncode


def row(scene, stage: str, cached: bool, measured_bytes: float, source: str) -> dict:
    p = stage_peak(scene, stage, cached)
    return {"scene": scene.name, "stage": stage, "estimate_mb": round(p.bytes / MIB),
            "measured_mb": round(measured_bytes / MIB), "ratio": round(p.bytes / measured_bytes, 3),
            "cached": int(cached), "builds_model": int(p.builds_model), "source": source}


def from_peaks(path: Path) -> list[dict]:
    """Rows from ``main_job_cost.py``'s CSV: the estimate with the cache state the stage met."""
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if int(r["exit_code"]) or not r["peak_mb"]:  # failed, or timed from a run's log (no peak of its own)
                continue
            scene = load_scene(r["scene"])
            cached = r["stage"] == "reduce" or int(r["cache_after"]) == int(r["cache_before"])  # no entry built
            rows.append(row(scene, r["stage"], cached, float(r["peak_mb"]) * MIB,
                            f"{path.name}: ru_maxrss, own process"))
    return rows


def reused(path: Path) -> list[dict]:
    """Rows of an ``estimates.csv`` written before (their measured peaks and cache states), re-estimated now."""
    with open(path, newline="") as fh:
        return [row(load_scene(r["scene"]), r["stage"], bool(int(r["cached"])), float(r["measured_mb"]) * MIB,
                    r["source"]) for r in csv.DictReader(fh)]


def in_job_order(rows: list[dict], names: list[str], fill: list[dict]) -> list[dict]:
    """``rows`` in the order the job runs the stages, a stage they lack taken from ``fill`` if it has it."""
    have = {(r["scene"], r["stage"]): r for r in fill}
    have.update({(r["scene"], r["stage"]): r for r in rows})
    order = [(n, st) for n in names for st in stages_of(load_scene(n))]
    return [have[k] for k in order if k in have]


def measure_stages(names: list[str], tmp: Path, partial: Path | None = None) -> list[dict]:
    """Each stage measured in a process of its own; the rows so far rewritten to ``partial`` after each."""
    rows = []
    for name in names:
        scene = load_scene(name)
        for stage in stages_of(scene):
            cached = rom_cached(scene)
            peak, wall, rc = stage_peak_measured(name, stage, tmp / name)
            if rc:
                print(f"{name} {stage}: exit {rc}", flush=True)
                continue
            rows.append(row(scene, stage, cached, peak, "VmHWM, own process (--measure)"))
            r = rows[-1]
            print(f"{name:24s} {stage:9s} measured {r['measured_mb']:6d} MiB  estimate {r['estimate_mb']:6d} MiB  "
                  f"ratio {r['ratio']:5.2f}  {wall:6.1f} s", flush=True)
            if partial is not None:
                write_csv(partial, FIELDS, rows)
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
            print("JOB " + json.dumps({"scene": name, "stage": stage, "rss_before": before,
                                       "peak_in_job": _status("VmHWM"), "rss_after": _status("VmRSS")}),
                  flush=True)
    return 0


def job_rows(log_text: str, names: list[str]) -> tuple[list[dict], dict]:
    """The job pass's rows and summary from its log (lines ``JOB {...}``), with the estimates."""
    recs = [json.loads(line[4:]) for line in log_text.splitlines() if line.startswith("JOB ")]
    recs = [{k.removesuffix("_bytes"): v for k, v in r.items()} for r in recs]  # an earlier version's keys
    peaks = job_peaks([load_scene(n) for n in names])
    est = {(p.scene, p.stage): p.bytes for p in peaks}
    rows = [{"scene": r["scene"], "stage": r["stage"], "rss_before_mb": round(r["rss_before"] / MIB),
             "peak_in_job_mb": round(r["peak_in_job"] / MIB), "rss_after_mb": round(r["rss_after"] / MIB),
             "estimate_mb": round(est[(r["scene"], r["stage"])] / MIB)} for r in recs]
    measured = max(r["peak_in_job"] for r in recs)
    estimate = job_bytes(peaks)
    summary = {"stages": len(recs), "complete": int(len(recs) == len(peaks)),
               "job_peak_mb": round(measured / MIB), "largest_stage_estimate_mb": round(max(est.values()) / MIB),
               "job_estimate_mb": round(estimate / MIB), "ratio": round(estimate / measured, 3)}
    return rows, summary


def measure_job(names: list[str], tmp: Path) -> tuple[list[dict], dict]:
    log = tmp / "job.log"
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        rc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--job-child", "--out", str(tmp / "job"),
                             "--scenes", *names], stdout=fh, stderr=subprocess.STDOUT, env=child_env(),
                            cwd=ROOT).returncode
    rows, summary = job_rows(log.read_text(errors="replace"), names)
    summary.update(wall_s=round(time.perf_counter() - t0, 1), exit_code=rc)
    return rows, summary


def write_csv(path: Path, fields: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{r['scene']} {r['stage']}{' *' if r['source'].startswith('main_job') else ''}" for r in rows]
    meas = [r["measured_mb"] / 1024 for r in rows]
    est = [r["estimate_mb"] / 1024 for r in rows]
    ratio = [r["ratio"] for r in rows]
    y = list(range(len(rows)))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 0.26 * len(rows) + 1.6), sharey=True,
                                  gridspec_kw={"width_ratios": [3, 1.2]}, layout="constrained")
    ax.barh([i - 0.2 for i in y], meas, height=0.4, color="tab:blue", label="measured peak (own process)")
    ax.barh([i + 0.2 for i in y], est, height=0.4, color="tab:orange", label="estimate (from the scene)")
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("peak resident memory [GiB]")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    ax2.axvspan(1.0, RATIO_MAX, color="tab:green", alpha=0.15, label=f"allowed: 1 to {RATIO_MAX}")
    ax2.scatter(ratio, y, color="k", s=14, zorder=3)
    ax2.set_xlabel("estimate / measured peak")
    ax2.set_xlim(min(0.9, min(ratio) - 0.05), max(1.4, max(ratio) + 0.05))
    ax2.legend(loc="lower right", fontsize=8)
    ax2.grid(axis="x", alpha=0.3)
    older = any(r["source"].startswith("main_job") for r in rows)
    fig.suptitle("Memory estimate against the measured peak, each stage in a process of its own"
                 + ("\n(* peak from an earlier main_job_cost.py run, ru_maxrss of the stage's own process; "
                    "the others VmHWM, --measure)"
                    if older else ""))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peaks", default=str(ROOT / "results" / "performance" / "main_job.csv"),
                    help="main_job_cost.py's CSV to read the peaks from (default results/performance/main_job.csv)")
    ap.add_argument("--measure", action="store_true", help="measure each stage's peak here instead")
    ap.add_argument("--reuse", default=None, help="an estimates.csv measured before: its peaks re-estimated (the "
                    "stages it lacks from --peaks)")
    ap.add_argument("--job", action="store_true", help="also run the whole job in one process and compare its peak")
    ap.add_argument("--scenes", nargs="*", default=None, help="scenes (default: every built-in one)")
    ap.add_argument("--out", default=str(ROOT / "results" / "memory-estimates"), help="folder of the CSV and plot")
    ap.add_argument("--job-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--job-log", default=None, help=argparse.SUPPRESS)  # a job pass's log already written
    args = ap.parse_args(argv)
    names = args.scenes or builtin_names()
    out = Path(args.out)
    if args.job_child:
        return job_child(names, out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} at the start", flush=True)
    with tempfile.TemporaryDirectory(prefix="memory_estimates-") as tmp_name:
        tmp = Path(tmp_name)
        if args.measure:
            rows = measure_stages(names, tmp, out / "estimates.partial.csv")
        elif args.reuse:  # measured before (a --measure run's rows), the rest from --peaks
            rows = in_job_order(reused(Path(args.reuse)), names, from_peaks(Path(args.peaks)))
        else:
            rows = from_peaks(Path(args.peaks))
        write_csv(out / "estimates.csv", FIELDS, rows)
        plot(rows, out / "estimates.png")
        if args.job or args.job_log:
            if args.job_log:
                job, summary = job_rows(Path(args.job_log).read_text(errors="replace"), names)
            else:
                job, summary = measure_job(names, tmp)
            write_csv(out / "job.csv", JOB_FIELDS, job)
            write_csv(out / "job_summary.csv", list(summary), [summary])
            print(f"job in one process: measured {summary['job_peak_mb']} MiB, estimate "
                  f"{summary['job_estimate_mb']} MiB (ratio {summary['ratio']}), {summary['stages']} stages")
    bad = [r for r in rows if not 1.0 <= r["ratio"] <= RATIO_MAX]
    for r in bad:
        print(f"outside [1, {RATIO_MAX}]: {r['scene']} {r['stage']} ratio {r['ratio']}")
    print(f"{len(rows)} stages, ratios {min(r['ratio'] for r in rows):.2f} to {max(r['ratio'] for r in rows):.2f}; "
          f"{len(bad)} outside [1, {RATIO_MAX}]; written {out}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
