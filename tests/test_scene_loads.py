"""[[load]] tables: read into the right loads, and every bad load refused in one line (exit 2)."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from bearingshaft.cli import main
from bearingshaft.scenes import load_scene

BASE = """
[model]
kind = "discrete"
[[load]]
{load}
[ringdown]
duration_s = 0.05
sample_rate_hz = 20000.0
"""
HAMMER = 'kind = "half_sine"\npoint = "x2"\npeak_N = 500.0\nduration_s = 1e-3\nstart_s = 0.002'
SHAKER = 'kind = "harmonic"\npoint = "x1"\namplitude_N = 3.0\nfreq_hz = 120.0\nphase_deg = 90.0'


def _scene(tmp_path, load: str, extra: str = "") -> str:
    path = tmp_path / "case.toml"
    path.write_text(BASE.format(load=load) + extra)
    return str(path)


def _check(scene: str) -> tuple[int, list[str]]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["check", "--scene", scene])
    return rc, err.getvalue().splitlines()


def test_loads_are_read_with_their_values(tmp_path):
    csv = tmp_path / "force.csv"
    csv.write_text("time_s,force_N\n0.0,0.0\n0.001,10.0\n0.003,-4.0\n")
    scene = load_scene(_scene(tmp_path, HAMMER, f"\n[[load]]\n{SHAKER}\n\n[[load]]\nkind = \"tabulated\"\n"
                                               f"point = \"x3\"\nfile = \"{csv}\"\nstart_s = 0.01\n"))
    hammer, shaker, table = scene.load_signals
    assert [s.point for s in scene.loads] == ["x2", "x1", "x3"]
    # the half sine peaks mid-pulse and is zero outside it
    assert hammer(0.0025) == pytest.approx(500.0)
    assert hammer(0.0019) == 0.0 and hammer(0.0031) == 0.0
    assert shaker(0.0) == pytest.approx(3.0 * np.cos(np.pi / 2), abs=1e-15)
    assert shaker(1 / 480) == pytest.approx(3.0 * np.cos(np.pi), rel=1e-12)
    # the file's times are shifted by start_s, linear in between, zero after the last sample
    assert table(0.0105) == pytest.approx(5.0) and table(0.012) == pytest.approx(3.0)
    assert table(0.0135) == 0.0


BAD = {
    "negative duration": (HAMMER.replace("duration_s = 1e-3", "duration_s = -1e-3"), "duration_s"),
    "zero duration": (HAMMER.replace("duration_s = 1e-3", "duration_s = 0.0"), "duration_s"),
    "NaN peak": (HAMMER.replace("500.0", "nan"), "peak_N"),
    "inf frequency": (SHAKER.replace("120.0", "inf"), "freq_hz"),
    "negative frequency": (SHAKER.replace("120.0", "-120.0"), "freq_hz"),
    "unknown point": (HAMMER.replace('"x2"', '"x9"'), "point"),
    "unknown kind": (HAMMER.replace("half_sine", "hammer"), "kind"),
    "key of another kind": (HAMMER + "\nfreq_hz = 3.0", "freq_hz"),
    "string for a number": (HAMMER.replace("500.0", '"500"'), "peak_N"),
    "bool for a number": (HAMMER.replace("500.0", "true"), "peak_N"),
    "unknown direction": (HAMMER + '\ndirection = "lateral"', "direction"),
    "starts after the run": (HAMMER.replace("start_s = 0.002", "start_s = 0.05"), "start_s"),
    "missing file": ('kind = "tabulated"\nfile = "no-such-force.csv"', "file"),
    "no file": ('kind = "tabulated"', "file"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_loads_are_refused_in_one_line(tmp_path, case):
    load, key = BAD[case]
    rc, lines = _check(_scene(tmp_path, load))
    assert rc == 2 and len(lines) == 1, lines
    assert "[[load]] 1" in lines[0] and key in lines[0], lines[0]
    assert "Traceback" not in lines[0]


@pytest.mark.parametrize("content,key", [
    ("0.0,1.0\n0.002,2.0\n0.001,3.0\n", "increase"),  # non-monotonic times
    ("0.0,1.0\n0.001,nan\n", "finite"),
    ("0.0,1.0\n", "at least 2"),
    ("0.0,1.0,2.0\n0.1,1.0,2.0\n", "two columns"),
    ("", "no samples"),
])
def test_bad_force_files_are_refused_in_one_line(tmp_path, content, key):
    csv = tmp_path / "force.csv"
    csv.write_text(content)
    rc, lines = _check(_scene(tmp_path, f'kind = "tabulated"\nfile = "{csv}"'))
    assert rc == 2 and len(lines) == 1, lines
    assert "[[load]] 1 file" in lines[0] and key in lines[0], lines[0]


@pytest.mark.parametrize("extra,table", [("\n[work_precision]\n", "work_precision"),
                                         ("\n[stiff_cases]\n", "stiff_cases")])
def test_loads_with_a_free_study_are_refused(tmp_path, extra, table):
    rc, lines = _check(_scene(tmp_path, HAMMER, extra))
    assert rc == 2 and len(lines) == 1 and table in lines[0]


def test_loads_need_a_ringdown(tmp_path):
    path = tmp_path / "case.toml"
    path.write_text(f'[model]\nkind = "discrete"\n[[load]]\n{HAMMER}\n[nnm]\n')
    rc, lines = _check(str(path))
    assert rc == 2 and len(lines) == 1 and "[ringdown]" in lines[0]


def test_load_as_a_table_not_an_array_is_refused(tmp_path):
    path = tmp_path / "case.toml"
    path.write_text(f'[model]\nkind = "discrete"\n[load]\n{HAMMER}\n[ringdown]\n')
    rc, lines = _check(str(path))
    assert rc == 2 and len(lines) == 1 and "array of tables" in lines[0]


def test_uff58_channels_round_trip_bit_for_bit(tmp_path):
    from fem.uff import TimeHistory, read_uff58, write_uff58

    rng = np.random.default_rng(1)
    chans = [TimeHistory("hammer", 1, -3, "force", rng.standard_normal(500), 5e-5),
             TimeHistory("beam_s1:z", 101, 3, "acceleration", 1e3 * rng.standard_normal(500), 5e-5, 0.25),
             TimeHistory("tip_lc1", 201, 3, "reaction_force", rng.standard_normal(500), 5e-5)]
    write_uff58(tmp_path / "t.uff", chans)
    back = read_uff58(tmp_path / "t.uff")
    assert [(c.name, c.node, c.direction, c.quantity, c.unit) for c in back] == \
        [(c.name, c.node, c.direction, c.quantity, c.unit) for c in chans]
    for a, b in zip(chans, back, strict=True):
        assert np.array_equal(a.data, b.data) and a.dt_s == b.dt_s and a.t0_s == b.t0_s


def test_tabulated_load_from_uff58_picks_the_excitation_force(tmp_path):
    from fem.uff import TimeHistory, write_uff58

    t_force = np.array([0.0, 1.0, 4.0, 1.0, 0.0])
    write_uff58(tmp_path / "test.uff", [TimeHistory("beam_s1:z", 101, 3, "acceleration", np.ones(5), 1e-3),
                                        TimeHistory("hammer", 1, -3, "force", t_force, 1e-3)])
    scene = load_scene(_scene(tmp_path, f'kind = "tabulated"\nfile = "{tmp_path / "test.uff"}"'))
    sig = scene.load_signals[0]
    assert np.array_equal(sig.force_N, t_force) and sig(0.0025) == pytest.approx(2.5)


@pytest.mark.parametrize("quantity,unit,key", [("acceleration", None, "forces"),
                                               ("force", "kN", "unit 'kN'")])
def test_uff58_without_a_usable_force_is_refused(tmp_path, quantity, unit, key):
    from fem.uff import TimeHistory, write_uff58

    write_uff58(tmp_path / "bad.uff", [TimeHistory("ch", 1, 3, quantity, np.ones(5), 1e-3)])
    if unit:  # a hand-edited unit label
        text = (tmp_path / "bad.uff").read_bytes().replace(b"N                   ", b"kN                  ", 1)
        (tmp_path / "bad.uff").write_bytes(text)
    rc, lines = _check(_scene(tmp_path, f'kind = "tabulated"\nfile = "{tmp_path / "bad.uff"}"'))
    assert rc == 2 and len(lines) == 1 and key in lines[0], lines
