"""Closed-form linear response of a modal model with non-proportional viscous damping.

The independent reference of the virtual hammer test's linear check: the structure is given
by m of its mass-normalised modes,

    q'' + Cm q' + diag(omega^2) q = b f(t),        y = R q,

with Cm (m, m) symmetric positive semi-definite and not necessarily diagonal. This module
holds

- :class:`ModalModel` (omega, Cm) with :meth:`ModalModel.poles` (the complex eigen-decomposition
  of the first-order form), :meth:`ModalModel.frf` (the pole-residue FRF
  H(s) = D + sum_k r_k / (s - lambda_k)) and :meth:`ModalModel.half_sine_response` (the exact
  inverse transform of H(s) F(s) for a half-sine force pulse, at any times, with no time
  stepping);
- :class:`ModalPoles` and :class:`HalfSineResponse`, the result objects;
- :func:`half_sine_laplace`, the Laplace transform F(s) of the pulse.

Nothing here integrates an ODE, so it checks time integrators and reduced models
independently. Only numpy is used; ``fem`` imports nothing from ``reduced`` or
``bearingshaft``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

QUANTITIES = ("displacement", "velocity", "acceleration")
COND_LIMIT = 1e10  # refuse cond(V) above: the response loses ~cond(V) * 2e-16 relative, and a
#                    defective (e.g. critically damped) pole pair gives cond(V) ~ 1e16
SYM_RTOL = 1e-10  # Cm must be symmetric to this, relative to max|Cm|
PSD_RTOL = 1e-10  # and its smallest eigenvalue >= -PSD_RTOL * max|Cm| (round-off of Phi^T C Phi)
RIGID_COUPLING_RTOL = 1e-12  # a zero-frequency direction v with |Cm v| <= this * max|Cm| is free
#                              (its damping is round-off of a projected Phi^T C Phi)
NEAR_RESONANCE = 0.5  # pole within this * (pi/d) of +-i pi/d: divided-difference form of the kernel
CHUNK_ELEMENTS = 1 << 21  # complex (pole x time) entries per block: 32 MB per temporary


def _finite_array(name: str, x, ndim: int) -> np.ndarray:
    """``x`` as a float array of ``ndim`` dimensions with finite entries, else a ValueError."""
    a = np.asarray(x, dtype=float)
    if a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got non-finite entries")
    return a


def _finite_scalar(name: str, x, positive: bool = False) -> float:
    """``x`` as a finite float (> 0 if ``positive``), else a ValueError."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {x!r}") from None
    if not np.isfinite(v) or (positive and not v > 0.0):
        raise ValueError(f"{name} must be finite{' and > 0' if positive else ''}, got {x!r}")
    return v


def half_sine_laplace(s, peak: float, duration: float, start: float = 0.0) -> np.ndarray:
    """Laplace transform of the half-sine pulse f(t) = P sin(a (t - t0)) on [t0, t0 + d), a = pi/d.

    F(s) = P a e^{-s t0} (1 + e^{-s d}) / (s^2 + a^2), entire in s. Evaluated as
    F = P a d e^{-s t0} phi_1(-(s - mu) d) / (s + mu) with mu = i a sign(Im s) the nearer root
    of s^2 + a^2 (e^{-mu d} = -1 gives 1 + e^{-s d} = -expm1(-(s - mu) d)), so there is no 0/0
    at s = +-i a, where F = -+i P d e^{-+i a t0} / 2. With s = i 2 pi f it is the Fourier transform
    of the pulse (N s).

    Parameters
    ----------
    s : complex or array_like of complex
        rad/s, Laplace variable(s).
    peak : float
        N, P.
    duration : float
        s, d > 0.
    start : float
        s, t0.

    Returns
    -------
    ndarray of complex
        N s, F(s), the shape of ``s``.
    """
    s = np.asarray(s, dtype=complex)
    a = np.pi / duration
    mu = np.where(s.imag >= 0.0, 1j * a, -1j * a)
    return peak * a * duration * np.exp(-s * start) * _phi1(-(s - mu) * duration) / (s + mu)


