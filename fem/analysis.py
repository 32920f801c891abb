"""One call from model parameters to labelled modes: mesh, assemble, solve, label.

Used by the ``modal`` stage, the calibration and the studies, so that all of them run the
same model the same way.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fem.labels import TABLE2_ORDER, TABLE2_TEST_HZ, ModeLabels, label_modes
from fem.modal import ModalResult, modal_analysis
from fem.model import AssemblyModel, FESystem, build_system

CENTRE = np.zeros(3)  # m, the beam's centre of mass: the model is symmetric about the origin


@dataclass(frozen=True, eq=False)
class ModalAnalysis:
    """A solved model with its pseudo-rigid mode labels (none for the free beam).

    Attributes
    ----------
    system : FESystem
        The assembled model: mesh, K, M and the DOF map.
    modes : ModalResult
        Its lowest modes.
    labels : ModeLabels or None
        Which mode is which pseudo-rigid mode of Table 2; None for the free beam.
    timing : dict of str to float
        s, wall times of the steps: ``mesh_s``, ``assembly_s``, ``factorize_s``, ``iterate_s``,
        ``eigensolution_s``, ``labels_s``.
    """

    system: FESystem
    modes: ModalResult
    labels: ModeLabels | None
    timing: dict = field(default_factory=dict)  # s: mesh, assembly, eigensolution, labels

    def table2(self) -> list[dict]:
        """Rows ``mode, description, freq_hz, test_hz, error_pct`` in Table 2 order."""
        if self.labels is None:
            raise ValueError("the free beam has no pseudo-rigid modes to compare with Table 2")
        rows = []
        for k, (name, test) in enumerate(zip(TABLE2_ORDER, TABLE2_TEST_HZ, strict=True)):
            f = float(self.modes.freq_hz[self.labels.mode_index[name]])
            rows.append({"mode": k + 1, "description": name, "freq_hz": f, "test_hz": test,
                         "error_pct": 100.0 * (f - test) / test})
        return rows

    def table2_freq(self) -> np.ndarray:
        """Hz, the six pseudo-rigid frequencies in Table 2 order."""
        return np.array([r["freq_hz"] for r in self.table2()])

    def labelled_indices(self) -> list[int]:
        return [self.labels.mode_index[n] for n in TABLE2_ORDER]

    def sensor_shapes(self, sensors: list[str], modes: list[int]) -> np.ndarray:
        """(3 n_sensors, n_modes) x, y, z displacement of each sensor in each mode."""
        return self.modes.phi[self.system.sensor_dofs(sensors)][:, modes]


def analyse(model: AssemblyModel, n_modes: int = 20, shift_hz: float = 1.0, solver: str = "pardiso",
            method: str = "cached", step: Callable[[str], None] | None = None) -> ModalAnalysis:
    """Mesh, assemble, solve and label ``model``; ``step(name)`` is called as each step starts.

    Parameters
    ----------
    model : AssemblyModel
        The apparatus (or the beam alone) to analyse; its ``layout`` decides the labels.
    n_modes : int
        Modes computed, rigid-body ones included.
    shift_hz : float
        Hz, magnitude of the negative shift of :func:`fem.modal.modal_analysis`.
    solver : {'pardiso', 'superlu'}
        Sparse factorization (PARDISO falls back to SuperLU when it is not installed).
    method : str
        Assembly method passed to :func:`fem.model.build_system` ('cached' by default).
    step : callable, optional
        ``step(name)`` called as each step starts ('mesh and assemble', 'eigensolution', 'labels').

    Returns
    -------
    ModalAnalysis
        System, modes, labels (the beam's pseudo-rigid modes, and the tube's for the assembly;
        None for 'beam-free') and the time of each step.
    """
    step = step or (lambda name: None)
    t0 = time.perf_counter()
    step("mesh and assemble")
    system = build_system(model, method=method)
    t1 = time.perf_counter()
    step("eigensolution")
    modes = modal_analysis(system.K, system.M, n_modes=n_modes, shift_hz=shift_hz, solver=solver)
    t2 = time.perf_counter()
    step("labels")
    labels = None
    if model.layout != "beam-free":
        bd = system.part_dofs("beam")
        if model.layout == "assembly":
            td = system.part_dofs("tube")
            labels = label_modes(modes.phi, system.M, bd, system.rigid_modes(bd, CENTRE),
                                 td, system.rigid_modes(td, CENTRE))
        else:
            labels = label_modes(modes.phi, system.M, bd, system.rigid_modes(bd, CENTRE))
    timing = {"mesh_s": system.mesh.wall_time_s, "assembly_s": t1 - t0 - system.mesh.wall_time_s,
              "factorize_s": modes.timing["factorize_s"], "iterate_s": modes.timing["iterate_s"],
              "eigensolution_s": t2 - t1, "labels_s": time.perf_counter() - t2}
    return ModalAnalysis(system=system, modes=modes, labels=labels, timing=timing)
