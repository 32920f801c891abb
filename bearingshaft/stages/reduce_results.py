"""The results of the reduce stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearingshaft.gap_modes import GapModeComparison
from bearingshaft.scenes import Scene
from reduced.models.rom import ReducedModel


@dataclass(frozen=True, eq=False)
class ReduceResult:
    """What the ``reduce`` stage computed: the reduced model, checked, against the full one.

    Parameters
    ----------
    scene : Scene
        The scene reduced.
    rom : ReducedModel
        The reduced model with every check (``rom.checks``: the reduction's own and the
        Rayleigh-Ritz upper bound), without provenance (added when it is written).
    fe : fem.model.FESystem
        The full 3-D model (its mesh carries the expanded modes).
    comparisons : dict
        ``{state: GapModeComparison}``, open and closed gap.
    mode_fields : dict
        ``{name: (N,) displacement}``: the reduced modes expanded to the mesh, unit peak.
    mode_shapes : list
        ``[(title, (N,) displacement)]``: the three lowest of each state that move the gaps.
    """

    scene: Scene
    rom: ReducedModel
    fe: object
    comparisons: dict[str, GapModeComparison]
    mode_fields: dict[str, np.ndarray]
    mode_shapes: list[tuple[str, np.ndarray]]

    @property
    def failed(self) -> list[str]:
        """The checks that did not pass."""
        return [c["check"] for c in self.rom.checks if not c["passed"]]
