"""The machine's speed states: the speed probe on each core in turn, for a while (issue 28).

    PYTHONPATH=. python benchmarks/machine_speed.py [--seconds 60] [--out results/performance]

One process moves between the cores (``os.sched_setaffinity``) and times, on each in turn, the speed probe
of benchmarks/process_median.py (a compiled loop of ``sin(a) * exp(b)`` calls that touches no array; the
fastest of 7 CPU times) and a dependent chain of multiplies and adds (latency only, no memory, no calls),
for ``--seconds``. On this machine class the probe runs at ~4.5 ms or at ~7 ms, on each core
independently, switching within a second (2026-11-27 18:01-18:03 UTC, 90 s: fast 30 % of the time), while the
chain shows no such two states (2.5-3.3 ms): the slow state is not the clock and not this guest's load
(nothing else runs, no steal time), it comes from the host (what shares the core with ours there). A benchmark timed
in one process draws these states; benchmarks/integrator_speed.py and converged_curve_speed.py therefore
report the median of several processes.

Writes ``machine_speed.csv`` (time, core, probe ms, chain ms) and ``machine_speed.png`` (both series per
core, and the probe's histogram).

    PYTHONPATH=. python benchmarks/machine_speed.py --watch FILE [--every 2]

instead samples the state while something else runs (benchmarks/job_times.py around each run): every ``--every``
seconds a short probe (:data:`WATCH_N` terms, the fastest of :data:`WATCH_REPEATS`: ~2 ms a call) on each core in
turn, a row appended to FILE, until terminated; ~0.4 % of the machine's CPU. The probe's CPU time is its own
(``time.process_time``), so a core busy with the job does not lengthen it, only the job's cache contents may.
"""

from __future__ import annotations

import argparse
import csv
import os
import signal
import sys
import time
from pathlib import Path

import numba as nb

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from process_median import fastest_ms, probe_ms, read_csv  # noqa: E402

from bearingshaft.output import machine_rows, write_rows  # noqa: E402

FAST_MS = 6.0  # probe times below this are the fast state (~4.7 ms; the slow one ~7-8 ms)
WATCH_N, WATCH_REPEATS = 100_000, 3  # the watch's short probe: a third of the terms, FAST_MS / 3 its threshold


@nb.njit(cache=True)
def _chain(n):
    s = 0.0
    for _ in range(n):
        s = s * 0.999999 + 1e-9
    return s


def chain_ms(n: int = 1_000_000, repeats: int = 7) -> float:
    """:func:`process_median.fastest_ms` of s <- 0.999999 s + 1e-9, n times: a dependent chain of a multiply and
    an add, no memory and no calls (its time is the clock's and the latency's only).

    Parameters
    ----------
    n : int
        Links of the chain.
    repeats : int
        Timed calls after one warm-up.

    Returns
    -------
    float
    """
    return fastest_ms(_chain, n, repeats)


def series(seconds: float) -> list[dict]:
    """Probe and chain on each core in turn for ``seconds``: rows (t_s, core, probe_ms, chain_ms).

    Parameters
    ----------
    seconds : float
        How long.

    Returns
    -------
    list of dict
    """
    cores = sorted(os.sched_getaffinity(0))
    rows = []
    t0 = time.perf_counter()
    try:
        while time.perf_counter() - t0 < seconds:
            for c in cores:
                os.sched_setaffinity(0, {c})
                rows.append({"t_s": round(time.perf_counter() - t0, 3), "core": c, "probe_ms": round(probe_ms(), 3),
                             "chain_ms": round(chain_ms(), 3)})
    finally:
        os.sched_setaffinity(0, set(cores))
    return rows


