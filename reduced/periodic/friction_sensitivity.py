"""The exact sensitivity of the friction flow: state transition matrices and saltation matrices, no differences.

Within one friction state s (:class:`reduced.transient.friction_tables.FrictionStates`: which stops are closed,
each slider sticking, slipping + or - or following its open tip) the flow of y = [x; v; w] is affine,

    y' = A_s y + c_s + [0; M^-1 b p(t); 0],

so dy(t1)/dy(t0) over a piece of the state is expm(A_s (t1 - t0)). At an event of guard g(y) = 0 (a gap, stick ->
slip on the cone, slip -> stick where the slip velocity passes zero) with reset y+ = R(y-) the sensitivity jumps
by the saltation matrix (Leine & Nijmeijer, Dynamics and Bifurcations of Non-smooth Mechanical Systems, 2004,
eq. 7.20)

    Sal = DR + (f+ - DR f-) n^T / (n^T f-),   n = grad g, f-+ the vector fields before and after,

R the identity except at a closing, where the sliders the stop engages start unloaded (w = Bt x: DR's w rows
[Bt, 0, 0]). A stick -> slip event moves w onto the cone, w + sigma g, which is the identity on g = 0 and gives
the same Sal. The segment's sensitivity is the product of the pieces' exponentials and the events' saltations
in the order the exact integrator met them (its event log: times, new states, states at the events).

A_s and c_s are read off the affine right-hand side written from the physics
(:func:`reduced.transient.friction._physics`, independent of the integrator's tables) at the unit vectors:
exact to round-off, the function being affine. The guard gradients: a gap side_j B_j; a stick ending
sigma Bt_q - mu k_j side_j B_j / k_t (x) and -sigma (w_q); a slip ending the w_q row of A_s (the slip velocity).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.friction import FrictionFlow, _physics, initial_friction_state

LOG_EVENTS = 100_000  # events logged a segment (a segment of T / 8 in contact has tens)


class FlowSensitivity:
    """dy(t0 + h)/dy(t0) of the exact friction flow under b P cos(2 pi f t + phi) (module docstring).

    Parameters
    ----------
    system : GapSystem, with friction
    b : (n,) the load direction
    amplitude_N : N, P
    freq_hz : Hz, f
    phase_deg : degrees, phi
    flows : the lean flow of this system, load direction and amplitude with LOG_EVENTS events logged
        (:class:`reduced.transient.friction.FrictionFlow`; default: one of its own)
    """

    def __init__(self, system: GapSystem, b, amplitude_N: float, freq_hz: float, phase_deg: float = 0.0,
                 flows: FrictionFlow | None = None):
        self.system, self.b = system, np.asarray(b, float)
        self.P, self.f, self.phase = float(amplitude_N), float(freq_hz), float(phase_deg)
        self.flows = FrictionFlow(system, b, amplitude_N, log_events=LOG_EVENTS) if flows is None else flows
        self.n, self.p = system.n, system.friction.p
        self.N = 2 * self.n + self.p
        self.Minv = np.linalg.inv(system.M)
        self._affine: dict = {}

    def affine(self, table, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(A_s (N, N), c_s (N,)) of state s: y' = A_s y + c_s without the load."""
        if s not in self._affine:
            st = table.states
            forces, _ = _physics(self.system, st.closed[s], st.slip[s])
            n, p, sy = self.n, self.p, self.system
            Bt = sy.friction.Bt

            def rhs(y):
                x, v, w = y[:n], y[n:2 * n], y[2 * n:]
                fc, fq, wd = forces(x, v, w)
                return np.concatenate([v, self.Minv @ (-sy.K @ x - sy.C @ v - fc - Bt.T @ fq), wd])

            c = rhs(np.zeros(self.N))
            A = np.column_stack([rhs(e) - c for e in np.eye(self.N)])
            self._affine[s] = (A, c)
            del p
        return self._affine[s]

    def _field(self, table, s: int, y: np.ndarray, t: float, loads) -> np.ndarray:
        A, c = self.affine(table, s)
        out = A @ y + c
        out[self.n:2 * self.n] += self.Minv @ loads.force(t)
        return out

    def _guard(self, table, s_before: int, slot: int, kind: str) -> np.ndarray:
        """(N,) the gradient of the event's guard (module docstring), in the state before it."""
        sy, fr, n = self.system, self.system.friction, self.n
        g = np.zeros(self.N)
        m = sy.m
        if slot < m:
            g[:n] = sy.side[slot] * sy.B[slot]
            return g
        q = (slot - m) // 2
        if kind == "stick":  # a slip ends: the slider's rate passes zero
            return self.affine(table, s_before)[0][2 * n + q].copy()
        sg = 1.0 if kind == "slip+" else -1.0
        j = table.states.stop_of[s_before, q]
        g[:n] = sg * fr.Bt[q] - fr.mu[q] * sy.k[j] * sy.side[j] * sy.B[j] / fr.k_t[q]
        g[2 * n + q] = -sg
        return g

    def _onto_cone(self, table, s: int) -> np.ndarray:
        """(N, N) the start's projection: a slipping slider's w is put on its cone, w = Bt x - sigma mu N / k_t
        (the integrator's slip state carries it so; a w off the cone does not act on x)."""
        sy, fr, n = self.system, self.system.friction, self.n
        DR = np.eye(self.N)
        for q in np.flatnonzero(table.states.slip[s] != 0):
            j, sg = table.states.stop_of[s, q], float(table.states.slip[s, q])
            DR[2 * n + q] = 0.0
            DR[2 * n + q, :n] = fr.Bt[q] - sg * fr.mu[q] * sy.k[j] * sy.side[j] * sy.B[j] / fr.k_t[q]
        return DR

    def segment(self, y0: np.ndarray, t0: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(y(t0 + h) (N,), dy(t0 + h)/dy(t0) (N, N)) from y0 = [x; v; w] at t0 over h s.

        Raises
        ------
        reduced.transient.exact.ExactIntegratorError
            The event log filled (more than LOG_EVENTS events).
        """
        n, sy = self.n, self.system
        loads = Loads(np.atleast_2d(self.b), (Harmonic(self.P, self.f, self.phase + 360.0 * self.f * t0),))
        y1 = self.flows(self.f, y0, t0, h, 1, self.phase)[-1].copy()  # integrate_exact_friction's bits, lean
        ev = self.flows.events
        if ev.n_total > len(ev):
            raise ExactIntegratorError(f"{ev.n_total} events in a segment: the log keeps {len(ev)}")
        table = ev.table
        s = initial_friction_state(sy, table, y0[:n], y0[2 * n:])
        Phi, t_prev = self._onto_cone(table, s), 0.0
        mine = sy.friction.engages(sy.tip)
        for k in range(len(ev)):
            te, ye, s_new = float(ev.t[k]), ev.y[k], int(ev.state[k])
            Phi = expm(self.affine(table, s)[0] * (te - t_prev)) @ Phi
            slot, kind = int(ev.slot[k]), str(ev.kind[k])
            DR = np.eye(self.N)
            if slot < sy.m and table.states.closed[s_new, slot] and not table.states.closed[s, slot]:
                for q in np.flatnonzero(mine[:, slot]):  # a closing: the sliders start unloaded, w = Bt x
                    DR[2 * n + q] = 0.0
                    DR[2 * n + q, :n] = sy.friction.Bt[q]
            # the field before from the state after the reset: the pre-state's open sliders do not act (their
            # w enters no force), so f- is the same at y- and y+
            fm = self._field(table, s, ye, te, loads)
            fp = self._field(table, s_new, ye, te, loads)
            ng = self._guard(table, s, slot, kind)
            den = float(ng @ fm)
            Sal = DR + np.outer(fp - DR @ fm, ng) / den if den != 0.0 else DR
            Phi = Sal @ Phi
            s, t_prev = s_new, te
        Phi = expm(self.affine(table, s)[0] * (h - t_prev)) @ Phi
        return y1, Phi




def segment_blocks(system: GapSystem, b, amplitude_N: float, freq_hz: float, phase_deg: float, Y: np.ndarray,
                   D: np.ndarray, periods: int = 1, flows: FrictionFlow | None = None) -> np.ndarray:
    """(S, N, N) the monodromies of the S segments of an orbit of nodes Y (S, N) = [x; v; w] over ``periods``
    forcing periods, in the shooting's coordinates z = [x; v; Bt x - w] and units D (N,): T_m Phi_k T_m scaled,
    T_m = [[I, 0, 0], [0, I, 0], [Bt, 0, -I]], Phi_k = :meth:`FlowSensitivity.segment` over periods T / S from
    node k at t_k = k periods T / S (exact: state transition and saltation matrices).

    Parameters
    ----------
    system, b, amplitude_N, freq_hz, phase_deg : the system and its load
    Y : (S, N) the nodes
    D : (N,) the units of z
    periods : the orbit's period in forcing periods
    flows : the lean flow with LOG_EVENTS events logged (default: one of its own)

    Returns
    -------
    ndarray
        (S, N, N).
    """
    from reduced._blas import single_thread_blas

    sens = FlowSensitivity(system, b, amplitude_N, freq_hz, phase_deg, flows=flows)
    S = Y.shape[0]
    h = periods / freq_hz / S
    n, N = system.n, D.size
    Tm = np.eye(N)
    Tm[2 * n:, :n] = system.friction.Bt
    Tm[2 * n:, 2 * n:] = -np.eye(system.friction.Bt.shape[0])
    scale = D[None, :] / D[:, None]
    with single_thread_blas():  # small matrices: threads only spin (measured 10 ms an expm at load 10, 20 us alone)
        return np.array([Tm @ sens.segment(Y[k], k * h, h)[1] @ Tm * scale for k in range(S)])


__all__ = ["LOG_EVENTS", "FlowSensitivity", "segment_blocks"]
