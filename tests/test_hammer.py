"""The virtual hammer test (issue 12): the point load, the channels, the energy, the crossings,
UFF 58 out and in, the comparison with a measured test and its refusals.

One small reduced apparatus (20 fixed-interface modes, every mode: planar = false) serves
every test; it is built once (about 15 s: mesh, assembly, Craig-Bampton).
"""

from __future__ import annotations

import contextlib
import io
import math
from dataclasses import replace

import numpy as np
import pytest

from bearingshaft.cli import main
from bearingshaft.stages.hammer import coupled_subsystem, default_location
from fem.rig import channel_names
from fem.uff import TimeHistory, read_uff58, write_uff58
from reduced.models.loads import HalfSine
from reduced.models.rig import virtual_rig
from reduced.models.rom import RomSpec, build_fe, cached_rom
from reduced.transient.integrate import ringdown

N_MODES = 20
SCENE = """
[model]
kind = "rom"
layout = "assembly"
planar = false
n_modes = {n_modes}
gap = {gap}
[hammer]
peak_N = 500.0
start_s = 0.005
levels_N = [20.0, 500.0]
backbone_modes = 0
[ringdown]
duration_s = 0.15
sample_rate_hz = 20000.0
[spectrogram]
dof = "beam_s3:z"
window_s = 0.02
overlap = 0.5
fmax_hz = 1000.0
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory, assembly_rom20):
    """(rom, fe) of the small apparatus (built once per session: conftest.py), stored in a private cache the
    CLI tests reuse."""
    import os

    cache = tmp_path_factory.mktemp("cache")
    old = os.environ.get("BEARINGSHAFT_CACHE")
    os.environ["BEARINGSHAFT_CACHE"] = str(cache)
    from reduced.models.rom import store_in_cache

    spec = RomSpec(layout="assembly", planar=False, n_modes=N_MODES)
    rom, fe = assembly_rom20
    assert N_MODES == 20 and rom.n_modes == N_MODES
    store_in_cache(rom, spec)
    yield rom, fe
    if old is None:
        os.environ.pop("BEARINGSHAFT_CACHE", None)
    else:
        os.environ["BEARINGSHAFT_CACHE"] = old


@pytest.fixture(scope="module")
def rig(built):
    rom, _ = built
    return virtual_rig(rom, default_location(rom), (0.0, 0.0, -1.0))


def _run(rig, peak, duration=0.05, rate=20000.0, method="exact", start=0.002, **kw):
    sig = HalfSine(peak, 1e-3, start)
    n = rig.system.n
    res = ringdown(rig.system, np.zeros(n), np.zeros(n), duration, rate, method, loads=rig.loads(sig), **kw)
    return res, sig


def _cli(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(args))
    return rc, out.getvalue(), err.getvalue()


# -- the model ------------------------------------------------------------------------------
def test_point_load_is_the_force_and_its_moment(built):
    """The consistent nodal load of a point force carries the force and its moment exactly:
    sum of nodal forces = d, sum r x f = X x d (shape functions partition unity and reproduce x)."""
    from fem.rig import point_load_vector

    _, fe = built
    X = np.array([0.05, 0.004, default_location(built[0])[2]])
    d = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    b = point_load_vector(fe.mesh.points, fe.mesh.hexes, fe.solid.element, fe.mesh.cell_part,
                          fe.mesh.part_names.index("beam"), X, d, fe.n_dofs).toarray().ravel()
    comp, loc = fe.solid.dof_component, fe.solid.dof_location
    force = np.array([b[comp == c].sum() for c in range(3)])
    np.testing.assert_allclose(force, d, atol=1e-12)
    moment = np.cross(loc, np.eye(3)[comp] * b[:, None]).sum(axis=0)
    np.testing.assert_allclose(moment, np.cross(X, d), atol=1e-9)  # the nudge along d adds no moment


def test_a_point_off_the_beam_is_refused(built):
    rom, _ = built
    with pytest.raises(ValueError, match="not on the beam"):
        virtual_rig(rom, (0.0, 0.0, 0.5), (0.0, 0.0, -1.0))
    with pytest.raises(ValueError, match="zero vector"):
        virtual_rig(rom, default_location(rom), (0.0, 0.0, 0.0))


def test_channels_are_named_as_on_the_rig(rig):
    assert rig.names == channel_names()
    assert len(rig.names) == 6 * 3 + 4 * 3 + 4 + 1
    c = {ch.name: ch for ch in rig.channels}
    assert (c["beam_s3:z"].node, c["beam_s3:z"].direction, c["beam_s3:z"].unit) == (3, 3, "m/s^2")
    assert (c["tube_s2:y"].node, c["tube_s2:y"].direction) == (102, 2)
    assert (c["tip_left_bottom"].node, c["tip_left_bottom"].direction, c["tip_left_bottom"].unit) == (202, -3, "N")
    assert (c["hammer"].node, c["hammer"].direction, c["hammer"].quantity) == (300, -3, "force")


def test_accelerations_are_the_derivative_of_the_velocities(rig):
    """The channels' accelerations (from the equation of motion at each sample) against the
    central difference of the sensors' velocities sampled at 400 kHz, gaps open (a 20 N blow): the
    difference's error is (omega dt)^2 / 6 <= 1e-3 for the 20-mode model's top mode (~3.5 kHz)."""
    res, sig = _run(rig, 20.0, duration=0.02, rate=400000.0)
    data = rig.channel_data(res.x, res.v, sig(res.t))
    acc = data[:30]
    vel = rig.acc_rows @ res.v.T
    dt = res.t[1] - res.t[0]
    fd = (vel[:, 2:] - vel[:, :-2]) / (2 * dt)
    err = np.max(np.abs(fd - acc[:, 1:-1])) / np.max(np.abs(acc))
    assert err < 2e-3


def test_load_cells_read_contact_force_minus_seismic_inertia(built):
    """With no seismic mass the cell reads the stop's compression exactly; with one, the difference
    is -m_a a_seat (top) and +m_a a_seat (bottom)."""
    rom, _ = built
    loc = default_location(rom)
    bare = virtual_rig(rom, loc, (0, 0, -1), seismic_mass_kg=0.0)
    heavy = virtual_rig(rom, loc, (0, 0, -1), seismic_mass_kg=0.05)
    res, sig = _run(bare, 500.0)
    p = sig(res.t)
    cells = slice(30, 34)
    d0, d1 = bare.channel_data(res.x, res.v, p), heavy.channel_data(res.x, res.v, p)
    np.testing.assert_array_equal(d0[cells], bare.system.stop_force(res.x).T)
    assert np.max(d0[cells]) > 100.0  # the 500 N blow closes the gaps
    a = np.linalg.solve(bare.system.M, (p[:, None] * bare.b - res.v @ bare.system.C - res.x @ bare.system.K
                                        - bare.system.contact_force(res.x)).T)
    seat = bare.seat_rows @ a
    np.testing.assert_allclose(d1[cells] - d0[cells], -0.05 * np.array([1, -1, 1, -1])[:, None] * seat,
                               rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(d0[-1], p)


def test_hammer_work_and_energy_balance(rig):
    """W_ext from the integrator equals the hammer channel times the struck point's velocity
    integrated (trapezoid at 400 kHz: O(dt^2) ~ 1e-5 of the pulse), and E + D = W_ext."""
    res, sig = _run(rig, 500.0, duration=0.02, rate=400000.0)
    work = np.trapezoid(sig(res.t) * (res.v @ rig.b), res.t)
    assert res.external[-1] > 0
    assert abs(work - res.external[-1]) < 1e-4 * res.external[-1]
    assert res.energy_balance_error < 1e-9


def test_no_crossing_missed_exact_against_explicit(rig):
    """The exact integrator's impacts are the explicit integrator's (omega dt = 0.02 on the top
    mode: an independent method that steps through every contact): same count per tip, and the
    first impact's peak force within 0.1 % (later ones drift apart as any two runs of an impacting
    ringdown do)."""
    from bearingshaft.stages.hammer import impacts

    # the two runs agree to 1 um for the first ~30 ms; after that an impacting ringdown's
    # sensitivity (symmetric motion splitting) separates any two runs
    ex, _ = _run(rig, 500.0, duration=0.025)
    ce, _ = _run(rig, 500.0, duration=0.025, method="explicit", omega_dt=0.02)

    class R:
        def __init__(self, r):
            self.x, self.t = r.x, r.t

    a, b = impacts(rig, R(ex)), impacts(rig, R(ce))
    assert sum(v["impacts"] for v in a.values()) >= 2
    for cell in a:
        assert a[cell]["impacts"] == b[cell]["impacts"]

    def first_peak(r, j):
        pen = rig.system.penetration(r.x)[:, j]
        closed = np.flatnonzero(pen > 0)
        end = closed[0] + np.argmax(pen[closed[0]:] <= 0)
        return rig.system.k[j] * pen[closed[0]:end].max()

    for j in range(4):
        if a[list(a)[j]]["impacts"]:
            assert first_peak(ex, j) == pytest.approx(first_peak(ce, j), rel=1e-3)
    assert ex.stats["n_events"] >= 2 * sum(v["impacts"] for v in a.values())


def test_open_gap_response_equals_its_modal_superposition(built):
    """Linear limit on the reduced model itself: gaps that never close, the exact integrator's
    channels against the closed-form modal superposition (fem.modal_response) of the same
    model's modes with its non-proportional damping: equal to 1e-7 of each channel's peak
    (the exact integrator is exact to round-off; the residual is the eigen-solutions')."""
    from fem.modal_response import ModalModel
    from reduced.models.modes import linear_modes

    rom, _ = built
    op = virtual_rig(replace(rom, gap=1.0), default_location(rom), (0, 0, -1))
    res, sig = _run(op, 50.0, duration=0.1)
    data = op.channel_data(res.x, res.v, sig(res.t))
    lm = linear_modes(op.system, "open")
    Cm = lm.phi.T @ op.system.C @ lm.phi
    ref = ModalModel(lm.omega, 0.5 * (Cm + Cm.T)).half_sine_response(
        res.t, lm.phi.T @ op.b, op.acc_rows @ lm.phi, 50.0, 1e-3, 0.002).acceleration
    scale = np.max(np.abs(ref), axis=1)
    strong = scale > 1e-6 * scale.max()
    err = np.max(np.abs(data[:30] - ref), axis=1)[strong] / scale[strong]
    assert np.max(err) < 1e-7


def test_coupled_subsystem_keeps_the_gap_dynamics(rig):
    """The NNM backbones' subsystem has the same open- and closed-gap frequencies for every mode
    that moves a gap."""
    from reduced.models.modes import gap_moving_modes, linear_modes

    sub = coupled_subsystem(rig.system)
    assert sub.n < rig.system.n
    for state in ("open", "closed"):
        full = linear_modes(rig.system, state).freq_hz[gap_moving_modes(rig.system, state, 3)]
        part = linear_modes(sub, state).freq_hz[gap_moving_modes(sub, state, 3)]
        np.testing.assert_allclose(part, full, rtol=1e-9)


# -- the stage: files, UFF 58 out and in -------------------------------------------------------
@pytest.fixture(scope="module")
def stage_run(built, tmp_path_factory):
    folder = tmp_path_factory.mktemp("hammer")
    scene = folder / "small.toml"
    scene.write_text(SCENE.format(n_modes=N_MODES, gap=2.54e-4))
    rc, out, err = _cli("hammer", "--scene", str(scene), "--out", str(folder / "res"), "--no-progress")
    assert rc == 0, err
    return folder, scene, out


def test_stage_writes_every_file(stage_run):
    folder, _, out = stage_run
    res = folder / "res"
    for name in ("hammer.npz", "channels.csv", "hammer.uff", "fig10.png", "fig11.png", "levels.png", "levels.csv",
                 "hammer.md"):
        assert (res / name).stat().st_size > 0, name
    text = (res / "hammer.md").read_text()
    assert "Impacts:" in text and "Pseudo-rigid" in text
    assert "virtual hammer test" in out
    rows = (res / "levels.csv").read_text().splitlines()
    assert rows[1].startswith("20.0,0,")  # the 20 N blow never closes a gap
    assert int(rows[2].split(",")[1]) > 0  # the 500 N blow does
    # the nominal record's largest Lyapunov exponent, one row per displaced run: the reproduction report's horizon
    import csv as _csv

    from bearingshaft.reproduction import horizon
    from bearingshaft.stages.hammer import LYAPUNOV_SEEDS

    with open(res / "lyapunov.csv", newline="") as fh:
        lyap = list(_csv.DictReader(fh))
    assert len(lyap) == LYAPUNOV_SEEDS and all(r["delta"] == "1e-09" for r in lyap)
    assert horizon(res, ("lyapunov.csv",)).exponent_per_s == max(
        float(r["exponent_per_s"]) for r in lyap if r["chaotic"] == "True" or not any(
            q["chaotic"] == "True" for q in lyap))


def test_uff_round_trip_reproduces_every_channel(stage_run):
    res = stage_run[0] / "res"
    with np.load(res / "hammer.npz") as z:
        data, t, names = z["data"], z["t"], [str(s) for s in z["names"]]
    back = {c.name: c for c in read_uff58(res / "hammer.uff")}
    assert list(back) == names
    for i, n in enumerate(names):
        np.testing.assert_array_equal(back[n].data, data[i])
        assert back[n].dt_s == pytest.approx(t[1] - t[0], rel=1e-15)
    assert back["hammer"].quantity == "force" and back["tip_right_top"].quantity == "reaction_force"


def test_measured_test_is_compared_channel_for_channel(stage_run, built, tmp_path):
    """A 'measured' file is read, drives the model by its hammer channel and is compared. The
    models blow with a measured force (force_file) sampled on the record's grid, so a file the
    model wrote itself gives it back the same force: every error is 0 to round-off over the
    first 50 ms (the record's last bits of time, re-read from the file, move the breakpoints by
    1e-19 s; the symmetric impacting motion is unstable and grows such differences by ~e^(250 t),
    so a whole 0.15 s record would not say 0), while a file made by another model (gap 1.5 x)
    gives errors of order one. (A half-sine
    blow re-read from its 20 kHz samples is another force, linear between samples, whose 0.4 %
    less impulse moves the impacts: in an impacting ringdown that alone makes O(1) differences.)"""
    import csv

    t = np.arange(0, 0.15 + 1e-12, 5e-5)
    force = tmp_path / "force.csv"
    np.savetxt(force, np.column_stack([t, HalfSine(500.0, 1e-3, 0.005)(t)]), delimiter=",", header="t_s,force_N")
    scenes = {}
    for name, gap in (("own", 2.54e-4), ("other", 3.81e-4)):
        scenes[name] = tmp_path / f"{name}.toml"
        scenes[name].write_text(SCENE.format(n_modes=N_MODES, gap=gap).replace(
            "[hammer]\n", f"[hammer]\nforce_file = '{force}'\ncompare_window_s = [0.0, 0.05]\n"))
        rc, _, err = _cli("hammer", "--scene", str(scenes[name]), "--out", str(tmp_path / f"{name}-run"),
                          "--no-progress")
        assert rc == 0, err
    for name in ("own", "other"):
        rc, out, err = _cli("hammer", "--scene", str(scenes["own"]), "--test",
                            str(tmp_path / f"{name}-run" / "hammer.uff"), "--out", str(tmp_path / name),
                            "--no-progress")
        assert rc == 0, err
        assert "driven by the test's hammer channel" in out
        assert (tmp_path / name / "test_compare.png").stat().st_size > 0
        assert (tmp_path / name / "test_spectrogram.png").stat().st_size > 0

    def errors(name):
        with open(tmp_path / name / "test_errors.csv") as f:
            return {r["name"]: float(r["rms_rel_error"]) for r in csv.DictReader(f)}

    own, other = errors("own"), errors("other")
    assert len(own) == len(channel_names()) - 1  # every channel but the hammer
    assert max(own[c] for c in own if c.endswith(":z")) < 1e-6
    assert min(other[c] for c in other if c.endswith(":z")) > 0.05


def test_measured_file_with_missing_channel_or_wrong_unit_is_refused(stage_run, tmp_path):
    folder, scene, _ = stage_run
    chans = read_uff58(folder / "res" / "hammer.uff")
    missing = tmp_path / "missing.uff"
    write_uff58(missing, [c for c in chans if c.name != "beam_s3:z"])
    rc, _, err = _cli("hammer", "--scene", str(scene), "--test", str(missing), "--out", str(tmp_path / "m"))
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "beam_s3:z" in err and "compare" in err
    assert not (tmp_path / "m").exists()

    wrong = tmp_path / "wrong.uff"  # an accelerometer in g: the unit label edited in an ASCII record
    write_uff58(wrong, [chans[0]], binary=False)
    text = wrong.read_text()
    assert text.count("m/s^2") == 1
    wrong.write_text(text.replace("m/s^2", "g    "))
    rc, _, err = _cli("hammer", "--scene", str(scene), "--test", str(wrong), "--out", str(tmp_path / "w"))
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "'g'" in err and "m/s^2" in err


def _stats(folder) -> dict:
    import json

    return json.loads((folder / "provenance.json").read_text())["stages"]["hammer"]["stats"]


def test_comparison_says_where_chaos_starts_and_what_matches_after(stage_run, tmp_path):
    """The model's own half-sine export read back: driven by its 20 kHz samples the model gets a
    blow ~0.3 % different ((pi dt / d)^2 / 8 of the peak), which the impacts grow until the traces
    part. The horizon the tool predicts from its own two runs is where the measured mismatch
    (median over the channels, 2 ms windows) crosses the tolerance: below it from the blow to the
    horizon, above it in the 20 ms after (an independent check: the prediction never sees the test's
    samples after the blow). Past the horizon the spectrogram ridges of the beam still agree."""
    import csv

    from bearingshaft.measured import HORIZON_TOL

    folder, scene, _ = stage_run
    out = tmp_path / "c"
    rc, text, err = _cli("hammer", "--scene", str(scene), "--test", str(folder / "res" / "hammer.uff"), "--out",
                         str(out), "--no-progress")
    assert rc == 0, err
    for name in ("test_errors.csv", "test_measures.csv", "test_horizon.csv", "test_compare.md", "test_compare.png",
                 "test_horizon.png", "test_measures.png", "test_spectrogram.png", "model.uff"):
        assert (out / name).stat().st_size > 0, name
    st = _stats(out)
    hz, start = float(st["horizon_s"]), 0.005 + 1e-3 + 1e-3  # the blow's end and the force window's margin
    assert start < hz < 0.15 and st["lyapunov_exponent_per_s"] > 0
    assert "predictable to" in text and "Where chaos starts" in (out / "test_compare.md").read_text()
    with open(out / "test_horizon.csv") as fh:
        rows = [{k: float(v) if v else float("nan") for k, v in r.items()} for r in csv.DictReader(fh)]
    before = [r["measured_mismatch"] for r in rows if start < r["t_s"] < hz]
    after = [r["measured_mismatch"] for r in rows if hz < r["t_s"] < hz + 0.02]
    assert before and max(before) < HORIZON_TOL, before
    assert after and np.median(after) > HORIZON_TOL, after
    with open(out / "test_errors.csv") as fh:
        errors = list(csv.DictReader(fh))
    assert len(errors) == len(channel_names()) - 1
    assert all(float(r["t_end_s"]) <= hz + 1e-9 for r in errors)
    assert max(float(r["rms_rel_error"]) for r in errors) < 2 * HORIZON_TOL
    with open(out / "test_measures.csv") as fh:
        ms = list(csv.DictReader(fh))
    assert {r["measure"] for r in ms} == {"ridges", "envelope", "impacts", "open"}  # backbone_modes = 0
    beam = [float(r["error"]) for r in ms if r["statistic"] == "frames within one bin" and r["channel"] == "beam_s3:z"]
    assert beam[0] > 0.5


def test_a_linear_test_has_no_horizon(built, tmp_path):
    """Gaps too large to close: the motion is linear, no horizon, and the pointwise errors hold over the
    whole record: the half-sine's 20 kHz samples (linear between them) move every strong channel by at
    most (pi dt / d)^2 / 8 = 0.31 % of its peak (test_a_measured_force_history_drives_the_blow), so
    its RMS error is below that (with the floor, judged against its sensor's largest axis: 1 %)."""
    scene = tmp_path / "open.toml"
    scene.write_text(SCENE.format(n_modes=N_MODES, gap=1.0).replace("levels_N = [20.0, 500.0]", "levels_N = [500.0]"))
    rc, _, err = _cli("hammer", "--scene", str(scene), "--out", str(tmp_path / "v"), "--no-progress")
    assert rc == 0, err
    rc, text, err = _cli("hammer", "--scene", str(scene), "--test", str(tmp_path / "v" / "hammer.uff"), "--out",
                         str(tmp_path / "c"), "--no-progress", "--measures", "time,envelope", "--window", "0:0.1")
    assert rc == 0, err
    st = _stats(tmp_path / "c")
    assert float(st["horizon_s"]) == math.inf and st["measures"] == ["time", "envelope"]
    assert st["worst_rms_rel_error"] < (np.pi * 5e-5 / 1e-3) ** 2 / 8
    assert "gaps do not close" in (tmp_path / "c" / "test_compare.md").read_text()
    assert not (tmp_path / "c" / "test_backbone.png").exists()


@pytest.mark.parametrize("args, words", [
    (["--window", "0.1"], ["--window", "START:END"]),
    (["--window", "0.2:0.1"], ["--window", "0 <= START < END"]),
    (["--measures", "ridge"], ["'ridge'", "did you mean 'ridges'"]),
])
def test_comparison_options_are_refused_in_one_line(stage_run, tmp_path, args, words):
    folder, scene, _ = stage_run
    rc, _, err = _cli("hammer", "--scene", str(scene), "--test", str(folder / "res" / "hammer.uff"), "--out",
                      str(tmp_path / "x"), *args)
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert all(w in err for w in words), err
    assert not (tmp_path / "x").exists()
    rc, _, err = _cli("hammer", "--scene", str(scene), "--out", str(tmp_path / "y"), "--window", "0:0.1")
    assert rc == 2 and "--test" in err and not (tmp_path / "y").exists()


def test_hammer_scene_errors_are_one_line(tmp_path):
    bad = {
        'kind = "discrete"': "[hammer]",
        "[hammer]\ncompare = [\"beam_s9:z\"]": "compare",
        "[hammer]\nstart_s = 0.2": "start_s",
        "[hammer]\nload_cell = \"tip_middle\"": "load_cell",
        "[hammer]\ndirection = [0.0, 0.0, 0.0]": "direction",
    }
    for change, word in bad.items():
        text = SCENE.format(n_modes=N_MODES, gap=2.54e-4)
        if change.startswith("kind"):
            text = "[model]\nkind = \"discrete\"\n" + text[text.index("[hammer]"):]
        else:
            key = change.split("\n")[1]
            text = text.replace("[hammer]\n", "[hammer]\n" + key + "\n", 1)
            text = text.replace("backbone_modes = 0", "backbone_modes = 0") if "start_s" not in key else \
                text.replace("start_s = 0.005\n", "")
        path = tmp_path / "bad.toml"
        path.write_text(text)
        rc, _, err = _cli("check", "--scene", str(path))
        assert rc == 2, (change, err)
        assert len(err.strip().splitlines()) == 1 and word in err, (change, err)


def test_a_measured_force_history_drives_the_blow(built, tmp_path):
    """force_file: a 500 N, 1 ms half-sine tabulated every dt (a CSV, and the same samples as a
    UFF 58 record written and read back) drives the apparatus as the analytic half-sine does, to
    the error of linear interpolation.

    Gaps open (1 m), so the response is linear in the force and the difference of two responses
    is the response to the difference of the forces (with impacts the symmetric motion is
    unstable and any difference grows, see the test above). The chord between samples of
    F sin(pi t / d) lies below it by at most F (pi dt / d)^2 / 8, so every channel's error is
    bounded by eps8 = (pi dt / d)^2 / 8 of its peak. The displacements and velocities are
    carried by the pseudo-rigid modes (10-35 Hz), for which the 1 ms blow is an impulse, and the
    tabulated blow's impulse is the trapezoid rule's, short of the half-sine's 2 F d / pi by
    (dt^2 / 12)(f'(start) - f'(end)) = 2 F d / pi x eps12, eps12 = (pi dt / d)^2 / 12: their
    error is that fraction of their peak (measured ratio 0.667 = 8 / 12 of eps8 at dt = 1, 5,
    10, 20 us; accelerations, with kHz modes, 0.70 - 0.75 of eps8). Second order: halving dt
    divides the error by 4 (measured 4.0).
    The UFF 58 record of the CSV's samples (binary: every bit; ASCII: 12 digits) is read back as
    the same force and drives the same response.
    """
    from bearingshaft.scenes import load_scene
    from bearingshaft.stages.hammer import blow

    rom, _ = built
    op = virtual_rig(replace(rom, gap=1.0), default_location(rom), (0.0, 0.0, -1.0))
    peak, d, start = 500.0, 1e-3, 0.002
    half_sine = HalfSine(peak, d, start)

    def scene_blow(force_file, level_N):
        text = SCENE.format(n_modes=N_MODES, gap=2.54e-4).replace(
            "[hammer]\n", f"[hammer]\nforce_file = '{force_file}'\n")
        path = tmp_path / "forced.toml"
        path.write_text(text)
        return blow(load_scene(str(path)).hammer, level_N)

    def tabulate(dt):
        t = np.arange(0, 0.004, dt)
        f = half_sine(t)
        csv = tmp_path / f"force_{dt:g}.csv"
        np.savetxt(csv, np.column_stack([t, f]), delimiter=",", header="t_s,force_N")
        return t, f, csv

    def response(sig):
        n = op.system.n
        res = ringdown(op.system, np.zeros(n), np.zeros(n), 0.02, 20000.0, "exact", loads=op.loads(sig))
        return res, op.channel_data(res.x, res.v, sig(res.t))[:-1]  # every channel but the hammer

    ref, ref_data = response(half_sine)
    scale = np.max(np.abs(ref_data), axis=1)
    strong = scale > 1e-6 * scale.max()  # axes zero by symmetry carry only round-off

    errors = {}
    for dt in (1e-5, 5e-6):
        t, f, csv = tabulate(dt)
        sig = scene_blow(csv, 2 * peak)
        np.testing.assert_allclose(sig.force_N, 2 * f, rtol=1e-15, atol=1e-12)  # scaled to the level's peak
        sig = scene_blow(csv, peak)
        res, data = response(sig)
        eps8, eps12 = (np.pi * dt / d) ** 2 / 8, (np.pi * dt / d) ** 2 / 12
        err = np.max(np.abs(data - ref_data), axis=1)[strong] / scale[strong]
        assert err.max() < eps8, (dt, err.max() / eps8)
        for mine, theirs in ((res.x, ref.x), (res.v, ref.v)):
            ratio = np.max(np.abs(mine - theirs)) / np.max(np.abs(theirs)) / eps12
            assert abs(ratio - 1.0) < 0.02, (dt, ratio)  # the impulse deficit; O(dt^2) of it more
        errors[dt] = err.max()
    rate = np.log2(errors[1e-5] / errors[5e-6])
    assert 1.9 < rate < 2.1, f"observed order {rate:.3f}"

    # the CSV's 10 us samples as a UFF 58 force record (the hammer's node and direction code),
    # read back by the force_file reader: the same table, the same response
    t, f, csv = tabulate(1e-5)
    from_csv = scene_blow(csv, peak)
    _, csv_data = response(from_csv)
    for binary in (True, False):
        uff = tmp_path / f"force_{binary}.uff"
        write_uff58(uff, [TimeHistory("hammer", 300, -3, "force", f, 1e-5)], binary=binary)
        from_uff = scene_blow(uff, peak)
        np.testing.assert_array_equal(from_uff.t_s, from_csv.t_s)
        if binary:
            np.testing.assert_array_equal(from_uff.force_N, from_csv.force_N)
            np.testing.assert_array_equal(response(from_uff)[1], csv_data)
        else:  # 12 significant digits (4E20.12): 5e-12 of the peak, and so of the response
            np.testing.assert_allclose(from_uff.force_N, from_csv.force_N, rtol=0, atol=5e-12 * peak)
            uff_err = np.max(np.abs(response(from_uff)[1] - csv_data), axis=1)[strong] / scale[strong]
            assert uff_err.max() < 1e-10


def test_rms_errors_judge_a_symmetry_zero_axis_against_its_sensor():
    """rms(a - ref) / rms(ref) per channel; an axis below 1 % of its sensor's largest is scaled by that."""
    from bearingshaft.stages.hammer_linear import rms_errors

    t = np.linspace(0.0, 1.0, 1001)
    ref = np.vstack([np.sin(20 * t), 1e-4 * np.sin(20 * t), np.cos(3 * t), 2.0 * np.ones_like(t)])
    a = ref + np.vstack([0.01 * np.sin(20 * t), 1e-4 * np.sin(20 * t), 0.0 * t, 0.02 * np.ones_like(t)])
    names = ["beam_s1:z", "beam_s1:x", "tube_s1:z", "tip_left_top"]
    mask = t >= 0.5
    e, near = rms_errors(a, ref, names, mask)
    np.testing.assert_allclose(e, [0.01, 1e-4, 0.0, 0.01], rtol=1e-12, atol=1e-15)
    assert near.tolist() == [False, True, False, False]


def _full_against_reduced(rom, scene):
    """rms errors per channel, in a 100 Hz band, of the open-gap reduced apparatus against the full
    3-D model's modal superposition (:func:`full_reference`), 20 N half-sine; and the names."""
    from bearingshaft.stages.hammer import run_record
    from bearingshaft.stages.hammer_linear import band_limited, full_reference, rms_errors

    rig = virtual_rig(replace(rom, gap=1.0), default_location(rom), (0.0, 0.0, -1.0))
    rec = run_record(rig, HalfSine(20.0, 1e-3, scene.hammer.start_s), scene, 20.0)
    full = full_reference(scene, rig, 20.0, rec.t.size, False)
    assert full.names == [*rig.names[:-1]] and full.top_hz < scene.hammer.linear_check_max_hz
    e, _ = rms_errors(band_limited(rec.data[:-1], 20000.0, 100.0), band_limited(full.data, 20000.0, 100.0),
                      full.names, rec.t >= scene.hammer.start_s)
    return e, full.names


def test_full_reference_agrees_with_the_reduced_apparatus_on_a_small_mesh(monkeypatch, tmp_path):
    """Fast variant of the slow test below, the same comparison on a smaller model: the hex8 mesh
    (4,185 DOFs against hex20's 15,087; Craig-Bampton and the full modes in ~2 s each) and a
    50 ms record. The 20 fixed-interface modes reach 4.9 kHz, the full modes 3.5 kHz; each
    misses its modes above, whose quasi-static share of a 100 Hz acceleration is (f / f_c)^2 ~
    4e-4 of their participation. Measured: accelerometer axes 4.8e-4 (bound 1.5e-3), the load
    cells, which read the seats' seismic inertia at the Craig-Bampton interface, 4.5e-3 (bound
    1e-2; 2.8e-5 with 80 modes, so it is the reduced model's truncation). A wrong load, mass or
    damping in either model gives errors of order one."""
    import fem.model
    import reduced.models.mesh_cache
    from bearingshaft.scenes import parse_scene

    spec = RomSpec(layout="assembly", planar=False, n_modes=N_MODES, element="hex8", gap=1.0)
    rom, fe = cached_rom(spec), build_fe(spec)  # the model cache's (a cached model is the build's bits)
    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))  # full_reference keeps its full modes there
    text = SCENE.format(n_modes=N_MODES, gap=1.0).replace("planar = false", 'planar = false\nelement = "hex8"')
    text = text.replace("backbone_modes = 0", "backbone_modes = 0\nlinear_check_max_hz = 4000.0")
    scene = parse_scene(text.replace("duration_s = 0.15", "duration_s = 0.05"), "t", "test")
    # full_reference assembles the scene's 3-D model again: it is the one just built (2 s saved)
    assert scene.model.fe_model() == spec.fe_model()
    monkeypatch.setattr(reduced.models.mesh_cache, "cached_mesh", lambda g: None)  # not meshed again either
    monkeypatch.setattr(fem.model, "build_system", lambda model, mesh=None: fe if model == spec.fe_model() else None)
    e, names = _full_against_reduced(rom, scene)
    cells = np.array([n.startswith("tip_") for n in names])
    assert cells.sum() == 4
    assert e[~cells].max() < 1.5e-3, e[~cells].max()
    assert e[cells].max() < 1e-2, e[cells].max()


