"""Passing through a friction state without its tables: the flow's Taylor series over a short reach.

A hammer record with friction enters many states only for an instant: the blow closes the two ends' tips
nearly together, and each end's closing, stick -> slip and opening follows the other's within 1e-13 to 1e-9 s
(on the hammer-test apparatus 49 of the 69 states that three blows enter last under 1 us in all). Building
such a state's tables (:class:`reduced.transient.friction_tables.LazyFrictionTables`: an eigendecomposition
of order 2n, its inverse, the work tables) costs ~40 ms; the motion in it, a few ns, needs none of that.

In a state the flow is y' = A_s y + b_s (:mod:`reduced.transient.friction_tables`):

    x' = v,   v' = M^-1 (-K_s x - C v + G_s w + F_s),   w' = R v,

so over a reach tau with omega_max tau <= ``REACH_OMEGA_TAU`` it is its Taylor series, in the scaled time
u = t / tau (so that no power of omega_max overflows),

    y(u tau) = sum_k c_k u^k / k!,   c_k = d_k tau^k,   d_0 = y(0), d_1 = A_s y(0) + b_s, d_k = A_s d_(k-1),

summed to ``ORDER`` terms (the last within round-off of the sum, checked: 1/24! ~ 2e-24 of the first at
omega_max tau = 1, the slowest term's), and each event function q_e = a_e^T y + c_e is a polynomial in u.
:func:`pass_through` finds the first event in the reach and the state, viscous work int v^T C v dt and friction
work int sum_slip f_k w_k' dt (f_k = a_k (B_j x - o_j), w_k' = R_k v) at it, all as polynomials (exact to
round-off, as the closed form).

**A zero start.** At a state's start the slots of the event that led to it sit at their threshold: a closing
stop's gap function is 0 and so are its sliders' cone functions (w = t and N = 0 at the closing), q(0) = 0 to
round-off. Such a slot is no event when it falls at once, q'(0) u-rate below -``GRAZE`` times its band: q' < 0
throughout the leading grid subintervals where q'(right end) < -|q''| h (q then below its start), and the
search for a crossing starts after them (:func:`_zero_start`, :func:`_falling_run`), as the kernel's march
passes a slot within its band whose rate is below its round-off (:func:`reduced.transient._modal._root_at`).
A slot that rises at once (a slider that slips at the closing), grazes, reads the accelerations (a slip end,
whose rate is the slip's acceleration) or is the slider that has just switched (the kernel's consistency rule
decides) is declined.

It declines (None) every other case that the kernel decides by its own round-off rules or that needs the
tables: a touch or a graze, two events at one instant, one held slot, a sample, a piece's end or the buffer's
end in the reach, a step below the march's floor, no event in the reach. The caller then builds the state and
lets the kernel go on as before. On the hammer-test apparatus (mu = 0.3, axial and lateral sliders) the
200, 500 and 1000 N blows run in order build 15, 24 and 26 states in all (were 23, 34 and 40 with a reach of
omega_max tau = 0.01 and every zero start declined).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from reduced.models.gaps import GapSystem
from reduced.transient.friction_tables import STICK, FrictionTable

EPS = float(np.finfo(float).eps)
REACH_OMEGA_TAU = 1.0  # the reach: omega_max tau at most this (the fastest term's phase; 0.01 built 8 more states
# of the hammer test's 3 blows, 3.0 none fewer)
ORDER = 24  # terms of the series (1/24! of the first at the reach's end: the last is checked within round-off)
BAND = 1e4 * EPS  # x the size of an event function's terms: q(0) below -BAND is clearly before its event
GRAZE = 100.0  # a crossing's rate at least GRAZE x its band per reach (dq/du), else a graze (a touch); a slot
# at its threshold at the start falls at least as fast
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


def _series(system: GapSystem, Minv: np.ndarray, parts: tuple, y: np.ndarray, h: float) -> np.ndarray:
    """(ORDER + 1, N): the Taylor coefficients of y in the scaled time u = t / h, d_k h^k (d_k the k-th
    derivative of y at the start, module docstring; scaled so that no power of omega_max overflows), the forces
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
        D[k, :n] = h * v
        D[k, n:2 * n] = h * (Minv @ f)
        D[k, 2 * n:] = h * (R @ v)
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
    D = _series(system, Minv, parts, y, reach)  # in u = t / reach: the reach is [0, 1]
    act = np.flatnonzero(table.eact[s])
    A = table.erow[s][act]
    Q = A @ D.T  # (E, ORDER + 1): the event functions' Taylor coefficients in u
    Q[:, 0] += table.ec[s][act]
    scale = np.abs(A) @ np.abs(y) + np.abs(table.ec[s][act])
    fact = np.array([math.factorial(k) for k in range(ORDER + 1)], float)
    terms = np.abs(Q) / fact
    if not np.all(np.isfinite(terms)) or np.any(terms[:, -1] > EPS * (terms.sum(axis=1) + scale) * 1e-3):
        return _decline("series")  # the series has not converged within the reach
    band = BAND * (terms.sum(axis=1) + scale)
    start = Q[:, 0] >= -band  # slots at their threshold at the start (module docstring: a zero start)
    if np.any(start):
        why = _zero_start(A[start], Q[start], band[start], act[start], fresh, system.n)
        if why:
            return _decline(why)
    grid = np.linspace(0.0, 1.0, GRID + 1)
    qg = _poly_grid(Q, grid)  # (E, GRID + 1)
    dg = _poly_grid(Q[:, 1:], grid)  # q'
    # |q''| over the reach bounds q between grid points: q <= max(ends) + |q''| h^2 / 8, and q is monotonic on a
    # subinterval where |q'| at an end exceeds |q''| h (its largest value then at an end)
    d2 = np.abs(Q[:, 2:]) @ (1.0 / fact[:ORDER - 1])
    h = 1.0 / GRID
    slack = d2 * h * h / 8.0
    first = None
    for i, e in enumerate(act):
        up = np.flatnonzero(qg[i, 1:] >= 0.0)
        mono = (dg[i, :-1] > d2[i] * h) | (dg[i, 1:] < -d2[i] * h)
        top = np.maximum(qg[i, :-1], qg[i, 1:]) + np.where(mono, 0.0, slack[i])
        if start[i]:  # falling from its threshold: below it on the leading subintervals where q' < 0 throughout
            lead = _falling_run(dg[i], d2[i] * h)
            if lead == 0 or not qg[i, lead] < -band[i]:
                return _decline("zero start: not clear of its threshold")
            top[:lead] = -np.inf
            up = up[up >= lead]
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
        if not d1 > GRAZE * band[i]:
            return _decline("graze")  # a touch, not a crossing
        if first is None or tau < first[0]:
            first = (tau, int(e), i)
    if first is None:
        return _decline("no event in the reach")
    u, e, i = first
    others = act != e
    if np.any(_poly_at(Q[others], u) >= -band[others]):
        return _decline("two events at one instant")
    if e == fresh or u * reach <= hmin:
        return _decline("the switched slot again or below the floor")
    yt = _poly_at(D.T, u)
    dW, dWf = _works(system, parts, D, u, fact)
    return PassThrough(float(u * reach), e, yt, reach * dW, reach * dWf)


