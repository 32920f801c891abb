"""The dominant frequency of a record: one estimator for the sweep's metrics, the hammer test's
correlation and a spectrogram's frames.

The record y_0 ... y_{N-1}, sampled at fs, is cut into segments s of n_seg samples (half
overlapping, Welch's average; by default one segment, the whole record), each with its mean
removed and a Hann window w (``numpy.hanning(n_seg)``) applied::

    Y_s(f) = sum_k w_k (y_{s,k} - mean_s) e^{-2 pi i f k / fs},     A(f) = sqrt(mean_s |Y_s(f)|^2)

and the dominant frequency is the f > 0 in [fmin_hz, fmax_hz] where A peaks: the largest bin of A on
a zero-padded grid (PAD x the next power of two of n_seg points, fs / nfft apart) refined by a
bounded scalar search of A(f) itself within one padded bin either side (the bin's own frequency
when the search finds nothing larger). For a damped sinusoid e^{-sigma t} cos(2 pi f_d t + phi)
in one segment this is f_d (the transform of the positive envelope w e^{-sigma t} peaks at zero)
up to the leakage of the negative-frequency image, which falls as the cube of the periods in the
segment: measured 2e-5 (relative) with 9 periods, 1e-6 with 18, 3e-4 with 2 (tests/test_sweep.py).

A spectrogram keeps the power of its frames, not their samples: given power spectra on their
frequencies (``freq_hz=``), the estimate is the largest bin in the band, unrefined.
"""

from __future__ import annotations

import math

import numpy as np

PAD = 8  # zero padding of a segment's DFT before the peak is refined
MIN_SAMPLES = 8  # shorter records (or segments) give NaN: no peak to speak of


def segment_length(n_samples: int, sample_rate_hz: float, resolution_hz: float) -> int:
    """Samples in a segment whose DFT bins are ``resolution_hz`` apart, at most the record, at least MIN_SAMPLES.

    Parameters
    ----------
    n_samples : int
        Samples of the record.
    sample_rate_hz : float
        Hz.
    resolution_hz : float
        Hz, the bin spacing wanted.

    Returns
    -------
    int
        min(n_samples, max(MIN_SAMPLES, round(sample_rate_hz / resolution_hz))).

    Examples
    --------
    >>> segment_length(10_000, 1000.0, 2.0), segment_length(300, 1000.0, 2.0), segment_length(100, 1000.0, 500.0)
    (500, 300, 8)
    """
    return int(min(n_samples, max(MIN_SAMPLES, round(sample_rate_hz / resolution_hz))))


def _segments(y: np.ndarray, n_seg: int) -> list[np.ndarray]:
    """The half-overlapping segments of y, each less its mean (the whole record when n_seg >= N).

    >>> [s.tolist() for s in _segments(np.arange(10.0), 4)]
    [[-1.5, -0.5, 0.5, 1.5], [-1.5, -0.5, 0.5, 1.5], [-1.5, -0.5, 0.5, 1.5], [-1.5, -0.5, 0.5, 1.5]]
    """
    if n_seg >= y.size:
        return [y - np.mean(y)]
    step = n_seg - n_seg // 2
    return [y[i:i + n_seg] - np.mean(y[i:i + n_seg]) for i in range(0, y.size - n_seg + 1, step)]


def _band(freq_hz: np.ndarray, fmin_hz: float, fmax_hz: float | None) -> np.ndarray:
    """The frequencies searched: fmin_hz <= f <= fmax_hz, and f > 0 (a mean is not a frequency).

    >>> f = np.array([0.0, 5.0, 10.0, 15.0])
    >>> _band(f, 0.0, None).tolist(), _band(f, 5.0, 5.0).tolist()
    ([False, True, True, True], [False, True, False, False])
    """
    band = (freq_hz >= fmin_hz) & (freq_hz > 0.0)
    if fmax_hz is not None:
        band &= freq_hz <= fmax_hz
    return band


