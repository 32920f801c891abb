"""Harmonic balance of a gap system with the stop forces projected exactly (no AFT sampling).

AFT (:mod:`reduced.periodic.hb`) samples the force at N phases: a stop that is closed for a
short part of the period, as near grazing, is seen by a few samples only, so the projected
force jumps by k_g / N each time a sample enters contact. With the paper's k_g = 3.5e7 N/m
those jumps dwarf the structure's stiffness unless N is in the tens of thousands, and a
forced-response curve drawn by AFT moves with N (its fold frequency at 1 N by a factor 2
between N = 256 and 4096 at H = 3). Here the phases where a stop is closed are found as the
roots of its penetration series and the force, linear in each contact state, is integrated
in closed form over them:

on stop j the motion s_j(tau) = B_j x(tau) = sum_h a_jh E_h(tau), a_j = Xm @ B_j, is a
trigonometric polynomial; the stop is closed on the union I_j of intervals where
side_j (s_j - o_j) > 0, and with W = diag(1/2pi, 1/pi, ..., 1/pi)

    F_j = k_j (G_j a_j - o_j g_j),   G_j = W int_{I_j} E(tau) E(tau)^T dtau,   g_j = W int_{I_j} E dtau,

the Fourier coefficients of f_j = k_j (s_j - o_j) on I_j (zero elsewhere). The force vanishes
at the ends of I_j, so the derivative has no boundary terms: dF/dX = sum_j k_j kron(G_j, B_j^T B_j),
exact and continuous in X. The integrals of E E^T are sums of the moments
int cos(q tau), int sin(q tau) (q <= 2H) over the intervals (``cos m cos n = (cos(m-n) +
cos(m+n)) / 2`` and so on). What is left is the truncation to H harmonics.

The roots: between consecutive extrema a series is monotone, so each sign change of the
penetration between two extrema is one root. The extrema are the roots of the derivative
series, bracketed by its sign changes on N phases (:func:`default_root_samples`, 8 per
coefficient) and refined, like the roots, by Newton steps safeguarded by bisection, to
round-off. A pair of extrema closer than 2 pi / N (a flat inflection) can be missed, and
with it a contact of that width whose force is second order in its depth. The search runs
in small numba kernels (one stop: a few microseconds).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.periodic.hb import GapForce, HarmonicBalance

ROOT_SAMPLES_PER_COEFFICIENT = 8  # phases per Fourier coefficient bracketing the extrema of a stop's motion
ROOT_ITERATIONS = 100  # safeguarded Newton steps per root (bisection alone needs ~55 to round-off)


def default_root_samples(H: int) -> int:
    """Phases per period bracketing the extrema of each stop's motion: a power of 2, >= 8 (2H+1), >= 64.

    Parameters
    ----------
    H : int
        Harmonics.

    Returns
    -------
    int
        max(64, 2^ceil(log2(ROOT_SAMPLES_PER_COEFFICIENT (2H + 1)))).
    """
    return max(64, int(2 ** math.ceil(math.log2(ROOT_SAMPLES_PER_COEFFICIENT * (2 * H + 1)))))


@nb.njit(cache=True)
def _series(a, t):
    """sum_h a[h] E_h(t), basis 1, cos t, sin t, ..., cos H t, sin H t."""
    H = (a.shape[0] - 1) // 2
    c1, s1 = math.cos(t), math.sin(t)
    ck, sk = 1.0, 0.0
    v = a[0]
    for k in range(1, H + 1):
        ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
        v += a[2 * k - 1] * ck + a[2 * k] * sk
    return v


@nb.njit(cache=True)
def _root(a, da, lo, hi):
    """The root of series a in [lo, hi] (a sign change there): safeguarded Newton on da."""
    flo = _series(a, lo)
    fhi = _series(a, hi)
    if flo == 0.0:
        return lo
    if fhi == 0.0:
        return hi
    t = lo - flo * (hi - lo) / (fhi - flo)
    if not (lo <= t <= hi):
        t = 0.5 * (lo + hi)
    eps = 2.0 * 2.220446049250313e-16
    for _ in range(100):
        f = _series(a, t)
        if f == 0.0:
            return t
        if (f > 0.0) == (flo > 0.0):
            lo, flo = t, f
        else:
            hi = t
        d = _series(da, t)
        tn = t - f / d if d != 0.0 else 0.5 * (lo + hi)
        if not (lo <= tn <= hi) or not math.isfinite(tn):
            tn = 0.5 * (lo + hi)
        tol = eps * (1.0 + abs(t))
        if abs(tn - t) <= tol or hi - lo <= tol:
            return tn
        t = tn
    return t


@nb.njit(cache=True)
def _grid_basis(H, samples, out):
    """out[i, k - 1] = (cos k t, sin k t) at t = (i + 1) 2 pi / samples, i < samples - 1, k = 1..H: the values
    :func:`_series` builds at those phases (the same cos, sin and recurrence: the same bits)."""
    h = 2.0 * math.pi / samples
    for i in range(samples - 1):
        t = (i + 1) * h
        c1, s1 = math.cos(t), math.sin(t)
        ck, sk = 1.0, 0.0
        for k in range(1, H + 1):
            ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
            out[i, k - 1, 0] = ck
            out[i, k - 1, 1] = sk


@functools.lru_cache(maxsize=32)
def grid_basis(H: int, samples: int) -> np.ndarray:
    """(samples - 1, H, 2) (cos k t, sin k t) on the phase grid of :func:`series_extrema` (cached, read-only).

    Parameters
    ----------
    H : int
        Harmonics.
    samples : int
        Phases per period.

    Returns
    -------
    ndarray
        Dimensionless, (samples - 1, H, 2).
    """
    out = np.empty((max(samples - 1, 0), H, 2))
    call_numba_kernel(_grid_basis, H, samples, out)
    out.flags.writeable = False
    return out


@nb.njit(cache=True)
def _series_on_grid(a, basis, i):
    """:func:`_series` of a at the grid phase (i + 1) 2 pi / samples from its tabulated basis: the same sum."""
    v = a[0]
    for k in range(1, basis.shape[1] + 1):
        v += a[2 * k - 1] * basis[i, k - 1, 0] + a[2 * k] * basis[i, k - 1, 1]
    return v


@nb.njit(cache=True)
def _extrema(da, dda, samples, basis, out):
    """Extrema of the series whose derivative is da (roots of da) into ``out``, sorted in [0, 2 pi); count.
    ``basis``: :func:`grid_basis` of (H, samples), the series at the grid phases (the values of :func:`_series`
    there)."""
    two_pi = 2.0 * math.pi
    h = two_pi / samples
    n = 0
    f0 = _series(da, 0.0)
    fprev = f0
    for i in range(samples):
        t1 = (i + 1) * h
        f1 = f0 if i == samples - 1 else _series_on_grid(da, basis, i)
        if (fprev > 0.0) != (f1 > 0.0):
            r = _root(da, dda, i * h, t1)
            if r >= two_pi:
                r -= two_pi
            out[n] = r
            n += 1
        fprev = f1
    out[:n].sort()
    return n


@nb.njit(cache=True)
def _intervals(p, dp, ext, n_ext, alpha, beta):
    """Intervals where series p > 0, given its extrema ext[:n_ext] (sorted); count (-1: the whole period)."""
    two_pi = 2.0 * math.pi
    if n_ext == 0:
        return -1 if p[0] > 0.0 else 0
    roots = np.empty(n_ext)
    rising = np.empty(n_ext, np.bool_)
    nr = 0
    for i in range(n_ext):
        lo = ext[i]
        hi = ext[(i + 1) % n_ext] + (two_pi if i + 1 == n_ext else 0.0)
        plo, phi = _series(p, lo), _series(p, hi)
        if (plo > 0.0) != (phi > 0.0):
            r = _root(p, dp, lo, hi)
            if r >= two_pi:
                r -= two_pi
            roots[nr] = r
            rising[nr] = phi > plo
            nr += 1
    if nr == 0:
        return -1 if _series(p, ext[0]) > 0.0 else 0
    order = np.argsort(roots[:nr])
    first = 0
    if not rising[order[0]]:
        first = 1  # start at an entry; the first exit closes the last interval
    n = 0
    for q in range(first, nr, 2):
        a = roots[order[q]]
        if q + 1 < nr:
            b = roots[order[q + 1]]
        else:
            b = roots[order[0]] + two_pi
        alpha[n] = a
        beta[n] = b
        n += 1
    return n


def series_extrema(a: np.ndarray, Nab: np.ndarray, samples: int) -> np.ndarray:
    """Sorted phases in [0, 2 pi) of the extrema of the series a (HB row layout); empty if a is constant.

    Parameters
    ----------
    a : (2H+1,) ndarray of float
        Coefficients [c_0, c_1, s_1, ..., c_H, s_H] of one scalar series.
    Nab : (2H+1, 2H+1) ndarray of float
        d/dtau on the coefficients (:attr:`HarmonicBalance.Nab`).
    samples : int
        Phases per period on which the derivative's sign changes bracket the extrema.

    Returns
    -------
    (k,) ndarray of float
        rad, the phases of the extrema, each refined to round-off.
    """
    da = np.ascontiguousarray(Nab @ a)
    out = np.empty(samples + 1)
    n = call_numba_kernel(_extrema, da, np.ascontiguousarray(Nab @ da), int(samples),
                          grid_basis((a.shape[0] - 1) // 2, int(samples)), out)
    return out[:n].copy()


def contact_intervals(p: np.ndarray, Nab: np.ndarray, samples: int, extrema: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(alpha, beta): the phase intervals [alpha_i, beta_i] (0 <= alpha_i < 2 pi, beta_i > alpha_i)
    where the series p (HB row layout) is positive. ``extrema``: those of p or of any series
    that differs from p by a constant and a sign (default :func:`series_extrema` of p).

    Parameters
    ----------
    p : (2H+1,) array_like of float
        Coefficients of the series (a stop's penetration side (s - o)).
    Nab : (2H+1, 2H+1) ndarray of float
        d/dtau on the coefficients.
    samples : int
        Phases per period bracketing the extrema (when they are not given).
    extrema : ndarray of float, optional
        rad, sorted phases of the extrema.

    Returns
    -------
    alpha, beta : (k,) ndarray of float
        rad, starts and ends of the intervals (an interval may run past 2 pi); empty if p is never
        positive, [0] and [2 pi] if it always is.
    """
    p = np.ascontiguousarray(p, dtype=float)
    ext = series_extrema(p, Nab, samples) if extrema is None else np.ascontiguousarray(extrema)
    alpha = np.empty(max(ext.size, 1))
    beta = np.empty(max(ext.size, 1))
    n = call_numba_kernel(_intervals, p, np.ascontiguousarray(Nab @ p), ext, ext.size, alpha, beta)
    if n < 0:
        return np.array([0.0]), np.array([2.0 * np.pi])
    return alpha[:n].copy(), beta[:n].copy()


