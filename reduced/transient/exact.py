"""Event-driven exact ringdown of a piecewise-linear gap system.

Inside one contact state the motion obeys the linear system y' = A y + b with
y = [x; v], A = [[0, I], [-M^-1 K_s, -M^-1 C]], b = [0; M^-1 F_s], solved in closed form:

    y(tau) = y_p + sum_i V[:, i] w_i exp(lambda_i tau),   w = V^-1 (y(0) - y_p),

with A V = V diag(lambda) and y_p = [K_s^-1 F_s; 0]. Undamped states use the real modes
of (K_s, M), so lambda = +-i omega exactly and energy is conserved to round-off.

The next gap crossing is the first root of q_j(tau) = +-(side_j (B_j x(tau) - o_j)),
signed so that q_j <= 0 until the stop changes state. A root is never stepped over: from
tau_a the march takes the largest h with

    q_j(tau_a) + q_j'(tau_a) h + 1/2 Q2 h^2 < 0,   Q2 = sum_i |c_i| |lambda_i|^2 e^{Re(lambda_i) tau_a}

(Q2 bounds |q''| for every tau >= tau_a, as Re(lambda) <= 0), which is a safe step for
any velocity. Approaching a crossing, h tends to the Newton step, so the event is located
to round-off; a grazing touch (q' -> 0 at q -> 0) is passed by the floor ``hmin``
without a state change. The dissipated work int v^T C v dt is integrated in closed form
(products of exponentials), so the energy balance E(0) = E(t) + W(t) holds to round-off.

Free segments (no load acting) run in :mod:`reduced.transient._modal`: the sum over the 2n
modes is written over one mode of each conjugate pair (K <= n terms, :func:`modal_table`, the
tables of every contact state worked out once a run), and one march serves all stops at once,
stepping by the smallest of their safe steps; besides the bound above each stop's step may come
from the cubic bound q + q' h + q'' h^2 / 2 + Q3 h^3 / 6 (Q3 bounds |q'''|) or from bounding the
terms that are fast over the step by their amplitude, all of them valid for every h, so no
crossing of any stop is stepped over. Segments with a load acting use the kernel below.

External forcing (``loads``, :mod:`reduced.models.loads`): M x'' + C x' + K x + B^T f(B x) =
sum_l b_l p_l(t). Between two load breakpoints (a start, an end, a tabulated sample), which
become segment boundaries like the crossings, every load is one piece
p_l(s) = Re(F_l e^{i omega_l s}) + p0_l + p1_l s (re-based to the segment start), and in state
s the solution is closed-form too:

    y(tau) = y_p + Re sum_l Y_l e^{i omega_l tau} + V eta(tau),
    Y_l = (i omega_l I - A_s)^-1 g_l F_l = [H_l b_l; i omega_l H_l b_l] F_l,
          H_l = (K_s - omega_l^2 M + i omega_l C)^-1,
    eta_i' = lambda_i eta_i + g0_i + g1_i tau,   eta(0) = V^-1 (y(0) - y_p - Re sum_l Y_l),

with g = V^-1 [0; M^-1 h] the modal loads of h0 = sum_l b_l p0_l, h1 = sum_l b_l p1_l. For a mode
fast over the segment (|lambda| tau_max >= ``SLOW_LT``) eta_i is the exponential plus the
polynomial particular solution P0 + P1 tau, P1 = -g1 / lambda = modal part of -A^-1 g1,
P0 = -(g0 / lambda + g1 / lambda^2) = modal part of A^-1 (P1 - g0); a slow mode, whose
exponential and quasi-static particular solution would cancel (a finely tabulated force on a
soft suspension: K^-1 p' is metres per second where the motion is millimetres per second), is
summed as its Taylor series of degree ``POLY_DEG`` instead (in a segment where a polynomial
piece acts; otherwise every mode stays an exponential). So over a segment

    y(tau) = y_p + Re sum_k X_k e^{z_k tau} + sum_m P_m tau^m,   z = (lambda_fast, +-i omega_l),

Re(Y e^{i omega tau}) being written as Y/2 e^{i omega tau} + conj(Y)/2 e^{-i omega tau}. The root
march applies to q_j = const + Re sum coef e^{z tau} + sum_m Q_m tau^m unchanged: Re z <= 0
still, and |q''| <= sum |coef| |z|^2 e^{Re z tau_a} + sum_m m (m - 1) |Q_m| tau_max^(m - 2) on
[tau_a, tau_max], so no crossing is stepped over. An undamped resonance (i omega_l within
``RESONANCE_REL`` of an eigenvalue of a state) has no bounded particular solution and is
refused (ExactIntegratorError), as is a load on a state with a rigid-body mode. The work of the
loads W_ext(t) = int v^T f_ext dt, and the dissipated work, are integrated in closed form from
the moments int_0^tau t^m e^{u t} dt (:func:`reduced.transient._exact_kernels._moments`: recursions run in their stable
directions, a series where |u tau| < ``TAYLOR_ZT``), so the balance
E(t) = E(0) + W_ext(t) - W(t) holds to round-off under forcing as well.

Layout: the tables of every contact state (:mod:`reduced.transient.exact_tables`), the numba
kernels (:mod:`reduced.transient._modal` for free segments, :mod:`reduced.transient._exact_kernels`
for forced ones), and here the driver: :class:`ExactStepper`, the method's step of the shared
driver :mod:`reduced.transient.stepper`, with its options :class:`ExactOptions`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.transient import stepper as _stepper
from reduced.transient._exact_kernels import (  # noqa: F401 (re-exported: the kernels' constants)
    MOMENT_TOP,
    POLY_DEG,
    SLOW_LT,
    _forced_kernel,
)
from reduced.transient._modal import (  # noqa: F401 (re-exported)
    BUFFER_FULL,
    EPS,
    MAX_MARCH_ITER,
    NOISE_FACTOR,
    QTOL_REL,
    TAYLOR_TERMS,
    TAYLOR_ZT,
    _free_kernel,
    _free_kernel_rows,
)
from reduced.transient.exact_tables import (  # noqa: F401 (re-exported: the tables are part of this method's API)
    MAX_COND,
    RESONANCE_REL,
    ExactIntegratorError,
    ForcedTable,
    StateTable,
    cached_forced_table,
    forced_arrays,
    forced_table,
    modal_table,
    run_tables,
    state_table,
)
from reduced.transient.result import RingdownResult, RingdownStream

HMIN_PERIODS = 1e-9  # the march's smallest step, in units of 1/omega_max (grazing floor)
REST_FLOOR = 1e-15  # motion this small relative to the initial one is round-off at rest
MAX_PIECE_S = 1.0  # s: the closed form is restarted from the state at least this often
PIECES = 50  # ... and at least this many times a run (the progress granularity)
MAX_EVENTS = 50_000_000  # default refusal: a run with more contact events than this is chattering
NO_SEGMENTS = np.zeros(0, np.int64)  # _modal._free_kernel records no segments (the flow's Jacobian does)
NO_TAU = np.zeros(0)


@dataclass(frozen=True, slots=True)
class ExactOptions:
    """Options of the exact integrator.

    Parameters
    ----------
    chunks : the run is split into at least this many pieces (and pieces of at most
        ``MAX_PIECE_S``), at whose ends the closed form restarts and progress is reported
    max_events : refuse (ExactIntegratorError) a run with more contact events than this
    work : integrate the dissipated energy and the work of the loads in closed form; False: a forced run's
        samples alone (the same states, several times faster), its ``dissipated`` and ``external`` NaN
    """

    chunks: int = PIECES
    max_events: int = MAX_EVENTS
    work: bool = True

    def checked(self, system: GapSystem) -> ExactOptions:
        """These options validated (ValueError naming the first bad one)."""
        return ExactOptions(_check.integer("chunks", self.chunks), _check.integer("max_events", self.max_events),
                            _check.flag("work", self.work))


def _check_status(status: int, t: float, max_events: int) -> None:
    if status == -1:
        raise ExactIntegratorError(
            f"more than {max_events} contact events before t = {t:.6g} s: chattering at "
            "a stop; raise max_events or damp the contact"
        )
    if status == -2:
        raise ExactIntegratorError("the motion reached an infeasible contact state")
    if status == -4:
        raise ExactIntegratorError(
            f"contact state flips back and forth at t = {t:.6g} s without progress (round-off "
            "at a stop exceeds the event tolerance); use method 'explicit'"
        )
    if status == -3:
        raise ExactIntegratorError(f"event search did not converge near t = {t:.6g} s")


class SampleRows:
    """Output rows of an exact run (:meth:`ExactStepper.sample_rows`): R y at every sample, the whole state only
    at every ``every``-th, and the per-state tables the kernels fill for them (R U, R y_p, e^{lam / fs}).

    Parameters
    ----------
    every : int
        >= 1: the whole state (and the work) at the samples j = 0, every, 2 every, ...
    R : (r, N) ndarray of float
        The rows, on the kernels' state y (N = 2n, or 2n + p with friction).
    store : dict, optional
        Where the per-state tables are kept for the next run on the same tables with the same rows and rate (a
        friction system's :class:`~reduced.transient.friction_tables.LazyFrictionTables` keeps one: the hammer
        test's levels), keyed by R, the rate and the tables' shape; a state's entries never change once filled.
    fs : float
        Hz, the samples' rate (the key of ``store``: e^{lam / fs}).
    """

    def __init__(self, every: int, R: np.ndarray, store: dict | None = None, fs: float = 0.0) -> None:
        self.every = int(every)
        self.R = np.ascontiguousarray(R, dtype=float)
        self._key: tuple | None = None
        self._arrays: tuple = ()
        self._store = store
        self._digest = (self.R.shape, self.R.tobytes(), float(fs))

    def acq(self, S: int, Kmax: int, out_z: np.ndarray) -> tuple:
        """The kernels' ``acq`` argument for tables of S states of at most Kmax terms (the per-state tables
        allocated anew, empty, when those change: a friction table's term arrays may grow during a run)."""
        if self._key != (S, Kmax):
            key = (self._digest, S, Kmax)
            if self._store is not None and key in self._store:
                self._arrays = self._store[key]
            else:
                r = self.R.shape[0]
                self._arrays = (np.zeros((S, 2, Kmax, r)), np.zeros((S, r)), np.zeros((S, Kmax), np.complex128),
                                np.zeros(S, np.bool_))
                if self._store is not None:
                    self._store.clear()  # the last rows' tables only
                    self._store[key] = self._arrays
            self._key = (S, Kmax)
        return (self.every, self.R, *self._arrays, out_z, np.zeros(self.R.shape[0]))


class ExactStepper(_stepper.Stepper):
    """The exact method's step: one kernel call over a run of segments (:mod:`reduced.transient.stepper`).

    The run [0, t_end] is cut into ``n_pieces = max(chunks, t_end / MAX_PIECE_S)`` equal pieces, at
    whose ends the closed form restarts from the state (y, contact state, W, W_ext): the piece grid
    (and the load breakpoints) fix every arithmetic operation, so the samples are the same bits
    whatever the buffers are. A free run without progress reports goes through all its pieces in
    one group (one kernel call a buffer); otherwise each piece is a group, and progress is reported
    at its end. A group is cut into runs where the loads start or stop being all zero: a free run
    (no load acting) goes to :func:`reduced.transient._modal._free_kernel`, a forced one to
    :func:`reduced.transient._exact_kernels._forced_kernel`.

    Parameters
    ----------
    system, n_samples, sample_rate_hz, loads, report
        As :class:`reduced.transient.stepper.Stepper`; the run itself is on
        ``system.fold_zero_gap_tips()``.
    x0 : (n,) ndarray of float
        m, initial displacement.
    v0 : (n,) ndarray of float
        m/s, initial velocity.
    duration_s : float
        s, length of the run.
    options : ExactOptions
        chunks and max_events, checked.

    Raises
    ------
    ExactIntegratorError
        A system or load the closed form cannot treat (:func:`reduced.transient.exact_tables.state_table`,
        :func:`reduced.transient.exact_tables.forced_table`); later, from :meth:`step`, too many
        events, an infeasible contact state or a non-finite state.
    """

    method = "exact"

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options: ExactOptions, loads, report: bool) -> None:
        super().__init__(system, n_samples, sample_rate_hz, loads, report)
        self.options = options
        tables = run_tables(system)  # kept for the last few systems run (their contents the key)
        self.run_system = run = tables["run"]
        self.table = table = tables["table"]
        self.ft = cached_forced_table(tables, loads) if self.forced else None
        omega_max = tables["omega_max"]
        self.mt = tables["modal"]
        self.hmin = HMIN_PERIODS / omega_max
        self.y = np.concatenate([x0, v0])
        self.active = run.penetration(self.y[:self.n]) > 0.0
        self.floor, self.load_scale = self._scales(omega_max)
        t_end = max(duration_s, (n_samples - 1) / sample_rate_hz)
        self.n_pieces = n_pieces = max(options.chunks, math.ceil(t_end / MAX_PIECE_S))
        self.breakpoints = loads.breakpoints(t_end) if self.forced else np.zeros(0)
        self.stats.update({"n_events": 0, "n_steps": 1, "n_march": 0, "n_states": int(table.valid.sum()),
                           "cond_V": float(np.max(table.cond)), "n_pieces": n_pieces})
        if self.forced:
            self.stats.update(n_loads=loads.n_loads, n_breakpoints=int(self.breakpoints.size))
        self.offset_max = float(np.max(np.abs(run.offset), initial=0.0))
        self.damped = not run.undamped
        # np.linspace(0, t_end, n_pieces + 1)[1:], one bound at a time (the same bits)
        bounds = np.array([t_end if c == n_pieces - 1 else (c + 1) * (t_end / n_pieces) for c in range(n_pieces)])
        # a free run without a progress bar goes through every piece in one kernel call
        self.groups = [bounds] if not self.forced and not report else [bounds[c:c + 1] for c in range(n_pieces)]
        self.t, self.W, self.E, self.n_events, self.n_iter = 0.0, 0.0, 0.0, 0, 0
        self.n_stuck = 0
        self.g = 0  # the group under way
        self.runs: list = []  # its runs still to go, the first under way
        self.c = 0  # the piece reached in the present run's bounds
        self.fargs: tuple = ()
        self.rows: SampleRows | None = None

    def sample_rows(self, every: int, R: np.ndarray) -> None:
        """Sample R y (R (r, 2n)) at every sample, into the buffers' last array (k, r), and the whole state and
        the works only at the samples j (at j / fs) that are multiples of ``every``: the same bits as a run
        without rows there; the other samples' entries of x, v, W are not written (a free segment's sample
        then costs the r rows instead of the state and its work: :func:`reduced.transient._modal.
        _free_kernel_rows`). Call it before the first step; :func:`reduced.transient.integrate.ringdown_rows`
        runs it."""
        self.rows = SampleRows(every, R)

    def _scales(self, omega_max: float) -> tuple[float, float]:
        """(floor, load_scale) in m: motion below REST_FLOOR of the initial one (or of the static
        deflection under the largest load) is round-off at rest (see _first_root); the largest
        static deflection under the loads."""
        run, n, y = self.run_system, self.n, self.y
        x_scale = np.abs(run.B) @ (np.abs(y[:n]) + np.abs(y[n:]) / omega_max)
        load_scale = 0.0
        if self.forced:
            pmax = np.array([s.work_scale() for s in self.loads.signals])
            x_scale = x_scale + np.abs(run.B) @ (np.abs(self.ft.Sb[0]) @ pmax)
            load_scale = float(np.max(np.abs(self.ft.Sb[0]) @ pmax))
        return REST_FLOOR * float(np.max(x_scale, initial=0.0)), load_scale

    def _runs(self, t: float, bound: float) -> list:
        """[(t_a, t_b, pieces or None)]: [t, bound) cut where the loads start or stop being all zero;
        None for a free stretch (no load, or every load zero on it)."""
        if not self.forced:
            return [(t, bound, None)]
        bp = self.breakpoints
        inside = bp[np.searchsorted(bp, t, "right"):np.searchsorted(bp, bound)]
        starts = np.concatenate([[t], inside])
        pc = self.loads.pieces_at(starts)
        zero = ~np.any((pc.F != 0.0) | (pc.p0 != 0.0) | (pc.p1 != 0.0), axis=1)
        out, k0 = [], 0
        for k in range(1, starts.size + 1):
            if k == starts.size or zero[k] != zero[k0]:
                t_b = bound if k == starts.size else float(starts[k])
                out.append((float(starts[k0]), t_b, None if zero[k0] else starts[k0:k]))
                k0 = k
        return out

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        out = np.empty((k, 2 * self.n)), np.empty(k), np.empty(k if self.forced else 0)
        return out if self.rows is None else (*out, np.empty((k, self.rows.R.shape[0])))

    def block(self, buf: _stepper.Buffer) -> tuple[np.ndarray, ...]:
        out_y, out_W, out_E = buf.arrays[:3]
        # one pass without a temporary: a non-finite sample makes the sum non-finite (the full test
        # only then, for a sum that overflowed)
        if not np.isfinite(np.add.reduce(out_y, axis=None)) and not np.all(np.isfinite(out_y)):
            raise ExactIntegratorError("non-finite state: the contact states are ill-conditioned")
        n = self.n
        if self.forced:
            if not self.options.work:  # not integrated (ExactOptions.work)
                out_W[:] = np.nan
                out_E[:] = np.nan
            return out_y[:, :n], out_y[:, n:], out_W, out_E
        return out_y[:, :n], out_y[:, n:], out_W

    def step(self, buf: _stepper.Buffer) -> float | None:
        """One kernel call: the present run from where it stands, until its end or the buffer is full."""
        if not self.runs:  # a new group: its runs from the state at its start
            self.runs = self._runs(self.t, float(self.groups[self.g][-1]))
            self.n_stuck = 0
            self._start_run()
        status = self._call(buf)
        if status == BUFFER_FULL:
            return None
        _check_status(status, self.t, self.options.max_events)
        self.runs.pop(0)
        if self.runs:
            self._start_run()
            return None
        self.g += 1
        self.finished = self.g == len(self.groups)
        return self.g / self.n_pieces

    def _start_run(self) -> None:
        _, _, starts = self.runs[0]
        self.c = 0
        if starts is not None:  # the loads' pieces from t to t_b
            self.fargs = forced_arrays(self.ft, self.loads.pieces_at(starts))

    def _call(self, buf: _stepper.Buffer) -> int:
        """The kernel of the present run on ``buf``; the state advanced; returns the kernel's status."""
        _, t_b, starts = self.runs[0]
        g = self.groups[self.g]
        run, tb, (out_y, out_W, out_E) = self.run_system, self.table, buf.arrays[:3]
        left = self.options.max_events - self.n_events
        filled = buf.filled
        if starts is None and self.rows is not None:
            bounds = g if len(g) > 1 else np.array([t_b])
            S, Kmax = self.mt[1].shape
            self.t, self.W, buf.filled, ne, ni, status, self.n_stuck, self.c = call_numba_kernel(_free_kernel_rows,
                self.mt, run.offset, run.side, run.tip, self.damped, self.y, self.active, self.t, bounds, self.c,
                buf.t, buf.filled, buf.t_after, out_y, out_W, self.W, self.hmin, self.floor, left, self.n_stuck,
                out_E, self.E, float(self.sample_rate_hz), self.rows.acq(S, Kmax, buf.arrays[3]))
        elif starts is None:
            bounds = g if len(g) > 1 else np.array([t_b])
            self.t, self.W, buf.filled, ne, ni, status, self.n_stuck, self.c = call_numba_kernel(_free_kernel,
                self.mt, run.offset, run.side, run.tip, self.damped, self.y, self.active, self.t, bounds, self.c,
                buf.t, buf.filled, buf.t_after, out_y, out_W, self.W, self.hmin, self.floor, left, self.n_stuck,
                out_E, self.E, NO_SEGMENTS, NO_TAU, float(self.sample_rate_hz))
        else:
            self.t, self.W, self.E, buf.filled, ne, ni, status, self.n_stuck = call_numba_kernel(_forced_kernel,
                tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, run.B, run.offset, run.side, run.tip, run.C, self.damped,
                self.y, self.active, self.t, t_b, buf.t, buf.filled, buf.t_after, out_y, out_W, self.W, self.hmin,
                self.floor, left, self.n_stuck, *self.fargs, out_E, self.E, self.options.work)
            if self.rows is not None:  # a forced stretch samples the whole state: its rows from it
                buf.arrays[3][filled:buf.filled] = out_y[filled:buf.filled] @ self.rows.R.T
        self.n_events += ne
        self.n_iter += ni
        self.stats.update(n_events=self.n_events, n_steps=self.n_events + 1, n_march=self.n_iter)
        return status

    def tolerance(self, amp: float) -> float:
        # evaluating V diag(e^{lam t}) V^-1 y loses cond(V) eps |y| at each event, and under loads
        # cond(V) eps |y - y_part|, y_part up to the static deflection under the largest load
        return float(np.max(self.table.cond)) * EPS * max(amp, self.offset_max, self.load_scale)


