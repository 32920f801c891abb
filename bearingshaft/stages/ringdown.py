"""Stage ``ringdown``: free response, its spectrogram with NNM overlays, symmetry breaking.

The run is streamed into ``ringdown.npz`` as it is computed and every later step (figures,
spectrogram, comparison with the exact integrator, symmetry) reads it, and any other run,
chunk by chunk: the stage's memory does not grow with the duration of the run (a ringdown
of 1e4 s works; its disk use is :func:`reduced.transient.integrate.ringdown_disk_bytes`).

Science files (CSV, npz) hold no wall-clock time: timings go to ``provenance.json``
(``writer.stats``), so a rerun of the same scene with the same code writes the same bytes.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearingshaft import plots
from bearingshaft.digits import text
from bearingshaft.estimates import MATPLOTLIB_BYTES, Estimate, n_dofs
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.progress import ProgressBar
from bearingshaft.scenes import Scene
from bearingshaft.systems import model_system, ringdown_options, scene_initial_state, scene_loads
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.loads import Loads
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.transient.compare import (
    MAX_WINDOWS,
    ComparisonAccumulator,
    LineFit,
    LyapunovAccumulator,
    aligned,
    binned,
    displaced_state,
)
from reduced.transient.exact import PIECES, stream_exact
from reduced.transient.integrate import default_chunk_samples, ringdown, ringdown_stream
from reduced.transient.result import RingdownResult, RingdownStream
from reduced.transient.spectrogram import BATCH_FLOATS, MAX_FRAMES, StftAccumulator
from reduced.transient.store import RingdownFile

REFERENCE_WINDOW_S = 0.05  # s, pointwise comparison window at the start of the run
COMPARE_WINDOW_S = 0.01  # s, windows of the separation, pointwise maxima and energy means
REFERENCE_SEEDS = 3  # exact runs displaced by LYAPUNOV_DELTA: the Lyapunov exponent and the chaotic spread
LYAPUNOV_DELTA = 1e-9  # relative size of their displacement (energy norm)
LYAPUNOV_SATURATION = 1e-3  # the separation has saturated at this fraction of the state's norm
FREQ_MIN_HZ = 5.0  # dominant frequencies are searched above this (the DC bin of a drifting record)
SYMMETRY_SEEDS = 5  # seeded runs of the symmetry study
# m, size of their antisymmetric perturbation. Measured on discrete-symmetric: seeds of 1e-12 and
# 1e-10 m still moved the break by up to 0.48 and 0.07 s when only the exact integrator's restart
# grid changed (the round-off it injects at ~1e4 contact events competes with them); from 1e-8 m
# the break time did not move (and rom-symmetric's from 1e-9 m).
SYMMETRY_PERTURBATION_M = 1e-8
BREAK_THRESHOLD_M = 1e-6  # m, the symmetry is broken once |x_a - x_b| exceeds this ("visibly")
GROWTH_BAND = 1e-2  # growth rates are fitted where BREAK_THRESHOLD_M x GROWTH_BAND < |x_a - x_b| < threshold
TITLE_NOTE = "break time from round-off alone is not reproducible across machines"


def run_ringdown(scene: Scene, system: GapSystem, P: np.ndarray, method: str, progress: bool,
                 out: str | Path | None = None) -> RingdownResult | RingdownFile:
    """The scene's ringdown of ``system`` (points P) from its initial state, by ``method``, with a
    progress bar: in memory, or streamed into the file ``out`` (returned as a RingdownFile)."""
    spec = scene.ringdown
    x0, v0 = scene_initial_state(scene, system, P)
    bar = ProgressBar(f"{scene.name}: {method}", progress)
    try:
        return ringdown(system, x0, v0, spec.duration_s, spec.sample_rate_hz, method, progress=bar, out=out,
                        **ringdown_options(scene, P))
    finally:
        bar.close()


def stream_ringdown(scene: Scene, system: GapSystem, P: np.ndarray, method: str, x0: np.ndarray, v0: np.ndarray,
                    progress=None) -> RingdownStream:
    """The scene's ringdown (with its loads) from (x0, v0) by ``method``, as a stream of chunks."""
    spec = scene.ringdown
    return ringdown_stream(system, x0, v0, spec.duration_s, spec.sample_rate_hz, method, progress=progress,
                           **ringdown_options(scene, P))


