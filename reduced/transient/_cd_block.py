"""The central-difference ringdown in blocks of steps: the modal recurrence of :mod:`reduced.transient._cd_modal`
jumped ``mb`` steps at a time while no stop opens or closes (free, frictionless systems).

Between two switches of the stops the step of :func:`reduced.transient._cd_modal.cd_modal` is affine in its state:
with s = (z_n, zd_{n+1/2}, 1) and the closed stops fixed (each adding k (B x - offset) to the force),
s_{n+1} = A_c s_n, A_c the one-step map of contact state c (one (2n + 1) x (2n + 1) matrix a state: a closed
stop adds its constant through the last column). So from s_k, with P_j = A_c^j, every quantity of the next mb
steps is one row of a matrix applied to s_k, all independent dot products (no chain of sums waiting for each
other, which is what bounds the step-by-step kernel: results/performance/README.md, the roofline):

- the stops' rows at steps k+1 .. k+mb, Bu P_j[:n] (nu mb rows): the block holds iff every stop is closed or
  open at each of those steps as in c, the rule of the stepping kernel (side (B x - offset) > 0 closes);
- the state at the block's end, P_mb[:2n], and its mean velocity v_{k+mb} = (P_{mb-1} + P_mb)[n:2n] / 2;
- the dissipated work of the block's steps, the trapezoidal sum dt (p_{k+1} + ... + p_{k+mb-1} + p_{k+mb} / 2)
  with p_{k+j} = v_{k+j}^T Cm v_{k+j} (Cm = diag(d) + U U^T), a quadratic form s^T H s of the block's start
  (one more matrix-vector product), to which 0.5 dt p_k is added as by the stepping kernel.

The contact state c is the one of the first step's stop rows; when a block does not hold (a stop switches
within it), its mb steps are taken by ``cd_modal`` itself (the same rules and the same code). The block ends on
output samples (mb divides the steps between samples), so a sample is the block's end state. The products
A_c^j are rounded differently from j steps, so a run equals the stepping kernel's to round-off, not bit for bit
(tests/test_explicit_block.py): on the chaotic reduced beam the two part after a while, as the modal and the
physical kernels do. The stability limit is the stepping scheme's: it is the same recurrence.
"""

from __future__ import annotations

import itertools

import numba as nb
import numpy as np

from reduced.transient._cd_modal import cd_modal

BLOCK_MAX = 25  # steps a block at most: mb is the largest divisor of the steps between samples up to this
BLOCK_MIN = 4  # fewer steps a block than this save nothing; such runs step
MAX_STATES = 32  # contact states (products of each stop row's) a form holds at most


def block_steps(every: int) -> int:
    """Steps a block: the largest divisor of ``every`` (steps between samples) in [BLOCK_MIN, BLOCK_MAX], or 0.

    Parameters
    ----------
    every : int
        Steps between output samples.

    Returns
    -------
    int
        The block's steps, 0 when no divisor is in range.
    """
    for mb in range(min(every, BLOCK_MAX), BLOCK_MIN - 1, -1):
        if every % mb == 0:
            return mb
    return 0


def _bounds(offset: np.ndarray, side: np.ndarray, stops: np.ndarray, mask: int) -> tuple[float, float]:
    """[lo, hi]: the stop rows g with exactly the stops ``stops`` of ``mask`` closed by the kernel's rule
    side (g - offset) > 0, i.e. g > offset closes an upper stop (side +1), g < offset a lower one (side -1): in
    floating point g - offset > 0 iff g > offset, so the bounds are offsets or their neighbours, and
    lo <= g <= hi is the rule exactly."""
    lo, hi = -np.inf, np.inf
    for j in stops:
        closed = bool(mask >> int(j) & 1)
        if side[j] > 0 and closed:
            lo = max(lo, np.nextafter(offset[j], np.inf))
        elif side[j] > 0:
            hi = min(hi, offset[j])
        elif closed:
            hi = min(hi, np.nextafter(offset[j], -np.inf))
        else:
            lo = max(lo, offset[j])
    return lo, hi


def _row_states(offset: np.ndarray, side: np.ndarray, stops: np.ndarray) -> list[int]:
    """The closed-stop masks a stop row can show (its stops ``stops``): evaluated below, at and between and above
    its offsets, by the kernel's rule side (g - offset) > 0."""
    offs = np.unique(offset[stops])
    span = max(float(np.abs(offs).max()), 1.0)
    probes = np.concatenate([offs, 0.5 * (offs[1:] + offs[:-1]), [offs[0] - span, offs[-1] + span]])
    masks = set()
    for g in probes:
        masks.add(sum(1 << int(j) for j in stops if side[j] * (g - offset[j]) > 0.0))
    return sorted(masks)


