"""How much each residual would change with no change of the parameters: the scatter that weights it.

A residual of the fit (:mod:`bearingshaft.identify.residuals`) moves for two reasons besides the
parameters, and both are estimated from the test and the model at the point, not from the misfit:

- **The sensors' noise** (:func:`noise_variance`). The test's channels carry noise of RMS n_c (their
  RMS before the blow). The model's own channels at the point, with K_NOISE fresh noise draws of
  that RMS shaped as a DAQ records broadband noise (:func:`bearingshaft.identify.virtual.daq_noise`,
  anti-alias filtered at the record's rate), stand in for K_NOISE tests; the variance of each
  residual over them is its noise variance. For the pointwise block this is (n_c / s_c)^2; for the
  envelopes, the ridges and the contact measures it is what the noise does to them, whatever their form.
- **The roughness: chaos and jumps** (:func:`local_fit`). Past the predictability horizon a measure
  is a noisy function of the parameters: a step of 1 % in the gap changes the impacts that follow
  it as a new realisation of the chaos would, and a contact that starts or stops grazing changes
  what follows it at once. A finite-difference derivative of such a measure is mostly that noise
  divided by the step, and J^T J then counts it as information. So the model is run at a cloud of
  points around theta (:func:`cloud`: a Latin hypercube of cloud_size(p) points within -+ a half-width
  in each scaled parameter, each run with its hammer force redrawn within the
  hammer channel's noise, :func:`bearingshaft.identify.problem.redrawn_force`, the force being known only
  to within it), and each residual is fitted by a plane in theta over the cloud and the point: the
  plane's slopes are the Jacobian of the intervals (a regression over the step, not a difference
  of two runs), and the variance about the plane (its degrees of freedom: the cloud's size less p)
  is the residual's roughness at that scale. A smooth measure (the first impacts, the signal before
  the horizon) lies on its plane to within the chaos the redrawn force adds; a rough one is weighted
  down by its own spread.

The intervals (:func:`bearingshaft.identify.fit.sandwich`) use the draws themselves, not only their
variances: the residuals of the K_NOISE noise draws, and of the cloud's runs about their planes, are
realisations of what the test's noise and the chaos do to the whole residual vector at once, with
all their correlations across channels, windows and blocks (a chaotic realisation moves every
envelope together, which per-residual weights cannot say). Projected on the Jacobian they give the
scatter of the gradient, and so of the estimate.

Both are estimated from few draws, so each is smoothed along a series' points (a moving average
over SMOOTH_SHARE of them: neighbouring samples and windows scatter alike) for series of at least
SMOOTH_MIN points. Shorter blocks (the first impacts, the contact measures: a row per load cell, a
column per quantity) keep each residual's own variance: the cells do not scatter alike (on the
apparatus the top tips' first contact chatters, its time jumping by whole bounces, while the bottom
tips' is smooth and known to ~1e-4 of its length; a variance pooled over the cells weighted the
smooth ones by the chattering ones' scatter, 40-160x too little, and left the fit to the rough
measures). A variance from K_NOISE draws and a cloud of 2p + 2 degrees of freedom is known to
~50 %, which weights tolerate (the intervals' sandwich uses the draws, not only the variances).
sigma_i = sqrt(noise_i + roughness_i).
"""

from __future__ import annotations

import numpy as np

from bearingshaft.identify.residuals import Target, blocks
from fem.uff import TimeHistory

K_NOISE = 12  # noise draws on the model's record (cheap: no model run); 12 give each variance to ~40 % before
# smoothing, a few per cent after it along a series of hundreds of points
CLOUD_PER_PARAMETER = 3  # cloud points per parameter and one more: 3 (p + 1), leaving 2p + 2 degrees of freedom
# to each residual's variance about its plane (12 runs for 3 parameters, once per pass)
SMOOTH_SHARE = 0.1  # the variances are averaged over this share of a series' points
SMOOTH_MIN = 10  # ... in series of at least this many points
DAQ_OVERSAMPLE = 4  # the noise drawn at 4x the record's rate and anti-alias filtered down, as a DAQ records it


