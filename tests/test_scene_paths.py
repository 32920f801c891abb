"""Paths in a scene (issue 24): a tabulated load's file, [hammer] force_file, [modal] test_shapes and
[model] rom_file are found from the scene file's folder (a built-in scene's: the package's), whatever
the working directory, and a missing one is refused naming the folder looked in."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from bearingshaft.scenes import SceneError, load_scene, parse_scene
from bearingshaft.sweep import build_plan

FORCE = "t_s,force_N\n0.0,0.0\n0.001,10.0\n0.002,0.0\n"
SCENE = """
[model]
kind = "discrete"
[ringdown]
duration_s = 0.01
sample_rate_hz = 2000.0
[[load]]
kind = "tabulated"
point = "x2"
file = "{file}"
"""


@pytest.fixture
def folders(tmp_path, monkeypatch) -> tuple[Path, Path]:
    """(the scene's folder, another folder that is the working directory)."""
    scene_dir, elsewhere = tmp_path / "case", tmp_path / "elsewhere"
    scene_dir.mkdir()
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    return scene_dir, elsewhere


def test_tabulated_load_is_read_from_the_scene_folder(folders):
    scene_dir, _ = folders
    (scene_dir / "force.csv").write_text(FORCE)
    path = scene_dir / "blow.toml"
    path.write_text(SCENE.format(file="force.csv"))
    scene = load_scene(str(path))
    sig = scene.load_signals[0]
    # piecewise linear through the file's samples: 5 N half-way up the ramp
    assert float(sig(np.array([0.0005]))[0]) == pytest.approx(5.0, rel=1e-12)
    assert scene.folder == str(scene_dir)


def test_missing_file_names_the_folder_looked_in(folders):
    scene_dir, elsewhere = folders
    path = scene_dir / "blow.toml"
    path.write_text(SCENE.format(file="force.csv"))
    (elsewhere / "force.csv").write_text(FORCE)  # in the working directory: not where a scene looks
    with pytest.raises(SceneError) as exc:
        load_scene(str(path))
    msg = str(exc.value)
    assert "[[load]] 1 (tabulated) file: no such file 'force.csv'" in msg
    assert f"in {str(scene_dir)!r}" in msg and "relative to its file's folder" in msg


@pytest.mark.parametrize("table, key", [
    ('[model]\nkind = "rom"\nlayout = "assembly"\n[ringdown]\nduration_s = 0.05\n[hammer]\n', "force_file"),
    ('[model]\nkind = "assembly"\n[modal]\n', "test_shapes"),
    ('[model]\nkind = "rom"\n', "rom_file"),
])
def test_every_path_key_is_relative_to_the_scene_folder(folders, table, key):
    scene_dir, _ = folders
    text = table + f'{key} = "data/input.dat"\n'  # a key of the table the text ends with
    path = scene_dir / "s.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as exc:
        load_scene(str(path))
    assert f"{key}: no such file 'data/input.dat' in {str(scene_dir)!r}" in str(exc.value)


def test_builtin_scenes_are_relative_to_the_package_folder():
    folder = Path(str(resources.files("bearingshaft") / "scenes"))
    assert load_scene("discrete-impulse").folder == str(folder)


def test_text_without_a_file_is_relative_to_the_working_directory(folders):
    _, elsewhere = folders
    (elsewhere / "force.csv").write_text(FORCE)
    scene = parse_scene(SCENE.format(file="force.csv"), "blow", "text")
    assert scene.loads[0].file == str(elsewhere / "force.csv")


def test_sweep_cases_find_the_file_from_any_folder(folders, tmp_path, monkeypatch):
    """A sweep writes each case's scene elsewhere (a worker's temporary folder): its paths are made absolute."""
    scene_dir, _ = folders
    (scene_dir / "force.csv").write_text(FORCE)
    path = scene_dir / "blow.toml"
    path.write_text(SCENE.format(file="force.csv") + '[sweep.vary]\n"load[0].start_s" = [0.0, 0.002]\n')
    scene = load_scene(str(path))
    plan = build_plan(scene, scene.sweep, "test")
    other = tmp_path / "worker"
    other.mkdir()
    monkeypatch.chdir(other)
    for case in plan.cases:
        assert f'file = "{scene_dir / "force.csv"}"' in case.text
        parse_scene(case.text, case.name, case.origin)  # read from the worker's folder: no refusal
