"""The numba kernels of fem._assembly against plain scipy.

- the scatter by places (a node's three DOFs share their rows' columns) gives, bit for bit, the
  matrices of the scatter DOF by DOF (forced by numbering the DOFs so that they form no places);
- K X and |K| |X| in one pass, and K X alone, give scipy's K @ X and |K| @ |X| bit for bit (the same
  sums in the same order), on both sides of the register kernel's width;
- the row merge A + B gives scipy's A + B bit for bit: pattern, values, index types, and the entries
  whose sum is exactly zero (cancellations, explicit zeros of either) left out as scipy leaves them.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from fem._assembly import NARROW, WIDE, _block_size, add, product, product_and_abs, scatter_pair


def _mesh_dofs(nx=3, ny=2, nz=2, bs=3):
    """Element DOF table of a structured grid of 8-node bricks with bs DOFs per node, interleaved
    (local DOF bs i + c of an element is global DOF bs q + c of its node q, as scikit-fem numbers them)."""
    node = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    elems = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                elems.append(node[i:i + 2, j:j + 2, k:k + 2].ravel())
    places = np.array(elems).T  # (8, n_elements)
    ed = (bs * places[:, None, :] + np.arange(bs)[None, :, None]).reshape(8 * bs, -1)
    return ed, bs * node.size


def test_scatter_by_places_equals_the_scatter_dof_by_dof_bit_for_bit():
    ed, n = _mesh_dofs()
    rng = np.random.default_rng(3)
    shape = rng.integers(0, 4, ed.shape[1])
    Ke = rng.standard_normal((4, ed.shape[0], ed.shape[0]))
    Me = rng.standard_normal((4, ed.shape[0], ed.shape[0]))
    assert _block_size(ed, n) == 3
    ip, ix, kd, md = scatter_pair(ed, shape, Ke, Me, n)
    # the same DOFs numbered at random: no places, so the kernel works DOF by DOF
    perm = rng.permutation(n)
    assert _block_size(perm[ed], n) == 1
    jp, jx, kp, mp = scatter_pair(perm[ed], shape, Ke, Me, n)
    for a, b in ((kd, kp), (md, mp)):
        A = sp.csr_matrix((a, ix, ip), shape=(n, n))
        B = sp.csr_matrix((b, jx, jp), shape=(n, n))[perm][:, perm]  # back to the first numbering
        B.sort_indices()
        # every entry is the sum of its element contributions in element order in both: equal bits
        assert np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)
        assert np.array_equal(A.data, B.data)
    # and the matrix is the sum of the element matrices (dense reference, round-off only)
    D = np.zeros((n, n))
    for e in range(ed.shape[1]):
        D[np.ix_(ed[:, e], ed[:, e])] += Ke[shape[e]]
    assert np.abs(sp.csr_matrix((kd, ix, ip), shape=(n, n)).toarray() - D).max() <= 1e-13 * np.abs(D).max()


@pytest.mark.parametrize("b", [1, 2, 3, NARROW, NARROW + 1, WIDE - 1, WIDE, 24])
def test_products_are_scipys_product_and_the_absolute_product(b):
    # widths on both sides of NARROW and WIDE: the register kernel (zero-padded to NARROW columns), scipy's
    # product and the row-parallel kernel
    rng = np.random.default_rng(4)
    K = sp.random(300, 300, density=0.05, random_state=5, format="csr") - sp.eye(300, format="csr")
    K = (K + K.T).tocsr()
    K.sort_indices()
    X = rng.standard_normal((300, b))
    KX, AX = product_and_abs(K, np.asfortranarray(X))
    # scipy sums each row in storage order too: the same bits, not just close
    assert np.array_equal(KX, K @ X)
    assert np.array_equal(product(K, np.asfortranarray(X)), K @ X)
    absK = sp.csr_matrix((np.abs(K.data), K.indices, K.indptr), shape=K.shape)
    assert np.array_equal(AX, absK @ np.abs(X))


def test_row_merge_is_scipys_sum_bit_for_bit_zero_sums_dropped():
    rng = np.random.default_rng(6)
    n = 400
    A = sp.random(n, n, density=0.03, random_state=7, format="csr")
    A.data[::7] = 0.0  # explicit zeros, as the solid's K holds them (exactly zero couplings)
    A.data[1::11] = -0.0
    rows, cols = rng.integers(0, n, 900), rng.integers(0, n, 900)
    vals = rng.standard_normal(900)
    B = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()  # duplicates summed, as build_system's
    # entries of B that cancel entries of A exactly: a zero sum, which scipy leaves out
    Bl = B.tolil()
    r, c = A.nonzero()
    for i in range(0, len(r), 5):
        Bl[r[i], c[i]] = -A[r[i], c[i]]
    B = Bl.tocsr()
    assert A.has_canonical_format and B.has_canonical_format
    C, R = add(A, B), (A + B).tocsr()
    assert C.nnz < A.nnz + B.nnz - 50  # the cancellations and zeros did leave entries out
    for name in ("indptr", "indices", "data"):
        a, b = getattr(C, name), getattr(R, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert np.array_equal(np.signbit(C.data), np.signbit(R.data))
    # a matrix that is not canonical goes to scipy's own sum: still its result
    D = sp.csr_matrix((np.ones(3), np.array([2, 1, 2]), np.array([0, 3] + [3] * (n - 1))), shape=(n, n))
    assert not D.has_canonical_format
    assert np.array_equal(add(D, B).toarray(), (D + B).toarray())
