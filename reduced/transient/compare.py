"""Comparing ringdowns when the motion is chaotic: the largest Lyapunov exponent, and the
quantities that stay comparable after nearby trajectories have separated.

Largest Lyapunov exponent (two-trajectory method, after Benettin et al. 1976, without
renormalisation): integrate the reference state y0 = (x0, v0) and a copy displaced by
delta_y, |delta_y| = delta |y0| in the energy norm

    |(x, v)|^2 = x^T K_n x + v^T M v   (K_n = K, or the closed-gap stiffness if K is singular),

and follow D(t) = |y_b(t) - y_a(t)| until it saturates, D(t) > ``saturation`` |y_a(t)|
(beyond that the two motions are no longer infinitesimally close). The oscillation of D
within a period is removed by taking its largest value in windows of ``window_s``,
L_k = ln max_{window k} D. A ringdown loses energy, so its exponent changes with time: an
impacting motion may keep nearby trajectories together for a while (L_k flat) and then
separate them fast. The estimate is therefore the least-squares slope lambda of L_k over
the *growth phase*: from the first window where D exceeds ``ONSET_FACTOR`` x its initial
level (the onset, reported) to the last window before saturation; when D never grows that
much (a stable or linear motion) the slope is fitted over the whole run. In a linear system
D is the norm of a free response, so lambda is the decay rate of its slowest mode
(-zeta omega; 0 undamped; +|c| / 2m with negative damping): the tests check these. In a
chaotic motion lambda > 0 and 1 / lambda, the Lyapunov time, is how fast a difference grows
once growth has set in: a pointwise comparison of two solutions means something before
the onset and for a few Lyapunov times after it, not beyond.

Beyond that horizon two runs are compared by what a chaotic motion keeps (RunComparison):
the energy envelope (mean energy over windows), the dominant frequency of a point's
spectrogram frame by frame, and the number of stop closures (impacts) counted from the
samples in the same way for both runs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.transient.spectrogram import StftAccumulator
from reduced.transient.store import Chunk

MAX_WINDOWS = 10_000  # energy-envelope windows of a long run (the window lengthens to keep to this)


# -- chunk plumbing -------------------------------------------------------------------------
def _slice(c: Chunk, i: int, j: int) -> Chunk:
    e = None if c._energy is None else c._energy[i:j]
    return Chunk(c.start + i, c.t[i:j], c.x[i:j], c.v[i:j], c.dissipated[i:j], c.system, e,
                 None if c.external is None else c.external[i:j])


def aligned(*runs: Iterable[Chunk]) -> Iterator[tuple[Chunk, ...]]:
    """Tuples of chunks covering the same samples, from chunk sequences with any boundaries.
    Stops at the end of the shortest run.

    Parameters
    ----------
    *runs : iterable of Chunk
        Chunk sequences on one sample grid, each starting at the same sample.

    Yields
    ------
    tuple of Chunk
        One chunk of each run, all covering the same samples.

    Raises
    ------
    ValueError
        Chunks that do not start at the same sample.
    """
    its = [iter(r) for r in runs]
    cur = [None] * len(its)
    off = [0] * len(its)
    while True:
        for k, it in enumerate(its):
            while cur[k] is None or off[k] >= len(cur[k]):
                cur[k] = next(it, None)
                off[k] = 0
                if cur[k] is None:
                    return
        starts = {cur[k].start + off[k] for k in range(len(its))}
        if len(starts) != 1:
            raise ValueError(f"runs are not aligned: chunks start at samples {sorted(starts)}")
        size = min(len(cur[k]) - off[k] for k in range(len(its)))
        yield tuple(_slice(cur[k], off[k], off[k] + size) for k in range(len(its)))
        for k in range(len(its)):
            off[k] += size


def energy_norm_matrix(system: GapSystem) -> np.ndarray:
    """K_n of the state norm x^T K_n x + v^T M v: K if positive definite, else the closed-gap
    stiffness, else omega_max^2 M.

    Parameters
    ----------
    system : GapSystem
        The system.

    Returns
    -------
    (n, n) ndarray of float
        N/m.
    """
    for K in (system.K, system.closed_stiffness()):
        if np.all(np.linalg.eigvalsh(0.5 * (K + K.T)) > 0):
            return K
    return system.omega_max() ** 2 * system.M


def state_norm(Kn: np.ndarray, M: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """sqrt(x^T K_n x + v^T M v) for x, v of shape (..., n).

    Parameters
    ----------
    Kn : (n, n) ndarray of float
        N/m, from :func:`energy_norm_matrix`.
    M : (n, n) ndarray of float
        kg.
    x : (..., n) ndarray of float
        m.
    v : (..., n) ndarray of float
        m/s.

    Returns
    -------
    ndarray of float
        sqrt(J), the root of twice the linear energy of the state, shape (...).
    """
    q = np.einsum("...i,ij,...j->...", x, Kn, x) + np.einsum("...i,ij,...j->...", v, M, v)
    return np.sqrt(np.maximum(q, 0.0))


# -- Lyapunov exponent -----------------------------------------------------------------------
@dataclass
class LineFit:
    """Running least squares of y = a + b t (sums only: memory independent of the samples).

    Attributes
    ----------
    n : int
        Points added.
    st, sy, stt, sty, syy : float
        Sums of t, y, t^2, t y and y^2, with t measured from ``t_first``.
    t_first, t_last : float
        First and last t added (nan before any).
    """

    n: int = 0
    st: float = 0.0
    sy: float = 0.0
    stt: float = 0.0
    sty: float = 0.0
    syy: float = 0.0
    t_first: float = math.nan
    t_last: float = math.nan

    def add(self, t: np.ndarray, y: np.ndarray) -> None:
        if t.size == 0:
            return
        if self.n == 0:
            self.t_first = float(t[0])
        self.t_last = float(t[-1])
        # centre on t_first so that the sums do not lose digits over long runs
        tc = t - self.t_first
        self.n += t.size
        self.st += float(np.sum(tc))
        self.sy += float(np.sum(y))
        self.stt += float(np.sum(tc * tc))
        self.sty += float(np.sum(tc * y))
        self.syy += float(np.sum(y * y))

    @property
    def slope(self) -> float:
        d = self.n * self.stt - self.st**2
        return (self.n * self.sty - self.st * self.sy) / d if self.n >= 2 and d > 0 else math.nan

    @property
    def residual(self) -> float:
        """rms of y about the line."""
        if self.n < 3:
            return math.nan
        b = self.slope
        a = (self.sy - b * self.st) / self.n
        ss = self.syy - 2 * a * self.sy - 2 * b * self.sty + self.n * a * a + 2 * a * b * self.st + b * b * self.stt
        return math.sqrt(max(ss, 0.0) / self.n)


def separation_exponent(t: np.ndarray, D: np.ndarray) -> float:
    """1/s, the least-squares slope of ln D(t) over the samples with D > 0 (NaN if fewer than 2).

    Parameters
    ----------
    t : (k,) array_like of float
        s, times.
    D : (k,) array_like of float
        The separation at each time (>= 0; zeros are left out).

    Returns
    -------
    float
        1/s.

    Raises
    ------
    InvalidArgument
        t not a finite 1-D series, or D not of its shape.
    """
    t = _check.series("t", t)
    D = np.asarray(D, dtype=float)
    if D.shape != t.shape:
        raise _check.InvalidArgument(f"D must have one value per time in t ({t.size}), got shape {D.shape}")
    fit = LineFit()
    keep = D > 0
    fit.add(t[keep], np.log(D[keep]))
    return fit.slope


ONSET_FACTOR = 100.0  # the separation has started to grow once its window maximum exceeds this x its first


@dataclass(frozen=True)
class LyapunovEstimate:
    """The largest Lyapunov exponent of a motion from the divergence of two runs (module docstring).

    Attributes
    ----------
    exponent_per_s : float
        1/s, lambda: slope of ln D over the growth phase.
    delta : float
        Initial separation, relative to the state's norm.
    saturation : float
        The separation saturates where D exceeds this fraction of the state's norm.
    window_s : float
        s, windows over which D is maximised.
    onset_s : float
        s, start of the growth phase (inf: D never grew ``ONSET_FACTOR`` x; fitted over the run).
    saturation_s : float
        s, when the separation saturated (inf: not within the run).
    fit_start_s, fit_end_s : float
        s, first and last window centres fitted.
    ln_growth : float
        ln D at the end of the fit less ln D at its start: the e-foldings fitted.
    residual : float
        rms of ln D about the fitted line.
    n_windows : int
        Windows fitted.
    """

    exponent_per_s: float  # 1/s, lambda: slope of ln D over the growth phase
    delta: float  # initial separation, relative to the state's norm
    saturation: float  # the separation saturates where D exceeds this fraction of the state's norm
    window_s: float  # s, windows over which D is maximized
    onset_s: float  # s, start of the growth phase (inf: D never grew ONSET_FACTOR x; fitted over the run)
    saturation_s: float  # s, when the separation saturated (inf: not within the run)
    fit_start_s: float  # s, first and last window centres fitted
    fit_end_s: float
    ln_growth: float  # ln D at the end of the fit over ln D at its start: e-foldings fitted
    residual: float  # rms of ln D about the fitted line
    n_windows: int  # windows fitted

    @property
    def lyapunov_time_s(self) -> float:
        """s, 1 / lambda (inf when lambda <= 0: nearby motions do not separate)."""
        return 1.0 / self.exponent_per_s if self.exponent_per_s > 0 else math.inf

    @property
    def chaotic(self) -> bool:
        """Nearby motions separate exponentially: growth set in, lambda > 0, and D grew by more
        than ONSET_FACTOR within the run."""
        return bool(math.isfinite(self.onset_s) and self.exponent_per_s > 0)


class LyapunovAccumulator:
    """Feed aligned chunks of the reference run and the displaced one; ``feed`` returns False
    once the separation has saturated (the runs may then be stopped); ``result()`` fits.

    Parameters
    ----------
    system : GapSystem
        The system run (its norm matrix :func:`energy_norm_matrix` and M).
    n_samples : int
        Samples of each run.
    sample_rate_hz : float
        Hz.
    delta : float
        Initial separation, relative (recorded in the result).
    saturation : float
        Fraction of the state's norm at which the separation saturates.
    window_s : float
        s, windows over which D is maximised (lengthened to at most ``MAX_WINDOWS`` windows and to
        a whole number of samples).

    Attributes
    ----------
    window_s : float
        s, the window used.
    Dmax : ndarray of float
        Largest D in each window so far.
    n_seen : int
        Samples fed before saturation.
    saturation_s : float
        s, when D first exceeded ``saturation`` |y_a| (inf until then).
    """

    def __init__(self, system: GapSystem, n_samples: int, sample_rate_hz: float, delta: float, saturation: float,
                 window_s: float) -> None:
        self.Kn = energy_norm_matrix(system)
        self.M = system.M
        self.fs = sample_rate_hz
        self.delta = delta
        self.saturation = saturation
        duration = (n_samples - 1) / sample_rate_hz
        self.window_s = max(window_s, duration / MAX_WINDOWS, 1.0 / sample_rate_hz)
        self.per = max(1, int(round(self.window_s * sample_rate_hz)))
        self.window_s = self.per / sample_rate_hz
        self.Dmax = np.zeros(-(-n_samples // self.per))
        self.n_seen = 0  # samples fed before saturation
        self.saturation_s = math.inf

    def feed(self, a: Chunk, b: Chunk) -> bool:
        if math.isfinite(self.saturation_s):
            return False
        D = state_norm(self.Kn, self.M, b.x - a.x, b.v - a.v)
        S = state_norm(self.Kn, self.M, a.x, a.v)
        over = np.flatnonzero(D > self.saturation * S)
        k = int(over[0]) if over.size else D.size
        if k:
            b, m = binned(np.maximum, D[:k], a.start, self.per)
            self.Dmax[b : b + m.size] = np.maximum(self.Dmax[b : b + m.size], m)
            self.n_seen = a.start + k
        if over.size:
            self.saturation_s = float(a.t[k])
        return not math.isfinite(self.saturation_s)

    def result(self) -> LyapunovEstimate:
        n_full = self.n_seen // self.per  # whole windows before saturation (or the end)
        if math.isinf(self.saturation_s) and self.n_seen % self.per:
            n_full += 1  # the run's last, shorter window
        L = np.log(self.Dmax[:n_full], out=np.full(n_full, -np.inf), where=self.Dmax[:n_full] > 0)
        tc = (np.arange(n_full) + 0.5) * self.window_s
        onset = math.inf
        first = 0
        if n_full and np.isfinite(L[0]):
            grown = np.flatnonzero(L > L[0] + math.log(ONSET_FACTOR))
            if grown.size:
                first = int(grown[0])
                onset = float(first * self.window_s)
                first = max(first - 1, 0)  # the window before the onset starts the growth
        sel = np.arange(first, n_full)
        sel = sel[np.isfinite(L[sel])]
        fit = LineFit()
        fit.add(tc[sel], L[sel])
        return LyapunovEstimate(
            exponent_per_s=fit.slope, delta=self.delta, saturation=self.saturation, window_s=self.window_s,
            onset_s=onset, saturation_s=self.saturation_s,
            fit_start_s=float(tc[sel[0]]) if sel.size else math.nan,
            fit_end_s=float(tc[sel[-1]]) if sel.size else math.nan,
            ln_growth=float(L[sel[-1]] - L[sel[0]]) if sel.size else math.nan, residual=fit.residual,
            n_windows=int(sel.size),
        )


def displaced_state(system: GapSystem, x0: np.ndarray, v0: np.ndarray, delta: float, seed: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(x0 + dx, v0 + dv) with (dx, dv) in a random direction (``seed``) of energy norm
    delta |(x0, v0)|.

    Parameters
    ----------
    system : GapSystem
        The system (its energy norm).
    x0 : (n,) ndarray of float
        m, the reference displacement.
    v0 : (n,) ndarray of float
        m/s, the reference velocity.
    delta : float
        Size of the displacement relative to |(x0, v0)|.
    seed : int
        Seed of the random direction.

    Returns
    -------
    x, v : (n,) ndarray of float
        m and m/s.

    Raises
    ------
    InvalidArgument
        A state at rest.
    """
    Kn = energy_norm_matrix(system)
    rng = np.random.default_rng(seed)
    n = system.n
    d = rng.standard_normal(2 * n)
    size = float(state_norm(Kn, system.M, x0, v0))
    if not size > 0:
        raise _check.InvalidArgument("x0, v0: the state is at rest (zero norm); a separation needs a motion")
    d *= delta * size / float(state_norm(Kn, system.M, d[:n], d[n:]))
    return x0 + d[:n], v0 + d[n:]