def step_map(mats: tuple, offset: np.ndarray, k: np.ndarray, dt: float, mask: int) -> np.ndarray:
    """The (2n + 1) x (2n + 1) affine one-step map of ``cd_modal`` (no loads) on s = (z, zd, 1) with the stops of
    ``mask`` closed, formed by the kernel's own operations on the columns of the identity.

    Parameters
    ----------
    mats : tuple
        ``modal_form(...)["mats"]``.
    offset, k : ndarray
        m and N/m, the stops' offsets and stiffnesses.
    dt : float
        s, the step.
    mask : int
        Bit j set: stop j closed.

    Returns
    -------
    ndarray
        A_c, s_{n+1} = A_c s_n.
    """
    dtgom2, alpha, _dtg, _d, UT, GUT, hQ, S, _Q, h, Bu, dtGBu, umap = mats
    n = dtgom2.shape[0]
    E = np.eye(2 * n + 1)
    z, zd, one = E[:n], E[n:2 * n], E[2 * n]
    a = UT @ zd
    z1 = z + dt * zd
    sB = Bu @ z1
    F = np.zeros_like(sB)
    for j in range(offset.shape[0]):
        if mask >> j & 1:
            F[umap[j]] += k[j] * (sB[umap[j]] - offset[j] * one)
    zn = alpha[:, None] * zd - dtgom2[:, None] * z1 - dtGBu.T @ F
    e = UT @ zn - hQ @ a
    c = S @ e
    zd1 = zn - GUT.T @ (h * a + c)
    return np.vstack([z1, zd1, one])


