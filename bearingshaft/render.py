"""Displacement shapes on the 3-D mesh rendered off screen (pyvista; matplotlib as fallback).

Each panel is the deformed mesh coloured by |u| over the largest |u| of the shape, the undeformed
outline in black lines and an axis triad, rendered by pyvista off screen; matplotlib lays the
panels out with their titles and one colour bar. Each shape is drawn at its own scale
(:func:`drawing_scale`): a translation shows as a visible shift of the part that moves, a
rotation is not exaggerated past a small angle.

A rendered figure is kept in the reduced-model cache folder (``shapes-<key>.png``, :mod:`reduced.cache`) under
the hash of everything it is drawn from (:func:`figure_key`), and copied from there when the same figure is asked
for again: the scenes that share a reduction draw the same ``gap_modes.png``, and rendering one (pyvista and
matplotlib) takes 2-3 s of CPU. A figure drawn by the matplotlib fallback is not kept.
"""

from __future__ import annotations

import hashlib
from itertools import combinations
from pathlib import Path

import numpy as np

SIZE_FRACTION = 0.08  # the largest displacement is drawn as this fraction of the model's largest extent ...
MAX_GRADIENT = 0.3  # ... unless an element would then turn or stretch by more than this (rad, or strain)
PANEL_PX = (720, 440)  # pixels of one rendered panel
COLOUR_LABEL = "|u| / largest |u| of the mode (every part, one scale)"


def drawing_scale(points: np.ndarray, hexes: np.ndarray, u: np.ndarray, size_fraction: float = SIZE_FRACTION,
                  max_gradient: float = MAX_GRADIENT) -> float:
    """The factor s a shape is drawn at: x + s u.

    s max|u| = size_fraction x (the model's largest extent), lowered where needed so that no element
    turns or stretches by more than ``max_gradient``: s max |u_i - u_j| / |x_i - x_j| <= max_gradient
    over every pair of corners of every cell (for a rigid rotation by theta the ratio is at most
    theta; for a translation it is 0).

    Parameters
    ----------
    points : (n_nodes, 3) ndarray of float
        m, the mesh's nodes.
    hexes : (n_cells, 8) ndarray of int
        The cells' corner nodes.
    u : (n_nodes, 3) ndarray of float
        The shape (any units: a mode shape's amplitude is arbitrary).
    size_fraction : float
        The largest displacement drawn, as a fraction of the model's largest extent.
    max_gradient : float
        The largest rotation (rad) or stretch of an element drawn.

    Returns
    -------
    float
        s (m per unit of u); 0 for a zero shape.

    Examples
    --------
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    >>> cells = np.arange(8)[None, :]
    >>> round(drawing_scale(pts, cells, np.tile([2.0, 0.0, 0.0], (8, 1))), 12)  # a translation: 8 % of 1 m over 2
    0.04
    """
    umax = float(np.max(np.linalg.norm(u, axis=1))) if u.size else 0.0
    if umax == 0.0:
        return 0.0
    extent = float(np.max(np.ptp(points, axis=0)))
    s = size_fraction * extent / umax
    grad = 0.0
    for i, j in combinations(range(hexes.shape[1]), 2):
        a, b = hexes[:, i], hexes[:, j]
        dx = np.linalg.norm(points[a] - points[b], axis=1)
        du = np.linalg.norm(u[a] - u[b], axis=1)
        ok = dx > 0
        if np.any(ok):
            grad = max(grad, float(np.max(du[ok] / dx[ok])))
    if grad * s > max_gradient:
        s = max_gradient / grad
    return s


