"""Private numba kernels of the exact integrator's free segments, in conjugate-pair modal form.

In contact state s a free segment is (:mod:`reduced.transient.exact`)

    y(tau) = y_p + Re sum_{i<K} U[:, i] w_i e^{lam_i tau},   w = Uinv (y(0) - y_p),

with K kept terms: one eigenvalue of each conjugate pair (Im lam > 0) with its eigenvector
doubled, and each real eigenvalue once (:func:`reduced.transient.exact.modal_table`). For a
real y this is the 2n-term sum V diag(e^{lam tau}) V^-1 (y(0) - y_p) exactly, so a state, a
stop function or the dissipated work costs K <= n exponentials instead of 2n.

The next crossing is found by one march for all stops at once (the exponentials are shared):
from tau_a the march steps by the smallest of the stops' safe steps, each the largest h with

    q_j(tau_a) + q_j'(tau_a) h + 1/2 Q2_j h^2 < 0,   Q2_j = sum_i |c_ji| |lam_i|^2 e^{Re(lam_i) tau_a},

Q2_j >= |q_j''| on [tau_a, inf) as Re(lam) <= 0, or the largest h of the same bound with the
fast terms (|lam_i| h > ``FAST_LT``, the last ones: terms are sorted by |lam|) bounded by their
amplitude instead, sum_fast (|c_ji| e^{Re(lam_i) tau_a} - Re(c_ji e^{lam_i tau_a})) added to
q_j and their share taken out of q_j' and Q2_j, or the largest h of the cubic bound
q + q' h + q'' h^2 / 2 + Q3 h^3 / 6 (q'' exact, Q3 = sum_i |c_ji| |lam_i|^3 e^{Re(lam_i) tau_a} >= |q'''|,
:func:`_cubic_step`), with or without the fast terms: each bound holds for every h >= 0, so the
step skips no root of any stop. A stop whose amplitude bound const_j + sum_i |c_ji|
e^{Re(lam_i) tau_a} stays below its round-off band can never cross in the segment and leaves
the march. Near a crossing the step tends to the Newton step; the crossing is taken where q is
within its round-off band (the decision rules of the single-stop march), or at the root of the
Taylor quadratic once the cubic remainder Q3 x^3 is within that band (:func:`_march`).

**Growing terms** (Re lam_i > 0: a slip state of a system with friction may flutter,
:mod:`reduced.transient.friction_tables`): |c_ji e^{lam_i tau}| grows, so e^{Re(lam_i) tau_a} bounds it only
at tau_a. A state with such terms is solved in segments no longer than H = ln 2 / max Re(lam) (the
caller restarts the closed form there), and each growing term enters every bound above with its size at
H, |c_ji| e^{Re(lam_i) H} <= 2 |c_ji| (``gm``), which bounds it anywhere on [0, H]: the bounds hold on the
whole segment again, and a stop whose amplitude bound stays below its band cannot cross within the segment.

The dissipated work over [0, tau] is closed-form (v = Re sum_i a_i e^{lam_i t}, a_i = U_v[:, i] w_i):

    int_0^tau v^T C v dt = 1/2 Re sum_{i,k} [ G_ik I(lam_i + lam_k) + H_ik I(lam_i + conj(lam_k)) ],
    G_ik = a_i^T C a_k,  H_ik = a_i^T C conj(a_k),  I(z) = int_0^tau e^{z t} dt,

the regular terms (|z| >= ``ZNEAR`` (|lam_i| + |lam_k|), I(z) = (e_i e_k - 1) / z) as quadratic
forms of p = w (e^{lam tau} - 1) (:func:`_work`), the diagonal of H (z = 2 Re lam_i) by expm1,
and the few near-cancelling pairs by I(z) = tau phi1(z tau), a series where |z tau| < ``TAYLOR_ZT``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

# The constants below are the exact integrator's, free and forced segments alike
# (reduced.transient._exact_kernels takes them from here).
EPS = np.finfo(float).eps
QTOL_REL = 64.0 * EPS  # q is a sum of ~2n terms: round-off of its evaluation, relative to the size of its terms
NOISE_FACTOR = 4.0  # margin on the propagated round-off of q and q'
MAX_MARCH_ITER = 10_000_000  # per segment (per stop and segment in the forced march): a hang guard, never reached
FAST_LT = 2.0  # |lam| h beyond which a term's amplitude bounds it better than its Taylor bound
CUBIC_REACH = 4.0  # the cubic bound is tried first on [0, CUBIC_REACH x the quadratic bound's step] ...
CUBIC_ITER = 1  # ... and on intervals moved this many times toward its step (more moves save march steps
#   but cost more than they save on the scenes' systems: issue 28)
TAYLOR_ZT = 0.5  # |z tau| below which int_0^tau t^r e^{z t} dt is summed as a series ...
TAYLOR_TERMS = 17  # ... of this many terms (0.5^18 / 18! ~ 6e-22: exact to round-off)
SAMPLE_ANCHOR = 32  # output samples: e^{lam tau} worked out afresh at least every this many, stepped between
MARCH_COLS = 13  # columns of the march's per-stop scratch P (:func:`_quadratic_step`)
BUFFER_FULL = 1  # kernel status (free and forced): the sample buffer is full inside the present segment


@nb.njit(cache=True, inline="always")
def switch_stop(active, tip, j_ev):
    """The contact state after stop ``j_ev`` crosses: an active stop opens; closing a stop opens
    its tip's other stop (at zero gap both cross together) and activates it.

    Parameters
    ----------
    active : (m,) ndarray of bool
        The closed stops, changed in place.
    tip : (m,) ndarray of int
        Tip of each stop (a clearance's two stops share it).
    j_ev : int
        The stop that crossed.

    Returns
    -------
    None
    """
    if active[j_ev]:
        active[j_ev] = False
        return
    for j in range(active.shape[0]):
        if tip[j] == tip[j_ev]:
            active[j] = False
    active[j_ev] = True


@nb.njit(cache=True)
def _state_of(active):
    """Index of a contact state in the tables: sum_j active_j 2^j (free and forced kernels, the flow)."""
    s = 0
    for j in range(active.shape[0]):
        if active[j]:
            s += 1 << j
    return s


@nb.njit(cache=True, inline="always")
def _terms(lam, K, tau, e, ea):
    """e_i = exp(lam_i tau) and ea_i = |e_i| = exp(Re(lam_i) tau), i < K."""
    for i in range(K):
        a = math.exp(lam[i].real * tau)
        b = lam[i].imag * tau
        e[i] = complex(a * math.cos(b), a * math.sin(b))
        ea[i] = a


@nb.njit(cache=True, inline="always")
def _terms_at(lam, s, K, tau, e, ea):
    """:func:`_terms` of state s, lam the (S, K) table (no view of a row: a view costs two atomic
    reference counts in a loop)."""
    for i in range(K):
        a = math.exp(lam[s, i].real * tau)
        b = lam[s, i].imag * tau
        e[i] = complex(a * math.cos(b), a * math.sin(b))
        ea[i] = a


@nb.njit(cache=True)
def _phi_int(z, tau):
    """I(z) = int_0^tau e^{z t} dt = tau (1 + z tau / 2 + (z tau)^2 / 6 + ...): a series for
    |z tau| < TAYLOR_ZT, else (e^{z tau} - 1) / z."""
    x = z * tau
    if abs(x) < TAYLOR_ZT:
        acc = 1.0 + 0.0j
        for j in range(TAYLOR_TERMS, 0, -1):
            acc = 1.0 + acc * x / (j + 1)
        return tau * acc
    return (np.exp(x) - 1.0) / z


@nb.njit(cache=True, inline="always")
def _terms_m1(lam, K, tau, e, em, am1):
    """e_i = exp(lam_i tau) and em_i = e_i - 1 to full relative accuracy (expm1 and half angles:
    em = expm1(a) cos(b) - 2 sin^2(b / 2) + i e^a sin(b), a + i b = lam_i tau), am1_i = expm1(a), i < K."""
    for i in range(K):
        a = lam[i].real * tau
        b = 0.5 * lam[i].imag * tau
        sh = math.sin(b)
        ch = math.cos(b)
        cb = 1.0 - 2.0 * sh * sh
        sb = 2.0 * sh * ch
        x = math.expm1(a)
        ea = 1.0 + x
        e[i] = complex(ea * cb, ea * sb)
        em[i] = complex(x * cb - 2.0 * sh * sh, ea * sb)
        am1[i] = x


@nb.njit(cache=True, inline="always")
def _terms_m1_at(lam, s, K, tau, e, em, am1):
    """:func:`_terms_m1` of state s, lam the (S, K) table (as :func:`_terms_at`)."""
    for i in range(K):
        a = lam[s, i].real * tau
        b = 0.5 * lam[s, i].imag * tau
        sh = math.sin(b)
        ch = math.cos(b)
        cb = 1.0 - 2.0 * sh * sh
        sb = 2.0 * sh * ch
        x = math.expm1(a)
        ea = 1.0 + x
        e[i] = complex(ea * cb, ea * sb)
        em[i] = complex(x * cb - 2.0 * sh * sh, ea * sb)
        am1[i] = x


@nb.njit(cache=True, inline="always")
def _work(s, K, w, em, am1, tau, Wm, Hd, gr, gi):
    """int_0^tau v^T C v dt over the regular pairs and the diagonal of H (module docstring), with
    p = w (e^{lam tau} - 1) (em = e - 1): the regular pairs' e_i e_k - 1 = em_i em_k + em_i + em_k, so
    their part is Re(p^T Gz r + p^T Hz conj(r)), r = p + 2 w (Gz = A + i B, Hz = C + i D hold 1/2 G / z,
    1/2 H / z there and 0 elsewhere), accurate however short tau is:
    g = Gz r + Hz conj(r) = [(A + C) x + (D - B) y] + i [(B + D) x + (A - C) y] (r = x + i y), the four
    real matrices transposed in Wm[s, 0..3] so that the sums over k run down contiguous rows; and
    H's diagonal, 1/2 H_ii |w_i|^2 (e^{2 a tau} - 1) / (2 a) = Hd[s, 0, i] |w_i|^2 am1_i (2 + am1_i),
    am1_i = expm1(a tau), a = Re lam_i, Hd[s, 0, i] = 1/2 H_ii / (2 a), or Hd[s, 1, i] |w_i|^2 tau with
    Hd[s, 1, i] = 1/2 H_ii where a = 0 (the other entry 0). gr, gi: scratch (K,). The near-cancelling
    pairs: :func:`_work_near`."""
    for i in range(K):
        gr[i] = 0.0
        gi[i] = 0.0
    for k in range(K):
        r = w[k] * em[k] + 2.0 * w[k]
        x = r.real
        y = r.imag
        for i in range(K):
            gr[i] += Wm[s, 0, k, i] * x + Wm[s, 1, k, i] * y
            gi[i] += Wm[s, 2, k, i] * x + Wm[s, 3, k, i] * y
    acc = 0.0
    for i in range(K):
        pi = w[i] * em[i]
        acc += pi.real * gr[i] - pi.imag * gi[i]
        wi2 = w[i].real * w[i].real + w[i].imag * w[i].imag
        acc += wi2 * (Hd[s, 0, i] * (am1[i] * (2.0 + am1[i])) + Hd[s, 1, i] * tau)
    return acc


@nb.njit(cache=True)
def _work_near(s, w, tau, ip, ii, ik, ikind, icoef, iz):
    """The near-cancelling pairs p of state s: sum_p Re(icoef_p w_i (w_k or conj(w_k)) I(iz_p))."""
    acc = 0.0
    for p in range(ip[s], ip[s + 1]):
        i = ii[p]
        k = ik[p]
        wk = w[k] if ikind[p] == 0 else np.conj(w[k])
        acc += (icoef[p] * w[i] * wk * _phi_int(iz[p], tau)).real
    return acc


@nb.njit(cache=True, inline="always")
def _eval(s, K, UT, yp, w, e, out):
    """y = y_p + Re sum_i U[:, i] w_i e_i, with UT[s, 0] = Re U^T and UT[s, 1] = Im U^T (rows contiguous)."""
    N = out.shape[0]
    for r in range(N):
        out[r] = yp[s, r]
    for i in range(K):
        u = w[i] * e[i]
        ur = u.real
        ui = u.imag
        for r in range(N):
            out[r] += UT[s, 0, i, r] * ur - UT[s, 1, i, r] * ui


@nb.njit(cache=True, inline="always")
def _rows_of_state(s, K, UT, yp, R, RT, Ryp):
    """The output rows R (r, N) on state s's terms: RT[s, 0, i] = R Re U[:, i], RT[s, 1, i] = R Im U[:, i] (rows
    contiguous, as UT) and Ryp[s] = R y_p, so that R y = R y_p + Re sum_i (R U)[:, i] w_i e_i (:func:`_rows_eval`)."""
    r = R.shape[0]
    N = R.shape[1]
    for c in range(r):
        acc = 0.0
        for q in range(N):
            acc += R[c, q] * yp[s, q]
        Ryp[s, c] = acc
    for i in range(K):
        for c in range(r):
            a = 0.0
            b = 0.0
            for q in range(N):
                a += R[c, q] * UT[s, 0, i, q]
                b += R[c, q] * UT[s, 1, i, q]
            RT[s, 0, i, c] = a
            RT[s, 1, i, c] = b


@nb.njit(cache=True, inline="always")
def _rows_eval(s, K, RT, Ryp, w, e, zt, out_z, j):
    """out_z[j] = R y = R y_p + Re sum_i (R U)[:, i] w_i e_i (:func:`_rows_of_state`; zt: scratch (r,)): r rows
    for K r products where the whole state costs K N: :func:`_eval` on the rows' tables, the same operations)."""
    _eval(s, K, RT, Ryp, w, e, zt)
    for c in range(zt.shape[0]):
        out_z[j, c] = zt[c]


