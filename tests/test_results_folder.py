"""Results folders under abuse: SIGKILL at any moment, 8 writers at once, bad --out paths.

A folder "looks complete" when its provenance lists files; it is consistent when every
file its provenance lists exists, nothing but those (and scene.toml, provenance.json) is in
it, and the ringdown it holds is the one its scene.toml asks for. A kill may leave the
previous consistent folder or none (if there was none), never an inconsistent one.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
import tomllib
from pathlib import Path

import forked_cli
import numpy as np
import pytest

import bearingshaft.stages.nnm as nnm_stage
from bearingshaft.cli import main
from bearingshaft.output import CRASH_ENV
from bearingshaft.pipeline import run_stage
from bearingshaft.scenes import parse_scene

SCENE = """
[model]
kind = "discrete"
[initial]
v0_m_s = [0.0, 0.0, {speed}]
[ringdown]
duration_s = {duration}
sample_rate_hz = 2000.0
"""


def _scene(tmp_path: Path, duration: float, speed: float = 20.0, name: str = "case", nnm: bool = False) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(SCENE.format(duration=duration, speed=speed) + ("[nnm]\nn_energy = 20\n" if nnm else ""))
    return path


def _cli(scene: Path, out: Path, env: dict | None = None) -> forked_cli.Child:
    """``bearingshaft ringdown`` in a process of its own, forked with the package imported (tests/forked_cli.py:
    ~1.3 s of CPU less per child than a fresh interpreter, issue 28), its stdout and stderr kept beside ``out``."""
    logs = out.parent / "logs"
    return forked_cli.start(["ringdown", "--scene", str(scene), "--out", str(out), "--no-progress"], logs, env)


def _consistent(out: Path) -> float:
    """Assert ``out`` is a consistent ringdown folder; its run length in s."""
    prov = json.loads((out / "provenance.json").read_text())
    listed = {f for s in prov["stages"].values() for f in s["files"]}
    present = {p.name for p in out.iterdir()}
    assert listed <= present, f"listed but missing: {listed - present}"
    assert present - listed == {"scene.toml", "provenance.json"}, present - listed
    duration = tomllib.loads((out / "scene.toml").read_text())["ringdown"]["duration_s"]
    with np.load(out / "ringdown.npz") as z:
        assert z["t"][-1] == pytest.approx(duration)
    return duration


def _snapshot(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in out.iterdir()}


@pytest.fixture(scope="module")
def quick_nnm2_check():
    """The nnm stage here is only a second stage whose files a run must carry over: its NNM 2 periods integrated
    near grazing (x0/g = 1.000001 ... 1.01) take ~2 s of DOP853 per run; two amplitudes away from grazing write
    the same files (as in tests/test_reproducible.py)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(nnm_stage, "CHECK_CHI", (1.1, 10.0))
        yield


@pytest.fixture(scope="module")
def old_folder(tmp_path_factory, quick_nnm2_check) -> Path:
    """A complete folder with a 0.02 s ringdown and the nnm stage's files."""
    tmp = tmp_path_factory.mktemp("old")
    out = tmp / "res"
    old = str(_scene(tmp, 0.02, name="old", nnm=True))
    for stage in ("ringdown", "nnm"):  # the new runs write ringdown only: the nnm files are linked over
        assert main([stage, "--scene", old, "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.mark.parametrize("point", ["written", "linking", "scene", "provenance", "aside", "swapped"])
def test_kill_at_each_step_of_the_commit_leaves_old_or_new_folder(tmp_path, old_folder, point):
    out = tmp_path / "res"
    shutil.copytree(old_folder, out)
    before = _snapshot(out)
    # "aside" is the non-atomic fallback's window: reach it by making renameat2 unavailable
    env = {CRASH_ENV: point}
    if point == "aside":
        env["BEARINGSHAFT_NO_RENAME_EXCHANGE"] = "1"
    proc = _cli(_scene(tmp_path, 0.03, name="new"), out, env)
    proc.communicate(timeout=120)
    assert proc.returncode == -signal.SIGKILL
    if point == "swapped":
        assert _consistent(out) == 0.03
    elif point == "aside":
        assert not out.exists()  # none, never a mix; the next run puts the old folder back
        assert main(["ringdown", "--scene", str(_scene(tmp_path, 0.04, name="next")), "--out", str(out),
                     "--no-progress"]) == 0
        assert _consistent(out) == 0.04
        assert not list(tmp_path.glob(".res.*-*"))
    else:
        assert _snapshot(out) == before
        assert _consistent(out) == 0.02


def test_kill_at_random_moments_never_leaves_a_mixed_folder(tmp_path, old_folder):
    out = tmp_path / "res"
    shutil.copytree(old_folder, out)
    new = _scene(tmp_path, 0.03, name="new")
    # the kills spread over a whole run on any machine and load: at fractions of an undisturbed run's wall time
    # (~1 s with the package imported; the named steps of the commit are killed one by one above)
    t0 = time.perf_counter()
    assert _cli(new, tmp_path / "alone" / "res").wait(timeout=120) == 0
    run_s = time.perf_counter() - t0
    seen = set()
    for fraction in (0.05, 0.2, 0.35, 0.5, 0.65, 0.8, 0.9, 1.0):
        proc = _cli(new, out)
        time.sleep(fraction * run_s)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=120)
        seen.add(_consistent(out))
    assert seen <= {0.02, 0.03}
    proc = _cli(new, out)  # and a run left alone completes, clearing the killed runs' scratch
    assert proc.wait(timeout=120) == 0
    assert _consistent(out) == 0.03
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".res.") and p.is_dir()]


