"""The ringdown stage's files and figures, from what it computed (:mod:`bearingshaft.stages.ringdown`).

:func:`write` reads the run back from ``ringdown.npz`` chunk by chunk (its envelopes: memory
independent of its length) and writes ``ringdown.png``, the stage's statistics and summary line,
then the files of each analysis: ``reference.csv`` and ``lyapunov.csv`` (:func:`write_reference`),
``spectrogram.png`` (:func:`write_spectrogram`), ``symmetry.csv``, ``symmetry_seeds.csv`` and
``symmetry.png`` (:func:`write_symmetry`). It runs no solver.
"""

from __future__ import annotations

import math

import numpy as np

from bearingshaft import plots
from bearingshaft.digits import text
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.stages.ringdown_results import (
    BREAK_THRESHOLD_M,
    GROWTH_BAND,
    LYAPUNOV_DELTA,
    REFERENCE_WINDOW_S,
    SYMMETRY_PERTURBATION_M,
    SYMMETRY_SEEDS,
    RingdownOutcome,
    SpectrogramData,
    SymmetryData,
)

TITLE_NOTE = "break time from round-off alone is not reproducible across machines"


def write(result: RingdownOutcome, writer: StageWriter) -> None:
    """ringdown.png, the stage's statistics (``writer.stats``) and summary line, then the analyses' files.

    Parameters
    ----------
    result : what :func:`bearingshaft.stages.ringdown.compute` returned
    writer : the stage's results folder (``ringdown.npz`` is already in it)
    """
    scene, res, method = result.scene, result.run, result.method
    spec = scene.ringdown
    env = plots.ringdown_envelopes(res, loads=result.loads)
    plots.ringdown_figure(res, writer.path("ringdown.png"), f"{scene.name}: {scene.description}", env, result.loads)
    forced = {}
    if result.loads is not None:
        t_W, W_ext = env["Wext"].upper()
        forced = {"loads": [f"{spec_l.kind} at {spec_l.point}" for spec_l in scene.loads],
                  "work_of_loads_J_max": float(np.max(W_ext)), "energy_J_max": env["scale"]}
    writer.stats.update(
        {"method": method, "duration_s": spec.duration_s, "energy_J_initial": env["E0"], **forced,
         "energy_balance_error": res.energy_balance_error, "n_samples": res.n_samples,
         "ringdown_npz_bytes": writer.path("ringdown.npz").stat().st_size, **res.stats}
    )
    print(f"[{scene.name}] {method}: {integrator_work(method, res.stats)}; "
          f"{res.n_samples} samples of {spec.duration_s:g} s, energy-balance error {res.energy_balance_error:.2g}"
          + (f" (with the work of the loads, {forced['work_of_loads_J_max']:.4g} J)" if forced else ""), flush=True)
    if result.summary is not None:
        writer.stats["summary"] = result.summary.stats()
        print(f"[{scene.name}] {summary_line(result.summary)}", flush=True)
    if result.reference is not None:
        write_reference(scene, res, result.reference, writer)
    if result.spectrogram is not None:
        write_spectrogram(scene, method, res.sample_rate_hz, result.spectrogram, env, writer)
    if result.symmetry is not None:
        write_symmetry(scene, res.n_samples, result.symmetry, writer)


def integrator_work(method: str, stats: dict) -> str:
    """What the integrator did, in words that say what its counts count.

    Parameters
    ----------
    method : str
        "exact", "explicit" or "dop853".
    stats : dict
        Its statistics (``n_events``, ``n_steps``, ``dt``).

    Returns
    -------
    str

    Examples
    --------
    >>> integrator_work("exact", {"n_events": 12864, "n_steps": 12865})
    '12864 contact switches, each found and crossed exactly (closed form between them)'
    >>> integrator_work("explicit", {"n_steps": 400000, "dt": 5e-06})
    '400000 time steps of 5e-06 s'
    >>> integrator_work("dop853", {"n_steps": 9000, "n_events": 12})
    '9000 accepted steps, restarted at 12 contact switches'
    >>> integrator_work("dop853", {"n_steps": 9000, "n_events": 0})
    '9000 accepted steps (adaptive, stepping over the contact switches)'
    """
    if method == "exact":
        return f"{stats.get('n_events', 0)} contact switches, each found and crossed exactly (closed form between them)"
    if method == "explicit":
        return f"{stats.get('n_steps', 0)} time steps of {stats.get('dt', float('nan')):.3g} s"
    if stats.get("n_events"):
        return f"{stats.get('n_steps', 0)} accepted steps, restarted at {stats['n_events']} contact switches"
    return f"{stats.get('n_steps', 0)} accepted steps (adaptive, stepping over the contact switches)"


