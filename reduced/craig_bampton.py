"""Craig-Bampton reduction with an interface given by constraint rows (distributing coupling).

The interface coordinates are u_b = T u (nb rows of T; a row is a single DOF, a difference
of DOFs, or the average motion of a contact patch: RBE3-like, it distributes and does not
stiffen). With Psi the constraint modes and Phi the fixed-interface modes,

    u = Psi u_b + Phi eta,
    K Psi = T^T Lambda, T Psi = I          (static response to a unit interface motion)
    K phi = omega^2 M phi, T phi = 0       (interface held fixed), phi^T M phi = 1,

the reduced matrices on q = [u_b; eta] are::

        [ M_bb  M_bq ]          [ K_bb   0          ]
    Mr = [ M_qb  I    ]     Kr = [ 0      diag(w^2) ]

(K_bq = 0 because Phi^T K Psi = Phi^T T^T Lambda = 0). Keeping every fixed-interface mode
makes the reduction an exact change of coordinates; keeping fewer gives eigenvalues that
bound the full ones from above. The interface needs K to be positive definite on its own
(a grounded structure); the constraint modes are then Psi = K^-1 T^T (T K^-1 T^T)^-1.

References: Craig and Bampton, AIAA J. 6 (1968); NASA pyyeti ``cb.cbcheck`` for the checks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass(frozen=True, eq=False)
class CBModel:
    """A Craig-Bampton reduced model: q = [u_b (nb); eta (nq)]."""

    M: np.ndarray  # (nb + nq, nb + nq) kg
    K: np.ndarray  # (nb + nq, nb + nq) N/m
    Psi: np.ndarray  # (N, nb) constraint modes
    Phi: np.ndarray  # (N, nq) fixed-interface modes, mass-normalized
    omega_fixed: np.ndarray  # (nq,) rad/s, fixed-interface frequencies
    boundary_names: tuple[str, ...]
    stats: dict = field(default_factory=dict)

    @property
    def nb(self) -> int:
        return self.Psi.shape[1]

    @property
    def nq(self) -> int:
        return self.Phi.shape[1]

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Full displacement u (..., N) from reduced coordinates q (..., nb + nq)."""
        q = np.asarray(q)
        return q[..., : self.nb] @ self.Psi.T + q[..., self.nb :] @ self.Phi.T

    def frequencies_hz(self) -> np.ndarray:
        """Hz, natural frequencies of the reduced model."""
        w2 = sla.eigh(self.K, self.M, eigvals_only=True)
        return np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)


def _solve_factory(K):
    if sp.issparse(K):
        lu = spla.splu(sp.csc_matrix(K))
        return lu.solve
    c = sla.cho_factor(np.asarray(K))
    return lambda b: sla.cho_solve(c, b)


