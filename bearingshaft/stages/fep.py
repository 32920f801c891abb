"""Frequency-energy plots of the NNMs by HB and shooting, their stability, HB convergence.

Called at the end of the nnm stage when the scene has an [fep] table. Writes

- ``fep.csv`` (nnm, method, harmonics, energy_J, freq_hz, stable) and ``fep.png``:
  HB backbones for each H of ``[fep] harmonics`` (stability by Hill's method) and the
  shooting orbits on the exact flow (stability by Floquet multipliers);
- ``stability.csv``: Hill against Floquet at each shooting energy, disagreements flagged;
- ``tongues.csv``: internal resonances met by the HB branches and what was done;
- ``hb_convergence.csv`` and ``hb_convergence.png``: HB frequency error against the exact
  NNM 2 relation and against shooting for each H (and AFT samples N at one H);
- ``hb_convergence_timing.csv`` (run time of each branch and of shooting) and
  ``hb_convergence_timing.png`` (error against run time): wall-clock times, which change
  with machine load, live only in files whose name ends in ``_timing`` (the project's
  convention, tests/test_reproducible.py), so a rerun reproduces every other file.

On another machine (other SIMD kernels in NumPy and OpenBLAS, so other last bits) the
continuation takes other steps: measured with OpenBLAS's Sandy Bridge kernels and NumPy's
AVX2/FMA paths disabled, fep.csv had 902 points instead of 905, one more shooting orbit
near NNM 1's tongues failed, tongue energies moved by up to 0.3 %, ``energy_reached_J``
(where the last step landed past ``energy_max_J``) by 2x and the maxima against shooting
over the tongue region by 30 %; the converged numbers agreed: HB against the exact NNM 2
relation to 5e-12 and against shooting above the last tongue to 4e-10 (relative). Writing
the backbones on a fixed energy grid would make the point sets machine-independent; the
path-dependent columns are reported as computed.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from tqdm import tqdm

from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from reduced._blas import single_thread_blas
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2
from reduced.periodic.backbones import START_FRACTION, hb_point_at_energy, nnm_branch
from reduced.periodic.hb import NewtonError
from reduced.periodic.shooting import conservative, shooting_branch
from reduced.periodic.stability import compare, hill
from reduced.transient.flow import Flow

GRAZING_BAND = 10.0  # "near grazing": energies below this many times the grazing energy


def _hb_at(b, E_q):
    """HB frequency at exactly the energies E_q (nan where no piece of the branch covers
    E_q or Newton fails): from the nearest point of a covering piece, corrected onto the
    energy by :func:`reduced.periodic.backbones.hb_point_at_energy`."""
    out = np.full(np.shape(E_q), np.nan)
    i_w = b.residual.hb.size
    for k, E in enumerate(E_q):
        if not np.isfinite(E):
            continue
        for seg in np.unique(b.segment):
            idx = np.flatnonzero(b.segment == seg)
            Es = b.energy_J[idx]
            if not Es.min() <= E <= Es.max():
                continue
            y0 = b.branches[seg].y[np.argmin(np.abs(np.log(Es / E)))]
            try:
                y = hb_point_at_energy(b.residual, y0, float(E))
            except NewtonError:
                continue
            if abs(y[i_w] / y0[i_w] - 1.0) < 0.05:  # stayed on this piece
                out[k] = y[i_w] * b.residual.omega_ref / (2 * np.pi)
                break
    return out


def fep_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Write fep.csv/png, stability.csv, tongues.csv, hb_convergence.csv/png (module docstring)."""
    with single_thread_blas():
        _fep_stage(scene, writer, progress)


