"""Test-model correlation of a hammer test: channels matched, errors measured, the errors CSV.

The model's channels (:class:`fem.uff.TimeHistory`, e.g. ``beam_s3:z``, ``tip_left_top``,
``hammer``) are paired with a test file's channels by node and axis (:func:`match_channels`);
a test channel along the opposite sense (direction code -d for the model's +d) is negated so
that both members of a pair share the model's sign. Each pair is compared on the samples the
two records have in common (:meth:`ChannelPair.aligned`): the model is run at the test's
sampling, so the grids coincide and nothing is resampled.

Error measures of one pair over a time window (:func:`channel_errors`), with m_k the model's
and x_k the test's samples in the window (raw signals, no mean removed)::

    rms_model = sqrt(mean(m_k^2)),   rms_test = sqrt(mean(x_k^2))
    rms_rel_error = sqrt(mean((m_k - x_k)^2)) / rms_test          (>= 0)
    peak_abs_model = max |m_k|,      peak_abs_test = max |x_k|
    f_dominant_*_hz = the peak of the Welch-averaged spectrum over fmin_hz <= f <= fmax_hz (below)
    f_rel_error = (f_dominant_model_hz - f_dominant_test_hz) / f_dominant_test_hz   (signed)

The dominant frequency is :func:`reduced.transient.spectral.dominant_freq_hz` (the estimator
of the sweep's metrics and the spectrograms too) over Hann segments of n_seg = min(N, round(fs /
resolution_hz)) samples (bins ``resolution_hz`` apart, 2 Hz by default, ``f_resolution_hz``;
the whole window as one segment when it is shorter), half overlapping, each segment's mean
removed: the peak of their averaged, zero-padded spectrum refined on the averaged continuous
spectrum, which places a single tone to a small fraction of a bin. A rms_test of 0 gives
rms_rel_error = inf (0 when the model is exactly 0 as well); a band without power gives NaN frequencies.

A relative error needs a floor: a channel that is zero by symmetry (an accelerometer's y axis
for a blow on the plane of symmetry) carries only round-off or noise, and its own RMS is no
scale to judge it by. With ``floors`` (:func:`channel_floors`) the error is
rms(m - x) / max(rms_test, floor): the floor is NEAR_ZERO of the largest test RMS among the
channels of its sensor (the same node and quantity: a triaxial accelerometer's three axes)
and NOISE_FACTOR times the test's RMS before the blow (its noise), whichever is larger; the
``judged_against`` column says which scale was used.

A test file is user input: :func:`check_test_channels` refuses, in one line naming the
record, a file without a hammer channel or with two, two records for one channel, NaN
samples and channels sampled differently from the hammer; :func:`force_window` applies a
test lab's force window to the hammer channel (zero outside the pulse and a margin).

All refusals are :class:`ChannelError` with a one-line message. Nothing here draws: the
comparison figures are the hammer stage's (:mod:`bearingshaft.stages.hammer_files`).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearingshaft.output import write_rows
from fem.uff import TimeHistory
from reduced import _checks
from reduced.transient.spectral import dominant_freq_hz, segment_length

DT_RTOL = 1e-9  # relative difference of two time steps still taken as the same sampling
# fraction of a sample by which the two grids may be offset and still be read as one: a shift of
# 1e-3 dt changes a tone at a quarter of the sample rate by 2 pi 0.25 1e-3 ~ 1.6e-3 relative, far
# below what a test-model comparison resolves; more means the model was not run at the test's t0
SAMPLE_OFFSET_TOL = 1e-3
WELCH_RESOLUTION_HZ = 2.0  # Hz, default bin spacing of the Welch PSD (~0.5 s segments)
FMIN_HZ = 5.0  # Hz, default lower edge of the dominant-frequency band: above the mean's leakage
MAX_PANELS = 6  # channels of a default comparison figure
CSV_DIGITS = 6  # significant digits in the errors CSV: reruns give byte-identical files
EXCITATION = "force"  # quantity of the hammer (an input, not a prediction: not compared by default)
COMPARE_KEY = "[hammer] compare = [...]"  # the scene key that lists the channels to compare
NEAR_ZERO = 0.01  # a channel below this share of its sensor's largest test RMS is judged against that one
NOISE_FACTOR = 3.0  # ... and never against less than this x its RMS before the blow (the noise)
PULSE_FRACTION = 0.02  # the hammer pulse: the samples about the peak with |F| above this share of it ...
PULSE_NOISE = 5.0  # ... and above this x the force channel's noise (robust sigma, from its median deviation)
DOUBLE_HIT_FRACTION = 0.1  # |F| above this share of the peak outside the force window is a second blow

ERROR_FIELDS = [
    "name", "test_name", "node", "direction", "quantity", "unit", "flipped", "t_start_s", "t_end_s",
    "n_samples", "rms_model", "rms_test", "rms_rel_error", "peak_abs_model", "peak_abs_test",
    "f_dominant_model_hz", "f_dominant_test_hz", "f_rel_error", "f_resolution_hz", "rms_floor", "judged_against",
]


class ChannelError(ValueError):
    """Model and test channels that cannot be compared; the message is one line."""


def direction_label(d: int) -> str:
    """A UFF direction code as the messages and figures say it.

    Parameters
    ----------
    d : int
        UFF direction code, -3 .. 3.

    Returns
    -------
    str

    Examples
    --------
    >>> direction_label(3), direction_label(-1), direction_label(0)
    ('+3 (+Z)', '-1 (-X)', '0 (scalar)')
    """
    return "0 (scalar)" if d == 0 else f"{d:+d} ({'+-'[d < 0]}{'XYZ'[abs(d) - 1]})"


def _describe(ch: TimeHistory) -> str:
    return f"{ch.name!r} (node {ch.node}, direction {direction_label(ch.direction)}, {ch.quantity} [{ch.unit}])"


def _axis(ch: TimeHistory) -> tuple[int, int]:
    return int(ch.node), abs(int(ch.direction))


def _sense(d: int) -> int:
    return -1 if d < 0 else 1


def _unknown(kind: str, name: str, known: list[str]) -> ChannelError:
    close = difflib.get_close_matches(name, known, n=1)
    more = ", ..." if len(known) > 8 else ""
    hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known[:8])}{more}"
    return ChannelError(f"unknown {kind} {name!r}; {hint}")


@dataclass(frozen=True, eq=False)
class AlignedPair:
    """Model and test samples at the same times ``t`` (s); ``test`` in the model's sense.

    Attributes
    ----------
    t : (n,) ndarray of float
        s, the common sample times (n >= 2).
    model : (n,) ndarray of float
        The model channel, in its unit.
    test : (n,) ndarray of float
        The test channel, same unit and sign convention.
    """

    t: np.ndarray  # s, (n,)
    model: np.ndarray  # (n,), the model channel's unit
    test: np.ndarray  # (n,), same unit and sign convention

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / float(self.t[1] - self.t[0])


@dataclass(frozen=True, eq=False)
class ChannelPair:
    """A model channel and the test channel at its node and axis.

    ``test`` is the test channel with its data negated (and its direction set to the model's)
    when it was measured along the opposite sense; ``flipped`` records that it was.

    Attributes
    ----------
    name : str
        The model channel's name.
    model : TimeHistory
        The model channel.
    test : TimeHistory
        The test channel at the same node and axis, sign-aligned with the model.
    flipped : bool
        The test channel was measured along the opposite sense (its data negated here).
    """

    name: str  # the model channel's name
    model: TimeHistory
    test: TimeHistory  # sign-aligned with the model
    flipped: bool

    @property
    def node(self) -> int:
        return self.model.node

    @property
    def direction(self) -> int:
        return self.model.direction

    @property
    def quantity(self) -> str:
        return self.model.quantity

    @property
    def unit(self) -> str:
        return self.model.unit

    def _offset(self) -> int:
        """Test sample index of model sample 0 (the grids coincide up to SAMPLE_OFFSET_TOL)."""
        return int(round((self.model.t0_s - self.test.t0_s) / self.test.dt_s))

    def common_range(self) -> tuple[int, int]:
        """Model sample indices [i0, i1) that the test record also covers."""
        k = self._offset()
        return max(0, -k), min(self.model.data.size, self.test.data.size - k)

    def aligned(self, window_s: tuple[float, float] | None = None) -> AlignedPair:
        """Both records on their common time grid (the model's samples that the test also has),
        optionally only the samples with window_s[0] <= t <= window_s[1] (s, absolute times)."""
        i0, i1 = self.common_range()
        k = self._offset()
        t = self.model.t[i0:i1]
        m = self.model.data[i0:i1]
        x = self.test.data[i0 + k:i1 + k]
        if window_s is not None:
            a, b = _window(window_s)
            eps = 1e-6 * self.model.dt_s  # a window edge on a sample keeps it despite rounding
            keep = (t >= a - eps) & (t <= b + eps)
            if np.count_nonzero(keep) < 2:
                raise ChannelError(f"channel {self.name!r}: window_s = ({a:.6g}, {b:.6g}) s holds fewer than 2 of "
                                   f"the common samples ({t[0]:.6g} .. {t[-1]:.6g} s)")
            t, m, x = t[keep], m[keep], x[keep]
        return AlignedPair(t=t, model=m, test=x)


def _window(window_s) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in window_s)
    except (TypeError, ValueError):
        raise ChannelError(f"window_s must be (t_start_s, t_end_s), got {window_s!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and a < b):
        raise ChannelError(f"window_s must be finite with t_start_s < t_end_s, got ({a!r}, {b!r})")
    return a, b


def match_channels(model: list[TimeHistory], test: list[TimeHistory], wanted: list[str] | None = None, *,
                   source: str = "the test file") -> list[ChannelPair]:
    """Pair each wanted model channel with the test channel at its node and axis.

    A test channel matches a model channel at the same node whose direction code is +d or -d
    (the model's being +d or -d) and whose quantity is the model's; along the opposite sense
    its data are negated (``flipped``). Several test channels at one node and axis are
    ambiguous only among those of the model's quantity (a file may hold a sensor's
    acceleration and its integrated velocity).

    Parameters
    ----------
    model, test : the channels of the model run and of the test file
    wanted : names of model channels to compare, in this order (default: every model channel
        but the excitation, quantity "force", i.e. the hammer: the model is driven by it)
    source : how messages name the test file (e.g. its path)

    Raises
    ------
    ChannelError (one line) for an unknown wanted name, a wanted channel the test lacks, a
    quantity mismatch, ambiguous test channels, different sampling (relative dt difference
    > 1e-9), grids offset by a fraction of a sample, no common samples or non-finite samples.
    """
    by_name: dict[str, TimeHistory] = {}
    for ch in model:
        if ch.name in by_name:
            raise ChannelError(f"the model has two channels named {ch.name!r}")
        by_name[ch.name] = ch
    if wanted is None:
        wanted = [ch.name for ch in model if ch.quantity != EXCITATION]
    else:
        wanted = list(dict.fromkeys(wanted))  # once each, in the given order
        for name in wanted:
            if name not in by_name:
                raise _unknown("model channel", name, list(by_name))
    if not wanted:
        raise ChannelError("no model channel to compare")
    at_axis: dict[tuple[int, int], list[TimeHistory]] = {}
    for ch in test:
        at_axis.setdefault(_axis(ch), []).append(ch)

    pairs = []
    missing = [name for name in wanted if not at_axis.get(_axis(by_name[name]))]
    if missing:
        ch = by_name[missing[0]]
        others = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
        raise ChannelError(f"model channel {_describe(ch)}{others} not in {source} (no channel at node {ch.node}, "
                           f"axis {'XYZ'[abs(ch.direction) - 1] if ch.direction else 'scalar'}); "
                           f"{len(wanted) - len(missing)} of the {len(wanted)} wanted channels are there: list "
                           f"the ones to compare in the scene key {COMPARE_KEY}")
    for name in wanted:
        m = by_name[name]
        candidates = at_axis[_axis(m)]
        same = [c for c in candidates if c.quantity == m.quantity]
        if not same:
            c = candidates[0]
            raise ChannelError(f"model channel {m.name!r} (node {m.node}, direction "
                               f"{direction_label(m.direction)}) predicts {m.quantity} [{m.unit}] but test channel "
                               f"{c.name!r} at its node and axis in {source} is {c.quantity} [{c.unit}]; give the "
                               f"test as {m.quantity} or leave the channel out of {COMPARE_KEY}")
        if len(same) > 1:
            raise ChannelError(f"model channel {_describe(m)}: {len(same)} test channels at node {m.node} and its "
                               f"axis in {source} are {m.quantity} ({', '.join(repr(c.name) for c in same)}): "
                               f"ambiguous; keep one")
        x = same[0]
        if abs(x.dt_s - m.dt_s) > DT_RTOL * max(x.dt_s, m.dt_s):
            raise ChannelError(f"channel {name!r}: the model is sampled at {1.0 / m.dt_s:.10g} Hz, test channel "
                               f"{x.name!r} at {1.0 / x.dt_s:.10g} Hz; run the model at the test's sampling")
        shift = (m.t0_s - x.t0_s) / x.dt_s
        frac = abs(shift - round(shift))
        if frac > SAMPLE_OFFSET_TOL:
            raise ChannelError(f"channel {name!r}: the model starts at {m.t0_s:.10g} s, test channel {x.name!r} at "
                               f"{x.t0_s:.10g} s, {frac:.3g} of a sample apart: the sample times differ; "
                               f"run the model from the test's t0")
        flipped = _sense(x.direction) != _sense(m.direction)
        aligned = TimeHistory(x.name, x.node, m.direction, x.quantity, -x.data if flipped else x.data,
                              x.dt_s, x.t0_s)
        pair = ChannelPair(name=name, model=m, test=aligned, flipped=flipped)
        i0, i1 = pair.common_range()
        if i1 - i0 < 2:
            raise ChannelError(f"channel {name!r}: the model spans {m.t[0]:.6g} .. {m.t[-1]:.6g} s, test channel "
                               f"{x.name!r} {x.t[0]:.6g} .. {x.t[-1]:.6g} s: fewer than 2 common samples")
        for label, ch in (("model", m), ("test", x)):
            if not np.all(np.isfinite(ch.data)):
                raise ChannelError(f"channel {name!r}: {label} channel {ch.name!r} has "
                                   f"{np.count_nonzero(~np.isfinite(ch.data))} non-finite samples")
        pairs.append(pair)
    return pairs


def _record(channels: list[TimeHistory], k: int, source: str) -> str:
    return f"{source} record {k + 1} ({channels[k].name!r})"


def check_test_channels(channels: list[TimeHistory], source: str = "the test file") -> int:
    """The index of a test's hammer channel, once its records are checked as one test.

    Refused (ChannelError, one line naming the record, numbered as the file's dataset 58
    records): no record; non-finite samples; two records with one name, or of one quantity at
    one node and axis (two records for one channel); no force record (the hammer, which drives
    the model) or more than one; a hammer that is zero throughout; a record sampled at another
    rate than the hammer's, starting at another time, or with another number of samples.

    Parameters
    ----------
    channels : list of TimeHistory
        The file's records, in file order.
    source : str
        How messages name the file.

    Returns
    -------
    int
        Index of the hammer channel in ``channels``.

    Examples
    --------
    >>> h = TimeHistory("hammer", 300, -3, "force", np.array([0.0, 5.0, 0.0]), 1e-3)
    >>> a = TimeHistory("a:z", 1, 3, "acceleration", np.zeros(3), 1e-3)
    >>> check_test_channels([a, h])
    1
    >>> try:
    ...     check_test_channels([a, a, h])
    ... except ChannelError as exc:
    ...     print(exc)
    the test file record 2 ('a:z'): record 1 is named 'a:z' too: two records for one channel; keep one
    """
    if not channels:
        raise ChannelError(f"{source}: no channel")
    names: dict[str, int] = {}
    axes: dict[tuple[int, int, str], int] = {}
    for k, ch in enumerate(channels):
        where = _record(channels, k, source)
        bad = np.flatnonzero(~np.isfinite(ch.data))
        if bad.size:
            raise ChannelError(f"{where}: {bad.size} of its {ch.data.size} samples are not finite (the first at "
                               f"t = {ch.t[bad[0]]:.6g} s); a test record must be complete")
        if ch.name in names:
            raise ChannelError(f"{where}: record {names[ch.name] + 1} is named {ch.name!r} too: two records for one "
                               f"channel; keep one")
        names[ch.name] = k
        key = (*_axis(ch), ch.quantity)
        if key in axes and ch.direction != 0:
            j = axes[key]
            raise ChannelError(f"{where}: record {j + 1} ({channels[j].name!r}) is {ch.quantity} at node {ch.node}, "
                               f"axis {'XYZ'[abs(ch.direction) - 1]} too: two records for one channel; keep one")
        axes[key] = k
    forces = [k for k, ch in enumerate(channels) if ch.quantity == EXCITATION]
    if not forces:
        raise ChannelError(f"{source}: no hammer channel among its {len(channels)} records (no record of quantity "
                           f"force, UFF data type 13): the model is driven by the measured force; add the hammer's "
                           f"record")
    if len(forces) > 1:
        raise ChannelError(f"{_record(channels, forces[1], source)}: a second force channel (record {forces[0] + 1} "
                           f"is one): a hammer test has one hammer; keep the hammer's record")
    h = forces[0]
    ref = channels[h]
    if not np.any(ref.data):
        raise ChannelError(f"{_record(channels, h, source)}: the hammer channel is zero throughout: no blow")
    for k, ch in enumerate(channels):
        where = _record(channels, k, source)
        if abs(ch.dt_s - ref.dt_s) > DT_RTOL * max(ch.dt_s, ref.dt_s):
            raise ChannelError(f"{where} is sampled at {1.0 / ch.dt_s:.10g} Hz, the hammer channel (record {h + 1}) "
                               f"at {1.0 / ref.dt_s:.10g} Hz: the channels of a test share one sampling; resample it")
        if abs(ch.t0_s - ref.t0_s) > SAMPLE_OFFSET_TOL * ref.dt_s:
            raise ChannelError(f"{where} starts at t0 = {ch.t0_s:.10g} s, the hammer channel (record {h + 1}) at "
                               f"{ref.t0_s:.10g} s: the channels of a test start together")
        if ch.data.size != ref.data.size:
            raise ChannelError(f"{where} has {ch.data.size} samples, the hammer channel (record {h + 1}) "
                               f"{ref.data.size}: a record cut short; the channels of a test cover the same time")
    return h


@dataclass(frozen=True, eq=False)
class ForceWindow:
    """A hammer channel through a force window (:func:`force_window`).

    Attributes
    ----------
    channel : TimeHistory
        The windowed force: offset removed, zero outside the window.
    offset_N : float
        N, the channel's median, removed first.
    noise_N : float
        N, its noise (1.4826 x the median absolute deviation).
    threshold_N : float
        N, |F| above which a sample about the peak is in the pulse.
    pulse_s : (float, float)
        s, first and last sample of the pulse.
    window_s : (float, float)
        s, first and last sample the window keeps (1 over the pulse, a half-cosine over the
        margins, 0 outside).
    margin_s : float
        s, the margin asked for.
    """

    channel: TimeHistory
    offset_N: float
    noise_N: float
    threshold_N: float
    pulse_s: tuple[float, float]
    window_s: tuple[float, float]
    margin_s: float

    def describe(self) -> str:
        """One sentence for the reports."""
        a, b = self.pulse_s
        return (f"force window: the pulse {1e3 * a:.4g}-{1e3 * b:.4g} ms (|F| >= {self.threshold_N:.3g} N) plus "
                f"{1e3 * self.margin_s:.3g} ms either side, half-cosine tapered, zero outside (the model is free "
                f"after {1e3 * self.window_s[1]:.4g} ms); offset {self.offset_N:.3g} N removed, noise "
                f"{self.noise_N:.3g} N")


def force_window(ch: TimeHistory, margin_s: float, *, source: str = "the hammer channel",
                 double_hit: bool = True) -> ForceWindow:
    """A test lab's force window on a hammer channel: the blow kept, the noise around it zeroed.

    The channel's median (its offset) is removed; the pulse is the run of samples about the peak
    |F| whose |F| stays at or above the threshold max(PULSE_FRACTION |F|_max, PULSE_NOISE sigma),
    sigma = 1.4826 median |F - median| (the noise, robust to the pulse); the window is 1 over
    the pulse, a half-cosine from 1 to 0 over ``margin_s`` on either side and 0 outside, so the
    model driven by it is free after the blow (a force that never returns to zero keeps the
    exact integrator on its forced path throughout).

    Parameters
    ----------
    ch : TimeHistory
        The hammer channel.
    margin_s : float
        s, >= 0, kept on either side of the pulse.
    source : str
        How a refusal names the channel.
    double_hit : bool
        Refuse a second blow outside the window (False: the window is found all the same).

    Returns
    -------
    ForceWindow

    Raises
    ------
    ChannelError
        A second blow outside the window (|F| above DOUBLE_HIT_FRACTION of the peak and
        2 PULSE_NOISE sigma): a double hit, which test practice rejects.

    Examples
    --------
    >>> f = np.zeros(40)
    >>> f[10:15] = [1.0, 3.0, 4.0, 3.0, 1.0]
    >>> w = force_window(TimeHistory("hammer", 1, 3, "force", f + 0.01, 1.0), 2.0)
    >>> w.pulse_s, w.window_s, w.offset_N
    ((10.0, 14.0), (8.0, 16.0), 0.01)
    >>> bool(np.all(w.channel.data[:8] == 0.0) and np.all(w.channel.data[17:] == 0.0))
    True
    """
    margin_s = _checks.number("margin_s", margin_s, lo=0.0, lo_open=False, unit="s")
    f = ch.data - float(np.median(ch.data))
    offset = float(np.median(ch.data))
    a = np.abs(f)
    noise = 1.4826 * float(np.median(a))
    k = int(np.argmax(a))
    thr = max(PULSE_FRACTION * a[k], PULSE_NOISE * noise)
    below = a < thr
    left = np.flatnonzero(below[:k])
    right = np.flatnonzero(below[k:])
    i_a = int(left[-1]) + 1 if left.size else 0
    i_b = k + int(right[0]) - 1 if right.size else a.size - 1
    m = int(math.ceil(margin_s / ch.dt_s - 1e-9))
    w = np.zeros(a.size)
    w[i_a:i_b + 1] = 1.0
    taper = 0.5 * (1.0 + np.cos(np.pi * np.arange(1, m + 1) / (m + 1)))  # 1 -> 0, both ends excluded
    hi = min(a.size, i_b + 1 + m)
    w[i_b + 1:hi] = taper[:hi - i_b - 1]
    lo = max(0, i_a - m)
    w[lo:i_a] = taper[:i_a - lo][::-1]
    out = np.flatnonzero((w == 0.0) & (a > max(DOUBLE_HIT_FRACTION * a[k], 2 * PULSE_NOISE * noise)))
    if double_hit and out.size:
        j = int(out[0])
        raise ChannelError(f"{source}: a second blow at t = {ch.t[j]:.6g} s ({f[j]:.4g} N, "
                           f"{100 * a[j] / a[k]:.3g} % of the peak) outside the force window "
                           f"{ch.t[lo]:.6g} .. {ch.t[hi - 1]:.6g} s: a double hit; repeat the blow, or set "
                           f"[hammer] force_window = false to drive the model with the whole record")
    windowed = TimeHistory(ch.name, ch.node, ch.direction, ch.quantity, f * w, ch.dt_s, ch.t0_s)
    return ForceWindow(windowed, offset, noise, float(thr), (float(ch.t[i_a]), float(ch.t[i_b])),
                       (float(ch.t[lo]), float(ch.t[hi - 1])), margin_s)


def rms(y: np.ndarray) -> float:
    """The root mean square of ``y`` (no mean removed).

    Parameters
    ----------
    y : array_like of float
        The samples.

    Returns
    -------
    float
        sqrt(mean(y^2)), in the unit of y.

    Examples
    --------
    >>> rms(np.array([3.0, -3.0, 3.0, -3.0]))
    3.0
    """
    return float(np.sqrt(np.mean(np.square(y))))


def channel_floors(pairs: list[ChannelPair], window_s: tuple[float, float] | None = None,
                   noise_s: tuple[float, float] | None = None) -> dict[str, tuple[float, str]]:
    """The floor of each pair's relative errors and what sets it (module docstring).

    floor = max(NEAR_ZERO x the largest test RMS over ``window_s`` among the pairs of its sensor
    (same node and quantity), NOISE_FACTOR x the test's RMS over ``noise_s``); the basis is
    ``"sensor"`` or ``"noise"``, whichever is larger.

    Parameters
    ----------
    pairs : list of ChannelPair
        From :func:`match_channels`.
    window_s : (float, float) or None
        s, the compared window (default: each pair's whole overlap).
    noise_s : (float, float) or None
        s, a stretch with no response (the pre-trigger) whose test RMS is the channel's noise;
        None (or fewer than 2 samples in it): no noise floor.

    Returns
    -------
    dict
        {pair name: (floor, basis)}, the floor in the channel's unit.

    Examples
    --------
    >>> t = np.arange(100) * 1e-3
    >>> z = TimeHistory("a:z", 1, 3, "acceleration", np.sin(60 * t), 1e-3)
    >>> y = TimeHistory("a:y", 1, 2, "acceleration", 1e-5 * np.sin(60 * t), 1e-3)
    >>> f = channel_floors(match_channels([z, y], [z, y]))
    >>> f["a:y"][1], bool(np.isclose(f["a:y"][0], NEAR_ZERO * rms(z.data)))
    ('sensor', True)
    """
    test_rms = {p.name: rms(p.aligned(window_s).test) for p in pairs}
    top: dict[tuple[int, str], float] = {}
    for p in pairs:
        key = (p.node, p.quantity)
        top[key] = max(top.get(key, 0.0), test_rms[p.name])
    out = {}
    for p in pairs:
        floor, basis = NEAR_ZERO * top[(p.node, p.quantity)], "sensor"
        if noise_s is not None:
            try:
                noise = NOISE_FACTOR * rms(p.aligned(noise_s).test)
            except ChannelError:  # fewer than 2 samples before the blow: no noise estimate
                noise = 0.0
            if noise > floor:
                floor, basis = noise, "noise"
        out[p.name] = (floor, basis)
    return out


def channel_errors(pairs: list[ChannelPair], window_s: tuple[float, float] | None = None,
                   fmin_hz: float = FMIN_HZ, fmax_hz: float | None = None,
                   resolution_hz: float = WELCH_RESOLUTION_HZ,
                   floors: dict[str, tuple[float, str]] | None = None) -> list[dict]:
    """One row of error measures per pair (the module docstring defines them; keys: ERROR_FIELDS).

    Parameters
    ----------
    pairs : from :func:`match_channels`
    window_s : (t_start_s, t_end_s), s, absolute times compared (default: each pair's whole overlap)
    fmin_hz, fmax_hz : Hz, band searched for the dominant frequency (default fmax: fs / 2)
    resolution_hz : Hz, Welch bin spacing asked for (coarser when the window is shorter than 1 / resolution_hz)
    floors : {name: (floor, basis)} from :func:`channel_floors`: rms_rel_error = rms(m - x) /
        max(rms_test, floor), ``judged_against`` the basis where the floor is the larger (default:
        no floor, every channel judged against itself)
    """
    fmin_hz = _checks.number("fmin_hz", fmin_hz, lo=0.0, lo_open=False, unit="Hz")
    if fmax_hz is not None:
        fmax_hz = _checks.positive("fmax_hz", fmax_hz, "Hz")
        if not fmax_hz > fmin_hz:
            raise ChannelError(f"fmax_hz = {fmax_hz!r} Hz must exceed fmin_hz = {fmin_hz!r} Hz")
    resolution_hz = _checks.positive("resolution_hz", resolution_hz, "Hz")
    rows = []
    for p in pairs:
        a = p.aligned(window_s)
        fs = a.sample_rate_hz
        rms_m, rms_x = rms(a.model), rms(a.test)
        rms_d = rms(a.model - a.test)
        floor, basis = floors[p.name] if floors is not None else (0.0, "itself")
        scale = max(rms_x, floor)
        judged = "itself" if rms_x >= floor else basis
        if rms_d == 0.0:
            rel = 0.0
        elif scale == 0.0:
            rel = math.inf
        else:
            rel = rms_d / scale
        n_seg = segment_length(a.t.size, fs, resolution_hz)
        df = fs / n_seg  # Hz, the segments' bin spacing
        f_m = dominant_freq_hz(a.model, fs, fmin_hz, fmax_hz, segment=n_seg)
        f_x = dominant_freq_hz(a.test, fs, fmin_hz, fmax_hz, segment=n_seg)
        f_rel = (f_m - f_x) / f_x if f_x > 0.0 else math.nan  # NaN propagates from either
        rows.append({
            "name": p.name, "test_name": p.test.name, "node": p.node, "direction": p.direction,
            "quantity": p.quantity, "unit": p.unit, "flipped": p.flipped,
            "t_start_s": float(a.t[0]), "t_end_s": float(a.t[-1]), "n_samples": int(a.t.size),
            "rms_model": rms_m, "rms_test": rms_x, "rms_rel_error": rel,
            "peak_abs_model": float(np.max(np.abs(a.model))), "peak_abs_test": float(np.max(np.abs(a.test))),
            "f_dominant_model_hz": f_m, "f_dominant_test_hz": f_x, "f_rel_error": f_rel, "f_resolution_hz": df,
            "rms_floor": floor, "judged_against": judged,
        })
    return rows


def write_errors_csv(rows: list[dict], path: str | Path, digits: int = CSV_DIGITS) -> None:
    """The rows of :func:`channel_errors` as CSV (columns ERROR_FIELDS), floats to ``digits``
    significant digits so that a rerun writes the same bytes.

    Parameters
    ----------
    rows : list of dict
        :func:`channel_errors` rows.
    path : str or Path
        The CSV file, replaced.
    digits : int
        Significant digits of the floats.

    Returns
    -------
    None
    """
    write_rows(path, rows, ERROR_FIELDS, float_format=f".{int(digits)}g")


def default_channels(pairs: list[ChannelPair], n: int = MAX_PANELS) -> list[str]:
    """Names of up to ``n`` pairs to draw: the hammer (an excitation force) if compared, the tip
    load cell of largest test rms, then the beam accelerometers (``beam_*``) of largest test rms,
    then any other channel by test rms.

    Parameters
    ----------
    pairs : list of ChannelPair
        The compared channels.
    n : int
        Most names returned.

    Returns
    -------
    list of str
        Channel names, in drawing order.
    """
    def test_rms(p: ChannelPair) -> float:
        return rms(p.aligned().test)

    chosen: list[str] = []
    force = [p for p in pairs if p.quantity == EXCITATION]
    if force:
        chosen.append(force[0].name)
    cells = sorted((p for p in pairs if p.quantity == "reaction_force"), key=test_rms, reverse=True)
    if cells:
        chosen.append(cells[0].name)
    rest = [p for p in pairs if p.name not in chosen]
    rest.sort(key=lambda p: (not p.name.startswith("beam_"), -test_rms(p)))  # stable: ties keep their order
    chosen += [p.name for p in rest]
    return chosen[:n]


def select_pairs(pairs: list[ChannelPair], channels: list[str] | None) -> list[ChannelPair]:
    """The pairs named ``channels``, once each in that order (default: :func:`default_channels`).

    Parameters
    ----------
    pairs : from :func:`match_channels`
    channels : names of compared channels, or None

    Returns
    -------
    list of ChannelPair (ChannelError, one line, for a name not among the pairs)
    """
    by_name = {p.name: p for p in pairs}
    if channels is None:
        return [by_name[n] for n in default_channels(pairs)]
    for n in channels:
        if n not in by_name:
            raise _unknown("compared channel", n, list(by_name))
    return [by_name[n] for n in dict.fromkeys(channels)]


__all__ = [
    "ChannelError", "ChannelPair", "AlignedPair", "match_channels", "channel_errors", "dominant_freq_hz",
    "write_errors_csv", "default_channels", "select_pairs", "rms", "direction_label", "ERROR_FIELDS",
    "channel_floors", "check_test_channels", "force_window", "ForceWindow",
]
