"""Private numba kernels of the exact integrator's forced segments and of the forced flow.

A segment in contact state s with the loads' piece in force is the closed form of
:mod:`reduced.transient.exact` (its module docstring gives the formulas):

    y(tau) = y_p + Re sum_k X[:, k] e^{z_k tau} + sum_m P[m] tau^m,

set up by :func:`_start_segment` (:func:`_forced_segment`), its first stop crossing found by
:func:`_next_crossing` (each stop's march, :func:`_first_root_forced`, a step that provably skips
no root), and evaluated, with the closed-form dissipated work and work of the loads, by
:func:`_segment_state`. :func:`_forced_kernel` marches these segments for the integrator and
:func:`reduced.transient.flow._flow_kernel` for the flow, from the same set-up. Free segments run
in :mod:`reduced.transient._modal`; :func:`_first_root` and :func:`_modal_start` (the single-stop
march on the full 2n-term series) are the reference the modal march is tested against.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from reduced.transient._cabs import cabs
from reduced.transient._modal import (
    BUFFER_FULL,
    EPS,
    MAX_MARCH_ITER,
    NOISE_FACTOR,
    QTOL_REL,
    TAYLOR_TERMS,
    TAYLOR_ZT,
    _state_of,
    switch_stop,
)

SLOW_LT = 1.0  # |lambda| tau below which a mode is slow over a segment: written as its Taylor series ...
POLY_DEG = 20  # ... of this degree (1 / 21! ~ 2e-20: exact to round-off)
MOMENT_TOP = 130  # start of the downward moment recursion: damps its start by prod |x| / m < 1e-40


@nb.njit(cache=True)
def _work_setup(X, C, lam, n, G, Gz, az):
    """Per segment: G[i, k] = a_i^T C a_k (v = sum_i a_i e^{lam_i t}, a_i = X[n:, i]), and for
    the primitive of e^{(lam_i + lam_k) t}: Gz = G / (lam_i + lam_k), az = |lam_i + lam_k|.

    Only the terms whose velocity part is not zero enter (a slow mode, summed as a polynomial, has
    none): their a_i are copied into contiguous rows first, so the sums run over contiguous memory;
    each sum adds the same products in the same order as over all terms, the others are 0."""
    N = lam.shape[0]
    cols = np.empty(N, np.int64)
    m = 0
    for k in range(N):
        for r in range(n):
            if X[n + r, k] != 0.0:
                cols[m] = k
                m += 1
                break
    Xv = np.empty((m, n), np.complex128)
    for j in range(m):
        for a in range(n):
            Xv[j, a] = X[n + a, cols[j]]
    CX = np.empty((m, n), np.complex128)  # CX[j, a] = (C a_cols[j])_a
    for j in range(m):
        for a in range(n):
            acc = 0.0 + 0.0j
            for b in range(n):
                if C[a, b] != 0.0:
                    acc += C[a, b] * Xv[j, b]
            CX[j, a] = acc
    for i in range(N):
        for k in range(i, N):
            G[i, k] = 0.0
            z = lam[i] + lam[k]
            az[i, k] = abs(z)
            Gz[i, k] = 0.0
    for ji in range(m):
        i = cols[ji]
        for jk in range(ji, m):
            k = cols[jk]
            acc = 0.0 + 0.0j
            for a in range(n):
                acc += Xv[ji, a] * CX[jk, a]
            G[i, k] = acc
            z = lam[i] + lam[k]
            Gz[i, k] = acc / z if z != 0.0 else 0.0


@nb.njit(cache=True)
def _series_at(coef, lam, tau, q, d, dscale, Q2):
    """Add the terms c_i e^{lam_i tau} to q, q' = Re sum lam_i c_i e^{lam_i tau}, the scale of q'
    (sum |lam_i c_i e^{lam_i tau}|) and the bound Q2 = sum |lam_i|^2 |c_i e^{lam_i tau}| on |q''| (the moduli by
    :func:`reduced.transient._cabs.cabs`, the library's hypot inlined: the same bits)."""
    N = lam.shape[0]
    i = 0
    while i < N:
        li = lam[i]
        x = np.exp(li * tau)
        al = cabs(li)
        al2 = al**2
        e = coef[i] * x
        q += e.real
        d += (li * e).real
        ae = cabs(e)
        dscale += ae * al
        Q2 += ae * al2
        i += 1
        if i < N and li.imag != 0.0 and lam[i].real == li.real and lam[i].imag == -li.imag:
            # the conjugate exponent (the modes and harmonic loads come in such pairs): e^{conj(lam) tau} is
            # conj(e^{lam tau}) to the bit (cos even, sin odd), |conj(lam)| = |lam| (a real exponent is
            # taken alone: the conjugate of e^{a tau} + 0j would carry -0j)
            lc = lam[i]
            e = coef[i] * np.conj(x)
            q += e.real
            d += (lc * e).real
            ae = cabs(e)
            dscale += ae * al
            Q2 += ae * al2
            i += 1
    return q, d, dscale, Q2


@nb.njit(cache=True)
def _march_step(q, d, qtol, dtol, Q2, tau, hmin):
    """One step of the root march at tau, from q, q' (known to within qtol, dtol) and Q2 >= |q''|
    ahead: (tau_root, True) at a crossing, else (tau + h, False) with h the largest step for which
    q + q' h + Q2 h^2 / 2 < 0 (no root skipped), at least hmin; (inf, True) when q can never
    reach the threshold (q' <= 0 and Q2 = 0)."""
    if q > -qtol:
        if q > qtol and d >= -dtol:
            return tau, True
        # At the threshold a crossing needs q' > 0 beyond its round-off; otherwise it is a
        # tangential graze. A q just past the threshold but falling back (q' < 0) is the
        # round-off of re-expanding the state right after a switch, not a crossing:
        # deciding either by noise would flip the state back and forth forever.
        if d > dtol:
            return tau + max(-q, 0.0) / d, True
    qn = -min(q, 0.0)
    disc = np.sqrt(d * d + 2.0 * Q2 * qn)
    if d > 0.0:
        h = 2.0 * qn / (d + disc)
    elif Q2 > 0.0:
        h = (disc - d) / Q2
    else:
        return np.inf, True
    return tau + max(h, hmin), False


@nb.njit(cache=True)
def _first_root(const, coef, lam, tau_limit, hmin, qnoise, dnoise, floor):
    """First tau in [0, tau_limit) where q = const + Re sum coef e^{lam tau} turns positive.

    q is known to QTOL_REL x the size of its terms plus ``qnoise``, the round-off carried
    in from the modal coordinates w (q' likewise, with ``dnoise``); within that band a
    stop is at its threshold. Returns (tau, n_iter); tau = inf when there is none
    before tau_limit. A motion smaller than ``floor`` is round-off about a state that
    rests on a stop's threshold (zero gap, heavy damping): it triggers no event.
    """
    N = lam.shape[0]
    osc = 0.0
    for i in range(N):
        osc += cabs(coef[i])
    if osc < floor and abs(const) < floor:
        return np.inf, 0
    qtol = QTOL_REL * (abs(const) + osc) + NOISE_FACTOR * qnoise
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        q, d, dscale, Q2 = _series_at(coef, lam, tau, const, 0.0, 0.0, 0.0)
        tau, found = _march_step(q, d, qtol, QTOL_REL * dscale + NOISE_FACTOR * dnoise, Q2, tau, hmin)
        if found:
            return tau, it
        if tau >= tau_limit:
            return np.inf, it
    return -1.0, MAX_MARCH_ITER


@nb.njit(cache=True)
def _stop_series(B, j, sgn, offset_j, yp_s, X, coef):
    """q_j(tau) = const + Re sum_i coef_i e^{lam_i tau}: fills coef, returns const."""
    n = B.shape[1]
    const = 0.0
    for r in range(n):
        const += B[j, r] * yp_s[r]
    for i in range(X.shape[1]):
        acc = 0.0 + 0.0j
        for r in range(n):
            acc += B[j, r] * X[r, i]
        coef[i] = sgn * acc
    return sgn * (const - offset_j)


@nb.njit(cache=True)
def _exponentials(lam, tau, e):
    """e_i = exp(lam_i tau) (the second of a conjugate pair as the conjugate of the first: the same bits,
    :func:`_series_at`)."""
    N = lam.shape[0]
    i = 0
    while i < N:
        x = np.exp(lam[i] * tau)
        e[i] = x
        if i + 1 < N and lam[i].imag != 0.0 and lam[i + 1].real == lam[i].real and lam[i + 1].imag == -lam[i].imag:
            e[i + 1] = np.conj(x)
            i += 1
        i += 1


@nb.njit(cache=True)
def _eval_with(yp, X, e, out):
    """y = y_p + Re sum_i X[:, i] e_i."""
    N = e.shape[0]
    for r in range(X.shape[0]):
        acc = 0.0
        for i in range(N):
            acc += (X[r, i] * e[i]).real
        out[r] = yp[r] + acc


@nb.njit(cache=True)
def _eval_state(yp, X, lam, tau, out):
    """y(tau) = y_p + Re sum_i X[:, i] e^{lam_i tau}."""
    e = np.empty(lam.shape[0], np.complex128)
    _exponentials(lam, tau, e)
    _eval_with(yp, X, e, out)


@nb.njit(cache=True)
def _modal_error(Vinv, i, y, yp_s, ypart):
    """sum_r |V^-1_ir| (|y_r| + |y_p,r| + |ypart_r|): the scale of the round-off of modal coordinate i."""
    err = 0.0
    for r in range(Vinv.shape[1]):
        err += abs(Vinv[i, r]) * (abs(y[r]) + abs(yp_s[r]) + abs(ypart[r]))
    return err


@nb.njit(cache=True)
def _forced_segment(s, sigma, ip, tau_lim, y, yp_s, lam_s, V, Vinv, fz, fY, fU, pF, pp0, pp1, n, X, z, P,
                    Fs, phi, gam, werr, ypart, noise=True):
    """A forced segment's closed form in state s (see the module docstring), with the loads' piece
    ``ip`` re-based to the segment start (``sigma`` after the piece start):

    y(tau) = y_p + Re sum_k X[:, k] e^{z_k tau} + sum_m P[m] tau^m,

    the terms k < 2n the modes, then Y_l / 2 and conj(Y_l) / 2 (z = +-i omega_l) of the harmonic
    loads fast over the segment (omega_l tau_lim >= SLOW_LT; Fs: their amplitudes, 0 for the
    others), and P (real, degree POLY_DEG) the polynomial part. The loads' polynomial part is
    phi[l, k] tau^k: p0 + p1 tau and the Taylor series of the slow harmonic loads. A fast mode
    carries its exponential and the polynomial particular solution sum_k c_k tau^k
    (c_D = -gam_D / lambda, c_k = ((k + 1) c_{k+1} - gam_k) / lambda, gam = V^-1 [0; M^-1 b] phi);
    a slow mode (|lambda| tau_lim < SLOW_LT) its Taylor series m h_m = lambda h_{m-1} + gam_{m-1},
    which cancels nothing. Fills X, z, P, Fs, phi and werr (the round-off of the modal
    coordinates; 0 without ``noise``: a march that passes no noise bound, :func:`_next_crossing`, does not
    read it); returns whether there is a polynomial part.
    """
    N = 2 * n
    L = fz.shape[0]
    M1 = P.shape[0]
    poly = False
    deg = -1
    for l in range(L):
        F = pF[ip, l]
        if F != 0.0 and sigma != 0.0:
            F = F * np.exp(1j * fz[l] * sigma)
        for k in range(M1):
            phi[l, k] = 0.0
        phi[l, 0] = pp0[ip, l] + pp1[ip, l] * sigma
        phi[l, 1] = pp1[ip, l]
        if F != 0.0 and fz[l] * tau_lim < SLOW_LT:
            # Re(F e^{i w tau}) = sum_k Re(F (i w)^k / k!) tau^k: to round-off for w tau < 1
            c = F
            for k in range(M1):
                phi[l, k] += c.real
                c = c * (1j * fz[l]) / (k + 1)
            F = 0.0 + 0.0j
        Fs[l] = F
        for k in range(M1):
            if phi[l, k] != 0.0:
                poly = True
                deg = max(deg, k)
    for r in range(N):
        ypart[r] = 0.0
    col = N
    for l in range(L):
        for r in range(N):
            Y = fY[s, r, l] * Fs[l]
            X[r, col] = 0.5 * Y
            X[r, col + 1] = 0.5 * np.conj(Y)
            ypart[r] += Y.real
        z[col] = 1j * fz[l]
        z[col + 1] = -1j * fz[l]
        col += 2
    for m in range(M1):
        for r in range(N):
            P[m, r] = 0.0
    for i in range(N):
        lam = lam_s[i]
        z[i] = lam
        wi = 0.0 + 0.0j
        for r in range(N):
            wi += Vinv[i, r] * (y[r] - yp_s[r] - ypart[r])
        werr[i] = EPS * _modal_error(Vinv, i, y, yp_s, ypart) if noise else 0.0
        if not poly:
            for r in range(N):
                X[r, i] = V[r, i] * wi
            continue
        for k in range(deg + 1):
            g = 0.0 + 0.0j
            for l in range(L):
                g += fU[s, i, l] * phi[l, k]
            gam[k] = g
        if abs(lam) * tau_lim < SLOW_LT:
            h = wi
            for r in range(N):
                X[r, i] = 0.0
                P[0, r] += (V[r, i] * h).real
            for m in range(1, M1):
                h = lam * h
                if m - 1 <= deg:
                    h += gam[m - 1]
                h = h / m
                for r in range(N):
                    P[m, r] += (V[r, i] * h).real
        else:
            c = -gam[deg] / lam
            for r in range(N):
                P[deg, r] += (V[r, i] * c).real
            for k in range(deg - 1, -1, -1):
                c = ((k + 1) * c - gam[k]) / lam
                for r in range(N):
                    P[k, r] += (V[r, i] * c).real
            for r in range(N):
                X[r, i] = V[r, i] * (wi - c)  # c is now c_0, the particular solution at tau = 0
    return poly


@nb.njit(cache=True)
def _first_root_forced(const, coef, lam, Qp, poly, tau_limit, hmin, qnoise, dnoise, floor, grow):
    """:func:`_first_root` for q = const + Re sum coef e^{lam tau} + sum_m Qp[m] tau^m (a forced
    segment): |q''| <= sum |coef| |lam|^2 e^{Re(lam) tau_a} + sum_m m (m - 1) |Qp[m]| tau_limit^(m - 2)
    on [tau_a, tau_limit], so the same march never steps over a root. With ``grow`` (a state of a system
    with friction, whose terms may grow: Re lam > 0), a growing term enters the bound with its size at
    tau_limit, |coef| e^{Re(lam) tau_limit}, its largest on [tau_a, tau_limit] (the caller keeps that
    growth small, :func:`reduced.transient._friction_kernels._friction_forced_kernel`)."""
    N = lam.shape[0]
    M = Qp.shape[0] - 1
    osc = 0.0
    for i in range(N):
        osc += cabs(coef[i]) * (math.exp(lam[i].real * tau_limit) if grow and lam[i].real > 0.0 else 1.0)
    Q2p = 0.0
    pmax = 0.0
    if poly:
        tm = 1.0  # tau_limit^m
        for m in range(M + 1):
            pmax += abs(Qp[m]) * tm
            tm *= tau_limit
        tm = 1.0  # tau_limit^(m - 2)
        for m in range(2, M + 1):
            Q2p += m * (m - 1) * abs(Qp[m]) * tm
            tm *= tau_limit
    if osc < floor and abs(const) < floor and pmax < floor:
        return np.inf, 0
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        pscale = 0.0
        q, d, dscale, Q2 = _series_at(coef, lam, tau, const, 0.0, 0.0, Q2p)
        if grow:
            for i in range(N):
                if lam[i].real > 0.0:  # its size at tau_limit, not at tau, bounds it ahead
                    Q2 += cabs(coef[i]) * (math.exp(lam[i].real * tau_limit) - math.exp(lam[i].real * tau)) * cabs(
                        lam[i]) ** 2
        if poly:
            pv = Qp[M]
            pd = M * Qp[M]
            ps = abs(Qp[M])
            pds = M * abs(Qp[M])
            for m in range(M - 1, -1, -1):
                pv = pv * tau + Qp[m]
                ps = ps * tau + abs(Qp[m])
                if m >= 1:
                    pd = pd * tau + m * Qp[m]
                    pds = pds * tau + m * abs(Qp[m])
            q += pv
            d += pd
            pscale = ps
            dscale += pds
        qtol = QTOL_REL * (abs(const) + osc + pscale) + NOISE_FACTOR * qnoise
        tau, found = _march_step(q, d, qtol, QTOL_REL * dscale + NOISE_FACTOR * dnoise, Q2, tau, hmin)
        if found:
            return tau, it
        if tau >= tau_limit:
            return np.inf, it
    return -1.0, MAX_MARCH_ITER


@nb.njit(cache=True)
def _stop_poly(B, j, sgn, P, Qp):
    """Qp[m] = sgn B_j P[m, :n]: the polynomial part of q_j."""
    n = B.shape[1]
    for m in range(P.shape[0]):
        acc = 0.0
        for r in range(n):
            acc += B[j, r] * P[m, r]
        Qp[m] = sgn * acc


@nb.njit(cache=True)
def _add_poly(P, tau, n_rows, out):
    """out[r] += sum_m P[m, r] tau^m (Horner), r < n_rows."""
    M = P.shape[0] - 1
    for r in range(n_rows):
        acc = P[M, r]
        for m in range(M - 1, -1, -1):
            acc = acc * tau + P[m, r]
        out[r] += acc


@nb.njit(cache=True)
def _series_terms(ax):
    """Terms of the series of e^x - 1 (and kin) for |x| = ax < TAYLOR_ZT: ax^j / j! below 1e-18."""
    if ax < 1e-3:
        return 5
    if ax < 0.05:
        return 9
    return TAYLOR_TERMS


@nb.njit(cache=True)
def _i0(u, ru, eu, tau):
    """int_0^tau e^{u t} dt with ru = 1 / u and eu = e^{u tau}: (eu - 1) / u, or its series where
    |u tau| < TAYLOR_ZT."""
    x = u * tau
    ax = abs(x)
    if ax < TAYLOR_ZT:
        acc = 1.0 + 0.0j
        for j in range(_series_terms(ax), 0, -1):
            acc = 1.0 + acc * x / (j + 1)
        return tau * acc
    return (eu - 1.0) * ru


@nb.njit(cache=True)
def _inv(u):
    """1 / u (0 for u = 0, where the series branch is taken)."""
    return 1.0 / u if u != 0.0 else 0.0 + 0.0j


@nb.njit(cache=True)
def _moments(u, tau, out):
    """out[m] = int_0^tau t^m e^{u t} dt = tau^(m+1) J_m(u tau), m = 0 .. len(out) - 1.

    J_m(x) = int_0^1 s^m e^{x s} ds by J_m = (e^x - m J_{m-1}) / x upward for m < |x| and
    J_{m-1} = (e^x - x J_m) / m downward from m = MOMENT_TOP (started at 0) for m >= |x|: each
    recursion run where it damps its errors (by m / |x|, resp. |x| / m), so every moment is
    accurate to a few eps for any u.
    """
    M = out.shape[0] - 1
    x = u * tau
    ex = np.exp(x)
    ax = abs(x)
    ms = M + 1 if ax >= M + 1 else int(ax)
    if ms >= 1:
        J = (ex - 1.0) / x
        out[0] = J
        for m in range(1, ms):
            J = (ex - m * J) / x
            out[m] = J
    if ms <= M:
        J = 0.0 + 0.0j
        for m in range(MOMENT_TOP, ms, -1):
            J = (ex - x * J) / m
            if m - 1 <= M:
                out[m - 1] = J
    tm = tau
    for m in range(M + 1):
        out[m] *= tm
        tm *= tau


@nb.njit(cache=True)
def _ext_setup(X, z, fb, fz, n, beta, rp, rm):
    """beta[k, l] = a_k^T b_l with a_k = X[n:, k] the velocity part of term k, and the inverses
    rp = 1 / (z_k + i omega_l), rm = 1 / (z_k - i omega_l) of the exponents of v^T f_ext."""
    for k in range(X.shape[1]):
        for l in range(fb.shape[0]):
            acc = 0.0 + 0.0j
            for r in range(n):
                acc += X[n + r, k] * fb[l, r]
            beta[k, l] = acc
            rp[k, l] = _inv(z[k] + 1j * fz[l])
            rm[k, l] = _inv(z[k] - 1j * fz[l])


@nb.njit(cache=True)
def _ext_work(beta, z, e, fz, Fs, tau, eiw, rp, rm):
    """int_0^tau v_E^T f_H dt for v_E = sum_k a_k e^{z_k t} (a real sum) and the fast harmonic
    loads f_H = sum_l b_l (F_l / 2 e^{i w_l t} + conj(F_l) / 2 e^{-i w_l t}), e_k = e^{z_k tau}."""
    K = beta.shape[0]
    L = beta.shape[1]
    acc = 0.0 + 0.0j
    for l in range(L):
        if Fs[l] == 0.0:
            continue
        eiw[l] = np.exp(1j * fz[l] * tau)
        w = 1j * fz[l]
        for k in range(K):
            bkl = beta[k, l]
            if bkl != 0.0:
                acc += bkl * (0.5 * Fs[l] * _i0(z[k] + w, rp[k, l], e[k] * eiw[l], tau)
                              + 0.5 * np.conj(Fs[l]) * _i0(z[k] - w, rm[k, l], e[k] * np.conj(eiw[l]), tau))
    return acc.real


@nb.njit(cache=True)
def _work_exp(G, Gz, az, z, tau, e):
    """int_0^tau v^T C v dt for v = sum_k a_k e^{z_k t}: :func:`_work` with the series of the
    forced path (to TAYLOR_ZT); G, Gz, az from :func:`_work_setup`."""
    K = z.shape[0]
    acc = 0.0 + 0.0j
    for i in range(K):
        for k in range(i, K):
            if G[i, k] != 0.0:
                x = (z[i] + z[k]) * tau
                if az[i, k] * tau < TAYLOR_ZT:
                    s = 1.0 + 0.0j
                    for j in range(_series_terms(az[i, k] * tau), 0, -1):
                        s = 1.0 + s * x / (j + 1)
                    term = G[i, k] * tau * s
                else:
                    term = Gz[i, k] * (e[i] * e[k] - 1.0)
                acc += term if k == i else 2.0 * term
    return acc.real


@nb.njit(cache=True)
def _poly_setup(X, P, C, fb, n, damped_, ACp, Cpp, Pb):
    """With p_m = P[m, n:] the velocity part of the polynomial: ACp[k, m] = a_k^T C p_m,
    Cpp[m, m'] = p_m^T C p_m' (damped), Pb[m, l] = p_m^T b_l."""
    M1 = P.shape[0]
    for m in range(M1):
        for l in range(fb.shape[0]):
            acc = 0.0
            for r in range(n):
                acc += P[m, n + r] * fb[l, r]
            Pb[m, l] = acc
    if not damped_:
        return
    Cp = np.empty(n)
    for m in range(M1):
        for a in range(n):
            ca = 0.0
            for b in range(n):
                ca += C[a, b] * P[m, n + b]
            Cp[a] = ca
        for k in range(X.shape[1]):
            acc = 0.0 + 0.0j
            for a in range(n):
                acc += X[n + a, k] * Cp[a]
            ACp[k, m] = acc
        for m2 in range(M1):
            acc2 = 0.0
            for a in range(n):
                acc2 += P[m2, n + a] * Cp[a]
            Cpp[m2, m] = acc2


@nb.njit(cache=True)
def _poly_work(ACp, Cpp, Pb, beta, phi, Fs, z, tau, MOM, damped_, N):
    """(W, W_ext) of the polynomial parts over [0, tau], with v = v_E + v_P (v_E = sum_k a_k e^{z_k t},
    v_P = sum_m p_m t^m) and f_ext = f_H + f_P (fast harmonic, f_P = sum_l b_l sum_k phi[l, k] t^k):
    int (2 v_E^T C v_P + v_P^T C v_P) dt and int (v_E^T f_P + v_P^T f_H + v_P^T f_P) dt, from the
    moments MOM[k, m] = int_0^tau t^m e^{z_k t} dt (:func:`_moments`)."""
    K = z.shape[0]
    M1 = Cpp.shape[0]
    L = Pb.shape[1]
    for k in range(K):
        _moments(z[k], tau, MOM[k])
    W = 0.0
    if damped_:
        acc = 0.0 + 0.0j
        for k in range(K):
            for m in range(M1):
                if ACp[k, m] != 0.0:
                    acc += ACp[k, m] * MOM[k, m]
        W = 2.0 * acc.real
        for m in range(M1):
            for m2 in range(M1):
                if Cpp[m, m2] != 0.0:
                    W += Cpp[m, m2] * tau ** (m + m2 + 1) / (m + m2 + 1)
    acc = 0.0 + 0.0j
    for l in range(L):
        for k in range(K):
            if beta[k, l] != 0.0:
                inner = 0.0 + 0.0j
                for j in range(M1):
                    if phi[l, j] != 0.0:
                        inner += phi[l, j] * MOM[k, j]
                acc += beta[k, l] * inner
        if Fs[l] != 0.0:
            # F/2 I_m(i w) + conj(F)/2 I_m(-i w) = Re(F I_m(i w)) for real p_m; i w_l is z[N + 2 l]
            inner = 0.0 + 0.0j
            for m in range(M1):
                inner += Pb[m, l] * MOM[N + 2 * l, m]
            acc += Fs[l] * inner
    E = acc.real
    for l in range(L):
        for m in range(M1):
            if Pb[m, l] != 0.0:
                for j in range(M1):
                    if phi[l, j] != 0.0:
                        E += Pb[m, l] * phi[l, j] * tau ** (m + j + 1) / (m + j + 1)
    return W, E


@nb.njit(cache=True)
def _piece_at(pstarts, ip, t, t_end):
    """(ip, t_lim): the load piece holding t (advanced from ip) and where the segment must end,
    the next breakpoint or t_end."""
    NP = pstarts.shape[0]
    while ip + 1 < NP and pstarts[ip + 1] <= t:
        ip += 1
    if ip + 1 < NP and pstarts[ip + 1] < t_end:
        return ip, pstarts[ip + 1]
    return ip, t_end


@nb.njit(cache=True)
def _modal_start(V_s, Vinv_s, y, yp_s, X, werr):
    """Free segment start: w = Vinv (y - yp), X[:, i] = V[:, i] w_i, and werr bounds the round-off in w."""
    N = y.shape[0]
    for i in range(N):
        wi = 0.0 + 0.0j
        err = 0.0
        for r in range(N):
            wi += Vinv_s[i, r] * (y[r] - yp_s[r])
            err += abs(Vinv_s[i, r]) * (abs(y[r]) + abs(yp_s[r]))
        werr[i] = EPS * err
        for r in range(N):
            X[r, i] = V_s[r, i] * wi


@nb.njit(cache=True)
def _segment_arrays(n, L):
    """Scratch of a forced segment with L loads (:func:`_start_segment`): X (2n, Kt), z, coef (Kt,),
    werr, ytmp, ypart (2n,), P (POLY_DEG + 1, 2n), Qp, Fs (L,), phi (L, POLY_DEG + 1), gam; Kt = 2n + 2L
    terms, the modes, then +-i omega_l per load."""
    N = 2 * n
    Kt = N + 2 * L
    M1 = POLY_DEG + 1
    return (np.empty((N, Kt), np.complex128), np.zeros(Kt, np.complex128), np.empty(Kt, np.complex128),
            np.empty(N), np.empty(N), np.zeros(N), np.zeros((M1, N)), np.zeros(M1), np.zeros(L, np.complex128),
            np.zeros((L, M1)), np.zeros(M1, np.complex128))


@nb.njit(cache=True)
def _work_arrays(n, L):
    """Scratch of the closed-form work integrals of a forced segment: G, Gz, az (Kt, Kt)
    (:func:`_work_setup`), e (Kt,), ACp (Kt, M1), Cpp (M1, M1), Pb (M1, L) (:func:`_poly_setup`),
    MOM (Kt, M1), beta, rp, rm (Kt, L) (:func:`_ext_setup`), eiw (L,); M1 = POLY_DEG + 1."""
    Kt = 2 * n + 2 * L
    M1 = POLY_DEG + 1
    return (np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt)),
            np.empty(Kt, np.complex128), np.zeros((Kt, M1), np.complex128), np.zeros((M1, M1)), np.zeros((M1, L)),
            np.zeros((Kt, M1), np.complex128), np.zeros((Kt, L), np.complex128), np.zeros((Kt, L), np.complex128),
            np.zeros((Kt, L), np.complex128), np.empty(L, np.complex128))


