"""The ``modal`` stage: mesh, modal analysis, correlation with Table 2, MAC, pictures.

Files written (through the stage writer, so a failure leaves nothing half-written):

- ``frequencies.csv``: ``mode,description,freq_hz,test_hz,error_pct`` for the six
  pseudo-rigid modes in Table 2 order (for ``beam-free``: the elastic modes against beam
  theory instead);
- ``modes.csv``: every computed mode with its label scores;
- ``mac_beam.csv``, ``mac_assembly.csv``, ``mac.png``: MAC on the sensor sets of Table 3
  (beam accelerometers; beam and tube). Test shapes come from ``[modal] test_shapes``
  (UFF dataset 55 or CSV); without them the FE auto-MAC is written and the files say so;
- ``fe_shapes.uff``: the FE shapes at the sensors (dataset 55), for the test team;
- ``mode_shapes.png`` (pyvista, off screen) and ``modes.vtu`` (ParaView).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from bearingshaft.output import StageWriter
from bearingshaft.scenes import Scene


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in r])


def modal_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Run the modal analysis of ``scene.model`` and write the correlation files."""
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
        rows.append([i + 1, float(f), *[float(v) for v in sc]])
    _write_csv(writer.path("modes.csv"), ["mode", "freq_hz", *[f"score_{c}" for c in COMPONENT_LABELS]], rows)

    if result.labels is None:
        _free_beam_table(result, writer)
        chosen = list(range(6, min(12, len(modes.freq_hz))))
        names = [f"elastic {i - 5}" for i in chosen]
    else:
        table = result.table2()
        _write_csv(writer.path("frequencies.csv"), ["mode", "description", "freq_hz", "test_hz", "error_pct"],
                   [[r["mode"], r["description"], r["freq_hz"], r["test_hz"], r["error_pct"]] for r in table])
        stats["max_abs_error_pct"] = max(abs(r["error_pct"]) for r in table)
        stats["label_purity"] = {n: round(result.labels.purity(n), 4) for n in TABLE2_ORDER}
        chosen = result.labelled_indices()
        names = list(TABLE2_ORDER)
        _mac_files(result, chosen, names, spec, writer)
    step("pictures")
    if spec.vtu:
        _write_vtu(result, chosen, names, writer.path("modes.vtu"))
    if spec.pictures:
        stats["pictures"] = _pictures(result, chosen, names, writer.path("mode_shapes.png"))
    bar.update(1)
    bar.close()


def _free_beam_table(result, writer: StageWriter) -> None:
    """Bending modes of the free beam (found by their dominant direction) against Euler-Bernoulli."""
    model = result.system.model
    b, h = model.beam_section
    l = model.beam_length
    A = b * h
    refs = []
    for bl in (4.730041, 7.853205):
        for name, I in (("bending z", b * h**3 / 12), ("bending y", h * b**3 / 12)):
            refs.append((name, bl**2 / (2 * np.pi * l**2) * np.sqrt(model.E * I / (model.rho * A))))
    # identify each elastic mode by the direction holding most of its kinetic energy
    system, modes = result.system, result.modes
    Mphi = system.M @ modes.phi
    comp = system.solid.dof_component
    share = np.array([[np.sum(modes.phi[comp == c, i] * Mphi[comp == c, i]) for c in range(3)]
                      for i in range(modes.phi.shape[1])])
    rows, k = [], 0
    for axis, name in ((2, "bending z"), (1, "bending y")):
        found = [i for i in range(6, len(modes.freq_hz)) if share[i, axis] > 0.8]
        for n, (i, (_, ref)) in enumerate(zip(found, [r for r in refs if r[0] == name], strict=False)):
            k += 1
            f = float(modes.freq_hz[i])
            rows.append([k, f"{name} {n + 1} (Euler-Bernoulli)", f, float(ref), 100 * (f - ref) / ref])
    header = ["mode", "description", "freq_hz", "test_hz", "error_pct"]
    _write_csv(writer.path("frequencies.csv"), header, rows)


def _mac_files(result, chosen, names, spec, writer: StageWriter) -> None:
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
