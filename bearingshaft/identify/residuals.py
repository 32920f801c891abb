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
    ln((e_m + f_c) / (e_x + f_c)) of the RMS envelopes in consecutive windows over the fitted window
    (:func:`bearingshaft.measures.envelope`), f_c the floor: a decay rate is a slope in it, and a
    channel's level is compared relatively whether it is large or small.
``ridges``
    ln(f_model / f_test) of the spectrogram ridges past the horizon
    (:func:`bearingshaft.measures.ridges`), in the frames where the test has a ridge (a model frame
    without one counts 0).
``impacts``
    Per tip load cell past the horizon: the impact count's relative error (floored at one impact)
    and those of the median, 90 % and largest peak forces (:func:`bearingshaft.measures.impact_comparison`).
``open``
    Per tip load cell: the time its last impact ends, relative to the test's (from the window's start).
``first``
    Per tip load cell: the first impact, before chaos has had time to act: the time its force first
    rises through the impact threshold (linear between samples, so that it moves smoothly with the gap),
    minus the test's, over the test's first impact's length; and its peak's relative error.

How the blocks are weighted (:func:`block_weights`): block b is multiplied by
w_b = sqrt(n_eff,b / n_b) / rms_b, where rms_b is its RMS at the point the weights are taken (the
fit's own estimate of that block's noise and model error: the misfit that no parameter removes)
and n_eff,b its effective number of independent residuals (:func:`effective_size`: neighbouring
samples of a channel are correlated, and so are the channels of one sensor). The weighted block
then sums to n_eff,b: each block counts as many independent unit-variance residuals as its data
hold, whatever its length or unit, and J^T J of the weighted residuals is the information matrix
from which the intervals follow (:mod:`bearingshaft.identify.fit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bearingshaft import measures
from bearingshaft.correlate import ChannelPair, rms
from bearingshaft.measured import Horizon
from fem.uff import TimeHistory

IMPACT_STATS = ((0.5, "median peak"), (0.9, "90 % peak"), (1.0, "largest peak"))
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
    """

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


def _envelope_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p, f in zip(pairs, target.envelope_floors, strict=True):
        env = measures.envelope(band_passed(p, target.envelope_band_hz), target.window_s, target.envelope_window_s, f)
        floor = max(f, 1e-300)
        out.append(np.log((env.model + floor) / (env.test + floor)))
    return np.array(out)


def _decay_block(target: Target, pairs) -> np.ndarray:
    out = []
    span = (max(target.window_s[0], target.free_decay_s), target.window_s[1])
    for p, f in zip(pairs, target.floors, strict=True):
        env = measures.envelope(p, span, target.envelope_window_s, f)
        if env is None:
            continue
        floor = max(f, 1e-300)
        r = np.log((env.model + floor) / (env.test + floor))
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


def _impact_block(target: Target, pairs) -> np.ndarray:
    out = []
    for p in _cells(target, pairs):
        c = measures.impact_comparison(p, target.post_s, target.window_s)
        if c is None:
            out.append([0.0] * (1 + len(IMPACT_STATS)))
            continue
        row = [_rel(c.model.count, c.test.count, 1.0)]
        row += [_rel(c.model.peak_stat(q), c.test.peak_stat(q)) for q, _ in IMPACT_STATS]
        out.append(row)
    return np.array(out).reshape(1, -1)


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
    return np.array(out).reshape(1, -1)


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
    return np.array(out).reshape(1, -1)


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


@dataclass(frozen=True)
class BlockWeight:
    """A block's weight and what sets it (module docstring).

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
        sqrt(n_eff / n) / rms.
    """

    measure: str
    n: int
    n_eff: float
    rms: float
    weight: float


def block_weights(found: dict[str, np.ndarray]) -> dict[str, BlockWeight]:
    """The weight of each block from its residuals at one point (module docstring).

    Parameters
    ----------
    found : dict
        {block: residuals (series, points)}, from :func:`blocks`.

    Returns
    -------
    dict
        {block: BlockWeight}; a block of zeros gets weight 0 (it carries no misfit to scale by).
    """
    out = {}
    for m, R in found.items():
        n = int(R.size)
        r = rms(R) if n else 0.0
        n_eff = effective_size(R) if n else 0.0
        w = math.sqrt(n_eff / n) / r if n and r > 0 else 0.0
        out[m] = BlockWeight(m, n, n_eff, r, w)
    return out


def stacked(found: dict[str, np.ndarray], weights: dict[str, BlockWeight]) -> np.ndarray:
    """The weighted residual vector: every block (in ``weights``' order) flattened and times its weight.

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
    return np.concatenate([weights[m].weight * found[m].ravel() for m in weights]) if weights else np.zeros(0)


__all__ = ["Target", "blocks", "effective_size", "BlockWeight", "block_weights", "stacked", "BLOCKS",
           "IMPACT_STATS"]
