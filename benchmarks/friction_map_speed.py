"""Cost of the response map with friction (issues 25, 27, 28) against the 6-point stepped sine it replaces in the
frc stage of discrete-friction-frc, in one process, interleaved (old, new, old, new, ...), CPU and wall.

    PYTHONPATH=. python benchmarks/friction_map_speed.py [--repeats 2] [--out FILE.csv]

- ``old``: the stage's stepped sine before the map: up the band at ``[frc] stepped_sine_points`` frequencies, each
  settled to ``stepped_sine_tol`` or ``stepped_sine_max_s`` (:func:`bearingshaft.stages.frc_friction.settle`);
- ``new``: the response map of the level, up and down (:func:`bearingshaft.stages.frc_friction_map.compute_map`),
  then the checks' 20 periods from the map's state at each check frequency.

The HB curve that sets the band is computed first and not timed. Prints each run and the medians; ``--out`` writes
them (way, repeat, cpu_s, wall_s).
"""

from __future__ import annotations

import argparse
import csv
import time

import numpy as np

from bearingshaft.scenes import load_scene
from bearingshaft.stages import frc_friction, frc_friction_map
from bearingshaft.systems import model_system
from reduced.periodic.frc import FRC_STEPS
from reduced.periodic.friction_aft import friction_frc


def main(argv=None) -> None:
    """Run the comparison (module docstring).

    Parameters
    ----------
    argv : the command line (default sys.argv)
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--level", type=float, default=2.0)
    ap.add_argument("--out", default="")
    args = ap.parse_args(argv)
    sc = load_scene("discrete-friction-frc")
    spec = sc.frc
    system, rows = model_system(sc.model, False)
    names = tuple(sc.model.point_names)
    rows = np.asarray(rows, float)
    b = frc_friction.load_vector(spec, rows, names)
    P = args.level
    br = friction_frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, spec.harmonics, harmonics="odd",
                      point_rows=rows, point_names=names, continuation=FRC_STEPS.replace(max_steps=spec.max_steps))
    n = system.n

    def old():
        state = (np.zeros(n), np.zeros(n), None)
        for f in frc_friction.check_frequencies(spec):
            state = frc_friction.settle(system, b, P, float(f), state, spec.stepped_sine_tol,
                                        spec.stepped_sine_max_s)[-1]

    def new():
        lvl = frc_friction_map.compute_map(system, b, P, spec, br, rows, names, frc_friction.check_frequencies(spec))
        for f in frc_friction.check_frequencies(spec):
            _, y = frc_friction_map.state_at(lvl, float(f))
            frc_friction.settle(system, b, P, float(f), (y[:n], y[n:2 * n], y[2 * n:]), 0.0, 15.0 / f)

    out = []
    for rep in range(args.repeats):
        for way, fn in (("old", old), ("new", new)):
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            out.append({"way": way, "repeat": rep, "cpu_s": time.process_time() - c0,
                        "wall_s": time.perf_counter() - t0})
            print(f"{rep} {way}: cpu {out[-1]['cpu_s']:.1f} s, wall {out[-1]['wall_s']:.1f} s", flush=True)
    for way in ("old", "new"):
        got = [r for r in out if r["way"] == way]
        print(f"{way}: median cpu {np.median([r['cpu_s'] for r in got]):.1f} s, "
              f"wall {np.median([r['wall_s'] for r in got]):.1f} s")
    if args.out:
        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(out[0]))
            w.writeheader()
            w.writerows(out)


if __name__ == "__main__":
    main()
