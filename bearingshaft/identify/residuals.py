"""The residuals of a fit of the model to a measured hammer test: blocks of the chaos-aware measures.

An impacting ringdown is chaotic, so a model and a test agree sample for sample only up to the
predictability horizon (:func:`bearingshaft.measured.horizon`); past it the fit uses what survives
chaos (:mod:`bearingshaft.measures`). Each block is a 2-D array (series x points) of dimensionless
residuals, model minus test, of fixed shape for a given :class:`Target` (the test and what is
measured where, fixed while a least-squares pass runs):

``time``
    (m_c(t_k) - x_c(t_k)) / s_c for every compared channel c and sample t_k from the blow's start
    to the horizon, s_c = max(RMS of the test over that span, the channel's floor)
    (:func:`bearingshaft.correlate.channel_floors`: a channel zero by symmetry is judged against its
    sensor, a noisy one against its noise).
``envelope``
    ln((e_m' + f_c) / (e_x + f_c)) of the RMS envelopes in consecutive windows over the fitted window
    (:func:`bearingshaft.measures.envelope`), f_c the floor: a decay rate is a slope in it, and a
    channel's level is compared relatively whether it is large or small. The test's envelope holds
    its sensor's noise, e_x^2 = e^2 + n_c^2 (n_c the test's RMS before the blow), so the model's
    is compared with it added, e_m' = sqrt(e_m^2 + n_c^2): without it a noisy late window pulls the
    damping (the model's envelope decays below the noise the test never drops under).
``ridges``
    ln(f_model / f_test) of the spectrogram ridges past the horizon
    (:func:`bearingshaft.measures.ridges`), in the frames where the test has a ridge (a model frame
    without one counts 0).
``impacts``
    Per tip load cell (a row each) past the horizon, quantities that move continuously with the parameters
    (:func:`contact_measures`): the share of the time the cell reads above the test's impact
    threshold (its crossings interpolated between samples: a grazing impact adds ~0, where an impact
    count would jump by one), its mean excess over the threshold (the impulse rate) and the largest
    reading, each as a relative error (floored at the threshold's).
``open``
    Per tip load cell (a row each): the time its last impact ends, relative to the test's (from the window's start).
``first``
    Per tip load cell (a row each): the first impact, before chaos has had time to act: the time its force first
    rises through the impact threshold (linear between samples, so that it moves smoothly with the gap),
    minus the test's, over the test's first impact's length; and its peak's relative error.

How the blocks are weighted (:func:`block_weights`): residual i of block b is divided by its own
scatter sigma_i, what it would change by with no change of the parameters
(:mod:`bearingshaft.identify.scatter`: the sensors' noise, the test's noise drawn again on the
model's record, and the chaotic motion's spread, the model rerun with its hammer force redrawn
within that channel's noise), z_i = r_i / sigma_i. The block is then multiplied by

    w_b = sqrt(n_eff,b / n_b) / sqrt(u_b),   u_b = max(1, mean_i z_i^2),

n_eff,b its effective number of independent residuals (:func:`effective_size` of z: neighbouring
samples of a channel are correlated, and so are the channels of one sensor) and u_b the share by
which its misfit at that point exceeds what noise and chaos explain (model error: a block the
model cannot fit counts for less; never more than its scatter allows, so a block that happens to
fit well is not taken for a precise one). A block's weighted sum of squares is then at most
n_eff,b, and J^T J of the weighted residuals is the information matrix from which the intervals
follow (:mod:`bearingshaft.identify.fit`). Without scatters (``sigma`` None) sigma_i is the
block's RMS at the point (u_b = 1): the misfit no parameter removes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from bearingshaft import measures
from bearingshaft.correlate import ChannelPair, rms
from bearingshaft.measured import Horizon
from fem.uff import TimeHistory

RIDGE_OVERLAP = 0.5  # the ridges' frames overlap by half (more overlap adds correlated frames, no information)


@dataclass(frozen=True, eq=False)
class Target:
    """The test as the residuals see it, and what each block measures where.

    Attributes
    ----------
    names : tuple of str
        The compared model channels.
    rows : tuple of int
        Their rows in the rig's channel order.
    tests : tuple of TimeHistory
        The test channels, in the model's sign convention, one per name.
    quantities : tuple of str
        Their quantities (the load cells, ``reaction_force``, carry the impacts).
    floors : (n,) ndarray of float
        The channels' floors, their units.
    window_s : (float, float)
        s, the fitted window, absolute times.
    time_span_s : (float, float)
        s, the pointwise block's span: the blow's start to the horizon (empty when end <= start).
    time_scale : (n,) ndarray of float
        s_c, the pointwise residuals' scale per channel.
    post_s : (float, float)
        s, past the horizon: the span of the ridges and impacts.
    envelope_window_s : float
        s.
    frame_s : float
        s, the ridges' frames.
    fmax_hz : float or None
        Hz, the ridges' band's top.
    ridge_mask : dict
        {channel: (frames,) bool}: the frames where the test has a ridge.
    measures : tuple of str
        The blocks.
    horizon : Horizon or None
        Where the pointwise block ends, as found.
    noise, envelope_noise : (n,) ndarray of float or None
        The test channels' noise RMS before the blow (as recorded; band-passed for the envelope):
        what the model's envelopes are compared with added (module docstring); None: nothing added.
    """

    def with_tests(self, tests) -> Target:
        """The same target against other test channels (the noise redrawn: :mod:`bearingshaft.identify.scatter`)."""
        return replace(self, tests=tuple(tests))

    names: tuple[str, ...]
    rows: tuple[int, ...]
    tests: tuple[TimeHistory, ...]
    quantities: tuple[str, ...]
    floors: np.ndarray
    window_s: tuple[float, float]
    time_span_s: tuple[float, float]
    time_scale: np.ndarray
    post_s: tuple[float, float]
    envelope_window_s: float
    frame_s: float
    fmax_hz: float | None
    ridge_mask: dict = field(default_factory=dict)
    measures: tuple[str, ...] = ("time", "envelope")
    horizon: Horizon | None = None
    envelope_band_hz: tuple[float, ...] = ()
    envelope_floors: np.ndarray | None = None
    free_decay_s: float = 0.0
    noise: np.ndarray | None = None  # (n,), each test channel's RMS before the blow (its sensor's noise), its unit
    envelope_noise: np.ndarray | None = None  # (n,), the same of the envelope's (band-passed) channels

    def pairs(self, model: list[TimeHistory]) -> list[ChannelPair]:
        """The model's channels (the compared ones, in ``names`` order) paired with the test's."""
        return [ChannelPair(n, m, x, False) for n, m, x in zip(self.names, model, self.tests, strict=True)]

    @property
    def has_time(self) -> bool:
        return "time" in self.measures and self.time_span_s[1] > self.time_span_s[0]


def _time_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p, s in zip(pairs, target.time_scale, strict=True):
        a = p.aligned(target.time_span_s)
        out.append((a.model - a.test) / s)
    return np.array(out)


def band_passed(pair: ChannelPair, band_hz) -> ChannelPair:
    """The pair with both channels band-passed to ``band_hz`` (zero-phase Butterworth of order
    :data:`bearingshaft.measures.BAND_ORDER`, forward and back, over the whole record); unchanged for None.

    Parameters
    ----------
    pair : ChannelPair
    band_hz : (float, float) or ()
        Hz.
    """
    if not band_hz:
        return pair
    from scipy.signal import butter, sosfiltfilt

    m, x = pair.model, pair.test
    sos = butter(measures.BAND_ORDER, tuple(band_hz), "bandpass", fs=1.0 / m.dt_s, output="sos")

    def filt(h: TimeHistory) -> TimeHistory:
        return TimeHistory(h.name, h.node, h.direction, h.quantity, sosfiltfilt(sos, h.data), h.dt_s, h.t0_s)

    return ChannelPair(pair.name, filt(m), filt(x), pair.flipped)


def _with_noise(e_model: np.ndarray, noise: float) -> np.ndarray:
    """The model's RMS envelope as a sensor of RMS noise ``noise`` would record it: sqrt(e^2 + n^2)."""
    return np.sqrt(e_model**2 + noise**2)


