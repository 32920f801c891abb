"""Speed of the response map (issue 25): one level of the 3-DOF model, both directions, 0.1 Hz steps over
the contact band, every frequency classified with its Lyapunov exponent, against a 60 s target on 2 cores.

    PYTHONPATH=. python benchmarks/response_map_speed.py [--scene discrete-frc] [--levels 1 10]
        [--repeats 2] [--out results/response-map-speed]

For each level the frequencies are the frc stage's (:func:`bearingshaft.stages.frc_map.contact_bands`:
the linear response's contact band and the HB curve's at the scene's H, widened by 1 Hz, at
``[frc] map_step_hz``; ``map_coarse_points`` log-spaced elsewhere; each sweep extends its fine steps
while its response stays in contact), and the map is run as the stage runs it
(:func:`reduced.periodic.response_map.response_map`), in two ways:

- ``serial``: up, then down, in this process (what the stage does);
- ``2 processes``: up and down at once in two worker processes (the machine's 2 cores), the process
  start and the numba cache load included in the wall time.

The HB curve that sets the band is computed first and not timed (the stage has it anyway). Both ways
give the same map, point for point (the sweeps are deterministic: seeded kicks and tangents); that is
checked. Writes ``response_map_speed_timing.csv`` (level, way, frequencies, wall and CPU seconds, the
target and whether it is met), ``response_map.csv`` (the maps, as the stage writes them) and
``response_map_speed.csv`` (per level and direction: regimes, jumps, the largest exponent).

The dwell study (``--dwell-level``, default 1 N): near the upper end of the 1 N chaotic band the chaos
is transient (a boundary crisis: lifetimes of 100-4000 periods), so where an up sweep jumps down depends
on how long it dwells at each frequency, in a test as here. The up sweep is run again recording
``DWELLS`` periods per frequency: ``response_map_dwell.csv`` gives its chaotic span and jumps for each,
``response_map_dwell_timing.csv`` the run times.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bearingshaft.output import staged_output, write_rows  # noqa: E402
from bearingshaft.scenes import load_scene  # noqa: E402
from bearingshaft.stages.frc_friction import load_vector  # noqa: E402
from bearingshaft.stages.frc_map import contact_bands  # noqa: E402
from bearingshaft.stages.frc_map_files import MAP_FIELDS, _sweep_rows  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.periodic.frc import frc  # noqa: E402
from reduced.periodic.response_map import MapOptions, map_frequencies, response_map  # noqa: E402

TARGET_S = 60.0  # the target for one level, both directions, on 2 cores
DWELLS = (128, 512, 2048)  # periods recorded per frequency in the dwell study


def _sweep(args):
    """One sweep (a worker's job): (direction, ResponseMap, wall s, CPU s)."""
    system, b, P, freqs, direction, rows, names, step, n_record = args
    t0, c0 = time.perf_counter(), time.process_time()
    with single_thread_blas():
        rm = response_map(system, b, P, freqs, direction=direction, point_rows=rows, point_names=names,
                          options=MapOptions(n_record=n_record), extend_step_hz=step)
    return direction, rm, time.perf_counter() - t0, time.process_time() - c0


def _same(a, b) -> bool:
    """Two maps classify every frequency alike, with the same exponents and envelopes."""
    return (np.array_equal(a.freq_hz, b.freq_hz) and a.regime == b.regime
            and np.array_equal(a.lyapunov_per_s, b.lyapunov_per_s) and np.array_equal(a.peak_stats(), b.peak_stats()))


def _dwell_study(system, b, P: float, spec, rows, names) -> tuple[list[dict], list[dict]]:
    """The up sweep at P over its contact band again for each dwell of DWELLS (module docstring)."""
    with single_thread_blas():
        curve = frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, spec.harmonics,
                    harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                    max_steps=spec.max_steps, stability=False)
    bands = contact_bands(system, b, P, spec, curve)
    fr = map_frequencies(spec.freq_min_hz, spec.freq_max_hz, bands, spec.map_step_hz, 0)
    out, timing = [], []
    for n_record in DWELLS:
        _, rm, wall, cpu = _sweep((system, b, P, fr, "up", rows, names, spec.map_step_hz, n_record))
        chaos = rm.freq_hz[np.array([r == "chaotic" for r in rm.regime])]
        out.append({"level": P, "direction": "up", "record_periods": n_record, "frequencies": rm.freq_hz.size,
                    "chaotic": chaos.size, "chaotic_from_hz": f"{chaos.min():.4g}" if chaos.size else "",
                    "chaotic_to_hz": f"{chaos.max():.4g}" if chaos.size else "",
                    "jump_hz": ";".join(f"{f:.4g}" for f in rm.jump_hz),
                    "unsettled": sum(not p.settled for p in rm.points)})
        timing.append({"level": P, "record_periods": n_record, "wall_s": round(wall, 3), "cpu_s": round(cpu, 3)})
        print(f"[response-map-speed] dwell {n_record} periods: chaotic {out[-1]['chaotic_from_hz']}-"
              f"{out[-1]['chaotic_to_hz']} Hz ({wall:.1f} s)", flush=True)
    return out, timing


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discrete-frc")
    ap.add_argument("--levels", type=float, nargs="*", default=None, help="N (default: the scene's levels)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default="results/response-map-speed")
    ap.add_argument("--dwell-level", type=float, default=1.0, help="N, the level of the dwell study (0: none)")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    spec = scene.frc
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)  # as the stage forms it (with [frc] also_points)
    levels = args.levels or list(spec.levels_N)
    timing, maps, summary = [], [], []
    with staged_output(args.out, "response-map-speed", scene.source, "response_map_speed") as w:
        for P in levels:
            with single_thread_blas():
                curve = frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, spec.harmonics,
                            harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                            max_steps=spec.max_steps, stability=False)
            bands = contact_bands(system, b, P, spec, curve)
            fr = map_frequencies(spec.freq_min_hz, spec.freq_max_hz, bands, spec.map_step_hz, spec.map_coarse_points)
            jobs = [(system, b, P, f, d, rows, names, spec.map_step_hz, spec.map_periods)
                    for d, f in (("up", fr), ("down", fr[::-1]))]
            _sweep(jobs[0][:3] + (fr[:3],) + jobs[0][4:])  # numba's kernels loaded once before timing
            ref = None
            for rep in range(args.repeats):
                for way in ("serial", "2 processes"):
                    t0 = time.perf_counter()
                    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                    c0 = time.process_time()
                    if way == "serial":
                        out = [_sweep(j) for j in jobs]
                    else:
                        with ProcessPoolExecutor(max_workers=2) as ex:
                            out = list(ex.map(_sweep, jobs))
                    wall = time.perf_counter() - t0
                    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                    cpu = time.process_time() - c0 + (r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime)
                    got = {d: rm for d, rm, _, _ in out}
                    same = ref is None or all(_same(ref[d], got[d]) for d in got)
                    ref = ref or got
                    timing.append({"level": P, "way": way, "repeat": rep + 1, "frequencies_up": got["up"].freq_hz.size,
                                   "frequencies_down": got["down"].freq_hz.size,
                                   "fine_step_hz": spec.map_step_hz, "bands_hz": ";".join(f"{a:.3f}-{c:.3f}"
                                                                                        for a, c in bands),
                                   "wall_s": round(wall, 3), "cpu_s": round(cpu, 3), "target_s": TARGET_S,
                                   "met": wall < TARGET_S, "same_map": same})
                    print(f"[response-map-speed] {P:g} N {way}: {wall:.1f} s wall, {cpu:.1f} s CPU", flush=True)
            for d, rm in ref.items():
                r, _ = _sweep_rows(P, d, rm, names.index("x1"))
                maps += r
                summary.append({"level": P, "direction": d, "frequencies": rm.freq_hz.size,
                                **{k: rm.regime.count(k) for k in ("periodic", "subharmonic", "quasi_periodic",
                                                                     "chaotic")},
                                "unsettled": sum(not p.settled for p in rm.points),
                                "jump_hz": ";".join(f"{f:.4g}" for f in rm.jump_hz),
                                "max_lyapunov_per_s": f"{np.max(rm.lyapunov_per_s):.4g}"})
        if args.dwell_level > 0:
            dwell, dwell_t = _dwell_study(system, b, args.dwell_level, spec, rows, names)
            write_rows(w.path("response_map_dwell.csv"), dwell)
            write_rows(w.path("response_map_dwell_timing.csv"), dwell_t)
        write_rows(w.path("response_map_speed_timing.csv"), timing)
        write_rows(w.path("response_map.csv"), maps, fields=MAP_FIELDS)
        write_rows(w.path("response_map_speed.csv"), summary)
        w.stats["response_map_speed"] = {"levels": levels, "target_s": TARGET_S}
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
