"""Parameter sweeps of any scene on Dask (issue 13): ``bearingshaft sweep``.

A sweep runs one scene over a design of parameter values. The values come from a
``[sweep]`` table in the scene or from ``--vary`` on the command line::

    [sweep]
    design = "grid"                    # grid (product) | zip (i-th of each) | random (Latin hypercube)
    samples = 0                        # random: number of cases
    seed = 0                           # random: seed of the Latin hypercube
    plots = ["freq_early_hz"]          # metrics drawn (default: a standard set the stages have)
    x = ""                             # plot against this metric column instead of the varied key
    overlay = ""                       # "nnm_stability": NNM 1 and 3 Floquet stability beside the plot
    [sweep.vary]
    "model.g" = "1e-4:1e-3:9:log"      # LO:HI:N (linear), LO:HI:N:log; random design: LO:HI[:log]
    "model.k_g" = [1e7, 1e8, 1e9]      # or a list (CLI: 1e7,1e8,1e9)
    "initial.v0_m_s[1]" = [1.0, 2.0]   # an element of a list key
    "load[0].peak_N" = [100.0, 500.0]  # a key of the first [[load]]

Keys are ``TABLE.KEY`` as in the scene, in the scene's units. Every case's scene is written
out (TOML) and read back by the scene parser (:func:`bearingshaft.scenes.parse_scene`) and
its memory checked (:mod:`bearingshaft.budget`) before anything runs: one bad value refuses
the whole sweep in one line naming the key, with exit code 2.

Each case runs the scene's stages through :func:`bearingshaft.pipeline.run_stage`, the code
of a single run, into ``<out>/<case-id>/`` (default ``results/<scene>/sweep/``; the case id
is the first 12 hex digits of the sha256 of the case's values), and returns one row of
scalar metrics read from the stage's own output (:func:`case_metrics`: ``provenance.json``
statistics and the files the stage wrote) plus its run time and worker. The rows go to
``sweep.parquet`` and ``sweep.csv`` in ``<out>``, the plots to ``sweep.png``
(:mod:`bearingshaft.sweep_report`).

Cases run on Dask: a :class:`distributed.LocalCluster` with one single-threaded worker
process per core (``--workers N`` to limit), started and closed by the sweep, or the
scheduler at ``--scheduler ADDRESS``. A rerun skips cases whose folder is complete (every
stage in its ``provenance.json``, written last by :mod:`bearingshaft.output`, and its
``scene.toml`` equal to the case's); a failing case (a solver error, a value refused by a
stage, a worker lost more often than Dask's ``allowed-failures``) is a row with its
one-line message, never the end of the sweep. A worker killed mid-case has its task rerun
elsewhere by Dask; the folder of a case is written whole or not at all, so nothing is lost
or doubled. A reduced model (``[model] kind = "rom"``) is built once before the sweep (for
each distinct reduction: contact and damping do not change it), scattered to the workers
once, and each worker puts it into its reduced-model cache, from where every case's
stages read it; the ``reduce`` stage is not repeated per case.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import itertools
import json
import logging
import math
import os
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bearingshaft.registry import stages_of
from bearingshaft.scenes import Scene, parse_scene
from bearingshaft.scenes.sweep import (  # noqa: F401  (the [sweep] schema, re-exported for the sweep's users)
    DESIGNS,
    INT_PATTERN,
    KEY_PATTERN,
    MAX_CASES,
    OVERLAYS,
    TABLES,
    SweepError,
    SweepSpec,
    Vary,
    check_key,
    check_spec,
    parse_sweep_table,
    parse_values,
    parse_vary_option,
)
from reduced._checks import one_line

ID_DIGITS = 12  # hex digits of a case id: 48 bits, a collision among 1e5 cases has odds ~1e-5
# metrics of a ringdown (see case_metrics)
WINDOW_FRACTION = 1 / 8  # early, middle and late windows of the dominant frequency: each 1/8 of the record
MAX_WINDOW_SAMPLES = 1 << 18  # and at most this many samples
PAD = 8  # zero padding of a window's DFT before the peak is refined
DECAY_FRACTION = 1e-2  # decay time: the energy first falls to 1 % of its peak (20 dB of amplitude)


def design_points(spec: SweepSpec) -> list[tuple]:
    """The cases' values in design order: the grid's product (last key fastest), the zip's i-th
    values, or the random design's Latin hypercube (one stratum per case and key, uniform inside it,
    on a log scale for log ranges; ``numpy.random.default_rng(seed)``)."""
    if not spec.vary:
        return []
    if spec.design == "grid":
        n = math.prod(len(v.values) for v in spec.vary)
        if n > MAX_CASES:
            raise SweepError(f"the grid has {n} cases, more than {MAX_CASES}: give fewer values")
        return list(itertools.product(*(v.values for v in spec.vary)))
    if spec.design == "zip":
        return list(zip(*(v.values for v in spec.vary), strict=True))
    if spec.samples > MAX_CASES:
        raise SweepError(f"samples = {spec.samples} is more than {MAX_CASES} cases")
    rng = np.random.default_rng(spec.seed)
    n = spec.samples
    columns = []
    for v in spec.vary:
        u = (rng.permutation(n) + rng.random(n)) / n
        if v.log:
            col = np.exp(np.log(v.low) + u * (np.log(v.high) - np.log(v.low)))
        else:
            col = v.low + u * (v.high - v.low)
        columns.append([int(round(c)) for c in col] if v.integer else [float(c) for c in col])
    return list(zip(*columns, strict=True))


# -- the cases --------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Case:
    """One case of a sweep: its values, its scene's TOML text and the stages it runs."""

    case_id: str
    values: tuple  # ((key, value), ...) in the order of the design's keys
    text: str = field(repr=False)  # the case's scene (TOML), as its folder's scene.toml
    name: str = ""
    origin: str = ""
    stages: tuple[str, ...] = ()
    shared_key: str = ""  # the reduction a reduced-model case needs (see _reduction_key), "" for none


