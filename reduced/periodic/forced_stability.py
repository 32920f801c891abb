"""Stability and bifurcations of forced periodic orbits (the forced-response curves of
:mod:`reduced.periodic.frc`); the free (NNM) orbits' are in :mod:`reduced.periodic.stability`.

A forced orbit has no trivial multiplier: it is stable when every Floquet multiplier
|mu| < 1. Three ways, compared in the frc stage's output:

- :func:`orbit_monodromy` (every point): the variational equation along the HB orbit is
  piecewise constant, y' = A_s y with A_s the state matrix of the contact state s, between
  the contact events the exact projection has already located, so Phi = prod exp(A_s tau_s)
  is exact for the HB orbit (the saltation matrices of penalty stops are identities);
- :func:`forced_hill` (Hill's method on the full system and all harmonics, the exponents of
  the first zone |Im lam| <= Omega / 2; its matrix is 2n (2H+1) square, so it is run on every
  point only where that is small);
- :func:`floquet_by_shooting`: the exact periodic orbit of the forced exact flow
  (:class:`reduced.transient.flow.Flow` with the load), shot from the HB orbit, and the
  eigenvalues of its monodromy (the reference).

**Bifurcations** are where multipliers leave the unit circle between consecutive points
(:func:`bifurcations`): through +1 a *fold* (saddle-node, where the curve turns in frequency)
or, where the curve does not turn, a *branch point* (a pitchfork: for the symmetric
three-mass model driven at x2, the symmetric orbit losing stability to an asymmetric one);
through -1 a *period doubling*; as a complex pair a *Neimark-Sacker* bifurcation.

:func:`branch_stability` runs the monodromy on every point of a curve, Hill's method on some,
and finds the bifurcations between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, lu_factor, lu_solve

from reduced.models.gaps import GapSystem
from reduced.periodic.forced_balance import ForcedBalance
from reduced.periodic.hb import _derivative_matrix, _phases, _synthesis_matrix
from reduced.periodic.shooting import ShootingError
from reduced.periodic.stability import HILL_TOL

STABILITY_TOL = 1e-6  # |mu| - 1 above this is unstable (monodromy and shooting: exact to ~1e-12)
REAL_TOL = 1e-3  # rad: a multiplier within this angle of the real axis is real
BIFURCATIONS = ("fold", "branch_point", "period_doubling", "neimark_sacker")


# -- stability ----------------------------------------------------------------------------------
def state_matrix(system: GapSystem, active: np.ndarray) -> np.ndarray:
    """A_s (2n, 2n) of y = [x; v] with the stops in ``active`` closed: y' = A_s y + const.

    Parameters
    ----------
    system : the gap system
    active : (m,) bool, the closed stops

    Returns
    -------
    ndarray
        [[0, I], [-M^-1 K_s, -M^-1 C]] with K_s the stiffness of that contact state.
    """
    Ks, _ = system.state_matrices(active)
    n = system.n
    Minv = np.linalg.inv(system.M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ Ks, -Minv @ system.C]])


def orbit_monodromy(system: GapSystem, intervals: list, omega: float) -> np.ndarray:
    """Phi (2n, 2n): the monodromy of the variational equation along a periodic orbit whose stop j
    is closed on the phase intervals ``intervals[j] = (alpha, beta)`` (radians, from tau = 0).

    Between events the variational equation is y' = A_s y with the contact state s constant,
    and the saltation matrices of penalty stops are identities (the force is continuous
    through a crossing), so Phi = exp(A_{s_K} tau_K / Omega) ... exp(A_{s_1} tau_1 / Omega).

    Parameters
    ----------
    system : the gap system
    intervals : per stop, (alpha, beta) arrays of the starts and ends of its closed intervals
        (:meth:`reduced.periodic.forced_balance.ForcedBalance.contact`)
    omega : rad/s, the orbit's angular frequency (period 2 pi / omega)

    Returns
    -------
    ndarray
        Phi (2n, 2n), the monodromy from tau = 0 over one period.
    """
    two_pi = 2.0 * math.pi
    ev = [0.0, two_pi]
    closed_at = []  # (j, start, end) unrolled to [0, 2 pi)
    for j, (a, b) in enumerate(intervals):
        for lo, hi in zip(a, b, strict=True):
            for lo_, hi_ in ((lo, min(hi, two_pi)), (0.0, hi - two_pi)) if hi > two_pi else ((lo, hi),):
                if hi_ > lo_:
                    closed_at.append((j, lo_, hi_))
                    ev += [lo_, hi_]
    ev = np.unique(np.clip(ev, 0.0, two_pi))
    Phi = np.eye(2 * system.n)
    cache = {}
    for t0, t1 in zip(ev[:-1], ev[1:], strict=True):
        if t1 <= t0:
            continue
        mid = 0.5 * (t0 + t1)
        active = np.zeros(system.m, bool)
        for j, lo, hi in closed_at:
            if lo <= mid < hi:
                active[j] = True
        key = active.tobytes()
        if key not in cache:
            cache[key] = state_matrix(system, active)
        Phi = expm(cache[key] * ((t1 - t0) / omega)) @ Phi
    return Phi


def multipliers_of(Phi: np.ndarray) -> np.ndarray:
    """Eigenvalues of Phi sorted by decreasing modulus.

    Parameters
    ----------
    Phi : (2n, 2n) a monodromy matrix

    Returns
    -------
    ndarray
        (2n,) complex Floquet multipliers, largest |mu| first (ties kept in eigvals' order).
    """
    mu = np.linalg.eigvals(Phi)
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def forced_hill(fb: ForcedBalance, z: np.ndarray, omega: float) -> np.ndarray:
    """(2n,) Floquet multipliers of the forced HB orbit by Hill's method, by decreasing |mu|.

    Full system, all 2H+1 harmonics (perturbations may break the orbit's half-wave symmetry):
    (J2 lam^2 + J1 lam + J0) p = 0 with J0 = A(Omega) + dF/dX, J1 = 2 Omega kron(Nab, M) + kron(I, C),
    J2 = kron(I, M) (:meth:`reduced.periodic.hb.HarmonicBalance.hill_matrices`), solved as a
    standard eigenproblem of size 2n(2H+1). Each exponent recurs shifted by i k Omega, its
    eigenvector's harmonics shifted by k; the 2n kept are those whose eigenvectors are centred on
    the constant harmonic (Lazarus & Thomas 2010): with the perturbation's complex harmonics
    c_k (k = -H..H, from the cos/sin blocks: c_{+-k} = (p_ck -+ i p_sk) / 2), the centroid
    kappa = sum k |c_k|^2 / sum |c_k|^2 nearest 0. Unlike the first zone |Im lam| <= Omega / 2, this
    keeps the exponent of a mode far above H Omega (which has no copy in that zone: a lightly damped
    731 Hz mode at 10 Hz and H = 15). A real negative multiplier has its exponent on the zone's edge
    with both copies at |kappa| = 1/2: of eigenvalues on the edge (within 1e-6 Omega) those with
    Im lam < 0 are ranked last so each counts once. mu = exp(2 pi lam / Omega). On a half-wave
    symmetric orbit (``fb.odd``) the problem splits into the even and the odd harmonics
    (:func:`_parity_blocks`), solved as two eigenproblems of about half the size (the same exponents to
    round-off, a quarter of the work: tests/test_hill_parity.py) when J0 couples the parities by round-off
    only (:func:`_hill_blocks`; not for the friction balance, whose slider derivative is not shown to keep it).

    Parameters
    ----------
    fb : the condensed balance the orbit solves
    z : (fb.size,) m, the orbit's free unknowns
    omega : rad/s, the excitation frequency

    Returns
    -------
    ndarray
        (2n,) complex multipliers by decreasing modulus.
    """
    s = fb.system
    h, n = 2 * fb.H + 1, fb.n
    I = np.eye(h)
    Nab = fb.Nab
    J0 = np.kron(I, s.K) + omega**2 * np.kron(Nab @ Nab, s.M) + omega * np.kron(Nab, s.C)
    J0 += fb.force_jacobian(fb.full_q(z))
    Minv = np.linalg.inv(s.M)
    J1 = 2.0 * omega * np.kron(Nab, np.eye(n)) + np.kron(I, Minv @ s.C)  # J2^-1 J1
    J0 = np.kron(I, Minv) @ J0  # J2^-1 J0
    size = h * n
    lam, vec = [], []
    for rows in _hill_blocks(fb, J0, size):
        m = rows.size
        A = np.block([[np.zeros((m, m)), np.eye(m)], [-J0[np.ix_(rows, rows)], -J1[np.ix_(rows, rows)]]])
        lb, vb = np.linalg.eig(A)
        full = np.zeros((size, lb.size), complex)
        full[rows] = vb[:m]
        lam.append(lb)
        vec.append(full)
    lam, vec = np.concatenate(lam), np.concatenate(vec, axis=1)
    kappa = _harmonic_centroid(vec, fb.H, n)
    edge = np.abs(np.abs(lam.imag) - 0.5 * omega) <= 1e-6 * omega
    key = np.abs(kappa) + np.where(edge & (lam.imag < 0.0), 1.0, 0.0)  # one copy of an edge pair
    cand = lam[np.argsort(key, kind="stable")][: 2 * n]
    mu = np.exp(cand * (2.0 * np.pi / omega))
    return mu[np.argsort(-np.abs(mu), kind="stable")]


PARITY_ROUNDOFF = 1e-12  # cross-parity entries of J0 below this times its largest: the parities decoupled


def _hill_blocks(fb: ForcedBalance, J0: np.ndarray, size: int) -> list[np.ndarray]:
    """The index sets Hill's problem is solved on: the two parities (:func:`_parity_blocks`) where the balance
    keeps odd harmonics alone, its class says its force derivative keeps the parity
    (``ForcedBalance.HILL_PARITY_SPLIT``) and J0 couples the parities by round-off only; else all of them."""
    if fb.odd and getattr(fb, "HILL_PARITY_SPLIT", False):
        even, odd = _parity_blocks(fb.H, fb.n)
        cross = max(float(np.max(np.abs(J0[np.ix_(even, odd)]))), float(np.max(np.abs(J0[np.ix_(odd, even)]))))
        if cross <= PARITY_ROUNDOFF * float(np.max(np.abs(J0))):
            return [even, odd]
    return [np.arange(size)]


def _parity_blocks(H: int, n: int) -> list[np.ndarray]:
    """Indices of the even harmonics (0, 2, ...) and of the odd ones (1, 3, ...) in the harmonic-major
    layout of (2H+1) n coefficients [p_0, p_c1, p_s1, ...], n each.

    Along a half-wave symmetric orbit (odd harmonics only, symmetric stops) the force derivative holds even
    harmonics only (the contact intervals of a coordinate's two stops are half a period apart, so the odd
    moments of their sum cancel), and the linear part keeps each harmonic: Hill's problem couples harmonics of
    one parity only, two eigenproblems of about half the size (a quarter of the work each, twice).

    >>> [b.tolist() for b in _parity_blocks(2, 1)]
    [[0, 3, 4], [1, 2]]
    """
    k = (np.arange(2 * H + 1) + 1) // 2
    idx = np.arange((2 * H + 1) * n).reshape(2 * H + 1, n)
    return [idx[k % 2 == 0].ravel(), idx[k % 2 == 1].ravel()]


def _harmonic_centroid(P: np.ndarray, H: int, n: int) -> np.ndarray:
    """(m,) kappa = sum_k k |c_k|^2 / sum_k |c_k|^2 of each column of P (the (2H+1) n cos/sin coefficients
    of a perturbation, harmonic-major: [p_0, p_c1, p_s1, ...], n each), c_{+-k} = (p_ck -+ i p_sk) / 2.

    Examples
    --------
    >>> P = np.array([[0.0], [1.0], [-1j]])  # cos t - i sin t = e^{-i t}: all on k = -1
    >>> _harmonic_centroid(P, 1, 1).round(12).tolist()
    [-1.0]
    """
    m = P.shape[1]
    B = P.reshape(2 * H + 1, n, m)
    w_pos = np.zeros((H + 1, m))
    w_neg = np.zeros((H + 1, m))
    w_pos[0] = np.sum(np.abs(B[0]) ** 2, axis=0)
    for k in range(1, H + 1):
        c, sn = B[2 * k - 1], B[2 * k]
        w_pos[k] = np.sum(np.abs(0.5 * (c - 1j * sn)) ** 2, axis=0)
        w_neg[k] = np.sum(np.abs(0.5 * (c + 1j * sn)) ** 2, axis=0)
    k = np.arange(H + 1)[:, None]
    total = np.maximum(w_pos.sum(axis=0) + w_neg[1:].sum(axis=0), 1e-300)
    return (k * w_pos).sum(axis=0) / total - (k * w_neg).sum(axis=0) / total


def classify_crossing(mu: np.ndarray, tol: float) -> str:
    """How the multiplier nearest the unit circle among those outside it left: ``fold`` (real
    > 0), ``period_doubling`` (real < 0) or ``neimark_sacker`` (complex).

    Parameters
    ----------
    mu : the multipliers at a point past the crossing
    tol : |mu| - 1 above this is outside the unit circle

    Returns
    -------
    str
        One of ``fold``, ``period_doubling``, ``neimark_sacker`` (within :data:`REAL_TOL` rad of
        the real axis a multiplier is real).

    Examples
    --------
    >>> classify_crossing([1.2, 0.5], 1e-6), classify_crossing([-1.1, 0.5], 1e-6), classify_crossing([1.1j], 1e-6)
    ('fold', 'period_doubling', 'neimark_sacker')
    """
    mu = np.asarray(mu)
    out = mu[np.abs(mu) > 1.0 + tol]
    if out.size == 0:
        out = mu
    m = out[np.argmin(np.abs(out))]
    ang = abs(np.angle(m))
    if ang < REAL_TOL:
        return "fold"
    if ang > np.pi - REAL_TOL:
        return "period_doubling"
    return "neimark_sacker"


def bifurcations(multipliers: np.ndarray, tol: float, folds=()) -> list[tuple[int, str]]:
    """[(point index, kind)] where the number of multipliers with |mu| > 1 + tol changes.

    The index is the first point past the crossing; the kind is read at the point of the pair
    that has the crossing multiplier outside. A real crossing through +1 is a ``fold`` if the
    curve turns in frequency within one point of it (``folds``: indices of the turning points,
    continuation's own detection), else a ``branch_point``.

    Parameters
    ----------
    multipliers : (k, 2n) the multipliers of consecutive points
    tol : |mu| - 1 above this is outside the unit circle
    folds : indices of the points where the curve turns in frequency

    Returns
    -------
    list
        (index of the first point past the crossing, kind), kind in :data:`BIFURCATIONS`.
    """
    mu = np.asarray(multipliers)
    n_out = np.sum(np.abs(mu) > 1.0 + tol, axis=1)
    folds = {int(i) for i in folds}
    out = []
    for i in range(1, len(mu)):
        if n_out[i] == n_out[i - 1]:
            continue
        j = i if n_out[i] > n_out[i - 1] else i - 1
        kind = classify_crossing(mu[j], tol)
        if kind == "fold" and not folds & {i - 1, i, i + 1}:
            kind = "branch_point"
        out.append((i, kind))
    return out


# -- the stability of a curve -----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BranchStability:
    """The stability of the points of a forced-response curve.

    ``multipliers`` are those of :func:`orbit_monodromy` at every point; ``hill`` Hill's
    multipliers at the points ``hill_index``; ``bifurcations`` (point index, kind), kind in
    :data:`BIFURCATIONS`, the index being the first point past the crossing.

    Attributes
    ----------
    multipliers : (k, 2n) ndarray of complex
        Floquet multipliers of the orbit monodromy at every point, by decreasing modulus.
    stable : (k,) ndarray of bool
        All |mu| <= 1 + ``STABILITY_TOL``.
    bifurcations : list of (int, str)
        (first point past the crossing, kind in ``BIFURCATIONS``).
    hill_index : (h,) ndarray of int
        Points where Hill's method ran.
    hill : (h, 2n) ndarray of complex
        Hill's multipliers there.
    """

    multipliers: np.ndarray  # (k, 2n) complex, by decreasing modulus
    stable: np.ndarray  # (k,) bool
    bifurcations: list
    hill_index: np.ndarray  # (h,) points where Hill's method ran
    hill: np.ndarray  # (h, 2n) complex

    @classmethod
    def skipped(cls, k: int, size: int, folds: list) -> BranchStability:
        """No stability computed: k points all 'stable', the folds as the only bifurcations."""
        return cls(np.zeros((k, size), complex), np.ones(k, bool), [(i, "fold") for i in folds], np.zeros(0, int),
                   np.zeros((0, size), complex))


def branch_stability(fb: ForcedBalance, Z: np.ndarray, omega: np.ndarray, folds: list, segment: np.ndarray,
                     hill_points: int | None) -> BranchStability:
    """The stability of the points (Z[i], omega[i]) of a curve of the balance ``fb``.

    Parameters
    ----------
    fb : the condensed balance the points solve
    Z : (k, size) m, the free unknowns of each point
    omega : (k,) rad/s
    folds : indices where the curve turns in frequency (a crossing through +1 within one point
        of a fold is a fold, else a branch point)
    segment : (k,) the continued piece of each point; no bifurcation is reported between pieces
    hill_points : Hill's method at every point (None) or at most this many, evenly spread

    Returns
    -------
    BranchStability
        Monodromy multipliers at every point, Hill's at the chosen ones, the bifurcations.
    """
    n2 = 2 * fb.n
    mu = np.array([multipliers_of(orbit_monodromy(fb.system, fb.contact(fb.full_q(z))[2], w))
                   for z, w in zip(Z, omega, strict=True)])
    stable = np.max(np.abs(mu), axis=1) <= 1.0 + STABILITY_TOL
    bif = [b for b in bifurcations(mu, STABILITY_TOL, folds) if segment[b[0]] == segment[b[0] - 1]]
    k = len(Z)
    if hill_points is None or hill_points >= k:
        hidx = np.arange(k)
    elif hill_points == 0:
        hidx = np.zeros(0, int)
    else:
        hidx = np.unique(np.round(np.linspace(0, k - 1, hill_points)).astype(int))
    hill = np.array([forced_hill(fb, Z[i], omega[i]) for i in hidx]).reshape(len(hidx), n2)
    return BranchStability(mu, stable, bif, hidx, hill)


# -- Floquet multipliers by shooting on the forced exact flow --------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedOrbit:
    """A periodic orbit of the forced exact flow and its Floquet multipliers.

    Attributes
    ----------
    x0 : (n,) ndarray of float
        m, displacement at t = 0 (the load's phase origin).
    v0 : (n,) ndarray of float
        m/s, velocity at t = 0.
    period_s : float
        s, the load's period.
    monodromy : (2n, 2n) ndarray of float
        d y(T) / d y(0), y = [x; v].
    multipliers : (2n,) ndarray of complex
        Its eigenvalues, by decreasing modulus.
    closure : float
        |y(T) - y(0)| / max|y(0)|, displacements and velocities scaled apart.
    n_iter : int
        Newton iterations.
    """

    x0: np.ndarray  # m, (n,) at t = 0 (the load's phase origin)
    v0: np.ndarray  # m/s
    period_s: float
    monodromy: np.ndarray  # (2n, 2n)
    multipliers: np.ndarray  # (2n,) complex, by decreasing modulus
    closure: float  # |y(T) - y(0)| / max|y(0)| (displacement and velocity scaled apart)
    n_iter: int

    @property
    def max_multiplier(self) -> float:
        return float(np.max(np.abs(self.multipliers)))

    @property
    def stable(self) -> bool:
        return self.max_multiplier <= 1.0 + STABILITY_TOL


def floquet_by_shooting(flow, Y: np.ndarray, period_s: float, *, tol: float = 1e-11, max_iter: int = 30
                        ) -> ForcedOrbit:
    """The periodic orbit of the forced exact flow ``flow`` (``Flow(system, loads=...)``, load
    period ``period_s``) through the states Y (S, 2n) guessed at t_k = k T / S (one row: single
    shooting), by multiple shooting, and its Floquet multipliers.

    Unknowns Y; equations phi(Y_k; t_k, T / S) - Y_{k+1} = 0 (cyclic), solved by damped Newton
    with the exact segment Jacobians. Each segment sees only the S-th root of the monodromy's
    growth, so orbits with multipliers of 1e3 (the contact plateau of the three-mass model) are
    found where single shooting's Newton diverges. The monodromy is the product of the segment
    Jacobians.

    Parameters
    ----------
    flow : the forced exact flow, :class:`reduced.transient.flow.Flow` with the load
    Y : (S, 2n) guessed states [x; v] at the S phases (e.g. :func:`hb_states`)
    period_s : s, the load's period
    tol : closure to reach, relative (displacements and velocities scaled apart)
    max_iter : Newton iterations at most

    Returns
    -------
    ForcedOrbit
        The orbit from t = 0, its monodromy and multipliers. Raises :class:`ShootingError` if
        the closure stays above ``tol``.
    """
    n = flow.system.n
    Y = np.atleast_2d(np.array(Y, float))
    S = Y.shape[0]
    h = period_s / S
    w = 2.0 * np.pi / period_s
    xs = max(float(np.max(np.abs(Y[:, :n]))), 1e-300)
    sc = np.concatenate([np.full(n, xs), np.full(n, w * xs)])

    def evaluate(Y):
        segs = [flow(Y[k, :n], Y[k, n:], h, jacobian=True, t0=k * h) for k in range(S)]
        r = np.concatenate([(segs[k].y - Y[(k + 1) % S]) / sc for k in range(S)])
        return segs, r

    segs, r = evaluate(Y)
    rn = float(np.max(np.abs(r)))
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        if rn <= tol:
            break
        J = np.zeros((2 * n * S, 2 * n * S))
        for k in range(S):
            rows = slice(2 * n * k, 2 * n * (k + 1))
            J[rows, rows] = segs[k].jacobian * (sc[None, :] / sc[:, None])
            kk = (k + 1) % S
            J[rows, 2 * n * kk:2 * n * (kk + 1)] -= np.eye(2 * n)
        try:
            dz = -lu_solve(lu_factor(J), r)
        except (ValueError, np.linalg.LinAlgError):
            break
        dY = (dz.reshape(S, 2 * n) * sc)
        lam = 1.0
        for _ in range(10):  # halve while the closure grows (a step across a contact change)
            try:
                segn, rnew = evaluate(Y + lam * dY)
                if float(np.max(np.abs(rnew))) < rn:
                    break
            except RuntimeError:
                pass
            lam *= 0.5
        else:
            break
        Y, segs, r = Y + lam * dY, segn, rnew
        rn = float(np.max(np.abs(r)))
    if rn > tol:
        raise ShootingError(f"no periodic orbit: closure {rn:.3g} after {it} iterations ({S} segments)")
    Phi = np.eye(2 * n)
    for sg in segs:
        Phi = sg.jacobian @ Phi
    return ForcedOrbit(Y[0, :n].copy(), Y[0, n:].copy(), float(period_s), Phi, multipliers_of(Phi), rn, it)


def hb_states(X: np.ndarray, omega: float, S: int) -> np.ndarray:
    """(S, 2n) states [x; v] of the HB orbit X (2H+1, n) at the phases 2 pi k / S.

    Parameters
    ----------
    X : (2H+1, n) m, HB coefficients (rows c_0, c_1, s_1, ...)
    omega : rad/s
    S : number of phases

    Returns
    -------
    ndarray
        (S, 2n): x and v = omega dx/dtau at tau = 2 pi k / S, k = 0..S-1.
    """
    H = (X.shape[0] - 1) // 2
    E = _synthesis_matrix(H, _phases(S))
    return np.hstack([E @ X, omega * (E @ (_derivative_matrix(H) @ X))])


__all__ = [
    "BIFURCATIONS",
    "HILL_TOL",
    "STABILITY_TOL",
    "BranchStability",
    "ForcedOrbit",
    "ShootingError",
    "bifurcations",
    "branch_stability",
    "classify_crossing",
    "floquet_by_shooting",
    "forced_hill",
    "hb_states",
    "multipliers_of",
    "orbit_monodromy",
    "state_matrix",
]
