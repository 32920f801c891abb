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
from bearingshaft.measures import MEASURE_FIELDS  # noqa: E402
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
FIG10_SPAN_S = 0.1  # s, Fig. 10's window after the blow's start (then on to the end of a contact in progress)
FIG10_MARGIN_S = 0.002  # s, open gaps shown after the last contact in Fig. 10's window
BLOW_THRESHOLD = 1e-3  # the blow: where |hammer| exceeds this fraction of its peak (Fig. 10's inset)
ZOOM_WINDOW_S = 0.5  # s, Fig. 11's low band: a window whose 2 Hz bins part most pseudo-rigid lines
ZOOM_MIN_HZ = 50.0  # Hz, the least top of Fig. 11's low band
ZOOM_HEADROOM = 1.3  # the low band reaches this much above the highest pseudo-rigid frequency (room for labels)
LABEL_GAP = 0.06  # the names of the pseudo-rigid lines: at least this fraction of the band apart


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
    fig11(writer.path("fig11.png"), rig, nominal, scene, result.labels, result.backbones,
          result.summary[nominal.level_N]["gaps_open_after_s"])
    levels_csv(writer.path("levels.csv"), result.summary)
    levels_figure(writer.path("levels.png"), rig, result.records, result.summary, scene)
    if result.linear is not None:
        linear_check_csv(writer.path("linear_check.csv"), result.linear)
        linear_check_figure(writer.path("linear_check.png"), result.linear)
    if result.lyapunov:
        lyapunov_csv(writer.path("lyapunov.csv"), result.lyapunov)
    if result.friction is not None:
        friction_csv(writer.path("friction.csv"), result.friction)
        _save(draw_friction(rig, nominal, result.friction, scene, result.labels), writer.path("friction.png"))
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




DECAY_SHOWN = ("longitudinal", "lateral", "yaw", "roll")  # the motions friction at the tips acts on (friction.png)
ENERGY_FLOOR = 1e-8  # friction.png's energy panel spans [ENERGY_FLOOR, 3] x the largest modal energy of either run


def friction_csv(path: Path, fc) -> None:
    """``friction.csv``: per pseudo-rigid motion, its modal energy's peak, end and 1 % time with friction and
    without, the decay rate of its energy once the gaps stay open (fitted, each run; and the closed form
    2 zeta_r omega_r of its open-gap mode), and the 1 % time extrapolated along that rate where the record ends
    before it (:class:`bearingshaft.stages.hammer_results.FrictionComparison`).

    Parameters
    ----------
    path : the CSV written
    fc : the comparison
    """
    rows = ["motion,freq_hz,peak_J_friction,peak_J_frictionless,end_J_friction,end_J_frictionless,"
            "t_1pct_s_friction,t_1pct_s_frictionless,rate_per_s_friction,rate_per_s_frictionless,rate_modal_per_s,"
            "t_1pct_est_s_friction,t_1pct_est_s_frictionless"]
    for label, d in sorted(fc.decay.items(), key=lambda kv: kv[1]["freq_hz"]):
        a, b = d["with"], d["without"]
        rows.append(f"{label},{d['freq_hz']:.6g},{a['peak_J']:.6g},{b['peak_J']:.6g},{a['end_J']:.6g},"
                    f"{b['end_J']:.6g},{a['t_1pct_s']:.4g},{b['t_1pct_s']:.4g},{a['rate_per_s']:.4g},"
                    f"{b['rate_per_s']:.4g},{a['rate_modal_per_s']:.4g},{a['t_1pct_est_s']:.4g},"
                    f"{b['t_1pct_est_s']:.4g}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def draw_friction(rig: VirtualRig, rec: Record, fc, scene: Scene, labels: dict):
    """``friction.png``: the spectrogram's channel in the pseudo-rigid band with friction and without (one
    colour scale), and the modal energy of the longitudinal, lateral, yaw and roll motions against time, both
    runs.

    Parameters
    ----------
    rig : the rig with friction
    rec : the nominal blow with friction
    fc : the comparison (its frictionless record and the motions' energies)
    scene : the scene ([spectrogram])
    labels : the pseudo-rigid modes

    Returns
    -------
    matplotlib.figure.Figure
    """
    name = spectrogram_channel(scene)
    channel = list(rig.names).index(name)
    fzoom = zoom_band_hz(labels)
    window = min(ZOOM_WINDOW_S, 0.25 * (rec.t[-1] - rec.t[0]))
    fig, axes = plt.subplots(3, 1, figsize=(10, 10), constrained_layout=True)
    top = max(float(_spectrogram_db(r, channel, window, 0.9, fzoom)[2].max()) for r in (rec, fc.frictionless))
    for ax, r, what in ((axes[0], rec, f"with friction (mu = {fc.mu:g})"), (axes[1], fc.frictionless,
                                                                           "without friction (mu = 0)")):
        mesh = _spectro(ax, r, channel, scene, fzoom, top=top, window_s=window)
        _pseudo_rigid_lines(ax, labels, fzoom)
        ax.set_ylabel("frequency [Hz]")
        ax.set_title(f"{name}, {rec.level_N:g} N blow, {what}: 0-{fzoom:g} Hz (Hann {window:g} s)", fontsize=10)
        fig.colorbar(mesh, ax=ax, label="PSD [dB]", pad=0.01)
    ax = axes[2]
    colors = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    peak = max((max(d["with"]["peak_J"], d["without"]["peak_J"]) for k, d in fc.decay.items() if k in DECAY_SHOWN),
               default=1.0)
    floor = peak * ENERGY_FLOOR
    hidden = []
    for c, label in zip(colors, DECAY_SHOWN, strict=True):
        if label not in fc.decay:
            continue
        d = fc.decay[label]
        for run, t, ls, what in (("with", rec.t, "-", f"{label} ({d['freq_hz']:.3g} Hz), friction"),
                                 ("without", fc.frictionless.t, "--", f"{label}, no friction")):
            if d[run]["peak_J"] < floor:  # never reaches the panel: no curve, no legend entry
                hidden.append((label, run))
                continue
            ax.semilogy(t, np.maximum(d[run]["energy_J"], 1e-300), color=c, lw=1.0, ls=ls, label=what)
    ax.set_ylim(floor, peak * 3)
    ax.set_xlim(rec.t[0], rec.t[-1])
    ax.set_xlabel("time [s]")
    ax.set_ylabel("modal energy [J]")
    title = "energy of the open-gap longitudinal, lateral, yaw and roll modes"
    if hidden:
        title += f"\nnot drawn, below {ENERGY_FLOOR:g} of the peak all the record: " + _hidden_text(hidden)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.22))  # below the axes, off the data
    return fig


