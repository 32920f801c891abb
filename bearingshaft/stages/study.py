"""Stage ``study``: error against run time, and the stiff and extreme cases."""

from __future__ import annotations

import numpy as np

from bearingshaft import plots
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.stages.ringdown import _Bar
from reduced.studies import stiff_cases, work_precision


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
    if scene.stiff_cases is not None:
        sc = scene.stiff_cases
        bar = _Bar(f"{scene.name}: stiff cases", progress)
        rows = stiff_cases(scene.model, sc.k_g, sc.gap, sc.speed, sc.c, sc.duration_s, sc.sample_rate_hz,
                           sc.methods, progress=bar)
        bar.close()
        fields = ["k_g", "gap", "speed", "c", "method", "status", "energy_J", "energy_balance_error",
                  "n_steps", "n_events", "runtime_s", "max_penetration_m", "reason"]
        write_rows(writer.path("stiff_cases.csv"), rows, fields)
        ok = [r for r in rows if r["status"] == "ok"]
        refused = [r for r in rows if r["status"] == "refused"]
        bad = [r for r in rows if r["status"] not in ("ok", "refused")]
        worst = {m: max((r for r in ok if r["method"] == m), key=lambda r: r["energy_balance_error"],
                        default=None) for m in sc.methods}
        writer.stats["stiff_cases"] = {"runs": len(rows), "ok": len(ok), "refused": len(refused),
                                       "failed": len(bad),
                                       "worst_energy_error": {m: (w["energy_balance_error"] if w else None)
                                                              for m, w in worst.items()}}
        lines += [
            "## Stiff and extreme cases",
            "",
            f"{len(rows)} runs of {sc.duration_s:g} s: k_g in {list(sc.k_g)} N/m, g in {list(sc.gap)} m, "
            f"v3(0) in {list(sc.speed)} m/s, c in {list(sc.c)} N s/m, methods {list(sc.methods)}. "
            f"{len(ok)} ran, {len(refused)} were refused with a reason, {len(bad)} produced a non-finite "
            "state. Energy-balance error = max_t |E(0) - E(t) - W(t)| / E(0).",
            "",
            "| method | worst energy-balance error | case (k_g, g, v, c) | steps | run time [s] |",
            "|---|---|---|---|---|",
        ]
        for m, w in worst.items():
            if w is not None:
                lines.append(
                    f"| {m} | {w['energy_balance_error']:.3g} | ({w['k_g']:.3g}, {w['gap']:.3g}, {w['speed']:.3g}, "
                    f"{w['c']:.3g}) | {w['n_steps']} | {w['runtime_s']:.3g} |"
                )
        if refused:
            lines += ["", "Refused:", ""]
            lines += [f"- {r['method']} at (k_g, g, v, c) = ({_fmt(r['k_g'])}, {_fmt(r['gap'])}, "
                      f"{_fmt(r['speed'])}, {_fmt(r['c'])}): {r['reason']}" for r in refused]
        lines.append("")
    writer.path("study.md").write_text("\n".join(lines), encoding="utf-8")
