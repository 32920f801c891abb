"""Frequency-energy plots of the NNMs by HB and shooting, their stability, HB convergence.

Called at the end of the nnm stage when the scene has an [fep] table. Runs on any gap
system: the 3-DOF model, or a reduced 3-D model (scene ``[model] kind = "rom"``), whose
NNMs followed are those of the lowest open-gap modes that move the gaps (heave, pitch,
first coupled bending: :func:`reduced.models.modes.gap_moving_modes`), numbered 1, 2, 3 as
the 3-DOF model's. Writes

- ``fep.csv`` (nnm, method, harmonics, energy_J, freq_hz, stable) and ``fep.png``:
  HB backbones for each H of ``[fep] harmonics`` (stability by Hill's method) and the
  shooting orbits on the exact flow (stability by Floquet multipliers);
- ``stability.csv``: Hill against Floquet at each shooting energy, disagreements flagged;
- ``tongues.csv``: internal resonances met by the HB branches and what was done;
- ``hb_convergence.csv`` and ``hb_convergence.png``: HB frequency error against shooting
  for each H (and AFT samples N at one H) and, for the symmetric 3-DOF model, against the
  exact NNM 2 relation (:mod:`reduced.periodic.nnm2`). A reduced model has no closed form:
  its reference is shooting on the exact flow alone, and the ``max_err_vs_exact`` columns
  are empty;
- ``hb_convergence_timing.csv`` (run time of each branch and of shooting) and
  ``hb_convergence_timing.png`` (error against run time): wall-clock times, which change
  with machine load, live only in files whose name ends in ``_timing`` (the project's
  convention, tests/test_reproducible.py), so a rerun reproduces every other file;
- for a reduced model, ``fep.md``: the converged H and why, HB against shooting, the
  tongues met and the shooting failures, in words (the 3-DOF model's ``fep.md`` in
  results/discrete-fep is written by hand and not touched).

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
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from bearingshaft.digits import dash
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.periodic import nnm2
from reduced.periodic.backbones import START_FRACTION, hb_point_at_energy, nnm_branch
from reduced.periodic.hb import NewtonError, default_samples
from reduced.periodic.shooting import conservative, shooting_branch
from reduced.periodic.stability import compare, hill
from reduced.transient.flow import Flow

N_FOLLOWED = 3  # NNMs followed: the lowest open-gap modes that move the gaps (the 3-DOF model's three)
ALL_NNMS_MAX_H = 15  # every followed NNM runs each H of the study up to this; above it, only the study NNM
# A reduced model's shooting (measured on rom-fep, 10 modes): near grazing the orbits are very
# unstable and most guesses fail; a failing guess whose iterates chatter (hundreds to thousands
# of contact events a period, ~1 ms each) cost up to 17 s, and NNM 1 took 15 min. An NNM orbit
# has 6-16 events a period, so iterates past ROM_MAX_EVENTS are refused, and a guess that does
# not halve its residual in ROM_STALL iterations is dropped: NNM 1 then takes ~20 s with the
# same orbits found. The 3-DOF model keeps the defaults (its results are unchanged).
ROM_MAX_EVENTS = 40
ROM_STALL = 3
ROM_SHOOTING = {"stall": ROM_STALL, "max_events": ROM_MAX_EVENTS, "max_substeps": 1, "pick": "nearest",
                "guide_at_energy": True}
CONVERGED_TOL = 1e-3  # fep.md: H is converged when HB is within this of shooting (relative frequency)


@dataclass(frozen=True)
class ExactReference:
    """A closed-form frequency-energy relation of one followed NNM: the HB study's reference."""

    nnm: int  # 0-based position among the followed NNMs
    freq_hz: Callable[[np.ndarray], np.ndarray]  # energy [J] -> frequency [Hz]
    grazing_energy_J: float  # J, where the NNM first touches a stop
    label: str = "exact"