def render_shapes(fe, shapes: list[tuple[str, np.ndarray]], path: str | Path, columns: int = 3) -> str:
    """Render ``shapes`` ([(title, (n_dofs,) displacement)]) in a grid; returns the renderer used.

    Every panel: the deformed mesh coloured by |u| / max |u| of that shape (the see-through parts,
    such as the tube, too), the undeformed outline (black lines), an axis triad, and in its title
    the largest displacement as drawn (mm) and each part's largest |u| against the shape's largest.
    Each shape is scaled by :func:`drawing_scale`. One colour bar serves every panel.

    Parameters
    ----------
    fe : FESystem
        The assembled model (mesh, nodal DOF map).
    shapes : list of (str, ndarray)
        (title, (n_dofs,) displacement vector) per panel.
    path : str or Path
        The image file.
    columns : int
        Panels a row.

    Returns
    -------
    str
        'pyvista', or 'matplotlib (pyvista failed: <why>)' when the fallback drew point clouds.
    """
    from reduced.cache import load_entry, write_entry
    from reduced.models.rom import cache_dir

    key = figure_key(fe, shapes, columns)
    entry = cache_dir() / f"shapes-{key[:20]}.png"
    png = load_entry(entry, key, lambda f: f.read())
    if png is not None:  # drawn before from the same inputs: the same bytes
        Path(path).write_bytes(png)
        return "pyvista"
    mesh = fe.mesh
    dofs = fe.solid.nodal_dofs  # (3, n_nodes)
    fields = [(title, np.asarray(u)[dofs].T) for title, u in shapes]
    panels = [panel(mesh, title, u) for title, u in fields]
    try:
        images = _pyvista_images(mesh, panels)
        renderer = "pyvista"
    except Exception as exc:  # no OpenGL context: fall back, and say so in the stats
        images = None
        renderer = f"matplotlib (pyvista failed: {exc})"
    fig = layout(mesh, panels, images, columns)
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    if images is not None:
        try:  # a cache that cannot be written: rendered again next time
            write_entry(entry, lambda f: f.write(Path(path).read_bytes()), key, info={"kind": "mode shapes figure"})
        except OSError:
            pass
    return renderer


def _hash_array(h, a) -> None:
    a = np.ascontiguousarray(a)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())


def figure_key(fe, shapes: list[tuple[str, np.ndarray]], columns: int = 3) -> str:
    """sha256 (hex) of everything :func:`render_shapes` draws from: the mesh's nodes and cells, each part's cells
    and nodes, the nodal DOF map, every shape's title and values (bit for bit), the panels a row, this module's
    source (the drawing, its sizes and dpi) and the versions of the libraries that draw (pyvista, VTK,
    matplotlib, Pillow, NumPy) with matplotlib's settings (but the backend's: every figure is drawn by Agg).

    Parameters
    ----------
    fe : FESystem
        The assembled model (mesh, nodal DOF map).
    shapes : list of (str, ndarray)
        (title, (n_dofs,) displacement vector) per panel.
    columns : int
        Panels a row.

    Returns
    -------
    str
        64 hex digits.
    """
    import importlib.metadata as md

    import matplotlib

    h = hashlib.sha256(Path(__file__).read_bytes())
    mesh = fe.mesh
    _hash_array(h, mesh.points)
    _hash_array(h, mesh.hexes)
    _hash_array(h, fe.solid.nodal_dofs)
    for p in mesh.part_names:
        h.update(repr(p).encode())
        _hash_array(h, mesh.part_cells(p))
        _hash_array(h, mesh.part_nodes(p))
    for title, u in shapes:
        h.update(repr(title).encode())
        _hash_array(h, np.asarray(u, dtype=float))
    h.update(repr(columns).encode())
    for lib in ("pyvista", "vtk", "matplotlib", "pillow", "numpy"):
        try:
            h.update(f"{lib} {md.version(lib)}".encode())
        except md.PackageNotFoundError:
            h.update(f"{lib} absent".encode())
    settings = {k: v for k, v in matplotlib.rcParams.items() if not k.startswith("backend") and k != "interactive"}
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()


def panel(mesh, title: str, u: np.ndarray) -> dict:
    """What one panel draws: the shape ``u`` (n_nodes, 3), its scale (:func:`drawing_scale`), ``mag``
    = |u| / max |u|, and a title with the largest displacement drawn (mm) and each part's largest |u|.

    Parameters
    ----------
    mesh : the model's mesh (points, hexes, parts)
    title : the shape's name
    u : (n_nodes, 3) the shape at the mesh's nodes
    """
    s = drawing_scale(mesh.points, mesh.hexes, u)
    mag = np.linalg.norm(u, axis=1)
    top = float(mag.max()) or 1.0
    share = ", ".join(f"{p} {float(mag[mesh.part_nodes(p)].max()) / top:.2f}" for p in mesh.part_names)
    head = f"{title}\nlargest displacement drawn as {1e3 * s * top:.3g} mm\nlargest |u| of each part: {share}"
    return {"u": u, "scale": s, "mag": mag / top, "title": head}


