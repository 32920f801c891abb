"""The hammer stage against a measured test (``bearingshaft hammer --test FILE.uff``).

The test file is read and checked, and its hammer channel force-windowed, by
:func:`bearingshaft.measured.read_test`; the stage runs the model at the test's sampling, driven
by that force, and :func:`compare` matches the two channel for channel
(:mod:`bearingshaft.correlate`), finds the predictability horizon
(:func:`bearingshaft.measured.horizon`), the pointwise errors up to it and the measures that
survive chaos past it (:mod:`bearingshaft.measures`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from bearingshaft import correlate, measures
from bearingshaft.measured import SEPARATION_WINDOW_S, Horizon, MeasuredTest, horizon, window_mismatch
from bearingshaft.scenes import Scene, SceneError
from bearingshaft.stages.hammer_results import Comparison, Record, histories
from reduced.models.rig import VirtualRig


def _window(spec, window_s, rec: Record) -> tuple[float, float]:
    """s, the compared window: ``window_s`` (--window), else [hammer] compare_window_s, else the record."""
    w = tuple(window_s) if window_s else tuple(spec.compare_window_s)
    return (float(w[0]), float(w[1])) if w else (float(rec.t[0]), float(rec.t[-1]))


def compare(scene: Scene, rig: VirtualRig, rec: Record, test: MeasuredTest, test_file: str, stats: dict, *,
            window_s: tuple[float, float] | None = None, wanted: tuple[str, ...] = measures.MEASURES,
            backbones: list | None = None) -> Comparison:
    """The model's record ``rec`` (run at the test's sampling) matched and compared with ``test``.

    The pointwise errors (:func:`bearingshaft.correlate.channel_errors`, with floors) are over the
    window up to the predictability horizon (:func:`horizon`); the measures that survive chaos
    (:func:`bearingshaft.measures.compare`) past it.

    Parameters
    ----------
    scene : the scene ([hammer] compare, compare_window_s; [spectrogram] window_s, overlap, fmax_hz)
    rig : the rig that made ``rec``
    rec : the model's record, driven as ``test.driven`` says
    test : from :func:`read_test`
    test_file : the test file's path, as the files and messages name it
    stats : the stage's statistics so far (the rig's); the comparison's are added
    window_s : s, the compared window (--window; default [hammer] compare_window_s, else the record)
    wanted : the measures (--measures): among :data:`bearingshaft.measures.MEASURES`
    backbones : the model's NNM backbones on channels (ChannelBackbone), for the ``backbone`` measure

    Returns
    -------
    Comparison (SceneError, one line, when the channels cannot be compared)
    """
    spec, sp = scene.hammer, scene.spectrogram
    model = histories(rig, rec.t, rec.data)
    window = _window(spec, window_s, rec)
    noise_end = test.pulse_start_s - test.window.margin_s
    noise = (float(rec.t[0]), noise_end) if noise_end > rec.t[0] else None
    try:
        pairs = correlate.match_channels(model, test.channels, list(spec.compare) or None, source=repr(test_file))
        floors = correlate.channel_floors(pairs, window, noise)
        hz = horizon(rig, rec.t, rec.x, test, pairs, floors, window)
        hz = replace(hz, **dict(zip(("mismatch_t", "mismatch"), window_mismatch(pairs, floors, SEPARATION_WINDOW_S),
                                    strict=True)))
        rows = []
        t_end = min(window[1], hz.horizon_s)
        if "time" in wanted and t_end > window[0]:
            rows = correlate.channel_errors(pairs, window_s=(window[0], t_end), floors=floors)
        bbs = [b for b in (backbones or []) if any(p.name == b.channel for p in pairs)]
        bands: dict = {}
        for b in bbs:
            bands.setdefault(b.channel, []).append((b.label, b.band_hz))
        found = measures.compare(pairs, window, hz.horizon_s, floors, wanted, frame_s=sp.window_s if sp else 0.05,
                                 overlap=sp.overlap if sp else 0.9, fmax_hz=sp.fmax_hz if sp else None,
                                 free_s=test.free_after_s, bands=bands)
    except correlate.ChannelError as exc:
        raise SceneError(f"--test: {exc}") from None
    curves = {(b.channel, b.label): b for b in bbs}
    for (name, label), c in found.backbones.items():  # the ringdowns' backbones against the model's NNM's
        hb = curves[(name, label)]
        dm = measures.distance_to_curve(c.model, hb.amplitude, hb.freq_hz)
        dx = measures.distance_to_curve(c.test, hb.amplitude, hb.freq_hz)
        found.rows.append({"measure": "backbone", "channel": f"{name} ({label})",
                           "statistic": "distance to the NNM backbone", "unit": "", "model": dm, "test": dx,
                           "error": dx, "t_start_s": found.spans["backbone"][0], "t_end_s": found.spans["backbone"][1]})
    stats = {**stats, "test_file": str(test_file), "driven_by": test.driven, "n_compared": len(pairs),
             "force_window": test.window.describe() if test.windowed else "none",
             "horizon_s": hz.horizon_s, "lyapunov_exponent_per_s": hz.exponent_per_s, "chaos_onset_s": hz.onset_s,
             "eps0": hz.eps0, "measures": list(wanted),
             "measure_medians": {m: found.summary(m) for m in wanted if m != "time"}}
    if rows:
        worst = max(rows, key=lambda r: r["rms_rel_error"])
        stats.update(worst_channel=worst["name"], worst_rms_rel_error=worst["rms_rel_error"])
    lines = (_summary_line(scene, test_file, test, hz, rows, found, len(pairs)),)
    return Comparison(scene=scene, test_file=str(test_file), driven=test.driven, model=model, pairs=pairs, rows=rows,
                      window_s=window, stats=stats, lines=lines, horizon=hz, measures=found, floors=floors,
                      backbones=bbs, force_text=test.window.describe() if test.windowed else "no force window",
                      wanted=tuple(wanted))


def _summary_line(scene: Scene, test_file: str, test: MeasuredTest, hz: Horizon, rows: list, found, n: int) -> str:
    text = f"[{scene.name}] compared {n} channels with {test_file}: model driven by {test.driven}; "
    if math.isfinite(hz.horizon_s):
        text += f"predictable to {1e3 * hz.horizon_s:.4g} ms"
        if math.isfinite(hz.exponent_per_s):
            text += f" (Lyapunov exponent {hz.exponent_per_s:.3g} 1/s)"
    else:
        text += "no predictability horizon within the window"
    if rows:
        worst = max(rows, key=lambda r: r["rms_rel_error"])
        text += f"; worst {worst['name']} {100 * worst['rms_rel_error']:.3g} % RMS up to it"
    past = [f"{m} {100 * found.summary(m):.2g} %" for m in ("ridges", "envelope", "backbone")
            if math.isfinite(found.summary(m))]
    if past:
        text += "; after it (median over channels): " + ", ".join(past)
    return text + " (test_compare.md)"


def parse_window(text: str | None) -> tuple[float, float] | None:
    """s, the window of ``--window START:END`` (None: not given); SceneError, one line, if malformed.

    Parameters
    ----------
    text : str or None

    Returns
    -------
    (float, float) or None

    Examples
    --------
    >>> parse_window("0.01:0.5"), parse_window(None)
    ((0.01, 0.5), None)
    """
    if text is None:
        return None
    try:
        a, b = (float(v) for v in text.split(":"))
    except ValueError:
        raise SceneError(f"--window must be START:END in seconds (e.g. 0:0.5), got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and 0 <= a < b):
        raise SceneError(f"--window must be START:END with 0 <= START < END, got {text!r}")
    return a, b


def parse_measures(text: str | None) -> tuple[str, ...]:
    """The measures of ``--measures a,b,...`` (default every one); SceneError, one line, for an unknown one.

    Parameters
    ----------
    text : str or None

    Returns
    -------
    tuple of str
    """
    try:
        return measures.parse_measures(text)
    except correlate.ChannelError as exc:
        raise SceneError(str(exc)) from None
