"""Forced-response curves (FRCs) of a gap system under a harmonic load, by harmonic balance.

The system (:class:`reduced.models.gaps.GapSystem`) driven by one harmonic load along b,

    M x'' + C x' + K x + B^T f(B x) = b P cos(Omega t + phi),

is balanced on H harmonics, condensed onto the contact coordinates with the stop forces
projected exactly over their contact intervals (:mod:`reduced.periodic.forced_balance`: its
size does not grow with the model). :func:`frc` continues the curve R = 0 in the excitation
frequency by the pseudo-arclength driver (:func:`reduced.periodic.continuation.continue_branch`)
in the scaled unknowns

    y = [q / x_ref, ln(Omega / omega_ref)],

rows scaled by 1 / x_ref, so it turns at folds and through the narrow tongues of internal
resonances (a step whose secant leaves the new tangent by more than ``max_angle_deg`` is
refused, which keeps the path on its own sheet where the tongue's sides nearly touch).
Each point's stability (monodromy, Hill) and the bifurcations between points come from
:mod:`reduced.periodic.forced_stability`; the reference, a stepped sine by the exact
integrator, from :mod:`reduced.periodic.stepped_sine`.

**Amplitude** at each output point r (a row of the point map): max over one period of
|r . x(tau)| (sampled, then refined by Newton on d/dtau (r . x) = 0 on the Fourier series,
so exact to round-off rather than to the sample spacing), and per harmonic sqrt(c_k^2 + s_k^2).
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.periodic import MAX_HARMONICS
from reduced.periodic.continuation import (
    STEP_FIELDS,
    Branch,
    ContinuationError,
    ContinuationOptions,
    continue_branch,
    tangent,
)
from reduced.periodic.exact_hb import default_root_samples
from reduced.periodic.forced_balance import ForcedBalance, ForcedResidual
from reduced.periodic.forced_stability import HILL_TOL, BranchStability, branch_stability
from reduced.periodic.hb import NewtonError, _phases, _synthesis_matrix, newton

AMPLITUDE_NEWTON_STEPS = 6  # Newton steps refining the phase of max |x| (quadratic: 2-3 suffice)
HARMONIC_SETS = ("all", "odd")
FRC_STEPS = ContinuationOptions(ds=0.02, ds_max=0.05, max_steps=5000)  # in the scaled unknowns y


# -- amplitudes -----------------------------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _synthesis(H: int, N: int) -> np.ndarray:
    """(N, 2H+1) synthesis matrix on N phases (cached: read-only)."""
    E = _synthesis_matrix(H, _phases(N))
    E.flags.writeable = False
    return E


def max_abs_over_period(X: np.ndarray, rows: np.ndarray, samples: int | None = None) -> np.ndarray:
    """(p,) m, max over tau of |rows[j] . x(tau)| for X (2H+1, n): the largest of ``samples`` phases,
    refined by Newton on the derivative of the Fourier series.

    Parameters
    ----------
    X : (2H+1, n) m, HB coefficients
    rows : (p, n) the output points as rows of the DOFs
    samples : phases sampled first (default max(64, 8 (2H+1)))

    Returns
    -------
    ndarray
        (p,) m, never below the largest sample.
    """
    H = (X.shape[0] - 1) // 2
    C = np.asarray(rows, float) @ X.T  # (p, 2H+1): each point's own series
    N = samples or max(64, 8 * (2 * H + 1))
    xs = C @ _synthesis(H, N).T  # (p, N)
    i = np.argmax(np.abs(xs), axis=1)
    tau = 2.0 * np.pi * i / N
    k = np.arange(1, H + 1, dtype=float)
    c, s = C[:, 1::2], C[:, 2::2]
    for _ in range(AMPLITUDE_NEWTON_STEPS):
        ck, sk = np.cos(np.outer(tau, k)), np.sin(np.outer(tau, k))
        d1 = np.sum(k * (-c * sk + s * ck), axis=1)
        d2 = np.sum(k**2 * (-c * ck - s * sk), axis=1)
        ok = d2 != 0.0
        step = np.where(ok, d1 / np.where(ok, d2, 1.0), 0.0)
        tau = tau - np.clip(step, -np.pi / N, np.pi / N)  # stay by the sample's own extremum
    ck, sk = np.cos(np.outer(tau, k)), np.sin(np.outer(tau, k))
    refined = np.abs(C[:, 0] + np.sum(c * ck + s * sk, axis=1))
    return np.maximum(refined, np.abs(xs[np.arange(len(i)), i]))


def harmonic_amplitudes(X: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(p, H + 1) m: |c_0| and sqrt(c_k^2 + s_k^2), k = 1..H, of each point ``rows[j] . x`` for X (2H+1, n).

    Parameters
    ----------
    X : (2H+1, n) m, HB coefficients
    rows : (p, n) the output points as rows of the DOFs

    Returns
    -------
    ndarray
        (p, H + 1) m, the amplitude of each harmonic at each point.
    """
    C = np.asarray(rows, float) @ X.T
    return np.column_stack([np.abs(C[:, 0]), np.hypot(C[:, 1::2], C[:, 2::2])])