@dataclass(frozen=True, eq=False)
class SweepPlan:
    """A validated sweep: the base scene, its design and every case."""

    scene: Scene
    spec: SweepSpec
    cases: tuple[Case, ...]
    source: str  # where the design came from: "--vary" or "<scene> [sweep]"
    shared: dict = field(default_factory=dict)  # reduction key -> RomSpec to build once


def case_id(values) -> str:
    """Short hash of a case's values: sha256 of their JSON (floats as Python writes them)."""
    blob = json.dumps([[k, v] for k, v in values], sort_keys=False, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:ID_DIGITS]


def _default(scene: Scene, table: str, ti: int | None, name: str):
    """The current value of a key the scene's TOML does not write (the dataclass default)."""
    if table == "load":
        obj = scene.loads[ti] if ti is not None and ti < len(scene.loads) else None
    else:
        obj = getattr(scene, table, None)
    if obj is None or not hasattr(obj, name):
        return None
    value = getattr(obj, name)
    return list(value) if isinstance(value, tuple) else value


def apply_values(scene: Scene, data: dict, values, where: str) -> dict:
    """A copy of the scene's TOML data with each (key, value) set."""
    data = json.loads(json.dumps(data))  # a deep copy of plain TOML data
    for key, value in values:
        m = KEY_PATTERN.match(key)
        table, name = m["table"], m["name"]
        ti = int(m["ti"]) if m["ti"] is not None else None
        if table == "load":
            loads = data.get("load", [])
            if ti >= len(loads):
                raise SweepError(f"{where} {key}: the scene has {len(loads)} [[load]] table(s); load[{ti}] is not one")
            tab = loads[ti]
        elif table in ("model", "initial"):  # present in every scene, if only as defaults
            tab = data.setdefault(table, {})
        elif table not in data:
            raise SweepError(f"{where} {key}: the scene has no [{table}] table, so nothing reads {key} "
                             f"(its tables: {', '.join(k for k in data if isinstance(data[k], dict)) or 'none'})")
        else:
            tab = data[table]
        if m["i"] is None:
            tab[name] = value
            continue
        i = int(m["i"])
        current = tab.get(name, _default(scene, table, ti, name))
        if not isinstance(current, list):
            raise SweepError(f"{where} {key}: [{table}] {name} is not a list, so it has no element [{i}]")
        if i >= len(current):
            raise SweepError(f"{where} {key}: [{table}] {name} has {len(current)} values; [{i}] is not one")
        current = list(current)
        current[i] = value
        tab[name] = current
    return data


