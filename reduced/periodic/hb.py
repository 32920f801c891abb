"""Harmonic balance (HB) for M x'' + C x' + K x + f_nl(x) = 0 with alternating frequency/time.

Layer 1 of the three-layer design (NLvib's ``HB_residual``): residuals with analytic
Jacobians. Layer 2 is :func:`newton` (below), layer 3 :mod:`reduced.periodic.continuation`.

Ansatz (real Fourier series in the phase tau = omega t, H harmonics)::

    x(tau) = c_0 + sum_{k=1..H} [ c_k cos(k tau) + s_k sin(k tau) ],    c_k, s_k in R^n.

**Layout of the coefficient vector X** (length n (2H + 1), harmonic-major)::

    X.reshape(2H + 1, n) = [c_0; c_1; s_1; c_2; s_2; ...; c_H; s_H]

so row ``h`` holds harmonic ``(h + 1) // 2``, a cosine for odd h, a sine for even h > 0.
Every operator that acts on a single harmonic is a Kronecker product ``kron(D, A)`` of a
(2H+1)x(2H+1) harmonic matrix D and an n x n structural matrix A.

Galerkin projection onto the same basis gives (paper, Eq. 4)

    R(X, omega) = [ kron(I, K) + omega^2 kron(Nab^2, M) + omega kron(Nab, C) ] X + F(X) = 0,

with Nab the derivative operator (d/dtau of cos(k tau) is -k sin(k tau); Nab^2 = -k^2 on
harmonic k) and F the Fourier
coefficients of f_nl(x(tau)). Alternating frequency/time (AFT, Cameron & Griffin 1989):
x is synthesised at N equally spaced phases, f_nl evaluated there, and projected back::

    x_i = sum_h E[i, h] X_h,      F_h = sum_i P[h, i] f(x_i),     P E = I  (N > 2H),

and dF/dX = sum_r kron(P diag(w_r) E, Q_r) when the force Jacobian at each sample is
written df/dx(x_i) = sum_r w_r(x_i) Q_r (for a gap system, r runs over the stops,
w_r = k_r [stop r closed] and Q_r = B_r^T B_r), exactly the derivative of the discrete
AFT map wherever no sample sits on a kink.

**How many samples.** For a polynomial force of degree d, N >= (d + 1) H + 1 makes the
AFT projection exact (4H + 1 for a cubic). A gap force is not polynomial: f(x(t)) has a
kink wherever a stop opens or closes, its harmonics decay only like k^-2 and the
trapezoidal projection of a kinked function errs by O(N^-2) whatever H is; the contact
pulse near grazing is also much shorter than the period. :func:`default_samples` takes
N = 2^ceil(log2(32 (2H + 1))): enough that AFT error stays below the truncation error of
H harmonics in the convergence study (hb_convergence.csv shows both).
"""

from __future__ import annotations

import functools
import math
import threading
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import LinAlgWarning, get_lapack_funcs, lu_factor, lu_solve

from reduced import _checks as _check
from reduced.models.gaps import GapSystem

SAMPLES_PER_COEFFICIENT = 32  # AFT samples per Fourier coefficient (gap forces need >> 2)
NEWTON_HALVINGS = 6  # trial steps of a Newton iteration: dy, dy/2, ..., dy/32
BLOCK_SOLVE_MIN_H = 15  # NNMResidual.solve_bordered from this H on. Measured on rom-fep's 12-coordinate model (CPU
# a branch): H = 25 12.5 -> 5.2 s, H = 15 6.7 -> 3.8 s (NNM 1) and 3.5 -> 2.0 s (NNM 2); at H = 9 a solve is 1.5x
# faster too, but the branches of H = 9 are drawn (fep.png), guide the shooting and give the stability, and a
# continuation path follows the last bits of its solves (results/rom-fep: from H = 15 on only the convergence
# study's branches change, at round-off, their tongue anchors with them)
BLOCK_SOLVE_TOL = 1e-12  # NNMResidual.solve_bordered: a residual |J z - r| above this times |J| |z| + |r| takes
# the dense LU instead (a dense LU's is ~1e-16 of it; an ill-conditioned harmonic block would show here)


class NewtonError(RuntimeError):
    """Newton's method did not converge (message: iterations, residual, step)."""


class GuardRefusal(NewtonError):
    """A trial point refused by a guard of the residual (e.g. a grazing crossed in a step longer than the
    guard allows), not a failure of Newton's method: the continuation shortens the step, and may take up
    the step it had before once the guard is passed (:class:`reduced.periodic.continuation.ContinuationOptions`
    ``resume_after_guard``)."""


def default_samples(H: int) -> int:
    """AFT samples per period for H harmonics with a gap force: a power of 2, >= 32 (2H+1).

    Parameters
    ----------
    H : int
        Harmonics.

    Returns
    -------
    int
        N = 2^ceil(log2(SAMPLES_PER_COEFFICIENT (2H + 1))).
    """
    return int(2 ** math.ceil(math.log2(SAMPLES_PER_COEFFICIENT * (2 * H + 1))))


