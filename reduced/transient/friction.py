"""Ringdowns of systems with friction at the tips: the exact, explicit and reference integrators.

A :class:`~reduced.models.gaps.GapSystem` with :class:`~reduced.models.gaps.Friction` has sliders (Jenkins
elements) at its tips; each of their states (stick, slip +, slip -, and the tip open) is linear because
the normal force is, so the motion stays piecewise linear in y = [x; v; w] (w: the sliders' positions).

- :class:`FrictionExactStepper`: the exact integrator on that flow. Every friction state's closed form and
  every event (gap, stick -> slip when |kt (t - w)| reaches mu N, slip -> stick when the slip velocity
  passes zero) are tabulated once (:mod:`reduced.transient.friction_tables`), and the march that skips no
  root (:mod:`reduced.transient._modal`) finds the next event among all of them; the viscous and friction
  work are integrated in closed form, so E(t) = E(0) + W_ext(t) - W_viscous(t) - W_friction(t) to
  round-off. Loads work as without friction (the forced closed form of :mod:`reduced.transient.exact`,
  on the augmented state).
- :class:`FrictionExplicitStepper`: central difference with a return mapping for the sliders.
- :func:`reference_dop853`: SciPy's DOP853 restarted at every state change, the independent reference.

The integrators of :mod:`reduced.transient.integrate` (``ringdown``) pick these steppers for a system with
friction (registered in :data:`reduced.transient.stepper.FRICTION_STEPPERS` on import). A run's result
carries the sliders' positions ``w`` (N, p) and the friction work ``friction`` (N,); its ``dissipated`` is
the viscous and friction work together, so ``energy_balance_error`` checks the whole balance. The sliders
start unloaded, w(0) = Bt x(0), unless ``w0`` is given.
"""

from __future__ import annotations

import functools
import hashlib
import math
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.transient import stepper as _stepper
from reduced.transient._friction_kernels import (
    NEW_STATE,
    _cd_friction_kernel,
    _friction_forced_kernel,
    _friction_free_kernel,
)
from reduced.transient._modal import BUFFER_FULL, EPS, no_rows
from reduced.transient.dop853 import Dop853Options
from reduced.transient.exact import (
    HMIN_PERIODS,
    MAX_EVENTS,
    MAX_PIECE_S,
    PIECES,
    REST_FLOOR,
    ExactIntegratorError,
    ExactOptions,
    SampleRows,
    _check_status,
)
from reduced.transient.exact_tables import forced_arrays
from reduced.transient.explicit import (
    DEFAULT_OMEGA_DT,
    LOAD_BLOCK_STEPS,
    ExplicitOptions,
    ExplicitStepper,
    _damping_factor,
)
from reduced.transient.friction_probe import REACH_OMEGA_TAU, pass_through, switch
from reduced.transient.friction_tables import (
    KIND_GAP,
    KIND_SLIP_END,
    KIND_STICK_DOWN,
    KIND_STICK_UP,
    FrictionTable,
    LazyForcedTable,
    LazyFrictionTables,
)
from reduced.transient.result import RingdownResult, RingdownStream, zeros_view

EVENT_KINDS = {KIND_GAP: "gap", KIND_STICK_UP: "slip+", KIND_STICK_DOWN: "slip-", KIND_SLIP_END: "stick"}
PASS_THROUGH = True  # states a free run enters for an instant passed through without their tables (_pass_through)
PASS_THROUGH_MIN_N = 40  # ... on systems of at least this many coordinates (a smaller one's state costs less to
# build than to probe: the discrete model's 4 coordinates build in ~1 ms)
TABLES_KEPT = 1  # systems whose friction tables are kept for the next run (each holds its built states')
_TABLES: OrderedDict = OrderedDict()  # digest of a system -> its LazyFrictionTables
_TABLES_LOCK = threading.Lock()


def _digest(system: GapSystem, omega_ref: float) -> str:
    """sha256 of everything the friction tables of ``system`` depend on."""
    h = hashlib.sha256()
    fr = system.friction
    for a in (system.M, system.C, system.K, system.B, system.k, system.offset, system.side, system.tip, fr.Bt, fr.tip,
              fr.k_t, fr.mu, fr.stop, np.array([omega_ref])):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def clear_tables() -> None:
    """Forget the kept friction tables (:func:`friction_tables`)."""
    with _TABLES_LOCK:
        _TABLES.clear()


def friction_tables(system: GapSystem, omega_ref: float) -> tuple[LazyFrictionTables, bool]:
    """(tables, reused) of ``system``: new (:class:`reduced.transient.friction_tables.LazyFrictionTables`, whose
    states are built as runs enter them) or, for the same system as a recent run (the hammer test's levels: the
    same rig under blows of other sizes), the recent run's with the states it built. The last ``TABLES_KEPT``
    systems' tables are kept, keyed by the sha256 of their matrices and friction; a state once built never
    changes.

    Parameters
    ----------
    system : GapSystem
        With friction.
    omega_ref : float
        rad/s, the slip-end events' scale (:func:`~reduced.transient.friction_tables.friction_table`).

    Returns
    -------
    (LazyFrictionTables, bool)
    """
    key = _digest(system, omega_ref)
    with _TABLES_LOCK:
        if key in _TABLES:
            _TABLES.move_to_end(key)
            return _TABLES[key], True
    entry = LazyFrictionTables(system, omega_ref)
    with _TABLES_LOCK:
        _TABLES[key] = entry
        while len(_TABLES) > TABLES_KEPT:
            _TABLES.popitem(last=False)
    return entry, False


@dataclass(frozen=True, slots=True)
class ExactFrictionOptions:
    """Options of the exact integrator with friction.

    Parameters
    ----------
    chunks, max_events : as :class:`reduced.transient.exact.ExactOptions`
    w0 : m, the sliders' initial positions (p,), or None: unloaded, w(0) = Bt x(0)
    log_events : events kept in the run's log (``result.events``), 0 for none
    """

    chunks: int = PIECES
    max_events: int = MAX_EVENTS
    w0: tuple | None = None
    log_events: int = 0

    def checked(self, system: GapSystem) -> ExactFrictionOptions:
        """These options validated (ValueError naming the first bad one)."""
        w0 = None if self.w0 is None else tuple(_check.vector("w0", self.w0, system.p))
        return ExactFrictionOptions(_check.integer("chunks", self.chunks),
                                    _check.integer("max_events", self.max_events), w0,
                                    _check.integer("log_events", self.log_events, lo=0))


@dataclass(frozen=True, eq=False)
class FrictionEvents:
    """The events of an exact run with friction, in order (the first ``len(t)`` if the log filled).

    Attributes
    ----------
    t : (k,) ndarray of float
        s, time of each event.
    slot : (k,) ndarray of int
        The event: j < m the gap of stop j, m + 2 i (+) or m + 2 i + 1 (-) slider i's.
    kind : (k,) ndarray of str
        'gap', 'slip+', 'slip-' (a stick ending) or 'stick' (a slip ending).
    state : (k,) ndarray of int
        The friction state after it (:class:`reduced.transient.friction_tables.FrictionStates`).
    y : (k, 2n + p) ndarray of float
        The state [x; v; w] at it (after a closing's reset of w).
    n_total : int
        Events of the run (more than ``len(t)`` when the log filled).
    table : FrictionTable
        The states, to read ``state`` (``table.states.describe(system, s)``).
    """

    t: np.ndarray
    slot: np.ndarray
    kind: np.ndarray
    state: np.ndarray
    y: np.ndarray
    n_total: int
    table: FrictionTable

    def __len__(self) -> int:
        return self.t.shape[0]


