"""The exact integrator's speed-ups of issue 28 against the paths they replace:

- its tables kept across runs: looked up by the system's contents, the same bits as tables worked out
  afresh, and a changed system never served the tables of the old one;
- its output samples stepped from one to the next (e^{lam (tau + 1/fs)} = e^{lam tau} e^{lam / fs}):
  within round-off of the samples worked out afresh, the trajectory itself untouched, and the same bits
  whatever the chunking.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import HalfSine, Loads
from reduced.transient import _modal
from reduced.transient import exact_tables as et
from reduced.transient.exact import NO_SEGMENTS, NO_TAU, ExactOptions, ExactStepper, integrate_exact, stream_exact
from reduced.transient.result import sample_count

P = DiscreteParams()
IMPULSE = (np.zeros(3), np.array([0.0, 0.0, 200.0]))


def test_a_system_built_again_is_served_its_kept_tables():
    et.clear_table_cache()
    a = et.run_tables(P.system())
    b = et.run_tables(P.system())  # another object with the same contents
    assert b is a
    # the kept tables are those worked out afresh (an independent call of the table builders)
    fresh = et.state_table(P.system().fold_zero_gap_tips())
    assert np.array_equal(a["table"].lam, fresh.lam) and np.array_equal(a["table"].V, fresh.V)


def test_a_changed_system_gets_its_own_tables():
    et.clear_table_cache()
    system = P.system()
    a = et.run_tables(system)
    stiffer = et.run_tables(replace(P, k_g=2.0 * P.k_g).system())
    assert stiffer is not a
    assert not np.array_equal(stiffer["table"].lam, a["table"].lam)
    system.K[0, 0] *= 1.5  # changed in place: its contents are a new key
    changed = et.run_tables(system)
    assert changed is not a
    assert np.max(np.abs(changed["table"].lam)) != np.max(np.abs(a["table"].lam))


def test_the_cache_keeps_only_the_last_few_systems():
    et.clear_table_cache()
    first = et.run_tables(P.system())
    for i in range(et.TABLE_CACHE_SIZE):
        et.run_tables(replace(P, k_g=P.k_g * (1.1 + 0.1 * i)).system())
    assert et.run_tables(P.system()) is not first  # evicted: worked out again


def test_tables_too_large_to_keep_are_worked_out_each_time(monkeypatch):
    et.clear_table_cache()
    size = et._nbytes(et.run_tables(P.system()))  # the discrete model's: ~45 kB
    assert 10_000 < size < 1_000_000
    monkeypatch.setattr(et, "TABLE_CACHE_ENTRY_BYTES", size - 1)
    et.clear_table_cache()
    assert et.run_tables(P.system()) is not et.run_tables(P.system())


def test_runs_with_kept_tables_are_the_bits_of_runs_without():
    # free and forced: a warm run (tables kept from the previous one) against a cold one
    system = P.system()
    blow = HalfSine(peak_N=300.0, duration_s=1e-3, start_s=1e-3)
    loads = Loads(np.array([[0.0, 1.0, 0.0]]), (blow,), ("x2",))
    for kw in ({}, {"loads": loads}):
        et.clear_table_cache()
        cold = integrate_exact(system, *IMPULSE, 0.02, 20000.0, **kw)
        warm = integrate_exact(system, *IMPULSE, 0.02, 20000.0, **kw)
        assert cold.stats["n_events"] > 0
        assert np.array_equal(cold.x, warm.x) and np.array_equal(cold.v, warm.v)
        assert np.array_equal(cold.dissipated, warm.dissipated)
        assert np.array_equal(cold.external, warm.external)


def test_loads_with_other_directions_get_their_own_forced_table():
    et.clear_table_cache()
    tables = et.run_tables(P.system())
    blow = HalfSine(peak_N=300.0, duration_s=1e-3, start_s=1e-3)
    at_2 = et.cached_forced_table(tables, Loads(np.array([[0.0, 1.0, 0.0]]), (blow,), ("x2",)))
    louder = et.cached_forced_table(tables, Loads(np.array([[0.0, 1.0, 0.0]]), (replace(blow, peak_N=900.0),),
                                                  ("x2",)))
    at_1 = et.cached_forced_table(tables, Loads(np.array([[1.0, 0.0, 0.0]]), (blow,), ("x1",)))
    assert louder is at_2  # the table does not depend on the amplitude
    assert at_1 is not at_2 and not np.array_equal(at_1.U, at_2.U)


def free_samples(system, x0, v0, T, fs, stepped):
    """(samples y, final y, kernel result) of a free exact run in one kernel call, its samples stepped
    (fs passed) or worked out afresh (fs = 0: the path before issue 28)."""
    N = sample_count(T, fs)
    st = ExactStepper(system, x0, v0, T, N, fs, ExactOptions(), None, False)
    out_y, out_W = np.empty((N, 2 * system.n)), np.empty(N)
    y, active = st.y.copy(), st.active.copy()
    r = _modal._free_kernel(st.mt, st.run_system.offset, st.run_system.side, st.run_system.tip, st.damped, y, active,
                            0.0, st.groups[0], 0, np.arange(N) / fs, 0, np.inf, out_y, out_W, 0.0, st.hmin, st.floor,
                            10**9, 0, np.empty(0), 0.0, NO_SEGMENTS, NO_TAU, fs if stepped else 0.0)
    return np.column_stack([out_y, out_W]), y, r


def test_stepped_samples_are_the_fresh_ones_to_round_off():
    # each step is one complex product (and a sum) per term, and an anchor is worked out afresh at
    # least every SAMPLE_ANCHOR samples: <= ~SAMPLE_ANCHOR x a few eps of the terms, ~1e-14 of the
    # motion; the sample times differ by their own rounding (ulp(t) x |lambda| ~ 1e-12 of the fastest
    # term at t = 0.5 s), so 1e-11 of max |y| (W: of its final value)
    system = P.system()
    a, ya, ra = free_samples(system, *IMPULSE, 0.5, 20000.0, True)
    b, yb, rb = free_samples(system, *IMPULSE, 0.5, 20000.0, False)
    assert ra[3] > 1000  # events
    assert ra[:8] == rb[:8] and np.array_equal(ya, yb)  # the trajectory is not touched: the same bits
    scale = np.max(np.abs(b), axis=0)
    assert np.max(np.abs(a - b) / scale) < 1e-11
    assert not np.array_equal(a, b)  # the stepped path was taken


def test_stepped_samples_do_not_depend_on_the_chunking():
    # buffers that start between anchors step from the last anchor: the same bits as one buffer
    system = P.system()
    whole = integrate_exact(system, *IMPULSE, 0.05, 20000.0)
    for chunk in (7, 33, 100):
        parts = list(stream_exact(system, *IMPULSE, 0.05, 20000.0, chunk_samples=chunk))
        x = np.concatenate([c.x for c in parts])
        W = np.concatenate([c.dissipated for c in parts])
        assert np.array_equal(x, whole.x) and np.array_equal(W, whole.dissipated), chunk
