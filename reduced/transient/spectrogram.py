"""Short-time Fourier transform of a ringdown and the NNM curves mapped onto time.

The STFT uses a Hann window of ``window_s`` seconds (n_win = round(window_s fs) samples)
moved by hop = round((1 - overlap) n_win) samples, the convention and scaling of
``scipy.signal.ShortTimeFFT(hann(n_win, sym=False), hop, fs, scale_to="psd")``: frame p is
centred on sample p hop, covers samples p hop - n_win // 2 ... + n_win, and

    S_p(f) = |sum_k w_k (y_{p hop - n_win//2 + k} - ybar) e^{-2 pi i f k / fs}|^2,
    w = hann / sqrt(fs sum hann^2)   (power spectral density, signal units^2 / Hz),

for the frames that lie wholly inside the record. A long record is transformed from
chunks of samples (:class:`StftAccumulator`) and, when it would give more than
``max_frames`` frames, with the hop lengthened by a whole factor so that it gives at most
that many: memory is one chunk plus the frames kept, whatever the record's length.

A frequency-energy curve f(E) of an NNM becomes a curve in time through the ringdown's
energy, f(t) = f(E(t)), interpolated in log E.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.fft import rfft, rfftfreq

from reduced import _checks as _check
from reduced.transient.spectral import dominant_freq_hz

MAX_FRAMES = 4000  # frames of a long record's spectrogram (the hop grows to keep to this)
BATCH_FLOATS = 1 << 18  # samples transformed at once (frames x n_win): 2 MB a copy
LEADING_ZEROS = 1  # hann(n, sym=False)[0] == 0: a frame's first sample is never weighted


@dataclass(frozen=True, eq=False)
class Spectrogram:
    """|STFT|^2 of a signal: ``power[f, t]`` on ``freq_hz`` x ``t``.

    Attributes
    ----------
    t : (n_frames,) ndarray of float
        s, frame centres.
    freq_hz : (n_freq,) ndarray of float
        Hz, bin frequencies from 0.
    power : (n_freq, n_frames) ndarray of float
        Power spectral density, signal units^2 / Hz.
    hop : int
        Samples between frames.
    n_win : int
        Samples in a window.
    """

    t: np.ndarray  # s, frame centres
    freq_hz: np.ndarray  # Hz
    power: np.ndarray  # (n_freq, n_frames), power spectral density, signal units^2 / Hz
    hop: int = 0  # samples between frames
    n_win: int = 0  # samples in a window

    def dominant_freq_hz(self, fmin_hz: float = 0.0) -> np.ndarray:
        """Hz, the frequency of the largest power in each frame, at or above ``fmin_hz`` and above 0
        (:func:`reduced.transient.spectral.dominant_freq_hz` of the frames' power; NaN for a frame
        without power there)."""
        return dominant_freq_hz(self.power, None, fmin_hz, freq_hz=self.freq_hz)


def frame_grid(n_samples: int, sample_rate_hz: float, window_s: float, overlap: float,
               max_frames: int | None = None) -> tuple[int, int, int, int]:
    """(n_win, hop, p_lo, p_hi): window and hop in samples and the frames p_lo <= p < p_hi inside
    the record (ShortTimeFFT's ``lower_border_end`` and ``upper_border_begin``: the periodic
    Hann window's first value is 0, so a frame may start one sample before the record).

    Parameters
    ----------
    n_samples : int
        Samples of the record.
    sample_rate_hz : float
        Hz.
    window_s : float
        s, window length (n_win = max(8, round(window_s fs))).
    overlap : float
        Fraction of a window shared by consecutive frames, in [0, 1).
    max_frames : int, optional
        Lengthen the hop so that at most this many frames lie inside the record.

    Returns
    -------
    n_win, hop, p_lo, p_hi : int

    Raises
    ------
    InvalidArgument
        A window longer than the record.
    """
    n_win = max(8, int(round(window_s * sample_rate_hz)))
    if n_win > n_samples:
        raise _check.InvalidArgument(f"window_s = {window_s} s is longer than the record "
                                     f"({n_samples / sample_rate_hz:.3g} s)")
    hop = max(1, int(round(n_win * (1.0 - overlap))))
    mid = n_win // 2 - LEADING_ZEROS

    def bounds(h: int) -> tuple[int, int]:
        lo = -(-mid // h)  # first frame whose weighted samples start at or after sample 0
        hi = (n_samples - n_win + n_win // 2) // h + 1  # first frame whose window runs past the end
        return lo, max(hi, lo)

    p_lo, p_hi = bounds(hop)
    if max_frames is not None and p_hi - p_lo > max_frames:
        hop *= math.ceil((p_hi - p_lo) / max_frames)
        p_lo, p_hi = bounds(hop)
        while p_hi - p_lo > max_frames:  # ceil of the frame count can leave one too many
            hop += 1
            p_lo, p_hi = bounds(hop)
    return n_win, hop, p_lo, p_hi


class StftAccumulator:
    """The spectrogram of a record fed in consecutive chunks: ``feed(start, y)``, then ``result()``.

    Holds the samples of the frame being assembled and the frames kept (rows up to
    ``fmax_hz``), never the record. ``mean`` is subtracted from every sample (the record's
    mean for a global detrend, as :func:`spectrogram`; 0 when it is not known in advance).

    Parameters
    ----------
    n_samples : int
        Samples of the record.
    sample_rate_hz : float
        Hz.
    window_s : float
        s, window length.
    overlap : float
        In [0, 1).
    mean : float
        Subtracted from every sample.
    fmax_hz : float, optional
        Keep the bins up to this frequency (default all).
    max_frames : int, optional
        Most frames kept (the hop is lengthened; None: no limit).
    t0 : float
        s, time of sample 0 (shifts the frame times).

    Raises
    ------
    InvalidArgument
        An argument out of range, or a window longer than the record.
    """

    def __init__(self, n_samples: int, sample_rate_hz: float, window_s: float, overlap: float, *,
                 mean: float = 0.0, fmax_hz: float | None = None, max_frames: int | None = MAX_FRAMES,
                 t0: float = 0.0) -> None:
        self.n_samples = _check.integer("n_samples", n_samples)
        self.fs = _check.positive("sample_rate_hz", sample_rate_hz, "Hz")
        window_s = _check.positive("window_s", window_s, "s")
        overlap = _check.number("overlap", overlap, lo=0.0, hi=1.0, lo_open=False)
        self.mean = _check.number("mean", mean)
        if fmax_hz is not None:
            fmax_hz = _check.positive("fmax_hz", fmax_hz, "Hz")
        if max_frames is not None:
            max_frames = _check.integer("max_frames", max_frames)
        self.t0 = _check.number("t0", t0, unit="s")
        self.n_win, self.hop, self.p_lo, self.p_hi = frame_grid(n_samples, self.fs, window_s, overlap, max_frames)
        # the window exactly as ShortTimeFFT scales it for a power spectral density (scipy.signal is imported
        # here, not with the module: it takes ~0.5 s, and a run without a spectrogram never needs it)
        from scipy.signal import ShortTimeFFT
        from scipy.signal.windows import hann

        self.win = ShortTimeFFT(hann(self.n_win, sym=False), hop=self.hop, fs=self.fs, scale_to="psd").win
        f = rfftfreq(self.n_win, 1.0 / self.fs)
        self.n_keep = f.size if fmax_hz is None else max(1, int(np.searchsorted(f, fmax_hz, side="right")))
        self.freq_hz = f[: self.n_keep]
        self.power = np.empty((self.n_keep, self.p_hi - self.p_lo))
        self.p = self.p_lo  # next frame to compute
        first = self._start(self.p_lo)
        self.b0 = min(first, 0)  # sample index of buf[0]: a frame may start on the zero-weight sample -1
        self.buf = np.zeros(-self.b0)
        self.next_start = 0  # sample index the next chunk must start at

    def _start(self, p: int) -> int:
        return p * self.hop - self.n_win // 2

    def feed(self, start: int, y: np.ndarray) -> None:
        """The samples start .. start + len(y) - 1 of the record."""
        if start != self.next_start:
            raise ValueError(f"chunks must be consecutive: expected sample {self.next_start}, got {start}")
        y = np.asarray(y, dtype=float)
        self.next_start = start + y.size
        if self.p >= self.p_hi:
            return
        first = self._start(self.p)
        lo = max(first - start, 0)  # samples before the next frame are not needed
        if lo >= y.size:
            self.b0 = start + y.size
            self.buf = np.empty(0)
            return
        if self.buf.size == 0 and self.b0 >= 0:
            self.b0 = start + lo
            self.buf = y[lo:] - self.mean
        else:
            self.buf = np.concatenate([self.buf, y[lo:] - self.mean])
        end = self.b0 + self.buf.size
        p_end = self.p
        while p_end < self.p_hi and self._start(p_end) + self.n_win <= end:
            p_end += 1
        batch = max(1, BATCH_FLOATS // self.n_win)
        for p0 in range(self.p, p_end, batch):
            p1 = min(p0 + batch, p_end)
            idx = self._start(p0) - self.b0 + np.arange(p1 - p0)[:, None] * self.hop + np.arange(self.n_win)
            spec = rfft(self.buf[idx] * self.win, axis=1)[:, : self.n_keep]
            self.power[:, p0 - self.p_lo : p1 - self.p_lo] = (spec.real**2 + spec.imag**2).T
        self.p = p_end
        keep_from = self._start(self.p) - self.b0 if self.p < self.p_hi else self.buf.size
        keep_from = min(max(keep_from, 0), self.buf.size)
        self.buf = self.buf[keep_from:].copy()
        self.b0 += keep_from

    def result(self) -> Spectrogram:
        """The spectrogram of every frame inside the record (all samples must have been fed)."""
        if self.p < self.p_hi:
            raise ValueError(f"spectrogram: {self.p_hi - self.p} frames not filled (record fed up to sample "
                             f"{self.next_start} of {self.n_samples})")
        t = self.t0 + np.arange(self.p_lo, self.p_hi) * self.hop / self.fs
        return Spectrogram(t=t, freq_hz=self.freq_hz, power=self.power, hop=self.hop, n_win=self.n_win)


def spectrogram_chunks(chunks: Iterable[tuple[int, np.ndarray]], n_samples: int, sample_rate_hz: float,
                       window_s: float, overlap: float, *, mean: float = 0.0, fmax_hz: float | None = None,
                       max_frames: int | None = MAX_FRAMES, t0: float = 0.0) -> Spectrogram:
    """The spectrogram of a record given as consecutive (start, samples) chunks (see the module
    docstring); ``mean`` is subtracted first (pass the record's mean for :func:`spectrogram`'s
    global detrend).

    Parameters
    ----------
    chunks : iterable of (int, ndarray)
        (index of the first sample, samples) of consecutive chunks of the record.
    n_samples : int
        Samples of the record.
    sample_rate_hz : float
        Hz.
    window_s : float
        s, window length.
    overlap : float
        In [0, 1).
    mean, fmax_hz, max_frames, t0
        As :class:`StftAccumulator`.

    Returns
    -------
    Spectrogram

    Raises
    ------
    InvalidArgument
        As :class:`StftAccumulator`.
    ValueError
        Chunks that are not consecutive, or a record not fed to its end.
    """
    acc = StftAccumulator(n_samples, sample_rate_hz, window_s, overlap, mean=mean, fmax_hz=fmax_hz,
                          max_frames=max_frames, t0=t0)
    for start, y in chunks:
        acc.feed(start, y)
    return acc.result()


def spectrogram(t: np.ndarray, y: np.ndarray, window_s: float, overlap: float, *, fmax_hz: float | None = None,
                max_frames: int | None = None) -> Spectrogram:
    """Hann-window STFT of samples y(t) on a uniform grid, minus their mean; frames inside the record only.

    Parameters
    ----------
    t : (N,) s, uniform, increasing
    y : (N,) the signal
    window_s : s, window length (> 0, at most the record)
    overlap : in [0, 1)
    fmax_hz : keep frequencies up to this (default all)
    max_frames : lengthen the hop to keep at most this many frames (default: no limit)

    Returns
    -------
    Spectrogram : frames centred at t[0] + p hop / fs, power in units of y^2 / Hz
    """
    t = _check.series("t", t, min_len=2)
    y = _check.series("y", y)
    if y.shape != t.shape:
        raise _check.InvalidArgument(f"y must have one value per time in t ({t.size}), got shape {y.shape}")
    dt = t[1] - t[0]
    if not dt > 0:
        raise _check.InvalidArgument(f"t must increase, got t[1] - t[0] = {dt!r}")
    return spectrogram_chunks([(0, y)], y.size, 1.0 / dt, window_s, overlap, mean=float(np.mean(y)),
                              fmax_hz=fmax_hz, max_frames=max_frames, t0=float(t[0]))


def curve_in_time(energy_t: np.ndarray, energy_J: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
    """Hz, f(E(t)) from a frequency-energy curve (NaN outside the curve's energy range).

    Parameters
    ----------
    energy_t : (k,) array_like of float
        J, the ringdown's energy at each time of interest.
    energy_J : (m,) array_like of float
        J, the curve's energies, > 0 (any order).
    freq_hz : (m,) array_like of float
        Hz, the curve's frequency at each energy.

    Returns
    -------
    (k,) ndarray of float
        Hz.

    Raises
    ------
    InvalidArgument
        energy_J not 1-D, or freq_hz not of its shape.
    """
    energy_t = np.asarray(energy_t, dtype=float)
    E = np.asarray(energy_J, dtype=float)
    f = np.asarray(freq_hz, dtype=float)
    if E.ndim != 1:
        raise _check.InvalidArgument(f"energy_J must be a 1-D array, got shape {E.shape}")
    if f.shape != E.shape:
        raise _check.InvalidArgument(f"freq_hz must have one value per energy in energy_J ({E.size}), "
                                     f"got shape {f.shape}")
    order = np.argsort(E)
    E, f = E[order], f[order]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.interp(np.log(energy_t), np.log(E), f, left=np.nan, right=np.nan)
    return out
