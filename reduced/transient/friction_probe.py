"""Passing through a friction state without its tables: the flow's Taylor series over a short reach.

A hammer record with friction enters many states only for an instant: the blow closes the two ends' tips
nearly together, and each end's closing, stick -> slip and opening follows the other's within 1e-13 to 1e-9 s
(on the hammer-test apparatus 49 of the 69 states that three blows enter last under 1 us in all). Building
such a state's tables (:class:`reduced.transient.friction_tables.LazyFrictionTables`: an eigendecomposition
of order 2n, its inverse, the work tables) costs ~40 ms; the motion in it, a few ns, needs none of that.

In a state the flow is y' = A_s y + b_s (:mod:`reduced.transient.friction_tables`):

    x' = v,   v' = M^-1 (-K_s x - C v + G_s w + F_s),   w' = R v,

so over a reach tau with omega_max tau <= ``REACH_OMEGA_TAU`` it is its Taylor series,

    y(t) = sum_k d_k t^k / k!,   d_0 = y(0), d_1 = A_s y(0) + b_s, d_k = A_s d_(k-1),

summed to ``ORDER`` terms (the last within round-off of the sum, checked), and each event function
q_e = a_e^T y + c_e is a polynomial in t. :func:`pass_through` finds the first event in the reach and the
state, viscous work int v^T C v dt and friction work int sum_slip f_k w_k' dt (f_k = a_k (B_j x - o_j),
w_k' = R_k v) at it, all as polynomials (exact to round-off, as the closed form). It declines (None) every
case that the kernel decides by its own round-off rules or that needs the tables: an event at the start
(q(0) within its band), a touch or a graze, two events at one instant, the slot that has just switched
(the consistency of a slider's switch) or one held, a sample, a piece's end or the buffer's end in the reach,
a step below the march's floor. The caller then builds the state and lets the kernel go on as before.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from reduced.models.gaps import GapSystem
from reduced.transient.friction_tables import STICK, FrictionTable

EPS = float(np.finfo(float).eps)
REACH_OMEGA_TAU = 1e-2  # the reach: omega_max tau at most this (every term of the series 1e-2 x the one before)
ORDER = 12  # terms of the series (1e-24 of the first at the reach's end: the last is checked within round-off)
BAND = 1e4 * EPS  # x the size of an event function's terms: q(0) below -BAND is clearly before its event
GRID = 64  # subintervals of the reach on which the event functions are checked for a crossing
DECLINED: Counter = Counter()  # why pass_through declined, by reason (diagnostics: reset it freely)


@dataclass(frozen=True)
class PassThrough:
    """The first event of a state met within the reach, and the motion to it.

    Attributes
    ----------
    tau : s, time from the state's start to the event
    slot : the event's slot (:mod:`reduced.transient.friction_tables`)
    y : (2n + p,) m, m/s, m: the state at the event (before the switch)
    dW : J, viscous work over [0, tau]
    dWf : J, friction work over [0, tau]
    """

    tau: float
    slot: int
    y: np.ndarray
    dW: float
    dWf: float


def _flow_parts(system: GapSystem, table: FrictionTable, s: int) -> tuple:
    """The low-rank parts of state s's forces (:func:`reduced.transient.friction_tables._state_parts` without
    forming K_s): (closed stops' rows B_c and k_c, sticking sliders' rows and kt, slipping sliders' rows Bt_k,
    their stops' rows B_j, offsets o_j and a_k = sigma_k mu_k k_j side_j, R, [(a_k, j, k)])."""
    fr = system.friction
    st = table.states
    closed, slip, stop_of = st.closed[s], st.slip[s], st.stop_of[s]
    c = np.flatnonzero(closed)
    stick = [k for k in range(fr.p) if stop_of[k] >= 0 and slip[k] == STICK]
    slipping = [(slip[k] * fr.mu[k] * system.k[stop_of[k]] * system.side[stop_of[k]], int(stop_of[k]), k)
                for k in range(fr.p) if stop_of[k] >= 0 and slip[k] != STICK]
    sl_k = [k for _, _, k in slipping]
    sl_j = [j for _, j, _ in slipping]
    return (system.B[c], system.k[c], system.offset[c], fr.Bt[stick], fr.k_t[stick], np.array(stick, np.int64),
            fr.Bt[sl_k], system.B[sl_j], system.offset[sl_j], np.array([a for a, _, _ in slipping]), table.R[s],
            slipping)


def _series(system: GapSystem, Minv: np.ndarray, parts: tuple, y: np.ndarray) -> np.ndarray:
    """(ORDER + 1, N): the Taylor coefficients d_k of y(t) in the state (module docstring), the forces
    M v' = -K x - C v - sum_closed k_j (B_j x - o_j) B_j - sum_stick kt_k (Bt_k x - w_k) Bt_k
    - sum_slip a_k (B_j x - o_j) Bt_k."""
    n = system.n
    Bc, kc, oc, Bs, kts, stick, Bl, Bj, oj, al, R, _ = parts
    D = np.zeros((ORDER + 1, y.size))
    D[0] = y
    for k in range(1, ORDER + 1):
        x, v, w = D[k - 1, :n], D[k - 1, n:2 * n], D[k - 1, 2 * n:]
        const = 1.0 if k == 1 else 0.0  # the offsets act on y itself, not on its derivatives
        f = -(system.K @ x) - system.C @ v
        if kc.size:
            f -= (kc * (Bc @ x - const * oc)) @ Bc
        if kts.size:
            f -= (kts * (Bs @ x - w[stick])) @ Bs
        if al.size:
            f -= (al * (Bj @ x - const * oj)) @ Bl
        D[k, :n] = v
        D[k, n:2 * n] = Minv @ f
        D[k, 2 * n:] = R @ v
    return D


def _poly_at(c: np.ndarray, t: float) -> np.ndarray:
    """sum_k c[..., k] t^k / k! at the scalar t (Horner)."""
    K = c.shape[-1] - 1
    out = c[..., K]
    for k in range(K - 1, -1, -1):
        out = c[..., k] + out * (t / (k + 1))
    return out


def _poly_grid(c: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(E, G): sum_k c[e, k] t_g^k / k! for c (E, K + 1) and the times t (G,)."""
    K = c.shape[-1] - 1
    out = np.repeat(c[:, K:K + 1], t.size, axis=1)
    for k in range(K - 1, -1, -1):
        out = c[:, k:k + 1] + out * (t[None, :] / (k + 1))
    return out


def _decline(reason: str) -> None:
    DECLINED[reason] += 1
    return None


def pass_through(system: GapSystem, table: FrictionTable, Minv: np.ndarray, s: int, y: np.ndarray, reach: float,
                 fresh: int, hold: int, hmin: float) -> PassThrough | None:
    """The first event of state ``s`` from ``y`` within ``reach`` s, or None where the kernel must decide
    (module docstring).

    Parameters
    ----------
    system : GapSystem
        The run's system (with friction).
    table : FrictionTable
        The lazy tables' arrays: the state's event rows, constants and which are active (built for every state).
    Minv : (n, n) M^-1
    s : the state entered
    y : (2n + p,) m, m/s, m: the state at its start
    reach : s, how far to look (the next sample, the piece's end and ``REACH_OMEGA_TAU`` / omega_max, whichever
        is first)
    fresh, hold : the kernel's slider slot that has just switched and the slot held (-1: none)
    hmin : s, the march's floor

    Returns
    -------
    PassThrough or None
    """
    if hold >= 0 or not reach > 0.0:
        return _decline("held slot or no reach")
    parts = _flow_parts(system, table, s)
    D = _series(system, Minv, parts, y)
    act = np.flatnonzero(table.eact[s])
    A = table.erow[s][act]
    Q = A @ D.T  # (E, ORDER + 1): the event functions' Taylor coefficients
    Q[:, 0] += table.ec[s][act]
    scale = np.abs(A) @ np.abs(y) + np.abs(table.ec[s][act])
    fact = np.array([math.factorial(k) for k in range(ORDER + 1)], float)
    terms = np.abs(Q) * reach ** np.arange(ORDER + 1) / fact
    if np.any(terms[:, -1] > EPS * (terms.sum(axis=1) + scale) * 1e-3):
        return _decline("series")  # the series has not converged within the reach
    band = BAND * (terms.sum(axis=1) + scale)
    if np.any(Q[:, 0] >= -band):
        return _decline("event at the start")  # the kernel's rules
    grid = np.linspace(0.0, reach, GRID + 1)
    qg = _poly_grid(Q, grid)  # (E, GRID + 1)
    dg = _poly_grid(Q[:, 1:], grid)  # q'
    # |q''| over the reach bounds q between grid points: q <= max(ends) + |q''| h^2 / 8, and q is monotonic on a
    # subinterval where |q'| at an end exceeds |q''| h (its largest value then at an end)
    d2 = np.abs(Q[:, 2:]) @ (reach ** np.arange(ORDER - 1) / fact[:ORDER - 1])
    h = reach / GRID
    slack = d2 * h * h / 8.0
    first = None
    for i, e in enumerate(act):
        up = np.flatnonzero(qg[i, 1:] >= 0.0)
        mono = (dg[i, :-1] > d2[i] * h) | (dg[i, 1:] < -d2[i] * h)
        top = np.maximum(qg[i, :-1], qg[i, 1:]) + np.where(mono, 0.0, slack[i])
        if up.size == 0:
            if np.any(top >= -band[i]):
                return _decline("touch between grid points")
            continue
        g = int(up[0])  # the first subinterval whose right end is >= 0; those before end below 0, so a monotonic
        # one has no root whatever its ends' size, another none when its bound is below the band
        if np.any(~mono[:g] & (top[:g] >= -band[i])):
            return _decline("touch before the crossing")
        tau = _root(Q[i], grid[g], grid[g + 1], qg[i, g], qg[i, g + 1])
        d1 = _poly_at(Q[i, 1:], tau)
        if not d1 > 100.0 * band[i] / reach:
            return _decline("graze")  # a touch, not a crossing
        if first is None or tau < first[0]:
            first = (tau, int(e), i)
    if first is None:
        return _decline("no event in the reach")
    tau, e, i = first
    others = act != e
    if np.any(_poly_at(Q[others], tau) >= -band[others]):
        return _decline("two events at one instant")
    if e == fresh or tau <= hmin:
        return _decline("the switched slot again or below the floor")
    yt = _poly_at(D.T, tau)
    dW, dWf = _works(system, parts, D, tau, fact)
    return PassThrough(float(tau), e, yt, dW, dWf)


def _root(q: np.ndarray, lo: float, hi: float, q_lo: float, q_hi: float) -> float:
    """The root of the polynomial q (Taylor coefficients) in [lo, hi], q(lo) < 0 <= q(hi): Newton from the
    bracket's end nearer the root, bisection where Newton would leave it; the right end of the last bracket.

    Parameters
    ----------
    q : (K,) the polynomial's Taylor coefficients (q(t) = sum_k q_k t^k / k!)
    lo, hi : s, the bracket
    q_lo, q_hi : q(lo) < 0 and q(hi) >= 0
    """
    for _ in range(100):
        x, qx = (hi, q_hi) if q_hi < -q_lo else (lo, q_lo)
        dx = _poly_at(q[1:], x)
        if dx > 0.0 and abs(qx) <= 2.0 * EPS * x * dx:
            return x - qx / dx  # Newton's step below the last bit: the root
        mid = x - qx / dx if dx > 0.0 else 0.5 * (lo + hi)
        if not lo < mid < hi:
            mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        q_mid = _poly_at(q, mid)
        if q_mid >= 0.0:
            hi, q_hi = mid, q_mid
        else:
            lo, q_lo = mid, q_mid
        if hi - lo <= 4.0 * EPS * hi or q_hi == 0.0:
            break
    return hi


def _works(system: GapSystem, parts: tuple, D: np.ndarray, tau: float, fact: np.ndarray) -> tuple[float, float]:
    """(viscous work, friction work) over [0, tau] of the state's series D: each an integral of a product of
    two polynomials, int_0^tau (sum_i p_i t^i / i!) (sum_j r_j t^j / j!) dt = p^T Wt r.

    Parameters
    ----------
    system : the run's system (its C, B, offsets)
    parts : :func:`_flow_parts`' tuple for the state (its last two: the sliders' rate rows and their terms)
    D : (ORDER + 1, 2n + p) the state's Taylor coefficients (:func:`_series`)
    tau : s, the upper limit
    fact : (ORDER + 1,) the factorials 0! ... ORDER!
    """
    n = system.n
    vq = D[:, n:2 * n]
    Cv = vq @ system.C  # (ORDER + 1, n)
    Gm = Cv @ vq.T  # v_i^T C v_j
    ij = np.arange(ORDER + 1)
    # int_0^tau (sum_i p_i t^i / i!) (sum_j r_j t^j / j!) dt = p^T Wt r
    Wt = tau ** (ij[:, None] + ij[None, :] + 1) / (fact[:, None] * fact[None, :] * (ij[:, None] + ij[None, :] + 1))
    dW = 0.0 if system.undamped else float(np.sum(Gm * Wt))
    dWf = 0.0
    for a, j, k in parts[-1]:
        pen = D[:, :n] @ system.B[j]
        pen[0] -= system.offset[j]
        rate = D[:, n:2 * n] @ parts[-2][k]
        dWf += a * float(pen @ Wt @ rate)
    return dW, dWf


def switch(system: GapSystem, table: FrictionTable, s: int, e: int, y: np.ndarray, fric: tuple) -> tuple[int, float]:
    """(state after event e of state s, friction work of the switch), y's sliders updated in place: the
    kernels' switch (:func:`reduced.transient._friction_kernels._switch`), in NumPy.

    Parameters
    ----------
    system : GapSystem
        The run's system (with friction).
    table : FrictionTable
        Its states' links (successors, resets, kinds).
    s, e : the state and the event's slot
    y : (2n + p,) the state at the event; its sliders' positions are updated
    fric : the kernels' slider data (:attr:`reduced.transient.friction.FrictionExactStepper.fric`)

    Returns
    -------
    (int, float)
        The next state and the friction work of the sliders' jumps, J.
    """
    Bt, slider_tip, stop_tip, slider_stop, ekind, stop_of, B, kstop, offset, side, mu, kt = fric
    n, p, m = system.n, Bt.shape[0], B.shape[0]
    s_new = int(table.succ[s, e])
    reset = bool(table.reset[s, e])
    dWf = 0.0
    for k in range(p):
        if reset:
            if slider_tip[k] != stop_tip[e] or (slider_stop[k] >= 0 and slider_stop[k] != e):
                continue
        elif not ((ekind[s, e] == 1 or ekind[s, e] == 2) and e - m == 2 * k + (ekind[s, e] - 1)):
            continue
        t = float(Bt[k] @ y[:n])
        w_old = y[2 * n + k]
        if reset:
            w_new = t
        else:
            j = stop_of[s_new, k]
            N = kstop[j] * side[j] * (float(B[j] @ y[:n]) - offset[j])
            sigma = 1.0 if ekind[s, e] == 1 else -1.0
            w_new = t - sigma * mu[k] * N / kt[k]
        dWf += 0.5 * kt[k] * ((t - w_old) * (t - w_old) - (t - w_new) * (t - w_new))
        y[2 * n + k] = w_new
    return s_new, dWf