def _zero_start(A: np.ndarray, Q: np.ndarray, band: np.ndarray, slots: np.ndarray, fresh: int, n: int) -> str:
    """Why the slots at their threshold at a state's start bar the pass-through ('' if none does): each must be
    a slot whose rate q' = a_x . v + a_w . w' reads the state's velocities alone (a gap or a cone function, not a
    slip end, whose rate needs the accelerations), not the slider that has just switched (the kernel's
    consistency rule decides that one), with q(0) within its band and falling beyond a graze's margin,
    dq/du(0) < -``GRAZE`` band (u = t / reach).

    Parameters
    ----------
    A : (Z, 2n + p) the slots' rows
    Q : (Z, ORDER + 1) their Taylor coefficients in u
    band : (Z,) m, their round-off bands
    slots : (Z,) their slot numbers
    fresh : the slider slot that has just switched (-1: none)
    n : coordinates
    """
    if np.any(A[:, n:2 * n] != 0.0):
        return "zero start: a slip end"
    if fresh in slots:
        return "zero start: the switched slot"
    if np.any(Q[:, 0] > band):
        return "event at the start"
    if np.any(Q[:, 1] >= -GRAZE * band):
        return "zero start: rising or grazing"
    return ""


def _falling_run(dq: np.ndarray, slope: float) -> int:
    """The number of leading grid subintervals on which q' < 0 throughout: q'(right end) < -``slope``
    (|q''| h, so q' <= q'(right end) + |q''| h < 0 on the subinterval).

    Parameters
    ----------
    dq : (GRID + 1,) q' at the grid points
    slope : |q''| bound times the subinterval's length
    """
    neg = dq[1:] < -slope
    return int(neg.size if np.all(neg) else np.argmin(neg))


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
    two polynomials, int_0^tau (sum_i p_i t^i / i!) (sum_j r_j t^j / j!) dt = p^T Wt r (in the series' own time:
    with D in u = t / h, tau in u and the works per unit u, h times them the works in J).

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
