"""What one fit needs and what one model run at trial parameters gives: the problem, the target,
the evaluation (runs on a Dask worker as well as here).

A :class:`Problem` holds the reduced apparatus, its rig, the scene, the measured test (read by
:func:`bearingshaft.measured.read_test`: its hammer channel through the force window drives the
model) and the parameters. :func:`record_at` runs the model at trial values theta over the fitted
window at the test's sampling, as ``bearingshaft hammer --test`` does
(:func:`bearingshaft.stages.hammer.run_record`: the exact integrator, the DAQ's anti-alias
filter); :func:`evaluate` turns that into the residual blocks
(:mod:`bearingshaft.identify.residuals`). :func:`define_target` fixes what the blocks measure where
(the compared channels, their floors, the predictability horizon at theta), once per pass.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from bearingshaft import correlate, measured
from bearingshaft.identify.parameters import Parameter, with_values
from bearingshaft.identify.residuals import RIDGE_OVERLAP, Target, blocks
from bearingshaft.measured import MeasuredTest
from bearingshaft.measures import CONTACT_QUANTITY
from bearingshaft.scenes import Scene
from bearingshaft.stages.hammer import run_record
from bearingshaft.stages.hammer_results import Record, histories
from reduced.models.gaps import GapSystem
from reduced.models.rig import VirtualRig

MIN_TIME_SPAN_S = 5e-3  # s, the pointwise block covers at least this much past the blow's end (module docstring
# of bearingshaft.identify.fit: at a first guess the horizon can end at the blow)


@dataclass(frozen=True, eq=False)
class Problem:
    """Everything a model run at trial parameters needs (shipped once to each worker).

    Attributes
    ----------
    scene : Scene
        The scene ([model], [hammer], [ringdown], [identify]).
    rom : ReducedModel
        The reduced apparatus (its contact and damping are set per run).
    rig : VirtualRig
        The rig at the scene's values, with ``n_modes`` fixed-interface modes.
    test : MeasuredTest
        The measured test.
    parameters : tuple of Parameter
        What is fitted.
    window_s : (float, float)
        s, the fitted window.
    names : tuple of str
        The compared channels.
    n_keep : int
        Coordinates of the reduced model kept: x1, x3 and the lowest ``n_modes`` modes.
    """

    scene: Scene
    rom: object
    rig: VirtualRig
    test: MeasuredTest
    parameters: tuple[Parameter, ...]
    window_s: tuple[float, float]
    names: tuple[str, ...]
    n_keep: int

    def values(self, theta) -> dict[str, float]:
        """{key: value} at scaled ``theta``."""
        return {p.key: p.value(float(t)) for p, t in zip(self.parameters, theta, strict=True)}

    @property
    def theta0(self) -> np.ndarray:
        return np.zeros(len(self.parameters)) if all(p.scale == "log" for p in self.parameters) else \
            np.array([p.theta(p.initial) for p in self.parameters])


def truncated(system: GapSystem, n: int) -> GapSystem:
    """``system`` on its first ``n`` coordinates (x1, x3 and the lowest n - 2 fixed-interface modes:
    the same as a reduction built with that many modes).

    Parameters
    ----------
    system : GapSystem
    n : int
        Coordinates kept.
    """
    if n >= system.n:
        return system
    s = slice(0, n)
    return replace(system, M=system.M[s, s], C=system.C[s, s], K=system.K[s, s], B=system.B[:, s],
                   dof_names=system.dof_names[:n])


def rig_at(problem: Problem, values: dict) -> VirtualRig:
    """The rig with the parameters at ``values`` ({key: value}; the others the scene's).

    Parameters
    ----------
    problem : Problem
    values : dict
        {key: value} of the fitted parameters.
    """
    spec = with_values(problem.scene.model, values)
    system = truncated(problem.rom.with_contact(spec).system(), problem.n_keep)
    return replace(problem.rig, system=system)


def make_problem(scene: Scene, rom, rig: VirtualRig, test: MeasuredTest, parameters, window_s,
                 names: tuple[str, ...]) -> Problem:
    """The :class:`Problem`, the rig cut to [identify] n_modes (0: every mode).

    Parameters
    ----------
    scene, rom, rig, test, parameters, window_s, names
        As :class:`Problem` holds them (``rig`` with every mode).

    Returns
    -------
    Problem
    """
    n_modes = scene.identify.n_modes
    n_keep = rig.system.n if n_modes == 0 else min(rig.system.n, 2 + n_modes)
    s = slice(0, n_keep)
    cut = replace(rig, system=truncated(rig.system, n_keep), acc_rows=rig.acc_rows[:, s],
                  seat_rows=rig.seat_rows[:, s], b=rig.b[s])
    return Problem(scene, rom, cut, test, tuple(parameters), (float(window_s[0]), float(window_s[1])), names, n_keep)


def hammer_noise(test: MeasuredTest) -> float:
    """N, the hammer channel's RMS before the blow (its noise; 0 without a pre-trigger).

    Parameters
    ----------
    test : MeasuredTest
    """
    ref = test.channels[correlate.check_test_channels(test.channels)]
    end = test.pulse_start_s - test.window.margin_s
    k = int(end / ref.dt_s)
    return float(np.sqrt(np.mean(ref.data[:k] ** 2))) if k >= 2 else 0.0


def redrawn_force(test: MeasuredTest, seed: int):
    """The test's driving force with its samples in the force window (all, without one) redrawn within the
    hammer's noise: plus white noise of :func:`hammer_noise`'s RMS (:mod:`bearingshaft.identify.scatter`).

    Parameters
    ----------
    test : MeasuredTest
    seed : int

    Returns
    -------
    Tabulated
    """
    from reduced.models.loads import Tabulated

    sig = test.signal
    t, f = np.asarray(sig.t_s, float), np.asarray(sig.force_N, float)
    a, b = test.window.window_s if test.windowed else (-np.inf, np.inf)
    inside = (t >= a) & (t <= b)
    e = np.random.default_rng(seed).standard_normal(t.size)
    return Tabulated(t, f + hammer_noise(test) * e * inside, source=f"{sig.source}, redrawn ({seed})")


def record_at(problem: Problem, theta, force_seed: int | None = None) -> tuple[VirtualRig, Record]:
    """The model at ``theta`` over the fitted window at the test's sampling, driven by its force.

    Parameters
    ----------
    problem : Problem
    theta : (p,) array_like of float
        Scaled parameters.
    force_seed : int, optional
        Drive it with the force redrawn within the hammer's noise (:func:`redrawn_force`).

    Returns
    -------
    (VirtualRig, Record)
    """
    test = problem.test
    rig = rig_at(problem, problem.values(theta))
    n = int(round(problem.window_s[1] * test.sample_rate_hz))
    force = test.signal if force_seed is None else redrawn_force(test, force_seed)
    rec = run_record(rig, force, problem.scene, test.level_N, duration_s=n / test.sample_rate_hz,
                     sample_rate_hz=test.sample_rate_hz)
    return rig, rec


def model_channels(problem: Problem, rig: VirtualRig, rec: Record) -> list:
    """The compared channels of a record, as TimeHistory, in ``problem.names`` order.

    Parameters
    ----------
    problem : Problem
    rig : VirtualRig
    rec : Record
        A run of ``rig``.
    """
    by = {h.name: h for h in histories(rig, rec.t, rec.data)}
    return [by[n] for n in problem.names]


def channels_at(problem: Problem, theta) -> tuple[np.ndarray, np.ndarray]:
    """(t, data): the compared channels (``problem.names`` order, rows) of the model at ``theta`` (a worker
    runs it for the overlays).

    Parameters
    ----------
    problem : Problem
    theta : (p,) array_like of float
        Scaled parameters.
    """
    rig, rec = record_at(problem, theta)
    rows = [list(rig.names).index(n) for n in problem.names]
    return rec.t, rec.data[rows]


@dataclass(frozen=True, eq=False)
class Evaluation:
    """One model run's residuals.

    Attributes
    ----------
    theta : (p,) ndarray of float
        Where (scaled).
    blocks : dict
        {block: (series, points) ndarray}.
    stats : dict
        ``wall_s``, ``cpu_s``, ``n_events`` of the run, ``worker``.
    noise_var : dict
        {block: variances from the test's noise} (:func:`bearingshaft.identify.scatter.noise_variance`;
        empty unless asked).
    noise_draws : dict
        {block: (draws, n_b) the noise draws' residuals less their mean} (the same; blocks not too large).
    """

    theta: np.ndarray
    blocks: dict
    stats: dict
    noise_var: dict = field(default_factory=dict)
    noise_draws: dict = field(default_factory=dict)


def evaluate(problem: Problem, target: Target, theta, force_seed: int | None = None,
             noise_draws: int = 0) -> Evaluation:
    """The residual blocks of the model at ``theta`` against the test (runs on a worker).

    Parameters
    ----------
    problem : Problem
    target : Target
    theta : (p,) array_like of float
    force_seed : int, optional
        The force redrawn within the hammer's noise (:func:`record_at`).
    noise_draws : int
        Also the residuals' variances from the test's noise, from this many draws (0: not).

    Returns
    -------
    Evaluation
    """
    import os

    from bearingshaft.identify.scatter import noise_variance

    t0, c0 = time.perf_counter(), time.process_time()
    rig, rec = record_at(problem, theta, force_seed)
    model = model_channels(problem, rig, rec)
    found = blocks(target, model)
    nv, nd = noise_variance(target, model, noise_draws) if noise_draws else ({}, {})
    stats = {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
             "n_events": int(rec.stats.get("n_events", -1)), "worker": os.getpid()}
    return Evaluation(np.asarray(theta, float).copy(), found, stats, nv, nd)


def define_target(problem: Problem, theta, measures: tuple[str, ...], *, envelope_window_s: float,
                  frame_s: float, fmax_hz: float | None, envelope_band_hz=()) -> tuple[Target, Record]:
    """What the residual blocks measure where, from the model at ``theta`` and the test.

    The floors come from the test alone (:func:`bearingshaft.correlate.channel_floors`, its
    pre-trigger as the noise); the predictability horizon (:func:`bearingshaft.measured.horizon`:
    two exact runs of the model a hair apart) from the model at ``theta``. The pointwise block
    runs from the blow's start to the horizon, and at least MIN_TIME_SPAN_S past the blow's end
    (the horizon at a poor first guess can end at the blow: the mismatch there is the guess's);
    the ridges and impacts from the horizon to the window's end.

    Parameters
    ----------
    problem : Problem
    theta : (p,) array_like of float
    measures : tuple of str
        The blocks.
    envelope_window_s, frame_s : float
        s, the envelope's windows and the ridges' frames.
    fmax_hz : float or None
        Hz, the ridges' band's top.
    envelope_band_hz : (float, float) or ()
        Hz, the envelope's channels band-passed to this first (() : as recorded).

    Returns
    -------
    (Target, Record): the target and the model's record at ``theta``.
    """
    test = problem.test
    rig, rec = record_at(problem, theta)
    model = model_channels(problem, rig, rec)
    pairs = correlate.match_channels(model, test.channels, list(problem.names))
    window = problem.window_s
    noise_end = test.pulse_start_s - test.window.margin_s
    noise = (0.0, noise_end) if noise_end > 0 else None
    floors = correlate.channel_floors(pairs, window, noise)
    noise_rms = np.array([correlate.rms(p.aligned(noise).test) if noise is not None else 0.0 for p in pairs])
    hz = None
    horizon_s = window[1]
    if any(m in measures for m in ("time", "ridges", "impacts")):
        hz = measured.horizon(rig, rec.t, rec.x, test, pairs, floors, window)
        horizon_s = min(window[1], hz.horizon_s)
    t_a = max(window[0], test.pulse_start_s)
    t_h = min(window[1], max(horizon_s, test.free_after_s + MIN_TIME_SPAN_S))
    f = np.array([floors[p.name][0] for p in pairs])
    scale = np.array([max(correlate.rms(p.aligned((t_a, t_h)).test), fl) if t_h > t_a else 1.0
                      for p, fl in zip(pairs, f, strict=True)])
    scale[scale <= 0] = 1.0
    post = (max(window[0], horizon_s), window[1]) if horizon_s < window[1] else window
    target = Target(names=problem.names, rows=tuple(list(rig.names).index(n) for n in problem.names),
                    tests=tuple(p.test for p in pairs), quantities=tuple(p.quantity for p in pairs), floors=f,
                    window_s=window, time_span_s=(t_a, t_h), time_scale=scale, post_s=post,
                    envelope_window_s=envelope_window_s, frame_s=frame_s, fmax_hz=fmax_hz, measures=tuple(measures),
                    horizon=hz, envelope_band_hz=tuple(envelope_band_hz), envelope_floors=f, noise=noise_rms,
                    envelope_noise=noise_rms)
    cells = [p for p in pairs if p.quantity == CONTACT_QUANTITY]
    last = [measured_last(p, window) for p in cells]
    last = [v for v in last if math.isfinite(v)]
    target = replace(target, free_decay_s=max(last) if last else window[0])
    if "envelope" in measures and envelope_band_hz:
        from bearingshaft.identify.residuals import band_passed

        banded = [band_passed(p, envelope_band_hz) for p in pairs]
        fb = correlate.channel_floors(banded, window, noise)
        target = replace(target, envelope_floors=np.array([fb[p.name][0] for p in banded]),
                         envelope_noise=np.array([correlate.rms(p.aligned(noise).test) if noise is not None else 0.0
                                                  for p in banded]))
    if "ridges" in measures:
        from bearingshaft.measures import ridges

        mask = {}
        for p, fl in zip(pairs, f, strict=True):
            r = ridges(p, post, frame_s, RIDGE_OVERLAP, fmax_hz=fmax_hz, floor=fl)
            if r is not None:
                mask[p.name] = r.valid & np.isfinite(r.f_test) & (r.f_test > 0)
        target = replace(target, ridge_mask=mask)
    return target, rec


def measured_last(pair, window_s) -> float:
    """s, the end of the test's last impact on a load cell (NaN: none)
    (:func:`bearingshaft.measures.impact_comparison`).

    Parameters
    ----------
    pair : ChannelPair
        A load cell's model and test channels.
    window_s : (float, float)
        s.
    """
    from bearingshaft.measures import impact_comparison

    c = impact_comparison(pair, window_s, window_s)
    return c.test.last_s if c is not None else math.nan


def horizon_text(target: Target) -> str:
    """The pointwise block's span in words.

    Parameters
    ----------
    target : Target
    """
    a, b = target.time_span_s
    if not target.has_time:
        return "no pointwise block"
    hz = target.horizon
    h = f"{1e3 * hz.horizon_s:.4g} ms" if hz is not None and math.isfinite(hz.horizon_s) else "none in the window"
    return f"pointwise from {1e3 * a:.4g} to {1e3 * b:.4g} ms (horizon {h})"


__all__ = ["Problem", "make_problem", "hammer_noise", "redrawn_force",
           "channels_at", "rig_at", "record_at", "evaluate", "Evaluation", "define_target",
           "truncated", "model_channels", "horizon_text", "MIN_TIME_SPAN_S"]
