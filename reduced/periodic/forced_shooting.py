"""Forced periodic orbits of a gap system on its exact flow, by multiple shooting (no harmonics).

The system (:class:`reduced.models.gaps.GapSystem`) under one harmonic load along b,

    M x'' + C x' + K x + B^T f(B x) = b P cos(Omega t + phi),

has a periodic orbit of period p T (T = 2 pi / Omega; p = 1, or 2 past a period doubling)
where the exact flow phi (:mod:`reduced.transient.flow`: closed form in each contact state,
events located to round-off) closes on itself. With S nodes y_k at the times t_k = k p T / S,

    R_k(y, Omega) = phi(y_k; t_k, p T / S) - y_{k+1} = 0,   k = 0..S-1 (y_S = y_0),

2 n S equations in the 2 n S node states: square for a given frequency, one short of square
along a curve, which :func:`reduced.periodic.continuation.continue_branch` follows in

    Y = [y_0 / D, ..., y_{S-1} / D, ln(Omega / omega_ref)],   D = [x_ref (n times), Omega x_ref (n times)],

rows scaled by D^-1 (displacements in units of x_ref, velocities in units of Omega x_ref).
dR_k/dy_k = Phi_k, the segment's monodromy (the product of the contact states' exponentials:
penalty stops have identity saltation matrices); dR/dOmega by central differences in
ln Omega (the particular solutions of the new frequency are a batched solve per contact
state). Each node sees only the S-th root of the orbit's growth per period, so orbits with
Floquet multipliers of 1e4-1e5 (the contact plateau of the three-mass model) converge where
single shooting does not. Nothing is truncated: the orbit is exact to round-off, unlike
harmonic balance, whose truncation in contact (1-5 % closed time against k_g = 3.5e7 N/m and
a 700 Hz bending mode that rings between impacts) needs H ~ 255
(tests/test_frc_contact.py). The orbit's monodromy is the product of the segments' (its
eigenvalues are the Floquet multipliers).

All segments are marched in one numba call (:func:`_march_nodes`, the flow's own segment
kernel :func:`reduced.transient.flow._flow_kernel`): a residual with its Jacobian costs a few
flows of one period (about 0.3 ms for the three-mass model in contact).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.shooting import ShootingError
from reduced.transient._cabs import cabs
from reduced.transient._exact_kernels import _eval_state, _exponentials, _next_crossing
from reduced.transient._modal import QTOL_REL, _state_of
from reduced.transient.exact import HMIN_PERIODS
from reduced.transient.exact_tables import forced_table, state_table
from reduced.transient.flow import MAX_SEGMENTS, _against_its_rate, _settle

SEGMENTS = 8  # default nodes per load period: a node sees |mu|^(1/8) of the orbit's growth (1e4 -> 3.2)
PEAK_SAMPLES_PER_PERIOD = 6.0  # samples of a contact state's closed form per period of its fastest mode ...
PEAK_MAX_SAMPLES = 256  # ... but at most this many a stretch (then Newton refines each bracketed extreme)
_BOUND_SLACK = 1e-9  # relative slack of a stretch's bound in _node_peaks, far above its samples' round-off (~1e-14)
_FRESH = 32  # the peaks' samples step e^{lam dt} from sample to sample; every 32nd is a fresh exp (drift ~32 eps)
GRAZING_EVENTS = 2  # contact events one grazing adds or removes per period (a stop closing and opening once)
D_LOG_OMEGA = 1e-6  # central-difference step of dR/d ln(Omega) (truncation ~1e-12, round-off ~1e-10)
MAX_STRETCHES = 512  # contact-state stretches of a segment kept for the peaks (more: marched again)
_STATUS = {-1: "too many contact events in a segment", -2: "the motion reached an infeasible contact state",
           -3: "event search did not converge"}


# -- the kernels ------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _initial_active(B, offset, side, y, active):
    """The contact state at y (the flow's rule: a stop within QTOL_REL of its threshold is closed
    when closing)."""
    n = B.shape[1]
    sx = 0.0
    for r in range(n):
        sx += abs(y[r])
    for j in range(B.shape[0]):
        pen = 0.0
        rate = 0.0
        for r in range(n):
            pen += B[j, r] * y[r]
            rate += B[j, r] * y[n + r]
        pen = side[j] * (pen - offset[j])
        rate = side[j] * rate
        atol = QTOL_REL * (sx + abs(offset[j]))
        active[j] = pen > atol or (abs(pen) <= atol and rate > 0.0)


@nb.njit(cache=True)
def _harmonic_flow(lam, V, Vinv, yp, valid, B, offset, side, y, active, T, hmin, seg_state, seg_tau, omega, fY, F0):
    """March the flow under the one harmonic load Re(F0 e^{i Omega t}) b from t = 0 to T; y and active are
    updated in place, each contact-state stretch recorded (seg_state, seg_tau). Returns (n_seg, status).

    The flow's own march (:func:`reduced.transient.flow._flow_kernel`) with the load's particular
    solution always in exponential form, y(tau) = y_s + Re(Y_s F e^{i Omega tau}) + Re sum X_i e^{lam_i tau}:
    the general kernel writes a harmonic load that is slow over the rest of its segment
    (Omega tau < 1, every multiple-shooting segment of S >= 7 nodes) as a degree-20 Taylor
    polynomial, needed for its polynomial loads, which costs several times more here. Each
    crossing is found by the same march (:func:`reduced.transient._exact_kernels._next_crossing`,
    a step that provably skips no root), and the same rules settle round-off roots and stops
    switching together.
    """
    n = B.shape[1]
    N = 2 * n
    Kt = N + 2
    X = np.empty((N, Kt), np.complex128)
    z = np.zeros(Kt, np.complex128)
    coef = np.empty(Kt, np.complex128)
    werr = np.empty(N)
    ytmp = np.empty(N)
    ypart = np.empty(N)
    P = np.zeros((1, N))
    Qp = np.zeros(1)
    t = 0.0
    n_seg = 0
    n_zero = 0
    max_seg = seg_state.shape[0]
    z[N] = 1j * omega
    z[N + 1] = -1j * omega
    while True:
        s = _state_of(active)
        if not valid[s]:
            return n_seg, -2
        F = F0 * np.exp(1j * omega * t)
        for r in range(N):
            Yr = fY[s, r, 0] * F
            X[r, N] = 0.5 * Yr
            X[r, N + 1] = 0.5 * np.conj(Yr)
            ypart[r] = Yr.real
        for i in range(N):
            z[i] = lam[s, i]
            wi = 0.0 + 0.0j
            for r in range(N):
                wi += Vinv[s, i, r] * (y[r] - yp[s, r] - ypart[r])
            werr[i] = 0.0
            for r in range(N):
                X[r, i] = V[s, r, i] * wi
        tau_ev, j_ev, _, status = _next_crossing(B, offset, side, active, yp[s], V[s], X, z, werr, False, P, Qp,
                                                 coef, T - t, hmin, 0.0, False)
        if status != 0:
            return n_seg, -3
        _eval_state(yp[s], X, z, tau_ev, ytmp)
        if j_ev >= 0 and _against_its_rate(B, side, active, j_ev, ytmp):
            # a round-off root next to a crossing just made: not an event; march hmin further
            tau_ev = min(tau_ev + hmin, T - t)
            _eval_state(yp[s], X, z, tau_ev, ytmp)
            j_ev = -2
        for r in range(N):
            y[r] = ytmp[r]
        if n_seg >= max_seg:
            return n_seg, -1
        seg_state[n_seg] = s
        seg_tau[n_seg] = tau_ev
        n_seg += 1
        t = T if j_ev == -1 else t + tau_ev
        if j_ev == -2:
            if t >= T:
                break
            continue
        if j_ev < 0:
            break
        active[j_ev] = not active[j_ev]
        n_zero = n_zero + 1 if tau_ev == 0.0 else 0
        if n_zero > 64:
            return n_seg, -1
        _settle(B, offset, side, active, y, j_ev, n_zero > 4)
    return n_seg, 0


@nb.njit(cache=True)
def _segment_exp(lam, V, Vinv, s, tau, W):
    """exp(A_s tau) (2n, 2n) from the closed form Re(V diag(exp(lam tau)) V^-1); W is scratch."""
    N = W.shape[0]
    e = np.empty(N, np.complex128)
    _exponentials(lam[s], tau, e)
    for r in range(N):
        for c in range(N):
            W[r, c] = V[s, r, c] * e[c]
    return np.ascontiguousarray((W @ Vinv[s]).real)


@nb.njit(cache=True)
def _particular(lam, V, fU, valid, omega, fY, fYd):
    """Per contact state s: fY[s] = [H b; i Omega H b] = V_s (U_s / (i Omega - lam_s)), the particular
    solution of the load e^{i Omega t} (H = (K_s - Omega^2 M + i Omega C)^-1, U_s = V_s^-1 [0; M^-1 b]),
    and fYd[s] its derivative in Omega, -V_s (i U_s / (i Omega - lam_s)^2)."""
    N = lam.shape[1]
    g = np.empty(N, np.complex128)
    gd = np.empty(N, np.complex128)
    for s in range(lam.shape[0]):
        if not valid[s]:
            for r in range(N):
                fY[s, r, 0] = 0.0
                fYd[s, r, 0] = 0.0
            continue
        for m in range(N):
            q = 1.0 / (1j * omega - lam[s, m])
            g[m] = fU[s, m, 0] * q
            gd[m] = -1j * fU[s, m, 0] * q * q
        for r in range(N):
            acc = 0.0 + 0.0j
            accd = 0.0 + 0.0j
            for m in range(N):
                acc += V[s, r, m] * g[m]
                accd += V[s, r, m] * gd[m]
            fY[s, r, 0] = acc
            fYd[s, r, 0] = accd


@nb.njit(cache=True)
def _walk(lam, V, Vinv, seg_state, seg_tau, n_seg, omega, F0k, t0k, fY, fYd, J, z, W, wa, wb):
    """Over the recorded contact-state stretches of one march: J, the product of their exponentials
    (the segment's monodromy), and z, the end state's derivative in Omega at fixed times
    (:meth:`ForcedFlow.march`), in place."""
    N = J.shape[0]
    for r in range(N):
        z[r] = 0.0
        for c in range(N):
            J[r, c] = 1.0 if r == c else 0.0
    sig = 0.0
    first = True
    for i in range(n_seg):
        s = seg_state[i]
        tau = seg_tau[i]
        if tau == 0.0:
            continue
        E = _segment_exp(lam, V, Vinv, s, tau, W)
        if first:
            J[:, :] = E  # E @ I: the same numbers, without the product
            first = False
        else:
            J[:, :] = E @ J
        # w(t) = Re((dY_s/dOmega + i t Y_s) P e^{i(Omega t + phi)}), t = t0k + sigma
        ea = F0k * np.exp(1j * omega * sig)
        eb = F0k * np.exp(1j * omega * (sig + tau))
        for r in range(N):
            wa[r] = ((fYd[s, r, 0] + 1j * (t0k + sig) * fY[s, r, 0]) * ea).real
            wb[r] = ((fYd[s, r, 0] + 1j * (t0k + sig + tau) * fY[s, r, 0]) * eb).real
        z[:] = E @ (z - wa) + wb
        sig += tau


@nb.njit(cache=True)
def _march_nodes(lam, V, Vinv, yp, valid, B, offset, side, Y0, t0, h, hmin, omega, fY, fYd, fU, fb, F0, jac, Yout,
                 Jout, dW, seg_state, seg_tau, n_events):
    """Each node Y0[k] (2n,) at the time t0[k] marched over h on the forced flow whose load's complex
    amplitude at t0[k] is F0[k] (1, 1): Yout[k]; with ``jac`` also the segment's monodromy Jout[k]
    and dW[k], the derivative of the end state in Omega at fixed times (:func:`_walk`). Returns
    (0, -1), or (status < 0, the node whose march failed)."""
    S, N = Y0.shape
    m = B.shape[0]
    active = np.empty(m, np.bool_)
    J = np.empty((N, N))
    W = np.empty((N, N), np.complex128)
    z = np.empty(N)
    wa = np.empty(N)
    wb = np.empty(N)
    for k in range(S):
        y = Y0[k].copy()
        _initial_active(B, offset, side, y, active)
        n_seg, status = _harmonic_flow(lam, V, Vinv, yp, valid, B, offset, side, y, active, h, hmin, seg_state,
                                       seg_tau, omega, fY, F0[k, 0])
        if status != 0:
            return status, k
        Yout[k] = y
        n_events[k] = n_seg - 1
        if jac:
            _walk(lam, V, Vinv, seg_state, seg_tau, n_seg, omega, F0[k, 0], t0[k], fY, fYd, J, z, W, wa, wb)
            Jout[k] = J
            dW[k] = z
    return 0, -1


@nb.njit(cache=True)
def _vector_field(Minv, K, C, B, kst, offset, side, b, p, y, out):
    """out = y' = [v; M^-1 (b p - C v - K x - B^T f(B x))] at the state y (2n,) and load value p."""
    n = K.shape[0]
    f = np.empty(n)
    for r in range(n):
        acc = b[r] * p
        for c in range(n):
            acc -= C[r, c] * y[n + c] + K[r, c] * y[c]
        f[r] = acc
    for j in range(B.shape[0]):
        sj = -offset[j]
        for c in range(n):
            sj += B[j, c] * y[c]
        if side[j] * sj > 0.0:
            for r in range(n):
                f[r] -= kst[j] * sj * B[j, r]
    for r in range(n):
        out[r] = y[n + r]
        acc = 0.0
        for c in range(n):
            acc += Minv[r, c] * f[c]
        out[n + r] = acc


@nb.njit(cache=True)
def _march_kernel(lam, V, Vinv, yp, valid, B, offset, side, amp, phase, Yv, d, h, hmin, omega, fU, seg_state, seg_tau,
                  R, Yend, n_events, st_state, st_tau, st_n):
    """The marches of :class:`ShootingResidual` at the scaled nodes Yv (S, 2n), D sqrt(S) = d (2n,), segment
    length h and frequency omega: R, the end states Yend (S, 2n), the events and each node's contact-state
    stretches (st_state, st_tau, st_n; st_n[k] = -1 if more than fit), in place; dR/dY from them is
    :func:`_jacobian_kernel`'s. Returns (0, -1) or (status < 0, the node whose march failed)."""
    S, N = Yv.shape
    m = B.shape[0]
    fY = np.empty((lam.shape[0], N, 1), np.complex128)
    fYd = np.empty((lam.shape[0], N, 1), np.complex128)
    _particular(lam, V, fU, valid, omega, fY, fYd)
    active = np.empty(m, np.bool_)
    y0 = np.empty(N)
    for k in range(S):
        t0k = k * h
        F0k = amp * np.exp(1j * (omega * t0k + phase))
        for r in range(N):
            y0[r] = Yv[k, r] * d[r]
        y = y0.copy()
        _initial_active(B, offset, side, y, active)
        n_seg, status = _harmonic_flow(lam, V, Vinv, yp, valid, B, offset, side, y, active, h, hmin, seg_state,
                                       seg_tau, omega, fY, F0k)
        if status != 0:
            return status, k
        n_events[k] = n_seg - 1
        if n_seg <= st_state.shape[1]:
            st_n[k] = n_seg
            st_state[k, :n_seg] = seg_state[:n_seg]
            st_tau[k, :n_seg] = seg_tau[:n_seg]
        else:
            st_n[k] = -1
        kk = (k + 1) % S
        o = k * N
        for r in range(N):
            Yend[k, r] = y[r]
            R[o + r] = y[r] / d[r] - Yv[kk, r]
    return 0, -1


@nb.njit(cache=True)
def _jacobian_kernel(lam, V, Vinv, yp, valid, B, offset, side, kst, Minv, K, C, bvec, amp, phase, Yv, Yend, d, dv, h,
                     hmin, omega, fU, seg_state, seg_tau, J, Js, st_state, st_tau, st_n):
    """dR/dY (:class:`ShootingResidual`) and the segments' monodromies Js, in place, from the marches of
    :func:`_march_kernel` (their end states Yend and stretches; a node whose stretches did not fit is marched
    again, to the same stretches); dv: Omega dD/dOmega / D of the velocity rows, 1 if they scale with
    Omega, else 0. Returns (0, -1) or (status < 0, the node whose march failed)."""
    S, N = Yv.shape
    n = N // 2
    m = B.shape[0]
    fY = np.empty((lam.shape[0], N, 1), np.complex128)
    fYd = np.empty((lam.shape[0], N, 1), np.complex128)
    _particular(lam, V, fU, valid, omega, fY, fYd)
    active = np.empty(m, np.bool_)
    Jk = np.empty((N, N))
    W = np.empty((N, N), np.complex128)
    z = np.empty(N)
    wa = np.empty(N)
    wb = np.empty(N)
    y0 = np.empty(N)
    f0 = np.empty(N)
    f1 = np.empty(N)
    M = S * N
    for r in range(M):
        for c in range(M + 1):
            J[r, c] = 0.0
    for k in range(S):
        t0k = k * h
        F0k = amp * np.exp(1j * (omega * t0k + phase))
        for r in range(N):
            y0[r] = Yv[k, r] * d[r]
        if st_n[k] >= 0:
            n_seg = st_n[k]
            seg_state[:n_seg] = st_state[k, :n_seg]
            seg_tau[:n_seg] = st_tau[k, :n_seg]
        else:
            y = y0.copy()
            _initial_active(B, offset, side, y, active)
            n_seg, status = _harmonic_flow(lam, V, Vinv, yp, valid, B, offset, side, y, active, h, hmin, seg_state,
                                           seg_tau, omega, fY, F0k)
            if status != 0:
                return status, k
        y = Yend[k]
        _walk(lam, V, Vinv, seg_state, seg_tau, n_seg, omega, F0k, t0k, fY, fYd, Jk, z, W, wa, wb)
        Js[k] = Jk
        _vector_field(Minv, K, C, B, kst, offset, side, bvec, amp * math.cos(omega * t0k + phase), y0, f0)
        _vector_field(Minv, K, C, B, kst, offset, side, bvec, amp * math.cos(omega * (t0k + h) + phase), y, f1)
        kk = (k + 1) % S
        o = k * N
        for r in range(N):
            for c in range(N):
                J[o + r, o + c] = Jk[r, c] * d[c] / d[r]
            J[o + r, kk * N + r] -= 1.0
        # d/d ln Omega: the load (z), the node time and the segment length (~1/Omega: the vector
        # field at both ends) and the velocity scale (~Omega)
        for r in range(N):
            acc = omega * z[r] - f1[r] * (t0k + h)
            for c in range(N):
                u = f0[c] * t0k + (dv * Yv[k, c] * d[c] if c >= n else 0.0)
                acc += Jk[r, c] * u
            if r >= n:
                acc -= dv * y[r]
            J[o + r, M] = acc / d[r]
    return 0, -1


@nb.njit(cache=True)
def _row_series(rows, Vs, Ys, yps, beta, Fa, omega, lam_s, sig, out, eb):
    """(x, x', x'') of each output point r . x at sigma into out (p, 3), for the closed form of one
    contact state: x(sigma) = r . (x_s + Re(Y_s Fa e^{i Omega sigma}) + Re(V_s beta e^{lam sigma})).
    eb: scratch (2n,) complex (beta e^{lam sigma}); the three sums are made in one pass over the terms."""
    n = rows.shape[1]
    e_h = Fa * np.exp(1j * omega * sig)
    _exponentials(lam_s, sig, eb)
    for m in range(eb.shape[0]):
        eb[m] = beta[m] * eb[m]
    for p in range(rows.shape[0]):
        c0 = 0.0
        ch = 0.0 + 0.0j
        c1 = 0.0 + 0.0j
        c2 = 0.0 + 0.0j
        c3 = 0.0 + 0.0j
        for r in range(n):
            w = rows[p, r]
            if w == 0.0:
                continue
            c0 += w * yps[r]
            ch += w * Ys[r]
            for m in range(eb.shape[0]):
                t = w * Vs[r, m] * eb[m]
                c1 += t
                # first and second derivatives: lam_m per term, twice
                u = t * lam_s[m]
                c2 += u
                c3 += u * lam_s[m]
        out[p, 0] = c0 + (ch * e_h).real + c1.real
        out[p, 1] = (1j * omega * ch * e_h).real + c2.real
        out[p, 2] = (-omega * omega * ch * e_h).real + c3.real


@nb.njit(cache=True)
def _node_peaks(lam, V, Vinv, yp, valid, B, offset, side, Y0, h, hmin, omega, fY, fU, fb, F0, rows, samples_per_rad,
                q_max, seg_state, seg_tau, pmax, pmin, st_state, st_tau, st_n):
    """The largest and smallest value of each output point r . x over the segment from each node
    Y0[k] (the march of :func:`_march_nodes`), into pmax, pmin (S, p): each contact state's closed
    form sampled (``samples_per_rad`` per radian of its fastest mode, 8 to ``q_max`` samples) and
    each extreme refined by safeguarded Newton on the closed form's derivative. Returns a status
    as :func:`_march_nodes`. Where st_n[k] >= 0 the node's contact-state stretches are taken from
    st_state[k], st_tau[k] (recorded by :func:`_march_kernel`) instead of marching again. A stretch whose
    closed form is bounded inside the extremes found so far (this node's and the earlier nodes') is not
    sampled: pmax, pmin of a node may then fall short of its own extremes, never of the largest and smallest
    over the nodes (all that :meth:`ForcedFlow.peaks` returns).

    Long because it is one numba kernel: per stretch the output rows are projected once and the samples
    stepped by e^{lam dt}, and each bracketed extreme refined in place, without allocating per sample."""
    S, N = Y0.shape
    n = N // 2
    m = B.shape[0]
    P = rows.shape[0]
    active = np.empty(m, np.bool_)
    W = np.empty((N, N), np.complex128)
    ev = np.empty((P, 3))
    prev = np.empty((P, 3))
    one = np.empty((1, 3))
    ya = np.empty(N)
    c = np.empty(N)
    RV = np.empty((P, N), np.complex128)
    c0p = np.empty(P)
    chp = np.empty(P, np.complex128)
    eb = np.empty(N, np.complex128)
    ebr = np.empty(N, np.complex128)
    step = np.empty(N, np.complex128)
    gmax = np.full(P, -np.inf)  # the extremes of the nodes before k
    gmin = np.full(P, np.inf)
    for k in range(S):
        if st_n[k] >= 0:
            n_seg = st_n[k]
            seg_state[:n_seg] = st_state[k, :n_seg]
            seg_tau[:n_seg] = st_tau[k, :n_seg]
        else:
            y = Y0[k].copy()
            _initial_active(B, offset, side, y, active)
            n_seg, status = _harmonic_flow(lam, V, Vinv, yp, valid, B, offset, side, y, active, h, hmin, seg_state,
                                           seg_tau, omega, fY, F0[k, 0])
            if status != 0:
                return status, k
        for p in range(P):
            pmax[k, p] = -np.inf
            pmin[k, p] = np.inf
        ya[:] = Y0[k]
        sig = 0.0
        for i in range(n_seg):
            s = seg_state[i]
            tau = seg_tau[i]
            if tau == 0.0:
                continue
            Fa = F0[k, 0] * np.exp(1j * omega * sig)
            for r in range(N):
                c[r] = ya[r] - yp[s, r] - (fY[s, r, 0] * Fa).real
            beta = Vinv[s] @ c.astype(np.complex128)
            fast = 0.0
            for mm in range(N):
                fast = max(fast, abs(lam[s, mm].imag))
            q = int(min(max(8.0, math.ceil(samples_per_rad * fast * tau)), q_max))
            Ys = fY[s, :n, 0]
            # the output rows projected once a stretch: x_p(sigma) = c0_p + Re(ch_p e_h) + Re(sum_m RV_pm eb_m),
            # eb_m = beta_m e^{lam_m sigma} stepped sample to sample (a fresh exp every _FRESH samples)
            for p in range(P):
                c0p[p] = 0.0
                chp[p] = 0.0
                for mm in range(N):
                    RV[p, mm] = 0.0
                for r in range(n):
                    w = rows[p, r]
                    if w == 0.0:
                        continue
                    c0p[p] += w * yp[s, r]
                    chp[p] += w * Ys[r]
                    for mm in range(N):
                        RV[p, mm] += w * V[s, r, mm]
            # a stretch whose closed form provably stays inside the extremes already found (of this node's and the
            # earlier nodes' stretches) is not sampled: |Re(ch e_h)| <= |ch| |Fa|, |Re(RV_m beta_m e^{lam_m sigma})|
            # <= |RV_m beta_m| max(1, e^{Re lam_m tau}); the result, the largest and smallest over all nodes, is
            # the same (every sample and refined extreme of the stretch lies below, resp. above, it)
            skip = True
            for p in range(P):
                acc = cabs(chp[p]) * cabs(Fa)  # the moduli inlined (the library's hypot's bits)
                for mm in range(N):
                    acc += cabs(RV[p, mm]) * cabs(beta[mm]) * max(1.0, math.exp(lam[s, mm].real * tau))
                slack = acc + _BOUND_SLACK * (abs(c0p[p]) + acc)
                if not (c0p[p] + slack < max(gmax[p], pmax[k, p]) and c0p[p] - slack > min(gmin[p], pmin[k, p])):
                    skip = False
                    break
            if not skip:
                dsig = tau / q
                for mm in range(N):
                    step[mm] = np.exp(lam[s, mm] * dsig)
                eh_step = np.exp(1j * omega * dsig)
                for j in range(q + 1):
                    sj = tau * j / q
                    if j % _FRESH == 0:
                        e_h = Fa * np.exp(1j * omega * sj)
                        for mm in range(N):
                            eb[mm] = beta[mm] * np.exp(lam[s, mm] * sj)
                    else:
                        e_h *= eh_step
                        for mm in range(N):
                            eb[mm] *= step[mm]
                    for p in range(P):
                        a0 = 0.0 + 0.0j
                        a1 = 0.0 + 0.0j
                        for mm in range(N):
                            t = RV[p, mm] * eb[mm]
                            a0 += t
                            a1 += t * lam[s, mm]
                        ev[p, 0] = c0p[p] + (chp[p] * e_h).real + a0.real
                        ev[p, 1] = (1j * omega * chp[p] * e_h).real + a1.real
                    for p in range(P):
                        v = ev[p, 0]
                        if v > pmax[k, p]:
                            pmax[k, p] = v
                        if v < pmin[k, p]:
                            pmin[k, p] = v
                        if j > 0 and (prev[p, 1] > 0.0) != (ev[p, 1] > 0.0):
                            # an extremum in (s_{j-1}, s_j); it can beat the extremes so far only if it lies
                            # within dt max |x'| of the bracket's ends: then Newton on x' = 0 in the bracket
                            reach = (tau / q) * max(abs(prev[p, 1]), abs(ev[p, 1]))
                            if prev[p, 1] > 0.0 and max(prev[p, 0], v) + reach < pmax[k, p]:
                                continue
                            if prev[p, 1] < 0.0 and min(prev[p, 0], v) - reach > pmin[k, p]:
                                continue
                            lo, hi = tau * (j - 1) / q, sj
                            flo = prev[p, 1]
                            t_ = 0.5 * (lo + hi)
                            for _ in range(40):
                                _row_series(rows[p:p + 1], V[s, :n], Ys, yp[s, :n], beta, Fa, omega, lam[s], t_,
                                            one, ebr)
                                d1, d2 = one[0, 1], one[0, 2]
                                if (d1 > 0.0) == (flo > 0.0):
                                    lo = t_
                                else:
                                    hi = t_
                                tn = t_ - d1 / d2 if d2 != 0.0 else 0.5 * (lo + hi)
                                if not (lo <= tn <= hi):
                                    tn = 0.5 * (lo + hi)
                                if abs(tn - t_) <= 1e-15 * tau or hi - lo <= 1e-15 * tau:
                                    t_ = tn
                                    break
                                t_ = tn
                            _row_series(rows[p:p + 1], V[s, :n], Ys, yp[s, :n], beta, Fa, omega, lam[s], t_, one, ebr)
                            if one[0, 0] > pmax[k, p]:
                                pmax[k, p] = one[0, 0]
                            if one[0, 0] < pmin[k, p]:
                                pmin[k, p] = one[0, 0]
                    for p in range(P):
                        prev[p, 0] = ev[p, 0]
                        prev[p, 1] = ev[p, 1]
            # the state at the end of this contact state's stretch: the closed form at tau
            E = _segment_exp(lam, V, Vinv, s, tau, W)
            Fb = F0[k, 0] * np.exp(1j * omega * (sig + tau))
            ya[:] = E @ c
            for r in range(N):
                ya[r] += yp[s, r] + (fY[s, r, 0] * Fb).real
            sig += tau
        for p in range(P):
            gmax[p] = max(gmax[p], pmax[k, p])
            gmin[p] = min(gmin[p], pmin[k, p])
    return 0, -1


# -- the flow of one frequency ---------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Shot:
    """The nodes' marches at one point (:meth:`ForcedFlow.shoot`): the scaled nodes Yv (S, 2n), their
    scales d (2n,), the segment length h (s), Omega (rad/s) and the load amplitude (N) they were marched
    with; R (2nS,), the end states Yend (S, 2n), the events per segment (S,) and the contact-state
    stretches (st_state, st_tau, st_n)."""

    Yv: np.ndarray
    d: np.ndarray
    h: float
    omega: float
    amplitude_N: float
    R: np.ndarray
    Yend: np.ndarray
    events: np.ndarray
    stretches: tuple



class ForcedFlow:
    """The exact forced flow of ``system`` under b P cos(Omega t + phi) at any Omega, lean: the
    contact states are decomposed once, the particular solutions of a new Omega are one batched
    solve, and every node of a multiple-shooting set is marched in one numba call.

    Parameters
    ----------
    system : the gap system (damped: every contact state must have a bounded forced response)
    b : (n,) force direction
    amplitude_N : N, P
    phase_deg : deg, phi
    """

    def __init__(self, system: GapSystem, b: np.ndarray, amplitude_N: float, phase_deg: float = 0.0) -> None:
        _check.gap_system(system)
        self.system = system
        self.b = _check.vector("b", b, system.n)
        self.amplitude_N = _check.number("amplitude_N", amplitude_N)
        self.phase = math.radians(_check.number("phase_deg", phase_deg))
        self.table = state_table(system)
        ft = forced_table(system, self.table, Loads(self.b[None, :], (Harmonic(1.0, 1.0),)))  # refuses rigid states
        self._U = np.ascontiguousarray(ft.U)
        self._fb = np.ascontiguousarray(ft.b)
        self._Minv = np.linalg.inv(system.M)
        self._Y = {}
        self.hmin = HMIN_PERIODS / system.omega_max()
        self._seg_state = np.empty(MAX_SEGMENTS, np.int64)
        self._seg_tau = np.empty(MAX_SEGMENTS)
        self.n = system.n

    def particular(self, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """(Y, dY/dOmega), each (states, 2n, 1) complex: [H b; i Omega H b] per contact state,
        H = (K_s - Omega^2 M + i Omega C)^-1 (m/N), and its derivative, from the modal form
        (:func:`_particular`)."""
        out = self._Y.get(omega)
        if out is None:
            tb = self.table
            Y = np.empty((tb.lam.shape[0], 2 * self.n, 1), complex)
            Yd = np.empty_like(Y)
            call_numba_kernel(_particular, tb.lam, tb.V, self._U, tb.valid, float(omega), Y, Yd)
            if len(self._Y) > 16:
                self._Y.clear()
            out = self._Y[omega] = (Y, Yd)
        return out

    def residual(self, Yv: np.ndarray, d: np.ndarray, h: float, omega: float, dv: float = 1.0,
                 jacobian: bool = True):
        """(R (2nS,), dR/dY (2nS, 2nS + 1), segment monodromies (S, 2n, 2n), events per segment (S,))
        of :class:`ShootingResidual` at the scaled nodes Yv (S, 2n) with scales d (2n,) (dv: 1 if the velocity
        scales grow with Omega, 0 if fixed): :meth:`shoot`, then :meth:`shot_jacobian`. Without ``jacobian``
        the flow alone is marched: R and the events, dR/dY and the monodromies None.

        Raises
        ------
        ShootingError
            A march the flow cannot finish.
        """
        shot = self.shoot(Yv, d, h, omega)
        if not jacobian:
            return shot.R, None, None, shot.events, shot.stretches
        J, Js = self.shot_jacobian(shot, dv)
        return shot.R, J, Js, shot.events, shot.stretches

    def shoot(self, Yv: np.ndarray, d: np.ndarray, h: float, omega: float) -> _Shot:
        """The nodes' marches of :meth:`residual` (one numba call, :func:`_march_kernel`): R, the end states,
        the events and the stretches, from which :meth:`shot_jacobian` gives dR/dY without marching again.

        Raises
        ------
        ShootingError
            A march the flow cannot finish.
        """
        tb, sy = self.table, self.system
        Yv = np.ascontiguousarray(Yv, dtype=float)
        d = np.ascontiguousarray(d, dtype=float)
        S, N = Yv.shape
        R = np.empty(S * N)
        Yend = np.empty((S, N))
        n_ev = np.zeros(S, np.int64)
        stretches = (np.empty((S, MAX_STRETCHES), np.int64), np.empty((S, MAX_STRETCHES)), np.empty(S, np.int64))
        status, k = call_numba_kernel(_march_kernel, tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, sy.B, sy.offset,
                                      sy.side, self.amplitude_N, self.phase, Yv, d, float(h), self.hmin, float(omega),
                                      self._U, self._seg_state, self._seg_tau, R, Yend, n_ev, *stretches)
        if status != 0:
            raise ShootingError(f"the exact flow failed from node {k} at {omega / (2 * math.pi):.6g} Hz: "
                                f"{_STATUS.get(status, status)}")
        return _Shot(Yv, d, float(h), float(omega), float(self.amplitude_N), R, Yend, n_ev, stretches)

    def shot_jacobian(self, shot: _Shot, dv: float = 1.0, out: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(dR/dY (2nS, 2nS + 1), segment monodromies (S, 2n, 2n)) of a :meth:`shoot` (its load amplitude,
        whatever the flow's is now), by :func:`_jacobian_kernel`: the numbers the marches and the Jacobian
        made together give. ``out``: a C-contiguous (2nS, 2nS + 1) array to write dR/dY into (e.g. the
        top rows of a bordered matrix), returned."""
        tb, sy = self.table, self.system
        S, N = shot.Yv.shape
        J = np.empty((S * N, S * N + 1)) if out is None else out
        Js = np.empty((S, N, N))
        status, k = call_numba_kernel(_jacobian_kernel, tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, sy.B, sy.offset,
                                      sy.side, sy.k, self._Minv, sy.K, sy.C, self.b, shot.amplitude_N, self.phase,
                                      shot.Yv, shot.Yend, shot.d, float(dv), shot.h, self.hmin, shot.omega, self._U,
                                      self._seg_state, self._seg_tau, J, Js, *shot.stretches)
        if status != 0:
            raise ShootingError(f"the exact flow failed from node {k} at {shot.omega / (2 * math.pi):.6g} Hz: "
                                f"{_STATUS.get(status, status)}")
        return J, Js

    def vector_field(self, Y: np.ndarray, t: np.ndarray, omega: float) -> np.ndarray:
        """(S, 2n) y' at the states Y (S, 2n) and times t (S,):
        [v; M^-1 (b P cos(Omega t + phi) - C v - K x - B^T f(B x))]."""
        s = self.system
        n = s.n
        x, v = Y[:, :n], Y[:, n:]
        p = self.amplitude_N * np.cos(omega * np.asarray(t, float) + self.phase)
        rhs = np.outer(p, self.b) - v @ s.C.T - x @ s.K.T - s.contact_force(x)
        return np.hstack([v, np.linalg.solve(s.M, rhs.T).T])

    def march(self, Y0: np.ndarray, t0: np.ndarray, h: float, omega: float, jacobian: bool = False):
        """Each state Y0[k] (S, 2n) at the time t0[k] marched over h seconds at load frequency omega:
        (Y (S, 2n), segment monodromies (S, 2n, 2n) or None, d Y / d Omega at fixed t0 and h (S, 2n)
        or None, contact events per segment (S,)).

        The derivative in Omega: within a contact state s the motion is
        y = y_s + Re(Y_s P e^{i(Omega t + phi)}) + exp(A_s (t - t_a)) (y(t_a) - ...), so over the
        segment [t_a, t_b] its derivative z obeys z_b = exp(A_s (t_b - t_a)) (z_a - w(t_a)) + w(t_b),
        w(t) = Re((dY_s/dOmega + i t Y_s) P e^{i(Omega t + phi)}); the contact times move with Omega
        but the vector field is continuous across them, so they add nothing (as for the monodromy).

        Raises
        ------
        ShootingError
            A march the flow cannot finish (too many events, an infeasible state, a failed search).
        """
        tb = self.table
        Y0 = np.ascontiguousarray(Y0, dtype=float)
        t0 = np.ascontiguousarray(t0, dtype=float)
        S, N = Y0.shape
        F0 = (self.amplitude_N * np.exp(1j * (omega * t0 + self.phase)))[:, None]
        Yout = np.empty((S, N))
        Jout = np.empty((S, N, N)) if jacobian else np.empty((S, 0, 0))
        dW = np.empty((S, N)) if jacobian else np.empty((S, 0))
        n_ev = np.zeros(S, np.int64)
        fY, fYd = self.particular(omega)
        status, k = call_numba_kernel(_march_nodes, tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, self.system.B,
                                      self.system.offset, self.system.side, Y0, t0, float(h), self.hmin, float(omega),
                                      fY, fYd, self._U, self._fb, np.ascontiguousarray(F0), jacobian, Yout, Jout, dW,
                                      self._seg_state, self._seg_tau, n_ev)
        if status != 0:
            raise ShootingError(f"the exact flow failed from node {k} at {omega / (2 * math.pi):.6g} Hz: "
                                f"{_STATUS.get(status, status)}")
        if not jacobian:
            return Yout, None, None, n_ev
        return Yout, Jout, dW, n_ev

    def peaks(self, Y0: np.ndarray, t0: np.ndarray, h: float, omega: float, rows: np.ndarray,
              samples_per_period: float = PEAK_SAMPLES_PER_PERIOD, stretches=None) -> tuple[np.ndarray, np.ndarray]:
        """(max (p,), min (p,)) in m of each output point r . x over the segments from the states Y0
        (S, 2n) at the times t0 (S,), each h long: every contact state's closed form sampled
        (``samples_per_period`` per period of its fastest mode; 8 to PEAK_MAX_SAMPLES a stretch) and
        every extreme between samples refined by Newton on the closed form's derivative, so the
        peak is exact to round-off (the penetration of a contact lasting 1 % of the period too).
        ``stretches``: the contact-state stretches of these very nodes from :meth:`residual` (no march)."""
        tb = self.table
        Y0 = np.ascontiguousarray(Y0, dtype=float)
        rows = np.ascontiguousarray(np.atleast_2d(rows), dtype=float)
        S = Y0.shape[0]
        F0 = (self.amplitude_N * np.exp(1j * (omega * np.asarray(t0, float) + self.phase)))[:, None]
        pmax = np.empty((S, rows.shape[0]))
        pmin = np.empty((S, rows.shape[0]))
        fY, _ = self.particular(omega)
        status, k = call_numba_kernel(_node_peaks, tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, self.system.B,
                                      self.system.offset, self.system.side, Y0, float(h), self.hmin, float(omega),
                                      fY, self._U, self._fb, np.ascontiguousarray(F0), rows,
                                      samples_per_period / (2.0 * math.pi), PEAK_MAX_SAMPLES, self._seg_state,
                                      self._seg_tau, pmax, pmin, *(stretches or _NO_STRETCHES(S)))
        if status != 0:
            raise ShootingError(f"the exact flow failed from node {k} at {omega / (2 * math.pi):.6g} Hz: "
                                f"{_STATUS.get(status, status)}")
        return pmax.max(axis=0), pmin.min(axis=0)

    def sample(self, Y: np.ndarray, omega: float, periods: int, per_segment: int) -> np.ndarray:
        """((S per_segment + 1), 2n): the orbit through the nodes Y (S, 2n) at t_k = k p T / S, sampled
        ``per_segment`` times a segment (each segment marched from its own node: no drift), and
        its first node again at the end."""
        S = Y.shape[0]
        T = periods * 2.0 * math.pi / omega
        h = T / S
        dt = h / per_segment
        out = np.empty((S * per_segment + 1, Y.shape[1]))
        cur = np.array(Y, float)
        for j in range(per_segment):
            out[j::per_segment][:S] = cur
            cur = self.march(cur, np.arange(S) * h + j * dt, dt, omega)[0]
        out[-1] = Y[0]
        return out


def _NO_STRETCHES(S: int) -> tuple:
    return np.zeros((S, 1), np.int64), np.zeros((S, 1)), np.full(S, -1, np.int64)


# -- the residual -----------------------------------------------------------------------------------
@dataclass(eq=False)
class ShootingResidual:
    """R(Y) of the multiple-shooting equations in the scaled unknowns of the module docstring:
    ``__call__(Y) -> (R (2nS,), dR/dY (2nS, 2nS + 1))`` (for
    :func:`reduced.periodic.continuation.continue_branch`).

    Parameters
    ----------
    flow : the forced flow
    segments : S, nodes over the orbit's period
    periods : p, the orbit's period in load periods (1; 2 for a period-doubled orbit)
    x_ref : m, scale of the displacements
    omega_ref : rad/s, reference of the frequency coordinate
    """

    flow: ForcedFlow
    segments: int
    periods: int
    x_ref: float
    omega_ref: float
    omega_v: float | None = None  # rad/s, fixed velocity scale (None: Omega)
    _memo: dict = field(default_factory=dict, repr=False)
    _events: dict = field(default_factory=dict, repr=False)
    _segments: tuple | None = field(default=None, repr=False)
    _gen: int = field(default=0, repr=False)  # forget() count: a Jacobian asked for after it is not memoised
    guard: tuple | None = field(default=None, repr=False)  # (Y_ref, its events, radius[, radius_multi]): _check_guard
    _scale: tuple | None = field(default=None, repr=False)  # (Omega, D sqrt(S)) of the last scale() asked for

    @property
    def n(self) -> int:
        return self.flow.n

    @property
    def size(self) -> int:
        """Unknowns besides the frequency: 2 n S."""
        return 2 * self.n * self.segments

    def velocity_scale(self, omega: float) -> float:
        """rad/s: the velocities are in units of this times the displacement scale: Omega, or a fixed
        ``omega_v`` (the fastest mode's: its ringing, spinning with Omega, then weighs what its
        displacement does in a step's length)."""
        return omega if self.omega_v is None else self.omega_v

    def scale(self, omega: float) -> np.ndarray:
        """(2n,) D sqrt(S): x_ref for displacements, Omega x_ref for velocities, times sqrt(S) so that
        a step's length is the RMS change of the nodes whatever S is."""
        hit = self._scale
        if hit is not None and hit[0] == omega:
            return hit[1]  # asked for several times at every trial point; callers never write into it
        c = math.sqrt(self.segments) * self.x_ref
        n = self.n
        d = np.empty(2 * n)
        d[:n] = c
        d[n:] = self.velocity_scale(omega) * c
        self._scale = (omega, d)
        return d

    def omega(self, Y: np.ndarray) -> float:
        return float(self.omega_ref * math.exp(Y[self.size]))

    def nodes(self, Y: np.ndarray) -> tuple[np.ndarray, float]:
        """(node states (S, 2n) in m and m/s, Omega in rad/s) of the point Y."""
        w = self.omega(Y)
        return Y[: self.size].reshape(self.segments, 2 * self.n) * self.scale(w), w

    def point(self, nodes: np.ndarray, omega: float) -> np.ndarray:
        """The scaled point Y of node states (S, 2n) at Omega."""
        return np.concatenate([(np.asarray(nodes, float) / self.scale(omega)).ravel(),
                               [math.log(omega / self.omega_ref)]])

    def times(self, omega: float) -> tuple[np.ndarray, float]:
        """(node times t_k (S,), segment length h) in s at Omega."""
        h = self.segment_length(omega)
        return np.arange(self.segments) * h, h

    def segment_length(self, omega: float) -> float:
        """s, h = p T / S at Omega (:meth:`times` without the node times)."""
        return self.periods * 2.0 * math.pi / omega / self.segments

    def __call__(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, jacobian = self.lazy(Y)
        return R, jacobian()

    def lazy(self, Y: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
        """(R(Y), a callable giving dR/dY): the nodes are marched now (:meth:`ForcedFlow.shoot`), the
        Jacobian's products made only when it is called (:meth:`ForcedFlow.shot_jacobian`): Newton's
        halving refuses many trial points on R alone, and a point the guard refuses needs none. The same
        numbers as ``self(Y)``; a point is memoised with its Jacobian."""
        key = Y.tobytes()
        if key in self._memo:
            self._check_guard(Y, key)
            R, J = self._memo[key]
            return R, lambda: J
        w = self.omega(Y)
        h = self.segment_length(w)
        shot = self.flow.shoot(Y[: self.size].reshape(self.segments, 2 * self.n), self.scale(w), h, w)
        self._events[key] = int(shot.events.sum())
        if len(self._events) > 64:
            self._events.pop(next(iter(self._events)))
        self._check_guard(Y, key)
        dv = 1.0 if self.omega_v is None else 0.0
        gen = self._gen

        def jacobian(below: np.ndarray | None = None) -> np.ndarray:
            hit = self._memo.get(key)
            if hit is not None and gen == self._gen:
                return hit[1] if below is None else np.vstack([hit[1], below])
            # with ``below``: dR/dY made in the top rows of [dR/dY; below] (a corrector's matrix, not copied)
            Jb = None if below is None else np.empty((self.size + 1, self.size + 1))
            J, Js = self.flow.shot_jacobian(shot, dv, None if Jb is None else Jb[:-1])
            if Jb is not None:
                Jb[-1] = below
            if gen == self._gen:  # not after forget(): the flow's load has changed since
                self._memo.clear()
                self._memo[key] = (shot.R, J)
                self._segments = (key, Js, shot.stretches)
            return J if Jb is None else Jb

        jacobian.stacks_below = True  # continue_branch's corrector asks for jacobian(below=t)
        return shot.R, jacobian

    def value(self, Y: np.ndarray) -> np.ndarray:
        """R(Y) alone (the same numbers as ``self(Y)[0]``): the flow marched without the Jacobian's
        products; memoised evaluations are used, nothing is memoised."""
        key = Y.tobytes()
        if key in self._memo:
            return self._memo[key][0]
        w = self.omega(Y)
        h = self.segment_length(w)
        return self.flow.shoot(Y[: self.size].reshape(self.segments, 2 * self.n), self.scale(w), h, w).R

    def _check_guard(self, Y: np.ndarray, key: bytes) -> None:
        """Refuse (NewtonError) a point farther than ``guard``'s radius from its reference point
        whose number of contact events differs from the reference's: a continuation step may
        cross a grazing only when it is short (the corrector's trial points are refused at their
        first evaluation, before any Newton iteration is spent on them). Raises
        :class:`reduced.periodic.hb.GuardRefusal`, a NewtonError."""
        if self.guard is None:
            return
        y_ref, ev_ref, radius, *multi = self.guard
        change = abs(self._events[key] - ev_ref)
        if multi and change > GRAZING_EVENTS:  # more than one grazing: (Y_ref, events, radius, radius of those)
            radius = multi[0]
        if change and float(np.linalg.norm(Y - y_ref)) > radius:
            from reduced.periodic.hb import GuardRefusal

            raise GuardRefusal("a grazing contact crossed in a long step")

    def forget(self) -> None:
        """Drop the memoised evaluations (after the flow's load changed)."""
        self._memo.clear()
        self._events.clear()
        self._segments = None
        self._gen += 1

    def events(self, Y: np.ndarray) -> int:
        """Contact events over the orbit's period at the point Y (a stop closing or opening): it
        changes only where a contact grazes, the corners of a curve."""
        key = Y.tobytes()
        if key not in self._events:
            self._memo.pop(key, None)
            self(Y)
        return self._events[key]

    def last_segment_monodromies(self, Y: np.ndarray) -> np.ndarray:
        """(S, 2n, 2n) the segments' monodromies at Y from its memoised evaluation (else evaluated)."""
        key = Y.tobytes()
        if self._segments is None or self._segments[0] != key:
            self._memo.pop(key, None)
            self(Y)
        return self._segments[1]

    def peaks(self, Y: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(max (p,), min (p,)) in m of the output points r . x over the orbit at Y
        (:meth:`ForcedFlow.peaks`, from the contact stretches of Y's evaluation when memoised)."""
        nodes, w = self.nodes(Y)
        t0, h = self.times(w)
        key = Y.tobytes()
        st = self._segments[2] if self._segments is not None and self._segments[0] == key else None
        return self.flow.peaks(nodes, t0, h, w, rows, stretches=st)

    def segment_monodromies(self, Y: np.ndarray) -> np.ndarray:
        """(S, 2n, 2n) physical d y_{k+1} / d y_k of each segment at the point Y."""
        nodes, w = self.nodes(Y)
        t0, h = self.times(w)
        return self.flow.march(nodes, t0, h, w, True)[1]

    def monodromy(self, Y: np.ndarray) -> np.ndarray:
        """(2n, 2n) the orbit's monodromy over p T: the product of the segments'."""
        Phi = np.eye(2 * self.n)
        for Jk in self.segment_monodromies(Y):
            Phi = Jk @ Phi
        return Phi


def shoot_at(res: ShootingResidual, nodes: np.ndarray, omega: float, *, tol: float = 1e-11, max_iter: int = 40,
             known: list | None = None) -> np.ndarray:
    """The scaled point Y of the periodic orbit at Omega nearest the guessed nodes (S, 2n): damped
    Newton on R(Y) = 0 at fixed frequency. ``known``: points Y of orbits to stay away from
    (deflation, Farrell, Birkisson & Funke 2015: R is multiplied by 1 / ||Y - Y*||^2 + 1 for each,
    so Newton cannot converge to them).

    Parameters
    ----------
    res : ShootingResidual
        The multiple-shooting residual.
    nodes : (S, 2n) ndarray
        The guessed states at the segments' starts.
    omega : float
        rad/s, the forcing frequency, held fixed.
    tol : float
        Newton's tolerance on the scaled residual.
    max_iter : int
        Newton steps at most.
    known : list of ndarray, optional
        Points Y of orbits to stay away from (deflation).

    Returns
    -------
    ndarray
        The scaled point Y of the orbit.

    Raises
    ------
    ShootingError
        Newton did not reach ``tol`` (max |R|, in units of x_ref and Omega x_ref).
    """
    from reduced.periodic.hb import NewtonError, newton

    Y0 = res.point(nodes, omega)
    nz = res.size
    lw = Y0[nz]
    known = [np.asarray(k)[:nz] for k in (known or [])]

    def fun(v):
        R, J = res(np.append(v, lw))
        J = J[:, :nz]
        for ks in known:
            d = v - ks
            dd = float(d @ d)
            m = 1.0 / dd + 1.0
            # d(m R)/dv = m J + R (dm/dv)^T, dm/dv = -2 d / dd^2
            J = m * J + np.outer(R, -2.0 * d / dd**2)
            R = m * R
        return R, J

    try:
        out = newton(fun, Y0[:nz], tol=tol, max_iter=max_iter)
    except NewtonError as exc:
        raise ShootingError(f"no periodic orbit at {omega / (2 * math.pi):.6g} Hz: {exc}") from None
    Y = np.append(out.y, lw)
    r = float(np.max(np.abs(res(Y)[0])))
    if r > max(tol, 1e-9):
        raise ShootingError(f"no periodic orbit at {omega / (2 * math.pi):.6g} Hz: residual {r:.3g}")
    return Y


__all__ = ["D_LOG_OMEGA", "SEGMENTS", "ForcedFlow", "ShootingResidual", "shoot_at"]
