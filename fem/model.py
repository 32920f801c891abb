"""The finite element model of the test apparatus: solids, spring beams, seats, bungees, masses.

One flat frozen dataclass, :class:`AssemblyModel`, holds what the paper fixes (k_s, L, g,
k_g, the beam's mass, kappa) and every choice the paper leaves open, each documented.
:func:`build_system` turns it into sparse K, M with the maps later stages need.

Beam section from the paper. The beam is a steel bar of length l_b whose area follows from
its mass, A = m / (rho l_b), and whose second moment about y follows from kappa by matching
the mid-span static stiffness of the 3-DOF model with its ends held (x1 = x3 = 0):
U = kappa/(2 L^2) (2 x2)^2 gives k_mid = 4 kappa / L^2, and a simply supported beam of span
2L gives k_mid = 48 EI / (2L)^3 = 6 EI / L^3, so EI = 2 kappa L / 3 (8.52e3 N m^2).
With I = b h^3 / 12 and A = b h: h = sqrt(12 I / A), b = A / h.

Springs (:mod:`fem.springs`) run from the centre of a seat patch on the beam to the centre of
a seat patch on the tube wall, each end coupled to its patch by a distributing (RBE3)
constraint, which adds no stiffness to the solid. The beam end is glued (rigid); the tube
end is only nested in a pocket, so its rotation is tied to the wall through rotational
springs ``seat_k_rx, seat_k_ry, seat_k_rz`` (N m/rad) that the calibration fits. Their
three extra DOFs per spring carry no mass and are condensed out exactly, spring by spring.
The impact tips are open in the linear (open-gap) model: k_g and g are carried for the
nonlinear stages; the tip assemblies (tip, bolt, load cell) are lumped on the tube seats.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields

import numpy as np
import scipy.sparse as sp

from fem._assembly import add as csr_add
from fem.material import Material
from fem.solid import SolidMatrices, assemble_solid
from fem.springs import CoilSpring, rbe3_map, rigid_modes, spring_element
from geometry.build import MeshData, build_mesh
from geometry.params import AssemblyGeometry

LAYOUTS = ("assembly", "beam-grounded", "beam-free")
SEATS = ("left_top", "left_bottom", "right_top", "right_bottom")


@dataclass(frozen=True, slots=True)
class AssemblyModel:
    """The apparatus of Section 4 (SI units); the calibrated values are the defaults.

    Parameters
    ----------
    layout : {'assembly', 'beam-grounded', 'beam-free'}
        Beam in its tube on bungees; beam on springs grounded at the tube's seats (no tube); or
        the free beam alone.
    k_s : float
        N/m, axial stiffness of one suspension spring (Table 1).
    L : float
        m, spring and tip axes at x = +-L.
    gap : float
        m, tip clearance (open in the linear model).
    k_g : float
        N/m, tip contact stiffness (used by the nonlinear stages).
    beam_mass : float
        kg, m1 + m2 + m3; with ``rho`` and ``beam_length`` it sets the beam's section area.
    kappa : float
        N m/rad, sets the beam's bending stiffness, EI = 2 kappa L / 3.
    E, nu, rho : float
        Pa, -, kg/m^3: the steel of beam and tube.
    beam_length : float
        m, overall length of the impact beam.
    coil_diameter : float
        m, mean coil diameter (lateral, bending and torsion stiffness of a spring; seat size).
    spring_length : float
        m, installed spring length (sets the tube's inner height).
    seat_k_rx, seat_k_ry, seat_k_rz : float
        N m/rad, rotational stiffness of a tube seat about x, y, z.
    tube_mass : float
        kg, box tube with its sensors and fixtures, smeared over its volume.
    tip_mass : float
        kg, one impact tip with bolt and load cell, lumped on its tube seat.
    tube_wall, tube_clearance_y, tube_overhang : float
        m, wall thickness, lateral gap from beam side to tube wall, tube beyond each beam end.
    bungee_kz, bungee_kxy : float
        N/m, vertical and horizontal stiffness of each of the 4 bungee attachments.
    element : {'hex8', 'hex20', 'hex27'}
        Solid element.
    element_size : float
        m, target element edge.
    wall_layers : int
        Elements through the tube wall.

    Raises
    ------
    ValueError
        An unknown layout, a number that is not finite (or not > 0, ``nu`` aside), an invalid
        material, or a geometry :class:`geometry.params.AssemblyGeometry` refuses.
    """

    layout: str = "assembly"  # assembly | beam-grounded (no tube, springs grounded) | beam-free
    # -- fixed by the paper (Table 1, Section 4) -------------------------------------------
    k_s: float = 8.03e3  # N/m, axial stiffness of one suspension spring
    L: float = 0.1614  # m, spring and tip axes at x = +-L
    gap: float = 2.54e-4  # m, tip clearance (open in the linear model)
    k_g: float = 3.502e7  # N/m, tip contact stiffness (inactive while the gap is open)
    beam_mass: float = 2.516  # kg, m1 + m2 + m3
    kappa: float = 79161.0  # N m/rad, sets the beam's bending stiffness (see module doc)
    # -- materials ------------------------------------------------------------------------
    E: float = 200e9  # Pa, steel (beam and tube)
    nu: float = 0.3  # steel
    rho: float = 7850.0  # kg/m^3, beam steel; the beam section follows from beam_mass
    # -- choices, fitted to Table 2 by fem.calibrate (see results/assembly-modal/) ---------
    beam_length: float = 0.43926  # m, overall length of the impact beam
    coil_diameter: float = 0.013961  # m, mean coil diameter: lateral, bending, torsion of a spring
    spring_length: float = 0.032792  # m, installed spring length (sets the tube's inner height)
    seat_k_rx: float = 2.5762  # N m/rad, tube seat rotational stiffness about x
    seat_k_ry: float = 1.3463  # N m/rad, tube seat rotational stiffness about y
    seat_k_rz: float = 9735.0  # N m/rad, tube seat torsion (at its bound: clamped; no influence)
    tube_mass: float = 13.183  # kg, box tube with its sensors and fixtures, smeared over its volume
    # -- other choices ---------------------------------------------------------------------
    tip_mass: float = 0.08  # kg, one impact tip + bolt + load cell, lumped on its tube seat
    tube_wall: float = 0.00635  # m, 1/4 in wall
    tube_clearance_y: float = 0.02  # m, lateral gap beam side to tube wall
    tube_overhang: float = 0.03  # m, tube beyond each beam end
    bungee_kz: float = 300.0  # N/m, vertical stiffness of each of 4 bungee attachments
    bungee_kxy: float = 30.0  # N/m, horizontal (pendulum) stiffness of each attachment
    # -- discretisation --------------------------------------------------------------------
    element: str = "hex20"  # hex8 | hex20 | hex27 (from the element study)
    element_size: float = 0.3  # m, target element edge (default from the mesh study)
    wall_layers: int = 3  # elements through the tube wall

    def __post_init__(self) -> None:
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {self.layout!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("layout", "element"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{f.name} must be a finite number, got {v!r}")
            if f.name != "nu" and not v > 0:
                raise ValueError(f"{f.name} must be > 0, got {v!r}")
        if self.element not in ("hex8", "hex20", "hex27"):
            raise ValueError(f"element must be hex8, hex20 or hex27, got {self.element!r}")
        Material(self.E, self.nu, self.rho)  # validates the material
        A = self.beam_mass / (self.rho * self.beam_length)  # a tiny rho overflows it to inf (a float, no error)
        h = math.sqrt(12 * self.beam_EI / self.E / A) if A > 0 and math.isfinite(A) else 0.0
        if not (math.isfinite(A) and A > 0 and h > 0 and math.isfinite(A / h)):
            raise ValueError(f"rho, beam_mass and beam_length give no beam section (A = beam_mass / (rho "
                             f"beam_length) = {A:.3g} m^2): rho = {self.rho!r} is out of range")
        self.geometry()  # validates the geometry before any gmsh call

    @property
    def beam_EI(self) -> float:
        """N m^2, 2 kappa L / 3 (mid-span stiffness of the 3-DOF model)."""
        return 2 * self.kappa * self.L / 3

    @property
    def beam_section(self) -> tuple[float, float]:
        """(width b, height h) in m from A = m / (rho l_b) and I = EI / E = b h^3 / 12."""
        A = self.beam_mass / (self.rho * self.beam_length)
        h = math.sqrt(12 * self.beam_EI / self.E / A)
        return A / h, h

    @property
    def spring(self) -> CoilSpring:
        return CoilSpring(self.k_s, self.coil_diameter, self.spring_length, self.nu)

    def geometry(self) -> AssemblyGeometry:
        """The gmsh geometry this model needs (the tube only for layout 'assembly')."""
        b, h = self.beam_section
        return AssemblyGeometry(
            L=self.L, beam_length=self.beam_length, beam_width=b, beam_height=h,
            seat_diameter=self.coil_diameter, spring_length=self.spring_length,
            tube_clearance_y=self.tube_clearance_y, tube_overhang=self.tube_overhang,
            tube_wall=self.tube_wall, element_size=self.element_size, wall_layers=self.wall_layers,
            parts=("beam", "tube") if self.layout == "assembly" else ("beam",),
        )


@dataclass(frozen=True, eq=False)
class FESystem:
    """Assembled model: K, M and the maps from names to DOFs.

    Attributes
    ----------
    model : AssemblyModel
        The model assembled.
    mesh : MeshData
        Its hexahedral mesh with the named node sets.
    solid : SolidMatrices
        The solids' matrices and DOF map (components, locations, nodal DOFs).
    K : (n_dofs, n_dofs) scipy.sparse.csr_matrix
        N/m, solids plus springs, seats and bungees.
    M : (n_dofs, n_dofs) scipy.sparse.csr_matrix
        kg, solids plus the lumped tip masses.
    timing : dict of str to float
        s, ``mesh_s``, ``assembly_s``, ``springs_s``.
    """

    model: AssemblyModel
    mesh: MeshData
    solid: SolidMatrices
    K: sp.csr_matrix  # N/m
    M: sp.csr_matrix  # kg
    timing: dict = field(default_factory=dict)  # s: mesh, assembly

    @property
    def n_dofs(self) -> int:
        return self.K.shape[0]

    def part_dofs(self, part: str) -> np.ndarray:
        """All DOFs of a solid part (nodal and higher-order)."""
        nodes = self.mesh.part_nodes(part)
        mask = np.zeros(len(self.mesh.points), bool)
        mask[nodes] = True
        # a DOF belongs to the part if the node nearest its location does: parts do not touch
        loc = self.solid.dof_location
        lo = self.mesh.points[nodes].min(axis=0) - 1e-9
        hi = self.mesh.points[nodes].max(axis=0) + 1e-9
        inside = np.all((loc >= lo) & (loc <= hi), axis=1)
        if part == "tube":  # the tube's box contains the beam's: exclude the beam's DOFs
            inside &= ~np.isin(np.arange(self.n_dofs), self.part_dofs("beam"))
        return np.flatnonzero(inside)

    def node_dofs(self, name: str) -> np.ndarray:
        """(3, n) x, y, z DOFs of the nodes of a named set (a sensor gives n = 1)."""
        return self.solid.nodal_dofs[:, self.mesh.node_sets[name]]

    def sensor_names(self, part: str) -> list[str]:
        names = [k for k in self.mesh.node_sets if k.startswith(f"{part}_s") and k[len(part) + 2:].isdigit()]
        return sorted(names, key=lambda k: int(k[len(part) + 2:]))

    def sensor_dofs(self, names: list[str]) -> np.ndarray:
        """DOF indices of sensors, x y z per sensor in order."""
        return np.concatenate([self.node_dofs(n)[:, 0] for n in names])

    def rigid_modes(self, dofs: np.ndarray, centre) -> np.ndarray:
        """(len(dofs), 6) rigid-body modes (u, theta) about ``centre`` restricted to ``dofs``."""
        loc = self.solid.dof_location[dofs] - np.asarray(centre, float)
        comp = self.solid.dof_component[dofs]
        out = np.zeros((len(dofs), 6))
        x, y, z = loc.T
        out[np.arange(len(dofs)), comp] = 1.0
        # theta x r: rows for ux, uy, uz
        rot = {0: ((4, z), (5, -y)), 1: ((3, -z), (5, x)), 2: ((3, y), (4, -x))}
        for c, terms in rot.items():
            sel = comp == c
            for j, val in terms:
                out[sel, j] = val[sel]
        return out


def _seat_patch(system_mesh: MeshData, solid: SolidMatrices, name: str):
    nodes = system_mesh.node_sets[name]
    T, c = rbe3_map(system_mesh.points[nodes])
    dofs = solid.nodal_dofs[:, nodes].T.ravel()  # x y z per node, matching rbe3_map's layout
    return T, c, dofs


def spring_with_seat(spring: CoilSpring, a: np.ndarray, b: np.ndarray, k_seat: np.ndarray) -> np.ndarray:
    """12x12 stiffness between the beam master (u, th at a) and the tube master (u, th at b).

    The spring's b-end rotation r is a separate DOF tied to the tube master's rotation by
    diag(k_seat); r carries no mass and is condensed out: K = K_mm - K_mr K_rr^-1 K_rm.

    Parameters
    ----------
    spring : CoilSpring
        The spring's equivalent-column rigidities.
    a, b : (3,) ndarray of float
        m, the spring's ends: the beam seat's centre and the tube seat's centre.
    k_seat : (3,) ndarray of float
        N m/rad, the tube seat's rotational stiffness about x, y, z.

    Returns
    -------
    (12, 12) ndarray of float
        Stiffness on (u, theta at a; u, theta of the tube master at b), N/m, N/rad, N m/rad.
    """
    Ke = spring_element(spring, a, b)  # DOFs: a(6), b_u(3), r(3)
    K15 = np.zeros((15, 15))  # a(6), tube master u(3), th(3), r(3)
    idx = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 13, 14]
    K15[np.ix_(idx, idx)] += Ke
    Ks = np.diag(k_seat)
    K15[12:, 12:] += Ks
    K15[9:12, 9:12] += Ks
    K15[12:, 9:12] -= Ks
    K15[9:12, 12:] -= Ks
    m, r = np.arange(12), np.arange(12, 15)
    return K15[np.ix_(m, m)] - K15[np.ix_(m, r)] @ np.linalg.solve(K15[np.ix_(r, r)], K15[np.ix_(r, m)])


def build_system(model: AssemblyModel, method: str = "cached", mesh: MeshData | None = None) -> FESystem:
    """Mesh (unless given), assemble the solids, add springs, seats, bungees and lumped masses.

    Parameters
    ----------
    model : AssemblyModel
        The apparatus (its layout decides which springs, seats and bungees are added).
    method : {'cached', 'skfem'}
        Solid assembly (:func:`fem.solid.assemble_solid`).
    mesh : MeshData, optional
        A mesh of ``model.geometry()`` already built (default: built here with gmsh).

    Returns
    -------
    FESystem
    """
    t0 = time.perf_counter()
    g = model.geometry()
    if mesh is None:
        mesh = build_mesh(g)
    t_mesh = time.perf_counter() - t0
    b, h = model.beam_section
    steel = Material(model.E, model.nu, model.rho)
    cell_material = [(mesh.part_cells("beam"), steel)]
    if "tube" in mesh.part_names:
        rho_t = model.tube_mass / g.tube_volume
        cell_material.append((mesh.part_cells("tube"), Material(model.E, model.nu, rho_t)))
    solid = assemble_solid(mesh.points, mesh.hexes, cell_material, model.element, method)
    t1 = time.perf_counter()
    n = solid.n_dofs
    rows, cols, vals = [], [], []

    def add(dofs, Kd):
        rows.append(np.repeat(dofs, len(dofs)))
        cols.append(np.tile(dofs, len(dofs)))
        vals.append(np.asarray(Kd).ravel())

    mrows, mvals = [], []
    if model.layout != "beam-free":
        k_seat = np.array([model.seat_k_rx, model.seat_k_ry, model.seat_k_rz])
        for seat in SEATS:
            Ta, ca, da = _seat_patch(mesh, solid, f"beam_seat_{seat}")
            tube_end = np.array(g.seat_centres("tube")[seat])
            if model.layout == "assembly":
                Tb, cb, db = _seat_patch(mesh, solid, f"tube_seat_{seat}")
            else:
                cb = tube_end
            Ks = spring_with_seat(model.spring, ca, cb, k_seat)
            if model.layout == "assembly":
                B = np.zeros((12, len(da) + len(db)))
                B[:6, :len(da)] = Ta
                B[6:, len(da):] = Tb
                add(np.concatenate([da, db]), B.T @ Ks @ B)
                # the tip assembly's mass, lumped equally on the tube seat's nodes
                mrows.append(db)
                mvals.append(np.full(len(db), model.tip_mass / (len(db) // 3)))
            else:  # grounded: the tube master does not move
                add(da, Ta.T @ Ks[:6, :6] @ Ta)
        if model.layout == "assembly":
            for i in range(1, 5):
                d = mesh.node_sets[f"bungee_{i}"]
                dofs = solid.nodal_dofs[:, d][:, 0]
                add(dofs, np.diag([model.bungee_kxy, model.bungee_kxy, model.bungee_kz]))
    K = solid.K
    M = solid.M
    if rows:
        # scipy's K + S bit for bit, merged row by row in numba (fem._assembly.add)
        K = csr_add(K, sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(n, n)).tocsr())
    if mrows:
        d = np.concatenate(mrows)
        M = csr_add(M, sp.coo_matrix((np.concatenate(mvals), (d, d)), shape=(n, n)).tocsr())
    timing = {"mesh_s": t_mesh if mesh is not None else 0.0, "assembly_s": time.perf_counter() - t0 - t_mesh,
              "springs_s": time.perf_counter() - t1}
    return FESystem(model=model, mesh=mesh, solid=solid, K=K.tocsr(), M=M.tocsr(), timing=timing)


__all__ = ["AssemblyModel", "FESystem", "build_system", "spring_with_seat", "rigid_modes", "LAYOUTS"]