@nb.njit(cache=True)
def no_rows(S, Kmax, N):
    """The ``acq`` argument of a run that samples the whole state at every sample (no output rows).

    Parameters
    ----------
    S : int
        States of the run's tables.
    Kmax : int
        Their most kept terms.
    N : int
        Length of the state y.

    Returns
    -------
    tuple
        (0, R (0, N), RT (S, 2, Kmax, 0), Ryp (S, 0), Es (S, Kmax), have (S,), out_z (0, 0), zt (0,)), as
        :func:`_free_kernel_rows` reads them.
    """
    return (0, np.zeros((0, N)), np.zeros((S, 2, Kmax, 0)), np.zeros((S, 0)), np.zeros((S, Kmax), np.complex128),
            np.zeros(S, np.bool_), np.zeros((0, 0)), np.zeros(0))


@nb.njit(cache=True, inline="always")
def _start(s, K, y, Uinv, aUinv, yp, BU, aBU, Byp, lam, alam, offset, side, active, floor, w, werr, coef, lc,
           l2c, a0, const, qtol, dnoise, live, dy, ay):
    """Segment start in state s: w = Uinv (y - y_p) and werr (its round-off, EPS sum |Uinv| (|y| + |y_p|)),
    then per stop j (signed so that q_j <= 0 until it changes state) q_j = const_j + Re sum_i coef_ji e^{lam_i tau},
    lc = lam coef, l2c = lam^2 coef, a0 = |coef|, the round-off band qtol_j
    of q_j and the noise dnoise_j of q_j'. A stop whose motion is below ``floor`` (round-off at rest) is not live.
    dy, ay: scratch (2n,). Returns the number of live stops."""
    N = y.shape[0]
    m = offset.shape[0]
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
    for j in range(m):
        sgn = -side[j] if active[j] else side[j]
        cj = sgn * (Byp[s, j] - offset[j])
        osc = 0.0
        qn = 0.0
        dn = 0.0
        for i in range(K):
            c = sgn * (BU[s, j, i] * w[i])
            coef[j, i] = c
            lc[j, i] = lam[s, i] * c
            l2c[j, i] = lam[s, i] * lc[j, i]
            a = math.sqrt(c.real * c.real + c.imag * c.imag)
            a0[j, i] = a
            osc += a
            qn += aBU[s, j, i] * werr[i]
            dn += aBU[s, j, i] * alam[s, i] * werr[i]
        const[j] = cj
        qtol[j] = QTOL_REL * (abs(cj) + osc) + NOISE_FACTOR * qn
        dnoise[j] = NOISE_FACTOR * dn
        live[j] = not (osc < floor and abs(cj) < floor)
        if live[j]:
            n_live += 1
    return n_live


