"""The ``modal`` stage's files, from what :func:`bearingshaft.stages.modal.compute` found.

``modes.csv`` (every mode with its label scores), ``frequencies.csv`` (Table 2, or beam theory
for the free beam), ``mac_beam.csv``, ``mac_assembly.csv``, ``mac.png`` and ``fe_shapes.uff``
(the correlation on Table 3's sensors), ``modes.vtu`` and ``mode_shapes.png``. Numbers go to
their converged digits (:data:`FREQ_DIGITS`, :data:`PCT_DECIMALS`, 4 decimals for scores and
MAC); no solver runs here.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from bearingshaft.output import StageWriter
from bearingshaft.stages.modal_results import Correlation, ModalStageResult  # noqa: F401  (re-exported)

FREQ_DIGITS = 6  # significant digits of a frequency: the eigensolver's are good to ~1e-9
PCT_DECIMALS = 3  # decimals of an error in percent (1e-5 relative, 10x the 6th digit's rounding)
RIGID_FLOOR = 1e-2  # a mode below RIGID_FLOOR x shift_hz is a rigid-body mode, written 0 Hz: its
# eigenvalue is the solver's noise, ~1e-5 sigma (fem.modal), i.e. f ~ 3e-3 shift_hz
SHAPE_DIGITS = 5  # fe_shapes.uff: each mode's components rounded to 5 decimal digits of its largest one; the
# pseudo-rigid modes lie close together and their shapes mix at ~1e-6 of the peak from one CPU (or thread count) to
# another, so components written in full (1e-7 where zero by symmetry) changed sign between machines
FREE_BEAM_FIELDS = ["mode", "description", "freq_hz", "theory", "theory_hz", "error_pct", "euler_bernoulli_hz",
                    "euler_bernoulli_error_pct"]


def freq_text(f: float, shift_hz: float, residual: float | None = None) -> str:
    """A frequency as written: 0 for a rigid-body mode, else :data:`FREQ_DIGITS` significant digits, fewer
    for a mode whose eigen-residual says its frequency is not resolved to them (:func:`resolved_digits`).

    Parameters
    ----------
    f : float
        Hz, the frequency.
    shift_hz : float
        Hz, the modal analysis's shift: below ``RIGID_FLOOR`` x shift_hz a mode is rigid.
    residual : float, optional
        The mode's relative residual ||K phi - w^2 M phi|| / ||K phi|| (None: not known).

    Returns
    -------
    str

    Examples
    --------
    >>> freq_text(1.2e-4, 1.0), freq_text(17.97912345, 1.0), freq_text(0.39904123, 0.1, residual=2.7e-3)
    ('0', '17.9791', '0.399')
    """
    if f < RIGID_FLOOR * shift_hz:
        return "0"
    return f"{f:.{resolved_digits(residual)}g}"


def resolved_digits(residual: float | None) -> int:
    """Significant digits of a frequency whose mode has relative residual ``residual``: the eigenvalue (and
    so the frequency) is known to about the residual, 1 + floor(-log10 residual) digits, at most
    :data:`FREQ_DIGITS`. The assembly's bungee modes (0.4-2.4 Hz) stop at their round-off floor, residuals
    6e-5 to 3e-3 (results/performance/modal_residuals.csv): between two machines, and between 1 and 2
    PARDISO threads, their sixth digit moved by up to 5.6e-4 relative.

    Parameters
    ----------
    residual : float or None
        The relative residual (None or non-finite: :data:`FREQ_DIGITS`).

    Returns
    -------
    int

    Examples
    --------
    >>> resolved_digits(2.65e-3), resolved_digits(5.8e-5), resolved_digits(1.9e-6), resolved_digits(None)
    (3, 5, 6, 6)
    """
    if residual is None or not math.isfinite(residual) or residual <= 0:
        return FREQ_DIGITS
    return int(min(FREQ_DIGITS, max(2, 1 + math.floor(-math.log10(residual)))))


def rounded_shapes(shapes: np.ndarray) -> np.ndarray:
    """Mode shapes rounded to :data:`SHAPE_DIGITS` decimal digits of each mode's largest component.

    Parameters
    ----------
    shapes : (n, m) ndarray of float
        One mode per column.

    Returns
    -------
    (n, m) ndarray of float
        Rounded (a column of zeros stays zero; no negative zeros).

    Examples
    --------
    >>> rounded_shapes(np.array([[0.578638], [-6.4e-07], [1.20484e-04]])).ravel().tolist()
    [0.57864, 0.0, 0.00012]
    """
    out = np.zeros_like(shapes, dtype=float)
    for k in range(shapes.shape[1]):
        peak = float(np.max(np.abs(shapes[:, k])))
        if peak > 0:
            out[:, k] = np.round(shapes[:, k], SHAPE_DIGITS - 1 - math.floor(math.log10(peak))) + 0.0
    return out


def pct_text(v: float) -> str:
    """An error in percent as written, empty if there is none.

    Parameters
    ----------
    v : float
        %, the error (nan for none).

    Returns
    -------
    str
        Signed, ``PCT_DECIMALS`` decimals, or ''.

    Examples
    --------
    >>> pct_text(-0.12345), pct_text(float("nan"))
    ('-0.123', '')
    """
    return "" if not math.isfinite(v) else f"{v:+.{PCT_DECIMALS}f}"


def _hz(v: float) -> str:
    return "" if not math.isfinite(v) else f"{v:.{FREQ_DIGITS}g}"


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    """CSV of rows already formatted (strings and integers)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def write(result: ModalStageResult, writer: StageWriter) -> None:
    """Write the ``modal`` stage's files, put its statistics in ``writer.stats``, print its summary.

    Parameters
    ----------
    result : ModalStageResult
        What :func:`bearingshaft.stages.modal.compute` returned.
    writer : StageWriter
        Where the files go.
    """
    from fem.labels import COMPONENT_LABELS

    scene, analysis = result.scene, result.analysis
    spec, model = scene.modal, scene.model
    system, modes = analysis.system, analysis.modes
    stats = writer.stats
    stats.update({
        "n_dofs": system.n_dofs, "n_cells": int(len(system.mesh.hexes)), "element": model.element,
        "element_size_m": model.element_size, "solver": modes.solver, "n_op": modes.n_op,
        "eigen_residual": modes.residual, **{k: round(v, 3) for k, v in analysis.timing.items()},
        "unique_element_shapes": system.solid.n_unique_shapes,
    })
    rows = []  # every computed mode with its label scores
    for i, f in enumerate(modes.freq_hz):
        sc = analysis.labels.score[i] if analysis.labels is not None else np.zeros(6)
        res = float(modes.residuals[i]) if modes.residuals is not None else None
        rows.append([i + 1, freq_text(float(f), spec.shift_hz, res), *[f"{abs(v):.4f}" for v in sc]])
    _write_csv(writer.path("modes.csv"), ["mode", "freq_hz", *[f"score_{c}" for c in COMPONENT_LABELS]], rows)
    lines = [f"[{scene.name}] {len(modes.freq_hz)} modes of {system.n_dofs} DOFs ({model.layout}, {model.element}, "
             f"element size {model.element_size:g} m)"]
    if result.free_beam is not None:
        lines += _free_beam_files(result.free_beam, model.layout, writer)
    else:
        lines += _table2_files(result, writer)
    if spec.vtu:
        _write_vtu(result, writer.path("modes.vtu"))
    if spec.pictures:
        stats["pictures"] = _pictures(result, writer.path("mode_shapes.png"))
    lines.append("  files: " + ", ".join(sorted(p.name for p in writer.scratch.iterdir())))
    print("\n".join(lines), flush=True)


