"""SciPy's DOP853 (``solve_ivp``) on a gap system: the independent baseline.

The first-order state is z = [x, v, W] with W' = v^T C v the dissipated work, so the
energy balance is checked against an independently integrated W. With ``events=True``
every stop crossing is located by ``solve_ivp``'s event search and the integration is
restarted there, so each leg integrates a smooth (linear) vector field: this is the
reference mode used to check the exact integrator. Without it, DOP853 steps over the
discontinuity of the force's derivative as a user of ``solve_ivp`` would.

External loads (``loads``): M x'' + C x' + K x + B^T f(B x) = f_ext(t) = sum_l b_l p_l(t), and
the state gains W_ext' = v^T f_ext(t), the loads' work, integrated as the dissipated work is.
The integration restarts at every load breakpoint (a start, an end, a tabulated sample),
with or without ``events``: a pulse shorter than a step is never stepped over, and inside a
leg the loads are the smooth piece p_l(t_a + s) = Re(F e^{i omega s}) + p0 + p1 s
(:meth:`~reduced.models.loads.Loads.pieces_at`, the signal's own value on [t_a, t_b)), so each
leg integrates a smooth vector field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.transient import stepper as _stepper
from reduced.transient.result import RingdownResult, RingdownStream

EPS = np.finfo(float).eps


def _rhs_factory(system: GapSystem):
    """f(t, z) of the free leg without events: z' = [v, M^-1 (-K x - C v - B^T f(B x)), v^T C v].

    Compiled (:func:`_free_rhs`, ~10x faster than the numpy expression it replaced: 2.3 M calls in
    discrete-symmetric's round-off run). Its round-off differs from numpy's (whose 3 x 3 products
    go through OpenBLAS, in another order of summation), so a run differs from the numpy RHS's
    from the last bits on; the only such run in the main job, the symmetry study's DOP853 run
    from round-off alone, is judged "sensitive" (not reproducible across machines) in its
    reproduction rules, and its numbers are those of the round-off it was given.
    """
    n = system.n
    Minv = np.linalg.inv(system.M)
    K, C = np.ascontiguousarray(system.K, dtype=float), np.ascontiguousarray(system.C, dtype=float)
    B = np.ascontiguousarray(system.B, dtype=float)
    stops = np.ascontiguousarray(np.stack([system.offset, system.side, system.k]), dtype=float)  # (3, m)

    def rhs(t, z):
        return _free_rhs(z, n, Minv, K, C, B, stops)

    return rhs


@nb.njit(cache=True)
def _free_rhs(z, n, Minv, K, C, B, stops):
    """[v, M^-1 (-K x - C v - B^T f(B x)), v^T C v] of z = [x, v, W] (:func:`_rhs_factory`); ``stops`` is
    (offset, side, k) of each stop, f_j = k_j (B_j x - o_j) where side_j (B_j x - o_j) > 0."""
    m = B.shape[0]
    w = np.zeros(n)  # -K x - C v - B^T f
    for j in range(m):
        s = -stops[0, j]
        for i in range(n):
            s += B[j, i] * z[i]
        if stops[1, j] * s > 0.0:
            f = stops[2, j] * s
            for i in range(n):
                w[i] -= f * B[j, i]
    out = np.empty(2 * n + 1)
    for i in range(n):
        acc = 0.0
        for l in range(n):
            acc += K[i, l] * z[l] + C[i, l] * z[n + l]
        w[i] -= acc
    work = 0.0
    for i in range(n):
        acc = 0.0
        vc = 0.0
        for l in range(n):
            acc += Minv[i, l] * w[l]
            vc += z[n + l] * C[l, i]
        out[i] = z[n + i]
        out[n + i] = acc
        work += vc * z[n + i]
    out[2 * n] = work
    return out


def _load_piece(loads, ta: float):
    """f_ext(t) = b^T (Re(F e^{i omega (t - ta)}) + p0 + p1 (t - ta)) on the piece that starts at ta."""
    pc = loads.pieces_at([ta])
    F, omega, p0, p1, b = pc.F[0], pc.omega[0], pc.p0[0], pc.p1[0], loads.b

    def force(t):
        s = t - ta
        return ((F * np.exp(1j * omega * s)).real + p0 + p1 * s) @ b

    return force


def _last_sample_at_or_before(t: float, fs: float, N: int) -> int:
    """Largest j < N with j / fs <= t (-1 if none): ``searchsorted(arange(N) / fs, t, "right") - 1``
    without the grid."""
    j = min(max(int(math.floor(t * fs)), -1), N - 1)
    while j + 1 < N and (j + 1) / fs <= t:
        j += 1
    while j >= 0 and j / fs > t:
        j -= 1
    return j


DENSE_DEGREE = 7  # SciPy's DOP853 dense output is a polynomial of this degree in x = (t - t_old) / h
_NODES = 0.5 - 0.5 * np.cos(np.pi * np.arange(DENSE_DEGREE + 1) / DENSE_DEGREE)  # Chebyshev-Lobatto, 0 .. 1
_TO_POWER = np.linalg.inv(np.vander(_NODES, DENSE_DEGREE + 1, increasing=True))  # values at nodes -> a_k of x^k
# power -> Bernstein coefficients on [0, 1]: b_k = sum_{i <= k} C(k, i) / C(D, i) a_i
_TO_BERNSTEIN = np.array([[math.comb(k, i) / math.comb(DENSE_DEGREE, i) if i <= k else 0.0
                           for i in range(DENSE_DEGREE + 1)] for k in range(DENSE_DEGREE + 1)])
CRIT_IMAG = 1e-6  # a critical point of the stop polynomial with |Im x| below this is taken as real (x in [0, 1])


def _polynomial_crossings(sol, t_old: float, t: float, system: GapSystem, direction: np.ndarray) -> list:
    """[(x_a, x_b, n_cross, a)] per stop: the first crossing of the stop in its event direction by DOP853's
    dense output over the step, bracketed in x = (t - t_old) / h between two points where that degree-7
    polynomial (power coefficients a) is monotone (None if it has none), and how many crossings it has.

    d_j g_j(x) (g_j = side (B_j x - o_j), d_j the direction) is interpolated exactly at 8 nodes; its
    Bernstein coefficients b_k bound it on [0, 1] and their sign changes bound its roots there (with the
    same parity): no change, no crossing; one change, one crossing over the whole step (if rising).
    Otherwise the polynomial is cut at its critical points (roots of its derivative) into monotone
    pieces, and a crossing is a piece rising through zero. A contact entered and left inside
    one step (both ends open, the sign test of ``solve_ivp`` sees nothing) is found this way.
    """
    n = system.n
    h = t - t_old
    Z = sol(t_old + h * _NODES)
    G = (direction * system.side)[:, None] * (system.B @ Z[:n] - system.offset[:, None])
    A = G @ _TO_POWER.T
    bern = A @ _TO_BERNSTEIN.T
    out: list = [None] * system.m
    for j in np.flatnonzero(bern[:, 1:].max(axis=1) >= 0.0):
        # b_0 = d g(t_old) alone >= 0 is the round-off of a stop that has just switched: the polynomial
        # is then below its chord to negative values, and cannot come back up past zero
        a, b = A[j], bern[j]
        if np.all(b != 0.0):
            changes = np.count_nonzero(b[:-1] * b[1:] < 0.0)  # bounds the roots in (0, 1), same parity
            if changes == 0:
                continue
            if changes == 1:  # one root: a crossing of the whole step if rising, none if falling
                if b[0] < 0.0:
                    out[j] = (0.0, 1.0, 1, a)
                continue
        r = np.roots((a[1:] * np.arange(1, DENSE_DEGREE + 1))[::-1])
        crit = np.sort(r.real[(np.abs(r.imag) <= CRIT_IMAG) & (r.real > 0.0) & (r.real < 1.0)])
        xs = np.concatenate([[0.0], crit, [1.0]])
        vals = np.polynomial.polynomial.polyval(xs, a)
        rising = np.flatnonzero((vals[:-1] <= 0.0) & (vals[1:] >= 0.0) & (vals[:-1] < vals[1:]))
        if rising.size:
            k = int(rising[0])
            out[j] = (float(xs[k]), float(xs[k + 1]), int(rising.size), a)
    return out


def _find_active_events(g, g_new, direction) -> np.ndarray:
    """Events whose function changed sign in the step, in their direction (as ``solve_ivp``)."""
    g, g_new = np.asarray(g), np.asarray(g_new)
    up = (g <= 0) & (g_new >= 0)
    down = (g >= 0) & (g_new <= 0)
    mask = up & (direction > 0) | down & (direction < 0) | (up | down) & (direction == 0)
    return np.nonzero(mask)[0]


def _first_event(sol, t_old: float, t: float, act: np.ndarray, funcs: list, system: GapSystem,
                 direction: np.ndarray) -> tuple[int, float]:
    """(stop, time) of the first crossing in the step (t_old, t], or (-1, t).

    As ``solve_ivp``: the stops whose event function changed sign between the step's ends (``act``),
    each root by ``brentq`` on the dense output over the step, the earliest taken. Beyond it: a stop
    that the dense output makes cross earlier, or more than once, in the step
    (:func:`_polynomial_crossings`; a short contact entered and left between two steps' ends, which
    the end test misses) is located by ``brentq`` on its monotone bracket instead.
    """
    poly = _polynomial_crossings(sol, t_old, t, system, direction)
    found = [(p[0], j) for j, p in enumerate(poly) if p is not None]
    first_poly = min(found) if found else None
    if first_poly is not None:
        j = first_poly[1]
        x_a, x_b, count, _ = poly[j]
        if not (j in act and count == 1):  # a crossing the end test misses or mislocates
            h = t - t_old
            ta, tb = t_old + h * x_a, t if x_b == 1.0 else t_old + h * x_b
            f = funcs[j]
            try:
                root = brentq(lambda tt: f(tt, sol(tt)), ta, tb, xtol=4 * EPS, rtol=4 * EPS)
            except ValueError:  # no sign change at the ends by round-off: the interpolant's own root
                a = poly[j][3]
                x = brentq(lambda x: np.polynomial.polynomial.polyval(x, a), x_a, x_b, xtol=4 * EPS)
                root = t_old + h * x
            return j, float(root)
    if act.size:
        roots = np.array([brentq(lambda tt, f=funcs[e]: f(tt, sol(tt)), t_old, t, xtol=4 * EPS, rtol=4 * EPS)
                          for e in act])
        first = int(np.argsort(roots, kind="stable")[0])
        return int(act[first]), float(roots[first])
    return -1, t


def _x_scale(system: GapSystem) -> float:
    """m, the displacement scale of the default atol and of the state switch: the largest stop offset or 1 mm."""
    return max(float(np.max(np.abs(system.offset), initial=0.0)), 1e-3)


@dataclass(frozen=True, slots=True)
class Dop853Options:
    """Options of the DOP853 integrator (see :func:`integrate_dop853`).

    Parameters
    ----------
    rtol : relative tolerance, in (0, 1)
    atol : m, absolute tolerance (> 0); None: rtol x (largest stop offset or 1e-3 m)
    events : restart at every stop crossing (the reference mode, see the module docstring)
    """

    rtol: float = 1e-10
    atol: float | None = None
    events: bool = False

    def checked(self, system: GapSystem) -> Dop853Options:
        """These options validated (ValueError naming the first bad one), atol resolved."""
        rtol = _check.number("rtol", self.rtol, lo=0.0, hi=1.0)
        atol = rtol * _x_scale(system) if self.atol is None else _check.positive("atol", self.atol, "m")
        return Dop853Options(rtol, atol, _check.flag("events", self.events))


class Dop853Stepper(_stepper.Stepper):
    """DOP853's step (:mod:`reduced.transient.stepper`): one step of SciPy's ``DOP853`` stepper.

    The stepper is driven exactly as ``solve_ivp`` drives it (the same steps, dense output at the
    samples, events located by ``brentq`` on the dense output to 4 eps), but it lives across
    buffers, so the samples do not depend on them. A run is a sequence of legs, each a smooth
    vector field: a leg ends at a stop crossing (``events``) or a load breakpoint, and the next
    starts from the state there. A step whose samples overflow the buffer finishes them in the
    next call, before the stepper moves on.

    Parameters
    ----------
    system, n_samples, sample_rate_hz, loads, report
        As :class:`reduced.transient.stepper.Stepper`.
    x0 : (n,) ndarray of float
        m, initial displacement.
    v0 : (n,) ndarray of float
        m/s, initial velocity.
    duration_s : float
        s, length of the run.
    options : Dop853Options
        rtol, atol and events, checked.

    Raises
    ------
    RuntimeError
        (from :meth:`step`) DOP853's step size became too small.
    """

    method = "dop853"

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options: Dop853Options, loads, report: bool) -> None:
        super().__init__(system, n_samples, sample_rate_hz, loads, report)
        self.options = options
        self.x_scale = _x_scale(system)
        self.T = (n_samples - 1) / sample_rate_hz
        self.z0 = np.concatenate([x0, v0, [0.0, 0.0] if self.forced else [0.0]])
        self.stats.update({"nfev": 0, "n_events": 0, "rtol": options.rtol, "atol": options.atol, "n_steps": 0,
                           "n_legs": 1})
        self.Minv = np.linalg.inv(system.M)
        self.breakpoints = loads.breakpoints(self.T) if self.forced else np.zeros(0)
        if self.forced:
            self.stats["n_loads"] = loads.n_loads
        self.active = system.penetration(x0) > 0.0 if options.events else None
        self.t0, self.z = 0.0, self.z0
        self.shown = 0  # progress reported, in 1/1000 of the run
        self.solver = None  # the leg under way
        self.pending = None  # [dense output or None, last sample, t, event stop, finished] of a step

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        return (np.empty((k, self.z0.size)),)

    def block(self, buf: _stepper.Buffer) -> tuple[np.ndarray, ...]:
        """(start, x, v, W[, W_ext]) views of the buffer's columns."""
        b, n = buf.arrays[0], self.n
        if self.forced:
            return b[:, :n], b[:, n : 2 * n], b[:, 2 * n], b[:, 2 * n + 1]
        return b[:, :n], b[:, n : 2 * n], b[:, 2 * n]

    def step(self, buf: _stepper.Buffer) -> float | None:
        """One DOP853 step (a new leg first, if one ended), its samples put into ``buf``."""
        if self.n_samples == 1:
            buf.arrays[0][0] = self.z0
            buf.filled = 1
            self.finished = True
            return None
        if self.pending is None:
            if self.solver is None:
                self.solver = self._leg()
            self._take_step()
        if not self._put(buf):
            return None  # the buffer is full: the step's other samples go into the next
        return self._end_step()

    def _leg(self) -> DOP853:
        """The solver of the leg from (t0, z): to the next load breakpoint (its loads: the piece in force
        at t0), in the contact state with its crossings as events (``events``)."""
        system, n, Minv, forced = self.system, self.n, self.Minv, self.forced
        t_bound = self.T
        if forced:
            kb = int(np.searchsorted(self.breakpoints, self.t0, side="right"))
            t_bound = float(self.breakpoints[kb]) if kb < self.breakpoints.size else self.T
            force = _load_piece(self.loads, float(self.breakpoints[kb - 1]) if kb > 0 else 0.0)
        if self.options.events:
            Ks, Fs = system.state_matrices(self.active)
            if forced:
                def fun(t, zz, Ks=Ks, Fs=Fs, force=force):
                    x, v = zz[:n], zz[n : 2 * n]
                    f = force(t)
                    a = Minv @ (Fs - Ks @ x - system.C @ v + f)
                    return np.concatenate([v, a, [v @ system.C @ v, v @ f]])
            else:
                def fun(t, zz, Ks=Ks, Fs=Fs):
                    x, v = zz[:n], zz[n : 2 * n]
                    a = Minv @ (Fs - Ks @ x - system.C @ v)
                    return np.concatenate([v, a, [v @ system.C @ v]])

            self.funcs = system.crossing_events(self.active)
            self.direction = np.array([f.direction for f in self.funcs])
            self.g = [f(self.t0, self.z) for f in self.funcs]
        elif forced:
            def fun(t, zz, force=force):
                x, v = zz[:n], zz[n : 2 * n]
                f = force(t)
                a = Minv @ (f - system.K @ x - system.C @ v - system.contact_force(x))
                return np.concatenate([v, a, [v @ system.C @ v, v @ f]])
        else:
            fun = _rhs_factory(system)
        self.t_bound = t_bound
        return DOP853(fun, self.t0, self.z, t_bound, rtol=self.options.rtol, atol=self.options.atol,
                      vectorized=False)

    def _take_step(self) -> None:
        """solver.step(); with ``events`` the first crossing in it; the last sample it reaches."""
        solver = self.solver
        solver.step()
        if solver.status == "failed":
            raise RuntimeError(f"DOP853 failed at t = {solver.t:.6g} s: step size too small")
        finished = solver.status == "finished"
        self.stats["n_steps"] += 1
        t, sol = solver.t, None
        je = -1
        if self.options.events:
            g_new = [f(t, solver.y) for f in self.funcs]
            act = _find_active_events(self.g, g_new, self.direction)
            sol = solver.dense_output()
            je, t = _first_event(sol, solver.t_old, t, act, self.funcs, self.system, self.direction)
            self.g = g_new
        self.pending = [sol, _last_sample_at_or_before(t, self.sample_rate_hz, self.n_samples), t, je, finished]

    def _put(self, buf: _stepper.Buffer) -> bool:
        """The pending step's samples from the dense output into ``buf``; False if it filled first."""
        p = self.pending
        upto = p[1]
        b = buf.arrays[0]
        while buf.j0 + buf.filled <= upto:
            if buf.full:
                return False
            if p[0] is None:
                p[0] = self.solver.dense_output()
            k = min(buf.k - buf.filled, upto + 1 - buf.j0 - buf.filled)
            tt = np.arange(buf.j0 + buf.filled, buf.j0 + buf.filled + k) / self.sample_rate_hz
            b[buf.filled : buf.filled + k] = p[0](tt).T
            buf.filled += k
        return True

    def _end_step(self) -> float | None:
        """After a step's samples: the progress mark, and a new leg at a crossing or a load breakpoint."""
        sol, _, t, je, finished = self.pending
        self.pending = None
        solver, stats = self.solver, self.stats
        fraction = None
        if int(1000 * t / self.T) > self.shown:
            self.shown = int(1000 * t / self.T)
            fraction = t / self.T
        if je >= 0:
            z = sol(t)
            self.z, self.t0 = z, t
            self.active = self.system.state_after_crossing(self.active, je, z[:self.n], z[self.n : 2 * self.n],
                                                           1e-9 * self.x_scale)
            stats["n_events"] += 1
            stats["n_legs"] += 1
            stats["nfev"] += solver.nfev
            self.solver = None
        elif finished and self.t_bound < self.T:  # a load breakpoint: a new leg in the same contact state
            self.z, self.t0 = solver.y.copy(), self.t_bound
            stats["n_legs"] += 1
            stats["nfev"] += solver.nfev
            self.solver = None
        elif finished:
            stats["nfev"] += solver.nfev
            self.finished = True
        return fraction

    def tolerance(self, amp: float) -> float:
        return float(self.options.atol + self.options.rtol * amp)


def stream_dop853(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
    events: bool = False,
    loads=None,
    chunk_samples: int | None = None,
    progress=None,
) -> RingdownStream:
    """DOP853 response, free or forced, chunk by chunk.

    See :func:`integrate_dop853` for the arguments; the samples come in chunks of at most
    ``chunk_samples`` (default: the whole run in one), the same bits whatever it is
    (:class:`Dop853Stepper`).

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz, rtol, atol, events, loads, progress : as :func:`integrate_dop853`
    chunk_samples : samples a chunk (default: the whole run in one)

    Returns
    -------
    RingdownStream : the run, computed as it is read
    """
    return _stepper.run(Dop853Stepper, system, x0, v0, duration_s, sample_rate_hz, Dop853Options(rtol, atol, events),
                        loads, progress, chunk_samples)


def integrate_dop853(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
    events: bool = False,
    loads=None,
    progress=None,
) -> RingdownResult:
    """DOP853 response of ``system`` from (x0, v0), free or under ``loads``, held in memory.

    Parameters
    ----------
    system : the gap system
    x0, v0 : (n,) initial displacement [m] and velocity [m/s]
    duration_s : s, length of the run (> 0)
    sample_rate_hz : Hz, output sampling (> 0)
    rtol : relative tolerance, in (0, 1)
    atol : m, absolute tolerance (> 0); default rtol x (largest stop offset or 1e-3 m)
    events : restart at every stop crossing (the reference mode, see the module docstring)
    loads : None (free response) or a :class:`~reduced.models.loads.Loads` on the system's n
        coordinates: M x'' + C x' + K x + B^T f(B x) = f_ext(t); restarts at its breakpoints, and
        its work int v^T f_ext dt (an extra state) is ``result.external``
    progress : None or a callable taking the fraction done

    Returns
    -------
    RingdownResult : the run held in memory, with the solver's statistics (nfev, n_steps, n_events)
    """
    return stream_dop853(system, x0, v0, duration_s, sample_rate_hz, rtol=rtol, atol=atol, events=events,
                         loads=loads, progress=progress).collect()
