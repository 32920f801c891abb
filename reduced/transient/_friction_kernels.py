"""Private numba kernels of the exact integrator with friction (:mod:`reduced.transient.friction`).

The state is y = [x; v; w] (the sliders' positions w), the friction states are those of
:mod:`reduced.transient.friction_tables`, and every event is the crossing of a linear function of y.
A free segment is the kept-term closed form of :mod:`reduced.transient._modal`,

    y(tau) = y_p + Re sum_{i<K} U[:, i] w_i e^{lam_i tau},   w = Uinv (y(0) - y_p),

with the sliders' zero eigenvalues among the terms (constants), and its first event is found by the
same march (:func:`reduced.transient._modal._march`), run on the event functions
q_e = E0_e + Re sum_i EU_ei w_i e^{lam_i tau} instead of the stops': its steps skip no root of any.
The dissipated work is :func:`reduced.transient._modal._work` on two quadratic forms, the viscous
v^T C v and the friction power's quadratic part, plus the friction power's linear part, LF . dx.
Forced segments: :func:`_friction_forced_kernel`, on the forced closed form of
:mod:`reduced.transient._exact_kernels` extended to the augmented state.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from reduced.transient._exact_kernels import (
    POLY_DEG,
    SLOW_LT,
    _add_poly,
    _exponentials,
    _ext_setup,
    _ext_work,
    _first_root_forced,
    _moments,
    _piece_at,
    _work_exp,
)
from reduced.transient._modal import (
    BUFFER_FULL,
    EPS,
    NOISE_FACTOR,
    QTOL_REL,
    _eval,
    _march,
    _rows_eval,
    _rows_of_state,
    _stop_scratch,
    _term_scratch,
    _terms,
    _terms_m1,
    _work,
    _work_near,
)
from reduced.transient.friction_tables import KIND_SLIP_END

STUCK_PER_EVENT = 8  # zero-length segments allowed in a row, per event slot, before the run is refused
NEW_STATE = 2  # kernel status (free and forced): the run entered a state whose tables are not built yet


@nb.njit(cache=True)
def _ev_start(s, K, y, Uinv, aUinv, yp, EU, aEU, E0, Escale, eact, lam, alam, floor, w, werr, coef, lc, l2c, a0,
              const, qtol, dnoise, live, dy, ay, gm):
    """Segment start in friction state s: w = Uinv (y - y_p) and its round-off werr, then per active event e
    q_e = const_e + Re sum_i coef_ei e^{lam_i tau} (as :func:`reduced.transient._modal._start` for the stops),
    its round-off band qtol_e (with the cancellation in a . y_p + c, eps Escale_e) and q_e' noise dnoise_e.
    An event whose motion is below ``floor`` (m) over the whole segment (a growing term at its largest,
    ``gm`` times its start) is not live. Returns the number of live events."""
    N = y.shape[0]
    E = E0.shape[1]
    for r in range(N):
        dy[r] = y[r] - yp[s, r]
        ay[r] = abs(y[r]) + abs(yp[s, r])
    for i in range(K):
        acc = 0.0 + 0.0j
        err = 0.0
        for r in range(N):
            acc += Uinv[s, i, r] * dy[r]
            err += aUinv[s, i, r] * ay[r]
        w[i] = acc
        werr[i] = EPS * err
    n_live = 0
    for e in range(E):
        if not eact[s, e]:
            live[e] = False
            continue
        cj = E0[s, e]
        osc = 0.0
        qn = 0.0
        dn = 0.0
        for i in range(K):
            c = EU[s, e, i] * w[i]
            coef[e, i] = c
            lc[e, i] = lam[s, i] * c
            l2c[e, i] = lam[s, i] * lc[e, i]
            a = math.sqrt(c.real * c.real + c.imag * c.imag)
            a0[e, i] = a
            osc += a * gm[i]
            qn += aEU[s, e, i] * werr[i]
            dn += aEU[s, e, i] * alam[s, i] * werr[i]
        const[e] = cj
        qtol[e] = QTOL_REL * (abs(cj) + osc) + NOISE_FACTOR * (qn + EPS * Escale[s, e])
        dnoise[e] = NOISE_FACTOR * dn
        live[e] = not (osc < floor and abs(cj) < floor)
        if live[e]:
            n_live += 1
    return n_live


@nb.njit(cache=True, inline="always")
def _seg_work(s, K, w, em, am1, tau, n, y0, yt, damped, slipping, wv, wf, LF, gr, gi):
    """(viscous, friction) work of the segment over [0, tau] (y0: its start, yt: its state at tau)."""
    Wm, Hd, ip, ii, ik, ikind, icoef, iz = wv
    Fm, Fd, fp, fi, fk, fkind, fcoef, fz = wf
    dW = 0.0
    if damped:
        dW = _work(s, K, w, em, am1, tau, Wm, Hd, gr, gi)
        if ip[s + 1] > ip[s]:
            dW += _work_near(s, w, tau, ip, ii, ik, ikind, icoef, iz)
    dWf = 0.0
    if slipping:
        dWf = _work(s, K, w, em, am1, tau, Fm, Fd, gr, gi)
        if fp[s + 1] > fp[s]:
            dWf += _work_near(s, w, tau, fp, fi, fk, fkind, fcoef, fz)
        for r in range(n):
            dWf += LF[s, r] * (yt[r] - y0[r])
    return dW, dWf


@nb.njit(cache=True, inline="always")
def _switch(s, e, y, n, succ, reset, fric):
    """(state after event e of state s, friction work of the switch), y's sliders updated in place.

    A closing stop starts the sliders it engages unloaded (w = t). A stick -> slip event puts the slider on the
    cone, w = t -+ mu N / kt: the march locates the event to within its step floor, and the slip state
    would keep the small excess |kt (t - w)| - mu N for good (it moves w with t -+ mu N / kt), so that the
    first stick after it would leave the cone at once. Either way the tangential spring's energy released,
    1/2 kt ((t - w_old)^2 - (t - w_new)^2), is friction work (a round-off amount), so the balance stays exact.
    """
    Bt, slider_tip, stop_tip, slider_stop, ekind, stop_of, B, kstop, offset, side, mu, kt = fric
    p = Bt.shape[0]
    m = B.shape[0]
    s_new = succ[s, e]
    dWf = 0.0
    for k in range(p):
        if reset[s, e]:
            if slider_tip[k] != stop_tip[e] or (slider_stop[k] >= 0 and slider_stop[k] != e):
                continue  # not engaged by the stop that closes (slot e < m is stop e)
        elif not ((ekind[s, e] == 1 or ekind[s, e] == 2) and e - m == 2 * k + (ekind[s, e] - 1)):
            continue
        t = 0.0
        for r in range(n):
            t += Bt[k, r] * y[r]
        w_old = y[2 * n + k]
        if reset[s, e]:
            w_new = t
        else:
            j = stop_of[s_new, k]
            sx = 0.0
            for r in range(n):
                sx += B[j, r] * y[r]
            N = kstop[j] * side[j] * (sx - offset[j])
            sigma = 1.0 if ekind[s, e] == 1 else -1.0
            w_new = t - sigma * mu[k] * N / kt[k]
        dWf += 0.5 * kt[k] * ((t - w_old) * (t - w_old) - (t - w_new) * (t - w_new))
        y[2 * n + k] = w_new
    return s_new, dWf


@nb.njit(cache=True, inline="always")
def _first_sign(d1, d2, d3, b1, b2, b3):
    """The sign of the first of q', q'', q''' beyond its round-off band (b1, b2, b3); 0 if none is."""
    if abs(d1) > b1:
        return 1 if d1 > 0.0 else -1
    if abs(d2) > b2:
        return 1 if d2 > 0.0 else -1
    if abs(d3) > b3:
        return 1 if d3 > 0.0 else -1
    return 0


@nb.njit(cache=True, inline="always")
def _ev_trend(s, K, j, coef, lam, alam, a0, aEU, werr, e):
    """Where event j of a free segment heads at tau (e = e^{lam tau}): the sign of its first derivative
    beyond round-off (:func:`_first_sign`), the band of the k-th as the march's of q' times |lam|^(k - 1)
    (QTOL_REL x the terms' size plus NOISE_FACTOR x sum |EU| |lam|^k werr, the modal coordinates' round-off)."""
    d1 = 0.0
    d2 = 0.0
    d3 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    for i in range(K):
        c1 = lam[s, i] * coef[j, i] * e[i]
        c2 = lam[s, i] * c1
        d1 += c1.real
        d2 += c2.real
        d3 += (lam[s, i] * c2).real
        al = alam[s, i]
        b = (QTOL_REL * a0[j, i] * abs(e[i]) + NOISE_FACTOR * aEU[s, j, i] * werr[i]) * al
        b1 += b
        b2 += b * al
        b3 += b * al * al
    return _first_sign(d1, d2, d3, b1, b2, b3)


@nb.njit(cache=True, inline="always")
def _pin(j, K, const, coef, qtol):
    """Hold event j at the start of a segment: its constant lowered so that q(0) <= -2 qtol (module docstring
    of :mod:`reduced.transient.friction_tables`, the consistency of a slider's switch)."""
    q0 = const[j]
    for i in range(K):
        q0 += coef[j, i].real
    if q0 > -2.0 * qtol[j]:
        const[j] -= q0 + 2.0 * qtol[j]


@nb.njit(cache=True, inline="always")
def _log(n_log, t, e, s, y, log_t, log_e, log_s, log_y):
    """Record an event (time, slot, new state, state y) while the log has room; returns the count."""
    if n_log < log_t.shape[0]:
        log_t[n_log] = t
        log_e[n_log] = e
        log_s[n_log] = s
        for r in range(y.shape[0]):
            log_y[n_log, r] = y[r]
    return n_log + 1


@nb.njit(cache=True)
def _friction_free_kernel(modal, events, wv, wf, fric, damped, n, y, s, t, bounds, c, t_samples, i_samp, t_after,
                          out_y, out_W, out_Wf, W, Wf, hmin, floor, max_events, n_stuck, log_t, log_e, log_s, log_y,
                          n_log, built, carry, fs, acq):
    """March events from t through the pieces ending at bounds[c], bounds[c + 1], ... (no loads), filling the
    sample buffer ``t_samples`` from i_samp (:func:`reduced.transient._modal._free_kernel` with friction).

    (y, s, t, W, Wf) is the state at the start of a segment and is advanced segment by segment: y the
    augmented state, s the friction state, W the viscous and Wf the friction work. ``out_W`` receives
    W + Wf (all the dissipated work), ``out_Wf`` Wf. When the buffer fills inside a segment that still has
    samples before its end, the kernel returns BUFFER_FULL without advancing it (the samples do not
    depend on the buffer size). Events are logged (time, slot, new state, y) while the log has room.
    ``fric`` holds the sliders' data for the switch (:func:`_switch`). A segment no longer than the march's
    floor counts as one without progress (``n_stuck``). A state with growing terms (flutter) is solved in
    segments of at most hseg[s] = ln 2 / max Re(lam), the closed form restarted at their ends, and its growing
    terms bounded by their size there, gmul[s] (:func:`reduced.transient._modal._march`). Returns (t, W, Wf,
    s, i_samp, n_events, n_iter, status, n_stuck, c, n_log).

    A slider that would switch back at the instant it switched is decided by the consistency of its two
    states (the module docstring of :mod:`reduced.transient.friction_tables`): the consistent one is kept and
    its slot pinned below its round-off band for the segment (:func:`_pin`), never toggled.

    The tables are built state by state as a run enters them (:class:`reduced.transient.friction_tables.
    LazyFrictionTables`): a segment that starts in a state with built[s] False returns NEW_STATE before it
    is searched, (y, s, t) at its start and the loop's memory of the last switch (the slot that held, the
    last event's slot, the fresh slider, the state before it, the trend) in ``carry`` (int64 (5,)), read
    back on entry, so that the run resumes where it stopped as if it had not.

    With output rows (``acq`` = (every, R, RT, Ryp, Es, have, out_z, zt), every > 0; :func:`reduced.transient.
    _modal._free_kernel_rows`; the samples at t_j = j / ``fs``), every sample's R y goes to out_z, and the whole
    state and the work to out_y, out_W, out_Wf only at the samples j that are multiples of ``every`` (the same bits
    as without rows; the others' entries are left as they are). A sample between those needs its terms e^{lam tau}
    alone: stepped from the sample before in the segment, e^{lam (tau + 1/fs)} = e^{lam tau} e^{lam / fs}
    (Es[s] = e^{lam / fs}, worked out with RT[s], Ryp[s] the first time a sample of state s needs them), afresh
    at the segment's first sample. ``acq`` = :func:`reduced.transient._modal.no_rows`: every sample whole.

    Long because it is the free kernel's loop with the friction work, the event switch, the consistency
    decision and the hold of a slider slot that fired twice in a row inlined, so that its arithmetic per
    segment reads in one place.
    """
    nK, lam, alam, UT, Uinv, aUinv, yp, gmul, hseg = modal
    EU, aEU, E0, Escale, eact, succ, reset, has_slip, LF = events
    N = y.shape[0]
    E = E0.shape[1]
    Kmax = lam.shape[1]
    ns = t_samples.shape[0]
    w, werr, e, ea, em, am1, gr, gi = _term_scratch(Kmax)
    coef, lc, l2c, a0, const, qtol, dnoise, live, hprev, hnext, P = _stop_scratch(E, Kmax)
    ytmp = np.empty(N)
    dy = np.empty(N)
    ay = np.empty(N)
    every, R, RT, Ryp, Es, have, out_z, zt = acq
    n_events = 0
    n_iter = 0
    status = 0
    t_end = bounds[c]
    m = fric[6].shape[0]  # the stops: slots e >= m are the sliders'
    hold = carry[0]  # a slider slot that may not fire within its round-off band in this segment (see below)
    e_prev = carry[1]  # the slot of the last event
    ekind = fric[4]
    fresh = carry[2]  # the slider slot of the event that started this segment (-1: none)
    s_from = carry[3]  # the state before it
    trend = carry[4]  # a stick -> slip event's cone function: the sign of its first derivative beyond round-off
    pin = -1  # a slider slot held at this segment's start (_pin), once its switch is found consistent
    while True:
        if not built[s]:  # only right after a switch (pin is -1 then): resumed here once s is built
            carry[0], carry[1], carry[2], carry[3], carry[4] = hold, e_prev, fresh, s_from, trend
            status = NEW_STATE
            break
        K = nK[s]
        slipping = has_slip[s]
        n_live = _ev_start(s, K, y, Uinv, aUinv, yp, EU, aEU, E0, Escale, eact, lam, alam, floor, w, werr, coef, lc,
                           l2c, a0, const, qtol, dnoise, live, dy, ay, gmul[s])
        if hold >= 0 and live[hold]:
            # a slider's slot fired twice in a row (a slip end, then at once the stick -> slip the same way, or
            # back): at a grazing slip end (w' and w'' both near 0) the two bands of one decision disagree and
            # the pair would repeat without end. The slot fires again only once it is past its band, q > 2 qtol:
            # a round-off delay of a decision the flow then makes consistently (no energy is lost: the switch
            # books the spring's change as friction work)
            const[hold] -= 2.0 * qtol[hold]
        if pin >= 0 and live[pin]:
            _pin(pin, K, const, coef, qtol)
        tau_lim = t_end - t
        capped = hseg[s] < tau_lim  # a growing state's segment ends where its terms have doubled at most
        if capped:
            tau_lim = hseg[s]
        tau_ev, e_ev, it = _march(s, K, lam, alam, const, coef, lc, l2c, a0, qtol, dnoise, live, n_live, tau_lim,
                                  hmin, e, ea, hprev, hnext, P, gmul[s])
        if e_ev == -2:
            status = -3
            break
        if e_ev == fresh and tau_ev <= hmin and pin < 0:
            # the slider that has just switched would switch back at once. In exact arithmetic its slot starts
            # at 0 in the new state, not rising: after a slip end the stick state's cone function has q = 0,
            # q' = the slip velocity = 0 and q'' = the slip velocity's rate < 0 (the slip end's own crossing),
            # so stick is consistent; after a stick -> slip the slip end's q = -sigma w' / omega_ref =
            # -(cone function)' / omega_ref, so slip is consistent if the cone function rose (trend > 0). The
            # re-expansion of y in the new state's modes errs by ~cond(V) eps, far above the march's band at
            # its start, so the march may see the slot rising there. The consistent state is kept (or the
            # stick restored, the slider left on the cone: a slip that would end at once is a graze of the
            # cone) and its slot pinned below its band for this segment; never toggled.
            n_iter += it
            if ekind[s_from, fresh] != KIND_SLIP_END and trend <= 0:
                s = s_from
                n_log -= 1  # not an event: its log entry (if kept) is overwritten
                n_events -= 1
            pin = fresh
            continue
        pin = -1
        fresh = -1
        t_next = (t + tau_lim if capped else t_end) if e_ev < 0 else t + tau_ev
        stepped = False  # e holds the terms of the sample before, in this segment
        while i_samp < ns and t_samples[i_samp] <= t_next:
            tau = max(t_samples[i_samp] - t, 0.0)
            if every > 0 and not have[s]:
                _rows_of_state(s, K, UT, yp, R, RT, Ryp)
                for i in range(K):  # e^{lam / fs}
                    a = math.exp(lam[s, i].real / fs)
                    b = lam[s, i].imag / fs
                    Es[s, i] = complex(a * math.cos(b), a * math.sin(b))
                have[s] = True
            if every == 0 or round(t_samples[i_samp] * fs) % every == 0:
                _terms_m1(lam[s], K, tau, e, em, am1)
                _eval(s, K, UT, yp, w, e, ytmp)
                dW, dWf = _seg_work(s, K, w, em, am1, tau, n, y, ytmp, damped, slipping, wv, wf, LF, gr, gi)
                out_W[i_samp] = (W + dW) + (Wf + dWf)
                out_Wf[i_samp] = Wf + dWf
                for r in range(N):
                    out_y[i_samp, r] = ytmp[r]
            elif stepped:
                for i in range(K):
                    e[i] = e[i] * Es[s, i]
            else:
                _terms(lam[s], K, tau, e, ea)
            if every > 0:
                _rows_eval(s, K, RT, Ryp, w, e, zt, out_z, i_samp)
            stepped = True
            i_samp += 1
        if i_samp == ns and t_after <= t_next:
            status = BUFFER_FULL
            break
        n_iter += it
        _terms_m1(lam[s], K, tau_ev, e, em, am1)
        if e_ev >= m:
            trend = _ev_trend(s, K, e_ev, coef, lam, alam, a0, aEU, werr, e)
        _eval(s, K, UT, yp, w, e, ytmp)
        dW, dWf = _seg_work(s, K, w, em, am1, tau_ev, n, y, ytmp, damped, slipping, wv, wf, LF, gr, gi)
        W += dW
        Wf += dWf
        for r in range(N):
            y[r] = ytmp[r]
        n_stuck = n_stuck + 1 if tau_ev <= hmin else 0
        if n_stuck > STUCK_PER_EVENT * E:
            status = -4
            break
        t = t_next
        if e_ev < 0 and capped:
            n_stuck = 0
            continue  # the closed form restarts in the same state
        if e_ev < 0:
            c += 1
            n_stuck = 0
            if c == bounds.shape[0]:
                break
            t_end = bounds[c]
            continue
        s_from = s
        s, dWf = _switch(s, e_ev, y, n, succ, reset, fric)
        Wf += dWf
        hold = e_ev if (e_ev == e_prev and e_ev >= m) else -1
        e_prev = e_ev
        fresh = e_ev if e_ev >= m else -1
        n_log = _log(n_log, t, e_ev, s, y, log_t, log_e, log_s, log_y)
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, Wf, s, i_samp, n_events, n_iter, status, n_stuck, c, n_log


@nb.njit(cache=True)
def _aug_segment(s, sigma, ip, tau_lim, y, yp_s, lam_s, V, Vinv, fz, fY, fU, pF, pp0, pp1, X, z, P, Fs, phi, gam,
                 werr, ypart):
    """:func:`reduced.transient._exact_kernels._forced_segment` on the augmented state (N = len(y) rows,
    the sliders' zero eigenvalues among the modes: slow, their Taylor series a constant, since the loads
    have no component on them). Fills X, z, P, Fs, phi, werr; returns whether there is a polynomial part."""
    N = y.shape[0]
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
        err = 0.0
        for r in range(N):
            wi += Vinv[i, r] * (y[r] - yp_s[r] - ypart[r])
            err += abs(Vinv[i, r]) * (abs(y[r]) + abs(yp_s[r]) + abs(ypart[r]))
        werr[i] = EPS * err
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
                X[r, i] = V[r, i] * (wi - c)
    return poly


@nb.njit(cache=True)
def _quad_setup(X, D, z, G, Gz, az, DX):
    """For int y_h^T D y_h with y_h = Re sum_k X[:, k] e^{z_k t}: G[i, k] = X_i^T D X_k (i <= k),
    Gz = G / (z_i + z_k), az = |z_i + z_k| (:func:`reduced.transient._exact_kernels._work_exp` reads them)."""
    N = X.shape[0]
    Kt = X.shape[1]
    for a in range(N):
        for k in range(Kt):
            acc = 0.0 + 0.0j
            for b in range(N):
                if D[a, b] != 0.0:
                    acc += D[a, b] * X[b, k]
            DX[a, k] = acc
    for i in range(Kt):
        for k in range(i, Kt):
            acc = 0.0 + 0.0j
            for a in range(N):
                acc += X[a, i] * DX[a, k]
            G[i, k] = acc
            zz = z[i] + z[k]
            az[i, k] = abs(zz)
            Gz[i, k] = acc / zz if zz != 0.0 else 0.0


@nb.njit(cache=True)
def _quad_poly_setup(DX, P, D, ACp, Cpp):
    """ACp[k, m] = X_k^T D p_m, Cpp[m, m'] = p_m^T D p_m' (p_m = P[m]) for the polynomial part of the form."""
    N = P.shape[1]
    M1 = P.shape[0]
    for k in range(DX.shape[1]):
        for m in range(M1):
            acc = 0.0 + 0.0j
            for a in range(N):
                acc += DX[a, k] * P[m, a]
            ACp[k, m] = acc
    for m in range(M1):
        for m2 in range(M1):
            acc2 = 0.0
            for a in range(N):
                for b in range(N):
                    if D[a, b] != 0.0:
                        acc2 += P[m, a] * D[a, b] * P[m2, b]
            Cpp[m, m2] = acc2


@nb.njit(cache=True)
def _quad_poly_work(ACp, Cpp, MOM, tau):
    """int (2 y_E^T D y_P + y_P^T D y_P) dt over [0, tau] from the moments MOM[k, m] = int t^m e^{z_k t} dt."""
    acc = 0.0 + 0.0j
    for k in range(ACp.shape[0]):
        for m in range(ACp.shape[1]):
            if ACp[k, m] != 0.0:
                acc += ACp[k, m] * MOM[k, m]
    W = 2.0 * acc.real
    M1 = Cpp.shape[0]
    for m in range(M1):
        for m2 in range(M1):
            if Cpp[m, m2] != 0.0:
                W += Cpp[m, m2] * tau ** (m + m2 + 1) / (m + m2 + 1)
    return W


@nb.njit(cache=True)
def _aug_arrays(N, L):
    """Scratch of a forced segment on the augmented state: X (N, Kt), z, coef (Kt,), werr, ytmp, ypart (N,),
    P (POLY_DEG + 1, N), Qp, Fs (L,), phi (L, POLY_DEG + 1), gam; Kt = N + 2L."""
    Kt = N + 2 * L
    M1 = POLY_DEG + 1
    return (np.empty((N, Kt), np.complex128), np.zeros(Kt, np.complex128), np.empty(Kt, np.complex128),
            np.empty(N), np.empty(N), np.zeros(N), np.zeros((M1, N)), np.zeros(M1), np.zeros(L, np.complex128),
            np.zeros((L, M1)), np.zeros(M1, np.complex128))


@nb.njit(cache=True)
def _aug_work_arrays(N, L):
    """Scratch of the work integrals (:func:`reduced.transient._exact_kernels._work_arrays`, Kt = N + 2L), and
    the friction form's G, Gz, az, DX, ACp, Cpp."""
    Kt = N + 2 * L
    M1 = POLY_DEG + 1
    return (np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt)),
            np.empty(Kt, np.complex128), np.zeros((Kt, M1), np.complex128), np.zeros((M1, M1)), np.zeros((M1, L)),
            np.zeros((Kt, M1), np.complex128), np.zeros((Kt, L), np.complex128), np.zeros((Kt, L), np.complex128),
            np.zeros((Kt, L), np.complex128), np.empty(L, np.complex128),
            np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt), np.complex128), np.zeros((Kt, Kt)),
            np.zeros((N, Kt), np.complex128), np.zeros((Kt, M1), np.complex128), np.zeros((M1, M1)))


