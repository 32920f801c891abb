"""A rerun with the same code writes the same science files, byte for byte.

The convention, for every stage of the project:

* **Timing files.** A file whose name, without its extension, ends in ``_timing``
  (``work_precision_timing.csv``, ``work_precision_timing.png``, ``study_timing.md``,
  ``hb_convergence_timing.csv``, ...) holds wall-clock run times, or a figure or table
  drawn from them, and may change on every run. ``provenance.json`` (commit, time,
  solver statistics with their wall times) may change too.
* **Science files.** Every other file a stage writes. It holds no wall-clock time (no
  ``runtime_s``/``wall_s`` column, no run time in a markdown table or a figure) and a rerun
  of the same code on the same machine writes it byte for byte: no unseeded random
  numbers, no dependence on set or dict order, on thread count or on machine load.
* **Digits.** Another machine's CPU makes NumPy and OpenBLAS pick other SIMD kernels at
  run time, which changes the last bits of sums; so science files write numbers to the
  digits that survive such a change (each stage's module docstring says which), and
  round-off-level quantities as the power of ten that bounds them.
* Quantities that are sensitive by nature (event counts of chaotic impacting runs,
  DOP853's error stepping over contact switches, the symmetry-break time of an unstable
  orbit) are written as computed and said to be sensitive where they are reported.

This file runs cheap stages twice in-process, each on a trimmed copy of a built-in scene
(``bearingshaft.scenes.parse_scene``), into two folders, and compares every science file.
It also checks that science CSVs carry no run-time column and that the timing files are
where the convention says. The reduced-model study needs the 3-D model: its version of the
test is marked ``slow``, and a fast variant runs the same stage on a smaller model (the hex8
mesh, 5 modes, one stiff case, 5 ms windows).
"""

from __future__ import annotations

import csv
import tomllib
from importlib import resources
from pathlib import Path

import pytest
import tomli_w

import bearingshaft.stages.nnm as nnm_stage
from bearingshaft.pipeline import run_stage
from bearingshaft.scenes import parse_scene

RUN_TIME_COLUMNS = ("runtime_s", "wall_s", "build_s", "exact_s", "explicit_s", "elapsed_s", "time_s")


def is_timing(path: Path) -> bool:
    """A timing file by the convention (or provenance.json): allowed to change on a rerun."""
    return path.name == "provenance.json" or path.stem.endswith("_timing")


def trimmed(name: str, changes: dict) -> str:
    """The TOML text of built-in scene ``name`` with ``changes`` ({table: {key: value} or None
    to drop the table}) applied."""
    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / f"{name}.toml").read_text("utf-8"))
    for table, keys in changes.items():
        if keys is None:
            data.pop(table, None)
        else:
            data.setdefault(table, {}).update(keys)
    return tomli_w.dumps(data)


def run_twice(tmp_path: Path, text: str, name: str, stages: tuple[str, ...]) -> tuple[Path, Path]:
    scene = parse_scene(text, name, f"trimmed {name}")
    outs = tmp_path / "a", tmp_path / "b"
    for out in outs:
        for stage in stages:
            run_stage(scene, stage, out, progress=False)
    return outs


def assert_same_science(a: Path, b: Path) -> list[str]:
    """Every science file of ``a`` is in ``b`` with the same bytes; returns their names."""
    files_a = sorted(p.name for p in a.iterdir() if p.is_file())
    assert files_a == sorted(p.name for p in b.iterdir() if p.is_file())
    science = [n for n in files_a if not is_timing(a / n)]
    for n in science:
        x, y = (a / n).read_bytes(), (b / n).read_bytes()
        if x != y:
            if n.endswith((".csv", ".md", ".toml")):
                lx, ly = x.decode().splitlines(), y.decode().splitlines()
                i = next((i for i, (u, v) in enumerate(zip(lx, ly, strict=False)) if u != v), min(len(lx), len(ly)))
                pytest.fail(f"{n} differs between two runs at line {i + 1}:\n  {lx[i:i + 1]}\n  {ly[i:i + 1]}")
            pytest.fail(f"{n} differs between two runs ({len(x)} and {len(y)} bytes)")
    for n in science:
        if n.endswith(".csv"):
            with open(a / n, newline="") as fh:
                header = next(csv.reader(fh), [])
            timed = [c for c in header if c in RUN_TIME_COLUMNS]
            assert not timed, f"science file {n} has run-time columns {timed}: move them to a *_timing.csv"
    return science


@pytest.fixture
def quick_nnm2_check(monkeypatch):
    # the NNM 2 periods integrated near grazing (x0/g = 1.000001 ... 1.01) take ~3 s of DOP853;
    # two amplitudes away from grazing exercise the same code and files
    monkeypatch.setattr(nnm_stage, "CHECK_CHI", (1.1, 10.0))


