"""The files of the hammer stage (:mod:`bearingshaft.stages.hammer`), from what it computed
(:mod:`bearingshaft.stages.hammer_results`): records, figures, the level sweep, the linear
check, ``hammer.md``, and the comparison with a measured test. Runs no solver.

Numbers in the science files are written to :data:`DIGITS` significant digits, to
:data:`EVENT_DIGITS` for the quantities that depend on where the exact integrator lands a
crossing (peak forces, times of contact).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft import correlate  # noqa: E402
from bearingshaft.correlate import ChannelError, ChannelPair  # noqa: E402
from bearingshaft.digits import roundoff_bound, sig, text, to_resolution  # noqa: E402
from bearingshaft.output import StageWriter, write_rows  # noqa: E402
from bearingshaft.plots import Envelope, wrap_title  # noqa: E402
from bearingshaft.reproduction import DELTA0, HORIZON_TOL  # noqa: E402
from bearingshaft.scenes import Scene  # noqa: E402
from bearingshaft.stages.hammer_results import Comparison, LinearCheck, Record, VirtualTest, histories  # noqa: E402
from fem.rig import TIP_CELLS  # noqa: E402
from fem.uff import write_uff58  # noqa: E402
from reduced import _checks  # noqa: E402
from reduced.models.rig import VirtualRig  # noqa: E402
from reduced.transient.spectrogram import MAX_FRAMES, curve_in_time, spectrogram  # noqa: E402

DIGITS = 6  # significant digits of the science files
EVENT_DIGITS = 4  # quantities set by where a crossing lands (peak forces, times of contact)
LINEAR_RESOLUTION = 1e-6  # linear check: a relative RMS error below this is written 0; the reduced model's matrices
# themselves move by ~1e-8 with the BLAS's rounding (another CPU), and such errors (axes near zero by symmetry) moved
# by 40 % between two machines
SPECTRO_DB = 80.0  # dB shown below each spectrogram's peak


def write(result: VirtualTest | Comparison, writer: StageWriter) -> None:
    """The files of the virtual test, or of the comparison with a measured test; the statistics into
    ``writer.stats``; the summary lines printed.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.hammer.compute`
    writer : the stage's writer (its folder and statistics)
    """
    if isinstance(result, Comparison):
        write_comparison(result, writer)
    else:
        write_virtual_test(result, writer)
    writer.stats.update(result.stats)
    for line in result.lines:
        print(line, flush=True)


def write_virtual_test(result: VirtualTest, writer: StageWriter) -> None:
    """``hammer.npz``, ``channels.csv``, ``hammer.uff``, ``fig10.png``, ``fig11.png``, ``levels.csv``,
    ``levels.png``, with a linear check ``linear_check.csv`` and ``linear_check.png``, and ``hammer.md``.

    Parameters
    ----------
    result : the virtual test
    writer : the stage's writer
    """
    scene, rig, nominal = result.scene, result.rig, result.nominal
    write_record(writer, rig, nominal, scene)
    fig10(writer.path("fig10.png"), rig, nominal, scene.hammer)
    fig11(writer.path("fig11.png"), rig, nominal, scene, result.labels, result.backbones)
    levels_csv(writer.path("levels.csv"), result.summary)
    levels_figure(writer.path("levels.png"), rig, result.records, result.summary, scene)
    if result.linear is not None:
        linear_check_csv(writer.path("linear_check.csv"), result.linear)
        linear_check_figure(writer.path("linear_check.png"), result.linear)
    if result.lyapunov:
        lyapunov_csv(writer.path("lyapunov.csv"), result.lyapunov)
    write_markdown(writer.path("hammer.md"), result)


def _chaos_text(estimates) -> list[str]:
    """The line of hammer.md that says how long the record's chaotic numbers are comparable (empty without
    an exponent)."""
    lam = max((e.exponent_per_s for e in estimates if e.chaotic and math.isfinite(e.exponent_per_s)), default=math.nan)
    if not math.isfinite(lam) or lam <= 0:
        return []
    t_h = math.log(HORIZON_TOL / DELTA0) / lam  # the reproduction report's horizon
    return [f"- Chaos: after the blow the motion separates from a run started 1e-9 away at up to {lam:.3g} /s "
            f"(the largest Lyapunov exponent, lyapunov.csv), so round-off alone grows to 1e-4 of the state in "
            f"{t_h:.2g} s: the impacts, peak forces, when the gaps stay open and the energy at the end differ from "
            "one machine to another, and the reproduction report compares them as chaotic."]


def lyapunov_csv(path: Path, estimates) -> None:
    """``lyapunov.csv``: the nominal record's largest Lyapunov exponent, one row per displaced run (the
    columns of the ringdown stage's ``lyapunov.csv``); the reproduction report reads its horizon here.

    Parameters
    ----------
    path : the CSV written
    estimates : LyapunovEstimate per displaced run (:func:`bearingshaft.stages.hammer.record_lyapunov`)
    """
    write_rows(path, [
        {"seed": k, "delta": text(e.delta), "saturation": text(e.saturation), "window_s": text(e.window_s),
         "exponent_per_s": text(e.exponent_per_s), "lyapunov_time_s": text(e.lyapunov_time_s),
         "onset_s": text(e.onset_s), "saturation_s": text(e.saturation_s), "fit_start_s": text(e.fit_start_s),
         "fit_end_s": text(e.fit_end_s), "ln_growth_fitted": text(e.ln_growth), "residual": text(e.residual, 2),
         "chaotic": e.chaotic} for k, e in enumerate(estimates)])


def balance_text(error: float) -> str:
    """The exact integrator's energy-balance error as written: round-off, so the power of ten that bounds it
    (:func:`bearingshaft.digits.roundoff_bound`; its digits change from one CPU to another).

    Parameters
    ----------
    error : float
        Relative energy-balance error.

    Returns
    -------
    str

    Examples
    --------
    >>> balance_text(9.6e-12), balance_text(3.4e-9)
    ('1e-10', '1e-08')
    """
    return f"{roundoff_bound(error):g}"


def write_record(writer: StageWriter, rig: VirtualRig, rec: Record, scene: Scene) -> None:
    """``hammer.npz``, ``channels.csv`` and ``hammer.uff`` of the nominal blow.

    Parameters
    ----------
    writer : the stage's writer
    rig : the rig that made ``rec``
    rec : the nominal blow's record
    scene : the scene (its name goes into the UFF header)
    """
    np.savez(writer.path("hammer.npz"), t=rec.t, data=rec.data, names=np.array(rig.names),
             nodes=np.array([c.node for c in rig.channels]), directions=np.array([c.direction for c in rig.channels]),
             units=np.array([c.unit for c in rig.channels]), level_N=rec.level_N,
             location_m=np.array(rig.location), direction=np.array(rig.direction))
    rows = []
    for c in rig.channels:
        where = {"accelerometer": c.name.split(":")[0], "load_cell": c.name, "hammer": "beam (struck point)"}[c.kind]
        rows.append({"name": c.name, "kind": c.kind, "where": where, "node": c.node, "direction": c.direction,
                     "quantity": c.quantity, "unit": c.unit})
    write_rows(writer.path("channels.csv"), rows)
    write_uff58(writer.path("hammer.uff"), histories(rig, rec.t, rec.data), model=f"bearingshaft {scene.name}")


# -- figures ---------------------------------------------------------------------------------
def fig10(path: Path, rig: VirtualRig, rec: Record, spec) -> None:
    """The hammer force and one tip load cell against time (the paper's Fig. 10).

    Parameters
    ----------
    path : the PNG written
    rig : the rig that made ``rec``
    rec : the nominal blow's record
    spec : the scene's [hammer] (start of the blow, the load cell drawn)
    """
    names = list(rig.names)
    t_end = min(rec.t[-1], spec.start_s + 0.1)
    keep = rec.t <= t_end
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
    a1.plot(rec.t[keep] * 1e3, rec.data[names.index("hammer")][keep], color="k", lw=1)
    a1.set_ylabel("hammer force [N]")
    a2.plot(rec.t[keep] * 1e3, rec.data[names.index(spec.load_cell)][keep], color="tab:red", lw=0.8)
    a2.set_ylabel(f"{spec.load_cell} load cell [N]")
    a2.set_xlabel("time [ms]")
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a1.set_title(wrap_title(f"Virtual hammer test: {rec.level_N:g} N blow at {where(rig.location)} (top) and the "
                            f"{spec.load_cell.replace('_', ' ')} load cell, contact force minus its seismic mass's "
                            "inertia (bottom); compare the paper's Fig. 10"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def where(location: tuple[float, float, float]) -> str:
    """The struck point, m, as the figures and hammer.md say it (mm, one decimal).

    Parameters
    ----------
    location : (float, float, float)
        m, the point struck.

    Returns
    -------
    str
        mm, one decimal each.

    Examples
    --------
    >>> where((0.0, -0.00125, 0.0254))
    '(0.0, -1.2, 25.4) mm'
    """
    x, y, z = location
    return f"({x * 1e3:.1f}, {y * 1e3:.1f}, {z * 1e3:.1f}) mm"


def _spectro(ax, rec: Record, channel: int, scene: Scene, fmax: float, db_range: float = SPECTRO_DB):
    sp = scene.spectrogram
    window, overlap = (sp.window_s, sp.overlap) if sp else (0.05, 0.9)
    s = spectrogram(rec.t, rec.data[channel], window, overlap, fmax_hz=fmax)
    db = 10 * np.log10(np.maximum(s.power, 1e-300))
    top = float(db.max())
    mesh = ax.pcolormesh(s.t, s.freq_hz, db, shading="nearest", cmap="viridis", vmin=top - db_range, vmax=top,
                         rasterized=True)
    ax.set_ylim(0, fmax)
    ax.set_xlim(s.t[0], s.t[-1])
    return mesh


def spectrogram_channel(scene: Scene) -> str:
    """The channel of Fig. 11: [spectrogram] dof if it names one, else the middle beam accelerometer's z.

    Parameters
    ----------
    scene : Scene
        The scene (its [spectrogram] table, if any).

    Returns
    -------
    str
        A rig channel name such as ``beam_s3:z``.
    """
    sp = scene.spectrogram
    return sp.dof if sp is not None and ":" in sp.dof else "beam_s3:z"


def fig11(path: Path, rig: VirtualRig, rec: Record, scene: Scene, labels: dict, curves: dict) -> None:
    """Spectrogram of a beam accelerometer with the pseudo-rigid open-gap frequencies (dashed) and
    the NNM backbones mapped onto time by the record's energy, f(E(t)).

    Parameters
    ----------
    path : the PNG written
    rig : the rig that made ``rec``
    rec : the nominal blow's record
    scene : the scene ([spectrogram]: channel, window, band, colour range)
    labels : {label: (mode index, freq_hz, score)} the pseudo-rigid modes
    curves : {label: (energy_J, freq_hz)} the NNM backbones
    """
    name = spectrogram_channel(scene)
    fmax = scene.spectrogram.fmax_hz if scene.spectrogram else 1500.0
    fig, ax = plt.subplots(figsize=(9, 5.5), constrained_layout=True)
    mesh = _spectro(ax, rec, list(rig.names).index(name), scene, fmax,
                    scene.spectrogram.db_range if scene.spectrogram else SPECTRO_DB)
    fig.colorbar(mesh, ax=ax, label="PSD [dB re 1 (m/s^2)^2/Hz]")
    rigid = sorted(labels.items(), key=lambda kv: kv[1][1])
    for _, (_, f, _) in rigid:
        ax.axhline(f, color="w", ls="--", lw=0.7, alpha=0.8)
    if rigid:
        ax.plot([], [], color="w", ls="--", lw=0.7,
                label="pseudo-rigid: " + ", ".join(f"{k} {v[1]:.1f}" for k, v in rigid) + " Hz")
    colors = ("r", "orange", "magenta", "cyan")
    for i, (label, (E, f)) in enumerate(curves.items()):
        ax.plot(rec.t, curve_in_time(np.maximum(rec.energy, 1e-300), E, f), color=colors[i % 4], lw=1.2,
                label=label)
    if curves or rigid:
        ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title(wrap_title(f"{name} after a {rec.level_N:g} N blow at {where(rig.location)}: spectrogram with the "
                            "six pseudo-rigid open-gap frequencies (dashed) and the NNM backbones f(E(t)); compare "
                            "the paper's Fig. 11"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- the level sweep ---------------------------------------------------------------------------
def levels_csv(path: Path, summary: dict) -> None:
    """``levels.csv``: one row per blow level (impacts, peak contact forces, when the gaps stay open,
    where the energy is at the end, the hammer's work, the energy balance).

    Parameters
    ----------
    path : the CSV written
    summary : {level_N: level summary (:func:`bearingshaft.stages.hammer.level_summary`)}
    """
    rows = []
    for level, s in summary.items():
        rows.append({"level_N": sig(level, DIGITS), "impacts": s["impacts_total"],
                     **{f"impacts_{c}": s["impacts"][c] for c in TIP_CELLS},
                     **{f"peak_contact_{c}_N": sig(s["peak_contact_N"][c], EVENT_DIGITS) for c in TIP_CELLS},
                     "gaps_open_after_s": sig(s["gaps_open_after_s"], EVENT_DIGITS),
                     "end_bungee_share": sig(s["end_bungee_share"], 3),
                     "end_mode_hz": sig(s["end_modes"][0]["freq_hz"], DIGITS), "end_mode": s["end_modes"][0]["label"],
                     "end_mode_share_of_beam": sig(s["end_modes"][0]["share"], 3),
                     "hammer_work_J": sig(s["hammer_work_J"], DIGITS),
                     "energy_balance_error": balance_text(s["energy_balance_error"])})
    write_rows(path, rows)


def levels_figure(path: Path, rig: VirtualRig, records: dict, summary: dict, scene: Scene) -> None:
    """``levels.png``: one spectrogram of the Fig. 11 channel per blow level.

    Parameters
    ----------
    path : the PNG written
    rig : the rig that made the records
    records : {level_N: Record}
    summary : {level_N: level summary}, for the panels' titles
    scene : the scene ([spectrogram])
    """
    name = spectrogram_channel(scene)
    fmax = scene.spectrogram.fmax_hz if scene.spectrogram else 1500.0
    n = len(records)
    cols = 2 if n > 1 else 1
    nrows = math.ceil(n / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(11, 2.8 * nrows + 0.8), sharex=True, sharey=True,
                             constrained_layout=True, squeeze=False)
    for ax, (level, rec) in zip(axes.ravel(), records.items(), strict=False):
        _spectro(ax, rec, list(rig.names).index(name), scene, fmax)
        s = summary[level]
        ax.set_title(f"{level:g} N: {s['impacts_total']} impacts, gaps open after "
                     f"{s['gaps_open_after_s']:.3g} s", fontsize=9)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("frequency [Hz]")
    fig.suptitle(wrap_title(f"{name}: how the ringdown changes with the blow level (each panel {SPECTRO_DB:g} dB "
                            "below its own peak)", 120), fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- the linear check --------------------------------------------------------------------------
def linear_check_csv(path: Path, linear: LinearCheck) -> None:
    """``linear_check.csv``: per channel, the relative RMS errors in the band and raw, over the
    window after the blow and over the whole record, and whether the axis is near zero.

    Parameters
    ----------
    path : the CSV written
    linear : the linear check
    """
    e = linear.errors

    def cell(v: float) -> str:  # below LINEAR_RESOLUTION: 0, the reduced model is not reproducible to less
        return text(to_resolution(float(v), LINEAR_RESOLUTION, 3), 3)

    write_rows(path, [{"channel": c, "near_zero": bool(linear.near_zero[i]),
                       "rms_rel_error": cell(e[('band', '50ms')][i]),
                       "rms_rel_error_record": cell(e[('band', 'record')][i]),
                       "rms_rel_error_raw": cell(e[('raw', '50ms')][i]),
                       "rms_rel_error_raw_record": cell(e[('raw', 'record')][i])}
                      for i, c in enumerate(linear.names)])


def linear_check_figure(path: Path, linear: LinearCheck) -> None:
    """``linear_check.png``: the worst channel, reduced against full, and every channel's error.

    Parameters
    ----------
    path : the PNG written
    linear : the linear check
    """
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 7), constrained_layout=True)
    worst = linear.worst_channel
    a1.plot(linear.t * 1e3, linear.full_band, color="k", lw=1.6, label="full 3-D, modal superposition")
    a1.plot(linear.t * 1e3, linear.rom_band, color="tab:orange", lw=0.8, ls="--",
            label="reduced model, exact integrator")
    a1.set_xlabel("time [ms]")
    a1.set_ylabel(f"{worst} [{'N' if worst.startswith('tip') else 'm/s^2'}]")
    a1.legend(fontsize=8)
    a1.set_title(wrap_title(f"Linear check, open gaps: the worst channel {worst} over the first 50 ms after the blow "
                            f"(both low-passed at {linear.band_hz:g} Hz)"), fontsize=10)
    band = linear.errors[("band", "50ms")]
    err = [100 * e for e in band]
    a2.bar(range(len(band)), err, color="tab:blue")
    a2.axhline(100 * linear.bound, color="r", ls="--", lw=1, label="1 % bound")
    a2.set_xticks(range(len(band)), linear.names, rotation=90, fontsize=6)
    a2.set_ylabel("RMS error [%]")
    a2.set_yscale("log")
    a2.legend(fontsize=8)
    a2.set_title(f"every channel: rms(reduced - full) / rms(full), {1e3 * linear.window_s:g} ms after the blow, "
                 f"{linear.band_hz:g} Hz band", fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- hammer.md ---------------------------------------------------------------------------------
def write_markdown(path: Path, result: VirtualTest) -> None:
    """``hammer.md``: the pseudo-rigid modes, the nominal blow, the level sweep, the backbones and
    the linear check, in numbers.

    Parameters
    ----------
    path : the Markdown file written
    result : the virtual test
    """
    from fem.labels import TABLE2_ORDER, TABLE2_TEST_HZ

    scene, rig, summary = result.scene, result.rig, result.summary
    spec = scene.hammer
    s = summary[spec.peak_N]
    lines = [f"# Virtual hammer test: {scene.name}", "",
             f"Reduced apparatus: {rig.system.n} coordinates (x1, x3 and {rig.system.n - 2} fixed-interface modes), "
             f"{len(rig.channels)} channels. Blow: "
             f"{'measured history ' + spec.force_file if spec.force_file else 'half-sine'}"
             f" of {spec.duration_s * 1e3:g} ms at {where(rig.location)} along "
             f"{tuple(round(d, 6) for d in rig.direction)}, "
             f"starting at {spec.start_s:g} s; record {scene.ringdown.duration_s:g} s at "
             f"{scene.ringdown.sample_rate_hz:g} Hz by the {scene.ringdown.method} integrator.", "",
             "## Pseudo-rigid open-gap modes (the dashed lines of fig11.png)", "",
             "| label | model [Hz] | paper's test, Table 2 [Hz] | score (1: a pure rigid motion) |",
             "|---|---|---|---|"]
    for label, (_, f, sc) in sorted(result.labels.items(), key=lambda kv: kv[1][1]):
        lines.append(f"| {label} | {f:.4g} | {TABLE2_TEST_HZ[TABLE2_ORDER.index(label)]:.4g} | {sc:.3f} |")
    lines += ["", f"## The nominal blow, {spec.peak_N:g} N", ""]
    lines += _level_text(s, result.end_share_s)
    lines += _chaos_text(result.lyapunov)
    lines += ["", "## Level sweep (levels.csv, levels.png)", "",
              "| level [N] | impacts | peak tip force [N] | gaps open after [s] | on the bungees at the end | "
              "the rest mostly in |", "|---|---|---|---|---|---|"]
    for level, t in summary.items():
        top = t["end_modes"][0]
        lines.append(f"| {level:g} | {t['impacts_total']} | {max(t['peak_contact_N'].values()):.4g} | "
                     f"{t['gaps_open_after_s']:.4g} | {100 * t['end_bungee_share']:.1f} % | {top['label']} "
                     f"{top['freq_hz']:.4g} Hz ({100 * top['share']:.1f} %) |")
    if result.backbones:
        lines += ["", "NNM backbones on fig11.png (HB, H = 1, on the subsystem of the modes the gaps couple to): "
                  + ", ".join(result.backbones) + "."]
    if result.linear is not None:
        lines += ["", "## Linear check (linear_check.csv, linear_check.png)", "", result.linear.text]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _level_text(s: dict, end_share_s: float) -> list[str]:
    """The bullet list of one level's summary in hammer.md."""
    lines = []
    if s["impacts_total"] == 0:
        lines.append("- The gaps never close: the response is linear.")
    else:
        per = ", ".join(f"{c.replace('tip_', '')} {n}" for c, n in s["impacts"].items())
        lines.append(f"- Impacts: {s['impacts_total']} ({per}); the exact integrator found {s['crossings_found']} "
                     f"gap crossings ({s['crossings_found'] // 2} closures and openings).")
        peak = ", ".join(f"{c.replace('tip_', '')} {f:.4g} N" for c, f in s["peak_contact_N"].items())
        lines.append(f"- Peak contact forces: {peak}.")
        lines.append(f"- The gaps stay open after {s['gaps_open_after_s']:.4g} s.")
    cells = ", ".join(f"{c.replace('tip_', '')} {f:.4g} N" for c, f in s["peak_load_cell_N"].items())
    lines.append(f"- Peak load-cell readings (contact plus seismic inertia): {cells}.")
    ends = "; ".join(f"mode {e['mode']} ({e['label']}) at {e['freq_hz']:.4g} Hz, {100 * e['share']:.1f} %"
                     for e in s["end_modes"])
    lines.append(f"- Energy in the last {end_share_s:g} s: {s['end_energy_J']:.3g} J, of which "
                 f"{100 * s['end_bungee_share']:.1f} % is the whole assembly swinging on its bungees; the rest "
                 f"(the beam on its springs and the elastic modes) is carried by: {ends}.")
    lines.append(f"- Work of the hammer: {s['hammer_work_J']:.6g} J by the integrator, "
                 f"{s['hammer_work_trapezoid_J']:.6g} J from the hammer channel times the struck point's velocity "
                 f"(trapezoid on the samples); energy balance error below {balance_text(s['energy_balance_error'])} "
                 "(round-off: written as the power of ten that bounds it).")
    return lines


# -- a measured test ---------------------------------------------------------------------------
def write_comparison(result: Comparison, writer: StageWriter) -> None:
    """``test_errors.csv``, ``test_compare.png``, ``test_spectrogram.png`` and ``model.uff``.

    Parameters
    ----------
    result : the comparison with a measured test
    writer : the stage's writer
    """
    scene, pairs = result.scene, result.pairs
    correlate.write_errors_csv(result.rows, writer.path("test_errors.csv"))
    comparison_figure(pairs, writer.path("test_compare.png"),
                      f"{scene.name} against {Path(result.test_file).name}: model driven by {result.driven}",
                      window_s=result.window_s)
    name = spectrogram_channel(scene)
    pair = next((p for p in pairs if p.name == name), pairs[0])
    sp = scene.spectrogram
    spectrogram_pair_figure(pair, writer.path("test_spectrogram.png"), sp.window_s if sp else 0.05,
                            sp.overlap if sp else 0.9, sp.fmax_hz if sp else 1500.0,
                            title=f"{pair.name}: model (left) and test (right)")
    write_uff58(writer.path("model.uff"), result.model, model=f"bearingshaft {scene.name}")


def comparison_figure(pairs: list[ChannelPair], path: str | Path, title: str, channels: list[str] | None = None,
                      window_s: tuple[float, float] | None = None) -> None:
    """Model and test time histories overlaid, one panel per channel, each titled with its
    rms_rel_error over the window. A long record is drawn as its min/max per pixel column
    (:class:`bearingshaft.plots.Envelope`).

    Parameters
    ----------
    pairs : matched channels (:func:`bearingshaft.correlate.match_channels`)
    path : the PNG written
    title : the figure's title
    channels : names of the pairs drawn, in this order (default: :func:`bearingshaft.correlate.default_channels`)
    window_s : (t_start_s, t_end_s), s, absolute times drawn (default: each pair's whole overlap)
    """
    chosen = correlate.select_pairs(pairs, channels)
    if not chosen:
        raise ChannelError("no channel to draw")
    fig, axes = plt.subplots(len(chosen), 1, figsize=(9, 1.9 * len(chosen) + 1.0), sharex=True,
                             constrained_layout=True, squeeze=False)
    for ax, p in zip(axes[:, 0], chosen, strict=True):
        a = p.aligned(window_s)
        env = Envelope(a.t.size, a.sample_rate_hz, 2)
        env.add(0, np.column_stack([a.model, a.test]))
        t, y = env.lines()
        t = t + a.t[0]
        ax.plot(t, y[:, 1], color="k", lw=0.8, label="test" + (" (sign flipped)" if p.flipped else ""))
        ax.plot(t, y[:, 0], color="C3", lw=0.8, alpha=0.85, label="model")
        rms_x = correlate.rms(a.test)
        err = correlate.rms(a.model - a.test) / rms_x if rms_x > 0 else math.inf
        ax.set_title(f"{p.name} (node {p.node}, direction {correlate.direction_label(p.direction)}): "
                     f"rms error {100 * err:.3g} %", fontsize=9, loc="left")
        ax.set_ylabel(f"{p.quantity.replace('_', ' ')}\n[{p.unit}]", fontsize=9)
        ax.legend(loc="upper right", fontsize=7)
        ax.set_xlim(a.t[0], a.t[-1])
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(wrap_title(title), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def spectrogram_pair_figure(pair: ChannelPair, path: str | Path, window_s: float, overlap: float, fmax_hz: float,
                            db_range: float = 60.0, title: str | None = None,
                            span_s: tuple[float, float] | None = None) -> None:
    """Spectrograms of the model (left) and the test (right) of one channel on one colour scale.

    ``window_s`` (s) and ``overlap`` are the STFT's (:func:`reduced.transient.spectrogram.spectrogram`:
    Hann window, PSD scaling, mean removed); the colour scale spans ``db_range`` dB below the
    larger of the two maxima.

    Parameters
    ----------
    pair : a matched channel (:func:`bearingshaft.correlate.match_channels`)
    path : the PNG written
    window_s, overlap : s, the STFT's window, and its overlap
    fmax_hz : Hz, the top of the frequency axis
    db_range : dB shown below the larger maximum
    title : the figure's title (default: the channel's name)
    span_s : (t_start_s, t_end_s), s, absolute times drawn (default: the common samples)
    """
    a = pair.aligned(span_s)
    specs = []
    for label, y in (("model", a.model), ("test", a.test)):
        try:
            specs.append(spectrogram(a.t, y, window_s, overlap, fmax_hz=fmax_hz, max_frames=MAX_FRAMES))
        except _checks.InvalidArgument as exc:
            raise ChannelError(f"channel {pair.name!r} ({label}): {exc}") from None
    dbs = [10.0 * np.log10(np.maximum(s.power, 1e-300)) for s in specs]
    top = max(float(np.max(d)) for d in dbs)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), sharey=True, constrained_layout=True)
    for ax, s, db, label in zip(axes, specs, dbs, ("model", "test" + (" (sign flipped)" if pair.flipped else "")),
                                strict=True):
        mesh = ax.pcolormesh(s.t, s.freq_hz, db, shading="nearest", cmap="viridis", vmin=top - db_range, vmax=top,
                             rasterized=True)
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("time [s]")
        ax.set_ylim(0, fmax_hz)
    axes[0].set_ylabel("frequency [Hz]")
    fig.colorbar(mesh, ax=axes, label=f"PSD [dB re 1 ({pair.unit})^2/Hz]")
    head = title or f"{pair.name}: model and test spectrograms"
    fig.suptitle(wrap_title(f"{head} (node {pair.node}, direction {correlate.direction_label(pair.direction)}; "
                            f"Hann {window_s:g} s, overlap {overlap:g})"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