def summary_line(s) -> str:
    """The run in engineering numbers, one line (:class:`~bearingshaft.stages.ringdown_results.RunSummary`).

    Parameters
    ----------
    s : RunSummary
        The run's summary.

    Returns
    -------
    str
        Impacts (per stop), peak tip force, when the gaps stay open, peak |x| and |a| of each point.
    """
    if s.impacts_total == 0:
        contact = "no impact (the gaps never close)"
    else:
        per = ", ".join(f"{name} {n}" for name, n in zip(s.stop_names, s.impacts, strict=True))
        late = " (still closing at the end of the run)" if s.still_closing else ""
        contact = (f"{s.impacts_total} impacts ({per}), peak tip force {s.peak_tip_force_N:.4g} N, "
                   f"gaps open after {s.gaps_open_after_s:.4g} s{late}")
    peaks = ", ".join(f"{p} {x:.3g} m, {a:.3g} m/s^2" for p, x, a in
                      zip(s.point_names, s.peak_displacement_m, s.peak_acceleration_m_s2, strict=True))
    return f"{contact}; peak |x|, |a|: {peaks}"


def write_spectrogram(scene: Scene, method: str, sample_rate_hz: float, data: SpectrogramData, env: dict,
                      writer: StageWriter) -> None:
    """spectrogram.png: the spectrogram of the [spectrogram] point with the NNM curves mapped onto
    time through the run's energy envelope ``env["E"]``.

    Parameters
    ----------
    scene : Scene
        A scene with a [spectrogram] table.
    method : str
        The run's integrator (in the title).
    sample_rate_hz : float
        Hz, the run's sampling.
    data : SpectrogramData
        The spectrogram and its overlays.
    env : dict
        :func:`bearingshaft.plots.ringdown_envelopes` of the run (``env["E"]`` is used).
    writer : StageWriter
        Where the figure goes.

    Returns
    -------
    None
    """
    sp, S = scene.spectrogram, data.spectrogram
    t_E, E = env["E"].upper()
    thinned = f", hop {S.hop / sample_rate_hz:.3g} s" if S.hop > round(sp.window_s * sample_rate_hz
                                                                        * (1 - sp.overlap)) + 1 else ""
    plots.spectrogram_figure(
        S, (t_E, E[:, 0]), data.curves, writer.path("spectrogram.png"),
        f"{scene.name}: spectrogram of {sp.dof} ({method}{thinned}); open-gap "
        f"{', '.join(f'{f:.1f}' for f in data.f_open_hz)} Hz",
        sp.fmax_hz, sp.db_range,
    )


# -- reference check: the run against the exact integrator -------------------------------------
def _spread(values: list[float]) -> tuple[float, float, float]:
    """(min, median, max) of the values that are not None or NaN (NaNs if none).

    >>> _spread([3.0, None, 1.0, float("nan"), 2.0])
    (1.0, 2.0, 3.0)
    """
    v = [x for x in values if x is not None and not math.isnan(x)]
    if not v:
        return math.nan, math.nan, math.nan
    return float(np.min(v)), float(np.median(v)), float(np.max(v))


