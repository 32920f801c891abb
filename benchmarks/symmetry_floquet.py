"""Why the symmetric ringdown v(0) = [0, 200, 0] m/s loses its symmetry (paper, Fig. 4).

Three measurements, written to results/discrete-fep/symmetry.csv and symmetry_*.csv:

1. the exact event-driven ringdown (damped, Table 1) and |x1 - x3|(t): its log slope
   over 50 ms windows is the *measured* growth rate of the asymmetry;
2. the transverse Lyapunov exponent along the same motion kept exactly symmetric: the
   state is symmetrised every 0.5 ms and an antisymmetric perturbation is carried by the
   exact tangent flow (products of segment exponentials, reduced.transient.flow); its log growth
   over the same windows is the *predicted* rate at which round-off asymmetry grows;
3. Floquet multipliers of the symmetric NNMs (1 and 3) by shooting at energies along the
   ringdown, with the symmetry class of the eigenvector of the largest multiplier: the
   growth rate ln|mu_max| / T of the orbits the motion is made of.

Run: python benchmarks/symmetry_floquet.py [out_dir]   (about 20 s on one core)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from bearingshaft.output import write_rows
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.periodic.shooting import floquet_scan, mirror_mode
from reduced.transient.exact import integrate_exact
from reduced.transient.flow import Flow

DURATION_S = 2.0
RATE_HZ = 20000.0
CHUNK_S = 5e-4  # symmetrisation interval of the reference trajectory
WINDOW_S = 0.05  # window of the growth-rate fits
BREAK_M = 1e-6  # m, |x1 - x3| that counts as broken symmetry (0.4 % of the gap, ~1e-4 of the motion)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0] if argv else "results/discrete-fep")
    out.mkdir(parents=True, exist_ok=True)
    p = DiscreteParams()
    system = p.system()
    x0 = np.zeros(3)
    v0 = np.array([0.0, 200.0, 0.0])
    t0 = time.perf_counter()

    # 1. the ringdown and its asymmetry
    r = integrate_exact(system, x0, v0, DURATION_S, RATE_HZ)
    asym = np.abs(r.x[:, 0] - r.x[:, 2])
    scale = np.max(np.abs(r.x[:, [0, 2]]), axis=1)
    energy = r.energy

    # 2. transverse Lyapunov exponent along the symmetrised motion (damped flow)
    flow = Flow(system)
    y = np.concatenate([x0, v0])
    w_ref = flow.system.omega_max()
    d = np.array([1.0, 0.0, -1.0, 0.0, 0.0, 0.0]) / np.sqrt(2.0)  # antisymmetric displacement
    log_growth = [0.0]
    t_chunks = [0.0]
    n_chunks = int(round(DURATION_S / CHUNK_S))
    acc = 0.0
    with single_thread_blas():
        for _ in range(n_chunks):
            fl = flow(y[:3], y[3:], CHUNK_S, jacobian=True)
            y = fl.y.copy()
            y[0] = y[2] = 0.5 * (y[0] + y[2])  # keep the reference exactly symmetric
            y[3] = y[5] = 0.5 * (y[3] + y[5])
            d = fl.jacobian @ d
            # norm in [x omega_ref, v]: the same weight for displacement and velocity
            nrm = float(np.hypot(np.linalg.norm(d[:3]) * w_ref, np.linalg.norm(d[3:])))
            acc += np.log(nrm)
            d /= nrm
            log_growth.append(acc)
            t_chunks.append(t_chunks[-1] + CHUNK_S)
    t_chunks = np.array(t_chunks)
    log_growth = np.array(log_growth)

    # windowed rates
    rows = []
    tw = np.arange(0.0, DURATION_S - WINDOW_S + 1e-12, WINDOW_S)
    for ta in tw:
        tb = ta + WINDOW_S
        i = (r.t >= ta) & (r.t < tb)
        a_lo = np.max(asym[(r.t >= ta) & (r.t < ta + 0.01)])
        a_hi = np.max(asym[(r.t >= tb - 0.01) & (r.t < tb)])
        measured = np.log(a_hi / a_lo) / (WINDOW_S - 0.01) if a_lo > 0 and a_hi > 0 else np.nan
        ja, jb = np.minimum(np.searchsorted(t_chunks, [ta, tb]), t_chunks.size - 1)
        predicted = (log_growth[jb] - log_growth[ja]) / (t_chunks[jb] - t_chunks[ja])
        rows.append(
            {
                "t_start_s": round(ta, 4),
                "energy_J": float(np.mean(energy[i])),
                "asymmetry_m": float(np.max(asym[i])),
                "asymmetry_rel": float(np.max(asym[i] / scale[i])),
                "growth_measured_1_s": float(measured),
                "transverse_lyapunov_1_s": float(predicted),
            }
        )
    write_rows(out / "symmetry_growth.csv", rows)

    # 3. Floquet multipliers of NNM 1 and 3 at energies along the ringdown
    frows = []
    energies = np.logspace(1, np.log10(3e4), 25)
    for mode, orbits in floquet_scan(system, (0, 2), energies).items():
        for o in orbits:
            if o is None:
                continue
            frows.append(
                {
                    "nnm": mode + 1,
                    "energy_J": float(o.energy_J),
                    "freq_hz": o.freq_hz,
                    "max_abs_mu": o.max_multiplier,
                    "stable": int(o.stable),
                    "growth_1_s": float(np.log(o.max_multiplier) * o.freq_hz),
                    "eigvec": mirror_mode(o),
                }
            )
    write_rows(out / "symmetry_floquet.csv", frows)

    # the break: first time |x1 - x3| exceeds the solver tolerance, and BREAK_M
    i_tol = int(np.argmax(asym > r.tolerance)) if np.any(asym > r.tolerance) else -1
    big = asym > BREAK_M
    i_rel = int(np.argmax(big)) if np.any(big) else -1
    summary = {
        "solver_tolerance_m": r.tolerance,
        "t_break_tolerance_s": float(r.t[i_tol]) if i_tol >= 0 else np.nan,
        "t_break_s": float(r.t[i_rel]) if i_rel >= 0 else np.nan,
        "energy_at_break_J": float(energy[i_rel]) if i_rel >= 0 else np.nan,
        "total_log_growth_transverse_0_to_break": float(np.interp(r.t[i_rel], t_chunks, log_growth))
        if i_rel >= 0
        else np.nan,
        "asymmetry_at_0.05s_m": float(np.max(asym[r.t < 0.05])),
        "wall_s": time.perf_counter() - t0,
    }
    # cumulative growth: measured ln(asym(t) / asym(t0)) against the transverse exponent's
    crow = []
    a0 = float(np.max(asym[(r.t >= 0.04) & (r.t < 0.05)]))
    for tc in np.arange(0.1, 1.01, 0.1):
        m = (r.t >= tc - 0.01) & (r.t < tc)
        crow.append(
            {
                "t_s": round(tc, 2),
                "energy_J": float(np.mean(energy[m])),
                "ln_asym_growth_measured": float(np.log(np.max(asym[m]) / a0)),
                "ln_growth_transverse": float(
                    np.interp(tc, t_chunks, log_growth) - np.interp(0.05, t_chunks, log_growth)
                ),
            }
        )
    write_rows(out / "symmetry_cumulative.csv", crow)
    # seeded asymmetry: the same instability must amplify a deliberate seed, breaking
    # symmetry earlier by the time the transverse growth needs to cover the head start
    seeds = []
    for seed in (1e-12, 1e-10, 1e-8):
        rs_ = integrate_exact(system, np.array([seed, 0.0, 0.0]), v0, 1.2, RATE_HZ)
        a_ = np.abs(rs_.x[:, 0] - rs_.x[:, 2])
        b_ = a_ > BREAK_M
        tb_ = float(rs_.t[int(np.argmax(b_))]) if np.any(b_) else np.nan
        seeds.append(
            {
                "seed_m": seed,
                "t_break_s": tb_,
                "ln_head_start": float(np.log(seed / summary["asymmetry_at_0.05s_m"])),
            }
        )
    write_rows(out / "symmetry_seeds.csv", seeds)
    print("seeded asymmetry (seed, t_break, ln head start):")
    for sd in seeds:
        print(f"  {sd['seed_m']:.0e}  {sd['t_break_s']:.4f}  {sd['ln_head_start']:.2f}")
    write_rows(out / "symmetry_summary.csv", [summary])
    print("cumulative log growth from t = 0.05 s (t, E, measured, transverse):")
    for c in crow:
        print(
            f"  {c['t_s']:.1f}  {c['energy_J']:8.1f}  {c['ln_asym_growth_measured']:7.2f}  "
            f"{c['ln_growth_transverse']:7.2f}"
        )
    for k, v in summary.items():
        print(f"{k}: {v}")
    print("window rates (t, E, asym, measured, transverse):")
    for row in rows[::2]:
        print(
            f"  {row['t_start_s']:.2f}  {row['energy_J']:9.1f}  {row['asymmetry_m']:.2e}  "
            f"{row['growth_measured_1_s']:8.2f}  {row['transverse_lyapunov_1_s']:8.2f}"
        )
    print("Floquet (nnm, E, f, |mu|max, growth 1/s, eigvec):")
    for fr in frows:
        print(
            f"  {fr['nnm']}  {fr['energy_J']:9.1f}  {fr['freq_hz']:7.2f}  {fr['max_abs_mu']:9.4f}  "
            f"{fr['growth_1_s']:8.2f}  {fr['eigvec']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
