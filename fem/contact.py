"""Penalty gap contact at the impact tips: one scalar gap coordinate per tip.

Each end of the beam (x = -L: ``x1``, x = +L: ``x3``, the discrete model's names) meets a
pair of impact tips, one above and one below, at the spring seats' axis. The beam side of a
tip is the contact patch on its face, coupled by a distributing (RBE3) row that averages
the vertical displacement of the patch nodes: it transmits the contact force as a uniform
nodal load and adds no stiffness between patch nodes. The gap coordinate of a tip is

    s_i = r_i . u = mean uz(beam patches at tip i) - mean uz(tube seats at tip i),

(the tube term only in the ``assembly`` layout, where the tips are bolted to the tube; in
``beam-grounded`` the tips are fixed). The top and bottom patches are averaged together:
the beam's through-thickness squeeze under a tip load is ~1e-9 of its vertical motion, so
one scalar gap per tip results. The tip acts as a two-sided clearance on s_i with normal
+z (upper tip) and -z (lower tip):

    f_i(s) = k_g (s - g)  for s > g,   0 for |s| <= g,   k_g (s + g)  for s < -g,

applied to the structure as r_i f_i (u' = K u + sum_i r_i f_i(r_i . u) in the equation of
motion). The *tied* (closed-gap) linearization is K + k_g sum_i r_i r_i^T: one tip of each
pair closed, the stiffest linear state, whose modes sit beside the open-gap ones.

**Tangential coordinates** (friction, :func:`tangential_rows`): where a tip touches, the beam may
slide along (x, *axial*) and across (y, *lateral*) the tip's face. The upper tip touches the top
patch and the lower tip the bottom one, and the two faces slide differently (a pitch of the beam
end moves its top face along x by -h/2 theta_y and its bottom face by +h/2 theta_y), so each stop has
its own tangential coordinates, built as the gap's: the mean displacement along x (or y) of that
face's patch nodes, a distributing row that adds no stiffness, less that of the tip's seat on the tube
in the ``assembly`` layout (the tip assembly, short and stiff, moves with its seat, as for the gap):

    t = mean ux(beam patch, top) - mean ux(tube seat, top)       (stop x1+, axial),

and likewise for the bottom face (x1-), across (uy), and at x3. Tied *and sticking* (every tip's
upper stop closed, its sliders stuck), the linearization adds their tangential springs,
K + k_g sum_i r_i r_i^T + k_t sum_{upper} t t^T (:func:`tied_stiffness` with ``sliders``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

TIPS = (("x1", "left"), ("x3", "right"))  # gap coordinate name, beam end
STOP_FACES = (("+", "top"), ("-", "bottom"))  # the upper stop touches the beam's top face, the lower its bottom
TANGENTIAL = {"axial": 0, "lateral": 1}  # a tangential direction and its displacement component (x, y)


@dataclass(frozen=True, eq=False)
class ContactPair:
    """One impact-tip clearance: gap coordinate s = row . u, two-sided stop |s| <= gap.

    Parameters
    ----------
    name : str
        "x1" (left tip, x = -L) or "x3" (right tip, x = +L).
    row : (n_dofs,) ndarray of float
        Distributing row of the gap coordinate, s = row @ u (m): the mean uz of the beam's two
        contact patches, less that of the tube seats in the 'assembly' layout.
    normal : tuple of 3 float
        Unit normal of the upper tip; the lower tip's is its opposite.
    gap : float
        m, clearance g on either side, >= 0.
    k_g : float
        N/m, penalty stiffness of a closed tip, > 0.
    centre : tuple of 3 float
        m, centroid of the beam-side patches.

    Raises
    ------
    ValueError
        ``gap`` negative or not finite, ``k_g`` not finite and > 0.
    """

    name: str  # "x1" (left tip, x = -L) or "x3" (right tip, x = +L)
    row: np.ndarray  # (n_dofs,) distributing row: s = row @ u [m]
    normal: tuple[float, float, float]  # unit normal of the upper tip (the lower one is its opposite)
    gap: float  # m, clearance g on either side
    k_g: float  # N/m, penalty stiffness of a closed tip
    centre: tuple[float, float, float]  # m, centroid of the beam-side patches

    def __post_init__(self) -> None:
        if not (np.isfinite(self.gap) and self.gap >= 0.0):
            raise ValueError(f"contact {self.name}: gap must be >= 0 m, got {self.gap!r}")
        if not (np.isfinite(self.k_g) and self.k_g > 0.0):
            raise ValueError(f"contact {self.name}: k_g must be > 0 N/m, got {self.k_g!r}")

    def force(self, s: np.ndarray) -> np.ndarray:
        """N, the tip force on the beam for gap coordinate s (positive: pushes s down)."""
        s = np.asarray(s, dtype=float)
        return self.k_g * (np.maximum(s - self.gap, 0.0) + np.minimum(s + self.gap, 0.0))


def _mean_uz_row(fe, names: list[str], component: int = 2) -> np.ndarray:
    """(n_dofs,) row averaging uz (or the displacement ``component``) over the nodes of the named sets
    (each node once)."""
    nodes = np.unique(np.concatenate([fe.mesh.node_sets[n] for n in names]))
    row = np.zeros(fe.n_dofs)
    row[fe.solid.nodal_dofs[component, nodes]] = 1.0 / len(nodes)
    return row


def contact_pairs(fe, gap: float | None = None, k_g: float | None = None) -> list[ContactPair]:
    """The two tip clearances of an assembled model (gap and k_g default to the model's).

    Parameters
    ----------
    fe : FESystem
        An assembled model of layout 'beam-grounded' or 'assembly'.
    gap : float, optional
        m, clearance (default ``fe.model.gap``).
    k_g : float, optional
        N/m, contact stiffness (default ``fe.model.k_g``).

    Returns
    -------
    list of ContactPair
        x1 (left) and x3 (right), each with normal +z.

    Raises
    ------
    ValueError
        Layout 'beam-free', which has no tips.
    """
    layout = fe.model.layout
    if layout == "beam-free":
        raise ValueError("layout 'beam-free' has no impact tips (use 'beam-grounded' or 'assembly')")
    gap = fe.model.gap if gap is None else gap
    k_g = fe.model.k_g if k_g is None else k_g
    pairs = []
    for name, end in TIPS:
        beam = [f"beam_contact_{end}_top", f"beam_contact_{end}_bottom"]
        row = _mean_uz_row(fe, beam)
        if layout == "assembly":
            row = row - _mean_uz_row(fe, [f"tube_seat_{end}_top", f"tube_seat_{end}_bottom"])
        nodes = np.concatenate([fe.mesh.node_sets[n] for n in beam])
        centre = tuple(float(c) for c in fe.mesh.points[nodes].mean(axis=0))
        pairs.append(ContactPair(name, row, (0.0, 0.0, 1.0), float(gap), float(k_g), centre))
    return pairs


@dataclass(frozen=True, eq=False)
class TangentialRow:
    """One tangential relative coordinate of a contact face: t = row . u (see the module docstring).

    Attributes
    ----------
    name : str
        ``<stop>:<direction>``, e.g. ``x1+:axial`` (the top face at the left tip, along the beam).
    tip : str
        The gap coordinate it belongs to, ``x1`` or ``x3``.
    stop : str
        ``x1+`` / ``x3+`` (upper tip, the beam's top face) or ``x1-`` / ``x3-`` (lower tip, bottom face).
    direction : {'axial', 'lateral'}
        Along the beam (x) or across it (y).
    row : (n_dofs,) ndarray of float
        Distributing row: mean displacement of the face's patch along the direction, less the seat's in the
        'assembly' layout (m per m).
    """

    name: str  # <stop>:<direction>
    tip: str  # x1 | x3
    stop: str  # x1+ | x1- | x3+ | x3-
    direction: str  # axial | lateral
    row: np.ndarray  # (n_dofs,) t = row @ u [m]


def tangential_rows(fe, directions: tuple[str, ...] = ("axial",)) -> list[TangentialRow]:
    """The tangential coordinates of every contact face: per tip (x1, x3), per stop (upper: the top face,
    lower: the bottom one), per direction (module docstring).

    Parameters
    ----------
    fe : FESystem
        An assembled model of layout 'beam-grounded' or 'assembly'.
    directions : tuple of {'axial', 'lateral'}
        Along the beam (x), across it (y), or both.

    Returns
    -------
    list of TangentialRow
        Tip-major, then the stop (upper, lower), then the direction, in the order given.

    Raises
    ------
    ValueError
        Layout 'beam-free', or an unknown or repeated direction.
    """
    if fe.model.layout == "beam-free":
        raise ValueError("layout 'beam-free' has no impact tips (use 'beam-grounded' or 'assembly')")
    if not directions or len(set(directions)) != len(directions) or any(d not in TANGENTIAL for d in directions):
        raise ValueError(f"directions must be distinct values of {tuple(TANGENTIAL)}, got {directions!r}")
    out = []
    for name, end in TIPS:
        for sign, face in STOP_FACES:
            for d in directions:
                row = _mean_uz_row(fe, [f"beam_contact_{end}_{face}"], TANGENTIAL[d])
                if fe.model.layout == "assembly":
                    row = row - _mean_uz_row(fe, [f"tube_seat_{end}_{face}"], TANGENTIAL[d])
                out.append(TangentialRow(f"{name}{sign}:{d}", name, f"{name}{sign}", d, row))
    return out


def contact_rows(pairs: list[ContactPair]) -> np.ndarray:
    """(n_tips, n_dofs) the gap coordinates' rows, s = R u.

    Parameters
    ----------
    pairs : list of ContactPair
        The tips, in the order of the rows.

    Returns
    -------
    (n_tips, n_dofs) ndarray of float
        R, one gap-coordinate row per tip (m per m of displacement).
    """
    return np.vstack([p.row for p in pairs])


def tied_stiffness(K: sp.spmatrix, pairs: list[ContactPair], sliders: list[TangentialRow] = (),
                   k_t: float = 0.0) -> sp.csr_matrix:
    """N/m, closed-gap linearization K + sum_i k_g r_i r_i^T (sparse: rows touch patch DOFs only); with
    ``sliders``, the tangential springs of the upper stops' faces sticking added, k_t sum t t^T (the tied
    state closes the upper stop of each tip, as :meth:`reduced.models.gaps.GapSystem.closed_stiffness`).

    Parameters
    ----------
    K : (n_dofs, n_dofs) sparse matrix
        N/m, the open-gap stiffness.
    pairs : list of ContactPair
        The tips tied, each with its own k_g and row r_i.
    sliders : list of TangentialRow
        Tangential coordinates (:func:`tangential_rows`); those of the upper stops stick.
    k_t : float
        N/m, their tangential stiffness.

    Returns
    -------
    (n_dofs, n_dofs) scipy.sparse.csr_matrix
        N/m, K + sum_i k_g,i r_i r_i^T (+ k_t sum t t^T over the upper stops' rows) (a copy: K is not changed).
    """
    out = sp.csr_matrix(K, copy=True)
    for p in pairs:
        r = sp.csr_matrix(p.row)
        out = out + p.k_g * (r.T @ r)
    for t in sliders:
        if t.stop.endswith("+"):
            r = sp.csr_matrix(t.row)
            out = out + k_t * (r.T @ r)
    return out.tocsr()


@dataclass(frozen=True, eq=False)
class GapModes:
    """Open- or closed-gap modes of the 3-D model, flagged by whether the tips can excite them.

    Attributes
    ----------
    state : {'open', 'closed'}
        The tips open (K) or tied (:func:`tied_stiffness`).
    freq_hz : (n,) ndarray of float
        Hz, ascending.
    phi : (n_dofs, n) ndarray of float
        Mode shapes, mass-normalised (phi^T M phi = I).
    tip_motion : (2, n) ndarray of float
        R phi, the gap coordinates of each mode, m / sqrt(kg).
    symmetric : (n,) ndarray of float
        phi^T M (mirror phi) about y = 0: +1 symmetric (in-plane), -1 antisymmetric.
    coupled : (n,) ndarray of bool
        A symmetric mode the tips can excite (see :func:`gap_modes`).
    """

    state: str  # "open" or "closed"
    freq_hz: np.ndarray  # (n,) Hz
    phi: np.ndarray  # (n_dofs, n) mass-normalized
    tip_motion: np.ndarray  # (2, n) gap coordinates of each mode, R phi [m / sqrt(kg)]
    symmetric: np.ndarray  # (n,) phi^T M (mirror phi): +1 symmetric in y (in-plane), -1 antisymmetric
    coupled: np.ndarray  # (n,) bool: an in-plane mode the tips can excite


def gap_modes(fe, pairs: list[ContactPair], state: str, n_modes: int = 20, Psi: np.ndarray | None = None,
              tip_tol: float = 1e-5, mass_tol: float = 1e-6, sliders: list[TangentialRow] = (),
              k_t: float = 0.0, modes: tuple[np.ndarray, np.ndarray] | None = None) -> GapModes:
    """Lowest ``n_modes`` modes with the tips open (K) or tied (K + k_g sum r r^T; with ``sliders``, tied and
    sticking, :func:`tied_stiffness`).

    Lanczos shift-invert (ARPACK to round-off: an eigenvalue carries ~eps ||K|| absolute, so
    ~1e-9 relative above 100 Hz but a few 1e-5 for the assembly's bungee modes near 0.4 Hz) so
    that the reduced models' errors can be measured against them. Factorized by SuperLU:
    single-threaded, so bit-reproducible from run to run (MKL PARDISO's threads move those
    bungee modes by up to 1e-4 between runs) and, at these sizes (15k DOFs), no slower.

    A mode is *coupled* when it is symmetric in y (the tips act
    in the plane y = 0; the mirror test gives +-1 to 1e-6) and it moves a gap coordinate
    (|R phi| > ``tip_tol`` of the largest) or, given the constraint modes ``Psi``, has mass
    coupling |Psi^T M phi| > ``mass_tol`` sqrt(max diag Psi^T M Psi) (the reduced model's own
    criterion: it catches rigid-like modes whose relative tip motion is small). Symmetric
    modes that are neither (surge, z-antisymmetric tube modes) sit at 1e-9 of these scales.

    Parameters
    ----------
    fe : FESystem
        The assembled model ('beam-grounded' or 'assembly' layout, mirror-symmetric about y = 0).
    pairs : list of ContactPair
        The tips (:func:`contact_pairs`): their rows, and their k_g for the closed state.
    state : {'open', 'closed'}
        Tips open or tied.
    n_modes : int
        Modes computed (shift 0.1 Hz, rigid-body modes counted).
    Psi : (n_dofs, n_c) ndarray of float, optional
        Constraint modes of a reduced model, for the mass-coupling test.
    tip_tol : float
        Relative tip-motion threshold of a coupled mode, against the largest |R phi| of the set.
    mass_tol : float
        Relative mass-coupling threshold, against sqrt(max diag Psi^T M Psi).
    sliders : list of TangentialRow
        Tangential coordinates whose upper-stop faces stick in the closed state (friction).
    k_t : float
        N/m, their tangential stiffness.
    modes : (freq_hz (n_modes,), phi (n_dofs, n_modes)), optional
        This eigensolution already computed (a cache of it): it is not solved again.

    Returns
    -------
    GapModes

    Raises
    ------
    ValueError
        ``state`` neither 'open' nor 'closed', or a mesh not symmetric about y = 0
        (:func:`mirror_map`).
    """
    from fem.modal import modal_analysis

    if state not in ("open", "closed"):
        raise ValueError(f"state must be 'open' or 'closed', got {state!r}")
    if modes is None:
        K = fe.K if state == "open" else tied_stiffness(fe.K, pairs, sliders, k_t)
        res = modal_analysis(K, fe.M, n_modes=n_modes, shift_hz=0.1, method="lanczos", solver="superlu")
        modes = (res.freq_hz, res.phi)
    freq_hz, phi = modes
    R = contact_rows(pairs)
    tip = R @ phi
    size = np.linalg.norm(tip, axis=0)
    moves = size > tip_tol * max(size.max(), 1e-300)
    if Psi is not None:
        scale = np.sqrt(np.max(np.einsum("ij,ij->j", Psi, fe.M @ Psi)))
        moves |= np.linalg.norm(Psi.T @ (fe.M @ phi), axis=0) > mass_tol * scale
    perm, sign = mirror_map(fe)
    sym = np.einsum("ij,ij->j", phi, fe.M @ (sign[:, None] * phi[perm]))
    return GapModes(state, freq_hz, phi, tip, sym, moves & (sym > 0.5))


def point_rows(fe) -> dict[str, np.ndarray]:
    """Rows of the three points the discrete model has: x1, x3 (beam side of the tips' gap
    coordinates) and x2 (mid-span vertical motion: mean uz of the middle sensors beam_s3, beam_s4).

    In the ``assembly`` layout the points are taken relative to the tube, as the gaps are: x1,
    x3 minus the tips' seats, x2 minus the mean of the tube sensors tube_s1..4 (their centroid is
    the tube's centre). Whole-assembly motion on the bungees then leaves the points at rest.

    Parameters
    ----------
    fe : FESystem
        An assembled model with the beam's contact patches and sensors beam_s3, beam_s4 (and, in
        the 'assembly' layout, the tube seats and sensors tube_s1..4).

    Returns
    -------
    dict of str to (n_dofs,) ndarray of float
        ``x1``, ``x2``, ``x3``: rows r with x = r @ u in m.
    """
    rows = {name: _mean_uz_row(fe, [f"beam_contact_{end}_top", f"beam_contact_{end}_bottom"])
            for name, end in TIPS}
    rows["x2"] = _mean_uz_row(fe, ["beam_s3", "beam_s4"])
    if fe.model.layout == "assembly":
        for name, end in TIPS:
            rows[name] = rows[name] - _mean_uz_row(fe, [f"tube_seat_{end}_top", f"tube_seat_{end}_bottom"])
        rows["x2"] = rows["x2"] - _mean_uz_row(fe, [f"tube_s{i}" for i in range(1, 5)])
    return {k: rows[k] for k in ("x1", "x2", "x3")}


def mirror_map(fe, tol: float = 1e-8, axis: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(perm, sign): the reflection of a DOF vector in the plane through the origin normal to ``axis``
    (1: y -> -y, the default; 0: x; 2: z), u_mirror = sign * u[perm].

    A mode is symmetric when phi^T M (sign * phi[perm]) = +1 and antisymmetric when it is -1.
    Raises ValueError if the mesh is not symmetric about that plane.

    Parameters
    ----------
    fe : FESystem
        The assembled model (its DOF locations and components are read).
    tol : float
        Largest mismatch of a mirrored DOF's location, relative to the model's largest extent.
    axis : {0, 1, 2}
        Normal of the mirror plane through the origin.

    Returns
    -------
    perm : (n_dofs,) ndarray of int
        Index of the mirror image of each DOF.
    sign : (n_dofs,) ndarray of float
        -1 for the DOFs along ``axis``, +1 for the others.

    Raises
    ------
    ValueError
        ``axis`` not 0, 1 or 2, or the mesh not symmetric about the plane.
    """
    from scipy.spatial import cKDTree

    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")
    loc = fe.solid.dof_location
    comp = fe.solid.dof_component
    scale = float(np.ptp(loc, axis=0).max())
    key = np.column_stack([loc, comp * scale * 10.0])
    mirrored = key.copy()
    mirrored[:, axis] *= -1.0
    dist, perm = cKDTree(key).query(mirrored)
    if np.max(dist) > tol * scale:
        plane = "xyz"[axis]
        raise ValueError(f"the mesh is not symmetric about {plane} = 0 (max mismatch {np.max(dist):.3g} m)")
    sign = np.where(comp == axis, -1.0, 1.0)
    return perm, sign


__all__ = ["ContactPair", "GapModes", "gap_modes", "contact_pairs", "contact_rows", "tied_stiffness", "point_rows",
           "mirror_map", "TIPS", "TangentialRow", "tangential_rows", "TANGENTIAL", "STOP_FACES"]
