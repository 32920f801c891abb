"""Friction in the forced harmonic balance: the Jenkins element by alternating frequency-time (AFT).

A slider of :class:`reduced.models.gaps.Friction` (tangential stiffness k_t in series with a Coulomb
slider of coefficient mu) acts along t = Bt x with the force

    stick:  f = k_t (t - w),  |f| < mu N,  w' = 0;       slip:  f = +-mu N;       open (N = 0):  f = 0,

N the normal force: that of the slider's stop, N = k_g max(0, side (B x - o)) (the gap contact), or a
constant normal load N0 (``normal_N``). f(tau) depends on the history of t and N, so it is evaluated in
time (**AFT**, Cameron & Griffin 1989; the Jenkins element as in NLvib, Krack & Gross 2019, Sec. 4.3):
t(tau_i) and N(tau_i) are synthesised at the samples tau_i = 2 pi i / Ns, the return map

    f_trial = f_{i-1} + k_t (t_i - t_{i-1}),   f_i = f_trial if |f_trial| < mu N_i else sign(f_trial) mu N_i

(f_i = 0 where N_i <= 0: an open stop unloads its slider, as in the exact integrator, which restarts
w = t at each closing) is marched over **two periods** from f = 0, and the second period is kept: the
first has visited t's extremes, so the second is the stationary loop (a play operator forgets its
initial state once its input has passed its global maximum and minimum). Its Fourier coefficients are
projected back (:func:`reduced.periodic.hb._projection_matrix`).

**Consistent Jacobian.** Every sample of the second period is either open (f_i = 0), slipping
(f_i = s mu N_i, s = +-1) or sticking since an anchor sample a (the last slip, opening or the start):
f_i = f_a + k_t (t_i - t_a). So

    df_i = k_t (dt_i - dt_a) + s_a mu dN_a    (stick since a slip at a; no dN term since an opening),
    df_i = s_i mu dN_i                          (slip),

and dF/dQ = P (df/ds) E exactly (the derivative of the discrete AFT map wherever no sample sits on a
switch), with dN_i / dq_i = k_g side [closed] for the gap contact.

:class:`FrictionBalance` adds the sliders to the condensed forced balance
(:class:`reduced.periodic.forced_balance.ForcedBalance`): the unknowns are the harmonics of the
contact coordinates U x and of the distinct tangential coordinates Bt x (one axial coordinate u for
:class:`reduced.models.discrete.DiscreteFrictionParams`), the stops' forces are still projected exactly
over their contact intervals and the friction forces by AFT. :func:`friction_frc` continues its
forced-response curve with the driver of :mod:`reduced.periodic.frc`, the stability of each point by
Hill's method on the consistent AFT Jacobian (:func:`reduced.periodic.forced_stability.forced_hill`).

Closed forms (tested): the describing function of the Jenkins element (:func:`jenkins_describing_function`)
and Den Hartog's steady response of the forced Coulomb oscillator (:func:`den_hartog_amplitude`).
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import ClassVar

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced._blas import single_thread_blas
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.periodic import MAX_HARMONICS
from reduced.periodic.continuation import ContinuationOptions
from reduced.periodic.forced_balance import ForcedBalance
from reduced.periodic.forced_stability import bifurcations, forced_hill
from reduced.periodic.hb import _derivative_matrix, _phases, _projection_matrix, _synthesis_matrix, default_samples
from reduced.periodic.stability import HILL_TOL

OPEN, STICK, SLIP = 0, 1, 2  # the state of a slider at a sample


# -- the Jenkins element in time -------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class JenkinsLoop:
    """The stationary loop of one Jenkins element at Ns samples of a period (:func:`jenkins_loop`).

    Attributes
    ----------
    f : (Ns,) N, the force k_t (t - w) at each sample.
    state : (Ns,) int, OPEN, STICK or SLIP.
    anchor : (Ns,) int, for a sticking sample the sample a it sticks since (its f_a, t_a), else itself.
    sign : (Ns,) float, s = +-1 of a slipping sample, or of a sticking sample's anchor if that slipped
        (0 if the anchor is an opening or the start).
    """

    f: np.ndarray
    state: np.ndarray
    anchor: np.ndarray
    sign: np.ndarray

    def derivatives(self, k_t: float, mu: float) -> tuple[np.ndarray, np.ndarray]:
        """(df/dt, df/dN), each (Ns, Ns): df_i / dt_j and df_i / dN_j (module docstring)."""
        Ns = self.f.size
        i = np.arange(Ns)
        G = np.zeros((Ns, Ns))
        Hn = np.zeros((Ns, Ns))
        st = self.state == STICK
        G[i[st], i[st]] += k_t
        np.add.at(G, (i[st], self.anchor[st]), -k_t)
        sl = self.state == SLIP
        Hn[i[sl], i[sl]] = self.sign[sl] * mu
        Hn[i[st], self.anchor[st]] = self.sign[st] * mu
        return G, Hn

    def synthesised(self, E: np.ndarray, k_t: float, mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(df/dt E (Ns, h), c (Ns,), j (Ns,)) for the synthesis matrix E (Ns, h): the derivative with respect
        to t's coefficients, and df_i/dN = c_i e_{j_i} (one sample each), without the dense (Ns, Ns) matrices."""
        st = self.state == STICK
        GE = np.where(st[:, None], k_t * (E - E[self.anchor]), 0.0)
        c = np.where(self.state == OPEN, 0.0, self.sign * mu)
        return GE, c, self.anchor