def test_full_modes_from_the_cache_are_the_bits_of_one_direct_solve(monkeypatch, tmp_path):
    """The linear check's full modes (:func:`full_modes`): the search (24, 48, ... modes until the top passes
    max_hz) returns the first count that passes, its modes those of one direct solve of that count bit for bit
    (seeded ARPACK start, SuperLU); a second call loads them from the cache, bit for bit, without solving.
    The hex8 apparatus (4,185 DOFs) with max_hz = 5 kHz (24 modes reach 4.4 kHz): 48
    modes, about 1 s a solve."""
    from bearingshaft.stages import hammer_linear
    from fem.modal import modal_analysis
    from fem.model import AssemblyModel, build_system

    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))
    fe = build_system(AssemblyModel(layout="assembly", element="hex8", gap=1.0))
    max_hz = 5000.0
    solved = hammer_linear.full_modes(fe, max_hz, False)
    k = solved.freq_hz.size
    assert k >= 48 and solved.freq_hz[-1] > max_hz >= solved.freq_hz[k // 2 - 1], (k, solved.freq_hz)  # it doubled
    direct = modal_analysis(fe.K, fe.M, n_modes=k, shift_hz=0.1, method="lanczos", solver="superlu")
    assert np.array_equal(solved.phi, direct.phi) and np.array_equal(solved.freq_hz, direct.freq_hz)
    assert len(list(tmp_path.glob("fullmodes-*.npz"))) == 1

    def solve_again(*args):
        raise AssertionError("solved again: the cache was not read")

    monkeypatch.setattr(hammer_linear, "_search_full_modes", solve_again)
    loaded = hammer_linear.full_modes(fe, max_hz, False)
    assert np.array_equal(loaded.phi, direct.phi) and np.array_equal(loaded.freq_hz, direct.freq_hz)
    assert np.array_equal(loaded.omega2, direct.omega2)
    with pytest.raises(AssertionError, match="solved again"):  # another max_hz is another entry
        hammer_linear.full_modes(fe, 2 * max_hz, False)


@pytest.mark.slow
def test_full_reference_agrees_with_the_reduced_apparatus_at_low_frequency(built):
    """The full 3-D model's modal superposition (:func:`full_reference`, modes to 4 kHz) and the
    20-mode reduced apparatus (fixed-interface modes to 1.9 kHz), open gaps, 20 N, both in a
    100 Hz band: each misses modes above its cut-off whose share of a 100 Hz acceleration is
    ~(f / f_c)^2 = (0.1 / 1.9)^2 ~ 3e-3 of their participation; measured 1.1e-3 (80 s)."""
    from bearingshaft.scenes import parse_scene

    rom, _ = built
    scene = parse_scene(SCENE.format(n_modes=N_MODES, gap=1.0).replace(
        "backbone_modes = 0", "backbone_modes = 0\nlinear_check_max_hz = 4000.0"), "t", "test")
    e, _ = _full_against_reduced(rom, scene)
    assert e.max() < 3e-3
