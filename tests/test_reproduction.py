"""The reproduction report and the runs/ folder: a run never writes into the committed results.

- the report passes on a run against itself, and fails (exit 1, naming the file and the number) when a
  deterministic number of the reference is changed;
- a chaotic number that differs is reported as chaotic with the horizon ln(tol / delta0) / lambda computed
  from the run's own Lyapunov exponent, not as a failure; a round-off bound may move by one decade;
- ``bearingshaft run`` and the stage subcommands write ``runs/<scene>/``; ``--update-reference`` writes
  ``results/<scene>/``; a run in a copy of the repository leaves ``git status`` clean.

The scenes are tiny (a 10 ms work-precision study of the 3-DOF model, ~3 s) so the whole file stays fast.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bearingshaft import cli, reproduction
from bearingshaft.registry import STAGES, stage
from bearingshaft.reproduction import (
    CHAOTIC_DIFF,
    DELTA0,
    DIFFERS,
    HORIZON_TOL,
    LAST_DIGIT,
    REPRODUCED,
    WITHIN,
    Reproduction,
    chaotic,
    compare_scene,
    exact,
    roundoff,
)

ROOT = Path(__file__).resolve().parents[1]

TINY = """description = "tiny: the impulse start, a 10 ms work-precision study"

[model]
kind = "discrete"

[initial]
x0_m = [0.0, 0.0, 0.0]
v0_m_s = [0.0, 0.0, 200.0]

[work_precision]
window_s = 0.01
explicit_omega_dt = [0.2, 0.1, 0.05]
dop853_rtol = [1e-4]
repeats = 1
"""


def _write_csv(path: Path, rows: list[list]) -> None:
    with open(path, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)


def _folder(path: Path, stage_files: dict[str, dict[str, str | list[list]]]) -> Path:
    """A results folder: each stage's files (text, or CSV rows) and a provenance.json listing them."""
    path.mkdir(parents=True)
    prov = {"stages": {}}
    for name, files in stage_files.items():
        for f, content in files.items():
            if isinstance(content, str):
                (path / f).write_text(content)
            else:
                _write_csv(path / f, content)
        prov["stages"][name] = {"files": sorted(files)}
    (path / "provenance.json").write_text(json.dumps(prov))
    (path / "scene.toml").write_text("[model]\n")
    return path


def _hammer_files(impacts: int, gaps_open: str, freq: str, balance: str, exponent: str) -> dict:
    return {
        "levels.csv": [["level_N", "impacts", "gaps_open_after_s", "end_mode_hz", "hammer_work_J",
                        "energy_balance_error"],
                       ["500.0", str(impacts), gaps_open, freq, "0.0292478", balance]],
        "lyapunov.csv": [["seed", "delta", "exponent_per_s", "chaotic"], ["0", "1e-09", exponent, "True"],
                         ["1", "1e-09", "3", "False"]],
        "channels.csv": [["name", "unit"], ["beam_s1:x", "m/s^2"]],
        "fig10.png": "png",
    }


def test_a_run_against_itself_reproduces(tmp_path):
    files = {"hammer": _hammer_files(84, "0.475", "1736.58", "1e-10", "40.97")}
    ref, run = _folder(tmp_path / "ref", files), _folder(tmp_path / "run", files)
    rows = compare_scene("s", run, ref, {s.name: s.reproduction for s in STAGES}, ("hammer",))
    assert not reproduction.failed(rows)
    assert {r.status for r in rows} == {REPRODUCED, reproduction.EXISTS}
    assert {r.file for r in rows} == {"scene.toml", "levels.csv", "lyapunov.csv", "channels.csv", "fig10.png"}


