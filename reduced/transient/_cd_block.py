"""The central-difference ringdown in blocks of steps: the modal recurrence of :mod:`reduced.transient._cd_modal`
jumped up to ``BLOCK_MAX`` steps at a time while no stop opens or closes (free, frictionless systems; issue 28).

Between two switches of the stops the step of :func:`reduced.transient._cd_modal.cd_modal` is affine in its state:
with s = (z_n, zd_{n+1/2}, 1) and the closed stops fixed (each adding k (B x - offset) to the force),
s_{n+1} = A_c s_n, A_c the one-step map of contact state c (a (2n + 1) x (2n + 1) matrix a state; a closed stop's
constant enters through the last column). So from s_k, with P_j = A_c^j, what the next mb steps need is one row of
a matrix applied to s_k each, all independent dot products: no chain of sums each waiting for the last, which is
what bounds the step-by-step kernel (results/performance/README.md, the roofline):

- the stop rows at steps k+1 .. k+mb, Bu P_j[:n] (nu mb rows): the block holds while every stop is closed or open
  as in c, by the stepping kernel's rule side (B x - offset) > 0 (as bounds lo <= g <= hi, the same rule exactly);
- the state after L steps, P_L[:2n], its mean velocity (P_{L-1} + P_L)[n:2n] / 2 and the stop rows there and at
  the next step, Bu P_L[:n] and Bu (P_L[:n] + dt P_L[n:2n]) (2 nu rows), for the lengths L the held steps are
  jumped in (every length up to mb, or mb and the powers of two below it for a large form);
- the dissipated work from the scheme's discrete energy balance (:func:`cd_block`): a short sum over the modes
  a block, the closed stops' terms from those stop rows (issue 28, session 14: no sums over the coordinates).

The contact state tried is the next step's as the last block's stop rows show it (else the first step's, from
the state); when a stop leaves it at step t + 1 of the
block, the t steps that held are jumped and the next block starts at the switch; a switch at the first step is one
step of ``cd_modal`` itself (the same rules, the same code). Blocks end on output samples (an interval of
``every`` steps is covered by blocks of at most mb), so a sample is a block's end state. The products A_c^j are
rounded differently from j steps, so a run equals the stepping kernel's to round-off, not bit for bit
(tests/test_explicit_block.py): on the chaotic reduced beam the two part after a while, as the modal and the
physical kernels do. The stability limit is the stepping scheme's: it is the same recurrence.
"""

from __future__ import annotations

import itertools

import numba as nb
import numpy as np

from reduced.transient._cd_modal import cd_modal

BLOCK_MAX = 25  # steps a block at most (the rom-impulse run's steps between samples; longer blocks fail more)
BLOCK_MIN = 4  # fewer steps a block than this save nothing; such runs step
MAX_STATES = 32  # contact states (products of each stop row's) a form holds at most
EVERY_LENGTH_BYTES = 16 << 20  # a form of every block length while its tables fit in this, else powers of two
_FORMS: dict = {}  # the last block form, keyed by its model, stops, step and block


def block_steps(every: int) -> int:
    """Steps of the longest block: min(every, BLOCK_MAX), or 0 when ``every`` (steps between samples) is below
    BLOCK_MIN.

    Parameters
    ----------
    every : int
        Steps between output samples.

    Returns
    -------
    int
        The longest block's steps, 0 for none.
    """
    return min(every, BLOCK_MAX) if every >= BLOCK_MIN else 0


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


def block_lengths(mb: int, every_length: bool = False) -> np.ndarray:
    """The block lengths a kernel tries, longest first: mb and the powers of two below it (steps), or with
    ``every_length`` all of mb, mb - 1, ..., 1.

    Every length lets the kernel jump the t steps that held before a switch, and the rest of an output interval
    after it, as one block each: the powers of two need one a set bit of t (a check and a jump each, for the
    rest), issue 28.

    Parameters
    ----------
    mb : int
        Steps of the longest block.
    every_length : bool
        All lengths from mb down to 1.

    Returns
    -------
    ndarray
        The lengths (int64).
    """
    if every_length:
        return np.arange(mb, 0, -1, dtype=np.int64)
    return np.array([mb] + [1 << i for i in range(mb.bit_length() - 1, -1, -1) if 1 << i < mb], np.int64)