def _hidden_text(hidden: list[tuple[str, str]]) -> str:
    """'lateral, yaw, roll (both runs); longitudinal (without friction)' from (mode, run) pairs."""
    runs = {}
    for label, run in hidden:
        runs.setdefault(label, []).append(run)
    both = [k for k, v in runs.items() if len(v) == 2]
    parts = [", ".join(both) + " (both runs)"] if both else []
    parts += [f"{k} ({v[0]} friction)" for k, v in runs.items() if len(v) == 1]
    return "; ".join(parts)


def friction_text(fc, end_share_s: float) -> list[str]:
    """The section of hammer.md on friction at the tips.

    Parameters
    ----------
    fc : FrictionComparison
        The nominal blow with friction and without.
    end_share_s : float
        s, the energy "at the end" is the mean over the record's last end_share_s.

    Returns
    -------
    list of str
        The section's lines.
    """
    fpi = fc.friction_per_impact_J
    lines = ["", f"## Friction at the tips (friction.csv, friction.png): mu = {fc.mu:g}, k_t = {fc.k_t:.4g} N/m, "
             f"{' and '.join(fc.directions)}", "",
             f"The nominal blow again with mu = 0 on the same reduction (the same tangential coordinates; only the "
             f"sliders differ): impacts {fc.impacts[0]} with friction, {fc.impacts[1]} without. Friction work "
             f"{fc.friction_work_J:.4g} J, {100 * fc.friction_work_J / fc.hammer_work_J:.3g} % of the hammer's "
             f"{fc.hammer_work_J:.4g} J; {fpi:.3g} J per impact.", "",
             f"| motion | [Hz] | peak energy, friction / none [J] | last {end_share_s:g} s, friction / none [J] | "
             "below 1 % of its peak after, friction / none [s] | decay rate once the gaps stay open, friction / "
             "none / closed form 2 zeta omega [1/s] |", "|---|---|---|---|---|---|"]
    extrapolated = False
    for label, d in sorted(fc.decay.items(), key=lambda kv: kv[1]["freq_hz"]):
        a, b = d["with"], d["without"]
        t1 = []
        for side in (a, b):
            est = not math.isfinite(side["t_1pct_s"]) and math.isfinite(side.get("t_1pct_est_s", math.nan))
            extrapolated |= est
            t1.append(f"{side.get('t_1pct_est_s', side['t_1pct_s']):.3g}{'*' if est else ''}")
        lines.append(f"| {label} | {d['freq_hz']:.4g} | {a['peak_J']:.3g} / {b['peak_J']:.3g} | "
                     f"{a['end_J']:.3g} / {b['end_J']:.3g} | {t1[0]} / {t1[1]} | "
                     f"{a.get('rate_per_s', math.nan):.3g} / {b.get('rate_per_s', math.nan):.3g} / "
                     f"{a.get('rate_modal_per_s', math.nan):.3g} |")
    g = fc.gaps_open_after_s
    lines += ["", f"The gaps stay open after {g[0]:.4g} s with friction, {g[1]:.4g} s without; from then on the motion "
              "is linear and each mode's energy decays at its modal rate (fitted over the rest of the record)."
              + (" *: the record ends before 1 %: extrapolated along that rate." if extrapolated else "")]
    bands = "; ".join(f"{band}: {w / wo:.3g} of the frictionless power" if wo > 0 else f"{band}: no power"
                      for band, (w, wo) in fc.spectrum_change.items())
    lines += ["", f"The spectrogram's channel after the blow (summed periodogram): {bands}."]
    return lines


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
def _save(fig, path: Path, dpi: int = 120) -> None:
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def fig10(path: Path, rig: VirtualRig, rec: Record, spec) -> None:
    """``fig10.png``: :func:`draw_fig10` saved.

    Parameters
    ----------
    path : the PNG written
    rig, rec, spec : as :func:`draw_fig10`
    """
    _save(draw_fig10(rig, rec, spec), path)


def closed_samples(rig: VirtualRig, rec: Record) -> np.ndarray:
    """(N,) bool, a tip gap is closed at the sample (as :func:`bearingshaft.stages.hammer.impacts` counts them).

    Parameters
    ----------
    rig : the rig that made ``rec`` (its stops)
    rec : a record (its states ``x``)
    """
    return np.any(rig.system.penetration(rec.x) > 0, axis=1)


def fig10_window(t: np.ndarray, closed: np.ndarray, start_s: float, span_s: float = FIG10_SPAN_S,
                 margin_s: float = FIG10_MARGIN_S) -> float:
    """s, the end of Fig. 10's window: ``start_s + span_s``, moved on to the end of the contact in
    progress then (so that the record never ends mid-impact) plus ``margin_s`` of open gaps, but
    before the next contact starts; the record's end if it comes first.

    Parameters
    ----------
    t : (N,) s, the sample times
    closed : (N,) bool, a gap is closed at the sample
    start_s : s, the blow's start
    span_s : s, the window's length asked for
    margin_s : s, open gaps shown after the last contact in the window

    Returns
    -------
    float
        s.

    Examples
    --------
    >>> t = np.arange(0.0, 0.2, 1e-3)
    >>> closed = (t > 0.105) & (t < 0.112)  # a contact from 106 to 111 ms
    >>> round(fig10_window(t, closed, 0.0, 0.108, 0.002), 6)  # asked to end at 108 ms, mid-impact
    0.114
    """
    k = min(int(np.searchsorted(t, start_s + span_s)), t.size - 1)
    while k < t.size - 1 and closed[k]:
        k += 1
    nxt = np.flatnonzero(closed[k:])
    stop = k + int(nxt[0]) - 1 if nxt.size else t.size - 1  # the last open sample before the next contact
    k_end = min(int(np.searchsorted(t, t[k] + margin_s)), stop)
    return float(t[max(k_end, k)])


