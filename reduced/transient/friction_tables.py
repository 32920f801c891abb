"""The exact integrator's tables with friction: every contact and stick/slip state of the augmented flow.

With sliders (:class:`reduced.models.gaps.Friction`) the state is y = [x (n); v (n); w (p)], the slider
positions w a state of their own, and in each *friction state* (which stops are closed; each slider of
a closed tip sticking, slipping + or slipping -; a slider of an open tip following its coordinate) the
motion is linear, y' = A_s y + b_s:

    x' = v,
    M v' = -K_s x - C v + G_s w + F_s,
    w_k' = R_k v,

    K_s = K + sum_closed k_j B_j^T B_j + sum_stick kt_k Bt_k^T Bt_k + sum_slip sigma_k mu_k k_j side_j Bt_k^T B_j,
    F_s = sum_closed k_j o_j B_j^T + sum_slip sigma_k mu_k k_j side_j o_j Bt_k^T,
    G_s = [kt_k Bt_k^T] on the sticking sliders' columns (0 elsewhere),
    R_k = Bt_k - sigma_k (mu_k k_j / kt_k) side_j B_j (slipping), Bt_k (open tip), 0 (sticking),

j the closed stop that engages slider k and sigma_k = +-1 its slip direction. K_s is not symmetric in a
slip state (the friction force follows the normal one), and its eigenvalues may leave the imaginary
axis (friction-induced flutter, Re lam > 0: on the 3-D apparatus the beam's pitch couples the normal and
tangential motion at a tip, and 15 of its 49 axial friction states grow, by up to 0.16 /s at 8.5 kHz with
mu = 0.3 and Mindlin's k_t). The closed form holds for them as for any state; the march bounds their growing
terms over segments of at most ``GROWTH_SEGMENT`` / max Re lam (:mod:`reduced.transient._modal`).

**The closed form.** A_s has the p zero eigenvalues of the sliders and the 2n of the structure,
A_z = [[0, I], [-M^-1 K_s, -M^-1 C]], and is diagonalizable when A_z is (K_s regular):

    structure:  A_z z = lam z                  ->  [z; R z_v / lam]   (R z_v: the sliders' rates)
    slider k:   sticking                       ->  [K_s^-1 kt_k Bt_k^T; 0; e_k]   (w_k shifts the static state)
                slipping or following          ->  [0; 0; e_k]        (w_k' does not depend on w)

so y(tau) = y_p + V diag(e^{lam tau}) V^-1 (y(0) - y_p) with y_p = [K_s^-1 F_s; 0; 0], as without
friction; the zero eigenvalues are set exactly (their terms are constants), the structure's come
from the real modes of (K_s, M) when the state is symmetric and undamped (lam = +-i omega exactly,
the energy conserved to round-off), else from LAPACK.

**Events** (a fixed list of m + 2p slots, each active in some states), every one the crossing of a
linear function q = a^T y + c, signed so that q <= 0 until it fires, and scaled to metres (the
march's floor and round-off bands are in metres):

    slot j < m        gap: q = +-side_j (B_j x - o_j), as without friction; a closing sets the
                      sliders it engages to stick, unloaded (w_k = t_k), an opening to follow;
    slot m + 2k       stick -> slip +: q = ((t_k - w_k) kt_k - mu_k N_j) / kt_k;
                      slip + -> stick: q = -w_k' / omega_ref (the slip velocity passes zero);
    slot m + 2k + 1   stick -> slip -: q = (-(t_k - w_k) kt_k - mu_k N_j) / kt_k;
                      slip - -> stick: q = +w_k' / omega_ref.

A slip velocity that touches zero and turns back (q' <= 0 at q = 0: the stick force would leave the
cone at once) is a graze, passed without a change, by the march's own rule. Sticking at closure,
or after a slip, with the force leaving the cone at once is the slip event at that instant.

**Consistency of a slider's switch.** On the cone the two states agree on x, v and the force, so with
g = sigma w'_slip = sigma t' - mu N' / kt the stick state's cone function c and the slip state's slip-end
function -g / omega_ref share their derivatives: c = 0, c' = g, c'' = g' (the accelerations are equal), and
c''' = g'' while g = 0. At a slip end (g = 0, falling) the stick force's rate kt t' equals mu N' exactly and
c'' = g' < 0: stick is consistent. After a stick -> slip, slip is consistent when c rose, the sign of the
first of c', c'', c''' beyond its round-off; a crossing that only grazed (c' = 0, c'' < 0) or a force past
the cone but falling back is a stick, the slider left on the cone. The kernels
(:mod:`reduced.transient._friction_kernels`) decide so when the new state's march would switch the slider
back at the same instant: re-expanding y in the new state's modes errs by ~cond(V) eps (1e-11 m/s in q'
on the reduced beam, cond 9e5, where the march's band is 3e-14), enough to see c rise at once. The
consistent state is kept and the slot pinned below its band for that segment; a state is never toggled.

**Work.** The dissipated power is y^T D y (+ a linear term): viscous, v^T C v; friction, f_k w_k' =
sigma_k mu_k k_j pen_j (R_k v) over the slipping sliders, pen_j = side_j B_j (x - x_p) + pen_j(y_p).
Its quadratic part x_h^T Q v_h (Q = sum sigma mu k side B_j^T R_k) is the form D_f = 1/2 [[0, Q],
[Q^T, 0]] integrated as the viscous one (:func:`reduced.transient.exact_tables.modal_table`), and its
linear part sum sigma mu k pen_j(y_p) R_k v integrates to L_s^T (x(tau) - x(0)) exactly.
"""

from __future__ import annotations

import math
import mmap
import threading
import time
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh, solve

from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.transient.exact_tables import MAX_COND, RESONANCE_REL, ZNEAR, ExactIntegratorError

GROWTH_SEGMENT = math.log(2.0)  # a growing state's closed form restarts once its fastest term has doubled
SMALL_PAGES_BYTES = 4 * 2**20  # a per-state table larger than this is mapped in small pages (_state_zeros)

FOLLOW, STICK, SLIP_UP, SLIP_DOWN = 0, 0, 1, -1  # slider codes (follow: its tip open; stick: closed)
KIND_GAP, KIND_STICK_UP, KIND_STICK_DOWN, KIND_SLIP_END = 0, 1, 2, 3  # event kinds, for the log