def write_reference(scene: Scene, res, cmp, writer: StageWriter) -> dict:
    """``reference.csv`` (one row per quantity: the run against the exact run beside the spread of the
    displaced exact runs among themselves), ``lyapunov.csv`` (one row per displaced pair), the summary
    (``writer.stats["reference"]``, returned) and its line.

    The quantities: the pointwise error at the points (max |p - p_exact| / max |p_exact|) over the
    first REFERENCE_WINDOW_S, up to the onset of the displaced pairs' separation and over the run;
    the energy envelope error (max over windows of |mean E - mean E_exact| / mean E_exact); the
    fraction of spectrogram frames whose dominant frequency agrees within one bin, and their median
    difference; the stop closures (impacts) counted from the samples; the Lyapunov exponent and the
    onset. The run is judged by whether its differences from the exact run are within the spread of
    the exact runs among themselves, not by a pointwise number over the whole run.

    Parameters
    ----------
    scene, res : the scene and its run
    cmp : a :class:`~bearingshaft.stages.ringdown_results.ReferenceComparison`
    writer : the stage's :class:`~bearingshaft.output.StageWriter`

    Returns
    -------
    dict : the summary
    """
    run_r, seed_r, est = cmp.run, cmp.seeds, cmp.lyapunov
    onsets = [e.onset_s for e in est]
    onset = float(np.min(onsets))  # the earliest: before it no displaced pair has separated
    lam = _spread([e.exponent_per_s for e in est if e.chaotic])
    chaotic = any(e.chaotic for e in est)
    rows = _reference_rows(scene, run_r, seed_r, est, onset, chaotic)
    write_rows(writer.path("reference.csv"), rows)
    write_rows(writer.path("lyapunov.csv"), [
        {"seed": k, "delta": text(e.delta), "saturation": text(e.saturation), "window_s": text(e.window_s),
         "exponent_per_s": text(e.exponent_per_s), "lyapunov_time_s": text(e.lyapunov_time_s),
         "onset_s": text(e.onset_s), "saturation_s": text(e.saturation_s), "fit_start_s": text(e.fit_start_s),
         "fit_end_s": text(e.fit_end_s), "ln_growth_fitted": text(e.ln_growth), "residual": text(e.residual, 2),
         "chaotic": e.chaotic} for k, e in enumerate(est)])
    summary = {"run_vs_exact": {r["quantity"]: r["run_vs_exact"] for r in rows},
               "closures_run": run_r.closures_run, "closures_exact": run_r.closures_ref,
               "lyapunov_exponent_per_s": lam, "onset_s": onset, "chaotic": chaotic,
               "exact_wall_s": cmp.exact_stats.get("wall_s"), "exact_n_events": cmp.exact_stats.get("n_events"),
               "exact_tolerance_m": cmp.exact_tolerance}
    writer.stats["reference"] = summary
    print(_reference_line(scene, res.method, run_r, seed_r, onset, lam, chaotic), flush=True)
    return summary


def _reference_rows(scene: Scene, run_r, seed_r: list, est: list, onset: float, chaotic: bool) -> list[dict]:
    """The rows of reference.csv."""
    names = scene.model.point_names
    duration_s = scene.ringdown.duration_s
    freq_point = names.index(scene.spectrogram.dof) if scene.spectrogram is not None else 0

    def row(quantity, unit, run_value, seed_values, meaning):
        lo, mid, hi = _spread(seed_values)
        return {"quantity": quantity, "unit": unit, "run_vs_exact": text(run_value),
                "exact_pairs_min": text(lo), "exact_pairs_median": text(mid), "exact_pairs_max": text(hi),
                "meaning": meaning}

    pts = "max |p - p_exact| / max |p_exact| at the points " + ", ".join(names)
    rows = [
        row("pointwise_error_first_window", "relative", run_r.pointwise_error[0],
            [r.pointwise_error[0] for r in seed_r], f"{pts} over the first {REFERENCE_WINDOW_S:g} s"),
    ]
    if math.isfinite(onset):
        rows.append(row("pointwise_error_to_onset", "relative", run_r.pointwise_error_until(onset),
                        [r.pointwise_error_until(onset) for r in seed_r],
                        f"{pts} up to {onset:g} s, when exact runs {LYAPUNOV_DELTA:g} apart start to separate"))
    rows += [
        row("pointwise_error_whole_run", "relative", run_r.pointwise_error[1], [r.pointwise_error[1] for r in seed_r],
            f"{pts} over the whole {duration_s:g} s run"
            + ("; after the onset it measures the chaos of the motion, not the integrator" if chaotic else "")),
        row("energy_envelope_error", "relative", run_r.energy_envelope_error,
            [r.energy_envelope_error for r in seed_r],
            f"max over {run_r.energy_window_s:g} s windows of |mean E - mean E_exact| / mean E_exact"),
        row("dominant_frequency_agreement", "fraction of frames", run_r.freq_agreement,
            [r.freq_agreement for r in seed_r],
            f"spectrogram frames of {names[freq_point]} whose peak frequencies agree within one bin "
            f"({run_r.freq_resolution_hz:g} Hz)"),
        row("dominant_frequency_median_difference", "Hz", run_r.freq_median_diff_hz,
            [r.freq_median_diff_hz for r in seed_r], "median over frames of |f_peak - f_peak,exact|"),
        row("stop_closures_difference", "relative", run_r.closures_diff, [r.closures_diff for r in seed_r],
            f"(closures - closures_exact) / closures_exact, counted from the samples; exact: {run_r.closures_ref}"),
        row("lyapunov_exponent", "1/s", None, [e.exponent_per_s for e in est],
            f"slope of ln |y_b - y_a| over its growth phase, exact runs {LYAPUNOV_DELTA:g} apart (lyapunov.csv)"),
        row("separation_onset", "s", None, [e.onset_s for e in est],
            "when the separation of the displaced exact runs has grown 100-fold (inf: never)"),
    ]
    return rows


