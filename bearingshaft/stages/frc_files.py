"""The ``frc`` stage's files, from what :func:`bearingshaft.stages.frc.compute` found.

``frc.csv`` (level, method, harmonics, freq_hz, point, amplitude_m, stable, bifurcation,
response: one row per curve point or stepped-sine frequency and per output point),
``frc.png``, ``frc_receptance.png`` (the response per newton, m/N), ``frc_harmonics.csv``
(amplitude per harmonic along each curve),
``frc_bifurcations.csv``, ``frc_stability.csv`` (monodromy, Hill and shooting side by side),
``stepped_sine.csv`` (each sweep point: how it settled, its amplitude against HB),
``frc_convergence.csv`` and ``frc_convergence_timing.csv`` / ``.png`` (run times: the
project's ``_timing`` convention, tests/test_reproducible.py), ``frc_backbone.csv`` and
``frc_backbone.png``; the response map's files (:mod:`bearingshaft.stages.frc_map_files`).
Amplitudes are written to :data:`DIGITS` significant digits; no solver
runs here.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

import numpy as np

from bearingshaft.digits import sig
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.stages import frc_contact, frc_map_files, frc_regimes
from bearingshaft.stages.frc_friction_results import FrictionFRCResult
from bearingshaft.stages.frc_plot import draw_curve
from bearingshaft.stages.frc_results import ConvergenceRun, FRCResult, PointCheck  # noqa: F401  (re-exported)

DIGITS = 10  # significant digits of frequencies and amplitudes (a rerun on this machine: identical)
ERR_DIGITS = 3  # relative errors
HILL_MATCH = 1e-3  # Hill's max |mu| within this (relative) of the monodromy's: the same multipliers
CONVERGENCE_FIELDS = ["level", "harmonics", "status", "n_points", "f_reached_hz", "n_folds", "highest_fold_hz",
                      "lowest_fold_hz", "n_vs_stepped_sine", "max_rel_err_vs_stepped_sine", "n_vs_shooting",
                      "n_shooting_failed", "max_rel_err_vs_shooting", "median_rel_err_vs_shooting"]
BIFURCATION_FIELDS = ["level", "harmonics", "kind", "index", "freq_hz", "amplitude_m", "max_abs_mu_before",
                      "max_abs_mu_after", "method", "family", "family_kind", "located_hz", "critical_mu", "grazing",
                      "child_family", "note"]
FRC_FIELDS = ["level", "method", "harmonics", "freq_hz", "point", "amplitude_m", "stable", "bifurcation", "response",
              "segment", "drawn", "family", "family_kind", "period_k", "receptance_m_per_N"]
FAMILY_FIELDS = ["level", "family", "kind", "period_k", "parent_family", "parent_index", "born_at", "n_points",
                 "freq_min_hz", "freq_max_hz", "stable_points", "max_amplitude_m", "max_abs_mu", "n_bifurcations",
                 "status", "notes"]
COVER_FIELDS = ["level", "freq_hz", "hb_amplitude_m", "verdict", "defect", "segments", "newton_residuals", "family",
                "family_kind", "band_lo_hz", "band_hi_hz", "note"]
CLOSE_RETURN_FIELDS = ["level", "freq_hz", "direction", "period_k", "sample", "distance", "defect", "family",
                       "family_freq_min_hz", "family_freq_max_hz", "max_abs_mu_min", "asymmetry", "half_wave", "note"]
BACKBONE_FIELDS = ["level", "scale", "load_N", "nnm", "peak_freq_hz", "peak_amplitude_m", "log_distance", "note"]


# -- the files ---------------------------------------------------------------------------------------
def write(result: FRCResult | FrictionFRCResult, writer: StageWriter) -> None:
    """Write the frc stage's files (module docstring) and put its statistics in ``writer.stats``.

    Parameters
    ----------
    result : FRCResult or FrictionFRCResult
        What :func:`bearingshaft.stages.frc.compute` returned (with sliders at the tips, the files of
        :func:`bearingshaft.stages.frc_friction_files.write`).
    writer : StageWriter
        Where the files go.
    """
    if isinstance(result, FrictionFRCResult):  # HB by AFT with the sliders: its own files (frc_friction_files)
        from bearingshaft.stages import frc_friction_files

        frc_friction_files.write(result, writer)
        return
    spec, names = result.spec, result.names
    stats = {"curves": _curve_stats(result), "stepped_sine": {}, "stability": {}}
    write_rows(writer.path("stepped_sine.csv"), _stepped_sine_rows(result, stats))
    _curve_files(result, writer, stats)
    conv_rows = [_convergence_row(spec.convergence_level_N, run) for run in result.convergence]
    timing_rows = _timing_rows(result)
    write_rows(writer.path("frc_convergence.csv"), conv_rows, fields=CONVERGENCE_FIELDS)
    write_rows(writer.path("frc_convergence_timing.csv"), timing_rows)
    Pc = spec.convergence_level_N
    sweeps = result.sweeps
    if Pc in sweeps and sweeps[Pc]:
        t_ss = sum(float(np.sum(s.wall_s)) for s in sweeps[Pc].values())
        t_hb = {r["harmonics"]: r["wall_s"] for r in timing_rows if r["what"].startswith("hb curve H=")
                and r["level"] == Pc and "monodromy" not in r["what"]}
        stats["speed_ratio_stepped_sine_over_hb"] = {f"H={h}": round(t_ss / t, 2) for h, t in t_hb.items() if t > 0}
    write_rows(writer.path("frc_backbone.csv"), _backbone_rows(result), fields=BACKBONE_FIELDS)
    write_rows(writer.path("frc_cover.csv"), _cover_rows(result), fields=COVER_FIELDS)
    write_rows(writer.path("frc_close_returns.csv"), _close_return_rows(result), fields=CLOSE_RETURN_FIELDS)
    drawn = drawn_curves(result)
    frc_map_files.write(result, writer, stats, drawn)  # response_map.csv, _jumps.csv, .png
    regimes = frc_regimes.regime_rows(result, drawn, frc_map_files.x1_column(result))
    write_rows(writer.path("frc_regimes.csv"), regimes, fields=frc_regimes.FIELDS)
    writer.stats["frc"] = stats
    writer.path("frc.md").write_text(frc_markdown(result, regimes), encoding="utf-8")
    stats["converged"] = _converged_stats(result)
    _plot_frc(writer.path("frc.png"), result)
    _plot_receptance(writer.path("frc_receptance.png"), result)
    _plot_backbone(writer.path("frc_backbone.png"), result.backbone_curves, result.backbones, names, result.load_col,
                   spec, result.peaks)
    _plot_convergence(writer.path("frc_convergence_timing.png"), conv_rows, timing_rows, Pc)


def _bool(v) -> str:
    """A verdict as frc.csv writes it.

    >>> _bool(True), _bool(np.False_)
    ('true', 'false')
    """
    return "true" if v else "false"


def _curve_stats(result: FRCResult) -> dict:
    """Per level: the curve's size, status, notes, folds, unstable points and run times, or why it failed."""
    out = {}
    for P, br in result.curves.items():
        if isinstance(br, Exception):
            out[f"{P:g} N"] = f"failed: {br}"
        else:
            out[f"{P:g} N"] = {
                "points": len(br.freq_hz), "status": br.status, "notes": br.notes,
                "folds_hz": [sig(f, 6) for f in br.freq_hz[br.folds]],
                "unstable_points": int(np.sum(~br.stable)), "wall_s": round(br.wall_s, 3),
                "stability_wall_s": round(br.stability_wall_s, 3)}
    return out


