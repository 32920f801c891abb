"""Scenes, the CLI and the results folders: happy paths and every bad-input path."""

from __future__ import annotations

import json

import numpy as np
import pytest

import bearingshaft.stages.nnm as nnm_stage
from bearingshaft.cli import main
from bearingshaft.registry import stages_of
from bearingshaft.scenes import SceneError, builtin_names, load_scene, parse_scene

SHORT = """
description = "short impulse"
[model]
kind = "discrete"
[initial]
x0_m = [0.0, 0.0, 0.0]
v0_m_s = [0.0, 0.0, 200.0]
[ringdown]
duration_s = 0.05
sample_rate_hz = 20000.0
[spectrogram]
window_s = 0.01
[symmetry]
[nnm]
n_energy = 50
"""


def write(tmp_path, text: str, name: str = "case.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_builtin_scenes_load_and_name_their_stages():
    names = builtin_names()
    for required in ("discrete-antisymmetric", "discrete-impulse", "discrete-symmetric"):
        assert required in names
    assert stages_of(load_scene("discrete-impulse")) == ("ringdown", "nnm", "study")
    assert stages_of(load_scene("discrete-symmetric")) == ("ringdown",)
    anti = load_scene("discrete-antisymmetric")
    assert anti.initial.x0_m == (0.0254, 0.0, -0.0254)  # 100 gaps, antisymmetric


@pytest.fixture
def quick_nnm2_check(monkeypatch):
    # the NNM 2 periods integrated near grazing (x0/g = 1.000001 ... 1.01) take ~2 s of DOP853 per nnm run and
    # nothing here reads them; two amplitudes away from grazing write the same files (as tests/test_reproducible.py;
    # the integrated periods against the closed form: tests/test_discrete_nnm2.py)
    monkeypatch.setattr(nnm_stage, "CHECK_CHI", (1.1, 10.0))


def test_ringdown_and_nnm_from_cli_write_complete_folder(tmp_path, quick_nnm2_check):
    scene = write(tmp_path, SHORT)
    out = tmp_path / "out"
    assert main(["ringdown", "--scene", scene, "--out", str(out), "--no-progress"]) == 0
    assert main(["nnm", "--scene", scene, "--out", str(out), "--no-progress"]) == 0
    for f in ("ringdown.npz", "ringdown.png", "spectrogram.png", "symmetry.png", "symmetry.csv",
              "nnm2_exact.csv", "nnm2_check.csv", "linear_modes.csv", "scene.toml", "provenance.json"):
        assert (out / f).exists(), f
    data = np.load(out / "ringdown.npz")
    assert data["x"].shape == (1001, 3) and data["t"][-1] == pytest.approx(0.05)
    assert float(data["energy_balance_error"]) < 1e-11
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["version"] and prov["git_commit"]
    assert prov["stages"]["ringdown"]["stats"]["n_events"] > 0
    assert set(prov["stages"]) == {"ringdown", "nnm"}
    assert (out / "scene.toml").read_text() == SHORT
    nnm = np.loadtxt(out / "nnm2_exact.csv", delimiter=",", skiprows=1)
    assert nnm.shape == (50, 2)
    assert not list(out.glob(".*partial*"))


def test_nnm2_csv_of_builtin_scene_spans_the_required_energies(tmp_path, quick_nnm2_check):
    assert main(["nnm", "--scene", "discrete-antisymmetric", "--out", str(tmp_path), "--no-progress"]) == 0
    header = (tmp_path / "nnm2_exact.csv").read_text().splitlines()[0]
    assert header == "energy_J,freq_hz"
    E, f = np.loadtxt(tmp_path / "nnm2_exact.csv", delimiter=",", skiprows=1).T
    assert E.size >= 400 and E[0] == pytest.approx(1e-4) and E[-1] == pytest.approx(1e5)
    assert np.allclose(np.diff(np.log(E)), np.log(E[1] / E[0]))  # log-spaced
    assert f[0] == pytest.approx(25.431, abs=1e-3)  # open-gap antisymmetric mode
    assert np.all(np.diff(f) >= 0)  # hardening


@pytest.mark.parametrize(
    "text, expected",
    [
        ("[model]\nkind = 'discrete'\nm1 = -1.0\n", "m1 must be > 0"),
        ("[model]\nm2 = nan\n", "m2: must be finite"),
        ("[model]\nk_s = 'stiff'\n", "k_s: expected a number"),
        ("[model]\nkind = 'ufo'\n", "unknown model 'ufo'"),
        ("[model]\ng = 1.0\n", "unknown key 'g' (did you mean 'gap'? the key was renamed)"),  # issue 24: one name
        ("[ringdown]\nmethod = 'euler'\n", "method must be one of"),
        ("[ringdown]\nduration_s = -1.0\n", "duration_s must be > 0"),
        ("[ringdown]\nduraton_s = 1.0\n", "unknown key 'duraton_s'"),
        ("[initial]\nx0_m = [0.0, 0.0]\n", "x0_m: needs 3 values"),
        ("[initial]\nv0_m_s = [0.0, inf, 0.0]\n", "v0_m_s[1]: must be finite"),
        ("[spectrogram]\n", "need a [ringdown] table"),
        ("[ringdown]\n[spectrogram]\ndof = 'x7'\n", "unknown DOF 'x7'"),
        ("[ringdown]\n[spectrogram]\noverlap = 1.5\n", "overlap must be in [0, 1)"),
        ("[nnm]\nn_energy = 2.5\n", "n_energy: expected an integer"),
        ("colour = 'red'\n", "unknown key 'colour'"),
        ("[model\n", "invalid TOML"),
    ],
)
def test_bad_scene_is_one_line_exit_2(tmp_path, capsys, text, expected):
    scene = write(tmp_path, text)
    out = tmp_path / "out"
    assert main(["ringdown", "--scene", scene, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert expected in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()  # refused before anything was written


def test_parse_errors_are_scene_errors():
    with pytest.raises(SceneError, match=r"\[model\]: m3 must be > 0"):
        parse_scene("[model]\nm3 = 0.0\n", "x", "case.toml")


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["ringdown", "--scene", "no-such-scene"], "unknown scene 'no-such-scene'"),
        (["ringdown", "--scene", "missing.toml"], "cannot read scene file"),
        (["study", "--scene", "discrete-symmetric"], "[stiff_cases] or [rom_convergence] table"),
        (["ringdown", "--scene", "discrete-impulse", "--method", "rk4"], "invalid choice"),
        (["frobnicate"], "invalid choice"),
    ],
)
def test_bad_command_line_exit_2(tmp_path, capsys, argv, expected):
    assert main([*argv, *(["--out", str(tmp_path / "o")] if argv[0] != "frobnicate" else [])]) == 2
    assert expected in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_unstable_user_step_refused_without_partial_results(tmp_path, capsys):
    text = SHORT.replace("duration_s = 0.05", "duration_s = 0.05\nmethod = 'explicit'\ndt_s = 1e-3")
    out = tmp_path / "out"
    assert main(["ringdown", "--scene", write(tmp_path, text), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exceeds the stable step" in err and err.count("\n") == 1
    assert not (out / "ringdown.npz").exists() and not list(out.glob(".*partial*"))


def test_failed_stage_keeps_previous_results(tmp_path):
    scene = write(tmp_path, SHORT)
    out = tmp_path / "out"
    assert main(["ringdown", "--scene", scene, "--out", str(out), "--no-progress"]) == 0
    before = (out / "ringdown.npz").read_bytes()
    bad = write(tmp_path, SHORT.replace("duration_s = 0.05", "duration_s = 0.05\nmethod = 'explicit'\ndt_s = 1.0"),
                "bad.toml")
    assert main(["ringdown", "--scene", bad, "--out", str(out), "--no-progress"]) == 2
    assert (out / "ringdown.npz").read_bytes() == before


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "discrete-impulse" in out and "ringdown, nnm, study" in out
