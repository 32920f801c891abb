"""A measured hammer test as the model meets it: the file read and checked, the hammer channel
through a force window, and the predictability horizon of the model against it.

:func:`read_test` reads a UFF 58 file (:func:`fem.uff.read_uff58`: units), refuses a truncated
file and the records :func:`bearingshaft.correlate.check_test_channels` refuses, and puts the hammer
channel through :func:`bearingshaft.correlate.force_window` (``[hammer] force_window``); the
result (:class:`MeasuredTest`) is the force that drives the model and the channels it is compared
with. :func:`horizon` finds where a pointwise comparison of the model's record with the test stops
meaning anything (:class:`Horizon`), from two exact runs of the model a hair apart; the measures
that survive chaos past it are :mod:`bearingshaft.measures`. Used by ``bearingshaft hammer --test``
(:mod:`bearingshaft.stages.hammer_compare`) and meant for any stage that fits the model to a test.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from bearingshaft import correlate
from bearingshaft.scenes import Scene, SceneError
from fem.uff import TimeHistory, UffError, read_uff58
from reduced.models.loads import Tabulated
from reduced.models.rig import VirtualRig

LYAPUNOV_DELTA = 1e-9  # the second run's blow is this much (relative) stronger than the first's
LYAPUNOV_SATURATION = 1e-3  # ... followed until it reaches this fraction of the state
SEPARATION_WINDOW_S = 2e-3  # s, the separation is maximised over windows this long (a period of the kHz modes)
CONTACT_TAIL_S = 0.05  # s, the runs go on this long after the model's last contact (then the motion is linear)
# the horizon: where the mismatch over the blow, grown as the model grows it, reaches this share of the
# signal (a quarter: the traces have parted; a blow's interpolation error grows from 5 % to 50 % within 2 ms)
HORIZON_TOL = 0.25
EPS0_MIN = 1e-9  # the mismatch over the blow is never taken below this (a file the model wrote itself)
CHUNK_SAMPLES = 200  # samples a chunk of the two runs (they stop at the chunk where they saturate)



@dataclass(frozen=True, eq=False)
class MeasuredTest:
    """A measured test's channels and the force that drives the model to compare with it.

    Attributes
    ----------
    channels : list of TimeHistory
        Every channel of the test file, the hammer's as recorded.
    signal : Tabulated
        The force that drives the model: the hammer channel, through the force window if the
        scene asks for one ([hammer] force_window).
    level_N : float
        N, the peak of that force.
    driven : str
        What drives the model, as the summary says it.
    duration_s : float
        s, the test's record.
    sample_rate_hz : float
        Hz, the test's sampling.
    window : ForceWindow
        The force window found on the hammer channel (its pulse, its margins).
    windowed : bool
        The window was applied (``[hammer] force_window``); else the whole channel drives the model.
    """

    channels: list[TimeHistory]
    signal: Tabulated  # the force that drives the model
    level_N: float  # N, the peak of that force
    driven: str  # what drives the model, as the summary says it
    duration_s: float  # s, the test's record
    sample_rate_hz: float  # Hz, the test's sampling
    window: correlate.ForceWindow  # the pulse and the window found on the hammer channel
    windowed: bool  # the window was applied

    @property
    def free_after_s(self) -> float:
        """s, the end of the blow: the force window's end (no force acts after it when it is applied)."""
        return self.window.window_s[1]

    @property
    def pulse_start_s(self) -> float:
        """s, the blow's first sample (the pre-trigger ends before it)."""
        return self.window.pulse_s[0]


def _complete(path: str) -> None:
    """SceneError unless the file ends with a dataset delimiter (``-1`` on a line of its own): a file
    cut short loses its last record without a word from the reader."""
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        size = fh.tell()
        fh.seek(max(0, size - 256))
        tail = fh.read()
    if not re.search(rb"    -1[ \t]*[\r\n]*$", tail):  # the delimiter's I6 field; binary 58b ends it so too
        raise SceneError(f"--test {path!r}: the file does not end with a dataset delimiter (-1): truncated "
                         f"(its last record would be lost); copy it again")


