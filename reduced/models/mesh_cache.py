"""The hexahedral mesh of an assembly geometry, kept in the reduced-model cache folder.

Meshing the beam and box tube with gmsh (:func:`geometry.build.build_mesh`: OCC boolean fragments, then the
structured hexahedra) takes 1.7 s of CPU for the assembly and 0.3 s for the beam alone, and the main job meshed
the same few geometries 15 times: every ``reduce`` stage builds the 3-D model again to compare it with the cached
reduction (:func:`build_fe` here), and the hammer test's linear check builds it once more. The mesh
is a function of the geometry and of the code that meshes it, so :func:`cached_mesh` keeps its arrays
(``mesh-<key>.npz``, :func:`reduced.cache.cached_arrays`, uncompressed ``np.savez``: the stored bits are the
computed ones) under the sha256 of ``repr(g)`` (every dimension at full float precision), the source of
``geometry/*.py`` and gmsh's version. A hit returns the arrays a new meshing gives, bit for bit
(tests/test_mesh_cache.py), so every model assembled from it is the same.
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path

import numpy as np

from reduced.cache import cached_arrays

_SET = "set:"  # prefix of a node set's array in the entry


def mesh_key(g) -> str:
    """sha256 (hex) of what the mesh of ``g`` depends on: ``repr(g)``, geometry/*.py and gmsh's version.

    Parameters
    ----------
    g : geometry.params.AssemblyGeometry
        The geometry (a frozen dataclass: its repr holds every field, floats round-trip exactly).

    Returns
    -------
    str
        64 hex digits.
    """
    import gmsh

    import geometry

    h = hashlib.sha256(repr(g).encode())
    for f in sorted(Path(geometry.__file__).resolve().parent.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    h.update(str(gmsh.__version__).encode())
    return h.hexdigest()


def _arrays(mesh) -> dict[str, np.ndarray]:
    """The mesh as named arrays (node sets in their order)."""
    out = {"points": mesh.points, "hexes": mesh.hexes, "cell_part": mesh.cell_part,
           "part_names": np.array(mesh.part_names)}
    out.update({_SET + name: idx for name, idx in mesh.node_sets.items()})
    return out


def cached_mesh(g):
    """:func:`geometry.build.build_mesh` of ``g``, from the cache when it holds it (stored there when not).

    Parameters
    ----------
    g : geometry.params.AssemblyGeometry
        The geometry.

    Returns
    -------
    geometry.build.MeshData
        Points, hexahedra, parts and node sets as meshing gives them; ``wall_time_s`` is this call's (reading the
        entry, or meshing and storing it).
    """
    from geometry.build import MeshData, build_mesh
    from reduced.models.rom import cache_dir

    t0 = time.perf_counter()
    key = mesh_key(g)
    z = cached_arrays(cache_dir() / f"mesh-{key[:20]}.npz", key, lambda: _arrays(build_mesh(g)),
                      info={"kind": "hexahedral mesh", "geometry": repr(g)})
    return MeshData(points=z["points"], hexes=z["hexes"], cell_part=z["cell_part"],
                    part_names=tuple(str(s) for s in z["part_names"]),
                    node_sets={k[len(_SET):]: v for k, v in z.items() if k.startswith(_SET)},
                    wall_time_s=time.perf_counter() - t0)


def build_fe(spec):
    """:func:`reduced.models.rom.build_fe` with the mesh from :func:`cached_mesh`: the same model, bit for bit.

    (Here, not in rom.py, whose source keys the reduced-model and full-mode cache entries.)

    Parameters
    ----------
    spec : reduced.models.rom.RomSpec
        Its ``fe_model()`` says what to mesh.

    Returns
    -------
    fem.model.FESystem
        The assembled model.
    """
    from fem._pardiso import fixed_threads
    from fem.model import build_system

    model = spec.fe_model()
    with fixed_threads():
        return build_system(model, mesh=cached_mesh(model.geometry()))


__all__ = ["build_fe", "cached_mesh", "mesh_key"]