def jenkins_loop(t: np.ndarray, N: np.ndarray, k_t: float, mu: float) -> JenkinsLoop:
    """The stationary loop of a Jenkins element driven by t (Ns,) [m] under the normal force N (Ns,) [N].

    The return map of the module docstring, marched over two periods from f = 0 (the element unloaded at
    the first sample), the second period kept. A loop that never slips nor opens is not unique (any w with
    |k_t (t - w)| <= mu N is periodic): this one keeps the start's, f(tau_0) = 0.

    Parameters
    ----------
    t : (Ns,) m, the tangential coordinate at the samples of one period
    N : (Ns,) N, the normal force there (<= 0: open, no friction)
    k_t : N/m, tangential stiffness
    mu : Coulomb coefficient

    Returns
    -------
    JenkinsLoop

    Examples
    --------
    >>> tau = 2 * np.pi * np.arange(8) / 8
    >>> loop = jenkins_loop(np.cos(tau), np.full(8, 1.0), 10.0, 0.5)   # slips at +-0.5 N near the extremes
    >>> loop.f.round(3).tolist()
    [0.5, -0.5, -0.5, -0.5, -0.5, 0.5, 0.5, 0.5]
    """
    Ns = t.size
    f_out = np.zeros(Ns)
    state = np.zeros(Ns, np.int64)
    anchor = np.arange(Ns)
    sign = np.zeros(Ns)
    call_numba_kernel(_jenkins_march, np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(N, dtype=float),
                      float(k_t), float(mu), f_out, state, anchor, sign)
    return JenkinsLoop(f_out, state, anchor, sign)


@nb.njit(cache=True)
def _jenkins_march(t, N, k_t, mu, f_out, state, anchor, sign):
    """:func:`jenkins_loop`'s return map marched over two periods from f = 0, the second period written into
    f_out, state, anchor and sign (anchor holds arange(Ns) on entry). The same scalar operations in the same
    order as the Python loop it replaced (tests/test_friction_aft.py holds that loop: the same bits)."""
    Ns = t.shape[0]
    f, a, s_a = 0.0, 0, 0.0  # force, anchor sample, sign of the anchor's slip (0: opening or start)
    for n in range(2 * Ns):
        i = n % Ns
        limit = mu * N[i]
        if limit <= 0.0:
            f, a, s_a, st, s = 0.0, i, 0.0, OPEN, 0.0
        else:
            trial = f + k_t * (t[i] - t[i - 1]) if n > 0 else 0.0
            if abs(trial) < limit:
                f, st, s = trial, STICK, s_a
            else:
                s = 1.0 if trial > 0.0 else -1.0
                f, a, s_a, st = s * limit, i, s, SLIP
        if n >= Ns:
            f_out[i], state[i], sign[i] = f, st, s
            anchor[i] = a if st == STICK else i


