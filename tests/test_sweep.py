"""Sweeps on Dask (issue 13): the design, refusals before anything runs, closed-form metrics of a
linear sweep, resume, failures as rows, and a worker killed mid-sweep.

The closed form: with the gaps far away (gap = 1 m, amplitudes of 1 mm) the 3-DOF model is
linear, and x(0) = [d, 0, -d], v(0) = 0 starts its antisymmetric mode alone (m1 = m3, C = c I:
the mode decouples). Its coordinate q = x1 = -x3 obeys m1 q'' + c q' + 2 k_s q = 0, so x1 rings at
f_d = sqrt(2 k_s / m1 - sigma^2) / (2 pi), sigma = c / (2 m1), in every window, and its energy
E = m1 q'^2 + 2 k_s q^2 is known at every sample.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import threading
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bearingshaft.cli import main
from bearingshaft.registry import stages_of
from bearingshaft.scenes import load_scene, parse_scene
from bearingshaft.sweep import (
    SweepError,
    SweepSpec,
    build_plan,
    case_complete,
    design_points,
    dominant_freq_hz,
    parse_vary_option,
    run_sweep,
)

M1, C, D = 0.629, 4.0, 1e-3  # kg, N s/m (Table 1), m: the start's amplitude
LINEAR = f"""
description = "linear antisymmetric mode"
[model]
kind = "discrete"
gap = 1.0
[initial]
x0_m = [{D}, 0.0, {-D}]
[ringdown]
duration_s = 4.0
sample_rate_hz = 2000.0
"""
K_S = (8000.0, 16000.0, 30000.0)  # N/m: f_d = 25.4 to 49.2 Hz, 12 to 25 periods in a 0.5 s window


def closed_form(k_s: float, t: np.ndarray) -> tuple[float, np.ndarray]:
    """(f_d, E(t)) of the antisymmetric mode from x1 = d, v = 0."""
    sigma = C / (2 * M1)
    wd = math.sqrt(2 * k_s / M1 - sigma**2)
    q = D * np.exp(-sigma * t) * (np.cos(wd * t) + sigma / wd * np.sin(wd * t))
    dq = -D * np.exp(-sigma * t) * (wd + sigma**2 / wd) * np.sin(wd * t)
    return wd / (2 * math.pi), M1 * dq**2 + 2 * k_s * q**2


def plan_of(text: str, *vary: str, design: str = "grid", **kw):
    scene = parse_scene(text, "lin", "lin.toml")
    spec = SweepSpec(tuple(parse_vary_option(v) for v in vary), design, **kw)
    return build_plan(scene, spec, "--vary")


@pytest.fixture(scope="module")
def client():
    from bearingshaft.sweep import dask_client

    with dask_client(workers=2) as (c, _):
        yield c


# -- the design --------------------------------------------------------------------------------
@pytest.mark.parametrize("text, values", [
    ("model.gap=1e-4:1e-3:3:log", (1e-4, 10**-3.5, 1e-3)),
    ("model.k_g=1e7,1e8", (1e7, 1e8)),
    ("model.c=0:8:5", (0, 2, 4, 6, 8)),  # integer ends: integers (the parser takes them for a float key)
    ("model.c=0.0:8.0:5", (0.0, 2.0, 4.0, 6.0, 8.0)),
    ("ringdown.method=exact,explicit", ("exact", "explicit")),
    ("fep.n_shooting=10:30:3", (10, 20, 30)),  # integer ends: integers
    ("initial.v0_m_s[2]=200", (200,)),
])
def test_vary_values(text, values):
    v = parse_vary_option(text)
    if isinstance(values[0], str):
        assert v.values == values
    else:
        assert v.values == pytest.approx(values, rel=1e-15)
    assert [type(a) for a in v.values] == [type(b) for b in values]


def test_random_design_is_a_latin_hypercube():
    spec = SweepSpec((parse_vary_option("model.c=0.0:8.0"), parse_vary_option("model.k_g=1e6:1e9:log")), "random",
                     samples=50, seed=3)
    pts = np.array(design_points(spec))
    assert pts.shape == (50, 2)
    # one sample in each of the 50 strata of each key (linear strata for c, log strata for k_g)
    assert sorted(np.floor(pts[:, 0] / 8 * 50).astype(int)) == list(range(50))
    assert sorted(np.floor(np.log(pts[:, 1] / 1e6) / np.log(1e3) * 50).astype(int)) == list(range(50))
    assert design_points(spec) == design_points(spec)  # seeded
    assert design_points(dataclasses.replace(spec, seed=4)) != design_points(spec)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(lo=st.floats(1e-12, 1e12), ratio=st.floats(1.0 + 1e-9, 1e6), n=st.integers(1, 60),
       scale=st.sampled_from(["", ":lin", ":log"]))
def test_ranges_keep_their_ends_and_order(lo, ratio, n, scale):
    hi = lo * ratio
    v = parse_vary_option(f"model.k_g={lo!r}:{hi!r}:{n}{scale}")
    assert len(v.values) == n and v.values[0] == lo
    if n > 1:
        assert v.values[-1] == pytest.approx(hi, rel=1e-12)
        assert all(b > a for a, b in zip(v.values, v.values[1:], strict=False))
    assert all(lo * (1 - 1e-12) <= x <= hi * (1 + 1e-12) for x in v.values)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=8))
def test_lists_round_trip(values):
    v = parse_vary_option("model.k_g=" + ",".join(repr(x) for x in values))
    assert v.values == tuple(values)


@settings(max_examples=500, deadline=None, derandomize=True)
@given(st.text(max_size=40))
def test_any_vary_text_parses_or_is_refused_in_one_line(text):
    try:
        parse_vary_option(text)
    except SweepError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("--vary")


# -- refusals: one line, exit 2, before anything runs -------------------------------------------
@pytest.mark.parametrize("argv, expected", [
    (["--vary", "model.g=1e-4,2e-4"], "[model]: unknown key 'g' (did you mean 'gap'? the key was renamed)"),
    (["--vary", "model.gap=-1e-3,1e-3"], "gap must be >= 0, got -0.001"),
    (["--vary", "modle.g=1e-4"], "unknown table 'modle' (did you mean 'model'?)"),
    (["--vary", "model.gap=1e-4", "--design", "grd"], "unknown design 'grd' (did you mean 'grid'?)"),
    (["--vary", "model.gap=1e-4,2e-4", "--vary", "model.k_g=1e7", "--design", "zip"], "every key needs as many"),
    (["--vary", "model.gap=1e-4,2e-4", "--design", "random", "--samples", "4"], "the random design samples a range"),
    (["--vary", "model.gap=1e-4:1e-3", "--design", "grid"], "needs the values"),
    (["--vary", "model.gap=1e-4:1e-3:0"], "number of values must be an integer >= 1"),
    (["--vary", "model.gap=1e-4:1e-3:4:log", "--vary", "model.gap=1e-4"], "model.gap: the key is varied twice"),
    (["--vary", "nnm.n_energy=10,20"], "the scene has no [nnm] table"),
    (["--vary", "initial.v0_m_s[3]=1.0"], "v0_m_s has 3 values; [3] is not one"),
    (["--vary", "ringdown.duration_s=1.0,nan"], "duration_s: must be finite"),
    (["--vary", "ringdown.method=exact,rk4"], "method must be one of"),
    (["--vary", "model.gap=1e-4,1e-4"], "two cases have the same values"),
    (["--vary", "model.gap"], "expected KEY=VALUES"),
    (["--vary", "model.gap=1e-4", "--workers", "0"], "--workers: expected an integer >= 1"),
    ([], "the scene has no [sweep] table; give --vary"),
])
def test_bad_sweep_is_one_line_exit_2_before_anything_runs(tmp_path, capsys, monkeypatch, argv, expected):
    import bearingshaft.sweep.run as sweep

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started for a sweep that must be refused")

    monkeypatch.setattr(sweep, "dask_client", no_cluster)
    scene = tmp_path / "lin.toml"
    scene.write_text(LINEAR)
    out = tmp_path / "out"
    assert main(["sweep", "--scene", str(scene), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bearingshaft: error: ") and err.count("\n") == 1, err
    assert expected in err, err
    assert not out.exists()


@pytest.mark.parametrize("table, expected", [
    ('[sweep]\ndesign = "grd"\n[sweep.vary]\n"model.gap" = [1e-4]\n', "[sweep] design: unknown design 'grd'"),
    ('[sweep]\nvary_ = 1\n', "[sweep]: unknown key 'vary_' (did you mean 'vary'?)"),
    ('[sweep.vary]\n"model.gap" = "1e-4:x:3"\n', "[sweep] vary model.gap: 'x' is not a number"),
    ('[sweep]\nsamples = -1\n', "[sweep] samples: expected an integer >= 0"),
    ('[sweep]\noverlay = "nnm"\n', "[sweep] overlay: unknown overlay 'nnm'"),
])
def test_bad_sweep_table_is_refused_by_check(tmp_path, capsys, table, expected):
    scene = tmp_path / "lin.toml"
    scene.write_text(LINEAR + table)
    assert main(["check", "--scene", str(scene), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1, err


def test_check_validates_every_case_of_a_sweep(tmp_path, capsys):
    # `bearingshaft check` refuses what `bearingshaft sweep` would refuse, before any case runs
    scene = tmp_path / "lin.toml"
    scene.write_text(LINEAR + '[sweep.vary]\n"model.k_s" = [8000.0, -5.0]\n')
    assert main(["check", "--scene", str(scene), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert "case model.k_s = -5.0 [model]: k_s must be > 0, got -5.0" in captured.err
    scene.write_text(LINEAR + '[sweep.vary]\n"model.k_s" = [8000.0, 16000.0, 30000.0]\n')
    assert main(["check", "--scene", str(scene), "--out", str(tmp_path / "out")]) == 0
    assert "[sweep]: 3 cases valid (grid over model.k_s)" in capsys.readouterr().out
    assert not (tmp_path / "out").exists()


def test_unreachable_scheduler_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    # the wait is Dask's own connect timeout, as configured (here 1 s); then one line naming the
    # option, exit 2
    import dask
    import distributed

    seen = {}
    real_client = distributed.Client

    def client(*a, **k):
        seen.update(k)
        return real_client(*a, **k)

    monkeypatch.setattr(distributed, "Client", client)
    scene = tmp_path / "lin.toml"
    scene.write_text(LINEAR)
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["sweep", "--scene", str(scene), "--out", str(tmp_path / "out"), "--vary",
                     "model.k_s=8000,16000", "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert seen["timeout"] == "1s"
    err = capsys.readouterr().err
    assert err.startswith("bearingshaft: error: --scheduler 'tcp://127.0.0.1:9': cannot connect") and \
        err.count("\n") == 1, err


def test_builtin_sweeps_validate_every_case():
    gap_kg = load_scene("sweep-gap-kg")
    plan = build_plan(gap_kg, gap_kg.sweep, "sweep-gap-kg [sweep]")
    assert [len(v.values) for v in gap_kg.sweep.vary] == [15, 15] and len(plan.cases) == 225
    energy = load_scene("sweep-energy")
    plan = build_plan(energy, energy.sweep, "sweep-energy [sweep]")
    assert len(plan.cases) >= 200 and len({c.case_id for c in plan.cases}) == len(plan.cases)
    v = np.array([dict(c.values)["initial.v0_m_s[1]"] for c in plan.cases])
    E0 = 0.5 * 1.258 * v**2  # J, m2 v^2 / 2
    assert E0[0] < 2 * 8.03e3 * 2.54e-4**2 < 1e5 < E0[-1]  # from below grazing to above Fig. 4's 25160 J
    assert stages_of(energy) == ("ringdown",) and energy.symmetry is not None


def test_dominant_frequency_of_a_damped_sinusoid():
    fs, f0, sigma = 2000.0, 31.7, 3.2
    t = np.arange(1000) / fs  # 0.5 s: 16 periods
    y = np.exp(-sigma * t) * np.cos(2 * np.pi * f0 * t + 0.4)
    # the negative-frequency image's leakage: ~1e-6 with 16 periods (see dominant_freq_hz)
    assert dominant_freq_hz(y, fs, 5.0) == pytest.approx(f0, rel=5e-6)
    assert math.isnan(dominant_freq_hz(np.zeros(100), fs, 5.0))


# -- runs on a LocalCluster ---------------------------------------------------------------------
def test_linear_sweep_matches_closed_form_and_resumes(tmp_path, client):
    plan = plan_of(LINEAR, "model.k_s=" + ",".join(map(repr, K_S)))
    out = tmp_path / "sweep"
    res = run_sweep(plan, out, client=client, progress=False)
    assert [r["status"] for r in res.rows] == ["ok"] * len(K_S), [r["message"] for r in res.rows]
    fs, N = 2000.0, 8001
    t = np.arange(N) / fs
    for r, k_s in zip(res.rows, K_S, strict=True):
        f_d, E = closed_form(k_s, t)
        for w in ("early", "middle", "late"):
            # 12-25 periods in each 0.5 s window: the estimator's bias is below 2e-6 there
            assert r[f"freq_{w}_hz"] == pytest.approx(f_d, rel=1e-5), (w, k_s)
        assert r["energy_J_initial"] == pytest.approx(2 * k_s * D**2, rel=1e-12)
        # the first sample with E <= E0 / 100, from the closed form; the integrator is exact to ~1e-12
        k = int(np.flatnonzero(E <= 1e-2 * E[0])[0])
        assert abs(r["decay_time_s"] - t[k]) <= 1.0 / fs + 1e-12, (r["decay_time_s"], t[k])
        assert r["impacts"] == 0 and r["peak_tip_force_N"] == 0.0 and r["gaps_open_after_s"] == 0.0
        assert r["energy_balance_error"] < 1e-11
        assert r["run_time_s"] > 0 and r["worker"].startswith("tcp://")
    # the tables: one row per case, the varied key and every metric as columns
    table = pq.read_table(out / "sweep.parquet").to_pylist()
    assert [r["model.k_s"] for r in table] == list(K_S)
    assert table[0]["freq_late_hz"] == res.rows[0]["freq_late_hz"]
    lines = (out / "sweep.csv").read_text().splitlines()
    assert len(lines) == 1 + len(K_S) and lines[0].startswith("case_id,model.k_s,")
    assert (out / "sweep.png").stat().st_size > 0
    again_scene = load_scene(str(out / "sweep_scene.toml"))  # the sweep as run, as a scene: the same cases
    assert [c.case_id for c in build_plan(again_scene, again_scene.sweep, "x").cases] == \
        [c.case_id for c in plan.cases]
    for case in plan.cases:
        assert case_complete(out / case.case_id, case)
        assert (out / case.case_id / "scene.toml").read_text() == case.text
    # resume: nothing runs again, the same numbers come back with the first run's run times
    stamps = {c.case_id: (out / c.case_id / "provenance.json").stat().st_mtime_ns for c in plan.cases}
    again = run_sweep(plan, out, client=client, progress=False)
    assert all(r["resumed"] and r["status"] == "ok" for r in again.rows)
    assert {c.case_id: (out / c.case_id / "provenance.json").stat().st_mtime_ns for c in plan.cases} == stamps
    for a, b in zip(res.rows, again.rows, strict=True):
        assert a["freq_early_hz"] == b["freq_early_hz"] and a["decay_time_s"] == b["decay_time_s"]
        assert a["run_time_s"] == b["run_time_s"] and a["worker"] == b["worker"]


def test_a_failing_case_is_a_row_and_the_sweep_goes_on(tmp_path, client):
    text = LINEAR.replace("duration_s = 4.0", "duration_s = 0.2\nmethod = \"explicit\"")
    # dt = 1e-3 s is past the central difference's stable step (omega_max dt = 2 at dt ~ 2e-4 s with the tips
    # closed); the integrator refuses it when the stage starts, not the parser: that case fails, the other runs
    plan = plan_of(text, "ringdown.dt_s=1e-5,1e-3")
    res = run_sweep(plan, tmp_path / "s", client=client, progress=False)
    ok, bad = res.rows
    assert ok["status"] == "ok" and ok["energy_balance_error"] < 1e-2
    assert bad["status"] == "failed" and "stable step" in bad["message"] and "\n" not in bad["message"]
    assert not (tmp_path / "s" / bad["case_id"]).exists()
    rows = pq.read_table(tmp_path / "s" / "sweep.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "failed"]


def test_worker_killed_mid_sweep_loses_and_doubles_no_case(tmp_path, client):
    """SIGKILL a worker process of the LocalCluster while it runs a case: Dask reruns that task on a
    worker (the nanny restarts the dead one); every case ends in the table once, ok, with one
    complete folder. (The module's cluster: after the restart it serves any later test as before.)

    Deterministic, no race with a polling thread: the first case a worker starts is held inside its
    stage (a wrapper put on the workers' ``_run_stage`` by ``client.run``, armed by a file only one
    worker can claim, by an atomic rename) until the test kills that worker; the other worker
    meanwhile completes at least one case. The held case is then running and not complete, so
    the kill is mid-sweep and mid-case by construction. The rerun finds the wire disarmed."""
    text = LINEAR.replace("duration_s = 4.0", "duration_s = 0.5")
    plan = plan_of(text, "model.k_s=8000:20000:6")
    out = tmp_path / "sweep"
    arm, held = tmp_path / "arm", tmp_path / "held"
    arm.write_text("")
    killed = {}

    def hold_first_stage(arm: str, held: str) -> None:  # runs on each worker (pickled by value)
        import os
        import time

        import bearingshaft.sweep.run as sweep

        original = getattr(sweep._run_stage, "original", sweep._run_stage)

        def held_stage(*args, **kwargs):
            try:
                os.rename(arm, arm + ".claimed")  # atomic: one worker claims the wire, once
            except FileNotFoundError:
                return original(*args, **kwargs)
            with open(held + ".tmp", "w") as f:
                f.write(str(os.getpid()))
            os.rename(held + ".tmp", held)
            for _ in range(6000):  # until killed; a guard against a hang, not a time bound of the test
                time.sleep(0.1)
            raise RuntimeError("held case was never killed")

        held_stage.original = original
        sweep._run_stage = held_stage

    def restore() -> None:  # on the workers that still hold the wrapper
        import bearingshaft.sweep.run as sweep

        sweep._run_stage = getattr(sweep._run_stage, "original", sweep._run_stage)

    client.run(hold_first_stage, str(arm), str(held))

    def kill_one() -> None:
        for _ in range(6000):  # a hang guard only: both conditions are reached whatever the machine's speed
            done = [c for c in plan.cases if (out / c.case_id / "provenance.json").exists()]
            if held.exists() and done:
                pid = int(held.read_text())
                address = next(a for a, p in client.run(os.getpid).items() if p == pid)
                keys = list(client.processing().get(address, ()))
                killed.update(address=address, keys=keys, pid=pid, done=len(done))
                os.kill(pid, signal.SIGKILL)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=kill_one)
    thread.start()
    try:
        res = run_sweep(plan, out, client=client, progress=False)
    finally:
        thread.join()
        client.run(restore)
    assert killed and killed["done"] < len(plan.cases), killed  # killed mid-sweep, while running a case
    ids = [r["case_id"] for r in res.rows]
    assert ids == [c.case_id for c in plan.cases]  # each case once, none lost
    assert all(r["status"] == "ok" for r in res.rows), [r["message"] for r in res.rows]
    folders = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert folders == sorted(ids)  # no scratch folder of the killed attempt left, no extra folder
    for c in plan.cases:
        prov = json.loads((out / c.case_id / "provenance.json").read_text())
        assert list(prov["stages"]) == ["ringdown"] and case_complete(out / c.case_id, c)
    interrupted = [str(k).split("-")[2] for k in killed["keys"] if "bearingshaft-case-" in str(k)]
    assert interrupted  # the killed worker was running a case: it is in the table once, ok
    assert all(ids.count(cid) == 1 and res.rows[ids.index(cid)]["status"] == "ok" for cid in interrupted)
    assert len(pq.read_table(out / "sweep.parquet")) == len(plan.cases)


def test_a_stage_that_needs_the_main_thread_runs_in_a_child_process(tmp_path, monkeypatch):
    """A stage listed in ``MESH_STAGES`` (none by default: gmsh starts in a worker thread too) runs as
    ``python -m bearingshaft.cli STAGE`` in a child process off the main thread. Exercised here on a cheap
    stage declared so: the folder it leaves is the single run's, for the case's scene."""
    import bearingshaft.pipeline as pipeline
    import bearingshaft.sweep.run as sweep

    monkeypatch.setattr(pipeline, "MESH_STAGES", ("ringdown",))
    plan = plan_of(LINEAR.replace("duration_s = 4.0", "duration_s = 0.1"), "model.k_s=9000")
    case = plan.cases[0]
    scene = parse_scene(case.text, case.name, case.origin)
    folder = tmp_path / case.case_id
    errors = []

    def worker() -> None:
        try:
            sweep._run_stage(scene, case, "ringdown", folder)
        except Exception as exc:  # reported below, in the test's thread
            errors.append(exc)

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert not errors, errors
    assert case_complete(folder, case)
    prov = json.loads((folder / "provenance.json").read_text())
    assert prov["stages"]["ringdown"]["stats"]["energy_balance_error"] < 1e-11


def test_cli_sweep_on_an_existing_scheduler(tmp_path, client, capsys):
    """``--scheduler ADDRESS``: the cases go to that cluster's workers; the command ends with its
    summary line and exit code 0."""
    scene = tmp_path / "lin.toml"
    scene.write_text(LINEAR.replace("duration_s = 4.0", "duration_s = 0.1"))
    out = tmp_path / "out"
    argv = ["sweep", "--scene", str(scene), "--out", str(out), "--vary", "model.k_s=8000,9000", "--no-progress",
            "--scheduler", client.scheduler.address]
    assert main(argv) == 0
    assert "2 of 2 cases ok (0 already done, 0 failed)" in capsys.readouterr().out
    rows = pq.read_table(out / "sweep.parquet").to_pylist()
    workers = set(client.nthreads())
    assert [r["model.k_s"] for r in rows] == [8000, 9000] and all(r["worker"] in workers for r in rows)
    assert main([*argv[:-2], "--workers", "2", "--scheduler", client.scheduler.address]) == 2  # one or the other


def test_hammer_and_frc_rows_are_the_stages_own_numbers():
    """The hammer and frc extractors read what those stages wrote (here the committed results of
    hammer-test and discrete-frc): the nominal blow's row of levels.csv, the scale-1 rows of
    frc_backbone.csv."""
    import csv
    from pathlib import Path
    from types import SimpleNamespace

    from bearingshaft.sweep import frc_metrics, hammer_metrics

    folder = Path(__file__).resolve().parents[1] / "results"
    stats = json.loads((folder / "hammer-test" / "provenance.json").read_text())["stages"]["hammer"]["stats"]
    row = hammer_metrics(SimpleNamespace(hammer=SimpleNamespace(peak_N=500.0)), stats)
    with open(folder / "hammer-test" / "levels.csv", newline="") as fh:
        level = next(r for r in csv.DictReader(fh) if float(r["level_N"]) == 500.0)
    assert row["impacts"] == int(level["impacts"])
    # levels.csv writes 4 significant digits
    assert row["peak_tip_force_N"] == pytest.approx(max(float(v) for k, v in level.items()
                                                        if k.startswith("peak_contact_")), rel=1e-3)
    assert row["gaps_open_after_s"] == pytest.approx(float(level["gaps_open_after_s"]), rel=1e-3)
    frc = frc_metrics(folder / "discrete-frc")
    with open(folder / "discrete-frc" / "frc_backbone.csv", newline="") as fh:
        ones = [r for r in csv.DictReader(fh) if r["scale"] == "1.0"]
    assert len(ones) == 3 and len(frc) == 6
    for r in ones:
        assert frc[f"frc_peak_hz_{float(r['level']):g}N"] == float(r["peak_freq_hz"])
        assert frc[f"frc_peak_m_{float(r['level']):g}N"] == float(r["peak_amplitude_m"])


def test_local_cluster_runs_with_dask_monitoring_slowed(client):
    """The cluster of ``run`` and ``sweep`` runs its workers with QUIET_CLUSTER (no 10 ms stack sampler, memory
    polled every 500 ms), also a worker its nanny restarted (test_worker_killed_mid_sweep_loses_and_doubles_no_case
    kills one, earlier in this module)."""
    import dask

    from bearingshaft.sweep.run import QUIET_CLUSTER

    seen = client.run(lambda dask_worker: ("profile" in dask_worker.periodic_callbacks,
                                           dask.config.get("distributed.worker.memory.monitor-interval"),
                                           dask.config.get("distributed.admin.tick.interval")))
    assert len(seen) == 2
    for profiled, memory, tick in seen.values():
        assert not profiled
        assert memory == QUIET_CLUSTER["distributed.worker.memory.monitor-interval"]
        assert tick == QUIET_CLUSTER["distributed.admin.tick.interval"]


def test_the_quiet_settings_last_as_long_as_the_local_cluster(monkeypatch):
    """QUIET_CLUSTER is in force while the cluster lives (a nanny reads it again to restart a worker) and the
    caller's Dask configuration is back as it was after (no cluster started: stand-ins record the setting)."""
    import dask
    import distributed

    from bearingshaft.sweep.run import dask_client

    before = dask.config.get("distributed.worker.profile.enabled")  # False while this module's cluster is open
    seen = []

    class Stub:
        def __init__(self, *a, **k):
            seen.append(dask.config.get("distributed.worker.profile.enabled"))

        def close(self):
            seen.append(dask.config.get("distributed.worker.profile.enabled"))

    monkeypatch.setattr(distributed, "LocalCluster", Stub)
    monkeypatch.setattr(distributed, "Client", Stub)
    with dask_client(workers=2) as (_, where):
        assert where == "LocalCluster(2)" and dask.config.get("distributed.worker.profile.enabled") is False
    assert seen == [False, False, False, False]  # cluster and client made and closed under it
    assert dask.config.get("distributed.worker.profile.enabled") is before
    with dask.config.set({"distributed.worker.profile.enabled": True}), dask_client(workers=1):
        pass
    assert seen[-4:] == [False, False, False, False]
