"""The files of the frc stage on a model with friction (:mod:`bearingshaft.stages.frc_friction`): frc.csv,
frc_friction_checks.csv, frc_friction_shooting.csv, frc.png and frc.md."""

from __future__ import annotations

import math

import numpy as np

from bearingshaft.output import write_rows
from bearingshaft.stages import frc_friction_map
from bearingshaft.stages.frc_friction_bands import clip, complement, contact_band
from bearingshaft.stages.frc_friction_results import SKIPPED, ShootingCurve

AGREE = (1e-3, 1e-2, 1e-1)  # the bands of |HB / shooting - 1| the agreement table counts points in
HB_CONVERGED = 1e-2  # HB is converged in H where no amplitude moves by more than this between its two highest H (the
# drawing's resolution; the shot orbits are exact to ~1e-9, by DOP853)


def write(result, writer) -> None:
    """Write the files and put the statistics in ``writer.stats["frc"]``.

    Parameters
    ----------
    result : FrictionFRCResult
    writer : StageWriter
    """
    write_rows(writer.path("frc.csv"), curve_rows(result))
    write_rows(writer.path("frc_friction_checks.csv"), check_rows(result))
    write_rows(writer.path("frc_friction_shooting.csv"), shooting_rows(result))
    write_rows(writer.path("frc_friction_sweep.csv"), sweep_rows(result))
    writer.stats["frc"] = {"friction": True, **result.stats}
    frc_friction_map.write(result, writer)  # response_map.csv, response_map_jumps.csv, response_map.png
    writer.path("frc.md").write_text(markdown(result), encoding="utf-8")
    _plot(writer.path("frc.png"), result)


def curve_rows(result) -> list[dict]:
    """frc.csv: per level and HB point, the amplitude at every point, each slider's open, stick and slip
    fractions of the period, the largest Hill multiplier and the verdict, and whether the point is part of the
    drawn curve (``drawn`` false: in contact where HB is not converged in H, :func:`hb_converged`; the continued
    exact orbits of frc_friction_shooting.csv are the drawn curve there).


    Parameters
    ----------
    result : FrictionFRCResult
    """
    rows = []
    for P, br in result.curves.items():
        if isinstance(br, Exception):
            continue
        fb = br.balance
        sliders = br.balance.system.friction.names
        faint = _hb_unconverged_in_contact(result, P, br)
        for i in range(len(br.freq_hz)):
            row = {"level_N": P, "freq_hz": float(br.freq_hz[i])}
            row.update({f"{n}_m": float(a) for n, a in zip(result.names, br.amplitude_m[i], strict=True)})
            st = fb.slider_state(br.z[i])
            for k, s in enumerate(sliders):
                row.update({f"{s}_open": float(st[k, 0]), f"{s}_stick": float(st[k, 1]), f"{s}_slip": float(st[k, 2])})
            row.update(max_abs_mu=float(np.max(np.abs(br.multipliers[i]))), stable="true" if br.stable[i] else "false",
                       drawn="false" if faint[i] else "true")
            rows.append(row)
    return rows


def check_rows(result) -> list[dict]:
    """frc_friction_checks.csv: the stepped sine's settled points against HB.


    Parameters
    ----------
    result : FrictionFRCResult
    """
    rows = []
    for P, checks in result.checks.items():
        for c in checks:
            row = {"level_N": P, "freq_hz": c.freq_hz}
            for n, e, h in zip(result.names, c.exact_m, c.hb_m, strict=True):
                row.update({f"{n}_exact_m": float(e), f"{n}_hb_m": float(h)})
            row.update(max_rel_error=c.rel_error, settled_change=c.settled_change,
                       settled="true" if c.settled else "false", simulated_s=c.simulated_s,
                       friction_work_per_period_J=c.friction_work_per_period_J)
            row.update(shoot_columns(c.shooting, result.names))
            rows.append(row)
    return rows


def shooting_rows(result) -> list[dict]:
    """frc_friction_shooting.csv: per level and continued exact orbit, its period in forcing periods (2: a
    period-doubled family), its frequency, the amplitudes shot (over its period) and of the
    HB curve nearest them, their largest relative difference, the largest |multiplier| and both verdicts, the
    defect, the rank and the corrector steps.

    Parameters
    ----------
    result : FrictionFRCResult
    """
    rows = []
    for P, scs in result.shooting.items():
        for m, sc in enumerate(_curves(scs)):
            br, err = sc.branch, sc.rel_error
            for i in range(len(br.freq_hz)):
                row = {"level_N": P, "branch": m + 1, "periods": int(br.periods), "freq_hz": float(br.freq_hz[i])}
                for k, n in enumerate(result.names):
                    row.update({f"{n}_shoot_m": float(br.amplitude_m[i, k]), f"{n}_hb_m": float(sc.hb_m[i, k])})
                hs = sc.hb_stable[i]
                row.update(hb_vs_shoot_rel=float(err[i]), max_abs_multiplier=float(br.max_abs_multiplier[i]),
                           shoot_stable="true" if br.stable[i] else "false",
                           hb_hill_stable="" if hs is None else ("true" if hs else "false"),
                           defect=float(br.defect[i]), rank=int(br.rank[i]), tangent_f=float(br.tangent_f[i]),
                           corrector_steps=int(br.n_corrector[i]),
                           bifurcation=" ".join(k for j, k in br.bifurcations if j == i))
                rows.append(row)
    return rows


