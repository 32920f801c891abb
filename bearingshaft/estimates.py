"""What a stage will hold at its peak, counted from the scene alone (no model is built).

Each stage declares its estimate in the registry (:mod:`bearingshaft.registry`); the budget
(:mod:`bearingshaft.budget`) checks them against the memory and disk available. The
estimates are upper bounds within a small factor (``COPIES``), not a profile: their job is
to stop a 149 GiB request before numpy makes it. Sizes: samples x channels x 8 bytes for
time histories held in memory, ((2H + 1) n)^2 x 8 bytes for harmonic-balance Jacobians.
"""

from __future__ import annotations

from dataclasses import dataclass

from bearingshaft.scenes import Scene

COPIES = 3  # a stage holds its result, a derived series (energy, points) and a plotting copy
JACOBIAN_COPIES = 4  # HB: Jacobian, its LU factors, the AFT blocks and a continuation copy
HILL_COPIES = 6  # FRC Hill: the real matrix, its Hessenberg/Schur work copies, complex eigenvalue output
FLOAT = 8  # bytes
MATPLOTLIB_BYTES = 64 * 2**20  # figures being drawn, fonts, the HB backbones: measured 10-30 MB


@dataclass(frozen=True, slots=True)
class Estimate:
    """Peak bytes one stage will hold, what they are, and the scene key that sizes them.

    Parameters
    ----------
    stage : str
        The stage's name.
    bytes : float
        Peak bytes held in memory.
    what : str
        What they are, for the refusal message.
    key : str
        ``"[table] key"``: the scene key that sizes them.
    disk : float
        bytes written to the results folder.
    advice : str
        What to do when it does not fit (default: "lower <key>").
    """

    stage: str
    bytes: float
    what: str
    key: str  # "[table] key"
    disk: float = 0.0  # bytes written to the results folder
    advice: str = ""  # what to do when it does not fit (default: "lower <key>")


def n_dofs(scene: Scene) -> int:
    """DOFs of the scene's gap system, known before it is built (3-D models: 0).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    int
        3 for the discrete model (4 with friction), n_modes + 2 for a reduced one (+ its tangential
        coordinates with friction: 4 along the beam, 8 along and across), 0 for a 3-D model.
    """
    if scene.model_kind == "discrete":
        return 3
    if scene.model_kind == "discrete_friction":
        return 4
    if scene.model_kind == "rom":
        return scene.model.n_modes + 2 + sliders(scene)
    return 0


def has_friction(scene: Scene) -> bool:
    """Whether the scene's model has friction at its tips (``mu`` > 0: the discrete friction model or a
    reduced model with sliders), which changes what the frc and hammer stages compute.

    Parameters
    ----------
    scene : Scene
        The scene.
    """
    return float(getattr(scene.model, "mu", 0.0) or 0.0) > 0.0


def sliders(scene: Scene) -> int:
    """Friction sliders of the scene's reduced model: one a stop and direction (reduced.models.rom).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    int
        0 without friction, 4 along the beam, 8 along and across it.
    """
    m = scene.model
    if scene.model_kind != "rom" or not has_friction(scene):
        return 0
    return 4 * (2 if m.friction_directions == "axial+lateral" else 1)


def history_bytes(samples: float, n: int, runs: int = 1) -> float:
    """Bytes of ``runs`` sampled histories: t, x (n), v (n), dissipated, energy per sample.

    Parameters
    ----------
    samples : float
        Samples of one history.
    n : int
        DOFs.
    runs : int
        Histories held.

    Returns
    -------
    float
        bytes, runs x ``COPIES`` x samples x (2 n + 3) x 8.
    """
    return runs * COPIES * samples * (2 * n + 3) * FLOAT