@nb.njit(cache=True)
def _moments(alpha, beta, H, G, g):
    """G = W int E E^T and g = W int E over the intervals [alpha_i, beta_i] (module docstring), in place."""
    qmax = 2 * H
    C = np.zeros(qmax + 1)
    S = np.zeros(qmax + 1)
    for i in range(alpha.shape[0]):
        a, b = alpha[i], beta[i]
        C[0] += b - a
        for q in range(1, qmax + 1):
            C[q] += (math.sin(q * b) - math.sin(q * a)) / q
            S[q] += (math.cos(q * a) - math.cos(q * b)) / q
    n = 2 * H + 1
    for r in range(n):
        m = (r + 1) // 2
        rs = r > 0 and r % 2 == 0  # row r is sin(m tau)
        w = 0.5 / math.pi if r == 0 else 1.0 / math.pi
        g[r] = w * (S[m] if rs else C[m])
        for c in range(n):
            k = (c + 1) // 2
            cs_ = c > 0 and c % 2 == 0
            d = abs(m - k)
            if rs and cs_:  # sin m sin k
                v = 0.5 * (C[d] - C[m + k])
            elif not rs and not cs_:  # cos m cos k
                v = 0.5 * (C[d] + C[m + k])
            elif not rs:  # cos m sin k = (sin (k+m) + sin (k-m)) / 2
                v = 0.5 * (S[m + k] + (S[d] if k >= m else -S[d]))
            else:  # sin m cos k = (sin (m+k) + sin (m-k)) / 2
                v = 0.5 * (S[m + k] + (S[d] if m >= k else -S[d]))
            G[r, c] = w * v


