"""NNMs of the reduced model (scene rom-fep): HB backbones, shooting, stability and the fep stage.

The reduced model is rom-fep's (beam-grounded, 10 planar modes: 12 coordinates), from the
model cache (built once, about 8 s, if absent).
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from beam_reference import timoshenko_beam_hz  # tests/beam_reference.py

from bearingshaft.output import StageWriter
from bearingshaft.registry import stages_of
from bearingshaft.scenes import load_scene, parse_scene
from bearingshaft.stages.nnm import nnm_stage
from bearingshaft.stages.nnm_fep import fep_model
from reduced.models.discrete import DiscreteParams
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.periodic import nnm2
from reduced.periodic.backbones import START_FRACTION, grazing_amplitude, hb_point_at_energy, nnm_branch
from reduced.periodic.hb import HarmonicBalance, NNMResidual
from reduced.periodic.shooting import conservative, shoot
from reduced.periodic.stability import hill
from reduced.transient.flow import Flow


@pytest.fixture(scope="module")
def fm():
    return fep_model(load_scene("rom-fep"))


def test_the_nnms_followed_are_the_open_gap_modes_that_move_the_gaps(fm):
    assert fm.kind == "rom" and fm.exact is None and fm.system.n == 12 and fm.system.undamped
    assert fm.modes == (0, 1, 2)  # heave, pitch, first coupled bending, as the 3-DOF model's three
    assert tuple(gap_moving_modes(fm.system, "open", 3)) == fm.modes
    f = linear_modes(fm.system, "open").freq_hz[list(fm.modes)]
    assert f == pytest.approx([17.98, 23.02, 731.36], abs=0.01)  # regression guard only (gap_modes.csv)
    # independent references (tests/beam_reference.py): heave in closed form, sqrt(4 k_s / m) for four
    # axial springs (the reduction is a Rayleigh-Ritz upper bound of the full model, which the beam's
    # flexibility puts 1.8e-4 below the rigid value: 5e-4 allowed); pitch and first bending against the
    # beam as a 1-D Timoshenko beam on point springs, which has no coil bending and no seat rotation
    # springs, both stiffening the pitch (measured +0.75 %; [0, +1.5 %] allowed), and a mesh one element
    # long between the seats, stiffening the bending (measured +4.1 %; [-0.5 %, +9 %] as in test_rom)
    model = load_scene("rom-fep").model.fe_model()
    heave = np.sqrt(4 * model.k_s / model.beam_mass) / (2 * np.pi)
    assert -5e-4 < f[0] / heave - 1 < 1e-6, f[0] / heave - 1
    beam = timoshenko_beam_hz(model)
    assert 0.0 < f[1] / beam[1] - 1 < 0.015, (f[1], beam[1])
    assert -5e-3 < f[2] / beam[2] - 1 < 0.09, (f[2], beam[2])
    # the 3-DOF model: the same three NNMs, and its exact NNM 2 relation as the reference
    d = fep_model(load_scene("discrete-fep"))
    assert d.kind == "discrete" and d.modes == (0, 1, 2) and d.exact.nnm == 1
    p = DiscreteParams()
    assert d.exact.freq_hz(np.array([0.1, 10.0])) == pytest.approx(nnm2.frequency_from_energy(p, [0.1, 10.0]))
    assert d.shooting == {} and d.branch == {} and d.hill == {}  # discrete-fep as it was


@pytest.mark.parametrize("H", [1, 5])
@pytest.mark.parametrize("k", [0, 1, 2])
def test_rom_backbone_starts_at_the_linear_open_gap_frequency(fm, k, H):
    """Below the grazing energy the HB orbit is the linear open-gap mode: its frequency is the
    mode's to round-off, for every H, until the mode first touches a stop."""
    mode = fm.modes[k]
    lin = linear_modes(fm.system, "open")
    omega = float(lin.omega[mode])
    E_graze = 0.5 * omega**2 * grazing_amplitude(fm.system, lin.phi[:, mode]) ** 2  # J, linear modal energy
    b = nnm_branch(fm.system, mode, H=H, energy_max_J=3.0 * E_graze, **fm.branch)
    assert b.energy_J[0] == pytest.approx(START_FRACTION**2 * E_graze, rel=1e-9)
    below = b.energy_J < 0.99 * E_graze
    assert below.sum() >= 2
    assert b.freq_hz[below] == pytest.approx(lin.freq_hz[mode], rel=1e-9)
    assert b.freq_hz[-1] > lin.freq_hz[mode] * (1 + 1e-3)  # and hardens once the tips touch


