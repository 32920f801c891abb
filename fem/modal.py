"""Modal analysis by shift-invert, robust to rigid-body (zero) modes.

Solves K phi = omega^2 M phi for the ``n_modes`` eigenvalues nearest a negative shift
sigma = -(2 pi f_shift)^2. K - sigma M is then positive definite even when K is singular
(free-free: six zero modes), so no singular factorization is ever attempted.

Eigensolvers (``method``):

- ``"krylov"`` (default): block shift-invert Krylov with Rayleigh-Ritz on (K, M) itself and a
  residual test per mode (:func:`_block_krylov`). Every mode is returned with
  ||K phi - omega^2 M phi|| <= max(tol ||K phi||, ROUNDOFF_FACTOR eps || |K| |phi| ||):
  the second term is the round-off of evaluating K phi in double precision, the floor no
  eigenvector stored in doubles can go below (it dominates for the sub-10 Hz modes of the
  apparatus, whose ||K phi|| is ~1e-11 of ||K|| ||phi||). Reported per mode in
  :attr:`ModalResult.residuals` and :attr:`ModalResult.floors`;
- ``"subspace"``: block subspace iteration (Bathe) stopping on the change of the eigenvalues;
- ``"lanczos"``: ARPACK (scipy.sparse.linalg.eigsh) with the factorization as OPinv.

Factorization back ends: ``"superlu"`` (SciPy's SuperLU, the plain baseline that eigsh
uses when given sigma) and ``"pardiso"`` (Intel MKL PARDISO Cholesky, :mod:`fem._pardiso`,
with its threads set to the cores that are free and OpenBLAS on one thread meanwhile).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh as dense_eigh
from scipy.sparse.linalg import LinearOperator, eigsh, splu

from fem._pardiso import PardisoCholesky, blas_threads, fixed_threads
from fem._pardiso import has_pardiso as _has_pardiso

SOLVERS = ("pardiso", "superlu")
METHODS = ("krylov", "subspace", "lanczos")
GRAM_FLOOR = 1e-13  # relative floor of the Gram eigenvalues when orthonormalising a block
SIGN_SEED = 20231  # seed of the fixed vector that sets each mode's sign (see _fix_signs)
KRYLOV_TOL = 1e-10  # relative residual ||K phi - w^2 M phi|| / ||K phi|| asked of every mode
ROUNDOFF_FACTOR = 10.0  # residual floor, in units of eps || |K| |phi| || (round-off of K phi)
GUARD = 0  # Krylov: Ritz vectors expanded beyond the unconverged wanted modes (112k and 15k DOFs:
# 0 needs the fewest solves, 67 against 100 with 4 and 168 with 16; the Krylov basis keeps the rest)
MAX_BLOCKS = 8  # Krylov: basis of at most MAX_BLOCKS blocks before a thick restart
MAX_STEPS = 60  # Krylov: block solves before giving up (a mode left unconverged is reported)


@dataclass(frozen=True, eq=False)
class ModalResult:
    """Natural frequencies and mass-normalised mode shapes (phi^T M phi = I), signs fixed by
    :func:`_fix_signs`.

    Attributes
    ----------
    freq_hz : (n_modes,) ndarray of float
        Hz, ascending (negative eigenvalues give 0).
    phi : (n_dofs, n_modes) ndarray of float
        Mode shapes, phi^T M phi = I.
    omega2 : (n_modes,) ndarray of float
        rad^2/s^2, the eigenvalues.
    solver : str
        '<factorization>/<method>', e.g. 'pardiso/krylov'.
    shift_hz : float
        Hz, magnitude of the negative shift.
    n_op : int
        Applications of (K - sigma M)^-1 to a vector (-1 when unknown).
    n_iter : int
        Subspace iterations or block Krylov steps (0 for ARPACK).
    timing : dict of str to float
        s, ``factorize_s``, ``iterate_s`` (and ``check_s`` or ``total_s``).
    residual : float
        max_i ||K phi_i - omega_i^2 M phi_i|| / ||K phi_i|| over the elastic modes.
    residuals, floors : (n_modes,) ndarray of float or None
        Each mode's relative residual and its round-off floor (:func:`residual_test`).
    converged : (n_modes,) ndarray of bool or None
        The Krylov residual test passed (Krylov method only).
    stats : dict
        Factorization statistics (factor non-zeros, MFLOP, threads).
    """

    freq_hz: np.ndarray  # Hz, (n_modes,) ascending
    phi: np.ndarray  # (n_dofs, n_modes)
    omega2: np.ndarray  # rad^2/s^2, eigenvalues
    solver: str
    shift_hz: float
    n_op: int  # applications of (K - sigma M)^-1 to a vector
    n_iter: int  # subspace iterations or block Krylov steps (0 for ARPACK)
    timing: dict = field(default_factory=dict)  # s: factorize, iterate
    residual: float = 0.0  # max_i ||K phi_i - omega_i^2 M phi_i|| / ||K phi_i|| over elastic modes
    residuals: np.ndarray | None = None  # (n_modes,) ||K phi_i - omega_i^2 M phi_i|| / ||K phi_i||
    floors: np.ndarray | None = None  # (n_modes,) eps || |K| |phi_i| || / ||K phi_i||: round-off floor
    converged: np.ndarray | None = None  # (n_modes,) bool, the Krylov residual test passed
    stats: dict = field(default_factory=dict)  # factor non-zeros, MFLOP, threads


def has_pardiso() -> bool:
    return _has_pardiso()


class PardisoFactor(PardisoCholesky):
    """Cholesky factor of a symmetric positive definite matrix by MKL PARDISO (mtype 2).

    Parameters
    ----------
    A, n_threads, iparm
        As :class:`fem._pardiso.PardisoCholesky`.
    """


def _fix_signs(phi: np.ndarray) -> np.ndarray:
    """Each column with the sign that makes w^T phi > 0 for one fixed pseudo-random w.

    An eigensolver returns +phi or -phi depending on round-off (MKL PARDISO's threads reorder
    sums); a fixed rule makes written shapes reproducible. w is random so that no structured
    mode (symmetric or antisymmetric about a plane, zero on a node) is orthogonal to it.
    """
    w = np.random.default_rng(SIGN_SEED).standard_normal(phi.shape[0])
    return phi * np.where(w @ phi < 0.0, -1.0, 1.0)


def _factorize(A: sp.csr_matrix, solver: str, n_threads: int | None = None):
    """(solve, stats) for A = K - sigma M."""
    if solver == "superlu":
        return splu(A.tocsc()).solve, {}
    if solver == "pardiso":
        f = PardisoFactor(A, n_threads=n_threads)
        return f.solve, dict(f.stats)
    raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")


def _abs(K: sp.spmatrix) -> sp.csr_matrix:
    K = K.tocsr()
    return sp.csr_matrix((np.abs(K.data), K.indices, K.indptr), shape=K.shape)


def residual_test(K, M, lam: np.ndarray, X: np.ndarray, absK=None, MX=None):
    """Per column: relative residual ||K x - lam M x|| / ||K x|| and its round-off floor
    eps || |K| |x| || / ||K x|| (the error of evaluating K x itself in double precision).

    Parameters
    ----------
    K, M : (n, n) sparse matrix
        N/m and kg.
    lam : (m,) ndarray of float
        rad^2/s^2, eigenvalue estimates.
    X : (n, m) ndarray of float
        Eigenvector estimates.
    absK : (n, n) sparse matrix, optional
        |K| entrywise (computed when not given).
    MX : (n, m) ndarray of float, optional
        M X, if already known.

    Returns
    -------
    residual, floor : (m,) ndarray of float
        ||K x - lam M x|| / ||K x|| and eps || |K| |x| || / ||K x|| of each column.
    """
    KX = K @ X
    MX = M @ X if MX is None else MX
    absK = _abs(K) if absK is None else absK
    r = np.linalg.norm(KX - MX * lam, axis=0)
    kx = np.maximum(np.linalg.norm(KX, axis=0), 1e-300)
    floor = np.finfo(float).eps * np.linalg.norm(absK @ np.abs(X), axis=0)
    return r / kx, floor / kx


def _svqb(W, MW, drop: float = 1e-12):
    """W, M W with W^T M W = I by SVQB (Stathopoulos & Wu 2002): columns scaled to unit
    M-norm, then the eigen-decomposition of their Gram matrix; directions whose Gram
    eigenvalue is below ``drop`` of the largest are dropped (their direction is round-off)."""
    d = 1.0 / np.sqrt(np.maximum(np.einsum("ij,ij->j", W, MW), 1e-300))
    g, U = dense_eigh(d[:, None] * (W.T @ MW) * d[None, :])
    keep = g > drop * max(g.max(), 1e-300)
    T = d[:, None] * (U[:, keep] / np.sqrt(g[keep]))
    return W @ T, MW @ T


def _extend(V, MV, W, M):
    """(W, M W) with W M-orthonormal and M-orthogonal to the M-orthonormal V: block
    Gram-Schmidt and SVQB, repeated until both hold to 1e-12 (twice is the rule, Kahan-Parlett).

    M W is recomputed from W after every pass, never updated alongside it: a column of W that
    lay mostly in span V (the modes already converged) keeps a remnant ~1e-10 of its length,
    and updating W and M W separately would leave them inconsistent by eps/1e-10.
    """
    for _ in range(4):
        if V.shape[1]:
            W = W - V @ (MV.T @ W)
        W, _ = _svqb(W, M @ W)
        MW = M @ W
        off = np.abs(MV.T @ W).max() if V.shape[1] else 0.0
        if off < 1e-12 and np.abs(W.T @ MW - np.eye(W.shape[1])).max() < 1e-12:
            break
    return W, MW


def _block_krylov(K, M, solve, n_modes: int, sigma: float, tol: float, seed: int, max_steps: int = MAX_STEPS):
    """Block shift-invert Krylov with Rayleigh-Ritz on (K, M) and a residual test per mode.

    The basis V (M-orthonormal) grows by (K - sigma M)^-1 M Y, Y the Ritz vectors of the
    wanted modes not yet converged plus GUARD more; span{y, OP M y} = span{y, OP r} for a
    Ritz pair (y, theta) with residual r, so each step is an exact shift-invert correction of
    every unconverged mode, and the converged ones stay in the basis (locked implicitly). The
    Ritz pairs come from V^T K V c = theta V^T M V c, so the inexact solves of the ill-conditioned
    K - sigma M (condition ~1e10) only slow the convergence, never bias a converged pair.
    Mode i is converged when ||K y - theta M y|| <= max(tol ||K y||, ROUNDOFF_FACTOR eps ||
    |K| |y| ||). Past MAX_BLOCKS blocks the basis restarts from its wanted and guard Ritz
    vectors. Returns (theta, Y, n_op, n_steps, converged).
    """
    n = K.shape[0]
    m = n_modes
    absK = _abs(K)
    eps = np.finfo(float).eps
    p = min(n, m + max(GUARD, 8))  # the first block: the wanted modes and 8 more
    W = np.random.default_rng(seed).standard_normal((n, p))
    V = np.empty((n, 0))
    MV = np.empty((n, 0))
    Kr = np.empty((0, 0))
    n_op, step = 0, 0
    conv = np.zeros(m, bool)
    while True:
        # -- extend the basis by W, M-orthogonal to V (two passes of block Gram-Schmidt)
        W, MW = _extend(V, MV, W, M)
        KW = K @ W
        Kr = np.block([[Kr, V.T @ KW], [KW.T @ V, W.T @ KW]])
        V = np.hstack([V, W])
        MV = np.hstack([MV, MW])
        del KW
        # -- Rayleigh-Ritz on (K, M); V^T M V = I to round-off, kept exact in the small problem
        Mr = V.T @ MV
        Kr = (Kr + Kr.T) / 2
        theta, Q = dense_eigh(Kr, (Mr + Mr.T) / 2)
        k = min(len(theta), m + GUARD)
        Y, MY = V @ Q[:, :k], MV @ Q[:, :k]
        KY = K @ Y[:, :m]
        r = np.linalg.norm(KY - MY[:, :m] * theta[:m], axis=0)
        bound = np.maximum(tol * np.linalg.norm(KY, axis=0),
                           ROUNDOFF_FACTOR * eps * np.linalg.norm(absK @ np.abs(Y[:, :m]), axis=0))
        conv = r <= bound
        if conv.all() or step >= max_steps or V.shape[1] >= n:
            return theta[:m], Y[:, :m], n_op, step, conv
        # -- next block: the unconverged wanted modes and the guard vectors
        if V.shape[1] + p > MAX_BLOCKS * p:  # thick restart from the Ritz vectors
            V, MV = Y, MY
            Kr = np.diag(theta[:k])
        sel = np.concatenate([np.flatnonzero(~conv), np.arange(m, k)])
        W = solve(MY[:, sel])
        n_op += len(sel)
        step += 1


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
                   solver: str = "pardiso", method: str = "krylov", tol: float | None = None,
                   max_iter: int = 40, seed: int = 0, n_threads: int | None = None) -> ModalResult:
    """Lowest ``n_modes`` modes of (K, M) by shift-invert about sigma = -(2 pi shift_hz)^2.

    Parameters
    ----------
    K, M : (n, n) sparse symmetric stiffness (N/m, positive semi-definite) and mass (kg).
    n_modes : number of modes, counting rigid-body ones.
    shift_hz : Hz, magnitude of the negative shift; below the first elastic frequency.
    solver : 'pardiso' (if installed) or 'superlu'.
    method : 'krylov' (block shift-invert Krylov, residual test per mode, see
        :func:`_block_krylov`), 'subspace' (block subspace iteration: one block solve per
        iteration) or 'lanczos' (ARPACK through eigsh with the factorization as OPinv).
    tol : krylov: relative residual ||K phi - w^2 M phi|| / ||K phi|| asked of every mode
        (default KRYLOV_TOL), floored at the round-off of K phi. subspace: stop when the
        eigenvalues change by less than tol (lam + |sigma|) between iterations (default 1e-4;
        the solves of K - sigma M, condition ~1e10, are accurate to about 1e-6, so the Ritz
        values of the near-zero modes wander by ~1e-5 of |sigma|; at least three iterations
        are always made). lanczos: not used (ARPACK to machine precision).
    max_iter : most subspace iterations (method 'subspace' only).
    seed : seed of the random start block (krylov, subspace) or start vector (lanczos).
    n_threads : PARDISO threads (default: :func:`fem._pardiso.solver_threads`, one unless BEARINGSHAFT_THREADS is set).

    Returns
    -------
    ModalResult
        Ascending, mass-normalised, signs fixed, with each mode's residual and round-off floor.

    Raises
    ------
    ValueError
        An unknown ``method``.
    """
    with fixed_threads():  # the same bits whatever the machine's cores (fem._pardiso.DEFAULT_THREADS)
        return _modal_analysis(K, M, n_modes, shift_hz, solver, method, tol, max_iter, seed, n_threads)


def _modal_analysis(K, M, n_modes, shift_hz, solver, method, tol, max_iter, seed, n_threads) -> ModalResult:
    if solver == "pardiso" and not has_pardiso():
        solver = "superlu"
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    n = K.shape[0]
    sigma = -(2 * np.pi * shift_hz) ** 2
    t0 = time.perf_counter()
    A = (K - sigma * M).tocsr()
    solve, stats = _factorize(A, solver, n_threads)
    del A
    t1 = time.perf_counter()
    conv = None
    # the eigensolvers' dense work is tall-skinny products: one OpenBLAS thread, so that it
    # does not fight PARDISO's threads for the cores (fem._pardiso)
    with blas_threads(1) if solver == "pardiso" else contextlib.nullcontext():
        if method == "krylov":
            lam, phi, n_op, n_iter, conv = _block_krylov(K, M, solve, n_modes, sigma,
                                                        KRYLOV_TOL if tol is None else tol, seed)
        elif method == "subspace":
            lam, phi, n_op, n_iter = _subspace(K, M, solve, n_modes, sigma, 1e-4 if tol is None else tol,
                                               max_iter, seed)
        else:
            count = [0]

            def op(x):
                count[0] += 1
                return solve(x)

            OPinv = LinearOperator((n, n), matvec=op, dtype=np.float64)
            v0 = np.random.default_rng(seed).standard_normal(n)
            lam, phi = eigsh(K, k=n_modes, M=M, sigma=sigma, which="LM", OPinv=OPinv, v0=v0)
            n_op, n_iter = count[0], 0
    t2 = time.perf_counter()
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    if conv is not None:
        conv = conv[order]
    mnorm = np.sqrt(np.einsum("ij,ij->j", phi, M @ phi))
    phi = _fix_signs(phi / mnorm)
    res, floors = residual_test(K, M, lam, phi)
    elastic = lam > (2 * np.pi * shift_hz) ** 2
    freq = np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)
    return ModalResult(freq_hz=freq, phi=phi, omega2=lam, solver=f"{solver}/{method}", shift_hz=shift_hz,
                       n_op=n_op, n_iter=n_iter,
                       timing={"factorize_s": t1 - t0, "iterate_s": t2 - t1, "check_s": time.perf_counter() - t2},
                       residual=float(res[elastic].max()) if elastic.any() else 0.0,
                       residuals=res, floors=floors, converged=conv, stats=stats)


def baseline_modal(K: sp.spmatrix, M: sp.spmatrix, n_modes: int = 20, shift_hz: float = 1.0,
                   seed: int = 0) -> ModalResult:
    """The plain SciPy baseline: eigsh(K, M=M, sigma=sigma) factorizing with SuperLU itself.

    Parameters
    ----------
    K, M : (n, n) sparse matrix
        N/m and kg.
    n_modes : int
        Number of modes, rigid-body ones included.
    shift_hz : float
        Hz, sigma = -(2 pi shift_hz)^2.
    seed : int
        Seed of ARPACK's random start vector.

    Returns
    -------
    ModalResult
        Mass-normalised, signs fixed; no residuals, ``n_op`` = -1, only ``total_s`` timed.
    """
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
