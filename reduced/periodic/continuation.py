"""Pseudo-arclength continuation of any residual R(y) = 0, R: R^(p+1) -> R^p.

Layer 3 of the HB design (NLvib's ``solve_and_continue``): the driver knows nothing of
harmonic balance; it takes ``fun(y) -> (R (p,), dR/dy (p, p+1))``.

From a point y_i with unit tangent t_i (dR/dy t_i = 0, t_{i-1} . t_i > 0):

    predictor   y_p = y_i + ds t_i
    corrector   R(y) = 0,  t_i . (y - y_p) = 0        (Newton, square system)

Step control (Allgower & Georg 2003, Ch. 6): the step is halved when Newton fails, needs
more than ``max_iter`` iterations, or the new tangent turns by more than ``max_angle``
from the last one (which keeps the path on its branch in steep stretches); it grows by ``growth``
when Newton converges in few iterations. Folds are sign changes of the tangent component
of each monitored coordinate.

Grazing: where a mode first touches a stop its frequency rises like the square root of
the amplitude excess, so the branch has a true corner (the tangent turns by up to 90
degrees in an arbitrarily short step) and AFT sampling adds small kinks each time a
sample enters contact. Below ``corner_ds`` a large turn is accepted (the corner is a
property of the branch, not a step too long), and Newton may travel ~sqrt(ds corner_ds)
from the predictor, the distance from the predictor to the branch past a square-root corner.
If the step still falls below ``ds_min``, a *corner step* fixes one monitored coordinate
(e.g. the frequency) a little away from the last point and corrects; it is recorded in
``Branch.corners``. The run stops when ``stop(y)`` is true (e.g. energy above a
bound), after ``max_steps`` points, or when the step falls below ``ds_min``
(``status`` says which; the path found so far is returned, never silently extended).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced.periodic.hb import NewtonError, newton


class ContinuationError(RuntimeError):
    """The start point could not be found."""


@dataclass(eq=False)
class Branch:
    """Points of a continued branch and diagnostics."""

    y: np.ndarray  # (n_points, p+1)
    tangent: np.ndarray  # (n_points, p+1)
    ds: np.ndarray  # (n_points,) step that reached each point
    n_iter: np.ndarray  # (n_points,) Newton iterations per point
    folds: list = field(default_factory=list)  # (point index, coordinate index)
    status: str = ""  # "stop" | "max_steps" | "min_step"
    n_rejected: int = 0
    wall_s: float = 0.0
    data: list = field(default_factory=list)  # post-processed values per point (callback)
    corners: list = field(default_factory=list)  # point indices reached by a corner step


def tangent(J: np.ndarray, t_prev: np.ndarray | None = None) -> np.ndarray:
    """Unit null vector of J (p, p+1), oriented along t_prev."""
    p1 = J.shape[1]
    if t_prev is None:
        # the right singular vector of the smallest singular value
        t = np.linalg.svd(J)[2][-1]
    else:
        A = np.vstack([J, t_prev])
        b = np.zeros(p1)
        b[-1] = 1.0
        try:
            t = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            t = np.linalg.svd(J)[2][-1]
    t = t / np.linalg.norm(t)
    if t_prev is not None and t @ t_prev < 0.0:
        t = -t
    return t


def continue_branch(
    fun,
    y0: np.ndarray,
    *,
    param: int,
    direction: float = 1.0,
    ds: float = 0.05,
    ds_min: float = 1e-6,
    ds_max: float = 0.5,
    max_steps: int = 2000,
    max_iter: int = 8,
    good_iter: int = 3,
    growth: float = 1.5,
    max_angle_deg: float = 15.0,
    corner_ds: float = 1e-3,
    tol: float = 1e-10,
    stop=None,
    monitor: tuple[int, ...] = (),
    callback=None,
    reject=None,
    progress=None,
) -> Branch:
    """Continue the solution curve of ``fun`` from ``y0`` (see the module docstring).

    Parameters
    ----------
    fun : y (p+1,) -> (R (p,), dR/dy (p, p+1))
    y0 : initial guess; corrected with coordinate ``param`` held fixed
    param : the coordinate that starts the branch (its tangent component has the sign
        of ``direction`` at the start) and whose folds are always reported
    stop : y -> bool, ends the run after the first point where it is true
    monitor : further coordinates whose folds are reported
    callback : y -> object stored in ``Branch.data`` for each point
    reject : (y_old, y_new) -> bool; a true answer rejects the step (halved), e.g. a
        jump in a physical quantity that the tangent angle does not see
    progress : callable(y) after every accepted point
    """
    t_wall = time.perf_counter()
    p1 = y0.size

    def max_jump(h):
        # past a square-root corner the branch lies ~sqrt(h) from the predictor
        return 4.0 * max(h, math.sqrt(h * corner_ds))

    def fixed(y):
        R, J = fun(y)
        e = np.zeros(p1)
        e[param] = 1.0
        return np.concatenate([R, [y[param] - y0[param]]]), np.vstack([J, e])

    try:
        start = newton(fixed, y0, tol=tol, max_iter=30)
    except NewtonError as exc:
        raise ContinuationError(f"start point not found: {exc}") from None
    y = start.y
    J = start.jacobian[:-1]  # dR/dy at y (the fixed row dropped)
    t = tangent(J)
    if t[param] * direction < 0.0:
        t = -t
    ys, ts, dss, its = [y], [t], [0.0], [start.n_iter]
    data = [callback(y)] if callback else []
    folds: list = []
    corners: list = []
    watch = tuple(dict.fromkeys((param, *monitor)))
    n_rej = 0
    status = "max_steps"
    cos_max = math.cos(math.radians(max_angle_deg))
    if stop is not None and stop(y):
        status = "stop"
        max_steps = 0
    for _ in range(max_steps):
        while True:
            yp = y + ds * t

            def corrector(z, yp=yp, t=t):
                R, Jz = fun(z)
                return np.concatenate([R, [t @ (z - yp)]]), np.vstack([Jz, t])

            ok = False
            try:
                res = newton(corrector, yp, tol=tol, max_iter=max_iter, max_step=max_jump(ds))
                tn = tangent(res.jacobian[:-1], t)  # newton's Jacobian is at res.y: the arclength row dropped
                # a corner (the square-root onset of contact at grazing) turns the tangent by
                # up to 90 degrees however short the step: accept it once the step is short
                turn_ok = tn @ t >= cos_max or (ds <= corner_ds and tn @ t > 0.0)
                ok = turn_ok and (reject is None or not reject(y, res.y))
            except NewtonError:
                pass
            if ok:
                break
            n_rej += 1
            ds *= 0.5
            if ds < ds_min:
                corner = _corner_step(fun, y, t, watch, param, corner_ds, tol, max_iter, reject)
                if corner is None:
                    status = "min_step"
                else:
                    res, tn = corner
                    corners.append(len(ys))
                    ds = corner_ds
                break
        if status == "min_step":
            break
        for c in watch:
            if t[c] * tn[c] < 0.0:
                folds.append((len(ys), c))
        y, t = res.y, tn
        ys.append(y)
        ts.append(t)
        dss.append(ds)
        its.append(res.n_iter)
        if callback:
            data.append(callback(y))
        if progress is not None:
            progress(y)
        if stop is not None and stop(y):
            status = "stop"
            break
        if res.n_iter <= good_iter:
            ds = min(ds * growth, ds_max)
    return Branch(
        np.array(ys),
        np.array(ts),
        np.array(dss),
        np.array(its),
        folds,
        status,
        n_rej,
        time.perf_counter() - t_wall,
        data,
        corners,
    )


def _corner_step(fun, y, t, coords, param, h, tol, max_iter, reject):
    """Leave a corner the tangent cannot turn: fix one coordinate at y_c +- h and correct.

    Past a corner sharper than 90 degrees (HB with H > 1 at grazing: the discretised
    branch folds back in amplitude while the frequency rises) the hyperplane normal to
    the old tangent misses the new branch and Newton cycles between contact sets. A step
    in one of the monitored coordinates (the frequency, say) meets it. Returns
    (NewtonResult, tangent) or None.
    """
    p1 = y.size
    for c in coords:
        if c == param:
            continue
        for sgn in (1.0, -1.0):
            for hh in (h, 0.1 * h, 0.01 * h):
                target = y[c] + sgn * hh

                def fixed(z, c=c, target=target):
                    R, J = fun(z)
                    e = np.zeros(p1)
                    e[c] = 1.0
                    return np.concatenate([R, [z[c] - target]]), np.vstack([J, e])

                # the last point may sit where the new branch has no foothold (e.g. no
                # contact yet, so R does not depend on the amplitude): nudge the start
                # parameter along its tangent sign as well
                for nudge in (0.0, hh, 10.0 * hh):
                    guess = y.copy()
                    guess[c] = target
                    guess[param] += nudge * (1.0 if t[param] >= 0 else -1.0)
                    try:
                        res = newton(fixed, guess, tol=tol, max_iter=3 * max_iter)
                    except NewtonError:
                        continue
                    d = res.y - y
                    if np.linalg.norm(d) < 0.5 * hh or (reject is not None and reject(y, res.y)):
                        continue
                    tn = tangent(res.jacobian[:-1], d / np.linalg.norm(d))
                    if tn @ t < -0.5:  # back along the branch we came from
                        continue
                    return res, tn
    return None


__all__ = ["Branch", "ContinuationError", "continue_branch", "tangent"]