def _table2_files(result: ModalStageResult, writer: StageWriter) -> list[str]:
    """frequencies.csv against Table 2 and the MAC files; the summary lines."""
    table, shift_hz = result.table2, result.scene.modal.shift_hz
    _write_csv(writer.path("frequencies.csv"), ["mode", "description", "freq_hz", "test_hz", "error_pct"],
               [[r["mode"], r["description"], freq_text(r["freq_hz"], shift_hz), f"{r['test_hz']:g}",
                 pct_text(r["error_pct"])] for r in table])
    worst = max(table, key=lambda r: abs(r["error_pct"]))
    stats = writer.stats
    stats["max_abs_error_pct"] = abs(worst["error_pct"])
    stats["label_purity"] = result.label_purity
    note = _mac_files(result, writer)
    return ["  Table 2: " + ", ".join(f"{r['description']} {r['freq_hz']:.2f} Hz ({r['error_pct']:+.2f} %)"
                                      for r in table),
            f"  worst error against Table 2: {worst['error_pct']:+.2f} % ({worst['description']}); "
            f"lowest label purity {min(stats['label_purity'].values()):.3f}",
            f"  MAC: {note}; largest off-diagonal {stats['mac_beam_max_offdiag']:.3f} (beam sensors), "
            f"{stats['mac_assembly_max_offdiag']:.3f} (beam and tube)"]


