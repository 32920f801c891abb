"""The ``modal`` stage: mesh, modal analysis, correlation with Table 2, MAC, pictures.

Files written (through the stage writer, so a failure leaves nothing half-written):

- ``frequencies.csv``: ``mode,description,freq_hz,test_hz,error_pct`` for the six
  pseudo-rigid modes in Table 2 order; for ``beam-free``, every computed elastic mode
  against beam theory instead: ``mode,description,freq_hz,theory,theory_hz,error_pct,
  euler_bernoulli_hz,euler_bernoulli_error_pct`` (bending against Timoshenko with
  Euler-Bernoulli beside it, torsion against St-Venant, axial against the rod; see
  :mod:`fem.beam_theory` and :func:`fem.labels.free_beam_families`);
- ``modes.csv``: every computed mode with its label scores;
- ``mac_beam.csv``, ``mac_assembly.csv``, ``mac.png``: MAC on the sensor sets of Table 3
  (beam accelerometers; beam and tube). Test shapes come from ``[modal] test_shapes``
  (UFF dataset 55 or CSV); without them the FE auto-MAC is written and the files say so;
- ``fe_shapes.uff``: the FE shapes at the sensors (dataset 55), for the test team;
- ``mode_shapes.png`` (pyvista, off screen) and ``modes.vtu`` (ParaView).

Numbers go to the digits that are converged, so that a rerun writes the same bytes (the
threaded sparse Cholesky changes the last digits from run to run): frequencies to
:data:`FREQ_DIGITS` significant digits, errors in percent to :data:`PCT_DECIMALS` decimals,
scores and MAC to 4 decimals. Wall-clock timings go to ``provenance.json`` only.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearingshaft.digits import human
from bearingshaft.estimates import Estimate
from bearingshaft.output import StageWriter
from bearingshaft.scenes import Scene

FREQ_DIGITS = 6  # significant digits of a frequency: the eigensolver's are good to ~1e-9
PCT_DECIMALS = 3  # decimals of an error in percent (1e-5 relative, 10x the 6th digit's rounding)
RIGID_FLOOR = 1e-2  # a mode below RIGID_FLOOR x shift_hz is a rigid-body mode, written 0 Hz: its
# eigenvalue is the solver's noise, ~1e-5 sigma (fem.modal), i.e. f ~ 3e-3 shift_hz


def _freq(f: float, shift_hz: float) -> str:
    return "0" if f < RIGID_FLOOR * shift_hz else f"{f:.{FREQ_DIGITS}g}"


def _pct(v: float) -> str:
    return "" if not math.isfinite(v) else f"{v:+.{PCT_DECIMALS}f}"


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    """CSV of rows already formatted (strings and integers)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def modal_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Run the modal analysis of ``scene.model``, write the correlation files, print a summary."""
    from tqdm import tqdm

    from fem.analysis import analyse
    from fem.labels import COMPONENT_LABELS, TABLE2_ORDER

    spec = scene.modal
    model = scene.model
    steps = ["mesh and assemble", "eigensolution", "labels", "correlation", "pictures"]
    bar = tqdm(total=len(steps), desc=f"modal {scene.name}", disable=not progress, unit="step")
    done = []

    def step(name: str) -> None:
        if done:
            bar.update(1)
        done.append(name)
        bar.set_postfix_str(name)

    result = analyse(model, n_modes=spec.n_modes, shift_hz=spec.shift_hz, solver=spec.solver, step=step)
    system, modes = result.system, result.modes
    step("correlation")
    stats = writer.stats
    stats.update({
        "n_dofs": system.n_dofs, "n_cells": int(len(system.mesh.hexes)), "element": model.element,
        "element_size_m": model.element_size, "solver": modes.solver, "n_op": modes.n_op,
        "eigen_residual": modes.residual, **{k: round(v, 3) for k, v in result.timing.items()},
        "unique_element_shapes": system.solid.n_unique_shapes,
    })
    # every computed mode with its label scores
    rows = []
    for i, f in enumerate(modes.freq_hz):
        sc = result.labels.score[i] if result.labels is not None else np.zeros(6)
        rows.append([i + 1, _freq(float(f), spec.shift_hz), *[f"{abs(v):.4f}" for v in sc]])
    _write_csv(writer.path("modes.csv"), ["mode", "freq_hz", *[f"score_{c}" for c in COMPONENT_LABELS]], rows)

    lines = [f"[{scene.name}] {len(modes.freq_hz)} modes of {system.n_dofs} DOFs ({model.layout}, {model.element}, "
             f"element size {model.element_size:g} m)"]
    if result.labels is None:
        table = _free_beam_table(result, writer)
        chosen = [r["index"] for r in table if r["family"] != "other"][:6]
        names = [r["description"] for r in table if r["family"] != "other"][:6]
        lines += _free_beam_summary(table, model.layout)
    else:
        table = result.table2()
        _write_csv(writer.path("frequencies.csv"), ["mode", "description", "freq_hz", "test_hz", "error_pct"],
                   [[r["mode"], r["description"], _freq(r["freq_hz"], spec.shift_hz), f"{r['test_hz']:g}",
                     _pct(r["error_pct"])] for r in table])
        worst = max(table, key=lambda r: abs(r["error_pct"]))
        stats["max_abs_error_pct"] = abs(worst["error_pct"])
        stats["label_purity"] = {n: round(result.labels.purity(n), 4) for n in TABLE2_ORDER}
        chosen = result.labelled_indices()
        names = list(TABLE2_ORDER)
        mac_note = _mac_files(result, chosen, names, spec, writer)
        lines.append("  Table 2: " + ", ".join(f"{r['description']} {r['freq_hz']:.2f} Hz ({r['error_pct']:+.2f} %)"
                                                for r in table))
        lines.append(f"  worst error against Table 2: {worst['error_pct']:+.2f} % ({worst['description']}); "
                     f"lowest label purity {min(stats['label_purity'].values()):.3f}")
        lines.append(f"  MAC: {mac_note}; largest off-diagonal {stats['mac_beam_max_offdiag']:.3f} (beam sensors), "
                     f"{stats['mac_assembly_max_offdiag']:.3f} (beam and tube)")
    step("pictures")
    if spec.vtu:
        _write_vtu(result, chosen, names, writer.path("modes.vtu"))
    if spec.pictures:
        stats["pictures"] = _pictures(result, chosen, names, writer.path("mode_shapes.png"))
    bar.update(1)
    bar.close()
    lines.append("  files: " + ", ".join(sorted(p.name for p in writer.scratch.iterdir())))
    print("\n".join(lines), flush=True)


def _free_beam_table(result, writer: StageWriter) -> list[dict]:
    """Elastic modes of the free beam, sorted into families by symmetry, against beam theory."""
    from fem.beam_theory import FAMILIES, free_beam_references
    from fem.labels import free_beam_families

    model = result.system.model
    modes = result.modes
    b, h = model.beam_section
    found = free_beam_families(result.system, modes.phi, modes.freq_hz > modes.shift_hz)
    counts = {f: sum(1 for m in found if m.family == f) for f in FAMILIES}
    refs = free_beam_references(model.E, model.nu, model.rho, model.beam_length, b, h, counts)
    table = []
    for m in found:
        f = float(modes.freq_hz[m.index])
        row = {"index": m.index, "mode": m.index + 1, "family": m.family, "freq_hz": f,
               "description": m.family if m.family == "other" else f"{m.family} {m.order}",
               "theory": "", "theory_hz": math.nan, "error_pct": math.nan, "eb_hz": math.nan, "eb_error_pct": math.nan}
        if m.family != "other":
            theory, f_t, f_eb = refs[m.family][m.order - 1]
            row.update(theory=theory, theory_hz=f_t, error_pct=100 * (f - f_t) / f_t, eb_hz=f_eb,
                       eb_error_pct=100 * (f - f_eb) / f_eb)
        table.append(row)
    header = ["mode", "description", "freq_hz", "theory", "theory_hz", "error_pct", "euler_bernoulli_hz",
              "euler_bernoulli_error_pct"]

    def hz(v: float) -> str:
        return "" if not math.isfinite(v) else f"{v:.{FREQ_DIGITS}g}"

    _write_csv(writer.path("frequencies.csv"), header,
               [[r["mode"], r["description"], hz(r["freq_hz"]), r["theory"], hz(r["theory_hz"]), _pct(r["error_pct"]),
                 hz(r["eb_hz"]), _pct(r["eb_error_pct"])] for r in table])
    writer.stats["beam_theory"] = {r["description"]: {"freq_hz": r["freq_hz"], "theory_hz": r["theory_hz"],
                                                      "error_pct": r["error_pct"]} for r in table}
    return table


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


def _mac_files(result, chosen, names, spec, writer: StageWriter) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem.mac import mac, read_shapes_csv, read_uff55, write_uff55

    system = result.system
    beam_s = system.sensor_names("beam")
    tube_s = system.sensor_names("tube")
    sets = {"beam": beam_s, "assembly": beam_s + tube_s}
    all_s = beam_s + tube_s
    fe_all = result.sensor_shapes(all_s, chosen)
    write_uff55(writer.path("fe_shapes.uff"), np.arange(1, len(all_s) + 1),
                result.modes.freq_hz[chosen], fe_all, name=system.model.layout)
    test = None
    if spec.test_shapes:
        path = Path(spec.test_shapes)
        if path.suffix.lower() == ".csv":
            dofs, vals = read_shapes_csv(path)
            order = {d: i for i, d in enumerate(dofs)}
            want = [f"{s}:{c}" for s in all_s for c in "xyz"]
            missing = [w for w in want if w not in order]
            if missing:
                raise ValueError(f"{path}: no test DOF {missing[0]} (rows are named like beam_s1:x)")
            test = vals[[order[w] for w in want]]
        else:
            nodes, _, test = read_uff55(path)
            if len(nodes) != len(all_s):
                raise ValueError(f"{path}: expected {len(all_s)} sensor nodes (1..{len(all_s)}), "
                                 f"got {len(nodes)}")
    note = "test shapes from " + spec.test_shapes if test is not None else (
        "no test shapes given: FE auto-MAC (can the sensors tell the modes apart?)")
    writer.stats["mac"] = note
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"wspace": 0.5})
    for ax, (set_name, sensors) in zip(axes, sets.items(), strict=True):
        rows_idx = np.concatenate([[3 * all_s.index(s) + c for c in range(3)] for s in sensors])
        A = fe_all[rows_idx]
        B = test[rows_idx] if test is not None else A
        Mx = mac(A, B)
        with open(writer.path(f"mac_{set_name}.csv"), "w", newline="") as fh:
            fh.write(f"# {note}; sensors: {' '.join(sensors)}\n")
            w = csv.writer(fh)
            w.writerow(["fe_mode", *[f"{'test' if test is not None else 'fe'}_{n}" for n in names]])
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
        ax.set_xlabel("test mode" if test is not None else "FE mode")
        ax.set_ylabel("FE mode")
    fig.colorbar(im, ax=axes, shrink=0.8, label="MAC")
    fig.suptitle("MAC: " + note, fontsize=10)
    fig.savefig(writer.path("mac.png"), dpi=120, bbox_inches="tight")
    plt.close(fig)
    return note


def _write_vtu(result, chosen, names, path: Path) -> None:
    from fem.vtu import write_vtu

    fields = {f"mode{i + 1:02d}_{name.replace(' ', '_')}_{result.modes.freq_hz[i]:.2f}Hz": result.modes.phi[:, i]
              for i, name in zip(chosen, names, strict=True)}
    write_vtu(result.system, fields, path)


def _pictures(result, chosen, names, path: Path) -> str:
    """Render the modes with pyvista off screen (matplotlib if VTK cannot render)."""
    from bearingshaft.render import render_shapes

    shapes = [(f"{name}  {result.modes.freq_hz[i]:.2f} Hz", result.modes.phi[:, i])
              for i, name in zip(chosen, names, strict=True)]
    return render_shapes(result.system, shapes, path)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Build the gmsh model of the scene's parts, assemble 3-D elasticity in scikit-fem and compute
its lowest modes; label the six pseudo-rigid modes and correlate them with the paper's test.
Writes frequencies.csv (against Table 2), mac_beam.csv, mac_assembly.csv, mac.png, modes.csv,
fe_shapes.uff (UFF 55), mode_shapes.png (pyvista, off screen) and modes.vtu (ParaView)."""


