"""The exact integrator's tables kept across runs (issue 28): looked up by the system's contents, the
same bits as tables worked out afresh, and a changed system never served the tables of the old one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import HalfSine, Loads
from reduced.transient import exact_tables as et
from reduced.transient.exact import integrate_exact

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
