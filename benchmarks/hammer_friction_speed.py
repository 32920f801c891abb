"""Speed of the virtual hammer test with friction at the tips (issue 27): each level's record with and without.

    PYTHONPATH=. python benchmarks/hammer_friction_speed.py [--levels 200 500 1000]
        [--mu 0.3] [--directions axial+lateral] [--out results/hammer-friction-speed]

The target: the ``hammer-test`` scene's record (2 s at 20 kHz, the exact integrator, channels acquired as
:func:`bearingshaft.stages.hammer.run_record` does) with friction at most 2x the frictionless one. Three models
of the scene's apparatus (assembly, 120 fixed-interface modes, not planar), each struck at every level:

- ``frictionless``: the scene's reduction without friction (122 coordinates), as main records it;
- ``basis, mu = 0``: the reduction with the tangential coordinates (130 with axial+lateral), run without
  friction (the frictionless kernels): the comparison run of the hammer stage;
- ``friction``: the same with mu (the friction kernels; 361 friction states with axial+lateral, each state's
  tables built the first time a record runs in it; a state entered for an instant is passed through without
  them, :mod:`reduced.transient.friction_probe`).

Each model runs a 20 ms record first (numba's compilation), then its tables are forgotten (both the
frictionless and the friction integrator's), and the levels run in order in one process, as the hammer stage
runs them: the first record builds the states it enters, the later ones reuse them and build those they
enter first. Each record is timed (CPU seconds of ``run_record``, its set-up and the tables it builds
included; BLAS on one thread, so CPU time is the work, whatever the machine's load; wall time too), and
then run again with every table it needs kept (``warm``); the whole is repeated ``--repeats`` times (tables
forgotten before each pass) and each record's median kept (one record's CPU time moves by 20-40 % from run to
run on the shared 2-core machine). Ratios are friction / frictionless (same level,
medians): per record cold (``ratio_cold``) and warm (``ratio_warm``), and over the stage, the sum of the
cold records of all levels (``stage``).
Writes hammer_friction_speed.csv (model, level_N, n, cold and warm CPU and wall s, table_s (the tables'
build inside the cold record), states built, n_events, energy_balance_error, friction_J, the ratios) and
machine.csv (load, versions, the stage's ratio).
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
    ap.add_argument("--levels", type=float, nargs="+", default=[200.0, 500.0, 1000.0])
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--directions", default="axial+lateral")
    ap.add_argument("--repeats", type=int, default=3, help="cold and warm passes per model (the median is kept: "
                    "CPU time of one record moves by 20-40 %% from run to run on the shared 2-core machine)")
    ap.add_argument("--out", default=str(ROOT / "results" / "hammer-friction-speed"))
    args = ap.parse_args(argv)
    from reduced.transient.exact_tables import clear_table_cache
    from reduced.transient.friction import clear_tables

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = load_scene("hammer-test")
    plain = replace(base.model, mu=0.0)
    fric = replace(base.model, mu=args.mu, friction_directions=args.directions)
    load0 = os.getloadavg()
    rows = []

    def timed(rig, scene, level):
        w0, c0 = time.perf_counter(), time.process_time()
        rec = hammer.run_record(rig, hammer.blow(scene.hammer, level), scene, level)
        return rec, time.perf_counter() - w0, time.process_time() - c0

    with single_thread_blas():
        rom_plain = plain.reduced(True)
        rom_fric = fric.reduced(True)
        models = {"frictionless": rom_plain, "basis, mu = 0": rom_fric.with_contact(replace(fric, mu=0.0)),
                  "friction": rom_fric}
        rigs = {}
        for name, rom in models.items():
            scene = replace(base, model=fric if name == "friction" else plain)
            rigs[name] = (hammer._rig(scene, rom), scene)
            hammer.run_record(rigs[name][0], hammer.blow(scene.hammer, 20.0), scene, 20.0, duration_s=0.02)  # compile
        passes = {name: [] for name in models}
        for _ in range(args.repeats):  # the models in turn within each pass: a slow spell of the machine falls on all
            for name, (rig, scene) in rigs.items():
                clear_tables()
                clear_table_cache()
                cold = {level: timed(rig, scene, level) for level in args.levels}  # the stage's order: tables
                # built as the records enter their states; then every table the record needs kept
                passes[name].append((cold, {level: timed(rig, scene, level) for level in args.levels}))
        for name, (rig, _) in rigs.items():
            ps = passes[name]
            for level in args.levels:
                rec = ps[0][0][level][0]
                wall, cpu = (float(np.median([p[0][level][k] for p in ps])) for k in (1, 2))
                table_s = float(np.median([p[0][level][0].stats.get("table_s", 0.0) for p in ps]))
                warm_wall, warm_cpu = (float(np.median([p[1][level][k] for p in ps])) for k in (1, 2))
                rows.append({"model": name, "level_N": level, "n": rig.system.n, "cold_cpu_s": cpu, "cold_wall_s": wall,
                             "warm_cpu_s": warm_cpu, "warm_wall_s": warm_wall, "table_s": table_s,
                             "states_built": rec.stats.get("n_states_built", 0),
                             "n_events": rec.stats.get("n_events", 0),
                             "energy_balance_error": rec.balance_error,
                             "friction_J": float(rec.friction[-1]) if rec.friction is not None else 0.0,
                             "hammer_work_J": float(rec.external[-1])})
                print(rows[-1], flush=True)
    ref = {r["level_N"]: r for r in rows if r["model"] == "frictionless"}
    lines = ["model,level_N,n,cold_cpu_s,cold_wall_s,warm_cpu_s,warm_wall_s,table_s,states_built,n_events,"
             "energy_balance_error,friction_J,hammer_work_J,ratio_cold,ratio_warm,target,met"]
    stage = {}
    for r in rows:
        b = ref[r["level_N"]]
        cold, warm = r["cold_cpu_s"] / b["cold_cpu_s"], r["warm_cpu_s"] / b["warm_cpu_s"]
        stage.setdefault(r["model"], 0.0)
        stage[r["model"]] += r["cold_cpu_s"]
        lines.append(f"{r['model']},{r['level_N']:g},{r['n']},{r['cold_cpu_s']:.3f},{r['cold_wall_s']:.3f},"
                     f"{r['warm_cpu_s']:.3f},{r['warm_wall_s']:.3f},{r['table_s']:.3f},{r['states_built']},"
                     f"{r['n_events']},{r['energy_balance_error']:.2e},{r['friction_J']:.6g},{r['hammer_work_J']:.6g},"
                     f"{cold:.3f},{warm:.3f},2.0,{'yes' if cold <= 2.0 else 'no'}")
    (out / "hammer_friction_speed.csv").write_text("\n".join(lines) + "\n")
    stage_ratio = stage["friction"] / stage["frictionless"]
    machine = {"machine": platform.machine(), "python": platform.python_version(), "numpy": np.__version__,
               "numba": numba.__version__, "cpus": os.cpu_count(), "load_before": " ".join(f"{x:.2f}" for x in load0),
               "load_after": " ".join(f"{x:.2f}" for x in os.getloadavg()), "mu": args.mu,
               "directions": args.directions, "repeats": args.repeats,
               "levels": " ".join(f"{v:g}" for v in args.levels),
               "stage_cpu_s_frictionless": f"{stage['frictionless']:.2f}",
               "stage_cpu_s_friction": f"{stage['friction']:.2f}", "stage_ratio": f"{stage_ratio:.3f}"}
    (out / "machine.csv").write_text("key,value\n" + "".join(f"{k},{v}\n" for k, v in machine.items()))
    print((out / "hammer_friction_speed.csv").read_text())
    print(f"stage (cold tables, levels {args.levels}): friction / frictionless CPU = {stage_ratio:.3f}")


if __name__ == "__main__":
    main()