def _reference_line(scene: Scene, method: str, run_r, seed_r: list, onset: float, lam: tuple, chaotic: bool) -> str:
    """The reference check's summary line."""
    duration_s = scene.ringdown.duration_s
    head = (f"[{scene.name}] {method} against exact: pointwise error {run_r.pointwise_error[0]:.2g} over the "
            f"first {REFERENCE_WINDOW_S:g} s")
    if not chaotic:
        return (f"{head}, {run_r.pointwise_error[1]:.2g} over the {duration_s:g} s run; exact runs "
                f"{LYAPUNOV_DELTA:g} apart do not separate (lambda = {lam[1]:.3g} /s), so the whole-run error is the "
                f"integrator's: energy envelope {run_r.energy_envelope_error:.2%}, stop closures "
                f"{run_r.closures_run} vs {run_r.closures_ref}")
    sp_e = _spread([r.energy_envelope_error for r in seed_r])
    sp_f = _spread([r.freq_agreement for r in seed_r])
    sp_c = _spread([r.closures_diff for r in seed_r])
    return (f"{head}, {run_r.pointwise_error_until(onset):.2g} up to {onset:.3g} s, when exact runs "
            f"{LYAPUNOV_DELTA:g} apart start to separate at lambda = {lam[1]:.3g} /s (Lyapunov time "
            f"{1e3 / lam[1]:.3g} ms): the motion is chaotic, so the {run_r.pointwise_error[1]:.2g} over the "
            f"{duration_s:g} s run is no integrator error. Over the run (run vs exact; exact pairs): energy "
            f"envelope {run_r.energy_envelope_error:.2%} ({sp_e[0]:.2%} to {sp_e[2]:.2%}), dominant frequency "
            f"agrees in {run_r.freq_agreement:.0%} of frames ({sp_f[0]:.0%} to {sp_f[2]:.0%}), stop closures "
            f"{run_r.closures_run} vs {run_r.closures_ref} ({run_r.closures_diff:+.1%}; "
            f"{sp_c[0]:+.1%} to {sp_c[2]:+.1%})")


