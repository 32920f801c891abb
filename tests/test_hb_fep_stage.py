"""The fep part of the nnm stage on a small configuration, and HB at a given energy."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from bearingshaft.output import StageWriter
from bearingshaft.registry import stages_of
from bearingshaft.scenes import parse_scene
from bearingshaft.stages.nnm_fep import fep_stage
from reduced.models.discrete import DiscreteParams
from reduced.periodic import nnm2
from reduced.periodic.backbones import hb_point_at_energy, nnm_branch

SCENE = """
[model]
kind = "discrete"
[nnm]
[fep]
harmonics = [1, 3]
convergence_harmonics = [1, 3]
samples_study_harmonics = 3
samples = [64, 128]
energy_max_J = 1e3
n_shooting = 8
"""


def test_fep_stage_writes_its_files(tmp_path):
    scene = parse_scene(SCENE, "fep-small", "test")
    assert stages_of(scene) == ("nnm",)
    w = StageWriter(tmp_path)
    fep_stage(scene, w, progress=False)
    for name in ("fep.csv", "fep.png", "hb_convergence.csv", "hb_convergence.png", "stability.csv", "tongues.csv"):
        assert (tmp_path / name).stat().st_size > 0, name
    rows = list(csv.DictReader(open(tmp_path / "fep.csv")))
    assert list(rows[0]) == ["nnm", "method", "harmonics", "energy_J", "freq_hz", "stable"]
    assert {r["method"] for r in rows} == {"hb", "shooting"}
    assert {r["nnm"] for r in rows} == {"1", "2", "3"}
    conv = list(csv.DictReader(open(tmp_path / "hb_convergence.csv")))
    nnm2_rows = [r for r in conv if r["nnm"] == "2" and r["samples_study"] == "0"]
    errs = {int(r["harmonics"]): float(r["max_err_vs_exact_above_10x_grazing"]) for r in nnm2_rows}
    assert errs[3] < errs[1]  # more harmonics, smaller error
    assert w.stats["shooting_vs_exact_nnm2_max_rel"] < 1e-12  # shooting is the exact NNM 2


def test_hb_point_at_energy_hits_the_energy():
    p = DiscreteParams()
    b = nnm_branch(p.system(), 1, H=5, energy_max_J=100.0)
    i = int(np.argmin(np.abs(np.log(b.energy_J / 20.0))))
    y = hb_point_at_energy(b.residual, b.branches[0].y[i], 20.0)
    assert b.residual.energy(y) == pytest.approx(20.0, rel=1e-10)
    f = y[b.residual.hb.size] * b.residual.omega_ref / (2 * np.pi)
    # H = 5 is within 0.4 % of the exact relation above ten times the grazing energy
    assert f == pytest.approx(float(nnm2.frequency_from_energy(p, 20.0)), rel=4e-3)
