"""Modal analysis by shift-invert Lanczos, robust to rigid-body (zero) modes.

Solves K phi = omega^2 M phi for the ``n_modes`` eigenvalues nearest a negative shift
sigma = -(2 pi f_shift)^2. K - sigma M is then positive definite even when K is singular
(free-free: six zero modes), so no singular factorization is ever attempted; ARPACK
(scipy.sparse.linalg.eigsh, mode 'normal') iterates with OP = (K - sigma M)^-1 M.

Factorization back ends: ``"superlu"`` (SciPy's SuperLU, the plain baseline that eigsh
uses when given sigma) and ``"pardiso"`` (Intel MKL PARDISO through pypardiso, a
multithreaded supernodal direct solver).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh as dense_eigh
from scipy.sparse.linalg import LinearOperator, eigsh, splu

SOLVERS = ("pardiso", "superlu")
GRAM_FLOOR = 1e-13  # relative floor of the Gram eigenvalues when orthonormalising a block
SIGN_SEED = 20231  # seed of the fixed vector that sets each mode's sign (see _fix_signs)


@dataclass(frozen=True, eq=False)
class ModalResult:
    """Natural frequencies and mass-normalised mode shapes (phi^T M phi = I), signs fixed by
    :func:`_fix_signs`."""

    freq_hz: np.ndarray  # Hz, (n_modes,) ascending
    phi: np.ndarray  # (n_dofs, n_modes)
    omega2: np.ndarray  # rad^2/s^2, eigenvalues
    solver: str
    shift_hz: float
    n_op: int  # applications of (K - sigma M)^-1 to a vector
    n_iter: int  # subspace iterations (0 for Lanczos)
    timing: dict = field(default_factory=dict)  # s: factorize, iterate
    residual: float = 0.0  # max_i ||K phi_i - omega_i^2 M phi_i|| / ||K phi_i||


def has_pardiso() -> bool:
    try:
        import pypardiso  # noqa: F401
    except ImportError:
        return False
    return True


class PardisoFactor:
    """Cholesky factor of a symmetric positive definite matrix by MKL PARDISO (mtype 2).

    A thin layer over pypardiso's binding: the upper triangle is factorized once; the
    one-based index arrays are converted once (pypardiso converts them on every solve) and
    blocks of right-hand sides are solved together (column-major, BLAS-3).
    """

    def __init__(self, A: sp.spmatrix) -> None:
        import ctypes

        import pypardiso

        self._ct = ctypes
        self._ps = pypardiso.PyPardisoSolver(mtype=2)
        U = sp.triu(A, format="csr")
        U.sort_indices()
        self.n = U.shape[0]
        self._data = np.ascontiguousarray(U.data, dtype=np.float64)
        self._ia = (U.indptr + 1).astype(np.int32)
        self._ja = (U.indices + 1).astype(np.int32)
        self._call(12, np.zeros((self.n, 1), order="F"))

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        ct, ps = self._ct, self._ps
        x = np.zeros_like(b)
        err = ct.c_int32(0)
        i32, f64 = ct.POINTER(ct.c_int32), ct.POINTER(ct.c_double)
        ps._mkl_pardiso(ps.pt.ctypes.data_as(ct.POINTER(ps._pt_type[0])), ct.byref(ct.c_int32(1)),
                        ct.byref(ct.c_int32(1)), ct.byref(ct.c_int32(2)), ct.byref(ct.c_int32(phase)),
                        ct.byref(ct.c_int32(self.n)), self._data.ctypes.data_as(f64),
                        self._ia.ctypes.data_as(i32), self._ja.ctypes.data_as(i32),
                        ps.perm.ctypes.data_as(i32), ct.byref(ct.c_int32(b.shape[1])),
                        ps.iparm.ctypes.data_as(i32), ct.byref(ct.c_int32(0)),
                        b.ctypes.data_as(f64), x.ctypes.data_as(f64), ct.byref(err))
        if err.value != 0:
            raise RuntimeError(f"PARDISO failed in phase {phase} with error {err.value}"
                               + (" (matrix not positive definite)" if err.value == -4 else ""))
        return x

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x = A^-1 b for a vector or an (n, k) block."""
        vec = b.ndim == 1
        B = np.asfortranarray(b.reshape(self.n, -1), dtype=np.float64)
        x = self._call(33, B)
        return x.ravel() if vec else x

    def __del__(self) -> None:
        try:
            self._call(-1, np.zeros((self.n, 1), order="F"))
        except Exception:
            pass


