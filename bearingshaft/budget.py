"""Memory before allocation: what each stage of a scene will hold, checked before any work.

Each stage declares its estimate in the registry (:mod:`bearingshaft.registry`, counted as
:mod:`bearingshaft.estimates` says, from the scene alone); a ringdown streams its samples to
disk in chunks, so its memory does not grow with its duration and its disk use is checked
against the space free where it writes. A scene whose estimate exceeds the memory available
(Linux ``MemAvailable``, less a margin) is refused in one line that gives the estimate and
the key to change.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from bearingshaft.digits import human
from bearingshaft.estimates import Estimate
from bearingshaft.registry import BY_NAME, stages_of
from bearingshaft.scenes import Scene, SceneError

HEADROOM = 0.8  # of the available memory a scene may plan to use


def available_bytes() -> int:
    """Bytes of memory available to a new allocation (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")


def estimates(scene: Scene) -> list[Estimate]:
    """What each stage of ``scene`` will hold at its peak, in pipeline order (the registry's estimates).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    list of Estimate
    """
    return [e for name in stages_of(scene) for e in BY_NAME[name].estimate(scene)]


def stage_bytes(scene: Scene, stage: str) -> int:
    """Peak bytes of ``stage`` of ``scene`` run in a process of its own (the largest of its estimates).

    Parameters
    ----------
    scene : Scene
        The scene.
    stage : str
        One of its stages.

    Returns
    -------
    int
        bytes.
    """
    return int(max((e.bytes for e in BY_NAME[stage].estimate(scene)), default=0))


def job_bytes(stages) -> int:
    """Peak bytes of ``stages`` ((scene, stage) pairs) run one after another in one process.

    Parameters
    ----------
    stages : iterable of (Scene, str)
        The stages, in the order they run.

    Returns
    -------
    int
        bytes.
    """
    return max((stage_bytes(scene, name) for scene, name in stages), default=0)


def free_disk_bytes(out_dir: str | Path) -> int:
    """Bytes free on the file system that holds (or will hold) ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        A folder, existing or not (its nearest existing parent is measured).

    Returns
    -------
    int
        bytes.
    """
    probe = Path(out_dir).absolute()
    while not probe.exists():
        probe = probe.parent
    return shutil.disk_usage(probe).free


def check_budget(scene: Scene, out_dir: str | Path | None = None, available: int | None = None) -> list[Estimate]:
    """The scene's estimates, or :class:`SceneError` naming the key if one does not fit in
    memory (or, given ``out_dir``, on its disk).

    Parameters
    ----------
    scene : Scene
        The scene.
    out_dir : str or Path, optional
        The results folder, for the disk check.
    available : int, optional
        bytes of memory available (default: :func:`available_bytes`).

    Returns
    -------
    list of Estimate

    Raises
    ------
    SceneError
        An estimate above ``HEADROOM`` of the memory available or of the free disk.
    """
    avail = available_bytes() if available is None else available
    ests = estimates(scene)
    if out_dir is not None:
        free = free_disk_bytes(out_dir)
        for e in ests:
            if e.disk > HEADROOM * free:
                raise SceneError(f"{scene.origin or scene.name} {e.key}: the {e.stage} stage would write "
                                 f"{human(e.disk)} ({e.what}), more than the {human(free)} free for {out_dir}; "
                                 f"lower {e.key.split('] ')[1]}")
    for e in ests:
        if e.bytes > HEADROOM * avail:
            raise SceneError(f"{scene.origin or scene.name} {e.key}: the {e.stage} stage would hold "
                             f"{human(e.bytes)} ({e.what}), more than the {human(HEADROOM * avail)} it may use "
                             f"of {human(avail)} available; {e.advice or 'lower ' + e.key.split('] ')[1]}")
    return ests
