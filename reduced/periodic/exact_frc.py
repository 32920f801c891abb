"""Forced-response curves on the exact flow: families of periodic orbits continued in frequency by
multiple shooting, with their stability, bifurcations and branch switching (no harmonics).

A family is a curve R(Y) = 0 of :class:`reduced.periodic.forced_shooting.ShootingResidual`
(node states and ln Omega), continued by :func:`reduced.periodic.continuation.continue_branch`.
In contact the curve of the three-mass model is piecewise smooth: each time a contact grazes
(a stop starts or stops touching within a period, the 700 Hz bending mode ringing between
impacts brings a tip back to the stop) the number of contact events per period changes and
the curve's curvature is unbounded there (the stop force grows like the 3/2 power of the
excess amplitude), and the superharmonic resonances of the bending mode (700 Hz / k for odd
k) make narrow tongues whose sheets lie close together. Three rules keep the path on its own
sheet:

- a step that changes the number of contact events per period is refused (and halved) while it
  is longer than ``grazing_ds`` (a grazing is crossed in a short step), and one that changes it by
  more than one grazing (more than two events) while it is longer than ``multi_grazing_ds``;
- a step whose secant leaves the new tangent by more than ``max_angle_deg`` is refused (it
  landed on a neighbouring sheet);
- the step may fall to ``ds_min`` = 1e-9 (the hairpins of the tongues' folds have radii of
  1e-5 in the scaled unknowns), and a corner step fixes the coordinates of the largest tangent
  components (:func:`reduced.periodic.continuation.continue_branch`'s ``corner_coords``).

**Round-off.** At the lower folds of the tongues the contact events per period change several times
within 1e-4 of arclength (discrete-frc 10 N at 37.027 Hz: 12, 14, 12, 14, 6 events); a step up to
``grazing_ds`` = 2e-2 may cross several of these grazings at once, and the sheet it lands on then
depends on round-off (with ``multi_grazing_ds`` = ``grazing_ds``, the rule before session 13, a corrector
stopped one Newton step earlier turns that level's main family from 26.8-953 Hz into 17.1-38.2 Hz; both
paths are smooth, symmetric to 1e-11, and part where they leave the fold at 37.026996 Hz). Along that
family a single grazing (the events change by 2, 1176 changes of the events in all) is 80 % of the
changes; the changes by more than one grazing are where the clusters are. With ``multi_grazing_ds`` =
1e-3 (the default) the family is the same under the corrector perturbed (``corrector_tol`` x 10) and from
another start (the linear orbit at the band's top instead of an HB orbit at 34.9 Hz): 17.13 Hz to the
band's top, the same 36 folds, the same stable stretches, in 5100 points, 1.9x the old rule's shorter,
round-off-made path (tests/test_exact_frc_robust.py); ``grazing_ds`` = 1e-3 for every change gives the same
family in 6700 points. Taking up the refused step after a short one (``resume_after_guard``) saves a fifth
of the points but is not robust: from the HB orbit at 34.9 Hz it turned back at 38.2 Hz (47 folds).

**Stability** of each point: the Floquet multipliers, eigenvalues of the monodromy (the product
of the segments' monodromies, exact for the exact orbit). **Symmetry.** The three-mass model
driven at x2 is invariant under the mirror x1 <-> x3 (a signed permutation R of the DOFs:
R M R^T = M, R K R^T = K, R C R^T = C, R b = b, stops onto stops) and, with symmetric
clearances, under the half-wave shift (t -> t + T/2, x -> -x). The monodromy of an orbit with
both symmetries is Phi = G^2 with G = -Phi(T/2) (the half-period map, negated), and Phi and G
commute with R: on the mirror-symmetric (+) and antisymmetric (-) subspaces of the state,

    real eigenvalue of G through +1 on (+)       fold (where the curve turns), else branch point
    real eigenvalue of G through -1 on (+)       pitchfork breaking the half-wave symmetry
                                                 (orbits x1 = x3 with even harmonics)
    real eigenvalue of G through +1 on (-)       pitchfork breaking the mirror symmetry
                                                 (asymmetric orbits x1 != x3, half-wave symmetric)
    real eigenvalue of G through -1 on (-)       pitchfork breaking both (x1(t + T/2) = -x3(t))
    real eigenvalue of Phi through -1            period doubling
    a complex pair leaving the unit circle       Neimark-Sacker

each detected by the sign of det(G - I), det(G + I), det(Phi + I) on each subspace between
consecutive points (without a symmetry the same tests run on Phi and the whole space).

**Branch switching** at a pitchfork or a period doubling: the crossing is located by bisection
along the curve, the critical eigenvector e of the block is propagated through the segments
(the nodes' perturbation dY, over two load periods for a period doubling: dY(T) = -e), and the
new family's first point solves R(Y) = 0 with e . (Y - Y_bp) = h: the hyperplane misses the
parent family entirely (the parent has no component along a symmetry-breaking e), so Newton
cannot fall back onto it. The new family is continued until it leaves the band or rejoins the
parent (its symmetry-breaking part falls back to zero, at another branch point), with its own
stability; its mirror image (x1 <-> x3) is a family too and is not computed again.

**Period-doubled families** (kind ``period_doubled``, period 2 T): at a multiplier of Phi through
-1 on any family (in contact they appear on the half-wave-broken families, whose Phi is not a
square), the 2 T family is shot over two load periods with 2 S nodes, started from the doubled
parent orbit plus h times the critical eigenvector propagated over 2 T (it changes sign after T),
and continued with the multipliers of its own 2 T monodromy, so its own doublings (to 4 T) are
found and followed to ``period_doubling_depth``. A period-doubled family is born at both ends of
its bubble (and on the symmetric images of its parent): a first orbit that is, at its frequency,
the orbit of a family already found, or its image under a symmetry or a shift by T, is not followed
again (:func:`_known`; the same test keeps the pitchfork families from being computed twice).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.periodic.continuation import ContinuationError, ContinuationOptions, continue_branch, tangent
from reduced.periodic.forced_shooting import SEGMENTS, ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.forced_stability import STABILITY_TOL, classify_crossing
from reduced.periodic.hb import NewtonError, newton
from reduced.periodic.shooting import ShootingError

SYMMETRY_TOL = 1e-7  # relative: an orbit whose symmetry-breaking part is below this has the symmetry
REAL_TOL = 1e-6  # relative imaginary part below which an eigenvalue is real
CORRECTOR_TOL = 1e-8  # last Newton step of a corrector, relative (the point is then within ~1e-16 of the curve)
RETRACE_DIST, RETRACE_ARC, RETRACE_BATCH = 0.03, 1.0, 500  # _Retrace: distance, arclength, tree rebuilds
RETRACE_MARGIN = 1e-9  # _Retrace: slack of the projections' prefilter, far above their round-off (~1e-14)
CLOSE_STEPS, CLOSE_DIST = 20, 1e-3  # a family back within CLOSE_DIST of its first point after CLOSE_STEPS is closed
LOAD_STEPS = 400  # continuation steps in the load of the first orbit at most
LOAD_DIFF = 1e-7  # forward-difference step of dR/d ln P in the load continuation of the first orbit
START_HARMONICS = 15  # harmonics of the balance that guesses the first orbit
BISECTIONS = 12  # bisections locating a crossing between two points (the bracket shrinks 4096 times)
SWITCH_H = (1e-3, 3e-4, 3e-3)  # offsets tried along the critical eigenvector (scaled unknowns), in order
SWITCH_MAX_STEP = 1.0  # a Newton step of a switch's first orbit longer than this (scaled, max norm) ends that try:
# the orbit sought lies within ~h of the branch point, and a step of the orbit's own size (~1 / sqrt(S)) has left
# it (rom-frc 1 N: such tries wandered to 0.8-1e5 Hz, 8.6 s CPU for one; the largest step of a try that
# converged, over the rom-frc and discrete-frc families, is 0.15)
FAMILY_KINDS = ("main", "asymmetric", "half_wave_broken", "asymmetric_half_wave", "period_doubled", "isolated",
                "close_return")
SWITCHED = {"pitchfork_mirror": "asymmetric", "pitchfork_half_wave": "half_wave_broken",
            "pitchfork_mirror_half_wave": "asymmetric_half_wave", "period_doubling": "period_doubled"}
PD_CRITICAL_TOL = 0.05  # |mu + 1| of the located critical multiplier beyond which a period doubling is not switched at
REJOIN_TOL = 1e-7  # symmetry-breaking part of a switched family, relative to its point, below which it has rejoined
SAME_ORBIT_TOL = 1e-6  # relative: two orbits shot at the same frequency closer than this (nodes) are one orbit
NEAR_ORBIT_TOL = 1e-2  # relative: a known family's point this close to a new first orbit is shot at its frequency too
COVER_TRIES = 4  # guesses tried per family of cover_families at most (a guess may find no orbit)
JOIN_DIST, JOIN_COS = 5e-3, 0.9  # an isolated family this close (scaled) to a known family's path, parallel: joined


@dataclass(frozen=True, slots=True)
class ExactFRCOptions:
    """How the exact families are continued and switched (module docstring).

    Parameters
    ----------
    segments : int
        Nodes per load period (2 per period are added to a period-2 family's). Even (the
        half-wave test splits the period at a node).
    ds, ds_max, ds_min : float
        First, largest and smallest continuation step in the scaled unknowns.
    max_angle_deg : float
        deg, largest turn of the tangent over a step, and of a step's secant from the new tangent.
    grazing_ds : float
        Longest step allowed to change the number of contact events per period.
    multi_grazing_ds : float
        Longest step allowed to change it by more than one grazing (more than two events; used if
        below ``grazing_ds``): the clusters of grazings at the tongues' folds are crossed in short
        steps, where the sheet a long step lands on depends on round-off (module docstring).
    resume_after_guard : bool
        After a step shortened by the grazing rules, the next step is the one refused
        (:class:`reduced.periodic.continuation.ContinuationOptions` ``resume_after_guard``). Off: the
        path then depends on the start again (module docstring).
    max_iter : int
        Newton iterations of a corrector.
    max_steps : int
        Points of the main family at most.
    branch_switching : bool
        Follow the families born at pitchforks (and, with ``period_doubling``, at period doublings).
    max_families : int
        Families switched onto at pitchforks at most (besides the main one).
    family_steps : int
        Points of a switched family at most.
    depth : int
        Generations of switching at pitchforks (1: families off the main curve only).
    period_doubling : bool
        Follow the period-doubled families born where a multiplier passes -1, on every family
        (whatever its generation), with ``branch_switching``.
    period_doubling_families : int
        Period-doubled families followed at most (besides ``max_families``).
    period_doubling_depth : int
        Doublings of a cascade followed: 1 the 2 T families only, 2 also the 4 T families born on them.
    period_doubling_steps : int
        Points of a period-doubled family at most (each costs about twice a period-1 point).
    cover_families : int
        Families started from the ``cover`` guesses of :func:`exact_frc` at frequencies no family
        covers (kind ``isolated``), at most; their branch points are switched at like the main one's.
    cover_steps : int
        Points of an isolated family at most, each way from its first orbit.
    deadline_s : float
        s of wall time after which no new family is started (the main one always runs).
    velocity_scale : {'fastest', 'omega'}
        Unit of the nodes' velocities in the continuation's unknowns (times x_ref): the angular
        frequency of the fastest mode with every stop open ('fastest'), or the load's (Omega).
        With Omega the ringing of a fast mode between impacts, whose phase at the nodes spins
        as Omega changes, dominates a step's length (its velocity is Omega_mode / Omega times its
        displacement): the curve takes several times more points for the same resolution.
    corrector_tol : float
        Relative size of a corrector's last Newton step (the point is then within about its square
        of the curve).
    angle_step : bool
        The step also from the tangent's turn (:class:`reduced.periodic.continuation.ContinuationOptions`
        ``angle_step``); off by default: the paths through the clusters of grazings at the tongues'
        folds depend on the step sequence, so a different step control follows other sheets there.
    """

    segments: int = SEGMENTS
    ds: float = 0.02
    ds_max: float = 0.1
    ds_min: float = 1e-9
    max_angle_deg: float = 15.0
    grazing_ds: float = 2e-2
    max_iter: int = 8
    max_steps: int = 30000
    branch_switching: bool = True
    max_families: int = 30
    family_steps: int = 4000
    depth: int = 1
    period_doubling: bool = True
    period_doubling_families: int = 4
    period_doubling_depth: int = 1
    period_doubling_steps: int = 600
    cover_families: int = 2
    cover_steps: int = 1000
    deadline_s: float = math.inf
    velocity_scale: str = "fastest"
    corrector_tol: float = CORRECTOR_TOL
    angle_step: bool = False
    resume_after_guard: bool = False
    multi_grazing_ds: float = 1e-3

    def __post_init__(self) -> None:
        _check.integer("segments", self.segments, lo=2)
        if self.segments % 2:
            raise _check.InvalidArgument(f"segments must be even, got {self.segments}")
        for key in ("ds", "ds_max", "ds_min", "max_angle_deg", "grazing_ds", "multi_grazing_ds", "corrector_tol"):
            _check.positive(key, getattr(self, key))
        if not self.deadline_s > 0.0:
            raise _check.InvalidArgument(f"deadline_s must be > 0 s, got {self.deadline_s!r}")
        for key in ("max_iter", "max_steps", "family_steps", "period_doubling_steps", "cover_steps"):
            _check.integer(key, getattr(self, key))
        _check.integer("max_families", self.max_families, lo=0)
        _check.integer("depth", self.depth, lo=0)
        _check.integer("period_doubling_families", self.period_doubling_families, lo=0)
        _check.integer("period_doubling_depth", self.period_doubling_depth, lo=0)
        _check.integer("cover_families", self.cover_families, lo=0)
        _check.flag("branch_switching", self.branch_switching)
        _check.flag("period_doubling", self.period_doubling)
        _check.choice("velocity_scale", self.velocity_scale, ("fastest", "omega"))
        _check.flag("angle_step", self.angle_step)
        _check.flag("resume_after_guard", self.resume_after_guard)

    def continuation(self, max_steps: int) -> ContinuationOptions:
        # tol bounds the last Newton step: the error after it is ~ its square (quadratic convergence)
        return ContinuationOptions(ds=self.ds, ds_max=self.ds_max, ds_min=self.ds_min, max_steps=max_steps,
                                   max_iter=self.max_iter, max_angle_deg=self.max_angle_deg, tol=self.corrector_tol,
                                   angle_step=self.angle_step, resume_after_guard=self.resume_after_guard)


# -- symmetries ----------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Symmetry:
    """The symmetries of a forced gap system: ``mirror`` (n, n) a signed permutation R of the DOFs
    leaving it invariant (None: none), ``half_wave`` whether x -> -x with t -> t + T/2 does.

    Attributes
    ----------
    mirror : (n, n) ndarray or None
        The signed permutation R (None: no mirror symmetry).
    half_wave : bool
        x -> -x with t -> t + T/2 leaves the system invariant.
    """

    mirror: np.ndarray | None
    half_wave: bool

    def state_mirror(self) -> np.ndarray | None:
        """(2n, 2n) R on [x; v] (built once, read-only: every point of a family asks for it)."""
        return self._state_mirror

    @functools.cached_property
    def _state_mirror(self) -> np.ndarray | None:
        if self.mirror is None:
            return None
        Rs = np.kron(np.eye(2), self.mirror)
        Rs.setflags(write=False)
        return Rs


def _stops(system: GapSystem, B: np.ndarray, offset: np.ndarray, side: np.ndarray) -> set:
    return {(tuple(np.round(B[j], 12)), round(float(offset[j]), 15), float(side[j]), float(system.k[j]))
            for j in range(system.m)}


def find_symmetry(system: GapSystem, b: np.ndarray, mirror: np.ndarray | None = None) -> Symmetry:
    """The symmetries of ``system`` under a load along b: the mirror ``mirror`` (default: the
    reversal of the DOFs, x1 <-> x3 of the three-mass model) if it leaves M, K, C, b and the
    stops invariant, and the half-wave symmetry if the stops are (every stop has its opposite).

    Parameters
    ----------
    system : the gap system
    b : (n,) force direction
    mirror : (n, n) a candidate signed permutation of the DOFs (default: the reversal)

    Returns
    -------
    Symmetry
    """
    n = system.n
    R = np.eye(n)[::-1] if mirror is None else np.asarray(mirror, float)
    ok = not np.allclose(R, np.eye(n))
    for A in (system.M, system.K, system.C):
        ok = ok and np.allclose(R @ A @ R.T, A, rtol=1e-12, atol=1e-12 * np.max(np.abs(A), initial=0.0))
    ok = ok and np.allclose(R @ b, b, rtol=1e-12, atol=1e-12 * np.max(np.abs(b)))
    stops = _stops(system, system.B, system.offset, system.side)
    ok = ok and _stops(system, system.B @ R.T, system.offset, system.side) == stops
    half = _stops(system, system.B, -system.offset, -system.side) == stops
    return Symmetry(R if ok else None, bool(half))


# -- the families ---------------------------------------------------------------------------------
@dataclass(eq=False)
class OrbitFamily:
    """One family of periodic orbits of the forced exact flow, in continuation order.

    Attributes
    ----------
    kind : str
        One of :data:`FAMILY_KINDS`: the main curve (from the bottom of the band), the family
        born at a pitchfork or period doubling, or (``isolated``) a family started from a guess at a
        frequency no other family covers (an isola, or a piece of the curve the others do not reach), or
        (``close_return``) one started from a close return of a chaotic response's Poincare samples
        (:mod:`reduced.periodic.uncovered`).
    periods : int
        The orbits' period in load periods.
    freq_hz, omega : (k,) ndarray of float
        Hz and rad/s, the load frequency of each point.
    nodes : (k, S, 2n) ndarray of float
        The orbit's states at the nodes t_j = j p T / S (m, m/s).
    amplitude_m : (k, p) ndarray of float
        m, max |r . x| over the orbit at each output point (exact: closed form, extremes refined).
    multipliers : (k, 2n) ndarray of complex
        Floquet multipliers over the orbit's period, by decreasing modulus.
    stable : (k,) ndarray of bool
        Every |mu| <= 1 + STABILITY_TOL.
    events : (k,) ndarray of int
        Contact events per orbit period (a stop closing or opening).
    asymmetry : (k,) ndarray of float
        max |x - R x| / max |x| over the nodes (0 on mirror-symmetric orbits).
    half_wave : (k,) ndarray of float
        max |x(t + T/2) + x(t)| / max |x| over the nodes (0 on half-wave symmetric orbits; nan
        for period-2 orbits).
    bifurcations : list of (int, str)
        (first point past the crossing, kind).
    folds : list of int
        Points where the curve turned in frequency.
    segment : (k,) ndarray of int
        The continued piece of each point.
    parent : tuple or None
        (family index, point index, kind) of the branch point it was switched from.
    status : str
        How the continuation ended, per piece, joined by '+'; "rejoined" when it met its parent again.
    notes : list of str
    wall_s : float
    start_hz : float
        Hz, the frequency of the first orbit (the guess it was found from) of a main or isolated family.
    """

    kind: str
    periods: int
    freq_hz: np.ndarray
    omega: np.ndarray
    nodes: np.ndarray
    amplitude_m: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    events: np.ndarray
    asymmetry: np.ndarray
    half_wave: np.ndarray
    bifurcations: list
    folds: list
    segment: np.ndarray
    parent: tuple | None = None
    status: str = ""
    notes: list = field(default_factory=list)
    wall_s: float = 0.0
    Y: np.ndarray | None = field(default=None, repr=False)  # (k, 2nS + 1) the scaled points
    signs: np.ndarray | None = field(default=None, repr=False)  # (k, c) test-function signs
    start_hz: float = math.nan

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.abs(self.multipliers[:, 0])

    def bifurcation_labels(self) -> list[str]:
        """Per point: '' or the kind of the bifurcation found just before it."""
        labels = [""] * len(self.freq_hz)
        for i, kind in self.bifurcations:
            labels[i] = kind
        return labels

    def pieces(self) -> list[np.ndarray]:
        return [np.flatnonzero(self.segment == k) for k in np.unique(self.segment)]


@dataclass(eq=False)
class ExactFRC:
    """The families of forced periodic orbits of one load level on the exact flow.

    Attributes
    ----------
    amplitude_N : float
        N, P.
    point_names : tuple of str
    point_rows : (p, n) ndarray of float
    families : list of OrbitFamily
        The main curve first, then the switched and isolated families in the order found.
    switches : list of dict
        Per branch point met: family, index, freq_hz, kind, and the family switched onto
        (``child``, -1 if none) or why not (``note``).
    symmetry : Symmetry
    options : ExactFRCOptions
    x_ref : float
        m.
    wall_s : float
    notes : list of str
    cover : list of dict
        Per ``cover`` guess tried (:func:`exact_frc`): its ``freq_hz``, the ``family`` it started
        (-1 if none) and ``note`` (why not).
    cover_freqs_hz : (c,) ndarray of float
        Hz, the frequencies of the ``cover`` guesses given (those to be covered).
    verdicts : list
        :class:`reduced.periodic.uncovered.Verdict` per HB point in contact no family covered, where judged.
    close_returns : list
        :class:`reduced.periodic.uncovered.CloseReturn` per seed tried from a chaotic response's Poincare samples.
    cpu_s : dict
        s of CPU time of the searches run after the families (``verdicts``, ``close_returns``).
    """

    amplitude_N: float
    point_names: tuple
    point_rows: np.ndarray
    families: list
    switches: list
    symmetry: Symmetry
    options: ExactFRCOptions
    x_ref: float
    wall_s: float
    notes: list = field(default_factory=list)
    cover: list = field(default_factory=list)
    cover_freqs_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    verdicts: list = field(default_factory=list)
    close_returns: list = field(default_factory=list)
    cpu_s: dict = field(default_factory=dict)

    @property
    def main(self) -> OrbitFamily:
        return self.families[0]

    def covered(self, freq_hz) -> np.ndarray:
        """(k,) bool: whether some family (any kind) has orbits at each frequency (:func:`covered`)."""
        return covered(self.families, freq_hz)

    def uncovered_bands(self) -> list[tuple[float, float, int]]:
        """(first Hz, last Hz, guesses) of each run of ``cover_freqs_hz`` no family covers, in frequency order."""
        f = np.sort(self.cover_freqs_hz)
        return [(float(f[r[0]]), float(f[r[-1]]), len(r)) for r in _runs(~self.covered(f))]


def covered(families: list, freq_hz) -> np.ndarray:
    """(k,) bool: whether each frequency lies in the frequency range of a piece of one of the families
    (a piece is a continuous curve: it has an orbit at each frequency of its range).

    Parameters
    ----------
    families : list of OrbitFamily
    freq_hz : (k,) Hz

    Returns
    -------
    ndarray
    """
    f = np.atleast_1d(np.asarray(freq_hz, float))
    out = np.zeros(f.shape, bool)
    for fam in families:
        for p in fam.pieces():
            lo, hi = fam.freq_hz[p].min(), fam.freq_hz[p].max()
            out |= (f >= lo * (1 - 1e-12)) & (f <= hi * (1 + 1e-12))
    return out


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """The runs of consecutive True entries of ``mask``, as index arrays."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