def _curves(scs) -> list:
    """The ShootingCurves of a level ([] where the continuation did not run: a str)."""
    return [c for c in scs if isinstance(c, ShootingCurve)] if isinstance(scs, list) else []


def _bifurcation_labels(result) -> list[tuple[float, int, int, float, str]]:
    """[(level, branch, point, f_hz, kinds)] every continued branch's bifurcation points (the kinds found between
    the same two points joined by " + "), numbered 1, 2, ... in this order in frc.png and frc.md."""
    out = []
    for P, scs in result.shooting.items():
        for m, sc in enumerate(_curves(scs)):
            at: dict = {}
            for i, k in sc.branch.bifurcations:
                at.setdefault(int(i), []).append(k)
            out += [(P, m + 1, i, float(sc.branch.freq_hz[i]), " + ".join(ks)) for i, ks in at.items()]
    return out


def shooting_markdown(result) -> list[str]:
    """frc.md's section on the continued shooting: how, where it went, its bifurcations, and a table of the
    frequency stretches where HB and shooting agree to 1e-3, 1e-2, 1e-1 or not.

    Parameters
    ----------
    result : FrictionFRCResult
    """
    lines = ["", "## Exact orbits continued by shooting (frc_friction_shooting.csv)", "",
             "From every orbit shot at an unsettled point (in frequency order), the exact friction orbits are "
             "continued both ways in frequency (reduced.periodic.friction_continuation.continue_friction: "
             "pseudo-arclength on the 8-node shooting equations with the frequency as unknown, a predictor with the "
             "curvature of the last two tangents, a chord corrector with Broyden's update and minimum-norm steps), "
             "each way until it leaves the band, leaves the contact (no stop "
             "closes over the period: the open-gap orbit, linear, where HB is exact), meets a branch continued "
             "before it (within 2e-2 of its amplitudes; a start on such a branch is not continued again), turns back "
             "onto its own path or its own down half past a fold, its corrector fails, or after [frc] "
             "shooting_steps / 2 points (the CPU budget: about 0.08 s a point in contact); each end is stated with "
             "its reason. Jacobian and monodromy exact "
             "(reduced.periodic.friction_sensitivity: "
             "the state transition matrices of the states visited and the saltation matrix at every stick, slip and "
             "gap event); bifurcations from the multipliers crossing the unit circle between two points (a fold "
             "where df/ds also changes sign; grazing where a tip opens or closes for the whole period: the "
             "multipliers jump), numbered as in frc.png. Each point against the HB curve's solution at its "
             "frequency nearest it (any "
             "stability): the largest |HB / shooting - 1| over the points.", ""]
    labels = {(P, m, i): j + 1 for j, (P, m, i, _, _) in enumerate(_bifurcation_labels(result))}
    for P, scs in result.shooting.items():
        if not isinstance(scs, list):
            lines.append(f"- {P:g} N: {scs}")
            continue
        for m, sc in enumerate(_curves(scs)):
            br = sc.branch
            bif = ", ".join(f"[{labels[(PP, mm, i)]}] {k} near {f:.5g} Hz"
                            for PP, mm, i, f, k in _bifurcation_labels(result) if (PP, mm) == (P, m + 1)) or "none"
            origin = f" ({sc.origin})" if sc.origin else ""
            origin += " (period 2T: the period-doubled family)" if br.periods == 2 else ""
            lines += [f"- {P:g} N, branch {m + 1}{origin}: {len(br.freq_hz)} orbits, {br.freq_hz.min():.5g}-"
                      f"{br.freq_hz.max():.5g} Hz (start {br.freq_hz[np.argmax(br.n_corrector == 0)]:.5g} Hz; "
                      f"{br.status}); {int(np.sum(br.stable))} stable; worst defect {float(np.max(br.defect)):.2g}; "
                      f"bifurcations (numbered as in frc.png): {bif}."]
        lines.append("")
        lines += coverage_lines(result, P)
        lines += ["| level [N] | branch | from [Hz] | to [Hz] | points | HB vs shooting | stable (shooting) | "
                  "stable (Hill on HB) |", "|---|---|---|---|---|---|---|---|"]
        for m, sc in enumerate(_curves(scs)):
            br = sc.branch
            for a, b, label in _stretches(sc.rel_error):
                hs = [sc.hb_stable[i] for i in range(a, b)]
                hill = {True: "yes", False: "no"}.get(hs[0], "n/a") if len(set(hs)) == 1 else "mixed"
                st = br.stable[a:b]
                lines.append(f"| {P:g} | {m + 1} | {br.freq_hz[a]:.5g} | {br.freq_hz[b - 1]:.5g} | {b - a} | {label} | "
                             f"{'yes' if st.all() else ('no' if not st.any() else 'mixed')} | {hill} |")
        lines.append("")
        lines += _switch_lines(P, _curves(scs), labels)
    return lines


def _sweeps(result, P: float) -> list:
    """[(f_from, f_to, FrictionSweep, hb (k, q))] of level P ([] where the grid did not run)."""
    sw = (getattr(result, "sweeps", {}) or {}).get(P)
    return sw if isinstance(sw, list) else []


