"""Initial states given at the discrete model's points rather than on a model's coordinates.

A scene gives the displacement and velocity of the three points x1, x2, x3 (the discrete
model's masses). On a model whose points are rows P of its coordinates (P = I for the
discrete model) they are realized in its lowest r = rows(P) open-gap modes that move the
points (|P phi| above ``MOVES`` of the largest; modes of a whole assembly swinging on its
bungees move the tube and beam together and leave relative points at rest), Phi_r:

    x0 = Phi_r a,  P Phi_r a = d0,        v0 = Phi_r b,  P Phi_r b = w0,

so the discrete model (r = n) gets d0 and w0 exactly, and a reduced 3-D model the motion of
the same three modes (heave, pitch, first bending) with the same point values. Point loads
or least-energy fields are not used on purpose: on a continuum they excite the local modes
near the point, and their energy grows without bound as modes are added (an impulse of
125.8 N s at x3 carries 1.0e4 J with 1 fixed-interface mode and 6.8e5 J with 50).
"""

from __future__ import annotations

import numpy as np

from reduced.models.modes import moving_modes

MOVES = 1e-2  # a mode moves the points if |P phi| exceeds this fraction of the largest


def initial_state(M: np.ndarray, K: np.ndarray, P: np.ndarray, x0_points, v0_points
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(x0, v0) on the model's coordinates from the displacement and velocity of its points.

    Parameters
    ----------
    M, K : (n, n) ndarray of float
        kg and N/m, the model's open-gap mass and stiffness.
    P : (r, n) array_like of float
        The points as rows of the coordinates (the identity for the discrete model).
    x0_points : (r,) array_like of float
        m, displacement of each point.
    v0_points : (r,) array_like of float
        m/s, velocity of each point.

    Returns
    -------
    x0 : (n,) ndarray of float
        m, initial displacement on the coordinates.
    v0 : (n,) ndarray of float
        m/s, initial velocity on the coordinates.

    Raises
    ------
    ValueError
        Fewer coordinates than points, fewer than r of the lowest r + 20 modes move the points,
        or P Phi_r too ill-conditioned (cond > 1e10) to set the points independently.
    """
    P = np.atleast_2d(np.asarray(P, float))
    d0, w0 = np.array(x0_points, float), np.array(v0_points, float)
    r, n = P.shape
    if r == n and np.array_equal(P, np.eye(n)):  # the points are the coordinates
        return d0, w0
    if n < r:
        raise ValueError(f"the model has {n} coordinates, fewer than its {r} points: keep at least "
                         f"{r - n} fixed-interface mode(s)")
    _, phi, _ = moving_modes(K, M, P, r, MOVES, search=r + 20)
    A = P @ phi
    if A.shape[1] < r:
        raise ValueError(f"fewer than {r} of the model's lowest modes move its points")
    if np.linalg.cond(A) > 1e10:
        raise ValueError("the lowest modes cannot set the point values independently (P Phi is singular)")
    return phi @ np.linalg.solve(A, d0), phi @ np.linalg.solve(A, w0)