def test_discrete_impulse_study_and_nnm_are_reproduced(tmp_path, quick_nnm2_check):
    text = trimmed("discrete-impulse", {
        "ringdown": None, "spectrogram": None,
        "nnm": {"n_energy": 40},
        "work_precision": {"window_s": 0.01, "explicit_omega_dt": [0.2, 0.1, 0.05, 0.025],
                           "dop853_rtol": [1e-4], "repeats": 1},
        # both integrators, zero and Table-1 gap, a stiff penalty, damped and undamped, plus long runs
        "stiff_cases": {"k_g": [3.502e7, 1e11], "gap": [0.0, 2.54e-4], "speed": [200.0], "c": [0.0, 4.0],
                        "duration_s": 0.02, "long_duration_s": 0.05},
    })
    a, b = run_twice(tmp_path, text, "impulse-trimmed", ("nnm", "study"))
    science = assert_same_science(a, b)
    assert {"work_precision.csv", "stiff_cases.csv", "study.md", "linear_modes.csv", "nnm2_check.csv",
            "nnm2_exact.csv", "nnm2.png"} <= set(science)
    timing = {p.name for p in a.iterdir() if is_timing(p)}
    assert {"work_precision_timing.csv", "work_precision_timing.png", "stiff_cases_timing.csv",
            "study_timing.md"} <= timing
    # the run times did go somewhere: the timing files have them
    with open(a / "stiff_cases_timing.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 20 and all(float(r["runtime_s"]) > 0 for r in rows)


def test_fep_is_reproduced(tmp_path, quick_nnm2_check):
    text = trimmed("discrete-fep", {
        "nnm": {"n_energy": 20},
        "fep": {"harmonics": [1, 3], "convergence_harmonics": [1, 3], "samples_study_harmonics": 3,
                "samples": [16], "energy_max_J": 1.0, "n_shooting": 3},
    })
    a, b = run_twice(tmp_path, text, "fep-trimmed", ("nnm",))
    science = assert_same_science(a, b)
    assert {"fep.csv", "fep.png", "stability.csv", "tongues.csv", "hb_convergence.csv",
            "hb_convergence.png"} <= set(science)
    assert (a / "hb_convergence_timing.csv").exists() and (a / "hb_convergence_timing.png").exists()


@pytest.mark.slow
def test_rom_impulse_study_is_reproduced(tmp_path):
    text = trimmed("rom-impulse", {
        "ringdown": None, "spectrogram": None,
        "rom_convergence": {"modes": [2, 5], "window_s": 0.01, "repeats": 1},
        "stiff_cases": {"k_g": [3.502e7, 1e9], "gap": [2.54e-4], "speed": [200.0], "c": [4.0],
                        "duration_s": 0.01, "long_duration_s": 0.02},
    })
    a, b = run_twice(tmp_path, text, "rom-trimmed", ("study",))
    science = assert_same_science(a, b)
    assert {"rom_convergence.csv", "rom_stiff_cases.csv", "study.md"} <= set(science)


def test_rom_impulse_study_on_a_small_model_is_reproduced(tmp_path, monkeypatch):
    """Fast variant of the slow test above: the same stage and files from a smaller model (hex8
    mesh: 4,185 full DOFs against 15,087; 5 fixed-interface modes, convergence over 1 and 2
    modes, one stiff case, 5 and 10 ms runs). Each run has its own empty reduced-model cache,
    so both build their models (a cached model would hide a build that is not reproducible)."""
    text = trimmed("rom-impulse", {
        "ringdown": None, "spectrogram": None,
        "model": {"element": "hex8", "n_modes": 5},
        "rom_convergence": {"modes": [1, 2], "window_s": 0.005, "repeats": 1},
        "stiff_cases": {"k_g": [3.502e7], "gap": [2.54e-4], "speed": [200.0], "c": [4.0],
                        "duration_s": 0.005, "long_duration_s": 0.01},
    })
    scene = parse_scene(text, "rom-small", "trimmed rom-impulse")
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path / f"cache-{out.name}"))
        run_stage(scene, "study", out, progress=False)
        assert list((tmp_path / f"cache-{out.name}").glob("rom-*.npz")), "the run built and stored its model"
    science = assert_same_science(a, b)
    assert {"rom_convergence.csv", "rom_stiff_cases.csv", "study.md"} <= set(science)
    timing = {p.name for p in a.iterdir() if is_timing(p)}
    assert {"rom_convergence_timing.csv", "rom_stiff_cases_timing.csv", "study_timing.md"} <= timing
