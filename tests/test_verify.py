"""Identification of the three-mass model from a Craig-Bampton model, and the verify stage."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest
from beam_reference import rigid_body_hz, timoshenko_beam_hz  # tests/beam_reference.py

from bearingshaft.cli import main
from reduced.models.craig_bampton import craig_bampton
from reduced.models.discrete import DiscreteParams
from reduced.models.identify import identify_discrete

TIPS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # rows picking x1 and x3 of the three-mass model


def own_cb(p: DiscreteParams):
    """The three-mass model's own Craig-Bampton form on x1, x3 and its one interior mode."""
    s = p.system()
    return craig_bampton(s.K, s.M, TIPS, n_modes=1)


def assert_same_params(a: DiscreteParams, b: DiscreteParams, rtol: float = 1e-12) -> None:
    for f in dataclasses.fields(DiscreteParams):
        assert getattr(a, f.name) == pytest.approx(getattr(b, f.name), rel=rtol, abs=0.0), f.name


def test_cb_form_of_the_three_mass_model_is_the_documented_one():
    p = DiscreteParams()
    cb = own_cb(p)
    Mbb = np.diag([p.m1, p.m3]) + p.m2 / 4 * np.ones((2, 2))
    np.testing.assert_allclose(cb.M[:2, :2], Mbb, rtol=1e-13)
    np.testing.assert_allclose(np.abs(cb.M[:2, 2]), np.sqrt(p.m2) / 2 * np.ones(2), rtol=1e-13)
    np.testing.assert_allclose(cb.K[:2, :2], 2 * p.k_s * np.eye(2), rtol=1e-13, atol=1e-9)
    assert cb.omega_fixed[0] ** 2 == pytest.approx(4 * p.a / p.m2, rel=1e-13)


@pytest.mark.parametrize("p", [DiscreteParams(),
                               DiscreteParams(m1=0.5, m2=1.1, m3=0.83, k_s=7.2e3, kappa=6.1e4, L=0.2, c=2.5)],
                         ids=["table1", "asymmetric"])
def test_identification_of_the_own_cb_model_is_exact(p):
    cb = own_cb(p)
    q, residuals = identify_discrete(cb.M, cb.K, p.L, k_g=p.k_g, gap=p.gap, c=p.c)
    assert_same_params(q, p)
    assert all(abs(v) < 1e-12 for v in residuals.values()), residuals


def test_identification_uses_the_first_mode_and_ignores_its_scale():
    p = DiscreteParams(m1=0.7, m3=0.6)
    cb = own_cb(p)
    S = np.diag([1.0, 1.0, -3.0])  # eta -> -3 eta: sign and normalization of the mode
    M, K = S @ cb.M @ S, S @ cb.K @ S
    q, residuals = identify_discrete(np.pad(M, (0, 1)) + np.diag([0, 0, 0, 1.0]),
                                     np.pad(K, (0, 1)) + np.diag([0, 0, 0, 1e9]), p.L, k_g=p.k_g, gap=p.gap, c=p.c)
    assert_same_params(q, p)
    assert residuals["M_qq"] == pytest.approx(8.0)  # the mode is no longer mass-normalized: reported


def test_residuals_report_what_the_three_mass_form_cannot_carry():
    p = DiscreteParams()
    cb = own_cb(p)
    K = cb.K.copy()
    K[0, 1] = K[1, 0] = -0.01 * 2 * p.k_s
    M = cb.M.copy()
    M[0, 1] = M[1, 0] = 1.05 * p.m2 / 4
    _, residuals = identify_discrete(M, K, p.L, k_g=p.k_g, gap=p.gap, c=p.c)
    assert residuals["K_bb01"] == pytest.approx(-0.01, rel=1e-12)
    assert residuals["M_bb01"] == pytest.approx(0.05, rel=1e-12)


def test_identification_refuses_an_antisymmetric_first_mode():
    p = DiscreteParams()
    cb = own_cb(p)
    M = cb.M.copy()
    M[1, 2] = M[2, 1] = -M[0, 2]
    with pytest.raises(ValueError, match="first fixed-interface mode"):
        identify_discrete(M, cb.K, p.L, k_g=p.k_g, gap=p.gap, c=p.c)


