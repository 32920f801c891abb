"""Backbones (frequency-energy curves) of the nonlinear normal modes of a gap system by HB.

:func:`nnm_branch` continues one NNM from its open-gap linear mode, below the energy at
which the mode first touches a stop, up to ``energy_max_J``; :func:`hb_backbones` gives
the paper's Fig. 2 curves (one harmonic) for every mode, for the spectrogram overlays.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.models.modes import linear_modes
from reduced.periodic import MAX_HARMONICS
from reduced.periodic.continuation import STEP_FIELDS, ContinuationOptions, continue_branch
from reduced.periodic.hb import HarmonicBalance, NewtonError, NNMResidual, default_samples, newton

START_FRACTION = 0.3  # start amplitude as a fraction of the grazing amplitude (open gap)
NNM_STEPS = ContinuationOptions(ds=0.05, ds_max=0.3, max_steps=3000)  # in log10 of the modal amplitude


def grazing_amplitude(system: GapSystem, phi: np.ndarray) -> float:
    """Modal amplitude a (phi mass-normalised) at which mode phi first reaches a stop.

    Parameters
    ----------
    system : GapSystem
        Its stop rows B and offsets (the clearances).
    phi : (n,) ndarray of float
        A mode shape, mass-normalised.

    Returns
    -------
    float
        sqrt(kg) m, min_j |offset_j| / |B_j phi| over the stops the mode moves (|B_j phi| above
        1e-12 of the largest); inf if it moves none.
    """
    s = np.abs(system.B @ phi)
    with np.errstate(divide="ignore"):
        a = np.where(s > 1e-12 * np.max(s), np.abs(system.offset) / s, np.inf)
    return float(np.min(a))


@dataclass(eq=False)
class NNMBranch:
    """One HB backbone: energy [J] and frequency [Hz] per point, with the continuation data.

    ``segment`` numbers the continued pieces: a new piece starts after an internal
    resonance tongue was stepped over (``tongues`` says where); points of different pieces
    are not joined by a computed path.

    Attributes
    ----------
    mode : int
        0-based index of the open-gap linear mode it starts from.
    H : int
        Harmonics.
    N : int
        AFT samples per period.
    energy_J : (n_points,) ndarray of float
        J, mean total energy of each point.
    freq_hz : (n_points,) ndarray of float
        Hz, frequency of each point.
    X : (n_points, n (2H+1)) ndarray of float
        HB coefficients (m on physical coordinates), layout of :mod:`reduced.periodic.hb`.
    omega : (n_points,) ndarray of float
        rad/s.
    segment : (n_points,) ndarray of int
        Continued piece of each point.
    branches : list of Branch
        The continuation data of each piece.
    residual : NNMResidual
        The residual continued.
    wall_s : float
        s, wall time.
    tongues : list of dict
        The internal-resonance tongues met: ``harmonic``, ``energy_J``, ``freq_hz``, ``action``.
    notes : list of str
        Remarks on the run.
    """

    mode: int  # 0-based index of the linear mode it starts from
    H: int
    N: int
    energy_J: np.ndarray
    freq_hz: np.ndarray
    X: np.ndarray  # (n_points, n (2H+1)) HB coefficients [m]
    omega: np.ndarray  # rad/s
    segment: np.ndarray  # (n_points,) int
    branches: list  # the Branch of each piece
    residual: NNMResidual
    wall_s: float
    tongues: list = field(default_factory=list)  # dicts: harmonic, energy_J, freq_hz, action
    notes: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return self.branches[-1].status

    @property
    def n_steps(self) -> int:
        return sum(len(b.y) for b in self.branches)


TONGUE_MEASURES = ("displacement", "velocity")


def harmonic_ratio(hb: HarmonicBalance, X: np.ndarray, measure: str | int = "displacement") -> tuple[float, int]:
    """Largest mass-norm amplitude of a harmonic k >= 2 over that of the fundamental, and k.

    ``measure = "velocity"`` weighs harmonic k by k (k a_k / a_1, the square root of its
    kinetic energy over the fundamental's): a k:1 resonance with a mode far above the NNM
    (a reduced model's local modes) holds most of the energy while its displacement is
    still small (k a_k / a_1 = 1 at k = 11 is a displacement ratio of 0.09). ``measure`` may
    also be a harmonic number k: that harmonic's velocity ratio k a_k / a_1.

    Parameters
    ----------
    hb : HarmonicBalance
        The discretisation X belongs to.
    X : (n (2H+1),) ndarray of float
        HB coefficients.
    measure : {'displacement', 'velocity'} or int
        Ratio of mass-norm amplitudes sqrt(c_k^T M c_k + s_k^T M s_k), or the same weighted by k,
        or the velocity ratio of one harmonic k.

    Returns
    -------
    ratio : float
        The largest ratio over k >= 2 (or that of harmonic ``measure``); 0 when H < 2 or the
        fundamental is zero.
    k : int
        The harmonic it belongs to (1 when the ratio is 0).
    """
    Xm = hb.unpack(X)
    amp = np.array(
        [
            math.sqrt(Xm[2 * k - 1] @ hb.M @ Xm[2 * k - 1] + Xm[2 * k] @ hb.M @ Xm[2 * k])
            for k in range(1, hb.H + 1)
        ]
    )
    if hb.H < 2 or amp[0] == 0.0:
        return 0.0, 1
    if not isinstance(measure, str):  # one harmonic's velocity ratio
        k = int(measure)
        return float(k * amp[k - 1] / amp[0]), k
    if measure == "velocity":
        amp = amp * np.arange(1, hb.H + 1)
    k = int(np.argmax(amp[1:])) + 2
    return float(amp[k - 1] / amp[0]), k


TONGUE_RATIO = 1.0  # a harmonic k >= 2 larger than the fundamental: an internal resonance
STALL_FRACTION = 0.1  # tongue_measure "velocity": a frequency rising 10 times slower than before has stalled
STEP_OVER_DW = (0.01, 0.02, 0.05, 0.1, 0.2, 0.35)  # tried relative frequency jumps past a tongue
# Newton iterations allowed to a step-over landing. Measured on discrete-fep (NNM 1, H = 3..50):
# every landing that converges does so in 4-6 iterations, and the ones that fail still hold a
# residual of O(1) after 40, where they cost two thirds of NNM 1's branch time
STEP_OVER_MAX_ITER = 15


def _nnm_start(system: GapSystem, mode: int, H: int, N: int | None,
               energy_start_J: float | None) -> tuple[NNMResidual, np.ndarray, float]:
    """(residual, first point y0, omega0 [rad/s]) of NNM ``mode`` below its grazing amplitude."""
    lin = linear_modes(system, "open")
    phi = lin.phi[:, mode]
    omega0 = float(lin.omega[mode])
    hb = HarmonicBalance.for_system(system, H, N or default_samples(H))
    res = NNMResidual(hb, omega0, int(np.argmax(np.abs(phi))))
    a_g = grazing_amplitude(system, phi)
    if not math.isfinite(a_g):  # the mode never touches a stop: any amplitude will do
        a_g = 1.0
    a0 = START_FRACTION * a_g
    if energy_start_J is not None:  # linear energy 1/2 omega0^2 a^2
        a0 = min(a0, math.sqrt(2.0 * energy_start_J) / omega0)
    return res, res.start(phi, omega0, math.log10(a0)), omega0


@dataclass(eq=False)
class _TongueWatch:
    """Bookkeeping of the continued pieces: the stop test, and the tongues met with their notes.

    Used as ``stop`` of :func:`continue_branch`: stops at ``energy_max_J`` or, with H > 1, on
    entering an internal resonance tongue (``in_tongue``). Call :meth:`reset` before each piece.
    """

    res: NNMResidual
    energy_max_J: float
    tongue_ratio: float
    follow_steps: int
    velocity_watch: bool = False  # also enter a tongue when a harmonic's velocity ratio exceeds tongue_ratio
    tongues: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    in_tongue: bool = False
    w_max: float = -np.inf  # highest relative frequency of this piece so far
    E_prev: float = -np.inf  # J, energy of the previous point
    count: int = 0  # points of this piece so far
    bend_at: int | None = None  # point at which the frequency began to fall with rising energy
    bend: tuple | None = None  # (harmonic, energy_J, w_max) there
    entered_by: int | None = None  # the harmonic whose velocity ratio entered the tongue (velocity_watch)
    ys: list = field(default_factory=list)  # this piece's points (velocity_watch)
    Es: list = field(default_factory=list)  # J, their energies
    ratios: dict = field(default_factory=dict)  # harmonic k: its velocity ratio at each of ys so far (stalled)
    last: tuple = (None, 0.0)  # (y, its energy [J]) of the last call of energy()

    def reset(self) -> None:
        """Start a new piece: not in a tongue, no bend, no points."""
        self.in_tongue = False
        self.w_max, self.E_prev, self.count, self.bend_at, self.bend = -np.inf, -np.inf, 0, None, None
        self.entered_by, self.ys, self.Es, self.ratios = None, [], [], {}

    def energy(self, y: np.ndarray) -> float:
        """J, the residual's energy at y, kept for the stop test of the same point (continue_branch calls its
        callback, then its stop, with each point)."""
        E = self.res.energy(y)
        self.last = (y, E)
        return E

    def stalled(self, k: int) -> bool:
        """Whether the frequency has stalled since harmonic k's velocity ratio was last below
        tongue_ratio / 3: its log-log slope against the energy since then is below
        STALL_FRACTION of the slope over as wide an energy span just before (a tongue's
        plateau, as opposed to the backbone's steady rise or its flattening at high energy,
        where no harmonic grows)."""
        hb, i_w = self.res.hb, self.res.hb.size
        done = self.ratios.setdefault(k, [])  # the ratios of the points before, computed once
        done.extend(harmonic_ratio(hb, y[: hb.size], k)[0] for y in self.ys[len(done):])
        r = np.array(done)
        quiet = np.flatnonzero(r < self.tongue_ratio / 3.0)
        if not quiet.size or quiet[-1] == len(self.ys) - 1:
            return False
        a = int(quiet[-1])
        E, w = np.array(self.Es), np.array([y[i_w] for y in self.ys])
        span = np.log(E[-1] / E[a])
        before = np.flatnonzero(np.log(E[a] / E[: a + 1]) >= span)
        b = int(before[-1]) if before.size else 0
        if b == a or span <= 0.0:
            return False
        slope_now = np.log(w[-1] / w[a]) / span
        slope_before = np.log(w[a] / w[b]) / np.log(E[a] / E[b])
        return bool(slope_now < STALL_FRACTION * slope_before)

    def __call__(self, y: np.ndarray) -> bool:
        """Whether continuation stops at y (the energy reached, or a tongue entered)."""
        hb = self.res.hb
        i_w = hb.size
        self.count += 1
        E = self.last[1] if self.last[0] is y else self.res.energy(y)
        if E >= self.energy_max_J:
            return True
        if hb.H > 1:
            r, k = harmonic_ratio(hb, y[: hb.size])
            if r > self.tongue_ratio:
                self.in_tongue = True
                return True
            if self.velocity_watch:
                self.ys.append(y)
                self.Es.append(E)
                rv, kv = harmonic_ratio(hb, y[: hb.size], "velocity")
                if rv > self.tongue_ratio and self.stalled(kv):
                    self.in_tongue, self.entered_by = True, kv
                    return True
            # on the backbone of a hardening gap system the frequency rises with the energy;
            # a frequency that falls while the energy rises is the bend into a tongue: follow
            # it for up to follow_steps points, hoping it returns above its highest frequency
            if self.bend_at is None:
                if y[i_w] < self.w_max * (1.0 - 1e-6) and E > self.E_prev:
                    self.bend_at = self.count
                    self.bend = (k, E, self.w_max)
            elif y[i_w] > self.bend[2] and r < self.tongue_ratio / 3.0:
                k0, E0, w0 = self.bend
                self.followed(k0, E0, w0 * self.res.omega_ref / (2 * np.pi), E)
                self.bend_at = None
            elif self.count - self.bend_at > self.follow_steps:
                self.in_tongue = True
                return True
        self.w_max = max(self.w_max, y[i_w])
        self.E_prev = E
        return False

    def followed(self, k: int, E0: float, f0: float, E: float) -> None:
        """Record a k:1 tongue entered at E0 [J], f0 [Hz] that the branch came back from at E."""
        self.tongues.append({"harmonic": k, "energy_J": E0, "freq_hz": f0, "action": "followed",
                             "energy_after_J": E})
        self.notes.append(f"{k}:1 internal resonance at E = {E0:.4g} J: followed (the branch "
                          f"returned at E = {E:.4g} J)")

    def stepped_over(self, k: int, E_a: float, f_a: float, E_b: float) -> None:
        """Record a k:1 tongue at E_a [J], f_a [Hz] stepped over to E_b [J]."""
        self.tongues.append({"harmonic": k, "energy_J": E_a, "freq_hz": f_a, "action": "stepped over",
                             "energy_after_J": E_b})
        self.notes.append(f"{k}:1 internal resonance at E = {E_a:.4g} J, {f_a:.2f} Hz: stepped over to "
                          f"E = {E_b:.4g} J")

    def stopped(self, k: int, E_a: float, f_a: float) -> None:
        """Record a k:1 tongue at E_a [J], f_a [Hz] that could not be stepped over."""
        self.tongues.append({"harmonic": k, "energy_J": E_a, "freq_hz": f_a, "action": "stopped"})
        self.notes.append(f"{k}:1 internal resonance at E = {E_a:.4g} J, {f_a:.2f} Hz: could not step over")


def _last_backbone_point(hb: HarmonicBalance, Y: np.ndarray, tongue_ratio: float,
                         measure: str | int = "displacement") -> int:
    """Index in Y of the last point clearly off a tongue (small ratio, frequency at its running maximum).

    With ``measure = "velocity"`` (or a harmonic number) the last point whose harmonics (or
    that harmonic) carry little energy: a k:1 tongue with a much higher mode shows in the
    energy before it shows in the displacements (a displacement ratio of 1/3 at k = 5 is
    already 2.8 times the fundamental's kinetic energy); see :func:`_nnm_branch`.
    """
    i_w = hb.size
    r = np.array([harmonic_ratio(hb, y[: hb.size], measure)[0] for y in Y])
    w_max = np.maximum.accumulate(Y[:, i_w])
    keep = np.flatnonzero((r < tongue_ratio / 3.0) & (Y[:, i_w] >= w_max))
    return int(keep[-1]) if keep.size else 0


def _step_over_predictions(anchor: np.ndarray, backbone1: np.ndarray, n1: int):
    """Predictor past a tongue: (w_t, log10 a, guess) for each jump of STEP_OVER_DW, two guesses each.

    The frequency is fixed a little above the anchor's: the resonance sits at one frequency
    (k omega = omega of the other mode), so a solve at fixed frequency past it stays well
    conditioned, where one at fixed amplitude may not. The amplitude comes from the
    one-harmonic backbone ``backbone1`` (its points y, ``n1`` coefficients each), scaled by the
    anchor's frequency ratio to it; the guess is the anchor's shape, then the one-harmonic
    solution with higher harmonics zero.
    """
    i_w, i_a = anchor.size - 3, anchor.size - 1  # y = [Psi, w, d, log10 a] (NNMResidual)
    la1 = backbone1[:, n1 + 2]
    bias = anchor[i_w] / float(np.interp(anchor[i_a], la1, backbone1[:, n1]))
    w1 = backbone1[:, n1]
    mono = np.maximum.accumulate(w1)  # the one-harmonic backbone, made monotone for inversion
    for jump, kind in [(j, g) for j in STEP_OVER_DW for g in ("anchor", "one-harmonic")]:
        w_t = anchor[i_w] * (1.0 + jump)
        la = float(np.interp(w_t / bias, mono, la1))
        if kind == "anchor":  # the anchor's shape at the predicted amplitude
            guess = anchor.copy()
        else:  # the one-harmonic solution at that amplitude, higher harmonics zero
            guess = np.zeros_like(anchor)
            for c in range(n1):
                guess[c] = np.interp(la, la1, backbone1[:, c])
        guess[i_w] = w_t
        guess[i_a] = la
        yield w_t, la, guess


def _correct_at_frequency(res: NNMResidual, guess: np.ndarray, w_t: float) -> np.ndarray | None:
    """Corrector: Newton on [R(y); w - w_t] from ``guess`` (w = omega / omega_ref); y, or None."""
    i_w = res.hb.size

    def fixed(z):
        R, jac = res.lazy(z)  # dR/dy only for the points Newton takes (the same numbers)
        e = np.zeros(z.size)
        e[i_w] = 1.0
        return np.concatenate([R, [z[i_w] - w_t]]), lambda: jac(below=e)

    try:
        return newton(fixed, guess, max_iter=STEP_OVER_MAX_ITER, max_step=5.0, final_jacobian=False,
                      solve=res.bordered_solver).y
    except NewtonError:
        return None


def _on_backbone(res: NNMResidual, y: np.ndarray, la: float, anchor: np.ndarray, E_a: float,
                 tongue_ratio: float) -> bool:
    """Whether y continues the backbone past the anchor: amplitude near la and above the anchor's,
    more energy, a dominant fundamental."""
    i_a = res.hb.size + 2
    return (
        abs(y[i_a] - la) < 0.5
        and harmonic_ratio(res.hb, y[: res.hb.size])[0] < tongue_ratio / 3.0
        and y[i_a] > anchor[i_a]
        and res.energy(y) > E_a
    )


def _step_over(res: NNMResidual, anchor: np.ndarray, E_a: float, backbone1: np.ndarray, n1: int,
               tongue_ratio: float) -> np.ndarray | None:
    """The first corrected prediction past the tongue that lands on the backbone, or None."""
    for w_t, la, guess in _step_over_predictions(anchor, backbone1, n1):
        y = _correct_at_frequency(res, guess, w_t)
        if y is not None and _on_backbone(res, y, la, anchor, E_a, tongue_ratio):
            return y
    return None


def _nnm_branch(
    system: GapSystem,
    mode: int,
    *,
    H: int = 1,
    N: int | None = None,
    energy_max_J: float = 1e5,
    energy_start_J: float | None = None,
    continuation: ContinuationOptions = NNM_STEPS,
    tongue_ratio: float = TONGUE_RATIO,
    max_tongues: int = 60,
    follow_steps: int = 100,
    tongue_measure: str = "displacement",
    progress=None,
    backbone1: np.ndarray | None = None,
) -> NNMBranch:
    """Continue NNM ``mode`` (0-based) by HB with H harmonics until energy >= energy_max_J.

    The branch starts at START_FRACTION of the amplitude at which the linear mode first
    touches a stop (or lower, at ``energy_start_J``), continued in log10 of the modal
    amplitude (:class:`reduced.periodic.hb.NNMResidual`) with the step control ``continuation``
    (its ``max_steps`` bounds the points of all pieces together).

    Internal resonances (tongues, H > 1): when a harmonic k >= 2 outgrows the fundamental
    (``tongue_ratio``), or the frequency falls while the energy rises and does not come back
    within ``follow_steps`` points (a tongue that does come back is "followed"), the branch
    has left the backbone for a k:1 resonance with another
    mode (for the 3-DOF model, NNM 1 meets NNM 3 wherever k f_1 = f_3; followed, such a
    tongue runs all the way along NNM 3). The tongue is *stepped over*: from the last
    backbone point before it (ratio < tongue_ratio / 3, frequency at its running
    maximum) the frequency is raised in jumps (STEP_OVER_DW), the amplitude predicted from
    the one-harmonic backbone, until a solution with a small ratio, a larger amplitude and
    a higher energy is found; continuation restarts there. Each tongue is reported in
    ``tongues`` with action "stepped over" (or "followed"); if no jump
    lands, the run ends with action "stopped" (never a silent jump).

    A step-over that finds no landing is retried from the last point quiet by energy
    (velocity ratio, :func:`harmonic_ratio`, below tongue_ratio / 3): at a resonance with a
    mode far above the NNM the anchor may already hold more energy than the backbone past
    the tongue. ``tongue_measure = "velocity"`` (reduced models) also enters a tongue when
    a harmonic's velocity ratio k a_k / a_1 exceeds ``tongue_ratio`` while the frequency
    has stalled (:meth:`_TongueWatch.stalled`; the impacts alone give velocity ratios of
    1/k, a triangle wave's, and NNM 1 climbs through its 3:1 resonance at a ratio of 0.99
    with a rising frequency) and anchors it at the last point
    where that harmonic's velocity ratio was below tongue_ratio / 3: a reduced
    model's NNMs meet k:1 resonances with local modes 10-100 times their frequency, whose
    displacements stay small, so that by displacement alone a tongue is entered unseen and
    followed as if it were the backbone (seen: NNM 2 of rom-fep at H = 15 held 827 Hz from
    12 to 99 J on its 11:1 resonance with the 9.1 kHz mode). The default "displacement"
    is the 3-DOF model's (results/discrete-fep).

    The step-overs predict from the one-harmonic backbone of the same NNM (same start and
    ``energy_max_J``), continued here at the first tongue unless ``backbone1`` gives its points
    (``branches[0].y`` of that :class:`NNMBranch`, e.g. the H = 1 branch a study computes anyway).
    """
    t0 = time.perf_counter()
    res, ystart, omega0 = _nnm_start(system, mode, H, N, energy_start_J)
    hb = res.hb
    i_w, i_a = hb.size, hb.size + 2
    watch = _TongueWatch(res, energy_max_J, tongue_ratio, follow_steps, tongue_measure == "velocity")
    backbone1 = None
    pieces = []  # (Branch, indices of its points kept)
    steps_left = continuation.max_steps
    for _ in range(max_tongues + 1):
        watch.reset()
        br = continue_branch(res, ystart, param=i_a, direction=1.0, options=continuation, max_steps=steps_left,
                             stop=watch, monitor=(i_w,), callback=watch.energy, progress=progress)
        steps_left -= len(br.y)
        if not watch.in_tongue:
            pieces.append((br, np.arange(len(br.y))))
            break
        last = _last_backbone_point(hb, br.y, tongue_ratio)  # keep the backbone up to there
        if watch.entered_by is not None:  # entered by a harmonic's energy: anchor where it was small
            last = min(last, _last_backbone_point(hb, br.y, tongue_ratio, watch.entered_by))
        pieces.append((br, np.arange(last + 1)))
        k = watch.entered_by or harmonic_ratio(hb, br.y[-1][: hb.size])[1]
        anchor, E_a = br.y[last], float(br.data[last])
        f_a = anchor[i_w] * omega0 / (2 * np.pi)
        if backbone1 is None:  # given or computed once: the same points either way
            one = _nnm_branch(system, mode, H=1, energy_max_J=energy_max_J, energy_start_J=energy_start_J)
            backbone1 = one.branches[0].y
        landed = _step_over(res, anchor, E_a, backbone1, system.n * 3, tongue_ratio)  # n * 3: H = 1 size
        if landed is None:
            # fallback: the anchor may already be in the tongue by energy (a high harmonic of
            # a stiff mode: reduced models), so that every landing has less energy than it.
            # Judge the landing against the last point quiet by energy, and keep the branch
            # only up to there
            quiet = _last_backbone_point(hb, br.y[: last + 1], tongue_ratio, "velocity")
            E_q = float(br.data[quiet])
            if quiet < last and E_q < E_a:
                landed = _step_over(res, anchor, E_q, backbone1, system.n * 3, tongue_ratio)
                if landed is not None:
                    pieces[-1] = (br, np.arange(quiet + 1))
                    E_a, f_a = E_q, br.y[quiet][i_w] * omega0 / (2 * np.pi)
        if landed is None or steps_left <= 0:
            watch.stopped(k, E_a, f_a)
            break
        watch.stepped_over(k, E_a, f_a, res.energy(landed))
        ystart = landed
    return _assemble_branch(res, mode, pieces, energy_max_J, watch, time.perf_counter() - t0)


def _assemble_branch(res: NNMResidual, mode: int, pieces: list, energy_max_J: float, watch: _TongueWatch,
                     wall_s: float) -> NNMBranch:
    """The :class:`NNMBranch` of the kept points of each piece, numbered by segment."""
    hb = res.hb
    Y = np.concatenate([b.y[idx] for b, idx in pieces])
    E = np.concatenate([np.asarray(b.data)[idx] for b, idx in pieces])
    seg = np.concatenate([np.full(idx.size, i) for i, (_, idx) in enumerate(pieces)])
    X = np.array([res.X_omega(y)[0] for y in Y])
    omega = Y[:, hb.size] * res.omega_ref
    notes = watch.notes
    if pieces[-1][0].status != "stop" or E[-1] < energy_max_J:
        notes.append(f"stopped early ({pieces[-1][0].status}) at E = {E[-1]:.3g} J")
    return NNMBranch(mode, hb.H, hb.N, E, omega / (2 * np.pi), X, omega, seg, [b for b, _ in pieces], res, wall_s,
                     watch.tongues, notes)


def nnm_branch(system: GapSystem, mode: int, **options) -> NNMBranch:
    """Continue NNM ``mode`` (0-based) by HB; see :func:`_nnm_branch` for the options.

    Parameters
    ----------
    system : the gap system (undamped for an NNM)
    mode : 0-based open-gap linear mode the branch starts from
    **options : those of :func:`_nnm_branch`; the step control is ``continuation``
        (a :class:`reduced.periodic.continuation.ContinuationOptions`, default
        :data:`NNM_STEPS`), whose fields may also be given one by one (``ds=0.01``)

    Returns
    -------
    NNMBranch
        The backbone's points with their continuation data and the tongues met.

    Runs with single-threaded BLAS (:mod:`reduced._blas`): the matrices are small. The
    arguments are checked before any work (one-line ValueError naming the argument).
    """
    options = _check_branch_options(system, mode, options)
    with single_thread_blas():
        return _nnm_branch(system, mode, **options)




def _check_branch_options(system: GapSystem, mode: int, options: dict) -> dict:
    """Refuse, in one line, the arguments of :func:`nnm_branch` that cannot be used; the options
    of :func:`_nnm_branch`, the step fields given one by one folded into ``continuation``."""
    _check.gap_system(system)
    _check.integer("mode", mode, lo=0, hi=system.n - 1)
    known = ("H", "N", "energy_max_J", "energy_start_J", "continuation", "tongue_ratio", "max_tongues",
             "follow_steps", "tongue_measure", "progress", "backbone1", *STEP_FIELDS)
    for key in options:
        if key not in known:
            raise _check.InvalidArgument(f"unknown option {key!r} (known: {', '.join(known)})")
    H = _check.integer("H", options.get("H", 1), lo=1, hi=MAX_HARMONICS)
    if options.get("N") is not None:
        _check.integer("N", options["N"], lo=2 * H + 1)
    for key in ("energy_max_J", "tongue_ratio"):
        if key in options:
            _check.positive(key, options[key])
    base = options.get("continuation", NNM_STEPS)
    if not isinstance(base, ContinuationOptions):
        raise _check.InvalidArgument(f"continuation must be a ContinuationOptions, got {_check.show(base)}")
    out = {k: v for k, v in options.items() if k not in STEP_FIELDS}
    out["continuation"] = base.replace(**{k: v for k, v in options.items() if k in STEP_FIELDS})
    if options.get("energy_start_J") is not None:
        _check.positive("energy_start_J", options["energy_start_J"], "J")
    if "follow_steps" in options:
        _check.integer("follow_steps", options["follow_steps"])
    if "max_tongues" in options:
        _check.integer("max_tongues", options["max_tongues"], lo=0)
    if options.get("tongue_measure", "displacement") not in TONGUE_MEASURES:
        raise _check.InvalidArgument(f"tongue_measure must be one of {', '.join(TONGUE_MEASURES)}, "
                                     f"got {options['tongue_measure']!r}")
    _check.callback("progress", options.get("progress"))
    if options.get("backbone1") is not None:
        b1 = options["backbone1"]
        width = system.n * 3 + 3  # y of the one-harmonic NNMResidual: n (2 + 1) coefficients, w, d, log10 a
        if not (isinstance(b1, np.ndarray) and b1.ndim == 2 and b1.shape[1] == width and b1.shape[0] >= 2
                and np.all(np.isfinite(b1))):
            raise _check.InvalidArgument(f"backbone1 must be the points (k >= 2, {width}) of the one-harmonic "
                                         f"branch (NNMBranch.branches[0].y), got {_check.show(b1)}")
    return out


def hb_backbones(
    system: GapSystem, harmonics: int = 1, energy_max_J: float = 1e5, modes=None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{"NNM 1": (energy_J, freq_hz), ...} of the NNMs ``modes`` (0-based; default every one)
    by HB, sorted by energy.

    The paper's Fig. 2 curves with ``harmonics = 1``. Where a branch folds back in energy
    (an internal resonance at H > 1) the points are still returned sorted by energy, so
    use a one-harmonic branch for overlays.

    Parameters
    ----------
    system : GapSystem
        The system (its damping is not used: NNMs of the conservative system).
    harmonics : int
        H, in [1, MAX_HARMONICS].
    energy_max_J : float
        J, the branches are continued up to this energy, > 0.
    modes : iterable of int, optional
        0-based open-gap modes (default: all n).

    Returns
    -------
    dict of str to (ndarray, ndarray)
        ``"NNM <mode + 1>"`` -> (energy_J, freq_hz), J and Hz, sorted by energy.

    Raises
    ------
    InvalidArgument
        A harmonic count or energy out of range, or an argument :func:`nnm_branch` refuses.
    """
    _check.integer("harmonics", harmonics, lo=1, hi=MAX_HARMONICS)
    _check.positive("energy_max_J", energy_max_J, "J")
    out = {}
    for mode in range(system.n) if modes is None else modes:
        b = nnm_branch(system, int(mode), H=harmonics, energy_max_J=energy_max_J)
        order = np.argsort(b.energy_J, kind="stable")
        out[f"NNM {int(mode) + 1}"] = (b.energy_J[order], b.freq_hz[order])
    return out


__all__ = [
    "NNM_STEPS",
    "NNMBranch",
    "nnm_branch",
    "hb_backbones",
    "grazing_amplitude",
    "harmonic_ratio",
    "hb_point_at_energy",
]


def hb_point_at_energy(
    res: NNMResidual, y_guess: np.ndarray, energy_J: float, *, tol: float = 1e-11
) -> np.ndarray:
    """The HB solution of ``res`` whose (mean) energy is ``energy_J``, from a nearby point.

    Newton on [R(y); (E(y) - E*) / E*] (square: the arclength row replaced by the energy),
    with the analytic dE/dy of :meth:`reduced.periodic.hb.NNMResidual.energy_gradient`.
    Raises :class:`reduced.periodic.hb.NewtonError` on failure. Used to compare HB with exact
    orbits at exactly the same energy, with no interpolation along the branch.

    Parameters
    ----------
    res : NNMResidual
        The NNM residual.
    y_guess : (res.size,) ndarray of float
        A nearby point of the branch, in the unknowns of ``res``.
    energy_J : float
        J, E*, the energy wanted (> 0).
    tol : float
        Newton tolerance.

    Returns
    -------
    (res.size,) ndarray of float
        The point y at energy E*.

    Raises
    ------
    NewtonError
        Newton did not converge.
    """

    def fun(y):
        # dR/dy and dE/dy only for the points Newton takes (NNMResidual.lazy: the same numbers; its halving
        # refuses trial points on R alone), the energy from the samples and forces R was made from
        R, jac, x, f = res._lazy(y)
        E, dE = res._energy_lazy(y, x, f)
        return np.concatenate([R, [(E - energy_J) / energy_J]]), lambda: jac(below=dE() / energy_J)

    with single_thread_blas():
        return newton(fun, y_guess, tol=tol, max_iter=30, final_jacobian=False, solve=res.bordered_solver).y
