"""``bearingshaft run`` on Dask: the stages of several scenes as the tasks of one graph.

Each stage is a task that runs :func:`bearingshaft.pipeline.run_stage_anywhere` on a worker (the
same code as ``bearingshaft STAGE``, so the files are those of a single run); the graph says what
must come first:

- the stages of one scene run in pipeline order, one at a time (they share its results folder);
- scenes whose reduced model is the same cache entry (:func:`reduced.models.rom.cache_key`) wait
  for the first of them to build it, so it is built once, not once per scene;
- independent chains run side by side, the longest first: a task's priority is the longest path of
  work from it to the end of the graph (list scheduling by "bottom level"), sized by ``STAGE_SECONDS``.

The client does the list scheduling (:func:`list_schedule`): it keeps as many stages in flight as the cluster
has worker threads and, whenever one finishes, submits the ready stage of the highest bottom level. Handing
Dask the whole graph at once with these priorities did not keep that order: tasks submitted first were
dispatched before the later, longer ones were known, and a worker started the task it already held rather
than the more urgent one its last stage had just made ready (``benchmarks/job_schedule.py``: the main job's graph
with each stage a sleep of its main_job.csv time, on LocalCluster(2): 438-443 s, rom-frc's 282 s stage started
at 156-162 s; by the client 402-404 s at 1/20 scale, whose round trips count 20 times; ideal 390 s).

The cluster is the sweep's (:func:`bearingshaft.sweep.run.dask_client`): a
:class:`distributed.LocalCluster` of single-threaded worker processes, as many as the cores and the
memory allow (:func:`default_workers`: the available memory over the largest stage estimate), or a
running scheduler. A failed stage is reported in one line and skips the later stages of its scene;
the others go on.
"""

from __future__ import annotations

import contextlib
import io
import resource
import sys
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

from bearingshaft.scenes import Scene, load_scene
from reduced._checks import one_line

# s, about what each stage takes in the main job (results/performance/main_job.csv, 2 cores): a scheduling hint
# only, so that the longest chains start first; a wrong hint changes the order, not the files
STAGE_SECONDS = {"modal": 8.0, "reduce": 10.0, "ringdown": 6.0, "nnm": 60.0, "study": 20.0, "verify": 9.0,
                 "frc": 100.0, "hammer": 60.0, "frf": 10.0}
# s, the main job's long stages, each by its scene (main_job.csv at 230e773, 486 s wall on 2 cores): their
# pieces run side by side (bearingshaft.fanout), but the longest of them (rom-frc's converged curve at 10 N,
# ~240 s) still sets the job's end, so that chain must start first
SCENE_SECONDS = {"rom-frc/frc": 300.0, "discrete-frc/frc": 120.0, "rom-fep/nnm": 100.0, "hammer-test/hammer": 52.0,
                 "discrete-fep/nnm": 42.0, "discrete-friction-frc/frc": 40.0, "discrete-symmetric/ringdown": 16.0}
BUILD_SECONDS = 40.0  # s, a reduced model built from the 3-D model, added to the stage that builds it


@dataclass(frozen=True, slots=True)
class StageTask:
    """One stage of one scene in the job's graph.

    Parameters
    ----------
    key : str
        ``"<scene>/<stage>"``, unique in the job.
    scene_arg : str
        How a worker finds the scene: a built-in name or an absolute TOML path.
    scene_name : str
        The scene's name.
    stage : str
        The stage.
    out : Path
        The scene's results folder.
    after : tuple of str
        Keys of the tasks that must finish first.
    seconds : float
        s, the scheduling hint of this task alone.
    level : float
        s, its bottom level (:func:`priorities`): the priority of the task and of the pieces it fans out.
    fan_out : bool
        Hand the stage's independent pieces (:mod:`bearingshaft.fanout`) to the cluster as tasks of their own.
    """

    key: str
    scene_arg: str
    scene_name: str
    stage: str
    out: Path
    after: tuple[str, ...] = ()
    seconds: float = 1.0
    level: float = 0.0
    fan_out: bool = False


