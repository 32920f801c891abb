"""Private numba kernels of the central-difference ringdown for small models (:mod:`reduced.transient.explicit`).

The recurrence is that of :func:`reduced.transient.explicit._cd_kernel`,

    x_{n+1} = x_n + dt v_{n+1/2},
    v_{n+3/2} = A v_{n+1/2} - dt G K x_{n+1} - dt G B^T f(B x_{n+1}) + dt G b^T p(t_{n+1}),

G = (M + dt/2 C)^-1, A = G (M - dt/2 C), with the same operations in the same order, so the same bits.
For n <= 3 DOFs (the paper's three masses) the state and the n x n matrices live in scalar
variables (rows padded with zeros to three: a padded term adds an exact 0), which keeps the whole
step in registers: the generic kernel's arrays cost it a load and a store per term.

Why a padded term changes no bit, signs of zeros included: each sum starts as 0.0 + t, which is never -0.0
(+0 + -0 = +0 in round-to-nearest), and a sum that is not -0.0 is unchanged by adding +-0. So three
columns, not four: a fourth column of zeros for the three masses cost a fifth of the step (4.0e7 against
4.8e7 steps/s, same process, 2 s of ``discrete-impulse``), for the same bits.
"""

from __future__ import annotations

import numba as nb
import numpy as np

SMALL_N = 3  # models up to this many DOFs use _cd_small


@nb.njit(cache=True)
def _cd_small(AT, dtGKT, dtGBT, L, B, offset, side, k, x, vh, dt, n_steps, every, out_x, out_v, out_W,
              W, pw_old, i0, dtGbT, b, P, out_E, E, pe_old):
    """:func:`reduced.transient.explicit._cd_kernel` for n <= 3: AT, dtGKT (3, 3), dtGBT (m, 3), L (3, r),
    B (m, 3), dtGbT and b (L, 3) and x, vh (3,) zero-padded beyond the model's n = out_x.shape[1]
    DOFs. Row i of v_{n+3/2} is 0 + sum_c (A_ic v_c - (dt G K)_ic x_c) - sum_j (dt G B^T)_ij f_j
    + sum_q (dt G b^T)_iq p_q, c = 0 .. 2 in order (the padded c add exact zeros).

    Long because the state and the two 3 x 3 matrices live in scalar variables, in registers, for the
    whole step loop, written out term by term: a helper would pass them through memory, which is
    what costs the generic kernel a load and a store per term (module docstring)."""
    n = out_x.shape[1]
    m = B.shape[0]
    r = L.shape[1]
    nl = b.shape[0]
    x0, x1, x2 = x[0], x[1], x[2]
    v0, v1, v2 = vh[0], vh[1], vh[2]
    a00, a01, a02 = AT[0, 0], AT[1, 0], AT[2, 0]
    a10, a11, a12 = AT[0, 1], AT[1, 1], AT[2, 1]
    a20, a21, a22 = AT[0, 2], AT[1, 2], AT[2, 2]
    g00, g01, g02 = dtGKT[0, 0], dtGKT[1, 0], dtGKT[2, 0]
    g10, g11, g12 = dtGKT[0, 1], dtGKT[1, 1], dtGKT[2, 1]
    g20, g21, g22 = dtGKT[0, 2], dtGKT[1, 2], dtGKT[2, 2]
    io = i0
    left = every
    for step in range(n_steps):
        x0 += dt * v0
        x1 += dt * v1
        x2 += dt * v2
        n0 = 0.0 + (a00 * v0 - g00 * x0)
        n0 += a01 * v1 - g01 * x1
        n0 += a02 * v2 - g02 * x2
        n1 = 0.0 + (a10 * v0 - g10 * x0)
        n1 += a11 * v1 - g11 * x1
        n1 += a12 * v2 - g12 * x2
        n2 = 0.0 + (a20 * v0 - g20 * x0)
        n2 += a21 * v1 - g21 * x1
        n2 += a22 * v2 - g22 * x2
        for j in range(m):
            s = -offset[j]
            s += B[j, 0] * x0
            s += B[j, 1] * x1
            s += B[j, 2] * x2
            if side[j] * s > 0.0:  # an open stop adds exactly 0
                fj = k[j] * s
                n0 -= dtGBT[j, 0] * fj
                n1 -= dtGBT[j, 1] * fj
                n2 -= dtGBT[j, 2] * fj
        for q in range(nl):
            pq = P[step, q]
            n0 += dtGbT[q, 0] * pq
            n1 += dtGbT[q, 1] * pq
            n2 += dtGbT[q, 2] * pq
        w0 = 0.5 * (v0 + n0)
        w1 = 0.5 * (v1 + n1)
        w2 = 0.5 * (v2 + n2)
        v0, v1, v2 = n0, n1, n2
        pw_new = 0.0
        for q in range(r):
            sq = 0.0
            sq += L[0, q] * w0
            sq += L[1, q] * w1
            sq += L[2, q] * w2
            pw_new += sq * sq
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




def pad(a: np.ndarray, rows: int | None, cols: int | None) -> np.ndarray:
    """``a`` zero-padded to (rows, cols) (None: keep that size), C-contiguous.

    Parameters
    ----------
    a : array_like of float
        A vector or a matrix.
    rows, cols : int or None
        Size wanted along each axis, >= the present one (None: keep it); ``cols`` is ignored for
        a vector.

    Returns
    -------
    ndarray of float
        A new C-contiguous array.
    """
    a = np.atleast_1d(a)
    shape = (a.shape[0] if rows is None else rows,) + ((a.shape[1] if cols is None else cols,) if a.ndim == 2 else ())
    out = np.zeros(shape)
    out[tuple(slice(0, s) for s in a.shape)] = a
    return out