def _unloaded(system: GapSystem, x0: np.ndarray, w0) -> np.ndarray:
    """m, the sliders' initial positions: ``w0`` (a slider of a closed tip pulling harder than mu N put on the
    cone, w = t -+ mu N / kt, as it would slip at once), or Bt x0 (unloaded)."""
    fr = system.friction
    if w0 is None:
        return fr.Bt @ x0
    w = np.array(w0, float)
    closed, slip = _initial_states(system, x0, w)
    t = fr.Bt @ x0
    stop_of = fr.engaged_by(system.tip, closed)
    for q in np.flatnonzero(slip):
        j = stop_of[q]
        w[q] = t[q] - slip[q] * fr.mu[q] * system.k[j] * system.penetration(x0)[j] / fr.k_t[q]
    return w


def _start_state(system: GapSystem, table: FrictionTable, x0: np.ndarray, w0) -> tuple[np.ndarray, int]:
    """(w (p,) m, s): ``_unloaded(system, x0, w0)`` and :func:`initial_friction_state` at it, the start's states
    (:func:`_initial_states`) found once where no slider is put on its cone (w unchanged: the same states again)."""
    if w0 is None:
        w = system.friction.Bt @ x0
        return w, table.states.index(*_initial_states(system, x0, w))
    w = np.array(w0, float)
    closed, slip = _initial_states(system, x0, w)
    if np.any(slip):
        w = _unloaded(system, x0, w0)
        closed, slip = _initial_states(system, x0, w)
    return w, table.states.index(closed, slip)


def initial_friction_state(system: GapSystem, table: FrictionTable, x0: np.ndarray, w0: np.ndarray) -> int:
    """The friction state at the start: the stops that penetrate closed (the deepest of a tip), a slider of
    a closed tip sticking when its spring force is inside the cone (|kt (t - w)| <= mu N), else slipping the
    way it pulls (:func:`_initial_states`).

    Parameters
    ----------
    system : GapSystem
    table : FrictionTable
    x0 : (n,) m
    w0 : (p,) m

    Returns
    -------
    int
        Index of the state.
    """
    return table.states.index(*_initial_states(system, x0, w0))


def _without_slivers(runs: list) -> list:
    """``runs`` [(t_a, t_b, pieces or None)] with each forced run no longer than the round-off of its times
    (t_b - t_a <= 4 eps |t_b|) given to its neighbour: a free run after it starts at its t_a, or, last, the run
    before it ends at its t_b. Such a sliver comes from one instant computed two ways (a blow's end 2 ms + 1 ms
    = 0.0029999999999999996 s and a piece bound 0.0024 + 0.0006 = 0.003 s); the forced kernel cannot advance t
    across it (t + tau == t) and would not return. Other runs are left as they are."""
    out = list(runs)
    k = 0
    while k < len(out):
        a, b, pieces = out[k]
        sliver = pieces is not None and b - a <= 4.0 * np.finfo(float).eps * max(abs(a), abs(b))
        if sliver and k + 1 < len(out) and out[k + 1][2] is None:
            out[k:k + 2] = [(a, out[k + 1][1], None)]
        elif sliver and k + 1 == len(out) and k > 0:
            out[k - 1:k + 1] = [(out[k - 1][0], b, out[k - 1][2])]
        else:
            k += 1
    return out


