"""From a scene to what the solvers take: its gap system and points, its initial state on the
system's DOFs, its loads, and the integrator options of its [ringdown] table."""

from __future__ import annotations

import numpy as np

from bearingshaft.scenes import Scene
from reduced.models.gaps import GapSystem
from reduced.models.initial import initial_state
from reduced.models.loads import Loads, point_loads


def model_system(model, progress: bool = False) -> tuple[GapSystem, np.ndarray]:
    """(system, P): a scene model's gap system and its points x1, x2, x3 as rows P of its DOFs.

    Parameters
    ----------
    model : DiscreteParams or RomSpec
        A scene's [model] (anything with ``system()`` and ``point_rows``, or ``reduced()``).
    progress : bool
        Print a line if a reduced model is built.

    Returns
    -------
    system : GapSystem
    P : (3, n) ndarray of float
        The points x1, x2, x3 as rows of the system's DOFs.
    """
    if hasattr(model, "reduced"):  # a reduced 3-D model: from rom.npz or the cache
        rom = model.reduced(progress)
        return rom.system(), rom.point_rows
    return model.system(), model.point_rows


def scene_initial_state(scene: Scene, system: GapSystem, P: np.ndarray, dx_points=None, dv_points=None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(x0, v0) on the system's DOFs from the scene's point values (:mod:`reduced.models.initial`),
    plus the point perturbations ``dx_points``, ``dv_points`` if given.

    Parameters
    ----------
    scene : Scene
        Its [initial] table gives the points' displacement (m) and velocity (m/s).
    system : GapSystem
        The model's system (M and K).
    P : (3, n) ndarray of float
        The points as rows of its DOFs.
    dx_points, dv_points : (3,) array_like of float, optional
        m and m/s added to the points' values (both or neither).

    Returns
    -------
    x0 : (n,) ndarray of float
        m.
    v0 : (n,) ndarray of float
        m/s.

    Raises
    ------
    ValueError
        As :func:`reduced.models.initial.initial_state`.
    """
    init = scene.initial
    x_pts, v_pts = np.array(init.x0_m, float), np.array(init.v0_m_s, float)
    if dx_points is not None:
        x_pts, v_pts = x_pts + dx_points, v_pts + dv_points
    return initial_state(system.M, system.K, P, x_pts, v_pts)


def scene_loads(scene: Scene, P: np.ndarray) -> Loads | None:
    """The scene's [[load]] tables as loads on the system's DOFs (b_l = the row of P of the load's
    point), or None for a free ringdown.

    Parameters
    ----------
    scene : Scene
        Its [[load]] tables.
    P : (3, n) ndarray of float
        The points as rows of the system's DOFs.

    Returns
    -------
    Loads or None
    """
    if not scene.loads:
        return None
    return point_loads(scene.load_signals, [spec.point for spec in scene.loads], P, scene.model.point_names)


def solver_options(spec) -> dict:
    """The integrator options of a [ringdown] table (each method checks the others' too).

    Parameters
    ----------
    spec : RingdownSpec
        A [ringdown] table.

    Returns
    -------
    dict
        ``dt``, ``omega_dt``, ``step_basis``, ``rtol``, ``atol``: keywords of
        :func:`reduced.transient.integrate.ringdown`.
    """
    return {"dt": spec.dt_s, "omega_dt": spec.omega_dt, "step_basis": spec.step_basis, "rtol": spec.rtol,
            "atol": spec.atol}


def ringdown_options(scene: Scene, P: np.ndarray) -> dict:
    """The integrator options of the scene's [ringdown] table with its loads, if any.

    Parameters
    ----------
    scene : Scene
        The scene (its [ringdown] table and loads).
    P : (3, n) ndarray of float
        The points as rows of the system's DOFs.

    Returns
    -------
    dict
        :func:`solver_options`, with ``loads`` when the scene has any.
    """
    loads = scene_loads(scene, P)
    return {**solver_options(scene.ringdown), **({"loads": loads} if loads is not None else {})}