# (NNM, energy [J]): above the last tongue of each NNM and away from grazing, where rom-fep's
# study (results/rom-fep/fep.md) found HB at H = 5 within 2e-6 of shooting
HB_VS_SHOOTING = [(0, 1.3e3), (1, 3.0e3), (2, 2.0e2), (2, 1.2e3)]
# HB against shooting: 1e-5. The study's H = 5 errors there are 1e-7 - 2e-6 (the truncation of
# five harmonics and N = 512 AFT samples); exact orbits of neighbouring families of the reduced
# model lie 1e-5 - 4e-5 apart (fep.md), so a tighter tolerance would also need the energies
# chosen off those, and a looser one (1e-4) would accept a neighbour as the NNM
HB_SHOOTING_RTOL = 1e-5


@pytest.mark.parametrize(("k", "E"), HB_VS_SHOOTING)
def test_hb_agrees_with_shooting_on_the_rom(fm, k, E):
    b = nnm_branch(fm.system, fm.modes[k], H=5, energy_max_J=1.5 * E, **fm.branch)
    i = int(np.argmin(np.abs(np.log(b.energy_J / E))))
    seg = b.segment[i]
    y0 = b.branches[seg].y[i - int(np.flatnonzero(b.segment == seg)[0])]
    y = hb_point_at_energy(b.residual, y0, E)
    X, omega = b.residual.X_omega(y)
    x, v = b.residual.hb.time_series(X, omega)
    orbit = shoot(Flow(fm.system), x[0], v[0], 2 * np.pi / omega, E)
    assert orbit.energy_J == pytest.approx(E, rel=1e-12) and orbit.closure < 1e-9
    f_hb = omega / (2 * np.pi)
    assert f_hb == pytest.approx(orbit.freq_hz, rel=HB_SHOOTING_RTOL), f"{f_hb / orbit.freq_hz - 1:.2e}"
    # stability: Hill on the HB orbit (first zone only, both solvers) and Floquet on the exact
    # orbit agree; Hill's multipliers to 2 % (truncation at H = 5, AFT Jacobian of a kink)
    qz = hill(b.residual.hb, X, omega, strict_zone=True)
    std = hill(b.residual.hb, X, omega, **fm.hill)
    assert std.max_multiplier == pytest.approx(qz.max_multiplier, rel=1e-4)  # Hill's eigenvalues: ill-conditioned
    assert qz.stable == std.stable == orbit.stable
    assert std.max_multiplier == pytest.approx(orbit.max_multiplier, rel=0.02)


@pytest.mark.parametrize("system_of", ["discrete", "rom"])
def test_nnm_residual_cached_operators_are_bit_for_bit_the_hb_operators(fm, system_of):
    """NNMResidual builds its Kronecker products once: the same float operations as
    HarmonicBalance's, so its Jacobian is bit for bit HarmonicBalance.residual's."""
    system = conservative(DiscreteParams().system()) if system_of == "discrete" else fm.system
    rng = np.random.default_rng(7)
    for H in (1, 4):
        hb = HarmonicBalance.for_system(system, H)
        res = NNMResidual(hb, 2 * np.pi * 100.0, 0)
        touched = 0
        for _ in range(6):
            y = rng.normal(size=res.size) * 1e-2
            y[hb.size], y[hb.size + 1], y[hb.size + 2] = 1.0 + rng.random(), 0.0, -3.0 + 2.0 * rng.random()
            _, J = res(y)
            X, omega = res.X_omega(y)
            _, J0, _ = hb.residual(X, omega)
            assert np.array_equal(J[: hb.size, : hb.size], J0 / res.omega_ref**2)
            touched += bool(np.any(hb.aft(X)[1]))
        assert touched >= 2  # samples in contact: the AFT Jacobian is exercised


SMALL = """
[model]
kind = "rom"
n_modes = 10
[nnm]
[fep]
harmonics = [1, 3]
convergence_harmonics = [1, 3]
samples_study_harmonics = 3
samples = [128]
energy_max_J = 1e4
n_shooting = 3
"""