def smoothed(V: np.ndarray) -> np.ndarray:
    """A block's per-residual variances (series x points) averaged along each series over SMOOTH_SHARE of its
    points (edges: the window shrinks), when it has at least SMOOTH_MIN points; else as they are (module docstring).

    Parameters
    ----------
    V : (k, n) ndarray of float

    Examples
    --------
    >>> smoothed(np.array([[0.0] * 10 + [9.0] * 10]))[0, [0, 9, 10, 19]].tolist()  # 20 points: over 3
    [0.0, 3.0, 6.0, 9.0]
    >>> smoothed(np.array([[1.0, 4.0], [1e-4, 2.0]])).tolist()  # short rows: each residual its own
    [[1.0, 4.0], [0.0001, 2.0]]
    """
    V = np.atleast_2d(np.asarray(V, float))
    k, n = V.shape
    if n < SMOOTH_MIN:
        return V.copy()
    half = max(1, int(round(SMOOTH_SHARE * n / 2)))
    c = np.concatenate([np.zeros((k, 1)), np.cumsum(V, axis=1)], axis=1)
    i = np.arange(n)
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, n)
    return (c[:, hi] - c[:, lo]) / (hi - lo)


def noisy(channels: list[TimeHistory], noise: np.ndarray, rng: np.random.Generator) -> list[TimeHistory]:
    """``channels`` with a fresh draw of DAQ-shaped noise of RMS ``noise`` (one per channel) added.

    Parameters
    ----------
    channels : list of TimeHistory
        On one grid.
    noise : (n,) ndarray of float
        Each channel's noise RMS, its unit.
    rng : numpy Generator
    """
    from bearingshaft.identify.virtual import daq_noise

    n = channels[0].data.size
    fs = 1.0 / channels[0].dt_s
    e = daq_noise((len(channels), n), fs, DAQ_OVERSAMPLE, rng)
    return [TimeHistory(h.name, h.node, h.direction, h.quantity, h.data + nz * row, h.dt_s, h.t0_s)
            for h, nz, row in zip(channels, noise, e, strict=True)]


MAX_DRAW_VALUES = 400_000  # a block's noise draws are kept (for the intervals) up to this many values in all


def noise_variance(target: Target, model: list[TimeHistory], draws: int = K_NOISE,
                   seed: int = 0) -> tuple[dict, dict]:
    """Each residual's variance from the test's noise (module docstring), smoothed, and the draws themselves.

    Parameters
    ----------
    target : Target
        With ``noise`` (each channel's noise RMS).
    model : list of TimeHistory
        The model's compared channels at the point (``target.names`` order, on the test's grid).
    draws : int
    seed : int

    Returns
    -------
    (dict, dict)
        {block: (series, points) variances} and {block: (draws, n_b) each draw's residuals less their mean}
        (blocks of at most MAX_DRAW_VALUES values in all).
    """
    if target.noise is None or draws < 2:
        return {}, {}
    rng = np.random.default_rng(seed)
    runs = [blocks(target.with_tests(noisy(model, target.noise, rng)), model) for _ in range(draws)]
    var, dev = {}, {}
    for m in runs[0]:
        R = np.array([r[m] for r in runs])
        var[m] = smoothed(np.var(R, axis=0, ddof=1))
        if R.size <= MAX_DRAW_VALUES:
            D = R.reshape(draws, -1)
            dev[m] = D - D.mean(axis=0)
    return var, dev


def cloud_size(p: int) -> int:
    """Points of the cloud for ``p`` parameters: CLOUD_PER_PARAMETER (p + 1).

    Parameters
    ----------
    p : the number of parameters
    """
    return CLOUD_PER_PARAMETER * (p + 1)