@nb.njit(cache=True)
def _start_segment(s, t, t_end, ip, pstarts, y, yp_s, lam_s, V_s, Vinv_s, fz, fY, fU, pF, pp0, pp1, n, X, z, P,
                   Fs, phi, gam, werr, ypart, noise=True):
    """The segment from (t, y) in state s: the loads' piece holding t (advanced from ``ip``), where the
    segment must end (the next load breakpoint or t_end) and its closed form (:func:`_forced_segment`).
    Returns (ip, t_lim, poly)."""
    ip, t_lim = _piece_at(pstarts, ip, t, t_end)
    poly = _forced_segment(s, t - pstarts[ip], ip, t_lim - t, y, yp_s, lam_s, V_s, Vinv_s, fz, fY, fU, pF, pp0,
                           pp1, n, X, z, P, Fs, phi, gam, werr, ypart, noise)
    return ip, t_lim, poly


@nb.njit(cache=True)
def _next_crossing(B, offset, side, active, yp_s, V_s, X, z, werr, poly, P, Qp, coef, tau_max, hmin, floor, noise):
    """The first stop crossing of the segment set up by :func:`_start_segment`: (tau, j, n_iter, status),
    j = -1 when no stop crosses before tau_max, status -3 when a march did not end. Each stop is
    signed so that q_j <= 0 until it changes state and marched up to the earliest crossing found so
    far. With ``noise`` each march knows q_j and q_j' to the round-off carried in from the modal
    coordinates (werr); without (the flow) to QTOL_REL of their terms, and ``floor`` is 0."""
    n = B.shape[1]
    m = B.shape[0]
    N = 2 * n
    tau_ev = tau_max
    j_ev = -1
    n_iter = 0
    for j in range(m):
        sgn = -side[j] if active[j] else side[j]
        const = _stop_series(B, j, sgn, offset[j], yp_s, X, coef)
        qnoise = 0.0
        dnoise = 0.0
        if noise:
            for i in range(N):
                pv = 0.0 + 0.0j
                for r in range(n):
                    pv += B[j, r] * V_s[r, i]
                qnoise += cabs(pv) * werr[i]
                dnoise += cabs(pv) * cabs(z[i]) * werr[i]  # z[i] = lambda_i for the modes i < 2n
        if poly:
            _stop_poly(B, j, sgn, P, Qp)
        tj, it = _first_root_forced(const, coef, z, Qp, poly, tau_ev, hmin, qnoise, dnoise, floor, False)
        n_iter += it
        if tj < 0.0:
            return tau_ev, j_ev, n_iter, -3
        if tj < tau_ev:
            tau_ev = tj
            j_ev = j
    return tau_ev, j_ev, n_iter, 0