@nb.njit(cache=True)
def _step(q, d, Q2):
    """Largest h >= 0 with q + d h + Q2 h^2 / 2 < 0 for q <= 0 (inf when d <= 0 and Q2 = 0)."""
    qn = -min(q, 0.0)
    disc = math.sqrt(d * d + 2.0 * Q2 * qn)
    if d > 0.0:
        return 2.0 * qn / (d + disc)
    if Q2 > 0.0:
        return (disc - d) / Q2
    return np.inf


@nb.njit(cache=True)
def _cubic_step(q, d, Q2, d2, Q3):
    """A safe step for q(h) <= q + d h + d2 h^2 / 2 + Q3 h^3 / 6 (and <= q + d h + Q2 h^2 / 2): the
    quadratic bound's step, or min(H, step with the curvature d2 + Q3 H / 3) (the cubic term is at
    most Q3 H / 3 h^2 / 2 on [0, H]), H moved ``CUBIC_ITER`` times toward that step (each move
    gives a larger safe step)."""
    return _cubic_from(_step(q, d, Q2), q, d, d2, Q3)


@nb.njit(cache=True)
def _cubic_from(h, q, d, d2, Q3):
    """:func:`_cubic_step` from h, the quadratic bound's step _step(q, d, Q2) (worked out already)."""
    if h == np.inf:
        return h
    H = CUBIC_REACH * h
    for _ in range(CUBIC_ITER):
        g = _step(q, d, max(d2 + Q3 * H / 3.0, 0.0))
        if g >= H:  # no root on [0, H]
            h = max(h, H)
            H = 2.0 * H if g == np.inf else math.sqrt(g * H)
        else:
            h = max(h, g)
            H = math.sqrt(g * H)
    return h


