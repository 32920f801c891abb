"""The lean entry point of the exact friction flow (reduced.transient.friction.FrictionFlow, issue 27): the runs
of the shooting methods, set up once, against the public ringdown API (integrate_exact_friction) bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from reduced import _checks as _check
from reduced.models.discrete import DiscreteFrictionParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.friction_shooting import flow
from reduced.transient.friction import FrictionFlow, integrate_exact_friction

B = np.array([0.0, 0.0, 1.0, 0.5])  # the discrete-friction-frc scene's slanted load: x3 and half of it along u
P = 20.0  # N: ten times the scene's level, so that the tips close, stick and slip within a few periods


def _states(system, f: float, count: int) -> np.ndarray:
    """(count, 2n + p) states [x; v; w] of a forced run from rest at f Hz, in contact, one every 1/7 period."""
    loads = Loads(np.atleast_2d(B), (Harmonic(P, f, 0.0),))
    r = integrate_exact_friction(system, np.zeros(4), np.zeros(4), 0.4, 7.0 * f, loads=loads)
    y = np.hstack([r.x, r.v, r.w])
    return y[-count:]


def test_the_lean_flow_is_the_public_runs_bits():
    # Every call of the lean flow against integrate_exact_friction (via flow(), the shooting's public form: a
    # fresh stepper, the loads' phase phi + 360 f t0, chunks=1): the same kernels from the same state and tables,
    # so equal to the bit (np.array_equal, no tolerance), over starts in contact, frequencies revisited after
    # more than FORCED_KEPT others (a forced table evicted and rebuilt), one and several samples, and a
    # logged run's events. A wrong reuse between calls (a stale forced table of another frequency, a state's
    # leftover event memory, an unreset work sum) changes bits.
    system = DiscreteFrictionParams(mu=0.3).system()
    ys = _states(system, 17.4, 4)
    lean = FrictionFlow(system, B, P)
    logged = FrictionFlow(system, B, P, log_events=1000)
    freqs = [17.4, 20.5, 17.4, 14.3, 26.9, 31.0, 17.4]  # 17.4 Hz again after four others: evicted, rebuilt
    events = 0
    for f in freqs:
        h = 1.0 / f / 8
        for k, y in enumerate(ys):
            for samples in (1, 5):
                ref = flow(system, B, P, f, y, k * h, h, samples, 30.0)
                assert np.array_equal(lean(f, y, k * h, h, samples, 30.0), ref), (f, k, samples)
            loads = Loads(np.atleast_2d(B), (Harmonic(P, f, 30.0 + 360.0 * f * (k * h)),))
            r = integrate_exact_friction(system, y[:4], y[4:8], h, 1.0 / h, w0=y[8:], loads=loads, chunks=1,
                                         log_events=1000)
            out = logged(f, y, k * h, h, 1, 30.0)
            assert np.array_equal(out, np.hstack([r.x, r.v, r.w]))
            a, b = r.events, logged.events
            assert a.n_total == b.n_total
            for name in ("t", "slot", "kind", "state", "y"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name
            events += a.n_total
    assert events > 40  # the runs cross events (gaps, stick -> slip, slip -> stick): measured 83
    assert lean.calls == len(freqs) * len(ys) * 2


def test_the_lean_flow_refuses_what_the_public_one_does():
    system = DiscreteFrictionParams(mu=0.3).system()
    with pytest.raises(_check.InvalidArgument):
        FrictionFlow(system, [1.0, 0.0], P)  # b of the wrong length
    with pytest.raises(_check.InvalidArgument):
        FrictionFlow(DiscreteFrictionParams(mu=0.0).system(), B, P)  # no friction
    lean = FrictionFlow(system, B, P)
    y = np.zeros(2 * system.n + system.p)
    for _ in range(2):  # the first call (which sets the stepper up) and a later one (which only restarts it)
        with pytest.raises(_check.InvalidArgument):
            lean(17.4, np.full_like(y, np.nan), 0.0, 1e-3)
        with pytest.raises(_check.InvalidArgument):
            lean(17.4, y[:-1], 0.0, 1e-3)
        assert np.array_equal(lean(17.4, y, 0.0, 1e-3)[-1], flow(system, B, P, 17.4, y, 0.0, 1e-3)[-1])


def _initial_states_reference(system, x0: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """reduced.transient.friction._initial_states as it was written first, on numpy arrays throughout: the deepest
    penetrating stop of each tip closed, a slider engaged by a closed stop slipping where |f| > mu k_j pen_j."""
    fr = system.friction
    pen = system.penetration(x0)
    closed = np.zeros(system.m, bool)
    for t_ in np.unique(system.tip):
        j = np.flatnonzero((system.tip == t_) & (pen > 0.0))
        if j.size:
            closed[j[np.argmax(pen[j])]] = True
    slip = np.zeros(fr.p, np.int8)
    f0 = fr.force(x0, w0)
    stop_of = fr.engaged_by(system.tip, closed)
    for q in range(fr.p):
        j = stop_of[q]
        if j >= 0 and abs(f0[q]) > fr.mu[q] * system.k[j] * pen[j]:
            slip[q] = 1 if f0[q] > 0 else -1
    return closed, slip


def test_the_start_states_are_the_reference_decisions():
    # _initial_states (each exact run starts there) against the numpy form it replaced, _initial_states_reference:
    # the same closed stops and slider codes over starts in contact from a forced run and random starts around the
    # gaps (open, either stop of a tip), the sliders inside and past their cone (w moved so that |k_t (t - w)|
    # crosses mu N)
    from reduced.transient.friction import _initial_states

    system = DiscreteFrictionParams(mu=0.3).system()
    n, p = system.n, system.p
    rng = np.random.default_rng(7)
    starts = [(y[:n], y[2 * n:]) for y in _states(system, 17.4, 20)]
    g = float(np.max(np.abs(system.offset)))
    for _ in range(400):
        x = rng.normal(0.0, 1.5 * g, n)
        w = system.friction.Bt @ x + rng.normal(0.0, 1e-6, p) * rng.choice([0.0, 1.0, 100.0])
        starts.append((x, w))
    seen = set()
    for x, w in starts:
        a, b = _initial_states(system, x, w), _initial_states_reference(system, x, w)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        assert a[0].dtype == b[0].dtype and a[1].dtype == b[1].dtype
        seen.add((tuple(a[0]), tuple(a[1])))
    assert len(seen) >= 20  # open, either stop closed, sticking and slipping both ways at both tips: measured 33