@dataclass(frozen=True, eq=False)
class FrictionStates:
    """Every friction state a motion can reach.

    Attributes
    ----------
    closed : (S, m) ndarray of bool
        The closed stops of each state (at most one a tip).
    slip : (S, p) ndarray of int8
        Each slider's code: 0 stick (its tip closed) or follow (open), +1 slip +, -1 slip -.
    stop_of : (S, p) ndarray of int
        The closed stop of each slider's tip, -1 when the tip is open.
    """

    closed: np.ndarray
    slip: np.ndarray
    stop_of: np.ndarray

    @property
    def S(self) -> int:
        return self.closed.shape[0]

    def index(self, closed: np.ndarray, slip: np.ndarray) -> int:
        """The state with these closed stops and slider codes (KeyError if infeasible)."""
        key = (np.asarray(closed, bool).tobytes(), np.asarray(slip, np.int8).tobytes())
        return self._lookup()[key]

    def _lookup(self) -> dict:
        d = self.__dict__.get("_index")
        if d is None:
            d = {(c.tobytes(), s.tobytes()): i for i, (c, s) in enumerate(zip(self.closed, self.slip, strict=True))}
            object.__setattr__(self, "_index", d)
        return d

    def describe(self, system: GapSystem, s: int) -> str:
        """'x1+ closed, u1 slip+' and the like."""
        parts = [f"{system.stop_names[j]} closed" for j in np.flatnonzero(self.closed[s])]
        names = ("stick", "slip+", "slip-")
        for k in range(self.slip.shape[1]):
            if self.stop_of[s, k] >= 0:
                parts.append(f"{system.friction.names[k]} {names[self.slip[s, k]]}")
        return ", ".join(parts) if parts else "all stops open"


def friction_states(system: GapSystem) -> FrictionStates:
    """Every feasible friction state of ``system``: each contact state (:meth:`GapSystem.feasible_states`)
    with each slider a closed stop engages sticking, slipping + or slipping - (3^(sliders engaged) states each;
    the others follow their coordinates).

    Parameters
    ----------
    system : GapSystem
        A system with friction.

    Returns
    -------
    FrictionStates
    """
    fr = system.friction
    closed_list, slip_list, stop_list = [], [], []
    for closed in system.feasible_states():
        stop_of = fr.engaged_by(system.tip, closed).astype(np.int64)
        engaged = np.flatnonzero(stop_of >= 0)
        for code in np.ndindex(*(3,) * engaged.size):
            slip = np.zeros(fr.p, np.int8)
            slip[engaged] = np.array([(STICK, SLIP_UP, SLIP_DOWN)[c] for c in code], np.int8)
            closed_list.append(closed.copy())
            slip_list.append(slip)
            stop_list.append(stop_of)
    return FrictionStates(np.array(closed_list), np.array(slip_list), np.array(stop_list))


@dataclass(frozen=True, eq=False)
class FrictionTable:
    """Closed form, events and work of every friction state (module docstring), indexed as
    :class:`FrictionStates`.

    Attributes
    ----------
    states : FrictionStates
    lam : (S, N) ndarray of complex
        1/s, eigenvalues of A_s (N = 2n + p; the last p are the sliders' zeros).
    V, Vinv : (S, N, N) ndarray of complex
        Eigenvectors and their inverse.
    yp : (S, N) ndarray of float
        Equilibrium [K_s^-1 F_s; 0; 0].
    cond : (S,) ndarray of float
        An upper bound of the condition number of V (:func:`condition_bound`, at most N times cond_2).
    Ks : (S, n, n) ndarray of float
        N/m, the state's stiffness (static deflections under loads).
    R : (S, p, n) ndarray of float
        Rows of the sliders' rates on v.
    erow : (S, E, N) ndarray of float
        Event rows a (scaled to metres), E = m + 2p.
    ec : (S, E) ndarray of float
        m, their constants c.
    eact : (S, E) ndarray of bool
        Which events watch in each state.
    succ : (S, E) ndarray of int
        The state after each event.
    reset : (S, E) ndarray of bool
        The event closes a stop: the sliders of its tip start unloaded (w = t).
    ekind : (E,) ... per state: (S, E) ndarray of int
        KIND_GAP, KIND_STICK_UP, KIND_STICK_DOWN or KIND_SLIP_END.
    Df : (S, N, N) ndarray of float
        The friction power's quadratic form (zero in states without slip).
    LF : (S, n) ndarray of float
        The friction power's linear part: W_lin = LF[s] . (x(tau) - x(0)).
    omega_ref : float
        rad/s, the scale of the slip-end events' rows (q = w' / omega_ref).
    """

    states: FrictionStates
    lam: np.ndarray
    V: np.ndarray
    Vinv: np.ndarray
    yp: np.ndarray
    cond: np.ndarray
    Ks: np.ndarray
    R: np.ndarray
    erow: np.ndarray
    ec: np.ndarray
    eact: np.ndarray
    succ: np.ndarray
    reset: np.ndarray
    ekind: np.ndarray
    Df: np.ndarray
    LF: np.ndarray
    omega_ref: float


def _state_parts(system: GapSystem, closed: np.ndarray, slip: np.ndarray, stop_of: np.ndarray) -> tuple:
    """(K_s, F_s, G_s (n, p), R (p, n), Q (n, n), sigma mu k side (p,) of the slipping sliders) of one state."""
    fr = system.friction
    n, p = system.n, fr.p
    Ks = system.K.copy()
    Fs = np.zeros(n)
    for j in np.flatnonzero(closed):
        Ks += system.k[j] * np.outer(system.B[j], system.B[j])
        Fs += system.k[j] * system.offset[j] * system.B[j]
    G = np.zeros((n, p))
    R = np.zeros((p, n))
    Q = np.zeros((n, n))
    smks = np.zeros(p)
    for k in range(p):
        b, j = fr.Bt[k], stop_of[k]
        if j < 0:
            R[k] = b  # an open tip's slider follows its coordinate
        elif slip[k] == STICK:
            Ks += fr.k_t[k] * np.outer(b, b)
            G[:, k] = fr.k_t[k] * b
        else:
            a = slip[k] * fr.mu[k] * system.k[j] * system.side[j]  # f_k = a (B_j x - o_j)
            Ks += a * np.outer(b, system.B[j])
            Fs += a * system.offset[j] * b
            R[k] = b - (a / fr.k_t[k]) * system.B[j]
            Q += a * np.outer(system.B[j], R[k])
            smks[k] = a
    return Ks, Fs, G, R, Q, smks