def _fep_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    spec = scene.fep
    p = scene.model
    system = conservative(p.system())
    n = system.n
    flow = Flow(system)
    open_hz = linear_modes(system, "open").freq_hz
    closed_hz = linear_modes(system, "closed").freq_hz
    Hs = sorted(set(spec.harmonics) | set(spec.convergence_harmonics))
    hs_study = spec.samples_study_harmonics
    # the work list: (mode, H, N) branches; NNM 2 for every H (exact reference), all modes
    # for the H drawn in fep.png and for the convergence study up to H = 15
    jobs = []
    for H in Hs:
        for mode in range(n):
            if mode == 1 or H in spec.harmonics or H <= 15:
                jobs.append((mode, H, None))
    for N in spec.samples:
        jobs.append((1, hs_study, N))
    total = len(jobs) + 3 * n
    bar = tqdm(total=total, desc=f"{scene.name}: NNM backbones", disable=not progress, unit="branch")
    branches = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        for mode, H, N in jobs:
            bar.set_postfix_str(f"NNM {mode + 1}, H={H}" + (f", N={N}" if N else ""))
            branches[(mode, H, N)] = nnm_branch(system, mode, H=H, N=N, energy_max_J=spec.energy_max_J)
            bar.update()
        # shooting along each NNM, guided by the best complete HB branches
        shots = {}
        for mode in range(n):
            bar.set_postfix_str(f"shooting NNM {mode + 1}")
            guides = [branches[(mode, 1, None)]]
            hi = max(spec.harmonics)
            if branches[(mode, hi, None)].energy_J[-1] >= spec.energy_max_J:
                guides.insert(0, branches[(mode, hi, None)])
            E0 = guides[-1].energy_J[0]
            energies = np.logspace(np.log10(E0), np.log10(spec.energy_max_J), spec.n_shooting)
            t0 = time.perf_counter()
            shots[mode] = (energies, shooting_branch(flow, energies, guides), time.perf_counter() - t0)
            bar.update()
        # Hill's method on every HB point of the drawn branches
        hills = {}
        for mode in range(n):
            bar.set_postfix_str(f"Hill NNM {mode + 1}")
            for H in spec.harmonics:
                b = branches[(mode, H, None)]
                hills[(mode, H)] = [hill(b.residual.hb, b.X[i], b.omega[i]) for i in range(len(b.energy_J))]
            bar.update()
    bar.close()

    # -- fep.csv ------------------------------------------------------------------------
    rows = []
    for mode in range(n):
        for H in spec.harmonics:
            b = branches[(mode, H, None)]
            for i in range(len(b.energy_J)):
                rows.append(
                    {
                        "nnm": mode + 1,
                        "method": "hb",
                        "harmonics": H,
                        "energy_J": b.energy_J[i],
                        "freq_hz": b.freq_hz[i],
                        "stable": int(hills[(mode, H)][i].stable),
                    }
                )
        energies, orbits, _ = shots[mode]
        for _E, o in zip(energies, orbits, strict=True):
            if o is not None:
                rows.append(
                    {
                        "nnm": mode + 1,
                        "method": "shooting",
                        "harmonics": "",
                        "energy_J": o.energy_J,
                        "freq_hz": o.freq_hz,
                        "stable": int(o.stable),
                    }
                )
    write_rows(writer.path("fep.csv"), rows)

    # -- stability.csv: Hill (each drawn H) against Floquet at the shooting energies -------
    srows = []
    n_dis = {}
    for mode in range(n):
        energies, orbits, _ = shots[mode]
        fl_max = np.array([o.max_multiplier if o else np.nan for o in orbits])
        fl_st = np.array([o.stable if o else False for o in orbits])
        for H in spec.harmonics:
            b = branches[(mode, H, None)]
            hm = np.array([h.max_multiplier for h in hills[(mode, H)]])
            hs = np.array([h.stable for h in hills[(mode, H)]])
            # the HB point nearest in log energy (on the same piece of branch)
            idx = [int(np.argmin(np.abs(np.log(b.energy_J / E)))) for E in energies]
            near = np.array(
                [abs(np.log(b.energy_J[i] / E)) < 0.05 for i, E in zip(idx, energies, strict=True)]
            )
            cmp = compare(energies, np.where(near, fl_max, np.nan), fl_st, hm[idx], hs[idx])
            n_dis[f"NNM {mode + 1} H={H}"] = cmp.n_disagree
            for k, E in enumerate(energies):
                if not near[k] or orbits[k] is None:
                    continue
                srows.append(
                    {
                        "nnm": mode + 1,
                        "harmonics": H,
                        "energy_J": E,
                        "floquet_max_abs_mu": fl_max[k],
                        "hill_max_abs_mu": hm[idx[k]],
                        "floquet_stable": int(fl_st[k]),
                        "hill_stable": int(hs[idx[k]]),
                        "agree": int(cmp.agree[k]),
                    }
                )
    write_rows(writer.path("stability.csv"), srows)
    writer.stats["stability_disagreements"] = n_dis

    # -- tongues.csv ----------------------------------------------------------------------
    trows = []
    for (mode, H, _N), b in branches.items():
        for t in b.tongues:
            trows.append(
                {
                    "nnm": mode + 1,
                    "harmonics": H,
                    "samples": b.N,
                    "resonance": f"{t['harmonic']}:1",
                    "energy_J": t["energy_J"],
                    "freq_hz": t["freq_hz"],
                    "action": t["action"],
                    "energy_after_J": t.get("energy_after_J", ""),
                }
            )
    write_rows(writer.path("tongues.csv"), trows)

    # -- hb_convergence.csv -------------------------------------------------------------------
    # against shooting: at every exact orbit of the reference branch, the HB frequency
    # interpolated (PCHIP in log energy) within the piece of branch that covers it
    crow = []
    # NNM 1's exact backbone has its own internal-resonance tongues, on which shooting
    # orbits are not the HB backbone's: report the error above the last tongue separately
    last_tongue = {
        m: max(
            [
                t.get("energy_after_J") or t["energy_J"]
                for (mm, _, _), bb in branches.items()
                if mm == m
                for t in bb.tongues
            ],
            default=0.0,
        )
        for m in range(n)
    }
    for (mode, H, N), b in branches.items():
        energies, orbits, _ = shots[mode]
        E_sh = np.array([o.energy_J if o else np.nan for o in orbits])
        f_sh = np.array([o.freq_hz if o else np.nan for o in orbits])
        f_hb = _hb_at(b, E_sh)
        e = np.abs(f_hb / f_sh - 1.0)
        ok = np.isfinite(e)
        E_gr = b.energy_J[0] / START_FRACTION**2  # the linear mode starts at START_FRACTION a_g
        near_s = ok & (E_sh < GRAZING_BAND * E_gr) & (E_sh > E_gr)
        far_s = ok & (E_sh >= GRAZING_BAND * E_gr)
        row = {
            "nnm": mode + 1,
            "harmonics": H,
            "samples": b.N,
            "samples_study": int(N is not None),
            "n_points": len(b.energy_J),
            "energy_reached_J": b.energy_J[-1],
            "n_compared": int(ok.sum()),
            "max_err_vs_shooting": float(np.max(e[ok])) if ok.any() else np.nan,
            "median_err_vs_shooting": float(np.median(e[ok])) if ok.any() else np.nan,
            "max_err_vs_shooting_near_grazing": float(np.max(e[near_s])) if near_s.any() else np.nan,
            "max_err_vs_shooting_above_10x_grazing": float(np.max(e[far_s])) if far_s.any() else np.nan,
        }
        above = ok & (E_sh > last_tongue[mode])
        row["max_err_vs_shooting_above_last_tongue"] = float(np.max(e[above])) if above.any() else np.nan
        row["n_folds"] = sum(len(br.folds) for br in b.branches)  # turning points of log10 a or omega
        row["n_corner_steps"] = sum(len(br.corners) for br in b.branches)  # grazing corners
        row["n_rejected_steps"] = sum(br.n_rejected for br in b.branches)
        row["last_tongue_energy_J"] = last_tongue[mode]
        if mode == 1 and p.m1 == p.m3:
            E_graze = p.grazing_energy_nnm2
            err_x = np.abs(b.freq_hz / nnm2.frequency_from_energy(p, b.energy_J) - 1.0)
            near = (b.energy_J > E_graze) & (b.energy_J < GRAZING_BAND * E_graze)
            far = b.energy_J >= GRAZING_BAND * E_graze
            row.update(
                {
                    "max_err_vs_exact": float(err_x.max()),
                    "max_err_vs_exact_near_grazing": float(err_x[near].max()) if near.any() else np.nan,
                    "max_err_vs_exact_above_10x_grazing": float(err_x[far].max()) if far.any() else np.nan,
                }
            )
        else:
            row.update(
                {
                    "max_err_vs_exact": "",
                    "max_err_vs_exact_near_grazing": "",
                    "max_err_vs_exact_above_10x_grazing": "",
                }
            )
        row["tongues"] = "; ".join(
            f"{t['harmonic']}:1 at {t['energy_J']:.3g} J {t['action']}" for t in b.tongues
        )
        crow.append(row)
    write_rows(writer.path("hb_convergence.csv"), crow)
    timing = [{"nnm": mode + 1, "harmonics": H, "samples": b.N, "samples_study": int(N is not None),
               "what": "hb branch", "wall_s": round(b.wall_s, 4)} for (mode, H, N), b in branches.items()]
    timing += [{"nnm": m + 1, "harmonics": "", "samples": "", "samples_study": 0, "what": "shooting",
                "wall_s": round(sh[2], 4)} for m, sh in shots.items()]
    write_rows(writer.path("hb_convergence_timing.csv"), timing)
    writer.stats["fep_wall_s"] = {
        f"NNM {m + 1} H={H}" + (f" N={N}" if N else ""): round(b.wall_s, 3)
        for (m, H, N), b in branches.items()
    }
    writer.stats["shooting_wall_s"] = {f"NNM {m + 1}": round(s[2], 3) for m, s in shots.items()}
    if n > 1 and p.m1 == p.m3:
        o2 = [o for o in shots[1][1] if o is not None]
        writer.stats["shooting_vs_exact_nnm2_max_rel"] = float(
            max(abs(o.freq_hz / float(nnm2.frequency_from_energy(p, o.energy_J)) - 1.0) for o in o2)
        )
    writer.stats["shooting_failures"] = {
        f"NNM {m + 1}": sum(o is None for o in s[1]) for m, s in shots.items()
    }

    _plot_fep(writer.path("fep.png"), branches, hills, shots, spec, open_hz, closed_hz)
    wall = {(t["nnm"], t["harmonics"], t["samples"]): t["wall_s"] for t in timing if t["what"] == "hb branch"}
    _plot_convergence(writer.path("hb_convergence.png"), crow, branches, p, spec)
    _plot_cost(writer.path("hb_convergence_timing.png"), crow, wall, spec)


