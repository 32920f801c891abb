"""The run of a sweep on Dask: a cluster, one task per case, resumption and failures as rows.

Cases run on a :class:`distributed.LocalCluster` with one single-threaded worker process per
core (or ``workers``), started and closed here, or on the scheduler at an address. Each case
(:func:`run_case`) runs its scene's stages through :func:`bearingshaft.pipeline.run_stage`,
the code of a single run, into ``<out>/<case id>/`` and returns its row of metrics
(:func:`bearingshaft.sweep.metrics.case_metrics`) with its run time and worker. A case whose
folder is complete is not run again (:func:`case_complete`); a failing case is a row with its
one-line message; a worker lost mid-case has its task rerun by Dask, and a folder is written
whole or not at all. A reduced model is built once before the cases, scattered to the workers
once and put into each worker's reduced-model cache.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import logging
import math
import os
import time
from pathlib import Path

import numpy as np

from bearingshaft.progress import bar as progress_bar
from bearingshaft.scenes import Scene, SweepError, parse_scene
from bearingshaft.sweep.metrics import case_metrics, sweep_overlay
from bearingshaft.sweep.plan import Case, SweepPlan
from bearingshaft.sweep.tables import SweepResult, write_results
from reduced._checks import one_line

_INSTALLED: set = set()  # reductions this worker process has put into its reduced-model cache


# -- one case, on a worker ------------------------------------------------------------------
def warm_up() -> None:
    """Import the stages and load numba's compiled kernels in a worker before its first case, so
    that a case's run time is the case's (the sweep's wall time still counts this, once per worker)."""
    import bearingshaft.pipeline  # noqa: F401
    import bearingshaft.plots  # noqa: F401
    from bearingshaft.systems import model_system  # noqa: F401
    from reduced.models.discrete import DiscreteParams
    from reduced.transient.integrate import ringdown

    ringdown(DiscreteParams().system(), np.zeros(3), np.array([0.0, 0.0, 1.0]), 1e-3, 1e4, "exact")


def worker_name() -> str:
    """The address of the Dask worker running the caller, else ``local:<pid>``."""
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"local:{os.getpid()}"


def case_complete(folder: Path, case: Case) -> bool:
    """Whether ``folder`` holds a finished run of ``case``.

    Parameters
    ----------
    folder : the case's folder
    case : the case

    Returns
    -------
    True when its scene.toml is the case's and its provenance.json (written last, in the same
    atomic swap as the files) lists every stage.
    """
    return not _missing_stages(folder, case)


def _missing_stages(folder: Path, case: Case) -> tuple[str, ...]:
    try:
        if (folder / "scene.toml").read_text(encoding="utf-8") != case.text:
            return case.stages
        done = json.loads((folder / "provenance.json").read_text(encoding="utf-8")).get("stages", {})
    except (OSError, ValueError, AttributeError):
        return case.stages
    return tuple(s for s in case.stages if s not in done)


def _run_stage(scene: Scene, case: Case, stage: str, folder: Path) -> None:
    """One stage of a case, as a single run (:func:`bearingshaft.pipeline.run_stage_anywhere`; a
    stage that meshes runs in a child process that reads the case from a temporary file)."""
    import tempfile

    from bearingshaft.pipeline import run_stage_anywhere

    with tempfile.TemporaryDirectory(prefix="bearingshaft-case-") as tmp:
        path = Path(tmp) / f"{case.name}.toml"
        path.write_text(case.text, encoding="utf-8")
        run_stage_anywhere(scene, stage, folder, str(path))


def run_case(case: Case, out_root: str, rom=None) -> dict:
    """Run (or find finished) one case into ``out_root/<case id>/``; runs on a worker.

    Parameters
    ----------
    case : the case
    out_root : the sweep's folder
    rom : the reduced model the case needs (scattered once; put into this worker's cache on first use)

    Returns
    -------
    The case's row: ``case_id``, its values, its metrics, ``status`` ("ok" or "failed"), ``resumed``,
    ``message`` (a failure in one line: a case never ends the sweep), ``run_time_s`` and ``worker``.
    """
    t0 = time.perf_counter()
    folder = Path(out_root) / case.case_id
    row = {"case_id": case.case_id, **dict(case.values)}
    try:
        scene = parse_scene(case.text, case.name, case.origin)
        if rom is not None and case.shared_key not in _INSTALLED:
            from reduced.models.rom import store_in_cache

            store_in_cache(rom, scene.model)
            _INSTALLED.add(case.shared_key)
        missing = _missing_stages(folder, case)
        resumed = not missing
        with contextlib.redirect_stdout(io.StringIO()):  # the stages' summary lines: not on the worker's stdout
            for stage in missing:
                _run_stage(scene, case, stage, folder)
        row.update(case_metrics(scene, folder))
        row.update(status="ok", resumed=resumed, message="")
    except Exception as exc:  # a failed case is a row of the table, not the end of the sweep
        row.update(status="failed", resumed=False, message=one_line(exc))
    row.update(run_time_s=time.perf_counter() - t0, worker=worker_name())
    return row


# -- the cluster -------------------------------------------------------------------------------
def local_cores() -> int:
    """The cores this process may run on.

    Returns
    -------
    The size of its CPU affinity set, else the machine's core count (the default number of workers).
    """
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


# Dask's own monitoring, slowed or off on the local cluster (none of it changes what a task computes): every
# worker's statistical profiler walks the running task's stack every 10 ms (for the dashboard's profile page),
# each server samples CPU and memory every 500 ms, every nanny and worker polls its memory every 100 ms and each
# event loop ticks every 20 ms. On 2 cores under the main job these cost CPU the stages then lack
# (benchmarks/dask_overhead.py, 2 cores at load 6-10: the process tree of LocalCluster(2) idle for 40 s used 6.0-6.4 s
# of CPU with Dask's defaults against 2.7-3.2 s with these, start and close included; with a task of a deep Python
# stack on each worker, 34.7 and 38.4 s against 29.0 and 32.2 s for the same work; `bearingshaft run
# discrete-impulse rom-impulse discrete-symmetric hammer-test`, 140.0 and 150.4 s against 128.7 and 126.9 s, the
# same files). The memory is still watched twice a second (a worker past 95 % of its limit is restarted);
# `bearingshaft check` sizes the job before it starts.
QUIET_CLUSTER = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.system-monitor.interval": "2s",
                 "distributed.worker.memory.monitor-interval": "500ms",
                 "distributed.admin.tick.interval": "500ms"}


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A Dask client for the sweep, closed (with its LocalCluster) on exit.

    Parameters
    ----------
    scheduler : address of a running scheduler; the wait for it is Dask's own
        ``distributed.comm.timeouts.connect`` (30 s unless set, e.g.
        ``DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=2min`` for a scheduler still starting)
    workers : without ``scheduler``, single-threaded worker processes of a LocalCluster (default: one per core),
        started with Dask's monitoring slowed (:data:`QUIET_CLUSTER`)

    Returns
    -------
    A context manager of (client, description of where the cases run).
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=dask.config.get("distributed.comm.timeouts.connect"))
        except (OSError, TimeoutError) as exc:
            raise SweepError(f"--scheduler {scheduler!r}: cannot connect ({one_line(exc)})") from None
        try:
            yield client, scheduler
        finally:
            client.close()
        return
    n = workers or local_cores()
    # read as the scheduler, nannies and workers start, and as a nanny restarts a worker that died: so set for the
    # cluster's life (in this process, which runs the scheduler and the nannies)
    with dask.config.set(QUIET_CLUSTER):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR)
        client = Client(cluster)
        try:
            yield client, f"LocalCluster({n})"
        finally:
            client.close()
            cluster.close()