@nb.njit(cache=True)
def _matvec(A, x, out):
    """out = A x by rows, each a sum from 0.0 in column order (for the derivative matrix Nab, one nonzero per
    row: the product itself, as numpy's A @ x gives it)."""
    for i in range(A.shape[0]):
        acc = 0.0
        for c in range(A.shape[1]):
            acc += A[i, c] * x[c]
        out[i] = acc


@nb.njit(cache=True)
def _stops_kernel(q, row_of, side, offset, Nab, samples, basis, ext, n_ext, alpha, beta, n_int, G, g):
    """Every stop's contact intervals and moments at once, as :func:`series_extrema`, :func:`contact_intervals`
    and :func:`_moments` give them stop by stop (the same kernels on the same numbers): q (2H+1, u) the
    coefficients of the contact coordinates, stop j on coordinate row_of[j] with penetration series
    side_j (q_r - o_j). Out: ext[r, :n_ext[r]] the extrema of coordinate r; per stop alpha[j, :n_int[j]],
    beta[j, :n_int[j]] its intervals (n_int[j] = 0: never closed), G[j], g[j] their moments (when n_int[j] > 0)."""
    h = q.shape[0]
    H = (h - 1) // 2
    a = np.empty(h)
    da = np.empty(h)
    dda = np.empty(h)
    p = np.empty(h)
    dp = np.empty(h)
    for r in range(q.shape[1]):
        for i in range(h):
            a[i] = q[i, r]
        _matvec(Nab, a, da)
        _matvec(Nab, da, dda)
        n_ext[r] = _extrema(da, dda, samples, basis, ext[r])
    for j in range(row_of.shape[0]):
        r = row_of[j]
        for i in range(h):
            p[i] = side[j] * q[i, r]
        p[0] -= side[j] * offset[j]
        _matvec(Nab, p, dp)
        n = _intervals(p, dp, ext[r, : n_ext[r]], n_ext[r], alpha[j], beta[j])
        if n < 0:  # closed over the whole period
            alpha[j, 0] = 0.0
            beta[j, 0] = 2.0 * math.pi
            n = 1
        n_int[j] = n
        if n > 0:
            _moments(alpha[j, :n], beta[j, :n], H, G[j], g[j])


