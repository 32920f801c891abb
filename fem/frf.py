"""Impact-test signal processing as a test lab does it: windows, H1/H2 FRFs and coherence.

A hammer test records, for each blow (one record of N samples at fs), the hammer's force
x(t) and the responses y_o(t). Before the transform:

- the *force window* keeps the force channel from ``pre_s`` before the trigger to
  ``width_s`` after it (1 inside, a half-cosine taper of ``taper_s`` at the end, 0 outside),
  so the noise of the quiet part of the force channel does not enter the spectrum;
- the *exponential window* w(t) = exp(-(t - t_trig) / tau) for t >= t_trig (1 before) makes a
  lightly damped response decay within the record (no leakage). It is applied to the force
  and the responses alike, from the same origin, so that for a force that is zero before the
  trigger y_w = (h w_h) * x_w exactly, with w_h(u) = exp(-u / tau): the measured FRF is that
  of the structure with every pole moved left by sigma = 1 / tau,

      lambda_w = lambda - sigma,   zeta_w = (zeta omega_n + sigma) / |lambda - sigma|,

  which :func:`exponential_correction` undoes exactly on identified poles (the "added
  damping" a test report states is zeta_w - zeta, about sigma / omega_n).

The estimators over n_avg blows (Bendat and Piersol, Random Data, 4th ed., Sec. 9.1;
X_a, Y_a the DFTs of blow a, S_xy = sum_a conj(X_a) Y_a):

    H1 = S_xy / S_xx,  H2 = S_yy / S_yx,  gamma^2 = |S_xy|^2 / (S_xx S_yy) = H1 / H2,

H1 unbiased by output noise, H2 by input noise; with noise on the output only, |H1| <= |H2|
and gamma^2 < 1. Several references (a polyreference test) give H of shape
(n_out, n_ref, n_freq): each reference's blows are averaged on their own (one hammer at a
time, so the inputs are never simultaneous and the single-input estimators apply per
reference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TAPER_S = 5e-4  # s, default half-cosine taper at the end of the force window


def force_window(n: int, sample_rate_hz: float, trigger_s: float, width_s: float, pre_s: float = 0.0,
                 taper_s: float = TAPER_S) -> np.ndarray:
    """(n,) force window: 1 on [trigger_s - pre_s, trigger_s + width_s], a half-cosine to 0 over
    ``taper_s`` after it, 0 elsewhere.

    Parameters
    ----------
    n : int
        Samples of the record.
    sample_rate_hz : float
        Hz, fs.
    trigger_s : float
        s, the blow's start (the trigger) from the record's first sample.
    width_s : float
        s, the window's flat part after the trigger, > 0.
    pre_s : float
        s, flat part before the trigger, >= 0.
    taper_s : float
        s, length of the cosine taper, >= 0.

    Returns
    -------
    (n,) ndarray of float

    Examples
    --------
    >>> force_window(8, 1.0, 2.0, 2.0, pre_s=1.0, taper_s=2.0).round(3).tolist()
    [0.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.0, 0.0]
    """
    if not (width_s > 0 and pre_s >= 0 and taper_s >= 0 and sample_rate_hz > 0):
        raise ValueError(f"need width_s > 0, pre_s >= 0, taper_s >= 0, fs > 0; got {width_s!r}, {pre_s!r}, "
                         f"{taper_s!r}, {sample_rate_hz!r}")
    t = np.arange(n) / sample_rate_hz
    w = ((t >= trigger_s - pre_s - 1e-12) & (t <= trigger_s + width_s + 1e-12)).astype(float)
    if taper_s > 0:
        u = (t - trigger_s - width_s) / taper_s
        tail = (u > 0) & (u < 1)
        w[tail] = 0.5 * (1.0 + np.cos(np.pi * u[tail]))
    return w


def exponential_window(n: int, sample_rate_hz: float, trigger_s: float, tau_s: float) -> np.ndarray:
    """(n,) w = exp(-(t - trigger_s) / tau_s) for t >= trigger_s, 1 before.

    Parameters
    ----------
    n : int
        Samples of the record.
    sample_rate_hz : float
        Hz, fs.
    trigger_s : float
        s, the window's origin (the blow's start).
    tau_s : float
        s, time constant, > 0 (``math.inf``: no window).

    Returns
    -------
    (n,) ndarray of float
    """
    if not tau_s > 0:
        raise ValueError(f"tau_s must be > 0, got {tau_s!r}")
    t = np.arange(n) / sample_rate_hz
    return np.exp(-np.maximum(t - trigger_s, 0.0) / tau_s)


def tau_for_end_value(n: int, sample_rate_hz: float, trigger_s: float, end_value: float) -> float:
    """s, the exponential window's time constant that brings it to ``end_value`` at the last sample.

    tau = (t_last - trigger_s) / ln(1 / end_value); ``end_value`` = 1 gives inf (no window).

    Parameters
    ----------
    n : int
        Samples of the record.
    sample_rate_hz : float
        Hz, fs.
    trigger_s : float
        s, the window's origin.
    end_value : float
        The window's value at the record's end, in (0, 1].

    Returns
    -------
    float, s

    Examples
    --------
    >>> round(tau_for_end_value(1001, 1000.0, 0.0, math.exp(-4.0)), 12)
    0.25
    """
    if not 0 < end_value <= 1:
        raise ValueError(f"end_value must lie in (0, 1], got {end_value!r}")
    if end_value == 1:
        return math.inf
    span = (n - 1) / sample_rate_hz - trigger_s
    if not span > 0:
        raise ValueError(f"the trigger at {trigger_s!r} s is not inside the record")
    return span / math.log(1.0 / end_value)


def exponential_correction(lam_w: np.ndarray, tau_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Poles of the structure from poles identified on exponentially windowed data.

    lambda = lambda_w + sigma, sigma = 1 / tau (exact: the window multiplies the impulse
    response by exp(-sigma t)); the added damping ratio of each pole is
    zeta_w - zeta = -Re(lambda_w) / |lambda_w| + Re(lambda) / |lambda|.

    Parameters
    ----------
    lam_w : array_like of complex
        rad/s, poles identified on windowed FRFs.
    tau_s : float
        s, the window's time constant (inf: no window).

    Returns
    -------
    lam : ndarray of complex
        rad/s, the corrected poles.
    added_zeta : ndarray of float
        The damping ratio the window added to each.

    Examples
    --------
    >>> lam, dz = exponential_correction(np.array([-3.0 + 100j]), 0.5)
    >>> lam.tolist(), round(float(dz[0]), 6)
    ([(-1+100j)], 0.019987)
    """
    lam_w = np.asarray(lam_w, complex)
    sigma = 0.0 if math.isinf(tau_s) else 1.0 / tau_s
    lam = lam_w + sigma
    return lam, -lam_w.real / np.abs(lam_w) + lam.real / np.abs(lam)