def coverage(result, P: float) -> tuple[list, list, list, list] | None:
    """(contact band, covered by the branches, covered by branches and grid, not covered) at level P: the HB curve's
    contact band (:func:`contact_band`), the parts of it the continued exact orbits' branches span (each branch from
    its lowest to its highest frequency), those and the grid's orbits (each converged grid frequency standing for
    the half step either side of it), and the rest; None where there is no HB curve or no continued branch.

    Parameters
    ----------
    result : the friction frc stage's result
    P : N, the level
    """
    br = (getattr(result, "curves", None) or {}).get(P)
    curves = _curves(result.shooting.get(P, []))
    if br is None or isinstance(br, Exception) or not curves:
        return None
    band = contact_band(br)
    spans = [(float(c.branch.freq_hz.min()), float(c.branch.freq_hz.max())) for c in curves]
    grid = [(f - 0.5 * sw.step_hz, f + 0.5 * sw.step_hz) for _, _, sw, _ in _sweeps(result, P)
            for f in sw.freq_hz[sw.converged]]
    both = clip(spans + grid, band)
    return band, clip(spans, band), both, complement(both, band)


def sweep_rows(result) -> list[dict]:
    """frc_friction_sweep.csv: per level and grid frequency of the sweeps (:func:`bearingshaft.stages.frc_friction.
    _swept`), whether an exact orbit was found and from which start, its amplitudes and HB's nearest them, their
    largest relative difference, the largest |multiplier|, the verdict, the defect and the Newton steps.

    Parameters
    ----------
    result : FrictionFRCResult
    """
    rows = []
    for P in result.curves:
        for m, (a, b, sw, hbs) in enumerate(_sweeps(result, P)):
            for j, f in enumerate(sw.freq_hz):
                row = {"level_N": P, "sweep": m + 1, "from_hz": a, "to_hz": b, "freq_hz": float(f),
                       "converged": "true" if sw.converged[j] else "false", "start": sw.start[j]}
                hb = hbs[j]
                for k, n in enumerate(result.names):
                    row.update({f"{n}_shoot_m": float(sw.amplitude_m[j, k]), f"{n}_hb_m": float(hb[k])})
                ok = bool(sw.converged[j])
                row.update(hb_vs_shoot_rel=float(np.max(np.abs(hb / sw.amplitude_m[j] - 1.0))) if ok else math.nan,
                           max_abs_multiplier=float(np.max(np.abs(sw.multipliers[j]))) if ok else math.nan,
                           stable=("true" if sw.stable[j] else "false") if ok else "",
                           defect=float(sw.defect[j]), newton_steps=int(sw.n_iter[j]))
                rows.append(row)
    return rows


def sweep_markdown(result) -> list[str]:
    """frc.md's section on the grid of exact orbits where the continued branches do not reach.

    Parameters
    ----------
    result : the friction frc stage's result
    """
    sws = [sw for P in result.curves for _, _, sw, _ in _sweeps(result, P)]
    lines = ["", "## Exact orbits on a grid where the continued branches do not reach (frc_friction_sweep.csv)", ""]
    if not sws:
        reasons = [(P, (getattr(result, "sweeps", {}) or {}).get(P)) for P in result.curves]
        return lines + [f"- {P:g} N: {r}" for P, r in reasons if isinstance(r, str)] + [""]
    step, max_iter, max_fail = sws[0].step_hz, sws[0].max_iter, sws[0].max_fail
    lines += [
             f"Over each stretch of the contact band (HB) no continued branch spans, the exact orbits at fixed "
             f"frequencies {step:g} Hz apart (reduced.periodic.friction_sweep.sweep_friction: Newton on the "
             "8-node shooting equations at each frequency, the exact Jacobian (state transition and saltation "
             "matrices), minimum-norm steps halved while the residual does not fall; from the previous frequency's "
             f"orbit extrapolated linearly, else from HB's orbit there, {max_iter} Newton steps from each), from each "
             "end of the stretch inwards (from the continued orbit at that end where a branch ends there, else from "
             "HB's); after a frequency without an orbit the next is twice as far (up to 4 steps), and a direction "
             f"ends after {max_fail} in a row. One orbit a frequency: where several coexist, the one Newton reaches; "
             "stability from its multipliers (exact monodromy).", ""]
    for P in result.curves:
        sws = (getattr(result, "sweeps", {}) or {}).get(P)
        if isinstance(sws, str):
            lines.append(f"- {P:g} N: {sws}")
            continue
        for a, b, sw, _ in sws or []:
            ok = sw.converged
            n_prev = int(np.sum(ok & (sw.start == "previous")))
            done = [f for f, c in zip(sw.freq_hz, ok, strict=True) if c]
            miss = [f for f, c in zip(sw.freq_hz, ok, strict=True) if not c]
            reached = f"{sw.freq_hz[-1]:.4g} Hz" if len(sw.freq_hz) else "none"
            lines.append(f"- {P:g} N, {a:.4g} -> {b:.4g} Hz: {int(ok.sum())} of {len(ok)} frequencies with an exact "
                         f"orbit ({n_prev} from the previous orbit, {int(ok.sum()) - n_prev} from HB), "
                         f"{int(np.sum(sw.stable & ok))} stable; last tried {reached}"
                         + (f"; orbits at {_hz_list(done, step)}" if done else "")
                         + (f"; none at {_hz_list(miss, step)}" if miss else "")
                         + (f"; worst defect of the orbits {float(np.max(sw.defect[ok])):.2g}" if ok.any() else "")
                         + ".")  # its CPU time in provenance.json (stats), not here: the file must reproduce
    lines.append("")
    return lines


