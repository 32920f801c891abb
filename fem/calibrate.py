"""Model updating: fit the open parameters of :class:`fem.model.AssemblyModel` to Table 2.

Least squares on the relative frequency errors of the six pseudo-rigid modes,

    min_p  sum_i r_i(p)^2,   r_i = (f_i(p) - f_i^test) / f_i^test,

over x = ln p (so that parameters of different units and sizes are scaled alike), with
bounds, by SciPy's trust-region reflective method and forward-difference Jacobians (one
full FE solve per parameter per iteration). The parameters the paper fixes (k_s, L, g,
k_g, the beam's mass, kappa) are never among the fitted ones. The result reports the
fitted values and the normalised sensitivities S_ij = d ln f_i / d ln p_j at the optimum.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from fem.labels import TABLE2_ORDER, TABLE2_TEST_HZ
from fem.model import AssemblyModel

FIXED_BY_PAPER = ("k_s", "L", "gap", "k_g", "beam_mass", "kappa")
DEFAULT_PARAMETERS = {  # name: (lower, upper) bounds
    "beam_length": (0.36, 0.60),  # m: the beam must reach past the seats at +-L
    "coil_diameter": (0.008, 0.026),  # m: must fit on the beam's width
    "spring_length": (0.015, 0.08),  # m
    "seat_k_rx": (0.05, 200.0),  # N m/rad
    "seat_k_ry": (0.05, 200.0),  # N m/rad
    "seat_k_rz": (0.05, 1e4),  # N m/rad
    "tube_mass": (4.0, 40.0),  # kg
}


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Fitted model, its frequencies and the sensitivities at the optimum.

    Attributes
    ----------
    model : AssemblyModel
        ``model`` with the fitted values put in.
    names : tuple of str
        The fitted parameters, in the order of ``initial`` and ``fitted``.
    initial, fitted : (n_params,) ndarray of float
        The parameters' values at the start and at the optimum (their own units, see
        ``DEFAULT_PARAMETERS``).
    freq_hz : (6,) ndarray of float
        Hz, the model's pseudo-rigid frequencies at the fitted values, Table 2 order.
    test_hz : (6,) ndarray of float
        Hz, the measured frequencies fitted to.
    sensitivity : (6, n_params) ndarray of float
        S_ij = d ln f_i / d ln p_j at the optimum (from the last finite-difference Jacobian).
    n_evaluations : int
        Distinct models evaluated.
    status, message
        ``scipy.optimize.least_squares``'s status and message.
    wall_time_s : float
        s, time of the fit.
    history : list of tuple
        (parameter values, frequencies in Hz) of every evaluation, in order.
    """

    model: AssemblyModel
    names: tuple[str, ...]
    initial: np.ndarray  # starting values of the fitted parameters
    fitted: np.ndarray  # fitted values
    freq_hz: np.ndarray  # Hz, Table 2 order, at the fitted values
    test_hz: np.ndarray  # Hz, Table 2
    sensitivity: np.ndarray  # (6, n_params) d ln f_i / d ln p_j
    n_evaluations: int
    status: int
    message: str
    wall_time_s: float
    history: list = field(default_factory=list)  # (parameters, frequencies) of every evaluation

    @property
    def error_pct(self) -> np.ndarray:
        return 100 * (self.freq_hz - self.test_hz) / self.test_hz


def calibrate(model: AssemblyModel, evaluate: Callable[[AssemblyModel], np.ndarray],
              parameters: dict[str, tuple[float, float]] | None = None,
              test_hz=TABLE2_TEST_HZ, max_nfev: int = 60, diff_step: float = 0.02,
              log: Callable[[str], None] | None = None) -> CalibrationResult:
    """Fit ``parameters`` of ``model`` so that ``evaluate(model)`` (Hz, Table 2 order) matches ``test_hz``.

    Parameters
    ----------
    model : AssemblyModel
        The starting model; its values of the fitted parameters are the starting point (clipped
        into the bounds).
    evaluate : callable
        ``evaluate(model) -> (6,) ndarray``, Hz, the model's frequencies in Table 2 order. A
        ValueError (infeasible geometry inside the bounds) counts as frequencies ten times the test.
    parameters : dict of str to (float, float), optional
        Field of AssemblyModel -> (lower, upper) bound, in the field's units (default
        ``DEFAULT_PARAMETERS``).
    test_hz : (6,) array_like of float
        Hz, the measured frequencies (Table 2).
    max_nfev : int
        Most residual evaluations of the least-squares solver.
    diff_step : float
        Relative step of the forward differences in ln p.
    log : callable, optional
        ``log(line)`` called after each new evaluation.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ValueError
        A parameter the paper fixes (``FIXED_BY_PAPER``) is asked to be fitted.
    """
    parameters = parameters or DEFAULT_PARAMETERS
    bad = [p for p in parameters if p in FIXED_BY_PAPER]
    if bad:
        raise ValueError(f"{bad[0]} is fixed by the paper and may not be fitted")
    names = tuple(parameters)
    test = np.asarray(test_hz, float)
    p0 = np.array([getattr(model, n) for n in names], float)
    lo = np.log([parameters[n][0] for n in names])
    hi = np.log([parameters[n][1] for n in names])
    x0 = np.clip(np.log(p0), lo + 1e-9, hi - 1e-9)
    # unknowns y = ln(p / p0): SciPy's finite-difference step is diff_step max(1, |y|), so about
    # diff_step relative in every parameter near the start (on ln p itself it grew with |ln p|:
    # 28 % for a stiffness of 1e6)
    x_ref = x0.copy()
    history: list = []
    cache: dict = {}

    def freq(y):
        x = x_ref + y
        key = tuple(np.round(x, 12))
        if key not in cache:
            m = dataclasses.replace(model, **{n: float(v) for n, v in zip(names, np.exp(x), strict=True)})
            try:
                f = np.asarray(evaluate(m), float)
            except ValueError:  # infeasible geometry inside the bounds: a large residual
                f = test * 10.0
            cache[key] = f
            history.append((np.exp(x), f))
            if log:
                err = 100 * (f - test) / test
                log(f"eval {len(history):3d}: max |err| {np.abs(err).max():6.2f} %  "
                    + " ".join(f"{n}={v:.4g}" for n, v in zip(names, np.exp(x), strict=True)))
        return cache[key]

    t0 = time.perf_counter()
    sol = least_squares(lambda y: freq(y) / test - 1.0, np.zeros_like(x0), bounds=(lo - x_ref, hi - x_ref),
                        method="trf", jac="2-point", diff_step=diff_step, max_nfev=max_nfev, x_scale=1.0)
    f = freq(sol.x)
    S = sol.jac * (test / f)[:, None]  # d ln f / d ln p from d r / d ln p (= d r / d y)
    fitted = np.exp(x_ref + sol.x)
    best = dataclasses.replace(model, **{n: float(v) for n, v in zip(names, fitted, strict=True)})
    return CalibrationResult(model=best, names=names, initial=p0, fitted=fitted, freq_hz=f, test_hz=test,
                             sensitivity=S, n_evaluations=len(history), status=sol.status,
                             message=sol.message,
                             wall_time_s=time.perf_counter() - t0, history=history)


__all__ = ["calibrate", "CalibrationResult", "DEFAULT_PARAMETERS", "FIXED_BY_PAPER", "TABLE2_ORDER"]
