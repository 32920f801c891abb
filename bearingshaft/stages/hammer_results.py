"""What the hammer stage computes (:mod:`bearingshaft.stages.hammer`), as the writers read it
(:mod:`bearingshaft.stages.hammer_files`): one record, the virtual test with its level sweep and
linear check, the comparison with a measured test.

Data only: nothing here integrates, draws or writes, so the computing modules and the writers
both import it (neither imports the other's module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bearingshaft.correlate import ChannelPair
from bearingshaft.measured import Horizon
from bearingshaft.measures import MeasureSet
from bearingshaft.scenes import Scene
from fem.uff import TimeHistory
from reduced.models.rig import VirtualRig


@dataclass(frozen=True, eq=False)
class Record:
    """One virtual test: every channel at the sample times, and what the integrator reported.

    Attributes
    ----------
    level_N : float
        N, the blow's peak.
    t : (N,) ndarray of float
        s, the sample times.
    data : (n_channels, N) ndarray of float
        Every rig channel (m/s^2 or N), in the rig's channel order.
    x, v : (N, n) ndarray of float
        The reduced state (for the modal energy at the end).
    energy : (N,) ndarray of float
        J.
    dissipated : (N,) ndarray of float
        J, work of the damping.
    external : (N,) ndarray of float
        J, work of the hammer.
    stats : dict
        The integrator's statistics.
    balance_error : float
        Relative energy-balance error of the run.
    w : (N, p) ndarray of float or None
        m, the sliders' positions (friction at the tips; None without).
    friction : (N,) ndarray of float or None
        J, the friction work (part of ``dissipated``; None without friction).
    """

    level_N: float  # N, the blow's peak
    t: np.ndarray  # (N,) s
    data: np.ndarray  # (n_channels, N)
    x: np.ndarray  # (N, n) reduced state (for the modal energy at the end)
    v: np.ndarray
    energy: np.ndarray  # (N,) J
    dissipated: np.ndarray  # (N,) J
    external: np.ndarray  # (N,) J, work of the hammer
    stats: dict
    balance_error: float
    w: np.ndarray | None = None  # (N, p) m, the sliders' positions (friction at the tips)
    friction: np.ndarray | None = None  # (N,) J, the friction work (part of dissipated)


@dataclass(frozen=True, eq=False)
class LinearCheck:
    """The open-gap response of the reduced rig against the full 3-D model's (:mod:`.hammer_linear`).

    ``errors`` maps (band, window) to rms(a_rom - a_full) / rms(a_full) per channel, band
    ``"band"`` (both low-passed at ``band_hz``) or ``"raw"``, window ``"50ms"`` (the first
    ``window_s`` after the blow) or ``"record"`` (from the blow to the end).

    Attributes
    ----------
    names : list of str
        The compared channels: accelerometer axes, then the tip load cells.
    errors : dict
        {(band, window): (len(names),) relative RMS error}.
    near_zero : (len(names),) ndarray of bool
        An axis judged against its sensor's largest.
    worst : float
        The worst band-limited error over the window.
    worst_channel : str
        The channel it is on.
    worst_raw : float
        The worst error without the low-pass.
    n_full_modes : int
        Modes of the full model in the reference.
    cond_V : float
        Condition number of the full model's damped modal basis.
    t : (k,) ndarray of float
        s, the figure's window: start_s <= t <= start_s + window_s.
    rom_band : (k,) ndarray of float
        The worst channel of the reduced model, low-passed at band_hz, in that window.
    full_band : (k,) ndarray of float
        The same of the full model.
    band_hz : float
        Hz, the band of the comparisons.
    window_s : float
        s, the window after the blow.
    bound : float
        The issue's bound on the band-limited error (1 %).
    text : str
        The paragraph of hammer.md.
    """

    names: list[str]  # the compared channels: accelerometer axes, then the tip load cells
    errors: dict  # {(band, window): (len(names),) relative RMS error}
    near_zero: np.ndarray  # (len(names),) bool, an axis judged against its sensor's largest
    worst: float  # the worst band-limited error over the window
    worst_channel: str
    worst_raw: float
    n_full_modes: int
    cond_V: float  # condition number of the full model's damped modal basis
    t: np.ndarray  # (k,) s, the figure's window: start_s <= t <= start_s + window_s
    rom_band: np.ndarray  # (k,) the worst channel of the reduced model, low-passed at band_hz, in that window
    full_band: np.ndarray  # (k,) the same of the full model
    band_hz: float  # Hz, the band of the comparisons
    window_s: float  # s, the window after the blow
    bound: float  # the bound on the band-limited error (1 %)
    text: str  # the paragraph of hammer.md


@dataclass(frozen=True, eq=False)
class VirtualTest:
    """The virtual hammer test: the nominal record, the level sweep, backbones and the linear check.

    Attributes
    ----------
    scene : Scene
        The scene.
    rig : VirtualRig
        The reduced apparatus with its channels.
    labels : dict
        {label: (mode index, freq_hz, score)} of the six pseudo-rigid open-gap modes.
    records : dict
        {level_N: Record}, in increasing level.
    summary : dict
        {level_N: :func:`bearingshaft.stages.hammer.level_summary` dict}, the same levels.
    backbones : dict
        {label: (energy_J, freq_hz)} NNM backbones (HB, H = 1).
    linear : LinearCheck or None
        The open-gap check against the full model, when asked for.
    end_share_s : float
        s, the energy "at the end" is the mean over the record's last end_share_s.
    stats : dict
        For provenance.json.
    lines : tuple of str
        The stage's summary lines.
    lyapunov : tuple of LyapunovEstimate
        The nominal record's largest Lyapunov exponent, one estimate per displaced run
        (:func:`bearingshaft.stages.hammer.record_lyapunov`).
    friction : FrictionComparison or None
        With friction at the tips (mu > 0), the nominal blow beside the frictionless one.
    """

    scene: Scene
    rig: VirtualRig
    labels: dict  # {label: (mode index, freq_hz, score)} of the six pseudo-rigid open-gap modes
    records: dict  # {level_N: Record}, in increasing level
    summary: dict  # {level_N: dict of level_summary}, the same levels
    backbones: dict  # {label: (energy_J, freq_hz)} NNM backbones (HB, H = 1)
    linear: LinearCheck | None
    end_share_s: float  # s, the energy "at the end" is the mean over the record's last end_share_s
    stats: dict  # for provenance.json
    lines: tuple[str, ...]  # the stage's summary lines
    lyapunov: tuple = ()  # LyapunovEstimate per displaced run of the nominal blow
    friction: FrictionComparison | None = None  # the nominal blow with friction and without (mu > 0)

    @property
    def nominal(self) -> Record:
        """The record of the nominal blow, ``[hammer] peak_N``."""
        return self.records[self.scene.hammer.peak_N]


@dataclass(frozen=True, eq=False)
class FrictionComparison:
    """The nominal blow with friction at the tips and without it (mu = 0 on the same reduction, the same
    tangential coordinates: only the sliders differ), :func:`bearingshaft.stages.hammer.friction_comparison`.

    Attributes
    ----------
    mu : float
        The scene's Coulomb coefficient.
    k_t : float
        N/m, the sliders' tangential stiffness.
    directions : tuple of str
        Where the faces rub (``axial``, ``lateral``).
    frictionless : Record
        The nominal blow without friction.
    decay : dict
        {label: {"freq_hz", "with": {...}, "without": {...}}} per pseudo-rigid motion, each side's modal energy
        ``peak_J`` (after the blow), ``end_J`` (mean over the last ``end_share_s``), ``t_1pct_s`` (when it falls
        for good below 1 % of its peak; NaN if it does not), ``rate_per_s`` (its energy's decay rate once the gaps
        stay open), ``rate_modal_per_s`` (the closed form 2 zeta_r omega_r) and ``t_1pct_est_s`` (t_1pct_s, or
        extrapolated along rate_per_s past the record's end) (:func:`bearingshaft.stages.hammer.motion_decay`).
    impacts : (int, int)
        Impacts with friction and without.
    friction_work_J : float
        J, the friction work of the record with friction.
    hammer_work_J : float
        J, the hammer's work (the same blow on both).
    spectrum_change : dict
        {band label: (power with, power without)} of the spectrogram's channel, summed over the record after the
        blow, per band (``pseudo-rigid`` below 100 Hz, ``structural`` above).
    gaps_open_after_s : (float, float)
        s, the gaps stay open after this, with friction and without.
    """

    mu: float
    k_t: float
    directions: tuple[str, ...]
    frictionless: Record
    decay: dict  # {label: {"freq_hz", "with": {...}, "without": {...}}}
    impacts: tuple[int, int]  # with friction, without
    friction_work_J: float
    hammer_work_J: float
    spectrum_change: dict  # {band: (power with, power without)}
    gaps_open_after_s: tuple[float, float] = (math.nan, math.nan)  # s, with friction, without

    @property
    def friction_per_impact_J(self) -> float:
        """J, the friction work per impact of the record with friction (NaN without impacts)."""
        return self.friction_work_J / self.impacts[0] if self.impacts[0] else math.nan


@dataclass(frozen=True, eq=False)
class ChannelBackbone:
    """An NNM backbone (HB, H = 1) seen on one accelerometer axis: its displacement amplitude and frequency.

    Attributes
    ----------
    label : str
        The NNM, e.g. ``"NNM at 19.6 Hz"``.
    channel : str
        The channel it is drawn on (where it shows most).
    amplitude : (m,) ndarray of float
        m, the axis's fundamental displacement amplitude along the backbone.
    freq_hz : (m,) ndarray of float
        Hz.
    energy_J : (m,) ndarray of float
        J.
    band_hz : (float, float)
        Hz, the band a ringdown's component of this NNM is band-passed to.
    """

    label: str
    channel: str
    amplitude: np.ndarray
    freq_hz: np.ndarray
    energy_J: np.ndarray
    band_hz: tuple[float, float]


@dataclass(frozen=True, eq=False)
class Comparison:
    """The model run at a measured test's sampling, driven by its hammer, compared channel for channel.

    Attributes
    ----------
    scene : Scene
        The scene.
    test_file : str
        The measured test (UFF 58).
    driven : str
        What drove the model (the test's hammer channel, or the scene's blow).
    model : list of TimeHistory
        Every channel of the model run.
    pairs : list of ChannelPair
        Model and test channels matched (:func:`bearingshaft.correlate.match_channels`).
    rows : list of dict
        Error measures, one per pair (:func:`bearingshaft.correlate.channel_errors`).
    window_s : (float, float) or None
        s, the compared window (--window, else [hammer] compare_window_s; None: the record).
    stats : dict
        For provenance.json.
    lines : tuple of str
        The stage's summary lines.
    horizon : Horizon or None
        The predictability horizon; the pointwise ``rows`` are over the window up to it.
    measures : MeasureSet or None
        The measures that survive chaos (:func:`bearingshaft.measures.compare`).
    floors : dict
        {channel: (floor, basis)} of the relative errors (:func:`bearingshaft.correlate.channel_floors`).
    backbones : list of ChannelBackbone
        The model's NNM backbones on the channels their ringdown components are measured on.
    force_text : str
        How the hammer channel was windowed, in words.
    wanted : tuple of str
        The measures asked for (--measures).
    """

    scene: Scene
    test_file: str
    driven: str  # what drove the model (the test's hammer channel)
    model: list[TimeHistory]  # every channel of the model run
    pairs: list[ChannelPair]  # model and test channels matched (bearingshaft.correlate.match_channels)
    rows: list[dict]  # error measures, one per pair, up to the horizon (bearingshaft.correlate.channel_errors)
    window_s: tuple[float, float] | None  # s, the compared window (--window or [hammer] compare_window_s)
    stats: dict  # for provenance.json
    lines: tuple[str, ...]  # the stage's summary lines
    horizon: Horizon | None = None  # the predictability horizon
    measures: MeasureSet | None = None  # the measures that survive chaos
    floors: dict = field(default_factory=dict)  # {channel: (floor, basis)}
    backbones: list = field(default_factory=list)  # ChannelBackbone: the model's NNMs on their channels
    force_text: str = ""  # how the hammer channel was windowed
    wanted: tuple[str, ...] = ()  # the measures asked for


def histories(rig: VirtualRig, t: np.ndarray, data: np.ndarray) -> list[TimeHistory]:
    """The channels of one record as :class:`fem.uff.TimeHistory` (uniform t).

    Parameters
    ----------
    rig : the rig whose channels ``data`` holds, in its channel order
    t : (N,) s, uniform sample times
    data : (n_channels, N) the channels' samples

    Returns
    -------
    list of TimeHistory, one per channel, named, placed and oriented as the rig's channels
    """
    dt = float(t[1] - t[0])
    return [TimeHistory(c.name, c.node, c.direction, c.quantity, data[i], dt, float(t[0]))
            for i, c in enumerate(rig.channels)]