def _stepped_sine_rows(result: FRCResult, stats: dict) -> list[dict]:
    """stepped_sine.csv: every sweep point, how it settled, its amplitudes and HB's there; the
    counts per level into ``stats["stepped_sine"]``."""
    ss_rows = []
    names, load_col = result.names, result.load_col
    for P in result.spec.levels_N:
        for direction, ss in result.sweeps[P].items():
            hb = result.sweep_hb[(P, direction)]
            for j, f in enumerate(ss.freq_hz):
                amp_ss = ss.amplitude_m[j]
                row = {"level": P, "direction": direction, "freq_hz": sig(f, DIGITS), "response": ss.response[j],
                       "settle_error": sig(float(ss.settle_error[j]), 3), "settle_s": sig(float(ss.settle_s[j]), 6),
                       "asymmetry": sig(float(ss.asymmetry[j]), 3)}
                for c, nm in enumerate(names):
                    row[f"amplitude_{nm}_m"] = sig(float(amp_ss[c]), DIGITS)
                err, hb_amp = "", ""
                a = hb[j]
                if a is not None:
                    hb_amp = sig(float(a[load_col]), DIGITS)
                    err = sig(float(np.max(np.abs(a / amp_ss - 1.0))), ERR_DIGITS)
                row["hb_amplitude_m"] = hb_amp  # at the load point, on the stable branch it landed on
                row["rel_err_hb"] = err  # max over the points of |A_hb / A_stepped - 1|
                ss_rows.append(row)
        if result.sweeps[P]:
            lv = [r for r in ss_rows if r["level"] == P]
            errs = [r["rel_err_hb"] for r in lv if r["rel_err_hb"] != ""]
            stats["stepped_sine"][f"{P:g} N"] = {
                "periodic": sum(r["response"] == "periodic" for r in lv),
                "settling": sum(r["response"] == "settling" for r in lv),
                "not_settled": sum(r["response"] == "not_settled" for r in lv),
                "compared_with_hb": len(errs), "max_rel_err_hb": max(errs) if errs else None,
                "wall_s": {d: round(float(np.sum(s.wall_s)), 3) for d, s in result.sweeps[P].items()}}
    return ss_rows


def _curve_files(result: FRCResult, writer: StageWriter, stats: dict) -> None:
    """frc.csv, frc_harmonics.csv, frc_bifurcations.csv, frc_stability.csv, frc_families.csv; the
    stability counts per level into ``stats["stability"]``."""
    rows_csv, harm_rows, bif_rows, stab_rows, fam_rows = [], [], [], [], []
    for P in result.spec.levels_N:
        br = result.curves[P]
        if not isinstance(br, Exception):
            rows_csv += _curve_rows(result, P, br)
            harm_rows += _harmonic_rows(result, P, br)
            bif_rows += _bifurcation_rows(result, P, br)
            st = [_stability_row(result, P, br, r) for r in result.checks[P]]
            stab_rows += st
            stats["stability"][f"{P:g} N"] = {
                "hill_points": sum(r["hill_stable"] != "" for r in st),
                "hill_disagree": sum(r["hill_stable"] not in ("", r["monodromy_stable"]) for r in st),
                # the verdicts can agree while the multipliers do not: Hill's max |mu| off the monodromy's by > 1e-3
                "hill_mismatch": sum(c.hill_stable is not None and abs(c.hill / c.mono - 1.0) > HILL_MATCH
                                     for c in result.checks[P]),
                "shooting_points": sum(r["shooting_stable"] != "" for r in st),
                "shooting_disagree": sum(r["shooting_stable"] not in ("", r["monodromy_stable"]) for r in st),
                "shooting_failed": sum(r["note"] != "" for r in st)}
        for direction, ss in result.sweeps[P].items():
            for j, f in enumerate(ss.freq_hz):
                for c, nm in enumerate(result.names):
                    rows_csv.append({"level": P, "method": f"stepped_sine_{direction}", "harmonics": "",
                                     "freq_hz": sig(float(f), DIGITS), "point": nm,
                                     "amplitude_m": sig(float(ss.amplitude_m[j, c]), DIGITS),
                                     "stable": _bool(ss.response[j] != "not_settled"), "bifurcation": "",
                                     "response": ss.response[j], "segment": "",
                                     "receptance_m_per_N": sig(float(ss.amplitude_m[j, c]) / P, DIGITS)})
        cc = result.converged.get(P)
        if cc is not None and cc.open_gap is not None:
            rows_csv += _open_gap_rows(result, P, cc.open_gap)
        if cc is not None and cc.exact is not None:
            rows_csv += _exact_rows(result, P, cc.exact)
            bif_rows += _exact_bifurcation_rows(result, P, cc.exact)
            fam_rows += _family_rows(P, cc.exact)
    write_rows(writer.path("frc.csv"), rows_csv, fields=FRC_FIELDS)
    write_rows(writer.path("frc_families.csv"), fam_rows, fields=FAMILY_FIELDS)
    write_rows(writer.path("frc_harmonics.csv"), harm_rows)
    write_rows(writer.path("frc_bifurcations.csv"), bif_rows, fields=BIFURCATION_FIELDS)
    write_rows(writer.path("frc_stability.csv"), stab_rows)


def _curve_rows(result: FRCResult, P: float, br) -> list[dict]:
    """frc.csv rows of one HB curve: each point at each output point."""
    H = result.spec.harmonics
    cc = result.converged.get(P)
    refined = cc.refined if cc is not None else ()
    fill = cc.hb_fill if cc is not None else np.zeros(0, bool)
    bands = [(sub.freq_hz.min(), sub.freq_hz.max()) for sub in refined]
    out = []
    for k, curve in enumerate((br, *refined)):
        labels = curve.bifurcation_labels()
        for i in range(len(curve.freq_hz)):
            f = curve.freq_hz[i]
            # drawn: HB's level, or beside the exact families (hb_fill); a refined band's own curve there
            drawn = cc is None or k > 0 or (cc.method == "hb" or (fill.size and fill[i])) \
                and not any(lo <= f <= hi for lo, hi in bands)
            out += [{"level": P, "method": "hb", "harmonics": H, "freq_hz": sig(f, DIGITS), "point": nm,
                     "amplitude_m": sig(float(curve.amplitude_m[i, c]), DIGITS), "stable": _bool(curve.stable[i]),
                     "bifurcation": labels[i], "response": "", "segment": int(curve.segment[i]) + 1000 * k,
                     "drawn": _bool(drawn), "family": 0, "family_kind": "main" if k == 0 else "main_refined",
                     "period_k": 1, "receptance_m_per_N": sig(float(curve.amplitude_m[i, c]) / P, DIGITS)}
                    for c, nm in enumerate(result.names)]
    return out


