"""How the main job's stages are laid out on the cluster: its graph replayed with each stage a sleep.

    PYTHONPATH=. python benchmarks/job_schedule.py [--scale 20] [--workers 2] [--out /tmp/DIR]

Builds the graph ``bearingshaft run`` builds for every built-in scene (:func:`bearingshaft.jobs.job_tasks`, its
priorities from the hints of :mod:`bearingshaft.jobs`) and runs it on a LocalCluster where each stage sleeps its
wall time in ``results/performance/main_job.csv`` divided by ``--scale``: the layout, with no CPU contention and
no stage's own variance, two ways:

- ``client``: :func:`bearingshaft.jobs.list_schedule`, what ``run`` does (the client submits the ready stage of the
  highest bottom level whenever a worker is free);
- ``dask``: the whole graph handed to Dask at once with the same priorities and dependencies (what ``run`` did
  before).

Prints each way's makespan (scaled back to seconds of the job; it includes the scale times the round trips of
the submissions) beside the ideal of list scheduling computed without a cluster, and writes ``job_schedule.csv``
(way, key, start_s, end_s, worker) under ``--out``. Sleeps only, so the machine's load hardly moves it.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.jobs import StageRun, job_tasks, list_schedule, priorities  # noqa: E402


def stage_walls() -> dict[str, float]:
    """s, each stage's wall time in the committed main_job.csv, by ``scene/stage``."""
    with open(ROOT / "results" / "performance" / "main_job.csv", newline="") as fh:
        return {f"{r['scene']}/{r['stage']}": float(r["wall_s"]) for r in csv.DictReader(fh)}


def _sleeper(task, seconds: float, *after):
    """A stand-in stage: sleeps ``seconds``; returns (key, start, end, worker) in the ``printed`` field."""
    from distributed import get_worker

    t0 = time.time()
    time.sleep(seconds)
    return StageRun(task.key, seconds, f"{t0:.6f} {time.time():.6f}", worker=get_worker().address)


def _by_client(client, tasks, walls, scale):
    return list(list_schedule(client, tasks, lambda t: _sleeper(t, walls[t.key] / scale)))


def _by_dask(client, tasks, walls, scale):
    from distributed import as_completed

    futures = {}
    for t in tasks:
        futures[t.key] = client.submit(_sleeper, t, walls[t.key] / scale, *(futures[k] for k in t.after),
                                       key=f"stage-{t.key}", priority=int(round(t.level)), pure=False)
    return [f.result() for f in as_completed(list(futures.values()))]


def ideal(tasks, walls, n_workers: int) -> float:
    """s, the makespan of list scheduling by bottom level with no overhead: each free worker takes the ready task
    of the highest level."""
    done: dict[str, float] = {}
    free = [0.0] * n_workers
    pending = list(tasks)
    while pending:
        w = min(range(n_workers), key=free.__getitem__)
        ready = [t for t in pending if all(done.get(a, float("inf")) <= free[w] for a in t.after)]
        if not ready:
            free[w] = min(v for v in done.values() if v > free[w])
            continue
        t = max(ready, key=lambda t: t.level)
        pending.remove(t)
        done[t.key] = free[w] = free[w] + walls[t.key]
    return max(free)


def main() -> int:
    import logging

    from distributed import Client, LocalCluster

    from bearingshaft.registry import stages_of
    from bearingshaft.scenes import builtin_names, load_scene

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scale", type=float, default=20.0, help="stage walls are divided by this (default 20)")
    p.add_argument("--workers", type=int, default=2, help="workers of the LocalCluster (default 2)")
    p.add_argument("--out", default="/tmp/job_schedule", help="folder of job_schedule.csv")
    args = p.parse_args()
    walls = stage_walls()
    graph = job_tasks([(n, load_scene(n), Path("unused") / n) for n in builtin_names()], stages_of)
    level = priorities(graph)
    tasks = [replace(t, level=level[t.key]) for t in graph]
    rows = []
    print(f"{len(tasks)} stages, their walls sum to {sum(walls[t.key] for t in tasks):.0f} s; ideal list schedule on "
          f"{args.workers} workers {ideal(tasks, walls, args.workers):.0f} s")
    for way, run in (("client", _by_client), ("dask", _by_dask)):
        with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                          silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            client.run(lambda: None)
            t0 = time.time()
            runs = run(client, tasks, walls, args.scale)
            span = (time.time() - t0) * args.scale
        workers = sorted({r.worker for r in runs})
        for r in runs:
            start, end = (float(x) for x in r.printed.split())
            rows.append({"way": way, "key": r.key, "start_s": round((start - t0) * args.scale, 2),
                         "end_s": round((end - t0) * args.scale, 2), "worker": workers.index(r.worker)})
        late = {r["key"]: r["start_s"] for r in rows if r["way"] == way}
        longest = max(tasks, key=lambda t: walls[t.key]).key
        print(f"{way}: makespan {span:.0f} s (scaled back); the longest stage, {longest}, "
              f"starts at {late[longest]:.0f} s")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "job_schedule.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(sorted(rows, key=lambda r: (r["way"], r["start_s"])))
    print(f"wrote {out / 'job_schedule.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