def block_form(mats: tuple, om2: np.ndarray, offset: np.ndarray, side: np.ndarray, k: np.ndarray, dt: float,
               mb: int) -> dict | None:
    """The block kernel's arrays for the modal form ``mats`` (``modal_form(...)["mats"]``, ``om2`` its squared
    frequencies), the stops and mb steps the longest block; None when the stop rows can show more than
    ``MAX_STATES`` contact states together. Kept for the last (mats, stops, dt, mb) asked for.

    Parameters
    ----------
    mats : tuple
        The modal kernel's arrays.
    om2 : ndarray
        rad^2/s^2, the open-gap modes' squared frequencies.
    offset, side, k : ndarray
        The stops: m, +1 / -1, N/m.
    dt : float
        s, the step.
    mb : int
        Steps of the longest block.

    Returns
    -------
    dict or None
        ``Ls`` the block lengths (:func:`block_lengths`: every length while the tables take at most
        ``EVERY_LENGTH_BYTES``, else the powers of two); ``TG`` (n_lengths, n_states, 2n + 1, RG): per length L
        and contact state the stop rows of each step (nu L of them, row u L + t the row u at step t + 1, zero
        rows up to ``RGL[length]``, a multiple of 8), stored column by column; ``TS`` (n_lengths, n_states,
        2n + 1, 3n + 2 nu rounded up to a multiple of 8) the end state, its mean velocity and the stop rows at the
        end and at the next step, likewise;
        ``LH`` (n_states, nu, 2) each state's bounds of each stop row; ``lut`` (2^m,) the state of a closed-stop
        mask (-1 where none); ``masks`` (n_states,); ``om2``.
    """
    key = (tuple(np.asarray(x).tobytes() for x in mats), offset.tobytes(), side.tobytes(), k.tobytes(), dt, mb)
    if key in _FORMS:
        return _FORMS[key]
    dtgom2, _alpha, _dtg, _d, _UT, *_rest, Bu, _dtGBu, umap = mats
    n, nu, m = dtgom2.shape[0], Bu.shape[0], offset.shape[0]
    rows_of = [np.flatnonzero(umap == u) for u in range(nu)]
    per_row = [_row_states(offset, side, rows_of[u]) for u in range(nu)]
    if m > 16 or np.prod([len(r) for r in per_row]) > MAX_STATES:
        return None
    masks = [sum(c) for c in itertools.product(*per_row)]
    ns = 2 * n + 1
    rg = -(-(nu * mb) // 8) * 8
    every_length = mb * len(masks) * ns * (rg + 3 * n) * 8 <= EVERY_LENGTH_BYTES
    Ls = block_lengths(mb, every_length)
    RGL = np.array([-(-(nu * L) // 8) * 8 for L in Ls], np.int64)
    TG = np.zeros((len(Ls), len(masks), ns, RGL.max()))
    TS = np.zeros((len(Ls), len(masks), ns, -(-(3 * n + 2 * nu) // 8) * 8))
    for ic, mask in enumerate(masks):
        A = step_map(mats, offset, k, dt, mask)
        Ps = [np.eye(ns)]  # A^j, j = 0 .. mb, each the product of the one before (the same bits for any length)
        for _ in range(mb):
            Ps.append(A @ Ps[-1])
        rows = [Bu @ P[:n] for P in Ps]
        for il, L in enumerate(Ls):
            for j in range(1, L + 1):
                TG[il, ic, :, np.arange(nu) * L + j - 1] = rows[j]
            TS[il, ic, :, :3 * n + 2 * nu] = np.vstack([Ps[L][:2 * n], 0.5 * (Ps[L - 1][n:2 * n] + Ps[L][n:2 * n]),
                                                        rows[L], Bu @ (Ps[L][:n] + dt * Ps[L][n:2 * n])]).T
    LH = np.array([[_bounds(offset, side, rows_of[u], mask) for u in range(nu)] for mask in masks])
    lut = np.full(1 << m, -1, np.int64)
    lut[masks] = np.arange(len(masks))
    form = {"Ls": Ls, "RGL": RGL, "TG": TG, "TS": TS, "LH": LH, "lut": lut,
            "masks": np.array(masks, np.int64), "om2": np.ascontiguousarray(om2, dtype=float), "mb": mb}
    _FORMS.clear()
    _FORMS[key] = form
    return form


KEYS = ("Ls", "RGL", "TG", "TS", "LH", "lut", "masks", "om2")  # the form's arrays cd_block takes, in order
CARRY = 6  # carry[:CARRY]: set, the last block's state, the next one's, E and its modal part at its end, W + dt p / 2


def new_carry(nu: int) -> np.ndarray:
    """A run's carry of :func:`cd_block` from call to call, not yet set: (CARRY + 2 nu,) zeros (the last block's
    stop rows at its end and at the next step after the first CARRY).

    Parameters
    ----------
    nu : int
        Distinct stop rows.

    Returns
    -------
    ndarray
        The carry (float64).
    """
    return np.zeros(CARRY + 2 * nu)


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def cd_block(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, Ls, RGL, TG, TS, LH, lut, masks, om2,
             PhiT, carry, offset, side, k, z, zd, dt, n_steps, every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P,
             out_E, E, pe_old):
    """Advance n_steps as :func:`reduced.transient._cd_modal.cd_modal` (same arguments and returns, with the block
    form's arrays ``KEYS`` after the modal arrays) in blocks where the contact state holds. Each output interval
    (``every`` steps) is covered greedily: the longest length of Ls that fits, the contact state that of its first
    step; when a stop leaves that state at a block's step t + 1, the t steps before it are known to hold and are
    jumped without a check (as one block when the form has every length, else longest lengths first), and the
    next block's state is found, not tried (it is not that one); when at its first step (a switch there), that
    step is one step of ``cd_modal``. Needs n_steps % every == 0 and no loads (else it steps throughout);
    ``a`` = U^T zd on exit.
    Unlike ``cd_modal`` it stores the samples in physical coordinates, x = Phi z and v = Phi zd (PhiT = Phi^T,
    :func:`_physical_rows`): in the kernel, a sample's two products cost less than a pass over the buffers after.
    What the blocks carry from one to the next (the last one's contact state and energy, the next one's state
    read off its rows, W + dt p_n / 2) is kept in ``carry`` (:func:`new_carry`) from call to call, so that the
    samples are the same bits however a run is cut into calls.

    Long because it is one numba loop over blocks whose branches (check, jump, one step) share the carried state;
    the matrix-vector products and the energy sums are helpers, called once a block, not a step.

    The work is carried as Wp = W + dt p_n / 2: over L steps in one contact state it grows by
    dt (p_{k+1} + ... + p_{k+L}) = E(s_k) - E(s_{k+L}), the scheme's discrete energy balance (exact for the
    recurrence: multiply its step by the mean velocity) with E(s) = (|zd|^2 + z^T om2 (z + dt zd)
    + sum over closed stops k (g(z + dt zd) - offset) (g(z) - offset)) / 2, g the stop's row. The mean velocity and
    p_n are formed at a sample and before a step of ``cd_modal``, from the last block's start. A block's E at its
    end is its modal part plus the closed stops' terms from the end-state table's stop rows (g at z and at
    z + dt zd); the next block's E at its start is that one when the contact state holds, else the same modal part
    with the new state's stop terms from those rows; only at a run's start and after a step of ``cd_modal`` is
    E formed from the state itself (:func:`_stop_energy_of`).

    Parameters
    ----------
    dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap : ndarray or float
        The modal kernel's arrays.
    Ls, RGL, TG, TS, LH, lut, masks, om2 : ndarray
        The block form (om2 in rad^2/s^2).
    PhiT : ndarray
        (n, n) Phi^T, the open-gap modes transposed (C-contiguous).
    carry : ndarray
        (CARRY + 2 nu,) the blocks' carry, :func:`new_carry` before a run's first call; changed in place.
    offset, side, k, z, zd, dt, n_steps, every, out_x, out_v, out_W, W, pw_old, i0, a, bm, P, out_E, E, pe_old
        As ``cd_modal`` (dt in s, W in J).
    """
    n = z.shape[0]
    if bm.shape[0] or n_steps % every:
        W, pw_old, io, E, pe_old = cd_modal(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap, offset,
                                            side, k, z, zd, dt, n_steps, every, out_x, out_v, out_W, W, pw_old, i0,
                                            a, bm, P, out_E, E, pe_old)
        for r in range(i0, io):
            _physical_rows(PhiT, out_x, out_v, r)
        carry[0] = 0.0  # a block after these steps starts afresh
        return W, pw_old, io, E, pe_old
    nu = Bu.shape[0]
    p = UT.shape[0]
    n2 = 2 * n
    y = np.empty(TG.shape[3])
    st = np.empty(n2 + 1)
    RS = TS.shape[3]
    nxt = np.empty(RS)  # the block's end state, its mean velocity and its stop rows now and at the next step
    for i in range(n):
        st[i] = z[i]
        st[n + i] = zd[i]
    st[n2] = 1.0
    zs = st[:n]
    zds = st[n:n2]
    Wp = W + 0.5 * dt * pw_old  # W + dt p_n / 2
    jumped = False  # the last advance was a block (p_n not formed yet)
    guess = -1  # the next block's contact state as the last block's rows show it, tried first
    last = -1  # the last block's contact state (-1 after a step of cd_modal)
    e_end = 0.0  # E of the state in contact state last (when last >= 0)
    em_end = _modal_energy(st, om2, dt)  # its modal part (without the stops'); here the start state's
    if carry[0]:  # as the last call left them
        last, guess, e_end, em_end, Wp = int(carry[1]), int(carry[2]), carry[3], carry[4], carry[5]
        for r in range(2 * nu):
            nxt[3 * n + r] = carry[CARRY + r]
    known = 0  # steps ahead known to stay in contact state ck
    ck = 0
    io = i0
    for _ in range(n_steps // every):
        pos = 0
        while pos < every:
            lim = every - pos
            if known:
                c = ck
                lim = min(lim, known)
            elif guess >= 0:
                c = guess
            else:
                c = _state(st, dt, Bu, umap, offset, side, lut)
            li = 0
            while Ls[li] > lim:
                li += 1
            L = Ls[li]
            held = L
            if not known:
                held = 0
                if c >= 0:
                    R = RGL[li]
                    _matvec(TG[li, c], st, y, R, n2)
                    bad = 0
                    for u in range(nu):  # every stop as in the state at every step: the rows within [lo, hi]
                        lo = LH[c, u, 0]
                        hi = LH[c, u, 1]
                        for t in range(L):
                            g = y[u * L + t]
                            bad += (g < lo) | (g > hi)
                    held = L
                    if bad:  # the steps before the first that leaves the state
                        for u in range(nu):
                            lo = LH[c, u, 0]
                            hi = LH[c, u, 1]
                            for t in range(held):
                                g = y[u * L + t]
                                if g < lo or g > hi:
                                    held = t
                                    break
                if held == 0 and guess >= 0:  # not the last block's state at the first step: find it
                    guess = -1
                    continue
                if 0 < held < L:  # jump the steps that hold first
                    known = held
                    ck = c
                    continue
            if held:  # the block holds: jump
                mk = masks[c]
                if last == c:
                    e0 = e_end
                elif last >= 0:  # the last block's end state, its stop rows (in nxt) in this block's state
                    e0 = em_end + _stop_energy(nxt, 3 * n, nu, umap, offset, k, mk)
                else:  # from the state itself, as at a call's start (em_end: its modal part)
                    e0 = em_end + _stop_energy_of(st, dt, Bu, umap, offset, k, mk)
                _matvec(TS[li, c], st, nxt, RS, n2)
                em_end = _modal_energy(nxt, om2, dt)
                e_end = em_end + _stop_energy(nxt, 3 * n, nu, umap, offset, k, mk)
                Wp += e0 - e_end
                for col in range(n2):
                    st[col] = nxt[col]
                jumped = True
                guess = _row_state(nxt, 3 * n + nu, umap, offset, side, lut)  # the next step's, from its rows
                last = c
                pos += L
                if known:
                    known -= L
            else:  # the switch is at the first step: one step of cd_modal
                if jumped:
                    W, pw_old = _work(nxt, d, UT, Wp, dt)
                    jumped = False
                for q in range(p):
                    s = 0.0
                    for i in range(n):
                        s += UT[q, i] * zds[i]
                    a[q] = s
                pos += 1
                store = 2  # no sample at this step ...
                if pos == every:
                    store = 1  # ... or one
                W, pw_old, io, E, pe_old = cd_modal(dtgom2, alpha, dtg, d, UT, GUT, hQ, S, Q, h, Bu, dtGBu, umap,
                                                    offset, side, k, zs, zds, dt, 1, store, out_x, out_v, out_W, W,
                                                    pw_old, io, a, bm, P, out_E, E, pe_old)
                if store == 1:  # the sample cd_modal stored, in modal coordinates
                    _physical_rows(PhiT, out_x, out_v, io - 1)
                Wp = W + 0.5 * dt * pw_old
                guess = -1
                last = -1
                em_end = _modal_energy(st, om2, dt)
        if jumped:  # the sample: the last block's end
            W, pw_old = _work(nxt, d, UT, Wp, dt)
            jumped = False
            for r in range(n):
                out_x[io, r] = 0.0
                out_v[io, r] = 0.0
            for i in range(n):  # x = Phi z, v = Phi (mean velocity), column by column
                zi = st[i]
                vi = nxt[n2 + i]
                for r in range(n):
                    out_x[io, r] += PhiT[i, r] * zi
                    out_v[io, r] += PhiT[i, r] * vi
            out_W[io] = W
            io += 1
    for i in range(n):
        z[i] = st[i]
        zd[i] = st[n + i]
    for q in range(p):  # a = U^T zd on exit, as cd_modal leaves it
        s = 0.0
        for i in range(n):
            s += UT[q, i] * zd[i]
        a[q] = s
    carry[0] = 1.0
    carry[1] = last
    carry[2] = guess
    carry[3] = e_end
    carry[4] = em_end
    carry[5] = Wp
    for r in range(2 * nu):
        carry[CARRY + r] = nxt[3 * n + r]
    return W, pw_old, io, E, pe_old


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _physical_rows(PhiT, out_x, out_v, r):
    """Row r of out_x and out_v from modal to physical coordinates in place: x = Phi z (PhiT = Phi^T), likewise v."""
    n = PhiT.shape[0]
    zx = out_x[r].copy()
    zv = out_v[r].copy()
    for c in range(n):
        out_x[r, c] = 0.0
        out_v[r, c] = 0.0
    for i in range(n):
        for c in range(n):
            out_x[r, c] += PhiT[i, c] * zx[i]
            out_v[r, c] += PhiT[i, c] * zv[i]


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _matvec(Tc, st, y, R, n2):
    """y[:R] = Tc[:, :R]^T st (Tc (n2 + 1, >= R) column by column, st[n2] = 1), four columns a pass (SIMD over
    the rows)."""
    for r in range(R):
        y[r] = Tc[n2, r]
    for col in range(0, n2 - 3, 4):
        s0, s1, s2, s3 = st[col], st[col + 1], st[col + 2], st[col + 3]
        for r in range(R):
            y[r] += Tc[col, r] * s0 + Tc[col + 1, r] * s1 + Tc[col + 2, r] * s2 + Tc[col + 3, r] * s3
    for col in range(n2 - n2 % 4, n2):
        sc = st[col]
        for r in range(R):
            y[r] += Tc[col, r] * sc


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _stop_energy_of(st, dt, Bu, umap, offset, k, mask):
    """The closed stops' part of the scheme's discrete energy E(s) (:func:`cd_block`), sum k (g1 - offset)
    (g0 - offset) / 2 over the stops of ``mask``, from the state st = (z, zd) itself: g0 = Bu z, g1 = Bu (z + dt
    zd) (J per unit modal mass)."""
    n = Bu.shape[1]
    e = 0.0
    j = 0
    while mask:
        if mask & 1:
            u = umap[j]
            g0 = 0.0
            g1 = 0.0
            for i in range(n):
                g0 += Bu[u, i] * st[i]
                g1 += Bu[u, i] * st[n + i]
            g1 = g0 + dt * g1
            e += k[j] * (g1 - offset[j]) * (g0 - offset[j])
        mask >>= 1
        j += 1
    return 0.5 * e


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _modal_energy(nxt, om2, dt):
    """The modal part of the scheme's discrete energy E(s) (:func:`cd_block`), (|zd|^2 + z^T om2 (z + dt zd)) / 2,
    of nxt = (z, zd, ...)."""
    n = om2.shape[0]
    e = 0.0
    for i in range(n):
        zi = nxt[i]
        zdi = nxt[n + i]
        e += zdi * zdi + om2[i] * zi * (zi + dt * zdi)
    return 0.5 * e


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _stop_energy(nxt, at, nu, umap, offset, k, mask):
    """The closed stops' part of E(s) (:func:`_stop_energy_of`), sum k (g1 - offset) (g0 - offset) / 2 over the stops of
    ``mask``, from the stop rows g0 = nxt[at + u] (at z) and g1 = nxt[at + nu + u] (at z + dt zd)."""
    e = 0.0
    j = 0
    while mask:
        if mask & 1:
            u = umap[j]
            e += k[j] * (nxt[at + nu + u] - offset[j]) * (nxt[at + u] - offset[j])
        mask >>= 1
        j += 1
    return 0.5 * e


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _row_state(nxt, at, umap, offset, side, lut):
    """The contact state of the stop rows g = nxt[at + u] by the kernel's rule (-1: none)."""
    mask = 0
    for j in range(offset.shape[0]):
        if side[j] * (nxt[at + umap[j]] - offset[j]) > 0.0:
            mask |= 1 << j
    return lut[mask]


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _state(st, dt, Bu, umap, offset, side, lut):
    """The contact state of the stop rows at the next step, g = Bu (z + dt zd), by the kernel's rule (-1: none)."""
    n = Bu.shape[1]
    mask = 0
    for j in range(offset.shape[0]):
        u = umap[j]
        s = 0.0
        for i in range(n):
            s += Bu[u, i] * (st[i] + dt * st[n + i])
        if side[j] * (s - offset[j]) > 0.0:
            mask |= 1 << j
    return lut[mask]


@nb.njit(cache=True, fastmath={"reassoc", "contract"})
def _work(nxt, d, UT, Wp, dt):
    """(W, p_n) at the end of a block: v = nxt[2n:] its mean velocity, p_n = v^T (diag(d) + U U^T) v,
    W = Wp - dt p_n / 2 (J)."""
    n = d.shape[0]
    pw = 0.0
    for i in range(n):
        v = nxt[2 * n + i]
        pw += d[i] * (v * v)
    for q in range(UT.shape[0]):
        s = 0.0
        for i in range(n):
            s += UT[q, i] * nxt[2 * n + i]
        pw += s * s
    return Wp - 0.5 * dt * pw, pw
