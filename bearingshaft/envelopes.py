"""Envelopes of long time series: what a dense line plot draws, accumulated chunk by chunk.

An :class:`Envelope` keeps the min and max of a record in each of a fixed number of bins, so a
record of any length is drawn (:mod:`bearingshaft.plots`) from memory independent of its length.
It computes nothing a figure needs matplotlib for: stages fill it while they compute.
"""

from __future__ import annotations

import numpy as np

from reduced.transient.compare import binned

N_COLUMNS = 2000  # envelope bins of a time plot: finer than the ~1000 pixel columns of a 9 in, 120 dpi axis


class Envelope:
    """Min and max of ``n_series`` time series in each of ``n_bins`` equal bins of samples, accumulated
    chunk by chunk: what a dense line plot draws in each pixel column, in memory independent of
    the record's length. A record of at most 2 n_bins samples is kept whole.

    Parameters
    ----------
    n_samples : int
        Samples of the record.
    sample_rate_hz : float
        Hz.
    n_series : int
        Series accumulated side by side.
    n_bins : int
        Bins (pixel columns) wanted.

    Attributes
    ----------
    per : int
        Samples a bin (1: the record is kept whole).
    lo, hi : (n_bins, n_series) ndarray of float
        Min and max of each bin so far (+inf and -inf before any sample).
    """

    def __init__(self, n_samples: int, sample_rate_hz: float, n_series: int, n_bins: int = N_COLUMNS) -> None:
        self.n_samples = n_samples
        self.fs = sample_rate_hz
        self.per = 1 if n_samples <= 2 * n_bins else -(-n_samples // n_bins)
        nb = -(-n_samples // self.per)
        self.lo = np.full((nb, n_series), np.inf)
        self.hi = np.full((nb, n_series), -np.inf)

    def add(self, start: int, values: np.ndarray) -> None:
        """Samples start .. start + len(values) - 1, shape (k, n_series) or (k,)."""
        v = np.asarray(values, dtype=float).reshape(len(values), -1)
        if v.shape[0] == 0:
            return
        b, lo = binned(np.minimum, v, start, self.per)
        hi = binned(np.maximum, v, start, self.per)[1]
        sl = slice(b, b + lo.shape[0])
        self.lo[sl] = np.minimum(self.lo[sl], lo)
        self.hi[sl] = np.maximum(self.hi[sl], hi)

    def lines(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, y): a line through each bin's min then max (the whole record when kept whole)."""
        t0 = np.arange(self.lo.shape[0]) * self.per / self.fs
        if self.per == 1:
            return t0, self.lo
        t = np.repeat(t0 + 0.5 * self.per / self.fs, 2)
        y = np.empty((2 * self.lo.shape[0], self.lo.shape[1]))
        y[0::2], y[1::2] = self.lo, self.hi
        return t, y

    def upper(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, y): each bin's max at its centre."""
        return (np.arange(self.hi.shape[0]) + 0.5 * (self.per > 1)) * self.per / self.fs, self.hi