# -- the curve ------------------------------------------------------------------------------------
@dataclass(eq=False)
class FRCBranch:
    """One forced-response curve: points in continuation order, with stability and bifurcations.

    ``multipliers`` are those of :func:`reduced.periodic.forced_stability.orbit_monodromy`
    (every point); ``hill`` holds Hill's multipliers at the points ``hill_index`` (all, or a
    subset where Hill's matrix is large). ``bifurcations`` lists (point index, kind), kind in
    :data:`reduced.periodic.forced_stability.BIFURCATIONS`, the index being the first point past
    the crossing; ``folds`` the indices where the curve turned in frequency.

    Attributes
    ----------
    amplitude_N : float
        N, P.
    H : int
        Harmonics.
    harmonics : {'all', 'odd'}
        The harmonic set balanced.
    freq_hz : (k,) ndarray of float
        Hz, excitation frequency of each point.
    omega : (k,) ndarray of float
        rad/s.
    X : (k, 2H+1, n) ndarray of float
        m, HB coefficients of every DOF.
    z : (k, size) ndarray of float
        Free unknowns of the condensed balance.
    point_names : tuple of str
        Names of the output points.
    point_rows : (p, n) ndarray of float
        The output points as rows of the DOFs.
    amplitude_m : (k, p) ndarray of float
        m, max |x| over one period at each point.
    harmonic_amplitude_m : (k, p, H + 1) ndarray of float
        m, amplitude of each harmonic at each point.
    multipliers : (k, 2n) ndarray of complex
        Floquet multipliers of the orbit monodromy, by decreasing modulus.
    stable : (k,) ndarray of bool
        From the multipliers.
    hill_index : (h,) ndarray of int
        Points where Hill's method ran.
    hill : (h, 2n) ndarray of complex
        Hill's multipliers there.
    bifurcations : list of (int, str)
        (first point past the crossing, kind).
    folds : list of int
        Points where the curve turned in frequency.
    balance : ForcedBalance
        The condensed balance solved.
    x_ref : float
        m, scale of the contact coordinates in the continuation.
    status : str
        :func:`reduced.periodic.continuation.continue_branch`'s status of each piece, joined by '+'.
    n_rejected : int
        Continuation steps rejected.
    wall_s : float
        s, continuation and amplitudes.
    stability_wall_s : float
        s, monodromy and Hill.
    notes : list of str
        Remarks (where each piece ended).
    segment : (k,) ndarray of int
        Continued piece of each point (0; 1 for a second piece).
    """

    amplitude_N: float
    H: int
    harmonics: str  # "all" | "odd"
    freq_hz: np.ndarray  # (k,)
    omega: np.ndarray  # (k,) rad/s
    X: np.ndarray  # (k, 2H+1, n) m, every DOF
    z: np.ndarray  # (k, size) free unknowns of the condensed balance
    point_names: tuple[str, ...]
    point_rows: np.ndarray  # (p, n) the output points as rows of the DOFs
    amplitude_m: np.ndarray  # (k, p) max |x| over one period at each point
    harmonic_amplitude_m: np.ndarray  # (k, p, H + 1)
    multipliers: np.ndarray  # (k, 2n) complex, orbit monodromy
    stable: np.ndarray  # (k,) bool
    hill_index: np.ndarray  # (h,) points where Hill's method ran
    hill: np.ndarray  # (h, 2n) complex
    bifurcations: list
    folds: list
    balance: ForcedBalance
    x_ref: float
    status: str  # continue_branch's status of each piece, joined by "+" ("stop": left the band)
    n_rejected: int
    wall_s: float  # continuation and amplitudes
    stability_wall_s: float = 0.0  # monodromy and Hill
    notes: list = field(default_factory=list)
    segment: np.ndarray | None = None  # (k,) continued piece of each point (0; 1 for a second piece, see frc)

    def __post_init__(self) -> None:
        if self.segment is None:
            self.segment = np.zeros(len(self.freq_hz), int)

    def pieces(self) -> list[np.ndarray]:
        """Indices of the points of each continued piece (points of different pieces are not joined)."""
        return [np.flatnonzero(self.segment == k) for k in np.unique(self.segment)]

    @property
    def max_multiplier(self) -> np.ndarray:
        return np.abs(self.multipliers[:, 0])

    @property
    def hill_stable(self) -> np.ndarray:
        return np.max(np.abs(self.hill), axis=1, initial=0.0) <= 1.0 + HILL_TOL

    def bifurcation_labels(self) -> list[str]:
        """Per point: '' or the kind of the bifurcation found just before it."""
        labels = [""] * len(self.freq_hz)
        for i, kind in self.bifurcations:
            labels[i] = kind
        return labels


