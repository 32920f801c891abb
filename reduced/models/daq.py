"""The acquisition of a virtual test: anti-alias filter and decimation, as a test's DAQ does.

A measured channel is low-passed before it is sampled, so that nothing above half the
sampling rate fs folds into the band. A model sampled at fs without that filter folds every
mode it has above fs/2 into the band (a 1 ms blow rings every mode up to tens of kHz). The
virtual rig records the way a delta-sigma DAQ does instead:

1. the channels u are computed at the fine rate q fs, the integer q the smallest with
   q fs / 2 >= MARGIN f_max, f_max the highest frequency the model rings at (its stiffest
   contact state), so the fine samples do not alias;
2. they are low-passed by a linear-phase FIR h of odd length L = 2 q m + 1 (Kaiser window,
   flat to 10^(-ATTEN_DB/20) up to PASSBAND fs, attenuated by ATTEN_DB from fs/2 on) with
   its delay D = (L - 1)/2 compensated, as a DAQ's decimation filter is:

       y[k] = sum_j h[j] u[q k + D - j],   k = 0, 1, ..., N - 1,

   so a channel's phase is that of the motion (no group delay);
3. every q-th filtered sample is kept: y is sampled at fs.

The record starts at rest (u = 0 before it), so the filter's start is exact; its end needs
``tail_samples`` fine samples past the last kept one, which the caller integrates on.

Nothing here integrates or models: it is signal processing on the recorded channels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PASSBAND = 0.4  # of fs: the band the acquisition keeps flat (a delta-sigma DAQ's alias-free band is 0.4-0.45 fs)
ATTEN_DB = 100.0  # dB, stop-band attenuation from fs/2 on (and pass-band ripple 1e-5)
MARGIN = 1.2  # the fine Nyquist frequency exceeds the model's highest frequency by this factor


def oversampling(f_max_hz: float, sample_rate_hz: float, margin: float = MARGIN) -> int:
    """The smallest integer q with q fs / 2 >= margin f_max (at least 1).

    Parameters
    ----------
    f_max_hz : float
        Hz, highest frequency the model rings at, >= 0.
    sample_rate_hz : float
        Hz, fs of the record, > 0.
    margin : float
        Factor by which the fine Nyquist frequency exceeds f_max.

    Returns
    -------
    int
        q >= 1.

    Raises
    ------
    ValueError
        f_max_hz negative or not finite, or sample_rate_hz not > 0.
    """
    if not (np.isfinite(f_max_hz) and f_max_hz >= 0 and sample_rate_hz > 0):
        raise ValueError(f"need f_max_hz >= 0 and sample_rate_hz > 0, got {f_max_hz!r}, {sample_rate_hz!r}")
    return max(1, math.ceil(2.0 * margin * f_max_hz / sample_rate_hz))


@dataclass(frozen=True)
class Acquisition:
    """Anti-alias filter and decimation of channels computed at ``oversample`` x ``sample_rate_hz``.

    Parameters
    ----------
    sample_rate_hz : float
        Hz, fs, the rate of the record, > 0.
    oversample : int
        q >= 1: the channels are computed at q fs.
    passband : float
        Edge of the flat band as a fraction of fs, in (0, 0.5).
    atten_db : float
        dB, stop-band attenuation from fs/2 on.

    Raises
    ------
    ValueError
        A rate not > 0, an oversampling factor that is not an integer >= 1, or a passband
        outside (0, 0.5).
    """

    sample_rate_hz: float  # Hz, fs: the rate of the record
    oversample: int = 1  # q: the channels are computed at q fs
    passband: float = PASSBAND
    atten_db: float = ATTEN_DB

    def __post_init__(self) -> None:
        if not (self.sample_rate_hz > 0 and int(self.oversample) == self.oversample >= 1):
            raise ValueError(f"need sample_rate_hz > 0 and an integer oversample >= 1, got "
                             f"{self.sample_rate_hz!r}, {self.oversample!r}")
        if not 0 < self.passband < 0.5:
            raise ValueError(f"passband must lie in (0, 0.5) of the sampling rate, got {self.passband!r}")

    @property
    def fine_rate_hz(self) -> float:
        return self.sample_rate_hz * self.oversample

    def taps(self) -> np.ndarray:
        """h: the Kaiser-window FIR (firwin), odd length with its delay a multiple of q, unit DC gain."""
        from scipy.signal import firwin, kaiserord

        q, fine = self.oversample, self.fine_rate_hz
        width = (0.5 - self.passband) * self.sample_rate_hz / (0.5 * fine)  # transition, of the fine Nyquist
        n, beta = kaiserord(self.atten_db, width)
        m = math.ceil((n - 1) / (2 * q))
        cutoff = 0.5 * (self.passband + 0.5) * self.sample_rate_hz
        return firwin(2 * q * m + 1, cutoff, window=("kaiser", beta), fs=fine)

    @property
    def tail_samples(self) -> int:
        """Fine samples needed past the last kept one: the filter's half length D."""
        return (len(self.taps()) - 1) // 2

    def acquire(self, u: np.ndarray, n_out: int) -> np.ndarray:
        """y (..., n_out): the channels u (..., N_fine) sampled at fs through the filter.

        ``u`` starts at rest at its first sample and must hold at least
        q (n_out - 1) + 1 + ``tail_samples`` samples (the filter's end is then exact)."""
        from scipy.signal import upfirdn

        h, q = self.taps(), self.oversample
        D = (len(h) - 1) // 2
        need = q * (n_out - 1) + 1 + D
        if u.shape[-1] < need:
            raise ValueError(f"the acquisition needs {need} fine samples for {n_out} outputs, got {u.shape[-1]}")
        y = upfirdn(h, u[..., :need], up=1, down=q, axis=-1)  # y[k] = sum_j h[j] u[q k - j]
        return y[..., D // q: D // q + n_out]

    def describe(self) -> str:
        """One line for the record's provenance."""
        return (f"channels computed at {self.fine_rate_hz:g} Hz ({self.oversample} x {self.sample_rate_hz:g}), "
                f"linear-phase Kaiser FIR of {len(self.taps())} taps, flat to {self.passband:g} fs, "
                f"-{self.atten_db:g} dB from fs/2, delay compensated, decimated to {self.sample_rate_hz:g} Hz")


__all__ = ["Acquisition", "oversampling", "PASSBAND", "ATTEN_DB", "MARGIN"]