@nb.njit(cache=True, inline="always")
def _stop_sums(s, j, K, i0, alam, const, coef, lc, l2c, a0, e, ea):
    """Stop j at the march's tau (e = e^{lam tau}, ea = |e|): q, the amplitude sum amp, the scale ds of q',
    and q', q'' (exact), Q2, Q3 (the bounds of the second and third derivatives) over the slow terms
    (i < i0) and over the fast ones, with the fast terms' slack sum (|c e| - Re(c e)):
    (q, amp, ds, d_s, d2_s, q2_s, q3_s, slack, d_f, d2_f, q2_f, q3_f)."""
    q = const[j]
    ds = 0.0
    amp = 0.0
    d_s = 0.0  # slow terms: q', q'' (exact), Q2, Q3
    d2_s = 0.0
    q2_s = 0.0
    q3_s = 0.0
    slack = 0.0  # fast terms: sum (|c e| - Re(c e)), q', q'', Q2, Q3
    d_f = 0.0
    d2_f = 0.0
    q2_f = 0.0
    q3_f = 0.0
    for i in range(K):
        r = (coef[j, i] * e[i]).real
        dr = (lc[j, i] * e[i]).real
        d2r = (l2c[j, i] * e[i]).real
        a = a0[j, i] * ea[i]
        al = alam[s, i]
        a1 = al * a
        a2 = al * a1
        q += r
        ds += a1
        amp += a
        if i < i0:
            d_s += dr
            d2_s += d2r
            q2_s += a2
            q3_s += al * a2
        else:
            slack += a - r
            d_f += dr
            d2_f += d2r
            q2_f += a2
            q3_f += al * a2
    return q, amp, ds, d_s, d2_s, q2_s, q3_s, slack, d_f, d2_f, q2_f, q3_f