@nb.njit(cache=True)
def _segment_state(tau, yp_s, X, z, P, poly, damped, G, Gz, az, ACp, Cpp, Pb, beta, rp, rm, phi, Fs, fz, MOM, e,
                   eiw, ytmp):
    """The segment's state at tau into ytmp and (dW, dE): the dissipated work and the work of the loads
    over [0, tau], in closed form (:func:`_work_exp`, :func:`_ext_work`, :func:`_poly_work`)."""
    N = ytmp.shape[0]
    _exponentials(z, tau, e)
    _eval_with(yp_s, X, e, ytmp)
    Wp = 0.0
    Ep = 0.0
    if poly:
        _add_poly(P, tau, N, ytmp)
        Wp, Ep = _poly_work(ACp, Cpp, Pb, beta, phi, Fs, z, tau, MOM, damped, N)
    dE = _ext_work(beta, z, e, fz, Fs, tau, eiw, rp, rm) + Ep
    dW = (_work_exp(G, Gz, az, z, tau, e) if damped else 0.0) + Wp
    return dW, dE


@nb.njit(cache=True)
def _state_only(tau, yp_s, X, z, P, poly, e, ytmp):
    """:func:`_segment_state`'s state alone (the same numbers), no work: (0, 0)."""
    _exponentials(z, tau, e)
    _eval_with(yp_s, X, e, ytmp)
    if poly:
        _add_poly(P, tau, ytmp.shape[0], ytmp)
    return 0.0, 0.0