def estimate(scene: Scene) -> list[Estimate]:
    """Mesh, K and M, the sparse Cholesky factor and the Krylov basis of the modal analysis."""
    return [modal_estimate(scene.model, scene.modal.n_modes)]


def modal_estimate(model, n_modes: int) -> Estimate:
    """Peak bytes of meshing, assembling and solving ``model`` (fem.model.AssemblyModel) for
    ``n_modes`` modes; the DOFs are counted from the block grid, before any gmsh call
    (:mod:`fem._modal_cost`, whose factor term is checked against measured peaks in
    ``results/performance/modal_scaling.csv``)."""
    from fem._modal_cost import count_dofs, modal_bytes

    n = count_dofs(model.geometry(), model.element)
    b = modal_bytes(n, n_modes)
    # the key that sizes the largest term: the mesh (factor, matrices) or the modes (Krylov basis)
    by_modes = b["krylov"] > b["factor"] + b["matrices"]
    return Estimate("modal", int(b["total"]),
                    f"{n:,} DOFs ({model.element}): K and M {human(b['matrices'])}, Cholesky factor "
                    f"{human(b['factor'])}, Krylov basis {human(b['krylov'])} for {n_modes} modes",
                    "[modal] n_modes" if by_modes else "[model] element_size",
                    advice="lower n_modes" if by_modes else "raise element_size")


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir) -> _Pending:
    return _Pending(scene, progress, {})


def write(result: _Pending, writer: StageWriter) -> None:
    modal_stage(result.scene, writer, result.progress, **result.options)
