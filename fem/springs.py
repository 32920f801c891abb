"""Suspension springs as beam elements, rigid maps and distributing (RBE3) couplings.

A helical spring of mean coil diameter D and installed length l with axial stiffness k_s
is replaced by an equivalent Timoshenko column (Haringx; Wahl, *Mechanical Springs*):

    EA = k_s l,      GA_s = (E_w/G_w) k_s l = 2 (1 + nu_w) k_s l,
    EI = (1 + nu_w) D^2 k_s l / (2 (2 + nu_w)),      GJ = (1 + nu_w) D^2 k_s l / 4,

obtained from the coil's wire energy with n = G_w d^4 / (8 D^3 k_s) active coils, so that
k_s stays exactly the paper's value whatever D is (the wire diameter drops out).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class CoilSpring:
    """Equivalent-column rigidities of a helical compression spring.

    Parameters
    ----------
    k_axial : float
        N/m, axial stiffness k_s.
    coil_diameter : float
        m, mean coil diameter D.
    length : float
        m, installed length l.
    nu_wire : float
        Poisson's ratio of the wire.
    """

    k_axial: float  # N/m, axial stiffness k_s
    coil_diameter: float  # m, mean coil diameter D
    length: float  # m, installed length l
    nu_wire: float = 0.3  # Poisson's ratio of the wire

    @property
    def EA(self) -> float:
        """N, axial rigidity k_s l."""
        return self.k_axial * self.length

    @property
    def GA(self) -> float:
        """N, shear rigidity 2 (1 + nu) k_s l."""
        return 2 * (1 + self.nu_wire) * self.k_axial * self.length

    @property
    def EI(self) -> float:
        """N m^2, bending rigidity (1 + nu) D^2 k_s l / (2 (2 + nu))."""
        nu = self.nu_wire
        return (1 + nu) * self.coil_diameter**2 * self.k_axial * self.length / (2 * (2 + nu))

    @property
    def GJ(self) -> float:
        """N m^2, torsional rigidity (1 + nu) D^2 k_s l / 4."""
        return (1 + self.nu_wire) * self.coil_diameter**2 * self.k_axial * self.length / 4

    @property
    def k_lateral(self) -> float:
        """N/m, lateral stiffness with both ends clamped: 1 / (l^3 / (12 EI) + l / GA)."""
        l = self.length
        return 1.0 / (l**3 / (12 * self.EI) + l / self.GA)


def timoshenko_beam_stiffness(EA: float, GA: float, EI: float, GJ: float, length: float) -> np.ndarray:
    """12x12 stiffness of a straight 2-node Timoshenko beam along its local x axis.

    DOF order per node: u_x, u_y, u_z, theta_x, theta_y, theta_z. Bending in both planes
    uses Phi = 12 EI / (GA l^2) (Przemieniecki, *Theory of Matrix Structural Analysis*).

    Parameters
    ----------
    EA : float
        N, axial rigidity.
    GA : float
        N, shear rigidity (shear coefficient included).
    EI : float
        N m^2, bending rigidity, the same in both planes.
    GJ : float
        N m^2, torsional rigidity.
    length : float
        m, l.

    Returns
    -------
    (12, 12) ndarray of float
        Local stiffness on (u, theta at node 1; u, theta at node 2): N/m, N/rad, N m/rad.
    """
    l = length
    K = np.zeros((12, 12))
    K[np.ix_([0, 6], [0, 6])] = EA / l * np.array([[1, -1], [-1, 1]])
    K[np.ix_([3, 9], [3, 9])] = GJ / l * np.array([[1, -1], [-1, 1]])
    phi = 12 * EI / (GA * l * l)
    c = EI / (l**3 * (1 + phi))
    kb = c * np.array([
        [12, 6 * l, -12, 6 * l],
        [6 * l, (4 + phi) * l * l, -6 * l, (2 - phi) * l * l],
        [-12, -6 * l, 12, -6 * l],
        [6 * l, (2 - phi) * l * l, -6 * l, (4 + phi) * l * l],
    ])
    K[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = kb  # v with theta_z
    s = np.diag([1.0, -1.0, 1.0, -1.0])  # w with theta_y: the rotation sign flips
    K[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = s @ kb @ s
    return K


def rotate_to(axis: np.ndarray) -> np.ndarray:
    """3x3 matrix R with rows the local axes (local x along ``axis``): u_local = R u_global.

    Parameters
    ----------
    axis : (3,) array_like of float
        Local x direction (any length but zero).

    Returns
    -------
    (3, 3) ndarray of float
        R, orthonormal rows ex, ey, ez (ey normal to ex and global z, or global x when ex is
        within 26 degrees of z).
    """
    ex = np.asarray(axis, float) / np.linalg.norm(axis)
    ref = np.array([0.0, 0.0, 1.0]) if abs(ex[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    ey = np.cross(ref, ex)
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    return np.vstack([ex, ey, ez])


def spring_element(spring: CoilSpring, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """12x12 global stiffness of ``spring`` from point a to point b (u_a, th_a, u_b, th_b).

    Parameters
    ----------
    spring : CoilSpring
        The spring's rigidities.
    a, b : (3,) ndarray of float
        m, its ends.

    Returns
    -------
    (12, 12) ndarray of float
        Global stiffness on (u_a, th_a, u_b, th_b): N/m, N/rad, N m/rad.
    """
    R = rotate_to(np.asarray(b, float) - np.asarray(a, float))
    T = np.kron(np.eye(4), R)
    Kl = timoshenko_beam_stiffness(spring.EA, spring.GA, spring.EI, spring.GJ, float(np.linalg.norm(b - a)))
    return T.T @ Kl @ T


def rigid_map(r: np.ndarray) -> np.ndarray:
    """(3, 6) map from rigid motion (u, theta) about the origin to the displacement at r: u + theta x r.

    Parameters
    ----------
    r : (3,) array_like of float
        m, the point relative to the origin of the rigid motion.

    Returns
    -------
    (3, 6) ndarray of float
        The map (u, theta) -> u + theta x r.
    """
    x, y, z = r
    return np.array([[1, 0, 0, 0, z, -y], [0, 1, 0, -z, 0, x], [0, 0, 1, y, -x, 0]], float)


def rigid_modes(X: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(3n, 6) rigid-body modes of points X (n, 3) about ``centre``, DOFs interleaved xyz per point.

    Parameters
    ----------
    X : (n, 3) array_like of float
        m, the points.
    centre : (3,) ndarray of float
        m, the origin of the rotations.

    Returns
    -------
    (3 n, 6) ndarray of float
        Columns: unit translations x, y, z, then unit rotations about x, y, z.
    """
    return np.vstack([rigid_map(r) for r in np.asarray(X) - centre])