def frc(
    system: GapSystem,
    load: np.ndarray,
    amplitude_N: float,
    f_min_hz: float,
    f_max_hz: float,
    H: int = 1,
    *,
    harmonics: str = "all",
    N: int | None = None,
    phase_deg: float = 0.0,
    point_rows: np.ndarray | None = None,
    point_names: tuple[str, ...] | None = None,
    x_ref: float | None = None,
    continuation: ContinuationOptions | None = None,
    stability: bool = True,
    hill_points: int | None = None,
    progress=None,
    **steps,
) -> FRCBranch:
    """The FRC of ``system`` under ``load`` (n,) x amplitude_N cos(Omega t + phase), from f_min to f_max.

    Parameters
    ----------
    system : the gap system (its damping C is used)
    load : (n,) force direction b (a point's row for a force at that point)
    amplitude_N : N, P > 0
    f_min_hz, f_max_hz : Hz, the band; the curve starts at f_min and stops when it leaves the
        band (above f_max, or below f_min after a fold). If it ends inside the band (the step
        fell below its minimum in an internal-resonance tongue, or ``max_steps``), a second
        piece is continued down from f_max (``FRCBranch.segment``; the notes say where each ended)
    H : harmonics
    harmonics : "all" or "odd" (half-wave symmetric response, module docstring)
    N : phases bracketing the extrema of each contact coordinate (default
        :func:`reduced.periodic.exact_hb.default_root_samples`)
    phase_deg : deg, phase of the load, amplitude_N cos(Omega t + phase)
    point_rows, point_names : (p, n) output points (default: the DOFs)
    x_ref : m, scale of the contact coordinates in the continuation (default
        :func:`default_x_ref`)
    continuation : the step control in the scaled unknowns (default :data:`FRC_STEPS`); its
        ``max_angle_deg`` also bounds the turn between a step's secant and the new tangent
    stability : orbit monodromy at every point (and Hill's method, see ``hill_points``)
    hill_points : Hill's method at every point (None) or at most this many, evenly spread
    progress : None or a callable taking the fraction of the band done
    **steps : fields of :class:`reduced.periodic.continuation.ContinuationOptions` replacing
        those of ``continuation`` (``ds=0.01, max_steps=2000``)

    Returns
    -------
    FRCBranch
        The curve's points with amplitudes, stability and bifurcations. Arguments are checked
        before any work (one-line :class:`reduced._checks.InvalidArgument`).
    """
    _check.gap_system(system)
    b = _check.vector("load", load, system.n)
    if not np.any(b):
        raise _check.InvalidArgument("load must have a nonzero entry (the force direction b)")
    P = _check.positive("amplitude_N", amplitude_N, "N")
    f0 = _check.positive("f_min_hz", f_min_hz, "Hz")
    f1 = _check.positive("f_max_hz", f_max_hz, "Hz")
    if not f1 > f0:
        raise _check.InvalidArgument(f"f_max_hz must exceed f_min_hz = {f0:g} Hz, got {f1!r}")
    H = _check.integer("H", H, lo=1, hi=MAX_HARMONICS)
    harmonics = _check.choice("harmonics", harmonics, HARMONIC_SETS)
    if N is not None:
        N = _check.integer("N", N, lo=2 * H + 1)
    phase_deg = _check.number("phase_deg", phase_deg)
    rows, names = _output_points(system, point_rows, point_names)
    if x_ref is not None:
        x_ref = _check.positive("x_ref", x_ref, "m")
    if continuation is not None and not isinstance(continuation, ContinuationOptions):
        raise _check.InvalidArgument(f"continuation must be a ContinuationOptions, got {_check.show(continuation)}")
    for key in steps:
        if key not in STEP_FIELDS:
            raise _check.InvalidArgument(f"unknown option {key!r} (known step fields: {', '.join(STEP_FIELDS)})")
    step_control = (continuation or FRC_STEPS).replace(**steps)
    stability = _check.flag("stability", stability)
    if hill_points is not None:
        hill_points = _check.integer("hill_points", hill_points, lo=0)
    _check.callback("progress", progress)
    if system.m == 0:
        raise _check.InvalidArgument("system has no stops: its FRC is the linear FRF (use linear_frf)")
    fb = ForcedBalance(system, b, P, phase_deg, H, N or default_root_samples(H), harmonics == "odd")
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        return _frc(fb, f0, f1, rows, names, x_ref, step_control, stability, hill_points, progress)


