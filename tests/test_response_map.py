"""The response map (reduced.periodic.response_map): each frequency of a stepped sine classified by the exact
flow, checked against closed forms (a linear system's orbit, multipliers and amplitude), against long
integrations by the exact integrator (an independent kernel: the chaos never returns, the orbits found are
the ones the integrator settles on) and on the classification's own pieces; and the frc stage's files."""

from __future__ import annotations

import csv
import math
import tomllib
from importlib import resources

import numpy as np
import pytest
import tomli_w

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.response_map import (
    SPECTRUM_BINS_PER_ORDER,
    MapOptions,
    _broadband,
    _returns,
    jumps,
    linear_contact_bands,
    map_frequencies,
    order_spectrum,
    response_map,
)
from reduced.transient.integrate import ringdown
from reduced.transient.lyapunov import PeriodMap, lyapunov_exponents

PARAMS = DiscreteParams()
SYSTEM = PARAMS.system()
LOAD = PARAMS.point_rows[1]


@pytest.fixture(scope="module")
def onset():
    """1 N, up from rest over 16.8-17.3 Hz: periodic below the gap, then chaos (the full map: 17.0-22.3 Hz)."""
    return response_map(SYSTEM, LOAD, 1.0, np.round(np.arange(16.8, 17.35, 0.1), 3), point_rows=PARAMS.point_rows,
                        point_names=PARAMS.point_names)


def test_a_linear_system_is_periodic_with_its_closed_form_orbit():
    # a gap beyond the motion: every response is the linear orbit, X = (K - w^2 M + i w C)^-1 b P, with the
    # multipliers of exp(A T): max |mu| = exp(-sigma T), sigma the slowest decay rate of all modes
    sy = DiscreteParams(gap=1.0).system()
    f = np.array([12.0, 18.0, 25.0, 90.0, 400.0])
    rm = response_map(sy, LOAD, 1.0, f, point_rows=PARAMS.point_rows, point_names=PARAMS.point_names,
                      jump_step_hz=0.1)
    n = sy.n
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(sy.M, sy.K), -np.linalg.solve(sy.M, sy.C)]])
    sigma = -np.max(np.linalg.eigvals(A).real)
    for fk, pt in zip(f, rm.points, strict=True):
        w = 2 * np.pi * fk
        X = np.linalg.solve(sy.K - w * w * sy.M + 1j * w * sy.C, LOAD)
        assert pt.regime == "periodic" and pt.period_k == 1 and pt.settled and not pt.contact
        assert math.isclose(pt.lyapunov_per_s, -sigma, rel_tol=1e-9), (fk, pt.lyapunov_per_s, -sigma)
        assert math.isclose(pt.max_abs_mu, math.exp(-sigma / fk), rel_tol=1e-9)
        # the per-period max |x1| from 64 uniform samples: below the true amplitude by at most 1 - cos(pi/64)
        amp = abs(X[0])
        assert amp * (1 - 1.3e-3) <= pt.peak[0, 0] <= amp * (1 + 1e-9), (fk, pt.peak[0, 0], amp)
        assert pt.asymmetry < 1e-9  # a load at x2 on a symmetric structure
    assert not rm.jump.any()  # coarse steps (> 1.5 jump_step_hz) never count as jumps


