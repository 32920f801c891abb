"""gmsh (OCC) model of the beam and box tube, meshed with hexahedra block by block.

Every solid is cut into axis-aligned blocks on a grid whose lines pass through the spring
seats, the tube wall and the sensor points, so that each seat is a named set of faces and
each sensor a named vertex. All blocks are fragmented together (conforming interfaces) and
meshed transfinite and recombined: hexahedra only, with ``wall_layers`` elements through
the tube wall. The result is a :class:`MeshData` with named node sets, independent of gmsh.
"""

from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geometry.params import AssemblyGeometry

BBOX_TOL = 1e-5  # m, entity selection tolerance; gmsh pads bounding boxes by ~1e-7 m
GMSH_HEX8 = 5  # gmsh element type of the 8-node hexahedron
_GMSH_LOCK = threading.Lock()  # gmsh is one global state per process: one session at a time, whichever thread
OCC_GLUE = 2  # Geometry.OCCBooleanGlue for the fragment of the blocks: 2 = OCC's "full" glue, for solids that only
# share whole faces (the blocks of a grid; beam and tube never touch). The same mesh bit for bit as the general
# fragment (0) at element sizes 0.3-0.008 m, beam alone or with the tube (tests/test_geometry.py), in 25 % less CPU:
# the fragment is most of build_mesh (112,629 DOFs: 1.34 -> 1.00 CPU s a mesh, medians of 3, issue 28)


@contextmanager
def gmsh_session(name: str = "model", verbose: bool = False):
    """Initialise gmsh, yield ``gmsh.model`` with a fresh OCC model, always finalise.

    Parameters
    ----------
    name : str
        Name of the gmsh model added.
    verbose : bool
        Let gmsh print to the terminal (``General.Terminal``).

    Yields
    ------
    gmsh.model
        The ``gmsh.model`` namespace, with a fresh model ``name`` current; ``gmsh.finalize()`` runs on
        leaving the block, also on an exception.

    Notes
    -----
    Sessions of several threads take turns (gmsh is one state per process). Off the main thread
    (a Dask worker's task) gmsh starts without its Ctrl-C handler (``interruptible=False``), which only
    the main thread may install: the stage then meshes in the worker instead of in a child process.
    """
    import gmsh

    main = threading.current_thread() is threading.main_thread()
    with _GMSH_LOCK:
        gmsh.initialize(["-noenv"], readConfigFiles=False, **({} if main else {"interruptible": False}))
        try:
            gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
            gmsh.model.add(name)
            yield gmsh.model
        finally:
            gmsh.finalize()


@dataclass(frozen=True, eq=False)
class MeshData:
    """A hexahedral mesh with named parts and named node sets (gmsh physical names).

    ``hexes`` use the gmsh/meshio node order; ``node_sets`` map a physical name (seat
    faces, sensor vertices, bungee points) to indices into ``points``.

    Attributes
    ----------
    points : (n_nodes, 3) ndarray of float
        m, node coordinates (x along the beam, y lateral, z up).
    hexes : (n_cells, 8) ndarray of int
        Node indices into ``points`` of each 8-node hexahedron, gmsh/meshio order.
    cell_part : (n_cells,) ndarray of int
        Index into ``part_names`` of each cell's part.
    part_names : tuple of str
        The parts meshed ('beam', 'tube').
    node_sets : dict of str to ndarray of int
        Physical name -> node indices into ``points`` (seat faces, sensor vertices, bungee points).
    wall_time_s : float
        s, wall time of building the gmsh model and meshing it.
    """

    points: np.ndarray  # m, (n_nodes, 3)
    hexes: np.ndarray  # (n_cells, 8) indices into points
    cell_part: np.ndarray  # (n_cells,) index into part_names
    part_names: tuple[str, ...]
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    wall_time_s: float = 0.0  # s, gmsh model + mesh time

    def part_cells(self, name: str) -> np.ndarray:
        """Indices of the cells of part ``name``."""
        return np.flatnonzero(self.cell_part == self.part_names.index(name))

    def part_nodes(self, name: str) -> np.ndarray:
        """Indices of the nodes of part ``name``."""
        return np.unique(self.hexes[self.part_cells(name)])

    def volume(self, name: str | None = None) -> float:
        """m^3, exact for straight-sided (trilinear) hexahedra: 2x2x2 Gauss quadrature of det J."""
        cells = self.hexes if name is None else self.hexes[self.part_cells(name)]
        return float(_hex_volumes(self.points[cells]).sum())

    def to_meshio(self):
        """A meshio.Mesh with the parts as cell sets and ``gmsh:physical`` cell data."""
        import meshio

        sets = {n: [self.part_cells(n)] for n in self.part_names}
        return meshio.Mesh(
            self.points, [("hexahedron", self.hexes)],
            cell_data={"part": [self.cell_part.astype(np.int32)]}, cell_sets=sets,
        )

    def write(self, path: str | Path) -> None:
        """Write the mesh (any meshio format, e.g. .vtu or .msh) with its part tags."""
        self.to_meshio().write(str(path))