def _output_points(system: GapSystem, point_rows, point_names) -> tuple[np.ndarray, tuple[str, ...]]:
    """(rows (p, n), names) of the output points: the DOFs by default; refused in one line if they
    do not fit the system."""
    if point_rows is None:
        rows = np.eye(system.n)
        names = tuple(point_names or system.dof_names)
    else:
        rows = np.atleast_2d(_check.series("point_rows", point_rows, ndim=2))
        if rows.shape[1] != system.n:
            raise _check.InvalidArgument(f"point_rows must have {system.n} columns, got shape {rows.shape}")
        names = tuple(point_names) if point_names is not None else tuple(f"p{j + 1}" for j in range(rows.shape[0]))
    if len(names) != rows.shape[0]:
        raise _check.InvalidArgument(f"point_names must name {rows.shape[0]} points, got {len(names)}")
    return rows, names


def linear_frf(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz: np.ndarray,
               rows: np.ndarray | None = None) -> np.ndarray:
    """(k, p) m: |rows (K - Omega^2 M + i Omega C)^-1 b P| with every stop open (the FRF of the linear part).

    Parameters
    ----------
    system : the gap system (its stops are ignored)
    load : (n,) force direction b
    amplitude_N : N, P
    freq_hz : (k,) Hz
    rows : (p, n) output points (default: the DOFs)

    Returns
    -------
    ndarray
        (k, p) m, the amplitude at each frequency and point.
    """
    rows = np.eye(system.n) if rows is None else np.atleast_2d(rows)
    out = []
    for f in np.atleast_1d(freq_hz):
        w = 2.0 * np.pi * float(f)
        x = np.linalg.solve(system.K - w**2 * system.M + 1j * w * system.C, np.asarray(load, float) * amplitude_N)
        out.append(np.abs(rows @ x))
    return np.array(out)