def _plot_fep(path, branches, hills, shots, spec, open_hz, closed_hz) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    colors = ["C0", "C1", "C2"]
    for f in open_hz:
        ax.axhline(f, color="k", ls="--", lw=0.8)
    for f in closed_hz:
        ax.axhline(f, color="r", ls="--", lw=0.8)
    styles = {h: s for h, s in zip(spec.harmonics, ["-", "--", "-."], strict=False)}
    widths = {h: w for h, w in zip(spec.harmonics, [0.9, 1.8, 1.8], strict=False)}
    for (mode, H, N), b in branches.items():
        if N is not None or H not in spec.harmonics:
            continue
        st = np.array([h.stable for h in hills[(mode, H)]])
        for seg in np.unique(b.segment):
            m = b.segment == seg
            ax.plot(
                b.energy_J[m],
                b.freq_hz[m],
                styles[H],
                color=colors[mode],
                lw=widths[H],
                label=f"NNM {mode + 1}, HB H={H}" if seg == 0 else None,
            )
        uns = ~st
        ax.plot(b.energy_J[uns], b.freq_hz[uns], "x", color=colors[mode], ms=3, alpha=0.6)
    for mode, (_energies, orbits, _) in shots.items():
        E = np.array([o.energy_J for o in orbits if o])
        f = np.array([o.freq_hz for o in orbits if o])
        s = np.array([o.stable for o in orbits if o])
        ax.plot(
            E[s],
            f[s],
            "o",
            mfc=colors[mode],
            mec="k",
            ms=3,
            mew=0.5,
            label=f"NNM {mode + 1}, shooting (stable)",
        )
        ax.plot(
            E[~s],
            f[~s],
            "o",
            mfc="none",
            mec=colors[mode],
            ms=4,
            mew=0.8,
            label=f"NNM {mode + 1}, shooting (unstable)",
        )
    ax.set_xscale("log")
    ax.set_xlabel("energy [J]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title(
        "Frequency-energy plot (black dashed: open gap, red dashed: closed gap;\n"
        "x: HB point unstable by Hill, open circles: unstable by Floquet)",
        fontsize=9,
    )
    ax.legend(fontsize=6.5, ncol=2, loc="upper left")
    ax.grid(True, which="both", alpha=0.2)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def _plot_convergence(path, rows, branches, p, spec) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 4.5))
    ax = axs[0]
    for (mode, H, N), b in branches.items():
        if mode != 1 or N is not None or H not in spec.convergence_harmonics:
            continue
        err = np.abs(b.freq_hz / nnm2.frequency_from_energy(p, b.energy_J) - 1.0)
        ax.loglog(b.energy_J, np.maximum(err, 1e-16), lw=1, label=f"H={H}")
    ax.axvline(p.grazing_energy_nnm2, color="k", ls=":", lw=0.8)
    ax.set_xlabel("energy [J]")
    ax.set_ylabel("|f_HB / f_exact - 1|, NNM 2")
    ax.legend(fontsize=7)
    ax.set_title("HB error along NNM 2 (dotted: grazing)", fontsize=9)
    ax = axs[1]
    for mode in range(3):
        r = [x for x in rows if x["nnm"] == mode + 1 and not x["samples_study"]]
        if not r:
            continue
        ax.loglog(
            [x["harmonics"] for x in r],
            [x["max_err_vs_shooting_above_last_tongue"] for x in r],
            "o-",
            label=f"NNM {mode + 1} vs shooting" + (" (above the tongues)" if mode == 0 else ""),
        )
    r = [x for x in rows if x["nnm"] == 2 and not x["samples_study"]]
    ax.loglog(
        [x["harmonics"] for x in r],
        [x["max_err_vs_exact_above_10x_grazing"] for x in r],
        "s--",
        label="NNM 2 vs exact, E > 10 E_graze",
    )
    ax.set_xlabel("harmonics H")
    ax.set_ylabel("max relative frequency error")
    ax.legend(fontsize=7)
    ax.set_title("error against H", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _plot_cost(path, rows, wall, spec) -> None:
    """NNM 2: HB error against the branch's run time (``wall``: {(nnm, H, N): s})."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for study, style, label, key in ((0, "o-", "H study (default N)", "harmonics"),
                                     (1, "s--", f"N study at H={spec.samples_study_harmonics}", "samples")):
        r = [x for x in rows if x["nnm"] == 2 and x["samples_study"] == study]
        t = [wall[(x["nnm"], x["harmonics"], x["samples"])] for x in r]
        ax.loglog(t, [x["max_err_vs_exact"] for x in r], style, label=label)
        for x, tx in zip(r, t, strict=True):
            ax.annotate(f"{'H' if key == 'harmonics' else 'N'}={x[key]}", (tx, x["max_err_vs_exact"]), fontsize=6)
    ax.set_xlabel("branch run time [s] (this run; varies with machine load)")
    ax.set_ylabel("max |f_HB / f_exact - 1|, NNM 2")
    ax.legend(fontsize=7)
    ax.set_title("HB error against run time", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


__all__ = ["fep_stage"]
