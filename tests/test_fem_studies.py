"""Long studies of the 3-D model (marked slow: run with ``pytest -m slow``), and a fast variant
of the calibration study, the only test of :mod:`fem.calibrate`."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_mesh_convergence_study_writes_a_default(tmp_path):
    mod = _load("mesh_convergence")
    mod.ORDER_STUDY = (("hex8", 0.3),)
    assert mod.main(["--out", str(tmp_path), "--sizes", "0.3", "0.12", "0.08"]) == 0
    text = (tmp_path / "mesh_convergence.csv").read_text()
    assert "# default mesh: hex20" in text
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    hex20 = [r for r in rows if r["element"] == "hex20"]
    # the pseudo-rigid modes are spring-and-mass dominated: every mesh is within 0.5 %
    assert all(float(r["max_error_pct"]) < 0.5 for r in hex20)
    assert (tmp_path / "mesh_convergence.png").exists()


@pytest.mark.slow
def test_speed_study_agrees_with_the_baseline(tmp_path):
    mod = _load("modal_speed")
    assert mod.main(["--out", str(tmp_path), "--sizes", "0.3", "--n-modes", "13"]) == 0
    rows = list(csv.DictReader((tmp_path / "modal_speed.csv").open()))
    assert {r["pipeline"] for r in rows} == {"ours", "baseline"}
    # both pipelines solve the same problem: frequencies agree to the solver noise
    assert float(rows[0]["max_rel_freq_diff"]) < 1e-4


@pytest.mark.slow
def test_calibration_recovers_known_parameters():
    # a synthetic "test": frequencies of a model with known seat stiffnesses; the fit from
    # a perturbed start must find them again (two parameters, cheap mesh)
    import dataclasses

    from fem.analysis import analyse
    from fem.calibrate import calibrate
    from fem.model import AssemblyModel

    truth = AssemblyModel(element_size=0.3)

    def evaluate(m):
        return analyse(m, n_modes=13).table2_freq()

    target = evaluate(truth)
    start = dataclasses.replace(truth, seat_k_rx=truth.seat_k_rx * 1.5, tube_mass=truth.tube_mass * 0.8)
    res = calibrate(start, evaluate, parameters={"seat_k_rx": (0.05, 200.0), "tube_mass": (4.0, 40.0)},
                    test_hz=target, max_nfev=20)
    np.testing.assert_allclose(res.fitted, [truth.seat_k_rx, truth.tube_mass], rtol=2e-3)
    assert np.abs(res.error_pct).max() < 0.01


def _rigid_body_frequencies(mesh):
    """evaluate(model) for fem.calibrate: Hz in Table 2 order, the beam and the tube taken rigid.

    The 12 rigid-body modes Phi of the two bodies (about the beam's centre) reduce the assembled
    K and M to (Phi^T K Phi) q = omega^2 (Phi^T M Phi) q (Rayleigh-Ritz: the bodies' own
    deformation is two orders above these modes, so the six pseudo-rigid frequencies lie just
    above the full eigensolution's: measured 3e-6 .. 2e-5 on hex8); the six are found among
    the 12 by fem.labels as in fem.analysis. The mesh is the same for every parameter fitted
    here, so it is built once. Returns evaluate and a dict holding the last model's Phi, q
    (Table 2 order) and M, for the sensitivity check.
    """
    import scipy.linalg as sl

    from fem.analysis import CENTRE
    from fem.labels import TABLE2_ORDER, label_modes
    from fem.model import build_system

    last = {}

    def evaluate(model):
        system = build_system(model, mesh=mesh)
        bd, td = system.part_dofs("beam"), system.part_dofs("tube")
        Pb, Pt = system.rigid_modes(bd, CENTRE), system.rigid_modes(td, CENTRE)
        Phi = np.zeros((system.K.shape[0], 12))
        Phi[bd, :6], Phi[td, 6:] = Pb, Pt
        Kr, Mr = Phi.T @ (system.K @ Phi), Phi.T @ (system.M @ Phi)
        w2, q = sl.eigh(0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T))
        labels = label_modes(Phi @ q, system.M, bd, Pb, td, Pt)
        order = [labels.mode_index[n] for n in TABLE2_ORDER]
        last.update(Phi=Phi, q=q[:, order], M=system.M)
        return np.sqrt(w2[order]) / (2 * np.pi)

    return evaluate, last


def test_calibration_recovers_known_parameters_of_a_small_model():
    """Fast variant of the slow test above: the same fit (seat_k_rx and tube_mass, from a start 25 %
    and 10 % off, to the frequencies of the model with the known values) on the hex8 mesh with the
    bodies taken rigid (:func:`_rigid_body_frequencies`: 0.2 s an evaluation, against 1-3 s).
    The sensitivity to the tube's mass is checked against Rayleigh's quotient: M is linear in
    it, so d ln f_i / d ln m_tube = -(1/2) u_i^T M_tube u_i / u_i^T M u_i, u_i = Phi q_i (the tube
    solid's share of mode i's kinetic energy; the lumped tip masses are not scaled with it);
    calibrate's forward differences agree to their first-order error (below).
    Stiffer seats can only raise a frequency: d ln f / d ln k_seat >= 0."""
    import dataclasses

    from fem.calibrate import calibrate
    from fem.model import AssemblyModel, build_system
    from geometry.build import build_mesh

    truth = AssemblyModel(element_size=0.3, element="hex8")
    mesh = build_mesh(truth.geometry())
    evaluate, last = _rigid_body_frequencies(mesh)
    target = evaluate(truth)
    start = dataclasses.replace(truth, seat_k_rx=truth.seat_k_rx * 1.25, tube_mass=truth.tube_mass * 0.9)
    res = calibrate(start, evaluate, parameters={"seat_k_rx": (0.05, 200.0), "tube_mass": (4.0, 40.0)},
                    test_hz=target, max_nfev=20)
    np.testing.assert_allclose(res.fitted, [truth.seat_k_rx, truth.tube_mass], rtol=2e-3)
    assert np.abs(res.error_pct).max() < 0.01

    # the tube solid's mass matrix: M is linear in the tube's density, so it is the difference
    # of M at twice the fitted tube mass and at the fitted one
    M_2 = build_system(dataclasses.replace(res.model, tube_mass=2 * res.model.tube_mass), mesh=mesh).M
    evaluate(res.model)  # the fitted model's modes and M, for Rayleigh's quotient
    M_tube = M_2 - last["M"]
    u = last["Phi"] @ last["q"]
    share = np.einsum("ij,ij->j", u, M_tube @ u) / np.einsum("ij,ij->j", u, last["M"] @ u)
    S_tube = res.sensitivity[:, res.names.index("tube_mass")]
    # scipy's 2-point step is diff_step max(1, |y|) in calibrate's unknown y = ln(p / p_start), so 0.02
    # here; a forward difference is first order, off by about h/2 |dS/dy + S^2| (a central difference
    # of evaluate at h = 1e-3 gives Rayleigh's value to 1e-7); measured 1.0e-3 = h / 20 (it was 2.2 % with
    # the step on ln p itself, 0.02 ln(13.18) = 0.052); h / 4 allowed
    i = res.names.index("tube_mass")
    h = 0.02 * max(1.0, abs(np.log(res.fitted[i] / res.initial[i])))
    np.testing.assert_allclose(S_tube, -0.5 * share, rtol=h / 4)
    assert np.all(res.sensitivity[:, res.names.index("seat_k_rx")] > -1e-6)