@nb.njit(cache=True, inline="always")
def _root_at(tau, q, d, d2, Q3, qt, dt):
    """Where the stop crosses, seen from tau (q, q' = d, q'' = d2 and Q3, a bound of the third derivative,
    q and q' known to qt and dt): tau itself, tau - q / q' or tau + x, x the root of the Taylor quadratic
    (:func:`_march`); -1 if not decided here."""
    if q > -qt:
        # at the threshold a crossing needs q' > 0 beyond its round-off; otherwise it is a
        # graze, or the round-off of re-expanding the state right after a switch
        if q > qt and d >= -dt:
            return tau
        if d > dt:
            return tau + max(-q, 0.0) / d
    elif d > dt:
        disc = d * d - 2.0 * d2 * q
        if disc >= 0.0:
            x = -2.0 * q / (d + math.sqrt(disc))  # q + q' x + q'' x^2 / 2 = 0
            if Q3 * x * x * x <= qt:  # the cubic remainder is within the round-off band
                return tau + x
    return -1.0


@nb.njit(cache=True, inline="always")
def _quadratic_step(j, q, d, d2, Q2, Q3, split, slack, d_s, d2_s, q2_s, q3_s, P):
    """Stop j's safe step from its quadratic bounds (with the fast terms by their amplitude when
    ``split``), its sums kept in P[j] for the cubic bounds (:func:`_refine_smallest`)."""
    h = _step(q, d, Q2)
    P[j, 11] = h
    if split and q + slack < 0.0:
        hs = _step(q + slack, d_s, q2_s)
        P[j, 12] = hs
        h = max(h, hs)
    P[j, 0] = q
    P[j, 1] = d
    P[j, 2] = d2
    P[j, 3] = Q2
    P[j, 4] = Q3
    P[j, 5] = q + slack if split else 1.0  # > 0: no partition
    P[j, 6] = d_s
    P[j, 7] = d2_s
    P[j, 8] = q2_s
    P[j, 9] = q3_s
    P[j, 10] = 0.0  # not refined yet
    return h


@nb.njit(cache=True, inline="always")
def _refine_smallest(m, live, hnext, P, tau, best, hmin):
    """Refine the smallest step by the cubic bounds until it is a refined one (or cannot matter)."""
    while True:
        jm = -1
        hm = np.inf
        for j in range(m):
            if live[j] and hnext[j] < hm:
                hm = hnext[j]
                jm = j
        if jm < 0 or P[jm, 10] != 0.0 or tau + max(hm, hmin) >= best:
            return
        h = max(hm, _cubic_from(P[jm, 11], P[jm, 0], P[jm, 1], P[jm, 2], P[jm, 4]))
        if P[jm, 5] < 0.0:
            h = max(h, _cubic_from(P[jm, 12], P[jm, 5], P[jm, 6], P[jm, 7], P[jm, 9]))
        hnext[jm] = h
        P[jm, 10] = 1.0


@nb.njit(cache=True, inline="always")
def _march(s, K, lam, alam, const, coef, lc, l2c, a0, qtol, dnoise, live, n_live, tau_limit, hmin, e, ea, hprev,
           hnext, P, gm):
    """First crossing of any live stop in [0, tau_limit): (tau, j, n_iter), j = -1 if none, j = -2 if the
    march did not end (module docstring). ``gm`` (K,): each term's bound factor, e^{Re(lam_i) H} for a growing
    term (> 1; tau_limit <= H then), 1 for the others.

    At tau, per live stop (:func:`_stop_sums`): the crossing is at tau when q > qtol and q' >= -dtol, at
    tau - q / q' when |q| <= qtol and q' > dtol (the decisions of
    :func:`reduced.transient._exact_kernels._march_step`), or, when q' > dtol, at tau + x with x the root
    of q + q' x + q'' x^2 / 2 if Q3 x^3 <= qtol (Q3 = sum |lam|^3 |c e| bounds the third derivative): the
    Taylor remainder is then within the round-off band, so the root is located as well as by stepping
    onto it (:func:`_root_at`). Otherwise the safe step is the largest of four bounds, each valid for
    every h in its range: the quadratic one (Q2), the cubic one q + q' h + q2 h^2 / 2 + Q3 h^3 / 6
    (q2 = Re sum lam^2 c e exact; :func:`_cubic_step`), and both again with the fast terms bounded by
    their amplitude. The cubic bounds are worked out only for the stop whose step is the smallest (the
    others' quadratic steps are already longer), until that stop's step is the smallest of the refined
    ones (:func:`_refine_smallest`). P[j] keeps each stop's sums for that. The helpers are inlined
    (numba ``inline="always"``): the march is still one loop body.
    """
    m = const.shape[0]
    best = tau_limit
    j_best = -1
    for j in range(m):
        hprev[j] = 0.0
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        if n_live == 0:
            return best, j_best, it
        if tau == 0.0:
            for i in range(K):
                e[i] = 1.0
                ea[i] = 1.0
        else:
            _terms_at(lam, s, K, tau, e, ea)
        for i in range(K):
            if gm[i] > 1.0:  # a growing term: its size at the segment's end bounds it on all of it
                ea[i] = gm[i]
        for j in range(m):
            if not live[j]:
                continue
            i0 = K  # terms i >= i0 are bounded by their amplitude
            hp = hprev[j]
            while i0 > 0 and alam[s, i0 - 1] * hp > FAST_LT:
                i0 -= 1
            q, amp, ds, d_s, d2_s, q2_s, q3_s, slack, d_f, d2_f, q2_f, q3_f = _stop_sums(
                s, j, K, i0, alam, const, coef, lc, l2c, a0, e, ea)
            d = d_s + d_f
            d2 = d2_s + d2_f
            Q3 = q3_s + q3_f
            qt = qtol[j]
            root = _root_at(tau, q, d, d2, Q3, qt, QTOL_REL * ds + dnoise[j])
            if root >= 0.0:
                live[j] = False
                n_live -= 1
                if root < best or (root == best and j < j_best):
                    best = root
                    j_best = j
                continue
            if const[j] + amp < -qt:
                hnext[j] = np.inf  # its amplitude can never bring it to the threshold
                P[j, 10] = 1.0
            else:
                hnext[j] = _quadratic_step(j, q, d, d2, q2_s + q2_f, Q3, i0 < K, slack, d_s, d2_s, q2_s, q3_s, P)
        _refine_smallest(m, live, hnext, P, tau, best, hmin)
        h_all = np.inf
        for j in range(m):
            if live[j]:
                hprev[j] = hnext[j]
                h = max(hnext[j], hmin)
                if tau + h >= best:  # no crossing of j before the best found
                    live[j] = False
                    n_live -= 1
                else:
                    h_all = min(h_all, h)
        if n_live == 0:
            return best, j_best, it + 1
        tau += h_all
    return best, -2, MAX_MARCH_ITER