def _exact_rows(result: FRCResult, P: float, ex) -> list[dict]:
    """frc.csv rows of the exact families of one level (method "shooting"): each point at each output point."""
    out = []
    for k, fam in enumerate(ex.families):
        labels = fam.bifurcation_labels()
        out += [{"level": P, "method": "shooting", "harmonics": "", "freq_hz": sig(fam.freq_hz[i], DIGITS), "point": nm,
                 "amplitude_m": sig(float(fam.amplitude_m[i, c]), DIGITS), "stable": _bool(fam.stable[i]),
                 "bifurcation": labels[i], "response": "", "segment": int(fam.segment[i]), "drawn": "true",
                 "family": k, "family_kind": fam.kind, "period_k": fam.periods,
                 "receptance_m_per_N": sig(float(fam.amplitude_m[i, c]) / P, DIGITS)}
                for i in range(len(fam.freq_hz)) for c, nm in enumerate(result.names)]
    return out


def _open_gap_rows(result: FRCResult, P: float, og) -> list[dict]:
    """frc.csv rows of the open-gap system's orbits that close no stop (method "open_gap", drawn; family -1)."""
    return [{"level": P, "method": "open_gap", "harmonics": 1, "freq_hz": sig(og.freq_hz[i], DIGITS), "point": nm,
             "amplitude_m": sig(float(og.amplitude_m[i, c]), DIGITS), "stable": _bool(og.stable), "bifurcation": "",
             "response": "", "segment": int(og.segment[i]), "drawn": "true", "family": -1, "family_kind": "open_gap",
             "period_k": 1, "receptance_m_per_N": sig(float(og.amplitude_m[i, c]) / P, DIGITS)}
            for i in range(og.freq_hz.size) for c, nm in enumerate(result.names)]


def _harmonic_rows(result: FRCResult, P: float, br) -> list[dict]:
    """frc_harmonics.csv rows of one curve: harmonics 0..min(H, 9) (the odd ones with odd_harmonics)."""
    spec, H = result.spec, result.spec.harmonics
    return [{"level": P, "harmonics": H, "index": i, "freq_hz": sig(br.freq_hz[i], DIGITS), "point": nm,
             "harmonic": kk, "amplitude_m": sig(float(br.harmonic_amplitude_m[i, c, kk]), DIGITS)}
            for i in range(len(br.freq_hz)) for c, nm in enumerate(result.names)
            for kk in range(min(br.H, 9) + 1) if not (spec.odd_harmonics and kk % 2 == 0)]


def _bifurcation_rows(result: FRCResult, P: float, br) -> list[dict]:
    """frc_bifurcations.csv rows of one curve."""
    H, col = result.spec.harmonics, result.load_col
    return [{"level": P, "harmonics": H, "kind": kind, "index": int(i), "freq_hz": sig(br.freq_hz[i], DIGITS),
             "amplitude_m": sig(float(br.amplitude_m[i, col]), DIGITS),
             "max_abs_mu_before": sig(float(np.abs(br.multipliers[i - 1, 0])), 6),
             "max_abs_mu_after": sig(float(np.abs(br.multipliers[i, 0])), 6), "method": "hb", "family": 0,
             "family_kind": "main"} for i, kind in br.bifurcations]


def _exact_bifurcation_rows(result: FRCResult, P: float, ex) -> list[dict]:
    """frc_bifurcations.csv rows of the exact families: every crossing, with where it was located, its
    critical multiplier and the family switched onto (or why not)."""
    col = result.load_col
    sw = {(r["family"], r["index"], r["kind"]): r for r in ex.switches}
    rows = []
    for k, fam in enumerate(ex.families):
        for i, kind in fam.bifurcations:
            r = sw.get((k, i, kind), {})
            crit = r.get("critical")
            rows.append({"level": P, "harmonics": "", "kind": kind, "index": int(i),
                         "freq_hz": sig(fam.freq_hz[i], DIGITS),
                         "amplitude_m": sig(float(fam.amplitude_m[i, col]), DIGITS),
                         "max_abs_mu_before": sig(float(np.abs(fam.multipliers[i - 1, 0])), 6),
                         "max_abs_mu_after": sig(float(np.abs(fam.multipliers[i, 0])), 6), "method": "shooting",
                         "family": k, "family_kind": fam.kind,
                         "located_hz": sig(r["located_hz"], DIGITS) if "located_hz" in r else "",
                         "critical_mu": sig(float(crit.real), 6) if crit is not None else "",
                         "grazing": _bool(r["grazing"]) if "grazing" in r else "",
                         "child_family": r["child"] if r.get("child", -1) >= 0 else "", "note": r.get("note", "")})
    return rows


def _family_rows(P: float, ex) -> list[dict]:
    """frc_families.csv: one row per exact family of a level."""
    rows = []
    for k, fam in enumerate(ex.families):
        pf, pi, born = fam.parent if fam.parent is not None else ("", "", "")
        if fam.kind == "isolated":
            born = f"guess at {fam.start_hz:.6g} Hz"
        elif fam.kind == "close_return":
            born = f"close return at {fam.start_hz:.6g} Hz"
        rows.append({"level": P, "family": k, "kind": fam.kind, "period_k": fam.periods, "parent_family": pf,
                     "parent_index": pi, "born_at": born, "n_points": len(fam.freq_hz),
                     "freq_min_hz": sig(float(fam.freq_hz.min()), DIGITS),
                     "freq_max_hz": sig(float(fam.freq_hz.max()), DIGITS), "stable_points": int(np.sum(fam.stable)),
                     "max_amplitude_m": sig(float(np.max(fam.amplitude_m)), DIGITS),
                     "max_abs_mu": sig(float(np.max(np.abs(fam.multipliers[:, 0]))), 6),
                     "n_bifurcations": len(fam.bifurcations), "status": fam.status,
                     "notes": "; ".join(fam.notes)})
    return rows


def _cover_rows(result: FRCResult) -> list[dict]:
    """frc_cover.csv: the verdict at each HB point in contact no exact family covered
    (:func:`reduced.periodic.uncovered.cover_verdicts`)."""
    rows = []
    for P, cc in result.converged.items():
        ex = cc.exact
        for v in (ex.verdicts if ex is not None else []):
            rows.append({"level": P, "freq_hz": sig(v.freq_hz, DIGITS), "hb_amplitude_m": sig(v.hb_amplitude_m, DIGITS),
                         "verdict": v.verdict, "defect": "" if not np.isfinite(v.defect) else sig(v.defect, ERR_DIGITS),
                         "segments": v.segments or "", "newton_residuals": v.iterations or "",
                         "family": v.family if v.family >= 0 else "",
                         "family_kind": ex.families[v.family].kind if v.family >= 0 else "",
                         "band_lo_hz": sig(v.band_hz[0], DIGITS), "band_hi_hz": sig(v.band_hz[1], DIGITS),
                         "note": v.note})
    return rows


