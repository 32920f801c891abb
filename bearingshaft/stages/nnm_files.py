"""The ``nnm`` stage's files, from what :func:`bearingshaft.stages.nnm.compute` found.

``linear_modes.csv``; for the symmetric 3-DOF model ``nnm2_exact.csv``, ``nnm2_check.csv`` and
``nnm2.png``; with [fep] (:mod:`bearingshaft.stages.nnm_fep`) ``fep.csv``, ``fep.png``,
``stability.csv``, ``tongues.csv``, ``hb_convergence.csv`` and ``.png``,
``hb_convergence_timing.csv`` and ``.png`` and, for a reduced model, ``fep.md``.

Numbers go to the digits that a rerun on another machine reproduces (its CPU picks other
SIMD kernels in NumPy and OpenBLAS, which moves the last bits; measured by rerunning with
OpenBLAS's Sandy Bridge kernels and NumPy's AVX2/FMA paths disabled): closed-form and
eigenvalue frequencies and energies to :data:`VALUE_DIGITS` significant digits, frequencies
integrated by DOP853 (rtol 1e-13, moved by 1e-13) to :data:`INTEGRATED_DIGITS`, relative
errors to 3 digits and 0 below :data:`CHECK_RESOLUTION` (what the integrated reference
resolves), mode shapes to :data:`SHAPE_DECIMALS` decimals with the sign of their first
largest entry positive. The [fep] files are written as computed (see
:mod:`bearingshaft.stages.nnm_fep` on what moves on another machine). No solver runs here.
"""

from __future__ import annotations

import numpy as np

from bearingshaft import plots
from bearingshaft.digits import dash, sig, to_resolution
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.stages.nnm_results import FEPResult, FEPSummary, NNM2Exact, NNMResult  # noqa: F401  (re-exported)

VALUE_DIGITS = 12  # closed forms and 3 x 3 eigenvalues: exact to ~1e-15, moved by 1e-16 on another CPU
INTEGRATED_DIGITS = 11  # DOP853 periods at rtol 1e-13: moved by up to 1e-13 on another CPU
CHECK_RESOLUTION = 1e-12  # relative errors against the integrated periods: below this, 0 (seen <= 2e-13)
SHAPE_DECIMALS = 10  # mode shapes scaled to a largest entry of 1: round-off zeros (~1e-13) written 0
TIE = 1e-8  # entries within this of the largest are equal (x1 = -x3 in antisymmetric modes)


# -- linear modes and the exact NNM 2 relation ---------------------------------------------------------
def unit_shape(phi: np.ndarray) -> np.ndarray:
    """``phi`` scaled so that its first largest entry (by magnitude, ties within :data:`TIE`) is 1.

    ``argmax |phi|`` alone picks between x1 and -x3 of an antisymmetric mode by round-off, which
    flips the sign of the written shape from one machine to another.

    Parameters
    ----------
    phi : (n,) ndarray of float
        A mode shape (not all zero).

    Returns
    -------
    (n,) ndarray of float
        phi / phi[k], k the first entry within ``TIE`` of the largest magnitude.

    Examples
    --------
    >>> unit_shape(np.array([0.5, 0.0, -0.5 - 1e-12])).tolist()
    [1.0, 0.0, -1.000000000002]
    """
    mag = np.abs(phi)
    k = int(np.flatnonzero(mag >= (1.0 - TIE) * mag.max())[0])
    return phi / phi[k]


def _shape_value(v: float) -> float:
    """A mode-shape entry as linear_modes.csv writes it.

    >>> _shape_value(-1e-13), _shape_value(0.123456789012345)
    (0.0, 0.123456789)
    """
    return round(float(v), SHAPE_DECIMALS) + 0.0  # + 0.0: no "-0.0"