def _noise(values: np.ndarray | None, n: int) -> np.ndarray:
    return np.zeros(n) if values is None else np.asarray(values, float)


def _envelope_block(target: Target, pairs) -> np.ndarray:
    out = []
    noise = _noise(target.envelope_noise, len(pairs))
    for p, f, nz in zip(pairs, target.envelope_floors, noise, strict=True):
        env = measures.envelope(band_passed(p, target.envelope_band_hz), target.window_s, target.envelope_window_s, f)
        floor = max(f, 1e-300)
        out.append(np.log((_with_noise(env.model, nz) + floor) / (env.test + floor)))
    return np.array(out)


def _decay_block(target: Target, pairs) -> np.ndarray:
    out = []
    span = (max(target.window_s[0], target.free_decay_s), target.window_s[1])
    for p, f, nz in zip(pairs, target.floors, _noise(target.noise, len(pairs)), strict=True):
        env = measures.envelope(p, span, target.envelope_window_s, f)
        if env is None:
            continue
        floor = max(f, 1e-300)
        r = np.log((_with_noise(env.model, nz) + floor) / (env.test + floor))
        out.append(r - r.mean())
    return np.array(out) if out else np.zeros((1, 0))


def _ridge_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p, f in zip(pairs, target.floors, strict=True):
        mask = target.ridge_mask.get(p.name)
        if mask is None or not mask.any():
            continue
        r = measures.ridges(p, target.post_s, target.frame_s, RIDGE_OVERLAP, fmax_hz=target.fmax_hz, floor=f)
        fm, fx = r.f_model[mask], r.f_test[mask]
        out.append(np.where(np.isfinite(fm) & (fm > 0), np.log(np.where(fm > 0, fm, 1.0) / fx), 0.0))
    return np.concatenate(out)[None, :] if out else np.zeros((1, 0))


