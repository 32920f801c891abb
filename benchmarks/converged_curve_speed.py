"""CPU time of the converged main curve with its stability, per load level (issue 25: "the converged curve
with stability in under 10 s" for one level of the 3-DOF model).

    PYTHONPATH=. python benchmarks/converged_curve_speed.py [--scene discrete-frc] [--levels 1 10]
        [--repeats 3] [--out results/performance] [--grazing-ds 2e-2] [--multi-grazing-ds 1e-3]

What is timed, per level, as the frc stage computes it (the scene's [frc] table, one BLAS thread):

1. the HB curve at the scene's ``harmonics`` with the monodromy stability of every point
   (:func:`bearingshaft.stages.frc._curve`, ``hill_points = 0``): it supplies the first orbits' guesses;
2. the drawn curve (:func:`bearingshaft.stages.frc.converged_curve`) with ``branch_switching = false`` and
   ``cover_families = 0``: where HB is not converged in H, the main family of exact periodic orbits (the
   family through the linear response at the band's ends), continued by multiple shooting with the Floquet
   multipliers of every point; no family born at a branch point, no isolated family.

The sum of both is the "converged curve with stability" compared with the 10 s target, in CPU seconds
(``time.process_time``: what the run costs on a shared machine) and wall seconds; the medians over
``--repeats`` runs in one process (numba's kernels loaded first by an untimed run at the lowest level).
The 1-minute load average is recorded beside each run. ``--grazing-ds`` and ``--multi-grazing-ds`` set the exact
families' ``grazing_ds`` and ``multi_grazing_ds`` (:class:`reduced.periodic.exact_frc.ExactFRCOptions`; defaults:
the stage's, 2e-2 and 1e-3, the main family robust to round-off, tests/test_exact_frc_robust.py; 2e-2 and 2e-2:
the rule before session 13).

Writes ``converged_curve_speed.csv`` (every run: level, repeat, HB and main-family CPU/wall, the points,
the band the main family spans, its folds, its stable points, the load), ``converged_curve_headline.csv``
(one row per level, the columns of benchmarks/performance_summary.py: what, ours_s = the median CPU,
target, met) and ``converged_curve_machine.csv``.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import bearingshaft.stages.frc as stage  # noqa: E402
from bearingshaft.output import machine_rows, write_rows  # noqa: E402
from bearingshaft.scenes import load_scene  # noqa: E402
from bearingshaft.stages.frc import _curve, converged_curve  # noqa: E402
from bearingshaft.stages.frc_friction import load_vector  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.periodic.exact_frc import ExactFRCOptions  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from converged_frc_speed import _timed  # noqa: E402  (one timing helper for both benchmarks)

TARGET_S = 10.0  # the target, CPU seconds of one level


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discrete-frc")
    ap.add_argument("--levels", type=float, nargs="*", default=None, help="N (default: the scene's levels)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="results/performance")
    ap.add_argument("--grazing-ds", type=float, default=None, help="the exact families' grazing_ds (default 2e-2)")
    ap.add_argument("--multi-grazing-ds", type=float, default=None,
                    help="the exact families' multi_grazing_ds (default 1e-3)")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    spec = replace(scene.frc, branch_switching=False, cover_families=0)
    grazing_ds, multi_ds = ExactFRCOptions().grazing_ds, ExactFRCOptions().multi_grazing_ds
    if args.grazing_ds is not None or args.multi_grazing_ds is not None:  # the [frc] table has no such keys
        grazing_ds = args.grazing_ds if args.grazing_ds is not None else grazing_ds
        multi_ds = args.multi_grazing_ds if args.multi_grazing_ds is not None else multi_ds
        stage.ExactFRCOptions = functools.partial(ExactFRCOptions, grazing_ds=grazing_ds, multi_grazing_ds=multi_ds)
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)
    levels = args.levels or list(spec.levels_N)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    load0 = os.getloadavg()[0]
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps, as the stage
        P0 = min(levels)
        converged_curve(system, b, P0, spec, _curve(system, b, P0, spec, spec.harmonics, rows, names,
                                                    hill_points=0), rows, names)  # numba's kernels loaded
        for rep in range(args.repeats):
            for P in levels:
                load = os.getloadavg()[0]
                br, hb_wall, hb_cpu = _timed(_curve, system, b, P, spec, spec.harmonics, rows, names, hill_points=0)
                cc, cc_wall, cc_cpu = _timed(converged_curve, system, b, P, spec, br, rows, names)
                row = {"scene": scene.name, "level_N": P, "repeat": rep + 1, "method": cc.method,
                       "hb_cpu_s": round(hb_cpu, 3), "hb_wall_s": round(hb_wall, 3),
                       "main_cpu_s": round(cc_cpu, 3), "main_wall_s": round(cc_wall, 3),
                       "total_cpu_s": round(hb_cpu + cc_cpu, 3), "total_wall_s": round(hb_wall + cc_wall, 3),
                       "load_1min": round(load, 2)}
                if cc.exact is not None:
                    f = cc.exact.families[0]
                    row.update(points=len(f.freq_hz), freq_min_hz=f"{f.freq_hz.min():.6g}",
                               freq_max_hz=f"{f.freq_hz.max():.6g}", folds=len(f.folds),
                               stable_points=int(np.sum(f.stable)), status=f.status)
                else:
                    row.update(points=len(br.freq_hz), freq_min_hz=f"{br.freq_hz.min():.6g}",
                               freq_max_hz=f"{br.freq_hz.max():.6g}", folds="", stable_points="", status="hb")
                runs.append(row)
                print(f"[converged-curve-speed] {scene.name} {P:g} N #{rep + 1} ({cc.method}): "
                      f"{row['total_cpu_s']:.1f} s CPU ({hb_cpu:.1f} HB + {cc_cpu:.1f} main), "
                      f"{row['total_wall_s']:.1f} s wall, load {load:.1f}", flush=True)
    write_rows(out / "converged_curve_speed.csv", runs)
    head = []
    for P in levels:
        mine = [r for r in runs if r["level_N"] == P]
        cpu = float(np.median([r["total_cpu_s"] for r in mine]))
        wall = float(np.median([r["total_wall_s"] for r in mine]))
        r0 = mine[0]
        head.append({"what": f"converged main curve with stability, {scene.name} {P:g} N ({r0['method']}: HB guesses "
                             f"{np.median([r['hb_cpu_s'] for r in mine]):.1f} s + main family "
                             f"{np.median([r['main_cpu_s'] for r in mine]):.1f} s, {r0['points']} points over "
                             f"{r0['freq_min_hz']}-{r0['freq_max_hz']} Hz, ended: {r0['status']}), CPU seconds "
                             f"(median of {args.repeats}; grazing_ds {grazing_ds:g}, multi_grazing_ds {multi_ds:g}; "
                             f"wall {wall:.1f} s)",
                     "ours_s": round(cpu, 2), "baseline": "", "baseline_s": "", "ratio": "", "error": "",
                     "target": f"<= {TARGET_S:g} s CPU", "met": bool(cpu <= TARGET_S)})
    write_rows(out / "converged_curve_headline.csv", head)
    write_rows(out / "converged_curve_machine.csv", machine_rows(scene=scene.name, load_1min_start=round(load0, 2)))
    for h in head:
        print(f"{h['what']}: {h['ours_s']} s, met {h['met']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