@nb.njit(cache=True)
def _term_scratch(K):
    """Per-term scratch of a free segment (K terms): w (complex), werr, e (complex), ea, em (complex), am1,
    gr, gi."""
    return (np.empty(K, np.complex128), np.empty(K), np.empty(K, np.complex128), np.empty(K),
            np.empty(K, np.complex128), np.empty(K), np.empty(K), np.empty(K))


@nb.njit(cache=True)
def _stop_scratch(m, K):
    """Per-stop scratch of the march (m stops, K terms): coef, lc, l2c (m, K) complex, a0 (m, K), const,
    qtol, dnoise (m,), live (m,) bool, hprev, hnext (m,), P (m, MARCH_COLS) (:func:`_march`)."""
    return (np.empty((m, K), np.complex128), np.empty((m, K), np.complex128), np.empty((m, K), np.complex128),
            np.empty((m, K)), np.empty(m), np.empty(m), np.empty(m), np.empty(m, np.bool_), np.empty(m),
            np.empty(m), np.empty((m, MARCH_COLS)))


@nb.njit(cache=True)
def _free_kernel(tb, offset, side, tip, damped, y, active, t, bounds, c, t_samples, i_samp, t_after, out_y, out_W,
                 W, hmin, floor, max_events, n_stuck, out_E, E, seg_s, seg_tau, fs=0.0):
    """March events from t through the pieces ending at bounds[c], bounds[c + 1], ... (no loads), filling
    the sample buffer ``t_samples`` from i_samp.

    ``tb`` is the modal table (:func:`reduced.transient.exact.modal_table`). (y, active, t, W) is the
    state at the start of a segment and is advanced in place; every piece bound ends a segment (the
    closed form restarts there) and resets n_stuck. When the buffer fills inside a segment that still
    has samples before its end (the next sample, at ``t_after``, lies in it), the kernel returns
    BUFFER_FULL without advancing that segment, so the samples do not depend on the buffer size.
    ``out_E`` (empty, or as long as the buffer) receives the loads' work E, constant here. When
    ``seg_s`` is not empty, segment k's contact state and length go to seg_s[k], seg_tau[k] (for the
    flow's Jacobian, :func:`flow_jacobian`; a segment ends at an event or a bound, so with one bound
    there are n_events + 1, and max_events must leave room for them).
    With ``fs`` > 0 the samples are t_j = j / fs (as the stepper's buffers hold them), and the terms
    e^{lam tau} of consecutive samples of a segment are stepped, e^{lam (tau + 1/fs)} = e^{lam tau} e^{lam / fs}
    (and e - 1, e^{Re(lam) tau} - 1 likewise, accurate however short tau is), instead of worked out afresh: a
    sample then costs a few products instead of K exponentials. A sample is an anchor, worked out afresh, when
    j is a multiple of SAMPLE_ANCHOR or the one before it is not in the segment (so the steps never add up
    more than SAMPLE_ANCHOR roundings); a buffer that starts between anchors steps from the last anchor up to
    its first sample, so the samples are the same bits whatever the buffers are.
    Returns (t, W, i_samp, n_events, n_iter, status, n_stuck, c): c the piece reached.
    """
    N = y.shape[0]
    S, Kmax = tb[1].shape
    return _free_run(tb, offset, side, tip, damped, y, active, t, bounds, c, t_samples, i_samp, t_after, out_y, out_W,
                     W, hmin, floor, max_events, n_stuck, out_E, E, seg_s, seg_tau, _term_scratch(Kmax),
                     _stop_scratch(offset.shape[0], Kmax), np.empty(N), np.empty(N), np.empty(N), fs,
                     (np.zeros(S, np.bool_), np.empty((S, Kmax), np.complex128), np.empty((S, Kmax), np.complex128),
                      np.empty((S, Kmax))), np.ones(Kmax), no_rows(S, Kmax, N))