def _close_return_rows(result: FRCResult) -> list[dict]:
    """frc_close_returns.csv: each close return of a chaotic response shot, and the family it started."""
    rows = []
    for P, cc in result.converged.items():
        ex = cc.exact
        for c in (ex.close_returns if ex is not None else []):
            fam = ex.families[c.family] if c.family >= 0 else None
            rows.append({"level": P, "freq_hz": sig(c.freq_hz, DIGITS), "direction": c.direction,
                         "period_k": c.period_k, "sample": c.index, "distance": sig(c.distance, ERR_DIGITS),
                         "defect": "" if not np.isfinite(c.defect) else sig(c.defect, ERR_DIGITS),
                         "family": c.family if fam is not None else "",
                         "family_freq_min_hz": sig(float(fam.freq_hz.min()), DIGITS) if fam is not None else "",
                         "family_freq_max_hz": sig(float(fam.freq_hz.max()), DIGITS) if fam is not None else "",
                         "max_abs_mu_min": sig(float(np.min(fam.max_multiplier)), 6) if fam is not None else "",
                         "asymmetry": sig(float(np.nanmax(fam.asymmetry)), ERR_DIGITS)
                         if fam is not None and np.any(np.isfinite(fam.asymmetry)) else "",
                         "half_wave": sig(float(np.nanmax(fam.half_wave)), ERR_DIGITS)
                         if fam is not None and np.any(np.isfinite(fam.half_wave)) else "",
                         "note": c.note})
    return rows


def _stability_row(result: FRCResult, P: float, br, r: PointCheck) -> dict:
    """frc_stability.csv row of one checked point: monodromy, Hill and shooting side by side."""
    col = result.load_col
    amp_hb = br.amplitude_m[r.index]
    shot = r.shoot_amp is not None
    return {
        "level": P, "harmonics": result.spec.harmonics, "index": r.index, "freq_hz": sig(r.freq_hz, DIGITS),
        "amplitude_m": sig(float(amp_hb[col]), DIGITS),
        "monodromy_max_abs_mu": sig(r.mono, 6), "monodromy_stable": _bool(r.mono_stable),
        "hill_max_abs_mu": sig(r.hill, 6) if r.hill_stable is not None else "",
        "hill_stable": _bool(r.hill_stable) if r.hill_stable is not None else "",
        "shooting_max_abs_mu": sig(r.shoot, 6) if r.shoot_stable is not None else "",
        "shooting_stable": _bool(r.shoot_stable) if r.shoot_stable is not None else "",
        "shooting_amplitude_m": sig(float(r.shoot_amp[col]), DIGITS) if shot else "",
        "hb_rel_err_vs_shooting": sig(float(np.max(np.abs(amp_hb / r.shoot_amp - 1.0))), ERR_DIGITS) if shot else "",
        "note": r.shoot_note}


def _convergence_row(Pc: float, run: ConvergenceRun) -> dict:
    """frc_convergence.csv row of one H: its curve, its errors against the stepped sine and shooting."""
    row = {"level": Pc, "harmonics": run.H}
    bc = run.curve
    if isinstance(bc, Exception):
        row.update({"status": "failed", "n_points": 0})
        return row
    e_ss, e_sh = run.err_stepped_sine, run.err_shooting
    fo = bc.freq_hz[bc.folds] if bc.folds else np.zeros(0)
    row.update({
        "status": bc.status, "n_points": len(bc.freq_hz),
        "f_reached_hz": sig(float(bc.freq_hz[bc.segment == 0][-1]), DIGITS),
        "n_folds": len(bc.folds),
        "highest_fold_hz": sig(float(fo.max()), DIGITS) if fo.size else "",
        "lowest_fold_hz": sig(float(fo.min()), DIGITS) if fo.size else "",
        "n_vs_stepped_sine": len(e_ss),
        "max_rel_err_vs_stepped_sine": sig(float(max(e_ss)), ERR_DIGITS) if e_ss else "",
        "n_vs_shooting": len(e_sh), "n_shooting_failed": run.shooting_failed,
        "max_rel_err_vs_shooting": sig(float(max(e_sh)), ERR_DIGITS) if e_sh else "",
        "median_rel_err_vs_shooting": sig(float(np.median(e_sh)), ERR_DIGITS) if e_sh else ""})
    return row


def _timing_rows(result: FRCResult) -> list[dict]:
    """frc_convergence_timing.csv: the run time of each H's curve, each sweep and each drawn curve."""
    Pc, H = result.spec.convergence_level_N, result.spec.harmonics
    rows = [{"level": Pc, "what": f"hb curve H={run.H}", "harmonics": run.H,
             "points": 0 if isinstance(run.curve, Exception) else len(run.curve.freq_hz),
             "wall_s": round(run.wall_s, 4)} for run in result.convergence]
    for P in result.spec.levels_N:
        for d, ss in result.sweeps.get(P, {}).items():
            rows.append({"level": P, "what": f"stepped sine {d}", "harmonics": "", "points": len(ss.freq_hz),
                         "wall_s": round(float(np.sum(ss.wall_s)), 4)})
        br = result.curves[P]
        if not isinstance(br, Exception):
            rows.append({"level": P, "what": f"hb curve H={H} with monodromy stability", "harmonics": H,
                         "points": len(br.freq_hz), "wall_s": round(br.wall_s, 4)})
        cc = result.converged.get(P)
        if cc is not None:  # the drawn curve: the comparison in H, the refined bands or the exact families
            rows.append({"level": P, "what": f"drawn curve ({cc.method})", "harmonics": "",
                         "points": 0 if cc.exact is None else sum(len(f.freq_hz) for f in cc.exact.families),
                         "wall_s": round(cc.wall_s, 4)})
            for k, f in enumerate(cc.exact.families if cc.exact is not None else ()):
                rows.append({"level": P, "what": f"exact family {k} ({f.kind})", "harmonics": "",
                             "points": len(f.freq_hz), "wall_s": round(f.wall_s, 4)})
            for what, t in (cc.exact.cpu_s.items() if cc.exact is not None else ()):
                rows.append({"level": P, "what": f"{what.replace('_', ' ')} (CPU s in wall_s)", "harmonics": "",
                             "points": len(getattr(cc.exact, what)), "wall_s": round(t, 4)})
    return rows


def _backbone_rows(result: FRCResult) -> list[dict]:
    """frc_backbone.csv: each scaled curve's peak and the backbone nearest it (log distance)."""
    rows = []
    for P in result.spec.levels_N:
        for eps in result.spec.backbone_scales:
            row = {"level": P, "scale": eps, "load_N": sig(P * eps, DIGITS)}
            if (P, eps) not in result.backbone_curves or not result.backbones:
                row["note"] = "no curve" if (P, eps) not in result.backbone_curves else "no backbone"
                rows.append(row)
                continue
            fp, A = result.peaks[(P, eps)]
            mode, dist = result.nearest[(P, eps)]
            row.update({"nnm": mode + 1, "peak_freq_hz": sig(fp, DIGITS), "peak_amplitude_m": sig(A, DIGITS),
                        "log_distance": sig(dist, ERR_DIGITS), "note": ""})
            rows.append(row)
    return rows