def draw_fig10(rig: VirtualRig, rec: Record, spec, closed: np.ndarray | None = None):
    """The hammer force and one tip load cell against time (the paper's Fig. 10), with the blow
    zoomed in an inset; the window ends with the gaps open (:func:`fig10_window`).

    Parameters
    ----------
    rig : the rig that made ``rec``
    rec : the nominal blow's record
    spec : the scene's [hammer] (start of the blow, the load cell drawn)
    closed : (N,) bool, a gap is closed at the sample (default: from the record's states)

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(rig.names)
    if closed is None:
        closed = closed_samples(rig, rec)
    t_end = fig10_window(rec.t, closed, spec.start_s)
    keep = rec.t <= t_end
    hammer = rec.data[names.index("hammer")]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6.4), sharex=True, constrained_layout=True)
    a1.plot(rec.t[keep] * 1e3, hammer[keep], color="k", lw=1)
    a1.set_ylabel("hammer force [N]")
    a2.plot(rec.t[keep] * 1e3, rec.data[names.index(spec.load_cell)][keep], color="tab:red", lw=0.8)
    a2.set_ylabel(f"{spec.load_cell} load cell [N]")
    a2.set_xlabel("time [ms]")
    a2.set_xlim(rec.t[0] * 1e3, t_end * 1e3)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    _blow_inset(a1, rec.t, hammer)
    a1.set_title(wrap_title(f"Virtual hammer test: {rec.level_N:g} N blow at {where(rig.location)} (top, the blow "
                            f"zoomed in the inset) and the {spec.load_cell.replace('_', ' ')} load cell, contact force "
                            "minus its seismic mass's inertia (bottom); the window ends with the gaps open; compare "
                            "the paper's Fig. 10"), fontsize=10)
    return fig


def _blow_inset(ax, t: np.ndarray, hammer: np.ndarray) -> None:
    """The blow (where |force| > 0.1 % of its peak) zoomed, half its length either side, in the top right."""
    on = np.flatnonzero(np.abs(hammer) > BLOW_THRESHOLD * np.max(np.abs(hammer)))
    if on.size == 0:
        return
    t0, t1 = t[on[0]], t[on[-1]]
    pad = max(0.5 * (t1 - t0), 2 * (t[1] - t[0]))
    sel = (t >= t0 - pad) & (t <= t1 + pad)
    ins = ax.inset_axes([0.58, 0.3, 0.39, 0.62])
    ins.plot(t[sel] * 1e3, hammer[sel], ".-", color="k", lw=1, ms=2.5)
    ins.set_xlabel("time [ms]", fontsize=8)
    ins.set_ylabel("force [N]", fontsize=8)
    ins.tick_params(labelsize=7)
    ins.grid(alpha=0.3)
    # its length: between the zero samples either side of it
    length = t[min(on[-1] + 1, t.size - 1)] - t[max(on[0] - 1, 0)]
    ins.set_title(f"the blow, {1e3 * length:.3g} ms (dots: the samples)", fontsize=8)


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


def _spectrogram_db(rec: Record, channel: int, window_s: float, overlap: float, fmax: float):
    """The channel's spectrogram, dB re 1 unit^2/Hz: (t, freq_hz, dB)."""
    s = spectrogram(rec.t, rec.data[channel], window_s, overlap, fmax_hz=fmax)
    return s.t, s.freq_hz, 10 * np.log10(np.maximum(s.power, 1e-300))


def _spectro(ax, rec: Record, channel: int, scene: Scene, fmax: float, db_range: float = SPECTRO_DB,
             top: float | None = None, window_s: float | None = None):
    """A spectrogram panel: ``db_range`` dB below ``top`` (default: its own peak)."""
    sp = scene.spectrogram
    window, overlap = (sp.window_s, sp.overlap) if sp else (0.05, 0.9)
    t, f, db = _spectrogram_db(rec, channel, window_s or window, overlap, fmax)
    top = float(db.max()) if top is None else top
    mesh = ax.pcolormesh(t, f, db, shading="nearest", cmap="viridis", vmin=top - db_range, vmax=top,
                         rasterized=True)
    ax.set_ylim(0, fmax)
    ax.set_xlim(rec.t[0], rec.t[-1])
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


def fig11(path: Path, rig: VirtualRig, rec: Record, scene: Scene, labels: dict, curves: dict,
          gaps_open_s: float) -> None:
    """``fig11.png``: :func:`draw_fig11` saved.

    Parameters
    ----------
    path : the PNG written
    rig, rec, scene, labels, curves, gaps_open_s : as :func:`draw_fig11`
    """
    _save(draw_fig11(rig, rec, scene, labels, curves, gaps_open_s), path)


def zoom_band_hz(labels: dict) -> float:
    """Hz, the top of Fig. 11's lower panel: the highest pseudo-rigid frequency and ZOOM_HEADROOM of it
    more, rounded up to 10 Hz.

    Parameters
    ----------
    labels : {label: (mode index, freq_hz, score)} the pseudo-rigid modes

    Returns
    -------
    float
        Hz.

    Examples
    --------
    >>> zoom_band_hz({"bounce": (9, 19.6, 1.0), "roll": (11, 33.7, 1.0)}), zoom_band_hz({})
    (50.0, 50.0)
    """
    top = max((v[1] for v in labels.values()), default=0.0)
    return float(max(ZOOM_MIN_HZ, 10.0 * math.ceil(ZOOM_HEADROOM * top / 10.0)))