class FrictionExactStepper(_stepper.Stepper):
    """The exact method's step for a system with friction (module docstring; the driver as
    :class:`reduced.transient.exact.ExactStepper`: the run cut into pieces at whose ends the closed form
    restarts, a free stretch in one kernel call, a forced one in the forced kernel).

    Parameters
    ----------
    system, x0, v0, duration_s, n_samples, sample_rate_hz, loads, report
        As :class:`reduced.transient.exact.ExactStepper` (the system has friction).
    options : ExactOptions or ExactFrictionOptions
        chunks and max_events; with the latter the sliders' initial positions and the event log.

    Raises
    ------
    ExactIntegratorError
        A friction state the closed form cannot treat (:func:`reduced.transient.friction_tables.friction_table`);
        later, from :meth:`step`, too many events or a state that flips back and forth.
    """

    method = "exact"
    friction = True

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options, loads, report: bool) -> None:
        super().__init__(system, n_samples, sample_rate_hz, loads, report)
        if isinstance(options, ExactOptions):
            options = ExactFrictionOptions(options.chunks, options.max_events)
        self.options = options = options.checked(system)
        self.run_system = system = system.fold_zero_gap_tips()  # zero-gap tips without friction: linear springs
        fr = system.friction
        self.p = fr.p
        with single_thread_blas():
            self.omega_max = omega_max = system.omega_max()
            t0 = time.perf_counter()
            self.lazy, self.cached = friction_tables(system, omega_max)
            self.table = table = self.lazy.table
            self.forced_table = LazyForcedTable(self.lazy, loads) if self.forced else None
            self.ft = self.forced_table.table if self.forced else None
        self.table_s = time.perf_counter() - t0
        self.hmin = HMIN_PERIODS / omega_max
        stop_tip = np.concatenate([system.tip, np.full(2 * fr.p, -1)]).astype(np.int64)  # the tip of each event slot
        c = np.ascontiguousarray
        self.fric = (c(fr.Bt), c(fr.tip), stop_tip, c(fr.stop), c(table.ekind), c(table.states.stop_of), c(system.B),
                     c(system.k), c(system.offset), c(system.side), c(fr.mu), c(fr.k_t))
        self.offset_max = float(np.max(np.abs(system.offset), initial=0.0))
        self.damped = not system.undamped
        self.pass_through = PASS_THROUGH and system.n >= PASS_THROUGH_MIN_N
        self._start(x0, v0, options.w0, duration_s, n_samples, sample_rate_hz, loads)

    def _start(self, x0: np.ndarray, v0: np.ndarray, w0, duration_s: float, n_samples: int, sample_rate_hz: float,
               loads) -> None:
        """The run's own state from (x0 m, v0 m/s, w0 m or None: unloaded) under ``loads`` over ``duration_s`` s,
        ``n_samples`` at ``sample_rate_hz`` Hz: everything of the set-up but the system's tables (:meth:`__init__`;
        :class:`FrictionFlow` calls it again for each of its runs, under loads of the same directions and
        frequencies, whose forced table it keeps)."""
        self.n_samples, self.sample_rate_hz, self.loads = n_samples, sample_rate_hz, loads
        system, options = self.run_system, self.options
        fr, table = system.friction, self.table
        t0 = time.perf_counter()
        with single_thread_blas():
            w0, self.s = _start_state(system, table, x0, w0)
            self.s0 = self.s
            self.y = np.concatenate([x0, v0, w0])
            self.lazy.ensure(self.s)
            if self.forced:
                self.forced_table.ensure(0)  # the open state's static deflections: the scales of the round-off
        self.floor, self.load_scale = self._scales(self.omega_max)
        t_end = max(duration_s, (n_samples - 1) / sample_rate_hz)
        self.n_pieces = n_pieces = max(options.chunks, math.ceil(t_end / MAX_PIECE_S))
        self.breakpoints = loads.breakpoints(t_end) if self.forced else np.zeros(0)
        self.stats.update({"n_events": 0, "n_steps": 1, "n_march": 0, "n_states": int(table.states.S),
                           "n_pieces": n_pieces, "n_sliders": fr.p, "tables_reused": self.cached, "n_passed": 0})
        self.table_s += time.perf_counter() - t0
        self._table_stats()
        if self.forced:
            self.stats.update(n_loads=loads.n_loads, n_breakpoints=int(self.breakpoints.size))
        bounds = np.array([t_end if c == n_pieces - 1 else (c + 1) * (t_end / n_pieces) for c in range(n_pieces)])
        self.groups = [bounds] if not self.forced and not self.report else [bounds[c:c + 1] for c in range(n_pieces)]
        self.t, self.W, self.Wf, self.E, self.n_events, self.n_iter = 0.0, 0.0, 0.0, 0.0, 0, 0
        self.n_stuck = 0
        self.n_passed = 0  # states passed through without their tables (_pass_through)
        # the states this run has run in by their closed form: with pass-through the kernels return NEW_STATE on
        # entering any other, so that which states are passed through depends on this run alone, not on the
        # states earlier runs built (the same bits whatever ran before, in this process or another)
        self.entered = np.zeros(table.states.S, bool)
        self.g = 0
        self.runs: list = []
        self.c = 0
        self.fargs: tuple = ()
        cap = options.log_events
        N = self.y.size
        if getattr(self, "log", None) is None or self.log[0].shape[0] != cap:  # a restart's (_start) is reused:
            # the kernels write it from n_log = 0 on, and :attr:`events` copies what they wrote
            self.log = (np.zeros(cap), np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros((cap, N)))
        self.n_log = 0
        self.carry = np.zeros(5, np.int64)  # the kernels' memory of the last switch, kept over a NEW_STATE return
        self.rows: SampleRows | None = None
        self.finished = False

    def sample_rows(self, every: int, R: np.ndarray) -> None:
        """As :meth:`reduced.transient.exact.ExactStepper.sample_rows`, R (r, 2n + p) on y = [x; v; w]: the
        whole state, the works and the sliders at every ``every``-th sample only (the same bits as without rows),
        R y at every sample (:func:`reduced.transient._friction_kernels._friction_free_kernel`)."""
        self.rows = SampleRows(every, R, self.lazy.row_tables, self.sample_rate_hz)

    def _table_stats(self) -> None:
        """The tables' statistics over the states built so far (the time to build them in this run included)."""
        table = self.table
        self.stats.update({"n_states_built": int(np.count_nonzero(self.lazy.built)), "table_s": self.table_s,
                           "cond_V": float(np.max(table.cond)),
                           "max_growth_per_s": float(max(np.max(table.lam.real), 0.0))})

    @property
    def events(self) -> FrictionEvents | None:
        """The event log (None when none was asked for)."""
        if not self.options.log_events:
            return None
        k = min(self.n_log, self.options.log_events)
        t, e, s, y = (a[:k].copy() for a in self.log)
        # the kind of an event is that of its slot in the state it left
        before = np.concatenate([[self.s0], s[:-1]]).astype(np.int64)
        kinds = self.table.ekind[before, e]
        return FrictionEvents(t, e, np.array([EVENT_KINDS[int(q)] for q in kinds]), s, y, self.n_log, self.table)

    def _scales(self, omega_max: float) -> tuple[float, float]:
        """(floor, load_scale) in m, as :meth:`reduced.transient.exact.ExactStepper._scales`."""
        system, n, y = self.run_system, self.n, self.y
        x_scale = np.abs(system.B) @ (np.abs(y[:n]) + np.abs(y[n:2 * n]) / omega_max)
        load_scale = 0.0
        if self.forced:
            pmax = np.array([s.work_scale() for s in self.loads.signals])
            x_scale = x_scale + np.abs(system.B) @ (np.abs(self.ft.Sb[0]) @ pmax)
            load_scale = float(np.max(np.abs(self.ft.Sb[0]) @ pmax))
        return REST_FLOOR * float(np.max(x_scale, initial=0.0)), load_scale

    def _runs(self, t: float, bound: float) -> list:
        """[(t_a, t_b, pieces or None)]: [t, bound) cut where the loads start or stop being all zero."""
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
        return _without_slivers(out)

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        out = np.empty((k, self.y.size)), np.empty(k), np.empty(k), np.empty(k if self.forced else 0)
        return out if self.rows is None else (*out, np.empty((k, self.rows.R.shape[0])))

    def block(self, buf: _stepper.Buffer) -> tuple[np.ndarray, ...]:
        out_y, out_W, out_Wf, out_E = buf.arrays[:4]
        if not np.all(np.isfinite(out_y)):
            raise ExactIntegratorError("non-finite state: the friction states are ill-conditioned")
        n = self.n
        ext = out_E if self.forced else zeros_view(out_y.shape[0])
        return out_y[:, :n], out_y[:, n:2 * n], out_W, ext, out_y[:, 2 * n:], out_Wf

    def step(self, buf: _stepper.Buffer) -> float | None:
        """One kernel call: the present run from where it stands, until its end or the buffer is full."""
        if not self.runs:
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
        if starts is not None:
            self.fargs = forced_arrays(self.ft, self.loads.pieces_at(starts))

    def _call(self, buf: _stepper.Buffer) -> int:
        """The kernel of the present run on ``buf``, resumed after building each state it enters for the first
        time (``NEW_STATE``); the state advanced; returns the kernel's status."""
        c = self.carry
        c[:] = -1, -1, -1, self.s, 0  # no switch remembered (hold, last slot, fresh slider, state before, trend)
        filled = buf.filled
        while True:
            status = self._call_once(buf)
            if status != NEW_STATE:
                break
            t0 = time.perf_counter()
            if self.runs[0][2] is None:
                if self.pass_through and self._pass_through(buf):
                    self.table_s += time.perf_counter() - t0
                    continue
                self.lazy.ensure(self.s)
                self.entered[self.s] = True
            else:
                self.forced_table.ensure(self.s)
            self.table_s += time.perf_counter() - t0
            self._table_stats()
        if self.runs[0][2] is None:
            buf.arrays[3][filled:buf.filled] = self.E  # a free stretch of a forced run: the loads' work stays
        elif self.rows is not None:  # a forced stretch samples the whole state: its rows from it
            buf.arrays[4][filled:buf.filled] = buf.arrays[0][filled:buf.filled] @ self.rows.R.T
        return status

    def _pass_through(self, buf: _stepper.Buffer) -> bool:
        """On a free run's return NEW_STATE: the state entered passed through to its first event by the flow's
        Taylor series (:func:`reduced.transient.friction_probe.pass_through`) when that event is within the
        reach and clear of every decision the kernel makes by its round-off rules; then the switch, the works,
        the log and the kernel's memory of the switch (``carry``) as the kernel would leave them, and True. False
        (nothing changed) where the state must be built."""
        hold, e_prev, fresh, _, _ = (int(v) for v in self.carry)
        g = self.groups[self.g]
        t_end = float(g[self.c]) if len(g) > 1 else float(self.runs[0][1])
        t_next_sample = float(buf.t[buf.filled]) if buf.filled < buf.k else float(buf.t_after)
        reach = min(REACH_OMEGA_TAU / self.omega_max, t_end - self.t, t_next_sample - self.t)
        if self.n_events + 1 >= self.options.max_events:
            return False
        self.lazy.link(self.s)
        res = pass_through(self.run_system, self.table, self.lazy._Minv, self.s, self.y, reach, fresh, hold,
                           self.hmin)
        if res is None:
            return False
        t = self.t + res.tau
        if not (t < t_end and t < t_next_sample):
            return False
        y = res.y.copy()
        s_new, dWf = switch(self.run_system, self.table, self.s, res.slot, y, self.fric)
        m = self.run_system.m
        e = res.slot
        self.W += res.dW
        self.Wf += res.dWf + dWf
        self.carry[:] = (e if (e == e_prev and e >= m) else -1), e, (e if e >= m else -1), self.s, 1
        self.t, self.y, self.s = t, y, s_new
        self.n_stuck = 0
        if self.n_log < self.log[0].shape[0]:
            self.log[0][self.n_log], self.log[1][self.n_log], self.log[2][self.n_log] = t, e, s_new
            self.log[3][self.n_log] = y
        self.n_log += 1
        self.n_events += 1
        self.n_passed += 1
        self.stats.update(n_events=self.n_events, n_steps=self.n_events + 1, n_passed=self.n_passed)
        return True

    def _call_once(self, buf: _stepper.Buffer) -> int:
        """One kernel call of the present run on ``buf`` (the state advanced); returns its status."""
        _, t_b, starts = self.runs[0]
        g = self.groups[self.g]
        out_y, out_W, out_Wf, out_E = buf.arrays[:4]
        left = self.options.max_events - self.n_events
        modal, events, wv, wf, built = self.lazy.arrays()
        if self.pass_through:
            built = self.entered
        if starts is None:
            bounds = g if len(g) > 1 else np.array([t_b])
            S, Kmax = modal[1].shape
            acq = no_rows(S, Kmax, out_y.shape[1]) if self.rows is None else self.rows.acq(S, Kmax, buf.arrays[4])
            (self.t, self.W, self.Wf, self.s, buf.filled, ne, ni, status, self.n_stuck, self.c,
             self.n_log) = call_numba_kernel(
                _friction_free_kernel, modal, events, wv, wf, self.fric, self.damped, self.n, self.y, self.s, self.t,
                bounds, self.c, buf.t, buf.filled, buf.t_after, out_y, out_W, out_Wf, self.W, self.Wf, self.hmin,
                self.floor, left, self.n_stuck, *self.log, self.n_log, built, self.carry, float(self.sample_rate_hz),
                acq)
        else:
            tb = self.table
            (self.t, self.W, self.Wf, self.E, self.s, buf.filled, ne, ni, status,
             self.n_stuck, self.n_log) = call_numba_kernel(
                _friction_forced_kernel, tb.lam, tb.V, tb.Vinv, tb.yp, tb.erow, tb.ec, tb.eact, tb.succ, tb.reset,
                tb.Df, tb.LF, events[7], modal[8], self.run_system.C, self.damped, self.n, self.fric, self.y, self.s,
                self.t, t_b,
                buf.t, buf.filled, buf.t_after, out_y, out_W, out_Wf, self.W, self.Wf, self.hmin, self.floor, left,
                self.n_stuck, *self.fargs, out_E, self.E, *self.log, self.n_log, self.forced_table.built, self.carry)
        self.n_events += ne
        self.n_iter += ni
        self.stats.update(n_events=self.n_events, n_steps=self.n_events + 1, n_march=self.n_iter)
        return status

    def tolerance(self, amp: float) -> float:
        return float(np.max(self.table.cond)) * EPS * max(amp, self.offset_max, self.load_scale)


