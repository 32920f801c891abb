"""What ``bearingshaft identify`` found, as its writer reads it (:mod:`bearingshaft.identify.report`).

Data only: nothing here runs the model or draws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bearingshaft.identify.fit import Fit
from bearingshaft.scenes import Scene


@dataclass(frozen=True, eq=False)
class Overlay:
    """The test and the model at its first guess and at the optimum, on the compared channels.

    Attributes
    ----------
    names : tuple of str
        The channels (rows).
    t : (N,) ndarray of float
        s.
    test : (n, N) ndarray of float
        The test, in the model's sign convention.
    initial, identified : (n, N) ndarray of float
        The model at the scene's values and at the identified ones.
    units : tuple of str
        The channels' units.
    """

    names: tuple[str, ...]
    t: np.ndarray
    test: np.ndarray
    initial: np.ndarray
    identified: np.ndarray
    units: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Identified:
    """An identification: the fit, the overlays, what to say.

    Attributes
    ----------
    scene : Scene
    test_file : str
    fit : Fit
    overlay : Overlay
    driven : str
        What drove the model (the test's hammer channel, its force window).
    lines : tuple of str
        The summary line(s) the command prints.
    stats : dict
        For provenance.json.
    """

    scene: Scene
    test_file: str
    fit: Fit
    overlay: Overlay
    driven: str
    lines: tuple[str, ...] = ()
    stats: dict = field(default_factory=dict)


__all__ = ["Identified", "Overlay"]