def _hz_list(fs, step: float) -> str:
    """Frequencies as runs ``step`` apart: 'a-b Hz (k)' or single values."""
    fs = sorted(float(f) for f in fs)
    runs, start = [], 0
    for i in range(1, len(fs) + 1):
        if i == len(fs) or abs(fs[i] - fs[i - 1]) > 1.01 * step:
            runs.append(f"{fs[start]:.4g}-{fs[i - 1]:.4g} Hz ({i - start})" if i - start > 1 else f"{fs[start]:.4g} Hz")
            start = i
    return ", ".join(runs)


def coverage_lines(result, P: float) -> list[str]:
    """frc.md's statement of what the continued exact orbits cover of level P's contact band, and what not.

    Parameters
    ----------
    result : the friction frc stage's result
    P : N, the level
    """
    def hz(ivs):
        return ", ".join(f"{a:.4g}-{b:.4g}" for a, b in ivs) or "none"

    def width(ivs):
        return sum(b - a for a, b in ivs)

    c = coverage(result, P)
    if c is None:
        return []
    band, cov, both, rest = c
    pct = 100.0 / max(width(band), 1e-300)
    return [f"**Coverage of the contact band at {P:g} N** (each branch from its lowest to its highest frequency; "
            "each orbit of the grid below for half its step either side): "
            f"contact band (HB: a tip touches over part of the period) {hz(band)} Hz ({width(band):.3g} Hz); covered "
            f"by the continued exact orbits {hz(cov)} Hz ({width(cov):.3g} Hz, {pct * width(cov):.0f} %); with the "
            f"grid of exact orbits {width(both):.3g} Hz ({pct * width(both):.0f} %); not covered {hz(rest)} Hz "
            f"({width(rest):.3g} Hz: no exact orbit found there from the neighbouring orbits nor from HB's; there the "
            "drawn curve is HB's, faint where HB is not converged in H).", ""]


def _switch_lines(P: float, curves: list, labels: dict) -> list[str]:
    """frc.md's list of the branch switching tried at one level's folds and branch points, with each outcome."""
    tried = [(m, sw) for m, sc in enumerate(curves) for sw in sc.switches]
    if not tried:
        return []
    lines = [f"Branch switching at {P:g} N (reduced.periodic.friction_continuation.switch_branch: at the point beside "
             "each fold and branch point whose real multiplier outside the circle is nearest +1, the orbit perturbed "
             "by 1e-2 D along its eigenvector (then 1e-1 D where both signs return), propagated to the 8 nodes by the "
             "exact state transition matrices, and Newton at that frequency from either sign; an orbit off the branch "
             "is a new family, continued both ways; at a period doubling the same from the orbit taken twice, Newton "
             "over two forcing periods (16 nodes), an orbit whose two halves differ being the period-doubled family, "
             "continued both ways with its multipliers over 2T; no switch where the critical multiplier beside the "
             "crossing is more than 1 from +-1: it jumped across the circle at a non-smooth transition):",
             ""]
    for m, sw in tried:
        at = labels.get((P, m + 1, int(sw.index)))
        what = {"new family": "a new family (listed above as a branch with this origin)",
                "same orbit": "both signs return to the orbit it started beside (no other orbit found within 1e-1 D)",
                "same branch": "an orbit of the same branch (the other side of a fold)",
                "no orbit": "Newton does not converge from either sign"}.get(sw.outcome, sw.outcome)
        dist = f", max |z - z0| / D {sw.distance:.2g}" if math.isfinite(sw.distance) else ""
        lines.append(f"- branch {m + 1}, [{at}] {sw.kind} near {sw.freq_hz:.5g} Hz (multiplier "
                     f"{sw.multiplier.real:.4g}): {what}{dist}.")
    lines.append("")
    return lines


def _stretches(err: np.ndarray) -> list[tuple[int, int, str]]:
    """[(first, end, label)] consecutive points in the same band of AGREE."""
    def label(e):
        if not math.isfinite(e):
            return "no HB solution"
        for a in AGREE:
            if e <= a:
                return f"agree within {a:g}"
        return f"differ by more than {AGREE[-1]:g}"

    out, a = [], 0
    for i in range(1, len(err) + 1):
        if i == len(err) or label(err[i]) != label(err[a]):
            worst = float(np.max(err[a:i])) if np.all(np.isfinite(err[a:i])) else math.nan
            out.append((a, i, label(err[a]) + (f" (worst {worst:.2g})" if math.isfinite(worst) else "")))
            a = i
    return out


