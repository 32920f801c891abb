"""The mirror symmetry of a gap system: the signed permutation that swaps the two tips.

The rig is symmetric about the beam's mid-plane: the mirror swaps the tips x1 <-> x3 and maps every
other coordinate to plus or minus itself. On the three-mass model that is the reversal of the DOFs
(x1, x2, x3) -> (x3, x2, x1). On the Craig-Bampton model q = [x1, x3, eta_1..n] it swaps the two
boundary coordinates and changes the sign of the fixed-interface modes that are antisymmetric about
the mid-plane (eta_k -> s_k eta_k): a signed permutation R with

    R M R^T = M,   R K R^T = K,   R C R^T = C,   R b = b,                                    (1)

and the stops mapped onto each other. The reduced matrices of a mirror-symmetric mesh satisfy (1)
only to the round-off of the assembly and the eigensolution (3e-11 of the largest entry on the
beam's mesh), which is more than a symmetry test at round-off accepts; :func:`symmetrized` averages
the system over the mirror,

    A_s = (A + R A R^T) / 2,   b_s = (b + R b) / 2,                                          (2)

which moves it by that round-off and makes (1) hold to the last bits, so that the forced-response
continuation sees the mirror pitchforks (asymmetric families, x1 != x3) as pitchforks.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reduced.models.gaps import GapSystem

MIRROR_RTOL = 1e-8  # relative asymmetry (of each matrix's largest entry) accepted as the round-off of a symmetric mesh


def signed_mirror(system: GapSystem, b: np.ndarray, pair: tuple[int, int], rtol: float = MIRROR_RTOL
                  ) -> np.ndarray | None:
    """The signed permutation R swapping DOFs ``pair`` and mapping every other DOF k to s_k times itself,
    if it satisfies (1) to ``rtol`` (relative to each matrix's largest entry) and maps the stops onto each
    other; None if no such R does.

    The sign s_k comes from DOF k's coupling to the pair: M[i, k] = s_k M[j, k] and K[i, k] = s_k K[j, k]
    for the pair (i, j); a DOF the pair does not couple to keeps its sign (+1; a load on it needs +1).

    Parameters
    ----------
    system : the gap system
    b : (n,) load direction
    pair : the two DOFs the mirror swaps (the tips)
    rtol : accepted relative asymmetry

    Returns
    -------
    (n, n) ndarray or None
    """
    n = system.n
    i, j = pair
    if i == j or not (0 <= i < n and 0 <= j < n):
        raise ValueError(f"pair must be two different DOFs of 0..{n - 1}, got {pair!r}")
    s = np.ones(n)
    tops = [(A, np.max(np.abs(A))) for A in (system.M, system.K)]
    for k in range(n):
        if k in pair:
            continue
        col = [(A[i, k], A[j, k], top) for A, top in tops]
        minus = all(abs(a + c) <= rtol * top for a, c, top in col)
        plus = all(abs(a - c) <= rtol * top for a, c, top in col)
        s[k] = -1.0 if minus and not plus else 1.0
    perm = np.arange(n)
    perm[i], perm[j] = j, i
    R = np.zeros((n, n))
    R[np.arange(n), perm] = s
    return R if mirror_error(system, b, R) <= rtol else None


def mirror_error(system: GapSystem, b: np.ndarray, R: np.ndarray) -> float:
    """max over M, K, C, b of max|R A R^T - A| / max|A| (inf if R does not map the stops onto each other).

    Parameters
    ----------
    system : the gap system
    b : (n,) load direction
    R : (n, n) the signed permutation
    """
    err = 0.0
    for A in (system.M, system.K, system.C):
        top = np.max(np.abs(A), initial=0.0)
        if top > 0:
            err = max(err, float(np.max(np.abs(R @ A @ R.T - A)) / top))
    top = np.max(np.abs(b), initial=0.0)
    if top > 0:
        err = max(err, float(np.max(np.abs(R @ b - b)) / top))
    return err if _stops(system, system.B @ R.T) == _stops(system, system.B) else np.inf


def tip_mirror(system: GapSystem, b: np.ndarray, rtol: float = MIRROR_RTOL) -> tuple[np.ndarray | None, float]:
    """(R, error): :func:`signed_mirror` swapping the DOFs named x1 and x3 (None, inf when the system has no
    such pair or no such mirror), and its :func:`mirror_error`.

    Parameters
    ----------
    system : the gap system (its DOFs named x1 and x3 are the tips)
    b : (n,) load direction
    rtol : accepted relative asymmetry (:data:`MIRROR_RTOL`)
    """
    names = tuple(system.dof_names)
    if "x1" not in names or "x3" not in names:
        return None, np.inf
    R = signed_mirror(system, b, (names.index("x1"), names.index("x3")), rtol)
    return R, (np.inf if R is None else mirror_error(system, b, R))


def symmetrized(system: GapSystem, b: np.ndarray, R: np.ndarray) -> tuple[GapSystem, np.ndarray]:
    """The system and load averaged over the mirror R, equation (2) (the stops and friction unchanged:
    :func:`signed_mirror` has checked that R maps them onto each other).

    Parameters
    ----------
    system : the gap system
    b : (n,) load direction
    R : (n, n) its mirror (:func:`signed_mirror`)
    """
    def avg(A):
        return 0.5 * (A + R @ A @ R.T)

    out = replace(system, M=avg(system.M), K=avg(system.K), C=avg(system.C))
    return out, 0.5 * (b + R @ b)


def _stops(system: GapSystem, B: np.ndarray) -> set:
    return {(tuple(np.round(B[m], 12)), float(system.offset[m]), float(system.side[m]), float(system.k[m]))
            for m in range(system.m)}
