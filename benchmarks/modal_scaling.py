"""Time and peak memory of the modal pipeline against the number of DOFs (issue 14).

    python benchmarks/modal_scaling.py [--sizes 0.3 0.02 0.012 0.008 0.006 0.005 0.004 0.00335 0.003]
                                       [--cap-gib 22] [--headroom 0.8] [--out results/performance]

For each element size of the apparatus (hex20, 16 modes), the DOFs and the peak memory are
estimated from the geometry before anything is meshed (fem._modal_cost, the estimate
``bearingshaft check`` uses); a size whose estimate exceeds ``--cap-gib`` or ``--headroom`` (the
tool's own 80 % by default) of the memory available now is refused with its estimate and not
meshed. Every other size runs in its own
process (so that its peak RSS is its own): mesh, assembly, factorization, Krylov iteration,
the largest relative residual and its ratio to the round-off floor, PARDISO's own peak.

Writes ``modal_scaling.csv`` (one row per size, measured peak beside the estimate) and
``modal_scaling.png`` (log-log time and memory against DOFs with the fitted exponents).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.budget import HEADROOM, available_bytes  # noqa: E402
from bearingshaft.output import machine_rows, write_rows  # noqa: E402
from fem._modal_cost import count_dofs, modal_bytes  # noqa: E402
from fem.model import AssemblyModel  # noqa: E402

GIB = 2**30


def child(h: float, n_modes: int) -> dict:
    """One size, in this process: the numbers of a row."""
    import resource

    from fem.modal import modal_analysis
    from fem.model import build_system
    from geometry.build import build_mesh

    model = dataclasses.replace(AssemblyModel(), element_size=h)
    load0 = os.getloadavg()[0]
    c0 = time.process_time()
    mesh = build_mesh(model.geometry())
    t0 = time.perf_counter()
    system = build_system(model, mesh=mesh)
    t_asm = time.perf_counter() - t0
    K, M = system.K, system.M
    del system
    t0 = time.perf_counter()
    r = modal_analysis(K, M, n_modes=n_modes, shift_hz=1.0)
    t_eig = time.perf_counter() - t0
    return {"n_dofs": K.shape[0], "nnz": K.nnz, "mesh_s": mesh.wall_time_s, "assembly_s": t_asm,
            "factorize_s": r.timing["factorize_s"], "iterate_s": r.timing["iterate_s"], "eigensolution_s": t_eig,
            "total_s": mesh.wall_time_s + t_asm + t_eig, "cpu_s": time.process_time() - c0, "n_op": r.n_op,
            "steps": r.n_iter, "threads": r.stats.get("n_threads", 1),
            "factor_peak_gib": r.stats.get("peak_factor_kib", 0) * 1024 / GIB,
            "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / GIB,
            "max_residual": float(r.residuals.max()),
            "max_elastic_residual": float(r.residuals[r.freq_hz > 100].max()),
            "max_residual_over_floor": float((r.residuals / r.floors).max()),
            "all_converged": bool(r.converged.all()), "f16_hz": float(r.freq_hz[-1]),
            "load_before": load0, "load_after": os.getloadavg()[0]}


def _num(v: str):
    try:
        return float(v)
    except ValueError:
        return v


def _fit(x, y) -> tuple[float, float]:
    """(exponent, coefficient) of y = c x^p by least squares in log-log."""
    p, c = np.polyfit(np.log(x), np.log(y), 1)
    return float(p), float(np.exp(c))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="*",
                    default=[0.3, 0.02, 0.012, 0.008, 0.006, 0.005, 0.004, 0.00335, 0.003])
    ap.add_argument("--n-modes", type=int, default=16)
    ap.add_argument("--cap-gib", type=float, default=22.0)
    ap.add_argument("--headroom", type=float, default=HEADROOM,
                    help="fraction of the available memory a run may plan to use (the tool's own: %(default)s)")
    ap.add_argument("--out", default="results/performance")
    ap.add_argument("--plot-only", action="store_true", help="redraw the figure from modal_scaling.csv in --out")
    ap.add_argument("--child", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(args.child, args.n_modes)))
        return 0
    out = Path(args.out)
    if args.plot_only:
        import csv

        with open(out / "modal_scaling.csv") as fh:
            rows = [{k: _num(v) for k, v in r.items() if v != ""} for r in csv.DictReader(fh)]
        _plot([r for r in rows if r.get("status") == "ok"], rows, out / "modal_scaling.png")
        _headline([r for r in rows if r.get("status") == "ok"], rows, out)
        return 0
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for h in args.sizes:
        model = dataclasses.replace(AssemblyModel(), element_size=h)
        n = count_dofs(model.geometry(), model.element)
        est = modal_bytes(n, args.n_modes)
        cap = min(args.cap_gib * GIB, args.headroom * available_bytes())
        row = {"element_size_m": h, "n_dofs_estimated": n, "estimate_gib": est["total"] / GIB,
               "estimate_factor_gib": est["factor"] / GIB, "cap_gib": cap / GIB}
        if est["total"] > cap:
            row["status"] = (f"refused before meshing: estimate {est['total'] / GIB:.3g} GiB > {cap / GIB:.3g} GiB "
                             f"(factor {est['factor'] / GIB:.3g} GiB)")
            print(row, flush=True)
            rows.append(row)
            continue
        p = subprocess.run([sys.executable, __file__, "--child", str(h), "--n-modes", str(args.n_modes)],
                           capture_output=True, text=True, cwd=ROOT)
        if p.returncode != 0:
            row["status"] = f"failed: {p.stderr.strip().splitlines()[-1] if p.stderr.strip() else p.returncode}"
        else:
            row.update(json.loads(p.stdout.strip().splitlines()[-1]))
            row["status"] = "ok"
            row["measured_over_estimate"] = row["peak_rss_gib"] / row["estimate_gib"]
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
        rows.append(row)
        fields = list(dict.fromkeys(k for r in rows for k in r))
        write_rows(out / "modal_scaling.csv", rows, fields=fields, float_format=".4g")
    fields = list(dict.fromkeys(k for r in rows for k in r))
    write_rows(out / "modal_scaling.csv", rows, fields=fields, float_format=".4g")
    write_rows(out / "modal_scaling_machine.csv", machine_rows(headroom=args.headroom))
    ok = [r for r in rows if r.get("status") == "ok"]
    if len(ok) >= 2:
        _plot(ok, rows, out / "modal_scaling.png")
        _headline(ok, rows, out)
    return 0


def _headline(ok, rows, out: Path) -> None:
    """One row for the summary table: the largest mesh that ran, the exponents, the target."""
    n = np.array([r["n_dofs"] for r in ok], float)
    p_cpu, _ = _fit(n, [r["cpu_s"] for r in ok])
    p_mem, _ = _fit(n, [r["peak_rss_gib"] for r in ok])
    big = max(ok, key=lambda r: r["n_dofs"])
    refused = [r for r in rows if str(r.get("status", "")).startswith("refused")]
    write_rows(out / "modal_scaling_headline.csv", [{
        "what": f"FE modal scaling {int(n.min()):,}-{int(big['n_dofs']):,} DOFs (16 modes): CPU ~ n^{p_cpu:.2f}, "
                f"peak RSS ~ n^{p_mem:.2f}; largest run {int(big['n_dofs']):,} DOFs in {big['cpu_s']:.0f} s CPU, "
                f"{big['peak_rss_gib']:.1f} GiB (estimate {big['estimate_gib']:.1f} GiB)"
                + (f"; {int(min(r['n_dofs_estimated'] for r in refused)):,} DOFs refused before meshing"
                   if refused else ""),
        "ours_s": big["cpu_s"], "baseline": "", "baseline_s": "", "ratio": "",
        "error": max(r["max_residual_over_floor"] for r in ok),
        "target": ">= 1e6 DOFs within the memory cap (error: max residual / round-off floor)",
        "met": big["n_dofs"] >= 1e6}], float_format=".4g")


def _plot(ok, rows, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([r["n_dofs"] for r in ok], float)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for key, label, style in (("total_s", "wall, total", "o-"), ("cpu_s", "CPU, total", "o--"),
                              ("factorize_s", "wall, factorize", "^-"), ("iterate_s", "wall, iterate", "v-"),
                              ("assembly_s", "wall, assembly", "s-")):
        y = np.array([r[key] for r in ok])
        p, c = _fit(n, y)
        ax[0].loglog(n, y, style, label=f"{label}: ~ n^{p:.2f}")
    ax[0].set_xlabel("DOFs")
    ax[0].set_ylabel("time (s)")
    for a in ax:
        a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax[0].set_title(f"apparatus, hex20, 16 modes (load {np.mean([r['load_before'] for r in ok]):.1f} on 2 cores)")
    ax[0].legend()
    ax[0].grid(True, which="both", alpha=0.3)
    y = np.array([r["peak_rss_gib"] for r in ok])
    p, _ = _fit(n, y)
    ax[1].loglog(n, y, "o-", label=f"measured peak RSS: ~ n^{p:.2f}")
    ne = np.array([r["n_dofs_estimated"] for r in rows], float)
    ax[1].loglog(ne, [r["estimate_gib"] for r in rows], "s--", label="estimate before meshing (budget)")
    for r in rows:
        if r.get("status", "").startswith("refused"):
            ax[1].annotate("refused", (r["n_dofs_estimated"], r["estimate_gib"]), textcoords="offset points",
                           xytext=(-30, 6))
    ax[1].axhline(rows[0]["cap_gib"], color="k", lw=0.8, ls=":", label="cap")
    ax[1].set_xlabel("DOFs")
    ax[1].set_ylabel("GiB")
    ax[1].legend()
    ax[1].grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
