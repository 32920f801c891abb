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
the moments int_0^tau t^m e^{u t} dt (:func:`_moments`: recursions run in their stable
directions, a series where |u tau| < ``TAYLOR_ZT``), so the balance
E(t) = E(0) + W_ext(t) - W(t) holds to round-off under forcing as well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.linalg import eigh, solve

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.transient import _modal
from reduced.transient.result import RingdownResult, RingdownStream, sample_count

EPS = np.finfo(float).eps
QTOL_REL = 64.0 * EPS  # q is a sum of ~2n terms: round-off of its evaluation, relative
HMIN_PERIODS = 1e-9  # the march's smallest step, in units of 1/omega_max (grazing floor)
MAX_MARCH_ITER = 10_000_000  # per stop per segment: a hang guard, never reached in practice
MAX_COND = 1e10  # refuse nearly defective (critically damped) states
NOISE_FACTOR = 4.0  # margin on the propagated round-off bound of q and q'
REST_FLOOR = 1e-15  # motion this small relative to the initial one is round-off at rest
RESONANCE_REL = 1e-6  # |i omega - lambda| below this x omega: an undamped resonance, refused
TAYLOR_ZT = 0.5  # |u tau| below which int_0^tau t^r e^{u t} dt is summed as a series ...
TAYLOR_TERMS = 17  # ... of at most this many terms (0.5^18 / 18! ~ 6e-22: exact to round-off)
SLOW_LT = 1.0  # |lambda| tau below which a mode is slow over a segment: written as its Taylor series ...
POLY_DEG = 20  # ... of this degree (1 / 21! ~ 2e-20: exact to round-off)
MOMENT_TOP = 130  # start of the downward moment recursion: damps its start by prod |x| / m < 1e-40


class ExactIntegratorError(RuntimeError):
    """The exact integrator cannot treat this system or run (the message says why)."""


@dataclass(frozen=True, eq=False)
class StateTable:
    """Closed-form data of every contact state, indexed by sum_j active_j 2^j."""

    lam: np.ndarray  # (S, 2n) complex, eigenvalues
    V: np.ndarray  # (S, 2n, 2n) complex, eigenvectors
    Vinv: np.ndarray  # (S, 2n, 2n) complex
    yp: np.ndarray  # (S, 2n), equilibrium [K_s^-1 F_s; 0]
    valid: np.ndarray  # (S,) bool, feasible states
    cond: np.ndarray  # (S,) condition number of V: the closed form loses cond eps |y|


