"""The ``study`` stage's files, from what :func:`bearingshaft.stages.study.compute` found.

``work_precision.csv``, ``stiff_cases.csv`` (``rom_stiff_cases.csv``), ``rom_convergence.csv``
and ``study.md`` hold no wall-clock time; ``*_timing.csv``, ``work_precision_timing.png``,
``rom_convergence_timing.png`` and ``study_timing.md`` hold the run times. Each number is
written to the digits that survive a rerun on another CPU (:mod:`bearingshaft.stages.study`
says how they were measured). No solver runs here.
"""

from __future__ import annotations

import math

from bearingshaft import plots
from bearingshaft.digits import ROUNDOFF_FLOOR, roundoff_bound, short, sig
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.stages.study_results import CONVERGENCE_BUDGET_S, StudyResult, step_basis  # noqa: F401  (re-exported)

RECOMMEND_FREQ_TOL = 1e-3  # relative error of the compared coupled frequencies (open and closed)
RECOMMEND_RINGDOWN_TOL = 1e-2  # relative max-norm error of the point motion against the reference

ERROR_DIGITS = 4  # significant digits of a truncation error (reproduced to >= 6 on another CPU)
SENSITIVE_DIGITS = 2  # DOP853's error without events, penetrations of chaotic runs: magnitudes only
VALUE_DIGITS = 12  # energies, steps, frequencies: exact up to round-off (~1e-15 relative)
PENETRATION_DIGITS = 4  # largest penetration: the same to 1e-15 except in chaotic runs (2e-5 seen)
TIMING_DIGITS = 4  # run times: machine load changes them by tens of percent anyway

WP_FIELDS = ["method", "setting", "error", "n_steps", "dt_s"]
TIMING_KEYS = {"work_precision": ["method", "setting"],
               "stiff": ["k_g", "gap", "speed", "c", "method", "duration_s"],
               "rom_convergence": ["n_modes"]}


def _timing_rows(rows: list[dict], keys: list[str], columns: list[str]) -> list[dict]:
    """The rows of a ``*_timing.csv``: the ``keys`` that name a run and its run times ``columns``.

    >>> _timing_rows([{"method": "exact", "setting": "", "runtime_s": 0.0123456, "error": 1e-9}],
    ...              ["method", "setting"], ["runtime_s"])
    [{'method': 'exact', 'setting': '', 'runtime_s': 0.01235}]
    """
    return [{**{k: r.get(k, "") for k in keys}, **{c: sig(r.get(c, ""), TIMING_DIGITS) for c in columns}}
            for r in rows]


def write(result: StudyResult, writer: StageWriter) -> None:
    """Write the studies' files, put their statistics in ``writer.stats``, print the observed order.

    Parameters
    ----------
    result : StudyResult
        What :func:`bearingshaft.stages.study.compute` returned.
    writer : StageWriter
        Where the files go.
    """
    scene = result.scene
    lines = [f"# Studies of scene `{scene.name}`", "",
             "Run times are in `study_timing.md` and the `*_timing.csv` files (they change with machine "
             "load on every run); every number here is reproduced by a rerun.", ""]
    timing = [f"# Run times of the studies of scene `{scene.name}`", "",
              "Wall-clock times of this run (machine load changes them by tens of percent between runs).", ""]
    if result.work_precision is not None:
        science, timed = _work_precision(scene, result.work_precision, result.explicit_order, writer)
        lines += science
        timing += timed
    if result.rom_convergence is not None:
        science, timed = _rom_convergence(scene, result.rom_convergence, result.n_full_dofs, writer)
        lines += science
        timing += timed
    if result.stiff_cases is not None:
        science, timed = _stiff_cases(scene, result.stiff_cases, result.stiff_fields, writer)
        lines += science
        timing += timed
    writer.path("study.md").write_text("\n".join(lines), encoding="utf-8")
    writer.path("study_timing.md").write_text("\n".join(timing), encoding="utf-8")