# -- point data: multipliers, symmetry tests, peaks -------------------------------------------------
def _real_signs_pm(lam: np.ndarray) -> tuple[float, float]:
    """(sign of det(A - I), sign of det(A + I)) from A's eigenvalues: complex pairs count |lam -+ 1|^2 > 0,
    so each is the product of sign(lam - c) over the real eigenvalues (c = +1, -1). The reference of
    :func:`_det_signs` (tests/test_exact_frc_speed.py)."""
    re = lam.real[np.abs(lam.imag) <= REAL_TOL * np.maximum(np.abs(lam), 1e-300)]
    return float(np.prod(np.sign(re - 1.0))), float(np.prod(np.sign(re + 1.0)))


@nb.njit(cache=True)
def _det_sign(A, c):
    """sign of det(A - c I) (A square): Gaussian elimination with partial pivoting, the product of the
    pivots' signs and the row swaps' (0 at a zero pivot column)."""
    m = A.shape[0]
    U = A.copy()
    for i in range(m):
        U[i, i] -= c
    sign = 1.0
    for k in range(m):
        p = k
        for i in range(k + 1, m):
            if abs(U[i, k]) > abs(U[p, k]):
                p = i
        if U[p, k] == 0.0:
            return 0.0
        if p != k:
            sign = -sign
            for j in range(k, m):
                U[k, j], U[p, j] = U[p, j], U[k, j]
        if U[k, k] < 0.0:
            sign = -sign
        for i in range(k + 1, m):
            f = U[i, k] / U[k, k]
            for j in range(k + 1, m):
                U[i, j] -= f * U[k, j]
    return sign


