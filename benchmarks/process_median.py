"""Benchmark rows timed in several processes and reported by the median process (issue 28).

This machine's cores run in two speed states, each core on its own, switching within a second and
sometimes holding one for tens of seconds (benchmarks/machine_speed.py, results/performance/
machine_speed.png: the fast state ~30 % of the time). A loop of ``sin(a) * exp(b)`` calls that
touches no array (:func:`probe_ms`) takes ~4.5 ms in the fast state and ~7 ms in the slow one, and
the same 2 s exact ringdown 18-22 ms or 31-36 ms; a dependent chain of multiplies and adds shows no
such states, so it is not the clock, and nothing else runs in this guest (no steal time either): it
comes from the host. The placement of the data, which session 15 suspected (a fresh copy of the
tables "flipped the mode"), does not explain it: the probe holds no data and switches too. A row timed in
one process, over a few seconds, draws one state. This module runs the same benchmark in several
child processes, one after the other, and keeps, for every headline row, the row of the process in
the middle of the row's deciding number (its ratio for a ``>= ...x`` target, else its time), so the
table's text and numbers stay those of one real measurement; the per-process numbers and each
process's probe (at its start and end) go beside it.

The pieces: :func:`probe_ms` (the speed probe), :func:`run_children` (the children, one at a time,
so that they do not share the cores), :func:`row_key` and :func:`median_rows` (the choice).
"""

from __future__ import annotations

import contextlib
import csv
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba as nb


@nb.njit(cache=True)
def _probe_loop(n):
    s = 0.0
    for i in range(n):
        s += math.sin(i * 1e-3) * math.exp(-i * 1e-9)
    return s


def fastest_ms(fn, n: int, repeats: int) -> float:
    """The fastest of ``repeats`` CPU times (ms) of ``fn(n)``, after one warm-up call ``fn(10)``.

    Parameters
    ----------
    fn : callable
        A compiled kernel of one integer.
    n : int
        Its argument in the timed calls.
    repeats : int
        Timed calls.

    Returns
    -------
    float
    """
    fn(10)
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        fn(n)
        best = min(best, time.process_time() - t0)
    return best * 1e3


def probe_ms(n: int = 300_000, repeats: int = 9) -> float:
    """The speed probe: :func:`fastest_ms` of sum_i sin(i 1e-3) exp(-1e-9 i), i < n, a compiled loop of libm
    calls that touches no array (~4.5 ms in this machine's fast state, ~7 ms in its slow one).

    Parameters
    ----------
    n : int
        Terms of the sum.
    repeats : int
        Timed calls after one warm-up.

    Returns
    -------
    float
        Milliseconds of CPU time.
    """
    return fastest_ms(_probe_loop, n, repeats)


def run_children(argv: list[str], n: int, out: Path) -> list[Path]:
    """Run ``python argv... --out out/p<k>`` for k < n, one after the other; the folders they wrote.

    Parameters
    ----------
    argv : list of str
        The benchmark script and its options (without ``--out``).
    n : int
        Child processes.
    out : Path
        Parent folder of the children's folders.

    Returns
    -------
    list of Path

    Raises
    ------
    RuntimeError
        A child that exits with a non-zero status (its command named).
    """
    dirs = []
    for k in range(n):
        d = out / f"p{k}"
        cmd = [sys.executable, *argv, "--out", str(d)]
        print(f"process {k + 1} of {n}: {' '.join(cmd)}", flush=True)
        if subprocess.run(cmd).returncode != 0:
            raise RuntimeError(f"child {k} failed: {' '.join(cmd)}")
        dirs.append(d)
    return dirs


@contextlib.contextmanager
def children(script: str, argv: list[str], n: int):
    """Run ``python script argv... --processes 1 --out <tmp>/p<k>`` for k < n (:func:`run_children`), in a
    temporary folder removed afterwards; ``--out`` and ``--processes`` are taken out of ``argv`` first; yields
    the children's folders.

    Parameters
    ----------
    script : str
        The benchmark script.
    argv : list of str
        Its command-line options as given.
    n : int
        Child processes.

    Yields
    ------
    list of Path
    """
    keep = [a for i, a in enumerate(argv) if not (a.startswith(("--out", "--processes"))
            or (i > 0 and argv[i - 1] in ("--out", "--processes")))]
    with tempfile.TemporaryDirectory(prefix=f"{Path(script).stem}_") as tmp:
        yield run_children([script, *keep, "--processes", "1"], n, Path(tmp))


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def row_key(row: dict) -> tuple[str, float]:
    """(name, value) of the number that decides a headline row: its ratio for a target ``>= ...x``,
    else its time ``ours_s`` (a time target, a steps-per-second target in CPU time, or no target).

    Parameters
    ----------
    row : dict
        A headline row (what, ours_s, baseline, baseline_s, ratio, error, target, met).

    Returns
    -------
    tuple of (str, float)

    >>> row_key({"target": ">= 1000x", "ratio": "1240", "ours_s": "0.003"})
    ('ratio', 1240.0)
    >>> row_key({"target": "<= 0.03 s", "ratio": "11", "ours_s": "0.02"})
    ('ours_s', 0.02)
    """
    target = (row.get("target") or "").strip()
    if target.startswith(">=") and target.endswith("x"):
        return "ratio", _num(row.get("ratio"))
    return "ours_s", _num(row.get("ours_s"))