# -- work-precision --------------------------------------------------------------------------
def _wp_error(row: dict):
    """The error as written: the exact row is the reference against DOP853 with events (round-off
    level), DOP853 without events steps over the contact switches (sensitive), explicit is a
    truncation error."""
    if row["method"] == "exact":
        return roundoff_bound(row["error"])
    return sig(row["error"], SENSITIVE_DIGITS if row["method"] == "dop853" else ERROR_DIGITS)


def _work_precision(scene: Scene, rows: list[dict], order: float, writer: StageWriter
                    ) -> tuple[list[str], list[str]]:
    """work_precision.csv, its timing CSV and figure; study.md's and study_timing.md's sections."""
    wp = scene.work_precision
    written = [{"method": r["method"], "setting": r["setting"], "error": _wp_error(r), "n_steps": r["n_steps"],
                "dt_s": sig(r.get("dt", ""), VALUE_DIGITS)} for r in rows]
    write_rows(writer.path("work_precision.csv"), written, WP_FIELDS)
    write_rows(writer.path("work_precision_timing.csv"),
               _timing_rows(rows, TIMING_KEYS["work_precision"], ["runtime_s"]))
    plots.work_precision_figure(rows, order, writer.path("work_precision_timing.png"), wp.window_s)
    fitted = math.isfinite(order)
    order_text = f"{order:.2f}" if fitted else "not fitted"
    print(f"[{scene.name}] explicit central difference: observed order of accuracy {order_text}"
          + ("" if fitted else " (fewer than two explicit errors in (1e-12, 1e-2): add smaller explicit_omega_dt)"))
    writer.stats["explicit_observed_order"] = order
    writer.stats["work_precision"] = rows
    exact = next(r for r in rows if r["method"] == "exact")
    science = [
        "## Work-precision",
        "",
        f"Window 0-{wp.window_s:g} s, error = max over samples ({wp.sample_rate_hz:g} Hz) and DOFs of "
        "|x - x_ref| / max |x_ref|, reference = the exact integrator. Its own error, measured against DOP853 "
        f"with every stop crossing located as an event (rtol 1e-13), is below {short(roundoff_bound(exact['error']))} "
        f"(round-off of the comparison; written as the power of ten that bounds it, at least {ROUNDOFF_FLOOR:g}). "
        "Steps: events of the exact "
        "integrator, steps of the explicit one, right-hand-side evaluations of DOP853.",
        "",
        (f"Explicit central difference: observed order of accuracy **{order:.2f}** (theory 2)." if fitted else
         "Explicit central difference: no order fitted (fewer than two errors in the asymptotic range "
         "1e-12 ... 1e-2)."),
        "",
        "DOP853 without events steps over the contact switches: its error depends on where its steps "
        "fall, which round-off moves (a rerun on another CPU changed it by up to 3x); it is written to "
        f"{SENSITIVE_DIGITS} digits and compared as a magnitude.",
        "",
        "| method | setting | error | steps |",
        "|---|---|---|---|",
        *[f"| {r['method']} | {r['setting']} | {short(r['error'], '.4g')} | {r['n_steps']} |" for r in written],
        "",
    ]
    timed = [
        "## Work-precision",
        "",
        f"Run time of the {wp.window_s:g} s window: best of {wp.repeats} (DOP853: one run). Error against run "
        "time: `work_precision_timing.png`.",
        "",
        "| method | setting | run time [s] | error |",
        "|---|---|---|---|",
        *[f"| {r['method']} | {r['setting']} | {r['runtime_s']:.3g} | {short(w['error'], '.4g')} |"
          for r, w in zip(rows, written, strict=True)],
        "",
    ]
    return science, timed


# -- stiff and extreme cases -----------------------------------------------------------------
def _stiff_written(row: dict) -> dict:
    """A stiff-case row with its numbers at the digits that survive a rerun on another CPU."""
    out = dict(row)
    out["energy_J"] = sig(row["energy_J"], VALUE_DIGITS)
    out["energy_balance_error"] = (roundoff_bound(row["energy_balance_error"]) if row["method"] == "exact"
                                   else sig(row["energy_balance_error"], ERROR_DIGITS))
    out["max_penetration_m"] = sig(row["max_penetration_m"], PENETRATION_DIGITS)
    return out


