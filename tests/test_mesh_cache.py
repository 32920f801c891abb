"""The mesh cache (reduced.models.mesh_cache) returns the mesh gmsh gives, bit for bit, and so the same model."""

import numpy as np
import pytest

from fem.model import AssemblyModel, build_system
from geometry.build import build_mesh
from reduced.models.mesh_cache import cached_mesh, mesh_key


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))
    return tmp_path


def _same_mesh(a, b) -> None:
    for name in ("points", "hexes", "cell_part"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert a.part_names == b.part_names
    assert list(a.node_sets) == list(b.node_sets)  # the same sets in the same order
    for k in a.node_sets:
        assert a.node_sets[k].dtype == b.node_sets[k].dtype and np.array_equal(a.node_sets[k], b.node_sets[k]), k


def test_a_cached_mesh_is_the_mesh_gmsh_gives_and_assembles_the_same_model(cache):
    model = AssemblyModel(layout="beam-grounded", element_size=0.3)
    g = model.geometry()
    fresh = build_mesh(g)
    first = cached_mesh(g)  # a miss: meshed and stored
    assert len(list(cache.glob("mesh-*.npz"))) == 1
    second = cached_mesh(g)  # a hit: read back
    _same_mesh(fresh, first)
    _same_mesh(fresh, second)
    a, b = build_system(model, mesh=fresh), build_system(model, mesh=second)
    for name in ("K", "M"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x != y).nnz == 0 and x.data.tobytes() == y.data.tobytes(), name


def test_the_key_follows_every_dimension():
    g = AssemblyModel(layout="beam-grounded", element_size=0.3).geometry()
    other = AssemblyModel(layout="beam-grounded", element_size=0.3 * (1 + 1e-15)).geometry()
    assert mesh_key(g) == mesh_key(AssemblyModel(layout="beam-grounded", element_size=0.3).geometry())
    assert mesh_key(g) != mesh_key(other)


def test_the_reduce_stage_s_model_is_the_one_rom_builds(cache):
    """mesh_cache.build_fe (the reduce stage's, the mesh cached) against reduced.models.rom.build_fe (meshed)."""
    from reduced.models import mesh_cache, rom

    spec = rom.RomSpec(n_modes=2, element="hex8", element_size=0.5)
    a, b = rom.build_fe(spec), mesh_cache.build_fe(spec)
    c = mesh_cache.build_fe(spec)  # from the entry b stored
    for fe in (b, c):
        for name in ("K", "M"):
            x, y = getattr(a, name), getattr(fe, name)
            assert (x != y).nnz == 0 and x.data.tobytes() == y.data.tobytes(), name
        assert a.mesh.points.tobytes() == fe.mesh.points.tobytes()