# -- the drawn curve of each level -----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DrawnCurve:
    """The exact families of one level as one curve to draw (each family's pieces kept apart): the
    fields :func:`_plot_frc` reads of an HB curve.

    Attributes
    ----------
    freq_hz, amplitude_m : ndarray
        Hz and m, the points (amplitude per point of the model, by column).
    stable : ndarray of bool
        Each point's stability.
    segment : ndarray of int
        The piece (family) each point belongs to.
    label : str
        How the curve was computed, for the legend.
    hb : ndarray of bool, optional
        The points that are HB's (where the exact families leave HB the band no stop closes in); None: all of
        them (a curve of HB alone).
    """

    freq_hz: np.ndarray
    amplitude_m: np.ndarray
    stable: np.ndarray
    segment: np.ndarray
    label: str
    hb: np.ndarray | None = None

    def pieces(self) -> list[np.ndarray]:
        return [np.flatnonzero(self.segment == k) for k in np.unique(self.segment)]

    def hb_pieces(self) -> list[np.ndarray]:
        """The pieces drawn from the HB curve (indices into the points)."""
        return [i for i in self.pieces() if self.hb is None or np.all(self.hb[i])]


def _spliced(br, refined: tuple) -> DrawnCurve:
    """The HB curve ``br`` with each refined band's curve put in place of its points there (each
    refined curve joined to the piece of ``br`` that steps over its band).

    >>> from types import SimpleNamespace as NS
    >>> br = NS(freq_hz=np.array([1.0, 2.0, 4.0]), amplitude_m=np.ones((3, 1)), stable=np.ones(3, bool),
    ...         segment=np.zeros(3, int), H=3)
    >>> sub = NS(freq_hz=np.array([2.5, 3.0, 3.5]), amplitude_m=2 * np.ones((3, 1)), stable=np.ones(3, bool))
    >>> _spliced(br, (sub,)).freq_hz.tolist()
    [1.0, 2.0, 2.5, 3.0, 3.5, 4.0]
    """
    f, a, st, seg = br.freq_hz, br.amplitude_m, br.stable, br.segment
    H = getattr(br, "H", None)
    for sub in refined:
        lo, hi = sub.freq_hz.min(), sub.freq_hz.max()
        keep = (f < lo) | (f > hi)
        f, a, st, seg = f[keep], a[keep], st[keep], seg[keep]
        j = next((i for i in range(len(f) - 1) if seg[i] == seg[i + 1] and min(f[i], f[i + 1]) < lo
                  and max(f[i], f[i + 1]) > hi), None)
        order = np.argsort(sub.freq_hz)
        if j is None:  # no piece steps over it: a piece of its own
            f, a = np.concatenate([f, sub.freq_hz]), np.concatenate([a, sub.amplitude_m])
            st, seg = np.concatenate([st, sub.stable]), np.concatenate([seg, np.full(len(sub.freq_hz), seg.max() + 1)])
            continue
        if f[j] > f[j + 1]:
            order = order[::-1]
        f = np.concatenate([f[: j + 1], sub.freq_hz[order], f[j + 1:]])
        a = np.concatenate([a[: j + 1], sub.amplitude_m[order], a[j + 1:]])
        st = np.concatenate([st[: j + 1], sub.stable[order], st[j + 1:]])
        seg = np.concatenate([seg[: j + 1], np.full(len(order), seg[j]), seg[j + 1:]])
    return DrawnCurve(f, a, st, seg, f"HB H={H}, {len(refined)} resonance{'s' * (len(refined) != 1)} refined")


def drawn_curves(result: FRCResult) -> dict:
    """P -> the drawn curve of each level: the HB curve (with its refined resonances spliced in), or
    its exact families (:class:`DrawnCurve`).

    Parameters
    ----------
    result : FRCResult
        The stage's result.

    Returns
    -------
    dict
    """
    out = {}
    for P, br in result.curves.items():
        cc = result.converged.get(P)
        if cc is None or cc.exact is None:
            out[P] = _spliced(br, cc.refined) if cc is not None and cc.refined and not isinstance(br, Exception) \
                else br
            continue
        fams = cc.exact.families
        seg = np.concatenate([1000 * k + f.segment for k, f in enumerate(fams)])
        label = f"exact flow ({len(fams)} famil{'y' if len(fams) == 1 else 'ies'})"
        parts = [(np.concatenate([f.freq_hz for f in fams]), np.concatenate([f.amplitude_m for f in fams]),
                  np.concatenate([f.stable for f in fams]), seg)]
        fill, hb_part = cc.hb_fill, -1
        if fill.size and fill.any():  # HB beside the families, where no stop closes (frc.converged_curve)
            idx = np.flatnonzero(fill)
            pieces = np.concatenate([[0], np.cumsum(np.diff(idx) > 1)])  # a new piece at each gap
            hb = _spliced(DrawnCurve(br.freq_hz[idx], br.amplitude_m[idx], br.stable[idx], pieces, ""), cc.refined)
            hb_part = len(parts)
            parts.append((hb.freq_hz, hb.amplitude_m, hb.stable, hb.segment + 1000 * (len(fams) + 1)))
            label += ", HB where no stop closes"
        og = cc.open_gap
        if og is not None:  # the open-gap system's orbits that close no stop (frc.converged_curve)
            parts.append((og.freq_hz, og.amplitude_m, np.full(og.freq_hz.size, og.stable),
                          og.segment + 1000 * (len(fams) + 2)))
            label += ", the open-gap orbit where it closes no stop"
        hb_points = np.concatenate([np.full(p[0].size, k == hb_part) for k, p in enumerate(parts)])
        out[P] = DrawnCurve(*(np.concatenate([p[j] for p in parts]) for j in range(4)), label, hb_points)
    return out


def _label(br) -> str:
    """The legend of a drawn curve."""
    return getattr(br, "label", None) or f"HB H={br.H}"


def _converged_stats(result: FRCResult) -> dict:
    """Per level: what is drawn and why, and the exact families' sizes and times."""
    out = {}
    for P, cc in result.converged.items():
        d = {"method": cc.method, "reason": cc.reason, "hb_change": None if not np.isfinite(cc.hb_change)
             else sig(cc.hb_change, 3), "wall_s": round(cc.wall_s, 3)}
        if cc.exact is not None:
            d["families"] = [{"kind": f.kind, "points": len(f.freq_hz), "status": f.status,
                              "wall_s": round(f.wall_s, 3)} for f in cc.exact.families]
            d["switches_followed"] = sum(r["child"] >= 0 for r in cc.exact.switches)
            d["switches_not_followed"] = sum(r["child"] < 0 for r in cc.exact.switches)
            d["contact_not_covered_hz"] = [[sig(a, DIGITS), sig(c, DIGITS), n]
                                           for a, c, n in cc.exact.uncovered_bands()]
        out[f"{P:g} N"] = d
    return out