def test_a_changed_deterministic_number_fails_and_a_chaotic_one_gets_a_horizon(tmp_path):
    ref = _folder(tmp_path / "ref", {"hammer": _hammer_files(84, "0.475", "1736.58", "1e-10", "40.97")})
    run = _folder(tmp_path / "run", {"hammer": _hammer_files(79, "0.3923", "1736.58", "1e-11", "25.5")})
    spec = stage("hammer").reproduction
    rows = compare_scene("s", run, ref, {"hammer": spec}, ("hammer",))
    assert not reproduction.failed(rows), reproduction.summary(rows)
    impacts = next(r for r in rows if r.quantity.startswith("impacts:"))
    assert impacts.status == CHAOTIC_DIFF
    # the horizon from the run's own exponent: its largest chaotic one (the non-chaotic row's 3 /s is left out)
    t_h = math.log(HORIZON_TOL / DELTA0) / 25.5
    assert f"not comparable past t = {t_h:.3g} s" in impacts.note and "lyapunov.csv" in impacts.note
    assert 1.0 < t_h < 1.1  # ln(1e-4 / 2.2e-16) = 26.8
    balance = next(r for r in rows if r.quantity.startswith("energy_balance_error"))
    assert balance.status == WITHIN  # a round-off bound one decade lower
    # a deterministic number of the reference changed: a failure that names the file and the number
    (ref / "levels.csv").write_text((ref / "levels.csv").read_text().replace("0.0292478", "0.0292578"))
    rows = compare_scene("s", run, ref, {"hammer": spec}, ("hammer",))
    bad = reproduction.failed(rows)
    assert [(r.file, r.reference, r.run) for r in bad] == [("levels.csv", "0.0292578", "0.0292478")]
    assert "levels.csv hammer_work_J [level_N=500.0]: reference '0.0292578', run '0.0292478'" in \
        reproduction.summary(rows)


def test_rules_compare_to_the_digits_written():
    assert reproduction.one_unit_apart("0.39899", "0.39900")  # a rounding boundary
    assert not reproduction.one_unit_apart("0.39899", "0.399213")  # the 4th digit
    assert not reproduction.one_unit_apart("84", "85")  # counts are equal or not
    assert not reproduction.one_unit_apart("1e-10", "1e-09")  # a bound: that is roundoff()'s decade


def test_text_lines_chaotic_or_judged(tmp_path):
    spec = Reproduction(rules=(chaotic("a.md", r"^- Impacts", why="impacts"), roundoff("a.md", r"^- balance"),
                               exact("a.md")))
    ref = _folder(tmp_path / "ref", {"x": {"a.md": "# t\n- Impacts: 84\n- balance 1e-10\n- f = 17.98 Hz\n"}})
    run = _folder(tmp_path / "run", {"x": {"a.md": "# t\n- Impacts: 79\n- balance 1e-11\n- f = 17.99 Hz\n"}})
    rows = compare_scene("s", run, ref, {"x": spec}, ("x",))
    by_line = {r.quantity: r.status for r in rows if r.file == "a.md"}
    assert by_line == {"line 2": CHAOTIC_DIFF, "line 3": WITHIN, "line 4": LAST_DIGIT}
    (run / "a.md").write_text("# t\n- Impacts: 79\n- balance 1e-11\n- f = 18.02 Hz\n")
    rows = compare_scene("s", run, ref, {"x": spec}, ("x",))
    assert [(r.file, r.quantity, r.status) for r in reproduction.failed(rows)] == [("a.md", "line 4", DIFFERS)]


def test_every_stage_declares_its_comparison():
    for s in STAGES:
        assert isinstance(s.reproduction, Reproduction), s.name
    # the stages whose files hold chaotic numbers read a horizon from the run
    assert stage("hammer").reproduction.lyapunov and stage("ringdown").reproduction.lyapunov


def _run_main(argv: list[str], cwd: Path, monkeypatch) -> int:
    monkeypatch.chdir(cwd)
    return cli.main(argv)


def test_run_writes_runs_and_the_report(tmp_path, monkeypatch, capsys):
    """--update-reference writes results/ (the reference) and no report; a plain run writes runs/ and the
    report, which passes against that reference and fails (exit 1) once one of its numbers is changed."""
    (tmp_path / "tiny.toml").write_text(TINY)
    assert _run_main(["run", "tiny.toml", "--no-progress", "--update-reference"], tmp_path, monkeypatch) == 0
    ref = tmp_path / "results"
    assert (ref / "tiny" / "work_precision.csv").is_file() and not (tmp_path / "runs").exists()
    assert not (ref / "reproduction.md").exists()  # no report against itself
    before = {p.name: p.read_bytes() for p in (ref / "tiny").iterdir()}
    argv = ["run", "tiny.toml", "--no-progress", "--reference", "results"]
    assert _run_main(argv, tmp_path, monkeypatch) == 0
    assert "reproduction: passed" in capsys.readouterr().out
    assert (tmp_path / "runs" / "tiny" / "work_precision.csv").is_file()
    assert "**Passed**" in (tmp_path / "runs" / "reproduction.md").read_text()
    assert {p.name: p.read_bytes() for p in (ref / "tiny").iterdir()} == before  # the reference untouched
    # a deterministic number of the reference changed: exit 1, the file and the number named
    wp = ref / "tiny" / "work_precision.csv"
    lines = wp.read_text().splitlines()
    row = next(i for i, line in enumerate(lines) if line.startswith("explicit,omega_dt=0.1,"))
    cells = lines[row].split(",")
    cells[2] = "0.5"
    lines[row] = ",".join(cells)
    wp.write_text("\n".join(lines) + "\n")
    assert _run_main(argv, tmp_path, monkeypatch) == 1
    out = capsys.readouterr().out
    assert "reproduction: FAILED" in out and "tiny/work_precision.csv error [method=explicit, setting=omega_dt=0.1]: " \
        "reference '0.5'" in out
    with open(tmp_path / "runs" / "reproduction.csv", newline="") as fh:
        assert [r["file"] for r in csv.DictReader(fh) if r["status"] == DIFFERS] == ["work_precision.csv"]
    assert _run_main(["run", "tiny.toml", "--update-reference", "--out", "x"], tmp_path, monkeypatch) == 2