def shoot_columns(sh, names: tuple[str, ...]) -> dict:
    """The shooting columns of frc_friction_checks.csv for one check (``sh`` a ShootCheck, or None where the
    stepped sine settled: no shooting, empty cells): the status and how Newton ended, the HB order it started
    from, the amplitudes shot and of the curve's HB at f, their relative difference at the first point and the
    time histories' at every point, the defects, the largest |multiplier| and the verdict, Hill's verdict on
    the HB solution, and the shooting Jacobian's rank.

    Parameters
    ----------
    sh : ShootCheck or None
    names : the output points
    """
    nan = math.nan
    out = {"shoot_status": "not run: settled" if sh is None else ("converged" if sh.converged else "not converged"),
           "shoot_message": "" if sh is None else sh.message, "shoot_start_H": "" if sh is None else sh.start_H}
    conv = sh is not None and sh.converged
    for k, n in enumerate(names):
        out[f"{n}_shoot_m"] = nan if sh is None or sh.shoot_m is None else float(sh.shoot_m[k])
        out[f"{n}_hb_any_m"] = nan if sh is None or sh.hb_m is None else float(sh.hb_m[k])
    out[f"hb_vs_shoot_{names[0]}_rel"] = float(sh.amp_rel[0]) if conv else nan
    for k, n in enumerate(names):
        out[f"{n}_hb_vs_shoot_history_rel"] = float(sh.history_rel[k]) if conv else nan
    out.update({"shoot_defect": nan if sh is None else sh.defect,
                "shoot_period_defect": nan if sh is None else sh.period_defect,
                "shoot_max_abs_multiplier": nan if sh is None else sh.max_abs_multiplier,
                "shoot_stable": "" if not conv else ("true" if sh.stable else "false"),
                "hb_hill_stable": "" if sh is None or sh.hb_stable is None else ("true" if sh.hb_stable else "false"),
                "shoot_rank": "" if sh is None else f"{sh.rank}/{sh.size}"})
    return out


def markdown(result) -> str:
    """frc.md: the curves, their stability through stick-slip, the exact check, and what is skipped and why.


    Parameters
    ----------
    result : FrictionFRCResult
    """
    spec, names = result.scene.frc, result.names
    sys_f = next((br.balance.system.friction for br in result.curves.values() if not isinstance(br, Exception)),
                 None)
    load = f"{spec.point}" + "".join(f" + {w:g} x {p}" for p, w in zip(spec.also_points, spec.also_weights,
                                                                        strict=True))
    lines = [f"# Forced response with friction at the tips: {result.scene.name}", "",
             f"Load P cos(2 pi f t) along ({load}), {spec.freq_min_hz:g}-{spec.freq_max_hz:g} Hz; HB by AFT "
             f"(reduced.periodic.friction_aft.friction_frc: the stops projected exactly, each Jenkins slider by AFT), "
             f"H = {spec.harmonics}{' (odd)' if spec.odd_harmonics else ''}; stability by Hill's method on the "
             "consistent AFT Jacobian at every point."]
    if sys_f is not None:
        lines[-1] += (f" Sliders: {', '.join(sys_f.names)}, mu = {float(np.max(sys_f.mu)):g}, "
                      f"k_t = {float(np.max(sys_f.k_t)):.4g} N/m.")
    # run times are in provenance.json (the stage's stats), not here: this file is compared digit for digit
    lines += ["", "| level [N] | HB points | stable | stick-slip points | bifurcations | "
              "stepped sine: settled | worst HB error at a settled point | unsettled points: orbit shot |",
              "|---|---|---|---|---|---|---|---|"]
    for P, br in result.curves.items():
        ok = [c for c in result.checks[P] if c.settled]
        errs = [c.rel_error for c in ok if math.isfinite(c.rel_error)]
        worst = f"{max(errs):.3g}" if errs else "n/a"
        shots = [c.shooting for c in result.checks[P] if c.shooting is not None]
        shot = f"{sum(s.converged for s in shots)}/{len(shots)}"
        if isinstance(br, Exception):
            lines.append(f"| {P:g} | failed: {' '.join(str(br).split())[:120]} | | | | "
                         f"{len(ok)}/{len(result.checks[P])} | {worst} | {shot} |")
            continue
        fb = br.balance
        ss = np.array([fb.slider_state(z) for z in br.z])  # (k, p, 3)
        stick_slip = int(np.sum(np.any((ss[:, :, 1] > 0) & (ss[:, :, 2] > 0), axis=1)))
        kinds = {}
        for _, kind in br.bifurcations:
            kinds[kind] = kinds.get(kind, 0) + 1
        bif = ", ".join(f"{v} {k}" for k, v in kinds.items()) or "none"
        lines.append(f"| {P:g} | {len(br.freq_hz)} | {int(np.sum(br.stable))} | {stick_slip} | "
                     f"{bif} | {len(ok)}/{len(result.checks[P])} | {worst} | {shot} |")
    lines += ["", *frc_friction_map.markdown(result)]
    mapped = any(lvl is not None for lvl in (getattr(result, "response_maps", {}) or {}).values())
    if mapped:
        lines += ["## HB checked at frequencies of the response map (frc_friction_checks.csv)", "",
                  f"At {spec.stepped_sine_points} frequencies spread over the band (on the map's grid), from the state "
                  "the map's up sweep ended in there, 20 periods more by the exact friction integrator (the last "
                  "period's amplitudes and friction work); settled where the map found a periodic response; a settled "
                  "point compared with the HB solution at its frequency on the stable piece nearest it (the largest "
                  f"relative error over the points {', '.join(names)}); elsewhere the map's regime."]
    else:
        lines += ["## The stepped sine by the exact friction integrator (frc_friction_checks.csv)", "",
                  f"Up the band at {spec.stepped_sine_points} frequencies, the state (sliders included) carried from "
                  f"one to the next; each settled until its last period's amplitudes move by less than "
                  f"{spec.stepped_sine_tol:g} (relative) over {10} periods, or {spec.stepped_sine_max_s:g} s; compared "
                  "with the HB solution at its frequency on the stable piece nearest it (the largest relative error "
                  f"over the points {', '.join(names)})."]
    lines += ["", "| level [N] | f [Hz] | " + " | ".join(f"{n} exact / HB [m]" for n in names)
              + " | error | settled | friction work a period [J] |",
              "|---" * (len(names) + 5) + "|"]
    for P, checks in result.checks.items():
        for c in checks:
            amps = " | ".join(f"{e:.4g} / {h:.4g}" for e, h in zip(c.exact_m, c.hb_m, strict=True))
            got = frc_friction_map.state_at((getattr(result, "response_maps", {}) or {}).get(P), c.freq_hz)
            why = f"no: {got[0].regime}" if got is not None else f"no ({c.settled_change:.2g})"
            lines.append(f"| {P:g} | {c.freq_hz:.4g} | {amps} | {c.rel_error:.3g} | "
                         f"{'yes' if c.settled else why} | {c.friction_work_per_period_J:.3g} |")
    lines += shoot_markdown(result)
    lines += shooting_markdown(result)
    lines += sweep_markdown(result)
    lines += verdict_markdown(result)
    lines += ["", "## Skipped with friction, and why", ""]
    lines += [f"- **{what}**: {why}." for what, why in SKIPPED]
    return "\n".join(lines) + "\n"


