"""Memory before allocation: what each stage of a scene will hold, checked before any work.

Each stage declares its estimate in the registry (:mod:`bearingshaft.registry`, counted as
:mod:`bearingshaft.estimates` says, from the scene alone); a ringdown streams its samples to
disk in chunks, so its memory does not grow with its duration and its disk use is checked
against the space free where it writes. A scene whose estimate exceeds the memory available
(Linux ``MemAvailable``, less a margin) is refused in one line that gives the estimate and
the key to change.

What a stage's process peaks at (:func:`stage_peak`) adds to those the interpreter and its imports,
the stage's fixed working set (figures, solver work space), the 3-D model when the stage builds it
(always for modal and reduce; a reduced model not in the cache is built first) and is calibrated on
the peaks measured for every stage of every built-in scene (``benchmarks/memory_estimates.py``,
``results/memory-estimates/``: within 1 to 1.3 times each). :func:`job_bytes` is the peak of stages run
one after another in one process, as ``bearingshaft run`` runs them: what an earlier stage held stays
resident (allocator fragmentation, MKL's and VTK's buffers), so it is not the largest stage's peak.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from bearingshaft.digits import human
from bearingshaft.estimates import Estimate, has_friction
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


MIB = 2**20
PROCESS_BYTES = 195 * MIB  # the interpreter with the package and matplotlib loaded: VmHWM of
# `python -c "import bearingshaft.cli, matplotlib.pyplot"` measured 194.6 MiB (Python 3.11, numpy with MKL)
MESH_IMPORTS_BYTES = 78 * MIB  # gmsh, scikit-fem and pyvista on top of it: measured 77.6 MiB more


@dataclass(frozen=True, slots=True)
class PeakModel:
    """How the peak of one stage run in a process of its own is counted, beyond :data:`PROCESS_BYTES`.

    Parameters
    ----------
    fixed : float
        bytes: the stage's own modules, figures and work space, whatever the scene's sizes.
    data_scale : float
        x the data the stage holds (the sum of its registry estimates, :mod:`bearingshaft.estimates`).
    model_scale : float
        x the 3-D model's arrays (:func:`fe_arrays_bytes`), for a stage whose work is on the 3-D model (modal,
        reduce, the hammer's linear check, the rom convergence study, an frf with the 3-D model's MAC).
    tables : tuple of (str, float)
        bytes added when the scene has the table (its solver's work space, not sized by the estimates).
    """

    fixed: float
    data_scale: float = 1.0
    model_scale: float = 0.0
    tables: tuple[tuple[str, float], ...] = ()


# Calibrated on the peaks of every stage of every built-in scene run each in its own process
# (benchmarks/memory_estimates.py, results/memory-estimates/estimates.csv): the estimate is at least the
# measured peak and at most 1.3x it. A stage with one size among the scenes (hammer, frf: one scene each) has
# its fixed term from that one measurement, not a law; the terms that grow with a scene's sizes are counted.
PEAK_MODELS: dict[str, PeakModel] = {
    # modal: its registry estimate is the whole modal solve's process (fem._modal_cost, fitted on meshes up to
    # 648k DOFs without figures); here its arrays only, with the figures and VTK rendering in the fixed term
    "modal": PeakModel(fixed=362 * MIB, data_scale=0.0, model_scale=0.5),
    "reduce": PeakModel(fixed=376 * MIB, data_scale=0.0, model_scale=1.2),  # the full gap modes, VTK figures
    "ringdown": PeakModel(fixed=68 * MIB, data_scale=0.45),  # its estimate counts two streams at once
    "hammer": PeakModel(fixed=413 * MIB, model_scale=1.0),  # one scene: the linear check's SuperLU modes
    "frf": PeakModel(fixed=0.0, data_scale=0.67, model_scale=1.0),  # one scene: its blows counted twice over
    "nnm": PeakModel(fixed=20 * MIB, tables=(("fep", 119 * MIB),)),  # HB continuation, shooting, figures
    "study": PeakModel(fixed=71 * MIB, model_scale=0.25),
    "verify": PeakModel(fixed=151 * MIB),  # one scene
    "frc": PeakModel(fixed=166 * MIB, data_scale=0.5),  # the Hill matrices did not show at H <= 25
    # the frc stage on a model with friction (stages/frc_friction.py: HB by AFT, Hill, a stepped sine; no shooting,
    # response map or convergence study): one scene, its fixed term from its one measurement (267 MiB)
    "frc_friction": PeakModel(fixed=100 * MIB, data_scale=0.5),
}
UNCALIBRATED = PeakModel(fixed=200 * MIB, model_scale=1.0)  # a stage added since: its estimates, the 3-D model
# and the largest fixed term of the stages above not on the 3-D model, until benchmarks/memory_estimates.py
# measures it
# A stage that finds its reduced model neither in the cache nor in a rom_file builds it first
# (reduced.models.rom.cached_rom: mesh, assemble, reduce, store) and frees the 3-D model before its own work,
# so its peak is the larger of its own and the build's: PROCESS_BYTES + MESH_IMPORTS_BYTES + BUILD_FIXED +
# BUILD_SCALE x the arrays. Measured (VmHWM, an empty cache): rom-symmetric's ringdown (2,511 DOFs) 330 MiB
# (296 MiB cached), rom-assembly's (15,087 DOFs) 827 MiB (338 MiB cached); the constants put the estimate
# 1.11x and 1.07x above those (the Craig-Bampton reduction holds about three copies of the arrays counted).
BUILD_FIXED = 0.0
BUILD_SCALE = 2.9


@dataclass(frozen=True, slots=True)
class StagePeak:
    """The estimated peak resident memory of one stage of a scene run in a process of its own.

    Parameters
    ----------
    scene : str
        The scene's name.
    stage : str
        The stage.
    bytes : float
        The estimate: process + fixed + model + data.
    process, fixed, model, data : float
        bytes of each term: the interpreter and imports, the stage's fixed working set, what the 3-D model adds
        (0 unless the stage builds it), the data it holds.
    builds_model : bool
        The stage meshes and assembles the 3-D model (a reduced model not yet in the cache, a stage that always
        does, or a modal analysis).
    """

    scene: str
    stage: str
    bytes: float
    process: float
    fixed: float
    model: float
    data: float
    builds_model: bool


def fe_dofs(scene: Scene) -> int:
    """DOFs of the scene's 3-D model, counted from its geometry before any meshing (0 without one).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    int
    """
    from fem._modal_cost import count_dofs

    model = scene.model
    if scene.model_kind == "rom":
        model = model.fe_model()
    elif not hasattr(model, "geometry"):
        return 0
    return count_dofs(model.geometry(), model.element)


def fe_arrays_bytes(scene: Scene, n_modes: int) -> float:
    """bytes of the 3-D model's arrays at a modal solve of ``n_modes``: K and M, the factor, the Krylov basis.

    Parameters
    ----------
    scene : Scene
        A scene with a 3-D model (a modal scene or a reduced model's).
    n_modes : int
        Modes solved for.

    Returns
    -------
    float
        :func:`fem._modal_cost.modal_bytes` without its process base.
    """
    from fem._modal_cost import modal_bytes

    b = modal_bytes(fe_dofs(scene), n_modes)
    return float(b["matrices"] + b["factor"] + b["krylov"])


def _model_modes(scene: Scene, stage: str) -> int:
    """Modes of the 3-D model's solve that sizes the stage's Krylov basis."""
    if stage == "modal":
        return scene.modal.n_modes
    if stage == "hammer":
        return 96  # the linear check's modes to linear_check_max_hz (24, 48, 96: hammer_linear.full_modes)
    if stage == "frf" and scene.frf.mac_reference == "fe":
        return scene.frf.fe_modes
    if stage == "reduce":
        return 16  # the full model's gap modes (fem.contact.gap_modes): the reduction's own fixed-interface
        # modes did not show in the peaks (hammer-test's 120 and rom-assembly's 10 peaked within 0.2 %)
    return scene.model.n_modes + 8  # a cached_rom build: the fixed-interface modes and the gap modes


def builds_model(scene: Scene, stage: str, cached: bool) -> bool:
    """Does ``stage`` of ``scene`` mesh and assemble the 3-D model?

    Parameters
    ----------
    scene : Scene
        The scene.
    stage : str
        One of its stages.
    cached : bool
        Its reduced model is in the cache (or in its ``rom_file``) when the stage starts.

    Returns
    -------
    bool
        modal and reduce always; the hammer's linear check, the rom convergence study and an frf whose MAC
        reference is the 3-D model always; any other stage of a reduced model when it is not cached.
    """
    if stage in ("modal", "reduce"):
        return True
    if scene.model_kind != "rom":
        return False
    if (stage == "hammer" and scene.hammer.linear_check) or (stage == "study" and scene.rom_convergence is not None) \
            or (stage == "frf" and scene.frf.mac_reference == "fe"):
        return True
    return not cached


def _cache_file(spec) -> Path:
    """Where the reduced-model cache keeps ``spec``'s model (reduced.models.rom's own path: a helper there would
    change the source hash that keys every cache entry)."""
    from reduced.models.rom import _cache_path

    return _cache_path(spec)


def rom_cached(scene: Scene, stored: frozenset = frozenset()) -> bool:
    """Is the scene's reduced model at hand without building: its ``rom_file``, the cache, or ``stored``?

    Parameters
    ----------
    scene : Scene
        A scene (a model other than a reduced one is never built: True).
    stored : frozenset of Path
        Cache files an earlier stage of the same job writes (``reduce`` stores its model).

    Returns
    -------
    bool
    """
    if scene.model_kind != "rom" or scene.model.rom_file:
        return True
    path = _cache_file(scene.model)
    return path in stored or path.exists()


def stage_peak(scene: Scene, stage: str, cached: bool | None = None) -> StagePeak:
    """The peak resident memory of ``stage`` of ``scene`` run in a process of its own, from the scene's sizes.

    Its own work: :data:`PROCESS_BYTES` + the stage's fixed working set (and its tables') + ``data_scale`` x
    the data it holds (its registry estimates) + for a stage whose work is on the 3-D model
    :data:`MESH_IMPORTS_BYTES` + ``model_scale`` x :func:`fe_arrays_bytes`, with the stage's
    :data:`PEAK_MODELS` entry; a stage that must first build its reduced model peaks at the larger of that
    and the build's (:data:`BUILD_FIXED`).

    Parameters
    ----------
    scene : Scene
        The scene.
    stage : str
        One of its stages.
    cached : bool, optional
        Its reduced model is in the cache when the stage starts (default: as the cache is now).

    Returns
    -------
    StagePeak
    """
    friction_frc = stage == "frc" and has_friction(scene)
    pm = PEAK_MODELS.get("frc_friction" if friction_frc else stage, UNCALIBRATED)
    cached = rom_cached(scene) if cached is None else cached
    fixed = pm.fixed + sum(b for table, b in pm.tables if getattr(scene, table, None) is not None)
    data = pm.data_scale * sum(e.bytes for e in BY_NAME[stage].estimate(scene))
    own = PROCESS_BYTES + fixed + data
    model = 0.0
    if pm.model_scale and builds_model(scene, stage, cached=True):  # its own work is on the 3-D model
        model = MESH_IMPORTS_BYTES + pm.model_scale * fe_arrays_bytes(scene, _model_modes(scene, stage))
    elif builds_model(scene, stage, cached):  # only because the reduced model is not at hand
        build = PROCESS_BYTES + MESH_IMPORTS_BYTES + BUILD_FIXED + BUILD_SCALE * fe_arrays_bytes(
            scene, scene.model.n_modes + 8)
        model = max(0.0, build - own)
    return StagePeak(scene.name, stage, own + model, PROCESS_BYTES, fixed, model, data,
                     builds_model(scene, stage, cached))


def job_peaks(scenes) -> list[StagePeak]:
    """Every stage of ``scenes`` in the order ``bearingshaft run`` runs them, each as :func:`stage_peak`, with
    the cache as it will be: a ``reduce`` stores its model, so the stages after it load it.

    Parameters
    ----------
    scenes : iterable of Scene
        In the order they run.

    Returns
    -------
    list of StagePeak
    """
    stored: set = set()
    out = []
    for scene in scenes:
        for name in stages_of(scene):
            out.append(stage_peak(scene, name, rom_cached(scene, frozenset(stored))))
            if name == "reduce" and not scene.model.rom_file:
                stored.add(_cache_file(scene.model))
    return out


JOB_RETAINED = 1.0  # share of an earlier stage's peak (less the process) a later stage of the same process cannot
# reuse: numpy's freed arrays go back to the allocator, but MKL's, gmsh's and VTK's buffers and a fragmented heap
# stay resident (measured in benchmarks/memory_estimates.py's job pass)


def job_bytes(peaks: list[StagePeak]) -> float:
    """The peak of a job running ``peaks``' stages one after another in one process (``bearingshaft run``).

    A stage's peak in the job is its own plus what the earlier stages left resident and it cannot reuse:
    ``max_i (peak_i + JOB_RETAINED x (max_{j<i} peak_j - PROCESS_BYTES))``: the largest stage's own peak with
    ``JOB_RETAINED`` = 0, with 1 each stage on top of the largest before it (less the process, counted once).

    Parameters
    ----------
    peaks : list of StagePeak
        In the order they run (:func:`job_peaks`).

    Returns
    -------
    float
        bytes.
    """
    best, before = 0.0, 0.0
    for p in peaks:
        best = max(best, p.bytes + JOB_RETAINED * max(0.0, before - PROCESS_BYTES))
        before = max(before, p.bytes)
    return best


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


def check_budget(scene: Scene, out_dir: str | Path | None = None, available: int | None = None,
                 stage: str | None = None) -> list[Estimate]:
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
    stage : str, optional
        Only this stage will run (one subcommand): the others' process peaks are not estimated (a
        ringdown from a ``rom_file`` never sizes the 3-D model that the scene's reduce stage would build).

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
    peaks = job_peaks([scene]) if stage is None else [stage_peak(scene, stage)]
    for p in peaks:  # the whole process: imports, the 3-D model if the stage builds it, the data
        if p.bytes > HEADROOM * avail:
            own = [e for e in ests if e.stage == p.stage]
            e = max(own, key=lambda e: e.bytes) if own else None
            fix = (e.advice or "lower " + e.key.split("] ")[1]) if e else "free memory"
            key = e.key if e else ""
            if p.model > p.data and hasattr(scene.model, "element_size"):  # the 3-D model is most of it
                key = "[model] element_size" + (f" or {key}" if key else "")
                fix = (f"the 3-D model's share is about {human(p.model)}: raise element_size (a coarser mesh)"
                       + (f", or {fix}" if e else ""))
            raise SceneError(f"{scene.origin or scene.name}{' ' + key if key else ''}: the {p.stage} stage's "
                             f"process would peak at about {human(p.bytes)}, more than the "
                             f"{human(HEADROOM * avail)} it may use of {human(avail)} available; {fix}")
    return ests