def _phi1(z: np.ndarray) -> np.ndarray:
    """phi_1(z) = (e^z - 1) / z, with phi_1(0) = 1 (numpy's complex expm1 is accurate near 0)."""
    small = z == 0
    return np.where(small, 1.0, np.expm1(z) / np.where(small, 1.0, z))


def _sine_kernel(lam: np.ndarray, tau: np.ndarray, a: float) -> np.ndarray:
    """K(lam, tau) = int_0^tau e^{lam (tau - v)} sin(a v) dv for 0 <= tau, lam (n, 1), tau (1, nt).

    Away from lam = +-i a: K = (a e^{lam tau} - a cos(a tau) - lam sin(a tau)) / (lam^2 + a^2).
    Near it (the resonant limit included) the same quantity by partial fractions,
    K = [E(lam, i a) - E(lam, -i a)] / (2 i), E(lam, mu) = (e^{lam tau} - e^{mu tau}) / (lam - mu)
    = e^{mu tau} tau phi_1((lam - mu) tau), which has no 0/0. Re(lam) <= 0 and tau >= 0, so no
    exponential can overflow.
    """
    near = np.minimum(np.abs(lam - 1j * a), np.abs(lam + 1j * a)) < NEAR_RESONANCE * a  # (n, 1)
    K = np.empty(np.broadcast_shapes(lam.shape, tau.shape), dtype=complex)
    far = ~near[:, 0]
    if far.any():
        lf = lam[far]
        K[far] = (a * np.exp(lf * tau) - a * np.cos(a * tau) - lf * np.sin(a * tau)) / (lf * lf + a * a)
    if near.any():
        ln = lam[~far]
        E_plus = np.exp(1j * a * tau) * tau * _phi1((ln - 1j * a) * tau)
        E_minus = np.exp(-1j * a * tau) * tau * _phi1((ln + 1j * a) * tau)
        K[~far] = (E_plus - E_minus) / 2j
    return K


@dataclass(frozen=True, eq=False)
class ModalPoles:
    """Complex eigen-decomposition of the first-order form of a :class:`ModalModel`.

    Free rigid directions (omega = 0 and Cm v = 0) are split off first: q = E q_e + G p with
    [E, G] orthogonal, p'' = G^T b f (a double pole at s = 0, handled in closed form). The
    rest, q_e'' + C_e q_e' + K_e q_e = E^T b f with C_e = E^T Cm E, K_e = E^T Omega^2 E
    (diagonal), is written z = [q_e; q_e'], z' = A z + [0; E^T b] f,
    A = [[0, I], [-K_e, -C_e]] = V diag(lam) V^-1. Without free rigid directions E = I and A
    is the full [[0, I], [-Omega^2, -Cm]].

    Attributes
    ----------
    lam : (2 m_e,) ndarray of complex
        rad/s, the poles, Re <= 0 (conjugate pairs or real).
    V, V_inv : (2 m_e, 2 m_e) ndarray of complex
        Eigenvectors of A (A V = V diag(lam)), [q_e; q_e'] rows, and their inverse.
    cond_V : float
        2-norm condition number of the eigenbasis of the balanced form (see
        :meth:`ModalModel.poles`).
    elastic_basis : (m, m_e) ndarray of float
        E, orthonormal columns: the coordinates of A.
    rigid_basis : (m, n_r) ndarray of float
        G, orthonormal columns: the free rigid directions.
    """

    lam: np.ndarray  # rad/s, (2 m_e,) complex poles, Re <= 0 (conjugate pairs or real)
    V: np.ndarray  # (2 m_e, 2 m_e) complex, A V = V diag(lam)
    V_inv: np.ndarray  # (2 m_e, 2 m_e) complex
    cond_V: float  # 2-norm condition number of the eigenbasis of the balanced form (see poles())
    elastic_basis: np.ndarray  # E, (m, m_e): orthonormal, the coordinates of A
    rigid_basis: np.ndarray  # G, (m, n_r): orthonormal, the free rigid directions

    @property
    def n_rigid(self) -> int:
        return self.rigid_basis.shape[1]