def predicted_full_modes() -> list[int]:
    """1-based indices, in the full beam-grounded model's spectrum, of its heave, pitch and first bending
    (open gaps) and of its three lowest modes with the tips tied (closed), predicted from references that
    do not solve the full model (tests/beam_reference.py): the six pseudo-rigid modes from the 6x6 problem
    on its rigid-body modes (10.0 x, 10.9 y, 13.9 yaw, 18.0 heave, 23.0 pitch, 33.5 Hz roll), the bending
    in z (open: 703, 1892 Hz; tied at x = +-L by k_g: 502, 1047, 1148 Hz) and in y (731 Hz: b > h) of the
    1-D Timoshenko beam. Tying the tips (on the y = 0 axis) changes heave and pitch only. Torsion (~3.3 kHz)
    and axial modes (5.7 kHz) lie above the eighth. The coarse mesh stiffens the bending by 0.5-7 %
    (test_rom), less than the 4 % between z and y bending at the tightest place (open: mode 7 vs 8)."""
    from fem.model import AssemblyModel, build_system

    model = AssemblyModel(layout="beam-grounded")
    rigid, labels = rigid_body_hz(build_system(model))
    moved = [labels.index("heave"), labels.index("pitch")]
    lateral = list(timoshenko_beam_hz(model, plane="xy")[2:])  # the first two are rigid (in the 6x6)
    bending = list(timoshenko_beam_hz(model)[2:])
    tied = list(timoshenko_beam_hz(model, model.k_g))
    spectrum = sorted([*rigid, *bending, *lateral])
    closed = sorted([f for i, f in enumerate(rigid) if i not in moved] + tied + lateral)
    return ([spectrum.index(rigid[i]) + 1 for i in moved] + [spectrum.index(bending[0]) + 1]
            + [closed.index(f) + 1 for f in tied[:3]])


def test_verify_cli_writes_its_files(tmp_path):
    out = tmp_path / "verify"
    assert main(["verify", "--scene", "verify-reduction", "--out", str(out), "--no-progress"]) == 0
    for name in ("identified.csv", "verify.csv", "nnm_backbones.csv", "residuals.csv", "verify.png", "verify.md"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "verify.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["state"], int(r["mode"])) for r in rows] == [(s, i) for s in ("open", "closed") for i in (1, 2, 3)]
    for r in rows:  # one fixed-interface mode: Rayleigh-Ritz upper bounds, close to the full model
        assert 0.0 <= float(r["reduced_rel"]) < 0.05
        assert float(r["reduced_mac"]) > 0.998  # paired by MAC with the full mode (reduce stage)
    # regression guard: heave, pitch, bending; tied: 524, 1055, 1154 Hz (the indices when written)
    assert [int(r["full_mode"]) for r in rows] == [4, 5, 7, 5, 7, 8]
    # independent: the same indices predicted without the full model's eigensolution
    assert [int(r["full_mode"]) for r in rows] == predicted_full_modes()
    md = (out / "verify.md").read_text()
    assert "## Full-model modes the reduction leaves out" in md
    assert "antisymmetric in y (out of plane)" in md and "beyond the 1 fixed-interface mode(s) kept" in md
    assert "wall time" not in md  # timings go to provenance.json: a rerun writes the same verify.md
    with open(out / "identified.csv") as fh:
        ident = {r["parameter"]: float(r["identified"]) for r in csv.DictReader(fh)}
    assert ident["L"] == pytest.approx(DiscreteParams().L, rel=1e-9)
    assert ident["m1"] == pytest.approx(ident["m3"], rel=1e-6)  # the beam is symmetric


@pytest.mark.parametrize("kw", [{}, {"k_tip": 1e7}, {"fixed": True}, {"plane": "xy"}])
def test_the_beam_reference_lanczos_gives_the_dense_eigenvalues(kw):
    """tests/beam_reference.py solves det(K - omega^2 M) = 0 by sparse shift-invert Lanczos; the dense generalized
    eigh of the same matrices (its former solver) gives the same six frequencies, on a mesh small enough for the
    dense one to be cheap (200 elements); the free lateral beam's two rigid modes (~0 Hz, round-off) left out."""
    from fem.model import AssemblyModel

    model = AssemblyModel(layout="beam-grounded")
    lanczos = timoshenko_beam_hz(model, n_el=200, **kw)
    dense = timoshenko_beam_hz(model, n_el=200, dense=True, **kw)
    keep = slice(2, None) if kw.get("plane") == "xy" else slice(None)
    assert lanczos[keep] == pytest.approx(dense[keep], rel=1e-6)
    assert np.all(lanczos[keep] > 1.0)  # no rigid mode among the compared ones