@nb.njit(cache=True)
def _aug_work_setup(X, C, z, n, G, Gz, az):
    """The viscous form's G, Gz, az (v^T C v, the velocity rows n .. 2n - 1 of X)."""
    Kt = X.shape[1]
    CX = np.zeros((n, Kt), np.complex128)
    for a in range(n):
        for b in range(n):
            if C[a, b] != 0.0:
                for k in range(Kt):
                    CX[a, k] += C[a, b] * X[n + b, k]
    for i in range(Kt):
        for k in range(i, Kt):
            acc = 0.0 + 0.0j
            for a in range(n):
                acc += X[n + a, i] * CX[a, k]
            G[i, k] = acc
            zz = z[i] + z[k]
            az[i, k] = abs(zz)
            Gz[i, k] = acc / zz if zz != 0.0 else 0.0


@nb.njit(cache=True)
def _aug_state(tau, yp_s, X, z, P, poly, damped, G, Gz, az, ACp, Cpp, Pb, beta, rp, rm, phi, Fs, fz, MOM, e, eiw,
               ytmp, C, n):
    """The augmented segment's state at tau into ytmp, and (dW viscous, dE loads) over [0, tau]
    (:func:`reduced.transient._exact_kernels._segment_state` with the moments always filled when there is a
    polynomial part: the friction work reads them)."""
    N = ytmp.shape[0]
    _exponentials(z, tau, e)
    for r in range(N):
        acc = 0.0
        for i in range(z.shape[0]):
            acc += (X[r, i] * e[i]).real
        ytmp[r] = yp_s[r] + acc
    Wp = 0.0
    Ep = 0.0
    if poly:
        _add_poly(P, tau, N, ytmp)
        for k in range(z.shape[0]):
            _moments(z[k], tau, MOM[k])
        Wp, Ep = _aug_poly_work(ACp, Cpp, Pb, beta, phi, Fs, z, tau, MOM, damped, N)
    dE = _ext_work(beta, z, e, fz, Fs, tau, eiw, rp, rm) + Ep
    dW = (_work_exp(G, Gz, az, z, tau, e) if damped else 0.0) + Wp
    return dW, dE


