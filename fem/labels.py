"""Automatic labelling of the impact beam's six pseudo-rigid modes.

Each mode's beam motion u_b is projected on the beam's rigid-body modes Phi_rb about its
centre of mass, q_b = (Phi_rb^T M_b Phi_rb)^-1 Phi_rb^T M_b u_b, and likewise the tube's
motion on the same six motions about the same point, q_t. The relative rigid motion
q = q_b - q_t separates the beam's modes on its springs from the whole assembly swinging
on its bungees (q ~ 0). The kinetic-energy share of component j,

    e_j = q_j^2 (Phi_rb^T M_b Phi_rb)_jj / sum_k q_k^2 (Phi_rb^T M_b Phi_rb)_kk,

times the fraction of the beam's motion that is rigid, scores each mode against
x (longitudinal), y (lateral), z (bounce), theta_x (roll), theta_y (pitch), theta_z (yaw);
a linear assignment picks one mode per label maximising the total score.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment

COMPONENT_LABELS = ("longitudinal", "lateral", "bounce", "roll", "pitch", "yaw")  # x y z rx ry rz
TABLE2_ORDER = ("longitudinal", "lateral", "yaw", "bounce", "pitch", "roll")
TABLE2_TEST_HZ = (10.92, 11.66, 15.08, 19.94, 24.11, 33.69)  # Hz, paper Table 2 (experiment)
TABLE2_PAPER_FE_HZ = (10.68, 11.24, 13.73, 18.50, 22.65, 34.72)  # Hz, paper Table 2 (its FE model)


@dataclass(frozen=True, eq=False)
class ModeLabels:
    """Which computed mode is which pseudo-rigid mode, and how clearly.

    Attributes
    ----------
    mode_index : dict of str to int
        Label (``COMPONENT_LABELS``: longitudinal, lateral, bounce, roll, pitch, yaw) -> index of its
        mode in the modal result.
    score : (n_modes, 6) ndarray of float
        Score of each mode against each component, in ``COMPONENT_LABELS`` order, in [0, 1].
    rigid_fraction : (n_modes,) ndarray of float
        Share of the beam's kinetic energy that is rigid motion, in [0, 1].
    relative_q : (n_modes, 6) ndarray of float
        Relative rigid motion q_b - q_t (q_b alone without a tube): translations x, y, z, then
        rotations about x, y, z, on the scale of ``phi``.
    """

    mode_index: dict[str, int]  # label -> index into the modal result
    score: np.ndarray  # (n_modes, 6) score of each mode against each component
    rigid_fraction: np.ndarray  # (n_modes,) share of the beam's kinetic energy that is rigid motion
    relative_q: np.ndarray  # (n_modes, 6) relative rigid motion q_b - q_t

    def purity(self, label: str) -> float:
        """Score of the chosen mode for its label (1 = a pure rigid motion of that kind)."""
        return float(self.score[self.mode_index[label], COMPONENT_LABELS.index(label)])


def rigid_projection(phi: np.ndarray, M: sp.spmatrix, Phi_rb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q = (Phi_rb^T M Phi_rb)^-1 Phi_rb^T M phi for every column of phi; returns (q (6, m), Mrb).

    Parameters
    ----------
    phi : (n, m) ndarray of float
        Displacement fields (e.g. mode shapes restricted to a part's DOFs).
    M : (n, n) sparse matrix
        kg, the mass matrix on the same DOFs.
    Phi_rb : (n, 6) ndarray of float
        Rigid-body modes (translations x, y, z, then rotations about x, y, z).

    Returns
    -------
    q : (6, m) ndarray of float
        Mass-weighted least-squares rigid motion of each column.
    Mrb : (6, 6) ndarray of float
        Phi_rb^T M Phi_rb, the rigid-body mass matrix.
    """
    MP = M @ Phi_rb
    Mrb = Phi_rb.T @ MP
    q = np.linalg.solve(Mrb, MP.T @ phi)
    return q, Mrb


