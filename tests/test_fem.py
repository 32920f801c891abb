"""3-D model: closed forms, invariants, the rigid body on springs, labels, MAC/UFF, the CLI."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import eigh

from fem.analysis import CENTRE, analyse
from fem.labels import COMPONENT_LABELS, label_modes
from fem.mac import mac, read_uff55, write_uff55
from fem.material import Material
from fem.modal import modal_analysis
from fem.model import AssemblyModel, build_system, spring_with_seat
from fem.solid import assemble_solid
from fem.springs import CoilSpring, rbe3_map, rigid_modes, spring_element
from geometry.build import build_mesh

COARSE = 0.3  # m, element size: one element per block along x; the pseudo-rigid modes are
#               mesh-independent to 1e-5 (results/assembly-modal/mesh_convergence.csv)


# -- the free-free bar against Timoshenko ----------------------------------------------------
def _bar_modes(element: str, size: float):
    g = replace(AssemblyModel(layout="beam-free").geometry(), L=0.05, beam_length=0.2, beam_width=0.02,
                beam_height=0.02, seat_diameter=0.01, element_size=size, section_layers=2)
    mesh = build_mesh(g)
    steel = Material(E=210e9, nu=0.3, rho=7850.0)
    s = assemble_solid(mesh.points, mesh.hexes, [(mesh.part_cells("beam"), steel)], element)
    return modal_analysis(s.K, s.M, n_modes=8, shift_hz=100.0).freq_hz


@pytest.fixture(scope="module")
def bar_hex20():
    return _bar_modes("hex20", 0.01)


def test_free_free_bar_first_bending_matches_timoshenko(bar_hex20):
    # REFERENCES.md: Timoshenko (Cowper shear factor) 2568.1 Hz, Euler-Bernoulli 2658.3 Hz.
    # The 3-D solid differs from Timoshenko beam theory by its cross-section warping and
    # Poisson coupling, a few tenths of a percent at l/h = 10; the mesh (20 x 4 x 2
    # serendipity hexahedra) adds < 0.1 %. 0.5 % separates this cleanly from Euler-Bernoulli (+3.5 %).
    f = bar_hex20
    assert np.all(f[:6] < 1.0), f"six rigid-body modes expected near 0 Hz, got {f[:6]}"
    pair = f[6:8]
    assert pair[1] - pair[0] < 1e-3 * pair[0], "square section: the two first bending modes coincide"
    err = (pair[0] - 2568.1) / 2568.1
    assert abs(err) < 5e-3, f"first bending {pair[0]:.1f} Hz, {100 * err:+.2f} % from Timoshenko"


def test_linear_hexahedra_lock_in_bending(bar_hex20):
    # element-order study in miniature: on the same mesh the trilinear hexahedron is far too
    # stiff (shear locking: +4.4 % against +0.04 % for the 20-node serendipity element)
    f8 = _bar_modes("hex8", 0.01)
    err8 = (f8[6] - 2568.1) / 2568.1
    err20 = abs(bar_hex20[6] - 2568.1) / 2568.1
    assert err8 > 0.03 and err8 > 10 * err20, f"hex8 {100 * err8:.1f} %, hex20 {100 * err20:.2f} %"


# -- invariants ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def free_beam():
    return build_system(AssemblyModel(layout="beam-free", element_size=COARSE))


@pytest.fixture(scope="module")
def assembly_no_bungees():
    return build_system(AssemblyModel(element_size=COARSE, bungee_kz=1e-12, bungee_kxy=1e-12))


def _rigid(system, dofs=None):
    dofs = np.arange(system.n_dofs) if dofs is None else dofs
    return system.rigid_modes(dofs, CENTRE)


def test_mass_matrix_holds_the_mass(free_beam, assembly_no_bungees):
    for system, mass in ((free_beam, 2.516),
                         (assembly_no_bungees, 2.516 + 13.47 + 4 * 0.08)):
        m = system.model
        mass = m.beam_mass + (m.tube_mass + 4 * m.tip_mass if m.layout == "assembly" else 0.0)
        for c in range(3):
            one = (system.solid.dof_component == c).astype(float)
            assert one @ system.M @ one == pytest.approx(mass, rel=1e-10)


def test_stiffness_annihilates_rigid_motion(free_beam, assembly_no_bungees):
    # no spurious stiffness: the RBE3 seats and the condensed seat springs are unstressed
    # by a rigid motion of the whole model
    for system in (free_beam, assembly_no_bungees):
        P = _rigid(system)
        scale = abs(system.K).max() * np.abs(P).max() * np.sqrt(system.n_dofs)
        assert np.linalg.norm(system.K @ P, axis=0).max() < 1e-10 * scale


def test_rigid_mass_properties_of_the_beam(free_beam):
    m = free_beam.model
    b, h = m.beam_section
    l = m.beam_length
    P = _rigid(free_beam)
    Mrb = P.T @ free_beam.M @ P
    I = m.beam_mass / 12 * np.diag([b * b + h * h, l * l + h * h, l * l + b * b])
    expected = np.block([[m.beam_mass * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), I]])
    np.testing.assert_allclose(Mrb, expected, rtol=1e-9, atol=1e-12 * m.beam_mass)


def test_rigid_body_on_springs_matches_the_6x6_problem():
    # the beam on its grounded springs: the six lowest modes against the 6x6 problem
    # (Phi^T K Phi) q = omega^2 (Phi^T M Phi) q of its rigid-body modes (REFERENCES.md).
    # Rayleigh-Ritz makes the 6x6 values upper bounds; the beam's own flexibility lowers
    # the FE values by ~(f / f_elastic)^2 x coupling, measured 1.6e-4 at most here (a beam
    # made 100 times stiffer agrees to the 1e-5 noise of the solves, condition ~1e12)
    system = build_system(AssemblyModel(layout="beam-grounded", element_size=COARSE, beam_length=0.45))
    P = _rigid(system)
    lam6 = eigh(P.T @ system.K @ P, P.T @ system.M @ P, eigvals_only=True)
    f6 = np.sqrt(lam6) / (2 * np.pi)
    fe = modal_analysis(system.K, system.M, n_modes=6, shift_hz=1.0).freq_hz
    rel = (fe - f6) / f6
    assert np.all(rel < 5e-6), f"FE above the Rayleigh-Ritz bound: {rel}"
    assert np.all(rel > -5e-4), f"FE too far below the rigid-body values: {rel}"


# -- springs and couplings ---------------------------------------------------------------
def test_coil_spring_element_keeps_the_paper_axial_stiffness():
    s = CoilSpring(8.03e3, 0.018, 0.04)
    a, b = np.zeros(3), np.array([0.0, 0.0, 0.04])
    K = spring_element(s, a, b)
    # axial: pull the b end along z, a fixed, rotations free
    free = [8]
    assert K[np.ix_(free, free)][0, 0] == pytest.approx(8.03e3, rel=1e-12)
    # guided lateral stiffness (both ends clamped) equals 1 / (l^3 / (12 EI) + l / GA)
    assert K[6, 6] == pytest.approx(s.k_lateral, rel=1e-12)
    # rotating both ends as a rigid body costs nothing
    P = np.vstack([rigid_modes(np.array([a]), a), np.zeros((3, 6)), rigid_modes(np.array([b]), a)])
    P = np.vstack([rigid_modes(np.array([a]), a)[:3], np.hstack([np.zeros((3, 3)), np.eye(3)]),
                   rigid_modes(np.array([b]), a)[:3], np.hstack([np.zeros((3, 3)), np.eye(3)])])
    assert np.abs(K @ P).max() < 1e-9 * np.abs(K).max()


def test_stiff_seat_is_the_clamped_spring():
    s = CoilSpring(8.03e3, 0.018, 0.04)
    a, b = np.zeros(3), np.array([0.0, 0.0, 0.04])
    np.testing.assert_allclose(spring_with_seat(s, a, b, np.full(3, 1e12)), spring_element(s, a, b),
                               rtol=1e-6, atol=1e-6 * np.abs(spring_element(s, a, b)).max())


def test_rbe3_is_exact_for_rigid_motion():
    rng = np.random.default_rng(1)
    X = rng.uniform(-0.01, 0.01, (9, 3))
    T, c = rbe3_map(X)
    q = rng.standard_normal(6)
    u = rigid_modes(X, c) @ q
    np.testing.assert_allclose(T @ u, q, atol=1e-12)


# -- labels ------------------------------------------------------------------------------
def test_labels_find_shuffled_pure_rigid_motions(free_beam):
    bd = np.arange(free_beam.n_dofs)
    P = _rigid(free_beam, bd)
    order = np.array([4, 0, 5, 2, 1, 3])
    rng = np.random.default_rng(2)
    phi = np.hstack([rng.standard_normal((free_beam.n_dofs, 3)) * 1e-3, P[:, order]])
    lab = label_modes(phi, free_beam.M, bd, P)
    for k, comp in enumerate(order):
        assert lab.mode_index[COMPONENT_LABELS[comp]] == 3 + k
        assert lab.purity(COMPONENT_LABELS[comp]) > 0.99


def test_labels_of_the_grounded_beam_follow_the_closed_form():
    # springs above and below at (+-L, 0, +-h/2), symmetric: the six motions decouple, and
    # the bounce frequency is exactly sqrt(4 k_s / m) / 2 pi for the rigid part (17.98 Hz)
    a = analyse(AssemblyModel(layout="beam-grounded", element_size=COARSE), n_modes=12)
    m = a.system.model
    f_bounce = np.sqrt(4 * m.k_s / m.beam_mass) / (2 * np.pi)
    assert a.modes.freq_hz[a.labels.mode_index["bounce"]] == pytest.approx(f_bounce, rel=2e-3)
    for name in COMPONENT_LABELS:
        assert a.labels.purity(name) > 0.95, name


# -- MAC and UFF -----------------------------------------------------------------------------
def test_uff_round_trip_gives_mac_one(tmp_path):
    rng = np.random.default_rng(3)
    shapes = rng.standard_normal((30, 6))
    path = tmp_path / "modes.uff"
    write_uff55(path, np.arange(1, 11), np.linspace(10, 35, 6), shapes)
    nodes, freq, back = read_uff55(path)
    np.testing.assert_array_equal(nodes, np.arange(1, 11))
    np.testing.assert_allclose(freq, np.linspace(10, 35, 6), rtol=1e-6)
    np.testing.assert_allclose(np.diag(mac(shapes, back)), 1.0, atol=1e-9)


def test_mac_is_one_for_parallel_zero_for_orthogonal():
    A = np.eye(4)[:, :2]
    np.testing.assert_allclose(mac(A, np.column_stack([-3 * A[:, 0], A[:, 1]])), np.eye(2))


# -- scene, stage and CLI ------------------------------------------------------------------
SCENE = """
description = "coarse assembly for the test suite"
[model]
kind = "assembly"
element_size = 0.3
[modal]
n_modes = 13
pictures = {pictures}
test_shapes = "{shapes}"
"""


def test_cli_modal_writes_the_correlation_files(tmp_path):
    from bearingshaft.cli import main

    scene = tmp_path / "coarse.toml"
    scene.write_text(SCENE.format(pictures="true", shapes=""))
    out = tmp_path / "out"
    assert main(["modal", "--scene", str(scene), "--out", str(out), "--no-progress"]) == 0
    for name in ("frequencies.csv", "mac_beam.csv", "mac_assembly.csv", "mac.png", "modes.vtu",
                 "mode_shapes.png", "fe_shapes.uff", "provenance.json"):
        assert (out / name).exists(), name
    lines = (out / "frequencies.csv").read_text().splitlines()
    assert lines[0] == "mode,description,freq_hz,test_hz,error_pct"
    labels = [ln.split(",")[1] for ln in lines[1:]]
    assert labels == ["longitudinal", "lateral", "yaw", "bounce", "pitch", "roll"]
    assert "no test shapes" in (out / "mac_beam.csv").read_text()
    # the FE shapes read back as "test" shapes correlate perfectly with themselves
    scene.write_text(SCENE.format(pictures="false", shapes=str(out / "fe_shapes.uff")))
    out2 = tmp_path / "out2"
    assert main(["modal", "--scene", str(scene), "--out", str(out2), "--no-progress"]) == 0
    rows = (out2 / "mac_assembly.csv").read_text().splitlines()[2:]
    diag = [float(r.split(",")[1 + i]) for i, r in enumerate(rows)]
    assert min(diag) > 0.9999


def test_scene_refuses_modal_on_the_discrete_model():
    from bearingshaft.scenes import SceneError, parse_scene

    with pytest.raises(SceneError, match="needs a 3-D model"):
        parse_scene('[model]\nkind = "discrete"\n[modal]\n', "x", "x.toml")
    with pytest.raises(SceneError, match="takes only a \\[modal\\]"):
        parse_scene('[model]\nkind = "assembly"\n[ringdown]\n', "x", "x.toml")
    scene = parse_scene('[model]\nkind = "assembly"\nlayout = "beam-free"\n[modal]\n', "x", "x.toml")
    assert scene.stages == ("modal",)


def test_beam_section_matches_the_mass_and_kappa_of_the_paper():
    # A = m / (rho l) and E I = 2 kappa L / 3: the mid-span stiffness 6 EI / L^3 of the beam
    # simply supported at +-L equals the 3-DOF model's 4 kappa / L^2 (fem.model docstring)
    m = AssemblyModel()
    b, h = m.beam_section
    assert m.rho * b * h * m.beam_length == pytest.approx(2.516, rel=1e-12)
    EI = m.E * b * h**3 / 12
    assert 6 * EI / m.L**3 == pytest.approx(4 * m.kappa / m.L**2, rel=1e-12)
    assert h > 0 and b > m.coil_diameter