def rbe3_map(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distributing coupling of a patch: master (u, theta) at the centroid from patch motion.

    u_m = mean(u_i),  theta_m = S^-1 sum_i r_i x u_i,  S = sum_i (|r_i|^2 I - r_i r_i^T),
    r_i = X_i - centroid: the least-squares rigid fit of the patch motion, exact for rigid
    motion and adding no stiffness between patch nodes. Returns (T (6, 3n), centroid).

    Parameters
    ----------
    X : (n, 3) array_like of float
        m, the patch nodes (not all on one line, or S is singular).

    Returns
    -------
    T : (6, 3 n) ndarray of float
        Master (u, theta) = T u_patch, u_patch interleaved x, y, z per node.
    centroid : (3,) ndarray of float
        m, the master's position.
    """
    X = np.asarray(X, float)
    c = X.mean(axis=0)
    r = X - c
    n = len(X)
    S = sum(np.dot(ri, ri) * np.eye(3) - np.outer(ri, ri) for ri in r)
    T = np.zeros((6, 3 * n))
    Sinv = np.linalg.inv(S)
    for i, ri in enumerate(r):
        T[:3, 3 * i:3 * i + 3] = np.eye(3) / n
        cross = np.array([[0, -ri[2], ri[1]], [ri[2], 0, -ri[0]], [-ri[1], ri[0], 0]])  # r x u
        T[3:, 3 * i:3 * i + 3] = Sinv @ cross
    return T, c
