"""What the frc stage computes on a model with friction (:mod:`bearingshaft.stages.frc_friction`), read by its
writers (:mod:`bearingshaft.stages.frc_friction_files`): the result objects and the parts of the frictionless
stage it skips, with the reason."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bearingshaft.scenes import Scene

SKIPPED = (
    ("converged curve by shooting", "the multiple shooting runs the exact flow without sliders: the sliders' "
     "positions are not in its state vector, so its periodic orbits are those of the frictionless system"),
    ("Floquet multipliers by shooting and monodromy", "the same: Hill's method on the consistent AFT Jacobian "
     "gives the stability instead"),
    ("response map", "its classifier (periodic, subharmonic, chaotic, Lyapunov exponent) runs the exact flow "
     "without sliders"),
    ("convergence in H", "each H's curve is a continuation with AFT (tens of seconds a curve); the stepped "
     "sine's error at the curve's H says how far it is"),
    ("backbone check", "with friction the free motion is not conservative: no NNM backbone to approach"),
)


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
    """

    level_N: float
    freq_hz: float
    exact_m: np.ndarray  # (p,) m, max |x| over the last period at each output point
    hb_m: np.ndarray  # (p,) m, the HB solution at freq_hz (NaN where no stable piece brackets it)
    settled_change: float  # relative change of the amplitudes over the last SETTLE_CHUNK periods
    settled: bool
    simulated_s: float
    friction_work_per_period_J: float  # of the last period

    @property
    def rel_error(self) -> float:
        """Largest |HB / exact - 1| over the output points (NaN without an HB solution)."""
        return float(np.max(np.abs(self.hb_m / self.exact_m - 1.0))) if np.all(np.isfinite(self.hb_m)) else math.nan


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
    """

    scene: Scene
    names: tuple[str, ...]
    load: np.ndarray  # (n,) the load direction b
    curves: dict  # {P: FRCBranch or ContinuationError}
    checks: dict  # {P: [FrictionCheck]}
    linear: dict  # {P: (freq_hz (k,), amplitude (k, p))} the open-gap response without friction
    stats: dict = field(default_factory=dict)


__all__ = ["SKIPPED", "FrictionCheck", "FrictionFRCResult"]
