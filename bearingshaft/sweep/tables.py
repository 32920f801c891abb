"""The files of a sweep: its rows as ``sweep.parquet`` and ``sweep.csv``, the overlay's
``nnm_stability.csv``, the figures (:mod:`bearingshaft.sweep.report`), ``sweep_provenance.json``
and ``sweep_scene.toml``. Each file is written through a temporary sibling renamed into place.
Nothing here computes: every number comes in the :class:`SweepResult`.
"""

from __future__ import annotations

import csv
import json
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from bearingshaft.output import git_commit, write_rows
from bearingshaft.sweep.metrics import STABILITY_FIELDS, NnmStability
from bearingshaft.sweep.plan import SweepPlan

FIRST = ("case_id",)
LAST = ("status", "resumed", "run_time_s", "worker", "message")


@dataclass(frozen=True, eq=False)
class SweepResult:
    """The rows of a sweep (design order) and where they were written.

    Attributes
    ----------
    rows : list of dict
        One per case run, design order: its values, metrics and ``status``, ``resumed``,
        ``run_time_s``, ``worker``, ``message``.
    out : Path
        The sweep's folder.
    wall_s : float
        s, wall time of the cases.
    workers : int
        Dask workers.
    where : str
        "LocalCluster(n)" or the scheduler's address.
    stability : NnmStability or None
        The NNM stability overlay, when asked for and written.
    """

    rows: list[dict]
    out: Path
    wall_s: float
    workers: int
    where: str  # "LocalCluster(n)" or the scheduler's address
    stability: NnmStability | None = None  # the NNM stability overlay, when asked for and written

    @property
    def n_failed(self) -> int:
        return sum(r.get("status") != "ok" for r in self.rows)

    @property
    def n_resumed(self) -> int:
        return sum(bool(r.get("resumed")) for r in self.rows)


def columns(plan: SweepPlan, rows: list[dict]) -> list[str]:
    """The table's columns: case_id, the varied keys, every metric (in the order first seen), status and the rest.

    Parameters
    ----------
    plan : the sweep (its varied keys)
    rows : the cases' rows

    Returns
    -------
    The column names.
    """
    keys = [v.key for v in plan.spec.vary]
    seen = []
    for r in rows:
        for k in r:
            if k not in seen and k not in FIRST and k not in LAST and k not in keys:
                seen.append(k)
    return [*FIRST, *keys, *seen, *LAST]


def _arrow_table(cols: list[str], rows: list[dict]):
    """A pyarrow table with one type per column: int64, float64 (NaN where a case has no value),
    bool or string."""
    import pyarrow as pa

    arrays = []
    for c in cols:
        vals = [r.get(c) for r in rows]
        present = [v for v in vals if v is not None and not (isinstance(v, float) and math.isnan(v))]
        if present and all(isinstance(v, bool) for v in present):
            arrays.append(pa.array(vals, pa.bool_()))
        elif present and all(isinstance(v, int) and not isinstance(v, bool) for v in present) and \
                len(present) == len(vals):
            arrays.append(pa.array(vals, pa.int64()))
        elif all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
            arrays.append(pa.array([math.nan if v is None else float(v) for v in vals], pa.float64()))
        else:
            arrays.append(pa.array(["" if v is None else str(v) for v in vals], pa.string()))
    return pa.table(arrays, names=cols)


def _replace_file(path: Path, write) -> None:
    """Write ``path`` through a temporary sibling renamed into place (readers never see half a file)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _cell(v):
    """A CSV cell: empty for a missing value or NaN, floats as Python writes them (repr).

    >>> _cell(None), _cell(float("nan")), _cell(0.1), _cell(3), _cell("ok")
    ('', '', '0.1', 3, 'ok')
    """
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return repr(v) if isinstance(v, float) else v


def write_tables(plan: SweepPlan, result: SweepResult) -> list[str]:
    """``sweep.parquet`` and ``sweep.csv`` in ``result.out``: one row per case, one column per key and metric.

    Parameters
    ----------
    plan : the sweep
    result : its rows

    Returns
    -------
    The names written.
    """
    import pyarrow.parquet as pq

    cols = columns(plan, result.rows)
    table = _arrow_table(cols, result.rows)
    _replace_file(result.out / "sweep.parquet", lambda p: pq.write_table(table, p))

    def csv_file(p: Path) -> None:
        with open(p, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for r in table.to_pylist():
                w.writerow([_cell(r[c]) for c in cols])

    _replace_file(result.out / "sweep.csv", csv_file)
    return ["sweep.parquet", "sweep.csv"]


def _provenance(plan: SweepPlan, result: SweepResult, files: list[str]) -> dict:
    """What ``sweep_provenance.json`` records: the design, the counts, the run's time and where it ran."""
    from bearingshaft import __version__

    ok = [r for r in result.rows if r["status"] == "ok"]
    s = plan.spec
    # resumed rows carry the run time of the run that made them (from the earlier sweep.parquet)
    run_time = sum(r["run_time_s"] for r in ok if math.isfinite(r["run_time_s"] or math.nan))
    return {"scene": plan.scene.name, "source": plan.source, "design": s.design,
            "vary": {v.key: v.text for v in s.vary}, "samples": s.samples, "seed": s.seed,
            "cases": len(plan.cases), "ok": len(ok), "failed": result.n_failed, "resumed": result.n_resumed,
            "wall_s": round(result.wall_s, 3), "workers": result.workers, "where": result.where,
            "case_run_time_s_sum": round(run_time, 3),
            "package": "bearingshaft", "version": __version__, "git_commit": git_commit(), "files": files}


def write_results(plan: SweepPlan, result: SweepResult) -> list[str]:
    """Tables, figures, the overlay's table, the sweep's scene and its provenance in ``result.out``.

    Parameters
    ----------
    plan : the sweep
    result : its rows and overlay

    Returns
    -------
    The names written.
    """
    from bearingshaft.sweep.report import write_plots  # matplotlib: only when figures are drawn

    files = write_tables(plan, result)
    files += write_plots(plan, result)
    if result.stability is not None:
        write_rows(result.out / "nnm_stability.csv", result.stability.rows, fields=STABILITY_FIELDS)
        files.append("nnm_stability.csv")
    prov = _provenance(plan, result, files)
    _replace_file(result.out / "sweep_provenance.json",
                  lambda p: p.write_text(json.dumps(prov, indent=2, sort_keys=True) + "\n", encoding="utf-8"))
    _replace_file(result.out / "sweep_scene.toml",
                  lambda p: p.write_text(sweep_scene_text(plan), encoding="utf-8"))
    return [*files, "sweep_provenance.json", "sweep_scene.toml"]


def sweep_scene_text(plan: SweepPlan) -> str:
    """The base scene with the [sweep] table that was run (from the scene or from --vary).

    Parameters
    ----------
    plan : the sweep

    Returns
    -------
    TOML text: ranges as written (LO:HI:N[:log]), lists as their values.
    """
    import tomli_w

    data = tomllib.loads(plan.scene.source)
    s = plan.spec
    table = {"design": s.design, **({"samples": s.samples, "seed": s.seed} if s.design == "random" else {}),
             **({"plots": list(s.plots)} if s.plots else {}), **({"x": s.x} if s.x else {}),
             **({"overlay": s.overlay} if s.overlay else {}),
             "vary": {v.key: v.text if ":" in v.text and not v.text.startswith("[") else list(v.values)
                      for v in s.vary}}
    data["sweep"] = table
    return tomli_w.dumps(data)
