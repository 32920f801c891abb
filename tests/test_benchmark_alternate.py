"""benchmarks/integrator_speed.py's alternate(): the explicit rows' kernels measured in one loop, each warmed once
and then run once a round in turn (issue 28, session 14: two rows of one kernel measured apart differed by 20 %)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _benchmark():
    spec = importlib.util.spec_from_file_location("integrator_speed", ROOT / "benchmarks" / "integrator_speed.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_alternate_warms_each_then_runs_them_in_turn_and_reports_cpu_medians():
    bench = _benchmark()
    calls = []

    def work(name, n):
        def fn():
            calls.append(name)
            return sum(range(n))  # CPU work, so the CPU times order as the work
        return fn

    res, t = bench.alternate({"short": work("short", 10_000), "long": work("long", 2_000_000)}, 3)
    assert calls == ["short", "long"] + ["short", "long"] * 3  # warm-ups, then rounds in turn
    assert res == {"short": sum(range(10_000)), "long": sum(range(2_000_000))}
    for c in ("short", "long"):
        assert t[c]["repeats"] == 3 and t[c]["min_s"] <= t[c]["median_s"] <= t[c]["max_s"]
        assert t[c]["wall_min_s"] <= t[c]["wall_median_s"]
    assert t["long"]["median_s"] > 10 * t["short"]["median_s"]  # CPU time (process_time), the kernels' measure