def base_value(scene: Scene, key: str):
    """The value the scene itself gives ``key`` (its TOML, else the default), None if it has none."""
    m = KEY_PATTERN.match(key)
    if m is None:
        return None
    table, name = m["table"], m["name"]
    ti = int(m["ti"]) if m["ti"] is not None else None
    data = tomllib.loads(scene.source)
    try:
        tab = data["load"][ti] if table == "load" else data.get(table, {})
    except (KeyError, IndexError, TypeError):
        return None
    value = tab.get(name, _default(scene, table, ti, name)) if isinstance(tab, dict) else None
    if m["i"] is not None:
        i = int(m["i"])
        value = value[i] if isinstance(value, list) and i < len(value) else None
    return value


def _show_values(values) -> str:
    return ", ".join(f"{k} = {v!r}" for k, v in values)


def _reduction_key(model) -> str:
    """What a reduced model's reduction depends on: the spec with contact and damping at their
    defaults (they are applied after the reduction, reduced.models.rom.RomSpec.reduced)."""
    from reduced.models.rom import RomSpec

    d = RomSpec()
    spec = dataclasses.replace(model, k_g=d.k_g, gap=d.gap, c_points=d.c_points, alpha=d.alpha)
    return hashlib.sha256(repr(spec).encode()).hexdigest()[:ID_DIGITS]


def case_stages(scene: Scene) -> tuple[str, ...]:
    """The stages a case runs: the scene's, less ``reduce`` (the reduction is built once per sweep)."""
    return tuple(s for s in stages_of(scene) if s != "reduce")


def build_plan(scene: Scene, spec: SweepSpec, source: str, out: Path | None = None,
               n_workers: int | None = None) -> SweepPlan:
    """Every case's scene written and parsed, memory and disk checked: :class:`SweepError` (one line,
    naming the key and value) at the first case that would be refused, before anything runs."""
    from bearingshaft.budget import HEADROOM, available_bytes, check_budget, free_disk_bytes
    from bearingshaft.digits import human

    if not spec.vary:
        raise SweepError(f"{source}: nothing is varied; give --vary KEY=VALUES or a [sweep.vary] table")
    if not case_stages(scene):
        raise SweepError(f"{scene.origin or scene.name}: the scene has no stage to run in each case "
                         f"(its stages: {', '.join(stages_of(scene)) or 'none'})")
    data = tomllib.loads(scene.source)
    data.pop("sweep", None)
    data.pop("name", None)
    import tomli_w

    points = design_points(spec)
    keys = [v.key for v in spec.vary]
    avail = available_bytes() // max(1, n_workers or 1)
    cases, seen, disk = [], {}, 0.0
    shared = {}
    for point in points:
        values = tuple(zip(keys, point, strict=True))
        cid = case_id(values)
        if cid in seen:
            raise SweepError(f"{source}: two cases have the same values ({_show_values(values)}); give each "
                             "value once")
        seen[cid] = values
        where = f"{source} case {_show_values(values)}"
        case_data = apply_values(scene, data, values, where)
        case_data = {"name": f"{scene.name}-{cid}",
                     "description": f"{scene.name} sweep case: {_show_values(values)}"[:500],
                     **{k: v for k, v in case_data.items() if k != "description"}}
        try:
            text = tomli_w.dumps(case_data)
        except (TypeError, ValueError) as exc:
            raise SweepError(f"{where}: cannot be written as TOML ({exc})") from None
        case_scene = parse_scene(text, f"{scene.name}-{cid}", where)
        ests = check_budget(case_scene, None, available=avail)
        disk += sum(e.disk for e in ests)
        shared_key = ""
        if case_scene.model_kind == "rom" and not case_scene.model.rom_file:
            shared_key = _reduction_key(case_scene.model)
            shared.setdefault(shared_key, case_scene.model)
        cases.append(Case(cid, values, text, case_scene.name, where, case_stages(case_scene), shared_key))
    if out is not None and disk > HEADROOM * free_disk_bytes(out):
        raise SweepError(f"{source}: the {len(cases)} cases would write {human(disk)} into {out}, more than the "
                         f"{human(free_disk_bytes(out))} free; lower [ringdown] duration_s or sample_rate_hz, or "
                         "the number of cases")
    return SweepPlan(scene, spec, tuple(cases), source, shared)


# -- one case, on a worker ------------------------------------------------------------------
_INSTALLED: set = set()  # reductions this worker process has put into its reduced-model cache


