"""The instrumented rig on the 3-D model: the test's channels and the hammer's point load.

Channels, named and numbered as the virtual test writes them to UFF 58 (:mod:`fem.uff`):

- ``beam_s1:x`` .. ``beam_s6:z``: the six triaxial accelerometers on the beam (Fig. 7),
  UFF nodes 1..6, directions +X, +Y, +Z (codes 1, 2, 3), m/s^2;
- ``tube_s1:x`` .. ``tube_s4:z``: the four triaxial sensors on the box tube (Fig. 8), nodes
  101..104;
- ``tip_left_top`` .. ``tip_right_bottom``: the load cells of the four impact tips, nodes
  201..204, direction +Z (top tips) and -Z (bottom tips): positive is compression, N;
- ``hammer``: the hammer's force, node 300, along the blow's dominant axis, N.

An accelerometer reads the absolute acceleration of its mesh node (a sensor point is a
mesh vertex, :mod:`geometry.build`), so its row picks one DOF. A tip load cell sits between
the tip (the part of the tip assembly above its gauge, the *seismic* mass m_a) and the tube
seat; the tip assembly is rigid up to its own resonance (a 1e9 N/m cell under tens of grams:
above 20 kHz, beyond any channel's band), so it moves with the seat and Newton on the tip
gives the gauge's compression

    F_top    = f_c,top    - m_a a_seat,z        (the beam pushes the upper tip up),
    F_bottom = f_c,bottom + m_a a_seat,z        (the beam pushes the lower tip down),

with f_c >= 0 the contact force and a_seat,z the seat's mean vertical acceleration
(:func:`seat_rows`). The cell therefore also reads an inertial signal while the gap is open.

The hammer's force P(t) along a unit vector d at a point X of the beam is the consistent
nodal load of a point force, b = P sum_c d_c N(X)_c, from the element's shape functions at
X (scikit-fem's probes: the transpose of the interpolation at X), so its work on any
displacement field u is P d . u(X). :func:`point_load_vector` needs only the mesh arrays,
which the reduced model keeps, so a blow anywhere on the beam is applied without meshing.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

AXES = "xyz"
BEAM_SENSORS = tuple(f"beam_s{i}" for i in range(1, 7))
TUBE_SENSORS = tuple(f"tube_s{i}" for i in range(1, 5))
TIP_CELLS = ("tip_left_top", "tip_left_bottom", "tip_right_top", "tip_right_bottom")
TUBE_NODE0 = 100  # UFF node of tube_s<i>: 100 + i
TIP_NODE0 = 200  # UFF node of the i-th tip load cell: 200 + i
HAMMER_NODE = 300  # UFF node of the hammer's force
NUDGE = 1e-7  # m, a location on the surface is moved this far along the blow to find its element


def sensor_node(name: str) -> int:
    """UFF node number of a sensor (beam_s<i>: i, tube_s<i>: 100 + i).

    Parameters
    ----------
    name : str
        ``beam_s<i>`` or ``tube_s<i>``.

    Returns
    -------
    int
        The UFF node number.
    """
    part, i = name.split("_s")
    return int(i) + (TUBE_NODE0 if part == "tube" else 0)


def tip_node(cell: str) -> tuple[int, int]:
    """(UFF node, direction code) of a tip load cell: 201..204, +3 for a top tip and -3 for a bottom one.

    Parameters
    ----------
    cell : str
        A member of ``TIP_CELLS``.

    Returns
    -------
    node, direction : int
        The UFF node number and direction code.

    Raises
    ------
    ValueError
        ``cell`` not a tip load cell.
    """
    return TIP_NODE0 + 1 + TIP_CELLS.index(cell), (3 if cell.endswith("top") else -3)


def channel_names() -> tuple[str, ...]:
    """Every channel of the apparatus in the order the virtual test writes them: beam and tube
    accelerometer axes, the four tip load cells, the hammer."""
    acc = [f"{s}:{a}" for s in (*BEAM_SENSORS, *TUBE_SENSORS) for a in AXES]
    return (*acc, *TIP_CELLS, "hammer")


def sensor_rows(fe, parts: tuple[str, ...] = ("beam", "tube")) -> dict[str, np.ndarray]:
    """{``<sensor>:<axis>``: DOF index} of every accelerometer axis of the parts present in the mesh.

    Parameters
    ----------
    fe : FESystem
        The assembled model.
    parts : tuple of str
        Parts whose sensors (``<part>_s<i>`` node sets) are wanted; a part absent from the mesh
        gives none.

    Returns
    -------
    dict of str to int
        ``<sensor>:<axis>`` (axis x, y, z) -> the DOF index of that displacement.
    """
    out = {}
    for part in parts:
        for name in fe.sensor_names(part):
            dofs = fe.node_dofs(name)[:, 0]
            for c, axis in enumerate(AXES):
                out[f"{name}:{axis}"] = int(dofs[c])
    return out


def seat_rows(fe) -> dict[str, np.ndarray]:
    """{tip load cell: (n_dofs,) row of its tube seat's mean vertical displacement} (assembly layout).

    Parameters
    ----------
    fe : FESystem
        An assembled model with the tube seats (layout 'assembly').

    Returns
    -------
    dict of str to (n_dofs,) ndarray of float
        Tip load cell -> row r, r @ u = the seat's mean uz in m (r @ a for its acceleration).
    """
    rows = {}
    for cell in TIP_CELLS:
        nodes = fe.mesh.node_sets[f"tube_seat_{cell[4:]}"]
        row = np.zeros(fe.n_dofs)
        row[fe.solid.nodal_dofs[2, nodes]] = 1.0 / len(nodes)
        rows[cell] = row
    return rows


def unit_direction(direction) -> np.ndarray:
    """The blow's unit vector; ValueError (one line) for a zero or non-finite vector.

    Parameters
    ----------
    direction : array_like of 3 float
        Any non-zero vector.

    Returns
    -------
    (3,) ndarray of float
        direction / |direction|.

    Raises
    ------
    ValueError
        Not three finite numbers, or the zero vector.
    """
    d = np.asarray(direction, dtype=float).reshape(-1)
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise ValueError(f"direction must be 3 finite numbers, got {direction!r}")
    n = float(np.linalg.norm(d))
    if not n > 0:
        raise ValueError("direction must not be the zero vector")
    return d / n


def dominant_axis(direction) -> int:
    """UFF direction code (+-1, +-2, +-3) of the axis nearest a blow's direction.

    Parameters
    ----------
    direction : array_like of 3 float
        Any non-zero vector.

    Returns
    -------
    int
        +-1, +-2, +-3 for +-X, +-Y, +-Z (the first of equal components wins).

    Raises
    ------
    ValueError
        As :func:`unit_direction`.
    """
    d = unit_direction(direction)
    k = int(np.argmax(np.abs(d)))
    return int(np.sign(d[k])) * (k + 1)


def point_load_vector(points: np.ndarray, hexes: np.ndarray, element: str, cell_part: np.ndarray,
                      part: int, location, direction, n_dofs: int) -> sp.csr_matrix:
    """(1, n_dofs) consistent nodal load of a unit force along ``direction`` at ``location`` (m).

    The location must lie in or on a cell of part index ``part`` (the beam); a point on the
    surface is moved ``NUDGE`` along the blow, into the solid it strikes. Raises ValueError
    (one line) when no cell of that part holds it.

    Parameters
    ----------
    points : (n_nodes, 3) ndarray of float
        m, the mesh's nodes.
    hexes : (n_cells, 8) ndarray of int
        gmsh-ordered hexahedra.
    element : {'hex8', 'hex20', 'hex27'}
        The model's element.
    cell_part : (n_cells,) ndarray of int
        Part index of each cell.
    part : int
        Index of the part that may be struck.
    location : array_like of 3 float
        m, the point struck.
    direction : array_like of 3 float
        The blow's direction (normalised here).
    n_dofs : int
        The model's DOFs; the mesh must give as many.

    Returns
    -------
    (1, n_dofs) scipy.sparse.csr_matrix
        b, with b @ u = d . u(X) (m per m) and b^T P the nodal forces of a force P (N).

    Raises
    ------
    ValueError
        ``location`` not three finite numbers, a zero direction, a mesh that is not the model's
        (DOF count differs), or no cell of ``part`` holding the location.
    """
    from skfem import Basis, ElementVector

    from fem.solid import ELEMENTS, skfem_mesh

    X = np.asarray(location, dtype=float).reshape(-1)
    if X.shape != (3,) or not np.all(np.isfinite(X)):
        raise ValueError(f"location must be 3 finite numbers (m), got {location!r}")
    d = unit_direction(direction)
    mesh = skfem_mesh(points, hexes)
    basis = Basis(mesh, ElementVector(ELEMENTS[element]()), intorder=1)
    if basis.N != n_dofs:
        raise ValueError(f"the mesh gives {basis.N} DOFs, the model has {n_dofs}: not the model's mesh")
    x = (X + NUDGE * d)[:, None]
    try:
        cell = int(mesh.element_finder()(*x)[0])
    except ValueError:
        cell = -1
    if cell < 0 or cell_part[cell] != part:
        raise ValueError(f"location {tuple(float(v) for v in X)} m is not on the beam "
                         "(struck along the direction given)")
    P = basis.probes(x).tocsr()  # (3, N): rows are u_x, u_y, u_z at x
    return sp.csr_matrix(d @ P)


__all__ = ["channel_names", "AXES", "BEAM_SENSORS", "TUBE_SENSORS", "TIP_CELLS", "HAMMER_NODE", "sensor_node",
           "tip_node",
           "sensor_rows", "seat_rows", "unit_direction", "dominant_axis", "point_load_vector"]