def _stiff_cases(scene: Scene, rows: list[dict], stiff_fields: tuple[str, ...], writer: StageWriter
                 ) -> tuple[list[str], list[str]]:
    """stiff_cases.csv (rom_stiff_cases.csv) and its timing CSV; study.md's and study_timing.md's sections."""
    sc = scene.stiff_cases
    rom = scene.model_kind == "rom"
    name = "rom_stiff_cases" if rom else "stiff_cases"
    fields = [f for f in stiff_fields if f != "runtime_s"]
    fields = fields[:4] + ["duration_s"] + fields[4:] if rom else fields
    written = [_stiff_written(r) for r in rows]
    write_rows(writer.path(f"{name}.csv"), written, fields)
    write_rows(writer.path(f"{name}_timing.csv"), _timing_rows(rows, TIMING_KEYS["stiff"], ["runtime_s"]))
    ok = [r for r in rows if r["status"] == "ok"]
    refused = [r for r in rows if r["status"] == "refused"]
    bad = [r for r in rows if r["status"] not in ("ok", "refused")]
    worst = {m: max((r for r in ok if r["method"] == m and r["duration_s"] == sc.duration_s),
                    key=lambda r: r["energy_balance_error"], default=None) for m in sc.methods}
    long_rows = [r for r in rows if r["duration_s"] != sc.duration_s]
    writer.stats["stiff_cases"] = {"runs": len(rows), "ok": len(ok), "refused": len(refused),
                                   "failed": len(bad),
                                   "worst_energy_error": {m: (w["energy_balance_error"] if w else None)
                                                          for m, w in worst.items()},
                                   "long_runs": [{k: r[k] for k in ("c", "method", "status", "energy_balance_error",
                                                                     "n_steps", "runtime_s")} for r in long_rows]}
    model = (f"the reduced model ({scene.model.n_modes} fixed-interface modes; c = dashpots at x1, x2, x3; "
             "v3(0) = velocity of the point x3, in the three lowest modes)" if rom else "the discrete model")
    science = [
        "## Stiff and extreme cases" + (" (reduced model)" if rom else ""),
        "",
        f"{len(rows)} runs of {model}: {len(rows) - len(long_rows)} of {sc.duration_s:g} s for k_g in "
        f"{list(sc.k_g)} N/m, g in {list(sc.gap)} m, "
        f"v3(0) in {list(sc.speed)} m/s, c in {list(sc.c)} N s/m, methods {list(sc.methods)}"
        + (f"; and {len(long_rows)} runs of {sc.long_duration_s:g} s of the nominal case (k_g = {sc.k_g[0]:g} N/m, "
           f"g = 2.54e-4 m, v3(0) = 200 m/s) for every c" if long_rows else "")
        + f". {len(ok)} ran, {len(refused)} were refused with a reason, {len(bad)} produced a non-finite "
        "state. Energy-balance error = max_t |E(0) - E(t) - W(t)| / E(0); the exact integrator's is round-off, "
        f"written as the power of ten that bounds it, at least {ROUNDOFF_FLOOR:g} (below that its size changes "
        "from one CPU to another).",
        "",
        "Runs with thousands of impacts are chaotic: their event counts and largest penetration depend on "
        "round-off (a rerun on another CPU changed a few counts by up to 5 %); they are written as computed "
        "and compared as magnitudes.",
        "",
        f"| method | worst energy-balance error ({sc.duration_s:g} s runs) | case (k_g, g, v, c) | steps |",
        "|---|---|---|---|",
    ]
    for m, w in worst.items():
        if w is None:
            continue
        err = _stiff_written(w)["energy_balance_error"]
        if m == "exact":  # round-off: which run is worst is itself round-off, so no case is named
            science.append(f"| {m} | < {short(err)} | (every run) | |")
        else:
            science.append(f"| {m} | {short(err)} | ({w['k_g']:.3g}, {w['gap']:.3g}, {w['speed']:.3g}, "
                           f"{w['c']:.3g}) | {w['n_steps']} |")
    if long_rows:
        science += ["", f"Long runs ({sc.long_duration_s:g} s, nominal case):", "",
                    "| method | c [N s/m] | status | energy-balance error | steps | events |",
                    "|---|---|---|---|---|---|"]
        science += [f"| {r['method']} | {short(r['c'])} | {r['status']} | {'< ' if r['method'] == 'exact' else ''}"
                    f"{short(_stiff_written(r)['energy_balance_error'])} | {r['n_steps']} | {r['n_events']} |"
                    for r in long_rows]
    if refused:
        science += ["", "Refused:", ""]
        science += [f"- {r['method']} at (k_g, g, v, c) = ({short(r['k_g'])}, {short(r['gap'])}, "
                    f"{short(r['speed'])}, {short(r['c'])}), {short(r['duration_s'])} s: {r['reason']}"
                    for r in refused]
    science.append("")
    return science, _stiff_timing(name, rom, ok, long_rows)


