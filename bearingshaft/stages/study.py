"""Stage ``study``: error against run time, the stiff and extreme cases, and (reduced model)
the convergence with the number of fixed-interface modes."""

from __future__ import annotations

import numpy as np

from bearingshaft import plots
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.stages.ringdown import _Bar
from reduced.studies import STIFF_FIELDS, rom_case, rom_convergence, stiff_cases, work_precision

ROM_MAX_EXPLICIT_STEPS = 1e8  # explicit stiff-case runs of the reduced model predicted beyond this
# are refused (~20 s at 7 DOFs; a 10 s run at k_g = 1e11 would need ~1.2e8)
CONVERGENCE_BUDGET_S = 2.0  # s, stop repeating a timed run once this is spent on it
RECOMMEND_FREQ_TOL = 1e-3  # relative error of the compared coupled frequencies (open and closed)
RECOMMEND_RINGDOWN_TOL = 1e-2  # relative max-norm error of the point motion against the reference


def _fmt(v, spec: str = ".3g") -> str:
    return format(v, spec) if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def study_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    lines = [f"# Studies of scene `{scene.name}`", ""]
    if scene.work_precision is not None:
        wp = scene.work_precision
        bar = _Bar(f"{scene.name}: work-precision", progress)
        rows, order = work_precision(
            scene.model.system(), np.array(scene.initial.x0_m), np.array(scene.initial.v0_m_s), wp.window_s,
            wp.sample_rate_hz, wp.explicit_omega_dt, wp.dop853_rtol, wp.repeats, progress=bar,
        )
        bar.close()
        write_rows(writer.path("work_precision.csv"), rows, ["method", "setting", "runtime_s", "error"])
        plots.work_precision_figure(rows, order, writer.path("work_precision.png"), wp.window_s)
        print(f"[{scene.name}] explicit central difference: observed order of accuracy {order:.3f}")
        writer.stats["explicit_observed_order"] = order
        writer.stats["work_precision"] = rows
        lines += [
            "## Work-precision",
            "",
            f"Window 0-{wp.window_s:g} s, error = max over samples ({wp.sample_rate_hz:g} Hz) and DOFs of "
            "|x - x_ref| / max |x_ref|, reference = the exact integrator (whose own error is measured "
            "against DOP853 with every stop crossing located as an event, rtol 1e-13). Run time is the "
            f"best of {wp.repeats} (DOP853: one run).",
            "",
            f"Explicit central difference: observed order of accuracy **{order:.3f}** (theory 2).",
            "",
            "| method | setting | run time [s] | error |",
            "|---|---|---|---|",
            *[f"| {r['method']} | {r['setting']} | {r['runtime_s']:.4g} | {r['error']:.3g} |" for r in rows],
            "",
        ]
    if scene.rom_convergence is not None:
        lines += _rom_convergence(scene, writer, progress)
    if scene.stiff_cases is not None:
        lines += _stiff_cases(scene, writer, progress)
    writer.path("study.md").write_text("\n".join(lines), encoding="utf-8")


def _step_basis(scene: Scene) -> str:
    """The explicit step basis of the scene's ringdown (reduced.transient.explicit), "top" without one."""
    return scene.ringdown.step_basis if scene.ringdown is not None else "top"


def _stiff_cases(scene: Scene, writer: StageWriter, progress: bool) -> list[str]:
    sc = scene.stiff_cases
    rom = scene.model_kind == "rom"
    bar = _Bar(f"{scene.name}: stiff cases", progress)
    if rom:
        spec = scene.model
        base = rom_case(spec.reduced(progress), spec)
        extra = {"long_duration_s": sc.long_duration_s, "max_steps": ROM_MAX_EXPLICIT_STEPS,
                 "step_basis": _step_basis(scene)}
    else:
        base, extra = scene.model, {"long_duration_s": sc.long_duration_s}
    rows = stiff_cases(base, sc.k_g, sc.gap, sc.speed, sc.c, sc.duration_s, sc.sample_rate_hz, sc.methods,
                       progress=bar, **extra)
    bar.close()
    name = "rom_stiff_cases.csv" if rom else "stiff_cases.csv"
    fields = STIFF_FIELDS if not rom else STIFF_FIELDS[:4] + ["duration_s"] + STIFF_FIELDS[4:]
    write_rows(writer.path(name), rows, fields)
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
    lines = [
        "## Stiff and extreme cases" + (" (reduced model)" if rom else ""),
        "",
        f"{len(rows)} runs of {model}: {len(rows) - len(long_rows)} of {sc.duration_s:g} s for k_g in "
        f"{list(sc.k_g)} N/m, g in {list(sc.gap)} m, "
        f"v3(0) in {list(sc.speed)} m/s, c in {list(sc.c)} N s/m, methods {list(sc.methods)}"
        + (f"; and {len(long_rows)} runs of {sc.long_duration_s:g} s of the nominal case (k_g = {sc.k_g[0]:g} N/m, "
           f"g = 2.54e-4 m, v3(0) = 200 m/s) for every c" if long_rows else "")
        + f". {len(ok)} ran, {len(refused)} were refused with a reason, {len(bad)} produced a non-finite "
        "state. Energy-balance error = max_t |E(0) - E(t) - W(t)| / E(0).",
        "",
        f"| method | worst energy-balance error ({sc.duration_s:g} s runs) | case (k_g, g, v, c) | steps | "
        "run time [s] |",
        "|---|---|---|---|---|",
    ]
    for m, w in worst.items():
        if w is not None:
            lines.append(
                f"| {m} | {w['energy_balance_error']:.3g} | ({w['k_g']:.3g}, {w['gap']:.3g}, {w['speed']:.3g}, "
                f"{w['c']:.3g}) | {w['n_steps']} | {w['runtime_s']:.3g} |"
            )
    if long_rows:
        lines += ["", f"Long runs ({sc.long_duration_s:g} s, nominal case):", "",
                  "| method | c [N s/m] | status | energy-balance error | steps | events | run time [s] |",
                  "|---|---|---|---|---|---|---|"]
        lines += [f"| {r['method']} | {_fmt(r['c'])} | {r['status']} | {_fmt(r['energy_balance_error'])} | "
                  f"{r['n_steps']} | {r['n_events']} | {_fmt(r['runtime_s'])} |" for r in long_rows]
    if refused:
        lines += ["", "Refused:", ""]
        lines += [f"- {r['method']} at (k_g, g, v, c) = ({_fmt(r['k_g'])}, {_fmt(r['gap'])}, "
                  f"{_fmt(r['speed'])}, {_fmt(r['c'])}), {_fmt(r['duration_s'])} s: {r['reason']}" for r in refused]
    lines.append("")
    return lines