# -- nonlinear forces in AFT form ------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class GapForce:
    """f_nl(x) = B^T f(B x) of a :class:`GapSystem`; df/dx = sum_j k_j [closed_j] B_j^T B_j.

    Parameters
    ----------
    system : GapSystem
        The stops: rows B (m, n), stiffness k, offsets and sides.
    """

    system: GapSystem

    @property
    def Q(self) -> np.ndarray:
        """(m, n, n) the outer products B_j^T B_j."""
        B = self.system.B
        return np.einsum("ji,jk->jik", B, B)

    def __call__(self, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces (N, n) and weights w (N, m) at the samples xs (N, n)."""
        s = self.system
        d = xs @ s.B.T - s.offset
        closed = s.side * d > 0.0
        w = np.where(closed, s.k, 0.0)
        return (w * d) @ s.B, w

    def potential(self, xs: np.ndarray) -> np.ndarray:
        """J, (N,) the stops' energy sum_j k_j max(penetration_j, 0)^2 / 2 at the samples xs (N, n)."""
        s = self.system
        pen = np.maximum(s.penetration(xs), 0.0)
        return 0.5 * (pen**2) @ s.k


@dataclass(frozen=True, eq=False)
class CubicForce:
    """f_nl(x) = gamma x^3 on every DOF (for tests: the Duffing oscillator).

    Parameters
    ----------
    gamma : (n,) ndarray of float
        N/m^3, cubic stiffness on each DOF.
    """

    gamma: np.ndarray  # N/m^3, (n,)

    @property
    def Q(self) -> np.ndarray:
        n = self.gamma.size
        Q = np.zeros((n, n, n))
        Q[np.arange(n), np.arange(n), np.arange(n)] = 1.0
        return Q

    def __call__(self, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.gamma * xs**3, 3.0 * self.gamma * xs**2

    def potential(self, xs: np.ndarray) -> np.ndarray:
        """J, (N,) sum_i gamma_i x_i^4 / 4 at the samples xs (N, n)."""
        return 0.25 * (xs**4) @ self.gamma


# -- the harmonic basis -----------------------------------------------------------------------
def _phases(N: int) -> np.ndarray:
    """(N,) the equally spaced phases tau_i = 2 pi i / N of one period."""
    return 2.0 * np.pi * np.arange(N) / N


def _synthesis_matrix(H: int, tau: np.ndarray) -> np.ndarray:
    """(N, 2H+1) E with x(tau_i) = sum_h E[i, h] X_h: columns 1, cos tau, sin tau, ..., sin H tau."""
    E = np.ones((tau.size, 2 * H + 1))
    for k in range(1, H + 1):
        E[:, 2 * k - 1] = np.cos(k * tau)
        E[:, 2 * k] = np.sin(k * tau)
    return E


def _projection_matrix(H: int, tau: np.ndarray) -> np.ndarray:
    """(2H+1, N) P, the trapezoidal Fourier coefficients of N samples: P E = I for N > 2H."""
    N = tau.size
    P = np.full((2 * H + 1, N), 1.0 / N)
    for k in range(1, H + 1):
        P[2 * k - 1] = 2.0 / N * np.cos(k * tau)
        P[2 * k] = 2.0 / N * np.sin(k * tau)
    return P


def _derivative_matrix(H: int) -> np.ndarray:
    """(2H+1, 2H+1) Nab, d/dtau on the coefficient rows: (c_k, s_k) -> (k s_k, -k c_k)."""
    Nab = np.zeros((2 * H + 1, 2 * H + 1))
    for k in range(1, H + 1):
        # x = c cos + s sin  ->  dx/dtau = (k s) cos + (-k c) sin
        Nab[2 * k - 1, 2 * k] = k
        Nab[2 * k, 2 * k - 1] = -k
    return Nab


# -- the harmonic balance operator ---------------------------------------------------------
@dataclass(frozen=True, eq=False)
class HarmonicBalance:
    """HB discretisation of M x'' + C x' + K x + f_nl(x) = 0 with H harmonics, N AFT samples.

    ``force(xs) -> (f (N, n), w (N, r))`` and ``force.Q`` (r, n, n) give the nonlinear force
    and its Jacobian df/dx = sum_r w_r Q_r at the samples (see the module docstring).

    Parameters
    ----------
    M, K : (n, n) ndarray of float
        Mass and stiffness (kg, N/m on physical coordinates).
    force : callable
        ``force(xs) -> (f (N, n), w (N, r))`` with a ``Q`` (r, n, n) attribute, e.g.
        :class:`GapForce` or :class:`CubicForce`; an optional ``potential(xs) -> (N,)``.
    H : int
        Harmonics, >= 0.
    N : int
        AFT samples per period, > 2H.
    C : (n, n) ndarray of float, optional
        N s/m; None for the conservative (NNM) problem.

    Attributes
    ----------
    E : (N, 2H+1) ndarray of float
        Synthesis matrix, x_i = E[i] X.
    P : (2H+1, N) ndarray of float
        Projection matrix, P E = I.
    Nab : (2H+1, 2H+1) ndarray of float
        d/dtau on the coefficients.
    Qr : (r, n, n) ndarray of float
        ``force.Q``.

    Raises
    ------
    InvalidArgument
        H or N not an integer in range, or N <= 2H.
    """

    M: np.ndarray
    K: np.ndarray
    force: object
    H: int
    N: int
    C: np.ndarray | None = None  # N s/m; None for the conservative (NNM) problem
    E: np.ndarray = field(init=False, repr=False)  # (N, 2H+1) synthesis
    P: np.ndarray = field(init=False, repr=False)  # (2H+1, N) projection
    Nab: np.ndarray = field(init=False, repr=False)  # (2H+1, 2H+1) d/dtau
    Qr: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        H = _check.integer("H", self.H, lo=0)
        N = _check.integer("N", self.N, lo=1)
        if N <= 2 * H:
            raise _check.InvalidArgument(f"N must exceed 2H = {2 * H} for the projection to invert synthesis, "
                                         f"got {N}")
        tau = _phases(N)
        object.__setattr__(self, "E", _synthesis_matrix(H, tau))
        object.__setattr__(self, "P", _projection_matrix(H, tau))
        object.__setattr__(self, "Nab", _derivative_matrix(H))
        object.__setattr__(self, "Qr", np.asarray(self.force.Q, float))

    @classmethod
    def for_system(cls, system: GapSystem, H: int, N: int | None = None, damped: bool = False):
        """HB of a gap system (conservative unless ``damped``; refused with friction)."""
        _check.frictionless(system, "harmonic balance")
        H = _check.integer("H", H, lo=0)
        return cls(
            system.M, system.K, GapForce(system), H, N or default_samples(H), system.C if damped else None
        )

    # -- sizes and layout -----------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.M.shape[0]

    @property
    def size(self) -> int:
        """Length of X: n (2H + 1)."""
        return self.n * (2 * self.H + 1)

    def unpack(self, X: np.ndarray) -> np.ndarray:
        """(2H+1, n) rows [c_0, c_1, s_1, ..., c_H, s_H] from the flat X (module docstring)."""
        return np.asarray(X).reshape(2 * self.H + 1, self.n)

    def harmonic_numbers(self) -> np.ndarray:
        """(2H+1,) harmonic k of each row of the unpacked X."""
        return (np.arange(2 * self.H + 1) + 1) // 2

    def pack_modes(self, amplitudes: dict[int, np.ndarray]) -> np.ndarray:
        """X with cosine coefficients {k: c_k}; the rest zero."""
        Xm = np.zeros((2 * self.H + 1, self.n))
        for k, c in amplitudes.items():
            Xm[0 if k == 0 else 2 * k - 1] = c
        return Xm.ravel()

    def time_series(self, X: np.ndarray, omega: float | None = None, N: int | None = None):
        """x at N phases (N, n); with ``omega``, also the velocity dx/dt (N, n)."""
        Xm = self.unpack(X)
        E = self.E if N is None else _synthesis_matrix(self.H, _phases(N))  # synthesis only: any N >= 1
        x = E @ Xm
        if omega is None:
            return x
        return x, omega * (E @ (self.Nab @ Xm))

    @functools.cached_property
    def synthesis_derivative(self) -> np.ndarray:
        """(N, 2H+1) E Nab: dx/dtau at the samples is E Nab X."""
        return self.E @ self.Nab

    # -- AFT: F(X) and dF/dX ----------------------------------------------------------------
    def aft(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F(X) (size,) and dF/dX (size, size) by alternating frequency/time."""
        f, w = self.force(self.E @ self.unpack(X))
        return (self.P @ f).ravel(), self._aft_jacobian(w)

    @functools.cached_property
    def _gram_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(i1, s1, i2, s2), each (2H+1, 2H+1), for :meth:`weighted_gram`: c_h times the product of
        basis functions h and h' is s1 T[i1] + s2 T[i2] with T = [cos 0 .. cos 2H, sin 0 .. sin 2H] tau
        (the identities' 1/2 and c_h folded into s1, s2)."""
        H = self.H
        k = self.harmonic_numbers()
        sine = (np.arange(2 * H + 1) % 2 == 0) & (k > 0)
        j, kk = k[:, None], k[None, :]
        sj, sk = sine[:, None], sine[None, :]
        d = j - kk
        S0 = 2 * H + 1  # offset of the sines in T
        # cos j cos k = 1/2 [cos(j-k) + cos(j+k)]     sin j sin k = 1/2 [cos(j-k) - cos(j+k)]
        # cos j sin k = 1/2 [sin(j+k) - sin(j-k)]     sin j cos k = 1/2 [sin(j+k) + sin(j-k)]
        mixed = sj != sk
        i1 = np.where(mixed, S0 + np.abs(d), np.abs(d))
        s1 = np.where(mixed, np.where(sj, 1.0, -1.0) * np.sign(d), 1.0)
        i2 = np.where(mixed, S0 + j + kk, j + kk)
        s2 = np.where(sj & sk, -1.0, 1.0)
        half_c = np.where(np.arange(2 * H + 1) == 0, 0.5, 1.0)[:, None]  # c_h / 2: c_0 = 1, else 2
        return i1, half_c * s1, i2, half_c * s2

    def weighted_gram(self, w: np.ndarray) -> np.ndarray:
        """G = P diag(w) E (2H+1, 2H+1) for sample weights w (N,), from the DFT of w; for w (N, r),
        one G per column (r, 2H+1, 2H+1).

        G[h, h'] = c_h / N sum_i w_i E[i, h] E[i, h'] (c_0 = 1, else 2), and the product of two
        basis functions is a sum of two harmonics of order <= 2H (the identities in
        :attr:`_gram_index`, exact at every sample), so G needs only the trapezoidal sums
        A_m = 1/N sum_i w_i cos(m tau_i) and S_m = 1/N sum_i w_i sin(m tau_i), m <= 2H < N, which
        are one FFT: O(N log N + H^2) instead of the O(N H^2) product (150x at H = 50, N = 4096).
        Equal to the product to round-off (tests/test_hb.py).
        """
        w = np.asarray(w, float)
        Fw = np.fft.fft(w.T)[..., : 2 * self.H + 1] / self.N  # A_m - i S_m, a row per column of w
        T = np.concatenate([Fw.real, -Fw.imag], axis=-1)
        i1, s1, i2, s2 = self._gram_index  # c_h / 2 folded into s1, s2
        G = np.take(T, i1, axis=-1)
        G *= s1
        G2 = np.take(T, i2, axis=-1)
        G2 *= s2
        G += G2
        return G

    def _aft_jacobian(self, w: np.ndarray) -> np.ndarray:
        """dF/dX = sum_r kron(P diag(w_r) E, Q_r) (size, size) from the force weights w (N, r):
        every column's Gram matrix (one FFT each), contracted with the Q_r at once."""
        if not w.any():
            return np.zeros((self.size, self.size))
        G = self.weighted_gram(w)  # (r, h, h'), zero for a stop that never closes
        h, n, r = 2 * self.H + 1, self.n, w.shape[1]
        dF = G.reshape(r, h * h).T @ self.Qr.reshape(r, n * n)  # (h h', i j)
        return dF.reshape(h, h, n, n).transpose(0, 2, 1, 3).reshape(self.size, self.size)

    # -- the linear part and the residual -----------------------------------------------------
    def linear_operator(self, omega: float) -> np.ndarray:
        """A(omega) = kron(I, K) + omega^2 kron(Nab^2, M) + omega kron(Nab, C)."""
        I = np.eye(2 * self.H + 1)
        A = np.kron(I, self.K) + omega**2 * np.kron(self.Nab @ self.Nab, self.M)
        if self.C is not None:
            A += omega * np.kron(self.Nab, self.C)
        return A

    def _linear_operator_domega(self, omega: float) -> np.ndarray:
        """dA/domega = 2 omega kron(Nab^2, M) + kron(Nab, C) (size, size)."""
        dA = 2.0 * omega * np.kron(self.Nab @ self.Nab, self.M)
        if self.C is not None:
            dA += np.kron(self.Nab, self.C)
        return dA

    def residual(self, X: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R(X, omega) = A(omega) X + F(X) (size,), dR/dX = A + dF/dX, dR/domega = dA/domega X (Eq. 4)."""
        X = np.asarray(X, float)
        F, dF = self.aft(X)
        A = self.linear_operator(omega)
        return A @ X + F, A + dF, self._linear_operator_domega(omega) @ X

    # -- post-processing ------------------------------------------------------------------
    def energy(self, X: np.ndarray, omega: float, potential=None) -> float:
        """J, mean over the AFT samples of T + V (constant along an exact conservative orbit).

        ``potential(xs) -> (N,)`` is the nonlinear potential; by default the force's own
        ``potential`` method (:class:`GapForce`, :class:`CubicForce`; zero if it has none).
        """
        x, v = self.time_series(X, omega)
        N = x.shape[0]
        # sum_i v_i^T M v_i as one dot product of the flattened arrays (a per-sample sum over the
        # short axis, or a three-operand einsum, costs 3-10x more)
        quad = (np.vdot(v @ self.M, v) + np.vdot(x @ self.K, x)) / (2 * N)
        potential = potential or getattr(self.force, "potential", None)
        return float(quad + (0.0 if potential is None else np.mean(potential(x))))

    def hill_matrices(self, X: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(J0, J1, J2) of Hill's quadratic eigenproblem (J2 lam^2 + J1 lam + J0) p = 0.

        A perturbation e^{lam t} p(tau) of the periodic solution, p in the HB basis, obeys
        J0 = dR/dX, J1 = 2 omega kron(Nab, M) + kron(I, C), J2 = kron(I, M).
        J0 is :meth:`residual`'s A + dF/dX (the same bits) without R and dR/domega, which Hill does not use.
        """
        _, w = self.force(self.E @ self.unpack(np.asarray(X, float)))
        J0 = self.linear_operator(omega) + self._aft_jacobian(w)
        I = np.eye(2 * self.H + 1)
        J1 = 2.0 * omega * np.kron(self.Nab, self.M)
        if self.C is not None:
            J1 += np.kron(I, self.C)
        return J0, J1, np.kron(I, self.M)


def _diagonal_blocks(A: np.ndarray, n: int) -> np.ndarray:
    """(h, n, n) view of the h diagonal n x n blocks of the C-contiguous square A (h n, h n)."""
    h = A.shape[0] // n
    st = A.strides
    return np.lib.stride_tricks.as_strided(A, shape=(h, n, n), strides=(n * (st[0] + st[1]), st[0], st[1]),
                                           writeable=A.flags.writeable)


# -- nonlinear modes: the NLvib NMA formulation -----------------------------------------------
@dataclass(frozen=True, eq=False)
class NNMResidual:
    """Residual of a conservative nonlinear normal mode for continuation in log amplitude.

    Unknowns ``y = [Psi (size), w, d, log10 a]`` (NLvib's nonlinear modal analysis,
    Krack & Gross 2019, Sec. 4.4):

    - ``X = a Psi`` are the HB coefficients (layout in the module docstring), ``a`` the
      modal amplitude (sqrt(kg) m: the mass-norm of the fundamental harmonic),
    - ``omega = w omega_ref`` (rad/s),
    - ``d`` an artificial damping coefficient, ``delta = d omega_ref``: the term
      ``-delta M x'`` makes the equations regular (in a conservative system the projection
      onto x' vanishes identically, so without it dR/dy is rank deficient); it is zero on
      every solution and serves as a check.

    Equations (size + 2), rows scaled by 1 / omega_ref^2 so they are O(Psi)::

        [ A(omega) Psi + F(a Psi) / a - delta omega kron(Nab, M) Psi ] / omega_ref^2 = 0
        Psi_{s_1}[ref] = 0                                   (phase: sine of DOF ref)
        Psi_{c_1}^T M Psi_{c_1} + Psi_{s_1}^T M Psi_{s_1} - 1 = 0   (amplitude normalisation)

    Parameters
    ----------
    hb : HarmonicBalance
        The discretisation (conservative: ``C`` None, for an NNM).
    omega_ref : float
        rad/s, scale of omega and delta (the linear mode's frequency).
    ref : int
        DOF whose fundamental sine coefficient fixes the phase.
    """

    hb: HarmonicBalance
    omega_ref: float  # rad/s
    ref: int  # DOF whose fundamental sine coefficient fixes the phase

    @property
    def size(self) -> int:
        return self.hb.size + 3

    def split(self, y: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        """Psi, omega [rad/s], delta [1/s], a  from y."""
        nX = self.hb.size
        return y[:nX], y[nX] * self.omega_ref, y[nX + 1] * self.omega_ref, 10.0 ** y[nX + 2]

    def X_omega(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        """HB coefficients X = a Psi [m] and omega [rad/s] of the point y."""
        Psi, omega, _, a = self.split(y)
        return a * Psi, omega

    @functools.cached_property
    def _operators(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kron(I, K), kron(Nab^2, M), kron(Nab, M)), built once.

        The Kronecker products do not change along a branch; rebuilding them at every call
        cost more than the LU on a 12-DOF reduced model. The sums below are the same float
        operations in the same order as :meth:`HarmonicBalance.linear_operator` and
        :meth:`HarmonicBalance._linear_operator_domega`, so the results are bit-for-bit theirs.
        """
        hb = self.hb
        I = np.eye(2 * hb.H + 1)
        return np.kron(I, hb.K), np.kron(hb.Nab @ hb.Nab, hb.M), np.kron(hb.Nab, hb.M)

    @functools.cached_property
    def _blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kron(I, K), kron(Nab^2, M), kron(Nab^2, M) (-1.0)) on their 2H+1 diagonal n x n blocks, each
        (2H+1, n, n): the only blocks of A(omega) and dA/domega that depend on omega (Nab^2 is diagonal)."""
        KI, NM2, _ = self._operators
        return _diagonal_blocks(KI, self.hb.n).copy(), _diagonal_blocks(NM2, self.hb.n).copy(), -1.0 * NM2

    @functools.cached_property
    def _scratch(self) -> threading.local:
        """Per-thread (A, dA, sign of dA's pattern) buffers of :meth:`_linear_parts`."""
        return threading.local()

    def __getstate__(self) -> dict:
        """Pickled (to another process: bearingshaft.fanout) without the per-thread buffers, which are
        rebuilt on first use there."""
        state = dict(self.__dict__)
        state.pop("_scratch", None)
        return state

    def _linear_parts(self, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """(A, dA) = (kron(I, K) + omega^2 kron(Nab^2, M), 2 omega kron(Nab^2, M)) of a conservative HB, bit
        for bit the full sums, with only the diagonal blocks recomputed (into buffers kept between calls).

        Off the diagonal blocks both are signed zeros that do not depend on omega: kron(I, K) + omega^2
        kron(Nab^2, M) there is 0 * K + omega^2 (0 * M), the sign of each zero fixed by the products'
        (omega^2 >= 0), computed once with omega^2 = 1; 2 omega (0 * M) takes the sign of omega as well,
        so dA's buffer holds the pattern of the sign of 2 omega. A non-finite omega (0 * inf is nan off
        the blocks) takes the full sums. The blocks get the same elementwise operations as the full
        sums; the matrix-vector products then run on the same matrices as before (the same BLAS sums).
        """
        KI, NM2, _ = self._operators
        w2, s = omega**2, 2.0 * omega
        if not (math.isfinite(w2) and math.isfinite(s)):
            return KI + w2 * NM2, s * NM2
        KIb, NM2b, NM2neg = self._blocks
        buf = self._scratch
        neg = bool(np.signbit(s))
        if getattr(buf, "A", None) is None:
            buf.A = KI + 1.0 * NM2
            buf.dA = (NM2neg if neg else NM2).copy()
            buf.neg = neg
            n = self.hb.n  # the views of the diagonal blocks, made once (as_strided costs ~10 us a call)
            buf.Ab, buf.dAb = _diagonal_blocks(buf.A, n), _diagonal_blocks(buf.dA, n)
            buf.omega = None
        elif neg != buf.neg:
            np.copyto(buf.dA, NM2neg if neg else NM2)
            buf.neg = neg
            buf.omega = None
        if buf.omega == omega:  # the buffers hold this omega already (lazy() then its jacobian(): the same bits)
            return buf.A, buf.dA
        Ab, dAb = buf.Ab, buf.dAb
        np.multiply(NM2b, w2, out=Ab)
        np.add(KIb, Ab, out=Ab)
        np.multiply(NM2b, s, out=dAb)
        buf.omega = omega
        return buf.A, buf.dA

    @functools.cached_property
    def _dm_blocks(self) -> tuple[tuple[slice, slice], ...]:
        """(rows, columns) of the n x n blocks of kron(Nab, M) that are not zero (Nab[p, q] != 0)."""
        n = self.hb.n
        return tuple((slice(p * n, (p + 1) * n), slice(q * n, (q + 1) * n))
                     for p, q in zip(*np.nonzero(self.hb.Nab), strict=True))

    @functools.cached_property
    def _force_pattern(self) -> tuple[tuple[int, int, tuple[int, ...]], ...] | None:
        """(i, j, the stops r with Q_r[i, j] != 0) of each entry (i, j) that some Q_r fills, when every Q_r
        holds only zeros and ones and no entry is filled by more than two stops (a gap system whose stops act
        on single coordinates: B_j a unit row); else None.

        Then dF/dX = sum_r kron(G_r, Q_r) is G_r, or G_r + G_r', on those entries of each block and zero
        elsewhere, exactly the numbers the contraction of :meth:`HarmonicBalance._aft_jacobian` gives (a
        product by 1 is exact, a sum of two terms rounds once whatever the order, added zeros change
        nothing), without its (h h', n n) product and transposed copy.
        """
        Q = self.hb.Qr
        if Q.ndim != 3 or not np.all((Q == 0.0) | (Q == 1.0)):
            return None
        out = []
        for i, j in zip(*np.nonzero(np.any(Q != 0.0, axis=0)), strict=True):
            stops = tuple(int(r) for r in np.flatnonzero(Q[:, i, j]))
            if len(stops) > 2:
                return None
            out.append((int(i), int(j), stops))
        return tuple(out)

    def _force_jacobian(self, w: np.ndarray) -> np.ndarray:
        """dF/dX (size, size) from the force weights w (N, r): :meth:`HarmonicBalance._aft_jacobian`'s numbers
        (up to the sign of its zeros), written into a per-thread buffer whose other entries stay zero when
        :attr:`_force_pattern` allows (valid until the next call in this thread)."""
        hb = self.hb
        pattern = self._force_pattern
        if pattern is None:
            return hb._aft_jacobian(w)
        buf = self._scratch
        if getattr(buf, "dF", None) is None:
            buf.dF = np.zeros((hb.size, hb.size))
        h, n = 2 * hb.H + 1, hb.n
        dF4 = buf.dF.reshape(h, n, h, n)
        if not w.any():
            for i, j, _ in pattern:
                dF4[:, i, :, j] = 0.0
            return buf.dF
        G = hb.weighted_gram(w)  # (r, h, h')
        for i, j, stops in pattern:
            if len(stops) == 1:
                dF4[:, i, :, j] = G[stops[0]]
            else:
                np.add(G[stops[0]], G[stops[1]], out=dF4[:, i, :, j])
        return buf.dF

    def _hb_rows(self, A: np.ndarray, dF: np.ndarray, delta: float, omega: float) -> np.ndarray:
        """A + dF - delta omega kron(Nab, M) (size, size), before the scaling by 1 / omega_ref^2, for the A of
        :meth:`_linear_parts` and the dF of :meth:`_force_jacobian`'s pattern buffer, summed only where a term is
        not a zero that every call has: the diagonal n x n blocks (A's), the pattern's entries (dF's) and, where
        delta != 0, the blocks of kron(Nab, M); into a per-thread buffer whose other entries stay +0.

        Elsewhere A holds signed zeros and dF +0, whose sum is +0 whatever A's sign: the full sum's numbers (a
        kron(Nab, M) block written with delta != 0 is written back to A + dF at the next call with delta = 0).
        Each entry that is summed gets the same operations in the same order as the full sum (A + dF, then
        - c DM), so the result is the full sum's bits (tests/test_fep_speedups.py); it reads and writes
        ~(2H + 1) n^2 + (2H + 1)^2 |pattern| entries instead of two passes over (n (2H + 1))^2.
        """
        hb, buf = self.hb, self._scratch
        h, n = 2 * hb.H + 1, hb.n
        T = getattr(buf, "T", None)
        if T is None:
            T = buf.T = np.zeros((hb.size, hb.size))
            buf.T4, buf.Td = T.reshape(h, n, h, n), _diagonal_blocks(T, n)
            buf.dF4, buf.dFd = dF.reshape(h, n, h, n), _diagonal_blocks(dF, n)
            pat = np.array([(i, j) for i, j, _ in self._force_pattern], int).reshape(-1, 2)
            buf.pi, buf.pj = pat[:, 0], pat[:, 1]
            buf.dm_p, buf.dm_q = np.nonzero(hb.Nab)  # the kron(Nab, M) blocks (p, q)
            buf.dirty = False
        T4, A4, dF4 = buf.T4, A.reshape(h, n, h, n), buf.dF4
        np.add(_diagonal_blocks(A, n), buf.dFd, out=buf.Td)
        pi, pj = buf.pi, buf.pj
        T4[:, pi, :, pj] = A4[:, pi, :, pj] + dF4[:, pi, :, pj]
        if delta != 0.0 or buf.dirty:
            p, q = buf.dm_p, buf.dm_q
            blk = A4[p, :, q, :] + dF4[p, :, q, :]
            if delta != 0.0:
                blk -= (delta * omega) * self._operators[2].reshape(h, n, h, n)[p, :, q, :]
            T4[p, :, q, :] = blk
            buf.dirty = delta != 0.0
        return T

    @functools.cached_property
    def _block_plan(self) -> tuple | None:
        """Index sets of :meth:`solve_bordered`'s elimination, or None (dense LU).

        F: the coefficients of the coordinates no stop acts on (nf of the n), by harmonic group (g = 0 the
        constant term, g = k the pair cos k, sin k); C: the coefficients of the coordinates the stops act
        on (nc), then the three last unknowns (w, d, log10 a); c_g: the C unknowns the rows of group g's F
        touch (its own stop coordinates and the three last), as positions in C. Returns (F0, c0, Fk (H,
        2 nf), ck (H, 2 nc + 3), C, F). Taken only where the stops act on few coordinates (nf >= 2 nc: a
        reduced model's two tips among its 12 coordinates; not the 3-DOF model) and H >= BLOCK_SOLVE_MIN_H.
        """
        pattern = self._force_pattern
        hb = self.hb
        if pattern is None or hb.H < BLOCK_SOLVE_MIN_H:
            return None
        n, nX, H = hb.n, hb.size, hb.H
        tips = np.array(sorted({i for i, _, _ in pattern} | {j for _, j, _ in pattern}))
        free = np.array([d for d in range(n) if d not in set(tips.tolist())])
        nt = tips.size
        if free.size < 2 * nt:
            return None
        border = np.arange((2 * H + 1) * nt, (2 * H + 1) * nt + 3)  # positions of w, d, log10 a in C
        F0 = free.copy()
        c0 = np.concatenate([np.arange(nt), border])
        Fk = np.array([np.concatenate([(2 * k - 1) * n + free, 2 * k * n + free]) for k in range(1, H + 1)])
        ck = np.array([np.concatenate([np.arange((2 * k - 1) * nt, (2 * k + 1) * nt), border])
                       for k in range(1, H + 1)])
        C = np.concatenate([(r * n + tips) for r in range(2 * H + 1)] + [np.arange(nX, nX + 3)])
        return F0, c0, Fk, ck, C, np.concatenate([F0, Fk.ravel()])

    @property
    def bordered_solver(self) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
        """:meth:`solve_bordered` where this model has its structure (:attr:`_block_plan`), else None (the
        callers' dense LU, as before)."""
        return self.solve_bordered if self._block_plan is not None else None

    def solve_bordered(self, J: np.ndarray, r: np.ndarray) -> np.ndarray:
        """J^-1 r for a square J (size, size) whose first hb.size rows are dR/dy's HB rows (any three rows
        below: the phase, the normalisation, and an arclength, energy or fixed-coordinate row).

        Those rows couple the coefficients of the coordinates no stop acts on only within one harmonic
        (A(omega) is block diagonal, kron(Nab, M) pairs cos k with sin k, dF/dX is zero there), and only
        to the stop coordinates of that harmonic and the three last unknowns. They are eliminated group
        by group (a small LU per harmonic, with pivoting inside it), leaving a dense LU on the stops'
        coordinates and the three last unknowns (:attr:`_block_plan`): at H = 25 on a 12-coordinate
        reduced model, 105 rows instead of 615. The same solution up to round-off; where the blocks are
        too ill-conditioned for that (a residual |J z - r| above BLOCK_SOLVE_TOL of |J| |z| + |r|), or the
        model has no such structure, the dense LU (:func:`_lu_solve`).

        Parameters
        ----------
        J : (size, size) ndarray of float
            The bordered Jacobian.
        r : (size,) ndarray of float
            Right-hand side.

        Returns
        -------
        (size,) ndarray of float
        """
        plan = self._block_plan
        if plan is None or J.shape != (self.size, self.size) or r.shape != (self.size,):
            return _lu_solve(J, r)
        F0, c0, Fk, ck, C, F = plan
        nC = C.size
        with np.errstate(all="ignore"):
            try:
                S = np.concatenate([J[np.ix_(C, C)], r[C, None]], axis=1)  # [J_CC, r_C], then its Schur complement
                # group 0: W0 = A_00^-1 [J_(F0, c0), r_F0]; S[c0, (c0, r)] -= J_(c0, F0) W0
                W0 = np.linalg.solve(J[np.ix_(F0, F0)], np.concatenate([J[np.ix_(F0, C[c0])], r[F0, None]], axis=1))
                cols0 = np.append(c0, nC)
                S[np.ix_(c0, cols0)] -= J[np.ix_(C[c0], F0)] @ W0
                # groups 1..H at once
                Ck = C[ck]  # (H, 2 nc + 3) unknowns
                Wk = np.linalg.solve(J[Fk[:, :, None], Fk[:, None, :]],
                                     np.concatenate([J[Fk[:, :, None], Ck[:, None, :]], r[Fk][:, :, None]], axis=2))
                U = J[Ck[:, :, None], Fk[:, None, :]] @ Wk  # (H, 2 nc + 3, 2 nc + 4)
                colsk = np.concatenate([ck, np.full((ck.shape[0], 1), nC)], axis=1)
                np.add.at(S, (ck[:, :, None], colsk[:, None, :]), -U)  # the three last rows and columns: summed
                zC = np.linalg.solve(S[:, :nC], S[:, nC])
            except np.linalg.LinAlgError:
                return _lu_solve(J, r)
            z = np.empty(self.size)
            z[C] = zC
            z[F0] = W0[:, -1] - W0[:, :-1] @ zC[c0]
            z[Fk] = Wk[:, :, -1] - np.einsum("hij,hj->hi", Wk[:, :, :-1], zC[ck])
            scale = max(float(np.max(J)), -float(np.min(J))) * float(np.max(np.abs(z))) + float(np.max(np.abs(r)))
            ok = bool(np.all(np.isfinite(z))) and float(np.max(np.abs(J @ z - r))) <= BLOCK_SOLVE_TOL * scale
        return z if ok else _lu_solve(J, r)

    def __call__(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R (size+2,) and dR/dy (size+2, size+3)."""
        R, jacobian = self.lazy(y)
        return R, jacobian()

    def _linear(self, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, dA/domega, kron(Nab, M)) at omega (the conservative ones from :meth:`_linear_parts`'s buffers)."""
        hb = self.hb
        if hb.C is None:
            A, dA = self._linear_parts(omega)
            return A, dA, self._operators[2]
        return hb.linear_operator(omega), hb._linear_operator_domega(omega), np.kron(hb.Nab, hb.M)

    def lazy(self, y: np.ndarray) -> tuple[np.ndarray, Callable[..., np.ndarray]]:
        """(R (size+2,), a callable giving dR/dy (size+2, size+3), or with ``below=row`` that with the row
        appended (size+3, size+3)): the AFT forces now, their Jacobian and
        the rest of dR/dy only when it is called (Newton's halving refuses many trial points on R alone:
        :func:`reduced.periodic.continuation.continue_branch` asks through this). The same numbers as
        ``self(y)``: the same operations, deferred (A and dA/domega made again from omega, which gives
        the same bits: :meth:`_linear_parts` reuses its buffers from call to call)."""
        R, jacobian, _, _ = self._lazy(y)
        return R, jacobian

    def _lazy(self, y: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray], np.ndarray, np.ndarray]:
        """:meth:`lazy`'s (R, dR/dy callable) and the samples x (N, n) and forces f (N, n) it synthesised."""
        hb, wr = self.hb, self.omega_ref
        n, nX = hb.n, hb.size
        Psi, omega, delta, a = self.split(y)
        x = hb.E @ hb.unpack(a * Psi)
        f, w = hb.force(x)  # HarmonicBalance.aft, its Jacobian deferred
        F = (hb.P @ f).ravel()
        A, _, DM = self._linear(omega)
        R = np.empty(nX + 2)
        DMPsi, Fa = DM @ Psi, F / a
        R[:nX] = (A @ Psi + Fa - delta * omega * DMPsi) / wr**2
        # phase: the fundamental sine coefficient of DOF ref
        i_s1 = 2 * n + self.ref
        R[nX] = Psi[i_s1]
        # normalisation of the fundamental
        c1, s1 = Psi[n : 2 * n], Psi[2 * n : 3 * n]
        R[nX + 1] = c1 @ hb.M @ c1 + s1 @ hb.M @ s1 - 1.0

        def jacobian(below: np.ndarray | None = None) -> np.ndarray:
            # ``below``: a row (size + 3,) appended, as np.vstack([jacobian(), below]) would (a corrector's
            # arclength or energy row) without copying the matrix again
            dF = self._force_jacobian(w)
            A, dA, _ = self._linear(omega)
            J = np.empty((nX + 2 + (below is not None), nX + 3))  # every entry written below
            Jx = J[:nX, :nX]
            if (dF is getattr(self._scratch, "dF", None) and hb.C is None and math.isfinite(omega**2)
                    and math.isfinite(2.0 * omega)):  # A from _linear_parts' buffers, dF the pattern's: its sums
                np.divide(self._hb_rows(A, dF, delta, omega), wr**2, out=Jx)
            else:
                np.add(A, dF, out=Jx)  # (A + dF - delta omega DM) / wr^2, in place
                if delta != 0.0:
                    c = delta * omega
                    for rows, cols in self._dm_blocks:  # DM = kron(Nab, M): elsewhere c DM is a zero (no change)
                        Jx[rows, cols] -= c * DM[rows, cols]
                Jx /= wr**2
            J[:nX, nX] = (dA @ Psi - delta * DMPsi) / wr
            J[:nX, nX + 1] = -omega * DMPsi / wr
            J[:nX, nX + 2] = np.log(10.0) * (dF @ Psi - Fa) / wr**2
            J[nX : nX + 2] = 0.0
            J[nX, i_s1] = 1.0
            J[nX + 1, n : 2 * n] = 2.0 * hb.M @ c1
            J[nX + 1, 2 * n : 3 * n] = 2.0 * hb.M @ s1
            if below is not None:
                J[nX + 2] = below
            return J

        jacobian.stacks_below = True  # continue_branch's corrector appends its row through ``below``
        return R, jacobian, x, f

    def start(self, phi: np.ndarray, omega: float, log10a: float) -> np.ndarray:
        """Initial y from a mass-normalised linear mode shape phi and its omega."""
        Psi = self.hb.pack_modes({1: phi / math.sqrt(phi @ self.hb.M @ phi)})
        return np.concatenate([Psi, [omega / self.omega_ref, 0.0, log10a]])

    def energy(self, y: np.ndarray) -> float:
        """J, mean total energy of the HB orbit at y."""
        X, omega = self.X_omega(y)
        return self.hb.energy(X, omega)

    def energy_gradient(self, y: np.ndarray) -> np.ndarray:
        """dE/dy of :meth:`energy` (:meth:`energy_and_gradient`)."""
        return self.energy_and_gradient(y)[1]

    def energy_and_gradient(self, y: np.ndarray) -> tuple[float, np.ndarray]:
        """(E, dE/dy): :meth:`energy` (equal to round-off) and its analytic gradient from one
        synthesis (dU/dx is the nonlinear force itself).

        With x_i = sum_h E[i,h] X_h and v_i = omega sum_h (E Nab)[i,h] X_h,
        E = mean_i [v_i^T M v_i / 2 + x_i^T K x_i / 2 + U(x_i)] and
        dE/dX_h = mean_i [E[i,h] (K x_i + f(x_i)) + omega (E Nab)[i,h] M v_i].
        """
        E, gradient = self._energy_lazy(y)
        return E, gradient()

    def _energy_lazy(self, y: np.ndarray, x: np.ndarray | None = None, f: np.ndarray | None = None
                     ) -> tuple[float, Callable[[], np.ndarray]]:
        """(E, a callable giving dE/dy) of :meth:`energy_and_gradient`, the gradient made only when called;
        ``x`` and ``f``, the samples and forces :meth:`_lazy` synthesised at the same y (the same numbers),
        are not made again."""
        hb = self.hb
        nX = hb.size
        Psi, omega, _, a = self.split(y)
        Xm = hb.unpack(a * Psi)
        if x is None:
            x = hb.E @ Xm
        G = hb.synthesis_derivative
        v = omega * (G @ Xm)
        N = x.shape[0]
        Kx, Mv = x @ hb.K, v @ hb.M
        kin2 = np.vdot(Mv, v) / N  # mean of v_i^T M v_i
        potential = getattr(hb.force, "potential", None)
        E = float(0.5 * kin2 + 0.5 * np.vdot(Kx, x) / N + (0.0 if potential is None else np.mean(potential(x))))

        def gradient() -> np.ndarray:
            fx = hb.force(x)[0] if f is None else f
            dX = (hb.E.T @ (Kx + fx) + omega * (G.T @ Mv)) / N
            g = np.zeros(nX + 3)
            g[:nX] = a * dX.ravel()
            g[nX] = float(kin2) / omega * self.omega_ref
            g[nX + 2] = np.log(10.0) * float(dX.ravel() @ (a * Psi))
            return g

        return E, gradient


# -- Newton ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class NewtonResult:
    """Converged point of :func:`newton`.

    Attributes
    ----------
    y : ndarray of float
        The solution.
    residual_norm : float
        ||R(y)||_inf.
    n_iter : int
        Newton iterations made.
    jacobian : ndarray of float or None
        dR/dy at y (square, as solved); None if :func:`newton` was told not to make it.
    """

    y: np.ndarray
    residual_norm: float
    n_iter: int
    jacobian: np.ndarray | None  # at y (square, as solved)


_DGETRF, _DGETRS = get_lapack_funcs(("getrf", "getrs"), (np.zeros((1, 1)),))


def _lu_solve(J: np.ndarray, R: np.ndarray) -> np.ndarray:
    """J^-1 R by LAPACK's getrf and getrs: the numbers of ``lu_solve(lu_factor(J), R)`` (the calls it
    makes), without its wrappers' overhead (a few tens of microseconds, as much as the factorisation
    of the 49 x 49 Jacobian of a shooting corrector). A zero pivot gives inf, as there. Raises
    ValueError on an illegal argument."""
    if J.dtype != np.float64 or R.dtype != np.float64 or J.ndim != 2 or R.ndim != 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LinAlgWarning)  # a zero pivot gives inf: the caller checks
            return lu_solve(lu_factor(J, check_finite=False), R, check_finite=False)
    if J.shape[0] != J.shape[1] or J.shape[0] != R.shape[0]:
        raise ValueError(f"Jacobian {J.shape} and residual {R.shape} do not match")
    lu, piv, info = _DGETRF(J)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal getrf")
    x, info = _DGETRS(lu, piv, R)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal getrs")
    return x


def _jacobian(J):
    """J itself, or J() when ``fun`` gave it as a callable (made only once its point is taken)."""
    return J() if callable(J) else J


def newton(
    fun, y0: np.ndarray, *, tol: float = 1e-10, max_iter: int = 20, max_step: float | None = None,
    final_jacobian: bool = True, solve: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> NewtonResult:
    """Solve fun(y) = 0, ``fun(y) -> (R, dR/dy)`` square, by Newton's method.

    Each step is halved (dy, dy/2, ..., dy/32) while it does not lower ||R||_2: with a gap
    force the AFT residual is piecewise smooth, and a full step from one side of a kink can
    overshoot into a cycle. If none lowers it, the last trial (dy/32) is taken, with its own
    residual and Jacobian. Converged when ``||dy||_inf <= tol (1 + ||y||_inf)`` with a
    small residual, or ``||R||_inf`` is at the round-off level of the first residual.
    Raises :class:`NewtonError` after ``max_iter`` iterations, on a singular Jacobian,
    a non-finite residual, or a step longer than ``max_step``.

    Parameters
    ----------
    fun : callable
        ``fun(y) -> (R (p,), dR/dy (p, p))``; dR/dy may be a callable returning it, called only for the
        points Newton takes (a trial point the halving refuses needs R alone).
    y0 : (p,) array_like of float
        Starting point.
    tol : float
        Relative step tolerance.
    max_iter : int
        Most iterations.
    max_step : float, optional
        Largest ||dy||_inf allowed (None: any).
    final_jacobian : bool
        Make dR/dy at the solution for ``NewtonResult.jacobian`` (False: None there, for a caller that
        needs the point alone; the iterations are the same).
    solve : callable, optional
        ``solve(J, R) -> J^-1 R`` (e.g. :meth:`NNMResidual.solve_bordered`); default: the dense LU.

    Returns
    -------
    NewtonResult

    Raises
    ------
    NewtonError
        No convergence, a singular Jacobian, a non-finite residual, a step beyond ``max_step``,
        or a converged step whose residual is not small (above 1e-6 max(||R0||, 1) and 1e-8).
    """
    y = np.array(y0, dtype=float)
    R, J = fun(y)
    r0 = float(np.max(np.abs(R)))
    rtiny = 1e3 * np.finfo(float).eps * max(r0, 1.0)
    step = np.inf
    for it in range(1, max_iter + 1):
        J = _jacobian(J)
        if not np.isfinite(R).all() or not np.isfinite(J).all():  # the methods: no wrapper overhead
            raise NewtonError(f"non-finite residual or Jacobian at iteration {it}")
        try:
            dy = -(_lu_solve if solve is None else solve)(J, R)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise NewtonError(f"singular Jacobian at iteration {it}: {exc}") from None
        if not np.isfinite(dy).all():
            raise NewtonError(f"singular Jacobian at iteration {it}")
        step = float(np.max(np.abs(dy)))
        if max_step is not None and step > max_step:
            raise NewtonError(f"Newton step {step:.3g} exceeds {max_step:.3g} at iteration {it}")
        r2 = float(R @ R)
        lam = 1.0
        for k in range(NEWTON_HALVINGS):
            Rn, Jn = fun(y + lam * dy)
            if (np.isfinite(Rn).all() and float(Rn @ Rn) < r2) or k == NEWTON_HALVINGS - 1:
                break  # the last trial is taken even if it did not lower ||R||: (R, J) are its own
            lam *= 0.5
        y = y + lam * dy
        R, J = Rn, Jn
        rn = float(np.max(np.abs(R)))
        if rn <= rtiny or (lam == 1.0 and step <= tol * (1.0 + float(np.max(np.abs(y))))):
            if rn > 1e-6 * max(r0, 1.0) and rn > 1e-8:
                raise NewtonError(f"step converged but residual {rn:.3g} is not small")
            return NewtonResult(y, rn, it, _jacobian(J) if final_jacobian else None)
    raise NewtonError(
        f"no convergence in {max_iter} iterations: |R| = {float(np.max(np.abs(R))):.3g}, last step {step:.3g}"
    )


__all__ = [
    "GuardRefusal",
    "NewtonError",
    "NewtonResult",
    "newton",
    "HarmonicBalance",
    "NNMResidual",
    "GapForce",
    "CubicForce",
    "default_samples",
]