def frc_markdown(result: FRCResult, regimes: list[dict]) -> str:
    """frc.md: per level, which curve is drawn and why, its families, bifurcations and branch switches.

    Parameters
    ----------
    result : FRCResult
        The stage's result.
    regimes : list of dict
        The rows of frc_regimes.csv (:func:`frc_regimes.regime_rows`).

    Returns
    -------
    str
    """
    spec = result.spec
    lines = [f"# Forced response: {result.scene_name}", "",
             f"Load P cos(2 pi f t) at {spec.point}, {spec.freq_min_hz:g}-{spec.freq_max_hz:g} Hz. The drawn curve "
             f"of each level (`[frc] curve = \"{spec.curve}\"`) is HB at H = {spec.harmonics} where its amplitudes "
             f"move by at most {spec.hb_converged_tol:g} from the next lower H, else the periodic orbits of the exact "
             "flow continued by multiple shooting (no harmonics), with their Floquet multipliers (frc.csv: `drawn`, "
             "`method`, `family`).", ""]
    lines += [result.mirror_note, ""] if result.mirror_note else []
    for P in spec.levels_N:
        cc = result.converged.get(P)
        if cc is None:
            continue
        lines += [f"## {P:g} N: {'exact flow (shooting)' if cc.method == 'shooting' else f'HB, H = {cc.hb_H}'}", "",
                  cc.reason + "." + _contact(cc, result.response_maps.get(P), spec), *frc_regimes.markdown(regimes, P),
                  "", *filter(None, [_stability_line(result.checks.get(P, []), spec.harmonics)])]
        ex = cc.exact
        if ex is None:
            continue
        lines += ["| family | kind | period | born at | points | f [Hz] | stable points | max amplitude [m] | "
                  "max abs mu | ended |", "|---|---|---|---|---|---|---|---|---|---|"]
        for k, f in enumerate(ex.families):
            born = (f"{f.parent[2]} of family {f.parent[0]} at {ex.families[f.parent[0]].freq_hz[f.parent[1]]:.5g} Hz"
                    if f.parent is not None else f"guess at {f.start_hz:.5g} Hz" if np.isfinite(f.start_hz)
                    else "f_min")
            lines.append(f"| {k} | {f.kind} | {f.periods} T | {born} | {len(f.freq_hz)} | {f.freq_hz.min():.5g}-"
                         f"{f.freq_hz.max():.5g} | {int(np.sum(f.stable))} | {np.max(f.amplitude_m):.4g} | "
                         f"{np.max(np.abs(f.multipliers[:, 0])):.3g} | {f.status} |")
        kinds = {}
        for f in ex.families:
            for _, kd in f.bifurcations:
                kinds[kd] = kinds.get(kd, 0) + 1
        followed = [r for r in ex.switches if r["child"] >= 0]
        skipped = [r for r in ex.switches if r["child"] < 0]
        lines += ["", "Bifurcations: " + (", ".join(f"{n} {kd}" for kd, n in sorted(kinds.items())) or "none") + ".",
                  f"Branch points (pitchforks, period doublings) met: {len(ex.switches)}; switched onto a new family: "
                  f"{len(followed)}; not followed: {len(skipped)}"
                  + (" (" + "; ".join(sorted({r['note'].split(':')[0] for r in skipped if r['note']})) + ")"
                     if skipped else "") + ". Each is a row of frc_bifurcations.csv.",
                  _period_doubled_line(ex, spec), _cover_line(ex, spec),
                  _close_return_line(ex, spec), *filter(None, [_found_switches_line(ex, spec)]),
                  "Run times: frc_convergence_timing.csv.", ""]
        for note in [n for f in ex.families for n in f.notes][:10]:
            lines.append(f"- {note}")
        lines.append("")
    return "\n".join(lines)


def _stability_line(checks: list, H: int) -> str:
    """frc.md: how the HB curve's stability by Hill's method compares with its orbits' monodromy (and shooting's
    exact orbits) at the checked points of frc_stability.csv, naming every point where the verdicts differ
    ('' without checks)."""
    hill = [c for c in checks if c.hill_stable is not None]
    if not hill:
        return ""
    off = [c for c in hill if c.hill_stable != c.mono_stable]
    far = [c for c in hill if abs(c.hill / c.mono - 1.0) > HILL_MATCH]
    shot = [c for c in checks if c.shoot_stable is not None]
    shot_off = [c for c in shot if c.shoot_stable != c.mono_stable]
    text = (f"Stability of the HB curve (H = {H}) at {len(checks)} checked points (frc_stability.csv): Hill's method "
            f"at {len(hill)} gives the monodromy's verdict at {len(hill) - len(off)}, its max |mu| within "
            f"{HILL_MATCH:g} (relative) of the monodromy's at {len(hill) - len(far)}")
    if off:
        text += "; the verdicts differ at " + ", ".join(
            f"{c.freq_hz:.5g} Hz (Hill {c.hill:.3g}, monodromy {c.mono:.3g})" for c in off[:6]) + (
            f" and {len(off) - 6} more" if len(off) > 6 else "")
    text += (f". Shooting found the exact orbit at {len(shot)} of them; its verdict differs from the HB "
             f"monodromy's at {len(shot_off)} (where the truncated HB orbit is not the exact one).")
    return text + "\n"


def _contact(cc, lvl, spec) -> str:
    """' Contact band (...): ...': the level's statement about its contact band
    (:func:`bearingshaft.stages.frc_contact.contact_statement`), '' without exact families or contact."""
    if cc.exact is None:
        return ""
    text = frc_contact.contact_statement(cc.exact, lvl, cc.open_gap, spec.verdict_points)
    return " " + text if text else ""


def _cover_line(ex, spec) -> str:
    """frc.md: the isolated families of a level (started from HB orbits in contact that no family covered)."""
    iso = [k for k, f in enumerate(ex.families) if f.kind == "isolated"]
    failed = {}
    for r in ex.cover:
        if r["family"] < 0:
            note = r["note"]
            why = ("orbit of a known family" if "one of family" in note else note.split(" (")[0].split(":")[0]
                   or "not followed")
            failed[why] = failed.get(why, 0) + 1
    return (f"Isolated families (started from HB orbits in contact no family covered, drawn with the others; "
            f"`[frc] cover_families = {spec.cover_families}`): " + (", ".join(str(k) for k in iso) if iso else "none")
            + ("; guesses tried without a new family: " + "; ".join(f"{n} {w}" for w, n in sorted(failed.items()))
               if failed else "") + ". What covers the contact band: the level's first paragraph.")


def _close_return_line(ex, spec) -> str:
    """frc.md: the families started from close returns of the chaotic Poincare samples (frc_close_returns.csv)."""
    made = [c for c in ex.close_returns if c.family >= 0]
    why = {}
    for c in ex.close_returns:
        if c.family < 0:
            key = c.note.split(" (")[0]
            why[key] = why.get(key, 0) + 1
    fams = "; ".join(
        f"family {c.family}: {c.period_k} T from {c.direction} at {c.freq_hz:.5g} Hz (return {c.distance:.2g}), "
        f"{ex.families[c.family].freq_hz.min():.5g}-{ex.families[c.family].freq_hz.max():.5g} Hz, |mu| >= "
        f"{np.min(ex.families[c.family].max_multiplier):.3g}" for c in made)
    return (f"Close-return families (unstable periodic orbits of the chaotic stepped sine, `[frc] "
            f"close_return_families = {spec.close_return_families}`): {len(ex.close_returns)} close returns shot"
            + (f"; {fams}" if fams else "; none converged to a new orbit")
            + ("; not followed: " + "; ".join(f"{n} {w}" for w, n in sorted(why.items())) if why else "") + ".")