def jenkins_describing_function(a: float, k_t: float, f_s: float) -> tuple[float, float]:
    """(a_1, b_1) N, the fundamental of the Jenkins element's stationary force under t = a cos(tau).

    With cos(beta) = 1 - 2 f_s / (k_t a) (slip for k_t a > f_s), the loop sticks for tau in (0, beta)
    from f = f_s down to -f_s and slips at -f_s until tau = pi (then the mirror image), so

        a_1 = (k_t a / pi) (beta - sin(2 beta) / 2),     b_1 = -(k_t a / pi) sin(beta)^2,

    f ~ a_1 cos(tau) + b_1 sin(tau); full stick (k_t a <= f_s): (k_t a, 0); large a: b_1 -> -4 f_s / pi,
    the Coulomb limit. (Derived here; the same as Krack & Gross 2019, Sec. 4.3, Eq. for elastic dry
    friction.)

    Parameters
    ----------
    a : m, amplitude of t
    k_t : N/m
    f_s : N, slip force mu N

    Returns
    -------
    tuple of float
        (a_1, b_1) N.
    """
    if k_t * a <= f_s:
        return k_t * a, 0.0
    beta = math.acos(1.0 - 2.0 * f_s / (k_t * a))
    return k_t * a / math.pi * (beta - 0.5 * math.sin(2.0 * beta)), -k_t * a / math.pi * math.sin(beta) ** 2


def den_hartog_amplitude(m: float, k: float, P: float, F: float, omega: float) -> float:
    """m, Den Hartog's (1931) steady amplitude of m x'' + k x + F sign(x') = P cos(Omega t), continuous slip.

    With r = Omega / omega_n, omega_n = sqrt(k / m), the half period from x = -X (at rest) to x = +X in
    closed form gives (derived here: the homogeneous part over a half period, x' = 0 at both ends)

        X = (P / k) sqrt( 1 / (1 - r^2)^2 - (F / P)^2 U^2 ),    U = tan(pi / (2 r)) / r,

    valid while the mass never sticks (two stops a period); nan where the root is imaginary.

    Parameters
    ----------
    m : kg
    k : N/m
    P : N, forcing amplitude
    F : N, Coulomb force mu N
    omega : rad/s, Omega

    Returns
    -------
    float
        m, X.
    """
    r = omega / math.sqrt(k / m)
    U = math.tan(math.pi / (2.0 * r)) / r
    rad = 1.0 / (1.0 - r * r) ** 2 - (F / P) ** 2 * U * U
    return (P / k) * math.sqrt(rad) if rad >= 0.0 else math.nan


