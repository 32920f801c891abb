"""Measures of a test against a model that survive chaos: a number per measure and channel.

An impacting ringdown is chaotic: two runs a hair apart agree sample for sample only up to a
predictability horizon (the hammer stage finds it from the model's largest Lyapunov exponent,
:func:`bearingshaft.measured.horizon`); past it a pointwise error says only that the traces
have parted. What a chaotic motion keeps, and what these functions compare, each on a
:class:`bearingshaft.correlate.ChannelPair` (model and test samples on one grid) over a span
``span_s = (t_start_s, t_end_s)`` of absolute times:

``ridges``
    The spectrogram's ridge: the frequency of the largest power in each frame (Hann frames of
    ``window_s``, :func:`reduced.transient.spectrogram.spectrogram`), refined by a parabola
    through the log power of the peak bin and its neighbours (a Hann window's main lobe: to a
    few hundredths of a bin for one tone). Frames whose test RMS is below the channel's floor
    are left out. ``error`` = median over frames of |f_model - f_test| / f_test; ``agreement``
    = share of frames within one bin (fs / n_win).
``envelope``
    The RMS of each channel in consecutive windows of ``window_s``, e_w:
    ``error`` = sqrt(sum_w (e_model,w - e_test,w)^2 / sum_w max(e_test,w, floor)^2).
``impacts``
    A tip load cell's impacts as the cell sees them: excursions of its reading, in the sense of
    the test's largest value, above IMPACT_FRACTION of that value (the same threshold for the
    model: the seismic mass's inertia between impacts stays below it), re-armed when the reading
    falls below IMPACT_REARM of the threshold; their number, rate and peak forces (median, 90th
    percentile, largest).
``open``
    The time the gaps stay open after: the end of a load cell's last impact.
``backbone``
    The instantaneous frequency and amplitude of one component of the free decay: the channel
    band-passed (zero-phase Butterworth, order BAND_ORDER) to the component's band, its analytic
    signal z (Hilbert; both in one product of spectra), amplitude |z| and frequency
    d(arg z)/dt / 2 pi averaged (weighted by
    |z|^2) over blocks of BACKBONE_PERIODS periods of the band's centre; an acceleration's component
    is integrated twice first (to a displacement: the impacts' harmonics in the band would bias
    the frequency of its fundamental upwards). Model and test are
    compared at the same amplitude: both are binned in log amplitude (BACKBONE_BINS a decade)
    and ``error`` = median over the common bins of |f_model - f_test| / f_test.

:func:`compare` runs a set of measures on a set of pairs and returns their rows (one per
measure, channel and statistic: ``model``, ``test``, ``error``), the arrays behind them for the
figures, and nothing else: no file, no figure, no model run (the identification reuses them
as residuals).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bearingshaft.correlate import ChannelError, ChannelPair, rms
from reduced import _checks

MEASURES = ("time", "ridges", "envelope", "impacts", "open", "backbone")  # "time": the correlate errors
IMPACT_FRACTION = 0.1  # an impact: a load cell's reading above this share of the test's largest ...
IMPACT_REARM = 0.5  # ... counted again once the reading has fallen below this share of that threshold
BAND_ORDER = 4  # Butterworth order of a backbone's band-pass (applied forward and back)
BACKBONE_PERIODS = 4  # a backbone point averages this many periods of the band's centre
BACKBONE_RANGE = 1e-3  # ... and is kept down to this share of the component's largest amplitude
BACKBONE_BINS = 10  # log-amplitude bins a decade where model and test backbones are compared
RIDGE_FMIN_HZ = 5.0  # Hz, a ridge is searched above this (the mean's leakage)
CONTACT_QUANTITY = "reaction_force"  # the tip load cells: impacts and the open-gap time are theirs

MEASURE_FIELDS = ["measure", "channel", "statistic", "unit", "model", "test", "error", "t_start_s", "t_end_s"]


def _span(pair: ChannelPair, span_s):
    try:
        return pair.aligned(span_s)
    except ChannelError:
        return None


# -- ridges ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Ridges:
    """The spectrogram ridges of a model and a test channel, frame by frame.

    Attributes
    ----------
    t : (n,) ndarray of float
        s, frame centres.
    f_model, f_test : (n,) ndarray of float
        Hz, the ridge of each frame (NaN: no power in the band).
    valid : (n,) ndarray of bool
        Frames whose test RMS is at or above the floor (the others are noise).
    bin_hz : float
        Hz, one bin, fs / n_win.
    """

    t: np.ndarray
    f_model: np.ndarray
    f_test: np.ndarray
    valid: np.ndarray
    bin_hz: float

    @property
    def _ok(self) -> np.ndarray:
        return self.valid & np.isfinite(self.f_model) & np.isfinite(self.f_test) & (self.f_test > 0)

    @property
    def error(self) -> float:
        """Median of |f_model - f_test| / f_test over the valid frames (NaN: none)."""
        ok = self._ok
        return float(np.median(np.abs(self.f_model[ok] - self.f_test[ok]) / self.f_test[ok])) if ok.any() else math.nan

    @property
    def agreement(self) -> float:
        """Share of the valid frames whose ridges are within one bin (NaN: none)."""
        ok = self._ok
        return float(np.mean(np.abs(self.f_model[ok] - self.f_test[ok]) <= self.bin_hz)) if ok.any() else math.nan

    def residuals(self) -> np.ndarray:
        """(f_model - f_test) / f_test of the valid frames."""
        ok = self._ok
        return (self.f_model[ok] - self.f_test[ok]) / self.f_test[ok]


def ridge_hz(freq_hz: np.ndarray, power: np.ndarray, fmin_hz: float, fmax_hz: float | None) -> np.ndarray:
    """Hz, the largest bin of each frame in [fmin_hz, fmax_hz], refined by a parabola through the
    log power of it and its neighbours (NaN for a frame without power in the band).

    Parameters
    ----------
    freq_hz : (n_freq,) ndarray of float
        Hz, uniformly spaced bin frequencies.
    power : (n_freq, n_frames) ndarray of float
        The frames' power.
    fmin_hz : float
        Hz, lower edge of the band.
    fmax_hz : float or None
        Hz, upper edge (None: the last bin).

    Returns
    -------
    (n_frames,) ndarray of float

    Examples
    --------
    >>> f = np.arange(64) * 10.0
    >>> p = np.exp(-((f - 203.0) / 15.0) ** 2)[:, None]  # a Gaussian lobe: the parabola in log is exact
    >>> round(float(ridge_hz(f, p, 5.0, None)[0]), 9)
    203.0
    """
    band = np.flatnonzero((freq_hz >= fmin_hz) & (freq_hz > 0) & ((freq_hz <= fmax_hz) if fmax_hz else True))
    out = np.full(power.shape[1], math.nan)
    if band.size == 0:
        return out
    sub = power[band]
    k = np.argmax(sub, axis=0)
    top = sub[k, np.arange(sub.shape[1])]
    df = float(freq_hz[1] - freq_hz[0])
    for j in np.flatnonzero(top > 0):
        i = band[k[j]]
        f = float(freq_hz[i])
        if 0 < i < freq_hz.size - 1 and power[i - 1, j] > 0 and power[i + 1, j] > 0:
            a, b, c = np.log(power[i - 1:i + 2, j])
            den = a - 2 * b + c
            if den < 0:
                f += df * 0.5 * (a - c) / den
        out[j] = f
    return out


def _frame_rms(y: np.ndarray, hop: int, n_win: int, n_frames: int) -> np.ndarray:
    """RMS of y (less its mean) over each STFT frame (frame p: samples p hop - n_win // 2 ... + n_win)."""
    c = np.concatenate([[0.0], np.cumsum((y - y.mean()) ** 2)])
    lo = np.clip(np.arange(n_frames) * hop - n_win // 2, 0, y.size)
    hi = np.clip(lo + n_win, 0, y.size)
    return np.sqrt((c[hi] - c[lo]) / np.maximum(hi - lo, 1))


def ridges(pair: ChannelPair, span_s, window_s: float, overlap: float = 0.9, fmin_hz: float = RIDGE_FMIN_HZ,
           fmax_hz: float | None = None, floor: float = 0.0) -> Ridges | None:
    """The ridges of a pair over ``span_s`` (module docstring); None when the span is shorter than a window.

    Parameters
    ----------
    pair : ChannelPair
        Model and test channel.
    span_s : (float, float) or None
        s, absolute times (None: the whole overlap).
    window_s : float
        s, the Hann window of a frame.
    overlap : float
        In [0, 1).
    fmin_hz, fmax_hz : float
        Hz, the band searched (fmax None: fs / 2).
    floor : float
        Frames whose test RMS is below this are left out (the channel's unit).

    Returns
    -------
    Ridges or None
    """
    from reduced.transient.spectrogram import MAX_FRAMES, spectrogram

    a = _span(pair, span_s)
    if a is None or (a.t.size - 1) / a.sample_rate_hz < window_s:
        return None
    sm = spectrogram(a.t, a.model, window_s, overlap, fmax_hz=fmax_hz, max_frames=MAX_FRAMES)
    sx = spectrogram(a.t, a.test, window_s, overlap, fmax_hz=fmax_hz, max_frames=MAX_FRAMES)
    valid = _frame_rms(a.test, sx.hop, sx.n_win, sx.t.size) >= floor
    return Ridges(sx.t, ridge_hz(sm.freq_hz, sm.power, fmin_hz, fmax_hz), ridge_hz(sx.freq_hz, sx.power, fmin_hz,
                                                                                     fmax_hz),
                  valid, a.sample_rate_hz / sx.n_win)


# -- envelope ----------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Envelope:
    """The RMS envelopes of a model and a test channel.

    Attributes
    ----------
    t : (n,) ndarray of float
        s, window centres.
    model, test : (n,) ndarray of float
        RMS in each window, the channel's unit.
    floor : float
        The channel's floor.
    """

    t: np.ndarray
    model: np.ndarray
    test: np.ndarray
    floor: float

    @property
    def error(self) -> float:
        """sqrt(sum (e_model - e_test)^2 / sum max(e_test, floor)^2) (NaN: no window, or all zero)."""
        den = float(np.sum(np.maximum(self.test, self.floor) ** 2))
        return math.sqrt(float(np.sum((self.model - self.test) ** 2)) / den) if den > 0 else math.nan

    def residuals(self) -> np.ndarray:
        """(e_model - e_test) / max(e_test, floor) in each window."""
        scale = np.maximum(self.test, self.floor)
        return np.divide(self.model - self.test, scale, out=np.zeros_like(scale), where=scale > 0)


def envelope(pair: ChannelPair, span_s, window_s: float, floor: float = 0.0) -> Envelope | None:
    """The RMS envelopes of a pair in consecutive windows of ``window_s`` over ``span_s`` (the last
    partial window dropped); None without a whole window.

    Parameters
    ----------
    pair : ChannelPair
        Model and test channel.
    span_s : (float, float) or None
        s, absolute times.
    window_s : float
        s, > 0.
    floor : float
        The channel's floor (:func:`bearingshaft.correlate.channel_floors`).

    Returns
    -------
    Envelope or None

    Examples
    --------
    >>> from fem.uff import TimeHistory
    >>> from bearingshaft.correlate import match_channels
    >>> t = np.arange(2000) * 1e-3
    >>> m = TimeHistory("a", 1, 3, "acceleration", 2.0 * np.sin(2 * np.pi * 50 * t), 1e-3)
    >>> x = TimeHistory("a", 1, 3, "acceleration", np.sin(2 * np.pi * 50 * t), 1e-3)
    >>> env = envelope(match_channels([m], [x])[0], None, 0.1)
    >>> env.t.size, round(env.error, 12)  # the model twice the test: the envelope 100 % off
    (20, 1.0)
    """
    window_s = _checks.positive("window_s", window_s, "s")
    a = _span(pair, span_s)
    if a is None:
        return None
    per = max(1, int(round(window_s * a.sample_rate_hz)))
    n = a.t.size // per
    if n == 0:
        return None
    cut = slice(0, n * per)

    def rms_blocks(y):
        return np.sqrt(np.mean(y[cut].reshape(n, per) ** 2, axis=1))

    t = a.t[cut].reshape(n, per).mean(axis=1)
    return Envelope(t, rms_blocks(a.model), rms_blocks(a.test), float(floor))


# -- impacts and the open-gap time ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Impacts:
    """A load cell's impacts as its reading shows them.

    Attributes
    ----------
    start_s, end_s : (k,) ndarray of float
        s, where each excursion above the threshold starts and ends.
    peak_N : (k,) ndarray of float
        N, the largest reading of each (in the contact's sense).
    threshold_N : float
        N.
    duration_s : float
        s, the span searched.
    """

    start_s: np.ndarray
    end_s: np.ndarray
    peak_N: np.ndarray
    threshold_N: float
    duration_s: float

    @property
    def count(self) -> int:
        return int(self.start_s.size)

    @property
    def rate_per_s(self) -> float:
        return self.count / self.duration_s if self.duration_s > 0 else math.nan

    def peak_stat(self, q: float) -> float:
        """The q-quantile (0 .. 1) of the peaks, N (NaN without impacts)."""
        return float(np.quantile(self.peak_N, q)) if self.count else math.nan

    @property
    def last_s(self) -> float:
        """s, the end of the last impact (NaN: none)."""
        return float(self.end_s[-1]) if self.count else math.nan


def impacts_of(t: np.ndarray, y: np.ndarray, threshold: float, sense: float = 1.0) -> Impacts:
    """The excursions of sense * y above ``threshold`` (re-armed below IMPACT_REARM x threshold).

    Parameters
    ----------
    t : (n,) ndarray of float
        s, uniform.
    y : (n,) ndarray of float
        N, a load cell's reading.
    threshold : float
        N, > 0.
    sense : float
        +1 or -1: the sense in which contact loads the cell.

    Returns
    -------
    Impacts

    Examples
    --------
    >>> t = np.arange(12) * 1.0
    >>> y = np.array([0, 5, 9, 4, 6, 1, 0, 8, 2, 0, 3, 0.0])
    >>> imp = impacts_of(t, y, 4.5)  # 9 -> 4 stays above 2.25: one impact; 8 is the second
    >>> imp.count, imp.peak_N.tolist(), imp.start_s.tolist(), imp.end_s.tolist()
    (2, [9.0, 8.0], [1.0, 7.0], [5.0, 8.0])
    """
    z = sense * np.asarray(y, float)
    rearm = IMPACT_REARM * threshold
    starts, ends, peaks = [], [], []
    i, n = 0, z.size
    above = np.flatnonzero(z > threshold)
    while above.size:
        i = int(above[0])
        low = np.flatnonzero(z[i:] < rearm)
        j = i + int(low[0]) if low.size else n
        starts.append(t[i])
        ends.append(t[j] if j < n else t[-1])
        peaks.append(float(np.max(z[i:j])))
        above = above[above >= j]
    dur = float(t[-1] - t[0]) + float(t[1] - t[0]) if t.size > 1 else 0.0
    return Impacts(np.array(starts), np.array(ends), np.array(peaks), float(threshold), dur)


@dataclass(frozen=True, eq=False)
class ImpactComparison:
    """The impacts of a model and a test load cell, one threshold for both.

    Attributes
    ----------
    model, test : Impacts
    sense : float
        The contact's sense on this cell (+1 or -1).
    """

    model: Impacts
    test: Impacts
    sense: float


def impact_comparison(pair: ChannelPair, span_s, whole_s=None) -> ImpactComparison | None:
    """The impacts of a load-cell pair over ``span_s``, the threshold IMPACT_FRACTION of the test's
    largest reading (in its sense) over ``whole_s`` (default: the span); None without samples or
    without a reading.

    Parameters
    ----------
    pair : ChannelPair
        A tip load cell (quantity reaction_force).
    span_s, whole_s : (float, float) or None
        s, absolute times.

    Returns
    -------
    ImpactComparison or None
    """
    whole = _span(pair, whole_s if whole_s is not None else span_s)
    a = _span(pair, span_s)
    if whole is None or a is None:
        return None
    k = int(np.argmax(np.abs(whole.test)))
    peak = float(whole.test[k])
    if peak == 0.0:
        return None
    sense = 1.0 if peak > 0 else -1.0
    thr = IMPACT_FRACTION * abs(peak)
    return ImpactComparison(impacts_of(a.t, a.model, thr, sense), impacts_of(a.t, a.test, thr, sense), sense)


# -- backbones from a ringdown -------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Backbone:
    """Instantaneous frequency and amplitude of one component of a free decay.

    Attributes
    ----------
    t : (k,) ndarray of float
        s, block centres.
    freq_hz : (k,) ndarray of float
        Hz, the block's mean instantaneous frequency (weighted by |z|^2).
    amplitude : (k,) ndarray of float
        The block's amplitude, the RMS of |z| (a sine's amplitude).
    band_hz : (float, float)
        Hz, the band-pass.
    """

    t: np.ndarray
    freq_hz: np.ndarray
    amplitude: np.ndarray
    band_hz: tuple[float, float]


def ringdown_backbone(t: np.ndarray, y: np.ndarray, band_hz: tuple[float, float], floor: float = 0.0,
                      periods: float = BACKBONE_PERIODS, integrate: int = 0) -> Backbone:
    """The backbone of the component of ``y`` in ``band_hz`` (module docstring): Hilbert on the band-passed channel.

    A block is ``periods`` periods of the band's centre sqrt(low high) long. Blocks whose amplitude
    is below ``floor`` or BACKBONE_RANGE of the largest are dropped, and so is one block at
    either end (the filter's and the transform's edge effects).

    Parameters
    ----------
    t : (n,) ndarray of float
        s, uniform.
    y : (n,) ndarray of float
        The channel.
    band_hz : (float, float)
        Hz, 0 < low < high < fs / 2.
    floor : float
        Amplitudes below this are dropped.
    periods : float
        Periods of the band's centre in a block.
    integrate : int
        Integrate the band-passed channel this many times first (in the frequency domain:
        Y(f) / (2 pi i f)^k): 2 turns an acceleration into a displacement, whose harmonics are
        k^2 weaker, so that the impacts' harmonics in the band do not bias the frequency of its
        fundamental.

    Returns
    -------
    Backbone

    Examples
    --------
    >>> t = np.arange(40000) / 4000.0
    >>> y = np.exp(-0.3 * t) * np.cos(2 * np.pi * (100 * t + 2.5 * t**2))  # 100 Hz rising 5 Hz/s
    >>> bb = ringdown_backbone(t, y, (60.0, 200.0))
    >>> k = np.argmin(np.abs(bb.t - 5.0))
    >>> f_err = bb.freq_hz[k] / (100 + 5 * bb.t[k]) - 1  # the chirp's frequency at the block's centre
    >>> a_err = bb.amplitude[k] / np.exp(-0.3 * bb.t[k]) - 1  # |z| = e^{-0.3 t}: its RMS over a 36 ms block
    >>> bool(abs(f_err) < 1e-4 and abs(a_err) < 1e-4)
    True
    """
    from scipy.fft import fft, fftfreq, ifft, next_fast_len
    from scipy.signal import butter, sosfreqz

    t = np.asarray(t, float)
    y = np.asarray(y, float)
    fs = 1.0 / float(t[1] - t[0])
    lo, hi = (float(v) for v in band_hz)
    if not 0 < lo < hi < fs / 2:
        raise ChannelError(f"band_hz must satisfy 0 < low < high < fs / 2 = {fs / 2:.6g} Hz, got {band_hz!r}")
    # the band-pass (forward and back: |H|^2) and the analytic signal in one product of spectra, on the record
    # padded with zeros to twice its length: the kernel of the product decays as the filter's response does, so
    # neither the record's abrupt start nor its wrap onto the end reaches the late, small samples (a plain
    # Hilbert transform's 1 / t tail of the start, at 40 Hz, is 3e-3 of it 3 s later)
    m = next_fast_len(2 * y.size)
    freq = fftfreq(m, 1.0 / fs)
    pos = freq > 0
    gain = np.zeros(m, complex)
    sos = butter(BAND_ORDER, (lo, hi), "bandpass", fs=fs, output="sos")
    gain[pos] = 2.0 * np.abs(sosfreqz(sos, worN=freq[pos], fs=fs)[1]) ** 2
    if integrate:
        gain[pos] /= (2j * np.pi * freq[pos]) ** int(integrate)
    z = ifft(fft(y, m) * gain)[:y.size]
    a2 = np.abs(z) ** 2
    f = np.gradient(np.unwrap(np.angle(z))) * fs / (2 * np.pi)
    per = max(4, int(round(periods * fs / math.sqrt(lo * hi))))
    n = z.size // per
    if n < 3:
        return Backbone(np.empty(0), np.empty(0), np.empty(0), (lo, hi))
    cut = slice(0, n * per)
    w = a2[cut].reshape(n, per)
    wsum = w.sum(axis=1)
    fb = np.divide((f[cut].reshape(n, per) * w).sum(axis=1), wsum, out=np.full(n, math.nan), where=wsum > 0)
    amp = np.sqrt(wsum / per)
    tb = t[cut].reshape(n, per).mean(axis=1)
    keep = np.zeros(n, bool)
    keep[1:-1] = True
    keep &= (amp >= max(floor, BACKBONE_RANGE * float(amp[keep].max(initial=0.0)))) & (amp > 0) & np.isfinite(fb)
    return Backbone(tb[keep], fb[keep], amp[keep], (lo, hi))


def _log_bins(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo = max(float(np.min(a)), float(np.min(b)))
    hi = min(float(np.max(a)), float(np.max(b)))
    if not (lo > 0 and hi > lo):
        return np.empty(0)
    n = max(1, int(math.ceil(BACKBONE_BINS * math.log10(hi / lo))))
    return np.geomspace(lo, hi, n + 1)


def _binned_median(amp: np.ndarray, f: np.ndarray, edges: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(edges, amp, side="right") - 1, 0, edges.size - 2)
    inside = (amp >= edges[0]) & (amp <= edges[-1])
    return np.array([np.median(f[inside & (idx == k)]) if np.any(inside & (idx == k)) else math.nan
                     for k in range(edges.size - 1)])


@dataclass(frozen=True, eq=False)
class BackboneComparison:
    """The backbones of one component in a model and a test channel, compared at the same amplitude.

    Attributes
    ----------
    label : str
        The component (e.g. the NNM it follows).
    model, test : Backbone
    amplitude : (k,) ndarray of float
        Geometric centres of the common log-amplitude bins.
    f_model, f_test : (k,) ndarray of float
        Hz, the median frequency of each in those bins (NaN: a bin one of them misses).
    """

    label: str
    model: Backbone
    test: Backbone
    amplitude: np.ndarray = field(default_factory=lambda: np.empty(0))
    f_model: np.ndarray = field(default_factory=lambda: np.empty(0))
    f_test: np.ndarray = field(default_factory=lambda: np.empty(0))

    @property
    def error(self) -> float:
        """Median over the common bins of |f_model - f_test| / f_test (NaN: none)."""
        ok = np.isfinite(self.f_model) & np.isfinite(self.f_test) & (self.f_test > 0)
        return float(np.median(np.abs(self.f_model[ok] - self.f_test[ok]) / self.f_test[ok])) if ok.any() else math.nan

    def residuals(self) -> np.ndarray:
        """(f_model - f_test) / f_test in the common bins."""
        ok = np.isfinite(self.f_model) & np.isfinite(self.f_test) & (self.f_test > 0)
        return (self.f_model[ok] - self.f_test[ok]) / self.f_test[ok]


def backbone_comparison(pair: ChannelPair, span_s, band_hz: tuple[float, float], label: str = "",
                        floor: float = 0.0, integrate: int = 0) -> BackboneComparison | None:
    """The backbones of the component in ``band_hz`` of a pair over ``span_s`` (a free decay),
    compared at the same amplitude (module docstring); None when the span is too short.

    Parameters
    ----------
    pair : ChannelPair
        Model and test channel.
    span_s : (float, float) or None
        s, absolute times: the free decay.
    band_hz : (float, float)
        Hz, the component's band.
    label : str
        Its name.
    floor : float
        Amplitudes below this are left out.
    integrate : int
        As :func:`ringdown_backbone` (2: an acceleration's component as a displacement).

    Returns
    -------
    BackboneComparison or None
    """
    a = _span(pair, span_s)
    if a is None:
        return None
    bm = ringdown_backbone(a.t, a.model, band_hz, floor, integrate=integrate)
    bx = ringdown_backbone(a.t, a.test, band_hz, floor, integrate=integrate)
    if bm.t.size == 0 or bx.t.size == 0:
        return BackboneComparison(label, bm, bx)
    edges = _log_bins(bm.amplitude, bx.amplitude)
    if edges.size < 2:
        return BackboneComparison(label, bm, bx)
    return BackboneComparison(label, bm, bx, np.sqrt(edges[:-1] * edges[1:]), _binned_median(bm.amplitude,
                              bm.freq_hz, edges), _binned_median(bx.amplitude, bx.freq_hz, edges))


def distance_to_curve(bb: Backbone, amplitude: np.ndarray, freq_hz: np.ndarray) -> float:
    """Median of |f - f_curve(a)| / f_curve(a) over the backbone's points within the curve's
    amplitude range, f_curve interpolated in log amplitude (NaN: no point in range).

    Parameters
    ----------
    bb : Backbone
        A ringdown's backbone.
    amplitude, freq_hz : (m,) ndarray of float
        A backbone curve (e.g. an NNM's, HB), in the channel's amplitude and Hz.

    Returns
    -------
    float

    Examples
    --------
    >>> bb = Backbone(np.zeros(3), np.array([10.0, 11.0, 12.0]), np.array([1.0, 10.0, 100.0]), (5.0, 20.0))
    >>> distance_to_curve(bb, np.array([1.0, 100.0]), np.array([10.0, 12.0]))  # 11 on a curve at 11
    0.0
    """
    order = np.argsort(amplitude)
    a, f = np.asarray(amplitude, float)[order], np.asarray(freq_hz, float)[order]
    ok = (a > 0) & np.isfinite(f)
    a, f = a[ok], f[ok]
    if a.size < 2:
        return math.nan
    inside = (bb.amplitude >= a[0]) & (bb.amplitude <= a[-1])
    if not inside.any():
        return math.nan
    fc = np.interp(np.log(bb.amplitude[inside]), np.log(a), f)
    return float(np.median(np.abs(bb.freq_hz[inside] - fc) / fc))


# -- all of them ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MeasureSet:
    """What :func:`compare` measured.

    Attributes
    ----------
    rows : list of dict
        One per measure, channel and statistic (keys MEASURE_FIELDS).
    ridges : dict
        {channel: Ridges}.
    envelopes : dict
        {channel: Envelope}.
    impacts : dict
        {channel: ImpactComparison}.
    backbones : dict
        {(channel, label): BackboneComparison}.
    spans : dict
        {measure: (t_start_s, t_end_s)} the span each was measured over.
    """

    rows: list
    ridges: dict
    envelopes: dict
    impacts: dict
    backbones: dict
    spans: dict

    def summary(self, measure: str) -> float:
        """The median over channels of a measure's main error (NaN: not measured)."""
        main = {"ridges": "ridge frequency", "envelope": "RMS envelope", "impacts": "impacts",
                "open": "open after", "backbone": "frequency at equal amplitude"}.get(measure)
        vals = [r["error"] for r in self.rows if r["measure"] == measure and r["statistic"] == main
                and math.isfinite(r["error"])]
        return float(np.median(vals)) if vals else math.nan


def parse_measures(text: str | None) -> tuple[str, ...]:
    """The measures named in ``text`` (comma separated; None, "" or "all": every one), in MEASURES order.

    Parameters
    ----------
    text : str or None

    Returns
    -------
    tuple of str

    Examples
    --------
    >>> parse_measures("envelope, time"), parse_measures(None) == MEASURES
    (('time', 'envelope'), True)
    """
    import difflib

    if text is None or text.strip() in ("", "all"):
        return MEASURES
    names = [w.strip() for w in text.split(",") if w.strip()]
    for w in names:
        if w not in MEASURES:
            close = difflib.get_close_matches(w, MEASURES, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ChannelError(f"--measures: unknown measure {w!r}{hint}; known: {', '.join(MEASURES)}, or all")
    return tuple(m for m in MEASURES if m in names)


def _rel(m: float, x: float, floor: float = 0.0) -> float:
    scale = max(abs(x), floor)
    if not (math.isfinite(m) and math.isfinite(x)):
        return math.nan
    return (m - x) / scale if scale > 0 else (0.0 if m == x else math.inf)


def _row(measure, channel, statistic, unit, model, test, error, span) -> dict:
    return {"measure": measure, "channel": channel, "statistic": statistic, "unit": unit, "model": model,
            "test": test, "error": error, "t_start_s": span[0], "t_end_s": span[1]}


def _ridge_rows(pairs, span, floors, window_s, overlap, fmin_hz, fmax_hz, out, rows):
    for p in pairs:
        r = ridges(p, span, window_s, overlap, fmin_hz, fmax_hz, floors.get(p.name, (0.0, ""))[0])
        if r is None:
            continue
        out[p.name] = r
        ok = r.valid
        fm = float(np.nanmedian(r.f_model[ok])) if np.any(ok & np.isfinite(r.f_model)) else math.nan
        fx = float(np.nanmedian(r.f_test[ok])) if np.any(ok & np.isfinite(r.f_test)) else math.nan
        rows.append(_row("ridges", p.name, "ridge frequency", "Hz", fm, fx, r.error, span))
        rows.append(_row("ridges", p.name, "frames within one bin", "", math.nan, math.nan, r.agreement, span))


def _impact_rows(pairs, span, whole, measures, out, rows):
    for p in pairs:
        if p.quantity != CONTACT_QUANTITY:
            continue
        if "impacts" in measures:
            c = impact_comparison(p, span, whole)
            if c is not None:
                out[p.name] = c
                m, x = c.model, c.test
                rows.append(_row("impacts", p.name, "impacts", "", m.count, x.count, _rel(m.count, x.count, 1.0),
                                 span))
                rows.append(_row("impacts", p.name, "impact rate", "1/s", m.rate_per_s, x.rate_per_s,
                                 _rel(m.rate_per_s, x.rate_per_s), span))
                for q, name in ((0.5, "median peak force"), (0.9, "90 % peak force"), (1.0, "largest peak force")):
                    rows.append(_row("impacts", p.name, name, "N", m.peak_stat(q), x.peak_stat(q),
                                     _rel(m.peak_stat(q), x.peak_stat(q)), span))
        if "open" in measures:
            c = impact_comparison(p, whole, whole)
            if c is not None:
                t0 = whole[0] if whole is not None else float(p.model.t0_s)
                m, x = c.model.last_s, c.test.last_s
                rows.append(_row("open", p.name, "open after", "s", m, x,
                                 _rel(m - t0, x - t0) if math.isfinite(m) and math.isfinite(x) else math.nan, whole))


def compare(pairs: list[ChannelPair], window_s: tuple[float, float], horizon_s: float,
            floors: dict[str, tuple[float, str]], measures=MEASURES, *, frame_s: float = 0.05, overlap: float = 0.9,
            fmin_hz: float = RIDGE_FMIN_HZ, fmax_hz: float | None = None, free_s: float | None = None,
            bands: dict | None = None) -> MeasureSet:
    """The measures that survive chaos (module docstring) of ``pairs``: ridges and impact statistics
    past the horizon, the RMS envelope over the whole window, the open-gap time, the backbones
    over the free decay.

    Parameters
    ----------
    pairs : list of ChannelPair
        The compared channels (:func:`bearingshaft.correlate.match_channels`).
    window_s : (float, float)
        s, the compared window, absolute times.
    horizon_s : float
        s, the predictability horizon (inf: none; then the ridges and impacts are over the window).
    floors : dict
        {channel: (floor, basis)} from :func:`bearingshaft.correlate.channel_floors`.
    measures : iterable of str
        Among MEASURES ("time" is the pointwise error: not here).
    frame_s, overlap : float
        s and fraction, the ridges' frames and the envelope's windows (frame_s).
    fmin_hz, fmax_hz : float
        Hz, the ridges' band.
    free_s : float or None
        s, where the free decay starts (the backbones'; default: the window's start).
    bands : dict or None
        {channel: [(label, (f_low_hz, f_high_hz)), ...]}: the components whose backbones are measured.

    Returns
    -------
    MeasureSet
    """
    a, b = window_s
    post = (max(a, horizon_s), b) if math.isfinite(horizon_s) and horizon_s < b else (a, b)
    free = (max(a, free_s if free_s is not None else a), b)
    rows: list[dict] = []
    out_r, out_e, out_i, out_b = {}, {}, {}, {}
    if "ridges" in measures:
        _ridge_rows(pairs, post, floors, frame_s, overlap, fmin_hz, fmax_hz, out_r, rows)
    if "envelope" in measures:
        for p in pairs:
            env = envelope(p, (a, b), frame_s, floors.get(p.name, (0.0, ""))[0])
            if env is not None:
                out_e[p.name] = env
                rows.append(_row("envelope", p.name, "RMS envelope", p.unit, rms(env.model), rms(env.test),
                                 env.error, (a, b)))
    if "impacts" in measures or "open" in measures:
        _impact_rows(pairs, post, (a, b), measures, out_i, rows)
    if "backbone" in measures and bands:
        by = {p.name: p for p in pairs}
        for name, comps in bands.items():
            for label, band in comps:
                fl, basis = floors.get(name, (0.0, ""))
                integrate = 2 if by[name].quantity == "acceleration" else 0  # the component's displacement
                c = backbone_comparison(by[name], free, band, label, 0.0 if integrate or basis != "noise" else fl,
                                        integrate)
                if c is None:
                    continue
                out_b[(name, label)] = c
                top = np.flatnonzero(np.isfinite(c.f_model) & np.isfinite(c.f_test))
                fm = float(c.f_model[top[-1]]) if top.size else math.nan
                fx = float(c.f_test[top[-1]]) if top.size else math.nan
                rows.append(_row("backbone", f"{name} ({label})", "frequency at equal amplitude", "Hz", fm, fx,
                                 c.error, free))
    spans = {"ridges": post, "impacts": post, "envelope": (a, b), "open": (a, b), "backbone": free}
    return MeasureSet(rows, out_r, out_e, out_i, out_b, {m: spans[m] for m in measures if m in spans})


__all__ = [
    "MEASURES", "MEASURE_FIELDS", "Ridges", "ridges", "ridge_hz", "Envelope", "envelope", "Impacts", "impacts_of",
    "ImpactComparison", "impact_comparison", "Backbone", "ringdown_backbone", "BackboneComparison",
    "backbone_comparison", "distance_to_curve", "MeasureSet", "compare", "parse_measures",
]
