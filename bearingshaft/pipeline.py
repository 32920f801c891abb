"""The runner: the stages a scene asks for (:mod:`bearingshaft.registry`), each computed and then
written into a staged results folder (:func:`bearingshaft.output.staged_output`), so a failure
leaves nothing half-written."""

from __future__ import annotations

import time
from pathlib import Path

from bearingshaft.output import check_out_dir, staged_output
from bearingshaft.registry import BY_NAME, stages_of
from bearingshaft.scenes import Scene

# stages sent straight to a child process off the main thread: none since gmsh meshes in any thread
# (geometry.build.gmsh_session); a child process cost each modal, reduce and verify stage of the main job 3-4 s of
# CPU in imports and start-up, and the reduce stages, which mesh too, first failed in the worker thread
MESH_STAGES: tuple[str, ...] = ()
MAIN_THREAD_ERROR = "signal only works in main thread"  # what a library that needs the main thread raises


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


def run_stage_anywhere(scene: Scene, stage: str, out_dir: str | Path, scene_arg: str) -> None:
    """:func:`run_stage` without progress, from any thread: a stage that raises "signal only works in main
    thread" in a worker thread (a Dask task; a library that installs a signal handler), or one listed in
    ``MESH_STAGES``, runs as ``python -m bearingshaft.cli STAGE --scene SCENE_ARG --out OUT_DIR --no-progress``
    in a child process instead, whose line is printed here. gmsh meshes in any thread
    (:func:`geometry.build.gmsh_session`), so the stages that mesh run in the worker.

    Parameters
    ----------
    scene : Scene
        The scene.
    stage : str
        The stage's name.
    out_dir : str or Path
        The results folder.
    scene_arg : str
        How a child process finds the scene: a built-in name or a TOML file path.

    Returns
    -------
    None

    Raises
    ------
    RuntimeError
        The child process failed: its last line of error output.
    """
    import subprocess
    import sys
    import threading

    if threading.current_thread() is threading.main_thread() or stage not in MESH_STAGES:
        try:
            run_stage(scene, stage, out_dir, progress=False)
            return
        except ValueError as exc:
            if MAIN_THREAD_ERROR not in str(exc):
                raise
    proc = subprocess.run([sys.executable, "-m", "bearingshaft.cli", stage, "--scene", scene_arg, "--out",
                           str(out_dir), "--no-progress"], capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        raise RuntimeError(lines[-1] if lines else f"{stage} stage: exit code {proc.returncode}")
    print(proc.stdout, end="", flush=True)
