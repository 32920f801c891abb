"""The files of the frf stage (:mod:`bearingshaft.stages.frf`), from what it computed
(:mod:`bearingshaft.stages.frf_results`): FRFs and coherences (UFF 58, NPZ), the test
geometry (UFF 15 / 2411 and 82), the stabilization diagram, the modes (CSV, UFF 55), the MAC
(CSV, figure) and ``frf.md``. Runs no solver.

Numbers in the CSV files are written to :data:`DIGITS` significant digits, MAC values to 4
decimals.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft.digits import sig  # noqa: E402
from bearingshaft.output import StageWriter, write_rows  # noqa: E402
from bearingshaft.plots import wrap_title  # noqa: E402
from bearingshaft.stages.frf_results import FRFResult  # noqa: E402
from fem.mac import write_uff55  # noqa: E402
from fem.rig import AXES, sensor_node  # noqa: E402
from fem.uff_frf import COHERENCE, FRF, FrequencyFunction, write_geometry, write_uff58_functions  # noqa: E402

DIGITS = 6  # significant digits of the CSV files


def write(result: FRFResult, writer: StageWriter) -> None:
    """Every file of the stage (:data:`bearingshaft.stages.frf.DESCRIPTION`); statistics into ``writer.stats``.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    writer : the stage's writer
    """
    write_functions(result, writer)
    write_geometry(writer.path("geometry.uff"), result.geometry, dataset=15)
    write_geometry(writer.path("geometry_2411.uff"), result.geometry, dataset=2411)
    write_rows(writer.path("geometry.csv"), [{"node": int(n), "name": name, "x_m": float(p[0]), "y_m": float(p[1]),
                                              "z_m": float(p[2])}
                                             for n, name, p in zip(result.geometry.nodes, result.geometry.names,
                                                                   result.geometry.xyz, strict=True)])
    write_modes(result, writer)
    write_mac(result, writer)
    draw_stabilization(result, writer.path("stabilization.png"))
    draw_frf(result, writer.path("frf.png"))
    writer.path("frf.md").write_text(report(result), encoding="utf-8")
    writer.stats.update(result.stats)
    for line in result.lines:
        print(line, flush=True)


def _export(result: FRFResult) -> slice:
    f = result.estimate.freq_hz
    return slice(0, int(np.searchsorted(f, result.scene.frf.export_max_hz, side="right")))


def write_functions(result: FRFResult, writer: StageWriter) -> None:
    """``frf.uff``: H1 of every response to every reference (type 4), then their coherences (type 6),
    up to ``[frf] export_max_hz``; ``frf.npz``: the same with H2 and the force auto spectra.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    writer : the stage's writer
    """
    est, b = result.estimate, result.blows
    keep = _export(result)
    f = est.freq_hz[keep]
    df = float(f[1] - f[0])
    frfs, cohs = [], []
    for i, ref in enumerate(b.references):
        for o, out in enumerate(b.outputs):
            name = f"{out.name}/{ref.name}"
            args = (out.node, out.direction, ref.node, ref.direction)
            frfs.append(FrequencyFunction(name, FRF, *args, out.quantity, ref.quantity, est.H1[o, i, keep],
                                          float(f[0]), df))
            cohs.append(FrequencyFunction(name, COHERENCE, *args, "", "", est.coherence[o, i, keep], float(f[0]), df))
    write_uff58_functions(writer.path("frf.uff"), frfs + cohs)
    np.savez_compressed(writer.path("frf.npz"), freq_hz=f, H1=est.H1[:, :, keep], H2=est.H2[:, :, keep],
                        coherence=est.coherence[:, :, keep], Gxx=est.Gxx[:, keep], n_averages=est.n_averages,
                        outputs=np.array([o.name for o in b.outputs]), output_nodes=[o.node for o in b.outputs],
                        output_directions=[o.direction for o in b.outputs],
                        output_quantities=np.array([o.quantity for o in b.outputs]),
                        references=np.array([r.name for r in b.references]),
                        reference_nodes=[r.node for r in b.references],
                        reference_directions=[r.direction for r in b.references], tau_s=result.windows.tau_s)


def mode_rows(result: FRFResult) -> list[dict]:
    """One row per identified mode: window-corrected frequency and damping, the window's share, the
    model's pole, the best-matching reference mode by MAC.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`

    Returns
    -------
    list of dict
    """
    rows = []
    zeta_w = result.selected.zeta
    for k in range(result.lam.size):
        j = int(result.match[k])
        have_model = result.model.freq_hz.size > 0
        mf = float(result.model.freq_hz[j]) if have_model else float("nan")
        mz = float(result.model.zeta[j]) if have_model else float("nan")
        best = int(np.argmax(result.mac_assembly[k])) if result.mac_assembly.size else -1
        rows.append({
            "mode": k + 1, "freq_hz": sig(float(result.freq_hz[k]), DIGITS), "zeta": sig(float(result.zeta[k]), DIGITS),
            "zeta_windowed": sig(float(zeta_w[k]), DIGITS), "zeta_added": sig(float(result.added_zeta[k]), DIGITS),
            "model_freq_hz": sig(mf, DIGITS), "freq_error_pct": sig(100 * (result.freq_hz[k] - mf) / mf, 3),
            "model_zeta": sig(mz, DIGITS), "zeta_error": sig(float(result.zeta[k]) - mz, 3),
            "stable_orders": int(result.selected.n_orders[k]), "complexity": round(float(result.complexity[k]), 4),
            "label": result.model.ref_names[best] if best >= 0 else "",
            "label_freq_hz": sig(float(result.model.ref_freq_hz[best]), DIGITS) if best >= 0 else float("nan"),
            "mac_beam": round(float(result.mac_beam[k, best]), 4) if best >= 0 else float("nan"),
            "mac_assembly": round(float(result.mac_assembly[k, best]), 4) if best >= 0 else float("nan"),
        })
    return rows


def write_modes(result: FRFResult, writer: StageWriter) -> None:
    """``modes.csv`` and ``modes.uff`` (the real shapes at the sensors as UFF 55, x y z per sensor node).

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    writer : the stage's writer
    """
    write_rows(writer.path("modes.csv"), mode_rows(result))
    sensors = list(dict.fromkeys(d.split(":")[0] for d in result.shape_dofs))
    full = np.zeros((3 * len(sensors), result.lam.size))
    for row, dof in zip(result.shapes, result.shape_dofs, strict=True):
        sensor, axis = dof.split(":")
        full[3 * sensors.index(sensor) + AXES.index(axis)] = row
    write_uff55(writer.path("modes.uff"), np.array([sensor_node(s) for s in sensors]), result.freq_hz, full,
                name="bearingshaft frf")


def write_mac(result: FRFResult, writer: StageWriter) -> None:
    """``mac.csv`` (beam and assembly sets, identified modes against the reference's) and ``mac.png``.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    writer : the stage's writer
    """
    names = result.model.ref_names
    rows = []
    for label, M in (("beam", result.mac_beam), ("assembly", result.mac_assembly)):
        for k in range(M.shape[0]):
            rows.append({"set": label, "mode": k + 1, "freq_hz": sig(float(result.freq_hz[k]), DIGITS),
                         **{n: round(float(M[k, j]), 4) for j, n in enumerate(names)}})
    write_rows(writer.path("mac.csv"), rows, fields=["set", "mode", "freq_hz", *names])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), constrained_layout=True)
    for ax, (label, M) in zip(axes, (("beam accelerometers", result.mac_beam),
                                     ("all accelerometers (assembly)", result.mac_assembly)), strict=True):
        im = ax.imshow(M, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        for (i, j), v in np.ndenumerate(M):
            ax.text(j, i, f"{v:.2f}", ha="center", va="center", color="w" if v < 0.6 else "k", fontsize=7)
        ax.set_xticks(range(len(names)), [n.split(" (")[0] for n in names], rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(M.shape[0]), [f"{f:.2f} Hz" for f in result.freq_hz], fontsize=8)
        ax.set_title(f"MAC, {label}", fontsize=10)
        ax.set_xlabel("reference mode")
        ax.set_ylabel("identified mode")
    fig.colorbar(im, ax=axes, shrink=0.8)
    fig.suptitle(wrap_title(f"{result.scene.name}: identified shapes against {result.model.source}"), fontsize=9)
    fig.savefig(writer.path("mac.png"), dpi=120)
    plt.close(fig)


def draw_stabilization(result: FRFResult, path) -> None:
    """The stabilization diagram over the band, on the mean receptance magnitude of the accelerometers.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    path : the PNG file
    """
    from fem.lscf import receptance

    est, band = result.estimate, result.band
    f = est.freq_hz[band]
    Hd = receptance(f, est.H1[result.acc_index][:, :, band], "acceleration")
    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    styles = [("new", "+", "0.6"), ("stable frequency", "o", "tab:orange"), ("stable frequency and damping", "o",
                                                                               "tab:blue"),
              ("stable frequency, damping and vector", "o", "tab:green")]
    for label, marker, colour in styles:
        xs, ys = [], []
        for o in result.diagram:
            if label == "new":
                sel = ~o.stable_freq
            elif label == "stable frequency":
                sel = o.stable_freq & ~o.stable_damping
            elif label == "stable frequency and damping":
                sel = o.stable_freq & o.stable_damping & ~o.stable_vector
            else:
                sel = o.stable
            xs += o.freq_hz[sel].tolist()
            ys += [o.order] * int(sel.sum())
        ax.scatter(xs, ys, marker=marker, s=14 if marker == "o" else 18, facecolors="none" if marker == "o" else colour,
                   edgecolors=colour if marker == "o" else None, linewidths=0.8, label=label)
    for fk in result.selected.freq_hz:
        ax.axvline(fk, color="k", lw=0.6, ls=":")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.set_xlim(f[0], f[-1])
    ax2 = ax.twinx()
    ax2.semilogy(f, np.mean(np.abs(Hd), axis=(0, 1)), color="0.3", lw=1.0)
    ax2.set_ylabel("mean |receptance| (m/N)")
    ax.legend(loc="upper left", fontsize=7, framealpha=0.9)
    ax.set_title(wrap_title(f"{result.scene.name}: pLSCF stabilization diagram ({len(result.blows.references)} "
                            f"references, windowed poles; dotted: the modes kept)"), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def draw_frf(result: FRFResult, path) -> None:
    """Per reference: |H1|, |H2| of its largest accelerometer response, the LSFD fit over the band, the coherence.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`
    path : the PNG file
    """
    est, b = result.estimate, result.blows
    keep = _export(result)
    f = est.freq_hz[keep]
    n_ref = len(b.references)
    fig, axes = plt.subplots(2, n_ref, figsize=(4.2 * n_ref, 6), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1]}, constrained_layout=True)
    band = result.band
    fb = est.freq_hz[band]
    s2 = (2j * np.pi * fb) ** 2
    for i, ref in enumerate(b.references):
        acc = result.acc_index
        o_local = int(np.argmax(np.sum(np.abs(est.H1[acc, i, band]), axis=1)))
        o = int(acc[o_local])
        ax = axes[0, i]
        ax.semilogy(f[1:], np.abs(est.H1[o, i, keep])[1:], lw=1.0, label="H1")
        ax.semilogy(f[1:], np.abs(est.H2[o, i, keep])[1:], lw=0.8, ls="--", label="H2")
        sign = np.sign(b.outputs[o].direction) or 1.0
        ax.semilogy(fb, np.abs(result.fit.synthesized[o_local, i] * s2) * abs(sign), lw=1.2, color="k", ls=":",
                    label="LSFD fit")
        ax.axvspan(fb[0], fb[-1], color="0.9", zorder=0)
        ax.set_title(f"{b.outputs[o].name} / {ref.name} ({int(est.n_averages[i])} averages)", fontsize=9)
        ax.set_ylabel("|H| (m/s^2/N)")
        ax.legend(fontsize=7)
        axc = axes[1, i]
        axc.plot(f, est.coherence[o, i, keep], lw=0.8)
        axc.set_ylim(0, 1.05)
        axc.set_ylabel("coherence")
        axc.set_xlabel("frequency (Hz)")
    fig.suptitle(wrap_title(f"{result.scene.name}: FRFs ({b.source}); grey: the identification band"), fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(result: FRFResult) -> str:
    """``frf.md``: what was averaged, the windows, the modes against the model, Table 3's MAC.

    Parameters
    ----------
    result : from :func:`bearingshaft.stages.frf.compute`

    Returns
    -------
    str, Markdown
    """
    spec, b, w = result.scene.frf, result.blows, result.windows
    rows = mode_rows(result)
    lines = [f"# {result.scene.name}: FRFs and modal parameters", "",
             f"Blows: {b.source}; {b.force.shape[0]} records of {b.n_samples} samples at {b.sample_rate_hz:g} Hz "
             f"(frequency lines every {b.sample_rate_hz / b.n_samples:.4g} Hz), {len(b.outputs)} responses.", "",
             "Windows: force window from the trigger (first sample at 5 % of the peak) less "
             f"{1e3 * float(np.max(w.trigger_s - w.origin_s)):.3g} ms to {1e3 * w.force_window_s:g} ms after it, "
             f"cosine taper; exponential window on every channel from the same origin, time constant "
             f"{w.tau_s:.4g} s ({spec.exp_end:g} at the record's end): every pole moved left by "
             f"sigma = {w.sigma:.4g} 1/s, undone exactly on the identified poles (lambda = lambda_w + sigma). "
             "H1 = S_xy / S_xx, H2 = S_yy / S_yx and the coherence, averaged per reference.", "",
             f"Identification: pLSCF on the accelerometers' H1 / s^2 in {spec.band_hz[0]:g}-{spec.band_hz[1]:g} Hz, "
             f"orders 1 to {spec.max_order}; a mode is a pole stable in frequency (1 %), damping (5 %) and "
             f"participation (MAC 98 %) at no fewer than {100 * spec.min_share:g} % of the orders; shapes by LSFD "
             f"(lowest FRF correlation of the fit {float(result.fit.correlation.min()):.4f}).", "",
             f"Model: the reduced rig's open-gap complex poles (modal damping of its dashpots); MAC reference: "
             f"{result.model.source}.", "",
             "| mode | f (Hz) | model f (Hz) | error (%) | zeta (%) | model zeta (%) | window added (%) | label | "
             "its f (Hz) | MAC beam | MAC assembly |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mode']} | {r['freq_hz']:.6g} | {r['model_freq_hz']:.6g} | {r['freq_error_pct']:.3g} | "
                     f"{100 * r['zeta']:.4g} | {100 * r['model_zeta']:.4g} | {100 * r['zeta_added']:.4g} | "
                     f"{r['label']} | {r['label_freq_hz']:.6g} | {r['mac_beam']:.4f} | {r['mac_assembly']:.4f} |")
    lines += ["", "Files: frf.uff (UFF 58, FRFs type 4 and coherences type 6), frf.npz, frf.png, stabilization.png, "
              "modes.csv, modes.uff (UFF 55), mac.csv, mac.png, geometry.uff (UFF 15 + 82), geometry_2411.uff "
              "(UFF 2411 + 82), geometry.csv.", ""]
    return "\n".join(lines)


__all__ = ["write", "write_functions", "write_modes", "write_mac", "draw_stabilization", "draw_frf", "report",
           "mode_rows"]
