"""Hill's method in the fep study (issue 28): every point by QZ (before) against QZ only where stability.csv
writes the multipliers and the screened verdict elsewhere (:func:`reduced.periodic.stability.hill_screened`).

    PYTHONPATH=. python benchmarks/fep_hill_speed.py [--scene discrete-fep] [--repeats 3]

Builds the drawn branches of the scene (each H of ``[fep] harmonics``, every followed NNM), then runs the
two paths interleaved in this process, ``--repeats`` times each, and prints the median CPU and wall time of
each, their ratio, whether the verdicts (every point) and the written multipliers (the points nearest the
shooting energies) are the same bits, and the largest |max |mu|_standard - max |mu|_qz| over every point.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bearingshaft.scenes.parse import load_scene  # noqa: E402
from bearingshaft.stages import nnm_fep  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.periodic.backbones import nnm_branch  # noqa: E402
from reduced.periodic.stability import hill  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="discrete-fep")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    scene = load_scene(a.scene)
    spec = scene.fep
    fm = nnm_fep.fep_model(scene)
    with single_thread_blas():
        jobs = []
        for mode in range(len(fm.modes)):
            b1 = nnm_branch(fm.system, fm.modes[mode], H=1, energy_max_J=spec.energy_max_J, **fm.branch)
            energies = nnm_fep._shooting_energies(spec, [b1])
            for H in spec.harmonics:
                b = b1 if H == 1 else nnm_branch(fm.system, fm.modes[mode], H=H, energy_max_J=spec.energy_max_J,
                                                 backbone1=b1.branches[0].y, **fm.branch)
                jobs.append((b, energies))
        n_points = sum(len(b.energy_J) for b, _ in jobs)

        def old():
            return [[hill(b.residual.hb, b.X[i], b.omega[i], **fm.hill) for i in range(len(b.energy_J))]
                    for b, _ in jobs]

        def new():
            return [nnm_fep._piece(("hill", fm, spec, 0, b, E)) for b, E in jobs]

        times = {"old": [], "new": []}
        for _ in range(a.repeats):
            for name, fn in (("old", old), ("new", new)):
                c, w = time.process_time(), time.perf_counter()
                out = fn()
                times[name].append((time.process_time() - c, time.perf_counter() - w))
                if name == "old":
                    ref = out
                else:
                    got = out
    same_verdicts = all(h.stable == g.stable for rs, gs in zip(ref, got, strict=True)
                        for h, g in zip(rs, gs, strict=True))
    same_written = all(ref[k][i].max_multiplier == got[k][i].max_multiplier
                       for k, (b, E) in enumerate(jobs) for i in nnm_fep._nearest_points(b, E))
    diff = max(abs(h.max_multiplier - hill(b.residual.hb, b.X[i], b.omega[i], solver="shift-invert").max_multiplier)
               for (b, _), rs in zip(jobs, ref, strict=True) for i, h in enumerate(rs))
    med = {k: np.median(np.array(v), axis=0) for k, v in times.items()}
    print(f"{a.scene}: {len(jobs)} branches, {n_points} points, {a.repeats} repeats interleaved")
    for k in ("old", "new"):
        print(f"  {k}: cpu {med[k][0]:.2f} s, wall {med[k][1]:.2f} s")
    print(f"  ratio old/new: cpu {med['old'][0] / med['new'][0]:.2f}, wall {med['old'][1] / med['new'][1]:.2f}")
    print(f"  same verdicts: {same_verdicts}; same written multipliers: {same_written}; "
          f"max |mu_shift-invert - mu_qz| over every point: {diff:.3g}")


if __name__ == "__main__":
    main()