def _found_switches_line(ex, spec) -> str:
    """frc.md: the families switched onto from the families found by verdicts and close returns (their own
    allowance, ``[frc] found_family_switches`` a family), and what their branch points gave."""
    found = ({v.family for v in ex.verdicts if v.verdict == "orbit"}
             | {c.family for c in ex.close_returns if c.family >= 0})
    recs = [r for r in ex.switches if r["family"] in found]
    if not found:
        return ""
    made = [f"{r['child']} ({ex.families[r['child']].kind}, {r['kind']} of family {r['family']} at "
            f"{r['freq_hz']:.5g} Hz)" for r in recs if r["child"] >= 0]
    return (f"Branch switching on the families found by verdicts and close returns "
            f"({', '.join(map(str, sorted(found)))}; `[frc] found_family_switches = {spec.found_family_switches}` a "
            f"family): {len(recs)} branch points met; "
            + (f"switched onto {', '.join(made)}" if made else "none switched onto") + ".")


def _period_doubled_line(ex, spec) -> str:
    """frc.md: the period-doubled families of a level and the period doublings not followed, by reason."""
    pd = [k for k, f in enumerate(ex.families) if f.kind == "period_doubled"]
    rest = {}
    for r in ex.switches:
        if r["kind"] == "period_doubling" and r["child"] < 0:
            why = r["note"].split(" (")[0].split(" is ")[0] or "no family found"
            rest[why] = rest.get(why, 0) + 1
    return (f"Period-doubled families (2 T, drawn with the others; `[frc] period_doubling = "
            f"{str(spec.period_doubling).lower()}`, at most {spec.period_doubling_families} off the main and "
            f"isolated families' trees, besides those of `[frc] found_family_switches`): "
            + (", ".join(str(k) for k in pd) if pd else "none")
            + ("; period doublings not switched at: " + "; ".join(f"{n} {w}" for w, n in sorted(rest.items()))
               if rest else "") + ".")


# -- the figures -------------------------------------------------------------------------------------
def _plot_frc(path, result: FRCResult) -> None:
    """frc.png: :func:`draw_frc` saved."""
    import matplotlib.pyplot as plt

    fig = draw_frc(result)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_receptance(path, result: FRCResult) -> None:
    """frc_receptance.png: :func:`draw_receptance` saved."""
    import matplotlib.pyplot as plt

    fig = draw_receptance(result)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _level_colours(levels) -> dict:
    """One colour per load level, in increasing level.

    >>> _level_colours([10.0, 0.1, 1.0])
    {0.1: 'C0', 1.0: 'C1', 10.0: 'C2'}
    """
    return {P: f"C{i % 10}" for i, P in enumerate(sorted(levels))}


def _draw_curves(ax, result: FRCResult, c: int, colours: dict, per_newton: bool, backbones: bool) -> None:
    """One output point's curves on ``ax``: per level its colour and its drawn curve (HB or the exact
    families, :func:`drawn_curves`), stable solid, unstable dashed; stepped sine up/down as triangles,
    open where it settled, filled where it did not; backbones dotted black. ``per_newton``: every
    amplitude divided by its level (receptance, m/N), the levels drawn from the highest, widest, to
    the lowest, narrowest: where they coincide each shows."""
    drawn = drawn_curves(result)
    levels = sorted(drawn, reverse=per_newton)
    for rank, P in enumerate(levels):
        br = drawn[P]
        col, scale = colours[P], (1.0 / P if per_newton else 1.0)
        lw = 1.2 + 1.4 * (len(levels) - 1 - rank) if per_newton else 1.2
        if not isinstance(br, Exception):
            draw_curve(ax, br, c, col, lw, scale)
        for d, mk in (("up", "^"), ("down", "v")):
            ss = result.sweeps.get(P, {}).get(d)
            if ss is None:
                continue
            per = np.array([r in ("periodic", "settling") for r in ss.response])
            ax.plot(ss.freq_hz[per], ss.amplitude_m[per, c] * scale, mk, mfc="none", mec=col, ms=6, mew=1.0,
                    ls="none")
            ax.plot(ss.freq_hz[~per], ss.amplitude_m[~per, c] * scale, mk, mfc=col, mec="k", ms=6, mew=0.6,
                    ls="none")
    if backbones:
        for f, amps in result.backbones.values():
            ax.plot(f, amps[:, c], ":", color="k", lw=1.3)


def _legend_handles(result: FRCResult, colours: dict, backbones: bool) -> list:
    """The legend: a colour per level, then a line or marker per kind of curve (black)."""
    from matplotlib.lines import Line2D

    drawn = drawn_curves(result)
    bad = {P for P, cc in result.converged.items() if cc.error}  # shooting failed: HB drawn, not converged
    out = [Line2D([], [], color=colours[P], lw=3, label=textwrap.fill(f"P = {P:g} N: {_label(drawn[P])}"
                  + (" (NOT converged)" if P in bad else ""), 44, subsequent_indent="  ")) for P in sorted(drawn)
           if not isinstance(drawn[P], Exception)]  # wrapped: a long label would squeeze the panels
    out += [Line2D([], [], color=colours[P], lw=3, label=f"P = {P:g} N (no curve)") for P in sorted(drawn)
            if isinstance(drawn[P], Exception)]
    out += [Line2D([], [], color="k", lw=1.2, label="periodic orbit, stable"),
            Line2D([], [], color="k", lw=0.9, ls="--", label="periodic orbit, unstable")]
    if any(result.sweeps.get(P) for P in result.curves):
        out += [Line2D([], [], color="k", marker="^", mfc="none", ls="none", ms=6, label="stepped sine up, settled"),
                Line2D([], [], color="k", marker="v", mfc="none", ls="none", ms=6, label="stepped sine down, settled"),
                Line2D([], [], color="k", marker="^", mfc="0.5", mec="k", ls="none", ms=6,
                       label="stepped sine, not settled\n(filled in the level's colour)")]
    if backbones and result.backbones:
        out.append(Line2D([], [], color="k", ls=":", lw=1.3, label="NNM backbones (H = 1)"))
    return out