@nb.njit(cache=True)
def _aug_poly_work(ACp, Cpp, Pb, beta, phi, Fs, z, tau, MOM, damped_, N):
    """:func:`reduced.transient._exact_kernels._poly_work` with the moments MOM already filled."""
    K = z.shape[0]
    M1 = Cpp.shape[0]
    L = Pb.shape[1]
    W = 0.0
    if damped_:
        W = _quad_poly_work(ACp, Cpp, MOM, tau)
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
def _aug_viscous_poly_setup(X, P, C, fb, n, damped_, ACp, Cpp, Pb):
    """ACp[k, m] = a_k^T C p_m, Cpp = p_m^T C p_m' (velocity parts), Pb[m, l] = p_m^T b_l
    (:func:`reduced.transient._exact_kernels._poly_setup`)."""
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
def _aug_next_event(erow, ec, eact, s, yp_s, V_s, X, z, werr, poly, P, Qp, coef, tau_max, hmin, floor, pin):
    """The first event of a forced segment in state s (each active event's march,
    :func:`reduced.transient._exact_kernels._first_root_forced`): (tau, e, n_iter, status). Event ``pin``
    (-1: none) is held at the start, its constant lowered so that q(0) <= -2 qtol (:func:`_pin`)."""
    N = X.shape[0]
    E = ec.shape[1]
    tau_ev = tau_max
    e_ev = -1
    n_iter = 0
    for e in range(E):
        if not eact[s, e]:
            continue
        const = ec[s, e]
        scale = abs(ec[s, e])
        for r in range(N):
            const += erow[s, e, r] * yp_s[r]
            scale += abs(erow[s, e, r]) * abs(yp_s[r])
        for i in range(X.shape[1]):
            acc = 0.0 + 0.0j
            for r in range(N):
                acc += erow[s, e, r] * X[r, i]
            coef[i] = acc
        qnoise = EPS * scale
        dnoise = 0.0
        for i in range(N):
            pv = 0.0 + 0.0j
            for r in range(N):
                pv += erow[s, e, r] * V_s[r, i]
            qnoise += abs(pv) * werr[i]
            dnoise += abs(pv) * abs(z[i]) * werr[i]
        if poly:
            for m in range(P.shape[0]):
                acc2 = 0.0
                for r in range(N):
                    acc2 += erow[s, e, r] * P[m, r]
                Qp[m] = acc2
        if e == pin:
            q0 = const + (Qp[0] if poly else 0.0)
            osc = abs(Qp[0]) if poly else 0.0
            for i in range(X.shape[1]):
                q0 += coef[i].real
                osc += abs(coef[i])
            qt = QTOL_REL * (abs(const) + osc) + NOISE_FACTOR * qnoise  # the march's band at tau = 0
            if q0 > -2.0 * qt:
                const -= q0 + 2.0 * qt
        tj, it = _first_root_forced(const, coef, z, Qp, poly, tau_ev, hmin, qnoise, dnoise, floor, True)
        n_iter += it
        if tj < 0.0:
            return tau_ev, e_ev, n_iter, -3
        if tj < tau_ev:
            tau_ev = tj
            e_ev = e
    return tau_ev, e_ev, n_iter, 0


