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

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced.periodic.hb import GuardRefusal, NewtonError, newton


class ContinuationError(RuntimeError):
    """The start point could not be found."""


@dataclass(eq=False)
class Branch:
    """Points of a continued branch and diagnostics.

    Attributes
    ----------
    y : (n_points, p+1) ndarray of float
        The points, in the scaled unknowns of the residual.
    tangent : (n_points, p+1) ndarray of float
        Unit tangent at each point.
    ds : (n_points,) ndarray of float
        Step that reached each point (0 for the start).
    n_iter : (n_points,) ndarray of int
        Newton iterations per point.
    folds : list of (int, int)
        (point index, coordinate index) where a watched coordinate turned back.
    status : {'stop', 'max_steps', 'min_step'}
        Why the run ended.
    n_rejected : int
        Steps rejected (and halved).
    wall_s : float
        s, wall time.
    data : list
        ``callback(y)`` of each point.
    corners : list of int
        Indices of the points reached by a corner step.
    """

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
    """Unit null vector of J (p, p+1), oriented along t_prev.

    Parameters
    ----------
    J : (p, p+1) the Jacobian dR/dy at a point
    t_prev : (p+1,) the previous tangent (None: the right singular vector of the smallest
        singular value, its sign as the SVD gives it)

    Returns
    -------
    ndarray
        (p+1,) unit vector t with J t = 0 and t . t_prev >= 0.
    """
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


def _corrector_tangent(Jb: np.ndarray, t_prev: np.ndarray, solve=None) -> np.ndarray:
    """``tangent(Jb[:-1], t_prev)`` for a corrector's Jacobian ``Jb`` = [dR/dy; t_prev]: the matrix that
    :func:`tangent` would stack is ``Jb`` itself, so it is solved as it stands (the same numbers, one copy
    of an HB Jacobian fewer each step); by ``solve(Jb, b)`` if given (the residual's own solver)."""
    if not np.array_equal(Jb[-1], t_prev):
        return tangent(Jb[:-1], t_prev)
    b = np.zeros(Jb.shape[1])
    b[-1] = 1.0
    try:
        t = np.linalg.solve(Jb, b) if solve is None else solve(Jb, b)
        if not np.all(np.isfinite(t)):
            raise np.linalg.LinAlgError("singular")
    except np.linalg.LinAlgError:
        t = np.linalg.svd(Jb[:-1])[2][-1]
    t = t / np.linalg.norm(t)
    if t @ t_prev < 0.0:
        t = -t
    return t