# -- the condensed forced balance with friction ------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrictionBalance(ForcedBalance):
    """Condensed HB of a system with friction under b P cos(Omega t + phi) (module docstring).

    The unknowns are the coefficients q (2H+1, u) of the coordinates V x, V the distinct stop rows (first,
    in the order of :class:`ForcedBalance`) and then the distinct friction rows Bt not among them.

    Parameters
    ----------
    system, b, amplitude_N, phase_deg, H, N, odd : as :class:`ForcedBalance`
    normal_N : N, a constant normal load on every slider, or None: that of its stop (N = k_g penetration)
    samples : AFT samples of a period for the sliders (0: :func:`reduced.periodic.hb.default_samples`)
    """

    HILL_PARITY_SPLIT: ClassVar[bool] = False  # the sliders' AFT derivative is not shown to keep the parity
    normal_N: float | None = None
    samples: int = 0
    trow: np.ndarray = field(init=False, repr=False)  # (p,) slider -> row of V
    _states: dict = field(default_factory=dict, init=False, repr=False)  # z's bytes -> slider_state(z)

    def __post_init__(self) -> None:
        s = self.system
        if s.friction is None:
            raise _check.InvalidArgument("system has no friction: use ForcedBalance")
        gap = ForcedBalance(s.with_friction(None), self.b, self.amplitude_N, self.phase_deg, self.H, self.N, self.odd)
        rows = list(gap.U)
        trow = []
        for bt in s.friction.Bt:
            for r, v in enumerate(rows):
                if np.array_equal(v, bt):
                    trow.append(r)
                    break
            else:
                rows.append(bt)
                trow.append(len(rows) - 1)
        if self.normal_N is None and s.m == 0:
            raise _check.InvalidArgument("system has no stops: give a constant normal load normal_N")
        Ns = self.samples or default_samples(self.H)
        tau = _phases(Ns)
        object.__setattr__(self, "samples", Ns)
        object.__setattr__(self, "U", np.array(rows).reshape(len(rows), s.n))
        object.__setattr__(self, "row_of", gap.row_of)
        object.__setattr__(self, "keep", gap.keep)
        object.__setattr__(self, "Nab", _derivative_matrix(self.H))
        object.__setattr__(self, "_Cr", s.C if np.any(s.C) else None)
        object.__setattr__(self, "trow", np.array(trow, int))
        object.__setattr__(self, "_gap", gap)
        object.__setattr__(self, "_E", _synthesis_matrix(self.H, tau))
        object.__setattr__(self, "_P", _projection_matrix(self.H, tau))

    # -- the forces ----------------------------------------------------------------------------------
    @functools.cached_property
    def _stops_of(self) -> tuple:
        """For each slider, ((stop j, its row of V), ...) over the stops of its tip, ascending j."""
        s, fr = self.system, self.system.friction
        return tuple(tuple((int(j), self.row_of[j]) for j in np.flatnonzero(s.tip == fr.tip[k])) for k in range(fr.p))

    def normal_force(self, qs: np.ndarray, k: int) -> tuple[np.ndarray, list]:
        """(N (Ns,), [(row, dN/dq_row (Ns,))]) of slider k at the samples qs (Ns, u) of the coordinates."""
        s = self.system
        if self.normal_N is not None:
            return np.full(qs.shape[0], float(self.normal_N)), []
        N = np.zeros(qs.shape[0])
        terms = []
        for j, r in self._stops_of[k]:
            d = s.side[j] * (qs[:, r] - s.offset[j])
            closed = d > 0.0
            N += s.k[j] * np.where(closed, d, 0.0)
            terms.append((r, np.where(closed, s.k[j] * s.side[j], 0.0)))
        return N, terms

    def loops(self, q: np.ndarray) -> list[JenkinsLoop]:
        """The stationary loop of every slider at q (2H+1, u)."""
        fr = self.system.friction
        qs = self._E @ q
        return [jenkins_loop(qs[:, self.trow[k]], self.normal_force(qs, k)[0], fr.k_t[k], fr.mu[k])
                for k in range(fr.p)]

    def contact(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
        """phi (2H+1, u), dphi (u, 2H+1, u, 2H+1) (d phi[:, r] / d q[:, c]) and the stops' contact intervals
        at q (2H+1, u): the stops projected exactly, the sliders by AFT (module docstring)."""
        h, u = 2 * self.H + 1, self.u
        ug = self._gap.u
        phi = np.zeros((h, u))
        dphi = np.zeros((u, h, u, h))
        pg, dpg, intervals = self._gap.contact(q[:, :ug])
        phi[:, :ug] = pg
        for r in range(ug):
            dphi[r, :, r, :] = dpg[r]
        fr = self.system.friction
        E, P = self._E, self._P
        qs = E @ q
        for k in range(fr.p):
            rt = self.trow[k]
            N, terms = self.normal_force(qs, k)
            loop = jenkins_loop(qs[:, rt], N, fr.k_t[k], fr.mu[k])
            if not loop.state.any():  # open over the whole period (OPEN = 0): f, GE and c are zeros, and so
                continue  # are their projections (+0, which leave phi and dphi as they are: test_friction_aft.py)
            GE, c, j = loop.synthesised(E, fr.k_t[k], fr.mu[k])
            phi[:, rt] += P @ loop.f
            dphi[rt, :, rt, :] += P @ GE
            for r, dN in terms:
                cdN = c * dN[j]
                if cdN.any():  # a stop that engages the slider at some sample (else zeros, as above)
                    dphi[rt, :, r, :] += P @ (cdN[:, None] * E[j])
        return phi, dphi, intervals

    # -- residual ----------------------------------------------------------------------------------
    def residual(self, z: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R (size,), dR/dz (size, size), dR/dOmega (size,) at the free unknowns z [m]: R = q - q_lin + Rc phi(q)
        as :meth:`ForcedBalance.residual`, the force derivative coupling the coordinates (friction)."""
        u, kp = self.u, self.keep
        q = self.full_q(z)
        phi, dphi, _ = self.contact(q)
        ks = self._harmonics_kept
        W, dW = self.receptances(omega, derivative=True, harmonics=ks)
        UW, UdW = np.einsum("rn,knc->krc", self.U, W), np.einsum("rn,knc->krc", self.U, dW)
        Rc, qlin = UW[:, :, :u], UW[:, :, u]
        dRc, dqlin = UdW[:, :, :u], UdW[:, :, u]
        phic = self._complex(phi)[ks]
        R = q[kp] - self._rows_of(qlin - np.einsum("krc,kc->kr", Rc, phic), ks)
        dRdw = -self._rows_of(dqlin - np.einsum("krc,kc->kr", dRc, phic), ks)
        S = self.size
        D = dphi[:, kp][:, :, :, kp].transpose(1, 0, 3, 2).reshape(S, S)  # rows (harmonic, coordinate)
        RD = np.empty((S, S))
        o = 0
        if ks[0] == 0:
            RD[:u] = Rc[0].real @ D[:u]
            o = 1
        Rk = Rc[o:]
        blk = np.empty((Rk.shape[0], 2 * u, 2 * u))
        blk[:, :u, :u] = blk[:, u:, u:] = Rk.real
        blk[:, :u, u:] = Rk.imag
        blk[:, u:, :u] = -Rk.imag
        RD[o * u:] = np.einsum("bij,bjs->bis", blk, D[o * u:].reshape(Rk.shape[0], 2 * u, S)).reshape(-1, S)
        RD[np.diag_indices(S)] += 1.0
        return R.ravel(), RD, dRdw.ravel()

    def force_jacobian(self, q: np.ndarray) -> np.ndarray:
        """dF/dX (n(2H+1), n(2H+1)) of the stop and friction forces on the full layout (for Hill's method)."""
        _, dphi, _ = self.contact(q)
        h, n = 2 * self.H + 1, self.n
        V = self.U
        dF = np.einsum("ahbk,ai,bj->hikj", dphi, V, V)
        return dF.reshape(h * n, h * n)

    def slider_state(self, z: np.ndarray) -> np.ndarray:
        """(p, 3) the fraction of the period each slider is open, sticking and slipping at z (a copy of the one
        worked out at the first call with these z: a stage reads each point's states several times)."""
        z = np.asarray(z, float)
        key = z.tobytes()
        got = self._states.get(key)
        if got is None:
            got = self._states[key] = np.array([[np.mean(lp.state == s) for s in (OPEN, STICK, SLIP)]
                                                for lp in self.loops(self.full_q(z))])
        return got.copy()


# -- forced-response curves with friction -----------------------------------------------------------
def friction_frc(system: GapSystem, load: np.ndarray, amplitude_N: float, f_min_hz: float, f_max_hz: float,
                 H: int = 1, *, harmonics: str = "all", normal_N: float | None = None, samples: int | None = None,
                 N: int | None = None, phase_deg: float = 0.0, point_rows: np.ndarray | None = None,
                 point_names: tuple[str, ...] | None = None, x_ref: float | None = None,
                 continuation: ContinuationOptions | None = None, stability: bool = True, progress=None, **steps):
    """The FRC of a system with friction under ``load`` (n,) x amplitude_N cos(Omega t + phase), f_min to f_max.

    As :func:`reduced.periodic.frc.frc` (same arguments, same :class:`~reduced.periodic.frc.FRCBranch`), the
    balance a :class:`FrictionBalance`; ``multipliers`` and ``stable`` are those of Hill's method on the
    consistent AFT Jacobian at every point (``hill`` holds them too), its bifurcations found from them.

    Parameters
    ----------
    system : the gap system with friction
    load, amplitude_N, f_min_hz, f_max_hz, H, harmonics, N, phase_deg, point_rows, point_names, x_ref,
    continuation, progress, steps : as :func:`reduced.periodic.frc.frc`
    normal_N : N, a constant normal load on every slider (None: the stops' contact force)
    samples : AFT samples of a period for the sliders (default :func:`reduced.periodic.hb.default_samples`)
    stability : Hill's method at every point

    Returns
    -------
    FRCBranch
    """
    from reduced.periodic import frc as _frc_mod

    _check.gap_system(system)
    if system.friction is None:
        raise _check.InvalidArgument("system has no friction: use reduced.periodic.frc.frc")
    b = _check.vector("load", load, system.n)
    if not np.any(b):
        raise _check.InvalidArgument("load must have a nonzero entry (the force direction b)")
    P = _check.positive("amplitude_N", amplitude_N, "N")
    f0 = _check.positive("f_min_hz", f_min_hz, "Hz")
    f1 = _check.positive("f_max_hz", f_max_hz, "Hz")
    if not f1 > f0:
        raise _check.InvalidArgument(f"f_max_hz must exceed f_min_hz = {f0:g} Hz, got {f1!r}")
    H = _check.integer("H", H, lo=1, hi=MAX_HARMONICS)
    harmonics = _check.choice("harmonics", harmonics, _frc_mod.HARMONIC_SETS)
    if normal_N is not None:
        normal_N = _check.positive("normal_N", normal_N, "N")
    if samples is not None:
        samples = _check.integer("samples", samples, lo=2 * H + 2)
    if N is not None:
        N = _check.integer("N", N, lo=2 * H + 1)
    rows, names = _frc_mod._output_points(system, point_rows, point_names)
    if x_ref is not None:
        x_ref = _check.positive("x_ref", x_ref, "m")
    step_control = (continuation or _frc_mod.FRC_STEPS).replace(**steps)
    fb = FrictionBalance(system, b, P, _check.number("phase_deg", phase_deg), H,
                         N or _frc_mod.default_root_samples(H), harmonics == "odd", normal_N, samples or 0)
    if x_ref is None and system.m == 0:
        x_ref = float(np.max(np.abs(_frc_mod.linear_frf(system, b, P, np.geomspace(f0, f1, 200), fb.U))))
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        br = _frc_mod._frc(fb, f0, f1, rows, names, x_ref, step_control, False, None, progress)
        if stability:
            t0 = time.perf_counter()
            mu = np.array([forced_hill(fb, z, w) for z, w in zip(br.z, br.omega, strict=True)])
            br.multipliers = mu
            br.stable = np.max(np.abs(mu), axis=1) <= 1.0 + HILL_TOL
            br.hill_index = np.arange(len(mu))
            br.hill = mu
            br.bifurcations = [b for b in bifurcations(mu, HILL_TOL, br.folds)
                               if br.segment[b[0]] == br.segment[b[0] - 1]]
            br.stability_wall_s = time.perf_counter() - t0
        br.notes.append("stability: Hill's method on the consistent AFT Jacobian of the sliders")
    return br


__all__ = ["FrictionBalance", "JenkinsLoop", "den_hartog_amplitude", "friction_frc", "jenkins_describing_function",
           "jenkins_loop"]