def _fix_signs(phi: np.ndarray) -> np.ndarray:
    """Each column with the sign that makes w^T phi > 0 for one fixed pseudo-random w.

    An eigensolver returns +phi or -phi depending on round-off (MKL PARDISO's threads reorder
    sums); a fixed rule makes written shapes reproducible. w is random so that no structured
    mode (symmetric or antisymmetric about a plane, zero on a node) is orthogonal to it.
    """
    w = np.random.default_rng(SIGN_SEED).standard_normal(phi.shape[0])
    return phi * np.where(w @ phi < 0.0, -1.0, 1.0)


def _factorize(A: sp.csr_matrix, solver: str):
    if solver == "superlu":
        return splu(A.tocsc()).solve
    if solver == "pardiso":
        return PardisoFactor(A).solve
    raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")


def _subspace(K, M, solve, n_modes: int, sigma: float, tol: float, max_iter: int, seed: int):
    """Subspace iteration with Rayleigh-Ritz (Bathe): X <- (K - sigma M)^-1 M X.

    p = max(2 m, m + 8) vectors; mode i converges like ((lam_i - sigma)/(lam_p+1 - sigma))^k.
    Stops when the m lowest Ritz values change by less than tol (lam + |sigma|).
    """
    n = K.shape[0]
    p = min(n, max(2 * n_modes, n_modes + 8))
    X = np.random.default_rng(seed).standard_normal((n, p))
    MX = M @ X
    lam_old = None
    n_op = 0
    for it in range(1, max_iter + 1):
        Y = solve(MX)
        n_op += p
        # orthonormalise: the modes far above the shift die out by ~1e-8 per iteration and
        # would leave Y numerically rank deficient (Y^T M Y not positive definite). Through
        # the small Gram matrix (BLAS-3 only: a tall QR is slow when MKL and OpenBLAS
        # threads share two busy cores); directions lost to round-off come back as noise
        # vectors, which the Rayleigh-Ritz step below handles like any other trial vector.
        g, V = dense_eigh(Y.T @ Y)
        Y = Y @ (V / np.sqrt(np.maximum(g, GRAM_FLOOR * g.max())))
        KY, MY = K @ Y, M @ Y
        Kr, Mr = Y.T @ KY, Y.T @ MY
        Kr, Mr = (Kr + Kr.T) / 2, (Mr + Mr.T) / 2
        lam, Q = dense_eigh(Kr, Mr)  # Q^T Mr Q = I, so X = Y Q is M-orthonormal
        X = Y @ Q
        MX = MY @ Q  # M X without another sparse product
        if lam_old is not None and it >= 3 and np.all(
                np.abs(lam[:n_modes] - lam_old[:n_modes]) <= tol * (np.abs(lam[:n_modes]) + abs(sigma))):
            break
        lam_old = lam
    return lam[:n_modes], X[:, :n_modes], n_op, it