def _stiff_timing(name: str, rom: bool, ok: list[dict], long_rows: list[dict]) -> list[str]:
    """study_timing.md's section on the stiff cases: the total, the slowest run, the long runs."""
    slowest = max(ok, key=lambda r: r["runtime_s"], default=None)
    total = sum(r["runtime_s"] for r in ok)
    timed = ["## Stiff and extreme cases" + (" (reduced model)" if rom else ""), "",
             f"{len(ok)} runs in {total:.3g} s of integration (`{name}_timing.csv` has each)."]
    if slowest is not None:
        timed.append(f"Slowest: {slowest['method']} at (k_g, g, v, c) = ({slowest['k_g']:.3g}, {slowest['gap']:.3g}, "
                     f"{slowest['speed']:.3g}, {slowest['c']:.3g}), {slowest['duration_s']:g} s: "
                     f"{slowest['runtime_s']:.3g} s for {slowest['n_steps']} steps.")
    if long_rows:
        timed += ["", "| method | c [N s/m] | run time [s] | steps |", "|---|---|---|---|"]
        timed += [f"| {r['method']} | {short(r['c'])} | {short(r['runtime_s'])} | {r['n_steps']} |"
                  for r in long_rows]
    timed.append("")
    return timed


# -- the reduced model against its number of modes ----------------------------------------------
def _recommend(rows: list[dict]) -> dict | None:
    """The fewest modes whose frequencies and ringdown meet the RECOMMEND_* tolerances."""
    good = [r for r in rows[:-1] if max(r["open_freq_error"], r["closed_freq_error"]) < RECOMMEND_FREQ_TOL
            and r["ringdown_error"] < RECOMMEND_RINGDOWN_TOL]
    return min(good, key=lambda r: r["n_modes"], default=None)


ROM_TIMING = ["build_s", "exact_s", "explicit_s"]
ROM_DIGITS = {"open_freq_error": ERROR_DIGITS, "closed_freq_error": ERROR_DIGITS, "ringdown_error": ERROR_DIGITS,
              "explicit_ringdown_error": ERROR_DIGITS, "explicit_error": ERROR_DIGITS, "omega_max": VALUE_DIGITS,
              "energy_J": VALUE_DIGITS}