@nb.njit(cache=True)
def _forced_kernel(lam, V, Vinv, yp, valid, B, offset, side, tip, C, damped, y, active, t, t_end, t_samples, i_samp,
                   t_after, out_y, out_W, W, hmin, floor, max_events, n_stuck, fz, fY, fU, fb, pstarts, pF, pp0, pp1,
                   out_E, E, work=True):
    """March events from t to t_end under the loads, filling the sample buffer ``t_samples`` from index i_samp.

    (y, active, t, W, E) is the state at the start of a segment (an event, a load breakpoint or a
    piece boundary) and is advanced in place segment by segment; E is the work of the loads, whose
    pieces start at ``pstarts`` (the first at or before t; see :func:`_forced_segment`). When the
    buffer fills inside a segment that still has samples before its end (the next sample, at
    ``t_after``, lies in it), the kernel returns BUFFER_FULL *without* advancing that segment:
    called again with a new buffer it recomputes the segment from the same state, so the samples
    do not depend on the buffer size. Without ``work`` the dissipated energy and the work of the loads
    are not integrated (W and E stay as they are; the states and events are the same numbers).
    Returns (t, W, E, i_samp, n_events, n_iter, status, n_stuck).
    """
    n = B.shape[1]
    m = B.shape[0]
    N = 2 * n
    L = fb.shape[0]
    ns = t_samples.shape[0]
    X, z, coef, werr, ytmp, ypart, P, Qp, Fs, phi, gam = _segment_arrays(n, L)
    G, Gz, az, e, ACp, Cpp, Pb, MOM, beta, rp, rm, eiw = _work_arrays(n, L)
    ip = max(np.searchsorted(pstarts, t, side="right") - 1, 0)
    n_events = 0
    n_iter = 0
    status = 0
    while True:
        s = _state_of(active)
        if not valid[s]:
            status = -2
            break
        ip, t_lim, poly = _start_segment(s, t, t_end, ip, pstarts, y, yp[s], lam[s], V[s], Vinv[s], fz, fY, fU, pF,
                                         pp0, pp1, n, X, z, P, Fs, phi, gam, werr, ypart)
        if work:
            if damped:
                _work_setup(X, C, z, n, G, Gz, az)
            _ext_setup(X, z, fb, fz, n, beta, rp, rm)
            if poly:
                _poly_setup(X, P, C, fb, n, damped, ACp, Cpp, Pb)
        tau_ev, j_ev, seg_iter, status = _next_crossing(B, offset, side, active, yp[s], V[s], X, z, werr, poly, P,
                                                        Qp, coef, t_lim - t, hmin, floor, True)
        if status != 0:
            break
        t_next = t_lim if j_ev < 0 else t + tau_ev
        while i_samp < ns and t_samples[i_samp] <= t_next:
            if work:
                dW, dE = _segment_state(max(t_samples[i_samp] - t, 0.0), yp[s], X, z, P, poly, damped, G, Gz, az,
                                        ACp, Cpp, Pb, beta, rp, rm, phi, Fs, fz, MOM, e, eiw, ytmp)
            else:
                dW, dE = _state_only(max(t_samples[i_samp] - t, 0.0), yp[s], X, z, P, poly, e, ytmp)
            out_E[i_samp] = E + dE
            out_W[i_samp] = W + dW
            for r in range(N):
                out_y[i_samp, r] = ytmp[r]
            i_samp += 1
        if i_samp == ns and t_after <= t_next:
            status = BUFFER_FULL  # the segment is searched again with the next buffer: count it then
            break
        n_iter += seg_iter
        if work:
            dW, dE = _segment_state(tau_ev, yp[s], X, z, P, poly, damped, G, Gz, az, ACp, Cpp, Pb, beta, rp, rm, phi,
                                    Fs, fz, MOM, e, eiw, ytmp)
        else:
            dW, dE = _state_only(tau_ev, yp[s], X, z, P, poly, e, ytmp)
        E += dE
        W += dW
        for r in range(N):
            y[r] = ytmp[r]
        n_stuck = n_stuck + 1 if tau_ev == 0.0 else 0
        if n_stuck > 8 * m:
            status = -4
            break
        t = t_next
        if j_ev < 0:
            if t_lim < t_end:
                continue  # a load breakpoint: the same contact state, a new piece
            break
        switch_stop(active, tip, j_ev)
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, E, i_samp, n_events, n_iter, status, n_stuck
