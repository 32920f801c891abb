"""Work the frc stage's stepped sines and response map no longer repeat (issue 28) gives the bits it gave.

Each shortcut keeps a value worked out once instead of at every frequency or every call: the
frequency-independent parts of forced_table, the energy norm of a sweep's period maps, the state
table of a stepped sine, the cos/sin basis on the phase grid of the HB stop projection. Every
comparison here is bit for bit (tobytes), against the old computation written out in the test: a
difference in the last bit of any of them would move a chaotic sweep's whole record.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic import exact_hb
from reduced.periodic.hb import _derivative_matrix
from reduced.periodic.response_map import _fixed_norm
from reduced.transient.exact_tables import forced_table, state_table
from reduced.transient.flow import Flow
from reduced.transient.lyapunov import PeriodMap, energy_norm_matrix

PARAMS = DiscreteParams()
SYSTEM = PARAMS.system()
LOAD = PARAMS.point_rows[1]


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _forced_table_before(system, table, loads):
    """forced_table as it was before its frequency-independent parts were kept (the reference)."""
    n = system.n
    b = np.ascontiguousarray(loads.b, dtype=float)
    omega = loads.omegas()
    S, L = table.lam.shape[0], b.shape[0]
    Y = np.zeros((S, 2 * n, L), complex)
    U = np.zeros((S, 2 * n, L), complex)
    Sb = np.zeros((S, n, L))
    Minv_b = np.linalg.solve(system.M, b.T)
    cache = {}
    for active in system.feasible_states():
        s = int(np.sum(active * (1 << np.arange(system.m))))
        Ks, _ = system.state_matrices(active)
        key = Ks.tobytes()
        if key not in cache:
            y = np.zeros((2 * n, L), complex)
            for l in range(L):
                if omega[l] > 0.0:
                    h = solve(Ks - omega[l] ** 2 * system.M + 1j * omega[l] * system.C, b[l].astype(complex))
                    y[:n, l], y[n:, l] = h, 1j * omega[l] * h
            cache[key] = (y, table.Vinv[s][:, n:] @ Minv_b, solve(Ks, b.T))
        Y[s], U[s], Sb[s] = cache[key]
    return Y, U, Sb


@pytest.mark.parametrize("rows", [[1], [0, 2]])
def test_forced_table_keeps_the_bits_over_frequencies_and_loads(rows):
    table = state_table(SYSTEM)
    b = PARAMS.point_rows[rows]
    for f in (3.0, 17.3, 17.3, 250.0):  # a repeated frequency: the kept parts read twice
        loads = Loads(b, tuple(Harmonic(1.0 + k, f * (1 + 0.1 * k)) for k in range(len(rows))))
        ft = forced_table(SYSTEM, table, loads)
        Y, U, Sb = _forced_table_before(SYSTEM, table, loads)
        assert _same(ft.Y, Y) and _same(ft.U, U) and _same(ft.Sb, Sb)


def test_forced_table_of_another_table_is_its_own():
    """A second decomposition of the same system (another StateTable object) gets its own parts."""
    loads = Loads(LOAD[None, :], (Harmonic(1.0, 20.0),))
    t1, t2 = state_table(SYSTEM), state_table(SYSTEM)
    a, b = forced_table(SYSTEM, t1, loads), forced_table(SYSTEM, t2, loads)
    Y, U, Sb = _forced_table_before(SYSTEM, t2, loads)
    assert _same(b.Y, Y) and _same(b.U, U) and _same(b.Sb, Sb) and _same(a.Y, b.Y)


def test_a_sweeps_energy_norm_is_each_frequencys():
    """K positive definite: D does not depend on the frequency, and the sweep's (D, D^-1) is each period
    map's own to the bit; a PeriodMap given them runs the same periods."""
    D, Dinv = _fixed_norm(SYSTEM, 15.0)
    for f in (15.0, 18.2, 40.0):
        own = PeriodMap(SYSTEM, LOAD, 1.0, f, rows=PARAMS.point_rows)
        assert _same(own.norm_matrix, D) and _same(own.norm_inverse, Dinv)
        assert _same(energy_norm_matrix(SYSTEM, 2 * np.pi * f), D)
    y0 = np.zeros(2 * SYSTEM.n)
    w = np.ones((2 * SYSTEM.n, 1))
    a = PeriodMap(SYSTEM, LOAD, 1.0, 18.2, rows=PARAMS.point_rows).run(y0, 6, tangent=w)
    b = PeriodMap(SYSTEM, LOAD, 1.0, 18.2, rows=PARAMS.point_rows, norm=(D, Dinv)).run(y0, 6, tangent=w)
    assert _same(a.poincare, b.poincare) and _same(a.log_growth, b.log_growth) and _same(a.peak, b.peak)


