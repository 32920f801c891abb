"""The response map: what a stepped-sine test sees at each frequency, classified by the exact flow.

At each frequency of a sweep (up or down, in the order given) the harmonic load b P cos(2 pi f t)
runs from the state the previous frequency ended in, through the exact period map and its tangent
(:class:`reduced.transient.lyapunov.PeriodMap`), and the response is classified from its Poincare
samples y_k (the state once per forcing period), its largest Lyapunov exponent lambda and its
spectrum (:func:`classify`):

- ``periodic`` / ``subharmonic``: the samples return, |y_{k+p} - y_k| <= ``periodic_tol`` (relative, in
  the energy norm) for the smallest p <= ``max_period`` (p = 1: periodic; p > 1: a subharmonic of
  period p forcing periods). A response still contracting (lambda < -lambda_tol), or one free of
  contact (a damped linear motion, whose periodic orbit is unique and attracts every state), is
  finished by Newton on the p-period map with its exact Jacobian (the product of the segment
  exponentials): y <- y + (I - dF^p/dy)^-1 (F^p(y) - y), accepted when the orbit it finds is stable
  and is the one the run approaches (within ``newton_radius`` of the last sample, or free of contact
  with the run). Its exponent is then exact: lambda = log max |mu| / (p T), mu the orbit's Floquet
  multipliers, and p is reduced to the orbit's smallest period.
- ``chaotic``: no return and lambda > lambda_tol;
- ``quasi_periodic``: no return and |lambda| <= lambda_floor sigma with lambda_tol within that too
  (a torus: lambda = 0, a discrete spectrum).

Undecided records (a long transient, or an exponent not yet within its error of 0) run another block
of ``n_record`` periods, up to ``max_blocks``; then the sign of lambda decides, with ``settled`` False.

lambda_tol = max(``lambda_floor`` sigma, 3 s_lambda) with sigma the slowest linear decay rate of
the structure (:func:`reduced.periodic.stepped_sine.slowest_decay_rate`) and s_lambda the standard
error of the four quarter-record estimates of lambda. ``broadband`` is the fraction of the power of
the Poincare samples of the first monitored row (mean removed, Hann window) outside the five
strongest lines (+-2 bins): 0 for a periodic or quasi-periodic response, large for chaos.

Each frequency records, over the last ``n_record`` periods (over the orbit when periodic): the
per-period maxima of |r . x| for every monitored row r (their min, mean and max: the envelope a
test measures), the asymmetry max |x_a - x_b| / max(|x_a|, |x_b|) of the ``mirror`` pair, and the
Poincare samples. A small seeded kick (``kick``, relative, energy norm) at each frequency's start
breaks exact symmetries, as a rig's imperfections do: without it a symmetric orbit unstable to
asymmetric motion would persist forever on its invariant subspace.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.periodic.stepped_sine import slowest_decay_rate
from reduced.transient.exact_tables import ExactIntegratorError, modal_table, state_table
from reduced.transient.lyapunov import PeriodMap, energy_norm_matrix

REGIMES = ("periodic", "subharmonic", "quasi_periodic", "chaotic")
SPECTRAL_LINES = 5  # strongest lines of the Poincare spectrum counted as lines (their +-2 bins)
JUMP_RATIO = 1.2  # a sweep jumps where the mean per-period max |x| changes by this factor between fine steps
SPECTRUM_ORDERS = 4  # the order spectrum of x1 spans 0 .. this many times the forcing frequency ...
SPECTRUM_BINS_PER_ORDER = 32  # ... in bins of 1/32 of it (a subharmonic of period p <= 8 has its lines apart)


@dataclass(frozen=True, slots=True)
class MapOptions:
    """How each frequency of a response map is run and classified (module docstring).

    Parameters
    ----------
    n_transient : int
        Periods run first at each frequency, not recorded, >= 0.
    n_record : int
        Periods recorded (Poincare samples, peaks, exponent), >= 16.
    max_blocks : int
        Record blocks at most while a response contracts without returning, >= 1.
    periodic_tol : float
        Relative return distance of a periodic response.
    max_period : int
        Longest period looked for, in forcing periods.
    newton_tol : float
        Relative closure of a periodic orbit found by Newton.
    newton_iter : int
        Newton steps at most.
    newton_radius : float
        Relative distance from the run within which Newton's orbit is accepted in contact.
    lambda_floor : float
        lambda_tol is at least this fraction of the slowest linear decay rate.
    kick : float
        Relative size of the seeded kick at each frequency's start (0: none).
    samples_per_period : int
        Uniform samples of each period for the peaks.
    inner_samples : int
        Samples inside each contact segment for the peaks.
    seed : int
        Of the kicks and tangent starts.
    """

    n_transient: int = 32
    n_record: int = 128
    max_blocks: int = 4
    periodic_tol: float = 1e-6
    max_period: int = 8
    newton_tol: float = 1e-10
    newton_iter: int = 10
    newton_radius: float = 1e-2
    lambda_floor: float = 0.1
    kick: float = 1e-9
    samples_per_period: int = 64
    inner_samples: int = 8
    seed: int = 0

    def __post_init__(self) -> None:
        for name, lo in (("n_transient", 0), ("n_record", 16), ("max_blocks", 1), ("max_period", 1),
                         ("newton_iter", 1), ("samples_per_period", 0), ("inner_samples", 0), ("seed", 0)):
            _check.integer(name, getattr(self, name), lo=lo)
        for name in ("periodic_tol", "newton_tol", "newton_radius", "lambda_floor"):
            _check.positive(name, getattr(self, name))
        _check.number("kick", self.kick, lo=0.0, lo_open=False)
        if self.max_period > self.n_record // 4:
            raise _check.InvalidArgument(f"max_period must be <= n_record / 4 = {self.n_record // 4}, "
                                         f"got {self.max_period}")


@dataclass(frozen=True, eq=False)
class PointResponse:
    """The response at one frequency of a map (:func:`classify`).

    Attributes
    ----------
    regime : str
        One of :data:`REGIMES`.
    period_k : int
        Period in forcing periods (periodic, subharmonic), 0 otherwise.
    lyapunov_per_s : float
        1/s, the largest Lyapunov exponent (Floquet's for an orbit found).
    lyapunov_tol : float
        1/s, lambda_tol of the classification.
    max_abs_mu : float
        The largest Floquet multiplier's modulus (nan if no orbit).
    settled : bool
        The classification is final (False: still contracting when the blocks ran out).
    peak : (K, p) ndarray of float
        m, the per-period max |r . x| over the recorded periods (over the orbit when periodic).
    poincare : (K, 2n) ndarray of float
        The Poincare samples recorded (the orbit's p samples when periodic).
    asymmetry : float
        Of the mirror pair (nan without one).
    broadband : float
        Fraction of the Poincare spectrum outside its strongest lines.
    n_periods : int
        Periods run.
    state : (2n,) ndarray of float
        Where the run ended (on the orbit when periodic).
    contact : bool
        A stop closed during the recorded periods (on the orbit when periodic).
    spectrum : (SPECTRUM_ORDERS * SPECTRUM_BINS_PER_ORDER + 1,) ndarray of float32
        The order spectrum of the first monitored row (:func:`order_spectrum`): the fraction of its power
        (mean removed) in each bin of response frequency / forcing frequency.
    """

    regime: str
    period_k: int
    lyapunov_per_s: float
    lyapunov_tol: float
    max_abs_mu: float
    settled: bool
    peak: np.ndarray
    poincare: np.ndarray
    asymmetry: float
    broadband: float
    n_periods: int
    state: np.ndarray
    contact: bool
    spectrum: np.ndarray


@dataclass(frozen=True, eq=False)
class ResponseMap:
    """A stepped sine classified at every frequency, in sweep order (:func:`response_map`).

    Attributes
    ----------
    amplitude_N : float
        N, P.
    direction : str
        ``up`` or ``down`` (the order of ``freq_hz``).
    freq_hz : (k,) ndarray of float
        Hz, in sweep order.
    point_names : tuple of str
        The monitored rows' names.
    points : list of PointResponse
        One per frequency.
    jump : (k,) ndarray of bool
        The response jumped on arriving at this frequency (:func:`jumps`).
    wall_s : (k,) ndarray of float
        s, per frequency.
    options : MapOptions
        As run.
    """

    amplitude_N: float
    direction: str
    freq_hz: np.ndarray
    point_names: tuple[str, ...]
    points: list
    jump: np.ndarray
    wall_s: np.ndarray
    options: MapOptions = field(default_factory=MapOptions)

    @property
    def regime(self) -> list[str]:
        return [p.regime for p in self.points]

    @property
    def lyapunov_per_s(self) -> np.ndarray:
        return np.array([p.lyapunov_per_s for p in self.points])

    def peak_stats(self, row: int = 0) -> np.ndarray:
        """(k, 3) m: min, mean and max over the recorded periods of the per-period max |r . x| of ``row``."""
        return np.array([[p.peak[:, row].min(), p.peak[:, row].mean(), p.peak[:, row].max()] for p in self.points])

    @property
    def spectrum_orders(self) -> np.ndarray:
        """The orders (response frequency / forcing frequency) of the bins of each point's ``spectrum``."""
        return np.arange(SPECTRUM_ORDERS * SPECTRUM_BINS_PER_ORDER + 1) / SPECTRUM_BINS_PER_ORDER

    @property
    def jump_hz(self) -> np.ndarray:
        """Hz, the frequencies where the sweep jumped."""
        return self.freq_hz[self.jump]


# -- the frequency grid -----------------------------------------------------------------------------------
def map_frequencies(freq_min_hz: float, freq_max_hz: float, bands, step_hz: float, coarse_points: int) -> np.ndarray:
    """Hz, increasing: ``step_hz`` steps over each band (on the grid of multiples of step_hz, its ends
    included), ``coarse_points`` log-spaced points over [freq_min_hz, freq_max_hz] outside the bands.

    Parameters
    ----------
    freq_min_hz, freq_max_hz : Hz, the whole range
    bands : iterable of (lo, hi) Hz, the fine intervals (clipped to the range)
    step_hz : Hz, the fine step
    coarse_points : points of the coarse log grid over the whole range (before dropping those in bands)

    Returns
    -------
    ndarray
        (k,) Hz, rounded to 1e-9 Hz.

    Examples
    --------
    >>> map_frequencies(10.0, 100.0, [(20.0, 20.3)], 0.1, 3).tolist()
    [10.0, 20.0, 20.1, 20.2, 20.3, 31.622776602, 100.0]
    """
    lo_all, hi_all = float(freq_min_hz), float(freq_max_hz)
    pts = list(np.geomspace(lo_all, hi_all, coarse_points)) if coarse_points > 0 else []
    fine = []
    for lo, hi in bands:
        lo, hi = max(float(lo), lo_all), min(float(hi), hi_all)
        if hi < lo:
            continue
        k0, k1 = math.ceil(lo / step_hz - 1e-9), math.floor(hi / step_hz + 1e-9)
        fine += [k * step_hz for k in range(k0, k1 + 1)]
        pts = [f for f in pts if not lo <= f <= hi]
    return np.unique(np.round(np.array(pts + fine, float), 9))


def merge_bands(bands, margin_hz: float = 0.0) -> list[tuple[float, float]]:
    """The union of intervals (lo, hi), each widened by ``margin_hz`` on both sides.

    Parameters
    ----------
    bands : iterable of (lo, hi)
        Hz, in any order, overlapping or not.
    margin_hz : float
        Hz, added on both sides of each.

    Returns
    -------
    list of (lo, hi)
        Hz, disjoint, increasing, rounded to 1e-9 Hz.

    Examples
    --------
    >>> merge_bands([(1.0, 2.0), (2.5, 3.0), (5.0, 6.0)], 0.3)
    [(0.7, 3.3), (4.7, 6.3)]
    """
    out: list[list[float]] = []
    for lo, hi in sorted((float(a) - margin_hz, float(b) + margin_hz) for a, b in bands):
        if out and lo <= out[-1][1]:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return [(round(a, 9), round(b, 9)) for a, b in out]


def linear_contact_bands(system: GapSystem, load, amplitude_N: float, freq_min_hz: float, freq_max_hz: float,
                         n_freq: int = 4000) -> list[tuple[float, float]]:
    """Hz: where the linear (open-gap) steady response to b P cos(2 pi f t) reaches a stop, |s_j| >= |o_j|,
    on ``n_freq`` log-spaced frequencies (each interval from the last point below to the first above).

    Parameters
    ----------
    system : the gap system (damped)
    load : (n,) b
    amplitude_N : N, P
    freq_min_hz, freq_max_hz : Hz
    n_freq : frequencies of the scan

    Returns
    -------
    list of (lo, hi)
        Hz, increasing, disjoint.
    """
    b = _check.vector("load", load, system.n)
    f = np.geomspace(freq_min_hz, freq_max_hz, n_freq)
    w = 2 * np.pi * f
    Z = system.K[None] - w[:, None, None] ** 2 * system.M[None] + 1j * w[:, None, None] * system.C[None]
    X = np.linalg.solve(Z, np.broadcast_to(amplitude_N * b, (f.size, system.n))[..., None])[..., 0]
    s = np.abs(X @ system.B.T)
    touch = np.any(s >= np.abs(system.offset)[None, :], axis=1)
    bands, i = [], 0
    while i < f.size:
        if touch[i]:
            j = i
            while j + 1 < f.size and touch[j + 1]:
                j += 1
            bands.append((float(f[max(i - 1, 0)]), float(f[min(j + 1, f.size - 1)])))
            i = j + 1
        else:
            i += 1
    return bands


# -- one frequency ----------------------------------------------------------------------------------------
def _returns(Y: np.ndarray, pm: PeriodMap, max_period: int, tail: int) -> np.ndarray:
    """d_p = max over the last ``tail`` samples of |y_{k+p} - y_k| / |y| (energy norm), p = 1..max_period."""
    D = pm.norm_matrix
    Z = Y @ D.T
    size = max(float(np.max(np.linalg.norm(Z, axis=1))), 1e-300)
    K = Z.shape[0]
    out = np.full(max_period, np.inf)
    for p in range(1, max_period + 1):
        k0 = max(K - tail - p, 0)
        if K - p > k0:
            out[p - 1] = float(np.max(np.linalg.norm(Z[k0 + p:] - Z[k0:K - p], axis=1))) / size
    return out


def _broadband(x: np.ndarray) -> float:
    """Fraction of the power of x (mean removed, Hann window) outside the SPECTRAL_LINES strongest lines (+-2 bins)."""
    x = np.asarray(x, float) - np.mean(x)
    P = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    total = float(P.sum())
    if total <= 1e-300 * max(x.size, 1) or total == 0.0:
        return 0.0
    keep = np.zeros(P.size, bool)
    Q = P.copy()
    for _ in range(SPECTRAL_LINES):
        i = int(np.argmax(Q))
        keep[max(i - 2, 0):i + 3] = True
        Q[max(i - 2, 0):i + 3] = -1.0
    return float(P[~keep].sum() / total)


def order_spectrum(x: np.ndarray, periodic: bool = False) -> np.ndarray:
    """The order spectrum of K periods of a signal sampled S times a period, x (K, S): the fraction of its
    power (mean removed) in each bin of order = response frequency / forcing frequency, 0 .. SPECTRUM_ORDERS
    in steps of 1 / SPECTRUM_BINS_PER_ORDER (float32). A Hann window over the K periods, unless ``periodic``
    (x is one period of a K-periodic orbit: its lines fall on the orders j / K exactly).

    Parameters
    ----------
    x : (K, S) ndarray of float
        The signal, period by period.
    periodic : bool
        x repeats after its K periods (no window).

    Returns
    -------
    ndarray
        (SPECTRUM_ORDERS * SPECTRUM_BINS_PER_ORDER + 1,) float32, summing to 1 (0 for a constant x).

    Examples
    --------
    >>> t = np.arange(4 * 64) / 64  # 4 periods, 64 samples each
    >>> s = order_spectrum((np.cos(2 * np.pi * t) + np.cos(2 * np.pi * 2.5 * t)).reshape(4, 64), periodic=True)
    >>> [round(float(v), 6) for v in s[[32, 80]]], round(float(s.sum()), 6)
    ([0.5, 0.5], 1.0)
    """
    K, S = x.shape
    v = x.ravel() - np.mean(x)
    if not periodic:
        v = v * np.hanning(v.size)
    P = np.abs(np.fft.rfft(v)) ** 2
    order = np.arange(P.size) / K
    keep = order <= SPECTRUM_ORDERS + 0.5 / SPECTRUM_BINS_PER_ORDER
    out = np.zeros(SPECTRUM_ORDERS * SPECTRUM_BINS_PER_ORDER + 1)
    np.add.at(out, np.round(order[keep] * SPECTRUM_BINS_PER_ORDER).astype(int), P[keep])
    total = float(P.sum())
    return (out / total if total > 0.0 else out).astype(np.float32)


def _asymmetry(peak: np.ndarray, mirror) -> float:
    """max |x_a - x_b| / max(|x_a|, |x_b|) from the peaks of the rows (a, b, a - b) = mirror."""
    if mirror is None:
        return float("nan")
    a, b, d = mirror
    return float(peak[:, d].max() / max(peak[:, a].max(), peak[:, b].max(), 1e-300))


def _newton_orbit(pm: PeriodMap, y: np.ndarray, p: int, opts: MapOptions):
    """(y*, dF^p/dy at y*, stop crossings on the orbit) of a p-periodic orbit by Newton from y, or None."""
    size = max(pm.norm(y), 1e-300)
    N = y.size
    for _ in range(opts.newton_iter):
        try:
            run = pm.jacobian(y, p)
        except ExactIntegratorError:
            return None
        res = run.y - y
        if pm.norm(res) <= opts.newton_tol * size:
            return y, run.tangent, run.n_events + int(np.any(run.active))
        try:
            y = y + np.linalg.solve(np.eye(N) - run.tangent, res)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(y)):
            return None
    return None


def _orbit_point(pm: PeriodMap, y: np.ndarray, J: np.ndarray, p: int, lam_tol: float, mirror, opts: MapOptions,
                 n_run: int) -> PointResponse:
    """The response on a p-periodic orbit through y (monodromy J): its p periods' peaks and samples,
    the exponent log max |mu| / (p T)."""
    mu = float(np.max(np.abs(np.linalg.eigvals(J))))
    r = pm.run(y, p, samples_per_period=opts.samples_per_period, inner_samples=opts.inner_samples,
               record_samples=True)
    lam = math.log(max(mu, 1e-300)) / (p * pm.period_s)
    return PointResponse("periodic" if p == 1 else "subharmonic", p, lam, lam_tol, mu, True, r.peak,
                         r.poincare[:-1].copy(), _asymmetry(r.peak, mirror), 0.0, n_run + p, y.copy(),
                         bool(r.n_events or np.any(r.active)), order_spectrum(r.samples[:, :, 0], periodic=True))


def _finish_orbit(pm: PeriodMap, r, y: np.ndarray, d: np.ndarray, p: int, opts: MapOptions):
    """A periodic orbit the run settles on, by Newton from its last state y: the return period p if it
    returned, else period 1 and the two nearest other returns; accepted when stable and either returned,
    within ``newton_radius`` of y, or the run and the orbit are free of contact (a linear motion, whose
    periodic orbit is unique and attracts all). (y*, J, minimal period) or None."""
    others = [int(i) + 1 for i in np.argsort(d) if int(i) > 0][:2]
    for q in ([p] if p else [1, *others]):
        orbit = _newton_orbit(pm, y, q, opts)
        if orbit is None:
            continue
        ys, J, crossings = orbit
        if not np.max(np.abs(np.linalg.eigvals(J))) < 1.0:
            continue
        near = pm.norm(ys - y) <= opts.newton_radius * max(pm.norm(y), 1e-300)
        free = crossings == 0 and r.n_events == 0 and not np.any(r.active)
        if p or near or free:
            return _minimal_period(pm, ys, J, q, opts)
    return None


def _minimal_period(pm: PeriodMap, ys: np.ndarray, J: np.ndarray, q: int, opts: MapOptions):
    """(y*, J, p): the smallest p dividing q with F^p(y*) = y* (a q-periodic orbit may have a shorter
    period: every periodic orbit is also 2-, 3-, ... periodic), its monodromy over p periods."""
    if q == 1:
        return ys, J, 1
    Y = pm.run(ys, q, samples_per_period=0, inner_samples=0).poincare
    size = max(pm.norm(ys), 1e-300)
    for p in range(1, q):
        if q % p == 0 and pm.norm(Y[p] - ys) <= opts.periodic_tol * size:
            return ys, pm.jacobian(ys, p).tangent, p
    return ys, J, q


def classify(pm: PeriodMap, y0: np.ndarray, sigma: float, opts: MapOptions, mirror=None,
             rng: np.random.Generator | None = None, defer: bool = True) -> PointResponse:
    """The response at one frequency from the state y0 (module docstring).

    Parameters
    ----------
    pm : the period map at this frequency (its rows: the monitored points, then the mirror difference)
    y0 : (2n,) the state the previous frequency ended in
    sigma : 1/s, the slowest linear decay rate (scale of lambda_tol)
    opts : MapOptions
    mirror : (a, b, a - b) row indices of the mirror pair in pm.rows, or None
    rng : of the kick and the tangent start (default seeded by opts.seed)
    defer : march the record blocks without sampling and sample them afterwards only if they are read
        (:meth:`PeriodMap.sampled`); False samples them on the march. The same numbers either way: a
        guess of which costs less (a response that ends chaotic reads its samples, a periodic one does not)

    Returns
    -------
    PointResponse
    """
    rng = rng if rng is not None else np.random.default_rng(opts.seed)
    N = y0.size
    Dinv = pm.norm_inverse  # np.linalg.inv(pm.norm_matrix), worked out once by the period map
    y = np.array(y0, float)
    if opts.kick > 0.0:
        u = Dinv @ rng.standard_normal(N)
        y = y + opts.kick * max(pm.norm(y), 1e-300) * u / pm.norm(u)
    w = Dinv @ rng.standard_normal((N, 1))
    W, active, n_run = w / pm.norm(w[:, 0]), None, 0
    if opts.n_transient:
        r = pm.run(y, opts.n_transient, tangent=W, samples_per_period=0, inner_samples=0)
        y, W, active, n_run = r.y, r.tangent, r.active, opts.n_transient
    for _ in range(opts.max_blocks):
        # the record's peaks and samples are read only if no periodic orbit ends the classification here: with
        # ``defer`` the march records its segments and samples them afterwards if they are (PeriodMap.sampled,
        # the same numbers), else it samples them on the way (cheaper where they are read: in a chaotic band)
        r = pm.run(y, opts.n_record, tangent=W, active=active, samples_per_period=opts.samples_per_period,
                   inner_samples=opts.inner_samples, record_samples=True, defer_samples=defer)
        n_run += opts.n_record
        y, W, active = r.y, r.tangent, r.active
        logs = r.log_growth[:, 0] / pm.period_s
        lam = float(logs.mean())
        quarters = np.array([q.mean() for q in np.array_split(logs, 4)])
        floor = opts.lambda_floor * sigma
        lam_tol = max(floor, 1.5 * float(np.std(quarters, ddof=1)))  # 3 standard errors of the mean of 4
        Y = r.poincare[1:]
        contact = bool(r.n_events or np.any(r.active))
        d = _returns(Y, pm, opts.max_period, opts.n_record // 4)
        p = int(np.argmax(d <= opts.periodic_tol)) + 1 if np.any(d <= opts.periodic_tol) else 0
        if p or lam < -lam_tol or not contact:  # returned, contracting, or linear (a unique periodic attractor)
            orbit = _finish_orbit(pm, r, y, d, p, opts)
            if orbit is not None:
                return _orbit_point(pm, *orbit[:2], orbit[2], lam_tol, mirror, opts, n_run)
        sure = lam_tol <= floor  # the finite-time error is below the floor: a near-zero exponent is zero
        if lam > lam_tol or (abs(lam) <= floor and sure):
            regime = "chaotic" if lam > lam_tol else "quasi_periodic"
            r = pm.sampled(r)
            return PointResponse(regime, 0, lam, lam_tol, float("nan"), True, r.peak, Y.copy(),
                                 _asymmetry(r.peak, mirror), _broadband(Y[:, 0]), n_run, y.copy(), contact,
                                 order_spectrum(r.samples[:, :, 0]))
    r = pm.sampled(r)
    spec = order_spectrum(r.samples[:, :, 0])
    # undecided when the blocks ran out (a long transient, or an exponent within its error of 0): by its sign
    if lam > floor or abs(lam) <= floor:
        regime = "chaotic" if lam > floor else "quasi_periodic"
        return PointResponse(regime, 0, lam, lam_tol, float("nan"), False, r.peak, Y.copy(),
                             _asymmetry(r.peak, mirror), _broadband(Y[:, 0]), n_run, y.copy(), contact, spec)
    q = int(np.argmin(d)) + 1  # still contracting when the blocks ran out: the nearest return, not final
    return PointResponse("periodic" if q == 1 else "subharmonic", q, lam, lam_tol, float("nan"), False, r.peak,
                         Y.copy(), _asymmetry(r.peak, mirror), _broadband(Y[:, 0]), n_run, y.copy(), contact,
                         spec)


# -- the sweep --------------------------------------------------------------------------------------------
def _fixed_norm(system: GapSystem, freq_hz: float) -> tuple | None:
    """(D, D^-1) of :func:`reduced.transient.lyapunov.energy_norm_matrix` when it does not depend on the
    frequency (K positive definite: the PeriodMap of every frequency works out the same two matrices), else
    None (a free structure: D at each frequency's omega).

    Parameters
    ----------
    system : the gap system
    freq_hz : Hz, any frequency of the sweep (unused when K is positive definite)

    Returns
    -------
    tuple or None
        (D, D^-1), each (2n, 2n).
    """
    try:
        np.linalg.cholesky(system.K)
    except np.linalg.LinAlgError:
        return None
    D = energy_norm_matrix(system, 2.0 * np.pi * freq_hz)
    return D, np.linalg.inv(D)


def _defer_after(points: list) -> bool:
    """Whether the next frequency's record blocks are sampled after the march (:func:`classify`'s ``defer``):
    yes unless the previous frequency read its samples (a chaotic, quasi-periodic or unsettled response: a
    sweep stays in such a band for many steps, where sampling on the march costs less than replaying it)."""
    return not points or (points[-1].settled and points[-1].regime in ("periodic", "subharmonic"))


def jumps(freq_hz: np.ndarray, points: list, max_step_hz: float) -> np.ndarray:
    """(k,) bool: the response jumped on arriving at frequency k from k - 1, a step of at most
    1.5 ``max_step_hz`` (coarse steps change the response anyway): its regime or period changed, or the
    mean per-period max |x| of the first row changed by more than JUMP_RATIO.

    Parameters
    ----------
    freq_hz : (k,) Hz in sweep order
    points : the PointResponse of each
    max_step_hz : Hz, the largest step between neighbours that can show a jump

    Returns
    -------
    ndarray
        (k,) bool, False at the first frequency.
    """
    out = np.zeros(len(points), bool)
    for k in range(1, len(points)):
        if abs(freq_hz[k] - freq_hz[k - 1]) > 1.5 * max_step_hz:
            continue
        a, b = points[k - 1], points[k]
        ma, mb = float(a.peak[:, 0].mean()), float(b.peak[:, 0].mean())
        ratio = max(ma, mb) / max(min(ma, mb), 1e-300)
        out[k] = (a.regime, a.period_k) != (b.regime, b.period_k) or ratio > JUMP_RATIO
    return out


def response_map(system: GapSystem, load, amplitude_N: float, freq_hz, *, direction: str = "up", point_rows=None,
                 point_names=None, mirror=("x1", "x3"), options: MapOptions | None = None, jump_step_hz: float = 0.0,
                 extend_step_hz: float = 0.0, y0=None, progress=None) -> ResponseMap:
    """A stepped sine by the exact flow, each frequency classified (module docstring; :func:`classify`).

    Parameters
    ----------
    system : the gap system, damped (:func:`reduced.periodic.stepped_sine.slowest_decay_rate`)
    load : (n,) the force direction b
    amplitude_N : N, P > 0
    freq_hz : Hz, the frequencies in sweep order
    direction : a label, ``up`` or ``down``
    point_rows, point_names : (p, n) the monitored points (default the DOFs); the first is the one the
        envelope, spectrum and jumps are read at
    mirror : two point names whose asymmetry is reported (skipped if either is missing)
    options : MapOptions
    jump_step_hz : Hz, the fine step: neighbours up to 1.5 times apart can show a jump (0: ``extend_step_hz``,
        else the smallest step)
    extend_step_hz : Hz; when > 0, a response in contact before a wider step is followed by steps of this
        size in the sweep's direction until it leaves contact or reaches the next frequency (the contact
        band found by the sweep itself, where the given fine bands end too early)
    y0 : (2n,) the state the sweep starts from (default rest)
    progress : None or a callable taking the fraction done

    Returns
    -------
    ResponseMap
        A failure of the exact flow is a RuntimeError naming the frequency.
    """
    _check.gap_system(system)
    b, P, freqs, opts, rows, names, pair = map_inputs(system, load, amplitude_N, freq_hz, direction, options,
                                                      point_rows, point_names, mirror)
    table = state_table(system)
    modal = modal_table(system, table)
    norm = _fixed_norm(system, float(freqs[0]))
    sigma = slowest_decay_rate(system, b)
    y = np.zeros(2 * system.n) if y0 is None else _check.vector("y0", y0, 2 * system.n)
    return sweep(lambda f: PeriodMap(system, b, P, f, rows=rows, table=table, modal=modal, norm=norm), y, P, freqs,
                 sigma, opts, direction=direction, names=names, mirror=pair, jump_step_hz=jump_step_hz,
                 extend_step_hz=extend_step_hz, progress=progress)


def map_inputs(system: GapSystem, load, amplitude_N: float, freq_hz, direction: str, options, point_rows,
               point_names, mirror) -> tuple:
    """A response map's inputs checked (one-line InvalidArgument naming the field) and its output rows: the
    points' rows, with the mirror pair's difference row appended where both its names are points.

    Parameters
    ----------
    system : the gap system (checked by the caller)
    load, amplitude_N, freq_hz, direction, options, point_rows, point_names, mirror : as :func:`response_map`

    Returns
    -------
    (b, P, freqs, opts, rows, names, pair) : the load (n,), its amplitude, the frequencies (> 0), the options,
        the output rows, their names, and (a, c, row of x_a - x_c) or None
    """
    b = _check.vector("load", load, system.n)
    P = _check.positive("amplitude_N", amplitude_N, "N")
    freqs = np.atleast_1d(_check.series("freq_hz", freq_hz))
    if np.any(freqs <= 0.0):
        raise _check.InvalidArgument("freq_hz must be > 0 Hz")
    _check.choice("direction", direction, ("up", "down"))
    opts = options if options is not None else MapOptions()
    rows = np.eye(system.n) if point_rows is None else np.atleast_2d(np.asarray(point_rows, float))
    names = tuple(point_names or system.dof_names)
    pair = None
    if all(m in names for m in mirror):
        a, c = names.index(mirror[0]), names.index(mirror[1])
        rows = np.vstack([rows, rows[a] - rows[c]])
        pair = (a, c, rows.shape[0] - 1)
    return b, P, freqs, opts, rows, names, pair


def sweep(period_map, y0: np.ndarray, amplitude_N: float, freq_hz: np.ndarray, sigma: float, opts: MapOptions, *,
          direction: str, names: tuple, mirror=None, jump_step_hz: float = 0.0, extend_step_hz: float = 0.0,
          progress=None, label: str = "response map") -> ResponseMap:
    """The stepped sine of :func:`response_map` on any period map: at each frequency, in order, ``period_map(f)``
    classified (:func:`classify`) from the state the previous frequency ended in, with the seeded kicks of one
    generator (``opts.seed``); a response in contact before a step wider than 1.5 ``extend_step_hz`` followed by
    steps of that size; the jumps (:func:`jumps`).

    Parameters
    ----------
    period_map : callable f (Hz) -> a period map with :class:`reduced.transient.lyapunov.PeriodMap`'s interface
    y0 : the start state
    amplitude_N : N, P (the result's label)
    freq_hz : Hz, in sweep order
    sigma : 1/s, the scale of the exponent's tolerance (:func:`classify`)
    opts : MapOptions
    direction : ``up`` or ``down``
    names : the monitored rows' names
    mirror : (a, b, a - b) row indices of the mirror pair, or None
    jump_step_hz, extend_step_hz, progress : as :func:`response_map`
    label : names the map in the error of a failed frequency

    Returns
    -------
    ResponseMap
    """
    y = y0
    rng = np.random.default_rng(opts.seed)
    points, wall, done = [], [], []
    todo = list(np.asarray(freq_hz, float))
    sign = 1.0 if direction == "up" else -1.0
    while todo:
        f = todo.pop(0)
        t0 = time.perf_counter()
        try:
            pt = classify(period_map(f), y, sigma, opts, mirror, rng, defer=_defer_after(points))
        except ExactIntegratorError as exc:
            raise RuntimeError(f"{label} at {f:.6g} Hz, {amplitude_N:g} N: {exc}") from None
        y = pt.state
        points.append(pt)
        done.append(f)
        wall.append(time.perf_counter() - t0)
        if extend_step_hz > 0.0 and pt.contact and todo and abs(todo[0] - f) > 1.5 * extend_step_hz:
            todo.insert(0, round(f + sign * extend_step_hz, 9))
        if progress is not None:
            progress(len(done) / (len(done) + len(todo)))
    freqs = np.array(done)
    step = jump_step_hz or extend_step_hz or (float(np.min(np.abs(np.diff(freqs)))) if freqs.size > 1 else 0.0)
    return ResponseMap(amplitude_N, direction, freqs, names, points, jumps(freqs, points, step), np.array(wall), opts)


__all__ = ["REGIMES", "SPECTRUM_BINS_PER_ORDER", "SPECTRUM_ORDERS", "MapOptions", "PointResponse", "ResponseMap",
           "classify", "jumps", "linear_contact_bands", "map_frequencies", "merge_bands", "order_spectrum",
           "response_map", "sweep"]