@nb.njit(cache=True)
def _free_kernel_rows(tb, offset, side, tip, damped, y, active, t, bounds, c, t_samples, i_samp, t_after, out_y,
                      out_W, W, hmin, floor, max_events, n_stuck, out_E, E, fs, acq):
    """:func:`_free_kernel` (no segments recorded; ``fs`` > 0) with output rows ``acq`` = (every, R, RT, Ryp, Es,
    have, out_z, zt): every sample's R y into out_z (:func:`_rows_eval`, R (r, N)); the whole state and the
    dissipated work into out_y and out_W only at the samples j (at j / fs) that are multiples of ``every``, the
    others' rows of out_y and out_W left as they are. Those samples are the same bits as :func:`_free_kernel`'s
    (the terms are stepped through every sample as there). RT, Ryp (S, 2, Kmax, r), (S, r) are filled for a
    state the first time a sample needs them (``have`` (S,) bool: per run, the run's tables); Es is not read.
    Returns as :func:`_free_kernel`."""
    N = y.shape[0]
    S, Kmax = tb[1].shape
    return _free_run(tb, offset, side, tip, damped, y, active, t, bounds, c, t_samples, i_samp, t_after, out_y, out_W,
                     W, hmin, floor, max_events, n_stuck, out_E, E, np.zeros(0, np.int64), np.zeros(0),
                     _term_scratch(Kmax), _stop_scratch(offset.shape[0], Kmax), np.empty(N), np.empty(N), np.empty(N),
                     fs, (np.zeros(S, np.bool_), np.empty((S, Kmax), np.complex128),
                          np.empty((S, Kmax), np.complex128), np.empty((S, Kmax))), np.ones(Kmax), acq)


@nb.njit(cache=True, inline="always")
def _anchor(j, fs, t):
    """Whether sample j (at j / fs) of a segment starting at t is worked out afresh (:func:`_free_kernel`)."""
    return j % SAMPLE_ANCHOR == 0 or (j - 1) / fs <= t


@nb.njit(cache=True, inline="always")
def _sample_terms(lam, s, K, tau, e, em, am1, j, fs, t, stepped, steps):
    """e, em = e - 1, am1 (:func:`_terms_m1_at`) at sample j (tau = j / fs - t, not below 0) of the segment
    starting at t: afresh at an anchor (:func:`_anchor`); else one step from sample j - 1 when ``stepped``
    (its terms are in e, em, am1), or from the last anchor. ``steps`` = (have, E, Em, Ah): per state,
    e^{lam / fs}, its - 1 and expm1(Re(lam) / fs), worked out on first use. Returns True (the terms are
    those of sample j)."""
    if fs <= 0.0 or _anchor(j, fs, t):
        _terms_m1_at(lam, s, K, tau, e, em, am1)
        return True
    have, Es, Ems, Ahs = steps
    if not have[s]:
        _terms_m1_at(lam, s, K, 1.0 / fs, e, em, am1)
        for i in range(K):
            Es[s, i] = e[i]
            Ems[s, i] = em[i]
            Ahs[s, i] = am1[i]
        have[s] = True
        stepped = False
    j0 = j - 1
    if not stepped:  # from the last anchor
        while not _anchor(j0, fs, t):
            j0 -= 1
        _terms_m1_at(lam, s, K, max(j0 / fs - t, 0.0), e, em, am1)
    for _ in range(j0, j):
        for i in range(K):
            a = Ahs[s, i]
            e[i] = e[i] * Es[s, i]
            em[i] = em[i] * Es[s, i] + Ems[s, i]
            am1[i] = am1[i] + a + am1[i] * a
    return True