def stage_estimate(scene: Scene, n_dofs: int, n_stops: int = 4, method: str | None = None) -> dict[str, int]:
    """What the ringdown stage of ``scene`` will hold and write, before any work (for a budget check).

    Returns {"memory": bytes, "disk": bytes}. Memory: the stage streams every run, so it holds
    at most ``streams`` runs' chunks at once (:func:`ringdown_peak_bytes`, streamed: 1, or
    1 + REFERENCE_SEEDS + 1 during the reference check of a reduced model run by a method
    other than exact), one chunk read back from ringdown.npz, the spectrogram's frames
    (at most MAX_FRAMES x the rows up to fmax_hz) and ``MATPLOTLIB_BYTES``; none of it grows
    with duration_s. Disk: ringdown.npz (:func:`ringdown_disk_bytes`) plus, while the
    symmetry study runs, 8 bytes a sample for each method compared (temporary files).
    """
    from reduced.transient import store
    from reduced.transient.integrate import ringdown_disk_bytes, ringdown_peak_bytes

    spec = scene.ringdown
    method = method or spec.method
    run = ringdown_peak_bytes(n_dofs, spec.duration_s, spec.sample_rate_hz, method, n_stops=n_stops)
    exact = ringdown_peak_bytes(n_dofs, spec.duration_s, spec.sample_rate_hz, "exact", n_stops=n_stops)
    reference = scene.model_kind == "rom" and method != "exact"
    streams = run + (REFERENCE_SEEDS + 1) * exact if reference else 2 * max(run, exact)
    N = int(np.floor(spec.duration_s * spec.sample_rate_hz * (1 + 1e-12))) + 1
    read = min(store.READ_CHUNK_SAMPLES, N) * 8 * (2 * n_dofs + 3)
    frames = 0
    if scene.spectrogram is not None:
        sp = scene.spectrogram
        rows = int(min(sp.fmax_hz, spec.sample_rate_hz / 2) * sp.window_s) + 2  # bins up to Nyquist
        frames = MAX_FRAMES * rows * 8 + 4 * BATCH_FLOATS * 8  # kept frames; one FFT batch and its copies
    disk = ringdown_disk_bytes(n_dofs, spec.duration_s, spec.sample_rate_hz)
    if scene.symmetry is not None:
        disk += 8 * N * len({method, *scene.symmetry.methods})
    return {"memory": int(MATPLOTLIB_BYTES + streams + read + frames), "disk": int(disk)}


def point_series(x: np.ndarray, P: np.ndarray, names: tuple[str, ...], name: str) -> np.ndarray:
    """The displacement of point ``name`` over time from DOF histories x (n_t, n)."""
    return x @ P[names.index(name)]