@dataclass(frozen=True, slots=True)
class StageRun:
    """What a task reports back.

    Parameters
    ----------
    key : str
        The task's key.
    wall_s : float
        s, the stage's wall time on its worker.
    printed : str
        What the stage printed (its summary line).
    error : str
        The failure in one line; empty when the stage succeeded.
    skipped : bool
        Not run: a stage it waited for failed (``error`` names it).
    peak_bytes : int
        The largest resident memory of the worker process and its children so far.
    worker : str
        The worker that ran it.
    """

    key: str
    wall_s: float
    printed: str
    error: str = ""
    skipped: bool = False
    peak_bytes: int = 0
    worker: str = ""


@dataclass(frozen=True, slots=True)
class JobResult:
    """The job: every task's report.

    Parameters
    ----------
    runs : tuple of StageRun
        In the order they finished (the skipped ones too).
    workers : str
        Where they ran (``LocalCluster(2)`` or a scheduler's address).
    wall_s : float
        s, the job's wall time.
    """

    runs: tuple[StageRun, ...]
    workers: str = ""
    wall_s: float = 0.0

    @property
    def failed(self) -> tuple[StageRun, ...]:
        """The stages that failed or were skipped after a failure."""
        return tuple(r for r in self.runs if r.error)

    @property
    def peak_bytes(self) -> int:
        """Bytes, the sum over workers of each one's largest resident memory: a bound on the job's peak."""
        per_worker: dict[str, int] = {}
        for r in self.runs:
            per_worker[r.worker] = max(per_worker.get(r.worker, 0), r.peak_bytes)
        return sum(per_worker.values())


def scene_arg(name_or_path: str) -> str:
    """How a worker process finds a scene given on the command line.

    Parameters
    ----------
    name_or_path : str
        A built-in scene's name or a TOML file path.

    Returns
    -------
    str
        The name, or the file's absolute path (a worker may run in another folder).
    """
    path = Path(name_or_path)
    return str(path.resolve()) if path.suffix == ".toml" or path.exists() else name_or_path


def _reduction_key(scene: Scene) -> str | None:
    if scene.model_kind != "rom":
        return None
    from reduced.models.rom import cache_key

    return cache_key(scene.model)


def stage_seconds(scene_name: str, stage: str) -> float:
    """s, the scheduling hint of one stage: :data:`SCENE_SECONDS` for the main job's long stages, else
    :data:`STAGE_SECONDS` of its kind (10 s for a stage it does not list).

    Parameters
    ----------
    scene_name : str
        The scene's name.
    stage : str
        The stage.

    Returns
    -------
    float
        s.

    Examples
    --------
    >>> stage_seconds("rom-frc", "frc"), stage_seconds("my-scene", "frc"), stage_seconds("x", "new")
    (300.0, 100.0, 10.0)
    """
    return SCENE_SECONDS.get(f"{scene_name}/{stage}", STAGE_SECONDS.get(stage, 10.0))


def job_tasks(runs: list[tuple[str, Scene, Path]], stages_of) -> list[StageTask]:
    """The graph of a job: each scene's stages in a chain; scenes sharing a reduced model after the first.

    Parameters
    ----------
    runs : list of (str, Scene, Path)
        Each scene as given on the command line, read, and its results folder.
    stages_of : callable
        ``stages_of(scene) -> tuple of str``, the stages a scene asks for (:func:`bearingshaft.registry.stages_of`).

    Returns
    -------
    list of StageTask
        In the order given; the first stage of a scene whose reduced model another scene builds
        waits for that scene's first stage, and carries no build cost.
    """
    tasks: list[StageTask] = []
    builder: dict[str, str] = {}  # reduction key -> the key of the task that builds it
    for arg, scene, out in runs:
        previous = None
        red = _reduction_key(scene)
        for i, stage in enumerate(stages_of(scene)):
            key = f"{scene.name}/{stage}"
            after = (previous,) if previous else ()
            seconds = stage_seconds(scene.name, stage)
            if i == 0 and red is not None:
                if red in builder:
                    after = (builder[red],)
                else:
                    builder[red] = key
                    seconds += BUILD_SECONDS
            tasks.append(StageTask(key, scene_arg(arg), scene.name, stage, Path(out), after, seconds))
            previous = key
    return tasks