@dataclass(frozen=True, slots=True)
class ContinuationOptions:
    """Step control of a pseudo-arclength continuation (module docstring), in the scaled unknowns.

    The one set of continuation options: :func:`continue_branch` takes it, and so do the curves
    continued on top of it (:func:`reduced.periodic.backbones.nnm_branch`,
    :func:`reduced.periodic.frc.frc`), each with its own defaults as an instance varied by
    :meth:`replace`. Checked on construction (one-line
    :class:`reduced._checks.InvalidArgument` naming the field).

    Parameters
    ----------
    ds : float
        First step, > 0.
    ds_min : float
        A step halved below this tries a corner step, then the run ends ("min_step").
    ds_max : float
        Largest step.
    max_steps : int
        Most points.
    max_iter : int
        Newton iterations of a corrector; a step needing more is halved.
    good_iter : int
        A corrector converged in at most this many iterations grows the step.
    growth : float
        By this factor, up to ``ds_max``.
    max_angle_deg : float
        deg, largest turn of the tangent over one step (above ``corner_ds``).
    corner_ds : float
        At or below this step a larger turn is a corner of the branch: accepted.
    tol : float
        Newton tolerance of the start point and the correctors.
    angle_step : bool
        Step control from the tangent's turn as well (False: by the Newton iterations alone, the rule
        above). A step that turned the tangent by theta (a converged corrector) is followed by
        ``ds * min(growth, 0.8 max_angle / theta)`` (also when it needs a shorter one), and one refused
        because theta > max_angle is retried at ``ds * min(0.5, max(0.1, 0.8 max_angle / theta))``:
        the turn of a smooth stretch grows like its step (theta ~ kappa ds), so the next step aims
        at 0.8 ``max_angle`` instead of being halved until it fits.
    resume_after_guard : bool
        After a step that a guard of the residual shortened (a trial point refused by
        :class:`reduced.periodic.hb.GuardRefusal`, e.g. a grazing crossed in a step longer than the
        guard allows), the next step is the one first refused (at most ``ds_max``), not the short step
        grown by ``growth``: the guard asks for a short step across a point of the path, not for short
        steps after it (False: the rule above).

    Raises
    ------
    InvalidArgument
        A float field that is not a finite number > 0, or an integer field that is not an
        integer >= 1.

    Examples
    --------
    >>> ContinuationOptions(ds=0.02).replace(max_steps=10).max_steps
    10
    >>> ContinuationOptions(ds=0.0)
    Traceback (most recent call last):
    ...
    reduced._checks.InvalidArgument: ds must be a finite number > 0, got 0.0
    """

    ds: float = 0.05  # first step
    ds_min: float = 1e-6  # a step halved below this tries a corner step, then the run ends ("min_step")
    ds_max: float = 0.5  # largest step
    max_steps: int = 2000  # points at most
    max_iter: int = 8  # Newton iterations of a corrector; a step needing more is halved
    good_iter: int = 3  # a corrector converged in at most this many iterations grows the step
    growth: float = 1.5  # by this factor, up to ds_max
    max_angle_deg: float = 15.0  # deg, largest turn of the tangent over one step (above corner_ds)
    corner_ds: float = 1e-3  # at or below this step a larger turn is a corner of the branch: accepted
    tol: float = 1e-10  # Newton tolerance of the start point and the correctors
    angle_step: bool = False  # the step also from the tangent's turn (ds * 0.8 max_angle / theta)
    resume_after_guard: bool = False  # after a step a guard shortened, the step it refused (not the short one grown)

    def __post_init__(self) -> None:
        for key in ("ds", "ds_min", "ds_max", "growth", "max_angle_deg", "corner_ds", "tol"):
            _check.positive(key, getattr(self, key))
        for key in ("max_steps", "max_iter", "good_iter"):
            _check.integer(key, getattr(self, key))
        _check.flag("angle_step", self.angle_step)
        _check.flag("resume_after_guard", self.resume_after_guard)

    def replace(self, **changes) -> ContinuationOptions:
        """These options with the fields ``changes`` replaced (checked again); ``self`` if none."""
        return dataclasses.replace(self, **changes) if changes else self


STEP_FIELDS = tuple(f.name for f in dataclasses.fields(ContinuationOptions))  # the keywords that vary them


