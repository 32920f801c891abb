"""The files of the virtual hammer test (:mod:`bearingshaft.stages.hammer`): records, figures,
the level sweep, the linear check, the comparison with a measured test and ``hammer.md``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft.digits import sig  # noqa: E402
from bearingshaft.output import StageWriter, write_rows  # noqa: E402
from bearingshaft.plots import wrap_title  # noqa: E402
from bearingshaft.scenes import Scene, SceneError  # noqa: E402
from fem.rig import TIP_CELLS  # noqa: E402
from fem.uff import TimeHistory, write_uff58  # noqa: E402
from reduced.models.rig import VirtualRig  # noqa: E402
from reduced.transient.spectrogram import curve_in_time, spectrogram  # noqa: E402

DIGITS = 6  # significant digits of the science files
EVENT_DIGITS = 4  # quantities set by where a crossing lands (peak forces, times of contact)
SPECTRO_DB = 80.0  # dB shown below each spectrogram's peak
END_SHARE_S = 0.1  # s, the energy "at the end" is the mean over the record's last 0.1 s


def histories(rig: VirtualRig, t: np.ndarray, data: np.ndarray) -> list[TimeHistory]:
    """The channels of one record as :class:`fem.uff.TimeHistory` (uniform t)."""
    dt = float(t[1] - t[0])
    return [TimeHistory(c.name, c.node, c.direction, c.quantity, data[i], dt, float(t[0]))
            for i, c in enumerate(rig.channels)]


def write_record(writer: StageWriter, rig: VirtualRig, rec, scene: Scene) -> None:
    """``hammer.npz``, ``channels.csv`` and ``hammer.uff`` of the nominal blow."""
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


# -- backbones and pseudo-rigid frequencies ---------------------------------------------------
def backbones(rig: VirtualRig, n_modes: int, energy_max_J: float) -> dict:
    """{label: (energy_J, freq_hz)}: HB (H = 1) backbones of the lowest ``n_modes`` NNMs that move
    the gaps, on the rig's coupled subsystem (exact for them: stages.hammer.coupled_subsystem)."""
    if n_modes == 0:
        return {}
    from bearingshaft.stages.hammer import coupled_subsystem
    from reduced.models.modes import gap_moving_modes
    from reduced.periodic.backbones import hb_backbones

    sub = coupled_subsystem(rig.system)
    curves = hb_backbones(sub, 1, energy_max_J=max(10.0 * energy_max_J, 1e-3),
                          modes=gap_moving_modes(sub, "open", n_modes))
    return {f"NNM at {f[0]:.1f} Hz (HB, H=1)": (E, f) for E, f in curves.values()}