def read_test(scene: Scene, test_file: str) -> MeasuredTest:
    """The channels of ``test_file`` and the force that drives the model (SceneError, one line, if unusable).

    The file is refused when it is truncated, and its records as
    :func:`bearingshaft.correlate.check_test_channels` says (no hammer channel, two records for
    one channel, non-finite samples, channels sampled or started differently, records of
    different lengths); the records' units are checked by :func:`fem.uff.read_uff58`. The
    hammer channel goes through the force window ([hammer] force_window, force_window_margin_s:
    :func:`bearingshaft.correlate.force_window`).

    Parameters
    ----------
    scene : the scene ([hammer] force_window, force_window_margin_s)
    test_file : path of a UFF 58 file of time histories starting at t = 0

    Returns
    -------
    MeasuredTest
    """
    spec = scene.hammer
    try:
        test = read_uff58(test_file)
    except UffError as exc:
        raise SceneError(f"--test: {exc}") from None
    _complete(test_file)
    try:
        h = correlate.check_test_channels(test, source=repr(test_file))
        ref = test[h]
        window = correlate.force_window(ref, spec.force_window_margin_s, double_hit=spec.force_window,
                                        source=f"{test_file!r} record {h + 1} ({ref.name!r})")
    except correlate.ChannelError as exc:
        raise SceneError(f"--test: {exc}") from None
    if abs(ref.t0_s) > 1e-12:
        raise SceneError(f"--test {test_file!r}: the record starts at t0 = {ref.t0_s!r} s; the model starts at rest "
                         f"at 0")
    force = window.channel if spec.force_window else ref
    signal = Tabulated(force.t, force.data, source=f"{test_file} ({ref.name})")
    level = float(np.max(np.abs(force.data)))
    driven = f"the test's hammer channel {ref.name!r} (peak {level:.4g} N)"
    if spec.force_window:
        driven += f" through a {1e3 * window.margin_s:.3g} ms force window"
    duration = (ref.data.size - 1) * ref.dt_s
    return MeasuredTest(test, signal, level, driven, duration, 1.0 / ref.dt_s, window, spec.force_window)


@dataclass(frozen=True, eq=False)
class Horizon:
    """Where a pointwise comparison of the model with a test stops meaning anything
    (:func:`horizon`).

    Two exact runs of the model from rest, the second's blow ``delta`` (relative) stronger,
    separate by r(t), the median relative difference of the compared channels over windows of
    ``window_s``; G(t) = r(t) / delta is how much the model itself grows a small difference of
    the blow by t. The test and the model already differ by ``eps0`` (the median relative RMS
    error over the blow, ``eps0_span_s``), as the model would differ from itself after a blow
    ``delta_eff`` stronger; the horizon is the first t where delta_eff G(t) reaches
    ``tolerance`` (past the measured growth, extrapolated with the exponent).

    Attributes
    ----------
    start_s : float
        s, the end of the blow (the force window's end: the model is free after it).
    delta : float
        The second run's blow is this much (relative) stronger.
    window_s : float
        s, the windows over which the separation is maximised.
    t : (k,) ndarray of float
        s, window centres (absolute times).
    growth : (k,) ndarray of float
        G(t), the median relative separation of the compared channels over delta in each window.
    exponent_per_s : float
        1/s, the largest Lyapunov exponent fitted over the growth phase (NaN: no run).
    onset_s : float
        s, absolute: where chaos starts, the first window after the blow with G >= 100 (inf: never;
        NaN: no run).
    chaotic : bool
        Nearby motions of the model separate exponentially.
    eps0 : float
        The test-model mismatch the model's own divergence grows.
    eps0_span_s : (float, float)
        s, where eps0 is measured (the blow and its margin).
    tolerance : float
        The relative pointwise error at which time-domain comparison stops.
    horizon_s : float
        s, absolute (inf: the divergence never reaches the tolerance within the window).
    last_contact_s : float
        s, the model's last contact (NaN: it never closes a gap).
    note : str
        How the horizon was found, in words.
    delta_eff : float
        eps0 as a blow that much (relative) stronger: eps0 over the runs' own separation over the
        blow, per delta (NaN: no runs).
    mismatch_t : (w,) ndarray of float
        s, centres of windows of ``window_s`` over the record.
    mismatch : (w,) ndarray of float
        The test-model mismatch in them: the median over the channels of the floored relative
        RMS error (what delta_eff G(t) predicts).
    """

    start_s: float
    delta: float
    window_s: float
    t: np.ndarray
    growth: np.ndarray
    exponent_per_s: float
    onset_s: float
    chaotic: bool
    eps0: float
    eps0_span_s: tuple[float, float]
    tolerance: float
    horizon_s: float
    last_contact_s: float
    note: str
    delta_eff: float = float("nan")
    mismatch_t: np.ndarray = field(default_factory=lambda: np.empty(0))
    mismatch: np.ndarray = field(default_factory=lambda: np.empty(0))

    @property
    def lyapunov_time_s(self) -> float:
        """s, 1 / exponent (inf when nearby motions do not separate)."""
        return 1.0 / self.exponent_per_s if self.exponent_per_s > 0 else float("inf")