def _hex_volumes(X: np.ndarray) -> np.ndarray:
    g = np.array([-1, 1]) / math.sqrt(3.0)
    sign = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], float)
    vol = np.zeros(len(X))
    for a in g:
        for b in g:
            for c in g:
                xi = np.array([a, b, c])
                dN = np.empty((8, 3))
                base = 1 + sign * xi  # (8, 3)
                for d in range(3):
                    o = [i for i in range(3) if i != d]
                    dN[:, d] = sign[:, d] * base[:, o[0]] * base[:, o[1]] / 8
                J = np.einsum("eni,nj->eij", X, dN)
                vol += np.linalg.det(J)
    return vol


def _grid(values) -> np.ndarray:
    return np.unique(np.round(np.asarray(values, float), 12))


def beam_grid(g: AssemblyGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block grid lines of the beam in x, y, z.

    Parameters
    ----------
    g : AssemblyGeometry
        Beam dimensions, seat positions and size.

    Returns
    -------
    xs, ys, zs : ndarray of float
        m, sorted unique grid coordinates (rounded to 1e-12 m). x: beam ends, both seat edges and
        axes at x = -+L, and the centre; y: the beam sides, the seat edges and 0; z: the beam's
        bottom and top faces.
    """
    s, L, l2 = g.seat_diameter / 2, g.L, g.beam_length / 2
    xs = _grid([-l2, -L - s, -L, -L + s, 0, L - s, L, L + s, l2])
    ys = _grid([-g.beam_width / 2, -s, 0, s, g.beam_width / 2])
    zs = _grid([-g.beam_height / 2, g.beam_height / 2])
    return xs, ys, zs


def tube_grid(g: AssemblyGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block grid lines of the tube in x, y, z (wall cells only are built).

    Parameters
    ----------
    g : AssemblyGeometry
        Tube dimensions, seat positions and size.

    Returns
    -------
    xs, ys, zs : ndarray of float
        m, sorted unique grid coordinates (rounded to 1e-12 m). x: the tube ends, seat edges and
        axes at x = -+L, and the centre; y: outer and inner walls, seat edges and 0; z: outer and
        inner faces of the bottom and top walls.
    """
    s, L, lt = g.seat_diameter / 2, g.L, g.tube_length / 2
    W, H = g.tube_outer_width / 2, g.tube_outer_height / 2
    w, h = g.tube_inner_width / 2, g.tube_inner_height / 2
    xs = _grid([-lt, -L - s, -L, -L + s, 0, L - s, L, L + s, lt])
    ys = _grid([-W, -w, -s, 0, s, w, W])
    zs = _grid([-H, -h, h, H])
    return xs, ys, zs


def _divisions(length: float, g: AssemblyGeometry, along_x: bool) -> int:
    if abs(length - g.tube_wall) < 1e-9:
        return g.wall_layers
    n = math.ceil(length / g.element_size - 1e-9)
    return max(1, n) if along_x else max(g.section_layers, n)


def build_mesh(g: AssemblyGeometry, verbose: bool = False, msh_path: str | Path | None = None) -> MeshData:
    """Build, name and mesh the parts in ``g.parts``; return the hexahedral :class:`MeshData`.

    Parameters
    ----------
    g : AssemblyGeometry
        The parts, their dimensions and the element size.
    verbose : bool
        Let gmsh print.
    msh_path : str or Path, optional
        Also write the gmsh mesh (``.msh``) here.

    Returns
    -------
    MeshData
        Nodes, 8-node hexahedra with their part, and the named node sets (seats, contact
        patches, sensors, bungee points); nodes of no hexahedron are dropped.
    """
    import time

    t0 = time.perf_counter()
    with gmsh_session("assembly", verbose) as model:
        _add_part_boxes(model.occ, g)
        model.occ.synchronize()
        vols = _name_volumes(model, g)
        _set_transfinite(model, g)
        named_faces, point_tags = _name_regions(model, g)
        model.mesh.generate(3)
        if msh_path is not None:
            import gmsh

            gmsh.write(str(msh_path))
        points, hexes, cell_part, node_sets = _read_mesh(model, vols, named_faces, point_tags)
    used = np.unique(hexes)
    if len(used) != len(points):  # drop nodes that belong to no hexahedron
        remap = -np.ones(len(points), dtype=np.int64)
        remap[used] = np.arange(len(used))
        points, hexes = points[used], remap[hexes]
        node_sets = {k: remap[v] for k, v in node_sets.items()}
    return MeshData(points=points, hexes=hexes, cell_part=cell_part, part_names=tuple(vols),
                    node_sets=node_sets, wall_time_s=time.perf_counter() - t0)


def _grid_boxes(occ, xs, ys, zs, skip=None) -> list[int]:
    """OCC boxes of the cells of a block grid (``skip(yc, zc)``: leave that cell out)."""
    tags = []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            for k in range(len(zs) - 1):
                if skip is not None and skip((ys[j] + ys[j + 1]) / 2, (zs[k] + zs[k + 1]) / 2):
                    continue
                tags.append(occ.addBox(xs[i], ys[j], zs[k], xs[i + 1] - xs[i], ys[j + 1] - ys[j], zs[k + 1] - zs[k]))
    return tags


def _add_part_boxes(occ, g: AssemblyGeometry) -> None:
    """The parts as block grids of boxes, fragmented so that touching blocks share their faces
    (with :data:`OCC_GLUE`: the blocks only touch, face to whole face)."""
    import gmsh

    boxes: dict[str, list[int]] = {p: [] for p in g.parts}
    if "beam" in g.parts:
        boxes["beam"] = _grid_boxes(occ, *beam_grid(g))
    if "tube" in g.parts:
        w, h = g.tube_inner_width / 2, g.tube_inner_height / 2
        boxes["tube"] = _grid_boxes(occ, *tube_grid(g), skip=lambda yc, zc: abs(yc) < w and abs(zc) < h)  # inside
    gmsh.option.setNumber("Geometry.OCCBooleanGlue", OCC_GLUE)
    occ.fragment([(3, t) for p in boxes.values() for t in p], [])


def _inside(model, box, dim: int) -> list[int]:
    """Tags of the entities of dimension ``dim`` in the box ((lo), (hi)), padded by BBOX_TOL."""
    lo, hi = box
    return [t for (_, t) in model.getEntitiesInBoundingBox(
        lo[0] - BBOX_TOL, lo[1] - BBOX_TOL, lo[2] - BBOX_TOL,
        hi[0] + BBOX_TOL, hi[1] + BBOX_TOL, hi[2] + BBOX_TOL, dim)]


def _name_volumes(model, g: AssemblyGeometry) -> dict[str, list[int]]:
    """{part: volume tags}, each a physical group: the beam by its box, the tube everything else."""
    vols: dict[str, list[int]] = {}
    if "beam" in g.parts:
        b2, h2, l2 = g.beam_width / 2, g.beam_height / 2, g.beam_length / 2
        vols["beam"] = _inside(model, ((-l2, -b2, -h2), (l2, b2, h2)), 3)
    if "tube" in g.parts:
        every = [t for (_, t) in model.getEntities(3)]
        vols["tube"] = [t for t in every if t not in vols["beam"]]
    for name, tags in vols.items():
        if not tags:
            raise RuntimeError(f"gmsh selected no volume for part {name!r}")
        model.addPhysicalGroup(3, tags, name=name)
    return vols


def _set_transfinite(model, g: AssemblyGeometry) -> None:
    """Transfinite hexahedral meshing: divisions from each curve's length and direction."""
    for _, c in model.getEntities(1):
        x0, y0, z0, x1, y1, z1 = model.getBoundingBox(1, c)
        ext = np.array([x1 - x0, y1 - y0, z1 - z0])
        d = int(np.argmax(ext))
        n = _divisions(float(ext[d]) - 2e-7, g, along_x=(d == 0))
        model.mesh.setTransfiniteCurve(c, n + 1)
    for _, s in model.getEntities(2):
        model.mesh.setTransfiniteSurface(s)
        model.mesh.setRecombine(2, s)
    for _, v in model.getEntities(3):
        model.mesh.setTransfiniteVolume(v)


def _name_regions(model, g: AssemblyGeometry) -> tuple[dict[str, list[int]], dict[str, list[int]]]:
    """Physical groups of the seats and contact patches (faces) and of the sensor and bungee points."""
    named_faces: dict[str, list[int]] = {}
    named_points: dict[str, tuple[float, float, float]] = {}
    s = g.seat_diameter / 2
    for part in g.parts:
        for key, (x, y, z) in g.seat_centres(part).items():
            tags = _inside(model, ((x - s, y - s, z), (x + s, y + s, z)), 2)
            named_faces[f"{part}_seat_{key}"] = tags
            if part == "beam":
                named_faces[f"beam_contact_{key}"] = tags
    if "beam" in g.parts:
        named_points.update(g.beam_sensors())
    if "tube" in g.parts:
        named_points.update(g.tube_sensors())
        lt, W, H = g.tube_length / 2, g.tube_outer_width / 2, g.tube_outer_height / 2
        for i, (x, y) in enumerate(((-lt, W), (-lt, -W), (lt, W), (lt, -W))):
            named_points[f"bungee_{i + 1}"] = (x, y, H)
    for name, tags in named_faces.items():
        if not tags:
            raise RuntimeError(f"gmsh selected no face for {name!r}")
        model.addPhysicalGroup(2, tags, name=name)
    point_tags = {}
    for name, (x, y, z) in named_points.items():
        tags = _inside(model, ((x, y, z), (x, y, z)), 0)
        if len(tags) != 1:
            raise RuntimeError(f"expected one vertex for {name!r} at {(x, y, z)}, found {len(tags)}")
        point_tags[name] = tags
        model.addPhysicalGroup(0, tags, name=name)
    return named_faces, point_tags


def _read_mesh(model, vols: dict, named_faces: dict, point_tags: dict):
    """(points, hexes, cell_part, node_sets) of the generated mesh, nodes in gmsh tag order."""
    node_tags, coords, _ = model.mesh.getNodes()
    order = np.argsort(node_tags)
    node_tags = node_tags[order]
    points = coords.reshape(-1, 3)[order]

    def index(tags):
        return np.searchsorted(node_tags, np.asarray(tags, dtype=node_tags.dtype))

    hexes, cell_part = [], []
    for pi, name in enumerate(vols):
        for v in vols[name]:
            types, _, conn = model.mesh.getElements(3, v)
            for et, cn in zip(types, conn, strict=True):
                if et != GMSH_HEX8:
                    raise RuntimeError(f"gmsh produced element type {et} in {name!r}: hexahedra only")
                h8 = index(cn).reshape(-1, 8)
                hexes.append(h8)
                cell_part.append(np.full(len(h8), pi))
    node_sets = {}
    for name, tags in named_faces.items():
        nt = np.concatenate([model.mesh.getNodes(2, t, includeBoundary=True)[0] for t in tags])
        node_sets[name] = np.unique(index(nt))
    for name, tags in point_tags.items():
        node_sets[name] = index(model.mesh.getNodes(0, tags[0])[0])
    return points, np.concatenate(hexes), np.concatenate(cell_part), node_sets