# -- symmetry breaking -----------------------------------------------------------------------
def write_symmetry(scene: Scene, n_samples: int, sym: SymmetryData, writer: StageWriter) -> None:
    """``symmetry_seeds.csv`` (one row per seed), ``symmetry.csv`` (one row per case: the seeded runs,
    then each method's round-off run), ``symmetry.png``, ``writer.stats["symmetry"]`` and the summary
    line of the study (:func:`bearingshaft.stages.ringdown.symmetry_runs`).

    Parameters
    ----------
    scene : Scene
        A scene with a [symmetry] table.
    n_samples : int
        Samples of the run.
    sym : SymmetryData
        The study.
    writer : StageWriter
        Where the files go.

    Returns
    -------
    None
    """
    for method, wall in sym.wall_s.items():
        writer.stats.setdefault("symmetry_wall_s", {})[method] = wall
    band = (BREAK_THRESHOLD_M * GROWTH_BAND, BREAK_THRESHOLD_M)
    seed_rows = [{"seed": k, "perturbation_m": text(SYMMETRY_PERTURBATION_M), "theta_rad": text(sym.thetas[k]),
                  "break_threshold_m": text(BREAK_THRESHOLD_M), "t_break_s": text(a.t_break, 6),
                  "growth_rate_per_s": text(a.growth_rate, 3)} for k, a in enumerate(sym.seeded)]
    write_rows(writer.path("symmetry_seeds.csv"), seed_rows)
    rates = _spread([a.growth_rate for a in sym.seeded])
    breaks = _spread([a.t_break if a.t_break is not None else math.nan for a in sym.seeded])
    n_broken = sum(a.t_break is not None for a in sym.seeded)
    common = {"break_threshold_m": text(BREAK_THRESHOLD_M), "growth_fit_band_m": f"{band[0]:g} to {band[1]:g}"}
    rows = [{"case": "seeded", "method": "exact", "perturbation_m": text(SYMMETRY_PERTURBATION_M),
             "runs": SYMMETRY_SEEDS, "growth_rate_per_s": text(rates[1], 3), "growth_rate_min_per_s": text(rates[0], 3),
             "growth_rate_max_per_s": text(rates[2], 3), "break_threshold_m": common["break_threshold_m"],
             "runs_broken": n_broken, "t_break_s": text(breaks[1], 6), "t_break_min_s": text(breaks[0], 6),
             "t_break_max_s": text(breaks[2], 6), "growth_fit_band_m": common["growth_fit_band_m"],
             "t_break_seed0_other_roundoff_s": text(sym.restarted_t_break, 6), "tolerance_m": "",
             "t_exceeds_tolerance_s": "",
             "reproducible_across_machines": "yes (the spread over seeds is the uncertainty)"}]
    for method, (a, tol) in sym.runs.items():
        rows.append({"case": "round-off", "method": method, "perturbation_m": 0, "runs": 1,
                     "growth_rate_per_s": text(a.growth_rate, 3), "growth_rate_min_per_s": "",
                     "growth_rate_max_per_s": "", "break_threshold_m": common["break_threshold_m"],
                     "runs_broken": int(a.t_break is not None), "t_break_s": text(a.t_break, 6), "t_break_min_s": "",
                     "t_break_max_s": "", "growth_fit_band_m": common["growth_fit_band_m"],
                     "t_break_seed0_other_roundoff_s": "", "tolerance_m": text(tol, 2),
                     "t_exceeds_tolerance_s": text(sym.t_tol[method], 6),
                     "reproducible_across_machines":
                         "no: round-off sets the break time and so the phase where the rate is fitted"})
    write_rows(writer.path("symmetry.csv"), rows)
    seeds_text = (f"seeded ({SYMMETRY_SEEDS} x {SYMMETRY_PERTURBATION_M:g} m, antisymmetric): growth "
                  f"{rates[1]:.3g}/s [{rates[0]:.3g}, {rates[2]:.3g}], break at {BREAK_THRESHOLD_M:g} m: "
                  f"{breaks[1]:.3g} s [{breaks[0]:.3g}, {breaks[2]:.3g}] ({n_broken} of {SYMMETRY_SEEDS} broke)")
    pair = sym.pair
    plots.symmetry_figure(
        sym.points, pair, sym.primary,
        {m: (a.env, tol, a.t_break) for m, (a, tol) in sym.runs.items()}, [a.env for a in sym.seeded],
        BREAK_THRESHOLD_M, writer.path("symmetry.png"),
        f"{scene.name}: symmetry breaking of {pair[0]} and {pair[1]}; {seeds_text}; the {TITLE_NOTE}",
    )
    writer.stats["symmetry"] = {"seeded": rows[0], "round_off": rows[1:], "seeds": seed_rows}
    roundoff = ", ".join(f"{m} {text(a.t_break, 4) or 'none'} s" for m, (a, _) in sym.runs.items())
    print(f"[{scene.name}] symmetry: {seeds_text}; seed 0 with another round-off: {text(sym.restarted_t_break, 4)} s; "
          f"from round-off alone (not reproducible across machines): {roundoff}", flush=True)