def window_mismatch(pairs, floors: dict, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, e): the test-model mismatch in consecutive windows of ``window_s`` from the record's start:
    e_w = median over the pairs of rms_w(model - test) / max(rms_w(test), floor) (window centres t, s).

    Parameters
    ----------
    pairs : list of ChannelPair
        The compared channels.
    floors : dict
        {name: (floor, basis)}.
    window_s : float
        s.

    Returns
    -------
    (ndarray, ndarray)
    """
    al = [p.aligned() for p in pairs]
    n = min(a.t.size for a in al)
    per = max(1, int(round(window_s * al[0].sample_rate_hz)))
    k = n // per
    cut = slice(0, k * per)
    m = np.array([a.model[cut] for a in al]).reshape(len(al), k, per)
    x = np.array([a.test[cut] for a in al]).reshape(len(al), k, per)
    floor = np.array([floors[p.name][0] for p in pairs])[:, None]
    scale = np.maximum(np.sqrt(np.mean(x**2, axis=2)), floor)
    err = np.divide(np.sqrt(np.mean((m - x) ** 2, axis=2)), scale, out=np.zeros_like(scale), where=scale > 0)
    return al[0].t[0] + (np.arange(k) + 0.5) * per / al[0].sample_rate_hz, np.median(err, axis=0)


def horizon(rig: VirtualRig, t_rec: np.ndarray, x_rec: np.ndarray, test: MeasuredTest, pairs, floors: dict,
            window_s: tuple[float, float]) -> Horizon:
    """The predictability horizon of the model against the test (:class:`Horizon`).

    Two exact runs of the model from rest (Long because the two runs, their separation in the
    channels and in the state, the exponent and the horizon are one pass over the chunks): one
    driven by the test's (windowed) hammer force, the other by that force times (1 + LYAPUNOV_DELTA),
    a blow a hair stronger. While the motion is linear their channels differ by exactly delta
    relative; impacts and then chaos grow the difference. In windows of SEPARATION_WINDOW_S the
    relative separation of the compared channels is

        e_w = median_c rms_w(ch_b - ch_a) / max(rms_w(ch_a), floor_c),     G_w = e_w / delta,

    the factor by which the model itself grows a small difference of the blow by then, in the
    metric of the pointwise errors. The test and the model differ by eps0 over the blow (the
    median over the channels of the floored relative RMS error between the pulse's start and
    the force window's end), which the model would show against itself after a blow
    delta_eff = eps0 / G_blow stronger (G_blow: the runs' separation over the same span, in the
    same metric, over delta: 1 when no gap closes during the blow); the horizon is the start of
    the first window with delta_eff G_w >= HORIZON_TOL (extrapolated with the exponent past
    saturation). The runs stop when
    the state separation D = |y_b - y_a| (energy norm) reaches LYAPUNOV_SATURATION of the state,
    or CONTACT_TAIL_S past the model's last contact (a motion whose gaps stay open is linear: a
    difference no longer grows), or at the window's end. Chaos starts (the onset) in the first
    window after the blow where G_w >= 100 (ONSET_FACTOR, :mod:`reduced.transient.compare`'s rule);
    the largest Lyapunov exponent is the slope of ln max_w D from the window before it to
    saturation.

    Parameters
    ----------
    rig : VirtualRig
        The model.
    t_rec : (N,) ndarray of float
        s, the model record's sample times (the test's).
    x_rec : (N, n) ndarray of float
        Its states' displacements there (the contacts).
    test : MeasuredTest
        The test (its force, its force window).
    pairs : list of ChannelPair
        The compared channels.
    floors : dict
        Their floors (:func:`bearingshaft.correlate.channel_floors`).
    window_s : (float, float)
        s, the compared window.

    Returns
    -------
    Horizon
    """
    from reduced.transient.compare import ONSET_FACTOR, LineFit, aligned, binned, energy_norm_matrix, state_norm
    from reduced.transient.integrate import ringdown_stream

    system = rig.system
    fs = test.sample_rate_hz
    t_free = test.free_after_s
    i_free = min(int(np.searchsorted(t_rec, t_free - 1e-6 / fs)), t_rec.size - 1)
    span = (test.pulse_start_s, float(t_rec[i_free]))
    errs = [r["rms_rel_error"] for r in correlate.channel_errors(pairs, window_s=span, floors=floors)]
    eps0 = max(float(np.median(errs)), EPS0_MIN)
    closed = np.flatnonzero(np.any(system.penetration(x_rec) > 0.0, axis=1))
    last = float(t_rec[closed[-1]]) if closed.size else math.nan
    end = min(window_s[1], (last if closed.size else t_free) + CONTACT_TAIL_S, float(t_rec[-1]))

    def done(note, t=None, growth=None, lam=math.nan, onset=math.nan, chaotic=False, hz=math.inf,
             delta_eff=math.nan):
        t, growth = (np.empty(0), np.empty(0)) if t is None else (t, growth)
        return Horizon(t_free, LYAPUNOV_DELTA, SEPARATION_WINDOW_S, t, growth, lam, onset, chaotic, eps0, span,
                       HORIZON_TOL, hz, last, note, delta_eff)

    if not closed.size or last <= t_free:
        return done("the model's gaps do not close after the blow: its motion is linear, nearby motions do not "
                    "separate, and the time-domain errors hold over the whole window")
    if eps0 >= HORIZON_TOL:
        return done(f"the model and the test already differ by {100 * eps0:.3g} % over the blow: no time-domain "
                    f"comparison past it", hz=t_free)
    sig_a = test.signal
    sig_b = Tabulated(sig_a.t_s, (1.0 + LYAPUNOV_DELTA) * sig_a.force_N, source=sig_a.source)
    zero = np.zeros(system.n)
    runs = [ringdown_stream(system, zero, zero, end, fs, "exact", loads=rig.loads(sig), chunk_samples=CHUNK_SAMPLES)
            for sig in (sig_a, sig_b)]
    idx = [list(rig.names).index(p.name) for p in pairs]
    floor = np.array([floors[p.name][0] for p in pairs])
    per = max(1, int(round(SEPARATION_WINDOW_S * fs)))
    n_win = -(-runs[0].n_samples // per)
    ss_d, ss_a = np.zeros((n_win, len(idx))), np.zeros((n_win, len(idx)))
    count, dmax, smax = np.zeros(n_win), np.zeros(n_win), np.zeros(n_win)
    blow_d, blow_a = np.zeros(len(idx)), np.zeros(len(idx))  # sums of squares over the blow (eps0's span)
    Kn = energy_norm_matrix(system)
    n_seen = 0
    try:
        for ca, cb in aligned(*runs):
            ch_a = rig.channel_data(ca.x, ca.v, sig_a(ca.t))[idx].T
            ch_b = rig.channel_data(cb.x, cb.v, sig_b(cb.t))[idx].T
            on = (ca.t >= span[0] - 0.5 / fs) & (ca.t <= span[1] + 0.5 / fs)
            blow_d += np.sum((ch_b[on] - ch_a[on]) ** 2, axis=0)
            blow_a += np.sum(ch_a[on] ** 2, axis=0)
            k0, m = binned(np.add, (ch_b - ch_a) ** 2, ca.start, per)
            sl = slice(k0, k0 + m.shape[0])
            ss_d[sl] += m
            ss_a[sl] += binned(np.add, ch_a**2, ca.start, per)[1]
            count[sl] += binned(np.add, np.ones(len(ca)), ca.start, per)[1]
            D = state_norm(Kn, system.M, cb.x - ca.x, cb.v - ca.v)
            S = state_norm(Kn, system.M, ca.x, ca.v)
            dmax[sl] = np.maximum(dmax[sl], binned(np.maximum, D, ca.start, per)[1])
            smax[sl] = np.maximum(smax[sl], binned(np.maximum, S, ca.start, per)[1])
            n_seen = sl.stop
            if np.any(D > LYAPUNOV_SATURATION * S):
                break
    finally:
        for r in runs:
            r.close()
    t = (np.arange(n_seen) + 0.5) * per / fs
    cnt = np.maximum(count[:n_seen], 1.0)[:, None]
    scale = np.maximum(np.sqrt(ss_a[:n_seen] / cnt), floor)
    e = np.median(np.divide(np.sqrt(ss_d[:n_seen] / cnt), scale, out=np.zeros_like(scale), where=scale > 0), axis=1)
    growth = e / LYAPUNOV_DELTA
    n_blow = max(1, int(round((span[1] - span[0]) * fs)) + 1)
    blow_scale = np.maximum(np.sqrt(blow_a / n_blow), floor)
    g_blow = float(np.median(np.divide(np.sqrt(blow_d / n_blow), blow_scale, out=np.zeros_like(blow_scale),
                                       where=blow_scale > 0))) / LYAPUNOV_DELTA
    delta_eff = eps0 / g_blow if g_blow > 0 else eps0  # the mismatch as the blow's own: that much stronger
    w_free = min(int(t_free * fs) // per, n_seen - 1)
    saturated = bool(n_seen and dmax[n_seen - 1] > LYAPUNOV_SATURATION * smax[n_seen - 1])
    fit_end = n_seen - 1 if saturated else n_seen  # the saturated window is past the fit
    grown = np.flatnonzero(growth[w_free:fit_end] >= ONSET_FACTOR) + w_free
    fit = LineFit()
    first = max(int(grown[0]) - 1, w_free) if grown.size else w_free
    keep = np.arange(first, fit_end)
    keep = keep[dmax[keep] > 0]
    fit.add(t[keep], np.log(dmax[keep]))
    lam = fit.slope
    onset = float(grown[0] * per / fs) if grown.size else math.inf
    chaotic = bool(grown.size and lam > 0)
    over = np.flatnonzero(delta_eff * growth >= HORIZON_TOL)
    head = (f"the test and the model differ by {100 * eps0:.2g} % over the blow, as a blow {100 * delta_eff:.2g} % "
            f"stronger would make the model differ from itself; ")
    if over.size:
        hz = float(over[0] * per / fs)
        note = head + (f"the model grows such a difference {growth[over[0]]:.3g}-fold by {1e3 * hz:.4g} ms, to "
                       f"{100 * HORIZON_TOL:g} % of the signal")
    elif chaotic and saturated and growth[n_seen - 1] > 0:
        hz = float(t[n_seen - 1]) + math.log(HORIZON_TOL / (delta_eff * growth[n_seen - 1])) / lam
        note = head + (f"the two runs saturated before that reached {100 * HORIZON_TOL:g} %: extrapolated with the "
                       f"exponent to {1e3 * hz:.4g} ms")
    else:
        hz = math.inf
        note = head + (f"the model grows it at most {growth.max(initial=1.0):.3g}-fold within the window, never to "
                       f"{100 * HORIZON_TOL:g} %")
    return done(note, t, growth, lam, onset, chaotic, hz, delta_eff)


__all__ = ["MeasuredTest", "read_test", "Horizon", "horizon", "window_mismatch", "HORIZON_TOL", "LYAPUNOV_DELTA",
           "SEPARATION_WINDOW_S"]