def test_chaos_never_returns_in_a_long_integration(onset):
    # the map says chaotic at 17.2 Hz after 160 periods; 600 more periods by the exact integrator (its own
    # kernel, sampled at t = k T) never come back to within 1e-3 of a sample 1..8 periods earlier, and the
    # exponent over 1000 periods from the same state stays positive, within the map's tolerance of its value
    k = list(onset.freq_hz).index(17.2)
    pt = onset.points[k]
    assert pt.regime == "chaotic" and pt.lyapunov_per_s > pt.lyapunov_tol > 0.0 and pt.contact
    f, K = 17.2, 600
    loads = Loads(LOAD[None, :], (Harmonic(1.0, f),))
    r = ringdown(SYSTEM, pt.state[:3], pt.state[3:], K / f, 8 * f, method="exact", loads=loads)
    Y = np.column_stack([r.x, r.v])[::8][: K + 1]
    assert np.allclose(r.t[::8][: K + 1], np.arange(K + 1) / f, rtol=0, atol=1e-12)
    pm = PeriodMap(SYSTEM, LOAD, 1.0, f)
    d = _returns(Y, pm, 8, K - 8)
    assert d.min() > 1e-3, d  # a periodic response returns to 1e-6 (the map's tolerance)
    long = lyapunov_exponents(pm, pt.state, 1000)
    # the 128-period estimate is within its stated tolerance (3 standard errors) of the 1000-period one
    assert abs(long.largest - pt.lyapunov_per_s) < pt.lyapunov_tol < long.largest, (long.largest, pt)
    assert pt.asymmetry > 0.3  # the chaos has left the symmetric subspace (|x1 - x3| of the order of |x1|)


def test_the_orbits_found_are_where_a_long_integration_settles(onset):
    # below contact (16.8, 16.9 Hz) Newton finished the orbit: 300 periods of the exact integrator from the
    # map's state stay on it (the orbit is exact and attracting), and its exponent is the linear one
    for k in (0, 1):
        pt, f = onset.points[k], float(onset.freq_hz[k])
        assert pt.regime == "periodic" and pt.period_k == 1 and not pt.contact
        loads = Loads(LOAD[None, :], (Harmonic(1.0, f),))
        r = ringdown(SYSTEM, pt.state[:3], pt.state[3:], 300 / f, 4 * f, method="exact", loads=loads)
        y_end = np.concatenate([r.x[-1], r.v[-1]])
        pm = PeriodMap(SYSTEM, LOAD, 1.0, f)
        assert pm.norm(y_end - pt.state) < 1e-8 * pm.norm(pt.state)  # round-off of 300 periods of closed forms
    assert onset.jump.tolist() == [False, False, True, False, False, False]  # the onset of chaos is a jump


def test_returns_find_the_smallest_period():
    pm = PeriodMap(SYSTEM, LOAD, 1.0, 20.0)
    rng = np.random.default_rng(0)
    cycle = rng.standard_normal((3, 6)) * 1e-4
    Y = np.vstack([cycle] * 20)
    d = _returns(Y, pm, 8, 16)
    assert d[2] == 0.0 and d[5] == 0.0 and min(d[0], d[1], d[3]) > 0.1  # periods 3 and 6 return, 1, 2, 4 do not
    Y = Y + 1e-9 * rng.standard_normal(Y.shape)
    assert _returns(Y, pm, 8, 16)[2] < 1e-4


def test_broadband_tells_lines_from_noise():
    k = np.arange(256)
    lines = np.cos(2 * np.pi * 0.1234 * k) + 0.3 * np.cos(2 * np.pi * 0.3 * k)  # two incommensurate lines: a torus
    assert _broadband(lines) < 0.01
    # white noise: the 5 strongest bins and their +-2 neighbours (25 of 129) hold ~40 % of its power
    assert _broadband(np.random.default_rng(1).standard_normal(256)) > 0.5
    assert _broadband(np.ones(64)) == 0.0


def test_order_spectra_show_lines_or_a_continuum(onset):
    # periodic below contact: all the power at order 1 (the linear orbit); chaos: a continuum between the
    # harmonics of the forcing (bins more than one bin away from an integer order)
    periodic, chaotic = onset.points[0].spectrum, onset.points[4].spectrum
    assert periodic[SPECTRUM_BINS_PER_ORDER] > 0.999 and abs(float(periodic.sum()) - 1.0) < 1e-5
    order = np.arange(chaotic.size) / SPECTRUM_BINS_PER_ORDER
    off = np.abs(order - np.round(order)) > 1.5 / SPECTRUM_BINS_PER_ORDER
    assert chaotic[off].sum() > 0.05 and periodic[off].sum() < 1e-6, (chaotic[off].sum(), periodic[off].sum())
    # a period-3 signal: lines at multiples of 1/3 only
    t = np.arange(3 * 64) / 64
    s = order_spectrum(np.cos(2 * np.pi * t / 3).reshape(3, 64), periodic=True)
    assert np.argmax(s) == round(SPECTRUM_BINS_PER_ORDER / 3) and s.max() > 0.999


