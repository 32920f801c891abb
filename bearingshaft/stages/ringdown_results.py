"""What the ringdown stage computes (:mod:`bearingshaft.stages.ringdown`) and writes
(:mod:`bearingshaft.stages.ringdown_files`): its result objects, and the accumulator of a
symmetric pair's asymmetry that the symmetry study fills while runs stream by."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bearingshaft.envelopes import Envelope
from bearingshaft.scenes import Scene
from reduced.models.gaps import GapSystem
from reduced.models.loads import Loads
from reduced.transient.compare import MAX_WINDOWS, LineFit, binned
from reduced.transient.spectrogram import Spectrogram
from reduced.transient.store import RingdownFile

COMPARE_WINDOW_S = 0.01  # s, windows of the separation, pointwise maxima and energy means
REFERENCE_WINDOW_S = 0.05  # s, pointwise comparison window at the start of the run
LYAPUNOV_DELTA = 1e-9  # relative size of the displacement of the exact runs compared with the exact one (energy norm)
SYMMETRY_SEEDS = 5  # seeded runs of the symmetry study
# m, size of their antisymmetric perturbation. Measured on discrete-symmetric: seeds of 1e-12 and
# 1e-10 m still moved the break by up to 0.48 and 0.07 s when only the exact integrator's restart
# grid changed (the round-off it injects at ~1e4 contact events competes with them); from 1e-8 m
# the break time did not move (and rom-symmetric's from 1e-9 m).
SYMMETRY_PERTURBATION_M = 1e-8
BREAK_THRESHOLD_M = 1e-6  # m, the symmetry is broken once |x_a - x_b| exceeds this ("visibly")
GROWTH_BAND = 1e-2  # growth rates are fitted where BREAK_THRESHOLD_M x GROWTH_BAND < |x_a - x_b| < threshold


class Asymmetry:
    """|x_a - x_b| of one run, chunk by chunk: envelope, first exceedances, growth fit in a band.

    Parameters
    ----------
    n_samples, fs : the run's samples and their rate [Hz]
    threshold : m, the run has broken once |x_a - x_b| exceeds it (``t_break``, s)
    band : m, (low, high): the growth rate is fitted where the windows' maxima lie inside it
    """

    def __init__(self, n_samples: int, fs: float, threshold: float, band: tuple[float, float]) -> None:
        self.env = Envelope(n_samples, fs, 1)
        self.threshold = threshold
        self.band = band
        self.t_break = None
        self.k_break = n_samples  # samples before the break
        duration = (n_samples - 1) / fs
        self.per = max(1, int(round(max(COMPARE_WINDOW_S, duration / MAX_WINDOWS) * fs)))  # growth-fit windows
        self.fs = fs
        self.wmax = np.zeros(-(-n_samples // self.per))  # max d in each window, up to the break

    def feed(self, start: int, t: np.ndarray, d: np.ndarray) -> bool:
        """Returns True once the threshold has been crossed."""
        self.env.add(start, d)
        if self.t_break is None:
            over = np.flatnonzero(d > self.threshold)
            k = int(over[0]) if over.size else d.size
            if k:
                b, m = binned(np.maximum, d[:k], start, self.per)
                self.wmax[b : b + m.size] = np.maximum(self.wmax[b : b + m.size], m)
            if over.size:
                self.t_break = float(t[k])
                self.k_break = start + k
        return self.t_break is not None

    @property
    def growth_rate(self) -> float:
        """1/s, slope of ln (window max of d) over the whole windows inside the band before the break."""
        m = self.wmax[: self.k_break // self.per]
        w = np.flatnonzero((m > self.band[0]) & (m < self.band[1]))
        fit = LineFit()
        fit.add((w + 0.5) * self.per / self.fs, np.log(m[w]))
        return fit.slope if fit.n >= 3 else math.nan


@dataclass(frozen=True, eq=False)
class ReferenceComparison:
    """The run against the exact integrator (:func:`bearingshaft.stages.ringdown.compare_with_exact`).

    ``run`` and each of ``seeds`` are :class:`reduced.transient.compare.RunComparison` results (the run,
    and each displaced exact run, against the exact run); ``lyapunov`` the
    :class:`reduced.transient.compare.LyapunovEstimate` of each displaced pair; the exact run's
    statistics and tolerance.

    Attributes
    ----------
    run : RunComparison
        The run against the exact run.
    seeds : list of RunComparison
        Each displaced exact run against the exact run.
    lyapunov : list of LyapunovEstimate
        Of each displaced pair.
    exact_stats : dict
        The exact run's statistics.
    exact_tolerance : float
        m, the exact run's tolerance.
    """

    run: object
    seeds: list
    lyapunov: list
    exact_stats: dict
    exact_tolerance: float


@dataclass(frozen=True, eq=False)
class SpectrogramData:
    """The spectrogram of one point's displacement, with what is drawn over it.

    Attributes
    ----------
    point : int
        Index of the point (``scene.model.point_names``).
    spectrogram : Spectrogram
        Of its displacement (m^2/Hz).
    f_open_hz : ndarray of float
        Hz, the open-gap frequencies of the lowest modes that move the gaps.
    curves : dict
        Label -> (E [J], f [Hz]): the NNM frequency-energy curves overlaid.
    """

    point: int  # index of the point (scene.model.point_names)
    spectrogram: Spectrogram
    f_open_hz: np.ndarray  # Hz, the open-gap frequencies of the lowest modes that move the gaps
    curves: dict  # label -> (E [J], f [Hz]): the NNM frequency-energy curves overlaid


@dataclass(frozen=True, eq=False)
class SymmetryData:
    """The symmetry study (:func:`bearingshaft.stages.ringdown.symmetry_runs`).

    Attributes
    ----------
    pair : (str, str)
        The two points.
    primary : str
        The stage's method: its run is the one drawn.
    points : Envelope
        The pair's two points over the primary run, m.
    runs : dict
        Method -> (Asymmetry, tolerance [m]) of the round-off runs.
    t_tol : dict
        Method -> s, when |x_a - x_b| first exceeds the method's tolerance (None: never).
    wall_s : dict
        Method -> s, wall time of the runs of the other methods.
    seeded : list of Asymmetry
        Each seeded exact run.
    thetas : list of float
        rad, the phase of each seed's perturbation.
    restarted_t_break : float or None
        s, break time of seed 0 again on another restart grid.
    """

    pair: tuple[str, str]
    primary: str  # the stage's method: its run is the one drawn
    points: Envelope  # the pair's two points over the primary run
    runs: dict  # method -> (Asymmetry, tolerance [m]) of the round-off runs
    t_tol: dict  # method -> s, when |x_a - x_b| first exceeds the method's tolerance (None: never)
    wall_s: dict  # method -> s, wall time of the runs of the other methods
    seeded: list  # Asymmetry of each seeded exact run
    thetas: list  # rad, the phase of each seed's perturbation
    restarted_t_break: float | None  # s, seed 0 again on another restart grid


LATE_FRACTION = 1 / 8  # a stop still closing in the last eighth of the run: the gaps may not stay open


@dataclass(frozen=True, eq=False)
class RunSummary:
    """The run in engineering numbers, as the hammer stage gives them (``ringdown.run_summary``).

    Counted on the samples: an impact is a stop found closed at a sample after an open one (or at
    the first sample), so a contact shorter than a sample interval can be missed, and peaks are
    sampled peaks (at most the true ones).

    Attributes
    ----------
    stop_names : tuple of str
        The stops (two per tip: ``x1+`` above, ``x1-`` below).
    impacts : tuple of int
        Impacts at each stop.
    peak_stop_force_N : tuple of float
        N, the largest sampled force in each stop.
    last_contact_s : tuple of float
        s, the last sample at which each stop is closed (NaN: never).
    point_names : tuple of str
        The points (x1, x2, x3).
    peak_displacement_m : tuple of float
        m, the largest |displacement| of each point.
    peak_acceleration_m_s2 : tuple of float
        m/s^2, the largest |acceleration| of each point (from ``ringdown.npz``'s ``a``).
    duration_s : float
        s, the run.
    """

    stop_names: tuple[str, ...]
    impacts: tuple[int, ...]
    peak_stop_force_N: tuple[float, ...]
    last_contact_s: tuple[float, ...]
    point_names: tuple[str, ...]
    peak_displacement_m: tuple[float, ...]
    peak_acceleration_m_s2: tuple[float, ...]
    duration_s: float

    @property
    def impacts_total(self) -> int:
        return int(sum(self.impacts))

    @property
    def peak_tip_force_N(self) -> float:
        """N, the largest sampled force in any stop (0 if none closes)."""
        return float(max(self.peak_stop_force_N, default=0.0))

    @property
    def gaps_open_after_s(self) -> float:
        """s, the last sample at which any stop is closed: the gaps stay open after it (0: never closed)."""
        last = [t for t in self.last_contact_s if not math.isnan(t)]
        return float(max(last)) if last else 0.0

    @property
    def still_closing(self) -> bool:
        """A stop closes in the last ``LATE_FRACTION`` of the run: the gaps may close again after it."""
        return self.gaps_open_after_s > (1.0 - LATE_FRACTION) * self.duration_s

    def stats(self) -> dict:
        """The numbers for ``provenance.json``: per stop and per point, and the totals."""
        return {"impacts_total": self.impacts_total, "peak_tip_force_N": self.peak_tip_force_N,
                "gaps_open_after_s": self.gaps_open_after_s, "still_closing_at_end": self.still_closing,
                "impacts": dict(zip(self.stop_names, self.impacts, strict=True)),
                "peak_stop_force_N": dict(zip(self.stop_names, self.peak_stop_force_N, strict=True)),
                "peak_displacement_m": dict(zip(self.point_names, self.peak_displacement_m, strict=True)),
                "peak_acceleration_m_s2": dict(zip(self.point_names, self.peak_acceleration_m_s2, strict=True))}


@dataclass(frozen=True, eq=False)
class RingdownOutcome:
    """What the ringdown stage computed: the run streamed into ``ringdown.npz`` and its analyses.

    Attributes
    ----------
    scene : Scene
        The scene.
    method : str
        The integrator.
    system : GapSystem
        The model run.
    P : (points, n) ndarray of float
        The points' displacements from the DOFs.
    run : RingdownFile
        The run, read lazily from ringdown.npz.
    loads : Loads or None
        The scene's loads.
    reference : ReferenceComparison or None
        For a reduced model not run by the exact method.
    spectrogram : SpectrogramData or None
        With [spectrogram].
    symmetry : SymmetryData or None
        With [symmetry].
    summary : RunSummary or None
        The run in engineering numbers.
    """

    scene: Scene
    method: str
    system: GapSystem
    P: np.ndarray  # (points, n): the points' displacements from the DOFs
    run: RingdownFile
    loads: Loads | None
    reference: ReferenceComparison | None  # a reduced model not run by the exact method
    spectrogram: SpectrogramData | None  # [spectrogram]
    symmetry: SymmetryData | None  # [symmetry]
    summary: RunSummary | None = None  # impacts, peak tip forces, peak displacements and accelerations
