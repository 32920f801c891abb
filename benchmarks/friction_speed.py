"""Speed of the ringdowns with friction at the tips (issue 27): the discrete friction model's 2 s ringdown.

    PYTHONPATH=. python benchmarks/friction_speed.py [--repeats 7] [--out results/friction-speed]

The target: the ``discrete-friction`` scene's 2 s ringdown (20 kHz, its start v0 = [0, 0, 0.3, 0.2] m/s) by
the exact integrator in under 0.1 s. Each case is timed in this process after one untimed run (numba's
kernels compiled and cached), ``--repeats`` times: the median and the smallest wall time (perf_counter)
and the CPU time beside them (the machine may be shared), all of ``reduced.transient.integrate.ringdown``
(its set-up included: the friction states' tables, 49 of them). The set-up alone is timed too.

Cases: the scene's start with friction (mu = 0.3) and without (mu = 0, the same 4-DOF model: the frictionless
kernels), and the paper's Fig. 3 (right) start, v0 = [0, 0, 200] m/s on the masses, with the axial velocity
0.2 m/s (2.5e4 J; 40 times the contact events), by the exact and the explicit integrators; the scene's
start by DOP853 restarted at every state change once (the reference, for scale).

Writes friction_speed.csv (case, method, mu, n_events, median_s, min_s, cpu_s, setup_s,
energy_balance_error, target_s, met) and friction_machine.csv (machine, versions, load).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import machine_rows, write_rows  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.models.discrete import DiscreteFrictionParams  # noqa: E402
from reduced.transient.friction_tables import friction_modal_table, friction_table  # noqa: E402
from reduced.transient.integrate import ringdown  # noqa: E402

FS = 20000.0  # Hz, the scene's output rate
DURATION_S = 2.0  # s, the scene's run
TARGET_S = 0.1  # s, the target for the scene's ringdown
STARTS = {"scene": [0.0, 0.0, 0.3, 0.2], "fig3-right+axial": [0.0, 0.0, 200.0, 0.2]}  # m/s at x1, x2, x3, u


def timed(fn, repeats: int) -> tuple[float, float, float, object]:
    """(median wall s, min wall s, median CPU s, last result) of ``repeats`` calls after one untimed call."""
    out = fn()
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.min(wall)), float(np.median(cpu)), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", default=str(ROOT / "results" / "friction-speed"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with single_thread_blas():
        for start, v0 in STARTS.items():
            for mu in (0.3, 0.0):
                system = DiscreteFrictionParams(mu=mu).system()
                setup = float("nan")
                if mu > 0:
                    setup = timed(lambda s=system: friction_modal_table(s, friction_table(s, s.omega_max())),
                                  args.repeats)[0]
                for method in ("exact", "explicit"):
                    med, best, cpu, r = timed(lambda s=system, v=v0, m=method: ringdown(
                        s, np.zeros(4), v, DURATION_S, FS, m), args.repeats)
                    rows.append({"case": start, "method": method, "mu": mu,
                                 "n_events": r.stats.get("n_events", ""), "median_s": med, "min_s": best,
                                 "cpu_s": cpu, "setup_s": setup if method == "exact" else float("nan"),
                                 "energy_balance_error": r.energy_balance_error,
                                 "target_s": TARGET_S if (start, method, mu) == ("scene", "exact", 0.3) else "",
                                 "met": (med < TARGET_S) if (start, method, mu) == ("scene", "exact", 0.3) else ""})
                    print(rows[-1], flush=True)
        system = DiscreteFrictionParams().system()
        t0, c0 = time.perf_counter(), time.process_time()
        r = ringdown(system, np.zeros(4), STARTS["scene"], DURATION_S, FS, "dop853")
        rows.append({"case": "scene", "method": "dop853 (restarted at every state change)", "mu": 0.3,
                     "n_events": r.stats["n_events"], "median_s": time.perf_counter() - t0,
                     "min_s": float("nan"), "cpu_s": time.process_time() - c0, "setup_s": float("nan"),
                     "energy_balance_error": r.energy_balance_error, "target_s": "", "met": ""})
        print(rows[-1], flush=True)
    write_rows(out / "friction_speed.csv", rows, float_format=".4g")
    write_rows(out / "friction_machine.csv", machine_rows(repeats=args.repeats))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