@nb.njit(cache=True)
def _aug_trend(erow, s, j, V_s, X, z, werr, poly, P, tau):
    """:func:`_ev_trend` for event j of a forced segment at tau: q = erow_j . (Re sum X_i e^{z_i tau} + sum_m
    P[m] tau^m) (+ constants), its bands those of the march's q' (QTOL_REL x the terms' size, NOISE_FACTOR x
    the modal coordinates' round-off) times |z|^(k - 1)."""
    N = X.shape[0]
    d1 = 0.0
    d2 = 0.0
    d3 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    for i in range(X.shape[1]):
        c = 0.0 + 0.0j
        for r in range(N):
            c += erow[s, j, r] * X[r, i]
        c = c * np.exp(z[i] * tau)
        c1 = z[i] * c
        c2 = z[i] * c1
        d1 += c1.real
        d2 += c2.real
        d3 += (z[i] * c2).real
        az = abs(z[i])
        b = QTOL_REL * abs(c) * az
        if i < N:
            pv = 0.0 + 0.0j
            for r in range(N):
                pv += erow[s, j, r] * V_s[r, i]
            b += NOISE_FACTOR * abs(pv) * werr[i] * az
        b1 += b
        b2 += b * az
        b3 += b * az * az
    if poly:
        M1 = P.shape[0]
        for m in range(1, M1):
            qm = 0.0
            for r in range(N):
                qm += erow[s, j, r] * P[m, r]
            d1 += m * qm * tau ** (m - 1)
            if m >= 2:
                d2 += m * (m - 1) * qm * tau ** (m - 2)
            if m >= 3:
                d3 += m * (m - 1) * (m - 2) * qm * tau ** (m - 3)
    return _first_sign(d1, d2, d3, b1, b2, b3)