@nb.njit(cache=True, _nrt=False)
def _free_run(tb, offset, side, tip, damped, y, active, t, bounds, c, t_samples, i_samp, t_after, out_y, out_W,
              W, hmin, floor, max_events, n_stuck, out_E, E, seg_s, seg_tau, terms, stops, ytmp, dy, ay, fs, steps,
              ones, acq):
    """:func:`_free_kernel`'s march, on its scratch (``terms``: :func:`_term_scratch`, ``stops``:
    :func:`_stop_scratch`, ytmp, dy, ay (2n,); ``ones`` (Kmax,) the march's bound factors: no growing terms, the
    states decay or oscillate; ``acq``: the output rows, :func:`_free_kernel_rows`, or :func:`no_rows`).
    Compiled without numba's reference counting (``_nrt=False``:
    it allocates nothing): every array passed to an inlined helper would otherwise cost two atomic
    reference counts per call, a fifth of the march's time on a small system."""
    (nK, lam, alam, UT, Uinv, aUinv, yp, BU, aBU, Byp, Wm, Hd, ip, ii, ik, ikind, icoef, iz) = tb
    N = y.shape[0]
    m = offset.shape[0]
    ns = t_samples.shape[0]
    has_E = out_E.shape[0] > 0
    w, werr, e, ea, em, am1, gr, gi = terms
    coef, lc, l2c, a0, const, qtol, dnoise, live, hprev, hnext, P = stops
    every, R, RT, Ryp, _, have, out_z, zt = acq
    n_events = 0
    n_iter = 0
    status = 0
    n_seg = 0
    rec = seg_s.shape[0] > 0
    t_end = bounds[c]
    while True:
        s = _state_of(active)
        K = nK[s]
        if K < 0:
            status = -2
            break
        near = ip[s + 1] > ip[s]
        n_live = _start(s, K, y, Uinv, aUinv, yp, BU, aBU, Byp, lam, alam, offset, side, active, floor, w, werr,
                        coef, lc, l2c, a0, const, qtol, dnoise, live, dy, ay)
        tau_ev, j_ev, it = _march(s, K, lam, alam, const, coef, lc, l2c, a0, qtol, dnoise, live, n_live, t_end - t,
                                  hmin, e, ea, hprev, hnext, P, ones)
        if j_ev == -2:
            status = -3
            break
        t_next = t_end if j_ev < 0 else t + tau_ev
        stepped = False  # e, em, am1 hold the terms of the sample before
        while i_samp < ns and t_samples[i_samp] <= t_next:
            tau = max(t_samples[i_samp] - t, 0.0)
            j = round(t_samples[i_samp] * fs) if fs > 0.0 else 0
            stepped = _sample_terms(lam, s, K, tau, e, em, am1, j, fs, t, stepped, steps)
            if every == 0 or j % every == 0:
                _eval(s, K, UT, yp, w, e, ytmp)
                out_W[i_samp] = W + ((_work(s, K, w, em, am1, tau, Wm, Hd, gr, gi)
                                      + (_work_near(s, w, tau, ip, ii, ik, ikind, icoef, iz) if near else 0.0))
                                     if damped else 0.0)
                for r in range(N):
                    out_y[i_samp, r] = ytmp[r]
            if has_E:
                out_E[i_samp] = E
            if every > 0:
                if not have[s]:
                    _rows_of_state(s, K, UT, yp, R, RT, Ryp)
                    have[s] = True
                _rows_eval(s, K, RT, Ryp, w, e, zt, out_z, i_samp)
            i_samp += 1
        if i_samp == ns and t_after <= t_next:
            status = BUFFER_FULL  # the segment is searched again with the next buffer: count it then
            break
        n_iter += it
        _terms_m1_at(lam, s, K, tau_ev, e, em, am1)
        _eval(s, K, UT, yp, w, e, ytmp)
        if damped:
            W += _work(s, K, w, em, am1, tau_ev, Wm, Hd, gr, gi)
            if near:
                W += _work_near(s, w, tau_ev, ip, ii, ik, ikind, icoef, iz)
        for r in range(N):
            y[r] = ytmp[r]
        if rec:
            seg_s[n_seg] = s
            seg_tau[n_seg] = tau_ev
            n_seg += 1
        n_stuck = n_stuck + 1 if tau_ev == 0.0 else 0
        if n_stuck > 8 * m:
            status = -4
            break
        t = t_next
        if j_ev < 0:
            c += 1  # the piece's end: the next piece, or done
            n_stuck = 0
            if c == bounds.shape[0]:
                break
            t_end = bounds[c]
            continue
        switch_stop(active, tip, j_ev)
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, i_samp, n_events, n_iter, status, n_stuck, c


@nb.njit(cache=True)
def flow_jacobian(tb, seg_s, seg_tau, n_seg, J):
    """J <- exp(A_{s_k} tau_k) ... exp(A_{s_1} tau_1) J over the recorded segments, in place (2n, 2n) real.

    exp(A_s tau) z = Re sum_{i<K} U[:, i] e^{lam_i tau} (Uinv z)_i for a real z (the kept-term form of
    V diag(e^{lam tau}) V^-1, module docstring), applied to each column of J.

    Parameters
    ----------
    tb : tuple
        The free segments' tables (:func:`reduced.transient.exact_tables.modal_table`); entries 0
        (kept terms per state), 1 (lam), 3 (U^T as Re/Im) and 4 (Uinv) are read.
    seg_s : (n_seg,) ndarray of int
        Contact state of each segment.
    seg_tau : (n_seg,) ndarray of float
        s, duration of each segment.
    n_seg : int
        Segments to apply, in order.
    J : (2n, 2n) ndarray of float
        The matrix multiplied, overwritten.

    Returns
    -------
    None
    """
    nK, lam, UT, Uinv = tb[0], tb[1], tb[3], tb[4]
    N = J.shape[0]
    Kmax = lam.shape[1]
    Z = np.empty((Kmax, N), np.complex128)
    e = np.empty(Kmax, np.complex128)
    ea = np.empty(Kmax)
    for k in range(n_seg):
        s = seg_s[k]
        K = nK[s]
        _terms(lam[s], K, seg_tau[k], e, ea)
        for i in range(K):
            for c in range(N):
                acc = 0.0 + 0.0j
                for r in range(N):
                    acc += Uinv[s, i, r] * J[r, c]
                Z[i, c] = acc * e[i]
        for r in range(N):
            for c in range(N):
                acc = 0.0
                for i in range(K):
                    acc += UT[s, 0, i, r] * Z[i, c].real - UT[s, 1, i, r] * Z[i, c].imag
                J[r, c] = acc