# -- the sweep ---------------------------------------------------------------------------------
def _previous_rows(out: Path) -> dict[str, dict]:
    """Rows of an earlier run of the sweep in ``out`` (for the run time and worker of resumed cases)."""
    path = out / "sweep.parquet"
    if not path.exists():
        return {}
    try:
        import pyarrow.parquet as pq

        return {r["case_id"]: r for r in pq.read_table(path).to_pylist()}
    except Exception:  # an unreadable old table only loses the old run times
        return {}


def _remove_dead_scratch(out: Path, cases) -> None:
    """Scratch folders (``.<case>.<stage>.partial-<pid>-*``) of killed workers' attempts, where that
    process is gone (bearingshaft.output removes them at the next commit into the same folder;
    a case whose retry found it complete makes no such commit)."""
    import shutil

    for case in cases:
        for p in out.glob(f".{case.case_id}.*.partial-*"):
            try:
                pid = int(p.name.split(".partial-")[1].split("-")[0])
                os.kill(pid, 0)
            except ProcessLookupError:
                shutil.rmtree(p, ignore_errors=True)
            except (ValueError, IndexError, PermissionError):
                continue


def _submit(client, plan: SweepPlan, out: Path, progress: bool) -> dict:
    """{future: case}: the workers warmed up, each shared reduced model built here and scattered
    to every worker once, one task per case."""
    client.run(warm_up)
    roms = {}
    for key, spec in plan.shared.items():  # built once here, shipped to each worker once
        print(f"[{plan.scene.name}] sweep: reduced model built once for the sweep ({spec.n_modes} modes)",
              flush=True)
        roms[key] = client.scatter(spec.reduced(progress), broadcast=True, hash=False)
    tag = f"{os.getpid()}-{time.time_ns()}"
    return {client.submit(run_case, case, str(out.absolute()), roms.get(case.shared_key),
                          key=f"bearingshaft-case-{case.case_id}-{tag}", pure=False): case
            for case in plan.cases}