def watch(path: Path, every_s: float) -> None:
    """Append (t_s, core, probe_ms) to the CSV ``path`` every ``every_s`` seconds, each core in turn, with the short
    probe (:data:`WATCH_N` terms), until SIGTERM.

    Parameters
    ----------
    path : Path
        The CSV written (its header first, a row flushed per sample).
    every_s : float
        Seconds between samples.
    """
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    cores = sorted(os.sched_getaffinity(0))
    t0 = time.perf_counter()
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["t_s", "core", "probe_ms"])
        while not stop:
            for c in cores:
                os.sched_setaffinity(0, {c})
                out.writerow([round(time.perf_counter() - t0, 3), c, round(probe_ms(WATCH_N, WATCH_REPEATS), 3)])
            fh.flush()
            os.sched_setaffinity(0, set(cores))
            time.sleep(every_s)


def watched_fast_fraction(path: Path) -> tuple[float, int]:
    """(fraction of the samples in the fast state, samples) of a :func:`watch` file (nan, 0 if it has none or
    does not exist: a watch terminated before its first sample).

    Parameters
    ----------
    path : Path
        The watch's CSV.

    Returns
    -------
    tuple of (float, int)
    """
    probes = [float(r["probe_ms"]) for r in read_csv(path)]
    if not probes:
        return float("nan"), 0
    return sum(p < FAST_MS * WATCH_N / 300_000 for p in probes) / len(probes), len(probes)


def figure(rows: list[dict], path: Path) -> None:
    """machine_speed.png: probe and chain against time per core, and the probe's histogram.

    Parameters
    ----------
    rows : list of dict
        :func:`series`'s rows.
    path : Path
        The PNG written.

    Returns
    -------
    None
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, axh) = plt.subplots(1, 2, figsize=(13, 4.5), width_ratios=(3, 1), constrained_layout=True)
    for c in sorted({r["core"] for r in rows}):
        mine = [r for r in rows if r["core"] == c]
        ax.plot([r["t_s"] for r in mine], [r["probe_ms"] for r in mine], ".-", lw=0.5, ms=3,
                label=f"core {c}: probe (sin exp calls)")
        ax.plot([r["t_s"] for r in mine], [r["chain_ms"] for r in mine], "x", ms=3,
                label=f"core {c}: dependent multiply-add chain")
    ax.axhline(FAST_MS, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("CPU time of one call [ms] (fastest of 7)")
    ax.set_title("Speed of this machine's cores over time: the probe switches between two states, the chain does "
                 "not", fontsize=10)
    ax.legend(fontsize=8, ncol=2)
    axh.hist([r["probe_ms"] for r in rows], bins=40, color="C0")
    fast = sum(r["probe_ms"] < FAST_MS for r in rows) / len(rows)
    axh.set_xlabel("probe [ms]")
    axh.set_title(f"probe: fast state (< {FAST_MS:g} ms) {100 * fast:.0f} % of the time", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--out", default="results/performance")
    ap.add_argument("--watch", help="sample the state into this CSV until terminated (see the module docstring)")
    ap.add_argument("--every", type=float, default=2.0, help="seconds between the watch's samples")
    args = ap.parse_args(argv)
    if not args.seconds > 0:
        ap.error("--seconds must be > 0")
    if args.watch:
        if not args.every > 0:
            ap.error("--every must be > 0")
        watch(Path(args.watch), args.every)
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = series(args.seconds)
    write_rows(out / "machine_speed.csv", rows)
    fast = sum(r["probe_ms"] < FAST_MS for r in rows) / len(rows)
    chain = sorted(r["chain_ms"] for r in rows)
    write_rows(out / "machine_speed_machine.csv", machine_rows(
        seconds=args.seconds, samples=len(rows), probe_fast_fraction=round(fast, 3),
        chain_ms_min=chain[0], chain_ms_median=chain[len(chain) // 2], chain_ms_max=chain[-1]))
    figure(rows, out / "machine_speed.png")
    print(f"{len(rows)} samples: probe fast {100 * fast:.0f} % of the time; chain {chain[0]:.2f}-{chain[-1]:.2f} ms; "
          f"wrote {out}/machine_speed.{{csv,png}}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