def _decompose_undamped(system: GapSystem, Ks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(lam, V, Vinv, cond(V)) of an undamped state from the real modes of (Ks, M): lam = +-i omega."""
    w2, phi = eigh(Ks, system.M)
    if w2[0] <= 1e-12 * w2[-1]:
        raise ExactIntegratorError(
            "a contact state has a zero-frequency mode (stiffness singular); "
            "the exact method needs every state to oscillate: use method 'explicit'"
        )
    w = np.sqrt(w2)
    V = np.block([[phi, phi], [1j * w * phi, -1j * w * phi]]).astype(complex)
    PM = phi.T @ system.M
    Vinv = 0.5 * np.block([[PM, PM / (1j * w)[:, None]], [PM, -PM / (1j * w)[:, None]]])
    lam = np.concatenate([1j * w, -1j * w])
    return lam, V, Vinv, float(np.linalg.cond(V))


def _decompose_damped(system: GapSystem, Ks_list: list[np.ndarray]) -> list[tuple]:
    """[(lam, V, Vinv, cond(V))] of the damped states with stiffnesses ``Ks_list``: the eigenpairs of
    A = [[0, I], [-M^-1 K_s, -M^-1 C]], all states in one stacked LAPACK call."""
    n = system.n
    Minv = np.linalg.inv(system.M)
    A = np.zeros((len(Ks_list), 2 * n, 2 * n))
    A[:, :n, n:] = np.eye(n)
    A[:, n:, :n] = -np.matmul(Minv, np.stack(Ks_list))
    A[:, n:, n:] = -Minv @ system.C
    lam, V = np.linalg.eig(A)
    sv = np.linalg.svd(V, compute_uv=False)
    cond = sv[:, 0] / sv[:, -1]
    for k in range(len(Ks_list)):
        if not np.isfinite(cond[k]) or cond[k] > MAX_COND:
            raise ExactIntegratorError(
                f"a contact state is nearly defective (eigenvector condition {cond[k]:.1e}, e.g. a "
                "critically damped mode); use method 'explicit' or 'dop853'"
            )
        if np.max(lam[k].real) > 1e-9 * np.max(np.abs(lam[k])):
            raise ExactIntegratorError("a contact state is unstable (Re lambda > 0): check K and C")
    Vinv = np.linalg.inv(V)
    return [(lam[k], V[k], Vinv[k], float(cond[k])) for k in range(len(Ks_list))]


def state_table(system: GapSystem) -> StateTable:
    """Decompose every feasible contact state; mirrored states share one decomposition.

    K_s = K + sum_j active_j k_j B_j^T B_j and F_s = sum_j active_j k_j o_j B_j for all states at once,
    y_p = K_s^-1 F_s by stacked LU (a mirrored state's F_s is the exact negative of its twin's, and so
    is its y_p). The dense algebra runs on one BLAS thread (:func:`reduced._blas.single_thread_blas`):
    these matrices are small, and threads on busy cores cost far more than they save."""
    _check.gap_system(system)
    n, m = system.n, system.m
    S = 2**m
    lam = np.zeros((S, 2 * n), complex)
    V = np.zeros((S, 2 * n, 2 * n), complex)
    Vinv = np.zeros((S, 2 * n, 2 * n), complex)
    yp = np.zeros((S, 2 * n))
    valid = np.zeros(S, bool)
    cond = np.ones(S)
    with single_thread_blas():
        act = np.array(system.feasible_states(), dtype=float)  # (F, m)
        index = (act @ (1 << np.arange(m))).astype(np.int64)
        BB = system.k[:, None, None] * (system.B[:, :, None] * system.B[:, None, :])  # (m, n, n)
        Ks_all = system.K + np.einsum("fj,jab->fab", act, BB)
        Fs_all = np.einsum("fj,ja->fa", act, (system.k * system.offset)[:, None] * system.B)
        keys: dict[bytes, int] = {}
        unique: list[np.ndarray] = []
        which = np.empty(len(index), np.int64)
        for f, Ks in enumerate(Ks_all):
            key = Ks.tobytes()
            if key not in keys:
                keys[key] = len(unique)
                unique.append(Ks)
            which[f] = keys[key]
        has_f = np.any(Fs_all != 0.0, axis=1)
        if np.any(has_f):
            yp[index[has_f], :n] = np.linalg.solve(Ks_all[has_f], Fs_all[has_f][:, :, None])[:, :, 0]
        if system.undamped:
            dec = [_decompose_undamped(system, Ks) for Ks in unique]
        else:
            dec = _decompose_damped(system, unique)
        for s, k in zip(index, which, strict=True):
            lam[s], V[s], Vinv[s], cond[s] = dec[k]
            valid[s] = True
    return StateTable(lam, V, Vinv, yp, valid, cond)


ZNEAR = 1e-2  # |z| below this x (|lam_i| + |lam_k|): a near-cancelling pair of the work integral


def _kept_terms(lam: np.ndarray, undamped: bool, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(kept indices, kappa): one eigenvalue of each conjugate pair (Im > 0, kappa = 2) and every real
    one (kappa = 1), sorted by |lam|; all 2n with kappa = 1 when the spectrum does not pair up."""
    if undamped:
        keep = np.arange(n)  # lam = [i omega, -i omega]
        kappa = np.full(n, 2.0)
    else:
        up = np.flatnonzero(lam.imag > 0.0)
        real = np.flatnonzero(lam.imag == 0.0)
        down = np.flatnonzero(lam.imag < 0.0)
        # LAPACK returns the pairs of a real matrix as exact conjugates, eigenvectors too
        paired = up.size == down.size and all(np.any(lam[down] == np.conj(lam[i])) for i in up)
        if not paired:
            return np.arange(2 * n), np.ones(2 * n)
        keep = np.concatenate([up, real])
        kappa = np.concatenate([np.full(up.size, 2.0), np.ones(real.size)])
    order = np.argsort(np.abs(lam[keep]), kind="stable")
    return keep[order], kappa[order]


def modal_table(system: GapSystem, table: StateTable) -> tuple:
    """The free segments' tables of :mod:`reduced.transient._modal` for the states of ``table``.

    For each state s: the K kept terms (:func:`_kept_terms`) lam, |lam|, U = kappa V[:, kept] (as
    Re/Im of U^T), Uinv = Vinv[kept], |Uinv|, the stops' rows B U and |B U|, B y_p, and the work
    integral's 1/2 G / z, 1/2 H / z over the regular pairs (as the four real matrices of
    :func:`reduced.transient._modal._work`), the diagonal of H (1/2 H_ii, z = 2 Re lam_i) and the
    near-cancelling pairs (|z| < ZNEAR (|lam_i| + |lam_k|)) as lists (pointer, i, k, kind 0: G, 1: H,
    coefficient, z), G = U_v^T C U_v, H = U_v^T C conj(U_v) (U_v: the velocity rows). The distinct
    decompositions are worked out together; states with fewer terms are padded with zeros; an
    infeasible state has K = -1.
    """
    n = system.n
    S = table.lam.shape[0]
    valid = np.flatnonzero(table.valid)
    keys: dict[bytes, int] = {}
    u_of = np.full(S, -1, np.int64)
    reps: list[int] = []
    for s in valid:
        key = table.V[s].tobytes()
        if key not in keys:
            keys[key] = len(reps)
            reps.append(int(s))
        u_of[s] = keys[key]
    kept = [_kept_terms(table.lam[s], system.undamped, n) for s in reps]
    Kmax = max(k.size for k, _ in kept)
    nU = len(reps)
    keep = np.zeros((nU, Kmax), np.int64)
    kappa = np.zeros((nU, Kmax))  # 0: a padding term
    nK_u = np.array([k.size for k, _ in kept])
    for u, (k, kp) in enumerate(kept):
        keep[u, :k.size], kappa[u, :k.size] = k, kp
    lk = np.take_along_axis(table.lam[reps], keep, axis=1) * (kappa != 0.0)
    Uk = np.take_along_axis(table.V[reps], keep[:, None, :], axis=2) * kappa[:, None, :]
    Uinvk = np.take_along_axis(table.Vinv[reps], keep[:, :, None], axis=1) * (kappa != 0.0)[:, :, None]
    Uv = Uk[:, n:, :]
    CU = np.matmul(system.C, Uv)
    G = 0.5 * np.matmul(Uv.transpose(0, 2, 1), CU)
    H = 0.5 * np.matmul(Uv.transpose(0, 2, 1), np.conj(CU))
    zG = lk[:, :, None] + lk[:, None, :]
    zH = lk[:, :, None] + np.conj(lk)[:, None, :]
    scale = ZNEAR * (np.abs(lk)[:, :, None] + np.abs(lk)[:, None, :])
    real = (kappa != 0.0)[:, :, None] & (kappa != 0.0)[:, None, :]  # both terms real ones, not padding
    offdiag = ~np.eye(Kmax, dtype=bool)
    regG = (np.abs(zG) >= scale) & (zG != 0.0)
    regH = (np.abs(zH) >= scale) & (zH != 0.0) & offdiag
    with np.errstate(divide="ignore", invalid="ignore"):
        Gz = np.where(regG & real, G / zG, 0.0)
        Hz = np.where(regH & real, H / zH, 0.0)
    upper = np.triu(np.ones((Kmax, Kmax), bool))
    irrG = np.nonzero(~regG & upper & real)
    irrH = np.nonzero(~regH & upper & offdiag & real)
    # per distinct decomposition: (i, k, kind, coefficient, z), G's off-diagonal pairs doubled, H's too
    irr_u: list[list] = [[] for _ in range(nU)]
    for u, i, k in zip(*irrG, strict=True):
        irr_u[u].append((i, k, 0, G[u, i, k] * (2.0 if k > i else 1.0), zG[u, i, k]))
    for u, i, k in zip(*irrH, strict=True):
        irr_u[u].append((i, k, 1, 2.0 * H[u, i, k], zH[u, i, k]))
    A, B, C, D = Gz.real, Gz.imag, Hz.real, Hz.imag  # see _modal._work
    Wm_u = np.stack([A + C, D - B, B + D, A - C], axis=1).transpose(0, 1, 3, 2)
    UT_u = np.stack([Uk.real, Uk.imag], axis=1).transpose(0, 1, 3, 2)  # (U, 2, K, N)
    BU_u = np.matmul(system.B, Uk[:, :n, :])

    def per_state(a_u: np.ndarray) -> np.ndarray:
        out = np.zeros((S,) + a_u.shape[1:], a_u.dtype)
        out[valid] = a_u[u_of[valid]]
        return np.ascontiguousarray(out)

    nK = np.full(S, -1, np.int64)
    nK[valid] = nK_u[u_of[valid]]
    lam, BU = per_state(lk), per_state(BU_u)
    Uinv = per_state(Uinvk)
    Byp = np.einsum("sa,ja->sj", table.yp[:, :n], system.B)  # the same sums for every state: mirrors negate
    ip = np.zeros(S + 1, np.int64)
    irr: list = []
    for s in range(S):
        if u_of[s] >= 0:
            irr.extend(irr_u[u_of[s]])
        ip[s + 1] = len(irr)
    ii = np.array([r[0] for r in irr], np.int64)
    ik = np.array([r[1] for r in irr], np.int64)
    ikind = np.array([r[2] for r in irr], np.int64)
    icoef = np.array([r[3] for r in irr], complex)
    iz = np.array([r[4] for r in irr], complex)
    # H's diagonal, 1/2 H_ii |w_i|^2 (e^{2 a tau} - 1) / (2 a), a = Re lam_i: [1/2 H_ii / (2 a), 0], or [0, 1/2 H_ii]
    # (times tau) where a = 0 (_modal._work)
    hd, zd = np.diagonal(H, axis1=1, axis2=2).real, 2.0 * lk.real
    with np.errstate(divide="ignore", invalid="ignore"):
        Hd = np.stack([np.where(zd != 0.0, hd / zd, 0.0), np.where(zd != 0.0, 0.0, hd)], axis=1)
    return (nK, lam, np.abs(lam), per_state(UT_u), Uinv, np.abs(Uinv), np.ascontiguousarray(table.yp), BU,
            np.abs(BU), np.ascontiguousarray(Byp), per_state(Wm_u), per_state(Hd), ip, ii, ik, ikind, icoef, iz)


@dataclass(frozen=True, eq=False)
class ForcedTable:
    """Per-state data of the loads (see the module docstring)."""

    omega: np.ndarray  # (L,) rad/s, each load's harmonic frequency (0: no harmonic term)
    Y: np.ndarray  # (S, 2n, L) complex, [H_l b_l; i omega_l H_l b_l], H_l = (K_s - omega_l^2 M + i omega_l C)^-1
    U: np.ndarray  # (S, 2n, L) complex, modal loads V^-1 [0; M^-1 b_l]
    Sb: np.ndarray  # (S, n, L), K_s^-1 b_l (static deflections: scales of the round-off)
    b: np.ndarray  # (L, n) load directions


def forced_table(system: GapSystem, table: StateTable, loads) -> ForcedTable:
    """Per-state particular solutions of ``loads`` (a :class:`~reduced.models.loads.Loads`) for the
    exact integrator and the flow; refuses an undamped resonance or a state with a rigid-body mode."""
    n = system.n
    b = np.ascontiguousarray(loads.b, dtype=float)
    omega = loads.omegas()
    S, L = table.lam.shape[0], b.shape[0]
    Y = np.zeros((S, 2 * n, L), complex)
    U = np.zeros((S, 2 * n, L), complex)
    Sb = np.zeros((S, n, L))
    Minv_b = np.linalg.solve(system.M, b.T)
    cache: dict[bytes, tuple] = {}
    for active in system.feasible_states():
        s = int(np.sum(active * (1 << np.arange(system.m))))
        Ks, _ = system.state_matrices(active)
        key = Ks.tobytes()
        if key not in cache:
            lam = table.lam[s]
            if np.min(np.abs(lam)) <= 1e-9 * np.max(np.abs(lam)):
                raise ExactIntegratorError(
                    f"contact state {_state_name(system, active)} has a rigid-body mode: a load on it has no "
                    "bounded particular solution; use method 'dop853' or 'explicit'")
            for l in range(L):
                if omega[l] > 0.0:
                    i = int(np.argmin(np.abs(1j * omega[l] - lam)))
                    if abs(1j * omega[l] - lam[i]) <= RESONANCE_REL * omega[l]:
                        raise ExactIntegratorError(
                            f"load {l + 1} ({loads.points[l]}) at {omega[l] / (2 * math.pi):.6g} Hz is at an undamped "
                            f"resonance of contact state {_state_name(system, active)} (natural frequency "
                            f"{abs(lam[i].imag) / (2 * math.pi):.6g} Hz): the exact closed form has no bounded "
                            "particular solution there; use method 'dop853' or 'explicit'")
            y = np.zeros((2 * n, L), complex)
            for l in range(L):
                if omega[l] > 0.0:
                    h = solve(Ks - omega[l] ** 2 * system.M + 1j * omega[l] * system.C, b[l].astype(complex))
                    y[:n, l], y[n:, l] = h, 1j * omega[l] * h
            cache[key] = (y, table.Vinv[s][:, n:] @ Minv_b, solve(Ks, b.T))
        Y[s], U[s], Sb[s] = cache[key]
    return ForcedTable(omega, Y, U, Sb, b)


def _state_name(system: GapSystem, active: np.ndarray) -> str:
    closed = [system.stop_names[j] for j in np.flatnonzero(active)]
    return "(" + (", ".join(closed) + " closed" if closed else "all stops open") + ")"


def free_forced_arrays(n: int) -> tuple:
    """The forcing arguments of the kernels for a free run (no loads): empty arrays."""
    return (np.zeros(0), np.zeros((1, 2 * n, 0), complex), np.zeros((1, 2 * n, 0), complex), np.zeros((0, n)),
            np.zeros(1), np.zeros((1, 0), complex), np.zeros((1, 0)), np.zeros((1, 0)))


def forced_arrays(ft: ForcedTable, pieces) -> tuple:
    """The forcing arguments of the kernels: the table and the pieces (a PieceTable)."""
    on = pieces.F != 0.0
    if np.any(on & (pieces.omega != ft.omega[None, :])):
        raise ExactIntegratorError("internal: a load piece's frequency differs from its load's")
    return (ft.omega, ft.Y, ft.U, ft.b, np.ascontiguousarray(pieces.starts), np.ascontiguousarray(pieces.F),
            np.ascontiguousarray(pieces.p0), np.ascontiguousarray(pieces.p1))


@nb.njit(cache=True)
def _work_setup(X, C, lam, n, G, Gz, az):
    """Per segment: G[i, k] = a_i^T C a_k (v = sum_i a_i e^{lam_i t}, a_i = X[n:, i]), and for
    the primitive of e^{(lam_i + lam_k) t}: Gz = G / (lam_i + lam_k), az = |lam_i + lam_k|."""
    N = lam.shape[0]
    CX = np.zeros((n, N), np.complex128)
    for a in range(n):
        for b in range(n):
            if C[a, b] != 0.0:
                for k in range(N):
                    CX[a, k] += C[a, b] * X[n + b, k]
    for i in range(N):
        for k in range(i, N):
            acc = 0.0 + 0.0j
            for a in range(n):
                acc += X[n + a, i] * CX[a, k]
            G[i, k] = acc
            z = lam[i] + lam[k]
            az[i, k] = abs(z)
            Gz[i, k] = acc / z if z != 0.0 else 0.0


@nb.njit(cache=True)
def _work(G, Gz, az, lam, tau, e):
    """int_0^tau v^T C v dt = sum_{i,k} G_ik (e^{(lam_i + lam_k) tau} - 1) / (lam_i + lam_k), with
    e_i = e^{lam_i tau}; G is symmetric (upper triangle used); a Taylor series where |z tau| < 1e-3."""
    N = lam.shape[0]
    acc = 0.0 + 0.0j
    for i in range(N):
        for k in range(i, N):
            if G[i, k] != 0.0:
                zt = (lam[i] + lam[k]) * tau
                if az[i, k] * tau < 1e-3:
                    term = G[i, k] * tau * (1.0 + zt / 2.0 + zt * zt / 6.0 + zt * zt * zt / 24.0)
                else:
                    term = Gz[i, k] * (e[i] * e[k] - 1.0)
                acc += term if k == i else 2.0 * term
    return acc.real


@nb.njit(cache=True)
def _series_at(coef, lam, tau, q, d, dscale, Q2):
    """Add the terms c_i e^{lam_i tau} to q, q' = Re sum lam_i c_i e^{lam_i tau}, the scale of q'
    (sum |lam_i c_i e^{lam_i tau}|) and the bound Q2 = sum |lam_i|^2 |c_i e^{lam_i tau}| on |q''|."""
    for i in range(lam.shape[0]):
        e = coef[i] * np.exp(lam[i] * tau)
        q += e.real
        d += (lam[i] * e).real
        dscale += abs(e) * abs(lam[i])
        Q2 += abs(e) * abs(lam[i]) ** 2
    return q, d, dscale, Q2


@nb.njit(cache=True)
def _march_step(q, d, qtol, dtol, Q2, tau, hmin):
    """One step of the root march at tau, from q, q' (known to within qtol, dtol) and Q2 >= |q''|
    ahead: (tau_root, True) at a crossing, else (tau + h, False) with h the largest step for which
    q + q' h + Q2 h^2 / 2 < 0 (no root skipped), at least hmin; (inf, True) when q can never
    reach the threshold (q' <= 0 and Q2 = 0)."""
    if q > -qtol:
        if q > qtol and d >= -dtol:
            return tau, True
        # At the threshold a crossing needs q' > 0 beyond its round-off; otherwise it is a
        # tangential graze. A q just past the threshold but falling back (q' < 0) is the
        # round-off of re-expanding the state right after a switch, not a crossing:
        # deciding either by noise would flip the state back and forth forever.
        if d > dtol:
            return tau + max(-q, 0.0) / d, True
    qn = -min(q, 0.0)
    disc = np.sqrt(d * d + 2.0 * Q2 * qn)
    if d > 0.0:
        h = 2.0 * qn / (d + disc)
    elif Q2 > 0.0:
        h = (disc - d) / Q2
    else:
        return np.inf, True
    return tau + max(h, hmin), False


@nb.njit(cache=True)
def _first_root(const, coef, lam, tau_limit, hmin, qnoise, dnoise, floor):
    """First tau in [0, tau_limit) where q = const + Re sum coef e^{lam tau} turns positive.

    q is known to QTOL_REL x the size of its terms plus ``qnoise``, the round-off carried
    in from the modal coordinates w (q' likewise, with ``dnoise``); within that band a
    stop is at its threshold. Returns (tau, n_iter); tau = inf when there is none
    before tau_limit. A motion smaller than ``floor`` is round-off about a state that
    rests on a stop's threshold (zero gap, heavy damping): it triggers no event.
    """
    N = lam.shape[0]
    osc = 0.0
    for i in range(N):
        osc += abs(coef[i])
    if osc < floor and abs(const) < floor:
        return np.inf, 0
    qtol = QTOL_REL * (abs(const) + osc) + NOISE_FACTOR * qnoise
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        q, d, dscale, Q2 = _series_at(coef, lam, tau, const, 0.0, 0.0, 0.0)
        tau, found = _march_step(q, d, qtol, QTOL_REL * dscale + NOISE_FACTOR * dnoise, Q2, tau, hmin)
        if found:
            return tau, it
        if tau >= tau_limit:
            return np.inf, it
    return -1.0, MAX_MARCH_ITER


@nb.njit(cache=True)
def _state_index(active):
    """Index of a contact state in the tables: sum_j active_j 2^j."""
    s = 0
    for j in range(active.shape[0]):
        if active[j]:
            s += 1 << j
    return s


@nb.njit(cache=True)
def _stop_series(B, j, sgn, offset_j, yp_s, X, coef):
    """q_j(tau) = const + Re sum_i coef_i e^{lam_i tau}: fills coef, returns const."""
    n = B.shape[1]
    const = 0.0
    for r in range(n):
        const += B[j, r] * yp_s[r]
    for i in range(X.shape[1]):
        acc = 0.0 + 0.0j
        for r in range(n):
            acc += B[j, r] * X[r, i]
        coef[i] = sgn * acc
    return sgn * (const - offset_j)


@nb.njit(cache=True)
def _exponentials(lam, tau, e):
    """e_i = exp(lam_i tau)."""
    for i in range(lam.shape[0]):
        e[i] = np.exp(lam[i] * tau)


@nb.njit(cache=True)
def _eval_with(yp, X, e, out):
    """y = y_p + Re sum_i X[:, i] e_i."""
    N = e.shape[0]
    for r in range(X.shape[0]):
        acc = 0.0
        for i in range(N):
            acc += (X[r, i] * e[i]).real
        out[r] = yp[r] + acc


@nb.njit(cache=True)
def _eval_state(yp, X, lam, tau, out):
    """y(tau) = y_p + Re sum_i X[:, i] e^{lam_i tau}."""
    e = np.empty(lam.shape[0], np.complex128)
    _exponentials(lam, tau, e)
    _eval_with(yp, X, e, out)


@nb.njit(cache=True)
def _forced_segment(s, sigma, ip, tau_lim, y, yp_s, lam_s, V, Vinv, fz, fY, fU, pF, pp0, pp1, n, X, z, P,
                    Fs, phi, gam, werr, ypart):
    """A forced segment's closed form in state s (see the module docstring), with the loads' piece
    ``ip`` re-based to the segment start (``sigma`` after the piece start):

    y(tau) = y_p + Re sum_k X[:, k] e^{z_k tau} + sum_m P[m] tau^m,

    the terms k < 2n the modes, then Y_l / 2 and conj(Y_l) / 2 (z = +-i omega_l) of the harmonic
    loads fast over the segment (omega_l tau_lim >= SLOW_LT; Fs: their amplitudes, 0 for the
    others), and P (real, degree POLY_DEG) the polynomial part. The loads' polynomial part is
    phi[l, k] tau^k: p0 + p1 tau and the Taylor series of the slow harmonic loads. A fast mode
    carries its exponential and the polynomial particular solution sum_k c_k tau^k
    (c_D = -gam_D / lambda, c_k = ((k + 1) c_{k+1} - gam_k) / lambda, gam = V^-1 [0; M^-1 b] phi);
    a slow mode (|lambda| tau_lim < SLOW_LT) its Taylor series m h_m = lambda h_{m-1} + gam_{m-1},
    which cancels nothing. Fills X, z, P, Fs, phi and werr (the round-off of the modal
    coordinates); returns whether there is a polynomial part.
    """
    N = 2 * n
    L = fz.shape[0]
    M1 = P.shape[0]
    poly = False
    deg = -1
    for l in range(L):
        F = pF[ip, l]
        if F != 0.0 and sigma != 0.0:
            F = F * np.exp(1j * fz[l] * sigma)
        for k in range(M1):
            phi[l, k] = 0.0
        phi[l, 0] = pp0[ip, l] + pp1[ip, l] * sigma
        phi[l, 1] = pp1[ip, l]
        if F != 0.0 and fz[l] * tau_lim < SLOW_LT:
            # Re(F e^{i w tau}) = sum_k Re(F (i w)^k / k!) tau^k: to round-off for w tau < 1
            c = F
            for k in range(M1):
                phi[l, k] += c.real
                c = c * (1j * fz[l]) / (k + 1)
            F = 0.0 + 0.0j
        Fs[l] = F
        for k in range(M1):
            if phi[l, k] != 0.0:
                poly = True
                deg = max(deg, k)
    for r in range(N):
        ypart[r] = 0.0
    col = N
    for l in range(L):
        for r in range(N):
            Y = fY[s, r, l] * Fs[l]
            X[r, col] = 0.5 * Y
            X[r, col + 1] = 0.5 * np.conj(Y)
            ypart[r] += Y.real
        z[col] = 1j * fz[l]
        z[col + 1] = -1j * fz[l]
        col += 2
    for m in range(M1):
        for r in range(N):
            P[m, r] = 0.0
    for i in range(N):
        lam = lam_s[i]
        z[i] = lam
        wi = 0.0 + 0.0j
        err = 0.0
        for r in range(N):
            wi += Vinv[i, r] * (y[r] - yp_s[r] - ypart[r])
            err += abs(Vinv[i, r]) * (abs(y[r]) + abs(yp_s[r]) + abs(ypart[r]))
        werr[i] = EPS * err
        if not poly:
            for r in range(N):
                X[r, i] = V[r, i] * wi
            continue
        for k in range(deg + 1):
            g = 0.0 + 0.0j
            for l in range(L):
                g += fU[s, i, l] * phi[l, k]
            gam[k] = g
        if abs(lam) * tau_lim < SLOW_LT:
            h = wi
            for r in range(N):
                X[r, i] = 0.0
                P[0, r] += (V[r, i] * h).real
            for m in range(1, M1):
                h = lam * h
                if m - 1 <= deg:
                    h += gam[m - 1]
                h = h / m
                for r in range(N):
                    P[m, r] += (V[r, i] * h).real
        else:
            c = -gam[deg] / lam
            for r in range(N):
                P[deg, r] += (V[r, i] * c).real
            for k in range(deg - 1, -1, -1):
                c = ((k + 1) * c - gam[k]) / lam
                for r in range(N):
                    P[k, r] += (V[r, i] * c).real
            for r in range(N):
                X[r, i] = V[r, i] * (wi - c)  # c is now c_0, the particular solution at tau = 0
    return poly


@nb.njit(cache=True)
def _first_root_forced(const, coef, lam, Qp, poly, tau_limit, hmin, qnoise, dnoise, floor):
    """:func:`_first_root` for q = const + Re sum coef e^{lam tau} + sum_m Qp[m] tau^m (a forced
    segment): |q''| <= sum |coef| |lam|^2 e^{Re(lam) tau_a} + sum_m m (m - 1) |Qp[m]| tau_limit^(m - 2)
    on [tau_a, tau_limit], so the same march never steps over a root."""
    N = lam.shape[0]
    M = Qp.shape[0] - 1
    osc = 0.0
    for i in range(N):
        osc += abs(coef[i])
    Q2p = 0.0
    pmax = 0.0
    if poly:
        tm = 1.0  # tau_limit^m
        for m in range(M + 1):
            pmax += abs(Qp[m]) * tm
            tm *= tau_limit
        tm = 1.0  # tau_limit^(m - 2)
        for m in range(2, M + 1):
            Q2p += m * (m - 1) * abs(Qp[m]) * tm
            tm *= tau_limit
    if osc < floor and abs(const) < floor and pmax < floor:
        return np.inf, 0
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        pscale = 0.0
        q, d, dscale, Q2 = _series_at(coef, lam, tau, const, 0.0, 0.0, Q2p)
        if poly:
            pv = Qp[M]
            pd = M * Qp[M]
            ps = abs(Qp[M])
            pds = M * abs(Qp[M])
            for m in range(M - 1, -1, -1):
                pv = pv * tau + Qp[m]
                ps = ps * tau + abs(Qp[m])
                if m >= 1:
                    pd = pd * tau + m * Qp[m]
                    pds = pds * tau + m * abs(Qp[m])
            q += pv
            d += pd
            pscale = ps
            dscale += pds
        qtol = QTOL_REL * (abs(const) + osc + pscale) + NOISE_FACTOR * qnoise
        tau, found = _march_step(q, d, qtol, QTOL_REL * dscale + NOISE_FACTOR * dnoise, Q2, tau, hmin)
        if found:
            return tau, it
        if tau >= tau_limit:
            return np.inf, it
    return -1.0, MAX_MARCH_ITER


@nb.njit(cache=True)
def _stop_poly(B, j, sgn, P, Qp):
    """Qp[m] = sgn B_j P[m, :n]: the polynomial part of q_j."""
    n = B.shape[1]
    for m in range(P.shape[0]):
        acc = 0.0
        for r in range(n):
            acc += B[j, r] * P[m, r]
        Qp[m] = sgn * acc


@nb.njit(cache=True)
def _add_poly(P, tau, n_rows, out):
    """out[r] += sum_m P[m, r] tau^m (Horner), r < n_rows."""
    M = P.shape[0] - 1
    for r in range(n_rows):
        acc = P[M, r]
        for m in range(M - 1, -1, -1):
            acc = acc * tau + P[m, r]
        out[r] += acc


@nb.njit(cache=True)
def _series_terms(ax):
    """Terms of the series of e^x - 1 (and kin) for |x| = ax < TAYLOR_ZT: ax^j / j! below 1e-18."""
    if ax < 1e-3:
        return 5
    if ax < 0.05:
        return 9
    return TAYLOR_TERMS


@nb.njit(cache=True)
def _i0(u, ru, eu, tau):
    """int_0^tau e^{u t} dt with ru = 1 / u and eu = e^{u tau}: (eu - 1) / u, or its series where
    |u tau| < TAYLOR_ZT."""
    x = u * tau
    ax = abs(x)
    if ax < TAYLOR_ZT:
        acc = 1.0 + 0.0j
        for j in range(_series_terms(ax), 0, -1):
            acc = 1.0 + acc * x / (j + 1)
        return tau * acc
    return (eu - 1.0) * ru


@nb.njit(cache=True)
def _inv(u):
    """1 / u (0 for u = 0, where the series branch is taken)."""
    return 1.0 / u if u != 0.0 else 0.0 + 0.0j


@nb.njit(cache=True)
def _moments(u, tau, out):
    """out[m] = int_0^tau t^m e^{u t} dt = tau^(m+1) J_m(u tau), m = 0 .. len(out) - 1.

    J_m(x) = int_0^1 s^m e^{x s} ds by J_m = (e^x - m J_{m-1}) / x upward for m < |x| and
    J_{m-1} = (e^x - x J_m) / m downward from m = MOMENT_TOP (started at 0) for m >= |x|: each
    recursion run where it damps its errors (by m / |x|, resp. |x| / m), so every moment is
    accurate to a few eps for any u.
    """
    M = out.shape[0] - 1
    x = u * tau
    ex = np.exp(x)
    ax = abs(x)
    ms = M + 1 if ax >= M + 1 else int(ax)
    if ms >= 1:
        J = (ex - 1.0) / x
        out[0] = J
        for m in range(1, ms):
            J = (ex - m * J) / x
            out[m] = J
    if ms <= M:
        J = 0.0 + 0.0j
        for m in range(MOMENT_TOP, ms, -1):
            J = (ex - x * J) / m
            if m - 1 <= M:
                out[m - 1] = J
    tm = tau
    for m in range(M + 1):
        out[m] *= tm
        tm *= tau


@nb.njit(cache=True)
def _ext_setup(X, z, fb, fz, n, beta, rp, rm):
    """beta[k, l] = a_k^T b_l with a_k = X[n:, k] the velocity part of term k, and the inverses
    rp = 1 / (z_k + i omega_l), rm = 1 / (z_k - i omega_l) of the exponents of v^T f_ext."""
    for k in range(X.shape[1]):
        for l in range(fb.shape[0]):
            acc = 0.0 + 0.0j
            for r in range(n):
                acc += X[n + r, k] * fb[l, r]
            beta[k, l] = acc
            rp[k, l] = _inv(z[k] + 1j * fz[l])
            rm[k, l] = _inv(z[k] - 1j * fz[l])


@nb.njit(cache=True)
def _ext_work(beta, z, e, fz, Fs, tau, eiw, rp, rm):
    """int_0^tau v_E^T f_H dt for v_E = sum_k a_k e^{z_k t} (a real sum) and the fast harmonic
    loads f_H = sum_l b_l (F_l / 2 e^{i w_l t} + conj(F_l) / 2 e^{-i w_l t}), e_k = e^{z_k tau}."""
    K = beta.shape[0]
    L = beta.shape[1]
    acc = 0.0 + 0.0j
    for l in range(L):
        if Fs[l] == 0.0:
            continue
        eiw[l] = np.exp(1j * fz[l] * tau)
        w = 1j * fz[l]
        for k in range(K):
            bkl = beta[k, l]
            if bkl != 0.0:
                acc += bkl * (0.5 * Fs[l] * _i0(z[k] + w, rp[k, l], e[k] * eiw[l], tau)
                              + 0.5 * np.conj(Fs[l]) * _i0(z[k] - w, rm[k, l], e[k] * np.conj(eiw[l]), tau))
    return acc.real


@nb.njit(cache=True)
def _work_exp(G, Gz, az, z, tau, e):
    """int_0^tau v^T C v dt for v = sum_k a_k e^{z_k t}: :func:`_work` with the series of the
    forced path (to TAYLOR_ZT); G, Gz, az from :func:`_work_setup`."""
    K = z.shape[0]
    acc = 0.0 + 0.0j
    for i in range(K):
        for k in range(i, K):
            if G[i, k] != 0.0:
                x = (z[i] + z[k]) * tau
                if az[i, k] * tau < TAYLOR_ZT:
                    s = 1.0 + 0.0j
                    for j in range(_series_terms(az[i, k] * tau), 0, -1):
                        s = 1.0 + s * x / (j + 1)
                    term = G[i, k] * tau * s
                else:
                    term = Gz[i, k] * (e[i] * e[k] - 1.0)
                acc += term if k == i else 2.0 * term
    return acc.real


@nb.njit(cache=True)
def _poly_setup(X, P, C, fb, n, damped_, ACp, Cpp, Pb):
    """With p_m = P[m, n:] the velocity part of the polynomial: ACp[k, m] = a_k^T C p_m,
    Cpp[m, m'] = p_m^T C p_m' (damped), Pb[m, l] = p_m^T b_l."""
    M1 = P.shape[0]
    for m in range(M1):
        for l in range(fb.shape[0]):
            acc = 0.0
            for r in range(n):
                acc += P[m, n + r] * fb[l, r]
            Pb[m, l] = acc
    if not damped_:
        return
    Cp = np.empty(n)
    for m in range(M1):
        for a in range(n):
            ca = 0.0
            for b in range(n):
                ca += C[a, b] * P[m, n + b]
            Cp[a] = ca
        for k in range(X.shape[1]):
            acc = 0.0 + 0.0j
            for a in range(n):
                acc += X[n + a, k] * Cp[a]
            ACp[k, m] = acc
        for m2 in range(M1):
            acc2 = 0.0
            for a in range(n):
                acc2 += P[m2, n + a] * Cp[a]
            Cpp[m2, m] = acc2


@nb.njit(cache=True)
def _poly_work(ACp, Cpp, Pb, beta, phi, Fs, z, tau, MOM, damped_, N):
    """(W, W_ext) of the polynomial parts over [0, tau], with v = v_E + v_P (v_E = sum_k a_k e^{z_k t},
    v_P = sum_m p_m t^m) and f_ext = f_H + f_P (fast harmonic, f_P = sum_l b_l sum_k phi[l, k] t^k):
    int (2 v_E^T C v_P + v_P^T C v_P) dt and int (v_E^T f_P + v_P^T f_H + v_P^T f_P) dt, from the
    moments MOM[k, m] = int_0^tau t^m e^{z_k t} dt (:func:`_moments`)."""
    K = z.shape[0]
    M1 = Cpp.shape[0]
    L = Pb.shape[1]
    for k in range(K):
        _moments(z[k], tau, MOM[k])
    W = 0.0
    if damped_:
        acc = 0.0 + 0.0j
        for k in range(K):
            for m in range(M1):
                if ACp[k, m] != 0.0:
                    acc += ACp[k, m] * MOM[k, m]
        W = 2.0 * acc.real
        for m in range(M1):
            for m2 in range(M1):
                if Cpp[m, m2] != 0.0:
                    W += Cpp[m, m2] * tau ** (m + m2 + 1) / (m + m2 + 1)
    acc = 0.0 + 0.0j
    for l in range(L):
        for k in range(K):
            if beta[k, l] != 0.0:
                inner = 0.0 + 0.0j
                for j in range(M1):
                    if phi[l, j] != 0.0:
                        inner += phi[l, j] * MOM[k, j]
                acc += beta[k, l] * inner
        if Fs[l] != 0.0:
            # F/2 I_m(i w) + conj(F)/2 I_m(-i w) = Re(F I_m(i w)) for real p_m; i w_l is z[N + 2 l]
            inner = 0.0 + 0.0j
            for m in range(M1):
                inner += Pb[m, l] * MOM[N + 2 * l, m]
            acc += Fs[l] * inner
    E = acc.real
    for l in range(L):
        for m in range(M1):
            if Pb[m, l] != 0.0:
                for j in range(M1):
                    if phi[l, j] != 0.0:
                        E += Pb[m, l] * phi[l, j] * tau ** (m + j + 1) / (m + j + 1)
    return W, E


@nb.njit(cache=True)
def _piece_at(pstarts, ip, t, t_end):
    """(ip, t_lim): the load piece holding t (advanced from ip) and where the segment must end,
    the next breakpoint or t_end."""
    NP = pstarts.shape[0]
    while ip + 1 < NP and pstarts[ip + 1] <= t:
        ip += 1
    if ip + 1 < NP and pstarts[ip + 1] < t_end:
        return ip, pstarts[ip + 1]
    return ip, t_end


@nb.njit(cache=True)
def _modal_start(V_s, Vinv_s, y, yp_s, X, werr):
    """Free segment start: w = Vinv (y - yp), X[:, i] = V[:, i] w_i, and werr bounds the round-off in w."""
    N = y.shape[0]
    for i in range(N):
        wi = 0.0 + 0.0j
        err = 0.0
        for r in range(N):
            wi += Vinv_s[i, r] * (y[r] - yp_s[r])
            err += abs(Vinv_s[i, r]) * (abs(y[r]) + abs(yp_s[r]))
        werr[i] = EPS * err
        for r in range(N):
            X[r, i] = V_s[r, i] * wi


BUFFER_FULL = 1  # _exact_kernel status: the sample buffer is full inside the present segment
NO_SEGMENTS = np.zeros(0, np.int64)  # _modal._free_kernel records no segments (the flow's Jacobian does)
NO_TAU = np.zeros(0)


@nb.njit(cache=True)
def _exact_kernel(lam, V, Vinv, yp, valid, B, offset, side, tip, C, damped,
                  y, active, t, t_end, t_samples, i_samp, t_after, out_y, out_W, W, hmin, floor, max_events,
                  n_stuck, forced, fz, fY, fU, fb, pstarts, pF, pp0, pp1, out_E, E):
    """March events from t to t_end, filling the sample buffer ``t_samples`` from index i_samp.

    (y, active, t, W, E) is the state at the start of a segment (an event, a load breakpoint or a
    piece boundary) and is advanced in place segment by segment. When the buffer fills inside a
    segment that still has samples before its end (the next sample, at ``t_after``, lies in it),
    the kernel returns BUFFER_FULL *without* advancing that segment: called again with a new
    buffer it recomputes the segment from the same state, so the samples do not depend on
    the buffer size. With ``forced``, the loads' pieces start at ``pstarts`` (the first at or before
    t; see :func:`_forced_segment`) and E is their work. Returns
    (t, W, E, i_samp, n_events, n_iter, status, n_stuck).
    """
    n = B.shape[1]
    m = B.shape[0]
    N = 2 * n
    L = fb.shape[0] if forced else 0
    Kt = N + 2 * L  # terms: the modes, then +-i omega_l per load
    M1 = POLY_DEG + 1 if forced else 1
    ns = t_samples.shape[0]
    X = np.empty((N, Kt), np.complex128)
    G = np.zeros((Kt, Kt), np.complex128)
    Gz = np.zeros((Kt, Kt), np.complex128)
    az = np.zeros((Kt, Kt))
    coef = np.empty(Kt, np.complex128)
    e = np.empty(Kt, np.complex128)
    z = np.zeros(Kt, np.complex128)
    werr = np.empty(N)
    ytmp = np.empty(N)
    ypart = np.zeros(N)
    P = np.zeros((M1, N))
    Qp = np.zeros(M1)
    ACp = np.zeros((Kt, M1), np.complex128)
    Cpp = np.zeros((M1, M1))
    Pb = np.zeros((M1, L))
    MOM = np.zeros((Kt, M1), np.complex128)
    beta = np.zeros((Kt, L), np.complex128)
    rp = np.zeros((Kt, L), np.complex128)
    rm = np.zeros((Kt, L), np.complex128)
    Fs = np.zeros(L, np.complex128)
    phi = np.zeros((L, M1))
    gam = np.zeros(M1, np.complex128)
    eiw = np.empty(L, np.complex128)
    ip = 0
    if forced:
        ip = max(np.searchsorted(pstarts, t, side="right") - 1, 0)
    poly = False
    n_events = 0
    n_iter = 0
    status = 0
    while True:
        s = _state_index(active)
        if not valid[s]:
            status = -2
            break
        lam_s = lam[s]
        zs = lam_s
        t_lim = t_end
        if forced:
            ip, t_lim = _piece_at(pstarts, ip, t, t_end)
            poly = _forced_segment(s, t - pstarts[ip], ip, t_lim - t, y, yp[s], lam_s, V[s], Vinv[s], fz, fY, fU,
                                   pF, pp0, pp1, n, X, z, P, Fs, phi, gam, werr, ypart)
            zs = z
        else:
            _modal_start(V[s], Vinv[s], y, yp[s], X, werr)
        if damped:
            _work_setup(X, C, zs, n, G, Gz, az)
        if forced:
            _ext_setup(X, zs, fb, fz, n, beta, rp, rm)
            if poly:
                _poly_setup(X, P, C, fb, n, damped, ACp, Cpp, Pb)
        tau_ev = t_lim - t
        j_ev = -1
        seg_iter = 0
        for j in range(m):
            sgn = -side[j] if active[j] else side[j]
            const = _stop_series(B, j, sgn, offset[j], yp[s], X, coef)
            qnoise = 0.0
            dnoise = 0.0
            for i in range(N):
                pv = 0.0 + 0.0j
                for r in range(n):
                    pv += B[j, r] * V[s, r, i]
                qnoise += abs(pv) * werr[i]
                dnoise += abs(pv) * abs(lam_s[i]) * werr[i]
            if forced:
                if poly:
                    _stop_poly(B, j, sgn, P, Qp)
                tj, it = _first_root_forced(const, coef, zs, Qp, poly, tau_ev, hmin, qnoise, dnoise, floor)
            else:
                tj, it = _first_root(const, coef, lam_s, tau_ev, hmin, qnoise, dnoise, floor)
            seg_iter += it
            if tj < 0.0:
                status = -3
                break
            if tj < tau_ev:
                tau_ev = tj
                j_ev = j
        if status != 0:
            break
        t_next = t_lim if j_ev < 0 else t + tau_ev
        while i_samp < ns and t_samples[i_samp] <= t_next:
            tau = max(t_samples[i_samp] - t, 0.0)
            _exponentials(zs, tau, e)
            _eval_with(yp[s], X, e, ytmp)
            if forced:
                Wp = 0.0
                Ep = 0.0
                if poly:
                    _add_poly(P, tau, N, ytmp)
                    Wp, Ep = _poly_work(ACp, Cpp, Pb, beta, phi, Fs, zs, tau, MOM, damped, N)
                out_E[i_samp] = E + (_ext_work(beta, zs, e, fz, Fs, tau, eiw, rp, rm) + Ep)
                out_W[i_samp] = W + ((_work_exp(G, Gz, az, zs, tau, e) if damped else 0.0) + Wp)
            else:
                out_W[i_samp] = W + (_work(G, Gz, az, zs, tau, e) if damped else 0.0)
            for r in range(N):
                out_y[i_samp, r] = ytmp[r]
            i_samp += 1
        if i_samp == ns and t_after <= t_next:
            status = BUFFER_FULL  # the segment is searched again with the next buffer: count it then
            break
        n_iter += seg_iter
        _exponentials(zs, tau_ev, e)
        _eval_with(yp[s], X, e, ytmp)
        if forced:
            Wp = 0.0
            Ep = 0.0
            if poly:
                _add_poly(P, tau_ev, N, ytmp)
                Wp, Ep = _poly_work(ACp, Cpp, Pb, beta, phi, Fs, zs, tau_ev, MOM, damped, N)
            E += _ext_work(beta, zs, e, fz, Fs, tau_ev, eiw, rp, rm) + Ep
            W += (_work_exp(G, Gz, az, zs, tau_ev, e) if damped else 0.0) + Wp
        elif damped:
            W += _work(G, Gz, az, zs, tau_ev, e)
        for r in range(N):
            y[r] = ytmp[r]
        n_stuck = n_stuck + 1 if tau_ev == 0.0 else 0
        if n_stuck > 8 * m:
            status = -4
            break
        t = t_next
        if j_ev < 0:
            if t_lim < t_end:
                continue  # a load breakpoint: the same contact state, a new piece
            break
        _modal.switch_stop(active, tip, j_ev)
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, E, i_samp, n_events, n_iter, status, n_stuck


MAX_PIECE_S = 1.0  # s: the closed form is restarted from the state at least this often
PIECES = 50  # ... and at least this many times a run (the progress granularity)


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


def stream_exact(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    loads=None,
    chunks: int = PIECES,
    max_events: int = 50_000_000,
    chunk_samples: int | None = None,
    progress=None,
) -> RingdownStream:
    """Exact (event-driven, closed-form) response of ``system`` from (x0, v0), chunk by chunk.

    See :func:`integrate_exact`; the samples come in chunks of at most ``chunk_samples``
    (default: the whole run in one). The run is cut into ``max(chunks, duration_s /
    MAX_PIECE_S)`` equal pieces, at whose ends the closed form restarts from the state
    (y, contact state, W, W_ext): the piece grid (and the load breakpoints) fix every
    arithmetic operation, so the samples are the same bits whatever ``chunk_samples`` is.
    """
    n, x0, v0, duration_s, sample_rate_hz = _check.run_args(system, x0, v0, duration_s, sample_rate_hz)
    loads = _check.loads(loads, n)
    chunks = _check.integer("chunks", chunks)
    max_events = _check.integer("max_events", max_events)
    _check.callback("progress", progress)
    N = sample_count(duration_s, sample_rate_hz)
    chunk_samples = N if chunk_samples is None else _check.integer("chunk_samples", chunk_samples)
    original, system = system, system.fold_zero_gap_tips()
    forced = loads is not None
    with single_thread_blas():  # small dense problems: see state_table
        table = state_table(system)
        ft = forced_table(system, table, loads) if forced else None
        omega_max = system.omega_max()
        mt = modal_table(system, table)
    hmin = HMIN_PERIODS / omega_max
    y = np.concatenate([x0, v0])
    active = system.penetration(y[:n]) > 0.0
    # motion below REST_FLOOR of the initial one (in m) is round-off: see _first_root
    x_scale = np.abs(system.B) @ (np.abs(y[:n]) + np.abs(y[n:]) / omega_max)
    if forced:  # ... or of the static deflection under the largest load
        pmax = np.array([s.work_scale() for s in loads.signals])
        x_scale = x_scale + np.abs(system.B) @ (np.abs(ft.Sb[0]) @ pmax)
    floor = REST_FLOOR * float(np.max(x_scale, initial=0.0))
    load_scale = float(np.max(np.abs(ft.Sb[0]) @ pmax)) if forced else 0.0  # m, largest static deflection
    t_last = (N - 1) / sample_rate_hz
    t_end = max(duration_s, t_last)
    n_pieces = max(chunks, math.ceil(t_end / MAX_PIECE_S))
    breakpoints = loads.breakpoints(t_end) if forced else np.zeros(0)
    stats = {"n_events": 0, "n_steps": 1, "n_march": 0, "n_states": int(table.valid.sum()),
             "cond_V": float(np.max(table.cond)), "n_pieces": n_pieces}
    if forced:
        stats.update(n_loads=loads.n_loads, n_breakpoints=int(breakpoints.size))
    offset_max = float(np.max(np.abs(system.offset), initial=0.0))

    damped = not system.undamped

    def runs(t: float, bound: float) -> list:
        """[(t_a, t_b, pieces or None)]: [t, bound) cut where the loads start or stop being all zero;
        None for a free stretch (no load, or every load zero on it)."""
        if not forced:
            return [(t, bound, None)]
        inside = breakpoints[np.searchsorted(breakpoints, t, "right"):np.searchsorted(breakpoints, bound)]
        starts = np.concatenate([[t], inside])
        pc = loads.pieces_at(starts)
        zero = ~np.any((pc.F != 0.0) | (pc.p0 != 0.0) | (pc.p1 != 0.0), axis=1)
        out, k0 = [], 0
        for k in range(1, starts.size + 1):
            if k == starts.size or zero[k] != zero[k0]:
                t_b = bound if k == starts.size else float(starts[k])
                out.append((float(starts[k0]), t_b, None if zero[k0] else starts[k0:k]))
                k0 = k
        return out

    # np.linspace(0, t_end, n_pieces + 1)[1:], one bound at a time (the same bits)
    bounds = np.array([t_end if c == n_pieces - 1 else (c + 1) * (t_end / n_pieces) for c in range(n_pieces)])
    # a free run without a progress bar goes through every piece in one kernel call
    groups = [bounds] if not forced and progress is None else [bounds[c:c + 1] for c in range(n_pieces)]

    def blocks():
        nonlocal y, active
        t, W, E, n_events, n_iter = 0.0, 0.0, 0.0, 0, 0
        j0 = 0
        k = min(chunk_samples, N)
        ts = np.arange(j0, j0 + k) / sample_rate_hz
        out_y, out_W, out_E = np.empty((k, 2 * n)), np.empty(k), np.empty(k if forced else 0)
        i = 0
        for c_done, g in enumerate(groups, 1):
            bound = float(g[-1])
            n_stuck = 0
            for _, t_b, starts in runs(t, bound):
                if starts is not None:  # the loads' pieces from t to t_b
                    fargs = forced_arrays(ft, loads.pieces_at(starts))
                tb_ = g if len(g) > 1 else np.array([t_b])
                c = 0
                while True:
                    t_after = (j0 + k) / sample_rate_hz if j0 + k < N else np.inf
                    if starts is None:
                        t, W, i, ne, ni, status, n_stuck, c = call_numba_kernel(_modal._free_kernel,
                            mt, system.offset, system.side, system.tip, damped, y, active, t, tb_, c, ts, i, t_after,
                            out_y, out_W, W, hmin, floor, max_events - n_events, n_stuck, out_E, E, NO_SEGMENTS, NO_TAU)
                    else:
                        t, W, E, i, ne, ni, status, n_stuck = call_numba_kernel(_exact_kernel,
                            table.lam, table.V, table.Vinv, table.yp, table.valid, system.B, system.offset,
                            system.side, system.tip, system.C, damped, y, active, t, t_b, ts, i,
                            t_after, out_y, out_W, W, hmin, floor, max_events - n_events, n_stuck, True, *fargs,
                            out_E, E)
                    n_events += ne
                    n_iter += ni
                    stats.update(n_events=n_events, n_steps=n_events + 1, n_march=n_iter)
                    if status == BUFFER_FULL:
                        yield j0, *_finite(out_y, out_W, out_E, n, forced)
                        j0 += k
                        k = min(chunk_samples, N - j0)
                        ts = np.arange(j0, j0 + k) / sample_rate_hz
                        out_y, out_W, out_E = np.empty((k, 2 * n)), np.empty(k), np.empty(k if forced else 0)
                        i = 0
                        continue
                    _check_status(status, t, max_events)
                    break
            if progress is not None:
                progress(c_done / n_pieces)
        if i != k or j0 + k != N:  # the last sample sits on t_end up to round-off
            raise ExactIntegratorError(f"internal: {N - j0 - i} samples not filled")
        yield j0, *_finite(out_y, out_W, out_E, n, forced)

    def tolerance(amp: float) -> float:
        # evaluating V diag(e^{lam t}) V^-1 y loses cond(V) eps |y| at each event, and under loads
        # cond(V) eps |y - y_part|, y_part up to the static deflection under the largest load
        return float(np.max(table.cond)) * EPS * max(amp, offset_max, load_scale)

    return RingdownStream(original, "exact", N, sample_rate_hz, chunk_samples, blocks(), tolerance, stats,
                          loads=loads)


def _finite(out_y: np.ndarray, out_W: np.ndarray, out_E: np.ndarray, n: int, forced: bool) -> tuple:
    if not np.all(np.isfinite(out_y)):
        raise ExactIntegratorError("non-finite state: the contact states are ill-conditioned")
    if forced:
        return out_y[:, :n], out_y[:, n:], out_W, out_E
    return out_y[:, :n], out_y[:, n:], out_W


def integrate_exact(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    loads=None,
    chunks: int = PIECES,
    max_events: int = 50_000_000,
    progress=None,
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

    The whole run is held in memory; :func:`stream_exact` gives it chunk by chunk.
    """
    return stream_exact(system, x0, v0, duration_s, sample_rate_hz, loads=loads, chunks=chunks,
                        max_events=max_events, progress=progress).collect()