# -- figures ---------------------------------------------------------------------------------
def fig10(path: Path, rig: VirtualRig, rec, spec) -> None:
    """The hammer force and one tip load cell against time (the paper's Fig. 10)."""
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
    a1.set_title(wrap_title(f"Virtual hammer test: {rec.level_N:g} N blow at {_where(rig)} (top) and the "
                            f"{spec.load_cell.replace('_', ' ')} load cell, contact force minus its seismic mass's "
                            "inertia (bottom); compare the paper's Fig. 10"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _where(rig: VirtualRig) -> str:
    x, y, z = rig.location
    return f"({x * 1e3:.1f}, {y * 1e3:.1f}, {z * 1e3:.1f}) mm"


def _spectro(ax, rec, channel: int, scene: Scene, fmax: float, db_range: float = SPECTRO_DB):
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
    """The channel of Fig. 11: [spectrogram] dof if it names one, else the middle beam accelerometer's z."""
    sp = scene.spectrogram
    return sp.dof if sp is not None and ":" in sp.dof else "beam_s3:z"


def fig11(path: Path, rig: VirtualRig, rec, scene: Scene, labels: dict, curves: dict) -> None:
    """Spectrogram of a beam accelerometer with the pseudo-rigid open-gap frequencies (dashed) and
    the NNM backbones mapped onto time by the record's energy, f(E(t))."""
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
    ax.set_title(wrap_title(f"{name} after a {rec.level_N:g} N blow at {_where(rig)}: spectrogram with the six "
                            "pseudo-rigid open-gap frequencies (dashed) and the NNM backbones f(E(t)); compare the "
                            "paper's Fig. 11"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- the level sweep ---------------------------------------------------------------------------
def mode_classes(lm, labels: dict) -> list[str]:
    """A name for every open-gap mode: its pseudo-rigid label, "bungee" for the whole assembly
    swinging on its bungees (below half the lowest pseudo-rigid frequency), else "elastic"."""
    name_of = {v[0]: k for k, v in labels.items()}
    f_low = 0.5 * min((v[1] for v in labels.values()), default=0.0)
    return [name_of.get(k, "bungee" if f < f_low else "elastic") for k, f in enumerate(lm.freq_hz)]


def level_summary(rig: VirtualRig, rec, lm, labels: dict) -> dict:
    """Peak tip forces, impacts, when the gaps stay open, energy shares at the end, energy balance."""
    from bearingshaft.stages.hammer import impacts, modal_energy_end

    imp = impacts(rig, rec)
    E_end = modal_energy_end(rig, rec, lm, END_SHARE_S)
    total = float(E_end.sum())
    kinds = mode_classes(lm, labels)
    bungee = float(sum(E for E, k in zip(E_end, kinds, strict=True) if k == "bungee"))
    beam = [k for k in np.argsort(E_end)[::-1] if kinds[k] != "bungee"][:3]
    rest = total - bungee
    names = list(rig.names)
    hammer = rec.data[names.index("hammer")]
    # the hammer's work from its own channel: int p d.u'(X) dt, with d.u'(X) = b^T q' (trapezoid)
    work = float(np.trapezoid(hammer * (rec.v @ rig.b), rec.t))
    last = [v["last_contact_s"] for v in imp.values() if not math.isnan(v["last_contact_s"])]
    return {
        "level_N": rec.level_N,
        "impacts": {k: v["impacts"] for k, v in imp.items()},
        "impacts_total": int(sum(v["impacts"] for v in imp.values())),
        "crossings_found": int(rec.stats.get("n_events", -1)),
        "peak_contact_N": {k: v["peak_contact_N"] for k, v in imp.items()},
        "peak_load_cell_N": {c: float(np.max(np.abs(rec.data[names.index(c)]))) for c in TIP_CELLS},
        "gaps_open_after_s": max(last) if last else 0.0,
        "end_energy_J": total,
        "end_bungee_share": bungee / total if total > 0 else 0.0,
        "end_modes": [{"mode": int(k + 1), "freq_hz": float(lm.freq_hz[k]), "label": kinds[k],
                       "share": float(E_end[k] / rest) if rest > 0 else 0.0} for k in beam],
        "hammer_work_J": float(rec.external[-1]),
        "hammer_work_trapezoid_J": work,
        "energy_balance_error": rec.balance_error,
        "wall_s": rec.stats.get("wall_s"),
    }


def levels_files(writer: StageWriter, rig: VirtualRig, records: dict, summary: dict, scene: Scene) -> None:
    """``levels.csv`` (one row per level) and ``levels.png`` (one spectrogram per level)."""
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
                     "energy_balance_error": f"{s['energy_balance_error']:.1e}"})
    write_rows(writer.path("levels.csv"), rows)
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
    fig.savefig(writer.path("levels.png"), dpi=110)
    plt.close(fig)


# -- hammer.md ---------------------------------------------------------------------------------
def write_markdown(path: Path, scene: Scene, rig: VirtualRig, rec, summary: dict, labels: dict, linear,
                   curves: dict) -> None:
    spec = scene.hammer
    s = summary[spec.peak_N]
    lines = [f"# Virtual hammer test: {scene.name}", "",
             f"Reduced apparatus: {rig.system.n} coordinates (x1, x3 and {rig.system.n - 2} fixed-interface modes), "
             f"{len(rig.channels)} channels. Blow: "
             f"{'measured history ' + spec.force_file if spec.force_file else 'half-sine'}"
             f" of {spec.duration_s * 1e3:g} ms at {_where(rig)} along {tuple(round(d, 6) for d in rig.direction)}, "
             f"starting at {spec.start_s:g} s; record {scene.ringdown.duration_s:g} s at "
             f"{scene.ringdown.sample_rate_hz:g} Hz by the {scene.ringdown.method} integrator.", "",
             "## Pseudo-rigid open-gap modes (the dashed lines of fig11.png)", "",
             "| label | model [Hz] | paper's test, Table 2 [Hz] | score (1: a pure rigid motion) |",
             "|---|---|---|---|"]
    from fem.labels import TABLE2_ORDER, TABLE2_TEST_HZ

    for label, (_, f, sc) in sorted(labels.items(), key=lambda kv: kv[1][1]):
        lines.append(f"| {label} | {f:.4g} | {TABLE2_TEST_HZ[TABLE2_ORDER.index(label)]:.4g} | {sc:.3f} |")
    lines += ["", f"## The nominal blow, {spec.peak_N:g} N", ""]
    lines += _level_text(s)
    lines += ["", "## Level sweep (levels.csv, levels.png)", "",
              "| level [N] | impacts | peak tip force [N] | gaps open after [s] | on the bungees at the end | "
              "the rest mostly in |", "|---|---|---|---|---|---|"]
    for level, t in summary.items():
        top = t["end_modes"][0]
        lines.append(f"| {level:g} | {t['impacts_total']} | {max(t['peak_contact_N'].values()):.4g} | "
                     f"{t['gaps_open_after_s']:.4g} | {100 * t['end_bungee_share']:.1f} % | {top['label']} "
                     f"{top['freq_hz']:.4g} Hz ({100 * top['share']:.1f} %) |")
    if curves:
        lines += ["", "NNM backbones on fig11.png (HB, H = 1, on the subsystem of the modes the gaps couple to): "
                  + ", ".join(curves) + "."]
    if linear is not None:
        lines += ["", "## Linear check (linear_check.csv, linear_check.png)", "", linear["text"]]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _level_text(s: dict) -> list[str]:
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
    lines.append(f"- Energy in the last {END_SHARE_S:g} s: {s['end_energy_J']:.3g} J, of which "
                 f"{100 * s['end_bungee_share']:.1f} % is the whole assembly swinging on its bungees; the rest "
                 f"(the beam on its springs and the elastic modes) is carried by: {ends}.")
    lines.append(f"- Work of the hammer: {s['hammer_work_J']:.6g} J by the integrator, "
                 f"{s['hammer_work_trapezoid_J']:.6g} J from the hammer channel times the struck point's velocity "
                 f"(trapezoid on the samples); energy balance error {s['energy_balance_error']:.1e}.")
    return lines


def summary_line(scene: Scene, rig: VirtualRig, rec, s: dict, linear) -> str:
    text = (f"[{scene.name}] virtual hammer test: {len(rig.channels)} channels, {rec.level_N:g} N blow: "
            f"{s['impacts_total']} impacts, peak tip force {max(s['peak_contact_N'].values()):.4g} N, gaps open after "
            f"{s['gaps_open_after_s']:.4g} s; balance {s['energy_balance_error']:.1e}")
    if linear is not None:
        text += f"; linear check worst {100 * linear['worst']:.3g} % RMS ({linear['worst_channel']})"
    return text


# -- a measured test ---------------------------------------------------------------------------
def compare_test(scene: Scene, rig: VirtualRig, writer: StageWriter, test_file: str, progress: bool) -> None:
    """Run the model at the test's sampling, driven by its hammer channel if it has one, and compare."""
    from bearingshaft import correlate
    from bearingshaft.stages.hammer import blow, run_record
    from fem.uff import UffError, read_uff58
    from reduced.models.loads import Tabulated

    spec = scene.hammer
    try:
        test = read_uff58(test_file)
    except UffError as exc:
        raise SceneError(f"--test: {exc}") from None
    forces = [c for c in test if c.quantity == "force"]
    if len(forces) > 1:
        raise SceneError(f"--test {test_file!r}: {len(forces)} force channels; a hammer test has one hammer")
    ref = forces[0] if forces else test[0]
    dt, t0 = ref.dt_s, ref.t0_s
    if abs(t0) > 1e-12:
        raise SceneError(f"--test {test_file!r}: the record starts at t0 = {t0!r} s; the model starts at rest at 0")
    duration = (max(c.data.size for c in test) - 1) * dt
    if forces:
        signal = Tabulated(forces[0].t, forces[0].data, source=f"{test_file} ({forces[0].name})")
        level = float(np.max(np.abs(forces[0].data)))
        driven = f"the test's hammer channel {forces[0].name!r} (peak {level:.4g} N)"
    else:
        signal, level = blow(spec, spec.peak_N), spec.peak_N
        driven = f"the scene's blow ({spec.peak_N:g} N): the test file has no force channel"
    rec = run_record(rig, signal, scene, level, duration_s=duration, sample_rate_hz=1.0 / dt)
    model = histories(rig, rec.t, rec.data)
    try:
        pairs = correlate.match_channels(model, test, list(spec.compare) or None, source=repr(test_file))
        window = tuple(spec.compare_window_s) or None
        rows = correlate.channel_errors(pairs, window_s=window)
    except correlate.ChannelError as exc:
        raise SceneError(f"--test: {exc}") from None
    correlate.write_errors_csv(rows, writer.path("test_errors.csv"))
    correlate.comparison_figure(pairs, writer.path("test_compare.png"),
                                f"{scene.name} against {Path(test_file).name}: model driven by {driven}",
                                window_s=window)
    name = spectrogram_channel(scene)
    pair = next((p for p in pairs if p.name == name), pairs[0])
    sp = scene.spectrogram
    correlate.spectrogram_pair_figure(pair, writer.path("test_spectrogram.png"), sp.window_s if sp else 0.05,
                                      sp.overlap if sp else 0.9, sp.fmax_hz if sp else 1500.0,
                                      title=f"{pair.name}: model (left) and test (right)")
    write_uff58(writer.path("model.uff"), model, model=f"bearingshaft {scene.name}")
    worst = max(rows, key=lambda r: r["rms_rel_error"])
    writer.stats.update({"test_file": str(test_file), "driven_by": driven, "n_compared": len(rows),
                         "worst_channel": worst["name"], "worst_rms_rel_error": worst["rms_rel_error"]})
    print(f"[{scene.name}] compared {len(rows)} channels with {test_file}: model driven by {driven}; worst "
          f"{worst['name']} {100 * worst['rms_rel_error']:.3g} % RMS (test_errors.csv)", flush=True)


BAND_HZ = 2000.0  # Hz, the band of the comparisons: both signals low-passed alike (zero phase)
CHECK_WINDOW_S = 0.05  # s, the linear check's window after the blow (as the mode-count study's)
NEAR_ZERO = 0.01  # an accelerometer axis below this share of its sensor's largest is judged against that one
LINEAR_CHECK_MAX = 0.01  # the bound: 1 % RMS per channel


def band_limited(y: np.ndarray, sample_rate_hz: float, band_hz: float = BAND_HZ) -> np.ndarray:
    """y low-passed at ``band_hz`` (8th-order Butterworth run forward and back: zero phase), along the
    last axis; y itself when the band reaches the Nyquist frequency."""
    from scipy.signal import butter, sosfiltfilt

    if band_hz >= 0.5 * sample_rate_hz:
        return y
    return sosfiltfilt(butter(8, band_hz, fs=sample_rate_hz, output="sos"), y, axis=-1)


def full_modes(fe, max_hz: float, progress: bool):
    """The full 3-D model's open-gap modes up to ``max_hz`` (at least one above it), shift-invert Lanczos."""
    from fem.modal import modal_analysis

    k = 24
    while True:
        if progress:
            print(f"  full 3-D modes: the lowest {k}", flush=True)
        res = modal_analysis(fe.K, fe.M, n_modes=k, shift_hz=0.1, method="lanczos", solver="superlu")
        if res.freq_hz[-1] > max_hz or k >= fe.n_dofs // 4:
            return res
        k *= 2


@dataclass(frozen=True, eq=False)
class FullReference:
    """The full 3-D model's open-gap response to a blow, on the rig's channels but the hammer."""

    names: list[str]  # accelerometer axes, then TIP_CELLS (their seismic inertia only: the gaps never close)
    data: np.ndarray  # (len(names), N) acquired at the scene's rate, as the rig's channels
    n_dofs: int
    n_modes: int
    top_hz: float
    cond_V: float


def full_reference(scene: Scene, rig: VirtualRig, level_N: float, n_out: int, progress: bool) -> FullReference:
    """The full 3-D model's response to the scene's half-sine blow of peak ``level_N`` at the rig's
    location and direction, on ``n_out`` samples at [ringdown]'s rate, by modal superposition.

    Its modes up to ``[hammer] linear_check_max_hz`` with the same damping (the dashpots
    c_points at x1, x2, x3 and alpha M projected on the modes: Cm = c Phi^T P^T P Phi + alpha I,
    not diagonal), in closed form from the pole-residue FRF (:class:`fem.modal_response.ModalModel`),
    acquired through the same anti-alias filter as the rig's channels (:mod:`reduced.models.daq`:
    computed at q fs with q from the top mode, so no mode above fs/2 folds into the band)."""
    from fem.contact import point_rows
    from fem.modal_response import ModalModel
    from fem.model import build_system
    from fem.rig import point_load_vector, seat_rows, sensor_rows
    from reduced.models.daq import Acquisition, oversampling

    spec, model = scene.hammer, scene.model
    if progress:
        print(f"[{scene.name}] linear check: building the full 3-D model", flush=True)
    fe = build_system(model.fe_model())
    modes = full_modes(fe, spec.linear_check_max_hz, progress)
    keep = modes.freq_hz <= spec.linear_check_max_hz
    phi, omega = modes.phi[:, keep], 2 * np.pi * modes.freq_hz[keep]
    Pr = np.vstack(list(point_rows(fe).values())) @ phi  # (3, m): x1, x2, x3 on the modes
    Cm = model.c_points * Pr.T @ Pr + model.alpha * np.eye(phi.shape[1])
    b_full = point_load_vector(fe.mesh.points, fe.mesh.hexes, fe.solid.element, fe.mesh.cell_part,
                               fe.mesh.part_names.index("beam"), rig.location, rig.direction, fe.n_dofs)
    b_modal = np.asarray(b_full @ phi).ravel()
    acc = sensor_rows(fe, ("beam", "tube"))
    names = [c.name for c in rig.channels if c.kind == "accelerometer"]
    R = np.vstack([phi[acc[n]] for n in names] + [r @ phi for r in seat_rows(fe).values()])
    fs = scene.ringdown.sample_rate_hz
    acq = Acquisition(fs, oversampling(float(omega.max()) / (2 * np.pi), fs))
    t_fine = np.arange(acq.oversample * (n_out - 1) + 1 + acq.tail_samples) / acq.fine_rate_hz
    ref = ModalModel(omega, 0.5 * (Cm + Cm.T)).half_sine_response(t_fine, b_modal, R, level_N, spec.duration_s,
                                                                  spec.start_s)
    a_ref = acq.acquire(ref.acceleration, n_out)
    sign = np.array([1.0 if c.endswith("top") else -1.0 for c in TIP_CELLS])[:, None]
    data = np.vstack([a_ref[: len(names)], -sign * rig.seismic_mass_kg * a_ref[len(names):]])
    return FullReference([*names, *TIP_CELLS], data, fe.n_dofs, int(phi.shape[1]), float(omega.max() / (2 * np.pi)),
                         float(ref.cond_V))


def rms_errors(a: np.ndarray, ref: np.ndarray, names: list[str], mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """rms(a - ref) / rms(ref) per channel over the samples ``mask``, and which axes were near zero:
    an accelerometer axis (``sensor:axis``) whose RMS is below NEAR_ZERO of its sensor's largest
    (zero by symmetry for a blow on the plane of symmetry) is judged against that largest axis."""
    rms_ref = np.sqrt(np.mean(ref[:, mask] ** 2, axis=1))
    scale, near_zero = rms_ref.copy(), np.zeros(len(names), bool)
    sensor = np.array([n.split(":")[0] if ":" in n else n for n in names])
    for i, name in enumerate(names):
        if ":" not in name:
            continue
        top = rms_ref[sensor == sensor[i]].max()
        if rms_ref[i] < NEAR_ZERO * top:
            scale[i], near_zero[i] = top, True
    return np.sqrt(np.mean((a[:, mask] - ref[:, mask]) ** 2, axis=1)) / scale, near_zero


def linear_check(scene: Scene, rom, rig: VirtualRig, writer: StageWriter, progress: bool) -> dict:
    """The open-gap response of the reduced rig against the full 3-D model's modal superposition.

    Gaps too large to close (the reduced model's gap set to 1 m): every channel but the hammer
    is compared, from the reduced model's exact integration, with the full model's response
    to the same blow (:func:`full_reference`; load cells read only their seismic inertia here).
    Both are compared low-passed alike at BAND_HZ (and raw), the error rms(a_rom - a_full) /
    rms(a_full) over the first CHECK_WINDOW_S after the blow (and over the whole record after
    it, where the phase of lightly damped kHz modes makes a 1e-5 frequency difference an O(1)
    RMS one), axes near zero by symmetry against their sensor's largest (:func:`rms_errors`,
    ``near_zero`` in ``linear_check.csv``).
    ``linear_check.csv``, ``linear_check.png``.
    """
    from dataclasses import replace

    from bearingshaft.stages.hammer import run_record
    from reduced.models.loads import HalfSine
    from reduced.models.rig import virtual_rig

    spec = scene.hammer
    level = spec.peak_N
    open_rig = virtual_rig(replace(rom, gap=1.0), rig.location, rig.direction, rig.seismic_mass_kg)
    rec = run_record(open_rig, HalfSine(level, spec.duration_s, spec.start_s), scene, level)
    full = full_reference(scene, rig, level, rec.t.size, progress)
    ref_data = full.data
    rom_data = rec.data[: len(full.names)]
    fs = scene.ringdown.sample_rate_hz
    chan = full.names
    windows = {"50ms": (rec.t >= spec.start_s) & (rec.t < spec.start_s + CHECK_WINDOW_S),
               "record": rec.t >= spec.start_s}
    bands = {"band": (band_limited(rom_data, fs), band_limited(ref_data, fs)), "raw": (rom_data, ref_data)}
    errors, near_zero = {}, np.zeros(len(chan), bool)
    for (b, (r_rom, r_ref)), (w, mask) in ((x, y) for x in bands.items() for y in windows.items()):
        errors[(b, w)], nz = rms_errors(r_rom, r_ref, chan, mask)
        near_zero |= nz
    band_rows = [{"channel": c, "rms_rel_error": errors[("band", "50ms")][i]} for i, c in enumerate(chan)]
    out_rows = [{"channel": c, "near_zero": bool(near_zero[i]),
                 "rms_rel_error": f"{errors[('band', '50ms')][i]:.3g}",
                 "rms_rel_error_record": f"{errors[('band', 'record')][i]:.3g}",
                 "rms_rel_error_raw": f"{errors[('raw', '50ms')][i]:.3g}",
                 "rms_rel_error_raw_record": f"{errors[('raw', 'record')][i]:.3g}"} for i, c in enumerate(chan)]
    raw_rows = [{"channel": c, "rms_rel_error": errors[("raw", "50ms")][i]} for i, c in enumerate(chan)]
    rec_worst = float(np.max(errors[("band", "record")]))
    write_rows(writer.path("linear_check.csv"), out_rows)
    worst = max(band_rows, key=lambda r: r["rms_rel_error"])
    worst_raw = max(raw_rows, key=lambda r: r["rms_rel_error"])
    _linear_figure(writer.path("linear_check.png"), rec.t, rom_data, ref_data, chan, worst["channel"],
                   fs, band_rows, spec)
    text = (f"Gaps too large to close; {len(band_rows)} channels of the reduced model ({rig.system.n} coordinates) "
            f"against the full 3-D model ({full.n_dofs} DOFs) by modal superposition of its {full.n_modes} modes up "
            f"to {spec.linear_check_max_hz:g} Hz (top {full.top_hz:.5g} Hz) with the same damping "
            f"(closed form, pole-residue FRF), {level:g} N blow, RMS over the first {1e3 * CHECK_WINDOW_S:g} ms after "
            f"the blow (axes near zero by symmetry against their sensor's largest axis). In the "
            f"{BAND_HZ:g} Hz band (both low-passed alike): worst {100 * worst['rms_rel_error']:.3g} % "
            f"({worst['channel']}), median "
            f"{100 * float(np.median([r['rms_rel_error'] for r in band_rows])):.3g} %; "
            f"{'within' if worst['rms_rel_error'] <= LINEAR_CHECK_MAX else 'OUTSIDE'} the 1 % bound. Raw samples "
            f"(to the Nyquist frequency, where the full model has modes the reduced one does not keep): worst "
            f"{100 * worst_raw['rms_rel_error']:.3g} % ({worst_raw['channel']}). Over the whole record in the band: "
            f"worst {100 * rec_worst:.3g} % (the phase of lightly damped kHz modes: see linear_check.csv).")
    writer.stats["linear_check"] = {"worst": worst["rms_rel_error"], "worst_channel": worst["channel"],
                                    "worst_raw": worst_raw["rms_rel_error"], "n_full_modes": full.n_modes,
                                    "cond_V": full.cond_V}
    return {"worst": worst["rms_rel_error"], "worst_channel": worst["channel"], "text": text}


def _linear_figure(path: Path, t, rom_data, ref_data, names, worst: str, fs: float, rows: list[dict], spec) -> None:
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 7), constrained_layout=True)
    i = names.index(worst)
    keep = (t >= spec.start_s) & (t <= spec.start_s + CHECK_WINDOW_S)
    a1.plot(t[keep] * 1e3, band_limited(ref_data[i], fs)[keep], color="k", lw=1.6,
            label="full 3-D, modal superposition")
    a1.plot(t[keep] * 1e3, band_limited(rom_data[i], fs)[keep], color="tab:orange", lw=0.8, ls="--",
            label="reduced model, exact integrator")
    a1.set_xlabel("time [ms]")
    a1.set_ylabel(f"{worst} [{'N' if worst.startswith('tip') else 'm/s^2'}]")
    a1.legend(fontsize=8)
    a1.set_title(wrap_title(f"Linear check, open gaps: the worst channel {worst} over the first 50 ms after the blow "
                            f"(both low-passed at {BAND_HZ:g} Hz)"), fontsize=10)
    err = [100 * r["rms_rel_error"] for r in rows]
    a2.bar(range(len(rows)), err, color="tab:blue")
    a2.axhline(100 * LINEAR_CHECK_MAX, color="r", ls="--", lw=1, label="1 % bound")
    a2.set_xticks(range(len(rows)), [r["channel"] for r in rows], rotation=90, fontsize=6)
    a2.set_ylabel("RMS error [%]")
    a2.set_yscale("log")
    a2.legend(fontsize=8)
    a2.set_title(f"every channel: rms(reduced - full) / rms(full), {1e3 * CHECK_WINDOW_S:g} ms after the blow, "
                 f"{BAND_HZ:g} Hz band", fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


__all__ = ["write_record", "backbones", "fig10", "fig11", "level_summary", "levels_files", "write_markdown",
           "compare_test", "linear_check", "histories", "summary_line"]
