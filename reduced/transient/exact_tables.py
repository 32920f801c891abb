"""The exact integrator's tables: the closed form of every contact state, worked out once a run.

- :func:`state_table` (:class:`StateTable`): the eigen-decomposition of every feasible contact
  state, y' = A_s y + b_s, A_s = [[0, I], [-M^-1 K_s, -M^-1 C]], and its equilibrium y_p;
- :func:`modal_table`: the same in conjugate-pair modal form with the stops' rows and the
  dissipated work's quadratic forms, for the free segments (:mod:`reduced.transient._modal`);
- :func:`forced_table` (:class:`ForcedTable`): the loads' particular solutions per state, and
  :func:`forced_arrays`, the kernels' arguments of the loads' pieces;
- :func:`run_tables` and :func:`cached_forced_table`: the same kept for the last few systems (and
  loads) run, keyed by their contents, so repeated runs of one system (the hammer levels, the
  stepped sine, repeats) work them out once.

The formulas are those of :mod:`reduced.transient.exact` (its module docstring).
"""

from __future__ import annotations

import hashlib
import math
import threading
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh, solve

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem

MAX_COND = 1e10  # refuse nearly defective (critically damped) states
RESONANCE_REL = 1e-6  # |i omega - lambda| below this x omega: an undamped resonance, refused


class ExactIntegratorError(RuntimeError):
    """The exact integrator cannot treat this system or run (the message says why)."""