def largest_lyapunov(system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, method: str = "exact",
                     *, delta: float = 1e-9, saturation: float = 1e-3, window_s: float = 0.01, seed: int = 0,
                     chunk_samples: int | None = None, **options) -> LyapunovEstimate:
    """Largest Lyapunov exponent of the motion from (x0, v0) by two runs ``delta`` apart (module docstring).

    Parameters
    ----------
    system : the gap system
    x0, v0 : (n,) m and m/s, the reference state; the other run starts ``delta`` from it
    duration_s : s, longest time followed (the runs stop once the separation saturates)
    sample_rate_hz : Hz, samples of the separation
    method, options : integrator (:func:`~reduced.transient.integrate.ringdown_stream`)
    delta : initial separation relative to the state's norm, in (0, saturation)
    saturation : in (0, 1): the fit ends where the separation exceeds this fraction of the state
    window_s : s, the separation is maximized over windows this long (a few periods of the motion)
    seed : direction of the displacement
    chunk_samples : samples per chunk of the two streams (default: the integrator's)

    Returns
    -------
    LyapunovEstimate
    """
    from reduced.transient.integrate import ringdown_stream

    _check.gap_system(system)
    saturation = _check.number("saturation", saturation, lo=0.0, hi=1.0)
    delta = _check.number("delta", delta, lo=0.0, hi=saturation)
    window_s = _check.positive("window_s", window_s, "s")
    seed = _check.integer("seed", seed, lo=0)
    x0 = _check.vector("x0", x0, system.n)
    v0 = _check.vector("v0", v0, system.n)
    xb, vb = displaced_state(system, x0, v0, delta, seed)
    a = ringdown_stream(system, x0, v0, duration_s, sample_rate_hz, method, chunk_samples=chunk_samples, **options)
    b = ringdown_stream(system, xb, vb, duration_s, sample_rate_hz, method, chunk_samples=chunk_samples, **options)
    acc = LyapunovAccumulator(system, a.n_samples, sample_rate_hz, delta, saturation, window_s)
    try:
        for ca, cb in aligned(a, b):
            if not acc.feed(ca, cb):
                break
    finally:
        a.close()
        b.close()
    return acc.result()


