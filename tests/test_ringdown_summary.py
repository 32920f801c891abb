"""The ringdown stage in engineering numbers (issue 24): ``ringdown.npz`` holds the force in each stop and
the accelerations, and the summary gives impacts, peak tip force, peak displacement and acceleration at
each point and when the gaps stay open; the integrator's counts are named for what they count."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bearingshaft.pipeline import run_stage
from bearingshaft.scenes import parse_scene
from bearingshaft.sweep.metrics import ringdown_metrics
from reduced import DiscreteParams

D = 1e-3  # m, the antisymmetric start's amplitude
LINEAR = f"""
[model]
kind = "discrete"
gap = 1.0
c = 0.0
[initial]
x0_m = [{D}, 0.0, {-D}]
[ringdown]
duration_s = 0.2
sample_rate_hz = 20000.0
"""
HAMMER = """
[model]
kind = "discrete"
[ringdown]
duration_s = 1.0
sample_rate_hz = 20000.0
[[load]]
kind = "half_sine"
point = "x2"
peak_N = 500.0
duration_s = 1e-3
"""


def _run(tmp_path, text: str, name: str, capsys=None):
    scene = parse_scene(text, name, f"{name}.toml")
    out = tmp_path / name
    run_stage(scene, "ringdown", out, progress=False)
    printed = capsys.readouterr().out if capsys is not None else ""
    stats = json.loads((out / "provenance.json").read_text())["stages"]["ringdown"]["stats"]
    return scene, out, stats, printed


def test_linear_mode_closed_form(tmp_path, capsys):
    """x = [d, 0, -d] cos(w t), w^2 = 2 k_s / m1, no damping, the gaps far away: peak |x| = d and
    peak |a| = w^2 d at t = 0, no impact."""
    _, out, stats, printed = _run(tmp_path, LINEAR, "linear", capsys)
    p = DiscreteParams()
    s = stats["summary"]
    assert s["impacts_total"] == 0 and s["peak_tip_force_N"] == 0.0 and s["gaps_open_after_s"] == 0.0
    assert s["peak_displacement_m"]["x1"] == pytest.approx(D, rel=1e-12)
    assert s["peak_displacement_m"]["x2"] < 1e-12 * D  # the mode does not move the middle mass
    assert s["peak_acceleration_m_s2"]["x3"] == pytest.approx(2 * p.k_s / p.m1 * D, rel=1e-12)
    assert "no impact (the gaps never close)" in printed
    with np.load(out / "ringdown.npz") as z:
        assert z["stop_force"].shape == (z["t"].size, 4) and not z["stop_force"].any()
        assert list(z["stop_names"]) == ["x1+", "x1-", "x3+", "x3-"]
        # a against the time derivative of v by central differences: error (w dt)^2 / 6 ~ 1e-5 of a
        a_fd = np.gradient(z["v"], z["t"], axis=0)[1:-1]
        assert np.max(np.abs(z["a"][1:-1] - a_fd)) < 1e-4 * np.max(np.abs(z["a"]))


def test_hammer_blow_summary_against_the_file_and_the_sweep_metrics(tmp_path, capsys):
    scene, out, stats, printed = _run(tmp_path, HAMMER, "blow", capsys)
    s = stats["summary"]
    with np.load(out / "ringdown.npz") as z:
        x, v, t, f, a = z["x"], z["v"], z["t"], z["stop_force"], z["a"]
    p = DiscreteParams()
    # the stop forces from the displacements: k_g max(|x_tip| - g, 0), above (+) and below (-)
    tips = x[:, [0, 0, 2, 2]] * np.array([1, -1, 1, -1])
    assert np.allclose(f, p.k_g * np.maximum(tips - p.gap, 0.0), rtol=1e-12, atol=1e-9)
    assert s["peak_tip_force_N"] == pytest.approx(f.max(), rel=1e-15)
    # the accelerations: Newton's law summed over the masses, m1 a1 + m2 a2 + m3 a3 = load - springs - stops
    total = a @ np.array([p.m1, p.m2, p.m3])
    load = np.where(t <= 1e-3, 500.0 * np.sin(np.pi * t / 1e-3), 0.0)
    springs = p.k_s * 2 * (x[:, 0] + x[:, 2]) + p.c * v.sum(axis=1)
    stops = f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3]
    assert np.allclose(total, load - springs - stops, rtol=0, atol=1e-9 * np.abs(total).max())
    # the sweep's metrics read the same file (they count closures after the first sample, and the
    # gaps open from the sample after the last contact)
    m = ringdown_metrics(scene, out, stats)
    assert s["impacts_total"] == m["impacts"] > 0
    assert s["peak_tip_force_N"] == m["peak_tip_force_N"]
    assert s["gaps_open_after_s"] == pytest.approx(m["gaps_open_after_s"] - 1 / 20000.0, abs=1e-12)
    assert not s["still_closing_at_end"]
    assert sum(s["impacts"].values()) == s["impacts_total"]
    assert f"{s['impacts_total']} impacts (x1+ {s['impacts']['x1+']}," in printed
    assert f"gaps open after {s['gaps_open_after_s']:.4g} s;" in printed
    # what the exact integrator's count counts
    assert f"exact: {stats['n_events']} contact switches, each found and crossed exactly" in printed
    assert stats["n_events"] >= s["impacts_total"] * 2 - 1  # a sampled impact closes and opens a stop


def test_explicit_run_names_its_steps(tmp_path, capsys):
    text = LINEAR.replace("duration_s = 0.2", "duration_s = 0.01\nmethod = \"explicit\"")
    _, _, stats, printed = _run(tmp_path, text, "explicit", capsys)
    assert f"explicit: {stats['n_steps']} time steps of {stats['dt']:.3g} s;" in printed
    assert math.isclose(stats["n_steps"] * stats["dt"], 0.01, rel_tol=1e-9)