def _structure(system: GapSystem, Ks: np.ndarray, Minv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lam, V_z) of A_z = [[0, I], [-M^-1 K_s, -M^-1 C]] (Minv = M^-1): the real modes when K_s is symmetric
    and the system undamped, else LAPACK's eigenpairs (flutter, Re lam > 0, included); refuses zero-frequency
    states (defective ones: :func:`friction_table`)."""
    n = system.n
    if system.undamped and np.array_equal(Ks, Ks.T):
        w2, phi = eigh(Ks, system.M)
        if w2[0] <= 1e-12 * w2[-1]:
            raise ExactIntegratorError("a friction state has a zero-frequency mode (stiffness singular); "
                                       "use method 'explicit'")
        w = np.sqrt(w2)
        return np.concatenate([1j * w, -1j * w]), np.block([[phi, phi], [1j * w * phi, -1j * w * phi]]).astype(complex)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ Ks, -Minv @ system.C]])
    lam, V = np.linalg.eig(A)
    if np.min(np.abs(lam)) <= 1e-9 * np.max(np.abs(lam)):
        raise ExactIntegratorError("a friction state has a zero-frequency mode (stiffness singular); "
                                   "use method 'explicit'")
    return lam, V


def _event_rows(system: GapSystem, st: FrictionStates, s: int, R: np.ndarray, omega_ref: float) -> tuple:
    """(rows (E, N), constants (E,), active (E,), successor states (E,), reset (E,), kinds (E,)) of state s."""
    fr = system.friction
    n, m, p = system.n, system.m, fr.p
    N, E = 2 * n + p, m + 2 * p
    closed, slip, stop_of = st.closed[s], st.slip[s], st.stop_of[s]
    rows = np.zeros((E, N))
    c = np.zeros(E)
    act = np.zeros(E, bool)
    succ = np.full(E, -1, np.int64)
    reset = np.zeros(E, bool)
    kind = np.zeros(E, np.int64)
    for j in range(m):
        sgn = -1.0 if closed[j] else 1.0
        rows[j, :n] = sgn * system.side[j] * system.B[j]
        c[j] = -sgn * system.side[j] * system.offset[j]
        act[j] = True
        new = closed.copy()
        if closed[j]:
            new[j] = False
        else:
            new[system.tip == system.tip[j]] = False
            new[j] = True
            reset[j] = True
        new_slip = slip.copy()
        new_slip[fr.tip == system.tip[j]] = STICK  # stick (engaged by the closing) or follow: both 0
        succ[j] = st.index(new, new_slip)
    for k in range(p):
        j = stop_of[k]
        if j < 0:
            continue
        up, down = m + 2 * k, m + 2 * k + 1
        muk = fr.mu[k] * system.k[j] * system.side[j]  # mu N_j = muk (B_j x - o_j)
        if slip[k] == STICK:
            for e, sign, code, kd in ((up, 1.0, SLIP_UP, KIND_STICK_UP), (down, -1.0, SLIP_DOWN, KIND_STICK_DOWN)):
                rows[e, :n] = (sign * fr.k_t[k] * fr.Bt[k] - muk * system.B[j]) / fr.k_t[k]
                rows[e, 2 * n + k] = -sign
                c[e] = muk * system.offset[j] / fr.k_t[k]
                act[e] = True
                new_slip = slip.copy()
                new_slip[k] = code
                succ[e] = st.index(closed, new_slip)
                kind[e] = kd
        else:
            e = up if slip[k] == SLIP_UP else down
            rows[e, n:2 * n] = -slip[k] * R[k] / omega_ref
            act[e] = True
            new_slip = slip.copy()
            new_slip[k] = STICK
            succ[e] = st.index(closed, new_slip)
            kind[e] = KIND_SLIP_END
    return rows, c, act, succ, reset, kind


def friction_table(system: GapSystem, omega_ref: float) -> FrictionTable:
    """Decompose every friction state of ``system`` (module docstring).

    Parameters
    ----------
    system : GapSystem
        A system with friction.
    omega_ref : float
        rad/s, scale of the slip-end events (the system's top frequency): q = w' / omega_ref in metres.

    Returns
    -------
    FrictionTable

    Raises
    ------
    ExactIntegratorError
        A state with a zero-frequency mode or a nearly defective one (cond(V) > ``MAX_COND``).
    """
    fr = system.friction
    n, m, p = system.n, system.m, fr.p
    N, E = 2 * n + p, m + 2 * p
    st = friction_states(system)
    S = st.S
    lam = np.zeros((S, N), complex)
    V = np.zeros((S, N, N), complex)
    Vinv = np.zeros((S, N, N), complex)
    yp = np.zeros((S, N))
    cond = np.ones(S)
    Ks_all = np.zeros((S, n, n))
    R_all = np.zeros((S, p, n))
    erow, ec = np.zeros((S, E, N)), np.zeros((S, E))
    eact, reset = np.zeros((S, E), bool), np.zeros((S, E), bool)
    succ, ekind = np.zeros((S, E), np.int64), np.zeros((S, E), np.int64)
    Df, LF = np.zeros((S, N, N)), np.zeros((S, n))
    table = FrictionTable(st, lam, V, Vinv, yp, cond, Ks_all, R_all, erow, ec, eact, succ, reset, ekind, Df, LF,
                          float(omega_ref))
    cache: dict[bytes, int] = {}
    with single_thread_blas():
        Minv = np.linalg.inv(system.M)
        for s in range(S):
            _state_links(system, table, s)
            _state_closed_form(system, table, s, Minv, cache)
    return table


def _slider_rates(system: GapSystem, slip: np.ndarray, stop_of: np.ndarray) -> np.ndarray:
    """R (p, n) of one state, the rows of the sliders' rates on v (:func:`_state_parts`'s, the same arithmetic,
    without the state's stiffness): Bt_k (open tip), 0 (sticking), Bt_k - (a_k / kt_k) B_j (slipping,
    a_k = sigma_k mu_k k_j side_j)."""
    fr = system.friction
    R = np.zeros((fr.p, system.n))
    for k in range(fr.p):
        j = stop_of[k]
        if j < 0:
            R[k] = fr.Bt[k]
        elif slip[k] != STICK:
            a = slip[k] * fr.mu[k] * system.k[j] * system.side[j]
            R[k] = fr.Bt[k] - (a / fr.k_t[k]) * system.B[j]
    return R


def _state_links(system: GapSystem, table: FrictionTable, s: int) -> None:
    """Fill state s's slider rates and events (rows, constants, successors; cheap) in ``table``."""
    st = table.states
    R = _slider_rates(system, st.slip[s], st.stop_of[s])
    table.R[s] = R
    rows, c, act, sc, rs, kd = _event_rows(system, st, s, R, table.omega_ref)
    table.erow[s], table.ec[s], table.eact[s], table.succ[s], table.reset[s], table.ekind[s] = rows, c, act, sc, rs, kd