def write(result: NNMResult, writer: StageWriter) -> None:
    """Write the nnm stage's files (module docstring) and put its statistics in ``writer.stats``.

    Parameters
    ----------
    result : NNMResult
        What :func:`bearingshaft.stages.nnm.compute` returned.
    writer : StageWriter
        Where the files go.
    """
    modes = result.linear
    rows = []
    for state, lm in modes.items():
        for r in range(len(result.dof_names)):
            shape = unit_shape(lm.phi[:, r])
            rows.append({"state": state, "mode": r + 1, "freq_hz": sig(lm.freq_hz[r], VALUE_DIGITS),
                         **{f"phi_{d}": _shape_value(shape[i]) for i, d in enumerate(result.dof_names)}})
    write_rows(writer.path("linear_modes.csv"), rows)
    writer.stats["open_hz"] = modes["open"].freq_hz.tolist()
    writer.stats["closed_hz"] = modes["closed"].freq_hz.tolist()
    if result.nnm2 is None:
        writer.stats["nnm2_exact"] = result.nnm2_skipped
    else:
        _write_nnm2(result.nnm2, writer, modes)
    if result.fep is not None:
        write_fep(result.fep, writer)


def _write_nnm2(ex: NNM2Exact, writer: StageWriter, modes: dict) -> None:
    """nnm2_exact.csv, the check against integrated periods (nnm2_check.csv) and nnm2.png."""
    np.savetxt(writer.path("nnm2_exact.csv"), np.column_stack([ex.energy_J, ex.freq_hz]), delimiter=",",
               header="energy_J,freq_hz", comments="", fmt=f"%.{VALUE_DIGITS}g")
    checks = ex.checks
    if ex.checked:
        digits = {"energy_J": VALUE_DIGITS, "freq_integrated_hz": INTEGRATED_DIGITS, "freq_exact_hz": VALUE_DIGITS,
                  "freq_paper_eq13_hz": VALUE_DIGITS}
        write_rows(writer.path("nnm2_check.csv"),
                   [{k: (to_resolution(v, CHECK_RESOLUTION, 3) if k.startswith("rel_err") else
                         sig(v, digits[k]) if k in digits else v) for k, v in c.items()} for c in checks])
        writer.stats["nnm2_max_rel_err_exact"] = max(abs(c["rel_err_exact"]) for c in checks)
        writer.stats["nnm2_max_rel_err_paper_eq13"] = max(abs(c["rel_err_paper"]) for c in checks)
    plots.nnm2_figure(ex.energy_J, ex.freq_hz, ex.freq_paper_hz, checks, modes["open"].freq_hz,
                      modes["closed"].freq_hz, writer.path("nnm2.png"))


# -- the [fep] files -----------------------------------------------------------------------------------
def write_fep(fep: FEPResult, writer: StageWriter) -> None:
    """fep.csv/png, stability.csv, tongues.csv, hb_convergence.csv/png, hb_convergence_timing.csv/png
    and, for a reduced model, fep.md; the statistics into ``writer.stats``.

    Parameters
    ----------
    fep : FEPResult
        What :func:`bearingshaft.stages.nnm_fep.compute_fep` returned.
    writer : StageWriter
        Where the files go.
    """
    spec, fm, branches, shots = fep.spec, fep.model, fep.branches, fep.shots
    write_rows(writer.path("fep.csv"), _fep_rows(fep))
    write_rows(writer.path("stability.csv"), fep.stability)
    writer.stats["stability_disagreements"] = fep.disagreements
    write_rows(writer.path("tongues.csv"), _tongue_rows(branches))
    write_rows(writer.path("hb_convergence.csv"), fep.convergence)
    timing = [{"nnm": mode + 1, "harmonics": H, "samples": b.N, "samples_study": int(N is not None),
               "what": "hb branch", "wall_s": round(b.wall_s, 4)} for (mode, H, N), b in branches.items()]
    timing += [{"nnm": m + 1, "harmonics": "", "samples": "", "samples_study": 0, "what": "shooting",
                "wall_s": round(sh[2], 4)} for m, sh in shots.items()]
    write_rows(writer.path("hb_convergence_timing.csv"), timing)
    _fep_stats(fep, writer.stats)
    summary = fep.summary
    if summary is not None:  # fep.md: no closed form, so the converged H is judged against shooting alone
        writer.path("fep.md").write_text(fep_markdown(fep), encoding="utf-8")
        writer.stats["converged_harmonics"] = summary.converged_H
        writer.stats["off_backbone_orbits"] = summary.n_off
    _plot_fep(writer.path("fep.png"), branches, fep.hill_stable, shots, spec, fep.open_hz, fep.closed_hz)
    wall = {(t["nnm"], t["harmonics"], t["samples"]): t["wall_s"] for t in timing if t["what"] == "hb branch"}
    _plot_convergence(writer.path("hb_convergence.png"), fep.convergence, branches, fm.exact, fep.exact_err, spec,
                      fep.errors, fm.study, {H: v[0] for H, v in summary.max_err.items()} if summary else None)
    _plot_cost(writer.path("hb_convergence_timing.png"), fep.convergence, wall, spec, fm.exact, fm.study)