def _warm_up() -> None:
    """Import the stages and load numba's compiled kernels in a worker before its first case, so
    that a case's run time is the case's (the sweep's wall time still counts this, once per worker)."""
    import bearingshaft.pipeline  # noqa: F401
    import bearingshaft.plots  # noqa: F401
    from bearingshaft.systems import model_system  # noqa: F401
    from reduced.models.discrete import DiscreteParams
    from reduced.transient.integrate import ringdown

    ringdown(DiscreteParams().system(), np.zeros(3), np.array([0.0, 0.0, 1.0]), 1e-3, 1e4, "exact")


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"local:{os.getpid()}"


def case_complete(folder: Path, case: Case) -> bool:
    """Whether ``folder`` holds a finished run of ``case``: its scene.toml is the case's and its
    provenance.json (written last, in the same atomic swap as the files) lists every stage."""
    return not _missing_stages(folder, case)


def _missing_stages(folder: Path, case: Case) -> tuple[str, ...]:
    try:
        if (folder / "scene.toml").read_text(encoding="utf-8") != case.text:
            return case.stages
        done = json.loads((folder / "provenance.json").read_text(encoding="utf-8")).get("stages", {})
    except (OSError, ValueError, AttributeError):
        return case.stages
    return tuple(s for s in case.stages if s not in done)


MESH_STAGES = ("modal", "verify")  # stages that mesh the 3-D model: gmsh needs the main thread (signals)
MAIN_THREAD_ERROR = "signal only works in main thread"


