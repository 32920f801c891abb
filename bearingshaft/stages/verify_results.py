"""The results of the verify stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

from dataclasses import dataclass

from bearingshaft.gap_modes import GapModeComparison
from bearingshaft.scenes import Scene
from reduced.models.discrete import DiscreteParams

STARTS = (("antisymmetric", "discrete-antisymmetric"), ("impulse", "discrete-impulse"),
          ("symmetric", "discrete-symmetric"))  # the paper's Section 3.2 initial conditions


MODELS = ("reduced", "identified", "table1")


@dataclass(frozen=True, eq=False)
class VerifyResult:
    """What the ``verify`` stage computed: the reduced 3-D model read as a three-mass model.

    Parameters
    ----------
    scene : Scene
        The scene verified.
    identified : DiscreteParams
        The three-mass model read from the reduced matrices.
    id_rows : list of dict
        Per parameter: ``parameter``, ``unit``, ``table1``, ``identified``, ``relative_difference``.
    residuals : dict
        ``{name: value}``: what the three-mass form cannot carry (:data:`RESIDUAL_MEANING`).
    freq_rows : list of dict
        The lowest coupled modes, open and closed gap: full, reduced (MAC partner), identified and
        Table 1 frequencies [Hz] and their relative differences against the full model.
    backbones : dict
        ``{model: {nnm: (energy_J, freq_hz)}}`` for the models of :data:`MODELS` (HB, H = 1).
    runs : dict
        ``{(start, model): RingdownResult}`` from the starts of :data:`STARTS`.
    spectra : dict
        ``{(start, model): Spectrogram}`` of x1 of each run.
    ring_rows : list of dict
        Per run: initial and final energy, x1's peak frequency in the first and last window,
        contact events, energy balance error, wall time.
    sensitivity : list of dict
        The reduced model's runs again from a perturbed start: final energy and events beside the
        unperturbed ones.
    perturbation : float
        The relative change of the initial state in ``sensitivity``.
    comparisons : dict
        ``{state: GapModeComparison}`` of the reduced model against the full one.
    facts : dict
        The numbers ``verify.md`` explains the differences with (masses, stiffnesses, sizes).
    wall_s : float
        s, the stage's compute time (provenance only).
    """

    scene: Scene
    identified: DiscreteParams
    id_rows: list[dict]
    residuals: dict
    freq_rows: list[dict]
    backbones: dict
    runs: dict
    spectra: dict
    ring_rows: list[dict]
    sensitivity: list[dict]
    perturbation: float
    comparisons: dict[str, GapModeComparison]
    facts: dict
    wall_s: float