def backbone_curves(model, system: GapSystem | None = None, n_modes: int = 3
                    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Frequency-energy curves to overlay: HB (H = 1) of the lowest ``n_modes`` NNMs whose linear
    modes move the gaps (an assembly's swinging on its bungees does not), and the exact NNM 2 of
    a symmetric discrete model."""
    from reduced.periodic import nnm2
    from reduced.periodic.backbones import hb_backbones

    system = model.system() if system is None else system
    curves = {f"{name}, HB H=1": c
              for name, c in hb_backbones(system, 1, modes=gap_moving_modes(system, "open", n_modes)).items()}
    if isinstance(model, DiscreteParams) and model.m1 == model.m3:
        E = np.logspace(-4, 5, 400)
        curves["NNM 2, exact"] = (E, nnm2.frequency_from_energy(model, E))
    return curves


# -- reference check: the run against the exact integrator -------------------------------------
def _spread(values: list[float]) -> tuple[float, float, float]:
    v = [x for x in values if x is not None and not math.isnan(x)]
    if not v:
        return math.nan, math.nan, math.nan
    return float(np.min(v)), float(np.median(v)), float(np.max(v))


def _displaced(scene: Scene, system: GapSystem, P: np.ndarray, x0: np.ndarray, v0: np.ndarray, k: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Seed k's start, LYAPUNOV_DELTA from (x0, v0) relative to its energy norm; a forced run from
    rest is displaced relative to the static deflection under the largest load instead."""
    if np.any(x0) or np.any(v0):
        return displaced_state(system, x0, v0, LYAPUNOV_DELTA, k)
    loads = scene_loads(scene, P)
    x_ref = np.linalg.solve(system.K, loads.b.sum(axis=0) * loads.max_abs())
    x, v = displaced_state(system, x_ref, np.zeros_like(x0), LYAPUNOV_DELTA, k)
    return x0 + (x - x_ref), v0 + v


def reference_check(scene: Scene, res: RingdownFile | RingdownResult, P: np.ndarray, writer: StageWriter,
                    progress: bool) -> dict:
    """The run against the exact integrator on the same model: ``reference.csv``, ``lyapunov.csv``.

    An impacting ringdown can be chaotic, and then a pointwise difference between two runs
    grows like exp(lambda t) whatever its origin, so it says nothing about the integrator
    beyond a few Lyapunov times. In one pass over the run, the exact run and
    ``REFERENCE_SEEDS`` exact runs displaced by ``LYAPUNOV_DELTA`` (relative, energy norm;
    :mod:`reduced.transient.compare`), this finds

    - the largest Lyapunov exponent lambda of the motion from each displaced pair (the slope
      of the log separation over its growth phase), the onset of that growth and its
      saturation: ``lyapunov.csv``;
    - for the run against the exact one *and* for each displaced exact run against the exact
      one (the spread a chaotic motion has by itself): the pointwise error at the points
      x1, x2, x3 (max |p - p_exact| / max |p_exact|) over the first REFERENCE_WINDOW_S, up to
      the onset and over the run; the energy envelope error (max over COMPARE_WINDOW_S windows
      of |mean E - mean E_exact| / mean E_exact); the fraction of spectrogram frames whose
      dominant frequency agrees within one bin; the stop closures (impacts) counted from the
      samples: ``reference.csv``, one row per quantity.

    The run is judged by whether its differences from the exact run are within the spread of
    the exact runs among themselves, not by a pointwise number over the whole run.
    """
    spec = scene.ringdown
    system, N, fs = res.system, res.n_samples, res.sample_rate_hz
    x0, v0 = scene_initial_state(scene, system, P)
    names = scene.model.point_names
    freq_point = names.index(scene.spectrogram.dof) if scene.spectrogram is not None else 0
    window = scene.spectrogram.window_s if scene.spectrogram is not None else REFERENCE_WINDOW_S
    overlap = scene.spectrogram.overlap if scene.spectrogram is not None else 0.9
    bar = ProgressBar(f"{scene.name}: exact reference", progress)
    ref = stream_ringdown(scene, system, P, "exact", x0, v0, progress=bar)
    seeds = [stream_ringdown(scene, system, P, "exact", *_displaced(scene, system, P, x0, v0, k))
             for k in range(REFERENCE_SEEDS)]

    def comparison() -> ComparisonAccumulator:
        return ComparisonAccumulator(system, N, fs, P, (REFERENCE_WINDOW_S, spec.duration_s), COMPARE_WINDOW_S,
                                     freq_point, min(window, 0.5 * (N - 1) / fs), overlap, FREQ_MIN_HZ)

    run_cmp = comparison()
    seed_cmp = [comparison() for _ in seeds]
    lyap = [LyapunovAccumulator(system, N, fs, LYAPUNOV_DELTA, LYAPUNOV_SATURATION, COMPARE_WINDOW_S) for _ in seeds]
    try:
        for run_c, ref_c, *seed_c in aligned(res.chunks(), ref, *seeds):
            run_cmp.feed(run_c, ref_c)
            for k, c in enumerate(seed_c):
                seed_cmp[k].feed(c, ref_c)
                lyap[k].feed(ref_c, c)
    finally:
        bar.close()
        for s in (ref, *seeds):
            s.close()
    run_r = run_cmp.result()
    seed_r = [c.result() for c in seed_cmp]
    est = [acc.result() for acc in lyap]
    onsets = [e.onset_s for e in est]
    onset = float(np.min(onsets))  # the earliest: before it no displaced pair has separated
    lam = _spread([e.exponent_per_s for e in est if e.chaotic])
    chaotic = any(e.chaotic for e in est)

    def row(quantity, unit, run_value, seed_values, meaning):
        lo, mid, hi = _spread(seed_values)
        return {"quantity": quantity, "unit": unit, "run_vs_exact": text(run_value),
                "exact_pairs_min": text(lo), "exact_pairs_median": text(mid), "exact_pairs_max": text(hi),
                "meaning": meaning}

    pts = "max |p - p_exact| / max |p_exact| at the points " + ", ".join(names)
    rows = [
        row("pointwise_error_first_window", "relative", run_r.pointwise_error[0],
            [r.pointwise_error[0] for r in seed_r], f"{pts} over the first {REFERENCE_WINDOW_S:g} s"),
    ]
    if math.isfinite(onset):
        rows.append(row("pointwise_error_to_onset", "relative", run_r.pointwise_error_until(onset),
                        [r.pointwise_error_until(onset) for r in seed_r],
                        f"{pts} up to {onset:g} s, when exact runs {LYAPUNOV_DELTA:g} apart start to separate"))
    rows += [
        row("pointwise_error_whole_run", "relative", run_r.pointwise_error[1], [r.pointwise_error[1] for r in seed_r],
            f"{pts} over the whole {spec.duration_s:g} s run"
            + ("; after the onset it measures the chaos of the motion, not the integrator" if chaotic else "")),
        row("energy_envelope_error", "relative", run_r.energy_envelope_error,
            [r.energy_envelope_error for r in seed_r],
            f"max over {run_r.energy_window_s:g} s windows of |mean E - mean E_exact| / mean E_exact"),
        row("dominant_frequency_agreement", "fraction of frames", run_r.freq_agreement,
            [r.freq_agreement for r in seed_r],
            f"spectrogram frames of {names[freq_point]} whose peak frequencies agree within one bin "
            f"({run_r.freq_resolution_hz:g} Hz)"),
        row("dominant_frequency_median_difference", "Hz", run_r.freq_median_diff_hz,
            [r.freq_median_diff_hz for r in seed_r], "median over frames of |f_peak - f_peak,exact|"),
        row("stop_closures_difference", "relative", run_r.closures_diff, [r.closures_diff for r in seed_r],
            f"(closures - closures_exact) / closures_exact, counted from the samples; exact: {run_r.closures_ref}"),
        row("lyapunov_exponent", "1/s", None, [e.exponent_per_s for e in est],
            f"slope of ln |y_b - y_a| over its growth phase, exact runs {LYAPUNOV_DELTA:g} apart (lyapunov.csv)"),
        row("separation_onset", "s", None, onsets,
            "when the separation of the displaced exact runs has grown 100-fold (inf: never)"),
    ]
    write_rows(writer.path("reference.csv"), rows)
    write_rows(writer.path("lyapunov.csv"), [
        {"seed": k, "delta": text(e.delta), "saturation": text(e.saturation), "window_s": text(e.window_s),
         "exponent_per_s": text(e.exponent_per_s), "lyapunov_time_s": text(e.lyapunov_time_s),
         "onset_s": text(e.onset_s), "saturation_s": text(e.saturation_s), "fit_start_s": text(e.fit_start_s),
         "fit_end_s": text(e.fit_end_s), "ln_growth_fitted": text(e.ln_growth), "residual": text(e.residual, 2),
         "chaotic": e.chaotic} for k, e in enumerate(est)])
    summary = {"run_vs_exact": {r["quantity"]: r["run_vs_exact"] for r in rows},
               "closures_run": run_r.closures_run, "closures_exact": run_r.closures_ref,
               "lyapunov_exponent_per_s": lam, "onset_s": onset, "chaotic": chaotic,
               "exact_wall_s": ref.stats.get("wall_s"), "exact_n_events": ref.stats.get("n_events"),
               "exact_tolerance_m": ref.tolerance}
    writer.stats["reference"] = summary
    sp_e = _spread([r.energy_envelope_error for r in seed_r])
    sp_f = _spread([r.freq_agreement for r in seed_r])
    sp_c = _spread([r.closures_diff for r in seed_r])
    head = (f"[{scene.name}] {res.method} against exact: pointwise error {run_r.pointwise_error[0]:.2g} over the "
            f"first {REFERENCE_WINDOW_S:g} s")
    if chaotic:
        text = (f"{head}, {run_r.pointwise_error_until(onset):.2g} up to {onset:.3g} s, when exact runs "
                f"{LYAPUNOV_DELTA:g} apart start to separate at lambda = {lam[1]:.3g} /s (Lyapunov time "
                f"{1e3 / lam[1]:.3g} ms): the motion is chaotic, so the {run_r.pointwise_error[1]:.2g} over the "
                f"{spec.duration_s:g} s run is no integrator error. Over the run (run vs exact; exact pairs): energy "
                f"envelope {run_r.energy_envelope_error:.2%} ({sp_e[0]:.2%} to {sp_e[2]:.2%}), dominant frequency "
                f"agrees in {run_r.freq_agreement:.0%} of frames ({sp_f[0]:.0%} to {sp_f[2]:.0%}), stop closures "
                f"{run_r.closures_run} vs {run_r.closures_ref} ({run_r.closures_diff:+.1%}; "
                f"{sp_c[0]:+.1%} to {sp_c[2]:+.1%})")
    else:
        text = (f"{head}, {run_r.pointwise_error[1]:.2g} over the {spec.duration_s:g} s run; exact runs "
                f"{LYAPUNOV_DELTA:g} apart do not separate (lambda = {lam[1]:.3g} /s), so the whole-run error is the "
                f"integrator's: energy envelope {run_r.energy_envelope_error:.2%}, stop closures "
                f"{run_r.closures_run} vs {run_r.closures_ref}")
    print(text, flush=True)
    return summary


# -- the stage -----------------------------------------------------------------------------
def _first_pass(res, P: np.ndarray, point: int | None, loads: Loads | None = None) -> tuple[dict, float]:
    """Envelopes of the ringdown figure and the mean of one point's series, from one pass."""
    total = [0.0]

    def add(c) -> None:
        if point is not None:
            total[0] += float(np.sum(c.x @ P[point]))

    env = plots.ringdown_envelopes(res, also=add, loads=loads)
    return env, total[0] / max(res.n_samples, 1)


def ringdown_stage(scene: Scene, writer: StageWriter, progress: bool, method: str | None = None) -> None:
    spec = scene.ringdown
    method = method or spec.method
    system, P = model_system(scene.model, progress)
    res = run_ringdown(scene, system, P, method, progress, out=writer.path("ringdown.npz"))
    names = scene.model.point_names
    sp = scene.spectrogram
    point = names.index(sp.dof) if sp is not None else None
    loads = scene_loads(scene, P)
    env, mean = _first_pass(res, P, point, loads)
    plots.ringdown_figure(res, writer.path("ringdown.png"), f"{scene.name}: {scene.description}", env, loads)
    forced = {}
    if loads is not None:
        t_W, W_ext = env["Wext"].upper()
        forced = {"loads": [f"{spec_l.kind} at {spec_l.point}" for spec_l in scene.loads],
                  "work_of_loads_J_max": float(np.max(W_ext)), "energy_J_max": env["scale"]}
    writer.stats.update(
        {"method": method, "duration_s": spec.duration_s, "energy_J_initial": env["E0"], **forced,
         "energy_balance_error": res.energy_balance_error, "n_samples": res.n_samples,
         "ringdown_npz_bytes": writer.path("ringdown.npz").stat().st_size, **res.stats}
    )
    count = res.stats.get("n_steps", res.stats.get("n_events"))
    print(f"[{scene.name}] {method}: {count} {'steps' if 'n_steps' in res.stats else 'events'}, "
          f"{res.n_samples} samples of {spec.duration_s:g} s, energy-balance error {res.energy_balance_error:.2g}"
          + (f" (with the work of the loads, {forced['work_of_loads_J_max']:.4g} J)" if forced else ""), flush=True)
    if scene.model_kind == "rom" and method != "exact":
        reference_check(scene, res, P, writer, progress)
    if sp is not None:
        acc = StftAccumulator(res.n_samples, res.sample_rate_hz, sp.window_s, sp.overlap, mean=mean,
                              fmax_hz=sp.fmax_hz, max_frames=MAX_FRAMES)
        for c in res.chunks(**({"fields": ("x",)} if isinstance(res, RingdownFile) else {})):
            acc.feed(c.start, c.x @ P[point])
        S = acc.result()
        f_open = linear_modes(system, "open").freq_hz[gap_moving_modes(system, "open", 3)]
        t_E, E = env["E"].upper()
        thinned = f", hop {S.hop / res.sample_rate_hz:.3g} s" if S.hop > round(sp.window_s * res.sample_rate_hz
                                                                                * (1 - sp.overlap)) + 1 else ""
        plots.spectrogram_figure(
            S, (t_E, E[:, 0]), backbone_curves(scene.model, system), writer.path("spectrogram.png"),
            f"{scene.name}: spectrogram of {sp.dof} ({method}{thinned}); open-gap "
            f"{', '.join(f'{f:.1f}' for f in f_open)} Hz",
            sp.fmax_hz, sp.db_range,
        )
    if scene.symmetry is not None:
        symmetry_stage(scene, res, P, writer, progress)


# -- symmetry breaking -----------------------------------------------------------------------
class _Asymmetry:
    """|x_a - x_b| of one run, chunk by chunk: envelope, first exceedances, growth fit in a band."""

    def __init__(self, n_samples: int, fs: float, threshold: float, band: tuple[float, float]) -> None:
        self.env = plots.Envelope(n_samples, fs, 1)
        self.threshold = threshold
        self.band = band
        self.t_break = None
        self.k_break = n_samples  # samples before the break
        duration = (n_samples - 1) / fs
        self.per = max(1, int(round(max(COMPARE_WINDOW_S, duration / MAX_WINDOWS) * fs)))  # growth-fit windows
        self.fs = fs
        self.wmax = np.zeros(-(-n_samples // self.per))  # max d in each window, up to the break

    def feed(self, start: int, t: np.ndarray, d: np.ndarray) -> bool:
        """Returns True once the threshold has been crossed."""
        self.env.add(start, d)
        if self.t_break is None:
            over = np.flatnonzero(d > self.threshold)
            k = int(over[0]) if over.size else d.size
            if k:
                b, m = binned(np.maximum, d[:k], start, self.per)
                self.wmax[b : b + m.size] = np.maximum(self.wmax[b : b + m.size], m)
            if over.size:
                self.t_break = float(t[k])
                self.k_break = start + k
        return self.t_break is not None

    @property
    def growth_rate(self) -> float:
        """1/s, slope of ln (window max of d) over the whole windows inside the band before the break."""
        m = self.wmax[: self.k_break // self.per]
        w = np.flatnonzero((m > self.band[0]) & (m < self.band[1]))
        fit = LineFit()
        fit.add((w + 0.5) * self.per / self.fs, np.log(m[w]))
        return fit.slope if fit.n >= 3 else math.nan


def _first_exceedance(d_file: Path, fs: float, threshold: float, chunk: int) -> float | None:
    """s, first sample of the float64 file ``d_file`` above threshold (None if none)."""
    with open(d_file, "rb") as fh:
        start = 0
        while True:
            d = np.fromfile(fh, dtype=np.float64, count=chunk)
            if d.size == 0:
                return None
            over = np.flatnonzero(d > threshold)
            if over.size:
                return float((start + over[0]) / fs)
            start += d.size


def _seed_perturbation(k: int, names: tuple[str, ...], pair: tuple[str, str], size_m: float, omega: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Point perturbations (dx, dv) of seed k: +-size_m (cos theta, omega sin theta) at the pair's two
    points (antisymmetric), theta uniform in [0, 2 pi) from ``np.random.default_rng(k)``."""
    theta = np.random.default_rng(k).uniform(0.0, 2.0 * np.pi)
    dx, dv = np.zeros(len(names)), np.zeros(len(names))
    ia, ib = names.index(pair[0]), names.index(pair[1])
    dx[ia], dx[ib] = size_m * np.cos(theta), -size_m * np.cos(theta)
    dv[ia], dv[ib] = size_m * omega * np.sin(theta), -size_m * omega * np.sin(theta)
    return dx, dv


def symmetry_stage(scene: Scene, res: RingdownFile | RingdownResult, P: np.ndarray, writer: StageWriter,
                   progress: bool) -> None:
    """Fig. 4: the symmetric motion's loss of symmetry, led by what is reproducible.

    The symmetric motion is transversally unstable (results/discrete-fep/symmetry.md): any
    asymmetry grows like exp(int lambda dt), and the time it takes to become visible is set by
    the size of the seed. With round-off as the only seed that time depends on the machine,
    the compiler and the order of operations (0.314 s committed, 0.138 s on another machine),
    so the stage leads with what does not: the break time and growth rate over
    ``SYMMETRY_SEEDS`` exact runs seeded with an antisymmetric perturbation of size
    ``SYMMETRY_PERTURBATION_M`` at the pair's points (+-, random phase between displacement
    and velocity), large enough that round-off does not move the break (checked in every
    run: seed 0 is repeated with the closed form restarted on another grid, i.e. another
    round-off history, column ``t_break_seed0_other_roundoff_s``). A run has broken when
    |x_a - x_b| exceeds ``BREAK_THRESHOLD_M``; growth rates are the least-squares slope of
    ln |x_a - x_b| (maxima over COMPARE_WINDOW_S windows) between GROWTH_BAND x that threshold
    and the threshold, i.e. over the last decades before the break (the transverse exponent
    changes with the energy, so a round-off run, which gets there later, shows a different
    rate). The round-off runs of each method follow, with the old criterion (|x_a - x_b| above
    the method's own tolerance), marked not reproducible. Files: ``symmetry.csv`` (one row per
    case), ``symmetry_seeds.csv`` (one row per seed).
    """
    names = scene.model.point_names
    pair = scene.symmetry.dofs
    pa, pb = (P[names.index(n)] for n in pair)
    system, N, fs = res.system, res.n_samples, res.sample_rate_hz
    band = (BREAK_THRESHOLD_M * GROWTH_BAND, BREAK_THRESHOLD_M)
    chunk = default_chunk_samples(system.n)
    points = plots.Envelope(N, fs, 2)
    runs: dict[str, tuple[_Asymmetry, float]] = {}
    with tempfile.TemporaryDirectory(dir=writer.scratch, prefix=".asym-") as tmp:
        files = {}

        def follow(method: str, chunks) -> tuple[_Asymmetry, Path]:
            a = _Asymmetry(N, fs, BREAK_THRESHOLD_M, band)
            path = Path(tmp) / f"{method}.f8"
            with open(path, "wb") as fh:
                for c in chunks:
                    d = np.abs(c.x @ (pa - pb))
                    a.feed(c.start, c.t, d)
                    d.tofile(fh)
                    if method == res.method:
                        points.add(c.start, np.column_stack([c.x @ pa, c.x @ pb]))
            return a, path

        a, files[res.method] = follow(res.method, res.chunks(chunk, **({"fields": ("x",)} if isinstance(
            res, RingdownFile) else {})))
        runs[res.method] = (a, res.tolerance)
        x0, v0 = scene_initial_state(scene, system, P)
        for other in scene.symmetry.methods:
            if other in runs:
                continue
            bar = ProgressBar(f"{scene.name}: {other}", progress)
            stream = stream_ringdown(scene, system, P, other, x0, v0, progress=bar)
            try:
                a, files[other] = follow(other, stream)
            finally:
                bar.close()
            runs[other] = (a, stream.tolerance)
            writer.stats.setdefault("symmetry_wall_s", {})[other] = stream.stats.get("wall_s")
        t_tol = {m: _first_exceedance(files[m], fs, tol, chunk) for m, (_, tol) in runs.items()}

    # seeded exact runs, each followed until it breaks
    omega = float(linear_modes(system, "open").omega[gap_moving_modes(system, "open", 1)[0]])
    spec = scene.ringdown
    loads = scene_loads(scene, P)

    def seeded_run(k: int, pieces: int = PIECES) -> _Asymmetry:
        dx, dv = _seed_perturbation(k, names, pair, SYMMETRY_PERTURBATION_M, omega)
        x0, v0 = scene_initial_state(scene, system, P, dx, dv)
        stream = stream_exact(system, x0, v0, spec.duration_s, spec.sample_rate_hz, chunks=pieces,
                              chunk_samples=chunk, **({"loads": loads} if loads is not None else {}))
        a = _Asymmetry(N, fs, BREAK_THRESHOLD_M, band)
        try:
            for c in stream:
                if a.feed(c.start, c.t, np.abs(c.x @ (pa - pb))):
                    break
        finally:
            stream.close()
        return a

    seeded, seed_rows = [], []
    for k in range(SYMMETRY_SEEDS):
        a = seeded_run(k)
        seeded.append(a)
        seed_rows.append({"seed": k, "perturbation_m": text(SYMMETRY_PERTURBATION_M),
                          "theta_rad": text(float(np.random.default_rng(k).uniform(0.0, 2.0 * np.pi))),
                          "break_threshold_m": text(BREAK_THRESHOLD_M), "t_break_s": text(a.t_break, 6),
                          "growth_rate_per_s": text(a.growth_rate, 3)})
    write_rows(writer.path("symmetry_seeds.csv"), seed_rows)
    # seed 0 again with the closed form restarted on another grid: another round-off history (as on
    # another machine); the same break time shows that the seed, not round-off, sets it
    restarted = seeded_run(0, PIECES + 7).t_break

    rates = _spread([a.growth_rate for a in seeded])
    breaks = _spread([a.t_break if a.t_break is not None else math.nan for a in seeded])
    n_broken = sum(a.t_break is not None for a in seeded)
    rows = [{"case": "seeded", "method": "exact", "perturbation_m": text(SYMMETRY_PERTURBATION_M),
             "runs": SYMMETRY_SEEDS, "growth_rate_per_s": text(rates[1], 3), "growth_rate_min_per_s": text(rates[0], 3),
             "growth_rate_max_per_s": text(rates[2], 3), "break_threshold_m": text(BREAK_THRESHOLD_M),
             "runs_broken": n_broken, "t_break_s": text(breaks[1], 6), "t_break_min_s": text(breaks[0], 6),
             "t_break_max_s": text(breaks[2], 6), "growth_fit_band_m": f"{band[0]:g} to {band[1]:g}",
             "t_break_seed0_other_roundoff_s": text(restarted, 6), "tolerance_m": "", "t_exceeds_tolerance_s": "",
             "reproducible_across_machines": "yes (the spread over seeds is the uncertainty)"}]
    for method, (a, tol) in runs.items():
        rows.append({"case": "round-off", "method": method, "perturbation_m": 0, "runs": 1,
                     "growth_rate_per_s": text(a.growth_rate, 3), "growth_rate_min_per_s": "",
                     "growth_rate_max_per_s": "", "break_threshold_m": text(BREAK_THRESHOLD_M),
                     "runs_broken": int(a.t_break is not None), "t_break_s": text(a.t_break, 6), "t_break_min_s": "",
                     "t_break_max_s": "", "growth_fit_band_m": f"{band[0]:g} to {band[1]:g}",
                     "t_break_seed0_other_roundoff_s": "", "tolerance_m": text(tol, 2),
                     "t_exceeds_tolerance_s": text(t_tol[method], 6),
                     "reproducible_across_machines":
                         "no: round-off sets the break time and so the phase where the rate is fitted"})
    write_rows(writer.path("symmetry.csv"), rows)
    seeds_text = (f"seeded ({SYMMETRY_SEEDS} x {SYMMETRY_PERTURBATION_M:g} m, antisymmetric): growth "
                  f"{rates[1]:.3g}/s [{rates[0]:.3g}, {rates[2]:.3g}], break at {BREAK_THRESHOLD_M:g} m: "
                  f"{breaks[1]:.3g} s [{breaks[0]:.3g}, {breaks[2]:.3g}] ({n_broken} of {SYMMETRY_SEEDS} broke)")
    plots.symmetry_figure(
        points, pair, res.method,
        {m: (a.env, tol, a.t_break) for m, (a, tol) in runs.items()}, [a.env for a in seeded], BREAK_THRESHOLD_M,
        writer.path("symmetry.png"),
        f"{scene.name}: symmetry breaking of {pair[0]} and {pair[1]}; {seeds_text}; the {TITLE_NOTE}",
    )
    writer.stats["symmetry"] = {"seeded": rows[0], "round_off": rows[1:], "seeds": seed_rows}
    roundoff = ", ".join(f"{m} {text(a.t_break, 4) or 'none'} s" for m, (a, _) in runs.items())
    print(f"[{scene.name}] symmetry: {seeds_text}; seed 0 with another round-off: {text(restarted, 4)} s; "
          f"from round-off alone (not reproducible across machines): {roundoff}", flush=True)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Integrate the scene's model from its initial state (with its [[load]] forces, if any) by the
exact, explicit or DOP853 integrator, streamed to disk. Writes ringdown.npz (time, states,
energies), ringdown.png, with [spectrogram] spectrogram.png and spectrogram.npz (NNM backbones
overlaid), with [symmetry] symmetry.png and symmetry.csv, a comparison with the exact
integrator (reference_check.csv) and ringdown.csv of its statistics."""


def estimate(scene: Scene) -> list[Estimate]:
    """The streamed run's chunks, the spectrogram's frames and the figures; disk: ringdown.npz."""
    r = scene.ringdown
    est = stage_estimate(scene, n_dofs(scene))
    samples = r.duration_s * r.sample_rate_hz + 1
    return [Estimate("ringdown", est["memory"], f"{samples:.3g} samples streamed to disk in chunks",
                     "[ringdown] duration_s or sample_rate_hz", disk=est["disk"])]


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir, method: str | None = None) -> _Pending:
    return _Pending(scene, progress, {"method": method})


def write(result: _Pending, writer: StageWriter) -> None:
    ringdown_stage(result.scene, writer, result.progress, **result.options)
