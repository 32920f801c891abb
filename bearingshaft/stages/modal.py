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
``FREQ_DIGITS`` significant digits, errors in percent to ``PCT_DECIMALS`` decimals, scores
and MAC to 4 decimals (:mod:`bearingshaft.stages.modal_files`). Wall-clock timings go to
``provenance.json`` only.

:func:`compute` meshes, solves, labels and correlates; :mod:`bearingshaft.stages.modal_files`
writes and draws.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from bearingshaft.digits import human
from bearingshaft.estimates import Estimate
from bearingshaft.progress import bar as progress_bar
from bearingshaft.reproduction import Reproduction
from bearingshaft.scenes import Scene
from bearingshaft.stages.modal_results import Correlation, ModalStageResult

__all__ = ["DESCRIPTION", "ModalStageResult", "compute", "estimate", "modal_estimate"]

STEPS = ("mesh and assemble", "eigensolution", "labels", "correlation")  # the progress bar's steps


def compute(scene: Scene, progress: bool, workdir) -> ModalStageResult:
    """Mesh and solve the scene's 3-D model, label its pseudo-rigid modes and correlate them.

    Parameters
    ----------
    scene : Scene
        A scene with a 3-D ``[model]`` and a ``[modal]`` table.
    progress : bool
        Show a progress bar of the steps.
    workdir : Path
        The stage's scratch folder (unused).

    Returns
    -------
    ModalStageResult
        The solved model with Table 2 and the MAC on the sensors, or, for the free beam, its
        elastic modes against beam theory.
    """
    from fem.analysis import analyse
    from fem.labels import TABLE2_ORDER

    spec = scene.modal
    bar = progress_bar(total=len(STEPS), desc=f"modal {scene.name}", enabled=progress, unit="step")
    done = []

    def step(name: str) -> None:
        if done:
            bar.update(1)
        done.append(name)
        bar.set_postfix_str(name)

    try:
        analysis = analyse(scene.model, n_modes=spec.n_modes, shift_hz=spec.shift_hz, solver=spec.solver,
                           step=step)
        step("correlation")
        if analysis.labels is None:
            table = _free_beam_table(analysis)
            chosen = [r["index"] for r in table if r["family"] != "other"][:6]
            names = [r["description"] for r in table if r["family"] != "other"][:6]
            return ModalStageResult(scene, analysis, chosen, names, free_beam=table)
        chosen = analysis.labelled_indices()
        names = list(TABLE2_ORDER)
        return ModalStageResult(scene, analysis, chosen, names, table2=analysis.table2(),
                                label_purity={n: round(analysis.labels.purity(n), 4) for n in TABLE2_ORDER},
                                correlation=_correlation(analysis, chosen, spec.test_shapes))
    finally:
        bar.update(1)
        bar.close()


def _free_beam_table(analysis) -> list[dict]:
    """Elastic modes of the free beam, sorted into families by symmetry, against beam theory."""
    from fem.beam_theory import FAMILIES, free_beam_references
    from fem.labels import free_beam_families

    model = analysis.system.model
    modes = analysis.modes
    b, h = model.beam_section
    found = free_beam_families(analysis.system, modes.phi, modes.freq_hz > modes.shift_hz)
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
    return table


def _test_shapes(test_shapes: str, sensors: list[str]) -> np.ndarray:
    """(3 n_sensors, n) test shapes read from a UFF 55 or CSV file, rows in the order of ``sensors``."""
    from fem.mac import read_shapes_csv, read_uff55

    path = Path(test_shapes)
    if path.suffix.lower() == ".csv":
        dofs, vals = read_shapes_csv(path)
        order = {d: i for i, d in enumerate(dofs)}
        want = [f"{s}:{c}" for s in sensors for c in "xyz"]
        missing = [w for w in want if w not in order]
        if missing:
            raise ValueError(f"{path}: no test DOF {missing[0]} (rows are named like beam_s1:x)")
        return vals[[order[w] for w in want]]
    nodes, _, test = read_uff55(path)
    if len(nodes) != len(sensors):
        raise ValueError(f"{path}: expected {len(sensors)} sensor nodes (1..{len(sensors)}), got {len(nodes)}")
    return test


def _correlation(analysis, chosen: list[int], test_shapes: str) -> Correlation:
    """The chosen FE modes on the beam's and the tube's sensors, MAC against the test shapes if given."""
    from fem.mac import mac

    system = analysis.system
    beam_s = system.sensor_names("beam")
    tube_s = system.sensor_names("tube")
    sets = {"beam": beam_s, "assembly": beam_s + tube_s}
    all_s = beam_s + tube_s
    fe_all = analysis.sensor_shapes(all_s, chosen)
    test = _test_shapes(test_shapes, all_s) if test_shapes else None
    note = "test shapes from " + Path(test_shapes).name if test is not None else (
        "no test shapes given: FE auto-MAC (can the sensors tell the modes apart?)")
    macs = {}
    for set_name, sensors in sets.items():
        rows_idx = np.concatenate([[3 * all_s.index(s) + c for c in range(3)] for s in sensors])
        A = fe_all[rows_idx]
        macs[set_name] = mac(A, test[rows_idx] if test is not None else A)
    return Correlation(all_s, sets, fe_all, test is not None, note, macs)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Build the gmsh model of the scene's parts, assemble 3-D elasticity in scikit-fem and compute
its lowest modes; label the six pseudo-rigid modes and correlate them with the paper's test.
Writes modes.csv (every mode, label scores), frequencies.csv (against Table 2), mac_beam.csv,
mac_assembly.csv, mac.png, fe_shapes.uff (UFF 55), mode_shapes.png (pyvista, off screen; unless
[modal] pictures = false) and modes.vtu (ParaView; unless vtu = false). The free beam (layout
beam-free) has no pseudo-rigid modes: its frequencies.csv is against beam theory and it writes
no MAC files."""


def estimate(scene: Scene) -> list[Estimate]:
    """Mesh, K and M, the sparse Cholesky factor and the Krylov basis of the modal analysis.

    Parameters
    ----------
    scene : Scene
        A scene with a [modal] table and a 3-D model.

    Returns
    -------
    list of Estimate
        One: :func:`bearingshaft.stages.modal.modal_estimate` of the model.
    """
    return [modal_estimate(scene.model, scene.modal.n_modes)]


def modal_estimate(model, n_modes: int) -> Estimate:
    """Peak bytes of meshing, assembling and solving ``model`` for ``n_modes`` modes.

    The DOFs are counted from the block grid, before any gmsh call (:mod:`fem._modal_cost`,
    whose factor term is checked against measured peaks in
    ``results/performance/modal_scaling.csv``).

    Parameters
    ----------
    model : fem.model.AssemblyModel
        The 3-D model's parameters (geometry, element).
    n_modes : int
        Modes asked for.

    Returns
    -------
    Estimate
        The peak bytes, what they are, and the scene key to change when they do not fit.
    """
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




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
REPRODUCTION = Reproduction(rules=(
    # every number is deterministic and written to the digits that reproduce: frequencies to the digits their
    # eigen-residual resolves (modal_files.resolved_digits), MAC and scores to 4 decimals, fe_shapes.uff rounded to
    # 5 digits of each mode's peak (modal_files.rounded_shapes); modes.vtu (ParaView) and the figures exist
))