def draw_fig11(rig: VirtualRig, rec: Record, scene: Scene, labels: dict, curves: dict, gaps_open_s: float):
    """Spectrogram of a beam accelerometer (top: the scene's band) with the NNM backbones mapped onto
    time by the record's energy, f(E(t)), drawn only while the gaps still close (up to
    ``gaps_open_s``: after it the motion is linear and the map does not hold); below, the band of the
    six pseudo-rigid open-gap modes (dashed, labelled) with a longer window that resolves them.

    Parameters
    ----------
    rig : the rig that made ``rec``
    rec : the nominal blow's record
    scene : the scene ([spectrogram]: channel, window, band, colour range)
    labels : {label: (mode index, freq_hz, score)} the pseudo-rigid modes
    curves : {label: (energy_J, freq_hz)} the NNM backbones
    gaps_open_s : s, the gaps stay open after this time (0: they never close)

    Returns
    -------
    matplotlib.figure.Figure
    """
    name = spectrogram_channel(scene)
    sp = scene.spectrogram
    fmax = sp.fmax_hz if sp else 1500.0
    db_range = sp.db_range if sp else SPECTRO_DB
    window = sp.window_s if sp else 0.05
    channel = list(rig.names).index(name)
    fzoom = min(zoom_band_hz(labels), fmax)
    zoom_window = min(ZOOM_WINDOW_S, 0.25 * (rec.t[-1] - rec.t[0]))
    fig, (ax, az) = plt.subplots(2, 1, figsize=(10, 8.4), sharex=True, constrained_layout=True,
                                 gridspec_kw={"height_ratios": [3, 2]})
    mesh = _spectro(ax, rec, channel, scene, fmax, db_range)
    fig.colorbar(mesh, ax=ax, label="PSD [dB re 1 (m/s^2)^2/Hz]", pad=0.01)
    hammer = rec.data[list(rig.names).index("hammer")]
    on = np.flatnonzero(np.abs(hammer) > BLOW_THRESHOLD * np.max(np.abs(hammer)))
    blow_end_s = float(rec.t[on[-1]]) if on.size else float(rec.t[0])
    handles = _backbones_in_time(ax, rec, curves, blow_end_s, gaps_open_s, fmax)
    ax.axhline(fzoom, color="w", ls=":", lw=0.8)
    ax.text(rec.t[-1], fzoom, f" {fzoom:g} Hz: the lower panel below ", color="w", fontsize=8, ha="right",
            va="bottom")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title(wrap_title(f"{name} after a {rec.level_N:g} N blow at {where(rig.location)}: spectrogram "
                            f"(Hann {window:g} s) with the NNM backbones f(E(t)) while the gaps close; compare the "
                            "paper's Fig. 11", 110), fontsize=10)
    mz = _spectro(az, rec, channel, scene, fzoom, db_range, window_s=zoom_window)
    fig.colorbar(mz, ax=az, label="PSD [dB re 1 (m/s^2)^2/Hz]", pad=0.01)
    _pseudo_rigid_lines(az, labels, fzoom)
    for a in (ax, az):
        if gaps_open_s > 0:
            a.axvline(gaps_open_s, color="w", ls="-.", lw=1.0)
    az.set_xlabel("time [s]")
    az.set_ylabel("frequency [Hz]")
    az.set_title(f"0-{fzoom:g} Hz (Hann {zoom_window:g} s: {1 / zoom_window:.2g} Hz bins): the six pseudo-rigid "
                 "open-gap frequencies (dashed)", fontsize=10)
    if gaps_open_s > 0:
        handles.append(plt.Line2D([], [], color="k", ls="-.", lw=1.0,
                                  label=f"the gaps stay open after {gaps_open_s:.3g} s"))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=1, fontsize=9, frameon=False)
    return fig


def _backbones_in_time(ax, rec: Record, curves: dict, blow_end_s: float, gaps_open_s: float, fmax: float) -> list:
    """Each backbone's f(E(t)) of the free motion, from the end of the blow to ``gaps_open_s`` (gid
    ``backbone``); legend handles, with a line for those not drawn (no point in the record's
    energies, the time or the band)."""
    colors = ("r", "orange", "magenta", "cyan")
    handles, hidden = [], []
    upto = (rec.t >= blow_end_s) & (rec.t <= gaps_open_s)
    for i, (label, (E, f)) in enumerate(curves.items()):
        fe = curve_in_time(np.maximum(rec.energy[upto], 1e-300), E, f)
        shown = np.isfinite(fe) & (fe <= fmax)
        if not np.any(shown):
            hidden.append(f"{label}: not drawn, {_why_hidden(rec, E, f, gaps_open_s, fmax)}")
            continue
        (line,) = ax.plot(rec.t[upto], fe, color=colors[i % 4], lw=1.4, label=f"{label}, f(E(t)) while the gaps close",
                          gid="backbone")
        handles.append(line)
    for name in hidden:
        handles.append(plt.Line2D([], [], color="none", label=name))
    return handles


def _why_hidden(rec: Record, E: np.ndarray, f: np.ndarray, gaps_open_s: float, fmax: float) -> str:
    """Why a backbone has no point on Fig. 11."""
    if gaps_open_s <= 0:
        return "the gaps never close"
    if np.min(f) > fmax:
        return f"above the {fmax:g} Hz shown"
    e_top = float(np.max(rec.energy))
    if np.min(E) > e_top:
        return f"its backbone starts at {np.min(E):.2g} J, above the record's peak energy {e_top:.2g} J"
    return "outside the record's energies while the gaps close"


def _pseudo_rigid_lines(ax, labels: dict, fzoom: float) -> None:
    """Dashed lines at the pseudo-rigid frequencies, each named at the right edge (names spread apart)."""
    rigid = sorted(((v[1], k) for k, v in labels.items() if v[1] <= fzoom))
    gap = LABEL_GAP * fzoom
    y_prev = -math.inf
    for f, label in rigid:
        ax.axhline(f, color="w", ls="--", lw=0.8, alpha=0.9)
        y = max(f, y_prev + gap)
        ax.annotate(f"{label} {f:.1f} Hz", xy=(1.0, f), xycoords=("axes fraction", "data"), xytext=(1.012, y),
                    textcoords=("axes fraction", "data"), fontsize=8, va="center",
                    arrowprops={"arrowstyle": "-", "lw": 0.5, "color": "0.3"})
        y_prev = y


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
    """``levels.png``: :func:`draw_levels` saved.

    Parameters
    ----------
    path : the PNG written
    rig, records, summary, scene : as :func:`draw_levels`
    """
    _save(draw_levels(rig, records, summary, scene), path, dpi=110)


def levels_db_range(levels_N, db_range: float = SPECTRO_DB) -> float:
    """dB, the span of ``levels.png``'s one colour scale: ``db_range`` plus 20 log10(strongest /
    weakest blow), the dB by which a linear response to the weakest blow lies below the strongest's,
    so that the weakest blow's panel still shows ``db_range`` dB of its own.

    Parameters
    ----------
    levels_N : N, the blow levels
    db_range : dB shown below each blow's own peak

    Returns
    -------
    float
        dB.

    Examples
    --------
    >>> levels_db_range([20.0, 2000.0], 80.0), levels_db_range([500.0], 80.0)
    (120.0, 80.0)
    """
    lv = [abs(v) for v in levels_N if v]
    return db_range + (20.0 * math.log10(max(lv) / min(lv)) if lv else 0.0)