def _fep_rows(fep: FEPResult) -> list[dict]:
    """fep.csv: each drawn HB branch (stability by Hill) and each NNM's shooting orbits (by Floquet)."""
    rows = []
    for mode in range(len(fep.model.modes)):
        for H in fep.spec.harmonics:
            b = fep.branches[(mode, H, None)]
            st = fep.hill_stable[(mode, H)]
            rows += [{"nnm": mode + 1, "method": "hb", "harmonics": H, "energy_J": b.energy_J[i],
                      "freq_hz": b.freq_hz[i], "stable": int(st[i])} for i in range(len(b.energy_J))]
        rows += [{"nnm": mode + 1, "method": "shooting", "harmonics": "", "energy_J": o.energy_J,
                  "freq_hz": o.freq_hz, "stable": int(o.stable)} for o in fep.shots[mode][1] if o is not None]
    return rows


def _tongue_rows(branches: dict) -> list[dict]:
    """tongues.csv: the internal resonances met by each branch and what was done."""
    return [{"nnm": mode + 1, "harmonics": H, "samples": b.N, "resonance": f"{t['harmonic']}:1",
             "energy_J": t["energy_J"], "freq_hz": t["freq_hz"], "action": t["action"],
             "energy_after_J": t.get("energy_after_J", "")}
            for (mode, H, _N), b in branches.items() for t in b.tongues]


def _fep_stats(fep: FEPResult, stats: dict) -> None:
    """Run times, the reference, the NNMs' linear modes and the shooting failures."""
    fm, exact = fep.model, fep.model.exact
    stats["fep_wall_s"] = {f"NNM {m + 1} H={H}" + (f" N={N}" if N else ""): round(b.wall_s, 3)
                           for (m, H, N), b in fep.branches.items()}
    stats["shooting_wall_s"] = {f"NNM {m + 1}": round(s[2], 3) for m, s in fep.shots.items()}
    if exact is not None:
        stats["shooting_vs_exact_nnm2_max_rel"] = fep.shooting_vs_exact
    stats["hb_reference"] = (f"shooting and the {exact.label} (NNM {exact.nnm + 1})" if exact else
                             "shooting on the exact flow (no closed form for this model)")
    stats["nnm_linear_modes"] = {f"NNM {k + 1}": m + 1 for k, m in enumerate(fm.modes)}
    stats["shooting_failures"] = {f"NNM {m + 1}": sum(o is None for o in s[1]) for m, s in fep.shots.items()}


# -- fep.md ------------------------------------------------------------------------------------------
def fep_markdown(fep: FEPResult) -> str:
    """fep.md of a model without a closed form: the converged H and why, HB against shooting.

    An H is *converged* when, on every followed NNM, its branch reaches ``[fep] energy_max_J``
    and its frequency is within the summary's ``converged_tol`` of every shooting orbit *on the
    backbone*, at every energy where both exist. An orbit is on the backbone when some H of
    the study comes within ``off_backbone_tol`` of it; the others (multi-impact orbits
    near grazing, orbits shifted by a resonance of higher order than any H of the study)
    are listed, not compared. Numbers to 2 digits: the file is a science file (rerun
    byte-identical; run times are in hb_convergence_timing.csv).

    Parameters
    ----------
    fep : FEPResult
        The [fep] study of a model whose ``summary`` is set (no closed form).

    Returns
    -------
    str
        The Markdown text, lines joined by newlines.
    """
    return "\n".join(_md_model(fep) + _md_converged(fep) + _md_off_backbone(fep) + _md_failures(fep)
                     + _md_tongues(fep) + _md_stability(fep))