@dataclass(frozen=True, eq=False)
class StateTable:
    """Closed-form data of every contact state, indexed by sum_j active_j 2^j.

    Attributes
    ----------
    lam : (S, 2n) ndarray of complex
        1/s, eigenvalues of A_s per state (S = 2^m, indexed by sum_j active_j 2^j).
    V : (S, 2n, 2n) ndarray of complex
        Eigenvectors, A_s V = V diag(lam).
    Vinv : (S, 2n, 2n) ndarray of complex
        Their inverse.
    yp : (S, 2n) ndarray of float
        Equilibrium [K_s^-1 F_s; 0] (m, m/s).
    valid : (S,) ndarray of bool
        Feasible states (the others are zero).
    cond : (S,) ndarray of float
        Condition number of V: the closed form loses cond eps |y|.
    """

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
    these matrices are small, and threads on busy cores cost far more than they save.

    Parameters
    ----------
    system : GapSystem
        The system.

    Returns
    -------
    StateTable

    Raises
    ------
    InvalidArgument
        Not a GapSystem.
    ExactIntegratorError
        A state with a zero-frequency mode (undamped), nearly defective (cond(V) > ``MAX_COND``)
        or unstable.
    """
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

    Parameters
    ----------
    system, table : the gap system and its :class:`StateTable`

    Returns
    -------
    tuple
        (K, lam, |lam|, U^T, Uinv, |Uinv|, y_p, B U, |B U|, B y_p, work, H_ii, pointer, i, k, kind, coefficient, z)
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
    """Per-state data of the loads (see the module docstring).

    Attributes
    ----------
    omega : (L,) ndarray of float
        rad/s, each load's harmonic frequency (0: no harmonic term).
    Y : (S, 2n, L) ndarray of complex
        [H_l b_l; i omega_l H_l b_l] per state, H_l = (K_s - omega_l^2 M + i omega_l C)^-1 (m/N).
    U : (S, 2n, L) ndarray of complex
        Modal loads V^-1 [0; M^-1 b_l].
    Sb : (S, n, L) ndarray of float
        K_s^-1 b_l, static deflections (m/N): scales of the round-off.
    b : (L, n) ndarray of float
        Load directions.
    """

    omega: np.ndarray  # (L,) rad/s, each load's harmonic frequency (0: no harmonic term)
    Y: np.ndarray  # (S, 2n, L) complex, [H_l b_l; i omega_l H_l b_l], H_l = (K_s - omega_l^2 M + i omega_l C)^-1
    U: np.ndarray  # (S, 2n, L) complex, modal loads V^-1 [0; M^-1 b_l]
    Sb: np.ndarray  # (S, n, L), K_s^-1 b_l (static deflections: scales of the round-off)
    b: np.ndarray  # (L, n) load directions


def forced_table(system: GapSystem, table: StateTable, loads) -> ForcedTable:
    """Per-state particular solutions of ``loads`` (a :class:`~reduced.models.loads.Loads`) for the
    exact integrator and the flow; refuses an undamped resonance or a state with a rigid-body mode.

    Parameters
    ----------
    system : GapSystem
        The system.
    table : StateTable
        Its states (:func:`state_table`).
    loads : Loads
        The loads, b (L, n) and their harmonic frequencies.

    Returns
    -------
    ForcedTable

    Raises
    ------
    ExactIntegratorError
        A state with a rigid-body mode, or a load at an undamped resonance of a state (within
        ``RESONANCE_REL``).
    """
    n = system.n
    b = np.ascontiguousarray(loads.b, dtype=float)
    omega = loads.omegas()
    S, L = table.lam.shape[0], b.shape[0]
    Y = np.zeros((S, 2 * n, L), complex)
    U = np.zeros((S, 2 * n, L), complex)
    Sb = np.zeros((S, n, L))
    for Ks, lam, states, rigid, u, sb in _load_parts(system, table, b):
        if rigid is not None:
            raise ExactIntegratorError(rigid)
        for l in range(L):
            if omega[l] > 0.0:
                i = int(np.argmin(np.abs(1j * omega[l] - lam)))
                if abs(1j * omega[l] - lam[i]) <= RESONANCE_REL * omega[l]:
                    raise ExactIntegratorError(
                        f"load {l + 1} ({loads.points[l]}) at {omega[l] / (2 * math.pi):.6g} Hz is at an undamped "
                        f"resonance of contact state {states[0][1]} (natural frequency "
                        f"{abs(lam[i].imag) / (2 * math.pi):.6g} Hz): the exact closed form has no bounded "
                        "particular solution there; use method 'dop853' or 'explicit'")
        y = np.zeros((2 * n, L), complex)
        for l in range(L):
            if omega[l] > 0.0:
                h = solve(Ks - omega[l] ** 2 * system.M + 1j * omega[l] * system.C, b[l].astype(complex))
                y[:n, l], y[n:, l] = h, 1j * omega[l] * h
        for s, _ in states:
            Y[s], U[s], Sb[s] = y, u, sb
    return ForcedTable(omega, Y, U, Sb, b)


LOAD_PARTS_SIZE = 8  # (table, load directions) whose frequency-independent parts forced_table keeps
LOAD_PARTS_ENTRY_BYTES = 4 * 2**20  # parts larger than this (a large model's many states) are not kept
_LOAD_PARTS: OrderedDict = OrderedDict()  # (id(table), id(system), b bytes) -> (weakref table, weakref system, parts)
_LOAD_PARTS_LOCK = threading.Lock()


def _load_parts(system: GapSystem, table: StateTable, b: np.ndarray) -> list:
    """The parts of :func:`forced_table` that do not depend on the loads' frequencies, kept for the last
    LOAD_PARTS_SIZE (table, b): per distinct stiffness K_s of the feasible states (in their order), (K_s, its
    eigenvalues, [(s, state name)] of the states that have it, the rigid-body refusal or None, the modal loads
    V^-1 [0; M^-1 b^T], K_s^-1 b^T). Worked out as forced_table did at every call (the same calls, the same
    bits); a stepped sine builds a table per frequency with the same system and load directions. The entries
    hold the table and the system by weak reference (a table run_tables lets go of is not kept alive here), and
    parts above LOAD_PARTS_ENTRY_BYTES are not kept."""
    key = (id(table), id(system), b.shape, b.tobytes())
    with _LOAD_PARTS_LOCK:
        hit = _LOAD_PARTS.get(key)
        if hit is not None and hit[0]() is table and hit[1]() is system:
            _LOAD_PARTS.move_to_end(key)
            return hit[2]
    Minv_b = np.linalg.solve(system.M, b.T)
    parts, index = [], {}
    for active in system.feasible_states():
        s = int(np.sum(active * (1 << np.arange(system.m))))
        Ks, _ = system.state_matrices(active)
        k = Ks.tobytes()
        if k in index:
            parts[index[k]][2].append((s, _state_name(system, active)))
            continue
        lam = table.lam[s]
        rigid = None
        if np.min(np.abs(lam)) <= 1e-9 * np.max(np.abs(lam)):
            rigid = (f"contact state {_state_name(system, active)} has a rigid-body mode: a load on it has no "
                     "bounded particular solution; use method 'dop853' or 'explicit'")
            parts.append((Ks, lam, [(s, _state_name(system, active))], rigid, None, None))
        else:
            parts.append((Ks, lam, [(s, _state_name(system, active))], None, table.Vinv[s][:, system.n:] @ Minv_b,
                          solve(Ks, b.T)))
        index[k] = len(parts) - 1
    size = sum(a.nbytes for part in parts for a in (part[0], part[1], part[4], part[5]) if a is not None)
    if size <= LOAD_PARTS_ENTRY_BYTES:
        with _LOAD_PARTS_LOCK:
            _LOAD_PARTS[key] = (weakref.ref(table), weakref.ref(system), parts)
            while len(_LOAD_PARTS) > LOAD_PARTS_SIZE:
                _LOAD_PARTS.popitem(last=False)
    return parts


def _state_name(system: GapSystem, active: np.ndarray) -> str:
    closed = [system.stop_names[j] for j in np.flatnonzero(active)]
    return "(" + (", ".join(closed) + " closed" if closed else "all stops open") + ")"




def forced_arrays(ft: ForcedTable, pieces) -> tuple:
    """The forcing arguments of the kernels: the table and the pieces (a PieceTable).

    Parameters
    ----------
    ft : ForcedTable
        The loads' per-state data.
    pieces : PieceTable
        The loads' pieces on the run's breakpoint grid.

    Returns
    -------
    tuple
        (omega, Y, U, b, starts, F, p0, p1), C-contiguous where the kernels need it.

    Raises
    ------
    ExactIntegratorError
        A piece whose frequency is not its load's (an internal error).
    """
    on = pieces.F != 0.0
    if np.any(on & (pieces.omega != ft.omega[None, :])):
        raise ExactIntegratorError("internal: a load piece's frequency differs from its load's")
    return (ft.omega, ft.Y, ft.U, ft.b, np.ascontiguousarray(pieces.starts), np.ascontiguousarray(pieces.F),
            np.ascontiguousarray(pieces.p0), np.ascontiguousarray(pieces.p1))



TABLE_CACHE_SIZE = 4  # systems (and, per system, loads) whose tables are kept by run_tables / cached_forced_table
TABLE_CACHE_ENTRY_BYTES = 128 * 2**20  # tables larger than this are not kept (memory: at most 4 x this is held)
_TABLES: OrderedDict = OrderedDict()  # fingerprint -> {"run", "table", "modal", "omega_max", "forced": OrderedDict}
_TABLES_LOCK = threading.Lock()


def _fingerprint(*arrays: np.ndarray) -> bytes:
    """A digest of the arrays' dtypes, shapes and bytes: equal digests, equal contents (to a
    collision of BLAKE2b-160)."""
    h = hashlib.blake2b(digest_size=20)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape};".encode())
        h.update(a.data)
    return h.digest()


def _system_key(system: GapSystem) -> bytes:
    names = np.frombuffer("\0".join((*system.dof_names, "|", *system.stop_names)).encode(), np.uint8)
    return _fingerprint(system.M, system.C, system.K, system.B, system.k, system.offset, system.side, system.tip,
                        names)


def _nbytes(value) -> int:
    """Bytes of the arrays in a table (a dict, tuple or dataclass of arrays, nested)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, dict):
        return sum(_nbytes(v) for v in value.values())
    if isinstance(value, (tuple, list)):
        return sum(_nbytes(v) for v in value)
    if isinstance(value, (StateTable, ForcedTable)):
        return sum(_nbytes(v) for v in vars(value).values())
    return 0