def _run_stage(scene: Scene, case: Case, stage: str, folder: Path) -> None:
    """One stage of a case, as a single run. A Dask worker runs tasks in a thread, where gmsh cannot
    start (it installs a signal handler); a stage that meshes (MESH_STAGES, or one that finds it must
    build a reduced model) then runs as ``python -m bearingshaft.cli STAGE`` in a child process."""
    import threading

    from bearingshaft.pipeline import run_stage

    if threading.current_thread() is threading.main_thread() or stage not in MESH_STAGES:
        try:
            run_stage(scene, stage, folder, progress=False)
            return
        except ValueError as exc:
            if MAIN_THREAD_ERROR not in str(exc):
                raise
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory(prefix="bearingshaft-case-") as tmp:
        path = Path(tmp) / f"{case.name}.toml"
        path.write_text(case.text, encoding="utf-8")
        proc = subprocess.run([sys.executable, "-m", "bearingshaft.cli", stage, "--scene", str(path), "--out",
                               str(folder), "--no-progress"], capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        raise RuntimeError(lines[-1] if lines else f"{stage} stage: exit code {proc.returncode}")


def run_case(case: Case, out_root: str, rom=None) -> dict:
    """Run (or find finished) one case into ``out_root/<case id>/``; its row of metrics.

    Runs on a worker. Any exception of the case becomes a row with status "failed" and its
    message in one line: a case never ends the sweep. ``rom``: the reduced model the case
    needs (scattered once; put into this worker's cache on first use).
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
    row.update(run_time_s=time.perf_counter() - t0, worker=_worker_name())
    return row




# -- metrics: the stage's own numbers -------------------------------------------------------
def _float(v) -> float:
    """A stats value as a float (the stages write some numbers as strings; '' is NaN)."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def dominant_freq_hz(y: np.ndarray, fs: float, fmin_hz: float) -> float:
    """Hz, frequency of the largest peak above ``fmin_hz`` of the Hann-windowed record y (mean removed).

    The peak of a zero-padded FFT (PAD x) is refined by maximising |sum_k w_k y_k e^{-2 pi i f k / fs}|
    over f within one padded bin. For a damped sinusoid e^{-sigma t} cos(2 pi f_d t + phi) this is f_d
    (the magnitude of the transform of the positive envelope w e^{-sigma t} peaks at zero) up to the
    leakage of the negative-frequency image, which falls as the cube of the periods in the window:
    measured 2e-5 (relative) with 9 periods, 1e-6 with 18, 3e-4 with 2 (tests/test_sweep.py).
    """
    from scipy.optimize import minimize_scalar

    y = np.asarray(y, float) - np.mean(y)
    n = y.size
    if n < 8 or not np.any(y):
        return math.nan
    w = np.hanning(n)
    yw = y * w
    nfft = PAD * (1 << int(np.ceil(np.log2(n))))
    spec = np.abs(np.fft.rfft(yw, nfft))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    ok = f >= fmin_hz
    if not np.any(ok) or not np.any(spec[ok]):
        return math.nan
    k = int(np.flatnonzero(ok)[np.argmax(spec[ok])])
    df = fs / nfft
    t = np.arange(n) / fs

    def neg(fq: float) -> float:
        return -abs(np.dot(yw, np.exp(-2j * np.pi * fq * t)))

    lo, hi = max(f[k] - df, fmin_hz), min(f[k] + df, fs / 2)
    res = minimize_scalar(neg, bounds=(lo, hi), method="bounded", options={"xatol": df * 1e-7})
    return float(res.x) if -res.fun >= spec[k] else float(f[k])


def ringdown_metrics(scene: Scene, folder: Path, stats: dict) -> dict:
    """Scalars of a ringdown from its stage's statistics and its ``ringdown.npz``.

    - ``energy_balance_error``, ``energy_J_initial``, ``contact_events`` (the event-driven solver's
      contact switches, ``n_events``; NaN for the explicit scheme): the stage's statistics;
    - ``impacts``: open -> closed transitions of the stops between samples (a contact shorter
      than a sample interval can be missed); ``peak_tip_force_N``: the largest stop force at a
      sample (sampled, so at most the true peak);
    - ``gaps_open_after_s``: the first sample after which no stop is closed (0 if none ever
      closes), NaN if a stop is still closed in the late window (the gaps may close again);
    - ``freq_early_hz``, ``freq_middle_hz``, ``freq_late_hz``: :func:`dominant_freq_hz` of the
      spectrogram's point (else x1) over the first, middle and last WINDOW_FRACTION of the record;
    - ``decay_time_s``: the first sample, after the energy's peak, with E <= DECAY_FRACTION x peak
      (NaN if not within the run);
    - with [symmetry]: the stage's seeded break time (median, min, max over its seeds),
      growth rate and runs broken, and ``energy_at_break_J``, the run's energy at that time.
    """
    from bearingshaft.stages.ringdown import FREQ_MIN_HZ
    from bearingshaft.systems import model_system
    from reduced.transient.compare import stop_closures
    from reduced.transient.store import RingdownFile

    system, P = model_system(scene.model)
    f = RingdownFile(folder / "ringdown.npz", system)
    N, fs = f.n_samples, f.sample_rate_hz
    names = scene.model.point_names
    point = names.index(scene.spectrogram.dof) if scene.spectrogram is not None else 0
    w = int(min(max(8, round(WINDOW_FRACTION * N)), MAX_WINDOW_SAMPLES, N))
    windows = {"early": 0, "middle": max(0, (N - w) // 2), "late": N - w}
    out = {"energy_balance_error": _float(stats.get("energy_balance_error")),
           "energy_J_initial": _float(stats.get("energy_J_initial")),
           "contact_events": _float(stats.get("n_events")) if "n_events" in stats else math.nan}
    for label, start in windows.items():
        y = f.read("x", start, start + w) @ P[point]
        out[f"freq_{label}_hz"] = dominant_freq_hz(y, fs, FREQ_MIN_HZ)
    impacts, closed_prev, last_closed, peak_force = 0, None, -1, 0.0
    e_peak, k_peak, k_decay = -math.inf, 0, -1
    for c in f.chunks(fields=("x", "energy")):
        n, closed_prev = stop_closures(system, c.x, closed_prev)
        impacts += n
        pen = system.penetration(c.x)
        closed = np.flatnonzero(np.any(pen > 0.0, axis=1))
        if closed.size:
            last_closed = c.start + int(closed[-1])
            peak_force = max(peak_force, float(np.max(system.stop_force(c.x))))
        E = c.energy
        j = int(np.argmax(E))
        if E[j] > e_peak:
            e_peak, k_peak, k_decay = float(E[j]), c.start + j, -1
        if k_decay < 0:
            below = np.flatnonzero(E[max(0, k_peak - c.start):] <= DECAY_FRACTION * e_peak)
            if below.size:
                k_decay = max(k_peak, c.start) + int(below[0])
    out["impacts"] = impacts
    out["peak_tip_force_N"] = peak_force
    out["gaps_open_after_s"] = (0.0 if last_closed < 0 else
                                math.nan if last_closed >= N - w or last_closed + 1 >= N else (last_closed + 1) / fs)
    out["decay_time_s"] = k_decay / fs if k_decay >= 0 else math.nan
    sym = stats.get("symmetry")
    if isinstance(sym, dict):
        seeded = sym.get("seeded", {})
        t_break = _float(seeded.get("t_break_s"))
        out.update(t_break_s=t_break, t_break_min_s=_float(seeded.get("t_break_min_s")),
                   t_break_max_s=_float(seeded.get("t_break_max_s")),
                   growth_rate_per_s=_float(seeded.get("growth_rate_per_s")),
                   runs_broken=_float(seeded.get("runs_broken")),
                   symmetry_perturbation_m=_float(seeded.get("perturbation_m")))
        k = int(round(t_break * fs)) if math.isfinite(t_break) else -1
        out["energy_at_break_J"] = float(f.read("energy", k, k + 1)[0]) if 0 <= k < N else math.nan
    return out


def hammer_metrics(scene: Scene, stats: dict) -> dict:
    """The nominal blow's summary from the hammer stage's statistics (its ``levels.csv`` row)."""
    level = stats.get("levels", {}).get(str(float(scene.hammer.peak_N)), {})
    peaks = level.get("peak_contact_N", {})
    return {"energy_balance_error": _float(level.get("energy_balance_error")),
            "impacts": _float(level.get("impacts_total")),
            "gaps_open_after_s": _float(level.get("gaps_open_after_s")),
            "peak_tip_force_N": max((_float(v) for v in peaks.values()), default=math.nan),
            "hammer_work_J": _float(level.get("hammer_work_J"))}


def frc_metrics(folder: Path) -> dict:
    """Peak amplitude and frequency of each level's HB curve, from the frc stage's frc_backbone.csv
    (the rows at damping and load scale 1: the curves of frc.csv)."""
    import csv

    out = {}
    path = folder / "frc_backbone.csv"
    if not path.exists():
        return out
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if _float(r.get("scale")) == 1.0:
                level = f"{_float(r['level']):g}N"
                out[f"frc_peak_hz_{level}"] = _float(r.get("peak_freq_hz"))
                out[f"frc_peak_m_{level}"] = _float(r.get("peak_amplitude_m"))
    return out


def _scalars(prefix: str, stats: dict) -> dict:
    """The top-level numbers of a stage's statistics (timings left out: they are not results)."""
    out = {}
    for k, v in stats.items():
        if "wall" in k or k.endswith("_s") and "time" in k:
            continue
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            out[f"{prefix}.{k}"] = float(v)
        elif isinstance(v, list) and v and len(v) <= 8 and all(isinstance(x, (int, float)) for x in v):
            out.update({f"{prefix}.{k}_{i + 1}": float(x) for i, x in enumerate(v)})
    return out


def case_metrics(scene: Scene, folder: Path) -> dict:
    """A finished case's row of scalar metrics, read from its folder (see :func:`ringdown_metrics`)."""
    prov = json.loads((folder / "provenance.json").read_text(encoding="utf-8"))
    stages = prov.get("stages", {})
    out = {}
    for stage, entry in stages.items():
        stats = entry.get("stats", {})
        if stage == "ringdown":
            out.update(ringdown_metrics(scene, folder, stats))
        elif stage == "hammer":
            out.update(hammer_metrics(scene, stats))
        elif stage == "frc":
            out.update(frc_metrics(folder))
        else:
            out.update(_scalars(stage, stats))
    return out


# -- the run ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SweepResult:
    """The rows of a sweep (design order) and where they were written."""

    rows: list[dict]
    out: Path
    wall_s: float
    workers: int
    where: str  # "LocalCluster(n)" or the scheduler's address

    @property
    def n_failed(self) -> int:
        return sum(r.get("status") != "ok" for r in self.rows)

    @property
    def n_resumed(self) -> int:
        return sum(bool(r.get("resumed")) for r in self.rows)


def local_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """(client, description): a client of the scheduler at ``scheduler``, or of a LocalCluster of
    ``workers`` single-threaded worker processes (default: one per core), closed on exit. The wait
    for a scheduler is Dask's own ``distributed.comm.timeouts.connect`` (30 s unless set, e.g.
    ``DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=2min`` for a scheduler still starting)."""
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
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        yield client, f"LocalCluster({n})"
    finally:
        client.close()
        cluster.close()


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


def run_sweep(plan: SweepPlan, out: str | Path, *, client=None, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, write: bool = True) -> SweepResult:
    """Run every case of ``plan`` on Dask into ``out``; write the tables and plots (``write``).

    ``client``: an existing :class:`distributed.Client` (kept open); else ``scheduler`` (an
    address) or a LocalCluster of ``workers`` processes, closed at the end.
    """
    from distributed import as_completed
    from tqdm import tqdm

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    previous = _previous_rows(out)
    t0 = time.perf_counter()
    rows: dict[str, dict] = {}
    with contextlib.ExitStack() as stack:
        if client is None:
            client, where = stack.enter_context(dask_client(scheduler, workers))
        else:
            where = str(getattr(client.scheduler, "address", "client"))
        n_workers = len(client.nthreads())
        client.run(_warm_up)
        roms = {}
        for key, spec in plan.shared.items():  # built once here, shipped to each worker once
            print(f"[{plan.scene.name}] sweep: reduced model built once for the sweep ({spec.n_modes} modes)",
                  flush=True)
            roms[key] = client.scatter(spec.reduced(progress), broadcast=True, hash=False)
        tag = f"{os.getpid()}-{time.time_ns()}"
        futures = {client.submit(run_case, case, str(out.absolute()), roms.get(case.shared_key),
                                 key=f"bearingshaft-case-{case.case_id}-{tag}", pure=False): case
                   for case in plan.cases}
        bar = tqdm(total=len(plan.cases), desc=f"{plan.scene.name}: sweep", unit="case", disable=not progress,
                   bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}{postfix}]")
        failed = 0
        try:
            for fut in as_completed(futures):
                case = futures[fut]
                try:
                    row = fut.result()
                except Exception as exc:  # the worker was lost too often (KilledWorker), or the task cancelled
                    row = {"case_id": case.case_id, **dict(case.values), "status": "failed", "resumed": False,
                           "message": f"worker lost: {one_line(exc)}", "run_time_s": math.nan, "worker": ""}
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
    _remove_dead_scratch(out, plan.cases)
    ordered = [rows[c.case_id] for c in plan.cases if c.case_id in rows]
    result = SweepResult(ordered, out, time.perf_counter() - t0, n_workers, where)
    if write:
        write_results(plan, result)
    return result


# -- tables ----------------------------------------------------------------------------------
FIRST = ("case_id",)
LAST = ("status", "resumed", "run_time_s", "worker", "message")


def columns(plan: SweepPlan, rows: list[dict]) -> list[str]:
    """case_id, the varied keys, every metric (in the order first seen), status and the rest."""
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


def write_tables(plan: SweepPlan, result: SweepResult) -> list[str]:
    """``sweep.parquet`` and ``sweep.csv``: one row per case, one column per key and metric."""
    import csv

    import pyarrow.parquet as pq

    cols = columns(plan, result.rows)
    table = _arrow_table(cols, result.rows)
    _replace_file(result.out / "sweep.parquet", lambda p: pq.write_table(table, p))

    def csv_file(p: Path) -> None:
        with open(p, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for r in table.to_pylist():
                w.writerow(["" if v is None or (isinstance(v, float) and math.isnan(v)) else
                            repr(v) if isinstance(v, float) else v for v in (r[c] for c in cols)])

    _replace_file(result.out / "sweep.csv", csv_file)
    return ["sweep.parquet", "sweep.csv"]


def write_results(plan: SweepPlan, result: SweepResult) -> list[str]:
    """Tables, plots, the sweep's scene and its provenance in ``result.out``."""
    from bearingshaft import __version__
    from bearingshaft.output import git_commit
    from bearingshaft.sweep_report import write_plots

    files = write_tables(plan, result)
    files += write_plots(plan, result)
    ok = [r for r in result.rows if r["status"] == "ok"]
    prov = {"scene": plan.scene.name, "source": plan.source, "design": plan.spec.design,
            "vary": {v.key: v.text for v in plan.spec.vary}, "samples": plan.spec.samples, "seed": plan.spec.seed,
            "cases": len(plan.cases), "ok": len(ok), "failed": result.n_failed, "resumed": result.n_resumed,
            "wall_s": round(result.wall_s, 3), "workers": result.workers, "where": result.where,
            # resumed rows carry the run time of the run that made them (from the earlier sweep.parquet)
            "case_run_time_s_sum": round(sum(r["run_time_s"] for r in ok if math.isfinite(r["run_time_s"] or
                                                                                             math.nan)), 3),
            "package": "bearingshaft", "version": __version__, "git_commit": git_commit(), "files": files}
    _replace_file(result.out / "sweep_provenance.json",
                  lambda p: p.write_text(json.dumps(prov, indent=2, sort_keys=True) + "\n", encoding="utf-8"))
    _replace_file(result.out / "sweep_scene.toml",
                  lambda p: p.write_text(sweep_scene_text(plan), encoding="utf-8"))
    return [*files, "sweep_provenance.json", "sweep_scene.toml"]


def sweep_scene_text(plan: SweepPlan) -> str:
    """The base scene with the [sweep] table that was run (from the scene or from --vary)."""
    import tomli_w

    data = tomllib.loads(plan.scene.source)
    s = plan.spec
    table = {"design": s.design, **({"samples": s.samples, "seed": s.seed} if s.design == "random" else {}),
             **({"plots": list(s.plots)} if s.plots else {}), **({"x": s.x} if s.x else {}),
             **({"overlay": s.overlay} if s.overlay else {}),
             # ranges as written (LO:HI:N[:log]), lists as their values
             "vary": {v.key: v.text if ":" in v.text and not v.text.startswith("[") else list(v.values)
                      for v in s.vary}}
    data["sweep"] = table
    return tomli_w.dumps(data)


# -- the command -----------------------------------------------------------------------------
def _positive_int(text: str | None, option: str, allow_zero: bool = False) -> int | None:
    if text is None:
        return None
    if not INT_PATTERN.match(str(text).strip()) or int(text) < (0 if allow_zero else 1):
        raise SweepError(f"{option}: expected an integer >= {0 if allow_zero else 1}, got {text!r}")
    return int(text)


def sweep_source(scene: Scene) -> str:
    """Where a scene's own [sweep] design comes from, as refusals name it."""
    return f"{scene.origin or scene.name} [sweep]"


def spec_from_args(scene: Scene, args) -> tuple[SweepSpec, str]:
    """The sweep's design: the scene's [sweep], with --vary replacing its keys and --design,
    --samples, --seed replacing its options."""
    base = scene.sweep if scene.sweep is not None else SweepSpec()
    source = sweep_source(scene)
    vary = base.vary
    if args.vary:
        vary = tuple(parse_vary_option(v) for v in args.vary)
        source = "--vary"
    elif scene.sweep is None:
        raise SweepError(f"{scene.origin or scene.name}: the scene has no [sweep] table; give --vary KEY=VALUES "
                         "(e.g. --vary model.g=1e-4:1e-3:9:log)")
    samples = _positive_int(args.samples, "--samples")
    seed = _positive_int(args.seed, "--seed", allow_zero=True)
    spec = dataclasses.replace(base, vary=vary, design=args.design or base.design,
                               samples=base.samples if samples is None else samples,
                               seed=base.seed if seed is None else seed)
    return check_spec(spec, source), source


def sweep_command(args, load_scene) -> int:
    """``bearingshaft sweep``: validate everything, then run; 0 if every case ran, 1 if any failed."""
    from bearingshaft.output import check_out_dir

    scene = load_scene(args.scene)
    spec, source = spec_from_args(scene, args)
    workers = _positive_int(args.workers, "--workers")
    if workers is not None and args.scheduler:
        raise SweepError("--workers sizes the local cluster; with --scheduler the cluster's own workers run")
    out = Path(args.out) if args.out else Path("results") / scene.name / "sweep"
    check_out_dir(out)
    plan = build_plan(scene, spec, source, out, None if args.scheduler else workers or local_cores())
    progress = not args.no_progress
    print(f"[{scene.name}] sweep: {len(plan.cases)} cases ({spec.design} over "
          f"{', '.join(v.key for v in spec.vary)}), stages {', '.join(case_stages(scene))}", flush=True)
    result = run_sweep(plan, out, scheduler=args.scheduler, workers=workers, progress=progress)
    n = len(result.rows)
    print(f"[{scene.name}] sweep: {n - result.n_failed} of {n} cases ok ({result.n_resumed} already done, "
          f"{result.n_failed} failed) in {out} ({result.wall_s:.1f} s on {result.where})", flush=True)
    for r in result.rows:
        if r["status"] != "ok":
            print(f"  failed {r['case_id']} ({_show_values([(v.key, r.get(v.key)) for v in spec.vary])}): "
                  f"{r['message']}", flush=True)
            break
    return 1 if result.n_failed else 0


__all__ = ["SweepSpec", "Vary", "Case", "SweepPlan", "SweepResult", "SweepError", "parse_sweep_table",
           "parse_values", "parse_vary_option", "design_points", "build_plan", "run_sweep", "run_case",
           "case_metrics", "dominant_freq_hz", "sweep_command"]
