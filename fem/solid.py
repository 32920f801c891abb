"""3-D linear elasticity of the meshed solids, assembled with scikit-fem.

Stiffness and consistent mass, K = sum_e int B^T D B dV and M = sum_e int rho N^T N dV,
per part with its own material. Two assembly paths give the same matrices:

- ``"skfem"``: scikit-fem's vectorised :func:`skfem.asm` over every element;
- ``"cached"``: the block-structured meshes of :mod:`geometry.build` hold only a few dozen
  distinct element shapes, so each shape's element matrices are computed once (by
  scikit-fem, in one assembly over a mesh of one element per shape) and scattered to all
  elements of that shape (:mod:`fem._assembly`, numba, straight into CSR). Exact, not an
  approximation: elements with the same node offsets have identical matrices.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from skfem import Basis, ElementHex1, ElementHex2, ElementHexS2, ElementVector, MeshHex1, asm
from skfem.assembly import Dofs
from skfem.io.meshio import INV_HEX_MAPPING

from fem.material import Material, mass_form, stiffness_form

ELEMENTS = {"hex8": ElementHex1, "hex20": ElementHexS2, "hex27": ElementHex2}
# Gauss rules exact for the element matrices of straight-sided (affine) hexahedra: the
# integrands are of degree <= 2 (hex8) and <= 4 (hex20, hex27) in each coordinate, so 2 and
# 3 points per direction suffice; scikit-fem's default (twice the element's degree) would
# use 4 points per direction for hex20 (64 instead of 27 per element) for the same matrices.
INTORDER = {"hex8": 3, "hex20": 5, "hex27": 5}
KEY_DECIMALS = 10  # m, element shapes equal to 1e-10 m share their matrices


@dataclass(frozen=True, eq=False)
class SolidMatrices:
    """Assembled stiffness and mass of the solids with their DOF map.

    Attributes
    ----------
    K : (n_dofs, n_dofs) scipy.sparse.csr_matrix
        N/m, stiffness of the solids.
    M : (n_dofs, n_dofs) scipy.sparse.csr_matrix
        kg, consistent mass of the solids.
    nodal_dofs : (3, n_nodes) ndarray of int
        DOF index of each node's x, y, z displacement.
    dof_component : (n_dofs,) ndarray of int
        0, 1, 2 for x, y, z.
    dof_location : (n_dofs, 3) ndarray of float
        m, the node, edge midpoint, face or cell centre each DOF sits at.
    element : str
        'hex8', 'hex20' or 'hex27'.
    n_unique_shapes : int
        Distinct element shapes whose matrices were computed (0 for the 'skfem' method).
    timing : dict of str to float
        s, per assembly step.
    """

    K: sp.csr_matrix  # N/m, (n_dofs, n_dofs)
    M: sp.csr_matrix  # kg, (n_dofs, n_dofs)
    nodal_dofs: np.ndarray  # (3, n_nodes) DOF index of each node's x, y, z displacement
    dof_component: np.ndarray  # (n_dofs,) 0, 1, 2 for x, y, z
    dof_location: np.ndarray  # m, (n_dofs, 3) node, edge midpoint, face or cell centre of each DOF
    element: str
    n_unique_shapes: int = 0
    timing: dict = field(default_factory=dict)  # s, per step

    @property
    def n_dofs(self) -> int:
        return self.K.shape[0]


def skfem_mesh(points: np.ndarray, hexes: np.ndarray) -> MeshHex1:
    """scikit-fem mesh from gmsh/meshio-ordered hexahedra.

    Parameters
    ----------
    points : (n_nodes, 3) ndarray of float
        m, node coordinates.
    hexes : (n_cells, 8) ndarray of int
        Hexahedra in gmsh/meshio node order.

    Returns
    -------
    skfem.MeshHex1
        The same mesh in scikit-fem's node order.
    """
    return MeshHex1(np.ascontiguousarray(points.T), np.ascontiguousarray(hexes[:, INV_HEX_MAPPING[:8]].T))


def dof_table(mesh: MeshHex1, dof: Dofs) -> tuple[np.ndarray, np.ndarray]:
    """Component (0, 1, 2) and location (n_dofs, 3) of every DOF of a vector Lagrange element.

    Each DOF is a displacement component at a node, an edge midpoint, a face centre or the
    cell centre, so a rigid motion u = a + theta x X is interpolated exactly by its values there.

    Parameters
    ----------
    mesh : skfem.MeshHex1
        The mesh.
    dof : skfem.Dofs
        DOFs of a vector element on it (3 components per place).

    Returns
    -------
    component : (n_dofs,) ndarray of int8
        0, 1, 2 for x, y, z.
    location : (n_dofs, 3) ndarray of float
        m, where each DOF sits.

    Raises
    ------
    RuntimeError
        A DOF layout without three components per place.
    """
    comp = np.empty(dof.N, dtype=np.int8)
    loc = np.empty((dof.N, 3))
    p = mesh.p
    places = [(dof.nodal_dofs, p),
              (dof.edge_dofs, p[:, mesh.edges].mean(axis=1) if dof.edge_dofs.size else None),
              (dof.facet_dofs, p[:, mesh.facets].mean(axis=1) if dof.facet_dofs.size else None),
              (dof.interior_dofs, p[:, mesh.t].mean(axis=1) if dof.interior_dofs.size else None)]
    for d, X in places:
        if d.size == 0:
            continue
        if d.shape[0] != 3:
            raise RuntimeError(f"unexpected DOF layout {d.shape}")
        for c in range(3):
            comp[d[c]] = c
            loc[d[c]] = X.T
    return comp, loc


def assemble_solid(points: np.ndarray, hexes: np.ndarray, cell_material: list[tuple[np.ndarray, Material]],
                   element: str = "hex20", method: str = "cached") -> SolidMatrices:
    """Assemble K and M of the hexahedral mesh.

    Parameters
    ----------
    points, hexes : (n, 3) node coordinates in m and (n_cells, 8) gmsh-ordered connectivity.
    cell_material : list of (cell indices, Material) covering the cells.
    element : 'hex8' (trilinear; locks in bending), 'hex20' (serendipity) or 'hex27'.
    method : 'cached' (shape-cached, default) or 'skfem' (plain scikit-fem).
    """
    if element not in ELEMENTS:
        raise ValueError(f"element must be one of {', '.join(ELEMENTS)}, got {element!r}")
    t0 = time.perf_counter()
    mesh = skfem_mesh(points, hexes)
    e = ElementVector(ELEMENTS[element]())
    if method == "skfem":
        n = Dofs(mesh, e).N
        K = sp.csr_matrix((n, n))
        M = sp.csr_matrix((n, n))
        for cells, mat in cell_material:
            basis = Basis(mesh, e, elements=np.asarray(cells), intorder=INTORDER[element])
            K = K + asm(stiffness_form(mat), basis)
            M = M + asm(mass_form(mat), basis)
        dof = Dofs(mesh, e)
        dofs = dof.nodal_dofs
        n_shapes = 0
    elif method == "cached":
        dof = Dofs(mesh, e)
        n = dof.N
        ed = dof.element_dofs  # (n_local, n_cells)
        dofs = dof.nodal_dofs
        X = points[hexes]  # (n_cells, 8, 3)
        shape = np.empty(len(hexes), dtype=np.int64)
        Kes, Mes = [], []
        n_shapes = 0
        for cells, mat in cell_material:
            cells = np.asarray(cells)
            key = np.round(X[cells] - X[cells, :1], KEY_DECIMALS).reshape(len(cells), -1)
            uniq, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
            shape[cells] = n_shapes + inv.ravel()
            n_shapes += len(uniq)
            Ke, Me = _element_matrices(X[cells[first]], e, element, mat)
            Kes.append(Ke)
            Mes.append(Me)
        from fem._assembly import scatter_pair

        indptr, indices, kdata, mdata = scatter_pair(ed, shape, np.concatenate(Kes), np.concatenate(Mes), n)
        K = sp.csr_matrix((kdata, indices, indptr), shape=(n, n))
        M = sp.csr_matrix((mdata, indices.copy(), indptr.copy()), shape=(n, n))
    else:
        raise ValueError(f"method must be 'cached' or 'skfem', got {method!r}")
    comp, loc = dof_table(mesh, dof)
    return SolidMatrices(K=K.tocsr(), M=M.tocsr(), nodal_dofs=np.asarray(dofs), dof_component=comp,
                         dof_location=loc, element=element,
                         n_unique_shapes=n_shapes, timing={"assembly_s": time.perf_counter() - t0})


def _element_matrices(Xs: np.ndarray, e, element: str, mat: Material) -> tuple[np.ndarray, np.ndarray]:
    """(n_shapes, n_local, n_local) stiffness and mass of the elements with corner nodes ``Xs``
    (n_shapes, 8, 3), each moved to its first node, in scikit-fem's local DOF order: one
    scikit-fem assembly over a mesh of the disjoint elements (its quadrature loops run once
    over the 60 x 60 local pairs for all shapes, not once per shape)."""
    ns = len(Xs)
    pts = (Xs - Xs[:, :1]).reshape(-1, 3)
    one = skfem_mesh(pts, np.arange(8 * ns).reshape(ns, 8))
    basis = Basis(one, e, intorder=INTORDER[element])
    out = []
    for form in (stiffness_form(mat), mass_form(mat)):
        coo = form.coo_data(basis)  # data[j, i, e]: trial j (column), test i (row), element e
        nu_, nv_ = coo.local_shape[1], coo.local_shape[0]
        out.append(np.ascontiguousarray(coo.data.reshape(nu_, nv_, ns).transpose(2, 1, 0)))
    return out[0], out[1]
