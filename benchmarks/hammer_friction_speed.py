"""Speed of the virtual hammer test with friction at the tips (issue 27): each level's record with and without.

    PYTHONPATH=. python benchmarks/hammer_friction_speed.py [--levels 200 500]
        [--mu 0.3] [--directions axial+lateral] [--out results/hammer-friction-speed]

The target: the ``hammer-test`` scene's record (2 s at 20 kHz, the exact integrator, channels acquired as
:func:`bearingshaft.stages.hammer.run_record` does) with friction at most 2x the frictionless one. Three models
of the scene's apparatus (assembly, 120 fixed-interface modes, not planar), each struck at every level:

- ``frictionless``: the scene's reduction without friction (122 coordinates), as main records it;
- ``basis, mu = 0``: the reduction with the tangential coordinates (130 with axial+lateral), run without
  friction (the frictionless kernels): the comparison run of the hammer stage;
- ``friction``: the same with mu (the friction kernels; 361 friction states with axial+lateral).

Each record is timed once (wall and CPU time of ``run_record``, its set-up included); the friction model's
first record builds the friction states' tables (``table_s``), which the later levels reuse (the stage runs
its levels in one process). The ratio is friction / frictionless per level, with and without the table.
The default levels are the two of the scene's that close the gaps and that the exact friction kernel runs:
at 1000 N it stops on a stick-slip loop at one instant (issue 27's known limitation, hammer-friction.toml).
Writes hammer_friction_speed.csv (model, level_N, n, wall_s, cpu_s, table_s, n_events, energy_balance_error,
friction_J, ratio...) and machine.csv (load, versions).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv=None) -> None:
    import numba

    from bearingshaft.scenes import load_scene
    from bearingshaft.stages import hammer
    from reduced._blas import single_thread_blas

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=float, nargs="+", default=[200.0, 500.0])
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--directions", default="axial+lateral")
    ap.add_argument("--out", default=str(ROOT / "results" / "hammer-friction-speed"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = load_scene("hammer-test")
    plain = replace(base.model, mu=0.0)
    fric = replace(base.model, mu=args.mu, friction_directions=args.directions)
    load0 = os.getloadavg()
    rows = []
    with single_thread_blas():
        rom_plain = plain.reduced(True)
        rom_fric = fric.reduced(True)
        models = {"frictionless": rom_plain, "basis, mu = 0": rom_fric.with_contact(replace(fric, mu=0.0)),
                  "friction": rom_fric}
        for name, rom in models.items():
            scene = replace(base, model=fric if name == "friction" else plain)
            rig = hammer._rig(scene, rom)
            hammer.run_record(rig, hammer.blow(scene.hammer, 20.0), scene, 20.0, duration_s=0.02)  # compile, tables
            for level in args.levels:
                w0, c0 = time.perf_counter(), time.process_time()
                rec = hammer.run_record(rig, hammer.blow(scene.hammer, level), scene, level)
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
                rows.append({"model": name, "level_N": level, "n": rig.system.n, "wall_s": wall, "cpu_s": cpu,
                             "table_s": rec.stats.get("table_s", 0.0), "n_events": rec.stats.get("n_events", 0),
                             "energy_balance_error": rec.balance_error,
                             "friction_J": float(rec.friction[-1]) if rec.friction is not None else 0.0,
                             "hammer_work_J": float(rec.external[-1])})
                print(rows[-1], flush=True)
    ref = {r["level_N"]: r for r in rows if r["model"] == "frictionless"}
    # the table of the first friction record, built once a system (timed in the untimed 20 ms warm-up run)
    with single_thread_blas():
        from reduced.transient.friction import clear_tables

        clear_tables()
        scene = replace(base, model=fric)
        rig = hammer._rig(scene, rom_fric)
        w0 = time.perf_counter()
        rec = hammer.run_record(rig, hammer.blow(scene.hammer, 20.0), scene, 20.0, duration_s=0.02)
        table_s, first_s = float(rec.stats["table_s"]), time.perf_counter() - w0
    lines = ["model,level_N,n,wall_s,cpu_s,table_s,n_events,energy_balance_error,friction_J,hammer_work_J,"
             "ratio_to_frictionless,ratio_with_table,target,met"]
    for r in rows:
        base_wall = ref[r["level_N"]]["wall_s"]
        ratio = r["wall_s"] / base_wall
        with_table = (r["wall_s"] + (table_s if r["model"] == "friction" else 0.0)) / base_wall
        met = "yes" if ratio <= 2.0 else "no"
        lines.append(f"{r['model']},{r['level_N']:g},{r['n']},{r['wall_s']:.3f},{r['cpu_s']:.3f},{r['table_s']:.3f},"
                     f"{r['n_events']},{r['energy_balance_error']:.2e},{r['friction_J']:.6g},{r['hammer_work_J']:.6g},"
                     f"{ratio:.3f},{with_table:.3f},2.0,{met}")
    (out / "hammer_friction_speed.csv").write_text("\n".join(lines) + "\n")
    machine = {"machine": platform.machine(), "python": platform.python_version(), "numpy": np.__version__,
               "numba": numba.__version__, "cpus": os.cpu_count(), "load_before": " ".join(f"{x:.2f}" for x in load0),
               "load_after": " ".join(f"{x:.2f}" for x in os.getloadavg()), "mu": args.mu,
               "directions": args.directions, "table_s": f"{table_s:.2f}", "first_20ms_record_s": f"{first_s:.2f}"}
    (out / "machine.csv").write_text("key,value\n" + "".join(f"{k},{v}\n" for k, v in machine.items()))
    print((out / "hammer_friction_speed.csv").read_text())


if __name__ == "__main__":
    main()