def _recommend(rows: list[dict]) -> dict | None:
    """The fewest modes whose frequencies and ringdown meet the RECOMMEND_* tolerances."""
    good = [r for r in rows[:-1] if max(r["open_freq_error"], r["closed_freq_error"]) < RECOMMEND_FREQ_TOL
            and r["ringdown_error"] < RECOMMEND_RINGDOWN_TOL]
    return min(good, key=lambda r: r["n_modes"], default=None)


def _rom_convergence(scene: Scene, writer: StageWriter, progress: bool) -> list[str]:
    from dataclasses import replace

    from bearingshaft.stages.reduce import full_gap_modes
    from fem.model import build_system
    from reduced.models.rom import build_rom

    rc, spec = scene.rom_convergence, scene.model
    fe = build_system(spec.fe_model())
    full = full_gap_modes(fe, spec)
    full_hz = {s: g.freq_hz[g.coupled] for s, g in full.items()}
    bar = _Bar(f"{scene.name}: reduced model vs modes", progress)
    roms = {}
    for i, n in enumerate(sorted(set(rc.modes))):
        roms[n] = build_rom(replace(spec, n_modes=n), fe=fe)[0]
        bar(0.2 * (i + 1) / len(rc.modes))
    rows = rom_convergence(roms, full_hz, scene.initial.x0_m, scene.initial.v0_m_s, rc.window_s,
                           rc.sample_rate_hz, rc.n_compare, rc.repeats, CONVERGENCE_BUDGET_S,
                           progress=lambda f: bar(0.2 + 0.8 * f), step_basis=_step_basis(scene))
    bar.close()
    write_rows(writer.path("rom_convergence.csv"), rows)
    plots.rom_convergence_figure(rows, writer.path("rom_convergence.png"), rc.window_s)
    best = _recommend(rows)
    writer.stats["rom_convergence"] = {"rows": rows, "recommended_modes": best["n_modes"] if best else None}
    ref = rows[-1]["n_modes"]
    lines = [
        "## Reduced model against its number of modes",
        "",
        f"The 3-D model ({spec.layout}, {fe.n_dofs} DOFs) reduced onto x1, x3 and n fixed-interface modes "
        f"({'planar: the coupled ones only' if spec.planar else 'all'}). Frequency error = max over the first "
        f"{rc.n_compare} contact-coupled modes (or as many as the reduced model has) of |f_r - f| / f against the "
        "full model (open gap; closed = tied tips). Ringdown error = max over the window "
        f"0-{rc.window_s:g} s ({rc.sample_rate_hz:g} Hz) of |x P^T - x_ref P^T| / max |x_ref P^T| at the points "
        f"x1, x2, x3 against {ref} modes, all by the exact integrator from v(0) = {list(scene.initial.v0_m_s)} m/s "
        "at the points. Build = Craig-Bampton time (the shared 3-D assembly not included); run times are the best "
        f"of {rc.repeats} (one run once {CONVERGENCE_BUDGET_S:g} s is spent); explicit = central difference at "
        f"its default step for step basis {_step_basis(scene)!r} (reduced.transient.explicit; "
        "explicit error: against the "
        "exact run of the same model; "
        f"explicit ringdown error: against the exact {ref}-mode run).",
        "",
        "| modes | DOFs | open freq error | closed freq error | ringdown error | build [s] | exact [s] | "
        "explicit [s] | explicit steps | explicit error | explicit ringdown error |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *[f"| {r['n_modes']} | {r['n_dofs']} | {r['open_freq_error']:.3g} | {r['closed_freq_error']:.3g} | "
          f"{r['ringdown_error']:.3g} | {r['build_s']:.3g} | {r['exact_s']:.3g} | {r['explicit_s']:.3g} | "
          f"{r['explicit_steps']} | {r['explicit_error']:.3g} | {r['explicit_ringdown_error']:.3g} |" for r in rows],
        "",
    ]
    if best:
        lines += [
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
        lines += ["No mode count below the reference meets the recommendation tolerances "
                  f"(frequencies {RECOMMEND_FREQ_TOL:g}, ringdown {RECOMMEND_RINGDOWN_TOL:g}).", ""]
    return lines