def test_eight_processes_writing_one_folder(tmp_path):
    out = tmp_path / "res"
    scenes = [_scene(tmp_path, 0.01 + 0.001 * i, name=f"s{i}") for i in range(8)]
    procs = [_cli(s, out) for s in scenes]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err
        assert err.strip() == ""
    assert _consistent(out) in {0.01 + 0.001 * i for i in range(8)}
    assert not list(tmp_path.glob(".*.lock")), "a lock file stayed behind"


def test_threads_writing_one_folder(tmp_path, quick_nnm2_check):
    """The Python API from 8 threads: provenance merges every stage, no temp-file race."""
    out = tmp_path / "res"
    text = SCENE.format(duration=0.01, speed=20.0) + "[nnm]\nn_energy = 20\n"
    scene = parse_scene(text, "case", "case.toml")
    errors = []

    def work(stage):
        try:
            run_stage(scene, stage, out, progress=False)
        except Exception as exc:  # noqa: BLE001 - collected and asserted below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=("nnm" if i in (2, 5) else "ringdown",)) for i in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == []
    prov = json.loads((out / "provenance.json").read_text())
    assert set(prov["stages"]) == {"ringdown", "nnm"}
    _consistent(out)
    assert not list(tmp_path.glob(".*.lock")), "a lock file stayed behind"


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002])
def test_results_folder_honours_the_umask(tmp_path, mask):
    """The folder and every file get 0777 / 0666 less the user's umask (mkdtemp alone gives drwx------),
    and no lock file stays beside them.

    In this process (issue 28: a child spent ~2 s of CPU importing for a 0.01 s run): the umask is read when the
    folder is made (reduced.cache.current_umask), not at import, and this test is the only thing running in its
    worker while the mask is set; it is put back before any assertion."""
    out = tmp_path / "res"
    scene = str(_scene(tmp_path, 0.01))
    old = os.umask(mask)
    try:
        rc = main(["ringdown", "--scene", scene, "--out", str(out), "--no-progress"])
    finally:
        os.umask(old)
    assert rc == 0
    assert out.stat().st_mode & 0o777 == 0o777 & ~mask
    for f in out.iterdir():
        assert f.stat().st_mode & 0o777 == 0o666 & ~mask, f.name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.toml", "res"]


def _refused(args: list[str], capsys) -> str:
    rc = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("case", ["file", "under_file", "devnull", "proc", "sys"])
def test_bad_out_is_refused_before_any_work(tmp_path, capsys, case):
    scene = str(_scene(tmp_path, 0.01))
    afile = tmp_path / "afile"
    afile.write_text("x")
    out = {"file": afile, "under_file": afile / "sub", "devnull": Path("/dev/null"),
           "proc": Path("/proc/bearingshaft-test/out"), "sys": Path("/sys/kernel/bearingshaft-test")}[case]
    msg = _refused(["ringdown", "--scene", scene, "--out", str(out), "--no-progress"], capsys)
    assert "--out" in msg and str(out) in msg
    assert afile.read_text() == "x"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders; /sys stands in above")
def test_read_only_out_is_refused(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    msg = _refused(["ringdown", "--scene", str(_scene(tmp_path, 0.01)), "--out", str(ro / "x")], capsys)
    assert "not writable" in msg