@dataclass(frozen=True, eq=False)
class HalfSineResponse:
    """Output rows y = R q of a :class:`ModalModel` and their derivatives under a half-sine pulse.

    Units: with mass-normalised modes (q in sqrt(kg) m) and R rows of the mode shapes
    (1/sqrt(kg)), displacement is in m, velocity m/s, acceleration m/s^2.

    Attributes
    ----------
    t : (nt,) ndarray of float
        s, the times asked for.
    displacement, velocity, acceleration : (r, nt) ndarray of float
        R q, R q', R q'' (the last with the feedthrough R b f).
    force : (nt,) ndarray of float
        N, f(t).
    peak_N, duration_s, start_s : float
        The pulse: P (N), d (s), t0 (s).
    imag_rel : float
        max |Im| / max |Re| of the complex sums before their real parts are taken (round-off).
    cond_V : float
        Condition number of the eigenbasis (:class:`ModalPoles`).
    n_poles, n_rigid : int
        Poles of the first-order form and free rigid directions.
    """

    t: np.ndarray  # s, (nt,)
    displacement: np.ndarray  # (r, nt): R q
    velocity: np.ndarray  # (r, nt): R q'
    acceleration: np.ndarray  # (r, nt): R q'' = R (b f - Cm q' - Omega^2 q), includes R b f
    force: np.ndarray  # N, (nt,): f(t)
    peak_N: float
    duration_s: float
    start_s: float
    imag_rel: float  # max |Im| / max |Re| of the three complex sums before .real (round-off)
    cond_V: float
    n_poles: int
    n_rigid: int