def _kept(cache: OrderedDict, key, make):
    """cache[key], made by ``make()`` when absent; the least recently used entry beyond
    TABLE_CACHE_SIZE is dropped, and a value larger than TABLE_CACHE_ENTRY_BYTES is not kept."""
    with _TABLES_LOCK:
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
    value = make()  # outside the lock: the tables of a large system take seconds
    if _nbytes(value) > TABLE_CACHE_ENTRY_BYTES:
        return value
    with _TABLES_LOCK:
        cache[key] = value
        cache.move_to_end(key)
        while len(cache) > TABLE_CACHE_SIZE:
            cache.popitem(last=False)
    return value


def run_tables(system: GapSystem) -> dict:
    """The free segments' tables of ``system`` (no friction), kept for the last TABLE_CACHE_SIZE systems.

    The system is identified by its contents (M, C, K, B, k, offset, side, tip and the names): a system built again,
    or changed in place, is looked up by what it holds. The tables are shared between runs: read them,
    never write them.

    Parameters
    ----------
    system : GapSystem
        The system (without friction).

    Returns
    -------
    dict
        ``run`` (:meth:`GapSystem.fold_zero_gap_tips`, the system the integrator runs), ``table``
        (:func:`state_table` of it), ``modal`` (:func:`modal_table`), ``omega_max`` (rad/s) and
        ``key`` (the fingerprint, for :func:`cached_forced_table`).

    Raises
    ------
    ExactIntegratorError
        As :func:`state_table` (a refused system is not kept).
    """
    key = _system_key(system)

    def make() -> dict:
        run = system.fold_zero_gap_tips()
        with single_thread_blas():
            table = state_table(run)
            return {"run": run, "table": table, "modal": modal_table(run, table), "omega_max": run.omega_max(),
                    "key": key, "forced": OrderedDict()}

    return _kept(_TABLES, key, make)


def cached_forced_table(tables: dict, loads) -> ForcedTable:
    """:func:`forced_table` of the run system of ``tables`` (:func:`run_tables`) under ``loads``, kept per
    system for the last TABLE_CACHE_SIZE load sets (identified by their directions and frequencies:
    the table does not depend on the amplitudes or the time histories).

    Parameters
    ----------
    tables : dict
        The run's tables, from :func:`run_tables`.
    loads : object
        The loads (``b``, their rows, and ``omegas()``, their frequencies).

    Returns
    -------
    ForcedTable
    """
    b = np.ascontiguousarray(loads.b, dtype=float)
    key = _fingerprint(b, np.asarray(loads.omegas(), dtype=float))

    def make() -> ForcedTable:
        with single_thread_blas():
            return forced_table(tables["run"], tables["table"], loads)

    return _kept(tables["forced"], key, make)


def clear_table_cache() -> None:
    """Forget every kept table (:func:`run_tables`): the next run of each system works them out again."""
    with _TABLES_LOCK:
        _TABLES.clear()
