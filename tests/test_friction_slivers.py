"""A forced stretch no longer than the round-off of its times (reduced.transient.friction._without_slivers): one
instant computed two ways, a blow's end 2 ms + 1 ms = 0.0029999999999999996 s and a piece bound 0.0024 + 0.0006 =
0.003 s, made a 4e-19 s forced run that the forced kernel could not cross (t + tau == t): the run never returned."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np

from reduced.transient.friction import _without_slivers

FORCED = np.array([0.0])  # a forced run's pieces (only None or not matters here)


def test_a_forced_sliver_goes_to_its_neighbour():
    a, b = 0.0029999999999999996, 0.003
    assert b - a > 0.0
    # followed by a free run: the free run starts where the sliver began
    assert _without_slivers([(0.0024, a, FORCED), (a, b, FORCED), (b, 0.0036, None)]) == [
        (0.0024, a, FORCED), (a, 0.0036, None)]
    # the last run: the run before it ends at its end
    runs = _without_slivers([(0.0024, a, None), (a, b, FORCED)])
    assert runs == [(0.0024, b, None)]
    # a run longer than round-off, or a free sliver, or a forced sliver between forced runs, is left alone
    keep = [(0.0024, 0.0025, FORCED), (0.0025, 0.0036, None)]
    assert _without_slivers(keep) == keep
    keep = [(0.0024, a, FORCED), (a, b, None), (b, 0.0036, FORCED)]
    assert _without_slivers(keep) == keep
    keep = [(0.0024, a, FORCED), (a, b, FORCED), (b, 0.0036, FORCED)]
    assert _without_slivers(keep) == keep


def test_the_blow_that_never_returned_now_ends():
    # In a child process with a time limit, so that a regression fails this test instead of hanging the suite. The
    # discrete friction model struck by a 400 N, 1 ms half-sine at 2 ms: the exact run ends, balances its energy
    # at round-off (seen 2e-13) and follows DOP853 restarted at every state change (rtol 1e-12: 4e-8 of max |x|
    # over 0.03 s, seen; bound 1e-6, the DOP853 run's own error over its 30 events).
    code = textwrap.dedent("""
        import numpy as np
        from reduced.models.discrete import DiscreteFrictionParams
        from reduced.models.loads import HalfSine, Loads
        from reduced.transient.integrate import ringdown
        s = DiscreteFrictionParams().system()
        loads = Loads(np.array([[0.0, 1.0, 0.0, 0.3]]), (HalfSine(400.0, 1e-3, 2e-3),), ("blow",))
        x0, v0 = np.zeros(4), np.array([0.0, 0.0, 0.3, 0.2])
        ex = ringdown(s, x0, v0, 0.03, 20000.0, method="exact", loads=loads)
        dp = ringdown(s, x0, v0, 0.03, 20000.0, method="dop853", loads=loads, rtol=1e-12)
        print(ex.energy_balance_error, np.abs(ex.x - dp.x).max() / np.abs(ex.x).max(), ex.stats["n_events"])
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    balance, diff, events = proc.stdout.split()
    assert float(balance) < 1e-10
    assert float(diff) < 1e-6
    assert int(events) > 10  # the blow drives the masses into the stops and the sliders through stick and slip