def draw_levels(rig: VirtualRig, records: dict, summary: dict, scene: Scene):
    """One spectrogram of the Fig. 11 channel per blow level, on one colour scale (one colour bar):
    the peak of the strongest blow's at the top, :func:`levels_db_range` below it.

    Parameters
    ----------
    rig : the rig that made the records
    records : {level_N: Record}
    summary : {level_N: level summary}, for the panels' titles
    scene : the scene ([spectrogram])

    Returns
    -------
    matplotlib.figure.Figure
    """
    name = spectrogram_channel(scene)
    sp = scene.spectrogram
    fmax = sp.fmax_hz if sp else 1500.0
    window, overlap = (sp.window_s, sp.overlap) if sp else (0.05, 0.9)
    channel = list(rig.names).index(name)
    specs = {level: _spectrogram_db(rec, channel, window, overlap, fmax) for level, rec in records.items()}
    top = max(float(db.max()) for _, _, db in specs.values())
    span = levels_db_range(list(records), sp.db_range if sp else SPECTRO_DB)
    n = len(records)
    cols = 2 if n > 1 else 1
    nrows = math.ceil(n / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(11, 2.8 * nrows + 1.0), sharex=True, sharey=True,
                             constrained_layout=True, squeeze=False)
    mesh = None
    for ax, (level, (t, f, db)) in zip(axes.ravel(), specs.items(), strict=False):
        mesh = ax.pcolormesh(t, f, db, shading="nearest", cmap="viridis", vmin=top - span, vmax=top,
                             rasterized=True)
        ax.set_ylim(0, fmax)
        rec = records[level]
        ax.set_xlim(rec.t[0], rec.t[-1])
        s = summary[level]
        what = (f"{s['impacts_total']} impacts, gaps open after {s['gaps_open_after_s']:.3g} s"
                if s["impacts_total"] else "no impact: the gaps never close")
        ax.set_title(f"{level:g} N: {what}", fontsize=9)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("frequency [Hz]")
    if mesh is not None:
        fig.colorbar(mesh, ax=axes, shrink=0.8, label="PSD [dB re 1 (m/s^2)^2/Hz], one scale for every panel")
    fig.suptitle(wrap_title(f"{name}: how the ringdown changes with the blow level (Hann {window:g} s; one colour "
                            f"scale, {span:.0f} dB below the strongest blow's peak)", 120), fontsize=10)
    return fig


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
             f"Reduced apparatus: {rig.system.n} coordinates (x1, x3{_n_tangential(rig)} and "
             f"{rig.system.n - 2 - _n_tangential(rig, False)} fixed-interface modes), "
             f"{len(rig.channels)} channels. Blow: "
             f"{'measured history ' + Path(spec.force_file).name if spec.force_file else 'half-sine'}"
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
    if result.friction is not None:
        lines += friction_text(result.friction, result.end_share_s)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _n_tangential(rig: VirtualRig, text: bool = True):
    """The tangential coordinates of the rig's model (friction at the tips): their count, or as words."""
    n = sum(":" in name for name in rig.system.dof_names)
    if not text:
        return n
    return f", {n} tangential coordinates of the tips' faces" if n else ""


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
    """The comparison with a measured test: ``test_errors.csv`` (pointwise, up to the horizon),
    ``test_measures.csv`` (what survives chaos), ``test_horizon.csv``, ``test_compare.md``, the
    figures ``test_compare.png``, ``test_spectrogram.png``, ``test_horizon.png``,
    ``test_measures.png``, ``test_backbone.png`` (with backbones) and ``model.uff``.

    Parameters
    ----------
    result : the comparison with a measured test
    writer : the stage's writer
    """
    scene, pairs, hz = result.scene, result.pairs, result.horizon
    correlate.write_errors_csv(result.rows, writer.path("test_errors.csv"))
    ms = result.measures
    write_rows(writer.path("test_measures.csv"), ms.rows if ms else [], MEASURE_FIELDS, float_format=f".{DIGITS}g")
    if hz is not None:
        horizon_csv(writer.path("test_horizon.csv"), hz)
        horizon_figure(writer.path("test_horizon.png"), result)
    horizon = hz.horizon_s if hz is not None else None
    comparison_figure(pairs, writer.path("test_compare.png"),
                      f"{scene.name} against {Path(result.test_file).name}: model driven by {result.driven}",
                      window_s=result.window_s, horizon_s=horizon, rows=result.rows)
    name = spectrogram_channel(scene)
    pair = next((p for p in pairs if p.name == name), pairs[0])
    sp = scene.spectrogram
    ridge = ms.ridges.get(pair.name) if ms else None
    spectrogram_pair_figure(pair, writer.path("test_spectrogram.png"), sp.window_s if sp else 0.05,
                            sp.overlap if sp else 0.9, sp.fmax_hz if sp else 1500.0,
                            title=f"{pair.name}: model (left) and test (right)", span_s=result.window_s,
                            ridges=ridge, horizon_s=horizon)
    if ms is not None and (ms.ridges or ms.envelopes or ms.impacts):
        measures_figure(writer.path("test_measures.png"), result, pair.name)
    if ms is not None and ms.backbones:
        backbone_figure(writer.path("test_backbone.png"), result)
    write_uff58(writer.path("model.uff"), result.model, model=f"bearingshaft {scene.name}")
    comparison_markdown(writer.path("test_compare.md"), result)


def horizon_csv(path: Path, hz) -> None:
    """``test_horizon.csv``: per window of the horizon's runs, G (the model's growth of a difference
    of the blow), the mismatch it predicts (delta_eff G) and the mismatch measured.

    Parameters
    ----------
    path : the CSV written
    hz : the comparison's Horizon
    """
    # both are windows of hz.window_s from the record's first sample: the k-th of one is the k-th of the other
    rows = [{"t_s": float(t), "growth": float(g), "predicted_mismatch": float(hz.delta_eff * g),
             "measured_mismatch": float(hz.mismatch[k]) if k < hz.mismatch.size else math.nan}
            for k, (t, g) in enumerate(zip(hz.t, hz.growth, strict=True))]
    write_rows(path, rows, ["t_s", "growth", "predicted_mismatch", "measured_mismatch"], float_format=f".{DIGITS}g")