def priorities(tasks: list[StageTask]) -> dict[str, float]:
    """Each task's bottom level: its own seconds plus the longest path of seconds after it.

    Parameters
    ----------
    tasks : list of StageTask
        The graph (a task's ``after`` keys are earlier in the list).

    Returns
    -------
    dict
        key -> s; Dask runs the ready task of the highest first.

    Examples
    --------
    >>> a = StageTask("a/x", "a", "a", "x", Path("."), (), 1.0)
    >>> b = StageTask("a/y", "a", "a", "y", Path("."), ("a/x",), 5.0)
    >>> c = StageTask("c/x", "c", "c", "x", Path("."), (), 4.0)
    >>> priorities([a, b, c])
    {'c/x': 4.0, 'a/y': 5.0, 'a/x': 6.0}
    """
    level: dict[str, float] = {}
    for t in reversed(tasks):
        level[t.key] = t.seconds + max((level[u.key] for u in tasks if t.key in u.after), default=0.0)
    return level


def _peak_bytes() -> int:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return int(max(own, children) * (1 if sys.platform == "darwin" else 1024))


def run_task(task: StageTask, *after: StageRun) -> StageRun:
    """Run one stage on a worker; never raises (a failure is the report's ``error``).

    Parameters
    ----------
    task : StageTask
        The stage.
    *after : StageRun
        The reports of the tasks it waited for: if one failed, this one is skipped (:func:`list_schedule`
        does not submit such a task at all, and passes none).

    Returns
    -------
    StageRun
    """
    from bearingshaft.fanout import mapping
    from bearingshaft.pipeline import run_stage_anywhere
    from bearingshaft.sweep.run import worker_name

    for r in after:
        if r.error:
            return StageRun(task.key, 0.0, "", f"not run: {r.key} failed", skipped=True, worker=worker_name())
    t0 = time.perf_counter()
    printed = io.StringIO()
    error = ""
    try:
        mapper = _cluster_map(task.level) if task.fan_out and _on_worker() else None
        with contextlib.redirect_stdout(printed), mapping(mapper):
            run_stage_anywhere(load_scene(task.scene_arg), task.stage, task.out, task.scene_arg)
    except MemoryError:
        error = "out of memory (see `bearingshaft check` for the estimates)"
    except Exception as exc:  # reported by the client, in one line
        error = one_line(exc, typed=False)
    return StageRun(task.key, time.perf_counter() - t0, printed.getvalue(), error, peak_bytes=_peak_bytes(),
                    worker=worker_name())


def _on_worker() -> bool:
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return False
    return True


def _cluster_map(level: float):
    """A mapper for :func:`bearingshaft.fanout.fan_out` from a task on a worker: the pieces become tasks of the
    same cluster, just above the priority of the stage that made them (its bottom level, so the pieces of the
    longest chain go first), and among themselves in the order given (a stage lists its longest pieces first);
    the stage's thread leaves the worker's pool while it waits (``worker_client`` secedes and rejoins), so the
    pieces may run on its own worker too."""

    def cluster_map(fn, items):
        from distributed import worker_client

        base = int(round(level)) + 1
        with worker_client() as client:
            futures = [client.submit(fn, item, key=f"fanout-{uuid.uuid4().hex}", pure=False,
                                     priority=base + (len(items) - i) / (len(items) + 1))
                       for i, item in enumerate(items)]
            return client.gather(futures)

    return cluster_map


def list_schedule(client, tasks: list[StageTask], run) -> Iterator[StageRun]:
    """Run a job's graph on ``client``'s cluster by list scheduling on the client.

    As many tasks are in flight as the cluster has worker threads (read again as each one finishes); each
    time one finishes, the ready tasks (every ``after`` key done) are submitted in decreasing bottom level
    (``task.level``, :func:`priorities`; graph order among equals) until the slots are full. A task whose
    predecessor failed or was skipped is not submitted: it is reported skipped, naming that predecessor.

    Parameters
    ----------
    client : distributed.Client
        The cluster's client.
    tasks : list of StageTask
        The graph with each task's level set (a task's ``after`` keys are earlier in the list).
    run : callable
        ``run(task) -> StageRun``, run on a worker (:func:`run_task`).

    Yields
    ------
    StageRun
        Each task's report as it finishes (the skipped ones when their predecessor's failure is known).
    """
    from distributed import as_completed

    waiting = {t.key: t for t in tasks}
    done: dict[str, StageRun] = {}
    running = as_completed()
    in_flight = 0
    while waiting or in_flight:
        ready = [t for t in waiting.values() if all(k in done for k in t.after)]
        n_skipped = 0
        for t in ready:
            failed = next((done[k] for k in t.after if done[k].error), None)
            if failed is not None:
                del waiting[t.key]
                done[t.key] = StageRun(t.key, 0.0, "", f"not run: {failed.key} failed", skipped=True)
                n_skipped += 1
                yield done[t.key]
        ready = sorted((t for t in ready if t.key in waiting), key=lambda t: -t.level)
        slots = max(1, sum(client.nthreads().values()))
        for t in ready[:max(0, slots - in_flight)]:
            del waiting[t.key]
            running.add(client.submit(run, t, key=f"stage-{t.key}", priority=int(round(t.level)), pure=False))
            in_flight += 1
        if not in_flight:
            if waiting and not n_skipped:  # a task waits for a key no task has: a malformed graph
                raise ValueError(f"tasks wait for keys that are not in the job: {sorted(waiting)}")
            continue  # the skipped ones may have made others ready
        r: StageRun = next(running).result()
        in_flight -= 1
        done[r.key] = r
        yield r


