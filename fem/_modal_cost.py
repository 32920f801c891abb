"""What a modal analysis will cost, known before meshing: DOFs from the block grid, memory.

The meshes of :mod:`geometry.build` are transfinite: every block of the grid gets the
divisions :func:`geometry.build._divisions` gives its edges, so the cells, nodes and edges,
and hence the DOFs, follow from the geometry alone (:func:`count_dofs`, exact). The memory
model (:func:`modal_bytes`) adds what the pipeline holds at its peak, the sparse Cholesky
factor being the term that grows fastest; its coefficients are fitted to the peaks measured by
``benchmarks/modal_scaling.py`` (``results/performance/modal_scaling.csv`` has both columns).
"""

from __future__ import annotations

import numpy as np

from geometry.build import _divisions, beam_grid, tube_grid
from geometry.params import AssemblyGeometry

FLOAT, INDEX = 8, 4  # bytes
NNZ_PER_ROW = 150  # K (and M, same pattern) entries per row, hex20: measured 146 at 15k and 112k DOFs
# Cholesky factor of K - sigma M (MKL PARDISO, METIS, VBSR): PARDISO's own peak (iparm[15] +
# iparm[16]) measured on the apparatus from 15,087 to 647,781 DOFs (modal_scaling.csv) follows
# 1.145e-6 GiB * n**1.15 to within -6/+9 % on one thread (two threads add 5-18 % at 15k-112k DOFs,
# which the other terms' slack covers): the thin tube walls fill less than the n^(4/3) of nested
# dissection on a cube. The estimate is that fit with a 10 % margin up to the largest mesh
# measured, and beyond it grows as n^(4/3), the 3-D bound, so that an extrapolation stays above.
FACTOR_COEF = 1.145e-6 * 2**30  # bytes at n = 1
FACTOR_EXP = 1.15
FACTOR_MARGIN = 1.1
FACTOR_MEASURED_DOFS = 647_781  # largest mesh of the fit
FACTOR_EXP_BEYOND = 4 / 3
KRYLOV_BLOCKS = 8  # the Krylov basis holds at most 8 blocks of n_modes + 8 columns (fem.modal)
MAX_COUNTED = 20_000_000  # fine cells counted one by one; beyond, an upper bound (about 3 M DOFs of
# hex20 is already far past any memory this estimate has to guard)
MAX_DOFS = 10**30  # counts are capped here, so that any estimate stays a finite float
BASE = 0.45 * 2**30  # bytes: the interpreter with numpy, scipy, scikit-fem, numba, gmsh and MKL loaded
# (the 15,087-DOF run peaked at 0.45 GiB for 0.17 GiB of arrays). With the matrices and Krylov terms
# below (8,660 bytes a DOF for 16 modes) this bounds the measured peak less the factor's, 0.30 GiB +
# 7,700 bytes a DOF (modal_scaling.csv, 15k to 648k DOFs), by 15 to 55 %.


def _part_cells(g: AssemblyGeometry, part: str) -> np.ndarray:
    """Boolean (Nx, Ny, Nz) mask of the fine cells of ``part`` on its own block grid."""
    grid = beam_grid(g) if part == "beam" else tube_grid(g)
    div = [np.array(d) for d in _divs(g, part)]
    block = [np.repeat(np.arange(len(dv)), dv) for dv in div]  # block index of each fine cell
    if part == "beam":
        mask = np.ones(tuple(len(b) for b in block), bool)
    else:
        _, ys, zs = grid
        w, h = g.tube_inner_width / 2, g.tube_inner_height / 2
        yc, zc = (ys[:-1] + ys[1:]) / 2, (zs[:-1] + zs[1:]) / 2
        hollow = (np.abs(yc)[:, None] < w) & (np.abs(zc)[None, :] < h)  # (blocks y, blocks z)
        mask = np.broadcast_to(~hollow[block[1]][:, block[2]][None], (len(block[0]), len(block[1]), len(block[2])))
    return np.asarray(mask)


def _used(mask: np.ndarray, axes: tuple[int, ...]) -> int:
    """Entities of the grid used by a cell: vertices (axes = 0, 1, 2), edges along one axis
    (the other two), faces (one) or cells (none); an entity is shared by the cells on each side
    of it along ``axes``."""
    m = mask
    for a in axes:
        pad = [(0, 0)] * 3
        pad[a] = (1, 1)
        p = np.pad(m, pad)
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[a], hi[a] = slice(0, -1), slice(1, None)
        m = p[tuple(lo)] | p[tuple(hi)]
    return int(m.sum())


