"""Displacement shapes on the 3-D mesh rendered off screen (pyvista; matplotlib as fallback)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def render_shapes(fe, shapes: list[tuple[str, np.ndarray]], path: str | Path, columns: int = 3) -> str:
    """Render ``shapes`` ([(title, (n_dofs,) displacement)]) in a grid; returns the renderer used.

    The largest beam displacement of each shape is drawn as 40 % of the beam's smaller side:
    translations show without turning a roll into radians. The tube is drawn see-through.

    Parameters
    ----------
    fe : FESystem
        The assembled model (mesh, nodal DOF map, beam section).
    shapes : list of (str, ndarray)
        (title, (n_dofs,) displacement vector) per panel.
    path : str or Path
        The image file.
    columns : int
        Panels a row.

    Returns
    -------
    str
        'pyvista', or 'matplotlib (pyvista failed: <why>)' when the fallback drew a point cloud
        (each shape then scaled to 8 % of the mesh's extent).
    """
    mesh = fe.mesh
    dofs = fe.solid.nodal_dofs  # (3, n_nodes)
    fields = [(title, np.asarray(u)[dofs].T) for title, u in shapes]
    rows = -(-len(fields) // columns)
    try:
        import pyvista as pv

        pv.OFF_SCREEN = True
        # VTK probes for an X display before falling back to off-screen rendering and
        # prints a warning that means nothing here
        import vtk

        vtk.vtkObject.GlobalWarningDisplayOff()

        def part_grid(part):
            hexes = mesh.hexes[mesh.part_cells(part)]
            cells = np.hstack([np.full((len(hexes), 1), 8), hexes]).ravel()
            return pv.UnstructuredGrid(cells, np.full(len(hexes), pv.CellType.HEXAHEDRON), mesh.points)

        grids = {p: part_grid(p) for p in mesh.part_names}
        pl = pv.Plotter(off_screen=True, shape=(rows, columns), window_size=(500 * columns, 450 * rows))
        for k, (title, u) in enumerate(fields):
            ub = u[mesh.part_nodes("beam")]
            scale = 0.4 * min(fe.model.beam_section) / max(np.abs(ub).max(), 1e-300)
            pl.subplot(k // columns, k % columns)
            for part, grid in grids.items():
                g = grid.copy()
                g.points = mesh.points + scale * u
                g["|u|"] = np.linalg.norm(u, axis=1)
                surf = g.extract_surface(algorithm="dataset_surface")
                if part == "beam":
                    pl.add_mesh(surf, scalars="|u|", cmap="viridis", show_scalar_bar=False,
                                clim=(0.0, float(np.linalg.norm(ub, axis=1).max())))
                else:  # the tube see-through, so that the beam inside shows
                    pl.add_mesh(surf, color="lightgrey", opacity=0.15, show_edges=False)
            pl.add_text(title, font_size=10)
            pl.camera_position = "iso"
            pl.camera.zoom(1.3)
        pl.screenshot(str(path))
        pl.close()
        return "pyvista"
    except Exception as exc:  # no OpenGL context: fall back, and say so in the stats
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(5 * columns, 4.5 * rows))
        for k, (title, u) in enumerate(fields):
            X = mesh.points + 0.08 * np.ptp(mesh.points) / np.abs(u).max() * u
            ax = fig.add_subplot(rows, columns, k + 1, projection="3d")
            ax.scatter(*X[::7].T, s=1, c=np.linalg.norm(u, axis=1)[::7])
            ax.set_title(title)
        fig.savefig(path, dpi=100)
        plt.close(fig)
        return f"matplotlib (pyvista failed: {exc})"