def hb_converged(v) -> bool | None:
    """Whether HB is converged in H at a branch's start (no amplitude moves by more than HB_CONVERGED between the two
    highest H with a solution; None: fewer than two).

    Parameters
    ----------
    v : BranchVerdict

    Returns
    -------
    bool or None
    """
    moves = v.hb_moves()
    return None if moves is None else bool(np.max(moves) <= HB_CONVERGED)


def verdict_markdown(result) -> list[str]:
    """frc.md's section on who is right where HB and shooting disagree: per continued branch, the start orbit checked
    independently, HB against it for each H, and which curve is drawn.

    Parameters
    ----------
    result : FrictionFRCResult
    """
    names = result.names
    verdicts = getattr(result, "verdicts", {}) or {}
    if not any(verdicts.values()):
        return []
    hs = sorted({H for vs in verdicts.values() for v in vs for H, _, _ in v.hb})
    lines = ["", "## Who is right where HB and shooting disagree: HB's convergence in H", "",
             "At each continued branch's start orbit. Shooting: its defect, the period defect of one exact run over "
             "the period, and an independent integration, DOP853 restarted at every state change "
             "(reduced.transient.friction.reference_dop853, rtol 1e-12), over the period from the orbit's start, "
             "against the exact flow (max |y_DOP853 - y_exact| in units of the amplitude, 512 samples). HB: Newton at "
             f"the orbit's frequency for H = {', '.join(str(h) for h in hs)} (the curve's harmonic set and AFT "
             "sampling rule, each H from the last found, else from the shot orbit's harmonics), its amplitudes "
             "against the shot orbit's (HB / shooting - 1) and the largest difference of the time histories over the "
             "period relative to the point's amplitude (worst point). Issue 25's rule: the drawn curve is the one "
             f"whose amplitudes no longer move with H (here: by at most {HB_CONVERGED:g} between the two highest H), "
             "or the orbits continued by shooting on the exact flow.", "",
             "| level [N] | branch | f [Hz] | shooting defect | period defect | DOP853 vs exact | max abs multiplier | "
             "H | " + " | ".join(f"{n}: HB / shot - 1" for n in names) + " | history (worst) |",
             "|---" * (len(names) + 9) + "|"]
    for P, vs in verdicts.items():
        for m, v in enumerate(vs):
            head = (f"| {P:g} | {m + 1} | {v.freq_hz:.5g} | {v.defect:.2g} | {v.period_defect:.2g} | "
                    f"{v.dop853_rel:.2g} | {v.max_abs_multiplier:.4g} |")
            for j, (H, a, h) in enumerate(v.hb):
                lead = head if j == 0 else "| | | | | | | |"
                if a is None:
                    lines.append(f"{lead} {H} | " + " | ".join("no HB solution" for _ in names) + " | |")
                    continue
                w = int(np.argmax(h))
                lines.append(f"{lead} {H} | " + " | ".join(f"{e:.3g}" for e in a) + f" | {h[w]:.3g} ({names[w]}) |")
    lines += ["", "Verdicts, per branch (the drawn curve):", ""]
    for P, vs in verdicts.items():
        for m, v in enumerate(vs):
            got = [(H, a) for H, a, _ in v.hb if a is not None]
            ok = hb_converged(v)
            exact = (f"the shot orbit is exact (defect {v.defect:.2g}, DOP853 within {v.dop853_rel:.2g} over a "
                     "period)")
            if ok is None:
                lines.append(f"- {P:g} N, branch {m + 1} ({v.freq_hz:.5g} Hz): {exact}; HB found at fewer than two H: "
                             "not judged. Drawn: the continued orbits.")
                continue
            moves = v.hb_moves()
            w = int(np.argmax(moves))
            (Ha, _), (Hb, ab) = got[-2], got[-1]
            k = int(np.argmax(np.abs(ab)))
            if ok:
                lines.append(f"- {P:g} N, branch {m + 1} ({v.freq_hz:.5g} Hz): {exact}; HB converged in H (amplitudes "
                             f"move by at most {moves[w]:.2g} between H = {Ha} and {Hb}) and within "
                             f"{abs(ab[k]):.2g} of it ({names[k]}). Both agree; drawn: the continued orbits.")
            else:
                lines.append(f"- {P:g} N, branch {m + 1} ({v.freq_hz:.5g} Hz): {exact}; HB is not converged in H: "
                             f"{names[w]} moves by {moves[w]:.2g} between H = {Ha} and {Hb} (HB / shooting - 1 at "
                             f"H = {Hb}: {ab[k]:.2g} at {names[k]}). The shooting is right; drawn: the continued "
                             "orbits, HB in contact faint.")
    return lines


