"""Long studies of the 3-D model (marked slow: run with ``pytest -m slow``)."""

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
