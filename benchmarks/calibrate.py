"""Calibrate the open parameters of the assembly model to Table 2 (fem.calibrate).

    python benchmarks/calibrate.py [--element-size 0.08] [--out results/assembly-modal]

Writes ``calibration.csv`` (parameter, initial, fitted, bounds), ``calibration_sensitivity.csv``
(d ln f / d ln p at the optimum), ``calibration_history.csv`` and prints the fitted values to
copy into the defaults of fem.model.AssemblyModel.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fem.analysis import analyse  # noqa: E402
from fem.calibrate import DEFAULT_PARAMETERS, calibrate  # noqa: E402
from fem.labels import TABLE2_ORDER  # noqa: E402
from fem.model import AssemblyModel  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--element-size", type=float, default=0.08, help="m, mesh used while fitting")
    ap.add_argument("--out", default="results/assembly-modal")
    ap.add_argument("--max-nfev", type=int, default=80)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = dataclasses.replace(AssemblyModel(), element_size=args.element_size)

    def evaluate(m: AssemblyModel):
        return analyse(m, n_modes=13, shift_hz=1.0).table2_freq()

    t0 = time.perf_counter()
    res = calibrate(start, evaluate, max_nfev=args.max_nfev, log=lambda s: print(s, flush=True))
    with open(out / "calibration.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["parameter", "initial", "fitted", "lower", "upper"])
        for n, a, b in zip(res.names, res.initial, res.fitted, strict=True):
            w.writerow([n, f"{a:.6g}", f"{b:.6g}", *DEFAULT_PARAMETERS[n]])
        w.writerow([])
        w.writerow(["mode", "freq_hz", "test_hz", "error_pct"])
        for n, f, t, e in zip(TABLE2_ORDER, res.freq_hz, res.test_hz, res.error_pct, strict=True):
            w.writerow([n, f"{f:.4f}", t, f"{e:.3f}"])
        w.writerow([])
        w.writerow(["element_size_m", args.element_size, "evaluations", res.n_evaluations,
                    "wall_time_s", f"{time.perf_counter() - t0:.0f}", "status", res.status])
    with open(out / "calibration_sensitivity.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["mode", *[f"dlnf/dln_{n}" for n in res.names]])
        for n, row in zip(TABLE2_ORDER, res.sensitivity, strict=True):
            w.writerow([n, *[f"{v:.4f}" for v in row]])
    with open(out / "calibration_history.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["eval", *res.names, *[f"{n}_hz" for n in TABLE2_ORDER]])
        for i, (p, f) in enumerate(res.history):
            w.writerow([i + 1, *[f"{v:.6g}" for v in p], *[f"{v:.4f}" for v in f]])
    print("fitted:", {n: round(float(v), 6) for n, v in zip(res.names, res.fitted, strict=True)})
    print("errors %:", dict(zip(TABLE2_ORDER, res.error_pct.round(2), strict=True)), res.message)
    return 0


if __name__ == "__main__":
    sys.exit(main())
