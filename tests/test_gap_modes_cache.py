"""The full model's gap modes kept in the reduced-model cache (bearingshaft.gap_modes, issue 28): a loaded
eigensolution is the bits of a solve, an entry is keyed by what the solve depends on, and a bad one is solved
again."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from reduced.models.rom import RomSpec

SPEC = RomSpec()  # beam-grounded, planar, Table-1 contact, the default mesh (a solve takes about a second)


@pytest.fixture(scope="module")
def fe():
    from fem.model import build_system

    return build_system(SPEC.fe_model())


def _entries(folder) -> list:
    return sorted(p.name for p in folder.glob("gapmodes-*.npz"))


def _same(a, b) -> None:
    for name in ("freq_hz", "phi", "tip_motion", "symmetric", "coupled"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and np.array_equal(x, y), name


def test_a_loaded_solution_is_the_bits_of_a_solve(fe, tmp_path, monkeypatch):
    from bearingshaft.gap_modes import STATES, full_gap_modes
    from fem.contact import contact_pairs, gap_modes

    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))
    first = full_gap_modes(fe, SPEC)
    assert len(_entries(tmp_path)) == 2  # one a state
    again = full_gap_modes(fe, SPEC)
    pairs = contact_pairs(fe, gap=SPEC.gap, k_g=SPEC.k_g)
    for s in STATES:
        _same(again[s], first[s])
        _same(again[s], gap_modes(fe, pairs, s, len(first[s].freq_hz)))  # the solve itself, no cache
    # the tied tips stiffen the lowest coupled mode: the two states are different solutions, not one entry
    assert first["closed"].freq_hz[first["closed"].coupled][0] > first["open"].freq_hz[first["open"].coupled][0]


def test_other_inputs_make_other_entries(fe, tmp_path, monkeypatch):
    from bearingshaft.gap_modes import full_gap_modes

    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))
    base = full_gap_modes(fe, SPEC)
    stiffer = full_gap_modes(fe, replace(SPEC, k_g=4.0 * SPEC.k_g))
    # the open state does not see k_g (the same entry), the closed one does (a new one, other frequencies)
    assert len(_entries(tmp_path)) == 3
    _same(stiffer["open"], base["open"])
    assert not np.array_equal(stiffer["closed"].freq_hz, base["closed"].freq_hz)
    fewer = full_gap_modes(fe, SPEC, n_modes=8)
    assert len(_entries(tmp_path)) == 5 and len(fewer["open"].freq_hz) == 8


def test_a_bad_entry_is_solved_again(fe, tmp_path, monkeypatch, caplog):
    from bearingshaft.gap_modes import full_gap_modes

    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path))
    first = full_gap_modes(fe, SPEC)
    for p in tmp_path.glob("gapmodes-*.npz"):
        data = bytearray(p.read_bytes())
        data[len(data) // 2] ^= 0xFF  # one flipped byte: the manifest's sha256 no longer matches
        p.write_bytes(bytes(data))
    again = full_gap_modes(fe, SPEC)
    for s in first:
        _same(again[s], first[s])
    assert sum("sha256" in r.getMessage() for r in caplog.records) == 2  # reported in one line each
    assert len(_entries(tmp_path)) == 2