def comparison_figure(pairs: list[ChannelPair], path: str | Path, title: str, channels: list[str] | None = None,
                      window_s: tuple[float, float] | None = None, horizon_s: float | None = None,
                      rows: list[dict] | None = None) -> None:
    """Model and test time histories overlaid, one panel per channel, each titled with its relative
    RMS error (from ``rows`` when given: up to the horizon, with its floor; else over the window).
    A long record is drawn as its min/max per pixel column (:class:`bearingshaft.plots.Envelope`);
    the predictability horizon, if given, is a dashed line.

    Parameters
    ----------
    pairs : matched channels (:func:`bearingshaft.correlate.match_channels`)
    path : the PNG written
    title : the figure's title
    channels : names of the pairs drawn, in this order (default: :func:`bearingshaft.correlate.default_channels`)
    window_s : (t_start_s, t_end_s), s, absolute times drawn (default: each pair's whole overlap)
    horizon_s : s, the predictability horizon (None or inf: not drawn)
    rows : :func:`bearingshaft.correlate.channel_errors` rows whose errors title the panels
    """
    chosen = correlate.select_pairs(pairs, channels)
    if not chosen:
        raise ChannelError("no channel to draw")
    by_row = {r["name"]: r for r in rows or []}
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
        if p.name in by_row:
            r = by_row[p.name]
            judged = "" if r["judged_against"] == "itself" else f", judged against its {r['judged_against']}"
            err = f"rms error {100 * r['rms_rel_error']:.3g} % to {1e3 * r['t_end_s']:.4g} ms{judged}"
        elif rows is not None:
            err = "no pointwise error: past the horizon"
        else:
            rms_x = correlate.rms(a.test)
            err = f"rms error {100 * (correlate.rms(a.model - a.test) / rms_x if rms_x > 0 else math.inf):.3g} %"
        ax.set_title(f"{p.name} (node {p.node}, direction {correlate.direction_label(p.direction)}): {err}",
                     fontsize=9, loc="left")
        if horizon_s is not None and math.isfinite(horizon_s) and a.t[0] < horizon_s < a.t[-1]:
            ax.axvline(horizon_s, color="C0", ls="--", lw=1.0, label="predictability horizon")
        ax.set_ylabel(f"{p.quantity.replace('_', ' ')}\n[{p.unit}]", fontsize=9)
        ax.legend(loc="upper right", fontsize=7)
        ax.set_xlim(a.t[0], a.t[-1])
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(wrap_title(title), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def spectrogram_pair_figure(pair: ChannelPair, path: str | Path, window_s: float, overlap: float, fmax_hz: float,
                            db_range: float = 60.0, title: str | None = None,
                            span_s: tuple[float, float] | None = None, ridges=None,
                            horizon_s: float | None = None) -> None:
    """Spectrograms of the model (left) and the test (right) of one channel on one colour scale.

    ``window_s`` (s) and ``overlap`` are the STFT's (:func:`reduced.transient.spectrogram.spectrogram`:
    Hann window, PSD scaling, mean removed); the colour scale spans ``db_range`` dB below the
    larger of the two maxima. With ``ridges`` (:class:`bearingshaft.measures.Ridges`) each
    panel carries both ridges (model red, test white) over the frames compared, and with
    ``horizon_s`` the predictability horizon (dashed).

    Parameters
    ----------
    pair : a matched channel (:func:`bearingshaft.correlate.match_channels`)
    path : the PNG written
    window_s, overlap : s, the STFT's window, and its overlap
    fmax_hz : Hz, the top of the frequency axis
    db_range : dB shown below the larger maximum
    title : the figure's title (default: the channel's name)
    span_s : (t_start_s, t_end_s), s, absolute times drawn (default: the common samples)
    ridges : Ridges or None, the ridges drawn over both panels
    horizon_s : s, the predictability horizon (None or inf: not drawn)
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
        if ridges is not None:
            ok = ridges.valid
            ax.plot(ridges.t[ok], ridges.f_model[ok], ".", color="C3", ms=2, label="model ridge")
            ax.plot(ridges.t[ok], ridges.f_test[ok], ".", color="w", ms=2, label="test ridge")
            ax.legend(loc="upper right", fontsize=7)
        if horizon_s is not None and math.isfinite(horizon_s):
            ax.axvline(horizon_s, color="w", ls="--", lw=0.8)
        ax.set_ylim(0, fmax_hz)
    axes[0].set_ylabel("frequency [Hz]")
    fig.colorbar(mesh, ax=axes, label=f"PSD [dB re 1 ({pair.unit})^2/Hz]")
    head = title or f"{pair.name}: model and test spectrograms"
    fig.suptitle(wrap_title(f"{head} (node {pair.node}, direction {correlate.direction_label(pair.direction)}; "
                            f"Hann {window_s:g} s, overlap {overlap:g})"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def horizon_figure(path: Path, result: Comparison) -> None:
    """The predictability horizon: the mismatch the model's own divergence predicts (delta_eff G(t))
    against the one measured, on a log scale, with the tolerance, the onset and the horizon.

    Parameters
    ----------
    path : the PNG written
    result : the comparison
    """
    hz = result.horizon
    fig, ax = plt.subplots(figsize=(9, 4.2), constrained_layout=True)
    end = hz.t[-1] if hz.t.size else hz.start_s
    end = max(end, hz.horizon_s if math.isfinite(hz.horizon_s) else 0.0) * 1.5 + 0.01
    m = hz.mismatch_t <= end
    ax.semilogy(1e3 * hz.mismatch_t[m], np.maximum(hz.mismatch[m], 1e-12), color="k", lw=1.2,
                label="measured: test against model (median over channels)")
    if hz.t.size and math.isfinite(hz.delta_eff):
        ax.semilogy(1e3 * hz.t, np.maximum(hz.delta_eff * hz.growth, 1e-12), color="C3", lw=1.2,
                    label=f"predicted: the model against itself after a blow {100 * hz.delta_eff:.2g} % stronger")
    ax.axhline(hz.tolerance, color="0.5", ls=":", lw=1.0, label=f"tolerance {100 * hz.tolerance:g} %")
    ax.axvspan(1e3 * hz.eps0_span_s[0], 1e3 * hz.eps0_span_s[1], color="C1", alpha=0.2, label="the blow (eps0)")
    if math.isfinite(hz.horizon_s):
        ax.axvline(1e3 * hz.horizon_s, color="C0", ls="--", label=f"horizon {1e3 * hz.horizon_s:.4g} ms")
    if math.isfinite(hz.onset_s):
        ax.axvline(1e3 * hz.onset_s, color="C2", ls="-.", label=f"chaos starts {1e3 * hz.onset_s:.4g} ms")
    ax.set_xlim(0, 1e3 * end)
    ax.set_ylim(1e-6, 10)
    ax.set_xlabel("time [ms]")
    ax.set_ylabel("relative RMS difference (2 ms windows)")
    ax.legend(loc="lower right", fontsize=7)
    lam = (f"largest Lyapunov exponent {hz.exponent_per_s:.3g} 1/s" if math.isfinite(hz.exponent_per_s)
           else "no separation runs")
    fig.suptitle(wrap_title(f"{result.scene.name} against {Path(result.test_file).name}: where pointwise comparison "
                            f"stops ({lam})"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def measures_figure(path: Path, result: Comparison, channel: str) -> None:
    """What survives chaos, on one channel and one load cell: the spectrogram ridges against time,
    the RMS envelope, and the impacts' peak forces against time, model and test.

    Parameters
    ----------
    path : the PNG written
    result : the comparison
    channel : the channel of the ridges and the envelope (the spectrogram's)
    """
    ms, hz = result.measures, result.horizon
    cell = result.scene.hammer.load_cell
    if cell not in ms.impacts and ms.impacts:
        cell = next(iter(ms.impacts))
    panels = [k for k, have in (("ridges", channel in ms.ridges), ("envelope", channel in ms.envelopes),
                                ("impacts", cell in ms.impacts)) if have]
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 2.6 * len(panels) + 0.8), sharex=True,
                             constrained_layout=True, squeeze=False)
    for ax, kind in zip(axes[:, 0], panels, strict=True):
        if kind == "ridges":
            r = ms.ridges[channel]
            ok = r.valid
            ax.plot(r.t[ok], r.f_test[ok], ".", color="k", ms=3, label="test")
            ax.plot(r.t[ok], r.f_model[ok], ".", color="C3", ms=3, label="model")
            ax.set_ylabel("ridge [Hz]")
            ax.set_title(f"{channel}: spectrogram ridge, {100 * r.agreement:.3g} % of the frames within one bin "
                         f"({r.bin_hz:.3g} Hz), median difference {100 * r.error:.2g} %", fontsize=9, loc="left")
        elif kind == "envelope":
            e = ms.envelopes[channel]
            ax.semilogy(e.t, np.maximum(e.test, 1e-300), color="k", lw=1.0, label="test")
            ax.semilogy(e.t, np.maximum(e.model, 1e-300), color="C3", lw=1.0, label="model")
            ax.set_ylabel(f"RMS [{next(p.unit for p in result.pairs if p.name == channel)}]")
            ax.set_title(f"{channel}: RMS envelope, error {100 * e.error:.3g} %", fontsize=9, loc="left")
        else:
            c = ms.impacts[cell]
            ax.plot(c.test.start_s, c.test.peak_N, "o", mfc="none", color="k", ms=4,
                    label=f"test: {c.test.count} impacts")
            ax.plot(c.model.start_s, c.model.peak_N, "x", color="C3", ms=4, label=f"model: {c.model.count} impacts")
            ax.axhline(c.test.threshold_N, color="0.5", ls=":", lw=0.8, label="threshold")
            ax.set_ylabel("peak force [N]")
            ax.set_title(f"{cell}: impacts as the load cell reads them (past the horizon)", fontsize=9, loc="left")
        if hz is not None and math.isfinite(hz.horizon_s):
            ax.axvline(hz.horizon_s, color="C0", ls="--", lw=0.8)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(wrap_title(f"{result.scene.name} against {Path(result.test_file).name}: what survives chaos "
                            f"(the dashed line: predictability horizon)"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def backbone_figure(path: Path, result: Comparison) -> None:
    """Backbones from the ringdown: instantaneous frequency against amplitude of each NNM's component
    of the free decay, test and model, over the model's NNM backbone (HB, H = 1) on the same channel.

    Parameters
    ----------
    path : the PNG written
    result : the comparison (its measures' backbones, its ChannelBackbone curves)
    """
    ms = result.measures
    curves = {(b.channel, b.label): b for b in result.backbones}
    keys = [k for k in ms.backbones if k in curves]
    fig, axes = plt.subplots(1, len(keys), figsize=(4.6 * len(keys) + 0.6, 4.4), constrained_layout=True,
                             squeeze=False)
    for ax, key in zip(axes[0], keys, strict=True):
        c, hb = ms.backbones[key], curves[key]
        ax.semilogx(hb.amplitude, hb.freq_hz, color="C0", lw=1.5, label="NNM backbone (HB, H=1)")
        ax.semilogx(c.test.amplitude, c.test.freq_hz, "o", mfc="none", color="k", ms=3, label="test ringdown")
        ax.semilogx(c.model.amplitude, c.model.freq_hz, "x", color="C3", ms=3, label="model ringdown")
        lo, hi = hb.band_hz
        ax.set_ylim(lo, hi)
        pts = np.concatenate([c.test.amplitude, c.model.amplitude])
        if pts.size:
            ax.set_xlim(pts.min() / 2, pts.max() * 2)
        ax.set_xlabel(f"{key[0]}: displacement amplitude [m]")
        ax.set_ylabel("frequency [Hz]")
        ax.set_title(f"{hb.label}, band {lo:.3g}-{hi:.3g} Hz: model vs test {100 * c.error:.2g} %",
                     fontsize=9)
        ax.legend(loc="upper left", fontsize=7)
    fig.suptitle(wrap_title(f"{result.scene.name} against {Path(result.test_file).name}: backbones from the free "
                            f"decay (Hilbert on the band-passed channel) over the model's NNM backbones"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _pct(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{100 * v:.3g} %"


def _horizon_text(result: Comparison) -> list[str]:
    hz = result.horizon
    out = ["## Where chaos starts (test_horizon.csv, test_horizon.png)", ""]
    if math.isfinite(hz.exponent_per_s):
        onset = f"from {1e3 * hz.onset_s:.4g} ms" if math.isfinite(hz.onset_s) else "never 100-fold within the runs"
        out.append(f"- Largest Lyapunov exponent of the model along the record: {hz.exponent_per_s:.3g} 1/s "
                   f"(Lyapunov time {1e3 * hz.lyapunov_time_s:.3g} ms); chaos starts {onset} (a difference of the "
                   f"blow grown 100-fold in the compared channels).")
    out.append(f"- Predictability horizon: **{_ms(hz.horizon_s)}**. {hz.note[0].upper() + hz.note[1:]}.")
    if math.isfinite(hz.last_contact_s):
        out.append(f"- The model's gaps stay open after {1e3 * hz.last_contact_s:.4g} ms.")
    if hz.mismatch.size and math.isfinite(hz.horizon_s):
        before = hz.mismatch[(hz.mismatch_t >= hz.start_s) & (hz.mismatch_t < hz.horizon_s)]
        after = hz.mismatch[hz.mismatch_t >= hz.horizon_s]
        if before.size and after.size:
            out.append(f"- Measured mismatch (median over channels, 2 ms windows): at most {_pct(before.max())} from "
                       f"the blow to the horizon, median {_pct(float(np.median(after)))} after it.")
    return out + [""]


def _ms(t: float) -> str:
    return f"{1e3 * t:.4g} ms" if math.isfinite(t) else "none within the window"


def _time_text(result: Comparison) -> list[str]:
    out = ["## Up to the horizon: pointwise errors (test_errors.csv, test_compare.png)", ""]
    if not result.rows:
        return out + ["No pointwise errors: " + ("not asked for (--measures)." if "time" not in result.wanted
                                                 else "the horizon precedes the window."), ""]
    rows = sorted(result.rows, key=lambda r: -r["rms_rel_error"])
    errs = [r["rms_rel_error"] for r in rows]
    floored = sum(r["judged_against"] != "itself" for r in rows)
    out.append(f"Over {1e3 * rows[0]['t_start_s']:.4g} .. {1e3 * rows[0]['t_end_s']:.4g} ms, relative RMS error "
               f"rms(model - test) / max(rms(test), floor): median {_pct(float(np.median(errs)))}, worst "
               f"{_pct(errs[0])} ({rows[0]['name']}); {floored} channels near zero judged against their sensor's "
               f"largest axis or the noise before the blow.")
    out += ["", "| channel | rms test | floor | judged against | error |", "|---|---|---|---|---|"]
    out += [f"| {r['name']} | {r['rms_test']:.3g} {r['unit']} | {r['rms_floor']:.3g} | {r['judged_against']} | "
            f"{_pct(r['rms_rel_error'])} |" for r in rows[:6]]
    return out + [""]


def _measure_text(result: Comparison) -> list[str]:
    ms = result.measures
    if ms is None or not ms.rows:
        return []
    out = ["## What survives chaos (test_measures.csv, test_measures.png, test_spectrogram.png)", ""]

    def worst(measure, statistic):
        rs = [r for r in ms.rows if r["measure"] == measure and r["statistic"] == statistic
              and math.isfinite(r["error"])]
        return max(rs, key=lambda r: abs(r["error"])) if rs else None

    def span(m):
        a, b = ms.spans[m]
        return f"{1e3 * a:.4g} ms .. {b:.4g} s"

    if ms.ridges:
        agree = [r.agreement for r in ms.ridges.values() if math.isfinite(r.agreement)]
        w = worst("ridges", "ridge frequency")
        out.append(f"- Spectrogram ridges ({span('ridges')}): the dominant frequencies of model and test agree within "
                   f"one bin in {_pct(float(np.median(agree)) if agree else math.nan)} of the frames (median over "
                   f"{len(ms.ridges)} channels); median relative difference {_pct(ms.summary('ridges'))}"
                   + (f", worst {_pct(w['error'])} ({w['channel']})." if w else "."))
    if ms.envelopes:
        w = worst("envelope", "RMS envelope")
        out.append(f"- RMS envelope ({span('envelope')}): error {_pct(ms.summary('envelope'))} (median over "
                   f"channels)" + (f", worst {_pct(w['error'])} ({w['channel']})." if w else "."))
    if ms.impacts:
        out.append(f"- Impacts past the horizon ({span('impacts')}), as the tip load cells read them:")
        for name, c in ms.impacts.items():
            out.append(f"  {name}: {c.model.count} (model) against {c.test.count} (test), "
                       f"{c.model.rate_per_s:.3g} against {c.test.rate_per_s:.3g} 1/s; median peak "
                       f"{c.model.peak_stat(0.5):.4g} against {c.test.peak_stat(0.5):.4g} N, largest "
                       f"{c.model.peak_stat(1.0):.4g} against {c.test.peak_stat(1.0):.4g} N.")
    opens = [r for r in ms.rows if r["measure"] == "open"]
    if opens:
        out.append("- Gaps open after (end of the last impact): " + "; ".join(
            f"{r['channel']} {r['model']:.4g} s (model) against {r['test']:.4g} s" for r in opens) + ".")
    for (name, label), c in ms.backbones.items():
        dist = next((r for r in ms.rows if r["measure"] == "backbone" and r["statistic"] == "distance to the NNM "
                     "backbone" and r["channel"] == f"{name} ({label})"), None)
        text = (f"- Backbone of the {label} component on {name} (band {c.test.band_hz[0]:.3g}-{c.test.band_hz[1]:.3g} "
                f"Hz, {c.test.t.size} test points): model against test at equal amplitude {_pct(c.error)}")
        if dist is not None:
            text += (f"; distance to the model's NNM backbone: test {_pct(dist['test'])}, model ringdown "
                     f"{_pct(dist['model'])}")
        out.append(text + " (test_backbone.png).")
    return out + [""]


def comparison_markdown(path: Path, result: Comparison) -> None:
    """``test_compare.md``: where chaos starts, the pointwise errors up to it, what still matches after it.

    Parameters
    ----------
    path : the Markdown file written
    result : the comparison
    """
    a, b = result.window_s
    lines = [f"# {result.scene.name} against {Path(result.test_file).name}", "",
             f"The model ({result.stats.get('n_dofs')} coordinates) at the test's sampling, driven by {result.driven}; "
             f"{result.force_text}. Compared: {len(result.pairs)} channels over {a:.4g} .. {b:.4g} s; measures: "
             f"{', '.join(result.wanted)}.", ""]
    if result.horizon is not None:
        lines += _horizon_text(result)
    lines += _time_text(result)
    lines += _measure_text(result)
    path.write_text("\n".join(lines))