def _cells(target: Target, pairs):
    return [p for p, q in zip(pairs, target.quantities, strict=True) if q == measures.CONTACT_QUANTITY]


def _rel(m: float, x: float, floor: float = 0.0) -> float:
    """(m - x) / max(|x|, floor); a missing model value (NaN: no impact) as 0, a missing test value: no residual."""
    if not math.isfinite(x):
        return 0.0
    m = m if math.isfinite(m) else 0.0
    scale = max(abs(x), floor)
    return (m - x) / scale if scale > 0 else 0.0


def time_above(z: np.ndarray, threshold: float) -> float:
    """The share of a sampled record's time that ``z`` (linear between samples) spends above ``threshold``.

    Continuous in the samples: a reading that just touches the threshold adds ~0 (an impact count
    would jump by one there).

    Parameters
    ----------
    z : (n,) ndarray of float, n >= 2
    threshold : float

    Examples
    --------
    >>> float(time_above(np.array([0.0, 2.0, 0.0]), 1.0))  # above from 0.5 to 1.5 of 2 intervals
    0.5
    """
    d = np.asarray(z, float) - threshold
    a, b = d[:-1], d[1:]
    both = (a > 0) & (b > 0)
    one = (a > 0) != (b > 0)
    part = np.where(one, np.maximum(a, b) / np.where(one, np.abs(a) + np.abs(b), 1.0), 0.0)
    return float((np.sum(both) + np.sum(part)) / max(d.size - 1, 1))


CONTACT_MEASURES = ("time above threshold", "mean excess", "largest reading")


def contact_measures(t: np.ndarray, y: np.ndarray, threshold: float, sense: float) -> np.ndarray:
    """A load cell's contact over a span, as quantities continuous in its record (module docstring):
    the share of the time above ``threshold`` (:func:`time_above`), the mean of max(z - threshold, 0)
    (N: the impulse above the threshold per second, over the span) and the largest z, z = sense * y.

    Parameters
    ----------
    t : (n,) ndarray of float
        s (unused but for its length: the samples are evenly spaced).
    y : (n,) ndarray of float
        N, the cell's reading.
    threshold : float
        N, the test's impact threshold.
    sense : float
        +1 or -1, the contact's sense on this cell.

    Returns
    -------
    (3,) ndarray of float, in CONTACT_MEASURES order
    """
    z = sense * np.asarray(y, float)
    if z.size < 2:
        return np.zeros(3)
    return np.array([time_above(z, threshold), float(np.mean(np.maximum(z - threshold, 0.0))), float(np.max(z))])


def _impact_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p in _cells(target, pairs):
        c = measures.impact_comparison(p, target.post_s, target.window_s)
        if c is None:
            out.append([0.0] * len(CONTACT_MEASURES))
            continue
        a = p.aligned(target.post_s)
        thr = c.test.threshold_N
        m = contact_measures(a.t, a.model, thr, c.sense)
        x = contact_measures(a.t, a.test, thr, c.sense)
        # floors: a thousandth of the time, a thousandth of the threshold per second, the threshold
        floors = (1e-3, 1e-3 * thr, thr)
        out.append([_rel(mi, xi, fl) for mi, xi, fl in zip(m, x, floors, strict=True)])
    return np.array(out).reshape(-1, len(CONTACT_MEASURES))


