"""The runner: the stages a scene asks for (:mod:`bearingshaft.registry`), each computed and then
written into a staged results folder (:func:`bearingshaft.output.staged_output`), so a failure
leaves nothing half-written."""

from __future__ import annotations

import time
from pathlib import Path

from bearingshaft.output import check_out_dir, staged_output
from bearingshaft.registry import BY_NAME, stages_of
from bearingshaft.scenes import Scene


class StageUnavailable(Exception):
    """The scene does not ask for this stage."""


def run_stage(scene: Scene, stage: str, out_dir: str | Path, progress: bool = True, **options) -> None:
    """Run one stage of ``scene`` into ``out_dir`` (refused if the scene lacks its table, or if
    ``out_dir`` cannot be a results folder, before any work); print one summary line.

    Parameters
    ----------
    scene : Scene
        The scene.
    stage : str
        A stage's name (:data:`bearingshaft.registry.STAGES`).
    out_dir : str or Path
        The results folder.
    progress : bool
        Draw progress bars.
    **options
        The stage's command-line options, passed to its compute.

    Returns
    -------
    None

    Raises
    ------
    StageUnavailable
        The scene has no table for the stage.
    ValueError
        ``out_dir`` cannot be a results folder; a stage's own errors propagate.
    """
    wanted = stages_of(scene)
    if stage not in wanted:
        entry = BY_NAME.get(stage)
        raise StageUnavailable(
            f"scene {scene.name!r} has no {entry.asked_by if entry else stage} table, so it has no {stage} stage "
            f"(its stages: {', '.join(wanted) or 'none'})"
        )
    entry = BY_NAME[stage]
    check_out_dir(out_dir)
    t0 = time.perf_counter()
    with staged_output(out_dir, scene.name, scene.source, stage) as writer:
        result = entry.compute(scene, progress, writer.scratch, **options)
        entry.write(result, writer)
        n_files = sum(1 for _ in writer.scratch.iterdir())
    print(f"[{scene.name}] {stage}: {n_files} files in {out_dir} ({time.perf_counter() - t0:.1f} s)", flush=True)


def run_scene(scene: Scene, out_dir: str | Path, progress: bool = True) -> None:
    """Every stage the scene asks for, in pipeline order.

    Parameters
    ----------
    scene : Scene
        The scene.
    out_dir : str or Path
        The results folder.
    progress : bool
        Draw progress bars.

    Returns
    -------
    None
    """
    for stage in stages_of(scene):
        run_stage(scene, stage, out_dir, progress=progress)
