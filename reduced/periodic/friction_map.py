"""The response map with friction at the tips: the period map of the exact friction flow and its exact tangent.

:mod:`reduced.periodic.response_map` classifies each frequency of a stepped sine from a period map (its
Poincare samples, its largest Lyapunov exponent, Newton on the p-period map); :class:`FrictionPeriodMap` is that
period map for a system with Coulomb sliders at its tips (:class:`reduced.models.gaps.Friction`), with the
interface of :class:`reduced.transient.lyapunov.PeriodMap` (``run``, ``sampled``, ``jacobian``, ``norm``,
``norm_matrix``, ``norm_inverse``, ``period_s``), so that :func:`reduced.periodic.response_map.classify` runs on it
unchanged; :func:`friction_response_map` is the sweep.

**The flow.** The state is y = [x; v; w] (w the sliders' positions, N = 2n + p), the period map F(y) the exact
friction flow (:class:`reduced.transient.friction.FrictionFlow`: stick, slip and gap events, each friction state in
closed form) under b P cos(2 pi f t) over T = 1/f. A run of K periods is one call of the flow over K T, sampled S
times a period: the Poincare samples are every S-th sample, the per-period peaks max |r . x| are read on the S + 1
samples of each period (uniform samples only: with S = 64 a smooth peak is within (pi / 64)^2 / 2 = 0.12 % of its
value, a contact peak of a few samples' width can be lower by a few per cent).

**The tangent** (Mueller 1995, Leine & Nijmeijer 2004 eq. 7.20). Within a friction state s the flow is affine,
y' = A_s y + c_s + [0; M^-1 b p(t); 0] (:class:`reduced.periodic.friction_sensitivity.FlowSensitivity.affine`), so a
tangent vector is carried over a piece of length tau by exp(A_s tau) = V_s diag(exp(lambda_s tau)) V_s^-1 (A_s
diagonalised once per state; a state whose eigenvectors are ill-conditioned falls back to scipy's expm), and at
every event of the flow's log (a gap closing or opening, stick -> slip, slip -> stick) it jumps by the saltation
matrix

    Sal = DR + (f+ - DR f-) n^T / (n^T f-),   n = grad g, f-+ the fields before and after, DR the reset,

as in :meth:`FlowSensitivity.segment` (the same guards, fields and resets), applied to the q tangent vectors
(vectors, not matrices: O(N q) a piece where expm of the matrix is O(N^3)).

**The sliders that are not stuck, and the dimension.** A slider whose tip is open has no force and its w follows
its tip (w' = Bt v) until the tip closes, when w is reset to Bt x; a slipping slider's w is on its cone, w = Bt x -
sigma mu N / k_t, a function of x. Only a stuck slider's w is a state of its own: the state space has dimension 2n
+ (sliders stuck), and it changes at the events. In y the other sliders' w are slaved to x, and a tangent vector
is **projected** onto the slaved manifold of the current state, dw_q = Bt_q dx (open) or dw_q = (Bt_q - sigma mu_q
k_j side_j B_j / k_t) dx (slipping), at the start and at every period start (:meth:`FrictionPeriodMap.projection`;
the flow keeps a projected vector projected except after a tip opens with its slider stuck, where the stuck dw
stays in y, moving nothing, until the next period start projects it away or a closing resets it). So a slaved
direction never dominates: in the monodromy (:meth:`FrictionPeriodMap.jacobian`: P Phi P over the periods) each
slaved slider adds a multiplier 0, not the 1 that a w moving nothing would give (a slider open the whole period),
and the largest Lyapunov exponent is the physical one. (A slider stuck the whole period with its tip closed is a
state of its own and has a multiplier 1: any w inside its cone is periodic, a family of orbits.)

**The norm** of the returns and of the tangent's growth: |D dy|^2 = dx^T K dx + dv^T M dv + sum_q k_t (dw_q -
Bt_q dx)^2 (:func:`friction_norm_matrix`): twice the energy of the perturbation of the open structure plus that of
the sliders' springs (0 for an open slider, whose projected dw = Bt dx).

References: R. Mueller, Chaos, Solitons & Fractals 5 (1995) 1671-1681; R. I. Leine, H. Nijmeijer, *Dynamics and
Bifurcations of Non-Smooth Mechanical Systems* (Springer, 2004), ch. 7.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.periodic.friction_sensitivity import LOG_EVENTS, FlowSensitivity
from reduced.periodic.response_map import MapOptions, ResponseMap, map_inputs, sweep
from reduced.periodic.stepped_sine import slowest_decay_rate
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.friction import FrictionFlow, initial_friction_state
from reduced.transient.lyapunov import PeriodRun, energy_norm_matrix

EIG_RTOL = 1e-9  # |V diag(lam) V^-1 - A| / |A| above this (or cond(V) above 1 / this): expm for that state


def friction_norm_matrix(system: GapSystem, omega: float) -> np.ndarray:
    """D (N, N), N = 2n + p: |D dy|^2 = dx^T K dx + dv^T M dv + sum_q k_t,q (dw_q - Bt_q dx)^2 (module docstring);
    the [x; v] block is :func:`reduced.transient.lyapunov.energy_norm_matrix` of the open structure.

    Parameters
    ----------
    system : the gap system with friction
    omega : rad/s, the forcing frequency (used only when K is singular)

    Returns
    -------
    ndarray
        (N, N), invertible (block lower triangular in its w rows).

    Examples
    --------
    >>> from reduced.models.gaps import Friction
    >>> s = GapSystem(M=np.eye(1), C=0.5 * np.eye(1), K=np.eye(1) * 4.0, B=np.eye(1), k=np.array([1e6]),
    ...               offset=np.array([1.0]), side=np.array([1.0]), tip=np.array([0]), dof_names=("x",),
    ...               stop_names=("s",), friction=Friction(np.eye(1), [0], 9.0, 0.3, ("t",)))
    >>> friction_norm_matrix(s, 1.0).tolist()
    [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-3.0, 0.0, 3.0]]
    """
    n, fr = system.n, system.friction
    p = fr.p
    D = np.zeros((2 * n + p, 2 * n + p))
    D[:2 * n, :2 * n] = energy_norm_matrix(system.with_friction(None), omega)
    sq = np.sqrt(fr.k_t)
    D[2 * n:, :n] = -sq[:, None] * fr.Bt
    D[2 * n:, 2 * n:] = np.diag(sq)
    return D


class _States:
    """Per friction state, built once for a system and shared by the period maps of a sweep: A_s, c_s (from
    :meth:`FlowSensitivity.affine`), its eigendecomposition, and the projection onto the slaved manifold."""

    def __init__(self, system: GapSystem, b: np.ndarray, amplitude_N: float) -> None:
        self.system = system
        self.flows = FrictionFlow(system, b, amplitude_N, log_events=LOG_EVENTS)
        self.sens = FlowSensitivity(system, b, amplitude_N, 1.0, flows=self.flows)
        self.n, self.p, self.N = system.n, system.p, 2 * system.n + system.p
        self.load = np.linalg.solve(system.M, np.asarray(b, float)) * float(amplitude_N)
        self._eig: dict = {}
        self._proj: dict = {}
        self._jump: dict = {}
        self.mine = system.friction.engages(system.tip)

    def propagator(self, table, s: int):
        """(idx, lam, V, V^-1, A_r) of state s: idx the coordinates that are states of their own (x, v and the stuck
        sliders' w), A_r = A_s[idx, idx] (the slaved w enter no row of x, v or a stuck w) and its eigendecomposition,
        lam None where its eigenvectors are ill-conditioned (then expm)."""
        got = self._eig.get(s)
        if got is None:
            n, st = self.n, table.states
            idx = np.array([*range(2 * n), *(2 * n + q for q in range(self.p)
                                             if st.stop_of[s, q] >= 0 and st.slip[s, q] == 0)])
            A = self.sens.affine(table, s)[0][np.ix_(idx, idx)]
            lam, V = np.linalg.eig(A)
            ok = np.linalg.cond(V) < 1.0 / EIG_RTOL
            Vinv = None
            if ok:
                Vinv = np.linalg.inv(V)
                ok = np.linalg.norm((V * lam) @ Vinv - A) < EIG_RTOL * max(np.linalg.norm(A), 1e-300)
            got = self._eig[s] = (idx, lam, V, Vinv, A) if ok else (idx, None, None, None, A)
        return got

    def carry(self, table, s: int, tau: float, W: np.ndarray) -> np.ndarray:
        """P_s exp(A_s tau) W: the coordinates of state s carried by A_r, the slaved w then read off x (module
        docstring); tau <= 0: P_s W."""
        P = self.projection(table, s)
        if tau <= 0.0:
            return P @ W
        idx, lam, V, Vinv, A = self.propagator(table, s)
        out = np.zeros_like(W)
        if lam is None:
            out[idx] = expm(A * tau) @ W[idx]
        else:
            out[idx] = (V @ (np.exp(lam * tau)[:, None] * (Vinv @ W[idx]))).real
        return P @ out

    def projection(self, table, s: int) -> np.ndarray:
        """(N, N) P_s: the identity but for each slider not stuck in state s, whose w row is slaved to x (module
        docstring): [Bt_q, 0, 0] (open) or [Bt_q - sigma mu k_j side_j B_j / k_t, 0, 0] (slipping)."""
        P = self._proj.get(s)
        if P is None:
            sy, fr, n = self.system, self.system.friction, self.n
            st = table.states
            P = np.eye(self.N)
            for q in range(self.p):
                j, sg = int(st.stop_of[s, q]), float(st.slip[s, q])
                if j >= 0 and sg == 0.0:
                    continue
                P[2 * n + q] = 0.0
                P[2 * n + q, :n] = fr.Bt[q]
                if j >= 0:
                    P[2 * n + q, :n] -= sg * fr.mu[q] * sy.k[j] * sy.side[j] * sy.B[j] / fr.k_t[q]
            self._proj[s] = P
        return P

    def jump(self, table, s: int, s_new: int, slot: int, kind: str) -> tuple:
        """(DR, n, A_s, c_s, A_new, c_new) of an event (:meth:`FlowSensitivity.segment`'s reset and guard)."""
        key = (s, s_new, slot, kind)
        got = self._jump.get(key)
        if got is None:
            sy, n = self.system, self.n
            DR = np.eye(self.N)
            if slot < sy.m and table.states.closed[s_new, slot] and not table.states.closed[s, slot]:
                for q in np.flatnonzero(self.mine[:, slot]):  # a closing: the sliders start unloaded, w = Bt x
                    DR[2 * n + q] = 0.0
                    DR[2 * n + q, :n] = sy.friction.Bt[q]
            ng = self.sens._guard(table, s, slot, kind)
            got = self._jump[key] = (DR, ng, *self.sens.affine(table, s), *self.sens.affine(table, s_new))
        return got


class FrictionPeriodMap:
    """The exact period map of a system with friction under b P cos(2 pi f t), with its exact tangent (module
    docstring); the interface of :class:`reduced.transient.lyapunov.PeriodMap`.

    Parameters
    ----------
    system : GapSystem
        With friction, damped.
    load : (n,) the force direction b
    amplitude_N : N, P > 0
    freq_hz : Hz, f > 0
    rows : (r, n) monitored rows (default the DOFs)
    states : the per-state data of a sweep (:class:`_States` of this system, b and P), if already built
    norm : (D, D^-1) of :func:`friction_norm_matrix`, if already worked out
    """

    def __init__(self, system: GapSystem, load, amplitude_N: float, freq_hz: float, *, rows=None,
                 states: _States | None = None, norm: tuple | None = None) -> None:
        _check.gap_system(system)
        if system.friction is None:
            raise _check.InvalidArgument("system has no friction: use reduced.transient.lyapunov.PeriodMap")
        b = _check.vector("load", load, system.n)
        P = _check.positive("amplitude_N", amplitude_N, "N")
        self.system = system
        self.freq_hz = float(_check.positive("freq_hz", freq_hz, "Hz"))
        self.period_s = 1.0 / self.freq_hz
        self.states = states if states is not None else _States(system, b, P)
        self.rows = np.eye(system.n) if rows is None else np.atleast_2d(np.asarray(rows, float))
        if norm is None:
            D = friction_norm_matrix(system, 2.0 * math.pi * self.freq_hz)
            norm = (D, np.linalg.inv(D))
        self.norm_matrix, self._norm_inv = norm

    @property
    def norm_inverse(self) -> np.ndarray:
        """(N, N) D^-1."""
        return self._norm_inv

    def norm(self, dy: np.ndarray) -> float:
        """|D dy| (:func:`friction_norm_matrix`)."""
        return float(np.linalg.norm(self.norm_matrix @ dy))

    def run(self, y0, n_periods: int, *, tangent=None, renormalise: bool = True, samples_per_period: int = 64,
            inner_samples: int = 0, record_samples: bool = False, active=None, defer_samples: bool = False
            ) -> PeriodRun:
        """``n_periods`` periods from y0 = [x; v; w] at phase 0 of the load, by one call of the exact friction flow.

        Parameters
        ----------
        y0 : (N,) m, m/s, m
        n_periods : K >= 1
        tangent : (N, q) tangent vectors (None: none), projected at the start (module docstring)
        renormalise : each period, the tangent's QR in the norm D and log |R_ii| recorded; else the product
            P dF^K/dy P W
        samples_per_period : S, uniform samples of each period (the peaks; 0: the period ends only)
        inner_samples, active, defer_samples : accepted for the interface, unused (the flow finds its state from
            y0; the peaks are read on the uniform samples)
        record_samples : keep the samples of r . x

        Returns
        -------
        PeriodRun
            ``n_events`` the flow's events (gap, stick, slip), ``active`` the stops closed at the end.

        Raises
        ------
        ExactIntegratorError
            The flow failed, or its event log overflowed.
        """
        del inner_samples, active, defer_samples
        st, sy = self.states, self.system
        N, n = st.N, sy.n
        y = _check.vector("y0", y0, N).copy()
        K = _check.integer("n_periods", n_periods, lo=1)
        S = _check.integer("samples_per_period", samples_per_period, lo=0)
        m = max(S, 1)
        T = self.period_s
        Y = st.flows(self.freq_hz, y, 0.0, K * T, K * m)
        ev = st.flows.events
        if ev.n_total > len(ev):
            raise ExactIntegratorError(f"{ev.n_total} events in {K} periods: the log keeps {len(ev)}")
        poincare = Y[::m].copy()
        X = Y[:, :n] @ self.rows.T  # (K m + 1, r)
        A = np.abs(X)
        peak = np.maximum(A[:-1].reshape(K, m, -1).max(axis=1), A[m::m])
        samples = X[:-1].reshape(K, m, -1).copy() if record_samples and S else None
        W = np.zeros((N, 0)) if tangent is None else np.array(tangent, float, ndmin=2)
        if W.shape[0] != N:
            raise _check.InvalidArgument(f"tangent must have {N} rows, got shape {W.shape}")
        logs = np.zeros((K, W.shape[1] if renormalise else 0))
        if W.shape[1]:
            W = self._tangent(y, ev, K, W, renormalise, logs)
        closed = sy.penetration(poincare[-1][:n]) > 0.0
        return PeriodRun(poincare, peak, samples, logs, W, closed, K * m + len(ev), len(ev))

    def _tangent(self, y0: np.ndarray, ev, K: int, W: np.ndarray, renormalise: bool, logs: np.ndarray) -> np.ndarray:
        """W carried over the K periods through the events of ``ev`` (module docstring), projected at the start and
        at every period start; renormalised there (QR in the norm D, log |R_ii| into ``logs``) when asked."""
        st, sy = self.states, self.system
        n, T = sy.n, self.period_s
        table = ev.table
        s = initial_friction_state(sy, table, y0[:n], y0[2 * n:])
        W = st.projection(table, s) @ W
        D, Dinv = self.norm_matrix, self._norm_inv
        w_omega = 2.0 * math.pi * self.freq_hz
        t_prev, k_next = 0.0, 1
        n_ev = len(ev)

        def boundary(W, k):
            W = st.projection(table, s) @ W
            if not renormalise:
                return W
            Q, R = np.linalg.qr(D @ W)
            d = np.diag(R)
            logs[k - 1] = np.log(np.abs(d))
            return Dinv @ (Q * np.where(d < 0.0, -1.0, 1.0))

        for i in range(n_ev + 1):
            te = float(ev.t[i]) if i < n_ev else K * T
            while k_next <= K and k_next * T <= te:
                W = st.carry(table, s, k_next * T - t_prev, W)
                t_prev = k_next * T
                W = boundary(W, k_next)
                k_next += 1
            if i == n_ev:
                break
            W = st.carry(table, s, te - t_prev, W)
            t_prev = te
            s_new, slot, kind = int(ev.state[i]), int(ev.slot[i]), str(ev.kind[i])
            DR, ng, A0, c0, A1, c1 = st.jump(table, s, s_new, slot, kind)
            ye = ev.y[i]
            load = np.zeros(st.N)
            load[n:2 * n] = st.load * math.cos(w_omega * te)
            fm = A0 @ ye + c0 + load
            fp = A1 @ ye + c1 + load
            den = float(ng @ fm)
            W = DR @ W + (np.outer(fp - DR @ fm, ng @ W) / den if den != 0.0 else 0.0)
            s = s_new
        return W

    def sampled(self, run: PeriodRun) -> PeriodRun:
        """``run`` as it is: the peaks are read on the march."""
        return run

    def jacobian(self, y0, n_periods: int = 1, active=None) -> PeriodRun:
        """The run of ``n_periods`` from y0 whose ``tangent`` is P dy/dy0 P (N, N) over them (module docstring)."""
        del active
        return self.run(y0, n_periods, tangent=np.eye(self.states.N), renormalise=False, samples_per_period=0)


def friction_response_map(system: GapSystem, load, amplitude_N: float, freq_hz, *, direction: str = "up",
                          point_rows=None, point_names=None, mirror=("x1", "x3"), options: MapOptions | None = None,
                          jump_step_hz: float = 0.0, extend_step_hz: float = 0.0, y0=None, progress=None
                          ) -> ResponseMap:
    """A stepped sine by the exact friction flow, each frequency classified by
    :func:`reduced.periodic.response_map.classify` on :class:`FrictionPeriodMap` (the arguments and the result as
    :func:`reduced.periodic.response_map.response_map`; y0 and each point's ``state`` of N = 2n + p values, the
    sliders' positions carried from one frequency to the next). sigma (the scale of the exponent's tolerance) is
    the slowest linear decay rate of the structure without its sliders.

    Parameters
    ----------
    system : the gap system with friction, damped
    load : (n,) the force direction b
    amplitude_N : N, P > 0
    freq_hz : Hz, the frequencies in sweep order
    direction : ``up`` or ``down`` (a label)
    point_rows, point_names : (p, n) the monitored points (default the DOFs); the first is the one the envelope,
        spectrum and jumps are read at
    mirror : two point names whose asymmetry is reported (skipped if either is missing)
    options : MapOptions
    jump_step_hz : Hz, neighbours up to 1.5 times this apart can show a jump (0: ``extend_step_hz``, else the
        smallest step)
    extend_step_hz : Hz; > 0: a response in contact before a wider step is followed by steps of this size
    y0 : (2n + p,) the state the sweep starts from (default rest, the sliders unloaded)
    progress : None or a callable taking the fraction done

    Returns
    -------
    ResponseMap
        A failure of the exact flow is a RuntimeError naming the frequency.
    """
    _check.gap_system(system)
    if system.friction is None:
        raise _check.InvalidArgument("system has no friction: use reduced.periodic.response_map.response_map")
    b, P, freqs, opts, rows, names, pair = map_inputs(system, load, amplitude_N, freq_hz, direction, options,
                                                      point_rows, point_names, mirror)
    states = _States(system, b, P)
    N = states.N
    try:
        np.linalg.cholesky(system.K)
        D = friction_norm_matrix(system, 2.0 * math.pi * float(freqs[0]))
        norm = (D, np.linalg.inv(D))
    except np.linalg.LinAlgError:
        norm = None
    sigma = slowest_decay_rate(system.with_friction(None), b)
    y = np.zeros(N) if y0 is None else _check.vector("y0", y0, N)
    return sweep(lambda f: FrictionPeriodMap(system, b, P, f, rows=rows, states=states, norm=norm), y, P, freqs,
                 sigma, opts, direction=direction, names=names, mirror=pair, jump_step_hz=jump_step_hz,
                 extend_step_hz=extend_step_hz, progress=progress, label="friction response map")


__all__ = ["EIG_RTOL", "FrictionPeriodMap", "friction_norm_matrix", "friction_response_map"]