def continue_branch(
    fun,
    y0: np.ndarray,
    *,
    param: int,
    direction: float = 1.0,
    options: ContinuationOptions | None = None,
    stop=None,
    monitor: tuple[int, ...] = (),
    callback=None,
    reject=None,
    progress=None,
    corner_coords=None,
    **steps,
) -> Branch:
    """Continue the solution curve of ``fun`` from ``y0`` (see the module docstring).

    Parameters
    ----------
    fun : y (p+1,) -> (R (p,), dR/dy (p, p+1)); with a ``lazy`` method, y -> (R, a callable giving dR/dy),
        the correctors ask for dR/dy only at the points Newton takes (the same numbers); with a
        ``bordered_solver`` (None, or a callable (J, r) -> J^-1 r), the correctors and tangents solve
        [dR/dy; t] z = r by it
    y0 : initial guess; corrected with coordinate ``param`` held fixed
    param : the coordinate that starts the branch (its tangent component has the sign
        of ``direction`` at the start) and whose folds are always reported
    direction : +1 or -1 (only its sign is used): the sense the branch leaves y0 in ``param``
    options : the step control (default :class:`ContinuationOptions`)
    stop : y -> bool, ends the run after the first point where it is true
    monitor : further coordinates whose folds are reported
    callback : y -> object stored in ``Branch.data`` for each point
    reject : (y_old, y_new) -> bool; a true answer rejects the step (halved), e.g. a
        jump in a physical quantity that the tangent angle does not see; a ``reject`` with a true attribute
        ``takes_tangent`` is called as reject(y_old, y_new, t_new) after a corrector, t_new the unit tangent
        at y_new oriented along the last one (so it need not solve for it again), and as before after a
        corner step
    progress : callable(y) after every accepted point
    corner_coords : None, or (y, t) -> coordinates a corner step may fix, in the order tried
        (default: the monitored ones). On a curve with corners where it also turns back in
        ``param`` (a grazing contact at a fold of a forced response), the coordinates of the
        largest tangent components are the ones that still move past the corner.
    **steps : fields of :class:`ContinuationOptions` replacing those of ``options``
        (``ds=0.1, max_steps=200``)

    Returns
    -------
    Branch
        The points reached, their tangents and steps, the folds of the watched coordinates,
        and why the run ended (``status``). Raises :class:`ContinuationError` if the start
        point is not found.
    """
    opt = (options or ContinuationOptions()).replace(**steps)
    t_wall = time.perf_counter()
    y, t, n_iter = _start_point(fun, y0, param, direction, opt.tol)
    ys, ts, dss, its = [y], [t], [0.0], [n_iter]
    data = [callback(y)] if callback else []
    folds: list = []
    corners: list = []
    watch = tuple(dict.fromkeys((param, *monitor)))
    n_rej = 0
    status = "max_steps"
    max_steps = opt.max_steps
    if stop is not None and stop(y):
        status = "stop"
        max_steps = 0
    ds = opt.ds
    for _ in range(max_steps):
        res, tn, ds, rejected, corner, ds_guard = _advance(
            fun, y, t, ds, opt, reject, watch if corner_coords is None else tuple(corner_coords(y, t)), param)
        n_rej += rejected
        if res is None:
            status = "min_step"
            break
        if corner:
            corners.append(len(ys))
        for c in watch:
            if t[c] * tn[c] < 0.0:
                folds.append((len(ys), c))
        y, t, t_old = res.y, tn, t
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
        if opt.angle_step and not corner:
            ds = min(ds * _angle_factor(float(t_old @ t), opt), opt.ds_max)
            if res.n_iter > opt.good_iter:
                ds = min(ds, dss[-1])
        elif res.n_iter <= opt.good_iter:
            ds = min(ds * opt.growth, opt.ds_max)
        if opt.resume_after_guard and ds_guard is not None and not corner:
            ds = min(max(ds, ds_guard), opt.ds_max)
    return Branch(np.array(ys), np.array(ts), np.array(dss), np.array(its), folds, status, n_rej,
                  time.perf_counter() - t_wall, data, corners)


