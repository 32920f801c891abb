"""A friction state entered for an instant passed through without its tables (issue 27's speed, cold).

:func:`reduced.transient.friction_probe.pass_through` follows the flow of a state by its Taylor series over a
short reach and finds its first event there. Checked against the matrix exponential of the state's affine
flow (an independent method: SciPy's expm, not the eigendecomposition of the tables nor the series): the
event's time, the state there and the viscous and friction work to round-off; and, in runs of the discrete
friction model (pass-through switched on for its 4 coordinates), against the same runs without it: the same
events, times and states to round-off until the motion's own sensitivity grows the difference, the energy
balance at round-off, fewer states built, and the same bits whatever states earlier runs built.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteFrictionParams
from reduced.transient import friction as friction_module
from reduced.transient.friction import clear_tables, friction_tables, integrate_exact_friction
from reduced.transient.friction_probe import REACH_OMEGA_TAU, pass_through
from reduced.transient.friction_tables import _state_parts, friction_table

V0 = [0.1, 0.5, 0.1001, 0.1]  # a blow on the discrete model whose tips close a few us apart: states passed through


def _affine(system, table, s):
    """[[A_s, b_s], [0, 0]] of state s, from the state's matrices (friction_tables._state_parts)."""
    n, p = system.n, system.p
    st = table.states
    Ks, Fs, G, R, _, _ = _state_parts(system, st.closed[s], st.slip[s], st.stop_of[s])
    Minv = np.linalg.inv(system.M)
    N = 2 * n + p
    A = np.zeros((N + 1, N + 1))
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -Minv @ Ks
    A[n:2 * n, n:2 * n] = -Minv @ system.C
    A[n:2 * n, 2 * n:N] = Minv @ G
    A[2 * n:N, n:2 * n] = R
    A[n:2 * n, N] = Minv @ Fs
    return A


def _probe_setup():
    """(system, its friction table of every state, M^-1, the probe's reach in s) of the discrete friction model."""
    system = DiscreteFrictionParams().system()
    om = system.omega_max()
    return system, friction_table(system, om), np.linalg.inv(system.M), REACH_OMEGA_TAU / om


def test_the_first_event_and_the_works_equal_the_matrix_exponentials():
    with single_thread_blas():  # SciPy's expm of an 11 x 11 matrix: 23 ms on a busy machine's threads, 0.1 ms on one
        _first_events_against_expm()


def _first_events_against_expm():
    # From points of a run just before its events (the state there by expm from the event before), the probe
    # finds the run's next event: the same slot, its time and the state there as expm's to round-off, and the
    # works as the quadrature of the powers along expm's motion.
    system, table, Minv, reach = _probe_setup()
    n = system.n
    nodes, weights = np.polynomial.legendre.leggauss(8)  # to ~1e-12 here (omega_max tau <= 1: the powers' terms
    # e^{2 i omega t} are polynomials of degree ~10 to round-off on the interval)
    kinds: dict = {}
    clear_tables()
    events = [integrate_exact_friction(system, np.zeros(4), v0, T, 20000.0, log_events=10_000).events
              for v0, T in ((V0, 0.02), ([0.0, 0.0, 0.3, 0.2], 0.3))]  # the second for a slip's end (rare here)
    for ev, i in ((log, i) for log in events for i in range(len(log) - 1)):
        s, y0, gap = int(ev.state[i]), ev.y[i], ev.t[i + 1] - ev.t[i]
        if gap < 1e-9 or kinds.get(str(ev.kind[i + 1]), 0) >= 3:
            continue
        lead = min(0.5 * reach, 0.5 * gap)  # start this long before the next event
        A = _affine(system, table, s)
        z = expm(A * (gap - lead)) @ np.append(y0, 1.0)
        res = pass_through(system, table, Minv, s, z[:-1], reach, -1, -1, 1e-15)
        if res is None:
            continue
        assert res.slot == ev.slot[i + 1]
        assert res.tau == pytest.approx(lead, rel=1e-8, abs=1e-15)
        y_ev = (expm(A * res.tau) @ z)[:-1]
        scale = np.abs(y_ev) + np.max(np.abs(y_ev[:n]))
        assert np.all(np.abs(res.y - y_ev) <= 1e-10 * scale)
        q = table.erow[s, res.slot] @ res.y + table.ec[s, res.slot]
        assert abs(q) <= 1e-12 * (np.abs(table.erow[s, res.slot]) @ np.abs(res.y) + abs(table.ec[s, res.slot]))

        st = table.states
        _, _, _, R, _, smks = _state_parts(system, st.closed[s], st.slip[s], st.stop_of[s])
        dW = dWf = 0.0
        for t_, w_ in zip(0.5 * res.tau * (nodes + 1.0), 0.5 * res.tau * weights, strict=True):
            y = (expm(A * t_) @ z)[:-1]
            dW += w_ * (y[n:2 * n] @ system.C @ y[n:2 * n])
            for k in np.flatnonzero(smks):
                j = st.stop_of[s, k]
                dWf += w_ * smks[k] * (system.B[j] @ y[:n] - system.offset[j]) * (R[k] @ y[n:2 * n])
        assert res.dW == pytest.approx(dW, rel=1e-9, abs=1e-18)
        assert res.dWf == pytest.approx(dWf, rel=1e-9, abs=1e-18)
        kinds[str(ev.kind[i + 1])] = kinds.get(str(ev.kind[i + 1]), 0) + 1
    assert set(kinds) == {"gap", "stick", "slip+", "slip-"}, kinds  # every kind of event met by the probe


