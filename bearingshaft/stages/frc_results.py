"""The results of the frc stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


# -- what the stage computed ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PointCheck:
    """Hill's method and shooting at one point of a curve, beside its monodromy verdict.

    Attributes
    ----------
    index : int
        The point on the curve.
    contact : bool
        A stop closes somewhere along its orbit.
    shot : bool
        Shooting was tried here.
    freq_hz : float
        Hz, the point's excitation frequency.
    mono : float
        max |mu| of the orbit monodromy.
    mono_stable : bool
        The monodromy's verdict.
    hill : float
        max |mu| by Hill's method (nan where not run).
    hill_stable : bool or None
        Hill's verdict, None where not run.
    shoot : float
        max |mu| of the exact orbit (nan where not found).
    shoot_stable : bool or None
        Shooting's verdict, None where not found.
    shoot_amp : (p,) ndarray of float or None
        m, the exact orbit's amplitude at each output point.
    shoot_note : str
        Why shooting failed ("" otherwise).
    """

    index: int  # the point on the curve
    contact: bool  # a stop closes somewhere along its orbit
    shot: bool  # shooting was tried here
    freq_hz: float
    mono: float  # max |mu| of the orbit monodromy
    mono_stable: bool
    hill: float  # max |mu| by Hill's method (nan where not run)
    hill_stable: bool | None  # None where not run
    shoot: float  # max |mu| of the exact orbit (nan where not found)
    shoot_stable: bool | None  # None where not found
    shoot_amp: np.ndarray | None  # (p,) m, the exact orbit's amplitude at each point
    shoot_note: str  # why shooting failed ("" otherwise)


@dataclass(frozen=True, eq=False)
class ConvergenceRun:
    """One H of the convergence study at ``[frc] convergence_level_N``.

    Attributes
    ----------
    H : int
        Harmonics of the curve.
    curve : FRCBranch or ContinuationError
        The curve, or the error of a curve that could not start (no stability).
    err_stepped_sine : list of float
        max relative amplitude error at each periodic stepped-sine point.
    err_shooting : list of float
        max relative amplitude error at each exact orbit found.
    shooting_failed : int
        Contact shooting points where no HB solution or no exact orbit was found.
    wall_s : float
        s, wall time of this H.
    """

    H: int
    curve: object  # FRCBranch, or the ContinuationError of a curve that could not start (no stability)
    err_stepped_sine: list  # max relative amplitude error at each periodic stepped-sine point
    err_shooting: list  # max relative amplitude error at each exact orbit found
    shooting_failed: int  # contact shooting points where no HB solution or no exact orbit was found
    wall_s: float


@dataclass(frozen=True, eq=False)
class ConvergedCurve:
    """The drawn curve of one level (``[frc] curve``): HB where its amplitudes no longer move with H,
    else the families of orbits of the exact flow continued by shooting (no H).

    Attributes
    ----------
    level : float
        N, the load amplitude.
    method : {'hb', 'shooting'}
        What is drawn.
    reason : str
        Why, in words with the numbers (frc.md).
    hb_H, check_H : int
        H of the HB curve and of the balance it was compared with (0: no comparison).
    hb_change : float
        Largest relative change of the amplitudes (every output point) between check_H and hb_H over
        the HB curve's points (inf where HB at check_H was not found; nan: not compared).
    contact : bool
        A stop closes somewhere along the HB curve.
    exact : ExactFRC or None
        The families (:class:`reduced.periodic.exact_frc.ExactFRC`) where shot.
    error : str
        Why shooting failed (then HB is drawn, marked as not converged).
    wall_s : float
        s, the comparison and the shooting.
    refined : tuple
        HB curves (FRCBranch) over the bands of lightly damped modes the HB curve stepped over
        (:func:`bearingshaft.stages.frc.resonance_refinements`), drawn there instead of it.
    hb_fill : ndarray
        (k,) bool over the HB curve's points: drawn beside the exact families (outside the main
        family's range, where the orbit closes no stop); empty where HB is drawn or not needed.
    open_gap : OpenGapOrbits or None
        The orbits of the open-gap (linear) system at the HB curve's frequencies in contact where they
        close no stop (exact orbits that coexist with the contact ones), drawn beside the families.
    """

    level: float
    method: str  # "hb" | "shooting"
    reason: str
    hb_H: int
    check_H: int
    hb_change: float
    contact: bool
    exact: object  # ExactFRC or None
    error: str = ""
    wall_s: float = 0.0
    refined: tuple = ()  # FRCBranch over the bands of modes the HB curve stepped over
    hb_fill: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # HB points drawn beside the families
    open_gap: object = None  # OpenGapOrbits or None


@dataclass(frozen=True, eq=False)
class OpenGapOrbits:
    """Orbits of the system with every stop open that close no stop (:func:`reduced.periodic.frc.open_gap_orbits`):
    exact periodic orbits of the gap system, drawn where the HB curve is in contact (and at the frequencies
    beside those, so that the line joins the HB points drawn there).

    Attributes
    ----------
    freq_hz : ndarray
        (k,) Hz, increasing.
    amplitude_m : ndarray
        (k, p) m, max |x| over a period at each output point.
    margin_m : ndarray
        (k,) m, the smallest clearance left over a period, min_j (side_j o_j - |B_j X|) > 0.
    stable : bool
        Asymptotically stable (the open system is: every eigenvalue has Re < 0).
    segment : ndarray
        (k,) int, a piece per run of consecutive frequencies.
    """

    freq_hz: np.ndarray
    amplitude_m: np.ndarray
    margin_m: np.ndarray
    stable: bool
    segment: np.ndarray


@dataclass(frozen=True, eq=False)
class MapLevel:
    """The response map at one load level (:mod:`bearingshaft.stages.frc_map`).

    Attributes
    ----------
    level_N : float
        N, the load amplitude P.
    bands : list of (float, float)
        Hz, the contact bands stepped at ``[frc] map_step_hz`` (the linear response's and the HB
        curve's, widened), before the sweeps' own extensions.
    sweeps : dict
        ``up``/``down`` -> :class:`reduced.periodic.response_map.ResponseMap`.
    wall_s : float
        s, both sweeps.
    """

    level_N: float
    bands: list
    sweeps: dict
    wall_s: float


@dataclass(frozen=True, eq=False)
class FRCResult:
    """Everything the frc stage computed (:func:`bearingshaft.stages.frc.compute`).

    Curves are :class:`reduced.periodic.frc.FRCBranch` objects; one that could not start is
    kept as its :class:`reduced.periodic.continuation.ContinuationError` (reported, not raised).
    Keys: P the load level [N], ``direction`` "up" or "down", ``scale`` a factor of
    ``[frc] backbone_scales``.

    Attributes
    ----------
    scene_name : str
        The scene's name.
    spec : FRCSpec
        The [frc] table.
    names : tuple of str
        Output points.
    load_col : int
        Index of the point the load acts at.
    curves : dict
        P -> FRCBranch or ContinuationError, H = [frc] harmonics.
    events : dict
        P -> (k,) Hz where the sweeps must jump (folds, ends of stable pieces).
    checks : dict
        P -> list of PointCheck.
    sweeps : dict
        P -> {direction: SteppedSine} (empty without a stepped sine).
    sweep_hb : dict
        (P, direction) -> per sweep frequency the HB amplitudes (p,) in m there, or None.
    convergence : list of ConvergenceRun
        One per H of [frc] convergence_harmonics.
    backbone_curves : dict
        (P, scale) -> FRCBranch (H = 1, damping and load scaled).
    backbones : dict
        Linear mode -> (freq_hz (k,), amplitudes (k, p) in m) of its NNM backbone.
    peaks : dict
        (P, scale) -> (Hz, m), the peak of the backbone curve at the load point.
    nearest : dict
        (P, scale) -> (mode, log distance) of the nearest backbone to that peak.
    converged : dict
        P -> ConvergedCurve, the drawn curve of each level.
    response_maps : dict
        P -> MapLevel, the response map (empty when ``[frc] map_step_hz = 0``).
    mirror_note : str
        How the model was averaged over its tip mirror (:func:`bearingshaft.stages.frc.mirror_symmetric`;
        empty: its mirror was exact, or it has none).
    """

    scene_name: str
    spec: object  # the [frc] table
    names: tuple[str, ...]  # output points
    load_col: int  # the point the load acts at
    curves: dict  # P -> FRCBranch | ContinuationError, H = [frc] harmonics
    events: dict  # P -> (k,) Hz where the sweeps must jump (folds, ends of stable pieces)
    checks: dict  # P -> list[PointCheck]
    sweeps: dict  # P -> {direction: SteppedSine} (empty without a stepped sine)
    sweep_hb: dict  # (P, direction) -> per sweep frequency the HB amplitudes (p,) there, or None
    convergence: list  # ConvergenceRun per H of [frc] convergence_harmonics
    backbone_curves: dict  # (P, scale) -> FRCBranch (H = 1, damping and load scaled)
    backbones: dict  # linear mode -> (freq_hz (k,), amplitudes (k, p)) of its NNM backbone
    peaks: dict  # (P, scale) -> (Hz, m) the peak of the backbone curve at the load point
    nearest: dict  # (P, scale) -> (mode, log distance) of the nearest backbone to that peak
    converged: dict = field(default_factory=dict)  # P -> ConvergedCurve, the drawn curve of each level
    response_maps: dict = field(default_factory=dict)  # P -> MapLevel (bearingshaft.stages.frc_map)
    mirror_note: str = ""  # how the model's tip mirror was made exact (empty: it was, or there is none)