def _open_block(target: Target, pairs) -> np.ndarray:
    out = []
    t0 = target.window_s[0]
    for p in _cells(target, pairs):
        c = measures.impact_comparison(p, target.window_s, target.window_s)
        if c is None or not math.isfinite(c.test.last_s):
            out.append(0.0)
            continue
        m = c.model.last_s if math.isfinite(c.model.last_s) else t0
        out.append((m - c.test.last_s) / (c.test.last_s - t0))
    return np.array(out).reshape(-1, 1)


def first_crossing(t: np.ndarray, z: np.ndarray, threshold: float) -> float:
    """s, where ``z`` first rises through ``threshold``, linear between samples (NaN: never).

    Parameters
    ----------
    t : (n,) ndarray of float
        s.
    z : (n,) ndarray of float
    threshold : float

    Examples
    --------
    >>> round(first_crossing(np.arange(4) * 1.0, np.array([0.0, 1.0, 3.0, 5.0]), 2.0), 12)
    1.5
    """
    above = np.flatnonzero(z > threshold)
    if not above.size:
        return math.nan
    i = int(above[0])
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (threshold - z[i - 1]) / (z[i] - z[i - 1]) * (t[i] - t[i - 1]))


def _first_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p in _cells(target, pairs):
        c = measures.impact_comparison(p, target.window_s, target.window_s)
        if c is None or not c.test.count:
            out.append([0.0, 0.0])
            continue
        a = p.aligned(target.window_s)
        thr = c.test.threshold_N
        t_x = first_crossing(a.t, c.sense * a.test, thr)
        t_m = first_crossing(a.t, c.sense * a.model, thr)
        scale = max(float(c.test.end_s[0] - c.test.start_s[0]), 1.0 / a.sample_rate_hz)
        t_m = t_m if math.isfinite(t_m) else target.window_s[1]
        peak_m = c.model.peak_N[0] if c.model.count else 0.0
        out.append([(t_m - t_x) / scale, _rel(peak_m, c.test.peak_N[0])])
    return np.array(out).reshape(-1, 2)


BLOCKS = {"first": _first_block, "time": _time_block, "envelope": _envelope_block, "decay": _decay_block,
          "ridges": _ridge_block,
          "impacts": _impact_block, "open": _open_block}


def blocks(target: Target, model: list[TimeHistory]) -> dict[str, np.ndarray]:
    """The residual blocks of the model's channels against the test (module docstring).

    Parameters
    ----------
    target : Target
        The test and what is measured where.
    model : list of TimeHistory
        The model's compared channels, in ``target.names`` order, on the test's grid.

    Returns
    -------
    dict
        {block: (series, points) ndarray}, in ``target.measures`` order (``time`` only when its span is not empty).
    """
    pairs = target.pairs(model)
    out = {}
    for m in target.measures:
        if m == "time" and not target.has_time:
            continue
        out[m] = BLOCKS[m](target, pairs)
    return out


def effective_size(R: np.ndarray) -> float:
    """The effective number of independent residuals in a block R (series x points).

    Along each series, the integrated autocorrelation time tau = 1 + 2 sum_{k=1}^{K} rho_k of the
    residuals about zero (a bias is one long correlation), rho averaged over the series and summed
    up to the first lag where it is <= 0 (Geyer's initial positive sequence); across the series,
    the participation ratio of R's singular values, k_eff = (sum s^2)^2 / sum s^4 (k independent
    series of equal size give k; k copies of one give 1). n_eff = k_eff n / tau, in [1, R.size].

    Parameters
    ----------
    R : (k, n) ndarray of float

    Returns
    -------
    float

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> white = rng.standard_normal((4, 4000))
    >>> 0.85 < effective_size(white) / white.size < 1.15  # independent samples: all of them
    True
    >>> round(effective_size(np.ones((4, 100))), 6)  # one bias repeated: one residual
    1.0
    """
    R = np.atleast_2d(np.asarray(R, float))
    k, n = R.shape
    if R.size == 0:
        return 0.0
    total = float(np.sum(R**2))
    if total == 0.0:
        return float(R.size)
    tau = 1.0
    if n >= 4:
        m = 1 << int(math.ceil(math.log2(2 * n)))
        F = np.fft.rfft(R, m, axis=1)
        acf = np.fft.irfft(np.sum(np.abs(F) ** 2, axis=0), m)[:n]
        rho = acf / acf[0]
        neg = np.flatnonzero(rho[1:] <= 0)
        K = int(neg[0]) if neg.size else n - 1
        tau = min(float(n), 1.0 + 2.0 * float(np.sum(rho[1:K + 1])))
    if k > 1:
        s2 = np.linalg.svd(R, compute_uv=False) ** 2
        k_eff = float(np.sum(s2) ** 2 / np.sum(s2**2))
    else:
        k_eff = 1.0
    return float(min(max(k_eff * n / tau, 1.0), R.size))