@nb.njit(cache=True)
def _det_signs(A):
    """(sign of det(A - I), sign of det(A + I)) of a real square A: the numbers of :func:`_real_signs_pm` on
    A's eigenvalues (det(A - c I) is the product of (lam - c) over them, a complex pair's |lam - c|^2 > 0),
    without the eigenvalues (they differ only where det(A -+ I) is at round-off, at a crossing itself)."""
    return _det_sign(A, 1.0), _det_sign(A, -1.0)


@dataclass(frozen=True, eq=False)
class _Analyser:
    """Multipliers, test functions and symmetry measures of the points of a family (module
    docstring): the channels are (block, map, c) with block '+', '-' or 'all', map 'G' (the
    half-period map) or 'Phi', c = +1 or -1."""

    res: ShootingResidual
    symmetry: Symmetry
    mirror_sym: bool
    half_sym: bool
    rows: np.ndarray

    @functools.cached_property
    def blocks(self) -> list:
        Rs = self.symmetry.state_mirror()
        if not self.mirror_sym or Rs is None:
            return [("all", np.eye(Rs.shape[0] if Rs is not None else 2 * self.res.n))]
        w, Q = np.linalg.eigh(Rs)
        return [("+", Q[:, w > 0]), ("-", Q[:, w < 0])]

    @functools.cached_property
    def channels(self) -> list[tuple[str, str, float]]:
        out = []
        for name, _ in self.blocks:
            if self.half_sym:
                out += [(name, "G", 1.0), (name, "G", -1.0)]
            else:
                out += [(name, "Phi", 1.0)]
            out += [(name, "Phi", -1.0)]
        return out

    def maps(self, Js: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(Phi, G or None) from the segments' monodromies (S, 2n, 2n)."""
        Phi = np.eye(Js.shape[1])
        G = None
        for k, Jk in enumerate(Js):
            Phi = Jk @ Phi
            if self.half_sym and k == Js.shape[0] // 2 - 1:
                G = -Phi
        return Phi, G

    def signs(self, Js: np.ndarray, maps: tuple | None = None) -> np.ndarray:
        """The test signs of the channels from the segments' monodromies (``maps``: their :meth:`maps`, if made)."""
        Phi, G = self.maps(Js) if maps is None else maps
        out = []
        for _, Q in self.blocks:
            # the whole space: Q = I, Q^T Phi Q is Phi to the bit (products by 1 and sums of zeros); the signs of
            # det(A -+ I) by elimination (:func:`_det_signs`: what the eigenvalues' signs give, a few us, not ~50)
            sp = call_numba_kernel(_det_signs, np.ascontiguousarray(Q.T @ Phi @ Q))
            out += ([*call_numba_kernel(_det_signs, np.ascontiguousarray(Q.T @ G @ Q)), sp[1]] if self.half_sym
                    else [*sp])
        return np.array(out)

    def measures(self, nodes: np.ndarray) -> tuple[float, float]:
        """(mirror asymmetry, half-wave asymmetry) of the orbit through the nodes (S, 2n), relative."""
        scale = max(float(np.max(np.abs(nodes[:, : self.res.n]))), 1e-300)
        sc = np.concatenate([np.ones(self.res.n), np.full(self.res.n, 1.0 / max(self._omega_scale(nodes), 1e-300))])
        Rs = self.symmetry.state_mirror()
        a = np.nan if Rs is None else float(np.max(np.abs((nodes - nodes @ Rs.T) * sc))) / scale
        S = nodes.shape[0]
        hw = np.nan
        if self.res.periods == 1 and S % 2 == 0:
            hw = float(np.max(np.abs((nodes[S // 2:] + nodes[: S // 2]) * sc))) / scale
        return a, hw

    def _omega_scale(self, nodes: np.ndarray) -> float:
        """rad/s: velocity / displacement scale of the orbit."""
        return float(np.max(np.abs(nodes[:, self.res.n:]))) / max(float(np.max(np.abs(nodes[:, : self.res.n]))),
                                                                  1e-300)

    def point(self, Y: np.ndarray) -> tuple:
        """(multipliers, test signs, events, asymmetry, half-wave asymmetry, amplitude (p,)) at Y
        (its residual is memoised: the corrector has just evaluated it)."""
        res = self.res
        res(Y)
        Js = res.last_segment_monodromies(Y)
        maps = self.maps(Js)
        mu = np.linalg.eigvals(maps[0])
        mu = mu[np.argsort(-np.abs(mu), kind="stable")]
        pmax, pmin = res.peaks(Y, self.rows)
        a, hw = self.measures(res.nodes(Y)[0])
        return mu, self.signs(Js, maps), res.events(Y), a, hw, np.maximum(pmax, -pmin)


# -- continuation of one family -------------------------------------------------------------------
class _Budget:
    """The wall-clock deadline of new families."""

    def __init__(self, deadline_s: float) -> None:
        self.t0 = time.perf_counter()
        self.deadline_s = deadline_s

    @property
    def spent(self) -> float:
        return time.perf_counter() - self.t0

    def left(self) -> bool:
        return self.spent < self.deadline_s


@nb.njit(cache=True)
def _within(Y, cand, y, r2):
    """The candidates c (in order) with sum_j (Y[c, j] - y[j])^2 <= r2, each sum stopped once past r2 (its
    partial sums only grow): :class:`_Retrace`'s prefilter before its full distances."""
    out = np.empty(cand.shape[0], np.int64)
    m = 0
    for c in cand:
        acc = 0.0
        for j in range(y.shape[0]):
            d = Y[c, j] - y[j]
            acc += d * d
            if acc > r2:
                break
        if acc <= r2:
            out[m] = c
            m += 1
    return out[:m]


class _Retrace:
    """Whether a family has come back onto its own path, going the same way (it is cycling around a
    closed loop, or a step jumped back onto a stretch already traced): a point within
    ``RETRACE_DIST`` of an earlier point more than ``RETRACE_ARC`` of arclength behind, with
    tangents within 25 degrees. Candidates come from a k-d tree of a few fixed random projections
    of the points (rebuilt every RETRACE_BATCH points; the newer ones are checked directly)."""

    def __init__(self, dim: int) -> None:
        rng = np.random.default_rng(0)
        self.Pm = rng.standard_normal((dim, 6)) / math.sqrt(dim)
        # the same directions, unit: |u . (y - Y_c)| <= |y - Y_c| rules a candidate out before its full distance
        self.U = self.Pm / np.linalg.norm(self.Pm, axis=0)
        self.Y = np.empty((1024, dim))
        self.T = np.empty((1024, dim))
        self.Yu = np.empty((1024, 6))
        self.s = np.empty(1024)
        self.k = 0
        self.tree, self.n_tree = None, 0

    def add(self, y: np.ndarray, t: np.ndarray) -> bool:
        """Record the point y with its tangent t; True if it retraces the path (see the class)."""
        from scipy.spatial import cKDTree

        k = self.k
        s = 0.0
        if k:
            d = y - self.Y[k - 1]
            s = self.s[k - 1] + math.sqrt(float(d.dot(d)))  # np.linalg.norm's sum and root, without its wrapper
        yu = y @ self.U
        # the points since the tree, then the tree's near ones, each kept if more than RETRACE_ARC behind (the
        # newer ones tested on a slice: the same numbers as on their indices)
        cand = np.flatnonzero(s - self.s[self.n_tree:k] > RETRACE_ARC) + self.n_tree
        if self.tree is not None:
            near = np.array(self.tree.query_ball_point(y @ self.Pm, RETRACE_DIST), int)
            if near.size:
                cand = np.concatenate([cand, near[s - self.s[near] > RETRACE_ARC]])
        if cand.size:
            # a candidate farther than RETRACE_DIST along a unit direction is farther in full: dropped before
            # the full distances (the margin covers the projections' round-off; the test itself is unchanged)
            cand = cand[np.max(np.abs(self.Yu[cand] - yu), axis=1) < RETRACE_DIST + RETRACE_MARGIN]
        if cand.size:
            # in many dimensions the projections keep most candidates (rom-frc: ~100 a point of 193 unknowns):
            # a candidate whose squared distance summed over its first coordinates already passes
            # (RETRACE_DIST + RETRACE_MARGIN)^2 is farther in full; dropped before the full distances
            cand = call_numba_kernel(_within, self.Y, cand, y, (RETRACE_DIST + RETRACE_MARGIN) ** 2)
        hit = bool(cand.size) and bool(np.any((np.linalg.norm(self.Y[cand] - y, axis=1) < RETRACE_DIST)
                                              & (self.T[cand] @ t > 0.9)))
        if k == self.Y.shape[0]:
            self.Y, self.T = np.vstack([self.Y, np.empty_like(self.Y)]), np.vstack([self.T, np.empty_like(self.T)])
            self.Yu = np.vstack([self.Yu, np.empty_like(self.Yu)])
            self.s = np.concatenate([self.s, np.empty_like(self.s)])
        self.Y[k], self.T[k], self.Yu[k], self.s[k] = y, t, yu, s
        self.k = k + 1
        if self.k - self.n_tree >= RETRACE_BATCH:
            self.tree, self.n_tree = cKDTree(self.Y[: self.k] @ self.Pm), self.k
        return hit


def _follow(res: ShootingResidual, y0: np.ndarray, param: int, direction: float, opts: ExactFRCOptions,
            max_steps: int, band: tuple[float, float], analyser: _Analyser, stop_extra=None, progress=None):
    """Continue a family from y0 (a solution): the points and their data, piece by piece (a piece
    that ends on the smallest step is taken up again by a step in frequency, both ways, from its
    last point). Returns (Y (k, .), data (list per point), folds, segment (k,), statuses, notes)."""
    i_w = res.size
    lo, hi = band
    cos_max = math.cos(math.radians(opts.max_angle_deg))

    retrace = _Retrace(res.size + 1)
    last = {}

    def stop(y):
        t = last.get("t") if last.get("y") is not None and np.array_equal(last["y"], y) else None
        if t is None:
            t = tangent(res(y)[1])
        if retrace.add(y, t):
            last["retraced"] = True
            return True
        return (not lo - 1e-12 <= y[i_w] <= hi + 1e-12) or (stop_extra is not None and stop_extra(y))

    def reject(yo, yn, tn=None):
        d = yn - yo
        dn = float(np.linalg.norm(d))
        if dn == 0.0:
            return False
        if tn is None:
            t = tangent(res(yn)[1], d / dn)
        else:  # the corrector's tangent at yn (the same null vector of dR/dY), oriented along the step
            t = tn if float(tn @ d) >= 0.0 else -tn
        last["y"], last["t"] = yn, t
        return abs(float(t @ d)) < cos_max * dn  # landed on a neighbouring sheet

    reject.takes_tangent = True

    def corner_coords(y, t):
        return [int(c) for c in np.argsort(-np.abs(t))[:3]]

    def prog(y):
        res.guard = _guard(res, y, opts)  # a grazing is crossed in a short step
        if progress is not None:
            progress(y)

    Ys, data, folds, seg, statuses, notes = [], [], [], [], [], []
    total = 0
    y_start, p_start, d_start = y0, param, direction
    k = 0
    while total < max_steps:
        res.guard = _guard(res, y_start, opts)
        try:
            br = continue_branch(res, y_start, param=p_start, direction=d_start,
                                 options=opts.continuation(max_steps - total), stop=stop, monitor=(i_w,),
                                 callback=analyser.point, reject=reject, progress=prog, corner_coords=corner_coords)
        finally:
            res.guard = None
        if last.pop("retraced", False):
            br.status = "retraced"
            notes.append(f"came back onto its own path at {res.omega(br.y[-1]) / (2 * math.pi):.6g} Hz (a closed "
                         "loop, or a step that jumped back onto a stretch already traced): stopped there")
        Ys.append(br.y)
        data += br.data
        folds += [i + total for i, c in br.folds if c == i_w]
        seg.append(np.full(len(br.y), k))
        statuses.append(br.status)
        total += len(br.y)
        if br.status != "min_step" or not lo - 1e-12 <= br.y[-1][i_w] <= hi + 1e-12:
            break
        restart = _restart(res, br.y[-1], br.tangent[-1], br.y[max(len(br.y) - 5, 0)])
        if restart is None:
            notes.append(f"ended at {res.omega(br.y[-1]) / (2 * math.pi):.6g} Hz: the step fell below "
                         f"{opts.ds_min:g} and no frequency step continued it")
            break
        y_start, p_start, d_start = restart
        notes.append(f"piece {k} ended at {res.omega(br.y[-1]) / (2 * math.pi):.6g} Hz (step below {opts.ds_min:g});"
                     f" piece {k + 1} from {res.omega(y_start) / (2 * math.pi):.6g} Hz")
        k += 1
    return np.concatenate(Ys), data, folds, np.concatenate(seg), statuses, notes


def _guard(res: ShootingResidual, y: np.ndarray, opts: ExactFRCOptions) -> tuple:
    """The residual's guard from the point y (:meth:`ShootingResidual._check_guard`): a step that changes the
    contact events per period is refused while longer than ``grazing_ds``, one that changes them by more than
    one grazing while longer than ``multi_grazing_ds`` (if shorter)."""
    if opts.multi_grazing_ds < opts.grazing_ds:
        return (y, res.events(y), opts.grazing_ds, opts.multi_grazing_ds)
    return (y, res.events(y), opts.grazing_ds)


def _restart(res: ShootingResidual, y: np.ndarray, t: np.ndarray, y_back: np.ndarray):
    """(y, param, direction) of a new piece: the orbit at a frequency a little past y's (both ways,
    growing steps), by Newton from y's nodes with y and a point behind it deflated (so it does not
    return onto the piece just traced); None if none is found."""
    i_w = res.size
    nodes, w = res.nodes(y)
    sgn = 1.0 if t[i_w] >= 0.0 else -1.0
    for dl in (1e-6, 1e-5, 1e-4, 1e-3):
        for s in (sgn, -sgn):
            try:
                yn = shoot_at(res, nodes, w * math.exp(s * dl), known=[y, y_back])
            except ShootingError:
                continue
            if np.linalg.norm(yn - y) > 1e-8:
                return yn, i_w, s
    return None


def _family(kind: str, periods: int, res: ShootingResidual, Y, data, folds, seg, statuses, notes, parent, wall,
            analyser: _Analyser) -> OrbitFamily:
    """An :class:`OrbitFamily` from the continued points and their data."""
    mu = np.array([d[0] for d in data])
    signs = np.array([d[1] for d in data])
    events = np.array([d[2] for d in data], int)
    asym = np.array([d[3] for d in data])
    hw = np.array([d[4] for d in data])
    amp = np.array([d[5] for d in data])
    omega = res.omega_ref * np.exp(Y[:, res.size])
    nodes = np.array([res.nodes(y)[0] for y in Y])
    stable = np.max(np.abs(mu), axis=1) <= 1.0 + STABILITY_TOL
    bif = _bifurcations(analyser, mu, signs, folds, seg)
    return OrbitFamily(kind, periods, omega / (2 * math.pi), omega, nodes, amp, mu, stable, events, asym, hw, bif,
                       sorted(set(folds)), seg, parent, "+".join(statuses), notes, wall, Y, signs)


def _bifurcations(analyser: _Analyser, mu: np.ndarray, signs: np.ndarray, folds: list, seg: np.ndarray
                  ) -> list[tuple[int, str]]:
    """[(first point past the crossing, kind)] from the test functions' sign changes (module
    docstring); a complex pair leaving the unit circle with no real crossing is Neimark-Sacker."""
    out = []
    chans = analyser.channels
    n_out = np.sum(np.abs(mu) > 1.0 + STABILITY_TOL, axis=1)
    fold_set = set(folds)
    for i in range(1, len(mu)):
        if seg[i] != seg[i - 1]:
            continue
        found = False
        for c, (block, mp, sign) in enumerate(chans):
            if signs[i, c] == signs[i - 1, c]:
                continue
            found = True
            out.append((i, _kind(block, mp, sign, analyser.mirror_sym, bool(fold_set & {i - 1, i, i + 1}))))
        if not found and n_out[i] != n_out[i - 1]:
            j = i if n_out[i] > n_out[i - 1] else i - 1
            if classify_crossing(mu[j], STABILITY_TOL) == "neimark_sacker":
                out.append((i, "neimark_sacker"))
    return out


def _kind(block: str, mp: str, sign: float, mirror_sym: bool, at_fold: bool) -> str:
    """The bifurcation of a crossing in channel (block, map, sign) (module docstring's table)."""
    if mp == "Phi" and sign < 0:
        return "period_doubling"
    breaks_mirror = mirror_sym and block == "-"
    breaks_half = mp == "G" and sign < 0
    if breaks_mirror and breaks_half:
        return "pitchfork_mirror_half_wave"
    if breaks_mirror:
        return "pitchfork_mirror"
    if breaks_half:
        return "pitchfork_half_wave"
    return "fold" if at_fold else "branch_point"


# -- branch switching -------------------------------------------------------------------------------
def _locate(res: ShootingResidual, analyser: _Analyser, ya: np.ndarray, yb: np.ndarray, channel: int):
    """The point between two consecutive points ya, yb of a family where the test function of
    ``channel`` changes sign, by bisection (each trial point corrected onto the curve on the
    hyperplane normal to the chord; a trial whose corrector fails is moved a tenth of the bracket
    towards its middle); (y, segment monodromies) of the end of the final bracket."""
    d = yb - ya
    t = d / float(np.linalg.norm(d))
    sa = analyser.signs(_monodromies(res, ya))[channel]
    lo, hi = 0.0, 1.0
    best = (ya, _monodromies(res, ya))
    for _ in range(BISECTIONS):
        y = None
        for shift in (0.0, 0.1, -0.1):
            th = 0.5 * (lo + hi) + shift * (hi - lo)
            yp = ya + th * d

            def corr(z, yp=yp):
                R, J = res(z)
                return np.concatenate([R, [t @ (z - yp)]]), np.vstack([J, t])

            try:
                y = newton(corr, yp, tol=1e-11, max_iter=20).y
                break
            except NewtonError:
                continue
        if y is None:
            break
        Js = _monodromies(res, y)
        if analyser.signs(Js)[channel] == sa:
            lo = th
        else:
            hi = th
        best = (y, Js)
    return best


def _critical_multiplier(analyser: _Analyser, Js: np.ndarray, channel: int) -> complex:
    """The eigenvalue of the channel's map and block nearest its sign (+1 or -1)."""
    block, mp, sign = analyser.channels[channel]
    Q = dict(analyser.blocks)[block]
    Phi, G = analyser.maps(Js)
    lam = np.linalg.eigvals(Q.T @ (G if mp == "G" else Phi) @ Q)
    return complex(lam[int(np.argmin(np.abs(lam - sign)))])


def _monodromies(res: ShootingResidual, y: np.ndarray) -> np.ndarray:
    res(y)
    return res.last_segment_monodromies(y)


def _critical_vector(analyser: _Analyser, Js: np.ndarray, channel: int) -> np.ndarray:
    """(2n,) the real eigenvector of the channel's map and block whose eigenvalue is nearest its
    sign (+1 or -1), in the full state space."""
    block, mp, sign = analyser.channels[channel]
    Q = dict(analyser.blocks)[block]
    Phi, G = analyser.maps(Js)
    A = Q.T @ (G if mp == "G" else Phi) @ Q
    lam, V = np.linalg.eig(A)
    i = int(np.argmin(np.abs(lam - sign)))
    e = Q @ V[:, i].real
    return e / np.linalg.norm(e)


def _switch(parent_res: ShootingResidual, analyser: _Analyser, y_bp: np.ndarray, Js: np.ndarray, channel: int,
            kind: str, opts: ExactFRCOptions):
    """The first point of the family born at a crossing: (residual of the family, Y, the
    perturbation direction (scaled), its h), or None. Each offset h of SWITCH_H is tried by Newton on the
    hyperplane d . (Y - Y_bp - h d) = 0; a try whose Newton step exceeds SWITCH_MAX_STEP has left the
    branch point's neighbourhood and is given up (the next h is tried)."""
    e = _critical_vector(analyser, Js, channel)
    nodes, w = parent_res.nodes(y_bp)
    S = parent_res.segments
    if kind == "period_doubling":
        res = ShootingResidual(parent_res.flow, 2 * S, 2 * parent_res.periods, parent_res.x_ref, parent_res.omega_ref,
                               parent_res.omega_v)
        nodes = np.concatenate([nodes, nodes])
        seq = list(Js) * 2
    else:
        res = ShootingResidual(parent_res.flow, S, parent_res.periods, parent_res.x_ref, parent_res.omega_ref,
                               parent_res.omega_v)
        seq = list(Js)
    dY = [e]
    for Jk in seq[:-1]:
        dY.append(Jk @ dY[-1])
    dY = np.array(dY)
    y_bp_new = res.point(nodes, w)
    d = res.point(nodes + dY, w) - y_bp_new  # the perturbation in scaled unknowns (Omega fixed)
    d[res.size] = 0.0
    # the symmetry the new family keeps, exactly (the crossing is located only to a bracket, where
    # the critical eigenvalue is not exactly +-1): Newton then stays in that invariant subspace
    block, mp, sign = analyser.channels[channel]
    Dn = d[: res.size].reshape(res.segments, 2 * res.n)
    Rs = analyser.symmetry.state_mirror()
    h2 = res.segments // 2
    if kind == "pitchfork_mirror" and analyser.half_sym:
        H = 0.5 * (Dn[:h2] - Dn[h2:])
        Dn[:] = np.concatenate([H, -H])
    elif kind == "pitchfork_half_wave" and analyser.mirror_sym:
        Dn[:] = 0.5 * (Dn + Dn @ Rs.T)
    elif kind == "pitchfork_mirror_half_wave":
        H = 0.5 * (Dn[:h2] - Dn[h2:] @ Rs.T)
        Dn[:] = np.concatenate([H, -H @ Rs.T])
    d /= np.linalg.norm(d)
    for h in SWITCH_H:
        target = y_bp_new + h * d

        def fun(z, target=target):
            R, J = res(z)
            return np.concatenate([R, [d @ (z - target)]]), np.vstack([J, d])

        try:
            y = newton(fun, target, tol=1e-11, max_iter=30, max_step=SWITCH_MAX_STEP).y
        except NewtonError:
            continue
        return res, y, d, h
    return None


def _breaking(res: ShootingResidual, kind: str, sym: Symmetry):
    """Y -> the symmetry-breaking part of the scaled nodes of a family born at a ``kind`` crossing
    (zero on the parent family), flattened: the mirror-antisymmetric part, the half-wave-symmetric
    part, both, or the difference between the two load periods of a period-2 orbit."""
    S, N = res.segments, 2 * res.n
    Rs = sym.state_mirror()

    def part(y):
        Yn = y[: res.size].reshape(S, N)
        if kind == "pitchfork_mirror":
            return 0.5 * (Yn - Yn @ Rs.T).ravel()
        if kind == "pitchfork_half_wave":
            return 0.5 * (Yn[S // 2:] + Yn[: S // 2]).ravel()
        if kind == "pitchfork_mirror_half_wave":
            return np.concatenate([0.5 * (Yn - Yn @ Rs.T).ravel(), 0.5 * (Yn[S // 2:] + Yn[: S // 2]).ravel()])
        return 0.5 * (Yn[S // 2:] - Yn[: S // 2]).ravel()  # period doubling: S = 2 S_parent

    return part


class _Watch:
    """The stop of a switched family: it rejoined its parent (its symmetry-breaking part, having
    doubled, fell below a quarter of its start, or reversed between two points: the family passed
    through the parent at another branch point; or it fell below REJOIN_TOL of the point: the
    family runs along an orbit of the parent's symmetry, which its residual holds too) or closed on
    itself (back within CLOSE_DIST of its first point after CLOSE_STEPS points)."""

    def __init__(self, part, y0: np.ndarray) -> None:
        self.part = part
        self.y0 = y0
        self.prev = part(y0)
        self.b0 = float(np.linalg.norm(self.prev))
        self.peak = self.b0
        self.steps = 0
        self.reason = ""

    def __call__(self, y: np.ndarray) -> bool:
        self.steps += 1
        p = self.part(y)
        b = float(np.linalg.norm(p))
        if (self.peak > 2.0 * self.b0 and (b < 0.25 * self.b0 or float(p @ self.prev) < 0.0)
                or b < REJOIN_TOL * float(np.linalg.norm(y[:-1]))):
            self.reason = "rejoined"
        elif self.steps > CLOSE_STEPS and float(np.linalg.norm(y - self.y0)) < CLOSE_DIST:
            self.reason = "closed"
        self.peak = max(self.peak, b)
        self.prev = p
        return bool(self.reason)


def hb_start(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz: float, segments: int,
             H: int = START_HARMONICS) -> np.ndarray:
    """(segments, 2n) a guess of the forced orbit at ``freq_hz``: the states of its harmonic balance
    (odd harmonics if the stops are symmetric, else all; condensed, the stop forces projected
    exactly; :func:`reduced.periodic.frc._start`, which raises the load gradually where the
    stops are already closed) at the nodes' phases.

    Parameters
    ----------
    system, load, amplitude_N : the gap system, the force direction (n,) and P (N)
    freq_hz : Hz
    segments : nodes
    H : harmonics

    Returns
    -------
    ndarray
        (segments, 2n) states [x; v] at the phases 2 pi k / segments.
    """
    from reduced.periodic.exact_hb import default_root_samples
    from reduced.periodic.forced_balance import ForcedBalance, ForcedResidual
    from reduced.periodic.forced_stability import hb_states
    from reduced.periodic.frc import _start, default_x_ref

    odd = find_symmetry(system, load).half_wave
    fb = ForcedBalance(system, np.asarray(load, float), float(amplitude_N), 0.0, H, default_root_samples(H), odd)
    w = 2.0 * math.pi * freq_hz
    res = ForcedResidual(fb, default_x_ref(fb, 0.5 * freq_hz, 2.0 * freq_hz), w)
    z, w = res.z_omega(_start(res, w))
    return hb_states(fb.response(z, w), w, segments)


class _LoadResidual:
    """R of a shooting residual at its fixed frequency with the load continued instead:
    y = [Y nodes, ln(P / P_0)] (dR/d ln P by forward differences: only the start uses it)."""

    def __init__(self, res: ShootingResidual, omega: float, P0: float) -> None:
        self.res, self.P0 = res, P0
        self.lw = math.log(omega / res.omega_ref)
        self.size = res.size

    def _at(self, y: np.ndarray, lp: float, jacobian: bool = True):
        self.res.flow.amplitude_N = self.P0 * math.exp(lp)
        self.res.forget()
        Y = np.append(y[: self.size], self.lw)
        return self.res(Y) if jacobian else self.res.value(Y)

    def __call__(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, jacobian = self.lazy(y)
        return R, jacobian()

    def lazy(self, y: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
        """(R(y), a callable giving dR/dy): the nodes marched at P now, the Jacobian's products and the march at
        P e^h of the load's difference only when it is called (Newton's halving refuses many trial points on R
        alone: :meth:`reduced.periodic.forced_shooting.ShootingResidual.lazy`). The same numbers in either order:
        each march and product depends on y and the load it was made at alone."""
        lp = float(y[self.size])
        self.res.flow.amplitude_N = self.P0 * math.exp(lp)
        self.res.forget()
        R, jac = self.res.lazy(np.append(y[: self.size], self.lw))

        def jacobian() -> np.ndarray:
            J = jac()  # from the marches at P (their load is kept with them), whatever the flow's load is now
            Rp = self._at(y, lp + LOAD_DIFF, jacobian=False)  # R only: the difference needs no Jacobian
            Jy = J.copy()
            Jy[:, self.size] = (Rp - R) / LOAD_DIFF
            return Jy

        return R, jacobian


def first_orbit(res: ShootingResidual, guess: np.ndarray, omega: float) -> np.ndarray:
    """The scaled point of the orbit at Omega: Newton from the guessed nodes, or, where that fails
    (hard contact at the start: the HB guess of the three-mass model at 10 N, 10 Hz is too far),
    the orbit continued in the load (pseudo-arclength in ln P, through its folds and grazings)
    from the linear orbit at a load that closes no stop up to P.

    Parameters
    ----------
    res : the shooting residual (its flow's load amplitude is P)
    guess : (S, 2n) guessed nodes
    omega : rad/s

    Returns
    -------
    ndarray
        The scaled point Y. Raises ShootingError if neither way finds the orbit.
    """
    try:
        return shoot_at(res, guess, omega)
    except ShootingError as exc:
        return _load_start(res, omega, exc)


def _load_start(res: ShootingResidual, omega: float, first: ShootingError) -> np.ndarray:
    """The load continuation of :func:`first_orbit` (its Newton failed with ``first``, raised again if this
    fails too)."""
    flow = res.flow
    P = flow.amplitude_N
    sy = flow.system
    t0, _ = res.times(omega)
    Y0, _ = flow.particular(omega)
    # state 0 (no stop closed): the linear orbit per newton at the nodes
    lin = (Y0[0, :, 0][None, :] * np.exp(1j * (omega * t0 + flow.phase))[:, None]).real
    reach = float(np.max(np.abs(lin[:, : sy.n] @ sy.B.T) / np.maximum(np.abs(sy.offset), 1e-300)))
    P0 = min(0.5 / max(reach, 1e-300), P)  # N: a load at which no stop closes (lin is per newton)
    lr = _LoadResidual(res, omega, P0)
    y0 = np.append(res.point(lin * P0, omega)[: res.size], 0.0)
    top = math.log(P / P0)
    try:
        br = continue_branch(lr, y0, param=res.size, direction=1.0,
                             options=ContinuationOptions(ds=0.05, ds_max=0.2, ds_min=1e-9, max_steps=LOAD_STEPS),
                             stop=lambda y: y[res.size] >= top)
        if br.status != "stop":
            raise first
        ya, yb = br.y[-2], br.y[-1]
        th = (top - ya[res.size]) / (yb[res.size] - ya[res.size])
        nodes = res.nodes(np.append(((1 - th) * ya + th * yb)[: res.size], math.log(omega / res.omega_ref)))[0]
        flow.amplitude_N = P
        res.forget()
        return shoot_at(res, nodes, omega)
    except (ContinuationError, ShootingError):
        raise first from None
    finally:
        flow.amplitude_N = P
        res.forget()


# -- the driver -----------------------------------------------------------------------------------
def exact_frc(system: GapSystem, load: np.ndarray, amplitude_N: float, f_min_hz: float, f_max_hz: float,
              starts, *, point_rows: np.ndarray | None = None, point_names: tuple | None = None,
              x_ref: float, options: ExactFRCOptions | None = None, mirror: np.ndarray | None = None,
              progress=None, cover=()) -> ExactFRC:
    """The forced-response families of ``system`` under load (n,) x amplitude_N cos(Omega t) on its
    exact flow over [f_min, f_max] (module docstring).

    The main family is continued from the first guess of ``starts`` whose orbit is found
    (:func:`first_orbit`), down to f_min and up to f_max; then, as the options say, the families
    born at its pitchforks and period doublings; then, up to ``options.cover_families``, families
    started from the ``cover`` guesses at frequencies no family covers yet (:func:`_cover`, kind
    ``isolated``), each with its own branch switching.

    Parameters
    ----------
    system : the gap system (damped)
    load : (n,) force direction b
    amplitude_N : N, P > 0
    f_min_hz, f_max_hz : Hz, the band
    starts : (S, 2n) a guess of the orbit at f_min at S = ``options.segments`` equally spaced phases
        (e.g. the HB orbit's states, :func:`reduced.periodic.forced_stability.hb_states`), or a
        sequence of (freq_hz, such a guess) tried in order; the linear orbit at f_max is tried
        last where it closes no stop
    point_rows, point_names : (p, n) output points (default: the DOFs)
    x_ref : m, scale of the displacements
    options : :class:`ExactFRCOptions`
    mirror : (n, n) candidate mirror of the DOFs (default: their reversal), kept if the system
        and load are invariant under it
    progress : None or a callable taking the fraction of the band the main family has covered
    cover : sequence of (freq_hz, (S, 2n) guess)
        Guesses of orbits at frequencies that should be covered (e.g. the HB orbits in contact): where
        no family has an orbit at such a frequency, the orbit is shot from its guess and followed both
        ways as a new family (not if it is the orbit, or an image, of a family already found)

    Returns
    -------
    ExactFRC
        The families with stability, bifurcations and the switches made. Raises
        :class:`reduced.periodic.shooting.ShootingError` if no guess leads to an orbit.
    """
    _check.gap_system(system)
    b = _check.vector("load", load, system.n)
    P = _check.positive("amplitude_N", amplitude_N, "N")
    f0 = _check.positive("f_min_hz", f_min_hz, "Hz")
    f1 = _check.positive("f_max_hz", f_max_hz, "Hz")
    if not f1 > f0:
        raise _check.InvalidArgument(f"f_max_hz must exceed f_min_hz = {f0:g} Hz, got {f1!r}")
    opts = options or ExactFRCOptions()
    rows = np.eye(system.n) if point_rows is None else np.atleast_2d(np.asarray(point_rows, float))
    names = tuple(point_names) if point_names is not None else tuple(system.dof_names)
    x_ref = _check.positive("x_ref", x_ref, "m")
    if isinstance(starts, np.ndarray):
        starts = [(f0, starts)]
    starts = [(float(f), np.atleast_2d(np.asarray(g, float))) for f, g in starts]
    cover = [(float(f), np.atleast_2d(np.asarray(g, float))) for f, g in cover]
    for f, g in starts + cover:
        if g.shape != (opts.segments, 2 * system.n) or not f0 <= f <= f1:
            raise _check.InvalidArgument(f"a start must be a frequency in the band and ({opts.segments}, "
                                         f"{2 * system.n}) nodes, got {f!r} Hz and {g.shape}")
    with single_thread_blas():
        return _exact_frc(system, b, P, f0, f1, starts, rows, names, x_ref, opts,
                          find_symmetry(system, b, mirror), progress, cover)


def _main_start(res: ShootingResidual, starts: list, f1: float) -> tuple[np.ndarray, list[str]]:
    """(the scaled point of the first orbit found from ``starts``, then the linear orbit at f1 where
    it closes no stop; notes on the guesses that failed). Raises ShootingError if none. Newton from each guess
    in turn, then :func:`first_orbit`'s load continuation at the first guess's frequency: the same orbit as
    :func:`first_orbit` on the first guess and Newton on the others, unless that continuation would have
    found the first guess's orbit where Newton did not (at 10 N it runs its 400 steps and fails: discrete-frc
    ~2 s CPU, now spent only where no guess converges)."""
    flow = res.flow
    w1 = 2 * math.pi * f1
    t0, _ = res.times(w1)
    lin = (flow.particular(w1)[0][0, :, 0][None, :] * np.exp(1j * (w1 * t0 + flow.phase))[:, None]).real
    lin = lin * flow.amplitude_N
    sy = flow.system
    cand = list(starts)
    if np.all(np.max(np.abs(lin[:, : sy.n] @ sy.B.T), axis=0) < np.abs(sy.offset)):
        cand.append((f1, lin))
    notes, first = [], None
    for f, g in cand:
        try:
            return shoot_at(res, g, 2 * math.pi * f), notes
        except ShootingError as exc:
            first = first or exc
            notes.append(f"no orbit from the guess at {f:.6g} Hz ({' '.join(str(exc).split())[:80]})")
    if cand:
        try:
            return _load_start(res, 2 * math.pi * cand[0][0], first), notes[1:]
        except ShootingError:
            pass
    raise ShootingError("no periodic orbit from any guess: " + "; ".join(notes))


def _exact_frc(system, b, P, f0, f1, starts, rows, names, x_ref, opts, sym, progress, cover=()) -> ExactFRC:
    budget = _Budget(opts.deadline_s)
    flow = ForcedFlow(system, b, P)
    w0, w1 = 2 * math.pi * f0, 2 * math.pi * f1
    S = opts.segments
    omega_v = None
    if opts.velocity_scale == "fastest":
        omega_v = float(np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(system.M, system.K)).real)))
    res = ShootingResidual(flow, S, 1, x_ref, w1, omega_v)
    band = (math.log(w0 / w1), 0.0)
    y0, start_notes = _main_start(res, starts, f1)
    nodes0, _ = res.nodes(y0)
    probe = _Analyser(res, sym, False, False, rows)
    a0, hw0 = probe.measures(nodes0)
    an = _Analyser(res, sym, bool(sym.mirror is not None and a0 < SYMMETRY_TOL),
                   bool(sym.half_wave and hw0 < SYMMETRY_TOL), rows)

    def prog(y):
        if progress is not None:
            progress(min(max((y[res.size] - band[0]) / (band[1] - band[0]), 0.0), 1.0))

    t0 = time.perf_counter()
    parts = []
    for direction in (-1.0, 1.0):  # down to f_min, then up to f_max, from the first orbit
        if direction < 0 and y0[res.size] <= band[0] + 1e-12 or direction > 0 and y0[res.size] >= band[1] - 1e-12:
            continue
        parts.append((direction, _follow(res, y0, res.size, direction, opts, opts.max_steps, band, an,
                                         progress=prog)))
    Y, data, folds, seg, st, notes = _join(parts)
    notes = start_notes + notes
    families = [_family("main", 1, res, Y, data, folds, seg, st, notes, None, time.perf_counter() - t0, an)]
    families[0].start_hz = res.omega(y0) / (2 * math.pi)
    switches = []
    residuals = {0: (res, an)}
    switching = opts.branch_switching and (opts.max_families > 0
                                           or opts.period_doubling and opts.period_doubling_families > 0)
    if switching:
        _switch_all(families, switches, residuals, opts, band, rows, sym, budget)
    tried = _cover(families, switches, residuals, cover, res, opts, band, rows, sym, budget, switching) if cover else []
    return ExactFRC(P, names, rows, families, switches, sym, opts, x_ref, budget.spent, cover=tried,
                    cover_freqs_hz=np.array([f for f, _ in cover]))


def _join(parts: list) -> tuple:
    """One family from the runs down and up from the same first point: the run down reversed (its
    first point, shared, dropped), then the run up; indices and pieces renumbered so that the first
    point's piece is one piece."""
    if len(parts) == 1 and parts[0][0] > 0:
        return parts[0][1]
    down = dict(parts)[-1.0]
    Yd, dd, fd, sd, std, nd = down
    top = int(sd.max())
    Y, data, seg = Yd[::-1], dd[::-1], top - sd[::-1]
    folds = [len(Yd) - 1 - i for i in fd]
    st, notes = list(std), list(nd)
    if len(parts) == 2:
        Yu, du, fu, su, stu, nu = parts[1][1]
        n0 = len(Yd) - 1
        Y = np.concatenate([Y[:-1], Yu])
        data = data[:-1] + du
        seg = np.concatenate([seg[:-1], su + top])
        folds += [n0 + i for i in fu]
        st += stu
        notes += nu
    return Y, data, sorted(folds), seg, st, notes


def _switch_all(families, switches, residuals, opts, band, rows, sym, budget, root: int = 0,
                max_new: int | None = None) -> None:
    """Branch switching at the pitchforks and period doublings of the families, within the budget
    (module docstring). Pitchforks first, family by family in the order found, on families of
    generation <= ``opts.depth`` (the main one is generation 1), up to ``opts.max_families``; then
    (with ``opts.period_doubling``) the period doublings of every family found, the least unstable
    parents first (the largest |mu| but the critical one's, the smaller of the two points around the
    crossing: a 2 T family born where the other multipliers are inside the unit circle can be
    stable), on families whose period is below 2^``period_doubling_depth`` load periods, up to
    ``opts.period_doubling_families``, each only where the critical multiplier located is within
    PD_CRITICAL_TOL of -1 (a multiplier that jumps past -1 at a grazing bifurcates no smooth 2 T
    family off the eigenvector). A family whose first orbit is one of a family already found (or its
    image under a symmetry, or shifted by a load period) is not followed again: a period-doubled
    family is born at both ends of its bubble, and on the symmetric images of its parent. ``root``: the
    family whose switches are made (with those of its children): the main one, or an isolated one.
    ``max_new``: families switched onto from ``root``'s tree at most, in place of the level's caps
    (:func:`_used_up`: a family found late, by a verdict or a close return, has its own)."""
    start = len(families)
    covered = set()  # (family, point) of branch points reached by a switched family's far end
    pending = []  # (rank, record, family, point) of the period doublings, followed after the pitchforks

    def attempt(rec, fi, i, kind, fam, res, an):
        if not budget.left():
            rec["note"] = f"not followed: deadline of {opts.deadline_s:g} s reached"
            return None
        child, info = _child(fam, res, an, i, kind, opts, band, rows, sym, fi, families, residuals)
        rec.update(info)
        if isinstance(child, str):
            rec["note"] = child
            return None
        fam_new, res_new, an_new, end_index = child
        families.append(fam_new)
        residuals[len(families) - 1] = (res_new, an_new)
        rec["child"] = len(families) - 1
        if end_index is not None:
            covered.add((fi, end_index))
        return len(families) - 1

    def scan(fi, gen):
        """Records of the switches of family fi; its pitchforks followed now, its period doublings queued."""
        fam = families[fi]
        res, an = residuals[fi]
        for i, kind in fam.bifurcations:
            if kind not in SWITCHED:
                continue
            rec = {"family": fi, "index": i, "freq_hz": float(fam.freq_hz[i]), "kind": kind, "child": -1, "note": ""}
            switches.append(rec)
            if kind == "period_doubling":
                if not opts.period_doubling:
                    rec["note"] = "not followed: period_doubling = false"
                elif fam.periods >= 2 ** opts.period_doubling_depth:
                    rec["note"] = f"not followed: period_doubling_depth = {opts.period_doubling_depth} reached"
                else:
                    pending.append((_pd_rank(fam, i), len(pending), rec, fi, i))
                continue
            if (fi, i) in covered:
                rec["note"] = "reached by a family switched onto before"
            elif gen > opts.depth or fam.kind == "period_doubled":
                rec["note"] = (f"not followed: depth = {opts.depth} reached" if gen > opts.depth else
                               "not followed: the pitchforks of a period-doubled family are not followed")
            elif full := _used_up(families, start, max_new, root, opts, False):
                rec["note"] = full
            else:
                k = attempt(rec, fi, i, kind, fam, res, an)
                if k is not None:
                    queue.append((k, gen + 1))

    queue = [(root, 1)]  # (family index, generation)
    gens = {}
    while queue:
        fi, gen = queue.pop(0)
        gens[fi] = gen
        scan(fi, gen)
    while pending:
        pending.sort(key=lambda p: p[:2])
        _, _, rec, fi, i = pending.pop(0)
        fam = families[fi]
        res, an = residuals[fi]
        if (fi, i) in covered:
            rec["note"] = "reached by a family switched onto before"
            continue
        if full := _used_up(families, start, max_new, root, opts, True):
            rec["note"] = full
            continue
        chans = an.channels
        c = next((c for c in range(len(chans)) if chans[c][1] == "Phi" and chans[c][2] < 0
                  and fam.signs[i, c] != fam.signs[i - 1, c]), None)
        if c is not None:
            _, Js = _locate(res, an, fam.Y[i - 1], fam.Y[i], c)
            mu_c = _critical_multiplier(an, Js, c)
            if abs(mu_c + 1.0) > PD_CRITICAL_TOL:
                rec.update(located_hz=float("nan"), critical=mu_c, grazing=bool(fam.events[i] != fam.events[i - 1]))
                rec["note"] = (f"not followed: the critical multiplier located is {mu_c.real:.3g}{mu_c.imag:+.3g}j, "
                               f"not within {PD_CRITICAL_TOL:g} of -1 (it jumps past -1 at a grazing)")
                continue
        k = attempt(rec, fi, i, "period_doubling", fam, res, an)
        if k is not None:
            gens[k] = gens.get(fi, 1) + 1
            scan(k, gens[k])


def _used_up(families: list, start: int, max_new: int | None, root: int, opts: ExactFRCOptions, pd: bool) -> str:
    """'' if one more switched family may be followed (:func:`_switch_all`), else the note that says which
    allowance is used up: ``max_new`` families since ``start`` (the families of ``root``'s tree), or the
    level's ``max_families`` (pitchforks) or ``period_doubling_families`` (``pd``)."""
    if max_new is not None:
        return "" if len(families) - start < max_new else (
            f"not followed: the {max_new} switched famil{'y' if max_new == 1 else 'ies'} allowed from family {root} "
            "(found from a verdict or a close return) reached")
    if pd:
        n, cap, key = sum(f.kind == "period_doubled" for f in families), opts.period_doubling_families, \
            "period_doubling_families"
    else:
        n, cap, key = sum(f.kind in SWITCHED.values() and f.kind != "period_doubled" for f in families), \
            opts.max_families, "max_families"
    return "" if n < cap else f"not followed: {key} = {cap} reached"


def _pd_rank(fam: OrbitFamily, i: int) -> float:
    """How unstable the parent of a period doubling before point i is, besides the critical
    multiplier: the largest |mu| but the one nearest -1, the smaller at points i - 1 and i."""
    out = math.inf
    for j in (i - 1, i):
        mu = fam.multipliers[j]
        out = min(out, float(np.max(np.delete(np.abs(mu), int(np.argmin(np.abs(mu + 1.0)))), initial=0.0)))
    return out


def _images(nodes: np.ndarray, periods: int, sym: Symmetry) -> list[np.ndarray]:
    """The node arrays (S, 2n) of the orbit through ``nodes`` (at t_k = k p T / S) and of its images
    under the system's symmetries: shifted by whole load periods, the half-wave image (x -> -x,
    t -> t + T/2) and the mirror's, each combination."""
    S = nodes.shape[0]
    out = [np.roll(nodes, -k * S // periods, axis=0) for k in range(periods)]
    if sym.half_wave and S % (2 * periods) == 0:
        out += [-np.roll(x, -S // (2 * periods), axis=0) for x in out]
    Rs = sym.state_mirror()
    if Rs is not None:
        out += [x @ Rs.T for x in out]
    return out


def _image_points(res: ShootingResidual, nodes: np.ndarray, omega: np.ndarray, periods: int, sym: Symmetry
                  ) -> list[np.ndarray]:
    """Per image of :func:`_images`, the scaled points (k, 2nS + 1) of ``res`` (``res.point``) of the orbits
    through nodes (k, S, 2n) at the frequencies omega (k,) rad/s: the same numbers as :func:`_images` and
    ``res.point`` point by point (the mirror is a signed permutation: its products are exact), all points at once."""
    k, S, N = nodes.shape
    out = [np.roll(nodes, -j * S // periods, axis=1) for j in range(periods)]
    if sym.half_wave and S % (2 * periods) == 0:
        out += [-np.roll(x, -S // (2 * periods), axis=1) for x in out]
    Rs = sym.state_mirror()
    if Rs is not None:
        out += [x @ Rs.T for x in out]
    D = np.array([res.scale(float(w)) for w in omega]).reshape(k, 1, N)
    lw = np.array([math.log(float(w) / res.omega_ref) for w in omega])  # math.log, as res.point
    return [np.concatenate([(x / D).reshape(k, S * N), lw[:, None]], axis=1) for x in out]


def _known(families: list, residuals: dict, res_new: ShootingResidual, y_new: np.ndarray, sym: Symmetry):
    """The index of a family of the same period whose orbit at y_new's frequency (Newton at that
    frequency from its nearest points on each side, and from its point nearest y_new's orbit or an image of
    it if within :data:`NEAR_ORBIT_TOL`) is y_new's orbit or one of its images (:data:`SAME_ORBIT_TOL`),
    else None."""
    nodes, w = res_new.nodes(y_new)
    f = w / (2 * math.pi)
    ims = _images(nodes, res_new.periods, sym)
    scale = max(float(np.max(np.abs(nodes[:, : res_new.n]))), 1e-300)
    sc = np.concatenate([np.ones(res_new.n), np.full(res_new.n, 1.0 / w)])
    for k, fam in enumerate(families):
        if fam.periods != res_new.periods or fam.nodes.shape[1] != nodes.shape[0]:
            continue
        res = residuals[k][0]
        d = fam.freq_hz - f
        cross = np.flatnonzero((d[:-1] * d[1:] <= 0) & (fam.segment[:-1] == fam.segment[1:]))
        near = [i if abs(d[i]) <= abs(d[i + 1]) else i + 1 for i in cross]
        # and its point nearest y_new (relative node distance, any image) if within NEAR_ORBIT_TOL: a family born
        # at the same branch point as y_new's (a parent that retraces its path passes it twice) starts at a fold
        # in frequency, its first points just beside y_new's frequency, where no crossing is
        dist = np.min([np.max(np.abs((fam.nodes - x) * sc), axis=(1, 2)) for x in ims], axis=0) / scale
        j = int(np.argmin(dist))
        extra = [j] if dist[j] < NEAR_ORBIT_TOL and j not in near else []
        for j in extra + near:
            try:
                other = res.nodes(shoot_at(res, fam.nodes[j], w))[0]
            except ShootingError:
                continue
            if min(float(np.max(np.abs((x - other) * sc))) for x in ims) < SAME_ORBIT_TOL * scale:
                return k
    return None


def _child(fam: OrbitFamily, res: ShootingResidual, an: _Analyser, i: int, kind: str, opts, band, rows, sym, fi,
           families: list, residuals: dict):
    """The family switched onto at the crossing before point i of ``fam``: ((family, residual,
    analyser, index of the parent's branch point where it rejoined or None), or why not (str)),
    and what was found at the crossing: its located frequency ``located_hz``, the ``critical``
    multiplier there (the eigenvalue of the channel's map nearest +-1: near it at a smooth
    crossing, not at one made within a grazing), whether a contact grazes between the two
    points (``grazing``) and the frequency of the family's first point (``start_hz``)."""
    chans = an.channels
    changed = [c for c in range(len(chans)) if fam.signs[i, c] != fam.signs[i - 1, c]]
    channel = next((c for c in changed if _kind(*chans[c], an.mirror_sym, False) == kind
                    or kind == "period_doubling" and chans[c][1] == "Phi" and chans[c][2] < 0), None)
    if channel is None:
        return "no channel", {}
    t0 = time.perf_counter()
    y_bp, Js = _locate(res, an, fam.Y[i - 1], fam.Y[i], channel)
    info = {"located_hz": res.omega(y_bp) / (2 * math.pi), "critical": _critical_multiplier(an, Js, channel),
            "grazing": bool(fam.events[i] != fam.events[i - 1])}
    sw = _switch(res, an, y_bp, Js, channel, kind, opts)
    if sw is None:
        return "branch switching found no orbit off the branch point", info
    res_new, y_new, d, h = sw
    info["start_hz"] = res_new.omega(y_new) / (2 * math.pi)
    same = _known(families, residuals, res_new, y_new, sym)
    if same is not None:
        return f"the family switched onto is family {same} (or an image of it under a symmetry)", info
    watch = _Watch(_breaking(res_new, kind, sym), y_new)
    nodes, _ = res_new.nodes(y_new)
    probe = _Analyser(res_new, sym, False, False, rows)
    a0, hw0 = probe.measures(nodes)
    an_new = _Analyser(res_new, sym, bool(sym.mirror is not None and a0 < SYMMETRY_TOL),
                       bool(sym.half_wave and res_new.periods == 1 and hw0 < SYMMETRY_TOL), rows)
    j = int(np.argmax(np.abs(d[: res_new.size])))
    try:
        steps = opts.period_doubling_steps if kind == "period_doubling" else opts.family_steps
        Y, data, folds, seg, st, notes = _follow(res_new, y_new, j, 1.0 if d[j] > 0 else -1.0, opts,
                                                 steps, band, an_new, stop_extra=watch)
    except (ContinuationError, ShootingError) as exc:
        return f"continuation failed: {' '.join(str(exc).split())[:120]}", info
    end = None
    if watch.reason:
        st[-1] = watch.reason
    if watch.reason == "rejoined":
        f_end = res_new.omega(Y[-1]) / (2 * math.pi)
        cand = [k for k, kd in fam.bifurcations if kd == kind and k != i]
        if cand:
            end = min(cand, key=lambda k: abs(fam.freq_hz[k] - f_end))
    fam_new = _family(SWITCHED[kind], res_new.periods, res_new, Y, data, folds, seg, st, notes, (fi, i, kind),
                      time.perf_counter() - t0, an_new)
    return (fam_new, res_new, an_new, end), info


# -- covering the band: isolated families -------------------------------------------------------------
class _Joined:
    """The stop of an isolated family: it ran onto the path of a family already found (or of one of
    its images under the symmetries), going along it: a point within JOIN_DIST (scaled unknowns)
    of a chord between two consecutive points of that path, the step's secant within
    arccos(JOIN_COS) of the chord (a family crossing it at a branch point is not stopped). ``own``:
    (Y, segment) of the family's own run the other way from its first point, whose points more than
    RETRACE_ARC of arclength from it count as a known path too (family -2: an isola closed)."""

    def __init__(self, families: list, res: ShootingResidual, sym: Symmetry, own=None) -> None:
        from scipy.spatial import cKDTree

        A, B, who = [], [], []
        if own is not None and len(own[0]) > 1:
            Yo, so = own
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(Yo, axis=0), axis=1))])
            keep = (so[:-1] == so[1:]) & (arc[:-1] > RETRACE_ARC)
            A.append(Yo[:-1][keep])
            B.append(Yo[1:][keep])
            who.append(np.flatnonzero(keep) - 2j)
        for k, fam in enumerate(families):
            if fam.periods != res.periods or fam.nodes.shape[1] != res.segments or len(fam.freq_hz) < 2:
                continue
            same = fam.segment[:-1] == fam.segment[1:]
            for Yi in _image_points(res, fam.nodes, fam.omega, fam.periods, sym):
                A.append(Yi[:-1][same])
                B.append(Yi[1:][same])
                who.append(np.flatnonzero(same) + 1j * k)
        self.A = np.concatenate(A) if A else np.zeros((0, res.size + 1))
        self.B = np.concatenate(B) if B else self.A
        self.who = np.concatenate(who) if who else np.zeros(0, complex)
        self.reach = float(np.max(np.linalg.norm(self.B - self.A, axis=1), initial=0.0))
        self.tree = cKDTree(0.5 * (self.A + self.B)) if len(self.A) else None
        self.prev = None
        self.family = -1

    def __call__(self, y: np.ndarray) -> bool:
        prev, self.prev = self.prev, y
        if self.tree is None or prev is None:
            return False
        step = y - prev
        ns = float(np.linalg.norm(step))
        if ns == 0.0:
            return False
        for j in self.tree.query_ball_point(y, 0.5 * self.reach + JOIN_DIST):
            a, c = self.A[j], self.B[j] - self.A[j]
            nc = float(c @ c)
            th = min(max(float((y - a) @ c) / nc, 0.0), 1.0) if nc > 0 else 0.0
            if (float(np.linalg.norm(y - a - th * c)) < JOIN_DIST
                    and abs(float(step @ c)) > JOIN_COS * ns * math.sqrt(nc)):
                self.family = int(self.who[j].imag)
                return True
        return False


def _cover(families, switches, residuals, cover, res, opts, band, rows, sym, budget, switching) -> list[dict]:
    """Isolated families from the ``cover`` guesses (:func:`exact_frc`), up to ``opts.cover_families``
    (at most COVER_TRIES guesses each): while some guess's frequency is covered by no family, the
    longest run (in ln f) of such guesses consecutive in frequency (split by covered frequencies and
    by guesses already tried) is taken, and its guess nearest its middle in ln f shot (:func:`shoot_at`, at its
    frequency). An orbit that is one of a family already found, or an image (:func:`_known`), is
    not followed; else it is followed down and up (each way until it leaves the band, retraces its
    path or runs onto a known family's path, :class:`_Joined`) as a family of kind ``isolated``,
    whose branch points are then switched at (:func:`_switch_all`). Returns a record per guess tried."""
    f = np.array([c[0] for c in cover])
    tried = np.zeros(len(f), bool)
    out = []
    n_new = 0
    order = np.argsort(f, kind="stable")
    while n_new < opts.cover_families and len(out) < COVER_TRIES * opts.cover_families:
        if not budget.left():
            out.append({"freq_hz": math.nan, "family": -1, "note": f"deadline of {opts.deadline_s:g} s reached"})
            break
        free = ~covered(families, f[order]) & ~tried[order]
        runs = _runs(free)
        if not runs:
            break
        run = max(runs, key=lambda r: (math.log(f[order[r[-1]]] / f[order[r[0]]]), len(r)))
        mid = math.sqrt(f[order[run[0]]] * f[order[run[-1]]])  # the run's middle in ln f
        j = int(order[run[int(np.argmin(np.abs(np.log(f[order[run]] / mid))))]])
        tried[j] = True
        rec = {"freq_hz": float(f[j]), "family": -1, "note": ""}
        out.append(rec)
        rec["note"] = _isolated(families, switches, residuals, cover[j], res, opts, band, rows, sym, budget, switching)
        if not rec["note"]:
            rec["family"] = len(families) - 1
            n_new += 1
    return out


def _isolated(families, switches, residuals, guess, res, opts, band, rows, sym, budget, switching,
              max_new: int | None = None) -> str:
    """Shoot the orbit of one cover guess (freq_hz, nodes) and follow it as an isolated family
    (appended to ``families``, its switches made with ``switching``, up to ``max_new`` families:
    :func:`_switch_all`); '' if done, else why not."""
    t0 = time.perf_counter()
    fq, nodes = guess
    w = 2 * math.pi * fq
    try:
        y0 = shoot_at(res, nodes, w)
    except ShootingError as exc:
        return f"no orbit from the guess ({' '.join(str(exc).split())[:80]})"
    same = _known(families, residuals, res, y0, sym)
    if same is not None:
        return f"the orbit found is one of family {same} (or an image of it under a symmetry)"
    nodes0, _ = res.nodes(y0)
    probe = _Analyser(res, sym, False, False, rows)
    a0, hw0 = probe.measures(nodes0)
    an = _Analyser(res, sym, bool(sym.mirror is not None and a0 < SYMMETRY_TOL),
                   bool(sym.half_wave and hw0 < SYMMETRY_TOL), rows)
    parts = []
    try:
        for direction in (-1.0, 1.0):
            if direction < 0 and y0[res.size] <= band[0] + 1e-12 or direction > 0 and y0[res.size] >= band[1] - 1e-12:
                continue
            watch = _Joined(families, res, sym, own=(parts[0][1][0], parts[0][1][3]) if parts else None)
            part = _follow(res, y0, res.size, direction, opts, opts.cover_steps, band, an, stop_extra=watch)
            if watch.family != -1:
                part[4][-1] = "joined" if watch.family >= 0 else "closed"
                f_end = res.omega(part[0][-1]) / (2 * math.pi)
                part[5].append(f"ran onto the path of family {watch.family} at {f_end:.6g} Hz: stopped there"
                               if watch.family >= 0 else f"came back onto its own run down at {f_end:.6g} Hz (an "
                               "isola): stopped there")
            parts.append((direction, part))
    except (ContinuationError, ShootingError) as exc:
        return f"continuation failed: {' '.join(str(exc).split())[:120]}"
    Y, data, folds, seg, st, notes = _join(parts)
    fam = _family("isolated", 1, res, Y, data, folds, seg, st, [f"started from the guess at {fq:.6g} Hz"] + notes,
                  None, time.perf_counter() - t0, an)
    fam.start_hz = fq
    families.append(fam)
    residuals[len(families) - 1] = (res, an)
    if switching:
        _switch_all(families, switches, residuals, opts, band, rows, sym, budget, root=len(families) - 1,
                    max_new=max_new)
    return ""


__all__ = ["ExactFRC", "ExactFRCOptions", "FAMILY_KINDS", "OrbitFamily", "Symmetry", "covered", "exact_frc",
           "find_symmetry", "first_orbit", "hb_start"]
