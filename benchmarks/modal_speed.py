"""Speed of the eigen-solution pipeline against the plain SciPy baseline (issue 4, item 7).

    python benchmarks/modal_speed.py [--sizes 0.3 0.012] [--out results/assembly-modal]

Both pipelines start from the same gmsh mesh and compute the same modes:

- baseline: scikit-fem's ``asm`` over all elements, then ``scipy.sparse.linalg.eigsh(K,
  M=M, sigma=sigma)``, which factorizes K - sigma M with SuperLU and runs ARPACK;
- ours: shape-cached assembly (fem.solid), MKL PARDISO Cholesky (pypardiso) and block
  subspace iteration (fem.modal).

Writes modal_speed.csv: the time of each step, the speed-up and the largest relative
difference between the two sets of frequencies.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bearingshaft.output import write_rows  # noqa: E402
from fem.modal import baseline_modal, modal_analysis  # noqa: E402
from fem.model import AssemblyModel, build_system  # noqa: E402
from geometry.build import build_mesh  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="*", default=[0.3, 0.012])
    ap.add_argument("--n-modes", type=int, default=16)
    ap.add_argument("--out", default="results/assembly-modal")
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows = []
    for h in args.sizes:
        model = dataclasses.replace(AssemblyModel(), element_size=h)
        t0 = time.perf_counter()
        mesh = build_mesh(model.geometry())
        t_mesh = time.perf_counter() - t0
        res = {}
        for name, method in (("ours", "cached"), ("baseline", "skfem")):
            t0 = time.perf_counter()
            system = build_system(model, method=method, mesh=mesh)
            t_asm = time.perf_counter() - t0
            t0 = time.perf_counter()
            if name == "ours":
                r = modal_analysis(system.K, system.M, n_modes=args.n_modes, shift_hz=1.0, solver="pardiso")
                fac, it = r.timing["factorize_s"], r.timing["iterate_s"]
            else:
                r = baseline_modal(system.K, system.M, n_modes=args.n_modes, shift_hz=1.0)
                fac, it = float("nan"), float("nan")
            t_eig = time.perf_counter() - t0
            res[name] = r
            rows.append({"element_size_m": h, "n_dofs": system.n_dofs, "pipeline": name,
                         "solver": r.solver, "mesh_s": t_mesh, "assembly_s": t_asm, "factorize_s": fac,
                         "iterate_s": it, "eigensolution_s": t_eig, "total_s": t_mesh + t_asm + t_eig})
            print(rows[-1], flush=True)
            del system
        fo, fb = res["ours"].freq_hz[6:], res["baseline"].freq_hz[6:]
        diff = float(np.max(np.abs(fo - fb) / fb))
        base, ours = rows[-1], rows[-2]
        for r in (ours, base):
            r["speedup_total"] = base["total_s"] / ours["total_s"]
            r["speedup_assembly_plus_eigen"] = (base["assembly_s"] + base["eigensolution_s"]) / (
                ours["assembly_s"] + ours["eigensolution_s"])
            r["max_rel_freq_diff"] = diff
    out.mkdir(parents=True, exist_ok=True)
    write_rows(out / "modal_speed.csv", rows, float_format=".4g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