@nb.njit(cache=True)
def _friction_forced_kernel(lam, V, Vinv, yp, erow, ec, eact, succ, reset, Df, LF, has_slip, hseg, C, damped, n, fric,
                            y, s, t, t_end, t_samples, i_samp, t_after, out_y, out_W, out_Wf, W, Wf, hmin, floor,
                            max_events, n_stuck, fz, fY, fU, fb, pstarts, pF, pp0, pp1, out_E, E, log_t, log_e, log_s,
                            log_y, n_log, built, carry):
    """March events from t to t_end under the loads (:func:`reduced.transient._exact_kernels._forced_kernel` on
    the augmented state y = [x; v; w] and its friction states): the forced closed form of each segment, its
    first event among the state's (gap, stick -> slip, slip -> stick), the viscous, friction and loads' work
    in closed form (the friction power's quadratic part by its form Df[s] with the moments of the polynomial
    part, its linear part LF[s] . dx). A growing state's segment ends at hseg[s] at most (the free kernel's
    rule) and its march bounds the growing terms by their size there. Returns (t, W, Wf, E, s, i_samp,
    n_events, n_iter, status, n_stuck, n_log); the buffer logic and the states built as the run enters them
    (NEW_STATE, ``built``, ``carry``) are those of the free kernel.

    Long because it is the forced kernel's loop with the friction work and the event switch inlined, so
    that its arithmetic per segment reads in one place."""
    N = y.shape[0]
    L = fb.shape[0]
    E_slots = ec.shape[1]
    ns = t_samples.shape[0]
    X, z, coef, werr, ytmp, ypart, P, Qp, Fs, phi, gam = _aug_arrays(N, L)
    (G, Gz, az, e, ACp, Cpp, Pb, MOM, beta, rp, rm, eiw, Gf, Gzf, azf, DX, ACf, Cpf) = _aug_work_arrays(N, L)
    ip = max(np.searchsorted(pstarts, t, side="right") - 1, 0)
    n_events = 0
    n_iter = 0
    status = 0
    ekind = fric[4]
    m = fric[6].shape[0]  # the stops: slots e >= m are the sliders'
    fresh = carry[2]  # as in the free kernel: the slider slot of the event that started this segment
    s_from = carry[3]
    trend = carry[4]
    pin = -1
    while True:
        if not built[s]:
            carry[2], carry[3], carry[4] = fresh, s_from, trend
            status = NEW_STATE
            break
        slipping = has_slip[s]
        ip, t_lim = _piece_at(pstarts, ip, t, t_end)
        t_lim = min(t_lim, t + hseg[s])  # a growing state: at most a doubling of its terms a segment
        poly = _aug_segment(s, t - pstarts[ip], ip, t_lim - t, y, yp[s], lam[s], V[s], Vinv[s], fz, fY, fU, pF, pp0,
                            pp1, X, z, P, Fs, phi, gam, werr, ypart)
        if damped:
            _aug_work_setup(X, C, z, n, G, Gz, az)
        _ext_setup(X, z, fb, fz, n, beta, rp, rm)
        if poly:
            _aug_viscous_poly_setup(X, P, C, fb, n, damped, ACp, Cpp, Pb)
        if slipping:
            _quad_setup(X, Df[s], z, Gf, Gzf, azf, DX)
            if poly:
                _quad_poly_setup(DX, P, Df[s], ACf, Cpf)
        tau_ev, e_ev, seg_iter, status = _aug_next_event(erow, ec, eact, s, yp[s], V[s], X, z, werr, poly, P, Qp,
                                                         coef, t_lim - t, hmin, floor, pin)
        if status != 0:
            break
        if e_ev == fresh and tau_ev <= hmin and pin < 0:
            # the slider that has just switched would switch back at once: the free kernel's decision
            n_iter += seg_iter
            if ekind[s_from, fresh] != KIND_SLIP_END and trend <= 0:
                s = s_from
                n_log -= 1
                n_events -= 1
            pin = fresh
            continue
        pin = -1
        fresh = -1
        t_next = t_lim if e_ev < 0 else t + tau_ev
        while i_samp < ns and t_samples[i_samp] <= t_next:
            tau = max(t_samples[i_samp] - t, 0.0)
            dW, dE = _aug_state(tau, yp[s], X, z, P, poly, damped, G, Gz, az, ACp, Cpp, Pb, beta, rp, rm, phi, Fs,
                                fz, MOM, e, eiw, ytmp, C, n)
            dWf = 0.0
            if slipping:
                dWf = _work_exp(Gf, Gzf, azf, z, tau, e) + (_quad_poly_work(ACf, Cpf, MOM, tau) if poly else 0.0)
                for r in range(n):
                    dWf += LF[s, r] * (ytmp[r] - y[r])
            out_E[i_samp] = E + dE
            out_W[i_samp] = (W + dW) + (Wf + dWf)
            out_Wf[i_samp] = Wf + dWf
            for r in range(N):
                out_y[i_samp, r] = ytmp[r]
            i_samp += 1
        if i_samp == ns and t_after <= t_next:
            status = BUFFER_FULL
            break
        n_iter += seg_iter
        if e_ev >= m:
            trend = _aug_trend(erow, s, e_ev, V[s], X, z, werr, poly, P, tau_ev)
        dW, dE = _aug_state(tau_ev, yp[s], X, z, P, poly, damped, G, Gz, az, ACp, Cpp, Pb, beta, rp, rm, phi, Fs, fz,
                            MOM, e, eiw, ytmp, C, n)
        if slipping:
            Wf += _work_exp(Gf, Gzf, azf, z, tau_ev, e) + (_quad_poly_work(ACf, Cpf, MOM, tau_ev) if poly else 0.0)
            for r in range(n):
                Wf += LF[s, r] * (ytmp[r] - y[r])
        E += dE
        W += dW
        for r in range(N):
            y[r] = ytmp[r]
        n_stuck = n_stuck + 1 if tau_ev <= hmin else 0
        if n_stuck > STUCK_PER_EVENT * E_slots:
            status = -4
            break
        t = t_next
        if e_ev < 0:
            if t_lim < t_end:
                continue
            break
        s_from = s
        s, dWf = _switch(s, e_ev, y, n, succ, reset, fric)
        Wf += dWf
        fresh = e_ev if e_ev >= m else -1
        n_log = _log(n_log, t, e_ev, s, y, log_t, log_e, log_s, log_y)
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, Wf, E, s, i_samp, n_events, n_iter, status, n_stuck, n_log


