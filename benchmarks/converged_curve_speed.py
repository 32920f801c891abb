"""CPU time of the converged main curve with its stability, per load level (issue 25: "the converged curve
with stability in under 10 s" for one level of the 3-DOF model).

    PYTHONPATH=. python benchmarks/converged_curve_speed.py [--scene discrete-frc] [--levels 1 10]
        [--repeats 3] [--out results/performance] [--no-hb] [--grazing-ds 2e-2] [--multi-grazing-ds 1e-3]

What is timed, per level (the scene's [frc] table with ``branch_switching = false`` and ``cover_families = 0``,
one BLAS thread), two ways in the same process, one after the other:

1. **the curve, no HB** (the headline): :func:`bearingshaft.stages.frc.linear_start_families`: the main family
   of exact periodic orbits continued by multiple shooting with the Floquet multipliers of every point, started
   from the linear orbit at the band's top (closed form, every stop open), the displacement scale from the
   linear response over the band; no harmonic balance at all. The same family as the stage's (its extent,
   folds and stability: tests/test_exact_frc_robust.py), traced from the other end (about as many points);
2. **the stage's path** (the baseline; skipped with ``--no-hb``): the HB curve at the scene's ``harmonics`` with
   the monodromy stability of every point (:func:`bearingshaft.stages.frc._curve`, ``hill_points = 0``), then
   the drawn curve (:func:`bearingshaft.stages.frc.converged_curve`: HB where it is converged in H, at 0.1 N,
   else the main family from the HB orbits' guesses). The stage needs its HB curve anyway (drawn beside the
   exact families, the choice between HB and shooting, the fill outside the families, the cover guesses).

With ``--processes`` P > 1 (default 5) the whole measurement runs in P child processes, one after the other, and
each headline row is that of the median process (benchmarks/process_median.py: a process of this machine runs at one
of two speeds), the runs of all in converged_curve_speed.csv with a ``process`` column. In each process: the
medians over ``--repeats`` runs (numba's kernels loaded first by an untimed run at the lowest
level), in CPU seconds (``time.process_time``: what the run costs on a shared machine) and wall seconds. The
1-minute load average is recorded beside each run. ``--grazing-ds`` and ``--multi-grazing-ds`` set the exact
families' ``grazing_ds`` and ``multi_grazing_ds`` (:class:`reduced.periodic.exact_frc.ExactFRCOptions`; defaults:
the stage's, 2e-2 and 1e-3, the main family robust to round-off, tests/test_exact_frc_robust.py; 2e-2 and 2e-2:
the rule before session 13).

Writes ``converged_curve_speed.csv`` (every run: level, repeat, the no-HB curve's CPU/wall, its points, band,
folds, stable points and how it ended; the stage path's HB and main-family CPU/wall and points; the load),
``converged_curve_headline.csv`` (one row per level, the columns of benchmarks/performance_summary.py: what,
ours_s = the no-HB curve's median CPU, baseline_s = the stage path's, target, met) and
``converged_curve_machine.csv``.
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
from bearingshaft.stages.frc import _curve, converged_curve, linear_start_families  # noqa: E402
from bearingshaft.stages.frc_friction import load_vector  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.periodic.exact_frc import ExactFRCOptions  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from converged_frc_speed import _timed  # noqa: E402  (one timing helper for both benchmarks)
from process_median import children, merge, probe_ms  # noqa: E402  (issue 28)

TARGET_S = 10.0  # the target, CPU seconds of one level


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discrete-frc")
    ap.add_argument("--levels", type=float, nargs="*", default=None, help="N (default: the scene's levels)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="results/performance")
    ap.add_argument("--processes", type=int, default=5,
                    help="child processes the whole measurement runs in, one after the other; each headline row is "
                         "that of the median process (benchmarks/process_median.py; odd; 1: this process alone)")
    ap.add_argument("--no-hb", action="store_true", help="skip the stage's path (HB curve + converged_curve)")
    ap.add_argument("--grazing-ds", type=float, default=None, help="the exact families' grazing_ds (default 2e-2)")
    ap.add_argument("--multi-grazing-ds", type=float, default=None,
                    help="the exact families' multi_grazing_ds (default 1e-3)")
    args = ap.parse_args(argv)
    if args.processes < 1 or args.processes % 2 == 0:
        ap.error("--processes must be odd and >= 1")
    if args.processes > 1:
        out = Path(args.out)
        argv = list(sys.argv[1:] if argv is None else argv)
        out.mkdir(parents=True, exist_ok=True)
        with children(str(Path(__file__).resolve()), argv, args.processes) as dirs:
            merge(dirs, "converged_curve", out, concat=("converged_curve_speed.csv",))
        print(f"wrote {out}/converged_curve_{{headline,processes,speed,machine}}.csv from {args.processes} processes")
        return 0
    probe0 = probe_ms()
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
        linear_start_families(system, b, P0, spec, rows, names)  # numba's kernels loaded
        if not args.no_hb:
            converged_curve(system, b, P0, spec, _curve(system, b, P0, spec, spec.harmonics, rows, names,
                                                        hill_points=0), rows, names)
        for rep in range(args.repeats):
            for P in levels:
                load = os.getloadavg()[0]
                ex, cc_wall, cc_cpu = _timed(linear_start_families, system, b, P, spec, rows, names)
                f = ex.families[0]
                row = {"scene": scene.name, "level_N": P, "repeat": rep + 1, "cpu_s": round(cc_cpu, 3),
                       "wall_s": round(cc_wall, 3), "points": len(f.freq_hz), "freq_min_hz": f"{f.freq_hz.min():.6g}",
                       "freq_max_hz": f"{f.freq_hz.max():.6g}", "folds": len(f.folds),
                       "stable_points": int(np.sum(f.stable)), "status": f.status, "load_1min": round(load, 2)}
                msg = (f"[converged-curve-speed] {scene.name} {P:g} N #{rep + 1}: no HB {cc_cpu:.1f} s CPU "
                       f"({cc_wall:.1f} s wall, {len(f.freq_hz)} points)")
                if not args.no_hb:
                    br, hb_wall, hb_cpu = _timed(_curve, system, b, P, spec, spec.harmonics, rows, names,
                                                 hill_points=0)
                    cc, st_wall, st_cpu = _timed(converged_curve, system, b, P, spec, br, rows, names)
                    row.update(stage_method=cc.method, stage_hb_cpu_s=round(hb_cpu, 3),
                               stage_hb_wall_s=round(hb_wall, 3), stage_main_cpu_s=round(st_cpu, 3),
                               stage_main_wall_s=round(st_wall, 3), stage_total_cpu_s=round(hb_cpu + st_cpu, 3),
                               stage_total_wall_s=round(hb_wall + st_wall, 3),
                               stage_points=len(cc.exact.families[0].freq_hz) if cc.exact is not None
                               else len(br.freq_hz))
                    msg += (f"; the stage's path ({cc.method}) {hb_cpu + st_cpu:.1f} s CPU ({hb_cpu:.1f} HB + "
                            f"{st_cpu:.1f} main, {row['stage_points']} points)")
                runs.append(row)
                print(msg + f", load {load:.1f}", flush=True)
    write_rows(out / "converged_curve_speed.csv", runs)
    head = []
    for P in levels:
        mine = [r for r in runs if r["level_N"] == P]
        cpu = float(np.median([r["cpu_s"] for r in mine]))
        wall = float(np.median([r["wall_s"] for r in mine]))
        r0 = mine[0]
        base, why = "", ""
        if not args.no_hb:
            base = float(np.median([r["stage_total_cpu_s"] for r in mine]))
            why = (f"; the stage's path ({r0['stage_method']}): HB guesses "
                   f"{np.median([r['stage_hb_cpu_s'] for r in mine]):.1f} s + "
                   f"{'main family' if r0['stage_method'] == 'shooting' else 'HB check'} "
                   f"{np.median([r['stage_main_cpu_s'] for r in mine]):.1f} s")
        head.append({"what": f"converged main curve with stability, {scene.name} {P:g} N (the exact main family "
                             f"from the linear orbit at the band's top, no HB: {r0['points']} points over "
                             f"{r0['freq_min_hz']}-{r0['freq_max_hz']} Hz, {r0['folds']} folds, ended: "
                             f"{r0['status']}), CPU seconds (median of {args.repeats}; grazing_ds {grazing_ds:g}, "
                             f"multi_grazing_ds {multi_ds:g}; wall {wall:.1f} s{why})",
                     "ours_s": round(cpu, 2), "baseline": "" if args.no_hb else "the stage's path: HB curve + "
                     "converged_curve, CPU s", "baseline_s": "" if args.no_hb else round(base, 2),
                     "ratio": "" if args.no_hb else round(base / cpu, 2), "error": "",
                     "target": f"<= {TARGET_S:g} s CPU", "met": bool(cpu <= TARGET_S)})
    write_rows(out / "converged_curve_headline.csv", head)
    write_rows(out / "converged_curve_machine.csv", machine_rows(scene=scene.name, load_1min_start=round(load0, 2),
                                                                 probe_ms_start=probe0, probe_ms_end=probe_ms()))
    for h in head:
        print(f"{h['what']}: {h['ours_s']} s, met {h['met']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
