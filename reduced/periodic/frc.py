"""Forced-response curves (FRCs) of a gap system under a harmonic load, by harmonic balance.

The system (:class:`reduced.models.gaps.GapSystem`) driven by one harmonic load along b,

    M x'' + C x' + K x + B^T f(B x) = b P cos(Omega t + phi),

is balanced on H harmonics of the phase tau = Omega t, with the layout of
:mod:`reduced.periodic.hb` (rows c_0, c_1, s_1, ..., c_H, s_H). Per harmonic k the linear
part is the dynamic stiffness Z_k = K - (k Omega)^2 M + i k Omega C, so in complex form
(x_k = c_k - i s_k) the balance of harmonic k is

    Z_k x_k = f_k - U^T phi_k,       f_1 = b P e^{i phi}, f_k = 0 otherwise,

with U the distinct rows of B (the *contact coordinates* q = U x: x1 and x3 for the
three-mass model) and phi_k the harmonics of the stops' forces on them. The forces depend
on q only, so the DOFs off the stops are eliminated exactly, harmonic by harmonic, and the
balance is solved on q alone (**condensed HB**; the receptance form of, e.g., Krack & Gross
2019, Sec. 4.2):

    R(q, Omega) = q - q_lin(Omega) + Rc(Omega) phi(q) = 0,
    q_lin,k = U Z_k^-1 f_k,   Rc_k = U Z_k^-1 U^T,

whose size, (2H + 1) x (number of contact coordinates), does not grow with the model (a
reduced beam with ten modes costs what the three-mass model costs). x follows from
x_k = Z_k^-1 (f_k - U^T phi_k). The forces phi(q) and their derivative are integrated exactly
over the contact intervals (:mod:`reduced.periodic.exact_hb`: no AFT sampling, whose
k_g / N jumps move a curve near grazing by a factor 2 in frequency at N = 256 against 4096).

``harmonics="odd"`` keeps only the odd harmonics: for symmetric clearances (|s| <= g) and no
static load the response to a cosine is half-wave symmetric, x(tau + pi) = -x(tau), so the
even rows of R vanish identically on the odd subspace; perturbations with even harmonics are
still seen by the stability analysis, which works on the full system.

The curve R = 0 is continued in the excitation frequency by the pseudo-arclength driver
(:func:`reduced.periodic.continuation.continue_branch`) in the scaled unknowns

    y = [q / x_ref, ln(Omega / omega_ref)],

rows scaled by 1 / x_ref, so it turns at folds and through the narrow tongues of internal
resonances (a step whose secant leaves the new tangent by more than ``max_angle_deg`` is
refused, which keeps the path on its own sheet where the tongue's sides nearly touch).

**Stability.** A forced orbit has no trivial multiplier: it is stable when every Floquet
multiplier |mu| < 1. Three ways, compared in the stage's output:

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
from scipy.linalg import expm, lu_factor, lu_solve

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.periodic.continuation import ContinuationError, continue_branch, tangent
from reduced.periodic.exact_hb import _moments, contact_intervals, default_root_samples, series_extrema
from reduced.periodic.hb import NewtonError, _derivative_matrix, _phases, _synthesis_matrix, newton

MAX_HARMONICS = 1000  # as reduced.periodic.backbones and the scene parser
STABILITY_TOL = 1e-6  # |mu| - 1 above this is unstable (monodromy and shooting: exact to ~1e-12)
HILL_TOL = 1e-3  # |mu| - 1 above this is unstable for Hill (truncation of the exponents)
REAL_TOL = 1e-3  # rad: a multiplier within this angle of the real axis is real
SECANT_TOL_DEG = 15.0  # default turn allowed between a step's secant and the new tangent
AMPLITUDE_NEWTON_STEPS = 6  # Newton steps refining the phase of max |x| (quadratic: 2-3 suffice)
BIFURCATIONS = ("fold", "branch_point", "period_doubling", "neimark_sacker")
HARMONIC_SETS = ("all", "odd")


# -- the condensed forced balance ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedBalance:
    """Condensed HB of ``system`` under b P cos(Omega t + phi) (module docstring).

    The unknowns are the coefficients q (2H+1, u) of the u contact coordinates U x, of which
    only the rows ``keep`` (all, or the odd harmonics) are free; the others are zero.
    """

    system: GapSystem
    b: np.ndarray  # (n,) force direction
    amplitude_N: float  # N, P
    phase_deg: float
    H: int
    N: int  # phases bracketing the extrema of each contact coordinate
    odd: bool
    U: np.ndarray = field(init=False, repr=False)  # (u, n) distinct stop rows
    row_of: np.ndarray = field(init=False, repr=False)  # (m,) stop -> row of U
    keep: np.ndarray = field(init=False, repr=False)  # harmonic rows kept
    Nab: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = self.system
        rows, row_of = [], []
        for j in range(s.m):
            for r, u in enumerate(rows):
                if np.array_equal(u, s.B[j]):
                    row_of.append(r)
                    break
            else:
                rows.append(s.B[j])
                row_of.append(len(rows) - 1)
        k = (np.arange(2 * self.H + 1) + 1) // 2
        keep = np.flatnonzero(k % 2 == 1) if self.odd else np.arange(2 * self.H + 1)
        object.__setattr__(self, "U", np.array(rows).reshape(len(rows), s.n))
        object.__setattr__(self, "row_of", np.array(row_of, int))
        object.__setattr__(self, "keep", keep)
        object.__setattr__(self, "Nab", _derivative_matrix(self.H))
        object.__setattr__(self, "_Cr", s.C if np.any(s.C) else None)

    # -- sizes -----------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.system.n

    @property
    def u(self) -> int:
        return self.U.shape[0]

    @property
    def size(self) -> int:
        """Free unknowns: kept harmonic rows x contact coordinates."""
        return self.keep.size * self.u

    def full_q(self, z: np.ndarray) -> np.ndarray:
        """(2H+1, u) q from the free unknowns z (size,)."""
        q = np.zeros((2 * self.H + 1, self.u))
        q[self.keep] = np.asarray(z).reshape(self.keep.size, self.u)
        return q

    # -- linear part -------------------------------------------------------------------------
    def receptances(self, omega: float, derivative: bool = False, harmonics: np.ndarray | None = None):
        """Per harmonic k (default 0..H): W_k = Z_k^-1 [U^T, f_k] (n, u + 1) complex, and dW_k/dOmega."""
        s = self.system
        n, u = self.n, self.u
        k = np.arange(self.H + 1) if harmonics is None else np.asarray(harmonics)
        Z = (s.K[None] - ((k * omega) ** 2)[:, None, None] * s.M[None]).astype(complex)
        if self._Cr is not None:
            Z = Z + 1j * (k * omega)[:, None, None] * self._Cr[None]
        rhs = np.zeros((k.size, n, u + 1), complex)
        rhs[:, :, :u] = self.U.T[None]
        rhs[k == 1, :, u] = self.b * self.amplitude_N * np.exp(1j * math.radians(self.phase_deg))
        W = np.linalg.solve(Z, rhs)
        if not derivative:
            return W, None
        dZ = (-2.0 * omega * k**2)[:, None, None] * s.M[None] + 0j
        if self._Cr is not None:
            dZ = dZ + 1j * k[:, None, None] * self._Cr[None]
        return W, -np.linalg.solve(Z, dZ @ W)

    @staticmethod
    def _real_rows(c: np.ndarray) -> np.ndarray:
        """(2H+1, ...) real rows [c_0, c_1, s_1, ...] of complex harmonics (H+1, ...) with x_k = c_k - i s_k."""
        out = np.empty((2 * (c.shape[0] - 1) + 1, *c.shape[1:]))
        out[0] = c[0].real
        out[1::2] = c[1:].real
        out[2::2] = -c[1:].imag
        return out

    @staticmethod
    def _complex(rows: np.ndarray) -> np.ndarray:
        """Complex harmonics (H+1, ...) from real rows (2H+1, ...)."""
        c = np.empty((rows.shape[0] // 2 + 1, *rows.shape[1:]), complex)
        c[0] = rows[0]
        c[1:] = rows[1::2] - 1j * rows[2::2]
        return c

    # -- the stops ---------------------------------------------------------------------------
    def contact(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
        """phi (2H+1, u), dphi (u, 2H+1, 2H+1) (d phi_r / d q_r) and the contact intervals of each
        stop [(alpha, beta)] at q (2H+1, u), by exact projection (:mod:`reduced.periodic.exact_hb`)."""
        s = self.system
        h = 2 * self.H + 1
        phi = np.zeros((h, self.u))
        dphi = np.zeros((self.u, h, h))
        ext = [series_extrema(q[:, r], self.Nab, self.N) for r in range(self.u)]
        intervals = []
        G = np.empty((h, h))
        g = np.empty(h)
        for j in range(s.m):
            r = self.row_of[j]
            p = s.side[j] * q[:, r]
            p[0] -= s.side[j] * s.offset[j]
            alpha, beta = contact_intervals(p, self.Nab, self.N, ext[r])
            intervals.append((alpha, beta))
            if alpha.size == 0:
                continue
            call_numba_kernel(_moments, alpha, beta, self.H, G, g)
            phi[:, r] += s.k[j] * (G @ q[:, r] - s.offset[j] * g)
            dphi[r] += s.k[j] * G
        return phi, dphi, intervals

    # -- residual ----------------------------------------------------------------------------
    def residual(self, z: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R (size,), dR/dz (size, size), dR/dOmega (size,) at the free unknowns z [m] (module docstring)."""
        u = self.u
        kp = self.keep
        q = self.full_q(z)
        phi, dphi, _ = self.contact(q)
        ks = self._harmonics_kept
        W, dW = self.receptances(omega, derivative=True, harmonics=ks)
        UW, UdW = np.einsum("rn,knc->krc", self.U, W), np.einsum("rn,knc->krc", self.U, dW)
        Rc, qlin = UW[:, :, :u], UW[:, :, u]  # (len(ks), u, u), (len(ks), u)
        dRc, dqlin = UdW[:, :, :u], UdW[:, :, u]
        phic = self._complex(phi)[ks]
        R = q[kp] - self._rows_of(qlin - np.einsum("krc,kc->kr", Rc, phic), ks)
        dRdw = -self._rows_of(dqlin - np.einsum("krc,kc->kr", dRc, phic), ks)
        # dR/dz = I + Rblk D: Rblk the real form of Rc, block diagonal over the harmonics (rows
        # (cos, sin) of harmonic k from (a, b) = (cos, sin) of phi_k: [[Re, Im], [-Im, Re]]), D
        # the force derivative, block diagonal over the contact coordinates
        nk, S = kp.size, self.size
        D = np.zeros((nk, u, nk, u))
        r = np.arange(u)
        D[:, r, :, r] = dphi[:, kp][:, :, kp]
        D = D.reshape(S, S)
        RD = np.empty((S, S))
        o = 0
        if ks[0] == 0:  # the constant row: real
            RD[:u] = Rc[0].real @ D[:u]
            o = 1
        Rk = Rc[o:]
        blk = np.empty((Rk.shape[0], 2 * u, 2 * u))
        blk[:, :u, :u] = blk[:, u:, u:] = Rk.real
        blk[:, :u, u:] = Rk.imag
        blk[:, u:, :u] = -Rk.imag
        RD[o * u:] = np.einsum("bij,bjs->bis", blk, D[o * u:].reshape(Rk.shape[0], 2 * u, S)).reshape(-1, S)
        J = RD
        J[np.diag_indices(S)] += 1.0
        return R.ravel(), J, dRdw.ravel()

    @property
    def _harmonics_kept(self) -> np.ndarray:
        """Harmonic numbers of the kept rows (each once, increasing)."""
        return np.unique((self.keep + 1) // 2)

    @staticmethod
    def _rows_of(c: np.ndarray, ks: np.ndarray) -> np.ndarray:
        """Real rows (kept order) of complex harmonics c (len(ks), ...) with x_k = c_k - i s_k."""
        o = 1 if ks[0] == 0 else 0
        out = np.empty((2 * (ks.size - o) + o, *c.shape[1:]))
        if o:
            out[0] = c[0].real
        out[o::2] = c[o:].real
        out[o + 1::2] = -c[o:].imag
        return out

    def linear_z(self, omega: float) -> np.ndarray:
        """z of the linear (all stops open) response."""
        ks = self._harmonics_kept
        W, _ = self.receptances(omega, harmonics=ks)
        return self._rows_of(np.einsum("rn,kn->kr", self.U, W[:, :, self.u]), ks).ravel()

    # -- the full response ------------------------------------------------------------------
    def response(self, z: np.ndarray, omega: float) -> np.ndarray:
        """X (2H+1, n): x_k = Z_k^-1 (f_k - U^T phi_k) for every DOF."""
        q = self.full_q(z)
        phi, _, _ = self.contact(q)
        W, _ = self.receptances(omega)
        x = W[:, :, self.u] - np.einsum("knr,kr->kn", W[:, :, : self.u], self._complex(phi))
        return self._real_rows(x)

    def force_jacobian(self, q: np.ndarray) -> np.ndarray:
        """dF/dX (n(2H+1), n(2H+1)) of the stop forces on the full layout (for Hill's method)."""
        _, dphi, _ = self.contact(q)
        h, n = 2 * self.H + 1, self.n
        dF = np.zeros((h, n, h, n))
        for r in range(self.u):
            Q = np.outer(self.U[r], self.U[r])
            dF += dphi[r][:, None, :, None] * Q[None, :, None, :]
        return dF.reshape(h * n, h * n)


# -- continuation ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedResidual:
    """R(y) / x_ref for continuation in y = [z / x_ref, ln(Omega / omega_ref)]:
    ``__call__(y) -> (R (size,), dR/dy (size, size + 1))``."""

    fb: ForcedBalance
    x_ref: float  # m
    omega_ref: float  # rad/s

    def __post_init__(self) -> None:
        object.__setattr__(self, "_memo", {})

    @property
    def size(self) -> int:
        return self.fb.size

    def z_omega(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        """Free unknowns z [m] and Omega [rad/s] of the point y."""
        return y[: self.size] * self.x_ref, float(self.omega_ref * math.exp(y[self.size]))

    def y_of(self, z: np.ndarray, omega: float) -> np.ndarray:
        return np.concatenate([np.asarray(z, float) / self.x_ref, [math.log(omega / self.omega_ref)]])

    def __call__(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = y.tobytes()
        if key in self._memo:  # the driver evaluates an accepted point again for its tangent
            return self._memo[key]
        z, omega = self.z_omega(y)
        R, J, dRdw = self.fb.residual(z, omega)
        Jy = np.empty((self.size, self.size + 1))
        Jy[:, : self.size] = J
        Jy[:, self.size] = dRdw * (omega / self.x_ref)
        out = (R / self.x_ref, Jy)
        self._memo.clear()
        self._memo[key] = out
        return out


# -- stability ----------------------------------------------------------------------------------
def state_matrix(system: GapSystem, active: np.ndarray) -> np.ndarray:
    """A_s (2n, 2n) of y = [x; v] with the stops in ``active`` closed: y' = A_s y + const."""
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
    """Eigenvalues of Phi sorted by decreasing modulus."""
    mu = np.linalg.eigvals(Phi)
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def forced_hill(fb: ForcedBalance, z: np.ndarray, omega: float) -> np.ndarray:
    """(2n,) Floquet multipliers of the forced HB orbit by Hill's method, by decreasing |mu|.

    Full system, all 2H+1 harmonics (perturbations may break the orbit's half-wave symmetry):
    (J2 lam^2 + J1 lam + J0) p = 0 with J0 = A(Omega) + dF/dX, J1 = 2 Omega kron(Nab, M) + kron(I, C),
    J2 = kron(I, M) (:meth:`reduced.periodic.hb.HarmonicBalance.hill_matrices`), solved as a
    standard eigenproblem of size 2n(2H+1). Each exponent recurs shifted by i k Omega; the 2n in
    the first zone |Im lam| <= Omega / 2 are kept, mu = exp(2 pi lam / Omega). A real negative
    multiplier has its exponent on the zone's edge with both copies in it: of eigenvalues on
    the edge (within 1e-6 Omega) those with Im lam < 0 are ranked last so each counts once.
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
    A = np.block([[np.zeros((size, size)), np.eye(size)], [-J0, -J1]])
    lam = np.linalg.eigvals(A)
    half = 0.5 * omega
    edge = np.abs(np.abs(lam.imag) - half) <= 1e-6 * omega
    key = np.where(edge & (lam.imag < 0.0), np.inf, np.abs(lam.imag))
    cand = lam[np.argsort(key, kind="stable")][: 2 * n]
    mu = np.exp(cand * (2.0 * np.pi / omega))
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def classify_crossing(mu: np.ndarray, tol: float) -> str:
    """How the multiplier nearest the unit circle among those outside it left: ``fold`` (real
    > 0), ``period_doubling`` (real < 0) or ``neimark_sacker`` (complex)."""
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


# -- amplitudes -----------------------------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _synthesis(H: int, N: int) -> np.ndarray:
    """(N, 2H+1) synthesis matrix on N phases (cached: read-only)."""
    E = _synthesis_matrix(H, _phases(N))
    E.flags.writeable = False
    return E


def max_abs_over_period(X: np.ndarray, rows: np.ndarray, samples: int | None = None) -> np.ndarray:
    """(p,) m, max over tau of |rows[j] . x(tau)| for X (2H+1, n): the largest of ``samples`` phases,
    refined by Newton on the derivative of the Fourier series."""
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
    """(p, H + 1) m: |c_0| and sqrt(c_k^2 + s_k^2), k = 1..H, of each point ``rows[j] . x`` for X (2H+1, n)."""
    C = np.asarray(rows, float) @ X.T
    return np.column_stack([np.abs(C[:, 0]), np.hypot(C[:, 1::2], C[:, 2::2])])


# -- the curve ------------------------------------------------------------------------------------
@dataclass(eq=False)
class FRCBranch:
    """One forced-response curve: points in continuation order, with stability and bifurcations.

    ``multipliers`` are those of :func:`orbit_monodromy` (every point); ``hill`` holds Hill's
    multipliers at the points ``hill_index`` (all, or a subset where Hill's matrix is large).
    ``bifurcations`` lists (point index, kind), kind in :data:`BIFURCATIONS`, the index being
    the first point past the crossing; ``folds`` the indices where the curve turned in frequency.
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
    ds: float = 0.02,
    ds_max: float = 0.05,
    max_steps: int = 5000,
    max_angle_deg: float = 15.0,
    stability: bool = True,
    hill_points: int | None = None,
    progress=None,
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
    H : harmonics; ``harmonics`` "all" or "odd" (half-wave symmetric response, module docstring)
    N : phases bracketing the extrema of each contact coordinate (default
        :func:`reduced.periodic.exact_hb.default_root_samples`)
    point_rows, point_names : (p, n) output points (default: the DOFs)
    x_ref : m, scale of the contact coordinates in the continuation (default
        :func:`default_x_ref`)
    ds, ds_max, max_steps, max_angle_deg : continuation step control (scaled unknowns)
    stability : orbit monodromy at every point (and Hill's method, see ``hill_points``)
    hill_points : Hill's method at every point (None) or at most this many, evenly spread
    progress : None or a callable taking the fraction of the band done

    Returns an :class:`FRCBranch`. Arguments are checked before any work (one-line
    :class:`reduced._checks.InvalidArgument`).
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
    if x_ref is not None:
        x_ref = _check.positive("x_ref", x_ref, "m")
    for key, v in (("ds", ds), ("ds_max", ds_max), ("max_angle_deg", max_angle_deg)):
        _check.positive(key, v)
    max_steps = _check.integer("max_steps", max_steps)
    stability = _check.flag("stability", stability)
    if hill_points is not None:
        hill_points = _check.integer("hill_points", hill_points, lo=0)
    _check.callback("progress", progress)
    if system.m == 0:
        raise _check.InvalidArgument("system has no stops: its FRC is the linear FRF (use linear_frf)")
    fb = ForcedBalance(system, b, P, phase_deg, H, N or default_root_samples(H), harmonics == "odd")
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        return _frc(fb, f0, f1, rows, names, x_ref, ds, ds_max, max_steps, max_angle_deg, stability,
                    hill_points, progress)


def linear_frf(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz: np.ndarray,
               rows: np.ndarray | None = None) -> np.ndarray:
    """(k, p) m: |rows (K - Omega^2 M + i Omega C)^-1 b P| with every stop open (the FRF of the linear part)."""
    rows = np.eye(system.n) if rows is None else np.atleast_2d(rows)
    out = []
    for f in np.atleast_1d(freq_hz):
        w = 2.0 * np.pi * float(f)
        x = np.linalg.solve(system.K - w**2 * system.M + 1j * w * system.C, np.asarray(load, float) * amplitude_N)
        out.append(np.abs(rows @ x))
    return np.array(out)


def default_x_ref(fb: ForcedBalance, f_min_hz: float, f_max_hz: float) -> float:
    """m, scale of the contact coordinates: their largest linear open-stop response over the band,
    but no more than the stops let through (largest stop offset + the closed-state response)."""
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


def _frc(fb, f0, f1, rows, names, x_ref, ds, ds_max, max_steps, max_angle_deg, stability, hill_points,
         progress) -> FRCBranch:
    t0 = time.perf_counter()
    if x_ref is None:
        x_ref = default_x_ref(fb, f0, f1)
    w0, w1 = 2 * np.pi * f0, 2 * np.pi * f1
    res = ForcedResidual(fb, x_ref, w1)
    i_w = res.size
    y_lo, y_hi = math.log(w0 / w1), 0.0

    def stop(y):
        return y[i_w] > y_hi or y[i_w] < y_lo - 1e-12

    def prog(y):
        if progress is not None:
            progress(min(max((y[i_w] - y_lo) / (y_hi - y_lo), 0.0), 1.0))

    cos_secant = math.cos(math.radians(max_angle_deg))

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

    def piece(w_start, direction, steps):
        try:
            return continue_branch(res, _start(res, w_start), param=i_w, direction=direction, ds=ds, ds_max=ds_max,
                                   max_steps=steps, max_angle_deg=max_angle_deg, stop=stop, progress=prog,
                                   monitor=corner, reject=reject)
        except ContinuationError as exc:
            raise ContinuationError(f"FRC at {fb.amplitude_N:g} N, H = {fb.H}: {exc}") from None

    pieces = [piece(w0, 1.0, max_steps)]
    notes = []
    if pieces[0].status != "stop":
        # the curve ended inside the band (an internal-resonance tongue it could not pass): take it
        # up again from the top of the band, downwards, as a second segment (not joined to the first)
        f_end = w1 * math.exp(pieces[0].y[-1][i_w]) / (2 * np.pi)
        notes.append(f"segment 0 ended early ({pieces[0].status}) at {f_end:.4g} Hz; segment 1 continued "
                     f"down from {f1:g} Hz")
        try:
            pieces.append(piece(w1 * (1.0 - 1e-9), -1.0, max_steps))
        except ContinuationError as exc:
            notes.append(f"segment 1 failed: {exc}")
    Ys, seg, folds, n_rej, status = [], [], [], 0, []
    for k, br in enumerate(pieces):
        Y = br.y
        if len(Y) > 1 and stop(Y[-1]):  # the last point lies just past the band
            Y = Y[:-1]
        folds += [i + sum(len(y) for y in Ys) for i, c in br.folds if c == i_w and i < len(Y)]
        Ys.append(Y)
        seg.append(np.full(len(Y), k))
        n_rej += br.n_rejected
        status.append(br.status)
    if len(pieces) > 1 and pieces[1].status != "stop":
        notes.append(f"segment 1 ended early ({pieces[1].status}) at "
                     f"{w1 * math.exp(pieces[1].y[-1][i_w]) / (2 * np.pi):.4g} Hz")
    Y = np.concatenate(Ys)
    segment = np.concatenate(seg)
    folds = sorted(set(folds))
    Z = Y[:, :i_w] * x_ref
    omega = w1 * np.exp(Y[:, i_w])
    X = np.array([fb.response(z, w) for z, w in zip(Z, omega, strict=True)])
    amp = np.array([max_abs_over_period(x, rows) for x in X])
    harm = np.array([harmonic_amplitudes(x, rows) for x in X])
    wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    n2 = 2 * fb.n
    if stability:
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
    else:
        mu = np.zeros((len(Z), n2), complex)
        stable = np.ones(len(Z), bool)
        bif = [(i, "fold") for i in folds]
        hidx, hill = np.zeros(0, int), np.zeros((0, n2), complex)
    return FRCBranch(fb.amplitude_N, fb.H, "odd" if fb.odd else "all", omega / (2 * np.pi), omega, X, Z, names,
                     rows, amp, harm, mu, stable, hidx, hill, bif, folds, fb, x_ref, "+".join(status), n_rej, wall,
                     time.perf_counter() - t1, notes, segment)


def solution_at_frequency(br: FRCBranch, freq_hz: float, amplitude_ref: float | None = None, col: int = 0,
                          stable_only: bool = True):
    """(amplitudes (p,), index of the piece, X (2H+1, n)) of the HB solution exactly at ``freq_hz`` on
    the piece of the curve bracketing it (stable at both ends if ``stable_only``) whose amplitude
    at point ``col`` is nearest ``amplitude_ref``: Newton at fixed frequency from the
    interpolated point. (None, -1, None) where no such piece brackets the frequency."""
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



# -- Floquet multipliers by shooting on the forced exact flow --------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedOrbit:
    """A periodic orbit of the forced exact flow and its Floquet multipliers."""

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


class ShootingError(RuntimeError):
    """Newton on the periodicity of the forced flow did not converge."""


def floquet_by_shooting(flow, Y: np.ndarray, period_s: float, *, tol: float = 1e-11, max_iter: int = 30
                        ) -> ForcedOrbit:
    """The periodic orbit of the forced exact flow ``flow`` (``Flow(system, loads=...)``, load
    period ``period_s``) through the states Y (S, 2n) guessed at t_k = k T / S (one row: single
    shooting), by multiple shooting, and its Floquet multipliers.

    Unknowns Y; equations phi(Y_k; t_k, T / S) - Y_{k+1} = 0 (cyclic), solved by damped Newton
    with the exact segment Jacobians. Each segment sees only the S-th root of the monodromy's
    growth, so orbits with multipliers of 1e3 (the contact plateau of the three-mass model) are
    found where single shooting's Newton diverges. The monodromy is the product of the segment
    Jacobians. Raises :class:`ShootingError` if the closure stays above ``tol`` (relative).
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
    """(S, 2n) states [x; v] of the HB orbit X (2H+1, n) at the phases 2 pi k / S."""
    H = (X.shape[0] - 1) // 2
    E = _synthesis_matrix(H, _phases(S))
    return np.hstack([E @ X, omega * (E @ (_derivative_matrix(H) @ X))])


# -- the reference: stepped sine by the exact integrator -------------------------------------------
SETTLE_ROUNDOFF = 1e-10  # relative change over a period below which the exact flow's round-off dominates
SETTLE_BLOCK_PERIODS = 8  # periods between the periodicity checks of the stepped sine (grows x2 up to 64)
RESPONSES = ("periodic", "settling", "period_2", "not_settled")
SETTLING_ERROR = 1e-3  # a response still contracting at the time limit, with a predicted error below this


@dataclass(eq=False)
class SteppedSine:
    """A stepped-sine sweep by the exact integrator: one entry per frequency, in sweep order.

    ``response``: "periodic" (settled to the load's period within the tolerance),
    "settling" (still contracting to a periodic orbit at the time limit, predicted distance
    ``settle_error`` < 1e-3), "period_2" (settled to twice the period) or "not_settled"
    (none of these within ``max_settle_s``: quasi-periodic or chaotic). ``asymmetry``:
    max |x_a - x_b| / max(|x_a|, |x_b|) over the last period for the point pair ``mirror``
    (x1, x3: zero on the symmetric orbit). ``settle_error``: the
    predicted distance of the last state from the periodic orbit (relative), from the
    period-to-period change d and its contraction rho, d rho / (1 - rho).
    """

    amplitude_N: float
    freq_hz: np.ndarray  # (k,)
    point_names: tuple[str, ...]
    amplitude_m: np.ndarray  # (k, p) max |x| over the last period (over the last window if not settled)
    response: list  # (k,) str
    settle_error: np.ndarray  # (k,)
    settle_s: np.ndarray  # (k,) simulated time spent at each frequency
    asymmetry: np.ndarray  # (k,)
    wall_s: np.ndarray  # (k,)
    final_state: np.ndarray  # (2n,) where the sweep ended

    @property
    def settled(self) -> np.ndarray:
        return np.array([r != "not_settled" for r in self.response])


def slowest_decay_rate(system: GapSystem, load: np.ndarray | None = None) -> float:
    """1/s, the smallest -Re(lam) of the damped modes of the all-open and the closed state (those
    the load moves, modal force above 1e-9 of the largest, if ``load`` is given): the slowest
    linear transient a sweep starts decays like exp(-rate t). (A mode the load leaves
    at rest, such as a reduced beam's antisymmetric bending with a node at every dashpot,
    would otherwise set hours of settling.)"""
    rates = []
    n = system.n
    Minv = np.linalg.inv(system.M)
    for K in (system.K, system.closed_stiffness()):
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ system.C]])
        lam, V = np.linalg.eig(A)
        keep = np.ones(lam.size, bool)
        if load is not None:
            # the modal force of the load on each eigenvector (left eigenvectors: rows of V^-1)
            part = np.abs(np.linalg.inv(V)[:, n:] @ (Minv @ np.asarray(load, float)))
            keep = part > 1e-9 * part.max()
        rates.append(float(np.min(-lam[keep].real)))
    rate = min(rates)
    if not rate > 0.0:
        raise _check.InvalidArgument("system must be damped for a stepped sine to settle (a linear state has a "
                                     f"mode decaying at {rate:.3g} 1/s)")
    return rate


def stepped_sine(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz, *, point_rows=None,
                 point_names=None, mirror=("x1", "x3"), settle_tol: float = 1e-6, max_settle_s: float = 10.0,
                 samples_per_period: int = 2048, y0=None, progress=None) -> SteppedSine:
    """Stepped sine by the exact flow: at each frequency (in the order given: a sweep up or down)
    the load b P cos(2 pi f t) runs from the state the previous frequency ended in (rest at the
    first, or ``y0``) until the response is periodic, then the amplitude is read.

    Settling: the state is mapped period by period with the exact forced flow
    (:class:`reduced.transient.flow.Flow`, loads included: the exact integrator's march), first
    for ln(1 / settle_tol) / sigma (sigma: :func:`slowest_decay_rate`, the time in which the
    slowest linear transient falls by ``settle_tol``), then in blocks of growing length; after
    each block the change d over one period and its contraction rate rho per period predict
    the remaining distance d rho / (1 - rho) (relative to the orbit's size); settled when it is
    below ``settle_tol`` (else twice the period is tried, else "not_settled" after
    ``max_settle_s`` of simulated time). The amplitude is then max |r . x| over one period
    sampled at ``samples_per_period`` points by :func:`reduced.transient.ringdown` (exact
    method, the load on): relative sampling error about (pi / samples)^2 / 2.
    """
    from reduced.models.loads import Harmonic, Loads
    from reduced.transient.exact import ExactIntegratorError
    from reduced.transient.flow import Flow
    from reduced.transient.integrate import ringdown

    _check.gap_system(system)
    b = _check.vector("load", load, system.n)
    P = _check.positive("amplitude_N", amplitude_N, "N")
    freqs = np.atleast_1d(_check.series("freq_hz", freq_hz))
    if np.any(freqs <= 0.0):
        raise _check.InvalidArgument("freq_hz must be > 0 Hz")
    settle_tol = _check.number("settle_tol", settle_tol, lo=0.0, hi=1.0)
    max_settle_s = _check.positive("max_settle_s", max_settle_s, "s")
    samples_per_period = _check.integer("samples_per_period", samples_per_period, lo=8)
    rows = np.eye(system.n) if point_rows is None else np.atleast_2d(np.asarray(point_rows, float))
    names = tuple(point_names or system.dof_names)
    n = system.n
    y = np.zeros(2 * n) if y0 is None else _check.vector("y0", y0, 2 * n)
    pair = [names.index(m) for m in mirror] if all(m in names for m in mirror) else None
    t_min = min(math.log(1.0 / settle_tol) / slowest_decay_rate(system, b), max_settle_s)
    out = {k: [] for k in ("amp", "resp", "err", "settle", "asym", "wall")}
    for i, f in enumerate(freqs):
        t0 = time.perf_counter()
        T = 1.0 / float(f)
        loads = Loads(b[None, :], (Harmonic(P, float(f)),))
        flow = Flow(system, loads=loads)

        def period(y, k=1, flow=flow, T=T):
            return flow(y[:n], y[n:], k * T).y

        t_sim, resp, err = 0.0, "not_settled", np.inf
        try:
            # first the time in which the slowest linear transient decays by settle_tol
            k0 = max(int(math.ceil(t_min * f)) - 1, 0)
            if k0:
                y = period(y, k0)
                t_sim += k0 * T
            block, d_prev, checks = 1, None, 0
            while True:
                checks += 1
                y1 = period(y)
                t_sim += T
                xs = max(float(np.max(np.abs(y[:n]))), float(np.max(np.abs(y1[:n]))), 1e-300)
                sc = np.concatenate([np.full(n, xs), np.full(n, xs * 2 * np.pi * f)])
                d = float(np.max(np.abs(y1 - y) / sc))
                y = y1
                if d <= SETTLE_ROUNDOFF:  # periodic to the flow's round-off
                    resp, err = "periodic", d
                    break
                if d_prev is not None:
                    rho = (d / d_prev) ** (1.0 / block)
                    err = d * rho / (1.0 - rho) if rho < 1.0 else np.inf
                    if err <= settle_tol:
                        resp = "periodic"
                        break
                if t_sim >= max_settle_s and checks >= 3:
                    break
                block = min(2 * block, SETTLE_BLOCK_PERIODS * 8)
                y = period(y, block - 1)
                t_sim += (block - 1) * T
                d_prev = d
            if resp != "periodic" and err < SETTLING_ERROR:
                resp = "settling"  # still contracting at the time limit: the error is err
            if resp == "not_settled":
                y2 = period(period(y))
                xs = max(float(np.max(np.abs(y[:n]))), 1e-300)
                sc = np.concatenate([np.full(n, xs), np.full(n, xs * 2 * np.pi * f)])
                d2 = float(np.max(np.abs(y2 - y) / sc))
                if d2 <= 10.0 * max(settle_tol, 1e-12) and d > 100.0 * d2:
                    resp, err = "period_2", d2
            window = 1 if resp in ("periodic", "settling") else (2 if resp == "period_2" else 10)
            r = ringdown(system, y[:n], y[n:], window * T, samples_per_period * float(f), method="exact",
                         loads=loads)
            xp = r.x[-(window * samples_per_period + 1):] @ rows.T
            y = np.concatenate([r.x[-1], r.v[-1]])
        except ExactIntegratorError as exc:
            raise RuntimeError(f"stepped sine at {f:.6g} Hz, {P:g} N: {exc}") from None
        amp = np.max(np.abs(xp), axis=0)
        if pair is not None:
            a, c = xp[-samples_per_period - 1:, pair[0]], xp[-samples_per_period - 1:, pair[1]]
            asym = float(np.max(np.abs(a - c)) / max(np.max(np.abs(a)), np.max(np.abs(c)), 1e-300))
        else:
            asym = np.nan
        for key, v in (("amp", amp), ("resp", resp), ("err", err), ("settle", t_sim), ("asym", asym),
                       ("wall", time.perf_counter() - t0)):
            out[key].append(v)
        if progress is not None:
            progress((i + 1) / freqs.size)
    return SteppedSine(P, freqs, names, np.array(out["amp"]), out["resp"], np.array(out["err"]),
                       np.array(out["settle"]), np.array(out["asym"]), np.array(out["wall"]), y)


__all__ = [
    "ForcedBalance",
    "ForcedResidual",
    "FRCBranch",
    "ForcedOrbit",
    "ShootingError",
    "frc",
    "linear_frf",
    "default_x_ref",
    "orbit_monodromy",
    "state_matrix",
    "multipliers_of",
    "forced_hill",
    "floquet_by_shooting",
    "hb_states",
    "stepped_sine",
    "solution_at_frequency",
    "slowest_decay_rate",
    "SteppedSine",
    "RESPONSES",
    "bifurcations",
    "classify_crossing",
    "max_abs_over_period",
    "harmonic_amplitudes",
    "BIFURCATIONS",
    "HARMONIC_SETS",
    "STABILITY_TOL",
    "HILL_TOL",
]