def cloud(theta: np.ndarray, step, bounds, seed: int = 0) -> list[np.ndarray]:
    """The cloud around ``theta``: a Latin hypercube of :func:`cloud_size` points in theta -+ ``step``, reflected
    into ``bounds`` (module docstring).

    Parameters
    ----------
    theta : (p,) ndarray of float
    step : float or (p,) array_like of float
        The half-width in each scaled parameter.
    bounds : ((p,), (p,)) ndarrays of float
    seed : int

    Returns
    -------
    list of (p,) ndarray

    Examples
    --------
    >>> pts = cloud(np.zeros(2), 0.01, (np.full(2, -1.0), np.full(2, 1.0)))
    >>> len(pts), bool(np.all(np.abs(np.array(pts)) <= 0.01))
    (9, True)
    """
    theta = np.asarray(theta, float)
    p = theta.size
    k = cloud_size(p)
    rng = np.random.default_rng(seed)
    # each parameter's k values in k equal strata of [-1, 1], shuffled independently
    u = (np.array([rng.permutation(k) for _ in range(p)]).T + rng.random((k, p))) / k * 2.0 - 1.0
    pts = theta + np.asarray(step, float) * u
    lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    pts = np.where(pts > hi, 2 * hi - pts, pts)
    pts = np.where(pts < lo, 2 * lo - pts, pts)
    return [np.clip(q, lo, hi) for q in pts]


def local_fit(theta: np.ndarray, points: list[np.ndarray], runs: list[dict]) -> tuple[dict, dict, dict]:
    """Each residual fitted by a plane in theta over the runs (module docstring): its slopes and its variance
    about the plane, smoothed.

    Parameters
    ----------
    theta : (p,) ndarray of float
        Where the slopes are taken.
    points : list of (p,) ndarray
        The runs' theta (theta itself among them).
    runs : list of dict
        {block: residuals} of each run.

    Returns
    -------
    (slopes, variances, about): {block: (n_b, p) ndarray}, {block: (series, points) ndarray} and
    {block: (runs, n_b) ndarray}: each run's residuals about the planes over sqrt(dof) (their outer products sum
    to the covariance about the planes), dof = runs - p - 1.

    Examples
    --------
    >>> pts = [np.array([0.0]), np.array([1.0]), np.array([2.0]), np.array([3.0])]
    >>> runs = [{"b": np.array([[2.0 * x[0] + e]])} for x, e in zip(pts, [0.1, -0.1, -0.1, 0.1])]
    >>> g, v, _ = local_fit(np.zeros(1), pts, runs)
    >>> round(float(g["b"][0, 0]), 12), round(float(v["b"][0, 0]), 12)  # slope 2; 4 x 0.01 over 4 - 2 dof
    (2.0, 0.02)
    """
    X = np.column_stack([np.ones(len(points)), np.array(points) - np.asarray(theta, float)])
    dof = len(points) - X.shape[1]
    slopes, var, about = {}, {}, {}
    for m in runs[0]:
        shape = runs[0][m].shape
        if not all(r[m].shape == shape for r in runs):
            continue
        Y = np.array([r[m].ravel() for r in runs])
        if Y.shape[1] == 0:
            continue
        coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
        slopes[m] = coef[1:].T
        if dof > 0:
            e = Y - X @ coef
            var[m] = smoothed((np.sum(e**2, axis=0) / dof).reshape(shape))
            about[m] = e / np.sqrt(dof)
    return slopes, var, about


def sigmas(noise: dict, rough: dict, found: dict) -> dict:
    """{block: sqrt(noise + roughness)} per residual, for the blocks in ``found`` (a block with neither: left out).

    Parameters
    ----------
    noise, rough : dict
        {block: variances}.
    found : dict
        {block: residuals}: the blocks and their shapes.
    """
    out = {}
    for m, R in found.items():
        v = np.zeros(R.shape)
        seen = False
        for part in (noise, rough):
            if m in part and part[m].shape == R.shape:
                v = v + part[m]
                seen = True
        if seen:
            out[m] = np.sqrt(v)
    return out


__all__ = ["noise_variance", "local_fit", "cloud", "cloud_size", "sigmas", "smoothed", "noisy", "K_NOISE",
           "CLOUD_PER_PARAMETER"]