@dataclass(frozen=True)
class FEPModel:
    """What the fep study needs of a scene's model: the conservative gap system and the NNMs.

    ``modes`` are the 0-based open-gap linear modes followed (NNM k + 1 starts from
    ``modes[k]``); ``study`` the position of the NNM on which every H and every N of the
    convergence study runs; ``exact`` the closed-form reference if the model has one.
    """

    system: GapSystem
    modes: tuple[int, ...]
    kind: str  # "discrete" | "rom"
    exact: ExactReference | None = None
    study: int = 1
    shooting: dict = field(default_factory=dict)  # options of shooting_branch
    hill: dict = field(default_factory=dict)  # options of reduced.periodic.stability.hill
    branch: dict = field(default_factory=dict)  # options of nnm_branch


def fep_model(scene: Scene, progress: bool = False) -> FEPModel:
    """The :class:`FEPModel` of a scene: the 3-DOF model (with its exact NNM 2 relation when
    m1 == m3) or a reduced model (reference: shooting alone)."""
    model = scene.model
    system, _ = model_system(model, progress)
    system = conservative(system)
    modes = tuple(int(m) for m in gap_moving_modes(system, "open", N_FOLLOWED))
    if isinstance(model, DiscreteParams):
        exact = None
        if model.m1 == model.m3:
            exact = ExactReference(1, lambda E: nnm2.frequency_from_energy(model, E), model.grazing_energy_nnm2,
                                   "exact NNM 2 relation")
        return FEPModel(system, modes, "discrete", exact)
    # a reduced model: more DOFs, so Hill's eigenproblem by the faster standard form, and only
    # the first zone's exponents (its local modes lie above H omega); tongues with the local
    # modes are watched by their energy too (reduced.periodic.backbones)
    return FEPModel(system, modes, "rom", None, 1, dict(ROM_SHOOTING), {"solver": "standard", "strict_zone": True},
                    {"tongue_measure": "velocity"})


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
    fm = fep_model(scene, progress)
    system, exact = fm.system, fm.exact
    n = len(fm.modes)  # NNMs followed, keyed 0..n-1 below (NNM k + 1 starts from linear mode fm.modes[k])
    flow = Flow(system)
    open_hz = linear_modes(system, "open").freq_hz[list(fm.modes)]
    closed_hz = linear_modes(system, "closed").freq_hz[list(gap_moving_modes(system, "closed", N_FOLLOWED))]
    Hs = sorted(set(spec.harmonics) | set(spec.convergence_harmonics))
    hs_study = spec.samples_study_harmonics
    # the work list: (nnm, H, N) branches; the study NNM (NNM 2) for every H, all NNMs for
    # the H drawn in fep.png and for the convergence study up to H = ALL_NNMS_MAX_H
    jobs = []
    for H in Hs:
        for mode in range(n):
            if mode == fm.study or H in spec.harmonics or H <= ALL_NNMS_MAX_H:
                jobs.append((mode, H, None))
    for N in spec.samples:
        jobs.append((fm.study, hs_study, N))
    total = len(jobs) + 3 * n
    bar = tqdm(total=total, desc=f"{scene.name}: NNM backbones", disable=not progress, unit="branch")
    branches = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        done = {}  # (mode, H, samples): a study branch at the default N is the branch already computed
        for mode, H, N in jobs:
            bar.set_postfix_str(f"NNM {mode + 1}, H={H}" + (f", N={N}" if N else ""))
            key = (mode, H, N or default_samples(H))
            if key not in done:
                done[key] = nnm_branch(system, fm.modes[mode], H=H, N=N, energy_max_J=spec.energy_max_J,
                                       **fm.branch)
            branches[(mode, H, N)] = done[key]
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
            shots[mode] = (energies, shooting_branch(flow, energies, guides, **fm.shooting), time.perf_counter() - t0)
            bar.update()
        # Hill's method on every HB point of the drawn branches
        hills = {}
        for mode in range(n):
            bar.set_postfix_str(f"Hill NNM {mode + 1}")
            for H in spec.harmonics:
                b = branches[(mode, H, None)]
                hills[(mode, H)] = [hill(b.residual.hb, b.X[i], b.omega[i], **fm.hill)
                                    for i in range(len(b.energy_J))]
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
    errors = {}  # (nnm, H, N): (shooting energies, |f_HB / f_shooting - 1| there)
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
    f_hb_of = {}  # id(branch): HB frequencies at the shooting energies (a shared branch once)
    for (mode, H, N), b in branches.items():
        energies, orbits, _ = shots[mode]
        E_sh = np.array([o.energy_J if o else np.nan for o in orbits])
        f_sh = np.array([o.freq_hz if o else np.nan for o in orbits])
        if id(b) not in f_hb_of:
            f_hb_of[id(b)] = _hb_at(b, E_sh)
        f_hb = f_hb_of[id(b)]
        e = np.abs(f_hb / f_sh - 1.0)
        errors[(mode, H, N)] = (E_sh, e)
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
        if exact is not None and mode == exact.nnm:
            E_graze = exact.grazing_energy_J
            err_x = np.abs(b.freq_hz / exact.freq_hz(b.energy_J) - 1.0)
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
    if exact is not None:
        o2 = [o for o in shots[exact.nnm][1] if o is not None]
        writer.stats["shooting_vs_exact_nnm2_max_rel"] = float(
            max(abs(o.freq_hz / float(exact.freq_hz(o.energy_J)) - 1.0) for o in o2)
        )
    writer.stats["hb_reference"] = (f"shooting and the {exact.label} (NNM {exact.nnm + 1})" if exact else
                                    "shooting on the exact flow (no closed form for this model)")
    writer.stats["nnm_linear_modes"] = {f"NNM {k + 1}": m + 1 for k, m in enumerate(fm.modes)}
    writer.stats["shooting_failures"] = {
        f"NNM {m + 1}": sum(o is None for o in s[1]) for m, s in shots.items()
    }

    summary = None
    if fm.kind == "rom":  # fep.md: no closed form, so the converged H is judged against shooting alone
        summary = fep_summary(scene, fm, crow, shots, branches, errors, n_dis)
        writer.path("fep.md").write_text(summary.text, encoding="utf-8")
        writer.stats["converged_harmonics"] = summary.converged_H
        writer.stats["off_backbone_orbits"] = summary.n_off
    _plot_fep(writer.path("fep.png"), branches, hills, shots, spec, open_hz, closed_hz)
    wall = {(t["nnm"], t["harmonics"], t["samples"]): t["wall_s"] for t in timing if t["what"] == "hb branch"}
    _plot_convergence(writer.path("hb_convergence.png"), crow, branches, exact, spec, errors, fm.study,
                      summary.max_err if summary else None)
    _plot_cost(writer.path("hb_convergence_timing.png"), crow, wall, spec, exact, fm.study)


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