def test_jumps_are_regime_changes_or_amplitude_steps_between_fine_neighbours():
    class P:
        def __init__(self, regime, amp, period=1):
            self.regime, self.period_k, self.peak = regime, period, np.full((4, 1), amp)

    pts = [P("periodic", 1.0), P("periodic", 1.1), P("chaotic", 1.1, 0), P("chaotic", 2.0, 0), P("periodic", 2.0),
           P("periodic", 9.0)]
    f = np.array([10.0, 10.1, 10.2, 10.3, 10.4, 20.0])
    assert jumps(f, pts, 0.1).tolist() == [False, False, True, True, True, False]  # the last step is coarse


def test_the_frequency_grid_and_the_linear_contact_band():
    f = map_frequencies(10.0, 900.0, [(16.0, 17.0)], 0.1, 24)
    fine = f[(f >= 16.0) & (f <= 17.0)]
    assert np.allclose(np.diff(fine), 0.1) and fine[0] == 16.0 and fine[-1] == 17.0
    assert f[0] == 10.0 and f[-1] == 900.0
    # the open-gap resonance at 1 N reaches the stops: the band holds the heave mode at 17.98 Hz
    bands = linear_contact_bands(SYSTEM, LOAD, 1.0, 10.0, 900.0)
    assert len(bands) == 1 and bands[0][0] < 17.98 < bands[0][1]
    assert linear_contact_bands(SYSTEM, LOAD, 0.1, 10.0, 900.0) == []  # 0.1 N stays inside the gap


def test_map_options_are_checked():
    with pytest.raises(ValueError, match="max_period"):
        MapOptions(n_record=16, max_period=8)
    with pytest.raises(ValueError, match="kick"):
        MapOptions(kick=-1.0)


# -- the stage ---------------------------------------------------------------------------------------------
def test_frc_stage_writes_the_response_map(tmp_path, monkeypatch):
    import bearingshaft.stages.frc as stage
    from bearingshaft.pipeline import run_stage
    from bearingshaft.scenes import parse_scene

    monkeypatch.setattr(stage, "BACKBONE_DS", 0.05)  # a coarser backbone: the map's files, not its accuracy

    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / "discrete-frc.toml").read_text("utf-8"))
    data["frc"].update({"levels_N": [1.0], "freq_min_hz": 15.0, "freq_max_hz": 30.0, "harmonics": 1,
                        "convergence_harmonics": [1], "hill_points": 0, "shooting_points": 0,
                        "stepped_sine_points": 0, "backbone_scales": [1.0], "max_steps": 200,
                        "map_step_hz": 0.5, "map_coarse_points": 4, "map_periods": 64,
                        "curve": "hb"})  # the map, not the exact families (tests/test_frc.py runs those)
    scene = parse_scene(tomli_w.dumps(data), "discrete-frc", "quick")
    run_stage(scene, "frc", tmp_path, progress=False)
    rows = list(csv.DictReader(open(tmp_path / "response_map.csv")))
    assert list(rows[0])[:11] == ["level", "direction", "freq_hz", "regime", "period_k", "lyapunov_per_s", "x1_min_m",
                                  "x1_mean_m", "x1_max_m", "asymmetry", "jump"]
    assert {r["direction"] for r in rows} == {"up", "down"}
    assert {r["regime"] for r in rows} <= {"periodic", "subharmonic", "quasi_periodic", "chaotic"}
    chaotic = [r for r in rows if r["regime"] == "chaotic"]
    assert chaotic and all(float(r["lyapunov_per_s"]) > 0 and r["period_k"] == "0" for r in chaotic)
    assert all(float(r["x1_min_m"]) <= float(r["x1_mean_m"]) <= float(r["x1_max_m"]) for r in rows)
    jumps_rows = list(csv.DictReader(open(tmp_path / "response_map_jumps.csv")))
    assert {r["direction"] for r in jumps_rows} == {"up", "down"}  # hysteresis: each sweep jumps in and out
    assert (tmp_path / "response_map.png").stat().st_size > 10_000
    assert (tmp_path / "response_map_spectra.png").stat().st_size > 10_000
    # what a test would see (frc_regimes.csv): every frequency of each sweep in exactly one band, in sweep order
    bands = list(csv.DictReader(open(tmp_path / "frc_regimes.csv")))
    for d in ("up", "down"):
        mine, swept = [b for b in bands if b["direction"] == d], [r for r in rows if r["direction"] == d]
        assert sum(int(b["points"]) for b in mine) == len(swept)
        assert mine[0]["freq_from_hz"] == swept[0]["freq_hz"] and mine[-1]["freq_to_hz"] == swept[-1]["freq_hz"]
        assert all(a["key"] != b["key"] for a, b in zip(
            [{"key": (x["regime"], x["period_k"], x["contact"], x["orbit"])} for x in mine[:-1]],
            [{"key": (x["regime"], x["period_k"], x["contact"], x["orbit"])} for x in mine[1:]], strict=True))
    # a periodic response without contact is the open-gap orbit (the linear system's only one); chaos has no
    # orbit and a positive exponent
    free = [b for b in bands if b["regime"] == "periodic" and b["contact"] == "false"]
    assert free and all(b["orbit"] == "open_gap" and b["orbit_stable"] == "true" for b in free)
    assert all(b["orbit"] == "" and float(b["lyapunov_max_per_s"]) > 0 for b in bands if b["regime"] == "chaotic")