def test_nnm_stage_with_fep_on_a_reduced_model(tmp_path):
    scene = parse_scene(SMALL, "rom-fep-small", "test")
    assert stages_of(scene) == ("reduce", "nnm")
    writers = []
    for run in ("a", "b"):  # twice: a rerun writes the same science files (tests/test_reproducible.py)
        (tmp_path / run).mkdir()
        writers.append(StageWriter(tmp_path / run))
        nnm_stage(scene, writers[-1], progress=False)
    science = sorted(p.name for p in (tmp_path / "a").iterdir() if not p.stem.endswith("_timing"))
    assert science == sorted(p.name for p in (tmp_path / "b").iterdir() if not p.stem.endswith("_timing"))
    for name in science:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    w, tmp_path = writers[0], tmp_path / "a"
    for name in ("linear_modes.csv", "fep.csv", "fep.png", "fep.md", "stability.csv", "tongues.csv",
                 "hb_convergence.csv", "hb_convergence.png", "hb_convergence_timing.csv"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert not (tmp_path / "nnm2_exact.csv").exists()  # the 3-DOF model's closed form only
    assert "reduced model has no closed form" in w.stats["nnm2_exact"]
    modes = list(csv.DictReader(open(tmp_path / "linear_modes.csv")))
    assert len(modes) == 24 and "phi_eta10" in modes[0]
    rows = list(csv.DictReader(open(tmp_path / "fep.csv")))
    assert {r["nnm"] for r in rows} == {"1", "2", "3"} and {r["method"] for r in rows} == {"hb", "shooting"}
    conv = list(csv.DictReader(open(tmp_path / "hb_convergence.csv")))
    assert all(r["max_err_vs_exact"] == "" for r in conv)  # no closed form: shooting is the reference
    far = {(r["nnm"], r["harmonics"]): float(r["max_err_vs_shooting_above_10x_grazing"]) for r in conv}
    assert all(math.isfinite(e) for e in far.values())
    md = (tmp_path / "fep.md").read_text()
    assert "Reference: shooting on the exact flow" in md and "## Converged H" in md
    assert w.stats["hb_reference"].startswith("shooting on the exact flow")
    assert w.stats["nnm_linear_modes"] == {"NNM 1": 1, "NNM 2": 2, "NNM 3": 3}


def _residual_reference(res, y):
    """NNMResidual.__call__ as it was before its diagonal-block update (issue 28): the full sums."""
    hb, wr = res.hb, res.omega_ref
    n, nX = hb.n, hb.size
    Psi, omega, delta, a = res.split(y)
    KI, NM2, DM = res._operators
    F, dF = hb.aft(a * Psi)
    A = KI + omega**2 * NM2
    dA = 2.0 * omega * NM2
    R = np.empty(nX + 2)
    J = np.zeros((nX + 2, nX + 3))
    DMPsi, Fa = DM @ Psi, F / a
    R[:nX] = (A @ Psi + Fa - delta * omega * DMPsi) / wr**2
    Jx = J[:nX, :nX]
    np.add(A, dF, out=Jx)
    if delta != 0.0:
        Jx -= delta * omega * DM
    Jx /= wr**2
    J[:nX, nX] = (dA @ Psi - delta * DMPsi) / wr
    J[:nX, nX + 1] = -omega * DMPsi / wr
    J[:nX, nX + 2] = np.log(10.0) * (dF @ Psi - Fa) / wr**2
    i_s1 = 2 * n + res.ref
    R[nX] = Psi[i_s1]
    J[nX, i_s1] = 1.0
    c1, s1 = Psi[n : 2 * n], Psi[2 * n : 3 * n]
    R[nX + 1] = c1 @ hb.M @ c1 + s1 @ hb.M @ s1 - 1.0
    J[nX + 1, n : 2 * n] = 2.0 * hb.M @ c1
    J[nX + 1, 2 * n : 3 * n] = 2.0 * hb.M @ s1
    return R, J


@pytest.mark.parametrize("system_of", ["discrete", "rom"])
def test_nnm_residual_block_update_is_bit_for_bit_the_full_sums(fm, system_of):
    """The residual recomputes only the diagonal blocks of A(omega) and dA/domega (buffers kept between
    calls): R and dR/dy are bit for bit (signed zeros included) those of the full sums, for either sign of
    omega (dA's zeros take its sign) and a nonzero artificial damping, call after call on one residual."""
    system = conservative(DiscreteParams().system()) if system_of == "discrete" else fm.system
    rng = np.random.default_rng(11)
    for H in (1, 3, 6):
        hb = HarmonicBalance.for_system(system, H)
        res = NNMResidual(hb, 2 * np.pi * 100.0, 0)
        for k in range(8):
            y = rng.normal(size=res.size) * 1e-2
            w = 1.0 + rng.random()
            y[hb.size] = -w if k in (3, 4) else w
            y[hb.size + 1] = 0.0 if k % 2 else 1e-3 * rng.normal()
            y[hb.size + 2] = -3.0 + 2.0 * rng.random()
            R, J = res(y)
            R0, J0 = _residual_reference(res, y)
            assert np.array_equal(R.view(np.int64), R0.view(np.int64))
            assert np.array_equal(J.view(np.int64), J0.view(np.int64))
