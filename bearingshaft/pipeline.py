"""Stages of the pipeline and the runner that does only what a scene asks for.

Each stage is a function ``stage(scene, writer, progress, **options)`` writing its files
through a :class:`bearingshaft.output.StageWriter`; :func:`run_stage` wraps it in a staged
output folder so a failure leaves nothing half-written.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from bearingshaft.output import StageWriter, check_out_dir, staged_output
from bearingshaft.scenes import Scene


class StageUnavailable(Exception):
    """The scene does not ask for this stage, or the stage is not built yet."""


def _modal(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.modal import modal_stage

    modal_stage(scene, writer, progress)


def _ringdown(scene: Scene, writer: StageWriter, progress: bool, method: str | None = None, **_) -> None:
    from bearingshaft.stages.ringdown import ringdown_stage

    ringdown_stage(scene, writer, progress, method=method)


def _nnm(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.nnm import nnm_stage

    nnm_stage(scene, writer, progress)


def _study(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.study import study_stage

    study_stage(scene, writer, progress)


def _reduce(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.reduce import reduce_stage

    reduce_stage(scene, writer, progress)


def _verify(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.verify import verify_stage

    verify_stage(scene, writer, progress)


def _frc(scene: Scene, writer: StageWriter, progress: bool, **_) -> None:
    from bearingshaft.stages.frc import frc_stage

    frc_stage(scene, writer, progress)


def _hammer(scene: Scene, writer: StageWriter, progress: bool, test_file: str | None = None, **_) -> None:
    from bearingshaft.stages.hammer import hammer_stage

    hammer_stage(scene, writer, progress, test_file=test_file)


STAGES: dict[str, Callable] = {
    "modal": _modal,
    "reduce": _reduce,
    "ringdown": _ringdown,
    "nnm": _nnm,
    "study": _study,
    "verify": _verify,
    "frc": _frc,
    "hammer": _hammer,
}


def run_stage(scene: Scene, stage: str, out_dir: str | Path, progress: bool = True, **options) -> None:
    """Run one stage of ``scene`` into ``out_dir`` (refused if the scene lacks its table, or if
    ``out_dir`` cannot be a results folder, before any work); print one summary line."""
    if stage not in scene.stages:
        tables = {"ringdown": "[ringdown]", "nnm": "[nnm]",
                  "study": "[work_precision], [stiff_cases] or [rom_convergence]",
                  "modal": "[modal]", "verify": "[verify]", "frc": "[frc]", "hammer": "[hammer]",
                  "reduce": '[model] kind = "rom"'}
        raise StageUnavailable(
            f"scene {scene.name!r} has no {tables.get(stage, stage)} table, so it has no {stage} stage "
            f"(its stages: {', '.join(scene.stages) or 'none'})"
        )
    check_out_dir(out_dir)
    t0 = time.perf_counter()
    with staged_output(out_dir, scene.name, scene.source, stage) as writer:
        STAGES[stage](scene, writer, progress, **options)
        n_files = sum(1 for _ in writer.scratch.iterdir())
    print(f"[{scene.name}] {stage}: {n_files} files in {out_dir} ({time.perf_counter() - t0:.1f} s)", flush=True)


def run_scene(scene: Scene, out_dir: str | Path, progress: bool = True) -> None:
    """Every stage the scene asks for, in pipeline order."""
    for stage in scene.stages:
        run_stage(scene, stage, out_dir, progress=progress)