# -- central difference with friction (reduced.transient.friction.FrictionExplicitStepper) ---------------------
@nb.njit(cache=True, inline="always")
def _return_map(x, f, side, stop_tip, slider_tip, slider_stop, Bt, mu, kt, w, ft, Wf):
    """The sliders' forces ft and positions w at x by the return mapping (:func:`_cd_friction_kernel`), f the
    stops' forces; returns Wf plus the step's friction work (trapezoidal on f w')."""
    n = x.shape[0]
    for q in range(Bt.shape[0]):
        N = 0.0
        for j in range(f.shape[0]):
            if stop_tip[j] == slider_tip[q] and (slider_stop[q] < 0 or slider_stop[q] == j) and f[j] != 0.0:
                N = side[j] * f[j]
        t = 0.0
        for c in range(n):
            t += Bt[q, c] * x[c]
        ftr = kt[q] * (t - w[q])
        cap = mu[q] * N
        f_old = ft[q]
        if abs(ftr) <= cap:
            ft[q] = ftr
        else:
            ft[q] = cap if ftr > 0.0 else -cap
            w_new = t - ft[q] / kt[q]
            Wf += 0.5 * (f_old + ft[q]) * (w_new - w[q])
            w[q] = w_new
    return Wf


@nb.njit(cache=True)
def _cd_friction_kernel(AT, dtGKT, dtGBT, LT, B, offset, side, k, dtGBtT, Bt, slider_tip, stop_tip, slider_stop, mu,
                        kt, x, vh, w, ft, dt, n_steps, every, out_x, out_v, out_W, out_w, out_Wf, W, pw_old, Wf, i0,
                        dtGbT, b, P, out_E, E, pe_old):
    """Advance n_steps of :func:`reduced.transient.explicit._cd_kernel` with the sliders' forces Bt^T f_t in the
    velocity update, f_t by the return mapping at x_{n+1} (w = w_n on entry, w_{n+1} on exit):

        N = k_j max(0, side_j (B_j x_{n+1} - o_j))   (the closed stop j that engages the slider; 0 if none),
        f_trial = kt (Bt x_{n+1} - w_n),
        f = f_trial, w_{n+1} = w_n                      if |f_trial| <= mu N (stick),
        f = sign(f_trial) mu N, w_{n+1} = t - f / kt    otherwise (slip; an open tip: f = 0, w = t).

    The friction work of a step is the trapezoidal rule on f w': (f_n + f_{n+1}) / 2 (w_{n+1} - w_n), second
    order through a smooth slip (``ft`` holds f_n on entry, f_{n+1} on exit). The return mapping itself takes
    kt (w_{n+1} - w_n)^2 / 2 more out of the tangential spring a slipping step (it is backward Euler on the
    slider), which the energy balance shows as the scheme's error. Stores x, the mean velocity, W + Wf, the
    sliders and Wf every ``every`` steps. Returns (W, pw_old, Wf, i, E, pe_old)."""
    n = x.shape[0]
    m = B.shape[0]
    p = Bt.shape[0]
    r = LT.shape[0]
    nl = b.shape[0]
    f = np.empty(m)
    acc = np.empty(n)
    v_int = np.empty(n)
    io = i0
    left = every
    for step in range(1, n_steps + 1):
        for i in range(n):
            x[i] += dt * vh[i]
        for j in range(m):
            s = -offset[j]
            for c in range(n):
                s += B[j, c] * x[c]
            f[j] = k[j] * s if side[j] * s > 0.0 else 0.0
        Wf = _return_map(x, f, side, stop_tip, slider_tip, slider_stop, Bt, mu, kt, w, ft, Wf)
        for i in range(n):
            acc[i] = 0.0
        for c in range(n):
            vc = vh[c]
            xc = x[c]
            for i in range(n):
                acc[i] += AT[c, i] * vc - dtGKT[c, i] * xc
        for j in range(m):
            fj = f[j]
            if fj != 0.0:
                for i in range(n):
                    acc[i] -= dtGBT[j, i] * fj
        for q in range(p):
            fq = ft[q]
            if fq != 0.0:
                for i in range(n):
                    acc[i] -= dtGBtT[q, i] * fq
        for q in range(nl):
            pq = P[step - 1, q]
            for i in range(n):
                acc[i] += dtGbT[q, i] * pq
        for i in range(n):
            v_int[i] = 0.5 * (vh[i] + acc[i])
            vh[i] = acc[i]
        pw_new = 0.0
        for q in range(r):
            s = 0.0
            for i in range(n):
                s += LT[q, i] * v_int[i]
            pw_new += s * s
        W += 0.5 * dt * (pw_old + pw_new)
        pw_old = pw_new
        if nl:
            pe_new = 0.0
            for q in range(nl):
                s = 0.0
                for i in range(n):
                    s += b[q, i] * v_int[i]
                pe_new += s * P[step - 1, q]
            E += 0.5 * dt * (pe_old + pe_new)
            pe_old = pe_new
        left -= 1
        if left == 0:
            left = every
            for i in range(n):
                out_x[io, i] = x[i]
                out_v[io, i] = v_int[i]
            for q in range(p):
                out_w[io, q] = w[q]
            out_W[io] = W + Wf
            out_Wf[io] = Wf
            if nl:
                out_E[io] = E
            io += 1
    return W, pw_old, Wf, io, E, pe_old