def _lost_row(case: Case, exc: BaseException) -> dict:
    """The row of a case whose task never returned (its worker lost too often, or the task cancelled)."""
    return {"case_id": case.case_id, **dict(case.values), "status": "failed", "resumed": False,
            "message": f"worker lost: {one_line(exc)}", "run_time_s": math.nan, "worker": ""}


def _collect(client, plan: SweepPlan, futures: dict, previous: dict, progress: bool) -> dict[str, dict]:
    """{case id: row} as the tasks finish, a bar of cases done and failed; on an interruption the
    tasks left are cancelled and the rows done are kept."""
    from distributed import as_completed
    rows: dict[str, dict] = {}
    bar = progress_bar(total=len(plan.cases), desc=f"{plan.scene.name}: sweep", unit="case", enabled=progress,
                       bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}{postfix}]")
    failed = 0
    try:
        for fut in as_completed(futures):
            case = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # the worker was lost too often (KilledWorker), or the task cancelled
                row = _lost_row(case, exc)
            if row.get("resumed") and case.case_id in previous:
                old = previous[case.case_id]
                row.update(run_time_s=old.get("run_time_s", math.nan), worker=old.get("worker", ""))
            rows[case.case_id] = row
            failed += row["status"] != "ok"
            bar.update()
            bar.set_postfix_str(f"failed {failed}", refresh=False)
            fut.release()
    finally:
        bar.close()
        if len(rows) < len(plan.cases):  # interrupted: cancel what is left, keep what is done
            client.cancel(list(futures))
    return rows


def run_sweep(plan: SweepPlan, out: str | Path, *, client=None, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, write: bool = True) -> SweepResult:
    """Run every case of ``plan`` on Dask into ``out``.

    Parameters
    ----------
    plan : the sweep (:func:`bearingshaft.sweep.plan.build_plan`)
    out : the sweep's folder (a folder per case, the tables, the figures)
    client : an existing :class:`distributed.Client` (kept open); else ``scheduler`` (an address)
        or a LocalCluster of ``workers`` processes, closed at the end
    scheduler : address of a running scheduler (:func:`dask_client`), without ``client``
    workers : LocalCluster worker processes without ``client`` or ``scheduler`` (default: one per core)
    progress : show a bar of the cases
    write : compute the overlay and write the tables, figures, scene and provenance
        (:func:`bearingshaft.sweep.tables.write_results`)

    Returns
    -------
    :class:`SweepResult`: the rows in design order, the wall time of the cases, where they ran
    and (with ``write``) the overlay.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    previous = _previous_rows(out)
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if client is None:
            client, where = stack.enter_context(dask_client(scheduler, workers))
        else:
            where = str(getattr(client.scheduler, "address", "client"))
        n_workers = len(client.nthreads())
        futures = _submit(client, plan, out, progress)
        rows = _collect(client, plan, futures, previous, progress)
    _remove_dead_scratch(out, plan.cases)
    ordered = [rows[c.case_id] for c in plan.cases if c.case_id in rows]
    result = SweepResult(ordered, out, time.perf_counter() - t0, n_workers, where)
    if write:
        result = dataclasses.replace(result, stability=sweep_overlay(plan, result.rows))
        write_results(plan, result)
    return result
