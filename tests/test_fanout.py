"""A stage's independent pieces as tasks of the job's cluster (bearingshaft.fanout, issue 28): the pieces run on
the workers, come back in their order, and the stage's files are those of the serial run, byte for byte."""

from __future__ import annotations

import sys
import tomllib
from importlib import resources
from pathlib import Path

import pytest
import tomli_w

from bearingshaft import jobs
from bearingshaft.fanout import fan_out, mapping
from bearingshaft.pipeline import run_stage
from bearingshaft.registry import stages_of
from bearingshaft.scenes import load_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_hb_fep_stage import SCENE as FEP_SCENE  # noqa: E402

pytestmark = pytest.mark.slow  # a cluster of two processes and two small stages run twice: ~40 s CPU

FEP = 'description = "fep on a small configuration (tests/test_hb_fep_stage.py)"\n' + FEP_SCENE


def _frc_scene() -> str:
    """discrete-frc cut down: two levels (open gap and contact), H = 3, the HB curve drawn (no families),
    a coarse response map."""
    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / "discrete-frc.toml").read_text("utf-8"))
    data["frc"].update({"levels_N": [0.1, 1.0], "freq_max_hz": 40.0, "harmonics": 3, "convergence_harmonics": [1, 3],
                        "convergence_level_N": 1.0, "hill_points": 3, "shooting_points": 2,
                        "stepped_sine_points": 6, "stepped_sine_max_s": 9.0, "backbone_scales": [1.0],
                        "map_step_hz": 2.0, "map_coarse_points": 6, "map_periods": 32, "curve": "hb",
                        "period_doubling": False})
    return tomli_w.dumps(data)


@pytest.fixture(scope="module")
def cluster():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as lc, \
            Client(lc) as client:
        yield client


def _where(i: int) -> tuple[int, str]:
    from bearingshaft.sweep.run import worker_name

    return i, worker_name()


def _a_stage(n: int) -> list:
    """What run_task does around a stage on a worker: install the cluster's mapper, then fan out."""
    with mapping(jobs._cluster_map(0.0)):
        return fan_out(_where, range(n))


def test_without_a_cluster_the_pieces_run_here_in_order():
    out = fan_out(_where, range(4))
    assert [i for i, _ in out] == [0, 1, 2, 3] and all(w.startswith("local:") for _, w in out)


def test_pieces_run_as_tasks_of_the_cluster_in_order(cluster):
    out = cluster.submit(_a_stage, 8, pure=False).result()
    assert [i for i, _ in out] == list(range(8))
    workers = set(cluster.scheduler_info()["workers"])
    assert {w for _, w in out} <= workers  # on the workers, none run where the stage waits serially


@pytest.mark.parametrize("name,stage", [("frc", "frc"), ("fep", "nnm")])
def test_a_stage_fanned_out_on_the_cluster_writes_the_files_of_a_serial_run(cluster, tmp_path, name, stage):
    """The same stage serially in this process and as a job's task whose pieces run on two workers: every file
    but provenance.json (finishing times) and the *_timing files (wall times) is the same, byte for byte."""
    from distributed import get_task_stream

    path = tmp_path / f"{name}-small.toml"
    path.write_text(_frc_scene() if name == "frc" else FEP)
    scene = load_scene(str(path))
    assert stages_of(scene) == (stage,)
    serial, par = tmp_path / "serial", tmp_path / "par"
    run_stage(scene, stage, serial, progress=False)
    with get_task_stream(cluster) as ts:
        job = jobs.run_job([(str(path), scene, par)], stages_of, scheduler=cluster.scheduler.address,
                           progress=False, echo=lambda *_: None, fan_out=True)
    assert not job.failed, job.failed
    pieces = [t for t in ts.data if t["key"].startswith("fanout")]
    assert len(pieces) >= 4, "the stage did not fan out"
    names = sorted(p.name for p in serial.iterdir())
    assert names == sorted(p.name for p in par.iterdir())
    compared = 0
    for n in names:
        if n == "provenance.json" or Path(n).stem.endswith("_timing"):
            continue
        assert (serial / n).read_bytes() == (par / n).read_bytes(), n
        compared += 1
    assert compared >= 6
