"""Geometry: named groups, meshed volumes against closed forms, validation before gmsh."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fem.model import AssemblyModel
from geometry.build import build_mesh
from geometry.params import AssemblyGeometry

COARSE = dict(element_size=0.08)


def geometry(**kwargs) -> AssemblyGeometry:
    """The apparatus as the model builds it (its one source of dimensions), coarsely meshed."""
    return replace(AssemblyModel().geometry(), **{**COARSE, **kwargs})


@pytest.fixture(scope="module")
def mesh():
    return build_mesh(geometry())


def test_every_named_group_exists_and_is_not_empty(mesh):
    g = geometry()
    assert mesh.part_names == ("beam", "tube")
    expected = [f"{p}_seat_{s}" for p in ("beam", "tube") for s in g.seat_centres("beam")]
    expected += [f"beam_contact_{s}" for s in g.seat_centres("beam")]
    expected += list(g.beam_sensors()) + list(g.tube_sensors()) + [f"bungee_{i}" for i in range(1, 5)]
    for name in expected:
        assert name in mesh.node_sets and len(mesh.node_sets[name]) > 0, name
    for name, xyz in {**g.beam_sensors(), **g.tube_sensors()}.items():
        # a sensor is one node exactly at its point (selection tolerance 1e-5 m > gmsh's 1e-7 padding)
        assert len(mesh.node_sets[name]) == 1
        np.testing.assert_allclose(mesh.points[mesh.node_sets[name][0]], xyz, atol=1e-9)


def test_meshed_volumes_equal_closed_forms(mesh):
    g = geometry()
    # trilinear hexahedra on straight blocks are exact: only round-off remains
    assert mesh.volume("beam") == pytest.approx(g.beam_volume, rel=1e-10)
    assert mesh.volume("tube") == pytest.approx(g.tube_volume, rel=1e-10)
    # beam mass at the paper's value with the section of fem.model
    assert 7850.0 * AssemblyModel().geometry().beam_volume == pytest.approx(2.516, rel=1e-12)


def test_three_hexahedra_through_the_tube_wall(mesh):
    g = geometry()
    top = g.tube_inner_height / 2
    p = mesh.points[mesh.part_nodes("tube")]
    # nodes on one vertical line through the top wall at a seat centre
    line = p[(np.abs(p[:, 0] - g.L) < 1e-9) & (np.abs(p[:, 1]) < 1e-9) & (p[:, 2] >= top - 1e-9)]
    assert len(np.unique(np.round(line[:, 2], 9))) == g.wall_layers + 1 >= 4


def test_only_the_parts_asked_for_are_built():
    m = build_mesh(geometry(parts=("beam",)))
    assert m.part_names == ("beam",)
    assert not any(k.startswith("tube") for k in m.node_sets)


def test_a_mesh_built_in_a_worker_thread_is_the_main_threads():
    """gmsh starts off the main thread too (a Dask task's thread: no Ctrl-C handler there), and two threads
    meshing at once take turns (one gmsh state per process): each mesh is bit for bit the main thread's."""
    import threading

    beam = geometry(parts=("beam",))  # the beam alone: cheaper, and gmsh's state is the same
    mesh = build_mesh(beam)
    built, errors = [], []

    def work() -> None:
        try:
            built.append(build_mesh(beam))
        except Exception as exc:  # reported below, in the test's thread
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert len(built) == 2
    for m in built:
        assert np.array_equal(m.points, mesh.points) and np.array_equal(m.hexes, mesh.hexes)
        assert m.node_sets.keys() == mesh.node_sets.keys()
        assert all(np.array_equal(m.node_sets[k], v) for k, v in mesh.node_sets.items())


def test_mesh_is_meshio_readable_with_tags(tmp_path, mesh):
    import meshio

    path = tmp_path / "assembly.vtu"
    mesh.write(path)
    back = meshio.read(path)
    assert back.cells_dict["hexahedron"].shape == mesh.hexes.shape
    np.testing.assert_array_equal(back.cell_data["part"][0], mesh.cell_part)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(tube_wall=-0.001), "tube_wall must be > 0"),
        (dict(tube_clearance_y=-0.01), "tube_clearance_y must be > 0"),
        (dict(tube_clearance_y=0.0), "tube_clearance_y must be > 0"),
        (dict(spring_length=0.0), "spring_length must be > 0"),
        (dict(beam_length=0.3), "must lie on the beam"),
        (dict(seat_diameter=0.03), "smaller than beam_width"),
        (dict(tube_wall=0.05), "too thick"),
        (dict(parts=("tube",)), "must include 'beam'"),
    ],
)
def test_bad_geometry_is_refused_before_gmsh_runs(monkeypatch, kwargs, message):
    import gmsh

    def boom(*a, **k):
        raise AssertionError("gmsh was started for an invalid geometry")

    monkeypatch.setattr(gmsh, "initialize", boom)
    with pytest.raises(ValueError, match=message):
        build_mesh(geometry(**kwargs))


def test_model_refuses_a_beam_inside_which_the_seats_do_not_fit():
    with pytest.raises(ValueError, match="must lie on the beam"):
        AssemblyModel(beam_length=0.3)
    with pytest.raises(ValueError, match="tube_mass must be > 0"):
        AssemblyModel(tube_mass=-1.0)


def test_the_mesh_has_the_dimensions_of_the_model_that_asked_for_it():
    # one source of truth: the beam meshed is the model's (length from the calibration, section
    # from its mass and kappa), not a second set of nominal dimensions in geometry.params
    m = AssemblyModel(layout="beam-free", element_size=0.1)
    b, h = m.beam_section
    p = build_mesh(m.geometry()).points
    np.testing.assert_allclose(np.ptp(p, axis=0), [m.beam_length, b, h], rtol=1e-9)
    with pytest.raises(TypeError, match="required keyword-only"):
        AssemblyGeometry(element_size=0.1)  # no dimensions of its own to fall back on


@pytest.mark.parametrize("kwargs", [dict(), dict(parts=("beam",))])
def test_the_glued_fragment_gives_the_general_fragments_mesh_bit_for_bit(monkeypatch, kwargs):
    """geometry.build.OCC_GLUE (OCC's full glue, for blocks that only share whole faces) changes the time of the
    fragment, never the mesh: points, hexahedra, parts and every named node set as the general fragment's."""
    import geometry.build as gb

    g = geometry(**kwargs)
    glued = build_mesh(g)
    monkeypatch.setattr(gb, "OCC_GLUE", 0)
    plain = build_mesh(g)
    assert gb.OCC_GLUE == 0 and glued.points.shape == plain.points.shape
    assert np.array_equal(glued.points, plain.points) and np.array_equal(glued.hexes, plain.hexes)
    assert np.array_equal(glued.cell_part, plain.cell_part) and glued.part_names == plain.part_names
    assert glued.node_sets.keys() == plain.node_sets.keys()
    assert all(np.array_equal(glued.node_sets[k], v) for k, v in plain.node_sets.items())