def shoot_markdown(result) -> list[str]:
    """frc.md's section on shooting at the unsettled points: per point the start, the outcome, the defects, the
    largest |multiplier|, and the shot orbit against the curve's HB orbit (or the defect reached and why not).

    Parameters
    ----------
    result : FrictionFRCResult
    """
    names = result.names
    shots = [(P, c) for P, checks in result.checks.items() for c in checks if c.shooting is not None]
    lines = ["", "## Shooting with the sliders at the unsettled points (frc_friction_checks.csv, shoot_*)", ""]
    if not shots:
        return lines + ["Every point of the stepped sine settled: nothing to shoot."]
    lines += ["Where the stepped sine does not settle, the periodic orbit of the exact friction flow is shot for "
              "(reduced.periodic.friction_shooting.shoot_friction: 8 nodes of the augmented state [x; v; w], w the "
              "sliders' positions; Newton with a finite-difference Jacobian and minimum-norm steps, a slider open "
              "or stuck the whole period being a free direction; the multipliers from the monodromy by central "
              "differences), from the curve's HB orbit at that frequency whatever its stability, then from HB "
              "with more harmonics at that frequency while Newton does not converge. The defect is in units of "
              "the amplitude (multiple shooting; the period defect from one run over the whole period). HB vs "
              f"shooting: the relative difference of max |{names[0]}|, and the largest difference of the time "
              f"histories over the period relative to the point's amplitude, at {names[0]} and at the worst point. "
              "Stable: by the shot orbit's multipliers / by Hill's method on the HB solution.", "",
              "| level [N] | f [Hz] | start H | converged | defect | period defect | max abs multiplier | stable | "
              + " | ".join(f"{n} shot / HB [m]" for n in names) + f" | HB vs shot: {names[0]} | history: "
              f"{names[0]} / worst |", "|---" * (len(names) + 10) + "|"]
    for P, c in shots:
        sh = c.shooting
        if sh.converged:
            amps = " | ".join(f"{a:.4g} / {h:.4g}" for a, h in zip(sh.shoot_m, sh.hb_m, strict=True))
            worst = int(np.argmax(sh.history_rel))
            hill = {True: "yes", False: "no", None: "mixed"}[sh.hb_stable]
            lines.append(f"| {P:g} | {c.freq_hz:.4g} | {sh.start_H} | yes | {sh.defect:.2g} | {sh.period_defect:.2g} "
                         f"| {sh.max_abs_multiplier:.4g} | {'yes' if sh.stable else 'no'} / {hill} | {amps} | "
                         f"{sh.amp_rel[0]:.3g} | {sh.history_rel[0]:.3g} / {sh.history_rel[worst]:.3g} "
                         f"({names[worst]}) |")
        else:
            why = sh.message.replace("|", "\\|")  # a message's |R| must not split the table's cell
            lines.append(f"| {P:g} | {c.freq_hz:.4g} | {sh.start_H} | no: {why} | {sh.defect:.2g} | | | |"
                         + " |" * len(names) + " | |")
    return lines


def _hb_unconverged_in_contact(result, P, br) -> np.ndarray:
    """(k,) bool: the HB curve's points where a slider's tip touches, if the verdict at some continued branch says
    HB is not converged in H there (:func:`hb_converged`): drawn faint, the continued orbits being the drawn curve."""
    vs = (getattr(result, "verdicts", {}) or {}).get(P, [])
    if not any(hb_converged(v) is False for v in vs):
        return np.zeros(len(br.freq_hz), bool)
    return np.array([bool(np.any(br.balance.slider_state(z)[:, 0] < 1.0)) for z in br.z])