@dataclass(frozen=True, eq=False)
class ModalModel:
    """m mass-normalised modes with viscous damping: q'' + Cm q' + diag(omega^2) q = b f(t).

    Rigid modes are given as omega = 0 exactly. A zero-frequency direction that Cm does not
    touch (Cm v = 0) is a free rigid mode, handled in closed form (q = double integral of the
    load); one that Cm damps stays in the first-order form (a simple pole at 0 and one at
    -c). Such a lightly damped rigid direction loses about log10(1 / (c t)) digits at time t
    (the partial fractions 1 / (s (s + c)) = (1/s - 1/(s + c)) / c cancel); give exactly zero
    damping coupling for a free mode. Exactly defective pole pairs (critical damping) are
    refused by :meth:`poles`.

    Parameters
    ----------
    omega : (m,) array_like of float
        rad/s, natural frequencies, >= 0 (0 exactly for a rigid mode).
    Cm : (m, m) array_like of float
        1/s, modal damping matrix, symmetric positive semi-definite (kept as (Cm + Cm^T) / 2).

    Raises
    ------
    ValueError
        Non-finite or empty ``omega``, a negative frequency, ``Cm`` of the wrong shape, not
        symmetric to ``SYM_RTOL`` or with an eigenvalue below -``PSD_RTOL`` max|Cm|.
    """

    omega: np.ndarray  # rad/s, (m,) >= 0, natural frequencies
    Cm: np.ndarray  # 1/s, (m, m) symmetric positive semi-definite, modal damping matrix

    def __post_init__(self) -> None:
        omega = _finite_array("omega", self.omega, 1)
        if omega.size == 0:
            raise ValueError("omega must hold at least one mode, got shape (0,)")
        if np.any(omega < 0.0):
            raise ValueError(f"omega must be >= 0 rad/s, got min {omega.min()!r}")
        Cm = _finite_array("Cm", self.Cm, 2)
        m = omega.size
        if Cm.shape != (m, m):
            raise ValueError(f"Cm must have shape ({m}, {m}) to match omega, got {Cm.shape}")
        scale = float(np.abs(Cm).max())
        if np.abs(Cm - Cm.T).max() > SYM_RTOL * scale:
            raise ValueError(f"Cm must be symmetric, got max|Cm - Cm^T| = {np.abs(Cm - Cm.T).max():.3g}")
        if scale > 0.0 and np.linalg.eigvalsh(0.5 * (Cm + Cm.T)).min() < -PSD_RTOL * scale:
            raise ValueError("Cm must be positive semi-definite, got a negative eigenvalue")
        object.__setattr__(self, "omega", omega)
        object.__setattr__(self, "Cm", 0.5 * (Cm + Cm.T))

    @property
    def m(self) -> int:
        return self.omega.size

    @cached_property
    def _poles(self) -> ModalPoles:
        m, omega, Cm = self.m, self.omega, self.Cm
        zero = np.flatnonzero(omega == 0.0)
        # split the zero-frequency subspace into free (Cm v = 0) and damped directions: Omega^2
        # vanishes on it, so any rotation inside it keeps K_e diagonal
        E, G = np.eye(m), np.zeros((m, 0))
        if zero.size:
            _, sv, Wh = np.linalg.svd(Cm[:, zero])
            sv = np.concatenate([sv, np.zeros(zero.size - sv.size)])
            free = sv <= RIGID_COUPLING_RTOL * np.abs(Cm).max()
            U = np.zeros((m, zero.size))
            U[zero] = Wh.T
            keep = np.setdiff1d(np.arange(m), zero)
            E = np.hstack([np.eye(m)[:, keep], U[:, ~free]])
            G = U[:, free]
        K_e = np.einsum("ik,i,il->kl", E, omega**2, E)
        C_e = E.T @ Cm @ E
        n = E.shape[1]
        if n == 0:
            empty = np.zeros((0, 0), complex)
            return ModalPoles(np.zeros(0, complex), empty, empty, 1.0, E, G)
        # balanced state zt = [W q; q'] with W = omega (C_e's diagonal for a damped rigid
        # direction): for an undamped model A_s = [[0, W], [-W, 0]] is normal, cond(V) = 1, so
        # cond(V) measures closeness to a defective matrix, not the choice of units
        w = np.sqrt(np.diag(K_e))
        w = np.where(w > 0.0, w, np.maximum(np.diag(C_e), np.finfo(float).tiny))
        A_s = np.block([[np.zeros((n, n)), np.diag(w)], [-K_e / w[None, :], -C_e]])
        lam, V_s = np.linalg.eig(A_s)
        cond = float(np.linalg.cond(V_s))
        if not cond <= COND_LIMIT:
            raise ValueError(f"Cm, omega: eigenbasis of the first-order form is defective or ill-conditioned "
                             f"(cond(V) = {cond:.3g} > {COND_LIMIT:.0e}), e.g. a critically damped mode; "
                             "the pole-residue form does not apply")
        V_s_inv = np.linalg.inv(V_s)
        S = np.concatenate([w, np.ones(n)])  # zt = S z
        return ModalPoles(lam=lam, V=V_s / S[:, None], V_inv=V_s_inv * S[None, :], cond_V=cond,
                          elastic_basis=E, rigid_basis=G)

    def poles(self) -> ModalPoles:
        """Poles and eigenvectors of the first-order form, A = V diag(lam) V^-1.

        z = [q; q'], z' = A z + B f, A = [[0, I], [-Omega^2, -Cm]], B = [0; b], after the free
        rigid directions are split off (see :class:`ModalPoles`). The eigenproblem is solved on
        the balanced form zt = [W q; q'] (W = diag(omega)) and mapped back; cond(V) of that
        form must be <= COND_LIMIT, else a one-line ValueError (a defective pair such as
        critical damping, 2 zeta omega = c with lam = -omega double, has no eigenbasis).
        """
        return self._poles

    def _check_load(self, b, R) -> tuple[np.ndarray, np.ndarray]:
        b = _finite_array("b", b, 1)
        if b.shape != (self.m,):
            raise ValueError(f"b must have shape ({self.m},), got {b.shape}")
        R = _finite_array("R", R, 2)
        if R.shape[1] != self.m:
            raise ValueError(f"R must have shape (r, {self.m}), got {R.shape}")
        return b, R

    def _residues(self, b: np.ndarray, R: np.ndarray):
        """Residue rows of the displacement and velocity outputs, (r, 2 m_e) each, and R G G^T b."""
        p = self._poles
        n = p.elastic_basis.shape[1]
        g = p.V_inv[:, n:] @ (p.elastic_basis.T @ b)  # V^-1 B
        RE = R @ p.elastic_basis
        res_d = (RE @ p.V[:n]) * g[None, :]
        res_v = (RE @ p.V[n:]) * g[None, :]
        rigid = R @ (p.rigid_basis @ (p.rigid_basis.T @ b))
        return res_d, res_v, rigid

    def frf(self, freq_hz, b, R, quantity: str = "acceleration") -> np.ndarray:
        """Frequency response R s^k (s^2 I + s Cm + Omega^2)^-1 b at s = i 2 pi freq_hz, (r, nf).

        Pole-residue form, k = 0, 1, 2 for displacement, velocity, acceleration:

            H(s) = D + sum_k r_k / (s - lam_k) + H_rigid(s),

        r_k^disp = R E V_top[:, k] (V^-1 B)_k, r_k^vel = R E V_bot[:, k] (V^-1 B)_k,
        r_k^acc = lam_k r_k^vel, D = R b for acceleration (the feedthrough; sum_k r_k^vel = R E E^T b)
        and 0 otherwise, H_rigid = R G G^T b / s^2 and / s for displacement and velocity (the
        rigid part of the acceleration is in D). Units per N of b f: m/N, m/s/N, m/s^2/N for
        mass-normalised modes. Not finite at a pole on the imaginary axis (freq_hz = 0 with a
        rigid mode, omega / 2 pi of an undamped mode).
        """
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
        f = _finite_array("freq_hz", freq_hz, 1)
        b, R = self._check_load(b, R)
        lam = self._poles.lam
        res_d, res_v, rigid = self._residues(b, R)
        s = 2j * np.pi * f
        if quantity == "displacement":
            res, D, k_rigid = res_d, np.zeros(R.shape[0]), 2
        elif quantity == "velocity":
            res, D, k_rigid = res_v, np.zeros(R.shape[0]), 1
        else:
            res, D, k_rigid = res_v * lam[None, :], R @ b, 0
        H = np.empty((R.shape[0], f.size), dtype=complex)
        step = max(1, CHUNK_ELEMENTS // max(lam.size, 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            for i in range(0, f.size, step):
                si = s[i:i + step]
                H[:, i:i + step] = res @ (1.0 / (si[None, :] - lam[:, None])) + D[:, None]
                if k_rigid:
                    H[:, i:i + step] += rigid[:, None] / si[None, :] ** k_rigid
        return H

    def half_sine_response(self, t, b, R, peak_N: float, duration_s: float,
                           start_s: float = 0.0) -> HalfSineResponse:
        """Exact response y = R q, its velocity and acceleration to a half-sine pulse, from rest.

        f(t) = P sin(a (t - t0)) for t0 <= t < t0 + d, 0 otherwise, a = pi/d. Per pole, with
        tau = t - t0, the modal state eta = V^-1 z is

            eta_k(t) = (V^-1 B)_k P K(lam_k, clip(tau, 0, d)) e^{lam_k max(tau - d, 0)},
            K(lam, tau) = int_0^tau e^{lam (tau - v)} sin(a v) dv
                        = (a e^{lam tau} - a cos(a tau) - lam sin(a tau)) / (lam^2 + a^2),

        zero before the pulse (K(lam, 0) = 0), the convolution inside it and the free decay
        of its end value after it. Near and at lam = +-i a (an undamped mode at the pulse's
        frequency) K is evaluated in divided-difference form, exact in the limit
        (K = (tau e^{i a tau} - sin(a tau) / a) / (2 i) at lam = i a). Then q = E V_top eta, q' =
        E V_bot eta, q'' = E V_bot (lam eta) + E E^T b f, plus the free rigid directions in
        closed form: p = G^T b F2(tau), p' = G^T b F1(tau), p'' = G^T b f with
        F1 = P (1 - cos(a tau)) / a, F2 = P (tau - sin(a tau) / a) / a inside the pulse and
        F1 = 2 P / a, F2 = P d / a + 2 P (tau - d) / a after it. The acceleration therefore
        equals R (b f - Cm q' - Omega^2 q), the feedthrough R b f included.

        Only e^{lam tau} with tau >= 0 and Re(lam) <= 0 is formed (no overflow); the work is
        done in blocks of times so that memory stays O(2 m * block + r * nt).

        Parameters
        ----------
        t : (nt,) s, any order.
        b : (m,) modal load Phi^T F per unit of f.
        R : (r, m) output rows (e.g. sensor rows of Phi).
        peak_N, duration_s, start_s : P (N), d (s, > 0), t0 (s).
        """
        t = _finite_array("t", t, 1)
        b, R = self._check_load(b, R)
        P = _finite_scalar("peak_N", peak_N)
        d = _finite_scalar("duration_s", duration_s, positive=True)
        t0 = _finite_scalar("start_s", start_s)
        p = self._poles
        lam = p.lam
        a = np.pi / d
        res_d, res_v, rigid = self._residues(b, R)
        res_a = res_v * lam[None, :]
        tau = t - t0
        on = (tau >= 0.0) & (tau < d)
        f = np.where(on, P * np.sin(a * np.where(on, tau, 0.0)), 0.0)
        r, nt = R.shape[0], t.size
        out = {q: np.zeros((r, nt), dtype=complex) for q in QUANTITIES}
        if lam.size:
            step = max(1, CHUNK_ELEMENTS // lam.size)
            for i in range(0, nt, step):
                ti = tau[None, i:i + step]
                eta = P * _sine_kernel(lam[:, None], np.clip(ti, 0.0, d), a) * np.exp(
                    lam[:, None] * np.maximum(ti - d, 0.0))
                out["displacement"][:, i:i + step] = res_d @ eta
                out["velocity"][:, i:i + step] = res_v @ eta
                out["acceleration"][:, i:i + step] = res_a @ eta
        # the real parts: what remains imaginary is round-off of the conjugate pairs
        re = {q: out[q].real for q in QUANTITIES}
        im = max(float(np.abs(out[q].imag).max(initial=0.0)) for q in QUANTITIES)
        mx = max(float(np.abs(re[q]).max(initial=0.0)) for q in QUANTITIES)
        # feedthrough of the elastic part (R E E^T b) and the free rigid directions
        th = np.clip(tau, 0.0, d)
        F1 = np.where(tau < d, P * (1.0 - np.cos(a * th)) / a, 2.0 * P / a)
        F2 = np.where(tau < d, P * (th - np.sin(a * th) / a) / a, P * d / a + 2.0 * P * np.maximum(tau - d, 0.0) / a)
        y = re["displacement"] + rigid[:, None] * F2[None, :]
        v = re["velocity"] + rigid[:, None] * F1[None, :]
        acc = re["acceleration"] + (R @ b)[:, None] * f[None, :]
        return HalfSineResponse(t=t, displacement=y, velocity=v, acceleration=acc, force=f, peak_N=P,
                                duration_s=d, start_s=t0, imag_rel=im / mx if mx > 0.0 else im,
                                cond_V=p.cond_V, n_poles=lam.size, n_rigid=p.n_rigid)


__all__ = ["ModalModel", "ModalPoles", "HalfSineResponse", "half_sine_laplace", "QUANTITIES", "COND_LIMIT"]
