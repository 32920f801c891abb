"""The central-difference ringdown in the modal coordinates of the open-gap system (frictionless systems).

The scheme is that of :func:`reduced.transient.explicit._cd_kernel`,

    x_{n+1} = x_n + dt v_{n+1/2},
    v_{n+3/2} = G (M - dt/2 C) v_{n+1/2} - dt G (K x_{n+1} + B^T f(B x_{n+1}) - b^T p(t_{n+1})),

G = (M + dt/2 C)^-1, written in the coordinates x = Phi z of the undamped open-gap modes
(Phi^T M Phi = I, Phi^T K Phi = Omega^2 = diag(om2)). With C = L L^T (rank r) and
Lm = Phi^T L, Woodbury's identity gives G = Phi (I - Lm S Lm^T) Phi^T, S = dt/2 (I_r + dt/2 Lm^T Lm)^-1,
and the step becomes

    z_{n+1}     = z_n + dt zd_{n+1/2},
    u           = Omega^2 z_{n+1} + Bm^T f(Bm z_{n+1}) - bm^T p(t_{n+1}),
    zd_{n+3/2}  = zd_{n+1/2} - dt u - Lm R2 (a - dt/2 Lm^T u),   a = Lm^T zd_{n+1/2},  R2 = 2 S,

(Bm = B Phi, bm = b Phi): the same recurrence, premultiplied by Phi^T, so the same numbers up to
round-off, at O(n (r + n_rows)) operations a step instead of the 2 n^2 of the dense matrix
products, n_rows the distinct rows of B (stops on one coordinate share a row: a two-sided
clearance is two stops, one row). The stops' forces enter through those rows only.

The dissipated work's rate p_n = v_n^T C v_n = |Lm^T v_n|^2, v_n = (zd_{n-1/2} + zd_{n+1/2}) / 2,
is |(a_{n-1/2} + a_{n+1/2}) / 2|^2, a carried from step to step (each a = Lm^T zd summed in the
same order, so the carried value is the one a new call recomputes: the samples do not depend on how
a run is cut into calls). The kernel stores z and (zd_{n-1/2} + zd_{n+1/2}) / 2; the caller maps
them to x = Phi z, v = Phi zd (:func:`to_physical`).

This form is for systems whose forces are the stops' alone; a system with other state-dependent
forces (friction) keeps the physical-coordinate kernel.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy.linalg import eigh


def modal_form(M: np.ndarray, K: np.ndarray, B: np.ndarray, L: np.ndarray, b: np.ndarray, dt: float) -> dict:
    """The matrices of :func:`_cd_modal` for M, K, stops' rows B (m, n), damping factor L (n, r)
    with C = L L^T, loads' rows b (n_loads, n) and the step dt (s).

    Parameters
    ----------
    M, K : (n, n) ndarray of float
        kg and N/m, symmetric, M positive definite.
    B : (m, n) ndarray of float
        The stops' rows.
    L : (n, r) ndarray of float
        C = L L^T (r = 0 without damping).
    b : (n_loads, n) ndarray of float
        The loads' rows (n_loads = 0 unforced).
    dt : float
        s, the step.

    Returns
    -------
    dict
        ``Phi`` (n, n) the mass-normalised open-gap modes, ``om2`` (n,) rad^2/s^2, ``LmT`` (r, n) = (Phi^T L)^T,
        ``R2`` (r, r) = dt (I + dt/2 Lm^T Lm)^-1, ``Bu`` (n_rows, n) the distinct rows of B Phi, ``umap`` (m,)
        each stop's row in Bu, ``Q`` (n_rows + r, n) = [Bu; Lm^T Omega^2], ``QF`` (r, n_rows) = Lm^T Bu^T,
        ``bm`` (n_loads, n) = b Phi, ``Qp`` (r, n_loads) = Lm^T bm^T.
    """
    om2, Phi = eigh(K, M)
    Lm = Phi.T @ L
    r = Lm.shape[1]
    R2 = dt * np.linalg.inv(np.eye(r) + 0.5 * dt * (Lm.T @ Lm)) if r else np.zeros((0, 0))
    rows, umap = np.unique(B, axis=0, return_inverse=True)
    Bu = rows @ Phi
    bm = b @ Phi
    c = np.ascontiguousarray
    return {"Phi": Phi, "om2": c(om2), "LmT": c(Lm.T), "R2": c(R2), "Bu": c(Bu),
            "umap": c(np.ravel(umap).astype(np.int64)), "Q": c(np.vstack([Bu, Lm.T * om2])), "QF": c(Lm.T @ Bu.T),
            "bm": c(bm), "Qp": c(Lm.T @ bm.T)}


@nb.njit(cache=True, inline="always")
def _dot4(A, q, x, n):
    """sum_i A[q, i] x[i] over n (a multiple of 4) terms as four interleaved partial sums added
    pairwise: a fixed order (the same bits on every machine) with a dependency chain n / 4 + 2 long."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for i in range(0, n, 4):
        s0 += A[q, i] * x[i]
        s1 += A[q, i + 1] * x[i + 1]
        s2 += A[q, i + 2] * x[i + 2]
        s3 += A[q, i + 3] * x[i + 3]
    return (s0 + s1) + (s2 + s3)


