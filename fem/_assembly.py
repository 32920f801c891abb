"""Scatter of element matrices into CSR, in numba: the pattern once, K and M together.

The block-structured meshes of :mod:`geometry.build` hold a few dozen distinct element
shapes, so the element matrices are few (:func:`fem.solid.assemble_solid`) and assembly is
the scatter of nel x 60 x 60 values (hex20). Building COO triplets and converting them
(``coo_matrix(...).tocsr()``, chunk by chunk with a sparse sum per chunk) moved 24 bytes of
indices per value and sorted them: 5.2 of the 16 s the 112,629-DOF apparatus took. Here the
CSR pattern is built once per row from the elements that touch it, then each row sums its own
entries (rows in parallel, no two threads write one row, and each entry is summed in element
order: the same bits whatever the thread count). Rows and columns are handled by places (a node,
edge or face and its three DOFs, which share their columns): 112,629-DOF apparatus, pattern and
sums 1.2 -> 0.43 CPU s, the same arrays bit for bit.

:func:`product_and_abs` is the product the modal residual test needs, K X and |K| |X| in one
pass over K (the round-off floor of K x without a copy of K's values made positive).

:func:`add` is scipy's canonical sparse sum A + B, bit for bit, with the rows merged in parallel:
the springs', seats' and bungees' entries added to the solid's K (fem.model.build_system).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _dof_elements(ed, n):
    """CSR adjacency DOF -> (element, local index) of the elements that hold it, by element."""
    nl, ne = ed.shape
    count = np.zeros(n + 1, np.int64)
    for e in range(ne):
        for i in range(nl):
            count[ed[i, e] + 1] += 1
    ptr = np.cumsum(count)
    fill = ptr[:-1].copy()
    elem = np.empty(ptr[-1], np.int64)
    loc = np.empty(ptr[-1], np.int64)
    for e in range(ne):
        for i in range(nl):
            r = ed[i, e]
            elem[fill[r]] = e
            loc[fill[r]] = i
            fill[r] += 1
    return ptr, elem, loc


@njit(cache=True)
def _row_cols(ed, r, ptr, elem):
    """Sorted distinct columns of row r."""
    nl = ed.shape[0]
    buf = np.empty((ptr[r + 1] - ptr[r]) * nl, np.int64)
    k = 0
    for a in range(ptr[r], ptr[r + 1]):
        e = elem[a]
        for j in range(nl):
            buf[k] = ed[j, e]
            k += 1
    return np.unique(buf)


@njit(cache=True, parallel=True)
def _pattern(ed, n, ptr, elem):
    counts = np.zeros(n + 1, np.int64)
    for r in prange(n):
        counts[r + 1] = len(_row_cols(ed, r, ptr, elem))
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[-1], np.int32)
    for r in prange(n):
        c = _row_cols(ed, r, ptr, elem)
        indices[indptr[r]:indptr[r + 1]] = c
    return indptr, indices


@njit(cache=True, parallel=True)
def _expand(pindptr, pindices, bs):
    """CSR of the DOFs from the CSR of the places: place q's row and columns become the bs x bs
    blocks of DOFs bs q + c (columns sorted, as the places' are)."""
    npl = len(pindptr) - 1
    indptr = np.zeros(bs * npl + 1, np.int64)
    for q in range(npl):
        w = bs * (pindptr[q + 1] - pindptr[q])
        for c in range(bs):
            indptr[bs * q + c + 1] = indptr[bs * q + c] + w
    indices = np.empty(indptr[-1], np.int32)
    for q in prange(npl):
        lo, hi = pindptr[q], pindptr[q + 1]
        for c in range(bs):
            o = indptr[bs * q + c]
            for a in range(lo, hi):
                for c2 in range(bs):
                    indices[o + bs * (a - lo) + c2] = bs * pindices[a] + c2
    return indptr, indices


@njit(cache=True, parallel=True)
def _fill(edp, bs, shape, Ke, Me, ptr, elem, loc, pindptr, pindices, indptr):
    """K and M data: each place row q sums its elements' blocks in element order (rows bs q + c)."""
    nlp = edp.shape[0]
    npl = len(pindptr) - 1
    kdata = np.zeros(indptr[-1])
    mdata = np.zeros(indptr[-1])
    for q in prange(npl):
        cols = pindices[pindptr[q]:pindptr[q + 1]]
        for a in range(ptr[q], ptr[q + 1]):
            e, i = elem[a], loc[a]
            s = shape[e]
            for jp in range(nlp):
                pos = bs * np.searchsorted(cols, edp[jp, e])
                for c in range(bs):
                    base = indptr[bs * q + c] + pos
                    li = bs * i + c
                    for c2 in range(bs):
                        kdata[base + c2] += Ke[s, li, bs * jp + c2]
                        mdata[base + c2] += Me[s, li, bs * jp + c2]
    return kdata, mdata


def _block_size(ed: np.ndarray, n: int) -> int:
    """bs in (3, 2) when the DOFs come in places of bs, local DOF bs i + c of an element being global
    DOF bs q + c of its place q (scikit-fem's vector elements), else 1."""
    for bs in (3, 2):
        if n % bs == 0 and ed.shape[0] % bs == 0 and np.all(ed[0::bs] % bs == 0) and all(
                np.array_equal(ed[c::bs], ed[0::bs] + c) for c in range(1, bs)):
            return bs
    return 1


def scatter_pair(ed: np.ndarray, shape: np.ndarray, Ke: np.ndarray, Me: np.ndarray, n: int):
    """(indptr, indices, K data, M data) of sum_e Ke[shape[e]] and sum_e Me[shape[e]] over the
    elements, whose global DOFs are ``ed[:, e]`` (n_local, n_elements); CSR, sorted columns.

    Parameters
    ----------
    ed : (n_local, n_elements) ndarray of int
        Global DOF of each local DOF of each element (e.g. 60 x n_elements for hex20).
    shape : (n_elements,) ndarray of int
        Index of each element's matrices in ``Ke`` and ``Me`` (elements of one shape share them).
    Ke, Me : (n_shapes, n_local, n_local) ndarray of float
        Element stiffness (N/m) and mass (kg) matrices, one per distinct shape.
    n : int
        Number of global DOFs (rows and columns).

    Returns
    -------
    indptr : (n + 1,) ndarray of int64
        CSR row pointers, shared by K and M (one pattern).
    indices : (nnz,) ndarray of int32
        Column of each entry, sorted within each row.
    kdata, mdata : (nnz,) ndarray of float
        Values of K and M; each entry is summed in element order (the same bits on any thread count).
    """
    ed = np.ascontiguousarray(ed, dtype=np.int64)
    shape = np.ascontiguousarray(shape, dtype=np.int64)
    # the pattern of the places (nodes, edges, ...) whose bs DOFs share their rows' columns: bs^2 less
    # sorting and bs^2 fewer searches than DOF by DOF, the same CSR and the same sums in the same order
    bs = _block_size(ed, n)
    edp = np.ascontiguousarray(ed[0::bs] // bs)
    ptr, elem, loc = _dof_elements(edp, n // bs)
    pindptr, pindices = _pattern(edp, n // bs, ptr, elem)
    indptr, indices = _expand(pindptr, pindices, bs)
    kdata, mdata = _fill(edp, bs, shape, np.ascontiguousarray(Ke, dtype=np.float64),
                         np.ascontiguousarray(Me, dtype=np.float64), ptr, elem, loc, pindptr, pindices, indptr)
    return indptr, indices, kdata, mdata


@njit(cache=True)
def _merge_upper(r, ap, ai, ax, bp, bi, bx, s, out_i, out_x, write):
    """Row r of the upper triangle (columns >= r) of A + s B, both rows sorted: the merged
    columns and values written from position 0 of out_i / out_x when ``write``; their count."""
    i, ie = ap[r], ap[r + 1]
    j, je = bp[r], bp[r + 1]
    while i < ie and ai[i] < r:
        i += 1
    while j < je and bi[j] < r:
        j += 1
    k = 0
    while i < ie or j < je:
        if j >= je or (i < ie and ai[i] < bi[j]):
            if write:
                out_i[k] = ai[i]
                out_x[k] = ax[i]
            i += 1
        elif i >= ie or bi[j] < ai[i]:
            if write:
                out_i[k] = bi[j]
                out_x[k] = s * bx[j]
            j += 1
        else:
            if write:
                out_i[k] = ai[i]
                out_x[k] = ax[i] + s * bx[j]
            i += 1
            j += 1
        k += 1
    return k


@njit(cache=True, parallel=True)
def _upper_sum(ap, ai, ax, bp, bi, bx, s, n):
    counts = np.zeros(n + 1, np.int64)
    dummy_i = np.empty(0, np.int32)
    dummy_x = np.empty(0)
    for r in prange(n):
        counts[r + 1] = _merge_upper(r, ap, ai, ax, bp, bi, bx, s, dummy_i, dummy_x, False)
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[-1], np.int32)
    data = np.empty(indptr[-1])
    for r in prange(n):
        lo = indptr[r]
        _merge_upper(r, ap, ai, ax, bp, bi, bx, s, indices[lo:], data[lo:], True)
    return indptr.astype(np.int32), indices, data


def upper_sum(A, B, s: float):
    """(indptr, indices, data) of the upper triangle (diagonal included) of A + s B in CSR with
    sorted columns, int32 indices (the layout PARDISO reads), from two CSR matrices of one order.

    Parameters
    ----------
    A, B : (n, n) scipy.sparse matrix
        Converted to CSR with sorted indices (and summed duplicates) if they are not.
    s : float
        The factor of B.

    Returns
    -------
    indptr : (n + 1,) ndarray of int32
    indices : (nnz,) ndarray of int32
        Sorted within each row, each >= its row.
    data : (nnz,) ndarray of float
        A_ij + s B_ij, summed in that order (an entry in one matrix only: A_ij or s B_ij).
    """
    import scipy.sparse as sp

    mats = []
    for X in (A, B):
        X = sp.csr_matrix(X)
        if not X.has_canonical_format:
            X = X.copy()
            X.sum_duplicates()
        mats.append(X)
    A, B = mats
    n = A.shape[0]
    return _upper_sum(A.indptr.astype(np.int64, copy=False), A.indices.astype(np.int32, copy=False),
                      A.data.astype(np.float64, copy=False), B.indptr.astype(np.int64, copy=False),
                      B.indices.astype(np.int32, copy=False), B.data.astype(np.float64, copy=False), float(s), n)


@njit(cache=True)
def _merge_row(r, ap, ai, ax, bp, bi, bx, out_i, out_x, write):
    """Row r of A + B, both rows sorted without duplicates, as scipy's canonical csr_plus_csr makes it:
    a + b where both hold the column, a + 0 or 0 + b where one does, and a zero sum left out. Written from
    position 0 of out_i / out_x when ``write``; returns the count."""
    i, ie = ap[r], ap[r + 1]
    j, je = bp[r], bp[r + 1]
    k = 0
    while i < ie or j < je:
        if j >= je or (i < ie and ai[i] < bi[j]):
            c, v = ai[i], ax[i] + 0.0
            i += 1
        elif i >= ie or bi[j] < ai[i]:
            c, v = bi[j], 0.0 + bx[j]
            j += 1
        else:
            c, v = ai[i], ax[i] + bx[j]
            i += 1
            j += 1
        if v != 0.0:
            if write:
                out_i[k] = c
                out_x[k] = v
            k += 1
    return k


@njit(cache=True, parallel=True)
def _add(ap, ai, ax, bp, bi, bx, n):
    counts = np.zeros(n + 1, np.int64)
    dummy_i = np.empty(0, ai.dtype)
    dummy_x = np.empty(0)
    for r in prange(n):
        counts[r + 1] = _merge_row(r, ap, ai, ax, bp, bi, bx, dummy_i, dummy_x, False)
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[-1], ai.dtype)
    data = np.empty(indptr[-1])
    for r in prange(n):
        lo = indptr[r]
        _merge_row(r, ap, ai, ax, bp, bi, bx, indices[lo:], data[lo:], True)
    return indptr, indices, data


def add(A, B):
    """A + B for two sparse matrices of one shape: the pattern and values of scipy's ``A + B``, bit for bit
    (with int32 indices when they fit, as scipy's own for int32 inputs).

    Rows merged in parallel in numba when both are canonical float64 CSR (sorted columns, no duplicates),
    scipy's own sum otherwise. scipy's canonical sum (csr_plus_csr) leaves out every entry whose sum is
    exactly zero, explicit zeros of A or B included; so does this. 112,629-DOF apparatus, the solid's K
    plus the springs' entries: 0.3-0.5 CPU s in scipy (the merge and a copy of the pruned arrays).

    Parameters
    ----------
    A, B : (n, m) scipy.sparse matrix
        Any units, the same for both.

    Returns
    -------
    scipy.sparse.csr_matrix
        A + B in canonical CSR.
    """
    import scipy.sparse as sp

    A, B = sp.csr_matrix(A), sp.csr_matrix(B)
    if (A.shape != B.shape or A.dtype != np.float64 or B.dtype != np.float64
            or not (A.has_canonical_format and B.has_canonical_format)):
        return (A + B).tocsr()
    idx = np.int64 if max(A.indices.dtype.itemsize, B.indices.dtype.itemsize) > 4 else np.int32
    indptr, indices, data = _add(A.indptr.astype(np.int64, copy=False), A.indices.astype(idx, copy=False), A.data,
                                 B.indptr.astype(np.int64, copy=False), B.indices.astype(idx, copy=False), B.data,
                                 A.shape[0])
    C = sp.csr_matrix((data, indices, indptr), shape=A.shape)
    C.has_canonical_format = True
    return C


@njit(cache=True, parallel=True)
def _product_and_abs(indptr, indices, data, X):
    n, b = len(indptr) - 1, X.shape[1]
    KX = np.zeros((n, b))
    AX = np.zeros((n, b))
    for r in prange(n):
        for p in range(indptr[r], indptr[r + 1]):
            a = data[p]
            c = indices[p]
            for j in range(b):
                KX[r, j] += a * X[c, j]
                AX[r, j] += abs(a) * abs(X[c, j])
    return KX, AX


@njit(cache=True, parallel=True)
def _narrow(indptr, indices, data, X, with_abs):
    """K X (and |K| |X| if ``with_abs``) for X of four columns: the sums in registers (the loops of
    :func:`_product_and_abs` keep them in memory), in storage order as scipy's."""
    n = len(indptr) - 1
    KX = np.empty((n, 4))
    AX = np.empty((n if with_abs else 0, 4))
    for r in prange(n):
        k0 = k1 = k2 = k3 = 0.0
        a0 = a1 = a2 = a3 = 0.0
        for p in range(indptr[r], indptr[r + 1]):
            a = data[p]
            c = indices[p]
            x0, x1, x2, x3 = X[c, 0], X[c, 1], X[c, 2], X[c, 3]
            k0 += a * x0
            k1 += a * x1
            k2 += a * x2
            k3 += a * x3
            if with_abs:
                aa = abs(a)
                a0 += aa * abs(x0)
                a1 += aa * abs(x1)
                a2 += aa * abs(x2)
                a3 += aa * abs(x3)
        KX[r, 0], KX[r, 1], KX[r, 2], KX[r, 3] = k0, k1, k2, k3
        if with_abs:
            AX[r, 0], AX[r, 1], AX[r, 2], AX[r, 3] = a0, a1, a2, a3
    return KX, AX


NARROW = 4  # columns up to which the register kernel (fewer padded with zero columns) beats scipy's product;
# 112,629 DOFs, K X for 4 columns: 0.055 -> 0.029 CPU s, with |K| |X|: 0.067 -> 0.033 (scipy's is
# faster for one column, and at 16 it takes 0.077 s where four passes of the register kernel take 0.15)


@njit(cache=True, parallel=True)
def _wide(indptr, indices, data, X):
    """K X for a C-order X of many columns: rows in parallel, each row's sums over its entries in
    storage order, column by column, as scipy's csr_matvecs (the same bits), which runs on one thread."""
    n, b = len(indptr) - 1, X.shape[1]
    KX = np.zeros((n, b))
    for r in prange(n):
        for p in range(indptr[r], indptr[r + 1]):
            a = data[p]
            c = indices[p]
            for j in range(b):
                KX[r, j] += a * X[c, j]
    return KX


WIDE = 6  # columns from which :func:`_wide` replaces scipy's product: 112,629 DOFs on 2 busy cores (load 7-10), CPU s
# (scipy -> _wide) 0.149 -> 0.106 at 24 columns, 0.112 -> 0.079 at 16, 0.092 -> 0.074 at 12, 0.094 -> 0.067 at 8,
# 0.112 -> 0.101 at 6, 0.062 -> 0.076 at 5; its two numba threads cut the wall time further when a core is free


def _narrow_call(K, X, with_abs):
    b = X.shape[1]
    X4 = np.zeros((X.shape[0], NARROW))
    X4[:, :b] = X
    KX, AX = _narrow(K.indptr, K.indices, K.data.astype(np.float64, copy=False), X4, with_abs)
    return KX[:, :b], AX[:, :b]


def product(K, X: np.ndarray) -> np.ndarray:
    """K X for a CSR matrix K: the numba register kernel for 2 to :data:`NARROW` columns, the numba
    row-parallel kernel :func:`_wide` from :data:`WIDE` columns, scipy's product otherwise (the same
    sums in the same order: the same bits either way).

    Parameters
    ----------
    K : (n, n) scipy.sparse.csr_matrix
        Any units.
    X : (n, b) ndarray of float
        The vectors.

    Returns
    -------
    (n, b) ndarray of float
        K X, in the units of K times those of X.
    """
    b = X.shape[1]
    if b >= WIDE and K.dtype == np.float64 and X.ndim == 2:
        return _wide(K.indptr, K.indices, K.data, np.ascontiguousarray(X, dtype=np.float64))
    if not 2 <= b <= NARROW:
        return K @ X
    return _narrow_call(K, X, False)[0]


def product_and_abs(K, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K X and |K| |X| (entrywise absolute values) in one pass over the CSR matrix K.

    Each row's sums run over its entries in storage order, as scipy's own CSR product does (the
    same bits as ``K @ X``), rows in parallel (the same bits whatever the thread count).

    Parameters
    ----------
    K : (n, n) scipy.sparse.csr_matrix
        Any units (N/m for a stiffness).
    X : (n, b) ndarray of float
        The vectors (C or Fortran order).

    Returns
    -------
    KX, AX : (n, b) ndarray of float
        K X and |K| |X|, in the units of K times those of X.
    """
    if X.shape[1] <= NARROW:
        return _narrow_call(K, X, True)
    X = np.ascontiguousarray(X, dtype=np.float64)
    return _product_and_abs(K.indptr, K.indices, K.data.astype(np.float64, copy=False), X)