def modal_analysis(K: sp.spmatrix, M: sp.spmatrix, n_modes: int = 20, shift_hz: float = 1.0,
                   solver: str = "pardiso", method: str = "subspace", tol: float = 1e-4,
                   max_iter: int = 40, seed: int = 0) -> ModalResult:
    """Lowest ``n_modes`` modes of (K, M) by shift-invert about sigma = -(2 pi shift_hz)^2.

    Parameters
    ----------
    K, M : (n, n) sparse symmetric stiffness (N/m, positive semi-definite) and mass (kg).
    n_modes : number of modes, counting rigid-body ones.
    shift_hz : Hz, magnitude of the negative shift; below the first elastic frequency.
    solver : 'pardiso' (if installed) or 'superlu'.
    method : 'subspace' (block subspace iteration: one block solve per iteration) or
        'lanczos' (ARPACK through eigsh with the factorization as OPinv).
    tol : subspace iteration stops when the eigenvalues change by less than tol (lam + |sigma|)
        between iterations. The solves of K - sigma M (condition ~1e10 here) are accurate to
        about 1e-6, so the Ritz values of the near-zero modes wander by ~1e-5 of |sigma|
        while the pseudo-rigid ones settle to ~1e-7 after two iterations (their convergence
        factor is ~1e-2 per iteration); at least three iterations are always made.
    """
    if solver == "pardiso" and not has_pardiso():
        solver = "superlu"
    n = K.shape[0]
    sigma = -(2 * np.pi * shift_hz) ** 2
    t0 = time.perf_counter()
    A = (K - sigma * M).tocsr()
    solve = _factorize(A, solver)
    t1 = time.perf_counter()
    if method == "subspace":
        lam, phi, n_op, n_iter = _subspace(K, M, solve, n_modes, sigma, tol, max_iter, seed)
    elif method == "lanczos":
        count = [0]

        def op(x):
            count[0] += 1
            return solve(x)

        OPinv = LinearOperator((n, n), matvec=op, dtype=np.float64)
        v0 = np.random.default_rng(seed).standard_normal(n)
        lam, phi = eigsh(K, k=n_modes, M=M, sigma=sigma, which="LM", OPinv=OPinv, v0=v0)
        n_op, n_iter = count[0], 0
    else:
        raise ValueError(f"method must be 'subspace' or 'lanczos', got {method!r}")
    t2 = time.perf_counter()
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    mnorm = np.sqrt(np.einsum("ij,ij->j", phi, M @ phi))
    phi = _fix_signs(phi / mnorm)
    Kphi = K @ phi
    res = np.linalg.norm(Kphi - (M @ phi) * lam, axis=0) / np.maximum(np.linalg.norm(Kphi, axis=0), 1e-300)
    elastic = lam > (2 * np.pi * shift_hz) ** 2
    freq = np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)
    return ModalResult(freq_hz=freq, phi=phi, omega2=lam, solver=f"{solver}/{method}", shift_hz=shift_hz,
                       n_op=n_op, n_iter=n_iter,
                       timing={"factorize_s": t1 - t0, "iterate_s": t2 - t1},
                       residual=float(res[elastic].max()) if elastic.any() else 0.0)


def baseline_modal(K: sp.spmatrix, M: sp.spmatrix, n_modes: int = 20, shift_hz: float = 1.0,
                   seed: int = 0) -> ModalResult:
    """The plain SciPy baseline: eigsh(K, M=M, sigma=sigma) factorizing with SuperLU itself."""
    n = K.shape[0]
    sigma = -(2 * np.pi * shift_hz) ** 2
    v0 = np.random.default_rng(seed).standard_normal(n)
    t0 = time.perf_counter()
    lam, phi = eigsh(K.tocsc(), k=n_modes, M=M.tocsc(), sigma=sigma, which="LM", v0=v0)
    t1 = time.perf_counter()
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    phi = _fix_signs(phi / np.sqrt(np.einsum("ij,ij->j", phi, M @ phi)))
    return ModalResult(freq_hz=np.sqrt(np.clip(lam, 0, None)) / (2 * np.pi), phi=phi, omega2=lam,
                       solver="scipy-eigsh-superlu", shift_hz=shift_hz, n_op=-1, n_iter=0,
                       timing={"factorize_s": float("nan"), "iterate_s": float("nan"), "total_s": t1 - t0})
