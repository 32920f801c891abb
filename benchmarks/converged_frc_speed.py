"""Speed of the converged forced-response curve with its stability (issue 25): per load level, the
frc stage's HB curve (with the monodromy of every point) and then its drawn curve
(:func:`bearingshaft.stages.frc.converged_curve`: HB where its amplitudes no longer move with H, else
the families of the exact flow by multiple shooting, with their Floquet multipliers and branch
switching), against a 10 s target; each level three times: as the scene says (with branch switching),
without the period-doubled families (``period_doubling = false``: what following them costs) and
with the main family only (``branch_switching = false``: the drawn curve with its stability, no
families born at its branch points).

    PYTHONPATH=. python benchmarks/converged_frc_speed.py [--scene discrete-frc] [--levels 1 10]
        [--repeats 1] [--out results/converged-frc-speed]

Both are computed as the stage computes them (the scene's [frc] table, one BLAS thread); numba's
kernels are loaded once before timing (a first converged curve at the lowest level, not timed).
Wall time and CPU time are both recorded: the machine is shared (its load average, from
/proc/loadavg, is recorded beside each run), so the CPU time is what the run costs and the wall time
what it took here. Writes ``converged_frc_speed_timing.csv`` (per level and repeat: HB and
converged-curve wall and CPU seconds, the load, the target and whether it is met),
``converged_frc_speed.csv`` (per level: the drawn method, its points, families and branch switches)
and ``converged_frc_families.csv`` (per level: each exact family's kind, points, band and stability).
The exact families' branch switching stops starting new families after ``[frc] switching_max_s`` of
wall time: on a loaded machine fewer families may be found than on an idle one.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bearingshaft.output import staged_output, write_rows  # noqa: E402
from bearingshaft.scenes import load_scene  # noqa: E402
from bearingshaft.stages.frc import _curve, converged_curve  # noqa: E402
from bearingshaft.stages.frc_friction import load_vector  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402

TARGET_S = 10.0  # the target: the converged curve with stability
WAYS = {"branch switching": {}, "no period doubling": {"period_doubling": False},
        "main family only": {"branch_switching": False}}  # [frc] keys changed


def _load() -> float:
    """The machine's 1-minute load average."""
    try:
        return float(Path("/proc/loadavg").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return float("nan")


def _timed(fn, *args, **kw):
    """(result, wall s, CPU s) of one call."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0, time.process_time() - c0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discrete-frc")
    ap.add_argument("--levels", type=float, nargs="*", default=None, help="N (default: the scene's levels)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", default="results/converged-frc-speed")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    spec = scene.frc
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)  # as the stage forms it (with [frc] also_points)
    levels = args.levels or list(spec.levels_N)
    timing, summary, families = [], [], []
    with staged_output(args.out, "converged-frc-speed", scene.source, "converged_frc_speed") as w, \
            single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps, as the stage
        P0 = min(levels)
        converged_curve(system, b, P0, spec, _curve(system, b, P0, spec, spec.harmonics, rows, names,
                                                    hill_points=0), rows, names)  # numba's kernels loaded
        for P, (way, sp) in itertools.product(levels, WAYS.items()):
            sp = replace(spec, **sp)
            for rep in range(args.repeats):
                load0 = _load()
                br, hb_wall, hb_cpu = _timed(_curve, system, b, P, sp, sp.harmonics, rows, names, hill_points=0)
                cc, cc_wall, cc_cpu = _timed(converged_curve, system, b, P, sp, br, rows, names)
                ex = cc.exact
                wall, cpu = hb_wall + cc_wall, hb_cpu + cc_cpu
                if rep == 0:
                    summary.append({
                        "scene": scene.name, "level": P, "way": way, "method": cc.method,
                        "hb_change": f"{cc.hb_change:.3g}",
                        "contact": cc.contact, "error": cc.error, "refined_bands": len(cc.refined),
                        "points": len(br.freq_hz) if ex is None and not isinstance(br, Exception)
                        else sum(len(f.freq_hz) for f in ex.families) if ex is not None else 0,
                        "families": len(ex.families) if ex is not None else 0,
                        "switches_followed": sum(r["child"] >= 0 for r in ex.switches) if ex is not None else 0,
                        "switches_not_followed": sum(r["child"] < 0 for r in ex.switches) if ex is not None else 0})
                timing.append({
                    "scene": scene.name, "level": P, "way": way, "repeat": rep + 1, "method": cc.method,
                    "hb_wall_s": round(hb_wall, 3), "hb_cpu_s": round(hb_cpu, 3),
                    "converged_wall_s": round(cc_wall, 3), "converged_cpu_s": round(cc_cpu, 3),
                    "total_wall_s": round(wall, 3), "total_cpu_s": round(cpu, 3), "target_s": TARGET_S,
                    "met_cpu": cpu < TARGET_S, "met_wall": wall < TARGET_S,
                    "load_before": load0, "load_after": _load()})
                print(f"[converged-frc-speed] {scene.name} {P:g} N, {way} ({cc.method}): {wall:.1f} s wall, "
                      f"{cpu:.1f} s CPU (HB {hb_cpu:.1f} s CPU), load {load0:.1f}", flush=True)
                if ex is not None and rep == 0 and way == "branch switching":
                    for k, f in enumerate(ex.families):
                        families.append({"scene": scene.name, "level": P, "family": k, "kind": f.kind,
                                         "period_k": f.periods, "points": len(f.freq_hz),
                                         "freq_min_hz": f"{f.freq_hz.min():.6g}",
                                         "freq_max_hz": f"{f.freq_hz.max():.6g}",
                                         "stable_points": int(np.sum(f.stable)), "status": f.status})
        write_rows(w.path("converged_frc_speed_timing.csv"), timing)
        write_rows(w.path("converged_frc_speed.csv"), summary)
        write_rows(w.path("converged_frc_families.csv"), families)
        w.stats["converged_frc_speed"] = {"scene": scene.name, "levels": levels, "target_s": TARGET_S}
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