_stepper.FRICTION_STEPPERS["exact"] = FrictionExactStepper


class FrictionFlow:
    """The exact friction flow of one system under harmonic loads b P cos(2 pi f t + phi) of one direction and
    amplitude, for many short runs: the lean entry point of the shooting methods
    (:mod:`reduced.periodic.friction_shooting`, :mod:`reduced.periodic.friction_continuation`), which run it
    thousands of times over a fraction of a period from states and at frequencies that change between calls.

    Each call is :func:`integrate_exact_friction` from y = [x; v; w] at t0 with the load's phase phi + 360 f t0
    and ``chunks=1``, to the bit (tests/test_friction_flow.py): the same stepper (:class:`FrictionExactStepper`)
    and kernels, but the system is checked and folded, omega_max computed and the friction tables looked up once
    (in the first call), and the loads' forced table (which depends on b and f, not on P, the phase or the start)
    once a frequency, the last ``FORCED_KEPT`` frequencies' kept; a call sets up only the run's own state
    (:meth:`FrictionExactStepper._start`) and drives the stepper on one buffer, with no stream, result object or
    event-log copies. A forced table keeps the states it built from call to call (a state's data never changes once
    built), so later calls do not stop to build them. The public ringdown API (:func:`integrate_exact_friction`)
    keeps its checks on every call; this one checks the system, the load and the grid.

    Parameters
    ----------
    system : GapSystem
        With friction.
    b : (n,) the load direction
    amplitude_N : N, P
    log_events : events kept in the log of each call (:attr:`events`), 0 for none
    """

    FORCED_KEPT = 4  # frequencies whose forced tables are kept (a continuation point: the corrector's, f and f + df)

    def __init__(self, system: GapSystem, b, amplitude_N: float, *, log_events: int = 0) -> None:
        from reduced.models.loads import Harmonic, Loads

        _check.gap_system(system)
        if system.friction is None:
            raise _check.InvalidArgument("system has no friction: use reduced.transient.exact.integrate_exact")
        self.system, self.n = system, system.n
        self.b = np.atleast_2d(_check.vector("b", b, system.n))
        self.amplitude_N = _check.number("amplitude_N", amplitude_N)
        self._loads = lambda f, phase: Loads(self.b, (Harmonic(self.amplitude_N, f, phase),))
        _check.loads(self._loads(1.0, 0.0), self.n)
        self.options = ExactFrictionOptions(1, MAX_EVENTS, None, log_events).checked(system)
        self._stepper: FrictionExactStepper | None = None
        self._forced: OrderedDict = OrderedDict()  # freq_hz -> LazyForcedTable
        self.calls = 0

    def __call__(self, freq_hz: float, y: np.ndarray, t0: float, duration_s: float, samples: int = 1,
                 phase_deg: float = 0.0) -> np.ndarray:
        """(samples + 1, 2n + p) [x, v, w] at t0 + j duration_s / samples, j = 0..samples, from y (2n + p,) m, m/s,
        m at t0 s over ``duration_s`` s under b P cos(2 pi f t + phi), f = ``freq_hz`` Hz, phi = ``phase_deg``
        degrees (as :func:`reduced.periodic.friction_shooting.flow`).

        Raises
        ------
        reduced._checks.InvalidArgument
            y not finite or not of 2n + p values.
        ExactIntegratorError
            As :func:`integrate_exact_friction`, or where the grid is not samples + 1 points.
        """
        from reduced.transient.result import sample_count

        n = self.n
        loads = self._loads(freq_hz, phase_deg + 360.0 * freq_hz * t0)
        fs = samples / duration_s
        N = sample_count(duration_s, fs)
        if N != samples + 1:
            raise ExactIntegratorError(f"{N} samples where {samples + 1} were asked")
        y = np.asarray(y, float)
        if y.shape != (2 * n + self.system.p,) or not np.all(np.isfinite(y)):
            raise _check.InvalidArgument(f"y must be finite, of shape ({2 * n + self.system.p},), got {y.shape}")
        x0, v0, w0 = (np.array(y[:n], float), np.array(y[n:2 * n], float), np.array(y[2 * n:], float))
        st = self._stepper
        if st is None:
            st = self._stepper = FrictionExactStepper(self.system, x0, v0, duration_s, N, fs,
                                                      ExactFrictionOptions(1, self.options.max_events, tuple(w0),
                                                                           self.options.log_events), loads, False)
            self._forced[freq_hz] = st.forced_table
        else:
            ft = self._forced.get(freq_hz)
            if ft is None:
                ft = self._forced[freq_hz] = LazyForcedTable(st.lazy, loads)
                while len(self._forced) > self.FORCED_KEPT:
                    self._forced.popitem(last=False)
            else:
                self._forced.move_to_end(freq_hz)
            st.forced_table, st.ft = ft, ft.table
            st._start(x0, v0, w0, duration_s, N, fs, loads)
        self.calls += 1
        buf = _stepper.Buffer(0, N, N, fs, st.arrays(N))
        while not st.finished:
            st.step(buf)
        if not buf.full:
            raise RuntimeError(f"internal: {N - buf.filled} exact samples not filled")
        out = buf.arrays[0]
        if not np.all(np.isfinite(out)):
            raise ExactIntegratorError("non-finite state: the friction states are ill-conditioned")
        return out

    @property
    def events(self) -> FrictionEvents | None:
        """The last call's event log (None before a call or without ``log_events``)."""
        return None if self._stepper is None else self._stepper.events


