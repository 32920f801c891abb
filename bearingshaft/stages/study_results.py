"""The results of the study stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from bearingshaft.scenes import Scene

CONVERGENCE_BUDGET_S = 2.0  # s, stop repeating a timed run once this is spent on it


@dataclass(frozen=True, eq=False)
class StudyResult:
    """What the ``study`` stage computed; a study the scene does not ask for is None.

    Parameters
    ----------
    scene : Scene
        The scene studied.
    work_precision : list of dict or None
        ``[work_precision]``: one row per run (:func:`reduced.studies.work_precision`).
    explicit_order : float
        The explicit integrator's observed order of accuracy (nan if not fitted).
    rom_convergence : list of dict or None
        ``[rom_convergence]``: one row per mode count (:func:`reduced.studies.rom_convergence`).
    n_full_dofs : int
        DOFs of the 3-D model reduced in ``rom_convergence`` (0 without it).
    stiff_cases : list of dict or None
        ``[stiff_cases]``: one row per run (:func:`reduced.studies.stiff_cases`).
    stiff_fields : tuple of str
        The columns of a stiff-case row (``reduced.studies.STIFF_FIELDS``).
    """

    scene: Scene
    work_precision: list[dict] | None = None
    explicit_order: float = math.nan
    rom_convergence: list[dict] | None = None
    n_full_dofs: int = 0
    stiff_cases: list[dict] | None = None
    stiff_fields: tuple[str, ...] = ()


def step_basis(scene: Scene) -> str:
    """The explicit step basis of the scene's ringdown (reduced.transient.explicit), "top" without one.

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    {'top', 'contact'}

    Examples
    --------
    >>> from bearingshaft.scenes import load_scene
    >>> step_basis(load_scene("rom-impulse")), step_basis(load_scene("verify-reduction"))
    ('contact', 'top')
    """
    return scene.ringdown.step_basis if scene.ringdown is not None else "top"