def _start_point(fun, y0: np.ndarray, param: int, direction: float, tol: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(y, unit tangent, Newton iterations) of the first point: ``y0`` corrected with coordinate
    ``param`` held fixed, the tangent oriented so that its ``param`` component has the sign of
    ``direction``."""
    p1 = y0.size

    def fixed(y):
        R, J = fun(y)
        e = np.zeros(p1)
        e[param] = 1.0
        return np.concatenate([R, [y[param] - y0[param]]]), np.vstack([J, e])

    try:
        start = newton(fixed, y0, tol=tol, max_iter=30)
    except NewtonError as exc:
        raise ContinuationError(f"start point not found: {exc}") from None
    t = tangent(start.jacobian[:-1])  # dR/dy at the start (the fixed row dropped)
    if t[param] * direction < 0.0:
        t = -t
    return start.y, t, start.n_iter


def _angle_factor(cos_turn: float, opt: ContinuationOptions) -> float:
    """Factor of the next step after a step that turned the tangent by arccos(cos_turn): the step whose
    turn would be 0.8 ``max_angle_deg`` on a stretch of constant curvature, at most ``growth``."""
    theta = math.degrees(math.acos(min(max(cos_turn, -1.0), 1.0)))
    return opt.growth if theta <= 0.0 else min(opt.growth, 0.8 * opt.max_angle_deg / theta)


def _max_jump(h: float, corner_ds: float) -> float:
    """Largest Newton step of a corrector after a step h: past a square-root corner the branch
    lies ~sqrt(h corner_ds) from the predictor."""
    return 4.0 * max(h, math.sqrt(h * corner_ds))


def _advance(fun, y: np.ndarray, t: np.ndarray, ds: float, opt: ContinuationOptions, reject, watch: tuple,
             param: int):
    """One accepted step from the point y with tangent t, trying ``ds`` first and halving it.

    Returns (NewtonResult, new tangent, the step that reached it, steps rejected, whether a
    corner step reached it, the first step a guard refused or None); the result and tangent are None
    when the step fell below ``ds_min`` and no corner step was found.
    """
    cos_max = math.cos(math.radians(opt.max_angle_deg))
    n_rej = 0
    ds_guard = None  # the first step a guard of the residual refused (GuardRefusal)
    lazy = getattr(fun, "lazy", None)  # fun.lazy(y) -> (R, callable giving dR/dy): the Jacobian only when taken
    solve = getattr(fun, "bordered_solver", None)  # fun.bordered_solver(J, r): its own solver of [dR/dy; t] z = r
    while True:
        yp = y + ds * t

        def corrector(z, yp=yp, t=t):
            if lazy is not None:
                R, Jz = lazy(z)
                if getattr(Jz, "stacks_below", False):  # Jz(below=t): the same matrix, made with its last row
                    return np.concatenate([R, [t @ (z - yp)]]), lambda: Jz(below=t)
                return np.concatenate([R, [t @ (z - yp)]]), lambda: np.vstack([Jz(), t])
            R, Jz = fun(z)
            return np.concatenate([R, [t @ (z - yp)]]), np.vstack([Jz, t])

        try:
            res = newton(corrector, yp, tol=opt.tol, max_iter=opt.max_iter, max_step=_max_jump(ds, opt.corner_ds),
                         solve=solve)
            tn = _corrector_tangent(res.jacobian, t, solve)  # newton's Jacobian is at res.y: [dR/dy; t]
            # a corner (the square-root onset of contact at grazing) turns the tangent by
            # up to 90 degrees however short the step: accept it once the step is short
            turn_ok = tn @ t >= cos_max or (ds <= opt.corner_ds and tn @ t > 0.0)
            if turn_ok and (reject is None or not (reject(y, res.y, tn) if getattr(reject, "takes_tangent", False)
                                                   else reject(y, res.y))):
                return res, tn, ds, n_rej, False, ds_guard
            # a turn beyond max_angle (angle_step): aim at 0.8 max_angle, not merely half the step
            cut = 0.5 if turn_ok or not opt.angle_step else min(0.5, max(0.1, _angle_factor(float(tn @ t), opt)))
        except GuardRefusal:
            cut = 0.5
            if ds_guard is None:
                ds_guard = ds
        except NewtonError:
            cut = 0.5
        n_rej += 1
        ds *= cut
        if ds < opt.ds_min:
            corner = _corner_step(fun, y, t, watch, param, opt.corner_ds, opt.tol, opt.max_iter, reject)
            if corner is None:
                return None, None, ds, n_rej, False, ds_guard
            return corner[0], corner[1], opt.corner_ds, n_rej, True, ds_guard


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


__all__ = ["Branch", "ContinuationError", "ContinuationOptions", "STEP_FIELDS", "continue_branch", "tangent"]