def test_subcommands_write_runs_unless_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli._out_dir(None, "rom-impulse") == Path("runs") / "rom-impulse"
    assert cli._out_dir(None, "rom-impulse", update_reference=True) == Path("results") / "rom-impulse"
    args = cli.build_parser().parse_args(["ringdown", "--scene", "discrete-impulse", "--update-reference"])
    assert args.update_reference


def test_sweep_default_folder_is_under_runs(tmp_path, monkeypatch):
    import argparse

    from bearingshaft.sweep import command

    seen = {}
    monkeypatch.setattr(command, "check_out_dir", lambda out: seen.setdefault("out", Path(out)) and
                        (_ for _ in ()).throw(SystemExit(0)))
    args = argparse.Namespace(scene="sweep-gap-kg", vary=None, design=None, samples=None, seed=None, workers=None,
                              scheduler=None, out=None, no_progress=True, update_reference=False)
    with pytest.raises(SystemExit):
        command.sweep_command(args, cli.load_scene)
    assert seen["out"] == Path("runs") / "sweep-gap-kg" / "sweep"


@pytest.mark.slow
def test_a_run_leaves_git_status_clean(tmp_path):
    """The README's main job in a copy of the repository (its tracked files, committed): the run goes to
    runs/, which .gitignore names, and nothing tracked changes. Slow: numba compiles its kernels again in
    the copy (its cache is keyed by the source's path), 1-2 min."""
    clone = tmp_path / "clone"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    for f in filter(None, files):
        src, dst = ROOT / f.decode(), clone / f.decode()
        if src.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    (clone / "tiny.toml").write_text(TINY)
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    subprocess.run([*git, "init", "-q"], cwd=clone, check=True)
    subprocess.run([*git, "add", "-A"], cwd=clone, check=True)
    subprocess.run([*git, "commit", "-q", "-m", "copy"], cwd=clone, check=True)
    env = {**os.environ, "PYTHONPATH": str(clone)}
    proc = subprocess.run([sys.executable, "-m", "bearingshaft.cli", "run", "tiny.toml", "--no-progress"], cwd=clone,
                          env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert (clone / "runs" / "tiny" / "work_precision.csv").is_file() and (clone / "runs" / "reproduction.md").is_file()
    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True, text=True, check=True)
    assert status.stdout == "", status.stdout


def _map_row(freq: str, regime: str, x1: str, lam: str, settled: str = "true", after: str = "false") -> list[str]:
    cells = {"level": "1.0", "direction": "up", "freq_hz": freq, "regime": regime,
             "period_k": "1" if regime == "periodic" else "0", "lyapunov_per_s": lam, "x1_min_m": x1,
             "x1_mean_m": x1, "x1_max_m": x1, "asymmetry": "0", "jump": "false", "lyapunov_tol_per_s": "0.5",
             "max_abs_mu": "0.9" if regime == "periodic" else "", "settled": settled, "contact": "true",
             "broadband": "0.001", "n_periods": "64", "after_chaos": after}
    from bearingshaft.stages.frc_map_files import MAP_FIELDS
    assert list(cells) == MAP_FIELDS  # the rows below are the file's columns in the file's order
    return list(cells.values())


