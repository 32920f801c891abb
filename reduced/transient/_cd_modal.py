"""The central-difference ringdown in the modal coordinates of the open-gap system (frictionless systems).

The scheme is that of :func:`reduced.transient.explicit._cd_kernel`,

    x_{n+1} = x_n + dt v_{n+1/2},
    v_{n+3/2} = G ((M - h C) v_{n+1/2} - dt (K x_{n+1} + B^T f(B x_{n+1}) - b^T p(t_{n+1}))),

h = dt / 2, G = (M + h C)^-1, written in the coordinates x = Phi z of the undamped open-gap modes
(Phi^T M Phi = I, Phi^T K Phi = diag(om2)). There the damping is Cm = Phi^T C Phi, and for the reduced
beam (dashpots at three points, mass-proportional and modal damping: :func:`reduced.models.rom.damping_matrix`)
Cm = diag(d) + U U^T with U of rank p = 3. Woodbury's identity gives

    (I + h Cm)^-1 = Dg^-1 - Dg^-1 U S U^T Dg^-1,   Dg = I + h diag(d),   S = (I_p / h + U^T Dg^-1 U)^-1,

and the step becomes, with a = U^T zd_{n+1/2} carried from step to step,

    z_{n+1}    = z_n + dt zd_{n+1/2},
    w          = Dg^-1 ((1 - h d) zd_{n+1/2} - h U a - dt (om2 z_{n+1} + Bu^T F - bm^T p(t_{n+1}))),
    e          = U^T w,  c = S e,
    zd_{n+3/2} = w - Dg^-1 U c,   a' = e - (U^T Dg^-1 U) c,

O(n (p + rows)) operations a step instead of the physical kernel's 3 n^2 (two n x n products and the
dissipation's |L^T v|^2 with a full-rank L). It is the same recurrence premultiplied by Phi^T M, so the
same numbers up to round-off (not the same bits: the reduced beam is chaotic, so a run differs from the
physical kernel's by round-off amplified; ``ExplicitOptions.coordinates`` chooses). The stops' forces
enter through the distinct rows Bu of B Phi (two for the two tips: an upper and a lower stop share a row).

The dissipated work's rate p_n = v_n^T Cm v_n = sum d v^2 + |(a + a') / 2|^2 with v_n = (zd_{n-1/2} +
zd_{n+1/2}) / 2, the loads' power v_n^T bm^T p(t_n). The kernel stores z and v in modal coordinates; the
caller maps them to x = Phi z (:func:`to_physical`).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy.linalg import eigh

SPLIT_TOL = 1e-14  # largest |off-diagonal error| / max |Cm| of an accepted diag + rank-p split (round-off)
SPLIT_ITER = 3000  # alternating-projection sweeps a rank is given at most
_SPLITS: dict = {}  # the last model's (om2, Phi, split), keyed by the bytes of M, K, C


def diagonal_plus_low_rank(Cm: np.ndarray, max_rank: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(d, U) with Cm = diag(d) + U U^T to round-off (|off-diagonal error| <= SPLIT_TOL max |Cm|), U of the
    lowest rank p <= max_rank that reaches it, or None.

    The low-rank part's diagonal is found by alternating projections (principal-axis factoring): fill
    the diagonal of the off-diagonal part with that of its best rank-p PSD approximation, repeat; a rank
    whose error stops falling (not halved in 300 sweeps) is given up.

    Parameters
    ----------
    Cm : (n, n) ndarray
        A symmetric matrix (the damping in modal coordinates).
    max_rank : int
        The largest rank of U tried.

    Returns
    -------
    tuple of ndarray or None
        ``(d, U)``, d (n,) and U (n, p); None when no rank up to ``max_rank`` reaches round-off.
    """
    n = Cm.shape[0]
    scale = float(np.abs(Cm).max(initial=0.0))
    if scale == 0.0:
        return np.zeros(n), np.zeros((n, 0))
    off = Cm - np.diag(np.diag(Cm))
    # the rank of an off-diagonal block (rows of one half, columns of the other) is the low-rank part's
    sv = np.linalg.svd(off[: n // 2, n // 2:], compute_uv=False)
    p0 = int(np.sum(sv > 1e-12 * scale))
    for p in range(p0, max_rank + 1):
        R = off.copy()
        best, best_at = np.inf, 0
        for it in range(SPLIT_ITER):
            lam, V = np.linalg.eigh(R)
            U = V[:, n - p:] * np.sqrt(np.maximum(lam[n - p:], 0.0)) if p else np.zeros((n, 0))
            W = U @ U.T
            err = float(np.abs(off - (W - np.diag(np.diag(W)))).max()) / scale
            if err <= SPLIT_TOL:
                return np.diag(Cm) - np.diag(W), np.ascontiguousarray(U)
            if err < 0.5 * best:
                best, best_at = err, it
            elif it - best_at > 300:
                break
            R = off + np.diag(np.diag(W))
    return None


def modal_form(M: np.ndarray, K: np.ndarray, C: np.ndarray, B: np.ndarray, b: np.ndarray, dt: float,
               max_rank: int | None = None) -> dict | None:
    """The arrays of :func:`cd_modal` for M, K, C, the stops' rows B (m, n), the loads' rows b (n_loads, n)
    and the step dt (s); None when Phi^T C Phi is no diagonal plus a rank <= ``max_rank`` (default n // 3,
    beyond which the form saves little) to round-off.

    Parameters
    ----------
    M, K, C : (n, n) ndarray
        Mass, stiffness and damping.
    B : (m, n) ndarray
        The stops' rows.
    b : (n_loads, n) ndarray
        The loads' rows.
    dt : float
        s, the step.
    max_rank : int, optional
        The largest rank of the damping's low-rank part (default n // 3).

    Returns
    -------
    dict or None
        ``Phi`` (n, n) the mass-normalised open-gap modes, ``PhiTM`` (n, n) = Phi^T M (x to z), ``om2`` (n,),
        ``d`` (n,), ``U`` (n, p), ``mats`` the kernel's leading arguments, ``a_of`` (p, n) = U^T (zd to a),
        ``bm`` (n_loads, n) = b Phi, ``rank`` p.
    """
    n = M.shape[0]
    key = (M.tobytes(), K.tobytes(), C.tobytes(), max_rank)
    if key not in _SPLITS:  # the modes and the split of the damping, once a model (a few ms)
        om2, Phi = eigh(K, M)
        Cm = Phi.T @ C @ Phi
        _SPLITS.clear()
        _SPLITS[key] = (om2, Phi, diagonal_plus_low_rank(0.5 * (Cm + Cm.T), n // 3 if max_rank is None else max_rank))
    om2, Phi, split = _SPLITS[key]
    if split is None:
        return None
    d, U = split
    h = 0.5 * dt
    dg = 1.0 + h * d
    if np.any(dg <= 0.0):
        return None
    p = U.shape[1]
    ginv = 1.0 / dg
    GU = U * ginv[:, None]
    Q = U.T @ GU
    S = np.linalg.inv(np.eye(p) / h + Q) if p else np.zeros((0, 0))
    rows, umap = np.unique(B, axis=0, return_inverse=True)
    c = np.ascontiguousarray
    Bu = rows @ Phi
    mats = (c(dt * ginv * om2), c((1.0 - h * d) * ginv), c(dt * ginv), c(d), c(U.T), c(GU.T), c(h * Q), c(S), c(Q), h,
            c(Bu), c(dt * Bu * ginv), c(np.ravel(umap).astype(np.int64)))
    return {"Phi": Phi, "PhiTM": Phi.T @ M, "om2": om2, "d": d, "U": U, "mats": mats, "a_of": c(U.T),
            "bm": c(b @ Phi), "rank": p}


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def cd_modal(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, offset, side, k, z, zd, dt, n_steps,
             every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P, out_E, E, pe_old):
    """Advance n_steps of the module's recurrence; z = z_n, zd = zd_{n+1/2}, a = U^T zd_{n+1/2} on entry
    and exit (changed in place); stores z and the mean velocity in modal coordinates every ``every``
    steps. alpha = (1 - h d) / dg, dtg = dt / dg, dtgom2 = dtg om2, UT = U^T, GUT = (Dg^-1 U)^T,
    Q = U^T Dg^-1 U, hQ = h Q, dtGBu = dt Bu Dg^-1. The step's two rank-p updates are one: with
    y = alpha zd - dtg (om2 z + Bu^T F - bm^T p), e = U^T y - h Q a, c = S e, zd' = y - Dg^-1 U (h a + c).
    With loads (bm (n_loads, n) = b Phi, P[i] the loads at the i-th step's end) E accumulates their work.
    Returns (W, pw_old, io, E, pe_old).

    Every loop over the n coordinates is an elementwise update or a dot product, compiled with
    reassociation (SIMD sums): a fixed order for a given build, so the samples do not depend on how a
    run is cut into calls, but not the physical kernel's order (its results are matched to round-off).

    Parameters
    ----------
    dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap : ndarray or float
        The step's arrays, ``modal_form(...)["mats"]`` (named above).
    offset, side, k : ndarray
        The stops: gap offsets, sides and stiffnesses.
    z, zd, a : ndarray
        The state, changed in place.
    dt : float
        s, the step.
    n_steps, every : int
        Steps to take, and a sample every ``every`` steps.
    out_x, out_v, out_W : ndarray
        Sample buffers: modal coordinates, mean velocities, dissipated work.
    W, pw_old : float
        The dissipated work so far and the last step's dissipated power.
    i0 : int
        The first sample row to fill.
    bm, P : ndarray
        The loads in modal coordinates and their values at each step's end.
    out_E : ndarray
        Sample buffer of the loads' work.
    E, pe_old : float
        The loads' work so far and the last step's power.

    Long because it is one numba step loop: a helper called per step costs a call and its arrays' loads
    in the 30-60 ns a step takes (two restructurings that hoisted the sums were slower, measured).
    """
    n = z.shape[0]
    p = UT.shape[0]
    nu = Bu.shape[0]
    m = offset.shape[0]
    nl = bm.shape[0]
    sB = np.empty(nu)
    F = np.empty(nu)
    e = np.empty(p)
    c = np.empty(p)
    zn = np.empty(n)
    io = i0
    left = every
    for step in range(n_steps):
        for i in range(n):
            z[i] += dt * zd[i]
        for u in range(nu):
            s = 0.0
            for i in range(n):
                s += Bu[u, i] * z[i]
            sB[u] = s
            F[u] = 0.0
        for j in range(m):
            s = sB[umap[j]] - offset[j]
            if side[j] * s > 0.0:
                F[umap[j]] += k[j] * s
        for i in range(n):
            zn[i] = alpha[i] * zd[i] - dtgom2[i] * z[i]
        for u in range(nu):
            fu = F[u]
            if fu != 0.0:
                for i in range(n):
                    zn[i] -= dtGBu[u, i] * fu
        for l in range(nl):
            pl = P[step, l]
            for i in range(n):
                zn[i] += (dtg[i] * bm[l, i]) * pl
        for q in range(p):
            s = 0.0
            for i in range(n):
                s += UT[q, i] * zn[i]
            for r in range(p):
                s -= hQ[q, r] * a[r]
            e[q] = s
        for q in range(p):
            s = 0.0
            for r in range(p):
                s += S[q, r] * e[r]
            c[q] = s
        for q in range(p):
            gq = h * a[q] + c[q]
            for i in range(n):
                zn[i] -= GUT[q, i] * gq
        pw_new = 0.0
        for i in range(n):
            v = zd[i] + zn[i]
            pw_new += d[i] * (v * v)
        pw_new *= 0.25
        for q in range(p):
            s = e[q]
            for r in range(p):
                s -= Q[q, r] * c[r]
            hq = 0.5 * (a[q] + s)
            pw_new += hq * hq
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
            for i in range(n):
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
    """Rows lo .. hi - 1 of ``out`` (samples of modal coordinates) replaced by Phi times them, in place.

    Parameters
    ----------
    Phi : (n, n) ndarray
        The modes.
    out : (n_samples, n) ndarray
        The samples, changed in place.
    lo, hi : int
        The rows to convert.

    Returns
    -------
    None
    """
    if hi > lo:
        out[lo:hi] = out[lo:hi] @ Phi.T