def label_modes(phi: np.ndarray, M: sp.spmatrix, beam_dofs: np.ndarray, Phi_beam: np.ndarray,
                tube_dofs: np.ndarray | None = None, Phi_tube: np.ndarray | None = None,
                candidates: np.ndarray | None = None) -> ModeLabels:
    """Label the six pseudo-rigid modes of the beam among the columns of ``phi``.

    ``Phi_beam`` (and ``Phi_tube``) are the rigid-body modes of the beam (tube) DOFs about
    the beam's centre of mass; ``candidates`` restricts the modes considered.

    Parameters
    ----------
    phi : (n_dofs, n_modes) ndarray of float
        Mode shapes.
    M : (n_dofs, n_dofs) sparse matrix
        kg, mass matrix.
    beam_dofs : (n_b,) ndarray of int
        The beam's DOFs.
    Phi_beam : (n_b, 6) ndarray of float
        Rigid-body modes on ``beam_dofs``.
    tube_dofs : (n_t,) ndarray of int, optional
        The tube's DOFs: with ``Phi_tube``, the motion is scored relative to the tube.
    Phi_tube : (n_t, 6) ndarray of float, optional
        Rigid-body modes on ``tube_dofs`` about the same point.
    candidates : ndarray of int, optional
        Indices of the modes that may be labelled (default: all).

    Returns
    -------
    ModeLabels
        One mode per label, chosen by a linear assignment maximising the total score.

    Raises
    ------
    ValueError
        Fewer than six candidate modes.
    """
    Mb = M[beam_dofs][:, beam_dofs]
    ub = phi[beam_dofs]
    qb, Mrb = rigid_projection(ub, Mb, Phi_beam)
    q = qb.copy()
    if tube_dofs is not None and Phi_tube is not None:
        Mt = M[tube_dofs][:, tube_dofs]
        qt, _ = rigid_projection(phi[tube_dofs], Mt, Phi_tube)
        q = qb - qt
    diag = np.diag(Mrb)
    e = q**2 * diag[:, None]
    total_beam = np.einsum("ij,ij->j", ub, Mb @ ub)
    rigid = np.einsum("ij,ij->j", qb, Mrb @ qb)
    rigid_fraction = np.clip(rigid / np.maximum(total_beam, 1e-300), 0.0, 1.0)
    rel_fraction = np.clip(e.sum(axis=0) / np.maximum(np.einsum("ij,ij->j", qb, Mrb @ qb), 1e-300), 0, 1)
    score = (e / np.maximum(e.sum(axis=0), 1e-300)) * rigid_fraction * rel_fraction
    score = score.T  # (n_modes, 6)
    cand = np.arange(phi.shape[1]) if candidates is None else np.asarray(candidates)
    if len(cand) < 6:
        raise ValueError(f"need at least 6 candidate modes to label, got {len(cand)}")
    r, c = linear_sum_assignment(-score[cand])
    mode_index = {COMPONENT_LABELS[j]: int(cand[i]) for i, j in zip(r, c, strict=True)}
    return ModeLabels(mode_index=mode_index, score=score, rigid_fraction=rigid_fraction, relative_q=q.T)


# (symmetry about y = 0, symmetry about z = 0) of each family of free-beam modes, and the
# direction that holds most of its kinetic energy (None: torsion, shared by y and z)
FREE_BEAM_SYMMETRY = {(1, -1): ("bending z", 2), (-1, 1): ("bending y", 1), (-1, -1): ("torsion", None),
                      (1, 1): ("axial", 0)}
SYMMETRY_TOL = 1e-3  # a mode of a mirror-symmetric mesh has phi^T M (mirror phi) = +-1 to ~1e-9


@dataclass(frozen=True, eq=False)
class FreeBeamMode:
    """One elastic mode of the free beam: which family it belongs to and its order in that family.

    Attributes
    ----------
    index : int
        Index of the mode in the modal result.
    family : {'bending z', 'bending y', 'torsion', 'axial', 'other'}
        Its family by mirror symmetry about y = 0 and z = 0.
    order : int
        n = 1, 2, ... within its family by frequency; 0 for 'other'.
    """

    index: int  # into the modal result
    family: str  # bending z | bending y | torsion | axial | other
    order: int  # n = 1, 2, ... within its family, by frequency (0 for "other")


def free_beam_families(fe, phi: np.ndarray, elastic: np.ndarray) -> list[FreeBeamMode]:
    """Sort the elastic modes of the free beam into bending in z and y, torsion and axial modes.

    The bar has mirror planes y = 0 and z = 0 and each mode is symmetric (+1) or antisymmetric
    (-1) about each, s = phi^T M (mirror phi). A displacement field u(x) mirrored in y is
    (u_x, -u_y, u_z)(x, -y, z): bending in z (u_z even in y) is (+1, -1), bending in y (-1, +1),
    torsion (u_y = -z theta, u_z = y theta) (-1, -1), axial (u_x) (+1, +1). The symmetry class is
    exact; the direction holding most of the kinetic energy (> 1/2) confirms it, so that a
    higher-order section mode of the same class (far above the modes computed here) reads
    "other". Orders count the modes of one family by ascending frequency.

    Parameters
    ----------
    fe : FESystem
        The free beam's assembled model (mirror-symmetric about y = 0 and z = 0).
    phi : (n_dofs, n_modes) ndarray of float
        Mass-normalised mode shapes.
    elastic : (n_modes,) ndarray of bool
        Which modes to sort (the rigid-body ones are left out).

    Returns
    -------
    list of FreeBeamMode
        One per elastic mode, in mode order; 'other' for a mode whose symmetry is not +-1 to
        ``SYMMETRY_TOL`` (a degenerate pair mixed by the solver) or whose energy is not mostly
        in its family's direction.
    """
    from fem.contact import mirror_map

    sym = []
    for axis in (1, 2):
        perm, sign = mirror_map(fe, axis=axis)
        sym.append(np.einsum("ij,ij->j", phi, fe.M @ (sign[:, None] * phi[perm])))
    sym = np.array(sym).T  # (n_modes, 2)
    Mphi = fe.M @ phi
    comp = fe.solid.dof_component
    share = np.array([np.einsum("ij,ij->j", phi[comp == c], Mphi[comp == c]) for c in range(3)]).T
    out, count = [], {}
    for i in np.flatnonzero(elastic):
        if not np.all(np.abs(np.abs(sym[i]) - 1.0) < SYMMETRY_TOL):  # degenerate pair mixed by the solver
            out.append(FreeBeamMode(int(i), "other", 0))
            continue
        family, direction = FREE_BEAM_SYMMETRY[tuple(int(np.sign(s)) for s in sym[i])]
        if direction is not None and share[i, direction] < 0.5 * share[i].sum():
            out.append(FreeBeamMode(int(i), "other", 0))
            continue
        count[family] = count.get(family, 0) + 1
        out.append(FreeBeamMode(int(i), family, count[family]))
    return out