# -- comparison of two runs -------------------------------------------------------------------
def stop_closures(system: GapSystem, x: np.ndarray, closed_before: np.ndarray | None) -> tuple[int, np.ndarray]:
    """(number of open -> closed transitions of the stops over samples x (k, n), the closed state
    of the last sample); ``closed_before`` is the state of the sample before x (None: the first).

    Parameters
    ----------
    system : GapSystem
        The stops.
    x : (k, n) ndarray of float
        m, consecutive samples.
    closed_before : (m,) ndarray of bool or None
        Closed stops at the sample before x (None: x starts the run, its first sample counts no
        closure).

    Returns
    -------
    count : int
        Open -> closed transitions within x (and from ``closed_before`` to x[0]).
    closed : (m,) ndarray of bool
        Closed stops at the last sample (``closed_before`` if x is empty).
    """
    closed = system.penetration(x) > 0.0
    if closed.shape[0] == 0:
        return 0, closed_before
    prev = np.vstack([closed[:1] if closed_before is None else closed_before[None, :], closed[:-1]])
    return int(np.count_nonzero(closed & ~prev)), closed[-1]


@dataclass
class RunComparison:
    """A run against a reference: what stays comparable when the motion is chaotic (module docstring).

    Attributes
    ----------
    windows_s : tuple of float
        s, ends of the pointwise-error windows [0, window].
    pointwise_error : tuple of float
        max |p - p_ref| / max |p_ref| at the points over each window.
    energy_window_s : float
        s, length of the energy-envelope windows.
    energy_t : (w,) ndarray of float
        s, window centres.
    energy_run, energy_ref : (w,) ndarray of float
        J, mean energy of the run and of the reference in each window.
    closures_run, closures_ref : int
        Stop closures (impacts) counted from the samples.
    freq_t : (f,) ndarray of float
        s, spectrogram frame centres.
    freq_run, freq_ref : (f,) ndarray of float
        Hz, dominant frequency of each frame.
    freq_resolution_hz : float
        Hz, one frequency bin (nan without a spectrogram).
    window_err, window_ref : (w,) ndarray of float
        m, max |p - p_ref| and max |p_ref| in each energy window.
    """

    windows_s: tuple[float, ...]  # ends of the pointwise-error windows
    pointwise_error: tuple[float, ...]  # max |p - p_ref| / max |p_ref| at the points, over [0, window]
    energy_window_s: float  # s, length of the energy-envelope windows
    energy_t: np.ndarray  # s, window centres
    energy_run: np.ndarray  # J, mean energy of the run in each window
    energy_ref: np.ndarray  # J, of the reference
    closures_run: int  # stop closures (impacts) counted from the samples
    closures_ref: int
    freq_t: np.ndarray  # s, spectrogram frame centres
    freq_run: np.ndarray  # Hz, dominant frequency of each frame
    freq_ref: np.ndarray
    freq_resolution_hz: float  # Hz, one frequency bin
    window_err: np.ndarray = field(repr=False, default=None)  # max |p - p_ref| in each energy window
    window_ref: np.ndarray = field(repr=False, default=None)  # max |p_ref| in each energy window

    def pointwise_error_until(self, t_s: float) -> float:
        """max |p - p_ref| / max |p_ref| over the energy windows that end by ``t_s``."""
        k = int(math.floor(t_s / self.energy_window_s * (1 + 1e-12)))
        if k <= 0:
            return math.nan
        ref = float(np.max(self.window_ref[:k]))
        return float(np.max(self.window_err[:k])) / ref if ref > 0 else math.nan

    @property
    def energy_envelope_error(self) -> float:
        """max over windows of |E_run - E_ref| / E_ref (window means)."""
        ok = self.energy_ref > 0
        return float(np.max(np.abs(self.energy_run[ok] - self.energy_ref[ok]) / self.energy_ref[ok],
                            initial=0.0))

    @property
    def freq_agreement(self) -> float:
        """Fraction of spectrogram frames whose dominant frequencies agree within one bin."""
        if self.freq_t.size == 0:
            return math.nan
        return float(np.mean(np.abs(self.freq_run - self.freq_ref) <= 1.01 * self.freq_resolution_hz))

    @property
    def freq_median_diff_hz(self) -> float:
        """Hz, median |f_run - f_ref| of the dominant frequencies over frames."""
        return float(np.median(np.abs(self.freq_run - self.freq_ref))) if self.freq_t.size else math.nan

    @property
    def closures_diff(self) -> float:
        """(closures_run - closures_ref) / closures_ref."""
        return (self.closures_run - self.closures_ref) / self.closures_ref if self.closures_ref else math.nan


