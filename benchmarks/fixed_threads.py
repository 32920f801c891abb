"""What a fixed solver thread count costs, and what it buys (issue 24).

    PYTHONPATH=. python benchmarks/fixed_threads.py [--repeats 2] [--out results/fixed-threads]

PARDISO's factorization and the model builds' OpenBLAS run on ``fem._pardiso.solver_threads()``
threads: one, unless ``BEARINGSHAFT_THREADS`` says otherwise (before, PARDISO took the cores free at
the moment and OpenBLAS all the cores, so a run depended on the machine's load and core count).
Two computations, each with 1 and 2 threads, alternating, ``--repeats`` times, in one process:

- ``modal``: the modal analysis of ``assembly-modal`` (15,087 DOFs, 16 modes, PARDISO + block Krylov);
- ``reduce``: the Craig-Bampton reduction of ``hammer-test``'s apparatus (120 fixed-interface modes,
  SuperLU, ARPACK and dense products), on the 3-D model built once.

For each: wall and CPU time (all threads), the 1-minute load, and what the thread count changes in the
result: the largest relative change of a frequency (modal) or of a reduced matrix entry (reduce)
between 1 and 2 threads, and whether repeats with the same count give the same bits.
Writes ``fixed_threads.csv`` (one row per run) and ``fixed_threads_summary.csv``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

THREADS = (1, 2)


def _modal(fe, spec):
    from fem.modal import modal_analysis

    res = modal_analysis(fe.K, fe.M, n_modes=spec.n_modes, shift_hz=spec.shift_hz, solver=spec.solver)
    return {"freq_hz": res.freq_hz}


def _reduce(fe, spec):
    from reduced.models.rom import build_rom

    rom, _ = build_rom(spec, fe=fe)
    return {"K": rom.K, "M": rom.M}


def _change(a: dict, b: dict) -> float:
    """Largest relative change over the arrays (relative to each array's largest entry for matrices)."""
    worst = 0.0
    for k in a:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        scale = np.abs(x) if x.ndim == 1 else np.max(np.abs(x))
        worst = max(worst, float(np.max(np.abs(x - y) / np.maximum(scale, 1e-300))))
    return worst


def _same_bits(a: dict, b: dict) -> bool:
    return all(np.asarray(a[k]).tobytes() == np.asarray(b[k]).tobytes() for k in a)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("results/fixed-threads"))
    args = ap.parse_args(argv)
    from bearingshaft.output import machine_rows, write_rows
    from bearingshaft.scenes import load_scene
    from fem.model import build_system

    modal_scene, rom_scene = load_scene("assembly-modal"), load_scene("hammer-test")
    cases = {
        "modal": (build_system(modal_scene.model), modal_scene.modal, _modal),
        "reduce": (build_system(rom_scene.model.fe_model()), rom_scene.model, _reduce),
    }
    rows, results = [], {}
    for case, (fe, spec, fn) in cases.items():
        for rep in range(args.repeats):
            for t in THREADS:
                os.environ["BEARINGSHAFT_THREADS"] = str(t)
                w0, c0 = time.perf_counter(), time.process_time()
                out = fn(fe, spec)
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
                results.setdefault((case, t), []).append(out)
                rows.append({"case": case, "threads": t, "repeat": rep, "wall_s": round(wall, 2),
                             "cpu_s": round(cpu, 2), "load_1min": round(os.getloadavg()[0], 2)})
                print(rows[-1], flush=True)
    os.environ.pop("BEARINGSHAFT_THREADS", None)
    args.out.mkdir(parents=True, exist_ok=True)
    write_rows(args.out / "fixed_threads.csv", rows)
    summary = []
    for case in cases:
        walls = {t: [r["wall_s"] for r in rows if r["case"] == case and r["threads"] == t] for t in THREADS}
        cpus = {t: [r["cpu_s"] for r in rows if r["case"] == case and r["threads"] == t] for t in THREADS}
        one, two = results[(case, 1)], results[(case, 2)]
        summary.append({
            "case": case, "wall_s_1_thread_median": float(np.median(walls[1])),
            "wall_s_2_threads_median": float(np.median(walls[2])),
            "cpu_s_1_thread_median": float(np.median(cpus[1])), "cpu_s_2_threads_median": float(np.median(cpus[2])),
            "wall_ratio_1_over_2": round(float(np.median(walls[1]) / np.median(walls[2])), 3),
            "max_rel_change_1_vs_2_threads": f"{_change(one[0], two[0]):.2e}",
            "same_bits_repeats_1_thread": all(_same_bits(one[0], o) for o in one[1:]),
            "same_bits_repeats_2_threads": all(_same_bits(two[0], o) for o in two[1:]),
        })
    write_rows(args.out / "fixed_threads_summary.csv", summary)
    with open(args.out / "fixed_threads_machine.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["key", "value"])
        w.writeheader()
        w.writerows(machine_rows(repeats=args.repeats))
    for s in summary:
        print(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