def _divs(g: AssemblyGeometry, part: str) -> list[list[int]]:
    grid = beam_grid(g) if part == "beam" else tube_grid(g)
    return [[_divisions(float(b - a), g, along_x=(d == 0)) for a, b in zip(v[:-1], v[1:], strict=True)]
            for d, v in enumerate(grid)]


def count_dofs(g: AssemblyGeometry, element: str = "hex20") -> int:
    """DOFs of the mesh :func:`geometry.build.build_mesh` would make of ``g`` (parts do not touch):
    exact, or, past MAX_COUNTED cells, the DOFs of the full block grid (an upper bound, counted
    without building the grid).

    Parameters
    ----------
    g : AssemblyGeometry
        The geometry and mesh controls :func:`geometry.build.build_mesh` would mesh.
    element : {'hex8', 'hex20', 'hex27'}
        Element type: DOFs on the vertices, plus the edge mid-nodes (hex20), plus the face and
        cell centres (hex27).

    Returns
    -------
    int
        Number of DOFs, 3 per node, capped at ``MAX_DOFS``.
    """
    n = 0
    for part in g.parts:
        Nx, Ny, Nz = (sum(d) for d in _divs(g, part))
        if Nx * Ny * Nz > MAX_COUNTED:
            per = {"hex8": 1, "hex20": 4, "hex27": 8}[element]
            n += per * (Nx + 1) * (Ny + 1) * (Nz + 1)
            continue
        mask = _part_cells(g, part)
        nodes = _used(mask, (0, 1, 2))
        if element == "hex8":
            n += nodes
            continue
        edges = sum(_used(mask, tuple(a for a in range(3) if a != d)) for d in range(3))
        n += nodes + edges
        if element == "hex27":
            n += sum(_used(mask, (d,)) for d in range(3)) + int(mask.sum())
    return min(3 * n, MAX_DOFS)


def factor_bytes(n_dofs: float) -> float:
    """Peak bytes of PARDISO's Cholesky factor of ``n_dofs`` DOFs of the apparatus:
    m c n^p for n <= n_m (the fit to the measured peaks, m = FACTOR_MARGIN), and that value at
    n_m times (n / n_m)^(4/3) beyond.

    Parameters
    ----------
    n_dofs : float
        Size of the matrix K - sigma M.

    Returns
    -------
    float
        bytes, the estimated peak of the factorization (``FACTOR_COEF``, ``FACTOR_EXP``,
        ``FACTOR_MARGIN`` and ``FACTOR_MEASURED_DOFS`` are c, p, m and n_m).
    """
    n = float(n_dofs)
    fit = FACTOR_MARGIN * FACTOR_COEF * min(n, FACTOR_MEASURED_DOFS) ** FACTOR_EXP
    return fit * max(n / FACTOR_MEASURED_DOFS, 1.0) ** FACTOR_EXP_BEYOND


def modal_bytes(n_dofs: int, n_modes: int) -> dict:
    """Peak bytes of mesh, assembly and modal analysis of ``n_dofs`` DOFs, by term.

    Parameters
    ----------
    n_dofs : int
        DOFs of the mesh (:func:`count_dofs`).
    n_modes : int
        Modes asked of the eigensolver.

    Returns
    -------
    dict of str to float
        bytes, by term: ``matrices`` (K, M, the triangle handed to PARDISO and the scatter's
        adjacency), ``factor`` (:func:`factor_bytes`), ``krylov`` (the Krylov basis and its
        products) and ``total`` (their sum plus the interpreter's ``BASE``).
    """
    nnz = NNZ_PER_ROW * n_dofs
    terms = {
        # K, M, the upper triangle of K - sigma M handed to PARDISO, and the scatter's adjacency
        "matrices": 2 * nnz * (FLOAT + INDEX) + nnz / 2 * (FLOAT + INDEX) + 60 * n_dofs / 3 * 2 * 8,
        "factor": factor_bytes(n_dofs),
        # the Krylov basis V and M V, with the Ritz vectors and a block of products beside them
        "krylov": (2 * KRYLOV_BLOCKS + 4) * (n_modes + 8) * n_dofs * FLOAT,
    }
    terms["total"] = BASE + sum(terms.values())
    return terms