def open_gap_orbits(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz: np.ndarray,
                    rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """The harmonic orbits of the system with every stop open, x(t) = Re(X e^{i Omega t}),
    X = (K - Omega^2 M + i Omega C)^-1 b P, and whether each is an orbit of the gap system.

    Over a period, max |r x(t)| = |r X| and the largest penetration of stop j is
    max_t side_j (B_j x(t) - o_j) = |B_j X| - side_j o_j. Where that is negative for every stop the
    orbit closes none: it is an exact periodic orbit of the gap system (no harmonics, no truncation),
    whatever other orbits coexist with it at that frequency. It is asymptotically stable when the open
    system is (every eigenvalue of its state matrix has Re < 0): a small perturbation decays before it
    can close a stop, the orbit's margin to every stop being positive.

    Parameters
    ----------
    system : the gap system
    load : (n,) force direction b
    amplitude_N : N, P
    freq_hz : (k,) Hz
    rows : (p, n) output points

    Returns
    -------
    tuple
        ((k, p) m the amplitudes max |r x|, (k,) m the largest penetration over a period of any stop
        (<= 0: no stop closes), whether the orbits are asymptotically stable).
    """
    rows = np.atleast_2d(rows)
    b = np.asarray(load, float) * amplitude_N
    amp, pen = [], []
    for f in np.atleast_1d(freq_hz):
        w = 2.0 * np.pi * float(f)
        X = np.linalg.solve(system.K - w**2 * system.M + 1j * w * system.C, b)
        amp.append(np.abs(rows @ X))
        pen.append(float(np.max(np.abs(system.B @ X) - system.side * system.offset)) if system.m else -math.inf)
    n = system.n
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(system.M, system.K),
                                                   -np.linalg.solve(system.M, system.C)]])
    stable = bool(np.max(np.linalg.eigvals(A).real) < 0.0)
    return np.array(amp).reshape(-1, rows.shape[0]), np.array(pen), stable


def default_x_ref(fb: ForcedBalance, f_min_hz: float, f_max_hz: float) -> float:
    """m, scale of the contact coordinates: their largest linear open-stop response over the band,
    but no more than the stops let through (largest stop offset + the closed-state response).

    Parameters
    ----------
    fb : the condensed balance
    f_min_hz, f_max_hz : Hz, the band (400 log-spaced frequencies are tried)

    Returns
    -------
    float
        m, at least 1e-300.
    """
    s = fb.system
    f = np.geomspace(f_min_hz, f_max_hz, 400)
    peak = {}
    for state, K in (("open", s.K), ("closed", s.closed_stiffness())):
        amp = 0.0
        for fk in f:
            w = 2 * np.pi * fk
            x = np.linalg.solve(K - w**2 * s.M + 1j * w * s.C, fb.b * fb.amplitude_N)
            amp = max(amp, float(np.max(np.abs(fb.U @ x))))
        peak[state] = amp
    cap = peak["closed"] + float(np.max(np.abs(s.offset)))
    return max(min(peak["open"], cap), 1e-300)


def _start(res: ForcedResidual, omega: float) -> np.ndarray:
    """y of the solution at ``omega``: Newton from the linear response, or, where that fails (the
    stops already closed at the start frequency), the load raised from where the linear response
    leaves every stop open, in steps that halve (in log) when Newton fails."""
    fb, nz = res.fb, res.size
    lw = math.log(omega / res.omega_ref)
    z_lin = fb.linear_z(omega)

    def solve(scale, guess):
        # the balance is affine in the load: R(z; scale) = R(z) + (1 - scale) q_lin
        shift = (1.0 - scale) * z_lin / res.x_ref

        def fun(v):
            R, J = res(np.append(v, lw))
            return R + shift, J[:, :nz]

        return newton(fun, guess, tol=1e-12, max_iter=40).y

    try:
        return np.append(solve(1.0, z_lin / res.x_ref), lw)
    except NewtonError:
        pass
    s = fb.system
    q = fb.full_q(z_lin)
    x = q.T @ _synthesis_matrix(fb.H, _phases(256)).T  # (u, 256)
    reach = max(float(np.max(np.abs(x[fb.row_of[j]]) / abs(s.offset[j]))) if s.offset[j] else np.inf
                for j in range(s.m))
    scale = min(0.99 / max(reach, 1e-300), 1.0)
    v = z_lin * scale / res.x_ref
    step = 0.25  # in log10 of the load scale
    while scale < 1.0:
        nxt = min(scale * 10.0**step, 1.0)
        try:
            v = solve(nxt, v * (nxt / scale))
            scale = nxt
            step = min(2.0 * step, 0.5)
        except NewtonError:
            step *= 0.5
            if step < 1e-4:
                raise ContinuationError(f"start point not found at {omega / (2 * np.pi):.4g} Hz: the load could "
                                        f"be raised only to {scale:.3g} of {fb.amplitude_N:g} N; start lower "
                                        "in frequency, where the stops are open") from None
    return np.append(v, lw)