@dataclass(frozen=True, eq=False)
class BlockWeight:
    """A block's weights and what sets them (module docstring).

    Attributes
    ----------
    measure : str
    n : int
        Residuals in the block.
    n_eff : float
        Effective independent ones.
    rms : float
        Their RMS where the weights were taken.
    weight : float
        sqrt(n_eff / n) / sqrt(u): the block's factor.
    sigma : (n,) ndarray of float or None
        Each residual's scatter (flattened); None: the block's RMS for all (no scatters given).
    scatter : float
        RMS of ``sigma`` (the block's RMS when None).
    inflation : float
        u = max(1, mean z^2): the misfit beyond the scatter (1: none).
    """

    measure: str
    n: int
    n_eff: float
    rms: float
    weight: float
    sigma: np.ndarray | None = None
    scatter: float = math.nan
    inflation: float = 1.0

    def apply(self, R: np.ndarray) -> np.ndarray:
        """The block's residuals weighted (flattened)."""
        r = np.asarray(R, float).ravel()
        if self.sigma is not None:
            r = r / self.sigma
        return self.weight * r

    def apply_rows(self, G: np.ndarray) -> np.ndarray:
        """Rows of derivatives of the block's residuals (n, p) weighted as the residuals."""
        G = np.asarray(G, float).reshape(self.n, -1)
        if self.sigma is not None:
            G = G / self.sigma[:, None]
        return self.weight * G


INFLATE_BLOCKS = False  # experiment
SIGMA_FLOOR = 1e-12  # a residual's scatter is never taken below this (dimensionless; a noiseless virtual test)


def block_weights(found: dict[str, np.ndarray], sigma: dict[str, np.ndarray] | None = None) -> dict[str, BlockWeight]:
    """The weights of each block from its residuals and their scatters at one point (module docstring).

    Parameters
    ----------
    found : dict
        {block: residuals (series, points)}, from :func:`blocks`.
    sigma : dict, optional
        {block: each residual's scatter, the block's shape} (:mod:`bearingshaft.identify.scatter`); a
        block missing from it, or None, is scaled by its RMS.

    Returns
    -------
    dict
        {block: BlockWeight}; a block of zeros with no scatter gets weight 0 (nothing to scale by).
    """
    out = {}
    for m, R in found.items():
        n = int(R.size)
        r = rms(R) if n else 0.0
        sg = None if sigma is None else sigma.get(m)
        if sg is None or not n:
            n_eff = effective_size(R) if n else 0.0
            w = math.sqrt(n_eff / n) / r if n and r > 0 else 0.0
            out[m] = BlockWeight(m, n, n_eff, r, w, None, r, 1.0)
            continue
        s = np.maximum(np.asarray(sg, float).reshape(R.shape), SIGMA_FLOOR * max(r, 1.0))
        Z = R / s
        u = max(1.0, float(np.mean(Z**2))) if INFLATE_BLOCKS else 1.0
        n_eff = effective_size(Z)
        out[m] = BlockWeight(m, n, n_eff, r, math.sqrt(n_eff / n / u), s.ravel(), rms(s), u)
    return out


def stacked(found: dict[str, np.ndarray], weights: dict[str, BlockWeight]) -> np.ndarray:
    """The weighted residual vector: every block (in ``weights``' order) flattened and weighted (BlockWeight.apply).

    Parameters
    ----------
    found : dict
        {block: residuals}.
    weights : dict
        {block: BlockWeight}.

    Returns
    -------
    (sum n_b,) ndarray of float
    """
    return np.concatenate([weights[m].apply(found[m]) for m in weights]) if weights else np.zeros(0)


__all__ = ["Target", "blocks", "effective_size", "BlockWeight", "block_weights", "stacked", "BLOCKS",
           "CONTACT_MEASURES", "contact_measures", "time_above"]
