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
    """Undamped modes of one linear state: K phi = omega^2 M phi, phi^T M phi = 1."""

    state: str
    omega: np.ndarray  # rad/s, (n,)
    phi: np.ndarray  # (n, n), columns mass-normalized
    freq_hz: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "freq_hz", self.omega / (2.0 * np.pi))


def linear_modes(system: GapSystem, state: str = "open") -> LinearModes:
    """Open-gap (all stops open) or closed-gap (one stop of every tip closed) modes."""
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
    """
    size = K.shape[0] if search is None else min(search, K.shape[0])
    lam, phi = eigh(K, M, subset_by_index=[0, size - 1])
    moves = np.linalg.norm(np.atleast_2d(rows) @ phi, axis=0)
    idx = np.flatnonzero(moves > tol * moves.max())[:n]
    return np.sqrt(np.clip(lam[idx], 0.0, None)), phi[:, idx], idx


def gap_moving_modes(system: GapSystem, state: str = "open", n: int = 3, tol: float = 1e-2) -> np.ndarray:
    """Indices of the lowest ``n`` modes of ``state`` that move the gaps (:func:`moving_modes` on B)."""
    if state not in ("open", "closed"):
        raise ValueError(f"state must be 'open' or 'closed', got {state!r}")
    K = system.K if state == "open" else system.closed_stiffness()
    return moving_modes(K, system.M, system.B, n, tol)[2]