@dataclass(frozen=True)
class _Band:
    """The band [f_min, f_max] in the continuation's frequency coordinate ln(Omega / omega_ref),
    entry ``i_w`` of y."""

    i_w: int
    y_lo: float  # ln(omega_min / omega_ref)
    y_hi: float  # ln(omega_max / omega_ref)

    def left(self, y: np.ndarray) -> bool:
        """Whether y lies past the band (the stop of the continuation)."""
        return y[self.i_w] > self.y_hi or y[self.i_w] < self.y_lo - 1e-12

    def fraction(self, y: np.ndarray) -> float:
        """The part of the band below y's frequency."""
        return min(max((y[self.i_w] - self.y_lo) / (self.y_hi - self.y_lo), 0.0), 1.0)


def _frc(fb, f0, f1, rows, names, x_ref, steps, stability, hill_points, progress) -> FRCBranch:
    t0 = time.perf_counter()
    if x_ref is None:
        x_ref = default_x_ref(fb, f0, f1)
    w0, w1 = 2 * np.pi * f0, 2 * np.pi * f1
    res = ForcedResidual(fb, x_ref, w1)
    band = _Band(res.size, math.log(w0 / w1), 0.0)  # omega_ref = w1: the top of the band
    pieces, notes = _continue_pieces(res, band, w0, f1, steps, progress)
    Y, segment, folds, n_rej, status = _join_pieces(pieces, band, w1, notes)
    i_w = band.i_w
    Z = Y[:, :i_w] * x_ref
    omega = w1 * np.exp(Y[:, i_w])
    X = np.array([fb.response(z, w) for z, w in zip(Z, omega, strict=True)])
    amp = np.array([max_abs_over_period(x, rows) for x in X])
    harm = np.array([harmonic_amplitudes(x, rows) for x in X])
    wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    if stability:
        st = branch_stability(fb, Z, omega, folds, segment, hill_points)
    else:
        st = BranchStability.skipped(len(Z), 2 * fb.n, folds)
    return FRCBranch(fb.amplitude_N, fb.H, "odd" if fb.odd else "all", omega / (2 * np.pi), omega, X, Z, names,
                     rows, amp, harm, st.multipliers, st.stable, st.hill_index, st.hill, st.bifurcations, folds, fb,
                     x_ref, "+".join(status), n_rej, wall, time.perf_counter() - t1, notes, segment)


def _continue_pieces(res: ForcedResidual, band: _Band, w0: float, f1: float, steps: ContinuationOptions,
                     progress) -> tuple[list[Branch], list[str]]:
    """The continued pieces of the curve and notes on them: up from the bottom of the band and, if
    that piece ends inside the band, a second one down from its top."""
    fb, i_w, w1 = res.fb, band.i_w, res.omega_ref
    cos_secant = math.cos(math.radians(steps.max_angle_deg))

    def prog(y):
        if progress is not None:
            progress(band.fraction(y))

    def reject(y_old, y_new):
        # a step that lands on a neighbouring sheet of the curve (the sides of a narrow
        # internal-resonance tongue lie within a step of each other) has a secant far from the
        # new tangent; on the curve's own sheet the two differ by about half the tangent's turn
        d = y_new - y_old
        dn = float(np.linalg.norm(d))
        if dn == 0.0:
            return False
        t = tangent(res(y_new)[1], d / dn)
        return abs(float(t @ d)) < cos_secant * dn

    # where a stop first closes the curve turns sharply (the stop force grows like the 3/2 power
    # of the excess amplitude): continue_branch's corner steps may fix a fundamental coefficient
    kp = list(fb.keep)
    corner = tuple(int(kp.index(h) * fb.u + r) for h in (1, 2) if h in kp for r in range(fb.u))

    def piece(w_start, direction):
        try:
            return continue_branch(res, _start(res, w_start), param=i_w, direction=direction, options=steps,
                                   stop=band.left, progress=prog, monitor=corner, reject=reject)
        except ContinuationError as exc:
            raise ContinuationError(f"FRC at {fb.amplitude_N:g} N, H = {fb.H}: {exc}") from None

    pieces = [piece(w0, 1.0)]
    notes = []
    if pieces[0].status != "stop":
        # the curve ended inside the band (an internal-resonance tongue it could not pass): take it
        # up again from the top of the band, downwards, as a second segment (not joined to the first)
        f_end = w1 * math.exp(pieces[0].y[-1][i_w]) / (2 * np.pi)
        notes.append(f"segment 0 ended early ({pieces[0].status}) at {f_end:.4g} Hz; segment 1 continued "
                     f"down from {f1:g} Hz")
        try:
            pieces.append(piece(w1 * (1.0 - 1e-9), -1.0))
        except ContinuationError as exc:
            notes.append(f"segment 1 failed: {exc}")
    return pieces, notes


