"""Stability of periodic orbits: Hill's method on HB solutions, compared with Floquet (shooting).

Hill's method (Lazarus & Thomas 2010; Krack & Gross 2019, Sec. 3.6): a perturbation
e^{lam t} p(tau) of an HB solution, p in the same Fourier basis, satisfies the quadratic
eigenproblem

    (J2 lam^2 + J1 lam + J0) p = 0,   J0 = dR/dX,  J1 = 2 omega kron(Nab, M) [+ kron(I, C)],
                                      J2 = kron(I, M)

(:meth:`reduced.periodic.hb.HarmonicBalance.hill_matrices`), solved as a 2 n (2H+1) linear
eigenproblem. Each Floquet exponent appears 2H+1 times, shifted by i k omega; the 2n
kept are those in the first zone |Im lam| <= omega / 2 (the classical criterion; a
centring criterion on the eigenvectors' mean harmonic, Guillot et al. 2020, was tried and
fails at H = 1, where the constant term always wins; an "unresolved eigenvector"
filter admitted truncation artefacts). The trivial pair at +1 is dropped before judging
stability (reduced.periodic.shooting.drop_trivial_pair); with the AFT Jacobian of a kinked force
that pair is itself split, by up to ~10 % in |mu| at H = 15 near 50 J on NNM 2, which
sets how far Hill's multipliers can be trusted. Multipliers mu = exp(lam T).

Floquet multipliers from :mod:`reduced.periodic.shooting` are the reference: Hill's method on a
truncated series with AFT Jacobians of a non-smooth force is an approximation, most of
all near grazing. :func:`compare` flags orbits where the two disagree on stability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.linalg import eig
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigs

from reduced.periodic.hb import _DGETRS, HarmonicBalance

HILL_TOL = 1e-3  # max |mu| - 1 above this is unstable for Hill (truncation and AFT errors
# of the exponents, ~1e-4 T^-1 on the converged branches, set this floor)


@dataclass(frozen=True, eq=False)
class HillResult:
    """Floquet exponents and multipliers of an HB solution by Hill's method (:func:`hill`).

    Attributes
    ----------
    exponents : (k,) ndarray of complex
        1/s, the Floquet exponents kept (k = 2n, fewer with ``strict_zone``), in the order of
        ``multipliers``.
    multipliers : (k,) ndarray of complex
        exp(lam T), by decreasing modulus.
    tol : float
        |mu| - 1 above this is unstable (:attr:`stable`).
    """

    exponents: np.ndarray  # (2n,) complex, 1/s
    multipliers: np.ndarray  # (2n,) complex, sorted by decreasing modulus
    tol: float

    @property
    def max_multiplier(self) -> float:
        """Largest |mu| without the trivial pair at +1 (see reduced.periodic.shooting)."""
        from reduced.periodic.shooting import drop_trivial_pair

        return float(np.max(np.abs(drop_trivial_pair(self.multipliers)), initial=1.0))

    @property
    def stable(self) -> bool:
        return self.max_multiplier <= 1.0 + self.tol


HILL_SOLVERS = ("qz", "standard", "shift-invert")
SHIFT = 0.01  # omega, the real shift of "shift-invert": off the trivial pair at 0 (J0 singular), inside the zone
EXTRA_EIGENVALUES = 16  # "shift-invert" asks ARPACK for 2n + this many eigenvalues nearest the shift
MU_MISSABLE = 1e4  # "shift-invert" is taken only if a first-zone exponent outside ARPACK's disc would have |mu| above
# this (the largest Hill multiplier on rom-fep's drawn branches is 8.3e2, Floquet's 1.1e2); else the dense "standard"
DENSE_BELOW = 4  # "shift-invert" falls back to "standard" when the companion matrix has fewer than this many times
# the eigenvalues asked for (H = 1 of a 12-DOF model: 72 rows, dense in 1 ms)


def hill(hb: HarmonicBalance, X: np.ndarray, omega: float, tol: float = HILL_TOL,
         solver: str = "qz", strict_zone: bool = False) -> HillResult:
    """Floquet exponents and multipliers of the HB solution (X, omega) by Hill's method.

    ``solver``: "qz" solves the pencil (A, B) as it stands (QZ); "standard" multiplies by
    B^-1 first, which is cheap because J2 = kron(I, M) is block diagonal, and solves
    B^-1 A with the Hessenberg QR, about 3 times faster (1.2 s against 0.37 s at n = 12,
    H = 15). Both give the same exponents up to round-off (the multipliers of a reduced
    model agree to ~1e-5: Hill's eigenvalues are ill-conditioned); the 3-DOF results were
    made with "qz" and are kept so, bit for bit. "shift-invert" computes only the eigenvalues
    nearest the real shift ``SHIFT`` omega (:func:`_nearest_exponents`: ARPACK on the pencil
    shifted and inverted through Q(sigma) = J0 + sigma J1 + sigma^2 J2, one LU of n (2H+1) rows),
    which hold the first zone: 3.5 times faster than "standard" at n = 12, H = 9 (15 against
    52 ms a point), the same exponents to ~1e-11 omega. It falls back to "standard" where
    ARPACK does not converge, where the problem is small (``DENSE_BELOW``) or where its disc
    of eigenvalues does not certify the selection below (``MU_MISSABLE``).

    The 2n exponents kept are those of smallest |Im lam|; with ``strict_zone`` only those in
    the first zone itself, |Im lam| <= omega / 2 (at most 2n). A model with modes above
    H omega (a reduced model's local modes, up to 78 kHz) has fewer than 2n exponents in the
    first zone: the 2n smallest |Im| then include copies from the zone edge |Im| = omega,
    truncation artefacts with |mu| up to 1.05 on orbits that Floquet finds stable.

    Parameters
    ----------
    hb : HarmonicBalance
        The discretisation of the solution.
    X : (n (2H+1),) ndarray of float
        HB coefficients.
    omega : float
        rad/s, the solution's frequency.
    tol : float
        Stability tolerance stored in the result.
    solver : {'qz', 'standard', 'shift-invert'}
        Eigensolver (above).
    strict_zone : bool
        Keep only the exponents with |Im lam| <= omega / 2.

    Returns
    -------
    HillResult

    Raises
    ------
    ValueError
        An unknown ``solver``.
    """
    if solver not in HILL_SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(HILL_SOLVERS)}, got {solver!r}")
    J0, J1, J2 = hb.hill_matrices(X, omega)
    n = hb.n
    lam = _nearest_exponents(J0, J1, J2, n, omega, strict_zone) if solver == "shift-invert" else None
    if lam is None:
        lam = _dense_eigenvalues(hb, J0, J1, J2, "qz" if solver == "qz" else "standard")
    lam = lam[np.isfinite(lam)]
    # each exponent recurs shifted by i k omega: keep the copies in the first zone
    keep = np.argsort(np.abs(lam.imag), kind="stable")[: 2 * n]
    if strict_zone:
        keep = keep[np.abs(lam[keep].imag) <= 0.5 * omega * (1.0 + 1e-9)]
    lam = lam[keep]
    T = 2.0 * np.pi / omega
    mu = np.exp(lam * T)
    order = np.argsort(-np.abs(mu), kind="stable")
    return HillResult(lam[order], mu[order], tol)


SCREEN_MARGIN = 1e-4  # hill_screened: a verdict by "shift-invert" is taken when its max |mu| is this far from
# 1 + tol; nearer, QZ decides. Measured on discrete-fep's drawn branches (740 points, H = 1 and 15): max |mu| by
# "shift-invert" within 5e-8 (relative) of QZ's at 739 points, within 2e-9 at the 311 points within 0.05 of
# 1 + tol; at one point (NNM 1, H = 15, 1.3e-3 J, near grazing) 3.65 against QZ's 4.20, the 2n exponents of
# smallest |Im| not the same ones (both unstable). The verdicts agreed at all 740 (benchmarks/fep_hill_speed.py).


def hill_screened(hb: HarmonicBalance, X: np.ndarray, omega: float, tol: float = HILL_TOL,
                  solver: str = "qz", strict_zone: bool = False) -> HillResult:
    """:func:`hill` for its stability verdict alone (the fep study's points whose multipliers are not
    written): ``hill(..., solver="qz")``'s ``stable`` where measured, about 4 times faster at H = 15 on
    the 3-DOF model (4 against 16 ms a point).

    The "shift-invert" solver first (the first-zone exponents by ARPACK, or the dense "standard" form
    where it cannot certify them); its exponents are QZ's up to round-off, so where its max |mu| is
    more than :data:`SCREEN_MARGIN` from the threshold 1 + tol, that result is returned; nearer the
    threshold (or not finite), the "qz" result. Not a proof: where Hill's selection of the 2n exponents
    of smallest |Im lam| is not robust (near grazing) the two solvers can keep different exponents
    (:data:`SCREEN_MARGIN`'s comment: one point of 740, both unstable). The multipliers returned may
    differ from QZ's: use :func:`hill` where they are written. Other solvers than "qz" are passed to
    :func:`hill` unchanged.

    Parameters
    ----------
    hb : HarmonicBalance
        The discretisation of the solution.
    X : (n (2H+1),) ndarray of float
        HB coefficients.
    omega : float
        rad/s, the solution's frequency.
    tol : float
        Stability tolerance stored in the result.
    solver : {'qz', 'standard', 'shift-invert'}
        "qz": screened as above; another is passed to :func:`hill`.
    strict_zone : bool
        As :func:`hill`.

    Returns
    -------
    HillResult
    """
    if solver != "qz":
        return hill(hb, X, omega, tol, solver, strict_zone)
    r = hill(hb, X, omega, tol, "shift-invert", strict_zone)
    m = r.max_multiplier
    if np.isfinite(m) and abs(m - (1.0 + tol)) > SCREEN_MARGIN:
        return r
    return hill(hb, X, omega, tol, "qz", strict_zone)


def _dense_eigenvalues(hb: HarmonicBalance, J0: np.ndarray, J1: np.ndarray, J2: np.ndarray, solver: str
                       ) -> np.ndarray:
    """All 2 n (2H+1) eigenvalues of Hill's companion pencil, by QZ or the standard form (:func:`hill`)."""
    nX = hb.size
    Z = np.zeros((nX, nX))
    I = np.eye(nX)
    if solver == "standard":
        Minv = np.linalg.inv(hb.M)
        J2inv = np.kron(np.eye(2 * hb.H + 1), Minv)  # J2 = kron(I, M)
        return np.linalg.eigvals(np.block([[Z, I], [-J2inv @ J0, -J2inv @ J1]]))
    A = np.block([[Z, I], [-J0, -J1]])
    B = np.block([[I, Z], [Z, J2]])
    return eig(A, B, right=False)


def _nearest_exponents(J0: np.ndarray, J1: np.ndarray, J2: np.ndarray, n: int, omega: float,
                       strict_zone: bool) -> np.ndarray | None:
    """The eigenvalues of Hill's problem nearest sigma = SHIFT omega, which hold every exponent
    :func:`hill` keeps, or None (use a dense solver).

    ARPACK (``eigs``, largest modulus) on the companion pencil shifted and inverted: (A - sigma)^-1
    [f; g] = [u; f + sigma u] with Q(sigma) u = -J2 g - (J1 + sigma J2) f, Q(sigma) = J0 + sigma J1
    + sigma^2 J2 (one LU of n (2H+1) rows, no companion matrix), k = 2n + EXTRA_EIGENVALUES
    eigenvalues, a fixed start vector (the same bits in every call), converged to machine
    precision. They are the k eigenvalues nearest sigma: every eigenvalue inside the disc
    |lam - sigma| < R (R: the farthest found) is among them. The exponents :func:`hill` keeps
    have |Im lam| <= b (omega / 2 with ``strict_zone``, else the largest |Im| kept), so one
    outside the disc would have |Re lam| >= sqrt(R^2 - b^2): the disc is taken only if that
    is |mu| = exp(|Re lam| T) > MU_MISSABLE; else None, as where ARPACK does not converge.
    """
    nX = J0.shape[0]
    k = 2 * n + EXTRA_EIGENVALUES
    if 2 * nX < DENSE_BELOW * k:
        return None
    sigma = SHIFT * omega
    try:
        lu = scipy.linalg.lu_factor(J0 + sigma * J1 + sigma**2 * J2)
    except (ValueError, np.linalg.LinAlgError):
        return None
    J1s = J1 + sigma * J2
    lu_, piv = lu

    def solve(z: np.ndarray) -> np.ndarray:
        # scipy.linalg.lu_solve(lu, b)'s LAPACK call (getrs, the same numbers) without its wrappers, which
        # cost as much as the solve here (ARPACK asks ~60 times a point)
        f, g = z[:nX], z[nX:]
        b = -(J2 @ g) - J1s @ f
        if not np.all(np.isfinite(b)):
            raise ValueError("array must not contain infs or NaNs")
        u, info = _DGETRS(lu_, piv, b)
        if info != 0:
            raise ValueError(f"illegal value in {-info}th argument of internal getrs")
        return np.concatenate([u, f + sigma * u])

    op = LinearOperator((2 * nX, 2 * nX), matvec=solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(2 * nX)
    try:
        nu = eigs(op, k=k, which="LM", v0=v0, tol=0.0, return_eigenvectors=False)
    except ArpackNoConvergence:
        return None
    if not np.all(np.isfinite(nu)) or np.any(nu == 0.0):
        return None
    lam = sigma + 1.0 / nu
    R = float(np.min(np.abs(nu))) ** -1
    if strict_zone:
        b = 0.5 * omega * (1.0 + 1e-9)  # hill's zone test
    else:
        b = float(np.sort(np.abs(lam.imag))[2 * n - 1])
    T = 2.0 * np.pi / omega
    if R <= b or T * np.sqrt(R**2 - b**2) <= np.log(MU_MISSABLE):
        return None
    return lam


@dataclass(frozen=True, eq=False)
class StabilityComparison:
    """Floquet (shooting) and Hill stability verdicts side by side, one entry per energy (:func:`compare`).

    Attributes
    ----------
    energy_J : (k,) ndarray of float
        J.
    floquet_max : (k,) ndarray of float
        max |mu| from shooting (nan where shooting failed).
    hill_max : (k,) ndarray of float
        max |mu| from Hill's method.
    floquet_stable, hill_stable : (k,) ndarray of bool
        The two verdicts.
    agree : (k,) ndarray of bool
        The verdicts agree (True where shooting failed: nothing to compare).
    """

    energy_J: np.ndarray
    floquet_max: np.ndarray  # max |mu| from shooting (nan where shooting failed)
    hill_max: np.ndarray
    floquet_stable: np.ndarray  # bool
    hill_stable: np.ndarray  # bool
    agree: np.ndarray  # bool (True where shooting failed: nothing to compare)

    @property
    def n_disagree(self) -> int:
        return int(np.sum(~self.agree))


def compare(energy_J, floquet_max, floquet_stable, hill_max, hill_stable) -> StabilityComparison:
    """Side-by-side stability verdicts; ``agree`` is False where they differ.

    Parameters
    ----------
    energy_J : (k,) array_like of float
        J.
    floquet_max : (k,) array_like of float
        max |mu| by shooting, nan where it failed.
    floquet_stable : (k,) array_like of bool
        Shooting's verdict.
    hill_max : (k,) array_like of float
        max |mu| by Hill's method.
    hill_stable : (k,) array_like of bool
        Hill's verdict.

    Returns
    -------
    StabilityComparison
    """
    fm = np.asarray(floquet_max, float)
    fs = np.asarray(floquet_stable, bool)
    hs = np.asarray(hill_stable, bool)
    agree = np.where(np.isfinite(fm), fs == hs, True)
    return StabilityComparison(np.asarray(energy_J, float), fm, np.asarray(hill_max, float), fs, hs, agree)


__all__ = ["HillResult", "hill", "hill_screened", "compare", "StabilityComparison", "HILL_TOL", "HILL_SOLVERS"]
