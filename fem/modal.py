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
with its threads set to the cores that are free and OpenBLAS on one thread meanwhile). With PARDISO and
the Krylov method the factorization runs on a second Python thread (ctypes releases the GIL) while the
start block is prepared (:data:`OVERLAP`); the arithmetic and its order are unchanged, so are the bits.
Single-precision PARDISO (iparm[27] = 1) was tried as an inexact shift-invert: its Cholesky of
K - sigma M breaks down (error -4, not positive definite) on the 112,629-DOF apparatus at shifts of
1, 10 and 100 Hz, K - sigma M's condition (~1e10) being above 1 / eps of float32 (1.7e7).
"""

from __future__ import annotations

import contextlib
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh as dense_eigh
from scipy.sparse.linalg import LinearOperator, eigsh, splu

from fem._assembly import product, product_and_abs, upper_sum
from fem._pardiso import PardisoCholesky, blas_threads, fixed_threads
from fem._pardiso import has_pardiso as _has_pardiso

SOLVERS = ("pardiso", "superlu")
METHODS = ("krylov", "subspace", "lanczos")
GRAM_FLOOR = 1e-13  # relative floor of the Gram eigenvalues when orthonormalising a block
SIGN_SEED = 20231  # seed of the fixed vector that sets each mode's sign (see _fix_signs)
KRYLOV_TOL = 1e-10  # relative residual ||K phi - w^2 M phi|| / ||K phi|| asked of every mode
ROUNDOFF_FACTOR = 10.0  # residual floor, in units of eps || |K| |phi| || (round-off of K phi)
GUARD = 0  # Krylov: Ritz vectors expanded beyond the unconverged wanted modes (112k and 15k DOFs:
# 0 needs the fewest solves, 67 against 100 with 4 and 168 with 16; the Krylov basis keeps the rest). Fewer
# steps do not pay either (112,629 DOFs, one factorization, same process): the four 700-1000 Hz modes gain
# 20-50x a step whatever the block, so guard vectors added only once few modes are left (blocks topped up to
# 8, 12, 16 columns) took 9 steps instead of 10 with 90-144 solves instead of 68, and 5-50 % more CPU
MAX_BLOCKS = 8  # Krylov: basis of at most MAX_BLOCKS blocks before a thick restart
MAX_STEPS = 60  # Krylov: block solves before giving up (a mode left unconverged is reported)
START_EXTRA = 8  # Krylov: the first block is the wanted modes and this many more
ORTHO_TOL = 1e-12  # Krylov: M-orthonormality asked of the basis (one Gram-Schmidt pass instead of two misses
# it in 10 of the 11 extensions at 112,629 DOFs: the repeats cost more than the second pass saves)
OVERLAP = True  # Krylov with PARDISO: factorize on a second thread while the start block is prepared (same bits)
FIRST_CHECK_N = 10_000  # Krylov: from this order on, the Ritz pairs after the first solve are not checked: one
# shift-invert step from the random block leaves every mode far from passing (112,629 DOFs: 1.7e4 to 2e7 times
# its bound, 15,087: see tests/test_modal_speed_paths.py); skipping the check saves K Y and |K| |Y| of the whole block


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


def _factorize(A: sp.csr_matrix, solver: str, n_threads: int | None = None, upper: bool = False):
    """(solve, stats) for A = K - sigma M (for PARDISO ``upper``: A is its upper triangle, canonical)."""
    if solver == "superlu":
        return splu(A.tocsc()).solve, {}
    if solver == "pardiso":
        f = PardisoFactor(A, n_threads=n_threads, upper=upper)
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
    return _fprod(W, T), _fprod(MW, T)


def _extend(V, MV, W, M):
    """(W, M W, V^T M W, W^T M W) with W M-orthonormal and M-orthogonal to the M-orthonormal V
    (``MV`` = M V); the two products are the new columns of the projected mass matrix.

    Block Gram-Schmidt against V twice (Kahan-Parlett: twice is enough; it needs M V, not M W),
    then one product M W and SVQB on the block. M W is computed from W after the projections,
    never updated alongside them: a column of W that lay mostly in span V (a mode already
    converged) keeps a remnant ~1e-10 of its length, and updating W and M W separately would
    leave them inconsistent by eps/1e-10. SVQB mixes the block's own columns only, so (W T, M W T)
    stay consistent to round-off times the condition of T; when the check W^T M W = I, V^T M W = 0
    (to ``ORTHO_TOL``) fails, the passes repeat with M W recomputed (at most three more).
    """
    for _pass in range(4):
        for _ in range(2):
            if V.shape[1]:
                W = W - _fprod(V, MV.T @ W)
        W, MW = _svqb(W, product(M, W))
        VtMW, WtMW = V.T @ MW, W.T @ MW
        if ((VtMW.size == 0 or np.abs(VtMW).max() < ORTHO_TOL)
                and np.abs(WtMW - np.eye(W.shape[1])).max() < ORTHO_TOL):
            break
    return W, MW, VtMW, WtMW


def _block_krylov(K, M, solve, n_modes: int, sigma: float, tol: float, seed: int, max_steps: int = MAX_STEPS,
                  info: dict | None = None):
    """Block shift-invert Krylov with Rayleigh-Ritz on (K, M) and a residual test per mode.

    The basis V (M-orthonormal) grows by (K - sigma M)^-1 M Y, Y the Ritz vectors of the
    wanted modes not yet converged plus GUARD more; span{y, OP M y} = span{y, OP r} for a
    Ritz pair (y, theta) with residual r, so each step is an exact shift-invert correction of
    every unconverged mode, and the converged ones stay in the basis (locked implicitly). It
    starts from a random block of the wanted modes and START_EXTRA more. The Ritz pairs come
    from V^T K V c = theta V^T M V c, so the inexact solves of the ill-conditioned K - sigma M
    (condition ~1e10) only slow the convergence, never bias a converged pair.

    M V is kept beside V and K W computed once per new block, so the projected matrices grow by
    a block a step. Every mode not yet locked is checked at every step with K y itself, K y and
    |K| |y| coming from one pass over K (:func:`fem._assembly.product_and_abs`; blocks of 2-4
    columns, the usual case once the low modes are locked, by a register kernel twice as fast as
    scipy's, :func:`fem._assembly.product`). Mode i is converged when ||K y - theta M y|| <=
    max(tol ||K y||, ROUNDOFF_FACTOR eps || |K| |y| ||); a converged mode is locked (its Ritz vector
    no longer drives a block), and when all are, the locked ones are checked again with their
    present Ritz vectors before returning (one that slipped is iterated again). Past MAX_BLOCKS
    blocks the basis restarts from its wanted and guard Ritz vectors. Returns (theta, Y, n_op,
    n_steps, converged); ``info``, if given, receives each returned mode's relative residual and
    floor (``residuals``, ``floors``: as :func:`residual_test`).

    112,629-DOF apparatus, 16 modes: 68 solves in 10 steps, the Krylov phase 5.0 CPU s (at load 6-10;
    2.3 s of it the solves), against 7.3 s before K V was dropped, the floors computed with K y and
    the narrow products added.
    """
    n = K.shape[0]
    m = n_modes
    p = min(n, m + START_EXTRA)
    cap = min(n, MAX_BLOCKS * p + p)
    # column-major: only the columns in use are ever touched (a fresh page costs more than its copy)
    V = np.empty((n, cap), order="F")
    MV = np.empty((n, cap), order="F")
    Kr = np.zeros((cap, cap))
    Mr = np.zeros((cap, cap))
    W = np.asfortranarray(np.random.default_rng(seed).standard_normal((n, p)))
    n_op, step, k = 0, 0, 0
    res = np.full(m, np.inf)
    kyx = np.ones(m)  # ||K y|| of each mode at its last check
    fabs = np.full(m, np.inf)  # eps || |K| |y| || of each mode at its last check
    locked = np.zeros(m, bool)
    first = 1 if n >= FIRST_CHECK_N else 0  # the first step whose Ritz pairs are checked
    while True:
        # -- extend the basis by W, M-orthogonal to V
        W, MW, VtMW, WtMW = _extend(V[:, :k], MV[:, :k], W, M)
        KW = product(K, W)
        b = W.shape[1]
        V[:, k:k + b], MV[:, k:k + b] = W, MW
        Kr[:k, k:k + b] = V[:, :k].T @ KW
        Kr[k:k + b, :k] = Kr[:k, k:k + b].T
        Kr[k:k + b, k:k + b] = (W.T @ KW + KW.T @ W) / 2
        Mr[:k, k:k + b] = VtMW
        Mr[k:k + b, :k] = VtMW.T
        Mr[k:k + b, k:k + b] = (WtMW + WtMW.T) / 2
        k += b
        del W, MW, KW
        # -- Rayleigh-Ritz on (K, M); every unlocked mode checked with K y itself and its floor
        theta, Q = dense_eigh(Kr[:k, :k], Mr[:k, :k])
        kk = min(k, m + GUARD)
        last = step >= max_steps or k >= n
        act = np.flatnonzero(~locked)
        MYa = _fprod(MV[:, :k], Q[:, act])
        if step > first or last:  # nothing to check in the random block (and after one solve of a large model)
            res[act], kyx[act], fabs[act], locked[act] = _check(K, _fprod(V[:, :k], Q[:, act]), MYa, theta[act], tol)
        if locked.all() or last:
            # -- the locked modes checked again with their present Ritz vectors (the basis moved on)
            Y, MY = _fprod(V[:, :k], Q[:, :m]), _fprod(MV[:, :k], Q[:, :m])
            old = np.setdiff1d(np.arange(m), act)
            if old.size:
                res[old], kyx[old], fabs[old], locked[old] = _check(K, Y[:, old], MY[:, old], theta[old], tol)
            if locked.all() or last:
                if info is not None:
                    info.update(residuals=res.copy(), floors=fabs / kyx)
                return theta[:m], Y, n_op, step, locked.copy()
            act = np.flatnonzero(~locked)
            MYa = MY[:, act]
            keep = np.ones(len(act), bool)
        else:
            keep = ~locked[act]
        # -- next block: the unconverged wanted modes and the guard vectors
        sel = np.concatenate([act[keep], np.arange(m, kk)])
        RHS = MYa[:, keep]
        if kk > m:
            RHS = np.hstack([RHS, MV[:, :k] @ Q[:, m:kk]])
        if k + len(sel) > cap - p:  # thick restart from the Ritz vectors
            Qk = Q[:, :kk]
            V[:, :kk], MV[:, :kk] = V[:, :k] @ Qk, MV[:, :k] @ Qk
            Kr[:] = 0.0
            Mr[:] = 0.0
            Kr[:kk, :kk] = np.diag(theta[:kk])
            Mr[:kk, :kk] = np.eye(kk)
            k = kk
        W = solve(RHS)
        n_op += len(sel)
        step += 1


def _fprod(A, B):
    """A @ B in column-major order (BLAS writes it so; no transposing copy when it is stored)."""
    return (B.T @ A.T).T


def _check(K, Y, MY, theta, tol):
    """Explicit residual test of Ritz pairs (theta, Y): (relative residual, ||K y||, eps || |K| |y| ||,
    passed) per column, K Y and |K| |Y| from one pass over K (:func:`fem._assembly.product_and_abs`)."""
    KY, AY = product_and_abs(K, Y)
    ky = np.maximum(np.linalg.norm(KY, axis=0), 1e-300)
    rd = np.linalg.norm(KY - MY * theta, axis=0)
    fabs = np.finfo(float).eps * np.linalg.norm(AY, axis=0)
    return rd / ky, ky, fabs, rd <= np.maximum(tol * ky, ROUNDOFF_FACTOR * fabs)


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
    overlap = OVERLAP and solver == "pardiso" and method == "krylov"
    if solver == "pardiso":  # the upper triangle of K - sigma M in one pass (fem._assembly.upper_sum)
        indptr, indices, data = upper_sum(K, M, -sigma)
        A = sp.csr_matrix((data, indices, indptr), shape=K.shape)
        if overlap:  # factorized on a second thread while the Krylov start block is prepared (see below)
            pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pardiso")
            t_submit = time.perf_counter()
            pending = pool.submit(_factorize, A, solver, n_threads, True)
            pool.shutdown(wait=False)
        else:
            solve, stats = _factorize(A, solver, n_threads, upper=True)
    else:
        A = (K - sigma * M).tocsr()
        solve, stats = _factorize(A, solver, n_threads)
    del A
    t1 = time.perf_counter()
    conv, info = None, None
    # the eigensolvers' dense work is tall-skinny products: one OpenBLAS thread, so that it
    # does not fight PARDISO's threads for the cores (fem._pardiso)
    with blas_threads(1) if solver == "pardiso" else contextlib.nullcontext():
        if method == "krylov":
            info = {}
            if overlap:
                # PARDISO runs on its own thread (ctypes releases the GIL) while this one builds the start
                # block (random block, M- and K-products, Rayleigh-Ritz): the first solve waits for the factor.
                # Same arithmetic in the same order as factorizing first, so the same bits (tests/test_modal*).
                def solve(B):
                    return pending.result()[0](B)
            lam, phi, n_op, n_iter, conv = _block_krylov(K, M, solve, n_modes, sigma,
                                                        KRYLOV_TOL if tol is None else tol, seed, info=info)
            if overlap:
                stats = pending.result()[1]
                t1 = t_submit + stats["analyse_s"] + stats["factor_s"]  # upper_sum + the factorization's walls
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
    mnorm = np.sqrt(np.einsum("ij,ij->j", phi, product(M, phi)))  # the same bits as M @ phi
    phi = _fix_signs(phi / mnorm)
    if conv is not None:  # the Krylov solver's own final test, on these vectors (both ratios scale-free)
        conv, res, floors = conv[order], info["residuals"][order], info["floors"][order]
    else:
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