def _plot_convergence(path, rows, branches, exact, spec, errors, study, backbone_err=None) -> None:
    """Left: the HB error along the study NNM for each H of the study, against the exact
    relation (3-DOF model) or against the shooting orbits (``errors``: {(nnm, H, N): (E, e)});
    right: the max error against H for each NNM, above the last tongue, or over the shooting
    orbits on the backbone (``backbone_err``: {H: {nnm: error}}, :func:`fep_summary`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 4.5))
    ax = axs[0]
    name = f"NNM {study + 1}"
    for (mode, H, N), b in branches.items():
        if mode != study or N is not None or H not in spec.convergence_harmonics:
            continue
        if exact is not None:
            err = np.abs(b.freq_hz / exact.freq_hz(b.energy_J) - 1.0)
            ax.loglog(b.energy_J, np.maximum(err, 1e-16), lw=1, label=f"H={H}")
        else:
            E, e = errors[(mode, H, N)]
            ok = np.isfinite(e)
            ax.loglog(E[ok], np.maximum(e[ok], 1e-16), "o-", ms=2.5, lw=0.8, label=f"H={H}")
    if exact is not None:
        ax.axvline(exact.grazing_energy_J, color="k", ls=":", lw=0.8)
        ax.set_ylabel(f"|f_HB / f_exact - 1|, {name}")
        ax.set_title(f"HB error along {name} (dotted: grazing)", fontsize=9)
    else:
        ax.set_ylabel(f"|f_HB / f_shooting - 1|, {name}")
        ax.set_title(f"HB error along {name} at the shooting orbits (no closed form)", fontsize=9)
    ax.set_xlabel("energy [J]")
    ax.legend(fontsize=7)
    ax = axs[1]
    for mode in sorted({x["nnm"] - 1 for x in rows}):
        r = [x for x in rows if x["nnm"] == mode + 1 and not x["samples_study"]]
        if not r:
            continue
        if backbone_err is not None:
            Hm = [H for H in sorted(backbone_err) if mode in backbone_err[H]]
            ax.loglog(Hm, [backbone_err[H][mode] for H in Hm], "o-",
                      label=f"NNM {mode + 1} vs shooting (orbits on the backbone)")
            continue
        ax.loglog(
            [x["harmonics"] for x in r],
            [x["max_err_vs_shooting_above_last_tongue"] for x in r],
            "o-",
            label=f"NNM {mode + 1} vs shooting" + (" (above the tongues)" if any(x["tongues"] for x in r) else ""),
        )
    if exact is not None:
        r = [x for x in rows if x["nnm"] == exact.nnm + 1 and not x["samples_study"]]
        ax.loglog(
            [x["harmonics"] for x in r],
            [x["max_err_vs_exact_above_10x_grazing"] for x in r],
            "s--",
            label=f"NNM {exact.nnm + 1} vs exact, E > 10 E_graze",
        )
    ax.set_xlabel("harmonics H")
    ax.set_ylabel("max relative frequency error")
    ax.legend(fontsize=7)
    ax.set_title("error against H", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _plot_cost(path, rows, wall, spec, exact, study) -> None:
    """The study NNM: HB error against the branch's run time (``wall``: {(nnm, H, N): s}); the
    error against the exact relation, or against shooting above the last tongue."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key_err = "max_err_vs_exact" if exact is not None else "max_err_vs_shooting_above_last_tongue"
    ref = "f_exact" if exact is not None else "f_shooting"
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for kind, style, label, key in ((0, "o-", "H study (default N)", "harmonics"),
                                    (1, "s--", f"N study at H={spec.samples_study_harmonics}", "samples")):
        r = [x for x in rows if x["nnm"] == study + 1 and x["samples_study"] == kind]
        t = [wall[(x["nnm"], x["harmonics"], x["samples"])] for x in r]
        ax.loglog(t, [x[key_err] for x in r], style, label=label)
        for x, tx in zip(r, t, strict=True):
            ax.annotate(f"{'H' if key == 'harmonics' else 'N'}={x[key]}", (tx, x[key_err]), fontsize=6)
    ax.set_xlabel("branch run time [s] (this run; varies with machine load)")
    ax.set_ylabel(f"max |f_HB / {ref} - 1|, NNM {study + 1}" + ("" if exact is not None else ", above the tongues"))
    ax.legend(fontsize=7)
    ax.set_title("HB error against run time", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


OFF_BACKBONE_TOL = 1e-3  # fep.md: a shooting orbit that no H of the study comes within this of is off the backbone



@dataclass(frozen=True)
class FEPSummary:
    """fep.md and the numbers it rests on."""

    text: str
    converged_H: int | None  # smallest H of the study within CONVERGED_TOL of shooting, or None
    max_err: dict  # H -> max error against the shooting orbits on the backbone, over the NNMs
    n_off: int  # shooting orbits off the HB backbone (none of the study's H within OFF_BACKBONE_TOL)


def fep_summary(scene: Scene, fm: FEPModel, rows: list, shots: dict, branches: dict, errors: dict,
                n_dis: dict) -> FEPSummary:
    """fep.md of a model without a closed form: the converged H and why, HB against shooting.

    An H is *converged* when, on every followed NNM, its branch reaches ``[fep] energy_max_J``
    and its frequency is within :data:`CONVERGED_TOL` of every shooting orbit *on the
    backbone*, at every energy where both exist. An orbit is on the backbone when some H of
    the study comes within :data:`OFF_BACKBONE_TOL` of it; the others (multi-impact orbits
    near grazing, orbits shifted by a resonance of higher order than any H of the study)
    are listed, not compared. Numbers to 2 digits: the file is a science file (rerun
    byte-identical; run times are in hb_convergence_timing.csv).
    """
    spec = scene.fep
    n = len(fm.modes)
    Hs = sorted({H for (_, H, N) in errors if N is None})
    lin_open = linear_modes(fm.system, "open").freq_hz
    lin_closed = linear_modes(fm.system, "closed").freq_hz
    closed_idx = list(gap_moving_modes(fm.system, "closed", N_FOLLOWED))
    # orbits on the backbone: some H of the study within OFF_BACKBONE_TOL
    best, off = {}, []
    for m in range(n):
        E = shots[m][0]
        stack = np.array([errors[(m, H, None)][1] for H in Hs if (m, H, None) in errors])
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-nan columns: no HB there
            best[m] = np.nanmin(stack, axis=0)
        for i, o in enumerate(shots[m][1]):
            if o is not None and np.isfinite(best[m][i]) and best[m][i] >= OFF_BACKBONE_TOL:
                off.append((m, o, best[m][i]))
    max_err = {}  # H: ({nnm: max error over its orbits on the backbone}, every branch run reached energy_max_J)
    for H in Hs:
        errs, ok = {}, True
        for m in range(n):
            if (m, H, None) not in errors:  # H > ALL_NNMS_MAX_H: the study NNM only
                continue
            e = errors[(m, H, None)][1]
            on = np.isfinite(e) & (best[m] < OFF_BACKBONE_TOL)
            errs[m] = float(np.max(e[on])) if on.any() else np.nan
            ok = ok and branches[(m, H, None)].energy_J[-1] >= spec.energy_max_J
        max_err[H] = (errs, ok)
    converged = next((H for H in Hs if max_err[H][1] and len(max_err[H][0]) == n
                      and all(np.isfinite(x) and x <= CONVERGED_TOL for x in max_err[H][0].values())), None)
    drawn = max(spec.harmonics)
    L = [f"# NNMs of the reduced model by HB and shooting (scene {scene.name})", "",
         f"Written by `bearingshaft nnm --scene {scene.name}` (bearingshaft/stages/fep.py) with fep.csv, "
         "fep.png, stability.csv, tongues.csv, hb_convergence.csv and .png; run times are in "
         "hb_convergence_timing.csv. Numbers to 2 digits.", "",
         f"Model: the reduced 3-D model, {fm.system.n} coordinates ({', '.join(fm.system.dof_names)}), "
         f"stops on x1 and x3. The NNMs followed start from the lowest open-gap modes that move the gaps:", "",
         "| NNM | linear mode | open gap [Hz] | closed gap [Hz] |", "|--:|--:|--:|--:|"]
    for k, mode in enumerate(fm.modes):
        L.append(f"| {k + 1} | {mode + 1} | {lin_open[mode]:.2f} | {lin_closed[closed_idx[k]]:.2f} |")
    L += ["", "**Reference: shooting on the exact flow** (reduced/periodic/shooting.py on "
          "reduced/transient/flow.py, Floquet multipliers from its monodromy). The exact NNM 2 relation "
          "(reduced/periodic/nnm2.py) exists only for the symmetric 3-DOF model; a reduced model has no "
          "closed form, so the `max_err_vs_exact` columns of hb_convergence.csv are empty.", "",
          "## Converged H", "",
          f"H is converged when, on every NNM, its branch reaches {spec.energy_max_J:g} J and its frequency is "
          f"within {CONVERGED_TOL:g} (relative) of every shooting orbit on the backbone where both exist "
          f"(an orbit is on the backbone when some H of the study comes within {OFF_BACKBONE_TOL:g} of it; the "
          "others are listed below). Max |f_HB / f_shooting - 1| over those orbits:", "",
          "| H | N | " + " | ".join(f"NNM {m + 1}" for m in range(n)) + " | the branches reach energy_max_J |",
          "|--:|--:|" + "--:|" * n + ":--|"]
    for H in Hs:
        errs, ok = max_err[H]
        cells = [dash(errs[m]) if m in errs else "not run" for m in range(n)]
        N = next(b.N for (_, HH, NN), b in branches.items() if HH == H and NN is None)
        L.append(f"| {H} | {N} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
    L.append("")
    if converged is None:
        L.append(f"**No H of the study is converged** by this test (tolerance {CONVERGED_TOL:g}).")
    else:
        L.append(f"**H = {converged} is the converged H**: the smallest H of the study that passes "
                 f"(max {dash(max(max_err[converged][0].values()))}). "
                 + ("It is the H drawn in fep.png and used for stability (Hill)." if converged == drawn else
                    f"fep.png draws H = {drawn} ([fep] harmonics), not H = {converged}."))
    L += ["", "The error is largest just above grazing, where the contact pulse is short, and where a harmonic "
          "k of the NNM meets a local mode of the beam (a k:1 internal resonance): HB with H < k cannot see "
          "such a resonance, HB with H >= k resolves it or steps over its tongue (below).", ""]
    # N study
    Ns = [r for r in rows if r["samples_study"]]
    if Ns:
        L += [f"AFT samples at H = {spec.samples_study_harmonics} (NNM {fm.study + 1}, max error against "
              "shooting above the last tongue): "
              + ", ".join(f"N = {r['samples']}: {dash(r['max_err_vs_shooting_above_last_tongue'])}" for r in Ns)
              + ".", ""]
    # off-backbone orbits
    L += ["## Shooting orbits off the HB backbone", ""]
    if off:
        L += ["No H of the study comes within the tolerance of these exact orbits (multi-impact orbits near "
              "grazing have more contact events a period than the 8 of a single impact of each tip; others "
              "are shifted by a resonance of higher order than the largest H, or belong to a neighbouring "
              "orbit family of the exact flow):", "",
              "| NNM | energy [J] | frequency [Hz] | contact events a period | best HB error |",
              "|--:|--:|--:|--:|--:|"]
        for m, o, b in off:
            L.append(f"| {m + 1} | {o.energy_J:.3g} | {o.freq_hz:.2f} | {o.n_events} | {dash(b)} |")
    else:
        L.append("None: every shooting orbit is reproduced by some H of the study.")
    # shooting failures
    L += ["", "## Shooting failures", "",
          f"{spec.n_shooting} energies per NNM, log-spaced from the start of the one-harmonic branch to "
          f"{spec.energy_max_J:g} J. Near grazing the exact orbits are very unstable and the local modes ring "
          "after each impact, so single shooting from the HB guesses fails there (each guess gives up after "
          f"{ROM_STALL} iterations without halving its residual or at more than {ROM_MAX_EVENTS} contact events a "
          "period):", ""]
    for m in range(n):
        E, orbits = shots[m][0], shots[m][1]
        bad = [E[i] for i, o in enumerate(orbits) if o is None]
        L.append(f"- NNM {m + 1}: {len(bad)} of {len(E)} failed"
                 + (f", between {min(bad):.3g} and {max(bad):.3g} J" if bad else "") + ".")
    # tongues
    L += ["", "## Internal resonances (tongues)", "",
          "Detected by a harmonic outgrowing the fundamental in displacement, or in velocity (k a_k / a_1, "
          "the energy it holds) while the frequency stalls, or by a frequency falling as the energy rises; "
          "stepped over (tongues.csv) or, where no landing was found, the branch stops there (action "
          "\"stopped\").", ""]
    for (m, H, _N), b in branches.items():
        if not b.tongues and b.energy_J[-1] >= spec.energy_max_J:
            continue
        what = "; ".join(f"{t['harmonic']}:1 at {t['energy_J']:.3g} J ({t['freq_hz']:.1f} Hz) {t['action']}"
                         for t in b.tongues) or "none"
        end = "" if b.energy_J[-1] >= spec.energy_max_J else f"; **stopped at {b.energy_J[-1]:.3g} J**"
        L.append(f"- NNM {m + 1}, H = {H}, N = {b.N}: {what}{end}")
    n_stopped = sum(b.energy_J[-1] < spec.energy_max_J for b in branches.values())
    L += ["", f"{n_stopped} of {len(branches)} branches stopped before {spec.energy_max_J:g} J.", "",
          "## Stability", "",
          "Hill's method on every HB point of the drawn branches against the Floquet multipliers of the "
          "shooting orbits (stability.csv); disagreements: "
          + ", ".join(f"{k}: {v}" for k, v in n_dis.items()) + ".", ""]
    return FEPSummary("\n".join(L), converged, {H: v[0] for H, v in max_err.items()}, len(off))


__all__ = ["fep_stage", "fep_model", "fep_summary", "FEPModel", "FEPSummary", "ExactReference"]
