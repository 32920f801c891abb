"""The condensed harmonic balance of a gap system under a harmonic load (the residual layer of
:mod:`reduced.periodic.frc`).

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

:class:`ForcedResidual` is R in the scaled unknowns of the continuation,

    y = [q / x_ref, ln(Omega / omega_ref)],

rows scaled by 1 / x_ref.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.periodic.exact_hb import stop_moments
from reduced.periodic.hb import _derivative_matrix


# -- the condensed forced balance ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedBalance:
    """Condensed HB of ``system`` under b P cos(Omega t + phi) (module docstring).

    The unknowns are the coefficients q (2H+1, u) of the u contact coordinates U x, of which
    only the rows ``keep`` (all, or the odd harmonics) are free; the others are zero.

    Parameters
    ----------
    system : the gap system (its damping C is used)
    b : (n,) force direction
    amplitude_N : N, P
    phase_deg : deg, phi
    H : harmonics
    N : phases bracketing the extrema of each contact coordinate
        (:func:`reduced.periodic.exact_hb.default_root_samples`)
    odd : keep only the odd harmonics (half-wave symmetric response)
    """

    HILL_PARITY_SPLIT: ClassVar[bool] = True  # on odd-harmonic orbits the stops' derivative keeps the parity
    # (a coordinate's two symmetric stops close half a period apart): Hill's problem splits (forced_stability)
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
        s = _check.frictionless(self.system, "harmonic balance")
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
        k, rhs, dZc = self._omega_free(harmonics)
        Z = (s.K[None] - ((k * omega) ** 2)[:, None, None] * s.M[None]).astype(complex)
        if self._Cr is not None:
            Z = Z + 1j * (k * omega)[:, None, None] * self._Cr[None]
        W = np.linalg.solve(Z, rhs)
        if not derivative:
            return W, None
        dZ = (-2.0 * omega * k**2)[:, None, None] * s.M[None] + 0j
        if dZc is not None:
            dZ = dZ + dZc
        return W, -np.linalg.solve(Z, dZ @ W)

    def _omega_free(self, harmonics: np.ndarray | None):
        """(k, the right-hand sides [U^T, f_k] (len(k), n, u + 1), the damping part i k C of dZ_k/dOmega or None)
        of :meth:`receptances`: what does not depend on Omega, made once per harmonic set (read-only)."""
        key = None if harmonics is None else (np.asarray(harmonics).dtype.str, np.asarray(harmonics).tobytes())
        memo = self._receptance_parts
        if key not in memo:
            n, u = self.n, self.u
            k = np.arange(self.H + 1) if harmonics is None else np.array(harmonics)
            rhs = np.zeros((k.size, n, u + 1), complex)
            rhs[:, :, :u] = self.U.T[None]
            rhs[k == 1, :, u] = self.b * self.amplitude_N * np.exp(1j * math.radians(self.phase_deg))
            dZc = 1j * k[:, None, None] * self._Cr[None] if self._Cr is not None else None
            for a in (k, rhs, dZc):
                if a is not None:
                    a.flags.writeable = False
            memo[key] = (k, rhs, dZc)
        return memo[key]

    @functools.cached_property
    def _receptance_parts(self) -> dict:
        """:meth:`_omega_free`'s parts by harmonic set (filled on use)."""
        return {}

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
        stop [(alpha, beta)] at q (2H+1, u), by exact projection (:mod:`reduced.periodic.exact_hb`; every
        stop's intervals and moments in one kernel call, :func:`reduced.periodic.exact_hb.stop_moments`)."""
        s = self.system
        h = 2 * self.H + 1
        phi = np.zeros((h, self.u))
        dphi = np.zeros((self.u, h, h))
        intervals, G, g = stop_moments(q, self.row_of, s.side, s.offset, self.Nab, self.N)
        for j in range(s.m):
            if intervals[j][0].size == 0:
                continue
            r = self.row_of[j]
            phi[:, r] += s.k[j] * (G[j] @ q[:, r] - s.offset[j] * g[j])
            dphi[r] += s.k[j] * G[j]
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

    @functools.cached_property
    def _harmonics_kept(self) -> np.ndarray:
        """Harmonic numbers of the kept rows (each once, increasing; made once, read-only)."""
        kept = np.unique((self.keep + 1) // 2)
        kept.flags.writeable = False
        return kept

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


# -- the residual of the continuation -----------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ForcedResidual:
    """R(y) / x_ref for continuation in y = [z / x_ref, ln(Omega / omega_ref)]:
    ``__call__(y) -> (R (size,), dR/dy (size, size + 1))``.

    Parameters
    ----------
    fb : the condensed balance
    x_ref : m, scale of the contact coordinates
    omega_ref : rad/s, reference of the frequency coordinate
    """

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


__all__ = ["ForcedBalance", "ForcedResidual"]
