"""The central-difference register kernel of :mod:`reduced.transient._cd` for lumped models: diagonal mass and
damping and each stop on one coordinate (the paper's three masses; issue 28).

The recurrence and the order of every sum are those of :func:`reduced.transient._cd._cd_small`,

    x_{n+1} = x_n + dt v_{n+1/2},
    v_{n+3/2} = A v_{n+1/2} - dt G K x_{n+1} - dt G B^T f(B x_{n+1}) + dt G b^T p(t_{n+1}),

G = (M + dt/2 C)^-1, A = G (M - dt/2 C). With M and C diagonal, A, G and the damping factor L (C = L L^T) are
diagonal, and a stop row B_j with one nonzero entry (column c_j) makes dt G B^T's row j one entry too. The
register kernel adds those zero terms; this kernel leaves them out, which changes no bit, signs of zeros
included: each velocity row starts as 0.0 + t (never -0.0, as +0 + -0 = +0 in round-to-nearest), a sum that is
not -0.0 stays so, and adding +-0 to it, or subtracting, leaves it as it is; a term 0 v - g x is -(g x)
exactly when g x != 0 (and +-0 otherwise). A stop's row -offset + B_j x is the same number whenever it is not
zero (the only case its force and its test side s > 0 use it), and the dissipation rate's
|(L^T w)_q|^2 = (0.0 + L_qq w_q)^2 = (L_qq w_q)^2 and 0.0 + (l_0 w_0)^2 = (l_0 w_0)^2. The first row's 0.0 + is
taken before x_0 enters it, (0.0 + p) - q = 0.0 + (p - q) (both are p - q unless that is -0, which needs p = -0
and q = +0, and then both are +0): it is off the path from x_{n+1} to v_{n+3/2}, which bounds a step. A stop's
side s > 0 is the test bs x_c > ts on the side-folded row (below); the stops sit in registers, two a column.
So the same bits with about 55 floating-point operations a step instead of 108 (three masses, four stops open,
three dashpots): tests/test_explicit_lumped_kernel.py.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from reduced.transient._cd import SMALL_N

SLOTS = 2  # stops a column at most (two: an upper and a lower); a model with more runs the register kernel


def lumped_form(AT: np.ndarray, dtGKT: np.ndarray, dtGBT: np.ndarray, L: np.ndarray, B: np.ndarray,
                offset: np.ndarray, side: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, ...] | None:
    """The leading arguments of :func:`cd_lumped` from those of ``_cd_small`` (zero-padded to ``SMALL_N``
    columns) and the stops, or None when the model is not lumped: A or L with an off-diagonal entry, L with more
    columns than the padded state, a stop row (of B or dt G B^T) with more than one nonzero entry or their entries
    in different columns, more than ``SLOTS`` stops on a column, or a side other than +-1.

    Parameters
    ----------
    AT, dtGKT : (3, 3) ndarray
        A^T and (dt G K)^T.
    dtGBT : (m, 3) ndarray
        (dt G B^T)^T.
    L : (3, r) ndarray
        The damping factor, C = L L^T (rows padded).
    B : (m, 3) ndarray
        The stops' rows.
    offset, side, k : (m,) ndarray
        m, +1 / -1, N/m: the stops.

    Returns
    -------
    tuple or None
        ``(a, dtGKT, bs, ts, os, ks, gs, l)``: a (3,) the diagonal of A; (3, SLOTS) tables of the stops by
        column c and slot (a column's stops in their order, empty slots never closed: ts = +inf):
        bs = side B_jc, ts = side offset (the row side (B_j x - offset) > 0 iff bs x_c > ts),
        os = -side offset, ks = k, gs = side (dt G B^T)_jc; l (3,) the diagonal of L (zero-padded).
    """
    S = SMALL_N
    off = ~np.eye(S, dtype=bool)
    if AT.shape != (S, S) or np.any(AT[off] != 0.0) or L.shape[0] != S or L.shape[1] > S:
        return None
    Lp = np.zeros((S, S))
    Lp[:, :L.shape[1]] = L
    if np.any(Lp[off] != 0.0) or np.any(np.abs(side) != 1.0):
        return None
    m = B.shape[0]
    col = np.zeros(m, np.int64)
    for j in range(m):
        nz = np.flatnonzero((B[j] != 0.0) | (dtGBT[j] != 0.0))
        if nz.size > 1:
            return None
        col[j] = nz[0] if nz.size else 0
    order = np.argsort(col, kind="stable")
    if np.bincount(col, minlength=S).max(initial=0) > SLOTS:
        return None
    # (column, slot) tables: each column's stops in their order, empty slots never closed (ts = +inf)
    bs, ts, os_, ks, gs = np.zeros((S, SLOTS)), np.full((S, SLOTS), np.inf), *np.zeros((3, S, SLOTS))
    used = np.zeros(S, np.int64)
    for j in order:
        c, sd = col[j], float(side[j])
        t = used[c]
        used[c] += 1
        bs[c, t], ts[c, t], os_[c, t] = sd * B[j, c], sd * offset[j], -(sd * offset[j])
        ks[c, t], gs[c, t] = k[j], sd * dtGBT[j, c]
    f = np.ascontiguousarray
    return (f(np.diag(AT)), f(dtGKT), bs, ts, os_, ks, gs, f(np.diag(Lp)))


@nb.njit(cache=True)
def cd_lumped(a, dtGKT, bs, ts, os, ks, gs, l, offset, side, k, x, vh, dt, n_steps, every, out_x, out_v,
              out_W, W, pw_old, i0, dtGbT, b, P, out_E, E, pe_old):
    """:func:`reduced.transient._cd._cd_small` (same arguments after the leading ones, which replace the stops'
    offset, side and k, same returns, same bits) for a lumped model (module docstring): row i of v_{n+3/2} is
    0.0 + (a_0 v_0 - (dt G K)_00 x_0) - ... in the register kernel's order with the zero terms of A left out; a
    stop on column c is closed when bs x_c > ts (side s > 0 for s = -offset + B_jc x_c: fl(u + w) > 0 iff
    u + w > 0, and side s = os + bs x_c exactly, side being +-1), its force then enters row c alone,
    gs (ks (os + bs x_c)) = (dt G B^T)_jc k s; and p_n = sum_q (l_q w_q)^2. The stops sit in (column, slot)
    tables, two slots a column in their order, an empty one never closed (ts = +inf).

    Long because, as in the register kernel, the state, the matrices and the stops' thresholds live in scalar
    variables for the whole step loop, written out term by term (a helper would pass them through memory).

    Parameters
    ----------
    a, dtGKT, bs, ts, os, ks, gs, l : ndarray
        :func:`lumped_form` of the model: diag(A) (3,), (dt G K)^T (3, 3), the stops' (3, SLOTS) tables
        (bs, ts in m, os in m, ks in N/m, gs), diag(L) (3,).
    offset, side, k : ndarray
        The stops (not read: their values are in the tables; kept for ``_cd_small``'s argument list).
    x, vh : ndarray
        (3,) x_n in m and v_{n+1/2} in m/s, zero-padded, advanced in place.
    dt : float
        s, the step.
    n_steps, every : int
        Steps to take; a sample every ``every`` steps.
    out_x, out_v, out_W : ndarray
        Sample buffers (x, v_n, the dissipated work W in J).
    W, pw_old : float
        J and W, the work so far and the last dissipation rate p_n.
    i0 : int
        The first sample row to fill.
    dtGbT, b, P : ndarray
        The loads: (dt G b^T)^T and b (n_loads, 3) zero-padded, P the loads at each step's end.
    out_E : ndarray
        Sample buffer of the loads' work.
    E, pe_old : float
        J and W, the loads' work so far and their last power.

    Returns
    -------
    tuple
        (W, pw_old, io, E, pe_old): io the next sample row."""
    n = out_x.shape[1]
    nl = b.shape[0]
    x0, x1, x2 = x[0], x[1], x[2]
    v0, v1, v2 = vh[0], vh[1], vh[2]
    a0, a1, a2 = a[0], a[1], a[2]
    l0, l1, l2 = l[0], l[1], l[2]
    g00, g01, g02 = dtGKT[0, 0], dtGKT[1, 0], dtGKT[2, 0]
    g10, g11, g12 = dtGKT[0, 1], dtGKT[1, 1], dtGKT[2, 1]
    g20, g21, g22 = dtGKT[0, 2], dtGKT[1, 2], dtGKT[2, 2]
    b00, b01, b10, b11, b20, b21 = bs[0, 0], bs[0, 1], bs[1, 0], bs[1, 1], bs[2, 0], bs[2, 1]
    t00, t01, t10, t11, t20, t21 = ts[0, 0], ts[0, 1], ts[1, 0], ts[1, 1], ts[2, 0], ts[2, 1]
    io = i0
    left = every
    for step in range(n_steps):
        x0 += dt * v0
        x1 += dt * v1
        x2 += dt * v2
        n0 = (0.0 + a0 * v0) - g00 * x0  # = 0.0 + (a0 v0 - g00 x0), one add shorter from x0 (docstring)
        n0 -= g01 * x1
        n0 -= g02 * x2
        n1 = 0.0 - g10 * x0
        n1 += a1 * v1 - g11 * x1
        n1 -= g12 * x2
        n2 = 0.0 - g20 * x0
        n2 -= g21 * x1
        n2 += a2 * v2 - g22 * x2
        bx = b00 * x0  # the stops of each column in their order (an open stop adds exactly 0)
        if bx > t00:
            n0 -= gs[0, 0] * (ks[0, 0] * (os[0, 0] + bx))
        bx = b01 * x0
        if bx > t01:
            n0 -= gs[0, 1] * (ks[0, 1] * (os[0, 1] + bx))
        bx = b10 * x1
        if bx > t10:
            n1 -= gs[1, 0] * (ks[1, 0] * (os[1, 0] + bx))
        bx = b11 * x1
        if bx > t11:
            n1 -= gs[1, 1] * (ks[1, 1] * (os[1, 1] + bx))
        bx = b20 * x2
        if bx > t20:
            n2 -= gs[2, 0] * (ks[2, 0] * (os[2, 0] + bx))
        bx = b21 * x2
        if bx > t21:
            n2 -= gs[2, 1] * (ks[2, 1] * (os[2, 1] + bx))
        for q in range(nl):
            pq = P[step, q]
            n0 += dtGbT[q, 0] * pq
            n1 += dtGbT[q, 1] * pq
            n2 += dtGbT[q, 2] * pq
        w0 = 0.5 * (v0 + n0)
        w1 = 0.5 * (v1 + n1)
        w2 = 0.5 * (v2 + n2)
        v0, v1, v2 = n0, n1, n2
        s0 = l0 * w0
        s1 = l1 * w1
        s2 = l2 * w2
        pw_new = s0 * s0  # = 0.0 + s0 * s0: a square is never -0.0
        pw_new += s1 * s1
        pw_new += s2 * s2
        W += 0.5 * dt * (pw_old + pw_new)
        pw_old = pw_new
        if nl:
            pe_new = 0.0
            for q in range(nl):
                sq = 0.0
                sq += b[q, 0] * w0
                sq += b[q, 1] * w1
                sq += b[q, 2] * w2
                pe_new += sq * P[step, q]
            E += 0.5 * dt * (pe_old + pe_new)
            pe_old = pe_new
        left -= 1
        if left == 0:
            left = every
            out_x[io, 0] = x0
            out_v[io, 0] = w0
            if n > 1:
                out_x[io, 1] = x1
                out_v[io, 1] = w1
            if n > 2:
                out_x[io, 2] = x2
                out_v[io, 2] = w2
            out_W[io] = W
            if nl:
                out_E[io] = E
            io += 1
    x[0], x[1], x[2] = x0, x1, x2
    vh[0], vh[1], vh[2] = v0, v1, v2
    return W, pw_old, io, E, pe_old