def stream_exact(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    loads=None,
    chunks: int = PIECES,
    max_events: int = MAX_EVENTS,
    chunk_samples: int | None = None,
    progress=None,
    work: bool = True,
) -> RingdownStream:
    """Exact (event-driven, closed-form) response of ``system`` from (x0, v0), chunk by chunk.

    See :func:`integrate_exact` for the arguments; the samples come in chunks of at most
    ``chunk_samples`` (default: the whole run in one), the same bits whatever ``chunk_samples``
    is (:class:`ExactStepper`).

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz, loads, chunks, max_events, progress, work : as
        :func:`integrate_exact`
    chunk_samples : samples a chunk (default: the whole run in one)

    Returns
    -------
    RingdownStream : the run, computed as it is read
    """
    return _stepper.run(ExactStepper, system, x0, v0, duration_s, sample_rate_hz,
                        ExactOptions(chunks, max_events, work), loads, progress, chunk_samples)


def integrate_exact(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    loads=None,
    chunks: int = PIECES,
    max_events: int = MAX_EVENTS,
    progress=None,
    work: bool = True,
) -> RingdownResult:
    """Exact (event-driven, closed-form) response of ``system`` from (x0, v0), free or forced.

    M x'' + C x' + K x + B^T f(B x) = sum_l b_l p_l(t) (the right-hand side 0 without loads),
    solved in closed form in every contact state between crossings and load breakpoints (the
    module docstring gives the particular solutions).

    Parameters
    ----------
    system : the gap system (every contact state must be a stable oscillator)
    x0, v0 : (n,) initial displacement [m] and velocity [m/s]
    duration_s : s, length of the run (> 0)
    sample_rate_hz : Hz, output sampling (the solution itself is exact between samples)
    loads : None (free response) or a :class:`~reduced.models.loads.Loads` on the system's n
        coordinates; its work int v^T f_ext dt is ``result.external``. A load at an undamped
        resonance of a contact state (|i omega - lambda| <= ``RESONANCE_REL`` omega) is refused
        (ExactIntegratorError)
    chunks : the run is split into at least this many pieces (and pieces of at most
        ``MAX_PIECE_S``), at whose ends the closed form restarts and ``progress`` (a
        callable taking the fraction done) is called
    max_events : refuse (ExactIntegratorError) a run with more contact events than this
    progress : None or a callable taking the fraction done, called at the end of each piece
    work : integrate the dissipated energy and the work of the loads (False: a forced run's states
        alone, the same numbers, its ``dissipated`` and ``external`` NaN; :class:`ExactOptions`)

    Returns
    -------
    RingdownResult : the run, with the statistics (n_events, n_march, n_states, cond_V, n_pieces)

    The whole run is held in memory; :func:`stream_exact` gives it chunk by chunk.
    """
    return stream_exact(system, x0, v0, duration_s, sample_rate_hz, loads=loads, chunks=chunks,
                        max_events=max_events, progress=progress, work=work).collect()