@pytest.mark.slow
def test_every_classification_of_the_1N_sweep_against_a_long_integration():
    # the 1 N sweep up over the contact band (16.5-23 Hz, 0.1 Hz), each frequency's state run on for 1000 more
    # periods: a periodic point stays on its orbit (exact integrator, 1e-8: round-off of 1000 periods); a
    # chaotic point (160-period dwell) either stays chaotic (exponent > 0 over the 1000 periods, no return
    # within 1e-3 in the exact integrator's 1000) or escapes to the contact-free orbit: transient chaos, which
    # the exact flow shows only in the band's last 1.5 Hz (a boundary crisis at its end; lifetimes of
    # 100-4000 periods measured there): a test with a longer dwell jumps down earlier
    f = np.round(np.arange(16.5, 23.05, 0.1), 3)
    rm = response_map(SYSTEM, LOAD, 1.0, f, point_rows=PARAMS.point_rows, point_names=PARAMS.point_names)
    chaotic = [fk for fk, pt in zip(rm.freq_hz, rm.points, strict=True) if pt.regime == "chaotic"]
    assert len(chaotic) > 40 and chaotic[0] == 17.0, chaotic  # 17.0 Hz to 21-22 Hz
    escaped = []
    for fk, pt in zip(rm.freq_hz, rm.points, strict=True):
        loads = Loads(LOAD[None, :], (Harmonic(1.0, float(fk)),))
        pm = PeriodMap(SYSTEM, LOAD, 1.0, float(fk))
        r = ringdown(SYSTEM, pt.state[:3], pt.state[3:], 1000 / fk, 4 * fk, method="exact", loads=loads)
        Y = np.column_stack([r.x, r.v])[::4][:1001]
        if pt.regime != "chaotic":
            assert pt.regime == "periodic" and pt.settled, (fk, pt.regime)
            assert pm.norm(Y[-1] - pt.state) < 1e-8 * pm.norm(pt.state), fk
            continue
        tail = pm.run(pt.state, 1000, samples_per_period=0, inner_samples=0)
        if pm.run(tail.y, 50, samples_per_period=0, inner_samples=0).n_events == 0:
            escaped.append(fk)  # out of contact for good: the chaos was transient
            continue
        assert _returns(Y, pm, 8, 992).min() > 1e-3, fk
        assert lyapunov_exponents(pm, pt.state, 1000).largest > 0.0, fk
    assert not escaped or min(escaped) >= chaotic[-1] - 1.5, (escaped, chaotic[-1])