def condition_bound(V: np.ndarray, Vinv: np.ndarray) -> float:
    """An upper bound of the 2-norm condition number ||V||_2 ||V^-1||_2 from the 1- and inf-norms of V and its
    inverse (computed anyway): ||A||_2 <= sqrt(||A||_1 ||A||_inf), so

        cond_2(V) <= sqrt(||V||_1 ||V||_inf ||V^-1||_1 ||V^-1||_inf) <= N cond_2(V).

    A state's first build needed an SVD for cond_2 (13 ms of its ~52 ms at the apparatus's N = 268); the bound
    costs four norms (0.2 ms). It only refuses nearly defective states (MAX_COND) and scales the run's reported
    round-off tolerance, so it errs on the safe side; the closed form (lam, V, V^-1) is unchanged.

    Parameters
    ----------
    V, Vinv : (N, N) complex, a state's eigenvectors and their inverse (NaN if singular)

    Returns
    -------
    float
        The bound (dimensionless; inf or NaN for a singular V).

    Examples
    --------
    >>> V = np.array([[1.0, 1.0], [0.0, 1e-3]])
    >>> s = np.linalg.svd(V, compute_uv=False)
    >>> c = condition_bound(V, np.linalg.inv(V))
    >>> bool(s[0] / s[-1] <= c <= 2 * s[0] / s[-1])
    True
    """
    n1, ni = np.linalg.norm(V, 1), np.linalg.norm(V, np.inf)
    m1, mi = np.linalg.norm(Vinv, 1), np.linalg.norm(Vinv, np.inf)
    return float(np.sqrt(n1 * ni) * np.sqrt(m1 * mi))


def _state_closed_form(system: GapSystem, table: FrictionTable, s: int, Minv: np.ndarray, cache: dict) -> None:
    """Fill state s's closed form (eigenpairs, equilibrium, condition) and friction power in ``table``
    (``cache``: the state decomposed for each set of state matrices so far); refuses a nearly defective state."""
    st = table.states
    n, p = system.n, system.friction.p
    N = 2 * n + p
    Ks, Fs, G, R, Q, smks = _state_parts(system, st.closed[s], st.slip[s], st.stop_of[s])
    table.Ks[s] = Ks
    stuck = [k for k in range(p) if np.any(G[:, k])]
    rhs = ([Fs] if np.any(Fs) else []) + [G[:, k] for k in stuck]
    # one factorization of K_s for the equilibrium and every stuck slider's column (a solve each factorized K_s
    # again: ~1 ms a solve at n = 130, ~0.5 s of the hammer-friction rig's 10 s)
    sol = np.linalg.solve(Ks, np.column_stack(rhs)) if rhs else np.zeros((n, 0))
    xp = sol[:, 0] if np.any(Fs) else np.zeros(n)
    table.yp[s, :n] = xp
    key = Ks.tobytes() + R.tobytes() + G.tobytes()
    if key in cache:  # a state of the same matrices decomposed before: its entries copied
        s0 = cache[key]
        for a in (table.lam, table.V, table.Vinv, table.cond):
            a[s] = a[s0]
    else:
        lz, Vz = _structure(system, Ks, Minv)
        Vs = np.zeros((N, N), complex)
        Vs[:2 * n, :2 * n] = Vz
        Vs[2 * n:, :2 * n] = (R @ Vz[n:, :]) / lz
        for k in range(p):
            Vs[2 * n + k, 2 * n + k] = 1.0
        for i, k in enumerate(stuck):
            Vs[:n, 2 * n + k] = sol[:, i + int(np.any(Fs))]
        try:
            Vi = np.linalg.inv(Vs)
        except np.linalg.LinAlgError:
            Vi = np.full((N, N), np.nan)
        cs = condition_bound(Vs, Vi)
        if not np.isfinite(cs) or cs > MAX_COND:
            raise ExactIntegratorError(
                f"friction state ({st.describe(system, s)}) is nearly defective (eigenvector condition "
                f"{cs:.1e}); use method 'explicit'")
        table.lam[s], table.V[s], table.Vinv[s], table.cond[s] = np.concatenate([lz, np.zeros(p)]), Vs, Vi, cs
        cache[key] = s
    table.Df[s, :n, n:2 * n] = 0.5 * Q
    table.Df[s, n:2 * n, :n] = 0.5 * Q.T
    for k in np.flatnonzero(smks):  # f_k = a (B_j x - o_j), its static part times R_k v
        j = st.stop_of[s, k]
        table.LF[s] += smks[k] * (system.B[j] @ xp - system.offset[j]) * R[k]