def default_workers(scenes: list[Scene], cores: int, available: int) -> int:
    """Workers of the local cluster: one per core, fewer if the largest stages would not fit side by side.

    Parameters
    ----------
    scenes : list of Scene
        The job's scenes.
    cores : int
        The cores this process may use.
    available : int
        Bytes of memory available.

    Returns
    -------
    int
        ``min(cores, available // largest stage estimate)``, at least 1.

    Examples
    --------
    >>> default_workers([], 2, 10**10)
    2
    """
    from bearingshaft.budget import estimates

    largest = max((e.bytes for s in scenes for e in estimates(s)), default=0.0)
    fit = int(available // largest) if largest > 0 else cores
    return max(1, min(cores, fit))


def run_job(runs: list[tuple[str, Scene, Path]], stages_of, *, workers: int | None = None,
            scheduler: str | None = None, progress: bool = True, echo=print, fan_out: bool = False) -> JobResult:
    """Every stage of ``runs`` on Dask, the longest chains first.

    Parameters
    ----------
    runs : list of (str, Scene, Path)
        Each scene as given on the command line, read, and its results folder.
    stages_of : callable
        The stages a scene asks for (:func:`bearingshaft.registry.stages_of`).
    workers : int, optional
        Worker processes of the local cluster (default :func:`default_workers`).
    scheduler : str, optional
        A running Dask scheduler's address instead of a local cluster.
    fan_out : bool
        Let stages hand their independent pieces to the cluster (:mod:`bearingshaft.fanout`). Off by default:
        on 2 cores the stages alone keep both workers busy, and the pieces cost more than they balance (the
        main job 521 s wall, 962 s CPU with them against 462 s and 907 s without, same session, load 0.9-1.6);
        on a cluster with more workers than long stages they let one stage use several.
    progress : bool
        A progress bar over the stages.
    echo : callable
        Prints each stage's line as it finishes (and each failure).

    Returns
    -------
    JobResult
    """
    from bearingshaft.budget import available_bytes
    from bearingshaft.progress import bar
    from bearingshaft.sweep.run import dask_client, local_cores, warm_up

    tasks = job_tasks(runs, stages_of)
    level = priorities(tasks)
    if workers is None and scheduler is None:
        workers = default_workers([s for _, s, _ in runs], local_cores(), available_bytes())
    t0 = time.perf_counter()
    done: list[StageRun] = []
    with dask_client(scheduler, workers) as (client, where):
        client.run(warm_up)
        pbar = bar(total=len(tasks), desc="run", unit="stage", enabled=progress)
        try:
            for r in list_schedule(client, [replace(t, level=level[t.key], fan_out=fan_out) for t in tasks],
                                   run_task):
                done.append(r)
                if r.error:
                    scene, stage = r.key.split("/", 1)
                    echo(f"bearingshaft: [{scene}] {stage}: {'skipped' if r.skipped else 'failed'}: {r.error}")
                elif r.printed:
                    echo(r.printed.rstrip("\n"))
                pbar.update(1)
        finally:
            pbar.close()
    return JobResult(tuple(done), where, time.perf_counter() - t0)


__all__ = ["SCENE_SECONDS", "STAGE_SECONDS", "JobResult", "StageRun", "StageTask", "default_workers", "job_tasks",
           "list_schedule", "priorities", "run_job", "run_task", "scene_arg", "stage_seconds"]