@nb.njit(cache=True)
def _cd_modal(om2, LmT, R2, Q, QF, Bu, umap, offset, side, k, z, zd, dt, n_steps, every, out_x, out_v, out_W,
              W, pw_old, i0, Qp, bm, P, out_E, E, pe_old):
    """Advance n_steps of the module's recurrence; z = z_n, zd = zd_{n+1/2} on entry and exit; stores z
    and the mean velocity every ``every`` steps in modal coordinates. Returns (W, pw_old, io, E, pe_old).

    Per step: w = Q z_{n+1} (the stops' distinct rows and Lm^T Omega^2 z, one pass over z), the forces
    F per row, Lm^T u = w_L + QF F - Qp p (no second pass over u), the r x r solve, zd_{n+3/2} and
    its Lm^T (a); every sum over the coordinates runs i = 0 .. n - 1.
    """
    n = z.shape[0]
    r = LmT.shape[0]
    nu = Bu.shape[0]
    nq = Q.shape[0]
    m = offset.shape[0]
    nl = bm.shape[0]
    a = np.empty(r)
    w = np.empty(nq)
    F = np.empty(nu)
    c = np.empty(r)
    zn = np.empty(n)
    for q in range(r):
        a[q] = _dot4(LmT, q, zd, n)
    io = i0
    left = every
    for step in range(n_steps):
        for i in range(n):
            z[i] += dt * zd[i]
        for q in range(nq):
            w[q] = _dot4(Q, q, z, n)
        for u in range(nu):
            F[u] = 0.0
        for j in range(m):
            s = w[umap[j]] - offset[j]
            if side[j] * s > 0.0:
                F[umap[j]] += k[j] * s
        for q in range(r):
            s = w[nu + q]
            for u in range(nu):
                s += QF[q, u] * F[u]
            for l in range(nl):
                s -= Qp[q, l] * P[step, l]
            w[nu + q] = a[q] - 0.5 * dt * s
        for q in range(r):
            s = 0.0
            for p in range(r):
                s += R2[q, p] * w[nu + p]
            c[q] = s
        for i in range(n):
            zn[i] = zd[i] - dt * (om2[i] * z[i])
        for u in range(nu):
            fu = F[u]
            if fu != 0.0:
                for i in range(n):
                    zn[i] -= (dt * fu) * Bu[u, i]
        for l in range(nl):
            pl = P[step, l]
            for i in range(n):
                zn[i] += (dt * pl) * bm[l, i]
        for q in range(r):
            cq = c[q]
            for i in range(n):
                zn[i] -= LmT[q, i] * cq
        pw_new = 0.0
        for q in range(r):
            s = _dot4(LmT, q, zn, n)
            h = 0.5 * (a[q] + s)
            pw_new += h * h
            a[q] = s
        W += 0.5 * dt * (pw_old + pw_new)
        pw_old = pw_new
        if nl:
            pe_new = 0.0
            for l in range(nl):
                s = 0.0
                for i in range(n):
                    s += bm[l, i] * (zd[i] + zn[i])
                pe_new += 0.5 * s * P[step, l]
            E += 0.5 * dt * (pe_old + pe_new)
            pe_old = pe_new
        left -= 1
        if left == 0:
            left = every
            for i in range(out_x.shape[1]):
                out_x[io, i] = z[i]
                out_v[io, i] = 0.5 * (zd[i] + zn[i])
            out_W[io] = W
            if nl:
                out_E[io] = E
            io += 1
        for i in range(n):
            zd[i] = zn[i]
    return W, pw_old, io, E, pe_old


def to_physical(Phi: np.ndarray, out: np.ndarray, lo: int, hi: int) -> None:
    """Rows lo .. hi - 1 of ``out`` (samples of modal coordinates) replaced by Phi times them, in place."""
    if hi > lo:
        out[lo:hi] = out[lo:hi] @ Phi.T