def _md_model(fep: FEPResult) -> list[str]:
    """The title, where the file comes from, the model and its NNMs, the reference."""
    fm, s = fep.model, fep.summary
    L = [f"# NNMs of the reduced model by HB and shooting (scene {fep.scene_name})", "",
         f"Written by `bearingshaft nnm --scene {fep.scene_name}` (bearingshaft/stages/nnm_fep.py) with fep.csv, "
         "fep.png, stability.csv, tongues.csv, hb_convergence.csv and .png; run times are in "
         "hb_convergence_timing.csv. Numbers to 2 digits.", "",
         f"Model: the reduced 3-D model, {fm.system.n} coordinates ({', '.join(fm.system.dof_names)}), "
         f"stops on x1 and x3. The NNMs followed start from the lowest open-gap modes that move the gaps:", "",
         "| NNM | linear mode | open gap [Hz] | closed gap [Hz] |", "|--:|--:|--:|--:|"]
    for k, mode in enumerate(fm.modes):
        L.append(f"| {k + 1} | {mode + 1} | {s.open_hz[mode]:.2f} | {s.closed_hz[s.closed_idx[k]]:.2f} |")
    L += ["", "**Reference: shooting on the exact flow** (reduced/periodic/shooting.py on "
          "reduced/transient/flow.py, Floquet multipliers from its monodromy). The exact NNM 2 relation "
          "(reduced/periodic/nnm2.py) exists only for the symmetric 3-DOF model; a reduced model has no "
          "closed form, so the `max_err_vs_exact` columns of hb_convergence.csv are empty.", ""]
    return L