def _rom_convergence(scene: Scene, rows: list[dict], n_full_dofs: int, writer: StageWriter
                     ) -> tuple[list[str], list[str]]:
    """rom_convergence.csv, its timing CSV and figure; study.md's and study_timing.md's sections."""
    rc, spec = scene.rom_convergence, scene.model
    written = [{k: sig(v, ROM_DIGITS[k]) if k in ROM_DIGITS else v for k, v in r.items() if k not in ROM_TIMING}
               for r in rows]
    write_rows(writer.path("rom_convergence.csv"), written)
    write_rows(writer.path("rom_convergence_timing.csv"), _timing_rows(rows, TIMING_KEYS["rom_convergence"],
                                                                       ROM_TIMING))
    plots.rom_convergence_figure(rows, writer.path("rom_convergence_timing.png"), rc.window_s)
    best = _recommend(rows)
    writer.stats["rom_convergence"] = {"rows": rows, "recommended_modes": best["n_modes"] if best else None}
    ref = rows[-1]["n_modes"]
    science = [
        "## Reduced model against its number of modes",
        "",
        f"The 3-D model ({spec.layout}, {n_full_dofs} DOFs) reduced onto x1, x3 and n fixed-interface modes "
        f"({'planar: the coupled ones only' if spec.planar else 'all'}). Frequency error = max over the first "
        f"{rc.n_compare} contact-coupled modes (or as many as the reduced model has) of |f_r - f| / f against the "
        "full model (open gap; closed = tied tips). Ringdown error = max over the window "
        f"0-{rc.window_s:g} s ({rc.sample_rate_hz:g} Hz) of |x P^T - x_ref P^T| / max |x_ref P^T| at the points "
        f"x1, x2, x3 against {ref} modes, all by the exact integrator from v(0) = {list(scene.initial.v0_m_s)} m/s "
        f"at the points. Explicit = central difference at its default step for step basis {step_basis(scene)!r} "
        "(reduced.transient.explicit; explicit error: against the exact run of the same model; explicit ringdown "
        f"error: against the exact {ref}-mode run). Build and run times: `study_timing.md`.",
        "",
        "| modes | DOFs | open freq error | closed freq error | ringdown error | exact events | explicit steps | "
        "explicit error | explicit ringdown error |",
        "|---|---|---|---|---|---|---|---|---|",
        *[f"| {r['n_modes']} | {r['n_dofs']} | {r['open_freq_error']:.3g} | {r['closed_freq_error']:.3g} | "
          f"{r['ringdown_error']:.3g} | {r['exact_events']} | {r['explicit_steps']} | {r['explicit_error']:.3g} | "
          f"{r['explicit_ringdown_error']:.3g} |" for r in rows],
        "",
    ]
    if best:
        science += [
            f"**Recommended: {best['n_modes']} modes**, the fewest with every compared frequency within "
            f"{RECOMMEND_FREQ_TOL:g} of the full model (open {best['open_freq_error']:.2g}, closed "
            f"{best['closed_freq_error']:.2g}) and the ringdown within {RECOMMEND_RINGDOWN_TOL:g} of the "
            f"{ref}-mode model ({best['ringdown_error']:.2g}) over the window. More modes add fixed-interface "
            "frequencies the contact barely excites and raise omega_max, hence the explicit step count "
            f"({best['explicit_steps']} steps over the window here, {rows[-1]['explicit_steps']} with {ref} modes) "
            "with step basis 'top'; step basis 'contact' sets the step by the contact dynamics instead "
            "(omega dt = 0.05 on the three lowest modes that move the gaps, capped at omega_max dt = 1; "
            "benchmarks/rom_speed.py measures both).",
            "",
        ]
    else:
        science += ["No mode count below the reference meets the recommendation tolerances "
                    f"(frequencies {RECOMMEND_FREQ_TOL:g}, ringdown {RECOMMEND_RINGDOWN_TOL:g}).", ""]
    timed = [
        "## Reduced model against its number of modes",
        "",
        f"Build = Craig-Bampton time (the shared 3-D assembly not included); run times of the {rc.window_s:g} s "
        f"window are the best of {rc.repeats} (one run once {CONVERGENCE_BUDGET_S:g} s is spent). Error against "
        "run time: `rom_convergence_timing.png`.",
        "",
        "| modes | build [s] | exact [s] | explicit [s] | ringdown error | explicit ringdown error |",
        "|---|---|---|---|---|---|",
        *[f"| {r['n_modes']} | {r['build_s']:.3g} | {r['exact_s']:.3g} | {r['explicit_s']:.3g} | "
          f"{r['ringdown_error']:.3g} | {r['explicit_ringdown_error']:.3g} |" for r in rows],
        "",
    ]
    return science, timed