def median_rows(tables: list[list[dict]], probes: list[str]) -> tuple[list[dict], list[dict], list[int]]:
    """For each headline row, the row of the process in the middle of its deciding number
    (:func:`row_key`), with a ``processes`` column saying so; the per-process rows; and the
    chosen process of each row.

    Parameters
    ----------
    tables : list of list of dict
        Each process's headline rows, in the same order (an odd number of processes).
    probes : list of str
        Each process's speed probe, as text (:func:`probe_ms` at its start and end).

    Returns
    -------
    tuple of (list of dict, list of dict, list of int)

    Raises
    ------
    ValueError
        An even number of processes, or tables whose rows differ in number or kind.
    """
    n = len(tables)
    if n % 2 == 0:
        raise ValueError(f"processes: {n} (an odd number, so that one process is the median)")
    if len({len(t) for t in tables}) != 1:
        raise ValueError(f"processes wrote {[len(t) for t in tables]} headline rows: not the same rows")
    rows, per, chosen = [], [], []
    for i, group in enumerate(zip(*tables, strict=True)):
        heads = {r["what"].split(",")[0] + (r.get("target") or "") for r in group}
        if len(heads) != 1:
            raise ValueError(f"row {i} differs between processes: {sorted(heads)}")
        name, _ = row_key(group[0])
        vals = [row_key(r)[1] for r in group]
        order = sorted(range(n), key=lambda k: (math.isnan(vals[k]), vals[k]))
        k_mid = order[n // 2]
        met = [r.get("met") for r in group]
        n_met = sum(m in (True, "True") for m in met)
        has_target = any(m not in ("", None) for m in met)
        text = (f"the median of {n} processes by {name} (process {k_mid}); per process {name}: "
                + ", ".join(f"{v:.4g}" for v in vals)
                + (f"; target met in {n_met} of {n}" if has_target else "")
                + f"; speed probe per process (ms, start/end): {'; '.join(probes)}")
        rows.append({**group[k_mid], "processes": text})
        chosen.append(k_mid)
        for k, r in enumerate(group):
            per.append({"row": i, "process": k, "what": r["what"].split(",")[0], "key": name, "value": vals[k],
                        "ours_s": r.get("ours_s"), "baseline_s": r.get("baseline_s"), "ratio": r.get("ratio"),
                        "met": r.get("met"), "probe_ms": probes[k], "chosen": k == k_mid})
    return rows, per, chosen


def read_csv(path: Path) -> list[dict]:
    """The rows of a CSV file ([] when it does not exist).

    Parameters
    ----------
    path : Path

    Returns
    -------
    list of dict
    """
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def probe_text(machine: list[dict]) -> str:
    """A process's probes as ``start/end`` text, from its machine rows (keys probe_ms_start, probe_ms_end; with a
    prefix, e.g. ``explicit_``, the last such key).

    Parameters
    ----------
    machine : list of dict
        Rows with ``key`` and ``value``.

    Returns
    -------
    str

    >>> probe_text([{"key": "probe_ms_start", "value": "4.71"}, {"key": "probe_ms_end", "value": "7.2"}])
    '4.7/7.2'
    """
    kv = {key: _num(r["value"]) for r in machine for key in ("probe_ms_start", "probe_ms_end")
          if r["key"].endswith(key)}
    return f"{kv.get('probe_ms_start', math.nan):.1f}/{kv.get('probe_ms_end', math.nan):.1f}"


def merge(dirs: list[Path], stem: str, out: Path, concat: tuple[str, ...] = ()) -> list[int]:
    """The tables of ``out`` from the children's folders ``dirs``: ``<stem>_headline.csv`` each row that of the
    median process (:func:`median_rows`), ``<stem>_processes.csv`` the per-process rows, each file of ``concat``
    every process's rows with a ``process`` column, and ``<stem>_machine.csv`` this machine's rows with each
    child's speed probes and final load (keys ``process<k>_...``).

    Parameters
    ----------
    dirs : list of Path
        The children's folders, as :func:`run_children` returns them.
    stem : str
        The benchmark's file prefix (``integrator``, ``converged_curve``).
    out : Path
        The folder written.
    concat : tuple of str
        Other CSV files of the children, concatenated.

    Returns
    -------
    list of int
        The process chosen for each headline row.
    """
    from bearingshaft.output import machine_rows, write_rows

    machines = [read_csv(d / f"{stem}_machine.csv") for d in dirs]
    heads, per, chosen = median_rows([read_csv(d / f"{stem}_headline.csv") for d in dirs],
                                     [probe_text(m) for m in machines])
    write_rows(out / f"{stem}_headline.csv", heads, [*[c for c in heads[0] if c != "processes"], "processes"])
    write_rows(out / f"{stem}_processes.csv", per)
    for name in concat:
        rows = [{"process": k, **r} for k, d in enumerate(dirs) for r in read_csv(d / name)]
        write_rows(out / name, rows, list(dict.fromkeys(c for r in rows for c in r)))
    keys = ("probe_ms_start", "probe_ms_end", "load_1min_end", "load_1min_start", "date_utc", "git_commit")
    info = machine_rows(processes=len(dirs))
    info += [{"key": f"process{k}_{r['key']}", "value": r["value"]} for k, m in enumerate(machines) for r in m
             if r["key"].endswith(keys)]
    write_rows(out / f"{stem}_machine.csv", info)
    return chosen