def _md_converged(fep: FEPResult) -> list[str]:
    """The converged H: the table of errors per H and NNM, the verdict, the N study."""
    spec, s, n = fep.spec, fep.summary, len(fep.model.modes)
    L = ["## Converged H", "",
         f"H is converged when, on every NNM, its branch reaches {spec.energy_max_J:g} J and its frequency is "
         f"within {s.converged_tol:g} (relative) of every shooting orbit on the backbone where both exist "
         f"(an orbit is on the backbone when some H of the study comes within {s.off_backbone_tol:g} of it; the "
         "others are listed below). Max |f_HB / f_shooting - 1| over those orbits:", "",
         "| H | N | " + " | ".join(f"NNM {m + 1}" for m in range(n)) + " | the branches reach energy_max_J |",
         "|--:|--:|" + "--:|" * n + ":--|"]
    for H, (errs, ok) in s.max_err.items():
        cells = [dash(errs[m]) if m in errs else "not run" for m in range(n)]
        N = next(b.N for (_, HH, NN), b in fep.branches.items() if HH == H and NN is None)
        L.append(f"| {H} | {N} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
    L.append("")
    converged, drawn = s.converged_H, max(spec.harmonics)
    if converged is None:
        L.append(f"**No H of the study is converged** by this test (tolerance {s.converged_tol:g}).")
    else:
        L.append(f"**H = {converged} is the converged H**: the smallest H of the study that passes "
                 f"(max {dash(max(s.max_err[converged][0].values()))}). "
                 + ("It is the H drawn in fep.png and used for stability (Hill)." if converged == drawn else
                    f"fep.png draws H = {drawn} ([fep] harmonics), not H = {converged}."))
    L += ["", "The error is largest just above grazing, where the contact pulse is short, and where a harmonic "
          "k of the NNM meets a local mode of the beam (a k:1 internal resonance): HB with H < k cannot see "
          "such a resonance, HB with H >= k resolves it or steps over its tongue (below).", ""]
    Ns = [r for r in fep.convergence if r["samples_study"]]
    if Ns:
        L += [f"AFT samples at H = {spec.samples_study_harmonics} (NNM {fep.model.study + 1}, max error against "
              "shooting above the last tongue): "
              + ", ".join(f"N = {r['samples']}: {dash(r['max_err_vs_shooting_above_last_tongue'])}" for r in Ns)
              + ".", ""]
    return L


def _md_off_backbone(fep: FEPResult) -> list[str]:
    """The shooting orbits that no H of the study reproduces."""
    L = ["## Shooting orbits off the HB backbone", ""]
    if fep.summary.off:
        L += ["No H of the study comes within the tolerance of these exact orbits (multi-impact orbits near "
              "grazing have more contact events a period than the 8 of a single impact of each tip; others "
              "are shifted by a resonance of higher order than the largest H, or belong to a neighbouring "
              "orbit family of the exact flow):", "",
              "| NNM | energy [J] | frequency [Hz] | contact events a period | best HB error |",
              "|--:|--:|--:|--:|--:|"]
        for m, o, b in fep.summary.off:
            L.append(f"| {m + 1} | {o.energy_J:.3g} | {o.freq_hz:.2f} | {o.n_events} | {dash(b)} |")
    else:
        L.append("None: every shooting orbit is reproduced by some H of the study.")
    return L


def _md_failures(fep: FEPResult) -> list[str]:
    """Where shooting failed, per NNM."""
    spec, sh = fep.spec, fep.model.shooting
    L = ["", "## Shooting failures", "",
         f"{spec.n_shooting} energies per NNM, log-spaced from the start of the one-harmonic branch to "
         f"{spec.energy_max_J:g} J. Near grazing the exact orbits are very unstable and the local modes ring "
         "after each impact, so single shooting from the HB guesses fails there (each guess gives up after "
         f"{sh['stall']} iterations without halving its residual or at more than {sh['max_events']} contact "
         "events a period):", ""]
    for m in range(len(fep.model.modes)):
        E, orbits = fep.shots[m][0], fep.shots[m][1]
        bad = [E[i] for i, o in enumerate(orbits) if o is None]
        L.append(f"- NNM {m + 1}: {len(bad)} of {len(E)} failed"
                 + (f", between {min(bad):.3g} and {max(bad):.3g} J" if bad else "") + ".")
    return L


def _md_tongues(fep: FEPResult) -> list[str]:
    """The internal resonances met and what was done, and the branches that stopped early."""
    spec = fep.spec
    L = ["", "## Internal resonances (tongues)", "",
         "Detected by a harmonic outgrowing the fundamental in displacement, or in velocity (k a_k / a_1, "
         "the energy it holds) while the frequency stalls, or by a frequency falling as the energy rises; "
         "stepped over (tongues.csv) or, where no landing was found, the branch stops there (action "
         "\"stopped\").", ""]
    for (m, H, _N), b in fep.branches.items():
        if not b.tongues and b.energy_J[-1] >= spec.energy_max_J:
            continue
        what = "; ".join(f"{t['harmonic']}:1 at {t['energy_J']:.3g} J ({t['freq_hz']:.1f} Hz) {t['action']}"
                         for t in b.tongues) or "none"
        end = "" if b.energy_J[-1] >= spec.energy_max_J else f"; **stopped at {b.energy_J[-1]:.3g} J**"
        L.append(f"- NNM {m + 1}, H = {H}, N = {b.N}: {what}{end}")
    n_stopped = sum(b.energy_J[-1] < spec.energy_max_J for b in fep.branches.values())
    L += ["", f"{n_stopped} of {len(fep.branches)} branches stopped before {spec.energy_max_J:g} J.", ""]
    return L


def _md_stability(fep: FEPResult) -> list[str]:
    """Hill against Floquet."""
    return ["## Stability", "",
            "Hill's method on every HB point of the drawn branches against the Floquet multipliers of the "
            "shooting orbits (stability.csv); disagreements: "
            + ", ".join(f"{k}: {v}" for k, v in fep.disagreements.items()) + ".", ""]


# -- the figures -------------------------------------------------------------------------------------
def _plot_fep(path, branches, hill_stable, shots, spec, open_hz, closed_hz) -> None:
    """fep.png: the drawn HB branches (x: unstable by Hill) and the shooting orbits (open: unstable by
    Floquet) over the open-gap (black) and closed-gap (red) linear frequencies."""
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
        st = np.array(hill_stable[(mode, H)])
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


def _plot_convergence(path, rows, branches, exact, exact_err, spec, errors, study, backbone_err=None) -> None:
    """Left: the HB error along the study NNM for each H of the study, against the exact
    relation (3-DOF model; ``exact_err``: {(nnm, H, N): error at each point}) or against the
    shooting orbits (``errors``: {(nnm, H, N): (E, e)});
    right: the max error against H for each NNM, above the last tongue, or over the shooting
    orbits on the backbone (``backbone_err``: {H: {nnm: error}}, :class:`FEPSummary`)."""
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
            err = exact_err[(mode, H, N)]
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


__all__ = ["FEPResult", "FEPSummary", "NNM2Exact", "NNMResult", "fep_markdown", "unit_shape", "write", "write_fep"]
