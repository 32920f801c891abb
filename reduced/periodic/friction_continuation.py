"""Forced periodic orbits with friction continued in frequency by shooting on the exact friction flow.

The multiple-shooting equations of :mod:`reduced.periodic.friction_shooting` (S nodes y_k = [x; v; w] at
t_k = k T / S, Newton's unknowns z = [x; v; d], d = Bt x - w the sliders' stretches, residual in units of D)
with the load's frequency f (Hz) as one more unknown, u = [z / D; f]:

    G(u) = R(Y(z), f) = 0   ((2n + p) S equations),
    t_i . (u - u_i) - ds = 0   (pseudo-arclength, t_i the unit tangent at the last point u_i).

**Predictor / corrector.** Predictor u_i + ds t_i + ds^2 / 2 (t_i - t_{i-1}) / |u_i - u_{i-1}| (the curvature
from the last two tangents: its error ~ ds^3; measured on discrete-friction-frc, max |G| at the predictor 2e-4 ..
5e-4 where the tangent alone gave 4e-3 .. 5e-3 at the same step), and u_i + ds t_i where that corrector fails (the
curvature misleads across a non-smooth transition) or at the first step; corrector Newton on
[G; t_i . (u - u_i) - ds] with the bordered Jacobian [[dG/dz, dG/df]; t_i^T], first as a chord (the Jacobian of the
last point) with Broyden's update at every step, a fresh Jacobian at the iterate where a step raises max |G| and
the corrector given up where one raises it again, or where the predictor's max |G| exceeds ``PREDICTOR_MAX`` (a
step too long: halving it costs less than a corrector that fails after ``MAX_CORRECTOR`` steps); each step the
minimum-norm least-squares solution (a slider open or stuck the whole period leaves a null direction of dG/dz, as
in the shooting at one frequency: rank < size). The tangent at a converged point solves
[[dG/du]; t_i^T] t = [0; 1] (least squares), normalised and oriented along t_i, so it passes folds where
df/ds = 0. ds grows by ``DS_GROW`` after a corrector of at most ``EASY_STEPS`` steps, shrinks by ``DS_SHRINK``
after one of at least ``HARD_STEPS`` and is halved after one that fails (down to ``ds_min``: the branch ends
there). Measured on discrete-friction-frc's four starts, 20 points each way (load 5-7, 2 cores): 12.5 s of CPU
where the chord corrector with Broyden's update only on slow steps and the tangent predictor took 22.0 s, over
the same branches (0.08 against 0.15 s a point).

**Where a branch ends**, each with its reason in ``status``: it leaves the band; the corrector fails down to
``ds_min``; a new point lies within ``RETRACE_STEP`` ds of an earlier point of its own (past a fold the path has
turned back onto orbits it passed); with ``leave_contact``, its orbit no longer touches a stop; the caller's
``stop`` says so (e.g. it meets a branch continued before,
:func:`on_branch`); or ``max_steps`` points.

**Jacobian, monodromy and the non-smooth transitions.** dG/dz is the segments' monodromies, exact
(:mod:`reduced.periodic.friction_sensitivity`: within a friction state the flow is affine, so over a piece the
sensitivity is the state's matrix exponential; at each event of the integrator's log (gap open / close,
stick -> slip, slip -> stick) the saltation matrix; no differences), dG/df by a forward difference of ``FD_FREQ``
f. (``JACOBIAN = "fd"`` restores the forward differences on the integrator, step ``FD_STEP`` D,
:meth:`_Residual.blocks`.) The Floquet multipliers at each point are the eigenvalues of the product of the same
blocks at the converged point (Phi = Phi_{S-1} ... Phi_0, in [x; v; w]): the **saltation** of every stick-slip,
slip-stick, closing and opening event is in it. At a grazing contact or a node on a slip reversal the map has a
kink: the exact product is the derivative of the side the integrator's event log takes; the HB-curve stage marks
such points by their neighbours' verdicts.

**Bifurcations** between two consecutive points, from the multipliers counted outside the unit circle
(|mu| > 1 + STABLE_TOL; a free slider's multiplier 1 is on it): a real one through +1 with a sign change of
df/ds is a ``fold``, without it a ``branch_point``; a real one through -1 a ``period_doubling``; a complex pair
a ``neimark_sacker``; two real ones meeting outside the circle and becoming a pair (or the reverse) nothing;
where a slider's tip opens or closes for the whole period between the two points (the rank of dG/dz changes) a
``grazing``, a non-smooth transition where the multipliers jump. Branch switching at folds, branch points and
period doublings (onto the family of period 2T, shot over two forcing periods and continued with its multipliers over
2T: ``periods`` = 2 of the start, :func:`switch_branch`). (A branch point where no multiplier crosses, e.g. a
symmetric pitchfork of a stable orbit, is not detected: the bordered determinant is zero along free-slider directions
and cannot be used.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.periodic.friction_sensitivity import LOG_EVENTS, FlowSensitivity, segment_blocks
from reduced.periodic.friction_shooting import (
    FD_STEP,
    RANK_RTOL,
    STABLE_TOL,
    FrictionShootingResult,
    _Residual,
    monodromy_of,
)
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.friction import FrictionFlow

JACOBIAN = "exact"  # dG/dz: "exact" (state transition and saltation matrices) or "fd" (forward differences)
FD_FREQ = 1e-7  # x f: the forward-difference step of dG/df (as FD_STEP in z: truncation ~1e-7 of the column)
TOL = 1e-10  # max |G| in units of D at a continued point (the integrator is exact to ~1e-13; a chord step
# converges linearly, 1e-10 keeps the amplitudes far below the 1e-4 the HB comparison reads)
MAX_CORRECTOR = 12  # corrector steps at most (chord and refreshed together)
EASY_STEPS = 4  # a corrector of at most this many steps grows ds
DS_GROW = 1.5  # the factor
HARD_STEPS = 8  # a corrector of at least this many steps shrinks ds (measured on discrete-friction-frc: a
# predictor error ~ h^3 aimed at 2e-3 grew ds, covered 10 % more Hz a branch for 30 % more CPU)
DS_SHRINK = 0.7  # the factor
PREDICTOR_CURVATURE = True  # predictor u + h t + h^2 / 2 (t - t_prev) / |u - u_prev| (error O(h^3)), else u + h t
PREDICTOR_MAX = 0.05  # max |G| at the predictor (units of D) above which the step is halved without correcting
RETRACE_SKIP = 3  # the last points a new one is not compared with for a retrace (its own neighbours)
RETRACE_STEP = 0.5  # x ds: a new point this near (in u) an earlier one of its own branch has turned back onto it
REAL_TOL = 1e-8  # |Im mu| <= this x |mu|: a real multiplier
SAMPLES_PER_SEGMENT = 50  # of each segment when the amplitudes are read (400 a period at S = 8: error ~3e-5)


@dataclass(eq=False)
class FrictionShootingBranch:
    """Periodic orbits with friction continued in frequency (:func:`continue_friction`).

    Attributes
    ----------
    freq_hz : (k,) Hz
    nodes : (k, S, 2n + p) the states [x; v; w] at t_j = j T / S of each orbit
    amplitude_m : (k, q) m, max |x| over the period at each output point (rows ``point_rows``)
    multipliers : (k, 2n + p) complex Floquet multipliers (forward-difference monodromy)
    stable : (k,) bool, max |mu| <= 1 + STABLE_TOL
    defect : (k,) max |G| at each point, in units of D
    rank : (k,) numerical rank of dG/dz (size - rank free slider directions)
    tangent_f : (k,) the tangent's frequency component (its sign changes at a fold)
    bifurcations : [(i, kind)]: between points i - 1 and i (module docstring)
    n_corrector : (k,) corrector steps of each point (0 for the start)
    status : why the branch ended
    wall_s : s
    periods : the orbits' period in forcing periods (2: a period-doubled family, :func:`switch_branch`)
    """

    freq_hz: np.ndarray
    nodes: np.ndarray
    amplitude_m: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    defect: np.ndarray
    rank: np.ndarray
    tangent_f: np.ndarray
    bifurcations: list = field(default_factory=list)
    n_corrector: np.ndarray | None = None
    status: str = ""
    wall_s: float = 0.0
    periods: int = 1

    @property
    def max_abs_multiplier(self) -> np.ndarray:
        """(k,) the largest |mu| at each point."""
        return np.max(np.abs(self.multipliers), axis=1)


class _Continuation:
    """G(u), its Jacobian and the monodromy at fixed D, S and load (module docstring)."""

    def __init__(self, system, b, P, phase_deg, S, D, periods: int = 1):
        self.system, self.b, self.P, self.phase, self.S, self.D = system, b, P, phase_deg, S, D
        self.periods = periods  # the orbits' period in forcing periods
        self.N = D.size
        self.flows = FrictionFlow(system, b, P)  # the lean flow, set up once for the branch (the same bits)
        self.logged = FrictionFlow(system, b, P, log_events=LOG_EVENTS)  # with the event log, for the sensitivity

    def res(self, f: float) -> _Residual:
        return _Residual(self.system, self.b, self.P, f, self.phase, self.S, self.D, self.flows, self.periods)

    def G(self, u: np.ndarray) -> tuple[np.ndarray, _Residual, np.ndarray, np.ndarray]:
        """(G, residual object, Y, ends) at u = [z / D; f]."""
        res = self.res(float(u[-1]))
        Y = res.y_of(u[:-1].reshape(self.S, self.N) * self.D)
        ends = res.ends(Y)
        return res.residual(Y, ends), res, Y, ends

    def blocks(self, f: float, Y: np.ndarray) -> np.ndarray:
        """(S, N, N) the segments' monodromies in z, units of D, exact (:mod:`reduced.periodic.friction_sensitivity`:
        state transition matrices and saltation matrices along the integrator's events)."""
        return segment_blocks(self.system, self.b, self.P, f, self.phase, Y, self.D, self.periods, self.logged)

    def jacobian(self, u: np.ndarray, G: np.ndarray, res: _Residual, Y: np.ndarray,
                 ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((S N, S N + 1) dG/du, (S, N, N) the blocks in units of D): dG/dz exact (``JACOBIAN`` = "exact") or by
        forward differences ("fd"), dG/df by a forward difference."""
        blocks = self.blocks(float(u[-1]), Y) if JACOBIAN == "exact" else res.blocks(Y, ends, FD_STEP)
        df = FD_FREQ * float(u[-1])
        up = u.copy()
        up[-1] += df
        Gf = self.G(up)[0]
        return np.hstack([res.jacobian(blocks), ((Gf - G) / df)[:, None]]), blocks

    def monodromy(self, res: _Residual, blocks: np.ndarray) -> np.ndarray:
        """(N, N) dy(T)/dy(0) in [x; v; w] from the blocks (as :meth:`_Residual.monodromy`)."""
        return monodromy_of(blocks, self.D, res.Bt)


def _rank(J: np.ndarray) -> int:
    """The numerical rank of dG/dz (J's first N S columns), relative to its largest singular value."""
    return int(np.linalg.matrix_rank(J[:, :-1], tol=RANK_RTOL * np.linalg.norm(J[:, :-1], 2)))


def _tangent(J: np.ndarray, t_prev: np.ndarray) -> np.ndarray:
    """The unit tangent: [J; t_prev^T] t = [0; 1] by least squares, oriented along t_prev."""
    A = np.vstack([J, t_prev[None, :]])
    rhs = np.zeros(A.shape[0])
    rhs[-1] = 1.0
    t = np.linalg.lstsq(A, rhs, rcond=RANK_RTOL)[0]
    t /= np.linalg.norm(t)
    return t if float(t @ t_prev) >= 0.0 else -t


def _counts(mu: np.ndarray) -> tuple[int, int, int]:
    """(real > 1, real < -1, complex) multipliers outside the unit circle."""
    out = np.abs(mu) > 1.0 + STABLE_TOL
    real = np.abs(mu.imag) <= REAL_TOL * np.abs(mu)
    return (int(np.sum(out & real & (mu.real > 0))), int(np.sum(out & real & (mu.real < 0))),
            int(np.sum(out & ~real)))


def bifurcations(multipliers: np.ndarray, tangent_f: np.ndarray,
                 rank: np.ndarray | None = None) -> list[tuple[int, str]]:
    """[(i, kind)]: the changes of the counts of multipliers outside the unit circle between points i - 1 and i
    (module docstring: fold, branch_point, period_doubling, neimark_sacker); where the rank of dG/dz changes
    between the two points (a slider's tip opens or closes for the whole period) the change is a ``grazing``
    (a non-smooth transition: the multipliers jump, they do not cross). Where two real multipliers outside the
    circle meet and leave the real axis as a complex pair outside it (or the reverse), no multiplier crosses the
    circle and nothing is reported (measured on discrete-friction-frc: the "branch points" at 20.42 and 20.72 Hz
    were such collisions, a real 4.9 and a pair -3.0 +- 1.2j beside 20.72 Hz, every multiplier beyond 3 in modulus).

    Parameters
    ----------
    multipliers : (k, N) complex
    tangent_f : (k,) the tangents' frequency components
    rank : (k,) the rank of dG/dz at each point (None: not used)

    Returns
    -------
    list of (int, str)

    Examples
    --------
    >>> mu = np.array([[0.5, 0.2], [1.5, 0.2], [1.5, -1.2]], complex)
    >>> bifurcations(mu, np.array([1.0, -1.0, -1.0]))
    [(1, 'fold'), (2, 'period_doubling')]
    >>> bifurcations(np.array([[2.0, 3.0], [2.5 + 1j, 2.5 - 1j]]), np.array([1.0, 1.0]))   # a collision outside
    []
    """
    out = []
    c = [_counts(m) for m in np.asarray(multipliers)]
    for i in range(1, len(c)):
        if rank is not None and rank[i] != rank[i - 1]:
            if c[i] != c[i - 1]:
                out.append((i, "grazing"))
            continue
        dp, dm, dc = (c[i][j] - c[i - 1][j] for j in range(3))
        if abs(dc) == 2 and ((dp == -dc and dm == 0) or (dm == -dc and dp == 0)):
            continue  # two real multipliers outside the circle met and left the axis as a pair (or a pair landed on
            # it and split): the number outside did not change, nothing crossed the circle
        if c[i][0] != c[i - 1][0]:
            out.append((i, "fold" if tangent_f[i] * tangent_f[i - 1] < 0 else "branch_point"))
        if c[i][1] != c[i - 1][1]:
            out.append((i, "period_doubling"))
        if c[i][2] != c[i - 1][2]:
            out.append((i, "neimark_sacker"))
    return out


def _retrace(us: list, u: np.ndarray, h: float) -> str | None:
    """Why the branch ends if its new point u (the last of ``us``) lies within RETRACE_STEP x h of an earlier point
    of its own (not one of its last RETRACE_SKIP): past a fold the path has turned back onto orbits it passed."""
    for j in range(len(us) - 1 - RETRACE_SKIP):
        if float(np.linalg.norm(us[j] - u)) <= RETRACE_STEP * h:
            return (f"turned back onto its own orbit at f = {u[-1]:.6g} Hz (point {j}, within {RETRACE_STEP:g} "
                    "of a step)")
    return None


def on_branch(freq_hz: np.ndarray, amplitude_m: np.ndarray, f: float, a: np.ndarray, rel: float) -> bool:
    """Whether the orbit of amplitudes a (q,) m at f Hz lies on the branch (freq_hz (k,), amplitude_m (k, q)): between
    two consecutive points of it, within ``rel`` of the amplitudes interpolated linearly in frequency.

    Parameters
    ----------
    freq_hz : (k,) Hz, the branch's points
    amplitude_m : (k, q) m, their amplitudes
    f : Hz, the orbit's frequency
    a : (q,) m, its amplitudes
    rel : the largest max |a / interpolated - 1| that counts as on the branch

    Returns
    -------
    bool

    Examples
    --------
    >>> on_branch(np.array([1.0, 2.0]), np.array([[1.0], [2.0]]), 1.5, np.array([1.51]), 0.02)
    True
    >>> on_branch(np.array([1.0, 2.0]), np.array([[1.0], [2.0]]), 2.5, np.array([2.5]), 0.02)
    False
    """
    F, A = freq_hz, amplitude_m
    for i in range(len(F) - 1):
        lo, hi = sorted((F[i], F[i + 1]))
        if lo <= f <= hi:
            w = (f - F[i]) / (F[i + 1] - F[i]) if F[i + 1] != F[i] else 0.0
            ref = (1.0 - w) * A[i] + w * A[i + 1]
            if float(np.max(np.abs(a / ref - 1.0))) <= rel:
                return True
    return False


def _correct(cont: _Continuation, J: np.ndarray, t: np.ndarray, u: np.ndarray, h: float, tol: float,
             v0: np.ndarray | None = None) -> tuple:
    """(converged, corrector steps, v, G, residual object, Y, ends, max |G| at the predictor): the corrector from the
    predictor v0 (default u + h t) on [G; t . (v - u) - h] = 0, chord with J and Broyden's update at every step, a
    fresh Jacobian where a step raises max |G| (module docstring); not converged if the integrator fails, if the
    predictor's max |G| exceeds ``PREDICTOR_MAX`` or if a step raises it again after a fresh Jacobian (a step too
    long: halving it is cheaper than more corrector steps)."""
    k_corr, v, r0 = 0, (u + h * t) if v0 is None else v0, math.inf
    try:
        Jc, fresh = J, False
        Gv, res_v, Yv, ends_v = cont.G(v)
        r = r0 = float(np.max(np.abs(Gv)))
        if r0 > PREDICTOR_MAX:
            return False, k_corr, v, None, None, None, None, r0
        for k_corr in range(1, MAX_CORRECTOR + 1):  # noqa: B007 (the count is returned)
            A = np.vstack([Jc, t[None, :]])
            rhs = -np.concatenate([Gv, [t @ (v - u) - h]])
            du = np.linalg.lstsq(A, rhs, rcond=RANK_RTOL)[0]
            v = v + du
            r_old, G_old = r, Gv
            Gv, res_v, Yv, ends_v = cont.G(v)
            r = float(np.max(np.abs(Gv)))
            if r <= tol:
                return True, k_corr, v, Gv, res_v, Yv, ends_v, r0
            if r > r_old:  # a fresh Jacobian at the iterate, once: a second rise ends the corrector
                if fresh:
                    break
                Jc, fresh = cont.jacobian(v, Gv, res_v, Yv, ends_v)[0], True
            else:  # Broyden's (good) update: superlinear where the chord alone converges linearly
                Jc = Jc + np.outer(Gv - G_old - Jc @ du, du) / float(du @ du)
    except (ExactIntegratorError, np.linalg.LinAlgError, ValueError):
        pass
    return False, k_corr, v, None, None, None, None, r0


def continue_friction(start: FrictionShootingResult, freq_min_hz: float, freq_max_hz: float, *,
                      direction: float = 1.0, ds: float = 0.05, ds_min: float = 1e-4, ds_max: float = 0.5,
                      max_steps: int = 40, point_rows: np.ndarray | None = None,
                      tol: float = TOL, stop=None, leave_contact: bool = False) -> FrictionShootingBranch:
    """Continue a converged friction orbit in frequency by pseudo-arclength on the shooting equations.

    Long because the predictor-corrector loop and its ends (module docstring) share the state of the branch.

    Unknowns u = [z / D; f] (z = [x; v; Bt x - w] at the S nodes, D the start's scale, f in Hz); equations
    R_k = (phi(y_k; t_k, T / S) - y_{k+1}) / D = 0 (:mod:`reduced.periodic.friction_shooting`) and
    t_i . (u - u_i) = ds; the Floquet multipliers of every point from the forward-difference monodromy; the
    bifurcations from their crossings (module docstring).

    Parameters
    ----------
    start : FrictionShootingResult
        A converged orbit (:func:`reduced.periodic.friction_shooting.shoot_friction`): its system, load, nodes.
    freq_min_hz, freq_max_hz : Hz, the branch ends when it leaves this band
    direction : the sign of df/ds at the start
    ds : the first arclength step (z / D and Hz together)
    ds_min, ds_max : its bounds
    max_steps : points after the start at most
    point_rows : (q, n) the output points' rows (default: the identity, every DOF)
    tol : max |G| at a point, units of D
    stop : callable, optional
        ``stop(f_hz, amplitude_m) -> str or None`` after each new point: a str ends the branch there (its status),
        e.g. where it meets another branch. (A point back on the branch's own path ends it too: module docstring.)
    leave_contact : end the branch, started in contact, at its first orbit on which no stop closes (sampled
        SAMPLES_PER_SEGMENT a segment): the open-gap orbit is linear, HB gives it exactly

    Returns
    -------
    FrictionShootingBranch

    Raises
    ------
    reduced._checks.InvalidArgument
        ``start`` not converged.
    """
    if not start.converged:
        raise _check.InvalidArgument("start must be a converged orbit (shoot_friction(...).converged)")
    f0 = _check.positive("freq_min_hz", freq_min_hz, "Hz")
    f1 = _check.positive("freq_max_hz", freq_max_hz, "Hz")
    max_steps = _check.integer("max_steps", max_steps, lo=0)
    system: GapSystem = start.system
    n = system.n
    rows = np.eye(n) if point_rows is None else np.asarray(point_rows, float)
    S, N = start.nodes.shape
    D = start.scale
    cont = _Continuation(system, start.b, start.amplitude_N, start.phase_deg, S, D, start.periods)
    t_clock = time.perf_counter()

    touching = []  # whether a stop closes somewhere on each point's orbit (sampled as the amplitudes)

    def amplitudes(Y: np.ndarray, f: float) -> np.ndarray:
        h = start.periods / f / S
        xs = np.vstack([cont.flows(f, Y[k], k * h, h, SAMPLES_PER_SEGMENT, start.phase_deg)[:, :n]
                        for k in range(S)])
        touching.append(bool(system.m) and bool(np.any(system.side * (xs @ system.B.T - system.offset) > 0.0)))
        return np.max(np.abs(xs @ rows.T), axis=0)

    res0 = cont.res(start.freq_hz)
    u = np.concatenate([(res0.z_of(start.nodes) / D).ravel(), [start.freq_hz]])
    G, res, Y, ends = cont.G(u)
    J, blocks = cont.jacobian(u, G, res, Y, ends)
    e = np.zeros(u.size)
    e[-1] = 1.0 if direction >= 0 else -1.0
    rank = _rank(J)
    t = _tangent(J, e)
    pts = []

    def record(u, G, res, Y, rank, blocks, t, k_corr):
        mu = np.linalg.eigvals(cont.monodromy(res, blocks))
        pts.append((float(u[-1]), Y.copy(), amplitudes(Y, float(u[-1])), mu, float(np.max(np.abs(G))), rank,
                    float(t[-1]), k_corr))

    record(u, G, res, Y, rank, blocks, t, 0)
    us = [u]  # the points in u, for the retrace check
    status, h = "", float(ds)
    t_prev, step_prev = None, 0.0  # the last tangent and the distance to the last point: the curvature's estimate
    while len(pts) <= max_steps:
        v0 = None if t_prev is None or not PREDICTOR_CURVATURE else u + h * t + 0.5 * h * h * (t - t_prev) / step_prev
        ok, k_corr, v, Gv, res_v, Yv, ends_v, _ = _correct(cont, J, t, u, h, tol, v0)
        if not ok and v0 is not None:  # across a non-smooth transition the curvature misleads: the tangent alone
            ok, k_corr, v, Gv, res_v, Yv, ends_v, _ = _correct(cont, J, t, u, h, tol)
        if not ok:
            h *= 0.5
            if h < ds_min:
                status = f"ds below {ds_min:g} at f = {u[-1]:.6g} Hz (the corrector does not converge)"
                break
            continue
        J, blocks = cont.jacobian(v, Gv, res_v, Yv, ends_v)
        t_prev, step_prev = t, float(np.linalg.norm(v - u))
        rank = _rank(J)
        t = _tangent(J, t)
        u, G, res, Y = v, Gv, res_v, Yv
        record(u, G, res, Y, rank, blocks, t, k_corr)
        us.append(u)
        if not f0 <= u[-1] <= f1:
            status = f"left the band at f = {u[-1]:.6g} Hz"
            break
        if leave_contact and touching[0] and not touching[-1]:
            status = (f"left the contact at f = {u[-1]:.6g} Hz (every stop open over the period: the open-gap "
                      "orbit, linear)")
            break
        why = _retrace(us, u, h) or (stop(float(u[-1]), pts[-1][2]) if stop is not None else None)
        if why:
            status = why
            break
        if k_corr <= EASY_STEPS:
            h = min(h * DS_GROW, ds_max)
        elif k_corr >= HARD_STEPS:
            h = max(h * DS_SHRINK, ds_min)
    status = status or f"point budget ({max_steps} points) at f = {u[-1]:.6g} Hz"
    f, Ys, A, mu, dfc, rk, tf, kc = (np.array(c) for c in zip(*pts, strict=True))
    stable = np.max(np.abs(mu), axis=1) <= 1.0 + STABLE_TOL
    return FrictionShootingBranch(f, Ys, A, mu, stable, dfc, rk, tf, bifurcations(mu, tf, rk), kc, status,
                                  time.perf_counter() - t_clock, start.periods)


def joined(down: FrictionShootingBranch, up: FrictionShootingBranch) -> FrictionShootingBranch:
    """One branch of two continued from the same start in opposite directions: ``down`` reversed (its start
    dropped, its tangents turned to point along ``up``'s), then ``up``; the bifurcations found again over the
    whole.

    Parameters
    ----------
    down, up : FrictionShootingBranch
        ``down.freq_hz[0] == up.freq_hz[0]`` (the common start).

    Returns
    -------
    FrictionShootingBranch
    """
    if down.freq_hz[0] != up.freq_hz[0]:
        raise _check.InvalidArgument("down and up must start at the same point")

    def cat(a, b):
        return np.concatenate([a[:0:-1], b])

    tf = np.concatenate([-down.tangent_f[:0:-1], up.tangent_f])
    mu, rk = cat(down.multipliers, up.multipliers), cat(down.rank, up.rank)
    return FrictionShootingBranch(cat(down.freq_hz, up.freq_hz), cat(down.nodes, up.nodes),
                                  cat(down.amplitude_m, up.amplitude_m), mu, cat(down.stable, up.stable),
                                  cat(down.defect, up.defect), rk, tf, bifurcations(mu, tf, rk),
                                  cat(down.n_corrector, up.n_corrector),
                                  f"down: {down.status}; up: {up.status}", down.wall_s + up.wall_s, up.periods)


SWITCH_EPS = 1e-2  # the perturbation along the critical eigenvector, in units of D (its largest x or v component):
# large enough that Newton at fixed f does not fall back onto the orbit it starts beside (the new family's orbits
# are O(sqrt(distance to the branch point)) away), small enough to stay in the branch point's basin
SWITCH_EPS_RETRY = 10.0  # x SWITCH_EPS: the second try where both signs return to the orbit they started beside
INSIDE_PENALTY = 1e6  # added to |mu -+ 1| of a multiplier inside the circle: any real one outside comes first
SWITCH_SAME = 1e-6  # max |z - z_0| / D below which the orbit shot from a perturbed start is the one it started from
SWITCH_ON_BRANCH = 1e-3  # its amplitudes within this of the branch's (interpolated) at its frequency: the same branch
SWITCH_JUMP = 1.0  # |mu - (+-1)| of the critical multiplier beside the crossing above which no switch is tried: the
# multiplier jumped across the circle at a non-smooth transition (a stick, slip or gap event appearing on the orbit),
# it did not pass +-1 (measured on discrete-friction-frc: 4.9, 9.7, 14, 42 and 45 beside such crossings, where both
# signs returned to the orbit they started beside, 0.4-0.9 s of CPU each; 1.009-1.8 beside the folds and branch
# points that were tried)


@dataclass(eq=False)
class BranchSwitch:
    """Branch switching at a bifurcation of a continued branch (:func:`switch_branch`).

    Attributes
    ----------
    index : the bifurcation's point on the branch (between points index - 1 and index)
    kind : its kind (:func:`bifurcations`)
    at : the point the switch starts from (index - 1 or index: the critical multiplier nearer +-1)
    freq_hz : Hz, that point's frequency
    multiplier : the critical multiplier there (complex)
    outcome : "new family", "same orbit", "same branch", "no orbit" (Newton did not converge) or "not run: why"
    distance : max |z - z_at| / D of the orbit shot from the perturbed start (either sign), NaN if none converged
    orbit : the new family's orbit (FrictionShootingResult) or None
    branch : the new family continued (FrictionShootingBranch) or None
    """

    index: int
    kind: str
    at: int
    freq_hz: float
    multiplier: complex
    outcome: str
    distance: float = math.nan
    orbit: object = None
    branch: FrictionShootingBranch | None = None


def _critical(cont: _Continuation, Y: np.ndarray, f: float, target: float) -> tuple[float, complex, np.ndarray]:
    """(|mu - target| (+ INSIDE_PENALTY if mu is inside the circle), mu, its eigenvector in [x; v; w]) of the
    critical multiplier of the orbit of nodes Y at f Hz: the real one of the target's sign (+-1) outside the circle
    nearest it (else the one inside nearest it); the free sliders' multipliers 1, whose eigenvectors move w alone,
    left out."""
    n, D, N = cont.system.n, cont.D, cont.N
    Phi = cont.monodromy(cont.res(f), cont.blocks(f, Y))
    mu, V = np.linalg.eig(Phi)
    real = np.abs(mu.imag) <= REAL_TOL * np.abs(mu)
    moves = np.max(np.abs(V[:2 * n]) / D[:2 * n, None], axis=0) > 1e-6 * np.max(np.abs(V) / D[:, None], axis=0)
    ok = real & moves & (np.sign(mu.real) == target)
    if not np.any(ok):
        return math.inf, complex(math.nan), np.zeros(N)
    score = np.abs(mu - target) + INSIDE_PENALTY * (np.abs(mu) <= 1.0 + STABLE_TOL)  # outside first
    k = int(np.argmin(np.where(ok, score, math.inf)))
    return float(score[k]), complex(mu[k]), V[:, k].real


def _shoot_beside(start: FrictionShootingResult, branch: FrictionShootingBranch, at: int, E: np.ndarray,
                  eps: float, rows: np.ndarray) -> tuple[list, list]:
    """([(on the branch, distance, orbit)] of the orbits off the one at point ``at``, [distance of every orbit
    found]): Newton at its frequency from its nodes + sign x size x E D, sign +-1, size eps then
    SWITCH_EPS_RETRY eps while none is off it (:func:`switch_branch`); distances max |z - z_at| / D."""
    from reduced.periodic.friction_shooting import shoot_friction

    system, D, n = start.system, start.scale, start.system.n
    f, Y0 = float(branch.freq_hz[at]), branch.nodes[at]
    res = _Residual(system, start.b, start.amplitude_N, f, start.phase_deg, Y0.shape[0], D, periods=branch.periods)
    z0 = res.z_of(Y0) / D
    found, dist = [], []
    for size in (eps, SWITCH_EPS_RETRY * eps):  # the larger one where the first returns to the same orbit
        for sign in (1.0, -1.0):
            r = shoot_friction(system, start.b, start.amplitude_N, f, Y0 + sign * size * E * D,
                               phase_deg=start.phase_deg, x_ref=float(D[0]), multipliers=False,
                               periods=branch.periods, jacobian="exact")
            if not r.converged:
                continue
            d = float(np.max(np.abs(res.z_of(r.nodes) / D - z0)))
            dist.append(d)
            if d <= SWITCH_SAME:
                continue
            a = np.max(np.abs(r.orbit(SAMPLES_PER_SEGMENT)[1][:, :n] @ rows.T), axis=0)
            found.append((on_branch(branch.freq_hz, branch.amplitude_m, f, a, SWITCH_ON_BRANCH), d, r))
        if found:
            break
    return found, dist


def switch_branch(start: FrictionShootingResult, branch: FrictionShootingBranch, index: int, kind: str, *,
                  eps: float = SWITCH_EPS, continue_kw: dict | None = None,
                  max_jump: float = SWITCH_JUMP) -> BranchSwitch:
    """Switch branches at the bifurcation ``(index, kind)`` of ``branch`` (continued from ``start``) by direct
    shooting from a perturbed orbit, and continue the new family where one is found.

    At the point beside the bifurcation whose critical real multiplier (the one through +1 for a ``branch_point`` or a
    ``fold``, through -1 for a ``period_doubling``; outside the circle, nearest it) is nearer +-1: its monodromy (exact,
    as along the branch), the critical eigenvector e (the free sliders' multipliers 1, whose eigenvectors move w alone,
    left out), propagated to the nodes by the segments' state transition matrices, y_k +- eps D_max e_k (e scaled to its
    largest x or v component in units of D); Newton at the point's frequency on the shooting equations
    (:func:`reduced.periodic.friction_shooting.shoot_friction`) from each sign, again with ``SWITCH_EPS_RETRY`` eps
    where both return to the orbit they started beside. The outcome: ``same orbit`` where both return to the orbit they
    started beside (within ``SWITCH_SAME``), ``same branch`` where an orbit lies on ``branch`` (within
    ``SWITCH_ON_BRANCH`` of its amplitudes: the other side of a fold), ``new family`` otherwise (then continued both
    ways by :func:`continue_friction` with ``continue_kw``), ``no orbit`` where Newton does not converge from either
    sign; ``not run`` where the critical multiplier beside the crossing is more than ``max_jump`` from +-1 (it jumped
    across the circle at a non-smooth transition: no smooth bifurcation whose family a small perturbation finds). At a
    period doubling the new family has period 2T (:func:`_doubled`: Newton over two periods of the orbit from the orbit
    taken twice, perturbed along the eigenvector of the multiplier through -1, which flips sign over one period).

    Parameters
    ----------
    start : FrictionShootingResult, the branch's start (its system, load and scale D)
    branch : FrictionShootingBranch, continued from ``start``
    index, kind : one of ``branch.bifurcations``
    eps : the perturbation, units of D
    continue_kw : keywords of :func:`continue_friction` for the new family (its band, budget, point_rows, stop)
    max_jump : the largest |mu - (+-1)| of the critical multiplier at which the switch is tried

    Returns
    -------
    BranchSwitch
    """
    kw = dict(continue_kw or {})
    band = kw.pop("band", (0.5 * float(np.min(branch.freq_hz)), 2.0 * float(np.max(branch.freq_hz))))
    if kind == "period_doubling":
        target = -1.0
    elif kind in ("branch_point", "fold"):
        target = 1.0
    else:
        return BranchSwitch(index, kind, index, float(branch.freq_hz[index]), complex(math.nan), f"not run: {kind}")
    system = start.system
    n = system.n
    S, N = branch.nodes.shape[1:]
    D = start.scale
    q = branch.periods
    cont = _Continuation(system, start.b, start.amplitude_N, start.phase_deg, S, D, q)

    c0, c1 = (_critical(cont, branch.nodes[j], float(branch.freq_hz[j]), target) for j in (index - 1, index))
    at, (_, mu_c, e) = (index - 1, c0) if c0[0] <= c1[0] else (index, c1)
    f = float(branch.freq_hz[at])
    out = BranchSwitch(index, kind, at, f, mu_c, "")
    if not np.all(np.isfinite(e)) or not np.any(e):
        out.outcome = "not run: no real multiplier of that sign beside the bifurcation"
        return out
    if abs(mu_c - target) > max_jump:
        out.outcome = (f"not run: the critical multiplier beside it is {mu_c.real:.4g} (more than {max_jump:g} from "
                       f"{target:+g}): it jumped across the circle at a non-smooth transition, it did not pass "
                       f"{target:+g}")
        return out
    Y0 = branch.nodes[at]
    sens = FlowSensitivity(system, start.b, start.amplitude_N, f, start.phase_deg, flows=cont.logged)
    h = q / f / S
    m = 2 if target < 0 else 1  # a period doubling: the eigenvector over two periods of the orbit (it flips sign)
    Yr = np.vstack([Y0] * m)
    E = np.empty((m * S, N))
    E[0] = e
    for k in range(1, m * S):
        E[k] = sens.segment(Yr[k - 1], (k - 1) * h, h)[1] @ E[k - 1]
    E /= np.max(np.abs(E[:, :2 * n]) / D[:2 * n])
    rows = kw.get("point_rows")
    if target < 0:
        return _doubled(start, branch, out, Yr, E, eps, kw, band)
    found, dist = _shoot_beside(start, branch, at, E, eps, np.eye(n) if rows is None else np.asarray(rows, float))
    out.distance = max(dist) if dist else math.nan
    new = [(d, r) for on, d, r in found if not on]
    if new:
        out.outcome = "new family"
        out.distance, out.orbit = new[0]
        down = continue_friction(out.orbit, *band, direction=-1.0, **kw)
        up = continue_friction(out.orbit, *band, direction=1.0, **kw)
        out.branch = joined(down, up)
    elif found:
        out.outcome = "same branch"
    elif dist:
        out.outcome = "same orbit"
    else:
        out.outcome = "no orbit"
    return out


def _doubled(start: FrictionShootingResult, branch: FrictionShootingBranch, out: BranchSwitch, Yr: np.ndarray,
             E: np.ndarray, eps: float, kw: dict, band: tuple) -> BranchSwitch:
    """The period-doubled family at a period doubling (:func:`switch_branch`): Newton on the shooting equations over
    two periods of the orbit, 2 q T (``periods`` 2 q, 2 S nodes: the orbit's S nodes twice, ``Yr``), from
    Yr +- size E D (E the critical eigenvector along the 2 S nodes: over one period it is multiplied by the critical
    multiplier ~ -1, so the perturbation has period 2 q T, not q T), size eps then SWITCH_EPS_RETRY eps while both
    signs return to the q T orbit; an orbit whose two halves differ by more than SWITCH_SAME (max |z_k - z_{k+S}| / D)
    is the new family, continued both ways (its multipliers over 2 q T: its stability)."""
    from reduced.periodic.friction_shooting import shoot_friction

    system, D, S = start.system, start.scale, branch.nodes.shape[1]
    q, f = branch.periods, out.freq_hz
    res = _Residual(system, start.b, start.amplitude_N, f, start.phase_deg, 2 * S, D, periods=2 * q)
    z0 = res.z_of(Yr) / D
    dist = []
    for size in (eps, SWITCH_EPS_RETRY * eps):
        for sign in (1.0, -1.0):
            r = shoot_friction(system, start.b, start.amplitude_N, f, Yr + sign * size * E * D,
                               phase_deg=start.phase_deg, x_ref=float(D[0]), multipliers=False, periods=2 * q,
                               jacobian="exact")
            if not r.converged:
                continue
            z = res.z_of(r.nodes) / D
            halves = float(np.max(np.abs(z[:S] - z[S:])))
            dist.append(float(np.max(np.abs(z - z0))))
            if halves > SWITCH_SAME:
                out.outcome, out.distance, out.orbit = "new family", dist[-1], r
                down = continue_friction(r, *band, direction=-1.0, **kw)
                up = continue_friction(r, *band, direction=1.0, **kw)
                out.branch = joined(down, up)
                return out
    out.distance = max(dist) if dist else math.nan
    out.outcome = "same orbit" if dist else "no orbit"
    return out


__all__ = ["FD_FREQ", "BranchSwitch", "FrictionShootingBranch", "bifurcations", "continue_friction", "joined",
           "on_branch", "switch_branch"]
