"""Independent references for the impact beam's modes, for tests (not a test module).

- :func:`timoshenko_beam_hz`: the beam as a 1-D Timoshenko beam (section and material of
  :class:`fem.model.AssemblyModel`, Cowper's shear factor) on point springs at the tip axes
  x = +-L, by 2-node elements (linear w and theta, one-point shear: locking-free; 600 elements
  converge the first six frequencies to 1e-5). It shares nothing with the 3-D model but the
  model's parameters: no mesh, no seats, no RBE3 patches.
- :func:`rigid_body_hz`: the six pseudo-rigid modes of a 3-D system as the 6x6 Rayleigh-Ritz
  problem (Phi_rb^T K Phi_rb) q = omega^2 (Phi_rb^T M Phi_rb) q on its rigid-body modes about
  the centre (Rayleigh-Ritz on the rigid-body modes), each labelled by its dominant rigid motion.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import eigsh

from fem.beam_theory import cowper_shear_coefficient

RIGID = ("x", "y", "heave", "roll", "pitch", "yaw")  # ux, uy, uz, theta_x, theta_y, theta_z


def timoshenko_beam_hz(model, k_tip: float = 0.0, *, fixed: bool = False, plane: str = "xz", n_el: int = 600,
                       n_modes: int = 6, dense: bool = False) -> np.ndarray:
    """Hz, the lowest bending frequencies of the beam in ``plane`` ("xz": bounce, bending about y with
    height h; "xy": lateral, about z with width b), with 2 k_s (the top and bottom suspension springs, axial
    along z; none in "xy") plus ``k_tip`` N/m at x = +-L, or with w = 0 there (``fixed``): the lowest
    ``n_modes`` roots of det(K - omega^2 M) = 0, by sparse shift-invert Lanczos, or by the dense
    generalized eigh (``dense``: the cross-check in tests/test_verify.py)."""
    b, h = model.beam_section
    if plane == "xy":
        b, h = h, b
    length, L = model.beam_length, model.L
    E, nu, rho = model.E, model.nu, model.rho
    A, I = b * h, b * h**3 / 12
    kGA = cowper_shear_coefficient(nu) * E / (2 * (1 + nu)) * A
    x = [-length / 2]
    for a, c in ((-length / 2, -L), (-L, L), (L, length / 2)):  # nodes at x = +-L exactly
        n = max(2, round(n_el * (c - a) / length))
        x += list(np.linspace(a, c, n + 1)[1:])
    x = np.array(x)
    N = x.size
    K, M = np.zeros((2 * N, 2 * N)), np.zeros((2 * N, 2 * N))  # DOFs (w, theta) per node
    for e in range(N - 1):
        le = x[e + 1] - x[e]
        d = np.arange(2 * e, 2 * e + 4)
        g = np.array([-1 / le, -0.5, 1 / le, -0.5])  # shear strain w' - theta at the midpoint
        Ke = kGA * le * np.outer(g, g)
        Ke[np.ix_([1, 3], [1, 3])] += E * I / le * np.array([[1.0, -1.0], [-1.0, 1.0]])
        Me = np.zeros((4, 4))
        Me[np.ix_([0, 2], [0, 2])] = rho * A * le / 6 * np.array([[2.0, 1.0], [1.0, 2.0]])
        Me[np.ix_([1, 3], [1, 3])] = rho * I * le / 6 * np.array([[2.0, 1.0], [1.0, 2.0]])
        K[np.ix_(d, d)] += Ke
        M[np.ix_(d, d)] += Me
    tips = [int(np.argmin(np.abs(x + L))), int(np.argmin(np.abs(x - L)))]
    for t in tips:
        K[2 * t, 2 * t] += (2 * model.k_s if plane == "xz" else 0.0) + k_tip
    keep = np.ones(2 * N, bool)
    if fixed:
        keep[[2 * t for t in tips]] = False
    K, M = K[np.ix_(keep, keep)], M[np.ix_(keep, keep)]
    if dense:
        lam = eigh(K, M, eigvals_only=True, subset_by_index=[0, n_modes - 1])
    else:
        # K and M are banded (two DOFs a node, neighbours only): shift-invert Lanczos about sigma < 0, where
        # K - sigma M is positive definite even for a free beam (K singular), finds the n_modes lowest
        # eigenvalues of the same matrices to round-off, in milliseconds; the dense eigh costs ~2 s CPU a call
        # at 600 elements (its O(N^3) tridiagonal reduction), a few dozen seconds of the suite (issue 28)
        lam = np.sort(eigsh(csc_matrix(K), k=n_modes, M=csc_matrix(M), sigma=-1.0, which="LM",
                            return_eigenvectors=False, tol=0.0))
    return np.sqrt(np.abs(lam)) / (2 * np.pi)


def rigid_body_hz(system, centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, tuple[str, ...]]:
    """(Hz ascending, labels): the 6x6 Rayleigh-Ritz problem on the system's rigid-body modes."""
    P = system.rigid_modes(np.arange(system.n_dofs), centre)
    Mr = P.T @ (system.M @ P)
    lam, q = eigh(P.T @ (system.K @ P), Mr)
    # label by the dominant rigid motion, weighed by its kinetic energy share
    share = q * (Mr @ q)
    labels = tuple(RIGID[int(np.argmax(np.abs(share[:, i])))] for i in range(6))
    return np.sqrt(np.abs(lam)) / (2 * np.pi), labels