def draw_frc(result: FRCResult):
    """frc.png: top row, every output point over the band (log-log); bottom row, the jump region
    (linear axes). A colour per level; stable solid, unstable dashed; stepped sine up and down;
    backbones dotted. The legend sits outside the axes, on the right.

    Parameters
    ----------
    result : FRCResult or FrictionFRCResult
        What :func:`bearingshaft.stages.frc.compute` returned (with sliders at the tips, the files of
        :func:`bearingshaft.stages.frc_friction_files.write`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves, names, spec, events = drawn_curves(result), result.names, result.spec, result.events
    p = len(names)
    colours = _level_colours(curves)
    fig, axs = plt.subplots(2, p, figsize=(4.6 * p + 3.2, 8.6), squeeze=False, constrained_layout=True)
    ev = np.concatenate([events[P] for P in curves] + [np.zeros(0)])
    zoom = (max(ev.min() / 1.15, spec.freq_min_hz), min(ev.max() * 1.15, spec.freq_max_hz)) if ev.size else None
    good = [br for br in curves.values() if not isinstance(br, Exception)]
    for row in range(2):
        for c in range(p):
            ax = axs[row][c]
            _draw_curves(ax, result, c, colours, per_newton=False, backbones=True)
            if row == 0:
                ax.set_xscale("log")
                ax.set_yscale("log")
                ax.set_xlim(spec.freq_min_hz, spec.freq_max_hz)
                if good:
                    ax.set_ylim(min(np.min(br.amplitude_m[:, c]) for br in good) / 2,
                                max(np.max(br.amplitude_m[:, c]) for br in good) * 3)
            elif zoom is not None:
                ax.set_xlim(*zoom)
                top = max((np.max(br.amplitude_m[(br.freq_hz >= zoom[0]) & (br.freq_hz <= zoom[1]), c], initial=0.0)
                           for br in good), default=1e-3)
                ax.set_ylim(0.0, 1.15 * top)
            ax.set_xlabel("excitation frequency [Hz]")
            ax.set_ylabel(f"max |{names[c]}| over a period [m]")
            ax.grid(True, which="both", alpha=0.2)
            if row == 1:
                ax.set_title(f"{names[c]}: the jump region (linear axes)", fontsize=9)
            else:
                ax.set_title(f"{names[c]}", fontsize=9)
    fig.legend(handles=_legend_handles(result, colours, True), loc="outside right upper", fontsize=9,
               frameon=False)
    fig.suptitle(f"{result.scene_name}: forced response to P cos(2 pi f t) at {spec.point}; top: the whole band, "
                 "bottom: the jump region", fontsize=10)
    return fig


def draw_receptance(result: FRCResult):
    """frc_receptance.png: the response per newton of load, max |x| / P in m/N, at every output point
    against frequency (log-log), a colour per level. Where the response is linear the curves of every
    level lie on one another (the receptance a test's FRF measures); contact makes them part.

    Parameters
    ----------
    result : FRCResult or FrictionFRCResult
        What :func:`bearingshaft.stages.frc.compute` returned (with sliders at the tips, the files of
        :func:`bearingshaft.stages.frc_friction_files.write`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves, names, spec = drawn_curves(result), result.names, result.spec
    p = len(names)
    colours = _level_colours(curves)
    fig, axs = plt.subplots(1, p, figsize=(4.6 * p + 3.2, 4.6), squeeze=False, constrained_layout=True)
    good = {P: br for P, br in curves.items() if not isinstance(br, Exception)}
    for c in range(p):
        ax = axs[0][c]
        _draw_curves(ax, result, c, colours, per_newton=True, backbones=False)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(spec.freq_min_hz, spec.freq_max_hz)
        if good:
            ax.set_ylim(min(np.min(br.amplitude_m[:, c]) / P for P, br in good.items()) / 2,
                        max(np.max(br.amplitude_m[:, c]) / P for P, br in good.items()) * 3)
        ax.set_xlabel("excitation frequency [Hz]")
        ax.set_ylabel(f"max |{names[c]}| / P [m/N]")
        ax.set_title(f"{names[c]} per newton at {spec.point}", fontsize=9)
        ax.grid(True, which="both", alpha=0.2)
    fig.legend(handles=_legend_handles(result, colours, False), loc="outside right upper", fontsize=9,
               frameon=False)
    fig.suptitle(f"{result.scene_name}: receptance, the response per newton of load at {spec.point} (m/N); where the "
                 "gaps stay open every level lies on one curve", fontsize=10)
    return fig


def _plot_backbone(path, bb_curves, bb, names, load_col, spec, peaks) -> None:
    """frc_backbone.png: the curves with damping and load scaled down, their peaks and the backbones."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {eps: (w, a) for eps, w, a in zip(sorted(spec.backbone_scales, reverse=True), (1.4, 1.0, 0.7, 0.5),
                                               (1.0, 0.8, 0.6, 0.5), strict=False)}
    levels = sorted({P for P, _ in bb_curves})
    for i, P in enumerate(levels):
        for eps in spec.backbone_scales:
            bc = bb_curves.get((P, eps))
            if bc is None:
                continue
            lw, al = styles.get(eps, (0.5, 0.5))
            ax.plot(bc.freq_hz, bc.amplitude_m[:, load_col], "-", color=f"C{i}", lw=lw, alpha=al,
                    label=f"{P:g} N, damping and load x {eps:g}")
            k = int(np.argmax(bc.amplitude_m[:, load_col]))
            ax.plot(bc.freq_hz[k], bc.amplitude_m[k, load_col], "o", color=f"C{i}", ms=4)
    for r, (f, amps) in bb.items():
        ax.plot(f, amps[:, load_col], ":", color="k", lw=1.5, label=f"NNM {r + 1} backbone (nnm stage, H=1)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    peaks = [peaks[key] for key in bb_curves]
    if peaks:  # around the peaks: off resonance the scaled load only shifts each curve down
        ax.set_xlim(spec.freq_min_hz, min(1.5 * max(f for f, _ in peaks), spec.freq_max_hz))
        ax.set_ylim(0.3 * min(a for _, a in peaks), 3.0 * max(a for _, a in peaks))
    ax.set_xlabel("excitation frequency [Hz]")
    ax.set_ylabel(f"max |{names[load_col]}| [m]")
    ax.set_title("FRC peaks (dots) approach the backbones as damping and load go to zero together (HB H=1)",
                 fontsize=8)
    ax.grid(True, which="both", alpha=0.2)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _plot_convergence(path, conv_rows, timing_rows, Pc) -> None:
    """frc_convergence_timing.png: the error of each H against its curve's run time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wall = {r["harmonics"]: r["wall_s"] for r in timing_rows if r["what"].startswith("hb curve H=")
            and "monodromy" not in r["what"]}
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for key, mk, label in (("max_rel_err_vs_shooting", "o-", "max error vs exact orbits (shooting)"),
                           ("median_rel_err_vs_shooting", "s--", "median error vs exact orbits"),
                           ("max_rel_err_vs_stepped_sine", "^:", "max error vs stepped sine (settled points)")):
        pts = [(wall[r["harmonics"]], r[key], r["harmonics"]) for r in conv_rows
               if r.get(key) not in (None, "") and r["harmonics"] in wall]
        if not pts:
            continue
        t, e, h = zip(*pts, strict=True)
        ax.loglog(t, np.maximum(np.array(e, float), 1e-16), mk, label=label)
        for ti, ei, hi in pts:
            ax.annotate(f"H={hi}", (ti, max(float(ei), 1e-16)), fontsize=6)
    ax.set_xlabel("HB curve run time [s] (this run; varies with machine load)")
    ax.set_ylabel("relative amplitude error")
    ax.set_title(f"HB forced response at {Pc:g} N: error against run time", fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:  # no point of the curve was compared (no exact orbit or settled stepped sine at this level)
        ax.text(0.5, 0.5, "no point compared with an independent method", ha="center", transform=ax.transAxes)
    ax.grid(True, which="both", alpha=0.2)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


__all__ = ["ConvergenceRun", "DrawnCurve", "FRCResult", "PointCheck", "drawn_curves", "frc_markdown", "write"]