def _free_beam_files(table: list[dict], layout: str, writer: StageWriter) -> list[str]:
    """frequencies.csv of the free beam against beam theory; the summary lines."""
    _write_csv(writer.path("frequencies.csv"), FREE_BEAM_FIELDS,
               [[r["mode"], r["description"], _hz(r["freq_hz"]), r["theory"], _hz(r["theory_hz"]),
                 pct_text(r["error_pct"]), _hz(r["eb_hz"]), pct_text(r["eb_error_pct"])] for r in table])
    writer.stats["beam_theory"] = {r["description"]: {"freq_hz": r["freq_hz"], "theory_hz": r["theory_hz"],
                                                      "error_pct": r["error_pct"]} for r in table}
    return _free_beam_summary(table, layout)


def _free_beam_summary(table: list[dict], layout: str) -> list[str]:
    """Summary lines: worst error per family against its theory, and the families not reached."""
    from fem.beam_theory import FAMILIES

    lines = []
    for family in FAMILIES:
        rows = [r for r in table if r["family"] == family]
        if not rows:
            lines.append(f"  {family}: no mode among those computed (raise [modal] n_modes)")
            continue
        worst = max(rows, key=lambda r: abs(r["error_pct"]))
        text = (f"  {family}: {len(rows)} mode(s), worst {worst['error_pct']:+.3f} % against {worst['theory']} "
                f"({worst['description']}: {worst['freq_hz']:.2f} Hz)")
        if family.startswith("bending"):
            eb = max(rows, key=lambda r: abs(r["eb_error_pct"]))
            text += f"; Euler-Bernoulli would say {eb['eb_error_pct']:+.2f} %"
        lines.append(text)
    other = [r for r in table if r["family"] == "other"]
    if other:
        lines.append(f"  unclassified: modes {', '.join(str(r['mode']) for r in other)}")
    return lines


def _mac_files(result: ModalStageResult, writer: StageWriter) -> str:
    """fe_shapes.uff, mac_<set>.csv and mac.png; the note on where the test shapes came from."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem.mac import write_uff55

    corr, names = result.correlation, result.names
    write_uff55(writer.path("fe_shapes.uff"), np.arange(1, len(corr.sensors) + 1),
                result.analysis.modes.freq_hz[result.chosen], rounded_shapes(corr.fe_shapes),
                name=result.scene.model.layout)
    note = corr.note
    writer.stats["mac"] = note
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"wspace": 0.5})
    for ax, (set_name, sensors) in zip(axes, corr.sets.items(), strict=True):
        Mx = corr.mac[set_name]
        with open(writer.path(f"mac_{set_name}.csv"), "w", newline="") as fh:
            fh.write(f"# {note}; sensors: {' '.join(sensors)}\n")
            w = csv.writer(fh)
            w.writerow(["fe_mode", *[f"{'test' if corr.test_given else 'fe'}_{n}" for n in names]])
            for n, row in zip(names, Mx, strict=True):
                w.writerow([n, *[f"{v:.4f}" for v in row]])
        writer.stats[f"mac_{set_name}_max_offdiag"] = float(np.max(Mx - np.diag(np.diag(Mx))))
        im = ax.imshow(Mx, vmin=0, vmax=1, cmap="viridis")
        for i in range(len(names)):
            for j in range(len(names)):
                ax.text(j, i, f"{Mx[i, j]:.2f}", ha="center", va="center",
                        color="w" if Mx[i, j] < 0.6 else "k", fontsize=8)
        ax.set_xticks(range(len(names)), names, rotation=45, ha="right")
        ax.set_yticks(range(len(names)), names)
        ax.set_title(f"{set_name} sensors ({len(sensors)} triaxial)")
        ax.set_xlabel("test mode" if corr.test_given else "FE mode")
        ax.set_ylabel("FE mode")
    fig.colorbar(im, ax=axes, shrink=0.8, label="MAC")
    fig.suptitle("MAC: " + note, fontsize=10)
    fig.savefig(writer.path("mac.png"), dpi=120, bbox_inches="tight")
    plt.close(fig)
    return note


def _write_vtu(result: ModalStageResult, path: Path) -> None:
    """modes.vtu: the chosen modes on the mesh, for ParaView."""
    from fem.vtu import write_vtu

    modes = result.analysis.modes
    fields = {f"mode{i + 1:02d}_{name.replace(' ', '_')}_{modes.freq_hz[i]:.2f}Hz": modes.phi[:, i]
              for i, name in zip(result.chosen, result.names, strict=True)}
    write_vtu(result.analysis.system, fields, path)


def _pictures(result: ModalStageResult, path: Path) -> str:
    """Render the chosen modes with pyvista off screen (matplotlib if VTK cannot render)."""
    from bearingshaft.render import render_shapes

    modes = result.analysis.modes
    shapes = [(f"{name}  {modes.freq_hz[i]:.2f} Hz", modes.phi[:, i])
              for i, name in zip(result.chosen, result.names, strict=True)]
    return render_shapes(result.analysis.system, shapes, path)
