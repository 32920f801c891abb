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
bound the full ones from above (Rayleigh-Ritz). The interface needs K to be positive
definite on its own (a grounded structure); the constraint modes are then
Psi = K^-1 T^T (T K^-1 T^T)^-1.

A fixed-interface mode enters the interface dynamics only through its column of M_bq. With
``coupled_only`` the modes whose column is zero (to ``coupling_tol``) are left out: no
interface force or interface initial condition can excite them. For the impact beam, whose
tips act in z on the plane y = 0, these are the out-of-plane modes (antisymmetric in y) and
the in-plane modes antisymmetric in z (surge on the springs): the *planar* reduction.

The fixed-interface problem is solved on the null space of T, u = Z y with T Z = 0, where Z
eliminates one pivot DOF per row (Z is as sparse as K because the rows touch only patch DOFs).

References: Craig and Bampton, AIAA J. 6 (1968); NASA pyyeti ``cb.cbcheck`` for the checks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

DENSE_MAX = 600  # DOFs up to which the fixed-interface problem is solved densely by default


@dataclass(frozen=True, eq=False)
class CBModel:
    """A Craig-Bampton reduced model: q = [u_b (nb); eta (nq)].

    Attributes
    ----------
    M : (nb + nq, nb + nq) ndarray of float
        Reduced mass matrix V^T M V, V = [Psi, Phi] (kg for the u_b block, 1 on the eta block).
    K : (nb + nq, nb + nq) ndarray of float
        Reduced stiffness matrix V^T K V (N/m for the u_b block, rad^2/s^2 on the eta block).
    Psi : (N, nb) ndarray of float
        Constraint modes, T Psi = I.
    Phi : (N, nq) ndarray of float
        Fixed-interface modes kept, mass-normalised (1/sqrt(kg)).
    omega_fixed : (nq,) ndarray of float
        rad/s, their frequencies.
    boundary_names : tuple of str
        Name of each interface row.
    stats : dict
        ``wall_s``, ``static_s`` (s), ``n_full``, ``n_boundary``, ``n_modes``, ``n_computed``,
        ``n_uncoupled_skipped`` and ``eig`` (dense or sparse shift-invert).
    """

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

    @property
    def coupling(self) -> np.ndarray:
        """(nq,) sqrt(kg), |M_bq[:, j]|: how strongly interface motion drives mode j."""
        return np.linalg.norm(self.M[: self.nb, self.nb:], axis=0)

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Full displacement u (..., N) from reduced coordinates q (..., nb + nq)."""
        q = np.asarray(q)
        return q[..., : self.nb] @ self.Psi.T + q[..., self.nb:] @ self.Phi.T

    def reduce_rows(self, rows: np.ndarray) -> np.ndarray:
        """(r, nb + nq): output rows R of the full model as rows of q (R u = R V q)."""
        rows = np.atleast_2d(rows)
        return np.hstack([rows @ self.Psi, rows @ self.Phi])

    def frequencies_hz(self) -> np.ndarray:
        """Hz, natural frequencies of the reduced model."""
        w2 = sla.eigh(self.K, self.M, eigvals_only=True)
        return np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)


def null_space_basis(T: np.ndarray) -> sp.csr_matrix:
    """Sparse Z (N, N - nb) with T Z = 0, eliminating one pivot DOF per row.

    The pivots come from a column-pivoted QR of T on its nonzero columns, so T_p is well
    conditioned; u_p = -T_p^-1 T_r u_r.

    Parameters
    ----------
    T : (nb, N) ndarray of float
        Interface rows, linearly independent.

    Returns
    -------
    (N, N - nb) scipy.sparse.csr_matrix
        Z: the pivot DOFs' rows are -T_p^-1 T_r, the other DOFs' rows the identity.

    Raises
    ------
    ValueError
        Rows of T linearly dependent (a pivot below 1e-12 of the largest).
    """
    nb, N = T.shape
    cols = np.flatnonzero(np.any(T != 0.0, axis=0))
    _, R, perm = sla.qr(T[:, cols], mode="economic", pivoting=True)
    if nb > len(cols) or abs(R[nb - 1, nb - 1]) <= 1e-12 * abs(R[0, 0]):
        raise ValueError("interface rows T are linearly dependent")
    piv = cols[perm[:nb]]
    rest = np.setdiff1d(np.arange(N), piv)
    G = -np.linalg.solve(T[:, piv], T[:, rest])  # (nb, N - nb), nonzero only on T's columns
    G[np.abs(G) < 1e-15 * np.max(np.abs(G), initial=1.0)] = 0.0
    Z = sp.vstack([sp.csr_matrix(G), sp.identity(N - nb, format="csr")]).tocsr()
    order = np.concatenate([piv, rest])  # row i of the stacked Z is DOF order[i]
    P = sp.csr_matrix((np.ones(N), (order, np.arange(N))), shape=(N, N))
    return (P @ Z).tocsr()


def _fixed_interface_modes(K, M, Z, k: int, dense: bool, shift: float = 1.0):
    """Lowest k eigenpairs (w2, Phi) of Z^T K Z y = w2 Z^T M Z y, Phi = Z y, mass-normalized
    (sparse: shift-invert about -shift, K being positive definite)."""
    Kz = (Z.T @ K @ Z) if sp.issparse(K) else Z.T @ (Z.T @ np.asarray(K)).T
    Mz = (Z.T @ M @ Z) if sp.issparse(M) else Z.T @ (Z.T @ np.asarray(M)).T
    n = Z.shape[1]
    if dense or k >= n - 1:
        Kd = Kz.toarray() if sp.issparse(Kz) else np.asarray(Kz)
        Md = Mz.toarray() if sp.issparse(Mz) else np.asarray(Mz)
        w2, Y = sla.eigh(0.5 * (Kd + Kd.T), 0.5 * (Md + Md.T), subset_by_index=[0, min(k, n) - 1])
    else:
        Kz, Mz = sp.csc_matrix(Kz), sp.csc_matrix(Mz)
        v0 = np.random.default_rng(0).standard_normal(n)
        w2, Y = spla.eigsh(Kz, k=k, M=Mz, sigma=-shift, which="LM", v0=v0, tol=1e-12)
        order = np.argsort(w2)
        w2, Y = w2[order], Y[:, order]
    Phi = Z @ Y
    return w2, Phi / np.sqrt(np.einsum("ij,ij->j", Phi, M @ Phi))


def craig_bampton(
    K,
    M,
    T: np.ndarray,
    n_modes: int | None = None,
    cutoff_hz: float | None = None,
    boundary_names: tuple[str, ...] | None = None,
    coupled_only: bool = False,
    coupling_tol: float = 1e-6,
    dense: bool | None = None,
    mode_filter=None,
) -> CBModel:
    """Reduce (K, M) onto the interface rows T and fixed-interface modes.

    Parameters
    ----------
    K, M : (N, N) dense arrays or sparse matrices; K positive definite
    T : (nb, N) interface rows, linearly independent
    n_modes : keep this many fixed-interface modes (None: all, or all below ``cutoff_hz``)
    cutoff_hz : keep only modes at or below this frequency
    boundary_names : a name per interface row (default b0, b1, ...)
    coupled_only : count and keep only modes with |M_bq[:, j]| > coupling_tol sqrt(max M_bb)
    coupling_tol : the threshold of ``coupled_only``, relative (above)
    dense : solve the fixed-interface problem densely (default: N <= DENSE_MAX or all modes)
    mode_filter : with ``coupled_only``, a function of the modes Phi (N, k) returning a (k,) bool
        mask of the modes allowed as well (e.g. the symmetric ones, whose coupling is not noise)

    Returns
    -------
    CBModel
        Reduced matrices on q = [u_b; eta], the constraint and fixed-interface modes kept, and
        statistics (times, modes computed, uncoupled modes skipped).

    Raises
    ------
    ValueError
        T without N columns or with dependent rows, n_modes < 0, or fewer (coupled)
        fixed-interface modes than ``n_modes`` when no cutoff is given.
    """
    t0 = time.perf_counter()
    T = np.atleast_2d(np.asarray(T, dtype=float))
    N = K.shape[0]
    nb = T.shape[0]
    if T.shape[1] != N:
        raise ValueError(f"T must have {N} columns, got {T.shape[1]}")
    if n_modes is not None and n_modes < 0:
        raise ValueError(f"n_modes must be >= 0, got {n_modes}")
    Z = null_space_basis(T)
    if sp.issparse(K):
        lu = spla.splu(sp.csc_matrix(K))
        KiT = lu.solve(T.T.copy())
    else:
        KiT = sla.cho_solve(sla.cho_factor(np.asarray(K)), T.T.copy())
    Psi = KiT @ np.linalg.inv(T @ KiT)
    t_static = time.perf_counter() - t0
    n_avail = N - nb
    if dense is None:
        dense = N <= DENSE_MAX or (n_modes is None and cutoff_hz is None)
    if n_modes is None and cutoff_hz is None:
        k = n_avail
    elif n_modes is None:
        k = min(n_avail, 40)
    else:
        k = min(n_avail, n_modes if not coupled_only else 2 * n_modes + 20)
    Mbb_scale = np.sqrt(np.max(np.diag(Psi.T @ (M @ Psi))))
    while True:
        w2, Phi = _fixed_interface_modes(K, M, Z, k, dense) if k > 0 else (np.zeros(0), np.zeros((N, 0)))
        f_hz = np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi)
        c = np.linalg.norm(Psi.T @ (M @ Phi), axis=0) / Mbb_scale
        ok = c > coupling_tol if coupled_only else np.ones(len(w2), bool)
        if coupled_only and mode_filter is not None and len(w2):
            ok &= np.asarray(mode_filter(Phi), bool)
        if cutoff_hz is not None:
            ok &= f_hz <= cutoff_hz
        keep = np.flatnonzero(ok)
        enough = (n_modes is not None and len(keep) >= n_modes) or (
            cutoff_hz is not None and len(w2) and f_hz[-1] > cutoff_hz)
        if enough or k >= n_avail or (n_modes is None and cutoff_hz is None):
            break
        k = min(n_avail, 2 * k)
    if n_modes is not None:
        keep = keep[:n_modes]
    if n_modes is not None and len(keep) < n_modes and cutoff_hz is None:
        raise ValueError(f"only {len(keep)} {'coupled ' if coupled_only else ''}fixed-interface modes exist, "
                         f"asked for {n_modes}")
    dropped = int(np.count_nonzero(~ok[: (keep[-1] + 1 if len(keep) else 0)]))
    Phi, w2 = Phi[:, keep], w2[keep]
    V = np.hstack([Psi, Phi])
    Mr = V.T @ (M @ V)
    Kr = V.T @ (K @ V)
    Mr, Kr = 0.5 * (Mr + Mr.T), 0.5 * (Kr + Kr.T)
    names = boundary_names or tuple(f"b{i}" for i in range(nb))
    stats = {"wall_s": time.perf_counter() - t0, "static_s": t_static, "n_full": N, "n_boundary": nb,
             "n_modes": len(keep), "n_computed": len(w2), "n_uncoupled_skipped": dropped,
             "eig": "dense" if dense else "sparse shift-invert"}
    return CBModel(Mr, Kr, Psi, Phi, np.sqrt(np.clip(w2, 0, None)), tuple(names), stats)


def cb_check(cb: CBModel, K_full=None, M_full=None, n_compare: int = 6, omega_full: np.ndarray | None = None,
             rigid: np.ndarray | None = None, M_rigid=None, rigid_tol: float = 1e-9) -> list[dict]:
    """pyyeti-style checks: rows of (check, value, tolerance, passed).

    M_qq = I, K_qq diagonal with the fixed-interface omega^2, K_bq = 0. With the full
    matrices (or the full model's lowest ``omega_full``): the reduced frequencies bound the
    full ones from above. With ``rigid`` (N, r) rigid-body motions of the full model and its
    mass ``M_rigid``: the reduced model's mass on their projection q = Mr^-1 V^T M R equals
    R^T M R (mass and inertia), to ``rigid_tol`` relative (exact only when R is in span V).

    Parameters
    ----------
    cb : CBModel
        The reduced model.
    K_full, M_full : (N, N) array or sparse matrix, optional
        The full matrices: their ``n_compare`` lowest frequencies (a dense eigensolution) are the
        reference when ``omega_full`` is not given; ``M_full`` is also the mass of the rigid check.
    n_compare : int
        Frequencies compared when they are computed from K_full, M_full.
    omega_full : (n,) ndarray of float, optional
        rad/s, the full model's lowest frequencies, ascending.
    rigid : (N, r) ndarray of float, optional
        Rigid-body motions of the full model.
    M_rigid : (N, N) array or sparse matrix, optional
        Mass for the rigid check (default ``M_full``).
    rigid_tol : float
        Tolerance of the rigid-body mass check, relative to sqrt(diag) scales.

    Returns
    -------
    list of dict
        One per check: ``check`` (its name), ``value``, ``tolerance`` and ``passed`` (value <=
        tolerance; >= for the frequency bound, whose tolerance is -1e-9).
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
    if omega_full is None and K_full is not None and M_full is not None:
        Kd = K_full.toarray() if sp.issparse(K_full) else np.asarray(K_full)
        Md = M_full.toarray() if sp.issparse(M_full) else np.asarray(M_full)
        n = min(n_compare, cb.M.shape[0])
        omega_full = np.sqrt(np.clip(sla.eigh(Kd, Md, eigvals_only=True, subset_by_index=[0, n - 1]), 0, None))
    if omega_full is not None:
        n = min(len(omega_full), cb.M.shape[0])
        w_red = np.sqrt(np.clip(sla.eigh(cb.K, cb.M, eigvals_only=True, subset_by_index=[0, n - 1]), 0, None))
        rows.append({"check": "min(omega_reduced - omega_full) / omega_full (>= 0: upper bounds)",
                     "value": float(np.min((w_red - omega_full[:n]) / omega_full[:n])), "tolerance": -1e-9})
    if rigid is not None:
        M = M_rigid if M_rigid is not None else M_full
        MR = M @ rigid
        full = rigid.T @ MR
        V = np.hstack([cb.Psi, cb.Phi])
        p = V.T @ MR
        red = p.T @ np.linalg.solve(cb.M, p)
        d = np.sqrt(np.diag(full))
        rows.append({"check": "max|R^T M R (reduced) - R^T M R| / (diag scale): rigid-body mass and inertia",
                     "value": float(np.max(np.abs(red - full) / np.outer(d, d))), "tolerance": rigid_tol})
    for r in rows:
        r["passed"] = bool(r["value"] >= r["tolerance"]) if r["check"].startswith("min(") else bool(
            r["value"] <= r["tolerance"])
    return rows
