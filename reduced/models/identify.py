"""The paper's three-mass parameters read off a Craig-Bampton model on the two tips.

The discrete model (:mod:`reduced.models.discrete`) written in Craig-Bampton form with boundary
x1, x3 and its one interior coordinate is exact. Holding x1, x3 and relaxing x2 (row 2 of K:
-2a x1 + 4a x2 - 2a x3 = 0) gives the constraint modes x2 = (x1 + x3) / 2; holding the tips
leaves one mode, x2 = eta / sqrt(m2) with omega_1^2 = 4a / m2. So, with a = kappa / L^2,

    M_bb = diag(m1, m3) + (m2 / 4) [[1, 1], [1, 1]],    M_bq = (sqrt(m2) / 2) [1, 1]^T,
    K_bb = 2 k_s I,                                      K_qq = omega_1^2 = 4 a / m2,

(M_bq up to the sign of the mode; M_qq = 1). A reduced 3-D model on the same coordinates
q = [x1, x3, eta_1] (:mod:`reduced.models.rom`, one fixed-interface mode) is read the same way:

    k_s = trace(K_bb) / 4,             m2 = (|M_bq[0]| + |M_bq[1]|)^2 / M_qq,
    m1 = M_bb[0, 0] - m2 / 4,           m3 = M_bb[1, 1] - m2 / 4,
    a = m2 omega_1^2 / 4,               kappa = a L^2,       omega_1^2 = K_qq / M_qq,

with L the half-distance between the tips' contact centres and k_g, g, c taken as given.
What the three-mass form cannot carry is returned as relative residuals (all zero for a
model that is itself a three-mass model): the boundary mass coupling beyond m2 / 4, a
stiffness coupling of the tips K_bb[0, 1] (a continuum's springs and the beam's rotation
couple them), unequal tip stiffnesses, unequal modal couplings, and K_bq, M_qq - 1 (zero in
any Craig-Bampton model).

Reference: Craig and Bampton, AIAA J. 6 (1968); the discrete model: Table 1 and Eq. 9 of
the paper (Goldberg et al., Section 3).
"""

from __future__ import annotations

import math

import numpy as np

from reduced.models.discrete import DiscreteParams


def identify_discrete(M: np.ndarray, K: np.ndarray, L: float, *, k_g: float, gap: float, c: float
                      ) -> tuple[DiscreteParams, dict[str, float]]:
    """Three-mass parameters and residuals from a Craig-Bampton model on q = [x1, x3, eta_1, ...].

    Parameters
    ----------
    M, K : (n, n), n >= 3, reduced mass [kg] and stiffness [N/m] with the two tip coordinates
        first and the fixed-interface modes after them (only the first mode is used: keeping
        one mode of a Craig-Bampton model is the sub-block on [x1, x3, eta_1])
    L : m, half-length between the tips (the discrete model's L)
    k_g, gap, c : N/m, m, N s/m, copied into the result

    Returns
    -------
    (params, residuals): :class:`DiscreteParams` and a dict of dimensionless residuals
    ``M_bb01`` (M_bb[0, 1] - m2/4) / (m2/4), ``K_bb01`` K_bb[0, 1] / (trace(K_bb)/2),
    ``K_bb_diag`` (K_bb[0, 0] - K_bb[1, 1]) / trace(K_bb), ``M_bq`` (|M_bq[0]| - |M_bq[1]|) /
    (|M_bq[0]| + |M_bq[1]|), ``K_bq`` max|K_bq| / sqrt(K_qq trace(K_bb) / 2), ``M_qq`` M_qq - 1.
    """
    M = np.asarray(M, dtype=float)
    K = np.asarray(K, dtype=float)
    if M.ndim != 2 or M.shape[0] < 3 or M.shape != K.shape or M.shape[0] != M.shape[1]:
        raise ValueError(f"M and K must be square, the same shape and at least 3 x 3, got {M.shape}, {K.shape}")
    if not (L > 0 and math.isfinite(L)):
        raise ValueError(f"L must be > 0, got {L!r}")
    Mbb, Kbb = M[:2, :2], K[:2, :2]
    Mbq, Kbq = M[:2, 2], K[:2, 2]
    Mqq, Kqq = M[2, 2], K[2, 2]
    if not (Mqq > 0 and Kqq > 0):
        raise ValueError(f"the fixed-interface block must be positive, got M_qq = {Mqq}, K_qq = {Kqq}")
    if Mbq[0] * Mbq[1] <= 0:
        raise ValueError(f"the first fixed-interface mode must move both tips' coupling the same way "
                         f"(a symmetric first bending mode), got M_bq = {Mbq.tolist()}")
    omega2 = Kqq / Mqq  # the mode's omega^2 whatever its normalization
    m2 = (abs(Mbq[0]) + abs(Mbq[1])) ** 2 / Mqq
    a = m2 * omega2 / 4.0
    params = DiscreteParams(
        k_s=float(np.trace(Kbb) / 4.0), kappa=float(a * L**2), k_g=float(k_g), L=float(L), gap=float(gap),
        m1=float(Mbb[0, 0] - m2 / 4.0), m2=float(m2), m3=float(Mbb[1, 1] - m2 / 4.0), c=float(c))
    residuals = {
        "M_bb01": float((Mbb[0, 1] - m2 / 4.0) / (m2 / 4.0)),
        "K_bb01": float(Kbb[0, 1] / (np.trace(Kbb) / 2.0)),
        "K_bb_diag": float((Kbb[0, 0] - Kbb[1, 1]) / np.trace(Kbb)),
        "M_bq": float((abs(Mbq[0]) - abs(Mbq[1])) / (abs(Mbq[0]) + abs(Mbq[1]))),
        "K_bq": float(np.max(np.abs(Kbq)) / math.sqrt(Kqq * np.trace(Kbb) / 2.0)),
        "M_qq": float(Mqq - 1.0),
    }
    return params, residuals


RESIDUAL_MEANING = {
    "M_bb01": "boundary mass coupling beyond m2/4, relative to m2/4",
    "K_bb01": "stiffness coupling of the two tips K_bb[0,1], relative to 2 k_s",
    "K_bb_diag": "unequal tip stiffnesses (K_bb[0,0] - K_bb[1,1]) / trace",
    "M_bq": "unequal modal coupling of the tips (|M_bq[0]| - |M_bq[1]|) / sum",
    "K_bq": "K_bq / sqrt(omega_1^2 2 k_s) (zero in Craig-Bampton form)",
    "M_qq": "M_qq - 1 (zero for a mass-normalized mode)",
}

__all__ = ["identify_discrete", "RESIDUAL_MEANING"]