def stream_exact_friction(system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, *, w0=None,
                          loads=None, chunks: int = PIECES, max_events: int = MAX_EVENTS, log_events: int = 0,
                          chunk_samples: int | None = None, progress=None) -> RingdownStream:
    """Exact response of a system with friction from (x0, v0, w0), chunk by chunk (:func:`integrate_exact_friction`).

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz : as :func:`integrate_exact_friction`
    w0, loads, chunks, max_events, log_events, progress : as :func:`integrate_exact_friction`
    chunk_samples : samples a chunk (default: the whole run in one)

    Returns
    -------
    RingdownStream
    """
    _check.gap_system(system)
    if system.friction is None:
        raise _check.InvalidArgument("system has no friction: use reduced.transient.exact.stream_exact")
    return _stepper.run(FrictionExactStepper, system, x0, v0, duration_s, sample_rate_hz,
                        ExactFrictionOptions(chunks, max_events, w0, log_events), loads, progress, chunk_samples)


def integrate_exact_friction(system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, *, w0=None,
                             loads=None, chunks: int = PIECES, max_events: int = MAX_EVENTS, log_events: int = 0,
                             progress=None) -> RingdownResult:
    """Exact (event-driven, closed-form) response of a system with friction, free or forced.

    M x'' + C x' + K x + B^T f(B x) + Bt^T f_t = sum_l b_l p_l(t), f_t the sliders' forces (stick:
    kt (Bt x - w); slip: +-mu N), each friction state solved in closed form between its events
    (module docstring).

    Parameters
    ----------
    system : GapSystem
        With friction.
    x0, v0 : (n,) array_like of float
        m and m/s.
    duration_s, sample_rate_hz : float
        s and Hz.
    w0 : (p,) array_like of float, optional
        m, the sliders' initial positions (default Bt x0: unloaded).
    loads : Loads, optional
        External loads (as :func:`reduced.transient.exact.integrate_exact`).
    chunks, max_events : int
        As :func:`reduced.transient.exact.integrate_exact`.
    log_events : int
        Events kept in ``result.events`` (:class:`FrictionEvents`), 0 for none.
    progress : callable, optional
        Called with the fraction done.

    Returns
    -------
    RingdownResult
        With ``w`` (N, p), ``friction`` (N,) the friction work, ``dissipated`` the viscous and friction work.
    """
    return stream_exact_friction(system, x0, v0, duration_s, sample_rate_hz, w0=w0, loads=loads, chunks=chunks,
                                 max_events=max_events, log_events=log_events, progress=progress).collect()


@dataclass(frozen=True, slots=True)
class ExplicitFrictionOptions:
    """Options of central difference with friction.

    Parameters
    ----------
    dt, omega_dt, step_basis, chunks : as :class:`reduced.transient.explicit.ExplicitOptions`
    w0 : m, the sliders' initial positions (p,), or None: unloaded, w(0) = Bt x(0)
    """

    dt: float | None = None
    omega_dt: float = DEFAULT_OMEGA_DT
    step_basis: str = "top"
    chunks: int = PIECES
    w0: tuple | None = None

    def checked(self, system: GapSystem) -> ExplicitFrictionOptions:
        """These options validated (ValueError naming the first bad one)."""
        e = ExplicitOptions(self.dt, self.omega_dt, self.step_basis, self.chunks).checked(system)
        w0 = None if self.w0 is None else tuple(_check.vector("w0", self.w0, system.p))
        return ExplicitFrictionOptions(e.dt, e.omega_dt, e.step_basis, e.chunks, w0)


