"""The results of the modal stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearingshaft.scenes import Scene


@dataclass(frozen=True, eq=False)
class Correlation:
    """The FE modes on the sensors of Table 3, against test shapes or themselves (auto-MAC).

    Parameters
    ----------
    sensors : list of str
        Every sensor, beam then tube (the nodes of ``fe_shapes.uff``, in order).
    sets : dict
        ``{set name: sensors}``: ``beam`` (beam accelerometers) and ``assembly`` (beam and tube).
    fe_shapes : (3 n_sensors, n_chosen) array
        x, y, z of each sensor in each chosen mode.
    test_given : bool
        Whether test shapes were read (else the MAC is the FE auto-MAC).
    note : str
        Where the test shapes came from, or that there were none.
    mac : dict
        ``{set name: (n_chosen, n_chosen) MAC}``, FE modes in rows.
    """

    sensors: list[str]
    sets: dict[str, list[str]]
    fe_shapes: np.ndarray
    test_given: bool
    note: str
    mac: dict[str, np.ndarray]


@dataclass(frozen=True, eq=False)
class ModalStageResult:
    """What the ``modal`` stage computed.

    Parameters
    ----------
    scene : Scene
        The scene analysed.
    analysis : fem.analysis.ModalAnalysis
        The solved model: its system (mesh, sensors), modes and labels (None for the free beam).
    chosen : list of int
        The modes shown and correlated (indices): the six pseudo-rigid ones in Table 2 order, or
        the free beam's first six classified modes.
    names : list of str
        Their names.
    table2 : list of dict or None
        Table 2 rows (``mode, description, freq_hz, test_hz, error_pct``); None for the free beam.
    label_purity : dict or None
        ``{Table 2 name: purity}`` of the labels.
    correlation : Correlation or None
        The MAC on the sensors (not for the free beam).
    free_beam : list of dict or None
        The free beam's elastic modes against beam theory (family, order, theory, Hz, errors).
    """

    scene: Scene
    analysis: object
    chosen: list[int]
    names: list[str]
    table2: list[dict] | None = None
    label_purity: dict[str, float] | None = None
    correlation: Correlation | None = None
    free_beam: list[dict] | None = None
