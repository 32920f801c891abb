"""Short-time Fourier transform of a ringdown and the NNM curves mapped onto time.

The STFT uses a Hann window of ``window_s`` seconds moved by ``(1 - overlap) window_s``
(scipy.signal.ShortTimeFFT). A frequency-energy curve f(E) of an NNM becomes a curve in
time through the ringdown's energy, f(t) = f(E(t)), interpolated in log E.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import ShortTimeFFT
from scipy.signal.windows import hann


@dataclass(frozen=True, eq=False)
class Spectrogram:
    """|STFT|^2 of a signal: ``power[f, t]`` on ``freq_hz`` x ``t``."""

    t: np.ndarray  # s, frame centres
    freq_hz: np.ndarray  # Hz
    power: np.ndarray  # (n_freq, n_frames), power spectral density, signal units^2 / Hz


def spectrogram(t: np.ndarray, y: np.ndarray, window_s: float, overlap: float) -> Spectrogram:
    """Hann-window STFT of samples y(t) on a uniform grid; frames inside the record only."""
    fs = 1.0 / (t[1] - t[0])
    nwin = max(8, int(round(window_s * fs)))
    if nwin > y.size:
        raise ValueError(f"window_s = {window_s} s is longer than the record ({y.size / fs:.3g} s)")
    hop = max(1, int(round(nwin * (1.0 - overlap))))
    stft = ShortTimeFFT(hann(nwin, sym=False), hop=hop, fs=fs, scale_to="psd")
    S = stft.spectrogram(y - np.mean(y))
    tt = stft.t(y.size)
    lo, hi = stft.lower_border_end[1], stft.upper_border_begin(y.size)[1]
    return Spectrogram(t=tt[lo:hi] + t[0], freq_hz=stft.f, power=S[:, lo:hi])


def curve_in_time(energy_t: np.ndarray, energy_J: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
    """Hz, f(E(t)) from a frequency-energy curve (NaN outside the curve's energy range)."""
    order = np.argsort(energy_J)
    E, f = np.asarray(energy_J)[order], np.asarray(freq_hz)[order]
    with np.errstate(divide="ignore"):
        out = np.interp(np.log(energy_t), np.log(E), f, left=np.nan, right=np.nan)
    return out
