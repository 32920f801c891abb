"""Exact flow map of an undamped or damped gap system and its derivative (the monodromy).

Reuses the closed-form state decompositions of :mod:`reduced.transient.exact` (``state_table``):
inside contact state s the state y = [x; v] obeys y' = A_s y + b_s, so over a segment of
length tau

    y(tau) = y_p + Re[ V diag(exp(lambda tau)) V^-1 ] (y(0) - y_p),
    dy(tau)/dy(0) = Re[ V diag(exp(lambda tau)) V^-1 ] = exp(A_s tau).

At a stop crossing the penalty force k (s - o) is zero on both sides, so the vector field
is continuous and the saltation matrix (Leine & Nijmeijer 2004)

    S = I + (f_+ - f_-) n^T / (n^T f_-)

is the identity: the derivative of the flow is the plain product of the segment
exponentials, ``Phi(T) = exp(A_{s_k} tau_k) ... exp(A_{s_1} tau_1)``, exact up to round-off.
(A grazing segment, n^T f_- = 0, changes nothing either, since S = I whatever the
denominator.) Without loads the events are located by the exact integrator's own free kernel
(:func:`reduced.transient._modal._free_kernel`: one march for all stops, in the kept-term modal
form, with no rest floor), which records each segment's state and length, and the Jacobian is
the product of the segment exponentials in numba (:func:`reduced.transient._modal.flow_jacobian`):
about 10 us for a period of the 3-DOF model with 8 events, 3x the old per-stop march with a
Python product. Stops crossing at the same instant are switched one after the other by
zero-length segments (the same exponential, exp(0) = I).

Under external loads (``Flow(system, loads=loads)``, for the Floquet multipliers of a forced
periodic orbit by shooting) the flow runs from the absolute time t0 to t0 + T and each segment
(also cut at the loads' breakpoints) is

    y(tau) = y_part(tau) + exp(A_s tau) (y(0) - y_part(0)),

with the closed-form particular solution y_part of the loads' piece (the module docstring of
:mod:`reduced.transient.exact`). y_part does not depend on y(0), so dy(tau)/dy(0) is still
exp(A_s tau), and the vector field is still continuous at a crossing (the loads do not depend
on the contact state), so the saltation matrix is still I: the Jacobian is the same product of
segment exponentials. The forced flow still marches each stop on its own (:func:`_flow_kernel`,
the forced kernel's segment set-up and root search, :mod:`reduced.transient._exact_kernels`) and
multiplies in Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.transient import _modal
from reduced.transient._exact_kernels import _add_poly, _eval_state, _next_crossing, _segment_arrays, _start_segment
from reduced.transient._modal import QTOL_REL, _state_of
from reduced.transient.exact import HMIN_PERIODS, NO_TAU
from reduced.transient.exact_tables import (
    ExactIntegratorError,
    StateTable,
    forced_arrays,
    forced_table,
    modal_table,
    state_table,
)

# The event march (a step that provably skips no root of q, Newton-like near one) and the
# closed-form evaluation are the exact integrator's own kernels (reduced.transient._exact_kernels);
# the flow passes no round-off noise bound (qnoise = dnoise = 0) and no rest floor.
MAX_SEGMENTS = 100_000  # per call: a hang guard (a period has tens of events)


@nb.njit(cache=True)
def _flow_kernel(lam, V, Vinv, yp, valid, B, offset, side, y, active, T, hmin, seg_state, seg_tau, fz, fY, fU, fb,
                 pstarts, pF, pp0, pp1):
    """March the forced flow from 0 to T; y and active are updated in place. Returns (n_seg, status).

    The loads' pieces start at ``pstarts`` (times from the start of the flow, the first 0) and every
    piece boundary ends a segment; each segment is set up and its first crossing found by the
    exact integrator's kernels (:func:`reduced.transient._exact_kernels._start_segment`,
    :func:`~reduced.transient._exact_kernels._next_crossing`, without round-off noise or rest floor).
    """
    n = B.shape[1]
    N = 2 * n
    X, z, coef, werr, ytmp, ypart, P, Qp, Fs, phi, gam = _segment_arrays(n, fb.shape[0])
    ip = 0
    t = 0.0
    n_seg = 0
    n_zero = 0
    max_seg = seg_state.shape[0]
    while True:
        s = _state_of(active)
        if not valid[s]:
            return n_seg, -2
        ip, t_lim, poly = _start_segment(s, t, T, ip, pstarts, y, yp[s], lam[s], V[s], Vinv[s], fz, fY, fU, pF, pp0,
                                         pp1, n, X, z, P, Fs, phi, gam, werr, ypart, False)
        tau_ev, j_ev, _, status = _next_crossing(B, offset, side, active, yp[s], V[s], X, z, werr, poly, P, Qp, coef,
                                                 t_lim - t, hmin, 0.0, False)
        if status != 0:
            return n_seg, -3
        _eval_state(yp[s], X, z, tau_ev, ytmp)
        if poly:
            _add_poly(P, tau_ev, N, ytmp)
        if j_ev >= 0 and _against_its_rate(B, side, active, j_ev, ytmp):
            # a round-off root next to a crossing just made: not an event; march hmin further
            # in the present state instead
            tau_ev = min(tau_ev + hmin, t_lim - t)
            _eval_state(yp[s], X, z, tau_ev, ytmp)
            if poly:
                _add_poly(P, tau_ev, N, ytmp)
            j_ev = -2
        for r in range(N):
            y[r] = ytmp[r]
        if n_seg >= max_seg:
            return n_seg, -1
        seg_state[n_seg] = s
        seg_tau[n_seg] = tau_ev
        n_seg += 1
        t = t_lim if j_ev == -1 else t + tau_ev
        if j_ev == -2:
            if t >= T:
                break
            continue
        if j_ev < 0:
            if t_lim < T:
                continue  # a load breakpoint: the same contact state, a new piece
            break
        active[j_ev] = not active[j_ev]
        n_zero = n_zero + 1 if tau_ev == 0.0 else 0
        if n_zero > 64:
            return n_seg, -1
        _settle(B, offset, side, active, y, j_ev, n_zero > 4)
    return n_seg, 0


@nb.njit(cache=True)
def _against_its_rate(B, side, active, j, y):
    """Does stop j cross against its own rate at y (closing while separating, or the reverse)?"""
    n = B.shape[1]
    rate = 0.0
    for r in range(n):
        rate += B[j, r] * y[n + r]
    rate = side[j] * rate
    return (rate > 0.0) == active[j] and rate != 0.0


@nb.njit(cache=True)
def _settle(B, offset, side, active, y, j_ev, settle_all):
    """After stop j_ev switched: switch the stops that cross at the same instant (symmetric motions)
    together, each at its threshold (within QTOL_REL) by the sign of its rate; with ``settle_all``
    (after repeated zero-length segments: a stop flipping on round-off at a crossing) set every stop
    from the sign of its penetration, ties by the sign of its rate."""
    n = B.shape[1]
    m = B.shape[0]
    scale = 0.0
    for r in range(n):
        scale += abs(y[r])
    for j in range(m):
        if j == j_ev and not settle_all:
            continue
        pen = 0.0
        rate = 0.0
        for r in range(n):
            pen += B[j, r] * y[r]
            rate += B[j, r] * y[n + r]
        pen = side[j] * (pen - offset[j])
        rate = side[j] * rate
        if abs(pen) <= QTOL_REL * (scale + abs(offset[j])):
            active[j] = rate > 0.0
        elif settle_all:
            active[j] = pen > 0.0


@dataclass(frozen=True, eq=False)
class FlowResult:
    """y(T) and, when asked, dy(T)/dy(0) (the monodromy when T is a period).

    Attributes
    ----------
    y : (2n,) ndarray of float
        [x; v] at the end, m and m/s.
    active : (m,) ndarray of bool
        Contact state at the end.
    jacobian : (2n, 2n) ndarray of float or None
        dy(T)/dy(0), when asked.
    n_events : int
        Contact events crossed.
    segments : (ndarray of int, ndarray of float)
        Contact state index and duration (s) of each segment.
    """

    y: np.ndarray  # (2n,) [x; v] at T
    active: np.ndarray  # (m,) contact state at T
    jacobian: np.ndarray | None  # (2n, 2n)
    n_events: int
    segments: tuple[np.ndarray, np.ndarray]  # (state index, duration) of each segment


class Flow:
    """The exact flow of a gap system: ``Flow(system)(x0, v0, T, jacobian=True)``.

    The state table is decomposed once; each call marches the events with the numba
    kernel and, for the Jacobian, multiplies the segment exponentials (saltation = I).
    With ``loads`` (a :class:`~reduced.models.loads.Loads`), ``flow(x0, v0, T, t0=t0)`` is the
    forced flow from the absolute time t0 to t0 + T; the Jacobian is still the product of the
    segment exponentials, as the particular solution does not depend on y(t0) (module docstring).

    Parameters
    ----------
    system : GapSystem
        The system (every contact state a stable oscillator, as for the exact integrator).
    table : StateTable, optional
        Its state table, if already decomposed.
    loads : Loads, optional
        External loads (the forced flow).

    Raises
    ------
    InvalidArgument
        A system, table or loads of the wrong kind.
    ExactIntegratorError
        A system or load the closed form cannot treat.
    """

    def __init__(self, system: GapSystem, table: StateTable | None = None, loads=None) -> None:
        _check.gap_system(system)
        _check.frictionless(system, "the flow map (shooting)")
        if table is not None and not isinstance(table, StateTable):
            raise _check.InvalidArgument(f"table must be None or a StateTable, got {type(table).__name__}")
        self.loads = _check.loads(loads, system.n)
        self.system = system
        self.table = table or state_table(system)
        self._forced = None if self.loads is None else forced_table(system, self.table, self.loads)
        self._modal = modal_table(system, self.table) if self.loads is None else None
        self._damped = not system.undamped
        self.hmin = HMIN_PERIODS / system.omega_max()
        self._seg_state = np.empty(MAX_SEGMENTS, np.int64)
        self._seg_tau = np.empty(MAX_SEGMENTS)

    def initial_state(self, x0: np.ndarray, v0: np.ndarray) -> np.ndarray:
        return self.system.contact_state(
            x0, v0, atol=QTOL_REL * (np.abs(x0).sum() + np.abs(self.system.offset))
        )

    def segment_exponential(self, s: int, tau: float) -> np.ndarray:
        """exp(A_s tau) (2n, 2n) from the closed form."""
        tb = self.table
        return ((tb.V[s] * np.exp(tb.lam[s] * tau)) @ tb.Vinv[s]).real

    def vector_field(self, y: np.ndarray, active: np.ndarray | None = None, t: float = 0.0) -> np.ndarray:
        """y' = [v; M^-1 (f_ext(t) - C v - K x - B^T f(B x))] (f_ext = 0 without loads)."""
        s = self.system
        n = s.n
        x, v = y[:n], y[n:]
        rhs = -(s.C @ v + s.K @ x + s.contact_force(x))
        if self.loads is not None:
            rhs = rhs + self.loads.force(t)
        a = np.linalg.solve(s.M, rhs)
        return np.concatenate([v, a])

    def __call__(self, x0: np.ndarray, v0: np.ndarray, T: float, jacobian: bool = False,
                 t0: float = 0.0) -> FlowResult:
        """y(t0 + T) from (x0, v0) at t0 (T >= 0 s, t0 >= 0 s, finite) and, with ``jacobian``,
        dy(t0 + T)/dy(t0). Without loads the flow is autonomous and t0 changes nothing."""
        T = _check.number("T", T, lo=0.0, lo_open=False, unit="s")
        t0 = _check.number("t0", t0, lo=0.0, lo_open=False, unit="s")
        jacobian = _check.flag("jacobian", jacobian)
        tb = self.table
        n = self.system.n
        y = np.concatenate([_check.vector("x0", x0, n), _check.vector("v0", v0, n)])
        active = self.initial_state(y[: self.system.n], y[self.system.n :])
        if self.loads is None:
            return self._free(y, active, float(T), jacobian)
        # the pieces on [t0, t0 + T], their starts counted from t0
        bp = self.loads.breakpoints(t0 + T)
        pieces = self.loads.pieces_at(np.concatenate([[t0], bp[bp > t0]]))
        fargs = list(forced_arrays(self._forced, pieces))
        fargs[4] = pieces.starts - t0
        n_seg, status = call_numba_kernel(_flow_kernel,
            tb.lam,
            tb.V,
            tb.Vinv,
            tb.yp,
            tb.valid,
            self.system.B,
            self.system.offset,
            self.system.side,
            y,
            active,
            float(T),
            self.hmin,
            self._seg_state,
            self._seg_tau,
            *fargs,
        )
        _check_status(status, MAX_SEGMENTS, T)
        seg = (self._seg_state[:n_seg].copy(), self._seg_tau[:n_seg].copy())
        J = None
        if jacobian:
            J = np.eye(2 * self.system.n)
            for s, tau in zip(*seg, strict=True):
                J = self.segment_exponential(int(s), float(tau)) @ J
        return FlowResult(y, active, J, n_seg - 1, seg)

    def jacobian_of(self, result: FlowResult) -> np.ndarray:
        """dy(T)/dy(0) of a flow this Flow computed without it: the product of the recorded segments'
        exponentials, the numbers ``jacobian=True`` gives (the same kernel on the same segments), for a caller
        that needs the Jacobian of some of its flows only (e.g. of the Gauss-Newton steps it takes).

        Parameters
        ----------
        result : FlowResult
            A result of this Flow.

        Returns
        -------
        (2n, 2n) ndarray of float
            ``result.jacobian`` if it has one, else the product.
        """
        if result.jacobian is not None:
            return result.jacobian
        states, taus = result.segments
        J = np.eye(2 * self.system.n)
        if self.loads is not None:
            for s, tau in zip(states, taus, strict=True):
                J = self.segment_exponential(int(s), float(tau)) @ J
            return J
        call_numba_kernel(_modal.flow_jacobian, self._modal, states, taus, states.size, J)
        return J

    def _free(self, y: np.ndarray, active: np.ndarray, T: float, jacobian: bool) -> FlowResult:
        """The autonomous flow by the exact integrator's free kernel (:mod:`reduced.transient._modal`:
        one march for all stops, no rest floor), each segment's state and length recorded, and the
        Jacobian as the product of the segment exponentials (:func:`reduced.transient._modal.flow_jacobian`)."""
        sy = self.system
        _, _, _, n_ev, _, status, _, _ = call_numba_kernel(_modal._free_kernel,
            self._modal, sy.offset, sy.side, sy.tip, self._damped, y, active, 0.0, np.array([T]), 0,
            NO_TAU, 0, np.inf, _NO_SAMPLES, NO_TAU, 0.0, self.hmin, 0.0, MAX_SEGMENTS - 1, 0, NO_TAU, 0.0,
            self._seg_state, self._seg_tau)
        _check_status(status, MAX_SEGMENTS - 1, T)
        n_seg = n_ev + 1
        seg = (self._seg_state[:n_seg].copy(), self._seg_tau[:n_seg].copy())
        J = None
        if jacobian:
            J = np.eye(2 * sy.n)
            call_numba_kernel(_modal.flow_jacobian, self._modal, self._seg_state, self._seg_tau, n_seg, J)
        return FlowResult(y, active, J, n_ev, seg)


_NO_SAMPLES = np.zeros((0, 0))
_STATUS = {-2: "the motion reached an infeasible contact state", -3: "event search did not converge",
           -4: "stuck: a stop switching back and forth at one instant"}


def _check_status(status: int, max_events: int, T: float) -> None:
    """Raise ExactIntegratorError for a kernel's failure status (-1: too many events)."""
    if status == -1:
        raise ExactIntegratorError(f"more than {max_events} contact events in {T:.4g} s")
    if status in _STATUS:
        raise ExactIntegratorError(_STATUS[status])


__all__ = ["Flow", "FlowResult"]
