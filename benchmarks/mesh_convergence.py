"""Mesh convergence and element-order study of the six pseudo-rigid modes (issue 4, item 6).

    python benchmarks/mesh_convergence.py [--out results/assembly-modal]

For each mesh: the six Table 2 frequencies, the first elastic mode of the assembly (where
element order and locking show), DOFs and wall time of mesh, assembly and eigensolution.
Richardson extrapolation over the three finest hex20 meshes (h ~ n_dofs^(-1/3)); when the
differences sit below the solver noise (~1e-6) the theoretical order 4 (eigenvalue error
O(h^2p), p = 2) is used. The default mesh is the cheapest hex20 mesh whose six frequencies
are all within 0.5 % of the extrapolated ones (cheapest: fewest DOFs; the wall times are
written too). Writes mesh_convergence.csv and .png.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fem.analysis import analyse  # noqa: E402
from fem.labels import TABLE2_ORDER  # noqa: E402
from fem.model import AssemblyModel  # noqa: E402

SIZES = (0.3, 0.08, 0.04, 0.025, 0.016, 0.012)  # m, target element edge
ORDER_STUDY = (("hex8", 0.3), ("hex8", 0.025), ("hex27", 0.3), ("hex27", 0.08))
NOISE = 2e-6  # relative: below this a frequency difference is solver noise
TOLERANCE = 0.005  # the default mesh is within 0.5 % of the extrapolated frequencies


def richardson(h: np.ndarray, f: np.ndarray) -> tuple[float, float]:
    """(f_inf, p) from the three finest meshes: f = f_inf + C h^p."""
    (h1, h2, h3), (f1, f2, f3) = h[-3:], f[-3:]
    d12, d23 = f1 - f2, f2 - f3
    p = 4.0
    if abs(d23) > NOISE * abs(f3) and abs(d12) > NOISE * abs(f3) and d12 * d23 > 0:
        r = np.log(h1 / h2)  # the ratios are close enough to constant for this estimate
        p = float(np.clip(np.log(d12 / d23) / r, 0.5, 8.0))
    f_inf = f3 + (f3 - f2) / ((h2 / h3) ** p - 1.0)
    return float(f_inf), p


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/assembly-modal")
    ap.add_argument("--sizes", type=float, nargs="*", default=SIZES)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = AssemblyModel()
    rows = []
    runs = [("hex20", h) for h in args.sizes] + list(ORDER_STUDY)
    for element, h in runs:
        m = dataclasses.replace(base, element=element, element_size=h)
        t0 = time.perf_counter()
        a = analyse(m, n_modes=14, shift_hz=1.0)
        f = a.table2_freq()
        row = {"element": element, "element_size_m": h, "n_dofs": a.system.n_dofs,
               "n_cells": len(a.system.mesh.hexes),
               **{f"{n}_hz": float(v) for n, v in zip(TABLE2_ORDER, f, strict=True)},
               "first_elastic_hz": float(a.modes.freq_hz[12]),
               "mesh_s": a.timing["mesh_s"], "assembly_s": a.timing["assembly_s"],
               "eigensolution_s": a.timing["eigensolution_s"], "total_s": time.perf_counter() - t0}
        rows.append(row)
        print(f"{element} h={h:.3f} dofs={row['n_dofs']} " + " ".join(f"{v:.5f}" for v in f)
              + f" elastic={row['first_elastic_hz']:.2f} t={row['total_s']:.1f}s", flush=True)
    hexs = sorted([r for r in rows if r["element"] == "hex20"], key=lambda r: r["n_dofs"])
    hh = np.array([r["n_dofs"] for r in hexs], float) ** (-1.0 / 3.0)
    ext, order = {}, {}
    for n in [*TABLE2_ORDER, "first_elastic"]:
        ext[n], order[n] = richardson(hh, np.array([r[f"{n}_hz"] for r in hexs]))
    for r in rows:
        errs = [abs(r[f"{n}_hz"] - ext[n]) / ext[n] for n in TABLE2_ORDER]
        r["max_error_pct"] = 100 * max(errs)
        fe = ext["first_elastic"]
        r["first_elastic_error_pct"] = 100 * (r["first_elastic_hz"] - fe) / fe
    ok = [r for r in hexs if r["max_error_pct"] < 100 * TOLERANCE]
    # cheapest = fewest DOFs: deterministic, and the wall times of neighbouring coarse meshes
    # differ by less than their run-to-run noise on a shared machine
    default = min(ok, key=lambda r: r["n_dofs"]) if ok else None
    cols = list(rows[0])
    with open(out / "mesh_convergence.csv", "w", newline="") as fh:
        fh.write("# Richardson-extrapolated (hex20, 3 finest meshes): "
                 + ", ".join(f"{n} {ext[n]:.6f} Hz (p={order[n]:.2f})" for n in ext) + "\n")
        if default is not None:
            fh.write(f"# default mesh: hex20, element_size {default['element_size_m']} m "
                     f"({default['n_dofs']} DOFs), max error {default['max_error_pct']:.2e} %\n")
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for element, marker in (("hex20", "o-"), ("hex8", "s--"), ("hex27", "^:")):
        rs = sorted([r for r in rows if r["element"] == element], key=lambda r: r["n_dofs"])
        if not rs:
            continue
        d = [r["n_dofs"] for r in rs]
        t = [r["total_s"] for r in rs]
        for n in TABLE2_ORDER:
            e = [max(abs(r[f"{n}_hz"] - ext[n]) / ext[n], 1e-9) for r in rs]
            axes[0].loglog(d, e, marker, label=f"{element} {n}" if element == "hex20" else None, alpha=0.8)
        e = [max(abs(r["first_elastic_error_pct"]) / 100, 1e-9) for r in rs]
        axes[1].loglog(t, e, marker, color="k", label=f"{element}: first elastic mode")
        e6 = [max(r["max_error_pct"] / 100, 1e-9) for r in rs]
        axes[1].loglog(t, e6, marker, color="tab:red", label=f"{element}: worst of the six")
    axes[0].axhline(TOLERANCE, color="grey", lw=0.8)
    axes[0].set_xlabel("DOFs")
    axes[0].set_ylabel("relative error against Richardson extrapolation")
    axes[0].set_title("six pseudo-rigid modes (below 1e-6: solver noise)")
    axes[0].legend(fontsize=7)
    axes[1].axhline(TOLERANCE, color="grey", lw=0.8)
    axes[1].set_xlabel("wall time: mesh + assembly + eigensolution (s)")
    axes[1].set_title("error against run time")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "mesh_convergence.png", dpi=120)
    if default is not None:
        print(f"default mesh: element_size {default['element_size_m']} m, {default['n_dofs']} DOFs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
