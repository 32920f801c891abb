"""Stability of periodic orbits: Hill's method on HB solutions, compared with Floquet (shooting).

Hill's method (Lazarus & Thomas 2010; Krack & Gross 2019, Sec. 3.6): a perturbation
e^{lam t} p(tau) of an HB solution, p in the same Fourier basis, satisfies the quadratic
eigenproblem

    (J2 lam^2 + J1 lam + J0) p = 0,   J0 = dR/dX,  J1 = 2 omega kron(Nab, M) [+ kron(I, C)],
                                      J2 = kron(I, M)

(:meth:`reduced.hb.HarmonicBalance.hill_matrices`), solved as a 2 n (2H+1) linear
eigenproblem. Each Floquet exponent appears 2H+1 times, shifted by i k omega; the 2n
representatives kept are those whose eigenvectors are most centred on the low harmonics
(the weighted mean harmonic number of |p|^2 is smallest; Guillot et al. 2020's
symmetry criterion, which is more robust than picking the smallest |Im lam| when many
harmonics are kept). Multipliers mu = exp(lam T).

Floquet multipliers from :mod:`reduced.shooting` are the reference: Hill's method on a
truncated series with AFT Jacobians of a non-smooth force is an approximation, most of
all near grazing. :func:`compare` flags orbits where the two disagree on stability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eig

from reduced.hb import HarmonicBalance

HILL_TOL = 1e-3  # max |mu| - 1 above this is unstable for Hill (truncation and AFT errors
# of the exponents, ~1e-4 T^-1 on the converged branches, set this floor)


@dataclass(frozen=True, eq=False)
class HillResult:
    exponents: np.ndarray  # (2n,) complex, 1/s
    multipliers: np.ndarray  # (2n,) complex, sorted by decreasing modulus
    tol: float

    @property
    def max_multiplier(self) -> float:
        return float(np.abs(self.multipliers[0]))

    @property
    def stable(self) -> bool:
        return self.max_multiplier <= 1.0 + self.tol


def hill(hb: HarmonicBalance, X: np.ndarray, omega: float, tol: float = HILL_TOL) -> HillResult:
    """Floquet exponents and multipliers of the HB solution (X, omega) by Hill's method."""
    J0, J1, J2 = hb.hill_matrices(X, omega)
    nX = hb.size
    n = hb.n
    Z = np.zeros((nX, nX))
    I = np.eye(nX)
    A = np.block([[Z, I], [-J0, -J1]])
    B = np.block([[I, Z], [Z, J2]])
    lam, V = eig(A, B)
    ok = np.isfinite(lam)
    lam, V = lam[ok], V[:, ok]
    P = np.abs(V[:nX]) ** 2
    kh = np.repeat(hb.harmonic_numbers(), n).astype(float)
    centre = (kh @ P) / np.maximum(P.sum(axis=0), 1e-300)
    keep = np.argsort(centre, kind="stable")[: 2 * n]
    lam = lam[keep]
    T = 2.0 * np.pi / omega
    mu = np.exp(lam * T)
    order = np.argsort(-np.abs(mu), kind="stable")
    return HillResult(lam[order], mu[order], tol)


@dataclass(frozen=True, eq=False)
class StabilityComparison:
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
    """Side-by-side stability verdicts; ``agree`` is False where they differ."""
    fm = np.asarray(floquet_max, float)
    fs = np.asarray(floquet_stable, bool)
    hs = np.asarray(hill_stable, bool)
    agree = np.where(np.isfinite(fm), fs == hs, True)
    return StabilityComparison(np.asarray(energy_J, float), fm, np.asarray(hill_max, float), fs, hs, agree)


__all__ = ["HillResult", "hill", "compare", "StabilityComparison", "HILL_TOL"]