def _join_pieces(pieces: list[Branch], band: _Band, w1: float, notes: list[str]):
    """(points y, piece of each point, fold indices, rejected steps, status of each piece) of the
    pieces laid end to end, each without a last point past the band; a note if the second piece
    also ended early."""
    i_w = band.i_w
    Ys, seg, folds, n_rej, status = [], [], [], 0, []
    for k, br in enumerate(pieces):
        Y = br.y
        if len(Y) > 1 and band.left(Y[-1]):  # the last point lies just past the band
            Y = Y[:-1]
        folds += [i + sum(len(y) for y in Ys) for i, c in br.folds if c == i_w and i < len(Y)]
        Ys.append(Y)
        seg.append(np.full(len(Y), k))
        n_rej += br.n_rejected
        status.append(br.status)
    if len(pieces) > 1 and pieces[1].status != "stop":
        notes.append(f"segment 1 ended early ({pieces[1].status}) at "
                     f"{w1 * math.exp(pieces[1].y[-1][i_w]) / (2 * np.pi):.4g} Hz")
    return np.concatenate(Ys), np.concatenate(seg), sorted(set(folds)), n_rej, status


def solution_at_frequency(br: FRCBranch, freq_hz: float, amplitude_ref: float | None = None, col: int = 0,
                          stable_only: bool = True):
    """(amplitudes (p,), index of the piece, X (2H+1, n)) of the HB solution exactly at ``freq_hz`` on
    the piece of the curve bracketing it (stable at both ends if ``stable_only``) whose amplitude
    at point ``col`` is nearest ``amplitude_ref``: Newton at fixed frequency from the
    interpolated point.

    Parameters
    ----------
    br : the curve
    freq_hz : Hz
    amplitude_ref : m, the amplitude at point ``col`` the solution should be nearest (None: the
        first piece found)
    col : the output point compared
    stable_only : only pieces stable at both ends

    Returns
    -------
    tuple
        (amplitudes (p,) m, i of the bracketing points i and i + 1, X (2H+1, n)), or (None, -1, None)
        where no such piece brackets the frequency.
    """
    res = ForcedResidual(br.balance, br.x_ref, 2 * np.pi * br.freq_hz.max())
    nz = res.size
    lw = math.log(2 * np.pi * freq_hz / res.omega_ref)
    f = br.freq_hz
    best = (None, -1, None)
    for i in range(len(f) - 1):
        if not (min(f[i], f[i + 1]) <= freq_hz <= max(f[i], f[i + 1])) or f[i] == f[i + 1]:
            continue
        if br.segment[i] != br.segment[i + 1]:
            continue
        if stable_only and not (br.stable[i] and br.stable[i + 1]):
            continue
        t = (freq_hz - f[i]) / (f[i + 1] - f[i])
        guess = ((1 - t) * br.z[i] + t * br.z[i + 1]) / br.x_ref

        def fun(v):
            R, J = res(np.append(v, lw))
            return R, J[:, :nz]

        try:
            v = newton(fun, guess, tol=1e-12, max_iter=30).y
        except NewtonError:
            continue
        X = br.balance.response(v * br.x_ref, 2 * np.pi * freq_hz)
        amp = max_abs_over_period(X, br.point_rows)
        if best[0] is None or (amplitude_ref is not None
                               and abs(amp[col] - amplitude_ref) < abs(best[0][col] - amplitude_ref)):
            best = (amp, i, X)
    return best


__all__ = [
    "FRC_STEPS",
    "FRCBranch",
    "HARMONIC_SETS",
    "default_x_ref",
    "frc",
    "harmonic_amplitudes",
    "linear_frf",
    "max_abs_over_period",
    "solution_at_frequency",
]