def _pyvista_images(mesh, panels: list[dict]) -> list[np.ndarray]:
    """One off-screen pyvista image per panel (RGB arrays)."""
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
    outlines = {p: g.extract_surface(algorithm="dataset_surface").extract_feature_edges(
        feature_angle=30.0, boundary_edges=True, non_manifold_edges=False, manifold_edges=False)
        for p, g in grids.items()}
    # the innermost part (the smallest) drawn solid, the others see-through so that it shows
    solid = min(mesh.part_names, key=lambda p: float(np.prod(np.ptp(mesh.points[mesh.part_nodes(p)], axis=0))))
    images = []
    for panel in panels:
        pl = pv.Plotter(off_screen=True, window_size=PANEL_PX)
        pl.set_background("white")
        for part, grid in grids.items():
            g = grid.copy()
            g.points = mesh.points + panel["scale"] * panel["u"]
            g["|u|"] = panel["mag"]
            surf = g.extract_surface(algorithm="dataset_surface")
            see_through = part != solid
            pl.add_mesh(surf, scalars="|u|", cmap="viridis", clim=(0.0, 1.0), show_scalar_bar=False,
                        opacity=0.3 if see_through else 1.0)
            pl.add_mesh(outlines[part], color="black", line_width=1.0 if see_through else 1.5,
                        opacity=0.35 if see_through else 1.0)
        pl.add_axes(interactive=False, line_width=3, viewport=(0.0, 0.0, 0.22, 0.3))
        pl.camera_position = "iso"
        pl.camera.zoom(1.3)
        images.append(pl.screenshot(return_img=True))
        pl.close()
    return images


def layout(mesh, panels: list[dict], images, columns: int):
    """The panels in a grid with their titles and one colour bar (point clouds when ``images`` is None).

    Parameters
    ----------
    mesh : the model's mesh (points; the fallback draws them)
    panels : one dict per shape: ``u`` (n_nodes, 3), ``scale``, ``mag`` (n_nodes,) |u| / max |u|, ``title``
    images : one RGB array per panel (pyvista's), or None for the point-cloud fallback
    columns : panels a row

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    n = len(panels)
    columns = max(1, min(columns, n))
    rows = -(-n // columns)
    fig = plt.figure(figsize=(5.2 * columns + 1.0, 3.8 * rows + 0.4), constrained_layout=True)
    axes = []
    for k, panel in enumerate(panels):
        if images is not None:
            ax = fig.add_subplot(rows, columns, k + 1)
            ax.imshow(images[k])
            ax.set_axis_off()
        else:
            ax = fig.add_subplot(rows, columns, k + 1, projection="3d")
            X0 = mesh.points[::5]
            X = (mesh.points + panel["scale"] * panel["u"])[::5]
            ax.scatter(*X0.T, s=0.3, c="0.6")
            ax.scatter(*X.T, s=1.5, c=panel["mag"][::5], cmap="viridis", vmin=0.0, vmax=1.0)
            ax.set_xlabel("x [m]", fontsize=7)
            ax.set_ylabel("y [m]", fontsize=7)
            ax.set_zlabel("z [m]", fontsize=7)
            ax.tick_params(labelsize=6)
        ax.set_title(panel["title"], fontsize=9)
        axes.append(ax)
    fig.colorbar(ScalarMappable(Normalize(0.0, 1.0), cmap="viridis"), ax=axes, shrink=0.6, label=COLOUR_LABEL)
    note = ("black lines: the undeformed outline; see-through: the enclosing parts; triad: the model's x, y, z"
            if images is not None else "grey: undeformed nodes (pyvista could not render)")
    fig.suptitle(f"Mode shapes, each drawn at its own scale ({note})", fontsize=10)
    return fig