class FrictionExplicitStepper(ExplicitStepper):
    """Central difference with friction: :class:`reduced.transient.explicit.ExplicitStepper`'s scheme with the
    sliders' forces by a return mapping at each step (:func:`reduced.transient._friction_kernels._cd_friction_kernel`).

    Stability: the sticking tip is a linear spring kt Bt^T Bt, so the stiffest state is every tip closed and
    sticking, K + sum k_g B^T B + sum kt Bt^T Bt (:meth:`reduced.models.gaps.GapSystem.closed_stiffness`), and
    the step is refused beyond ``SWITCHING_SAFETY`` x 2 / omega_max of that state (with damping, as without
    friction). A slipping tip is softer (its friction force follows N, not the tangential motion), and the
    return mapping only takes energy out of the slider, so the sticking state sets the limit: central
    difference grows just past omega_max dt = 2 with the tips held closed and sticking, and stays bounded just
    below it (tests/test_friction.py).

    Parameters
    ----------
    As :class:`reduced.transient.explicit.ExplicitStepper`; ``options`` an ExplicitOptions or an
    :class:`ExplicitFrictionOptions` (with ``w0``).
    """

    friction = True

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options, loads, report: bool) -> None:
        if isinstance(options, ExplicitOptions):
            options = ExplicitFrictionOptions(options.dt, options.omega_dt, options.step_basis, options.chunks)
        self.w0 = _unloaded(system, x0, options.w0)
        super().__init__(system, x0, v0, duration_s, n_samples, sample_rate_hz, options, loads, report)
        self.stats["n_sliders"] = system.p

    def _matrices(self) -> None:
        """As :meth:`ExplicitStepper._matrices`, the generic kernel always, with (dt G Bt^T)^T for the sliders."""
        system, n, dt = self.system, self.n, self.dt
        fr = system.friction
        M, C, K = system.M, system.C, system.K
        G = np.linalg.inv(M + 0.5 * dt * C)
        A = G @ (M - 0.5 * dt * C)
        c = np.ascontiguousarray
        self.L = L = _damping_factor(C)
        b = c(self.loads.b) if self.forced else np.zeros((0, n))
        self.small = False
        self.kernel = _cd_friction_kernel
        self.mats = (c(A.T), c((dt * (G @ K)).T), c((dt * (G @ system.B.T)).T), c(L.T), c(system.B), system.offset,
                     system.side, system.k, c((dt * (G @ fr.Bt.T)).T), c(fr.Bt), c(fr.tip), c(system.tip), c(fr.stop),
                     fr.mu, fr.k_t)
        self.dtGbT, self.b = c((dt * (G @ b.T)).T), b

    def _first_state(self, x0: np.ndarray, v0: np.ndarray) -> None:
        """x_0, v_{1/2} = v_0 + dt/2 a_0 with the sliders' forces at x_0 (on the cone), the work sums' first terms."""
        system, dt, fr = self.system, self.dt, self.system.friction
        x, v = x0.copy(), v0.copy()
        self.x0, self.v0 = x0.copy(), v0.copy()
        N = np.zeros(fr.p)
        f = system.stop_force(x0)
        eng = fr.engages(system.tip)
        for q in range(fr.p):
            N[q] = f[eng[q]].max(initial=0.0)
        ft = np.clip(fr.force(x0, self.w0), -fr.mu * N, fr.mu * N)
        rhs0 = -(system.K @ x) - system.contact_force(x) - fr.Bt.T @ ft - system.C @ v
        if self.forced:
            f0 = self.loads.force(0.0)
            rhs0 = rhs0 + f0
        a0 = np.linalg.solve(system.M, rhs0)
        self.x, self.vh, self.w, self.ft = x, v + 0.5 * dt * a0, self.w0.copy(), ft
        self.W, self.pw, self.Wf = 0.0, float(np.sum((v @ self.L) ** 2)), 0.0
        self.E, self.pe = 0.0, (float(v @ f0) if self.forced else 0.0)

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        p = self.system.p
        return (np.empty((k, self.n)), np.empty((k, self.n)), np.empty(k), np.empty(k if self.forced else 0),
                np.empty((k, p)), np.empty(k))

    def block(self, buf) -> tuple[np.ndarray, ...]:
        out_x, out_v, out_W, out_E, out_w, out_Wf = buf.arrays
        return out_x, out_v, out_W, (out_E if self.forced else zeros_view(out_x.shape[0])), out_w, out_Wf

    def step(self, buf) -> float | None:
        """Sample 0 (the initial state) or one kernel call of whole output intervals."""
        out_x, out_v, out_W, out_E, out_w, out_Wf = buf.arrays
        N = self.n_samples
        if buf.j0 == 0 and buf.filled == 0:
            out_x[0], out_v[0], out_W[0], out_w[0], out_Wf[0] = self.x0, self.v0, 0.0, self.w0, 0.0
            if self.forced:
                out_E[0] = 0.0
            buf.filled = 1
            if N == 1:
                self.finished = True
                return 1.0
            if buf.full:
                return None
        nout = min(buf.k - buf.filled, self.per_piece - self.done % self.per_piece)
        P = np.zeros((0, 0))
        if self.forced:
            nout = min(nout, max(1, LOAD_BLOCK_STEPS // self.every))
            steps = self.done * self.every + np.arange(1, nout * self.every + 1)
            P = np.ascontiguousarray(self.loads.values(steps * self.dt))
        self.W, self.pw, self.Wf, buf.filled, self.E, self.pe = call_numba_kernel(
            self.kernel, *self.mats, self.x, self.vh, self.w, self.ft, self.dt, nout * self.every, self.every, out_x,
            out_v, out_W, out_w, out_Wf, self.W, self.pw, self.Wf, buf.filled, self.dtGbT, self.b, P, out_E, self.E,
            self.pe)
        self.done += nout
        if not np.all(np.isfinite(self.x)):
            raise FloatingPointError(
                f"central difference diverged before t = {self.done * (1.0 / self.sample_rate_hz):.4g} s "
                f"(dt = {self.dt:.3g} s)")
        self.finished = self.done == N - 1
        if self.done % self.per_piece == 0 or self.finished:
            return self.done / (N - 1)
        return None


_stepper.FRICTION_STEPPERS["explicit"] = FrictionExplicitStepper


REFERENCE_NEWTON = 3  # Newton corrections of a reference event's time (the dense output locates it first)
REFERENCE_EVENT_TOL = 1e-11  # x the run's displacement scale: an event function starting this near zero is
# armed at this level (a function that starts at its threshold, as a closing stop's unloaded slider does, would
# otherwise fire again at once)


def _physics(system: GapSystem, closed: np.ndarray, slip: np.ndarray):
    """(forces, events) of one friction state written from the physics, independently of the tables:
    forces(x, v, w) -> (contact force on x (n,), slider forces f (p,), slider rates w' (p,)); events: [(name,
    g(x, v, w)) ...], each firing when g rises through zero."""
    fr = system.friction
    B, k, o, side, tip = system.B, system.k, system.offset, system.side, system.tip
    stop_of = fr.engaged_by(tip, closed)

    def forces(x, v, w):
        fc = np.zeros(system.n)
        for j in np.flatnonzero(closed):
            fc += k[j] * (B[j] @ x - o[j]) * B[j]
        f = np.zeros(fr.p)
        wd = np.zeros(fr.p)
        for q in range(fr.p):
            j, b = stop_of[q], fr.Bt[q]
            if j < 0:
                wd[q] = b @ v  # an open tip's slider follows
            elif slip[q] == 0:
                f[q] = fr.k_t[q] * (b @ x - w[q])
            else:  # w = t - sigma mu N / kt
                N = k[j] * side[j] * (B[j] @ x - o[j])
                f[q] = slip[q] * fr.mu[q] * N
                wd[q] = b @ v - slip[q] * fr.mu[q] * k[j] * side[j] * (B[j] @ v) / fr.k_t[q]
        return fc, f, wd

    events = []
    for j in range(system.m):
        sgn = -1.0 if closed[j] else 1.0
        events.append((("gap", j), lambda x, v, w, j=j, sgn=sgn: sgn * side[j] * (B[j] @ x - o[j])))
    for q in range(fr.p):
        j = stop_of[q]
        if j < 0:
            continue
        if slip[q] == 0:
            for sg in (1, -1):
                events.append((("slip", q, sg), lambda x, v, w, q=q, j=j, sg=sg: (
                    sg * (fr.Bt[q] @ x - w[q]) - fr.mu[q] * k[j] * side[j] * (B[j] @ x - o[j]) / fr.k_t[q])))
        else:
            events.append((("stick", q), lambda x, v, w, q=q, forces=forces: -slip[q] * forces(x, v, w)[2][q]))
    return forces, events


def _reference_switch(system: GapSystem, closed, slip, what, x, v, w) -> tuple:
    """The friction state after event ``what`` at (x, v, w), from the physics: a closing starts the
    sliders it engages unloaded (w = t) and sticking unless the spring force leaves the cone at once (its rate
    +-kt t' - mu N' > 0 with w' = 0), then slipping that way."""
    fr = system.friction
    closed, slip, w = closed.copy(), slip.copy(), w.copy()
    if what[0] == "gap":
        j = what[1]
        mine = fr.engages(system.tip)[:, j]
        if closed[j]:
            closed[j] = False
            slip[mine] = 0
        else:
            closed[system.tip == system.tip[j]] = False
            closed[j] = True
            for q in np.flatnonzero(mine):
                w[q] = fr.Bt[q] @ x
                dN = fr.mu[q] * system.k[j] * system.side[j] * (system.B[j] @ v)
                rate = fr.k_t[q] * (fr.Bt[q] @ v)
                slip[q] = 1 if rate - dN > 0.0 else (-1 if -rate - dN > 0.0 else 0)
    elif what[0] == "slip":  # on the cone (the event is located to the integrator's tolerance)
        q = what[1]
        slip[q] = what[2]
        j = fr.engaged_by(system.tip, closed)[q]
        w[q] = fr.Bt[q] @ x - what[2] * fr.mu[q] * system.k[j] * system.side[j] * (system.B[j] @ x
                                                                                  - system.offset[j]) / fr.k_t[q]
    else:
        slip[what[1]] = 0
    return closed, slip, w


def _land_on_event(rhs, t0: float, z0: np.ndarray, t_e: float, g, rtol: float, atol: np.ndarray) -> np.ndarray:
    """[z(t_e); t_e]: the leg integrated from (t0, z0) to the event time t_e, and t_e corrected by Newton's
    rule on the event function g (g' by a centred difference of g along the flow) until it is at its root."""
    from scipy.integrate import solve_ivp

    z = z0
    for _ in range(REFERENCE_NEWTON):
        z = solve_ivp(rhs, (t0, t_e), z0, method="DOP853", rtol=rtol, atol=atol).y[:, -1]
        h = 1e-7 * max(t_e - t0, 1e-12)
        dz = rhs(t_e, z)
        dg = (g(t_e, z + h * dz) - g(t_e, z - h * dz)) / (2.0 * h)
        step = -g(t_e, z) / dg if dg != 0.0 else 0.0
        if not np.isfinite(step) or abs(step) > 0.5 * (t_e - t0) or abs(step) <= 4 * EPS * max(t_e, 1e-300):
            break
        t_e = t_e + step
    return np.concatenate([z, [t_e]])


def _initial_states(system: GapSystem, x0: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(closed stops, slider codes) at the start, from the physics (as :func:`initial_friction_state`): at each
    tip the deepest penetrating stop closed (the first of equals), a slider engaged by a closed stop slipping
    (sign of its force) where |k_t (Bt x - w)| > mu k_j pen_j. The same decisions on the same numbers as
    the numpy form it replaced (tests/test_friction_flow.py), with the system's tips and engagements
    worked out once (:func:`_start_layout`): each exact flow run starts here."""
    fr = system.friction
    pen = system.penetration(x0)
    by_tip, engages, mu_k = _start_layout(system)
    pl = pen.tolist()
    closed = np.zeros(system.m, bool)
    for js in by_tip:
        best = -1
        for j in js:
            if pl[j] > 0.0 and (best < 0 or pl[j] > pl[best]):
                best = j
        if best >= 0:
            closed[best] = True
    slip = np.zeros(fr.p, np.int8)
    f0 = fr.force(x0, w0).tolist()
    for q, stops in enumerate(engages):
        j = next((j for j in stops if closed[j]), -1)
        if j >= 0 and abs(f0[q]) > mu_k[q][j] * pl[j]:
            slip[q] = 1 if f0[q] > 0 else -1
    return closed, slip


@functools.lru_cache(maxsize=64)
def _start_layout(system: GapSystem) -> tuple:
    """(stops of each tip (by tip number, ascending stop index), stops engaging each slider (ascending),
    mu_q k_j of each slider q and stop j (float products as numpy makes them)) of ``system``, kept for the
    last 64 systems (by identity: a GapSystem compares and hashes as itself)."""
    fr = system.friction
    by_tip = tuple(tuple(int(j) for j in np.flatnonzero(system.tip == t_)) for t_ in np.unique(system.tip))
    eng = fr.engages(system.tip)
    engages = tuple(tuple(int(j) for j in np.flatnonzero(row)) for row in eng)
    mu_k = tuple(tuple(float(fr.mu[q] * system.k[j]) for j in range(system.m)) for q in range(fr.p))
    return by_tip, engages, mu_k


def _reference_leg(system: GapSystem, closed, slip, loads, t0: float, t_bound: float, z: np.ndarray, rtol: float,
                   atol: np.ndarray, x_scale: float):
    """One leg of :func:`reference_dop853`: (solution or None, event index or -1, leg end, events) of the
    friction state from (t0, z) to the first event or t_bound."""
    from scipy.integrate import solve_ivp

    fr, n, p = system.friction, system.n, system.p
    Minv = np.linalg.inv(system.M)
    forces, events = _physics(system, closed, slip)
    # within one state the physics is affine in y = (x, v, w): sample it at y = 0 and the N unit vectors
    # once (exact to round-off), so each of DOP853's ~10^5 evaluations is a few products, not a Python loop
    N = 2 * n + p
    cols = [np.concatenate(forces(e[:n], e[n:2 * n], e[2 * n:])) for e in np.vstack([np.zeros(N), np.eye(N)])]
    S = np.array(cols).T  # (n + 2p, N + 1): the forces at 0, then at each unit vector
    s0, G = S[:, 0], S[:, 1:] - S[:, :1]
    A = -Minv @ (np.hstack([system.K, system.C, np.zeros((n, p))]) + G[:n] + fr.Bt.T @ G[n:n + p])
    a0 = -Minv @ (s0[:n] + fr.Bt.T @ s0[n:n + p])
    # u = R y + r0 = (v, v', w', f): the state's rate and the slider forces in one product
    R = np.vstack([np.eye(n, N, n), A, G[n + p:], G[n:n + p]])
    r0 = np.concatenate([np.zeros(n), a0, s0[n + p:], s0[n:n + p]])
    C = system.C

    def rhs(t, zz):
        u = R @ zz[:N]
        u += r0
        v, wd, f = u[:n], u[2 * n:N], u[N:]
        if loads is None:
            return np.concatenate([u[:N], (v @ C @ v, f @ wd, 0.0)])
        fe = loads.force(t)
        u[n:2 * n] += Minv @ fe
        return np.concatenate([u[:N], (v @ C @ v, f @ wd, v @ fe)])

    funcs = []
    for _, g in events:
        g0 = g(z[:n], z[n:2 * n], z[2 * n:2 * n + p])
        arm = REFERENCE_EVENT_TOL * x_scale if abs(g0) <= REFERENCE_EVENT_TOL * x_scale else 0.0
        ev = lambda t, zz, g=g, arm=arm: g(zz[:n], zz[n:2 * n], zz[2 * n:2 * n + p]) - arm  # noqa: E731
        ev.terminal, ev.direction = True, 1.0
        funcs.append(ev)
    if t_bound <= t0:
        return None, -1, t0, events, z
    sol = solve_ivp(rhs, (t0, t_bound), z, method="DOP853", rtol=rtol, atol=atol, events=funcs, dense_output=True)
    if sol.status == -1:
        raise RuntimeError(f"DOP853 failed at t = {sol.t[-1]:.6g} s: {sol.message}")
    hits = [(tt[0], i) for i, tt in enumerate(sol.t_events) if tt.size]
    if not hits:
        return sol, -1, t_bound, events, sol.y[:, -1].copy()
    t_e, i = min(hits)
    # the event's state from a step that ends on it (DOP853's dense output is a degree lower than its
    # steps), its time moved by Newton's rule on the event function until it is at its root
    ze = _land_on_event(rhs, t0, z, t_e, funcs[i], rtol, atol)
    return sol, i, float(ze[-1]), events, ze[:-1].copy()


def reference_dop853(system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, *, w0=None, loads=None,
                     rtol: float = 1e-12, max_events: int = 100_000) -> RingdownResult:
    """The response of a system with friction by SciPy's DOP853, restarted at every state change: the
    independent reference of :class:`FrictionExactStepper`.

    Each leg integrates one friction state's smooth vector field, written from the physics
    (:func:`_physics`: the contact and slider forces, the sliders' rates), with its events (gap crossings,
    |kt (t - w)| reaching mu N, the slip velocity passing zero) located by ``solve_ivp`` on the dense output
    and refined on the steps (:func:`_land_on_event`); the next state is decided from the physics at the
    event (:func:`_reference_switch`), and the run restarts from the state there. The viscous, friction and
    loads' work are integrated as three more states. A load breakpoint also ends a leg. Like ``solve_ivp``
    it sees an event by a sign change between two steps' ends, so a slip shorter than a step (the brief slips
    of a stick whose force a moving load brings back past the cone once a stick period) can pass unseen;
    the exact integrator's march cannot miss one (tests/test_friction.py, the moving belt).

    Parameters
    ----------
    system : GapSystem
        With friction.
    x0, v0 : (n,) array_like of float
        m and m/s.
    duration_s, sample_rate_hz : float
        s and Hz.
    w0 : (p,) array_like of float, optional
        m, the sliders' initial positions (default Bt x0).
    loads : Loads, optional
        External loads.
    rtol : float
        DOP853's relative tolerance (its absolute one: rtol x the scale of each state).
    max_events : int
        Refuse a run with more events than this (RuntimeError).

    Returns
    -------
    RingdownResult
        method 'dop853-restart', with ``w``, ``friction`` and ``events`` (:class:`FrictionEvents`; its
        ``state`` zeros and ``table`` None).
    """
    from reduced.transient.result import sample_count

    _check.gap_system(system)
    n, x0, v0, duration_s, sample_rate_hz = _check.run_args(system, x0, v0, duration_s, sample_rate_hz)
    loads = _check.loads(loads, n)
    p = system.p
    Ns = sample_count(duration_s, sample_rate_hz)
    ts = np.arange(Ns) / sample_rate_hz
    T = float(ts[-1])
    omega = system.omega_max()
    w = _unloaded(system, x0, w0)
    x_scale = max(float(np.max(np.abs(x0))), float(np.max(np.abs(v0))) / omega, float(np.max(np.abs(system.offset))),
                  1e-9)
    atol = rtol * np.concatenate([np.full(n, x_scale), np.full(n, x_scale * omega), np.full(p, x_scale),
                                  np.full(3, max(float(system.energy(x0, v0, w)), 1e-12))])
    breakpoints = loads.breakpoints(T) if loads is not None else np.zeros(0)
    closed, slip = _initial_states(system, x0, w)
    out = np.zeros((Ns, 2 * n + p + 3))
    z = np.concatenate([x0, v0, w, [0.0, 0.0, 0.0]])
    t0, filled, log = 0.0, 0, []
    while True:
        kb = int(np.searchsorted(breakpoints, t0, side="right"))
        t_bound = float(breakpoints[kb]) if kb < breakpoints.size else T
        sol, i, t_end, events, z_end = _reference_leg(system, closed, slip, loads, t0, t_bound, z, rtol, atol,
                                                      x_scale)
        upto = int(np.searchsorted(ts, t_end, side="right"))
        if upto > filled and sol is not None:
            out[filled:upto] = sol.sol(ts[filled:upto]).T
            filled = upto
        z, t0 = z_end, t_end
        if i < 0:
            if t_bound >= T:
                break
            continue
        what = events[i][0]
        ended = 1 if what[0] == "stick" and slip[what[1]] < 0 else 0  # a slip - ends in slot m + 2 q + 1
        E_spring = system.friction.energy(z[:n], z[2 * n:2 * n + p])
        closed, slip, z[2 * n:2 * n + p] = _reference_switch(system, closed, slip, what, z[:n], z[n:2 * n],
                                                             z[2 * n:2 * n + p])
        z[-2] += E_spring - system.friction.energy(z[:n], z[2 * n:2 * n + p])  # released by a slider's jump
        kind = "gap" if what[0] == "gap" else ("stick" if what[0] == "stick" else ("slip+" if what[2] > 0 else "slip-"))
        slot = what[1] if what[0] == "gap" else system.m + 2 * what[1] + (1 if kind == "slip-" else ended)
        log.append((t_end, slot, kind, z[:2 * n + p].copy()))
        if len(log) > max_events:
            raise RuntimeError(f"more than {max_events} events before t = {t0:.6g} s")
    ev = FrictionEvents(np.array([e[0] for e in log]), np.array([e[1] for e in log], np.int64),
                        np.array([e[2] for e in log]), np.zeros(len(log), np.int64),
                        np.array([e[3] for e in log]).reshape(len(log), 2 * n + p), len(log), None)
    Wv, Wf, We = out[:, -3], out[:, -2], out[:, -1]
    return RingdownResult(system=system, t=ts, x=out[:, :n].copy(), v=out[:, n:2 * n].copy(), dissipated=Wv + Wf,
                          method="dop853-restart", tolerance=float(rtol * x_scale),
                          stats={"n_events": len(log), "rtol": rtol}, external=We if loads is not None else None,
                          loads=loads, w=out[:, 2 * n:2 * n + p].copy(), friction=Wf.copy(), events=ev)


class FrictionDop853Stepper(_stepper.Stepper):
    """The 'dop853' method for a system with friction: :func:`reference_dop853` (DOP853 restarted at every
    state change, with rtol of the options), run whole when set up and handed out buffer by buffer.

    Parameters
    ----------
    As :class:`reduced.transient.dop853.Dop853Stepper`; ``options`` a Dop853Options (its rtol; atol is
    rtol x each state's scale, :func:`reference_dop853`).
    """

    method = "dop853"
    friction = True

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options: Dop853Options, loads, report: bool) -> None:
        super().__init__(system, n_samples, sample_rate_hz, loads, report)
        self.res = reference_dop853(system, x0, v0, (n_samples - 1) / sample_rate_hz if n_samples > 1 else duration_s,
                                    sample_rate_hz, loads=loads, rtol=options.rtol)
        self.stats.update(self.res.stats)
        self.events = self.res.events

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        return ()

    def block(self, buf) -> tuple[np.ndarray, ...]:
        r, a, b = self.res, buf.j0, buf.j0 + buf.k
        ext = r.external[a:b] if self.forced else zeros_view(buf.k)
        return r.x[a:b], r.v[a:b], r.dissipated[a:b], ext, r.w[a:b], r.friction[a:b]

    def step(self, buf) -> float | None:
        buf.filled = buf.k
        self.finished = buf.j0 + buf.k >= self.n_samples
        return (buf.j0 + buf.k) / self.n_samples

    def tolerance(self, amp: float) -> float:
        return float(self.res.tolerance + self.res.stats["rtol"] * amp)


_stepper.FRICTION_STEPPERS["dop853"] = FrictionDop853Stepper