def test_a_flow_on_a_kept_state_table_is_the_flow_on_its_own():
    loads = Loads(LOAD[None, :], (Harmonic(1.0, 18.2),))
    x0 = np.array([2e-4, 1e-4, -1e-4])
    a = Flow(SYSTEM, loads=loads)(x0, np.zeros(3), 3 / 18.2, jacobian=True)
    b = Flow(SYSTEM, table=state_table(SYSTEM), loads=loads)(x0, np.zeros(3), 3 / 18.2, jacobian=True)
    assert _same(a.y, b.y) and _same(a.jacobian, b.jacobian)


@pytest.mark.parametrize("H", [1, 3, 15, 31])
def test_the_tabulated_phase_grid_is_the_series_own(H):
    """The HB stop projection's extrema search reads the series on its phase grid from a table: each value
    is _series's at that phase, bit for bit, for coefficients over nine decades."""
    N = exact_hb.default_root_samples(H)
    basis = exact_hb.grid_basis(H, N)
    rng = np.random.default_rng(H)
    h = 2.0 * math.pi / N
    for _ in range(10):
        a = rng.standard_normal(2 * H + 1) * 10.0 ** rng.integers(-6, 3)
        old = np.array([exact_hb._series(a, (i + 1) * h) for i in range(N - 1)])
        new = np.array([exact_hb._series_on_grid(a, basis, i) for i in range(N - 1)])
        assert _same(old, new)
    # and the extrema found from it: those of the closed form of a two-term series (round-off: 1e-12 rad)
    Nab = _derivative_matrix(H)
    a = np.zeros(2 * H + 1)
    a[1] = 1.0  # cos t: extrema at 0 and pi
    ext = exact_hb.series_extrema(a, Nab, N)
    assert np.allclose(np.sort(np.mod(ext + 1e-9, 2 * np.pi)) - 1e-9, [0.0, math.pi], atol=1e-12)


def test_the_kept_parts_keep_no_table_alive_and_large_ones_are_not_kept(monkeypatch):
    """The parts hold their table by weak reference (run_tables drops a large table: it must go), and parts
    above LOAD_PARTS_ENTRY_BYTES are worked out at each call (still the same bits)."""
    import gc
    import weakref

    from reduced.transient import exact_tables

    loads = Loads(LOAD[None, :], (Harmonic(1.0, 20.0),))
    table = state_table(SYSTEM)
    forced_table(SYSTEM, table, loads)
    gone = weakref.ref(table)
    del table
    gc.collect()
    assert gone() is None
    monkeypatch.setattr(exact_tables, "LOAD_PARTS_ENTRY_BYTES", 0)
    exact_tables._LOAD_PARTS.clear()
    table = state_table(SYSTEM)
    ft = forced_table(SYSTEM, table, loads)
    assert len(exact_tables._LOAD_PARTS) == 0
    Y, U, Sb = _forced_table_before(SYSTEM, table, loads)
    assert _same(ft.Y, Y) and _same(ft.U, U) and _same(ft.Sb, Sb)
