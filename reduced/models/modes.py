"""Linear modes of a gap system's open and closed states, and the modes that move given rows.

Undamped modes K phi = omega^2 M phi with phi^T M phi = 1, in the open state (every stop
open, K) or the closed one (one stop of every tip closed, K + B^T k_g B over those stops).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import eigh

from reduced.models.gaps import GapSystem


@dataclass(frozen=True, eq=False)
class LinearModes:
    """Undamped modes of one linear state: K phi = omega^2 M phi, phi^T M phi = 1.

    Attributes
    ----------
    state : {'open', 'closed'}
        The linear state.
    omega : (n,) ndarray of float
        rad/s, ascending (negative eigenvalues give 0).
    phi : (n, n) ndarray of float
        Mode shapes in columns, mass-normalised.
    freq_hz : (n,) ndarray of float
        Hz, omega / (2 pi) (derived, not a constructor argument).
    """

    state: str
    omega: np.ndarray  # rad/s, (n,)
    phi: np.ndarray  # (n, n), columns mass-normalized
    freq_hz: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "freq_hz", self.omega / (2.0 * np.pi))


def linear_modes(system: GapSystem, state: str = "open") -> LinearModes:
    """Open-gap (all stops open) or closed-gap (one stop of every tip closed) modes.

    Parameters
    ----------
    system : GapSystem
        The system.
    state : {'open', 'closed'}
        K, or K with one stop of every tip closed (:meth:`GapSystem.closed_stiffness`).

    Returns
    -------
    LinearModes

    Raises
    ------
    ValueError
        Another ``state``.
    """
    if state == "open":
        K = system.K
    elif state == "closed":
        K = system.closed_stiffness()
    else:
        raise ValueError(f"state must be 'open' or 'closed', got {state!r}")
    lam, phi = eigh(K, system.M)
    return LinearModes(state, np.sqrt(np.clip(lam, 0.0, None)), phi)


def moving_modes(K: np.ndarray, M: np.ndarray, rows: np.ndarray, n: int, tol: float = 1e-2,
                 search: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(omega, phi, index): the lowest ``n`` modes of (K, M), mass-normalized, that move ``rows``.

    A mode moves the rows if |rows phi| exceeds ``tol`` of the largest over the ``search``
    lowest modes (default: all). For a gap system these are the modes the discrete model has
    (heave, pitch, bending), not an assembly's swinging on its bungees.

    Parameters
    ----------
    K, M : (N, N) ndarray of float
        N/m and kg.
    rows : (r, N) array_like of float
        The rows to be moved.
    n : int
        Modes wanted.
    tol : float
        Threshold of |rows phi|, relative to the largest of the modes searched.
    search : int, optional
        Lowest modes computed and searched (default: all N).

    Returns
    -------
    omega : (k,) ndarray of float
        rad/s.
    phi : (N, k) ndarray of float
        The modes, mass-normalised.
    index : (k,) ndarray of int
        Their indices among the modes searched; k <= n (fewer when fewer modes move the rows).
    """
    size = K.shape[0] if search is None else min(search, K.shape[0])
    lam, phi = eigh(K, M, subset_by_index=[0, size - 1])
    moves = np.linalg.norm(np.atleast_2d(rows) @ phi, axis=0)
    idx = np.flatnonzero(moves > tol * moves.max())[:n]
    return np.sqrt(np.clip(lam[idx], 0.0, None)), phi[:, idx], idx


def gap_moving_modes(system: GapSystem, state: str = "open", n: int = 3, tol: float = 1e-2) -> np.ndarray:
    """Indices of the lowest ``n`` modes of ``state`` that move the gaps (:func:`moving_modes` on B).

    Parameters
    ----------
    system : GapSystem
        The system.
    state : {'open', 'closed'}
        The linear state.
    n : int
        Modes wanted.
    tol : float
        As :func:`moving_modes`.

    Returns
    -------
    (k,) ndarray of int
        Indices (into all the state's modes), k <= n.

    Raises
    ------
    ValueError
        Another ``state``.
    """
    if state not in ("open", "closed"):
        raise ValueError(f"state must be 'open' or 'closed', got {state!r}")
    K = system.K if state == "open" else system.closed_stiffness()
    return moving_modes(K, system.M, system.B, n, tol)[2]
