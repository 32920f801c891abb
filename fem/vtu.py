"""VTU files of displacement fields on the 3-D mesh, for ParaView."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_vtu(fe, fields: dict[str, np.ndarray], path: str | Path) -> None:
    """Write ``fields`` ({name: (n_dofs,) displacement vector}) as nodal vectors on the hex mesh.

    Only the corner nodes carry points in the file (the mesh's hexahedra); higher-order DOFs
    are left out. The cell data ``part`` numbers the solid parts.

    Parameters
    ----------
    fe : FESystem
        The assembled model (mesh and nodal DOF map).
    fields : dict of str to (n_dofs,) ndarray of float
        Name -> displacement vector (e.g. a mode shape), written as float32 point vectors.
    path : str or Path
        The .vtu file.

    Returns
    -------
    None
    """
    import meshio

    mesh = fe.mesh
    dofs = fe.solid.nodal_dofs  # (3, n_nodes)
    data = {name: np.asarray(u)[dofs].T.astype(np.float32) for name, u in fields.items()}
    meshio.Mesh(mesh.points.astype(np.float32), [("hexahedron", mesh.hexes.astype(np.int32))],
                point_data=data, cell_data={"part": [mesh.cell_part.astype(np.int32)]}).write(str(path))