@dataclass(frozen=True, eq=False)
class FRFEstimate:
    """H1, H2 and the ordinary coherence of n_out responses to n_ref references.

    Attributes
    ----------
    freq_hz : (nf,) ndarray of float
        Hz, the DFT lines k fs / N, k = 0 .. N // 2.
    H1, H2 : (n_out, n_ref, nf) ndarray of complex
        Response per unit reference (e.g. m/s^2/N).
    coherence : (n_out, n_ref, nf) ndarray of float
        gamma^2 in [0, 1].
    Gxx : (n_ref, nf) ndarray of float
        Auto spectrum of each reference (sum over its blows, |X|^2).
    n_averages : (n_ref,) ndarray of int
        Blows averaged per reference.
    """

    freq_hz: np.ndarray
    H1: np.ndarray
    H2: np.ndarray
    coherence: np.ndarray
    Gxx: np.ndarray
    n_averages: np.ndarray


def frf_estimates(x: np.ndarray, y: np.ndarray, sample_rate_hz: float, reference: np.ndarray | None = None
                  ) -> FRFEstimate:
    """H1, H2 and coherence from windowed blows: x (n_blows, N) forces, y (n_blows, n_out, N) responses.

    Blow a belongs to reference ``reference[a]`` (0 .. n_ref - 1; all 0 by default); each
    reference's blows are averaged on their own:

        S_xx = sum_a |X_a|^2, S_xy = sum_a conj(X_a) Y_a, S_yy = sum_a |Y_a|^2,
        H1 = S_xy / S_xx, H2 = S_yy / conj(S_xy), gamma^2 = |S_xy|^2 / (S_xx S_yy).

    Parameters
    ----------
    x : (n_blows, N) ndarray of float
        The (windowed) force of each blow.
    y : (n_blows, n_out, N) ndarray of float
        The (windowed) responses of each blow.
    sample_rate_hz : float
        Hz, fs.
    reference : (n_blows,) array_like of int, optional
        The reference of each blow.

    Returns
    -------
    FRFEstimate

    Raises
    ------
    ValueError
        Shapes that do not agree, or a reference without blows.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.ndim != 2 or y.ndim != 3 or y.shape[0] != x.shape[0] or y.shape[2] != x.shape[1]:
        raise ValueError(f"need x (n_blows, N) and y (n_blows, n_out, N), got {x.shape} and {y.shape}")
    ref = np.zeros(x.shape[0], int) if reference is None else np.asarray(reference, int)
    n_ref = int(ref.max()) + 1
    counts = np.bincount(ref, minlength=n_ref)
    if ref.shape != (x.shape[0],) or ref.min() < 0 or np.any(counts == 0):
        raise ValueError(f"reference must give every one of 0..{n_ref - 1} at least one blow, got {ref.tolist()}")
    X = np.fft.rfft(x, axis=-1)
    Y = np.fft.rfft(y, axis=-1)
    n_out, nf = y.shape[1], X.shape[-1]
    Sxx = np.zeros((n_ref, nf))
    Sxy = np.zeros((n_out, n_ref, nf), complex)
    Syy = np.zeros((n_out, n_ref, nf))
    for r in range(n_ref):
        a = ref == r
        Sxx[r] = np.sum(np.abs(X[a]) ** 2, axis=0)
        Sxy[:, r] = np.einsum("af,aof->of", np.conj(X[a]), Y[a])
        Syy[:, r] = np.sum(np.abs(Y[a]) ** 2, axis=0)
    tiny = np.finfo(float).tiny
    with np.errstate(divide="ignore", invalid="ignore"):
        H1 = Sxy / np.maximum(Sxx[None], tiny)
        H2 = Syy / np.where(np.abs(Sxy) > 0, np.conj(Sxy), tiny)
        coh = np.abs(Sxy) ** 2 / np.maximum(Sxx[None] * Syy, tiny)
    freq = np.fft.rfftfreq(x.shape[1], 1.0 / sample_rate_hz)
    return FRFEstimate(freq_hz=freq, H1=H1, H2=H2, coherence=np.clip(coh, 0.0, 1.0), Gxx=Sxx, n_averages=counts)


__all__ = ["force_window", "exponential_window", "tau_for_end_value", "exponential_correction", "FRFEstimate",
           "frf_estimates", "TAPER_S"]
