"""The numbers of a sweep: a finished case's row of scalar metrics, and the NNM stability overlay.

A case's row is read from what its stages wrote (:func:`case_metrics`): the ``provenance.json``
statistics and the stage's own files; nothing is recomputed but the ringdown's windowed
frequencies, impacts and decay, read from its ``ringdown.npz``. The overlay
(``[sweep] overlay = "nnm_stability"``) is the one number of a sweep that is not a case's: the
Floquet stability of the symmetric NNMs over the swept energies, by shooting
(:func:`nnm_stability`), computed once all cases are in (:func:`sweep_overlay`).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearingshaft.scenes import Scene
from bearingshaft.stages.ringdown import FREQ_MIN_HZ, SYMMETRY_SEEDS
from bearingshaft.systems import model_system
from reduced.transient.compare import stop_closures
from reduced.transient.spectral import dominant_freq_hz
from reduced.transient.store import RingdownFile

# metrics of a ringdown (see ringdown_metrics)
WINDOW_FRACTION = 1 / 8  # early, middle and late windows of the dominant frequency: each 1/8 of the record
MAX_WINDOW_SAMPLES = 1 << 18  # and at most this many samples
DECAY_FRACTION = 1e-2  # decay time: the energy first falls to 1 % of its peak (20 dB of amplitude)
# the NNM stability overlay
STABILITY_ENERGIES = 40  # energies of the overlay (log-spaced over the sweep's range)
UNSTABLE = 1.0 + 1e-6  # |mu|max above this: unstable (shooting's multipliers are good to ~1e-12 here)
STABILITY_FIELDS = ["nnm", "energy_J", "found", "freq_hz", "max_abs_mu", "stable", "unstable_eigvec"]


def _float(v) -> float:
    """A stats value as a float (the stages write some numbers as strings; '' is NaN).

    >>> _float("2.5"), _float(3), _float("")
    (2.5, 3.0, nan)
    """
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _windows(n_samples: int) -> tuple[int, dict[str, int]]:
    """(w, {label: first sample}): the early, middle and late windows of the dominant frequency.

    >>> _windows(8001)
    (1000, {'early': 0, 'middle': 3500, 'late': 7001})
    """
    w = int(min(max(8, round(WINDOW_FRACTION * n_samples)), MAX_WINDOW_SAMPLES, n_samples))
    return w, {"early": 0, "middle": max(0, (n_samples - w) // 2), "late": n_samples - w}


def _contacts_and_decay(system, f: RingdownFile) -> tuple[int, float, int, int]:
    """(impacts, peak stop force, last sample with a stop closed or -1, first sample after the
    energy's peak with E <= DECAY_FRACTION x peak or -1), in one pass over the record's chunks."""
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
    return impacts, peak_force, last_closed, k_decay


def _symmetry_metrics(sym: dict, f: RingdownFile) -> dict:
    """The seeded symmetry break of the ringdown stage's statistics, and the energy at that time."""
    seeded = sym.get("seeded", {})
    t_break = _float(seeded.get("t_break_s"))
    out = {"t_break_s": t_break, "t_break_min_s": _float(seeded.get("t_break_min_s")),
           "t_break_max_s": _float(seeded.get("t_break_max_s")),
           "growth_rate_per_s": _float(seeded.get("growth_rate_per_s")),
           "runs_broken": _float(seeded.get("runs_broken")),
           "symmetry_perturbation_m": _float(seeded.get("perturbation_m"))}
    fs, N = f.sample_rate_hz, f.n_samples
    k = int(round(t_break * fs)) if math.isfinite(t_break) else -1
    out["energy_at_break_J"] = float(f.read("energy", k, k + 1)[0]) if 0 <= k < N else math.nan
    return out


def ringdown_metrics(scene: Scene, folder: Path, stats: dict) -> dict:
    """Scalars of a ringdown from its stage's statistics and its ``ringdown.npz``.

    - ``energy_balance_error``, ``energy_J_initial``, ``contact_events`` (the event-driven solver's
      contact switches, ``n_events``; NaN for the explicit scheme): the stage's statistics;
    - ``impacts``: open -> closed transitions of the stops between samples (a contact shorter
      than a sample interval can be missed); ``peak_tip_force_N``: the largest stop force at a
      sample (sampled, so at most the true peak);
    - ``gaps_open_after_s``: the first sample after which no stop is closed (0 if none ever
      closes), NaN if a stop is still closed in the late window (the gaps may close again);
    - ``freq_early_hz``, ``freq_middle_hz``, ``freq_late_hz``: the dominant frequency
      (:func:`reduced.transient.spectral.dominant_freq_hz`, above FREQ_MIN_HZ) of the
      spectrogram's point (else x1) over the first, middle and last WINDOW_FRACTION of the record;
    - ``decay_time_s``: the first sample, after the energy's peak, with E <= DECAY_FRACTION x peak
      (NaN if not within the run);
    - for a model with a friction coefficient (``model.mu``; 0 without sliders): ``friction_work_J``,
      the work the tips' friction took over the run (closed form, the ringdown's ``friction``
      history at its end), and ``friction_work_fraction``, that work over the initial energy;
    - with [symmetry]: the stage's seeded break time (median, min, max over its seeds),
      growth rate and runs broken, and ``energy_at_break_J``, the run's energy at that time.

    Parameters
    ----------
    scene : the case's scene
    folder : the case's folder (its ``ringdown.npz``)
    stats : the ringdown stage's statistics (its ``provenance.json`` entry)

    Returns
    -------
    {metric: number} in the order above.
    """
    system, P = model_system(scene.model)
    f = RingdownFile(folder / "ringdown.npz", system)
    N, fs = f.n_samples, f.sample_rate_hz
    names = scene.model.point_names
    point = names.index(scene.spectrogram.dof) if scene.spectrogram is not None else 0
    w, windows = _windows(N)
    out = {"energy_balance_error": _float(stats.get("energy_balance_error")),
           "energy_J_initial": _float(stats.get("energy_J_initial")),
           "contact_events": _float(stats.get("n_events")) if "n_events" in stats else math.nan}
    for label, start in windows.items():
        y = f.read("x", start, start + w) @ P[point]
        out[f"freq_{label}_hz"] = dominant_freq_hz(y, fs, FREQ_MIN_HZ)
    impacts, peak_force, last_closed, k_decay = _contacts_and_decay(system, f)
    out["impacts"] = impacts
    out["peak_tip_force_N"] = peak_force
    out["gaps_open_after_s"] = (0.0 if last_closed < 0 else
                                math.nan if last_closed >= N - w or last_closed + 1 >= N else (last_closed + 1) / fs)
    out["decay_time_s"] = k_decay / fs if k_decay >= 0 else math.nan
    if getattr(scene.model, "mu", None) is not None:
        w_fric = float(f.read("friction", N - 1, N)[0]) if N and f.has("friction") else 0.0
        e0 = out["energy_J_initial"]
        out["friction_work_J"] = w_fric
        out["friction_work_fraction"] = w_fric / e0 if e0 > 0 else math.nan
    sym = stats.get("symmetry")
    if isinstance(sym, dict):
        out.update(_symmetry_metrics(sym, f))
    return out


def hammer_metrics(scene: Scene, stats: dict) -> dict:
    """The nominal blow's summary from the hammer stage's statistics (its ``levels.csv`` row).

    Parameters
    ----------
    scene : the case's scene (its ``[hammer] peak_N`` names the nominal blow)
    stats : the hammer stage's statistics

    Returns
    -------
    {metric: number}: energy balance, impacts, gaps-open time, peak tip force, hammer work.
    """
    level = stats.get("levels", {}).get(str(float(scene.hammer.peak_N)), {})
    peaks = level.get("peak_contact_N", {})
    return {"energy_balance_error": _float(level.get("energy_balance_error")),
            "impacts": _float(level.get("impacts_total")),
            "gaps_open_after_s": _float(level.get("gaps_open_after_s")),
            "peak_tip_force_N": max((_float(v) for v in peaks.values()), default=math.nan),
            "hammer_work_J": _float(level.get("hammer_work_J"))}


def frc_metrics(folder: Path) -> dict:
    """Peak amplitude and frequency of each level's HB curve, from the frc stage's ``frc_backbone.csv``.

    Parameters
    ----------
    folder : the case's folder

    Returns
    -------
    {``frc_peak_hz_<level>N``, ``frc_peak_m_<level>N``: number} from the rows at damping and load
    scale 1 (the curves of frc.csv); empty when the file is not there.
    """
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
    """The top-level numbers of a stage's statistics (timings left out: they are not results).

    >>> _scalars("nnm", {"n_orbits": 12, "wall_s": 3.0, "freqs": [1, 2], "name": "x"})
    {'nnm.n_orbits': 12.0, 'nnm.freqs_1': 1.0, 'nnm.freqs_2': 2.0}
    """
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
    """A finished case's row of scalar metrics, read from its folder.

    Parameters
    ----------
    scene : the case's scene
    folder : the case's folder, every stage in its ``provenance.json``

    Returns
    -------
    {metric: number}: :func:`ringdown_metrics`, :func:`hammer_metrics`, :func:`frc_metrics`, and
    for any other stage the top-level numbers of its statistics (``<stage>.<key>``).
    """
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


# -- the NNM stability overlay ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class NnmStability:
    """The overlay of a sweep over energies: NNM 1 and 3 stability rows (STABILITY_FIELDS).

    Attributes
    ----------
    rows : list of dict
        One per NNM and energy, NNM 1 first (:func:`nnm_stability`).
    symmetry_seeds : int
        Seeded runs of each case's symmetry study (the figure's title says it).
    """

    rows: list[dict]  # one per NNM and energy, NNM 1 first (:func:`nnm_stability`)
    symmetry_seeds: int  # seeded runs of each case's symmetry study (the figure's title says it)


def nnm_stability(model, energy_min_J: float, energy_max_J: float, n: int = STABILITY_ENERGIES) -> list[dict]:
    """Floquet stability of NNM 1 and NNM 3 (the 3-DOF model's symmetric NNMs) at ``n`` log-spaced energies.

    The largest multiplier of each orbit found by shooting on the exact flow of the undamped
    model (:func:`reduced.periodic.shooting.floquet_scan`, guided by the HB H = 1 branch) and
    whether its eigenvector is symmetric (x1 = x3) or antisymmetric (x1 = -x3,
    :func:`reduced.periodic.shooting.mirror_mode`): an antisymmetrically unstable orbit is one
    the symmetric motion leaves.

    Parameters
    ----------
    model : the discrete model's parameters (``DiscreteParams``)
    energy_min_J, energy_max_J : J, the range of energies
    n : energies, log-spaced over the range

    Returns
    -------
    Rows of STABILITY_FIELDS, NNM 1's energies then NNM 3's; an energy where shooting finds no
    orbit is a row with ``found`` = 0 and the other fields empty.
    """
    from reduced.periodic.shooting import floquet_scan, mirror_mode

    E = np.geomspace(energy_min_J, energy_max_J, n)
    rows = []
    for mode, orbits in floquet_scan(model.system(), (0, 2), E).items():
        for e, o in zip(E, orbits, strict=True):
            if o is None:
                rows.append({"nnm": mode + 1, "energy_J": float(e), "found": 0, "freq_hz": "", "max_abs_mu": "",
                             "stable": "", "unstable_eigvec": ""})
                continue
            unstable = o.max_multiplier > UNSTABLE
            rows.append({"nnm": mode + 1, "energy_J": float(o.energy_J), "found": 1, "freq_hz": float(o.freq_hz),
                         "max_abs_mu": float(o.max_multiplier), "stable": int(not unstable),
                         "unstable_eigvec": mirror_mode(o) if unstable else ""})
    return rows


def sweep_overlay(plan, rows: list[dict]) -> NnmStability | None:
    """The overlay a sweep asks for (``[sweep] overlay``), over the energies its cases reached.

    Parameters
    ----------
    plan : the :class:`~bearingshaft.sweep.plan.SweepPlan`
    rows : the cases' rows

    Returns
    -------
    :class:`NnmStability` over the range of the ok cases' ``energy_J_initial`` for
    ``overlay = "nnm_stability"`` on a discrete model; None when there is no overlay, no ok
    case or no positive initial energy.
    """
    if plan.spec.overlay != "nnm_stability" or plan.scene.model_kind != "discrete":
        return None
    E0 = np.array([r.get("energy_J_initial", np.nan) for r in rows if r.get("status") == "ok"], float)
    E0 = E0[np.isfinite(E0) & (E0 > 0)]
    if not E0.size:
        return None
    return NnmStability(nnm_stability(plan.scene.model, float(np.min(E0)), float(np.max(E0))), SYMMETRY_SEEDS)