def test_response_map_chaotic_rows_and_the_sweep_after_them(tmp_path):
    """The frc stage's response map: a chaotic frequency is chaotic (horizon from the run's own largest exponent in
    response_map.csv), what follows it in the sweep is sensitive, what precedes it must reproduce."""
    from bearingshaft.stages.frc_map_files import MAP_FIELDS

    spec = stage("frc").reproduction
    ref_rows = [MAP_FIELDS, _map_row("20.0", "periodic", "1.234567891e-04", "-3.2"),
                _map_row("20.1", "chaotic", "2.0e-04", "41.7"),
                _map_row("20.2", "periodic", "1.5e-04", "-2.9", after="true")]
    run_rows = [MAP_FIELDS, _map_row("20.0", "periodic", "1.234567894e-04", "-3.2"),  # 2e-9 relative: within 1e-6
                _map_row("20.1", "chaotic", "2.2e-04", "38.5"),
                _map_row("20.2", "subharmonic", "1.9e-04", "-1.1", after="true")]
    ref = _folder(tmp_path / "ref", {"frc": {"response_map.csv": ref_rows}})
    run = _folder(tmp_path / "run", {"frc": {"response_map.csv": run_rows}})
    rows = compare_scene("s", run, ref, {"frc": spec}, ("frc",))
    assert not reproduction.failed(rows), reproduction.summary(rows)
    def quantities(kind: str) -> set[str]:
        return {r.quantity.split(" [")[0].split(":")[0] for r in rows if r.status == kind}

    assert quantities(WITHIN) == {"x1_min_m", "x1_mean_m", "x1_max_m"}  # the first frequency's, to 1e-6
    assert quantities(CHAOTIC_DIFF) == {"x1_min_m", "x1_mean_m", "x1_max_m", "lyapunov_per_s"}
    assert {"regime", "period_k", "max_abs_mu"} <= quantities(reproduction.SENSITIVE_DIFF)
    chaos = next(r for r in rows if r.status == CHAOTIC_DIFF)
    t_h = math.log(HORIZON_TOL / DELTA0) / 38.5  # the run's largest exponent, not the reference's 41.7
    assert f"not comparable past t = {t_h:.3g} s" in chaos.note, chaos.note
    # before the chaos the regime is deterministic: another one is a failure
    run_rows[1] = _map_row("20.0", "subharmonic", "1.234567891e-04", "-3.2")
    _write_csv(run / "response_map.csv", run_rows)
    bad = reproduction.failed(compare_scene("s", run, ref, {"frc": spec}, ("frc",)))
    assert {r.quantity.split(" [")[0] for r in bad} == {"regime", "period_k", "max_abs_mu"}
    # a frequency more or less (the grid follows the HB curve's contact band): sensitive, not a failure
    _write_csv(run / "response_map.csv", [*ref_rows, _map_row("20.3", "periodic", "1e-04", "-3.0", after="true")])
    rows = compare_scene("s", run, ref, {"frc": spec}, ("frc",))
    assert not reproduction.failed(rows)
    assert [r.status for r in rows if r.file == "response_map.csv"] == [reproduction.SENSITIVE_DIFF]


def test_response_map_marks_what_follows_chaos():
    """frc_map_files writes after_chaos: true from the frequency after the first chaotic, quasi-periodic or
    unsettled one of a sweep, in sweep order."""
    from types import SimpleNamespace as N

    import numpy as np

    from bearingshaft.stages.frc_map_files import _sweep_rows

    def point(regime, settled=True):
        return N(peak=np.ones((4, 3)), regime=regime, period_k=1, lyapunov_per_s=-1.0, asymmetry=0.0,
                 lyapunov_tol=0.1, max_abs_mu=0.5, settled=settled, contact=True, broadband=0.0, n_periods=64)

    regimes = [("periodic", True), ("periodic", False), ("periodic", True), ("chaotic", True), ("periodic", True)]
    rm = N(freq_hz=np.arange(5.0), points=[point(r, s) for r, s in regimes], jump=[False, False, True, False, True])
    rows, jumps = _sweep_rows(1.0, "up", rm, 0)
    assert [r["after_chaos"] for r in rows] == ["false", "false", "true", "true", "true"]
    assert [j["after_chaos"] for j in jumps] == ["true", "true"]


def test_lines_added_with_a_blank_line(tmp_path):
    """A table added to a text file (a scene's new [frf], after a blank line): the added lines differ, the blank
    one is no quantity."""
    ref = _folder(tmp_path / "ref", {"x": {"a.md": "[ringdown]\nduration_s = 2\n"}})
    run = _folder(tmp_path / "run", {"x": {"a.md": "[ringdown]\nduration_s = 2\n\n[frf]\nblows = 5\n"}})
    rows = compare_scene("s", run, ref, {"x": Reproduction()}, ("x",))
    assert [(r.quantity, r.status, r.run) for r in rows if r.file == "a.md"] == [
        ("line 4", DIFFERS, "[frf]"), ("line 5", DIFFERS, "blows = 5")]