def _kept(lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(kept indices, kappa): one eigenvalue of each exact conjugate pair (Im > 0, kappa 2) and every real
    one (kappa 1), sorted by |lam| (the march bounds the last, fastest terms by their amplitude); all with
    kappa 1 when the spectrum does not pair up exactly."""
    up = np.flatnonzero(lam.imag > 0.0)
    real = np.flatnonzero(lam.imag == 0.0)
    down = np.flatnonzero(lam.imag < 0.0)
    paired = up.size == down.size and bool(np.all(np.any(lam[down][None, :] == np.conj(lam[up])[:, None], axis=1)))
    if not paired:
        keep, kappa = np.arange(lam.size), np.ones(lam.size)
    else:
        keep = np.concatenate([up, real])
        kappa = np.concatenate([np.full(up.size, 2.0), np.ones(real.size)])
    order = np.argsort(np.abs(lam[keep]), kind="stable")
    return keep[order], kappa[order]


def work_tables(lk: np.ndarray, Uk: np.ndarray, kappa: np.ndarray, D: np.ndarray) -> tuple:
    """The work integral int_0^tau y_h^T D_s y_h dt of every state in the kept-term form of
    :func:`reduced.transient.exact_tables.modal_table` (there D = [[0, 0], [0, C]]), for any symmetric D_s.

    Parameters
    ----------
    lk : (S, K) ndarray of complex
        Kept eigenvalues per state (0 for padding).
    Uk : (S, N, K) ndarray of complex
        Kept eigenvectors times kappa.
    kappa : (S, K) ndarray of float
        2 (a pair), 1 (real) or 0 (padding).
    D : (N, N) or (S, N, N) ndarray of float
        The symmetric quadratic form of the power.

    Returns
    -------
    tuple
        (Wm (S, 4, K, K), Hd (S, 2, K), pointer, i, k, kind, coefficient, z) as
        :func:`reduced.transient._modal._work` and :func:`reduced.transient._modal._work_near` read them.
    """
    S = Uk.shape[0]
    D = np.broadcast_to(D, (S,) + D.shape[-2:])
    Wm, Hd, irr_s = [], [], []
    for a in range(0, S, WORK_CHUNK):  # a few states at a time: the (S, K, K) complex temporaries of every
        # state at once (~100 MB each for the hammer-friction rig) cost more in page faults than in arithmetic;
        # every operation is per state (a GEMM per state, elementwise sums), so the chunks change no bits
        b = min(S, a + WORK_CHUNK)
        w, h, irr = _work_chunk(lk[a:b], Uk[a:b], kappa[a:b], D[a:b])
        Wm.append(w)
        Hd.append(h)
        irr_s.extend(irr)
    ip = np.zeros(S + 1, np.int64)
    irr: list = []
    for s in range(S):
        irr.extend(irr_s[s])
        ip[s + 1] = len(irr)
    return (np.ascontiguousarray(np.concatenate(Wm)), np.ascontiguousarray(np.concatenate(Hd)), ip,
            np.array([r[0] for r in irr], np.int64), np.array([r[1] for r in irr], np.int64),
            np.array([r[2] for r in irr], np.int64), np.array([r[3] for r in irr], complex),
            np.array([r[4] for r in irr], complex))


WORK_CHUNK = 16  # states a chunk of work_tables


def _work_chunk(lk: np.ndarray, Uk: np.ndarray, kappa: np.ndarray, D: np.ndarray) -> tuple:
    """(Wm, Hd, near-cancelling terms per state) of :func:`work_tables` for the states given (all arrays
    cut to them)."""
    S, _, Kmax = Uk.shape
    nz = np.flatnonzero(np.any(D != 0.0, axis=(0, 1)))  # the coordinates the power involves (D symmetric): the
    # viscous form only the velocities', the friction form a few contact rows; the products over them alone,
    # real D times the real and imaginary parts (the same sums without their zero terms, in another order)
    Un = Uk[:, nz, :]
    Dn = D[:, nz][:, :, nz]
    DU = np.matmul(Dn, Un.real) + 1j * np.matmul(Dn, Un.imag)
    G = 0.5 * np.matmul(Un.transpose(0, 2, 1), DU)
    H = 0.5 * np.matmul(Un.transpose(0, 2, 1), np.conj(DU))
    zG = lk[:, :, None] + lk[:, None, :]
    zH = lk[:, :, None] + np.conj(lk)[:, None, :]
    scale = ZNEAR * (np.abs(lk)[:, :, None] + np.abs(lk)[:, None, :])
    real = (kappa != 0.0)[:, :, None] & (kappa != 0.0)[:, None, :]
    offdiag = ~np.eye(Kmax, dtype=bool)
    regG = (np.abs(zG) >= scale) & (zG != 0.0)
    regH = (np.abs(zH) >= scale) & (zH != 0.0) & offdiag
    with np.errstate(divide="ignore", invalid="ignore"):
        Gz = np.where(regG & real, G / zG, 0.0)
        Hz = np.where(regH & real, H / zH, 0.0)
    upper = np.triu(np.ones((Kmax, Kmax), bool))
    irrG = np.nonzero(~regG & upper & real & (G != 0.0))
    irrH = np.nonzero(~regH & upper & offdiag & real & (H != 0.0))
    irr_s: list[list] = [[] for _ in range(S)]
    for s, i, k in zip(*irrG, strict=True):
        irr_s[s].append((i, k, 0, G[s, i, k] * (2.0 if k > i else 1.0), zG[s, i, k]))
    for s, i, k in zip(*irrH, strict=True):
        irr_s[s].append((i, k, 1, 2.0 * H[s, i, k], zH[s, i, k]))
    A, B, C, Dm = Gz.real, Gz.imag, Hz.real, Hz.imag
    Wm = np.stack([A + C, Dm - B, B + Dm, A - C], axis=1).transpose(0, 1, 3, 2)
    hd, zd = np.diagonal(H, axis1=1, axis2=2).real, 2.0 * lk.real
    with np.errstate(divide="ignore", invalid="ignore"):
        Hd = np.stack([np.where(zd != 0.0, hd / zd, 0.0), np.where(zd != 0.0, 0.0, hd)], axis=1)
    return Wm, Hd, irr_s


def friction_modal_table(system: GapSystem, ft: FrictionTable, work: tuple[bool, bool] = (True, True)) -> tuple:
    """The free segments' tables of :mod:`reduced.transient._friction_kernels`: the kept-term closed form,
    the events projected on the terms, the viscous and friction work.

    Parameters
    ----------
    system : GapSystem
        The system (with friction).
    ft : FrictionTable
        Its states.
    work : (bool, bool)
        Whether to tabulate the viscous and the friction work; a table not asked for is None (the kernels
        read neither the viscous work of an undamped system nor the friction work of a state without slip).

    Returns
    -------
    tuple
        (modal, events, viscous work, friction work): modal = (nK, lam, |lam|, U^T (S, 2, K, N) as Re/Im,
        Uinv (S, K, N), |Uinv|, y_p, gmul (S, K), hseg (S,)); events = (EU (S, E, K), |EU|, E0 (S, E),
        Escale (S, E), active, successor, reset, has_slip (S,), LF); the work tuples as :func:`work_tables`.
        hseg[s] is the longest segment of state s, ``GROWTH_SEGMENT`` / max Re lam (inf when no term grows),
        and gmul[s, i] = e^{Re(lam_i) hseg[s]} (<= 2) a growing term's factor over it, 1 for the others.
    """
    S, N = ft.lam.shape
    kept = [_kept(ft.lam[s]) for s in range(S)]
    Kmax = max(k.size for k, _ in kept)
    keep = np.zeros((S, Kmax), np.int64)
    kappa = np.zeros((S, Kmax))
    nK = np.array([k.size for k, _ in kept], np.int64)
    for s, (k, kp) in enumerate(kept):
        keep[s, :k.size], kappa[s, :k.size] = k, kp
    pad = kappa != 0.0
    lk = np.take_along_axis(ft.lam, keep, axis=1) * pad
    Uk = np.take_along_axis(ft.V, keep[:, None, :], axis=2) * kappa[:, None, :]
    Uinvk = np.take_along_axis(ft.Vinv, keep[:, :, None], axis=1) * pad[:, :, None]
    UT = np.ascontiguousarray(np.stack([Uk.real, Uk.imag], axis=1).transpose(0, 1, 3, 2))
    n = system.n
    Dv = np.zeros((N, N))
    Dv[n:2 * n, n:2 * n] = system.C
    EU = np.ascontiguousarray(np.matmul(ft.erow, Uk))
    E0 = np.ascontiguousarray(np.einsum("sen,sn->se", ft.erow, ft.yp) + ft.ec)
    Escale = np.ascontiguousarray(np.einsum("sen,sn->se", np.abs(ft.erow), np.abs(ft.yp)) + np.abs(ft.ec))
    has_slip = np.any(ft.states.slip != 0, axis=1)
    hseg, gmul = growth_segments(lk)
    modal = (nK, np.ascontiguousarray(lk), np.abs(lk), UT, np.ascontiguousarray(Uinvk), np.abs(Uinvk),
             np.ascontiguousarray(ft.yp), gmul, hseg)
    events = (EU, np.abs(EU), E0, Escale, np.ascontiguousarray(ft.eact), np.ascontiguousarray(ft.succ),
              np.ascontiguousarray(ft.reset), has_slip, np.ascontiguousarray(ft.LF))
    return (modal, events, work_tables(lk, Uk, kappa, Dv) if work[0] else None,
            work_tables(lk, Uk, kappa, ft.Df) if work[1] else None)


def growth_segments(lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hseg (S,), gmul (S, K)) of the states' eigenvalues ``lam`` (S, K): the longest segment of each state,
    ``GROWTH_SEGMENT`` / max Re lam (inf when no term grows), and each term's growth factor over it,
    e^{Re(lam_i) hseg} (<= 2) for a growing term, 1 for the others (:func:`reduced.transient._modal._march`).

    Parameters
    ----------
    lam : (S, K) ndarray of complex
        1/s, each state's eigenvalues (0 for padding).

    Returns
    -------
    hseg : (S,) ndarray of float
        s.
    gmul : (S, K) ndarray of float
        >= 1.
    """
    g = np.max(np.maximum(lam.real, 0.0), axis=1)
    with np.errstate(divide="ignore"):
        hseg = np.where(g > 0.0, GROWTH_SEGMENT / g, np.inf)
    gmul = np.ones(lam.shape)
    grow = lam.real > 0.0
    gmul[grow] = np.exp(lam.real[grow] * np.broadcast_to(hseg[:, None], lam.shape)[grow])
    return np.ascontiguousarray(hseg), gmul


@dataclass(frozen=True, eq=False)
class FrictionForcedTable:
    """Per-state data of the loads on the augmented flow (as :class:`reduced.transient.exact_tables.ForcedTable`).

    Attributes
    ----------
    omega : (L,) ndarray of float
        rad/s, each load's harmonic frequency (0: none).
    Y : (S, N, L) ndarray of complex
        (i omega_l I - A_s)^-1 [0; M^-1 b_l; 0]: the harmonic particular solutions.
    U : (S, N, L) ndarray of complex
        Modal loads V^-1 [0; M^-1 b_l; 0] (zero on the sliders' zero eigenvalues).
    Sb : (S, n, L) ndarray of float
        K_s^-1 b_l, static deflections (m/N): scales of the round-off.
    b : (L, n) ndarray of float
        Load directions.
    """

    omega: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    Sb: np.ndarray
    b: np.ndarray


def friction_forced_table(system: GapSystem, ft: FrictionTable, loads) -> FrictionForcedTable:
    """Per-state particular solutions of ``loads`` on the augmented flow; refuses an undamped resonance.

    Parameters
    ----------
    system : GapSystem
        The system (with friction).
    ft : FrictionTable
        Its states.
    loads : Loads
        The loads.

    Returns
    -------
    FrictionForcedTable

    Raises
    ------
    ExactIntegratorError
        A load at an undamped resonance of a state (within ``RESONANCE_REL``).
    """
    n, p = system.n, system.p
    N = 2 * n + p
    b = np.ascontiguousarray(loads.b, dtype=float)
    omega = loads.omegas()
    S, L = ft.lam.shape[0], b.shape[0]
    Minv_b = np.linalg.solve(system.M, b.T)
    g = np.zeros((N, L))
    g[n:2 * n] = Minv_b
    table = FrictionForcedTable(omega, np.zeros((S, N, L), complex), np.zeros((S, N, L), complex),
                                np.zeros((S, n, L)), b)
    for s in range(S):
        _forced_state(system, ft, table, s, g, loads)
    return table


def _forced_state(system: GapSystem, ft: FrictionTable, table: FrictionForcedTable, s: int, g: np.ndarray,
                  loads) -> None:
    """Fill state s of ``table`` (``g`` (N, L): [0; M^-1 b_l; 0]); refuses a load at an undamped resonance."""
    n = system.n
    omega, b, U = table.omega, table.b, table.U
    lam = ft.lam[s, :2 * n]
    U[s] = ft.Vinv[s] @ g
    table.Sb[s] = solve(ft.Ks[s], b.T)
    for l in range(b.shape[0]):
        if omega[l] > 0.0:
            i = int(np.argmin(np.abs(1j * omega[l] - lam)))
            if abs(1j * omega[l] - lam[i]) <= RESONANCE_REL * omega[l]:
                raise ExactIntegratorError(
                    f"load {l + 1} ({loads.points[l]}) at {omega[l] / (2 * math.pi):.6g} Hz is at an undamped "
                    f"resonance of friction state ({ft.states.describe(system, s)}); use method 'explicit'")
            # (i w - A)^-1 g = V diag(1 / (i w - lam)) V^-1 g
            table.Y[s, :, l] = ft.V[s] @ (U[s, :, l] / (1j * omega[l] - ft.lam[s]))


def _state_zeros(shape: tuple, dtype=float) -> np.ndarray:
    """np.zeros(shape, dtype) for a table with a slice per state, of which a run fills a few, scattered: above
    ``SMALL_PAGES_BYTES`` mapped in small pages where the OS allows (madvise MADV_NOHUGEPAGE). With transparent huge
    pages the first write to a state's slice (~1 MB for the hammer-friction rig) would make the OS zero the 2 MB
    pages around it, for each of the tables: measured 4.8 ms a 0.6 MB slice against 0.27 ms in small pages, a third
    of a state's build. The values are zeros either way."""
    dtype = np.dtype(dtype)
    count = math.prod(shape)
    if count * dtype.itemsize <= SMALL_PAGES_BYTES or not hasattr(mmap, "MADV_NOHUGEPAGE"):
        return np.zeros(shape, dtype)
    buf = mmap.mmap(-1, count * dtype.itemsize, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)  # zero-filled
    buf.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(buf, dtype=dtype, count=count).reshape(shape)


def _empty_table(system: GapSystem, omega_ref: float) -> FrictionTable:
    """A FrictionTable of every state of ``system`` with zeros (cond 1) in place of the states' data."""
    n, m, p = system.n, system.m, system.friction.p
    N, E = 2 * n + p, m + 2 * p
    st = friction_states(system)
    S = st.S
    z = _state_zeros
    return FrictionTable(st, z((S, N), complex), z((S, N, N), complex), z((S, N, N), complex), z((S, N)), np.ones(S),
                         z((S, n, n)), z((S, p, n)), z((S, E, N)), z((S, E)), z((S, E), bool), z((S, E), np.int64),
                         z((S, E), bool), z((S, E), np.int64), z((S, N, N)), z((S, n)), float(omega_ref))


def _one_state(ft: FrictionTable, s: int) -> FrictionTable:
    """State s of ``ft`` as a table of one state (views; the successors keep their indices into ``ft``)."""
    st = ft.states
    one = slice(s, s + 1)
    return FrictionTable(FrictionStates(st.closed[one], st.slip[one], st.stop_of[one]), ft.lam[one], ft.V[one],
                         ft.Vinv[one], ft.yp[one], ft.cond[one], ft.Ks[one], ft.R[one], ft.erow[one], ft.ec[one],
                         ft.eact[one], ft.succ[one], ft.reset[one], ft.ekind[one], ft.Df[one], ft.LF[one], ft.omega_ref)


class LazyFrictionTables:
    """The tables of :func:`friction_table` and :func:`friction_modal_table`, each state's built the first time
    a run enters it (:meth:`ensure`): a motion visits few of the states (a hammer record of the apparatus 36-61
    of its 361), and a state's closed form (an eigendecomposition of order 2n + p, its inverse, condition and
    work tables) is most of the tables' cost.

    The links of a state (event rows, successors, resets, kinds; ~1 ms) are filled the first time a run reads
    them (:meth:`link`: on entering it, before its closed form or without it). A state's entries, once built,
    are those :func:`friction_table` and :func:`friction_modal_table` give it (the same arithmetic on the
    state's slice) and never change; unbuilt entries hold zeros, which the
    kernels never read (they return ``NEW_STATE`` on entering a state whose ``built`` flag is False). When a
    state keeps more terms than the term arrays hold, they are reallocated larger. Each build makes a new
    ``built`` array (and new arrays of the near-cancelling work terms), so a kernel running on the arrays of
    :meth:`arrays` (in another thread) only reads states built before its call.

    Parameters
    ----------
    system : GapSystem
        With friction.
    omega_ref : float
        rad/s, the slip-end events' scale (:func:`friction_table`).
    """

    def __init__(self, system: GapSystem, omega_ref: float) -> None:
        self.system = system
        self.table = _empty_table(system, omega_ref)
        self.linked = np.zeros(self.S, bool)  # states whose links are filled (:meth:`link`)
        self.built = np.zeros(self.S, bool)
        self.has_slip = np.any(self.table.states.slip != 0, axis=1)
        with single_thread_blas():
            self._Minv = np.linalg.inv(system.M)
        self._cache: dict[bytes, int] = {}
        self._groups: list | None = None  # the modal, events, viscous and friction work arrays of every state
        self._near: tuple = ([()] * self.S, [()] * self.S)  # each state's near-cancelling work terms
        self._lock = threading.Lock()
        self.build_s = 0.0  # s spent building states
        self.row_tables: dict = {}  # the output rows' per-state tables of the runs' kernels (exact.SampleRows)

    @property
    def S(self) -> int:
        return self.table.states.S

    def link(self, s: int) -> None:
        """Fill state s's links (slider rates, event rows, constants, successors, resets, kinds; ~1 ms) unless
        they are: what a run reads of a state it enters before or without its closed form (the pass-through of
        :mod:`reduced.transient.friction_probe`, an event's kind in the log)."""
        if not self.linked[s]:
            _state_links(self.system, self.table, s)
            self.linked[s] = True

    def ensure(self, s: int) -> bool:
        """Build state ``s`` unless it is built; True if it was built now.

        Raises
        ------
        ExactIntegratorError
            The state is nearly defective or has a zero-frequency mode (:func:`friction_table`).
        """
        if self.built[s]:
            return False
        with self._lock:
            if self.built[s]:
                return False
            t0 = time.perf_counter()
            self.link(s)
            with single_thread_blas():
                _state_closed_form(self.system, self.table, s, self._Minv, self._cache)
                groups = friction_modal_table(self.system, _one_state(self.table, s),
                                              (not self.system.undamped, bool(self.has_slip[s])))
            self._store(s, groups)
            built = self.built.copy()
            built[s] = True
            self.built = built
            self.build_s += time.perf_counter() - t0
        return True

    def _store(self, s: int, groups: tuple) -> None:
        """Write state s's entries (``groups``: :func:`friction_modal_table` of the state alone)."""
        K1 = groups[0][1].shape[1]
        if self._groups is None or K1 > self._groups[0][1].shape[1]:
            self._grow(K1)
        for g, i in self._term_keys:
            if groups[g] is None:
                continue  # a work table not needed: its zeros stay
            a = groups[g][i][0]  # its term axes may be shorter than the arrays'
            self._groups[g][i][s][tuple(slice(0, d) for d in a.shape)] = a
        modal, events = self._groups[0], self._groups[1]
        modal[0][s], modal[8][s] = groups[0][0][0], groups[0][8][0]
        events[2][s], events[3][s] = groups[1][2][0], groups[1][3][0]
        for w in (0, 1):
            work = groups[2 + w]
            if work is not None:
                self._near[w][s] = tuple(a[work[2][0]:work[2][1]] for a in work[3:])
                self._groups[2 + w][2:] = _near_arrays(self._near[w])

    def _grow(self, K: int) -> None:
        """(Re)allocate the arrays of every state for K kept terms, the built states' entries copied."""
        S, old = self.S, self._groups
        t = self.table
        N, E = t.lam.shape[1], t.ec.shape[1]
        new = [[np.zeros(S, np.int64)] + [None] * 5 + [t.yp] + [None, np.zeros(S)],
               [None, None, np.zeros((S, E)), np.zeros((S, E)), t.eact, t.succ, t.reset, self.has_slip, t.LF],
               [None] * 8, [None] * 8]
        shapes = {(0, 1): ((S, K), complex), (0, 2): ((S, K), float), (0, 3): ((S, 2, K, N), float),
                  (0, 4): ((S, K, N), complex), (0, 5): ((S, K, N), float), (0, 7): ((S, K), float),
                  (1, 0): ((S, E, K), complex), (1, 1): ((S, E, K), float), (2, 0): ((S, 4, K, K), float),
                  (2, 1): ((S, 2, K), float), (3, 0): ((S, 4, K, K), float), (3, 1): ((S, 2, K), float)}
        self._term_keys = tuple(shapes)  # the arrays whose axes run over the kept terms, by (group, index)
        for (g, i), (shape, dtype) in shapes.items():
            new[g][i] = np.ones(shape, dtype) if (g, i) == (0, 7) else _state_zeros(shape, dtype)  # gmul pads with 1
            if old is not None:
                b = old[g][i]
                new[g][i][tuple(slice(0, n) for n in b.shape)] = b
        if old is not None:
            for g, i in ((0, 0), (0, 8), (1, 2), (1, 3)):
                new[g][i] = old[g][i]
        for w in (2, 3):
            new[w][2:] = _near_arrays(self._near[w - 2])
        self._groups = new

    def arrays(self) -> tuple:
        """(modal, events, viscous work, friction work, built): the kernels' tables of every state
        (:func:`friction_modal_table`'s layout) as they stand, with the flags of the states built."""
        if self._groups is None:
            raise RuntimeError("no state built yet: call ensure(s) first")
        return tuple(tuple(g) for g in self._groups) + (self.built,)


def _near_arrays(near: list) -> list:
    """[pointer (S + 1,), i, k, kind, coefficient, z] of :func:`work_tables` from each state's near-cancelling
    terms (a tuple of those five arrays, or () for a state without)."""
    counts = [t[0].size if t else 0 for t in near]
    ip = np.zeros(len(near) + 1, np.int64)
    ip[1:] = np.cumsum(counts)
    parts = [t for t in near if t]
    dtypes = (np.int64, np.int64, np.int64, complex, complex)
    cols = [np.concatenate([t[c] for t in parts]).astype(dt) if parts else np.zeros(0, dt)
            for c, dt in enumerate(dtypes)]
    return [ip] + cols


class LazyForcedTable:
    """The loads' per-state data (:func:`friction_forced_table`), each state's built with the state's tables
    (:meth:`ensure`, :class:`LazyFrictionTables`).

    Parameters
    ----------
    tables : LazyFrictionTables
    loads : Loads
    """

    def __init__(self, tables: LazyFrictionTables, loads) -> None:
        system = tables.system
        n, p = system.n, system.p
        N, S = 2 * n + p, tables.S
        b = np.ascontiguousarray(loads.b, dtype=float)
        L = b.shape[0]
        self.tables, self.loads = tables, loads
        self.table = FrictionForcedTable(loads.omegas(), np.zeros((S, N, L), complex), np.zeros((S, N, L), complex),
                                         np.zeros((S, n, L)), b)
        self._g = np.zeros((N, L))
        self._g[n:2 * n] = np.linalg.solve(system.M, b.T)
        self.built = np.zeros(S, bool)

    def ensure(self, s: int) -> bool:
        """Build state ``s`` (its tables first) unless it is built; True if it was built now."""
        if self.built[s]:
            return False
        self.tables.ensure(s)
        with single_thread_blas():
            _forced_state(self.tables.system, self.tables.table, self.table, s, self._g, self.loads)
        built = self.built.copy()
        built[s] = True
        self.built = built
        return True
