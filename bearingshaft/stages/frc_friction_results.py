"""What the frc stage computes on a model with friction (:mod:`bearingshaft.stages.frc_friction`), read by its
writers (:mod:`bearingshaft.stages.frc_friction_files`): the result objects and the parts of the frictionless
stage it skips, with the reason."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bearingshaft.scenes import Scene

SKIPPED = (
    ("converged curve by shooting", "the exact orbits are continued by shooting with the sliders "
     "(reduced.periodic.friction_continuation, exact Jacobians) from every orbit shot at an unsettled point, each way "
     "for at most [frc] shooting_steps / 2 points (about 0.08 s of CPU a point in contact), and shot on a 0.1 Hz grid "
     "(reduced.periodic.friction_sweep) over the stretches of the contact band they leave, not continued over the "
     "whole band: in contact the exact branch advances 0.02-0.04 Hz a point and folds back (measured on this scene: "
     "0.65-0.85 Hz in 20 points, 0.75-0.97 Hz in 40), so 14.3-30 Hz would take 400-800 points, 30-65 s of CPU (the "
     "stage's whole budget is about 70 s); where neither the grid's previous orbit nor HB's converges (HB not "
     "converged in H there) no exact orbit is found: frc.md's coverage says where; Hill's method gives the "
     "stability along the whole HB curve"),
    ("convergence in H of the whole curve", "each H's curve is a continuation with AFT (tens of seconds a curve): "
     "HB's convergence in H is measured at each continued branch's start instead (its section above)"),
    ("backbone check", "with friction the free motion is not conservative: no NNM backbone to approach"),
)


@dataclass(eq=False)
class ShootCheck:
    """Shooting on the exact friction flow (:func:`reduced.periodic.friction_shooting.shoot_friction`) from the HB
    orbit at a frequency where the stepped sine did not settle.

    Attributes
    ----------
    converged : whether Newton reached the shooting tolerance
    message : how Newton ended (the defect reached and why, if not converged), or why it did not run
    start_H : the HB order of the start shot from last (the curve's H, or a higher one at that frequency)
    shoot_m : (p,) m, max |x| over the shot orbit at each output point (NaN if not converged)
    hb_m : (p,) m, the curve's HB solution at the frequency whatever its stability (NaN if none)
    amp_rel : (p,) |HB / shooting - 1| of the amplitudes
    history_rel : (p,) max over the period of |x_HB(t) - x_shooting(t)| / max |x_shooting| at each point
    defect : the multiple-shooting defect reached, in units of the amplitude
    period_defect : |y(T) - y(0)| / amplitude of one exact run over the whole period from the orbit's start
    max_abs_multiplier : the largest |Floquet multiplier| (NaN if not converged)
    stable : the multipliers within the unit circle (None if not converged)
    hb_stable : Hill's verdict on the curve's HB solution at the frequency (None where the bracketing points
        disagree)
    rank, size : numerical rank of the shooting Jacobian, and its size (size - rank free slider directions)
    n_iter : Newton steps of the last start
    wall_s : s, all starts together
    """

    converged: bool
    message: str
    start_H: int = 0
    shoot_m: np.ndarray | None = None
    hb_m: np.ndarray | None = None
    amp_rel: np.ndarray | None = None
    history_rel: np.ndarray | None = None
    defect: float = math.nan
    period_defect: float = math.nan
    max_abs_multiplier: float = math.nan
    stable: bool | None = None
    hb_stable: bool | None = None
    rank: int = 0
    size: int = 0
    n_iter: int = 0
    wall_s: float = 0.0
    orbit: object = None  # the FrictionShootingResult where converged (the continued shooting's start)


@dataclass(eq=False)
class FrictionCheck:
    """One settled frequency of the stepped sine by the exact friction integrator, against HB.

    Attributes
    ----------
    level_N, freq_hz : the load amplitude (N) and frequency (Hz)
    exact_m : (p,) m, max |x| over the last period at each output point
    hb_m : (p,) m, the HB solution at freq_hz (NaN where no stable piece brackets it)
    settled_change : relative change of the amplitudes over the last SETTLE_CHUNK periods
    settled : whether that change fell below ``[frc] stepped_sine_tol``
    simulated_s : s of motion run at this frequency
    friction_work_per_period_J : J, the friction work of the last period
    shooting : ShootCheck where the stepped sine did not settle, else None
    """

    level_N: float
    freq_hz: float
    exact_m: np.ndarray  # (p,) m, max |x| over the last period at each output point
    hb_m: np.ndarray  # (p,) m, the HB solution at freq_hz (NaN where no stable piece brackets it)
    settled_change: float  # relative change of the amplitudes over the last SETTLE_CHUNK periods
    settled: bool
    simulated_s: float
    friction_work_per_period_J: float  # of the last period
    shooting: ShootCheck | None = None  # where the stepped sine did not settle

    @property
    def rel_error(self) -> float:
        """Largest |HB / exact - 1| over the output points (NaN without an HB solution)."""
        return float(np.max(np.abs(self.hb_m / self.exact_m - 1.0))) if np.all(np.isfinite(self.hb_m)) else math.nan


@dataclass(eq=False)
class ShootingCurve:
    """The exact friction orbits continued in frequency by shooting
    (:func:`reduced.periodic.friction_continuation.continue_friction`), each against the HB curve.

    Attributes
    ----------
    branch : FrictionShootingBranch
    hb_m : (k, p) m, the HB curve's solution at each point's frequency nearest its amplitude at the first
        output point, any stability (NaN where none)
    hb_stable : [bool or None] Hill's verdict there (None: none, or the bracketing points disagree)
    switches : [BranchSwitch] the branch switching tried at its folds and branch points
        (:func:`reduced.periodic.friction_continuation.switch_branch`)
    origin : "" for a branch continued from a shot orbit; where a new family was switched onto, from which branch
        and bifurcation
    """

    branch: object
    hb_m: np.ndarray
    hb_stable: list
    switches: list = field(default_factory=list)
    origin: str = ""

    @property
    def rel_error(self) -> np.ndarray:
        """(k,) the largest |HB / shooting - 1| over the output points (NaN without HB)."""
        return np.max(np.abs(self.hb_m / self.branch.amplitude_m - 1.0), axis=1)


@dataclass(eq=False)
class BranchVerdict:
    """Who is right where HB and shooting disagree, at a continued branch's start orbit
    (:func:`bearingshaft.stages.frc_friction._verdict`).

    Attributes
    ----------
    freq_hz : Hz, the start orbit's frequency
    shoot_m : (p,) m, max |x| over the shot orbit at each output point
    defect : the multiple-shooting defect, in units of the amplitude
    period_defect : |y(T) - y(0)| / D of one exact run over the whole period from the orbit's start
    dop853_rel : max over one period of |y_DOP853(t) - y_exact(t)| / D, DOP853 restarted at every state change
        (:func:`reduced.transient.friction.reference_dop853`, rtol 1e-12) from the orbit's start: the independent check
    max_abs_multiplier : the largest |Floquet multiplier| of the start orbit
    hb : [(H, (p,) amplitude HB / shooting - 1 or None where Newton found no HB solution, (p,) max over the period
        of |x_HB - x_shooting| / max |x_shooting|, or None)] HB at the orbit's frequency for each H of HB_CONVERGENCE_H
    """

    freq_hz: float
    shoot_m: np.ndarray
    defect: float
    period_defect: float
    dop853_rel: float
    max_abs_multiplier: float
    hb: list = field(default_factory=list)

    def hb_moves(self) -> np.ndarray | None:
        """(p,) |A_H / A_H' - 1| between the two highest H with a solution (None: fewer than two)."""
        got = [(H, a) for H, a, _ in self.hb if a is not None]
        if len(got) < 2:
            return None
        return np.abs((1.0 + got[-1][1]) / (1.0 + got[-2][1]) - 1.0)


@dataclass(eq=False)
class FrictionFRCResult:
    """What :func:`bearingshaft.stages.frc_friction.compute` returns (its ``write`` writes it).

    Attributes
    ----------
    scene : the scene
    names : the output points
    load : (n,) the load direction b
    curves : {P: FRCBranch or ContinuationError}, the friction HB curves
    checks : {P: [FrictionCheck]}, the stepped sine's settled points
    linear : {P: (freq_hz (k,), amplitude (k, p))}, the open-gap response without friction
    stats : the stage's statistics
    shooting : {P: ShootingCurve or str}, the exact orbits continued by shooting, or why not
    verdicts : {P: [BranchVerdict]}, one per continued branch (its start orbit): shooting checked independently, HB
        against it for H = HB_CONVERGENCE_H
    sweeps : {P: [(f_from, f_to, FrictionSweep, HB's amplitudes nearest its orbits (k, q))] or why not}, the exact
        orbits on a grid where the continued branches do not reach (:func:`bearingshaft.stages.frc_friction._swept`)
    response_maps : {P: MapLevel or None}, the stepped sine up and down classified at every frequency
        (:mod:`bearingshaft.stages.frc_friction_map`)
    """

    scene: Scene
    names: tuple[str, ...]
    load: np.ndarray  # (n,) the load direction b
    curves: dict  # {P: FRCBranch or ContinuationError}
    checks: dict  # {P: [FrictionCheck]}
    linear: dict  # {P: (freq_hz (k,), amplitude (k, p))} the open-gap response without friction
    stats: dict = field(default_factory=dict)
    shooting: dict = field(default_factory=dict)  # {P: ShootingCurve or str}
    verdicts: dict = field(default_factory=dict)  # {P: [BranchVerdict]}
    sweeps: dict = field(default_factory=dict)  # {P: [(f_from, f_to, FrictionSweep, hb (k, q))] or str}
    response_maps: dict = field(default_factory=dict)  # {P: MapLevel or None} (bearingshaft.stages.frc_friction_map)


__all__ = ["SKIPPED", "BranchVerdict", "FrictionCheck", "FrictionFRCResult", "ShootCheck", "ShootingCurve"]