def _peak_bins(freq_hz: np.ndarray, power: np.ndarray, fmin_hz: float, fmax_hz: float | None) -> np.ndarray:
    """Hz, the frequency of the largest ``power`` (rows on ``freq_hz``) in the band, per column;
    NaN for a column without power there."""
    band = _band(freq_hz, fmin_hz, fmax_hz)
    out = np.full(power.shape[1], np.nan)
    if not np.any(band) or power.shape[1] == 0:
        return out
    p = power[band]
    k = np.argmax(p, axis=0)
    has = np.any(p > 0.0, axis=0)
    out[has] = freq_hz[band][k[has]]
    return out


def dominant_freq_hz(y: np.ndarray, sample_rate_hz: float | None, fmin_hz: float = 0.0,
                     fmax_hz: float | None = None, *, segment: int | None = None,
                     freq_hz: np.ndarray | None = None) -> float | np.ndarray:
    """Hz, the dominant frequency of a record in [fmin_hz, fmax_hz] (the module docstring says how).

    Parameters
    ----------
    y : (N,) samples of the record; or, with ``freq_hz``, power spectra (n_freq, n_frames), one
        frame per column on the frequencies ``freq_hz`` (a spectrogram's |STFT|^2)
    sample_rate_hz : Hz, fs of the record (not used for power spectra: None)
    fmin_hz, fmax_hz : Hz, the band searched, ends included, DC never (default: above 0 to fs / 2)
    segment : samples per Welch segment (default: the whole record, one segment)
    freq_hz : Hz, (n_freq,) the frequencies of the rows of ``y`` when ``y`` holds power spectra

    Returns
    -------
    float, Hz: NaN when the record is shorter than MIN_SAMPLES or has no power in the band; with
    ``freq_hz``, an (n_frames,) array, the largest bin of each frame (NaN for a frame without power).
    """
    if freq_hz is not None:
        return _peak_bins(np.asarray(freq_hz, float), np.asarray(y, float), fmin_hz, fmax_hz)
    from scipy.optimize import minimize_scalar

    fs = float(sample_rate_hz)
    y = np.asarray(y, float)
    n_seg = y.size if segment is None else min(int(segment), y.size)
    segs = _segments(y, n_seg)
    if n_seg < MIN_SAMPLES or not any(np.any(s) for s in segs):
        return math.nan
    w = np.hanning(n_seg)
    yws = [s * w for s in segs]
    nfft = PAD * (1 << int(np.ceil(np.log2(n_seg))))
    Yw = np.array(yws) if len(yws) > 1 else None
    if Yw is None:
        spec = np.abs(np.fft.rfft(yws[0], nfft))
    else:
        spec = np.sqrt(np.mean(np.abs(np.fft.rfft(Yw, nfft, axis=1)) ** 2, axis=0))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    band = _band(f, fmin_hz, fmax_hz)
    if not np.any(band) or not np.any(spec[band]):
        return math.nan
    k = int(np.flatnonzero(band)[np.argmax(spec[band])])
    df = fs / nfft
    t = np.arange(n_seg) / fs

    def neg(fq: float) -> float:  # -A(fq)
        if Yw is None:
            return -abs(np.dot(yws[0], np.exp(-2j * np.pi * fq * t)))
        phase = 2.0 * np.pi * fq * t  # real products: a complex one would cast every segment each call
        re, im = Yw @ np.cos(phase), Yw @ np.sin(phase)
        return -math.sqrt(float(np.mean(re * re + im * im)))

    lo, hi = max(f[k] - df, fmin_hz), min(f[k] + df, fs / 2)
    if fmax_hz is not None:
        hi = min(hi, fmax_hz)
    res = minimize_scalar(neg, bounds=(lo, hi), method="bounded", options={"xatol": df * 1e-7})
    return float(res.x) if -res.fun >= spec[k] else float(f[k])
