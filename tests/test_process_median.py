"""benchmarks/process_median.py: headline rows measured in several processes, reported by the median process
(issue 28: a process of this machine runs at one of two speeds, so a row timed in one process draws one)."""

import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("process_median", ROOT / "benchmarks" / "process_median.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _head(what, ours, ratio, target, met):
    return {"what": what, "ours_s": str(ours), "baseline": "b", "baseline_s": str(ours * ratio), "ratio": str(ratio),
            "error": "", "target": target, "met": str(met)}


def _tables():
    """Five processes: a ratio row (target >= 1000x) and a time row (target <= 0.03 s), in slow and fast draws."""
    ratios = [737.0, 1240.0, 1102.0, 690.0, 1350.0]
    times = [0.033, 0.020, 0.021, 0.035, 0.019]
    return [[_head("exact vs DOP853, 0.2 s", 0.004, r, ">= 1000x", r >= 1000),
             _head("exact ringdown, discrete-impulse", t, 10.0, "<= 0.03 s", t <= 0.03)]
            for r, t in zip(ratios, times, strict=True)]


def test_each_row_is_the_median_process_by_its_deciding_number():
    pm = _module()
    probes = ["7.2/7.3", "4.7/4.8", "4.6/7.1", "7.4/7.4", "4.7/4.7"]
    rows, per, chosen = pm.median_rows(_tables(), probes)
    # ratios sorted 690, 737, 1102, 1240, 1350: the median 1102 is process 2's
    assert chosen[0] == 2 and rows[0]["ratio"] == "1102.0" and rows[0]["met"] == "True"
    # times sorted 0.019, 0.020, 0.021, 0.033, 0.035: the median 0.021 is process 2's too, by ours_s
    assert chosen[1] == 2 and rows[1]["ours_s"] == "0.021"
    assert "target met in 3 of 5" in rows[0]["processes"] and "by ratio (process 2)" in rows[0]["processes"]
    assert "by ours_s" in rows[1]["processes"] and "4.6/7.1" in rows[1]["processes"]
    assert len(per) == 10 and sum(r["chosen"] for r in per) == 2
    assert [r["value"] for r in per if r["row"] == 0] == [737.0, 1240.0, 1102.0, 690.0, 1350.0]


def test_a_row_without_a_ratio_target_is_decided_by_its_time():
    pm = _module()
    assert pm.row_key({"target": ">= 3e+07 steps/s in CPU time (<= 0.0333 s)", "ours_s": "0.03", "ratio": "9"}) == (
        "ours_s", 0.03)
    assert pm.row_key({"target": "", "ours_s": "0.1", "ratio": "2"}) == ("ours_s", 0.1)


def test_an_even_count_or_rows_that_differ_are_refused():
    pm = _module()
    tables = _tables()
    with pytest.raises(ValueError, match="odd"):
        pm.median_rows(tables[:4], ["x"] * 4)
    with pytest.raises(ValueError, match="not the same rows"):
        pm.median_rows([tables[0], tables[1], tables[2][:1]], ["x"] * 3)
    swapped = [tables[0], tables[1], tables[2][::-1]]
    with pytest.raises(ValueError, match="row 0 differs"):
        pm.median_rows(swapped, ["x"] * 3)


def test_merge_writes_the_median_rows_the_per_process_rows_and_every_run(tmp_path):
    pm = _module()
    from bearingshaft.output import write_rows

    dirs = []
    for k, rows in enumerate(_tables()[:3]):
        d = tmp_path / f"p{k}"
        d.mkdir()
        write_rows(d / "x_headline.csv", rows)
        write_rows(d / "x_machine.csv", [{"key": "probe_ms_start", "value": 4.7 + k}, {"key": "probe_ms_end",
                                                                                       "value": 7.0}])
        write_rows(d / "x_runs.csv", [{"level": 1, "cpu_s": 0.1 * k}, {"level": 10, "cpu_s": 1.0 + k}])
        dirs.append(d)
    chosen = pm.merge(dirs, "x", tmp_path, concat=("x_runs.csv",))
    assert chosen == [2, 2]  # ratios 737, 1240, 1102; times 0.033, 0.020, 0.021
    with open(tmp_path / "x_headline.csv") as f:
        head = list(csv.DictReader(f))
    assert [h["ratio"] for h in head] == ["1102.0", "10.0"] and list(head[0])[-1] == "processes"
    with open(tmp_path / "x_runs.csv") as f:
        runs = list(csv.DictReader(f))
    assert [r["process"] for r in runs] == ["0", "0", "1", "1", "2", "2"] and runs[5]["cpu_s"] == "3.0"
    with open(tmp_path / "x_machine.csv") as f:
        machine = {r["key"]: r["value"] for r in csv.DictReader(f)}
    assert machine["processes"] == "3" and machine["process1_probe_ms_start"] == "5.7"


def test_job_times_takes_the_run_of_the_median_wall_and_names_every_run():
    spec = importlib.util.spec_from_file_location("job_times", ROOT / "benchmarks" / "job_times.py")
    jt = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(jt)
    rows = [{"label": "ours", "wall_s": 377.0, "cpu_s": 745.0},
            {"label": "ours-2", "wall_s": 348.0, "cpu_s": 687.0},
            {"label": "ours-3", "wall_s": 353.0, "cpu_s": 696.0},
            {"label": "baseline", "wall_s": 700.0, "cpu_s": 700.0}]
    mid, text = jt.median_run(rows)
    assert mid["label"] == "ours-3"  # walls 348, 353, 377: the baseline is not one of ours
    assert text == "; the median of 3 runs one after the other (wall s 377, 348, 353; CPU s 745, 687, 696)"
    assert jt.median_run(rows[:1]) == (rows[0], "")
    watched = [dict(r, host_fast=f) for r, f in zip(rows[:3], (0.36, 0.42, 0.54), strict=True)]
    assert jt.median_run(watched)[1].endswith("CPU s 745, 687, 696; host's fast state % 36, 42, 54)")


def test_the_watch_counts_the_fast_samples_below_the_scaled_threshold(tmp_path):
    spec = importlib.util.spec_from_file_location("machine_speed", ROOT / "benchmarks" / "machine_speed.py")
    ms = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ms)
    path = tmp_path / "w.csv"
    # the short probe (a third of the terms): ~1.55 ms fast, ~2.3-2.9 ms slow; the threshold FAST_MS / 3 = 2 ms
    path.write_text("t_s,core,probe_ms\n0.0,0,1.55\n0.01,1,2.43\n2.0,0,1.99\n2.01,1,2.01\n4.0,0,2.9\n")
    assert ms.watched_fast_fraction(path) == (pytest.approx(0.4), 5)
    path.write_text("t_s,core,probe_ms\n")  # terminated before its first sample
    fast, n = ms.watched_fast_fraction(path)
    assert n == 0 and fast != fast
    fast, n = ms.watched_fast_fraction(tmp_path / "none.csv")  # terminated before it wrote its header
    assert n == 0 and fast != fast
