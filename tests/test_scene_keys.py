"""``bearingshaft keys`` (issue 24): every table and key of a scene with type, unit, default, allowed values
and meaning, generated from the dataclasses; ``bearingshaft scenes --show``; subcommand help that says what
each command writes."""

from __future__ import annotations

import argparse
import csv
import io
import re
import tomllib
from dataclasses import dataclass
from importlib import resources

import pytest

from bearingshaft.cli import build_parser, main
from bearingshaft.scenes import builtin_names, load_scene
from bearingshaft.scenes.keys import field_comments, scene_tables, select_tables, table_keys, unit_and_meaning

ALL = [k for t, c in scene_tables().items() for k in table_keys(t, c)]
BY_TABLE = {(t, c): table_keys(t, c) for t, c in scene_tables().items()}
SUFFIX_UNITS = {"_s": "s", "_hz": "Hz", "_N": "N", "_J": "J", "_m": "m", "_kg": "kg", "_m_s": "m/s", "_deg": "degrees"}


def _listed(table: str, kind: str | None = None) -> set[str]:
    name = f"{table}.{kind}" if kind else table
    return {k.key for k in table_keys(name, scene_tables()[name])}


@pytest.mark.parametrize("scene", builtin_names())
def test_every_key_of_every_builtin_scene_is_listed(scene):
    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / f"{scene}.toml").read_text())
    for table, value in data.items():
        if table == "model":
            assert set(value) <= _listed("model", value.get("kind", "discrete")), table
        elif table == "load":
            for load in value:
                assert set(load) <= _listed("load", load["kind"])
        elif table == "sweep":
            assert set(value) <= _listed("sweep")
        elif isinstance(value, dict):
            assert set(value) <= _listed(table), table


def test_every_key_has_a_meaning_and_its_name_agrees_with_its_unit():
    for k in ALL:
        assert k.meaning, f"{k.table} {k.key}: no comment on its field"
        for suffix, unit in sorted(SUFFIX_UNITS.items(), key=lambda kv: -len(kv[0])):
            if k.key.endswith(suffix):
                if len(k.key) - len(suffix) >= 2:  # not k_s, a stiffness
                    assert k.unit == unit, f"{k.table} {k.key}: unit {k.unit!r}, its name says {unit}"
                break


def _bound(rule: str):
    """(lo, lo_open, hi, hi_open) of a rule "> 0", ">= 2", "in (0, 1)", "in [0, 1)"; None for others
    (written here again, not taken from bearingshaft.scenes.keys: the test reads the listing as a user would)."""
    if m := re.fullmatch(r"(>=?) (-?[\d.e+-]+)", rule):
        return float(m[2]), m[1] == ">", None, None
    if m := re.fullmatch(r"in ([(\[])(-?[\d.e+-]+), (-?[\d.e+-]+)([)\]])", rule):
        return float(m[2]), m[1] == "(", float(m[3]), m[4] == ")"
    return None


def test_listed_ranges_are_what_the_classes_accept_and_refuse():
    """Each simple rule of the listing checked on its class: the bound itself refused or accepted as the
    rule says, and a value just inside accepted."""
    checked = 0
    for (table, cls), keys in BY_TABLE.items():
        for k in keys:
            b = _bound(k.allowed) if k.type in ("float", "int") else None  # COUPLED keys are left out: no
            # value is inside the range whatever the other keys
            if b is None:
                continue
            lo, lo_open, hi, hi_open = b
            cast = int if k.type == "int" else float

            def ok(v, _cls=cls, _k=k, _cast=cast):
                try:
                    obj = _cls(**{_k.key: _cast(v)})
                    if hasattr(obj, "signal"):  # a [[load]] is checked by its time function, as the parser does
                        obj.signal()
                    return True
                except ValueError:
                    return False

            assert ok(lo) is not lo_open, f"{table} {k.key} = {lo}: the listing says {k.allowed!r}"
            inside = lo + 1 if hi is None else 0.5 * (lo + hi)
            if k.type == "float" or float(inside).is_integer():
                assert ok(inside), f"{table} {k.key} = {inside}: the listing says {k.allowed!r}"
            if hi is not None:
                assert ok(hi) is not hi_open, f"{table} {k.key} = {hi}: the listing says {k.allowed!r}"
            checked += 1
    assert checked >= 50  # most numeric keys have a simple range


def test_the_gap_is_listed_once_under_one_name():
    rows = {(k.table, k.key): k for k in ALL}
    for kind in ("discrete", "rom", "assembly"):
        gap = rows[(f'[model] kind = "{kind}"', "gap")]
        assert gap.unit == "m" and gap.default == "0.000254" and "clearance" in gap.meaning
        assert (f'[model] kind = "{kind}"', "g") not in rows
    assert rows[('[model] kind = "discrete"', "gap")].allowed == ">= 0"
    assert rows[("[ringdown]", "omega_dt")].allowed.startswith("> 0; <= 1.6")
    assert rows[("[ringdown]", "method")].allowed == "one of exact, explicit, dop853"
    assert rows[("[ringdown]", "dt_s")].default == "not set"


def test_field_comments_follow_continuations_and_stop_at_headings():
    @dataclass
    class Planted:
        a: float = 1.0  # m, first line
        # and its second line
        b: int = 2
        # -- a heading ---------------
        c: str = "x"  # which one

    assert field_comments(Planted) == {"a": "m, first line and its second line", "b": "", "c": "which one"}
    assert unit_and_meaning("N s/m, damping") == ("N s/m", "damping")
    assert unit_and_meaning("exact | explicit") == ("", "exact | explicit")


def test_keys_command(capsys):
    assert main(["keys", "ringdown"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("[ringdown]\n") and "omega_dt" in out and "[spectrogram]" not in out
    assert main(["keys", "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == len(ALL) and set(rows[0]) == {"table", "key", "type", "unit", "default", "allowed", "meaning"}
    assert main(["keys", "ringdwn"]) == 2
    assert "unknown table 'ringdwn' (did you mean 'ringdown'?)" in capsys.readouterr().err
    assert set(select_tables("model")) == {"model.discrete", "model.discrete_friction", "model.rom", "model.assembly"}


def test_scenes_show_prints_a_builtin_scene_to_start_from(capsys, tmp_path):
    assert main(["scenes", "--show", "discrete-impulse"]) == 0
    text = capsys.readouterr().out
    assert text == (resources.files("bearingshaft") / "scenes" / "discrete-impulse.toml").read_text()
    copy = tmp_path / "mine.toml"
    copy.write_text(text)
    assert load_scene(str(copy)).ringdown == load_scene("discrete-impulse").ringdown
    assert main(["scenes", "--show", "discrete-impuls"]) == 2
    assert "did you mean 'discrete-impulse'?" in capsys.readouterr().err


def test_every_subcommand_help_says_what_it_does_and_writes():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        assert p.description and len(p.description) > 80, f"{name}: no description"
        assert re.search(r"\b[Ww]rites\b", p.description), f"{name}: its help does not say what it writes"