def _run(duration_s, **kw):
    system = DiscreteFrictionParams().system()
    return integrate_exact_friction(system, np.zeros(4), V0, duration_s, 20000.0, log_events=10_000, **kw)


def test_runs_with_states_passed_through_equal_those_without_to_round_off(monkeypatch):
    # 12 ms of the blow: the same events (slots, states), at the same times and states to round-off (the motion
    # is sensitive: a round-off difference grows ~10x every 3 ms, so the run is short, and the times are compared
    # within a band that grows so, 1e-15 s x 10^(t / 3 ms) (the states 1e-12 x theirs): 2e-16 s differences at
    # 2 ms grew to 3e-14 at 8.6 ms),
    # energy balance at round-off, states passed through and fewer built.
    monkeypatch.setattr(friction_module, "PASS_THROUGH_MIN_N", 0)
    out = {}
    for flag in (False, True):
        monkeypatch.setattr(friction_module, "PASS_THROUGH", flag)
        clear_tables()
        out[flag] = _run(0.012)
    a, b = out[False], out[True]
    assert a.stats["n_passed"] == 0 < b.stats["n_passed"]
    assert b.stats["n_states_built"] < a.stats["n_states_built"]
    ea, eb = a.events, b.events
    assert len(ea) == len(eb) > 20
    np.testing.assert_array_equal(ea.slot, eb.slot)
    np.testing.assert_array_equal(ea.state, eb.state)
    assert np.all(np.abs(eb.t - ea.t) <= 1e-15 * 10.0 ** (ea.t / 3e-3))
    scale = np.max(np.abs(ea.y), axis=0) + np.max(np.abs(ea.y[:, :4]))
    assert np.all(np.abs(eb.y - ea.y) <= 1e-12 * 10.0 ** (ea.t / 3e-3)[:, None] * scale)
    assert np.all(np.abs(b.x - a.x) <= 1e-12 * 10.0 ** (a.t / 3e-3)[:, None] * np.max(np.abs(a.x)))
    assert a.energy_balance_error < 1e-11 and b.energy_balance_error < 1e-11


def test_which_states_pass_depends_on_the_run_alone(monkeypatch):
    # The same run on fresh tables and on tables with every state built: the same bits (a state is passed
    # through or run by its closed form on this run's own entries, not on what earlier runs built).
    monkeypatch.setattr(friction_module, "PASS_THROUGH_MIN_N", 0)
    clear_tables()
    first = _run(0.03)
    system = DiscreteFrictionParams().system()
    tables, reused = friction_tables(system.fold_zero_gap_tips(), system.omega_max())
    assert reused
    for s in range(tables.S):
        tables.ensure(s)
    again = _run(0.03)
    assert first.stats["n_passed"] == again.stats["n_passed"] > 0
    for f in ("x", "v", "w", "friction", "dissipated"):
        np.testing.assert_array_equal(getattr(again, f), getattr(first, f), err_msg=f)
    np.testing.assert_array_equal(again.events.t, first.events.t)


def test_a_zero_start_is_passed_to_the_first_event_of_expm():
    with single_thread_blas():
        _zero_starts_against_expm()


def _zero_starts_against_expm():
    # From the state just after each closing of a run (the closed stop's gap function and its sliders' cone
    # functions at 0: a zero start), the probe finds the run's next event: its slot, its time and the state there
    # as expm's (an independent method) to round-off, and along expm's motion on a fine grid every active event
    # function stays below 0 until then (no event missed behind the start). Some zero starts must pass.
    system, table, Minv, reach = _probe_setup()
    clear_tables()
    ev = integrate_exact_friction(system, np.zeros(4), V0, 0.03, 20000.0, log_events=10_000).events
    passed = 0
    for i in range(len(ev) - 1):
        s, y0, gap = int(ev.state[i]), ev.y[i], ev.t[i + 1] - ev.t[i]
        if ev.kind[i] != "gap" or not table.reset[int(ev.state[i - 1]) if i else 0, ev.slot[i]]:
            continue  # not a closing
        q0 = table.erow[s] @ y0 + table.ec[s]
        zero = table.eact[s] & (np.abs(q0) <= 1e-9 * (np.abs(table.erow[s]) @ np.abs(y0) + np.abs(table.ec[s])))
        assert np.count_nonzero(zero) >= 1  # the closed stop's slot at least
        res = pass_through(system, table, Minv, s, y0, reach, -1, -1, 1e-15)
        if res is None:
            continue
        assert res.slot == ev.slot[i + 1]
        assert res.tau == pytest.approx(gap, rel=1e-8, abs=1e-15)
        A = _affine(system, table, s)
        z0 = np.append(y0, 1.0)
        y_ev = (expm(A * res.tau) @ z0)[:-1]
        scale = np.abs(y_ev) + np.max(np.abs(y_ev[:system.n]))
        assert np.all(np.abs(res.y - y_ev) <= 1e-10 * scale)
        for u in np.linspace(0.0, res.tau, 101)[1:-1]:
            y = (expm(A * u) @ z0)[:-1]
            q = table.erow[s] @ y + table.ec[s]
            assert np.all(q[table.eact[s]] < 0.0), (i, u)
        passed += 1
    assert passed >= 2