def block_form(mats: tuple, offset: np.ndarray, side: np.ndarray, k: np.ndarray, dt: float, mb: int) -> dict | None:
    """The block kernel's arrays for the modal form ``mats`` (``modal_form(...)["mats"]``), the stops and mb steps a
    block; None when the stop rows can show more than ``MAX_STATES`` contact states together.

    Parameters
    ----------
    mats : tuple
        The modal kernel's arrays.
    offset, side, k : ndarray
        The stops: m, +1 / -1, N/m.
    dt : float
        s, the step.
    mb : int
        Steps a block.

    Returns
    -------
    dict or None
        ``T`` (n_states, 2n + 1, R8): per contact state the block's R rows (the stop rows of each step,
        nu mb; the end state, 2n; its mean velocity, n; H s, 2n + 1; zero rows up to R8, a multiple of 8),
        stored column by column; ``lut`` (2^m,) the state
        of a closed-stop mask (-1 where none); ``masks`` (n_states,); ``mb``.
    """
    dtgom2, _alpha, _dtg, d, UT, *_rest, Bu, _dtGBu, umap = mats
    n, nu, m = dtgom2.shape[0], Bu.shape[0], offset.shape[0]
    per_row = [_row_states(offset, side, np.flatnonzero(umap == u)) for u in range(nu)]
    if m > 16 or np.prod([len(r) for r in per_row]) > MAX_STATES:
        return None
    masks = [sum(c) for c in itertools.product(*per_row)]
    Cm = np.diag(d) + UT.T @ UT
    ns = 2 * n + 1
    R = nu * mb + 3 * n + ns
    R8 = -(-R // 8) * 8
    T = np.zeros((len(masks), ns, R8))
    for ic, mask in enumerate(masks):
        A = step_map(mats, offset, k, dt, mask)
        rows = np.empty((R, ns))
        H = np.zeros((ns, ns))
        P = np.eye(ns)
        for j in range(1, mb + 1):
            Pn = A @ P
            rows[np.arange(nu) * mb + j - 1] = Bu @ Pn[:n]
            V = 0.5 * (P[n:2 * n] + Pn[n:2 * n])
            H += (dt if j < mb else 0.5 * dt) * (V.T @ Cm @ V)
            P = Pn
        g0 = nu * mb
        rows[g0:g0 + 2 * n] = P[:2 * n]
        rows[g0 + 2 * n:g0 + 3 * n] = V
        rows[g0 + 3 * n:] = 0.5 * (H + H.T)
        T[ic, :, :R] = rows.T
    rows_of = [np.flatnonzero(umap == u) for u in range(nu)]
    LH = np.array([[_bounds(offset, side, rows_of[u], mask) for u in range(nu)] for mask in masks])
    lut = np.full(1 << m, -1, np.int64)
    lut[masks] = np.arange(len(masks))
    return {"T": np.ascontiguousarray(T), "LH": LH, "lut": lut, "masks": np.array(masks, np.int64), "mb": mb}


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def cd_block(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, T, LH, lut, mb, offset, side, k, z, zd, dt,
             n_steps, every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P, out_E, E, pe_old):
    """Advance n_steps as :func:`reduced.transient._cd_modal.cd_modal` (same arguments and returns, with the block
    form T, LH, lut, mb of :func:`block_form` after the modal arrays), mb steps at a time where the contact state
    holds, by ``cd_modal`` where it does not. Needs every % mb == 0 and n_steps % every == 0 (else, and with
    loads, it steps); ``a`` is set from zd before each stepped block.

    Parameters
    ----------
    dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap : ndarray or float
        The modal kernel's arrays.
    T, LH, lut : ndarray
        The block form.
    mb : int
        Steps a block.
    offset, side, k, z, zd, dt, n_steps, every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P, out_E, E, pe_old
        As ``cd_modal`` (dt in s, W in J).
    """
    n = z.shape[0]
    nl = bm.shape[0]
    if nl or mb == 0 or every % mb or n_steps % every:
        return cd_modal(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, offset, side, k, z, zd, dt,
                        n_steps, every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P, out_E, E, pe_old)
    nu = Bu.shape[0]
    m = offset.shape[0]
    p = UT.shape[0]
    R8 = T.shape[2]
    g0 = nu * mb
    h0 = g0 + 3 * n
    y = np.empty(R8)
    st = np.empty(2 * n + 1)
    st[2 * n] = 1.0
    sB = np.empty(nu)
    io = i0
    left = every
    for _ in range(n_steps // mb):
        for u in range(nu):  # the stop rows at the first step: the block's contact state
            s = 0.0
            for i in range(n):
                s += Bu[u, i] * (z[i] + dt * zd[i])
            sB[u] = s
        mask = 0
        for j in range(m):
            if side[j] * (sB[umap[j]] - offset[j]) > 0.0:
                mask |= 1 << j
        c = lut[mask]
        ok = c >= 0
        if ok:
            for i in range(n):
                st[i] = z[i]
                st[n + i] = zd[i]
            Tc = T[c]
            for r in range(R8):
                y[r] = Tc[2 * n, r]
            for col in range(0, 2 * n - 3, 4):  # y = T_c s, four columns a pass (SIMD over the rows)
                s0, s1, s2, s3 = st[col], st[col + 1], st[col + 2], st[col + 3]
                for r in range(R8):
                    y[r] += Tc[col, r] * s0 + Tc[col + 1, r] * s1 + Tc[col + 2, r] * s2 + Tc[col + 3, r] * s3
            for col in range(2 * n - (2 * n) % 4, 2 * n):
                sc = st[col]
                for r in range(R8):
                    y[r] += Tc[col, r] * sc
            for u in range(nu):  # every stop as in the state at every step: the rows within [lo, hi]
                lo = LH[c, u, 0]
                hi = LH[c, u, 1]
                for t in range(mb):
                    g = y[u * mb + t]
                    ok &= (g >= lo) & (g <= hi)
        if ok:
            wq = y[h0 + 2 * n]
            for i in range(n):
                wq += z[i] * y[h0 + i] + zd[i] * y[h0 + n + i]
            pw_new = 0.0
            for i in range(n):
                v = y[g0 + 2 * n + i]
                pw_new += d[i] * (v * v)
            for q in range(p):
                s = 0.0
                for i in range(n):
                    s += UT[q, i] * y[g0 + 2 * n + i]
                pw_new += s * s
            W += 0.5 * dt * pw_old + wq
            pw_old = pw_new
            for i in range(n):
                z[i] = y[g0 + i]
                zd[i] = y[g0 + n + i]
            left -= mb
            if left == 0:
                left = every
                for i in range(n):
                    out_x[io, i] = z[i]
                    out_v[io, i] = y[g0 + 2 * n + i]
                out_W[io] = W
                io += 1
        else:  # a stop switches within the block: its steps one by one
            for q in range(p):
                s = 0.0
                for i in range(n):
                    s += UT[q, i] * zd[i]
                a[q] = s
            left -= mb
            store = mb + 1  # no sample within the block ...
            if left == 0:
                store = mb  # ... or one at its end
            W, pw_old, io, E, pe_old = cd_modal(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, offset,
                                                side, k, z, zd, dt, mb, store, out_x, out_v, out_W, W, pw_old, io, a,
                                                bm, P, out_E, E, pe_old)
            if left == 0:
                left = every
    for q in range(p):  # a = U^T zd on exit, as cd_modal leaves it
        s = 0.0
        for i in range(n):
            s += UT[q, i] * zd[i]
        a[q] = s
    return W, pw_old, io, E, pe_old