def craig_bampton(
    K,
    M,
    T: np.ndarray,
    n_modes: int | None = None,
    cutoff_hz: float | None = None,
    boundary_names: tuple[str, ...] | None = None,
) -> CBModel:
    """Reduce (K, M) onto the interface rows T and fixed-interface modes.

    Parameters
    ----------
    K, M : (N, N) dense arrays or sparse matrices; K positive definite
    T : (nb, N) interface rows, linearly independent
    n_modes : keep this many fixed-interface modes (None: all, dense only)
    cutoff_hz : keep the modes below this frequency (applied after ``n_modes``)
    """
    t0 = time.perf_counter()
    T = np.atleast_2d(np.asarray(T, dtype=float))
    N = K.shape[0]
    nb = T.shape[0]
    if T.shape[1] != N:
        raise ValueError(f"T must have {N} columns, got {T.shape[1]}")
    if np.linalg.matrix_rank(T) < nb:
        raise ValueError("interface rows T are linearly dependent")
    solve = _solve_factory(K)
    KiT = solve(T.T.copy())  # (N, nb)
    S = T @ KiT  # interface flexibility
    Psi = KiT @ np.linalg.inv(S)
    # fixed-interface modes on the null space of T: u = Z y with T Z = 0
    dense = not sp.issparse(K) or N <= 3000
    if dense:
        Kd = K.toarray() if sp.issparse(K) else np.asarray(K)
        Md = M.toarray() if sp.issparse(M) else np.asarray(M)
        Z = sla.null_space(T)
        w2, Y = sla.eigh(Z.T @ Kd @ Z, Z.T @ Md @ Z)
        Phi = Z @ Y
        keep = np.arange(len(w2)) if n_modes is None else np.arange(min(n_modes, len(w2)))
    else:
        if n_modes is None:
            raise ValueError("n_modes is required for a sparse model")
        # shift-invert on the saddle point [[K, T^T], [T, 0]]: its solution respects T u = 0
        A = sp.bmat([[sp.csc_matrix(K), sp.csc_matrix(T.T)], [sp.csc_matrix(T), None]], format="csc")
        lu = spla.splu(A)

        def op(x):
            rhs = np.concatenate([M @ x, np.zeros(nb)])
            return lu.solve(rhs)[:N]

        Op = spla.LinearOperator((N, N), matvec=op, dtype=float)
        mu, Phi = spla.eigsh(Op, k=n_modes, M=M, which="LM")
        order = np.argsort(-mu)
        w2 = 1.0 / mu[order]
        Phi = Phi[:, order]
        keep = np.arange(n_modes)
    if cutoff_hz is not None:
        keep = keep[np.sqrt(np.clip(w2[keep], 0, None)) / (2 * np.pi) <= cutoff_hz]
    Phi = Phi[:, keep]
    w2 = w2[keep]
    Phi = Phi / np.sqrt(np.einsum("ij,ij->j", Phi, M @ Phi))  # mass-normalize
    V = np.hstack([Psi, Phi])
    Mr = V.T @ (M @ V)
    Kr = V.T @ (K @ V)
    Mr, Kr = 0.5 * (Mr + Mr.T), 0.5 * (Kr + Kr.T)
    names = boundary_names or tuple(f"b{i}" for i in range(nb))
    return CBModel(Mr, Kr, Psi, Phi, np.sqrt(np.clip(w2, 0, None)), tuple(names),
                   {"wall_s": time.perf_counter() - t0, "n_full": N, "n_boundary": nb, "n_modes": len(keep)})


def cb_check(cb: CBModel, K_full=None, M_full=None, n_compare: int = 6) -> list[dict]:
    """pyyeti-style checks: rows of (check, value, tolerance, passed).

    M_qq = I, K_qq diagonal with the fixed-interface omega^2, K_bq = 0; with the full
    matrices also: the reduced frequencies bound the full ones from above.
    """
    nb = cb.nb
    Mqq, Kqq, Kbq = cb.M[nb:, nb:], cb.K[nb:, nb:], cb.K[:nb, nb:]
    kscale = max(np.max(np.abs(cb.K)), 1e-300)
    rows = [
        {"check": "max|M_qq - I|", "value": float(np.max(np.abs(Mqq - np.eye(cb.nq)), initial=0.0)),
         "tolerance": 1e-9},
        {"check": "max|K_qq - diag(w^2)| / max|K|",
         "value": float(np.max(np.abs(Kqq - np.diag(cb.omega_fixed**2)), initial=0.0) / kscale), "tolerance": 1e-9},
        {"check": "max|K_bq| / max|K|", "value": float(np.max(np.abs(Kbq), initial=0.0) / kscale),
         "tolerance": 1e-9},
    ]
    if K_full is not None and M_full is not None:
        Kd = K_full.toarray() if sp.issparse(K_full) else np.asarray(K_full)
        Md = M_full.toarray() if sp.issparse(M_full) else np.asarray(M_full)
        n = min(n_compare, cb.M.shape[0])
        f_full = np.sqrt(np.clip(sla.eigh(Kd, Md, eigvals_only=True, subset_by_index=[0, n - 1]), 0, None))
        f_red = np.sqrt(np.clip(sla.eigh(cb.K, cb.M, eigvals_only=True, subset_by_index=[0, n - 1]), 0, None))
        rows.append({"check": "min(omega_reduced - omega_full) / omega_full (>= 0: upper bounds)",
                     "value": float(np.min((f_red - f_full) / f_full)), "tolerance": -1e-9})
    for r in rows:
        r["passed"] = bool(r["value"] >= r["tolerance"]) if r["check"].startswith("min(") else bool(
            r["value"] <= r["tolerance"])
    return rows