def _plot(path, result) -> None:
    """frc.png: the HB curves at the load's point (stable solid, unstable dotted; faint in contact where HB is not
    converged in H), the exact orbits continued by shooting (the drawn curve there), the frictionless open-gap
    response dashed, the exact settled points as circles; below, the stick and slip fractions of each slider."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = [result.names.index(result.scene.frc.point)]
    cols += [result.names.index(p) for p in result.scene.frc.also_points if result.names.index(p) not in cols]
    fig, axes = plt.subplots(len(cols) + 1, 1, figsize=(11, 3.2 * (len(cols) + 1)), sharex=True,
                             constrained_layout=True)
    for ax, col in zip(axes, cols, strict=False):
        for k, (P, br) in enumerate(result.curves.items()):
            c = f"C{k}"
            f_lin, a_lin = result.linear[P]
            ax.plot(f_lin, a_lin[:, col] * 1e3, "--", color=c, lw=0.7, label=f"open gaps, no friction, {P:g} N")
            if not isinstance(br, Exception):
                a = br.amplitude_m[:, col] * 1e3
                H = br.balance.H
                faint = _hb_unconverged_in_contact(result, P, br)
                sure = np.where(faint, np.nan, a)
                ax.plot(br.freq_hz, np.where(br.stable, sure, np.nan), "-", color=c,
                        label=f"HB with friction, H = {H}, {P:g} N")
                ax.plot(br.freq_hz, np.where(br.stable, np.nan, sure), ":", color=c)
                if np.any(faint):
                    ax.plot(br.freq_hz, np.where(faint, a, np.nan), "-", color=c, lw=0.6, alpha=0.35,
                            label=f"HB, H = {H}, in contact: not converged in H (frc.md), {P:g} N")
            pts = result.checks[P]
            ax.plot([p.freq_hz for p in pts], [p.exact_m[col] * 1e3 for p in pts], "o", mfc="none", color=c,
                    label=f"exact, stepped sine, {P:g} N")
            for m, sc in enumerate(_curves(result.shooting.get(P))):
                sb = sc.branch
                a = sb.amplitude_m[:, col] * 1e3
                first = m == 0
                ax.plot(sb.freq_hz, np.where(sb.stable, a, np.nan), "-", color="k", lw=1.6,
                        label=f"exact orbits continued by shooting, stable, {P:g} N" if first else None)
                ax.plot(sb.freq_hz, np.where(sb.stable, np.nan, a), ".", color="k", ms=3,
                        label=f"exact orbits continued by shooting, unstable, {P:g} N" if first else None)
            for j, (PP, m, i, f, _kind) in enumerate(_bifurcation_labels(result)):
                if PP != P:
                    continue
                ai = result.shooting[P][m - 1].branch.amplitude_m[i, col] * 1e3
                ax.plot(f, ai, "s", mfc="none", color="r", ms=6,
                        label="bifurcations of the continued orbits (numbered: frc.md)" if j == 0 else None)
                # numbers above and below by turns, at two heights each: apart from each other and off the curve
                ax.annotate(str(j + 1), (f, ai), xytext=(0, (9, -14, 18, -23)[j % 4]), textcoords="offset points",
                            fontsize=7, color="r", ha="center",
                            bbox=dict(boxstyle="round,pad=0.1", fc="w", ec="none", alpha=0.8))
            for m, (_, _, sw, _) in enumerate(_sweeps(result, P)):
                ok = sw.converged
                ax.plot(sw.freq_hz[ok & sw.stable], sw.amplitude_m[ok & sw.stable, col] * 1e3, "D", color="k", ms=3,
                        label=f"exact orbits on a grid, stable, {P:g} N" if m == 0 else None)
                ax.plot(sw.freq_hz[ok & ~sw.stable], sw.amplitude_m[ok & ~sw.stable, col] * 1e3, "d", mfc="none",
                        color="k", ms=3, label=f"exact orbits on a grid, unstable, {P:g} N" if m == 0 else None)
            shot = [p for p in pts if p.shooting is not None and p.shooting.converged]
            if shot:
                ax.plot([p.freq_hz for p in shot], [p.shooting.shoot_m[col] * 1e3 for p in shot], "x", color=c,
                        label=f"exact periodic orbit by shooting, {P:g} N")
        ax.set_yscale("log")
        ax.set_ylabel(f"max |{result.names[col]}| [mm]")
    # the amplitude panels share their entries: one legend, beside the first panel, not over the curves
    axes[0].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax = axes[-1]
    for k, (P, br) in enumerate(result.curves.items()):
        if isinstance(br, Exception):
            continue
        ss = np.array([br.balance.slider_state(z) for z in br.z])
        for j, name in enumerate(br.balance.system.friction.names):
            ax.plot(br.freq_hz, ss[:, j, 1], "-", color=f"C{k}", lw=0.8 + j, label=f"{name} stick, {P:g} N")
            ax.plot(br.freq_hz, ss[:, j, 2], "--", color=f"C{k}", lw=0.8 + j, label=f"{name} slip, {P:g} N")
    ax.set_ylabel("share of the period")
    ax.set_xlabel("excitation frequency [Hz]")
    if ax.lines:
        ax.legend(fontsize=7, ncol=2)
    fig.suptitle(f"{result.scene.name}: forced response with friction at the tips (HB by AFT, exact orbits by "
                 "shooting)", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
