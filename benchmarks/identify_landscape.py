"""The misfit landscape of the identification's residual blocks (issue 26): which measures are smooth
enough in gap, contact stiffness and damping to fit by least squares.

A virtual test of the built-in ``hammer-test`` apparatus (500 N, 2 s at 20 kHz, 120 modes) with other
parameters (gap 3.0e-4 m, k_g 5e7 N/m, c_points 5 N s/m: 1.18x, 1.43x, 1.25x the scene's) and 2 % noise
through the DAQ filter is fitted by nothing here: the model is run on lines through the true values (each
parameter alone, ln steps of 0.05 over +-0.5, the Jacobian's step) and on a gap x k_g grid, and each
residual block's mean square (``bearingshaft.identify.residuals``, the target fixed at the true values:
floors, horizon, spans) is written per point.

    python benchmarks/identify_landscape.py [--workers 2] [--quick]

writes results/identify-landscape/landscape.csv, landscape_lines.png, landscape_grid.png and README.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUT = ROOT / "results" / "identify-landscape"
TRUTH = {"model.gap": 3.0e-4, "model.k_g": 5.0e7, "model.c_points": 5.0}
NOISE = 0.02
ALL = ("time", "envelope", "decay", "ridges", "impacts", "open")


def run_point(problem, target, theta):
    """Every block's mean square at theta (one model run)."""
    from bearingshaft.identify.problem import model_channels, record_at
    from bearingshaft.identify.residuals import blocks

    rig, rec = record_at(problem, theta)
    found = blocks(target, model_channels(problem, rig, rec))
    return {m: float(np.mean(found[m] ** 2)) if found[m].size else float("nan") for m in found}


def setup(test_file: Path):
    from bearingshaft import measured
    from bearingshaft.identify.parameters import parameters_of
    from bearingshaft.identify.problem import define_target, make_problem
    from bearingshaft.identify.virtual import scene_rig, write_virtual_test
    from bearingshaft.scenes import load_scene, parse_scene

    scene = parse_scene(load_scene("hammer-test").source + "\n[identify]\n", "hammer-test", "landscape")
    rom = scene.model.reduced(False)
    if not test_file.exists():
        write_virtual_test(test_file, scene, rom, TRUTH, NOISE, seed=1)
    test = measured.read_test(scene, str(test_file))
    params = parameters_of(scene)
    rig = scene_rig(scene, rom)
    names = tuple(c.name for c in rig.channels if c.quantity != "force")
    problem = make_problem(scene, rom, rig, test, params, (0.0, scene.ringdown.duration_s), names)
    truth = np.array([p.theta(TRUTH[p.key]) for p in params])
    target, _ = define_target(problem, truth, ALL, envelope_window_s=0.05, frame_s=0.05, fmax_hz=1000.0)
    return problem, target, truth, params


def points(truth, quick: bool):
    out = []
    steps = np.arange(-0.5, 0.5001, 0.1 if quick else 0.05)
    for j in range(3):
        for s in steps:
            d = np.zeros(3)
            d[j] = s
            out.append((f"line_{j}", truth + d))
    grid = np.arange(-0.5, 0.5001, 0.25 if quick else 0.1)
    for a in grid:
        for b in grid:
            out.append(("grid", truth + np.array([a, b, 0.0])))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    from bearingshaft.output import write_rows
    from bearingshaft.sweep.run import _warm_up, dask_client

    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    problem, target, truth, params = setup(Path("/tmp") / "identify_landscape_test.uff")
    pts = points(truth, args.quick)
    rows = []
    with dask_client(None, args.workers) as (client, where):
        client.run(_warm_up)
        fp = client.scatter(problem, broadcast=True, hash=False)
        ft = client.scatter(target, broadcast=True, hash=False)
        futs = [client.submit(run_point, fp, ft, th, pure=False) for _, th in pts]
        for (kind, th), f in zip(pts, futs, strict=True):
            ms = f.result()
            row = {"set": kind, **{p.key: p.value(t) for p, t in zip(params, th, strict=True)},
                   **{f"dln_{p.name}": round(float(t - u), 6) for p, t, u in zip(params, th, truth, strict=True)},
                   **{f"ms_{m}": ms.get(m, float("nan")) for m in ALL}}
            rows.append(row)
            print(kind, [round(float(t - u), 3) for t, u in zip(th, truth, strict=True)],
                  {m: round(v, 4) for m, v in ms.items()}, flush=True)
    write_rows(OUT / "landscape.csv", rows)
    hz = target.horizon
    (OUT / "target.txt").write_text(
        f"time span {target.time_span_s}, horizon {hz.horizon_s if hz else None}, free decay from "
        f"{target.free_decay_s}, post {target.post_s}\n{hz.note if hz else ''}\nwall {time.perf_counter() - t0:.0f} s "
        f"on {where}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