def stop_moments(q: np.ndarray, row_of: np.ndarray, side: np.ndarray, offset: np.ndarray, Nab: np.ndarray,
                 samples: int) -> tuple[list, np.ndarray, np.ndarray]:
    """Per stop, its contact intervals and the moments G_j, g_j over them (module docstring), all stops in one
    kernel call: what :func:`series_extrema` (once per contact coordinate), :func:`contact_intervals` and
    :func:`_moments` (once per stop) give, to the bit (tests/test_stop_moments.py).

    Parameters
    ----------
    q : (2H+1, u) ndarray of float
        Coefficients of the contact coordinates (HB row layout).
    row_of : (m,) ndarray of int
        Stop j acts on coordinate row_of[j].
    side, offset : (m,) ndarray of float
        Stop j is closed where side_j (q_r - offset_j) > 0.
    Nab : (2H+1, 2H+1) ndarray of float
        d/dtau on the coefficients.
    samples : int
        Phases per period bracketing the extrema.

    Returns
    -------
    tuple
        ([(alpha_j, beta_j)] the intervals of each stop (empty arrays: never closed; [0], [2 pi]: always),
        G (m, 2H+1, 2H+1) and g (m, 2H+1): the moments of stop j in G[j], g[j], zero where it never closes).
    """
    h, u = q.shape
    m = row_of.shape[0]
    ext = np.empty((u, samples + 1))
    n_ext = np.zeros(u, np.int64)
    width = samples + 1
    alpha, beta = np.empty((m, width)), np.empty((m, width))
    n_int = np.zeros(m, np.int64)
    G, g = np.zeros((m, h, h)), np.zeros((m, h))
    call_numba_kernel(_stops_kernel, np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(row_of, np.int64),
                      np.ascontiguousarray(side, dtype=float), np.ascontiguousarray(offset, dtype=float),
                      np.ascontiguousarray(Nab, dtype=float), int(samples), grid_basis((h - 1) // 2, int(samples)),
                      ext, n_ext, alpha, beta, n_int, G, g)
    intervals = [(alpha[j, : n_int[j]].copy(), beta[j, : n_int[j]].copy()) for j in range(m)]
    return intervals, G, g


@dataclass(frozen=True, eq=False)
class ExactGapBalance(HarmonicBalance):
    """:class:`HarmonicBalance` of a gap system whose stop forces are projected exactly (module
    docstring), not by AFT. ``N`` is the number of phases that bracket the extrema of each
    stop's motion (and of :meth:`time_series`): :func:`default_root_samples`. Everything built
    on :meth:`aft` (:meth:`residual`, :meth:`hill_matrices`) uses the exact projection.

    Parameters
    ----------
    M, K, force, H, N, C
        As :class:`HarmonicBalance`; ``force`` must be a :class:`GapForce` and ``N`` is the number
        of root-bracketing phases (:func:`default_root_samples`).

    Raises
    ------
    InvalidArgument
        As :class:`HarmonicBalance`, or a force that is not a GapForce.
    """

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.force, GapForce):
            raise _check.InvalidArgument(f"ExactGapBalance needs a GapForce, got {type(self.force).__name__}")
        B = self.force.system.B
        rows = [next(r for r in range(j + 1) if np.array_equal(B[r], B[j])) for j in range(B.shape[0])]
        object.__setattr__(self, "_ix", {"row_of": rows})

    @classmethod
    def for_system(cls, system: GapSystem, H: int, N: int | None = None, damped: bool = False):
        """Exactly projected HB of a gap system (conservative unless ``damped``)."""
        _check.gap_system(system)
        H = _check.integer("H", H, lo=0)
        return cls(system.M, system.K, GapForce(system), H, N or default_root_samples(H),
                   system.C if damped else None)

    def _moment_matrices(self, alpha: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(G, g) of the intervals (module docstring)."""
        n = 2 * self.H + 1
        G, g = np.empty((n, n)), np.empty(n)
        call_numba_kernel(_moments, np.ascontiguousarray(alpha), np.ascontiguousarray(beta), self.H, G, g)
        return G, g

    def stop_matrices(self, X: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray, int]]:
        """Per stop closed somewhere in the period: (j, G_j, g_j, number of contact intervals) at X."""
        s = self.force.system
        Xm = self.unpack(X)
        extrema = {}
        out = []
        for j in range(s.m):
            r = self._ix["row_of"][j]
            if r not in extrema:  # the stops of one row (a clearance's two sides) share the extrema of s
                extrema[r] = series_extrema(Xm @ s.B[r], self.Nab, self.N)
            p = s.side[j] * (Xm @ s.B[j])
            p[0] -= s.side[j] * s.offset[j]  # the penetration series side (s - o)
            alpha, beta = contact_intervals(p, self.Nab, self.N, extrema[r])
            if alpha.size:
                G, g = self._moment_matrices(alpha, beta)
                out.append((j, G, g, alpha.size))
        return out

    def aft(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F(X) (size,) and dF/dX (size, size), exactly projected. The AFT method's name is
        kept so that :meth:`residual` and :meth:`hill_matrices` use it."""
        s = self.force.system
        Xm = self.unpack(X)
        h, n = Xm.shape
        F = np.zeros_like(Xm)
        dF = np.zeros((h, n, h, n))
        Gsum = {}  # k_j G_j summed over the stops of one row: one Kronecker product per row
        for j, G, g, _ in self.stop_matrices(X):
            Fj = s.k[j] * (G @ (Xm @ s.B[j]) - s.offset[j] * g)
            F += np.outer(Fj, s.B[j])
            r = self._ix["row_of"][j]
            Gsum[r] = Gsum[r] + s.k[j] * G if r in Gsum else s.k[j] * G
        for r, G in Gsum.items():
            dF += G[:, None, :, None] * self.Qr[r][None, :, None, :]  # kron(G, B_r^T B_r)
        return F.ravel(), dF.reshape(self.size, self.size)


__all__ = ["ExactGapBalance", "contact_intervals", "default_root_samples", "series_extrema", "stop_moments"]