@dataclass
class ComparisonAccumulator:
    """Feed aligned chunks of a run and its reference; ``result()`` gives the RunComparison.

    ``points`` (k, n): rows giving the compared point displacements from the DOFs;
    ``freq_point``: which row's spectrogram is compared (window ``window_s``, ``overlap``).

    Parameters
    ----------
    system : GapSystem
        The system run (stops, for the closures).
    n_samples : int
        Samples of each run.
    sample_rate_hz : float
        Hz.
    points : (k, n) ndarray of float
        Rows giving the compared point displacements from the DOFs.
    windows_s : tuple of float
        s, ends of the pointwise-error windows.
    energy_window_s : float
        s, energy-envelope window (lengthened to at most ``MAX_WINDOWS`` windows).
    freq_point : int
        Row of ``points`` whose spectrogram is compared.
    window_s : float
        s, spectrogram window.
    overlap : float
        Spectrogram overlap, in [0, 1).
    fmin_hz : float
        Hz, lowest frequency a dominant frequency may have.
    """

    system: GapSystem
    n_samples: int
    sample_rate_hz: float
    points: np.ndarray
    windows_s: tuple[float, ...]
    energy_window_s: float
    freq_point: int = 0
    window_s: float = 0.05
    overlap: float = 0.9
    fmin_hz: float = 0.0
    _state: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        fs = self.sample_rate_hz
        duration = (self.n_samples - 1) / fs
        self.energy_window_s = max(self.energy_window_s, duration / MAX_WINDOWS, 1.0 / fs)
        self._per_window = max(1, int(round(self.energy_window_s * fs)))
        self.energy_window_s = self._per_window / fs
        n_win = -(-self.n_samples // self._per_window)
        self._Esum = np.zeros((2, n_win))
        self._Ecount = np.zeros(n_win)
        self._werr = np.zeros(n_win)
        self._wref = np.zeros(n_win)
        self._err = np.zeros(len(self.windows_s))
        self._ref = np.zeros(len(self.windows_s))
        self._ends = [int(math.floor(w * fs * (1 + 1e-12))) + 1 for w in self.windows_s]
        self._closures = [0, 0]
        self._closed = [None, None]
        self._stft = None
        if self.n_samples >= max(8, round(self.window_s * fs)):
            self._stft = [StftAccumulator(self.n_samples, fs, self.window_s, self.overlap) for _ in range(2)]

    def feed(self, run: Chunk, ref: Chunk) -> None:
        p, pr = run.x @ self.points.T, ref.x @ self.points.T
        i0 = run.start
        for w, end in enumerate(self._ends):
            k = min(max(end - i0, 0), len(run))
            if k:
                self._err[w] = max(self._err[w], float(np.max(np.abs(p[:k] - pr[:k]))))
                self._ref[w] = max(self._ref[w], float(np.max(np.abs(pr[:k]))))
        if len(run) == 0:
            return
        per = self._per_window
        b, m = binned(np.maximum, np.max(np.abs(p - pr), axis=1), i0, per)
        sl = slice(b, b + m.size)
        self._werr[sl] = np.maximum(self._werr[sl], m)
        self._wref[sl] = np.maximum(self._wref[sl], binned(np.maximum, np.max(np.abs(pr), axis=1), i0, per)[1])
        self._Ecount[sl] += binned(np.add, np.ones(len(run)), i0, per)[1]
        for r, c in enumerate((run, ref)):
            self._Esum[r, sl] += binned(np.add, c.energy, i0, per)[1]
            n, self._closed[r] = stop_closures(self.system, c.x, self._closed[r])
            self._closures[r] += n
            if self._stft is not None:
                self._stft[r].feed(i0, (p if r == 0 else pr)[:, self.freq_point])

    def result(self) -> RunComparison:
        with np.errstate(invalid="ignore", divide="ignore"):
            err = tuple(float(e / r) if r > 0 else math.nan for e, r in zip(self._err, self._ref, strict=True))
            E = self._Esum / np.maximum(self._Ecount, 1.0)
        centres = (np.arange(self._Ecount.size) + 0.5) * self._per_window / self.sample_rate_hz
        if self._stft is not None:
            s_run, s_ref = (a.result() for a in self._stft)
            f_run, f_ref = s_run.dominant_freq_hz(self.fmin_hz), s_ref.dominant_freq_hz(self.fmin_hz)
            t_f, res = s_run.t, float(s_run.freq_hz[1] - s_run.freq_hz[0])
        else:
            t_f = f_run = f_ref = np.empty(0)
            res = math.nan
        return RunComparison(
            windows_s=self.windows_s, pointwise_error=err, energy_window_s=self.energy_window_s,
            energy_t=centres, energy_run=E[0], energy_ref=E[1], closures_run=self._closures[0],
            closures_ref=self._closures[1], freq_t=t_f, freq_run=f_run, freq_ref=f_ref, freq_resolution_hz=res,
            window_err=self._werr, window_ref=self._wref,
        )


def compare_runs(system: GapSystem, run: Iterable[Chunk], ref: Iterable[Chunk], n_samples: int,
                 sample_rate_hz: float, points: np.ndarray, *, windows_s: tuple[float, ...] = (0.05,),
                 energy_window_s: float = 0.05, freq_point: int = 0, window_s: float = 0.05, overlap: float = 0.9,
                 fmin_hz: float = 0.0) -> RunComparison:
    """``run`` against ``ref`` (chunk sequences of the same grid, e.g. ``res.chunks()``, a
    :class:`RingdownFile` or a stream), in one pass: see :class:`RunComparison`.

    Parameters
    ----------
    system : GapSystem
        The system both runs integrate.
    run, ref : iterable of Chunk
        The run and its reference, on the same sample grid.
    n_samples : int
        Samples of each run.
    sample_rate_hz : float
        Hz.
    points : (k, n) array_like of float
        Rows giving the compared points from the DOFs.
    windows_s : tuple of float
        s, ends of the pointwise-error windows, > 0.
    energy_window_s : float
        s, > 0.
    freq_point : int
        Row of ``points`` whose spectrogram is compared.
    window_s, overlap : float
        s and fraction, the spectrogram's window and overlap.
    fmin_hz : float
        Hz, lowest dominant frequency.

    Returns
    -------
    RunComparison

    Raises
    ------
    InvalidArgument
        A system, count, rate, window or point row out of range.
    """
    _check.gap_system(system)
    n_samples = _check.integer("n_samples", n_samples)
    sample_rate_hz = _check.positive("sample_rate_hz", sample_rate_hz, "Hz")
    points = np.atleast_2d(np.asarray(points, dtype=float))
    if points.shape[1] != system.n:
        raise _check.InvalidArgument(f"points must have {system.n} columns (one per DOF), got shape {points.shape}")
    for w in windows_s:
        _check.positive("windows_s", w, "s")
    energy_window_s = _check.positive("energy_window_s", energy_window_s, "s")
    freq_point = _check.integer("freq_point", freq_point, lo=0, hi=points.shape[0] - 1)
    acc = ComparisonAccumulator(system, n_samples, sample_rate_hz, points, tuple(windows_s), energy_window_s,
                                freq_point, window_s, overlap, fmin_hz)
    for a, b in aligned(run, ref):
        acc.feed(a, b)
    return acc.result()


def binned(op, values: np.ndarray, start: int, per: int) -> tuple[int, np.ndarray]:
    """(first bin, op.reduceat of ``values`` (k, ...) over the bins of ``per`` samples): samples
    start .. start + k - 1 fall in bins start // per ...; the first and last may be partial.

    Parameters
    ----------
    op : numpy ufunc
        The reduction (``np.add``, ``np.maximum``).
    values : (k, ...) ndarray
        Consecutive samples ``start`` .. ``start + k - 1``.
    start : int
        Index of the first sample.
    per : int
        Samples per bin.

    Returns
    -------
    first : int
        Index of the first bin touched.
    reduced : ndarray
        One reduction per bin touched.
    """
    k = values.shape[0]
    first = start // per
    edges = np.arange((first + 1) * per, start + k, per) - start
    return first, op.reduceat(values, np.concatenate([[0], edges]), axis=0)
