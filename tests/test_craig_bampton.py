"""Craig-Bampton reduction: exactness with all modes, cbcheck identities, upper bounds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from reduced.models.craig_bampton import cb_check, craig_bampton
from reduced.models.discrete import DiscreteParams


def spring_chain(n: int, k: float = 1e4, m: float = 0.1, seed: int = 1):
    """A grounded chain of n masses with random (seeded) stiffness and mass."""
    rng = np.random.default_rng(seed)
    ks = k * (0.5 + rng.random(n + 1))
    K = np.diag(ks[:-1] + ks[1:]) - np.diag(ks[1:-1], 1) - np.diag(ks[1:-1], -1)
    M = np.diag(m * (0.5 + rng.random(n)))
    return K, M


def test_discrete_model_reduced_to_its_contact_dofs_is_exact():
    # treat the 3-DOF model as the "full" model: interface x1, x3; one interior mode (x2)
    sys = DiscreteParams().system()
    T = np.array([[1.0, 0, 0], [0, 0, 1.0]])
    cb = craig_bampton(sys.K, sys.M, T)
    assert cb.nq == 1
    w_full = np.sqrt(sla.eigh(sys.K, sys.M, eigvals_only=True))
    w_red = np.sqrt(sla.eigh(cb.K, cb.M, eigvals_only=True))
    assert np.allclose(w_red, w_full, rtol=1e-12)
    # the interior mode with x1 = x3 = 0 is x2 alone: omega^2 = 4 kappa / L^2 / m2
    p = DiscreteParams()
    assert cb.omega_fixed[0] ** 2 == pytest.approx(4 * p.kappa / p.L**2 / p.m2, rel=1e-12)
    assert all(r["passed"] for r in cb_check(cb, sys.K, sys.M))


def test_all_modes_reproduce_full_eigenvalues_and_fewer_bound_them():
    K, M = spring_chain(40)
    T = np.zeros((2, 40))
    T[0, 5], T[1, 30] = 1.0, 1.0
    full = np.sqrt(sla.eigh(K, M, eigvals_only=True))
    cb_all = craig_bampton(K, M, T)
    assert np.allclose(np.sqrt(sla.eigh(cb_all.K, cb_all.M, eigvals_only=True)), full, rtol=1e-10)
    prev = None
    for nq in (1, 3, 8):
        cb = craig_bampton(K, M, T, n_modes=nq)
        red = np.sqrt(sla.eigh(cb.K, cb.M, eigvals_only=True))
        assert np.all(red >= full[: red.size] * (1 - 1e-12))  # Rayleigh-Ritz upper bounds
        if prev is not None:
            assert np.all(red[:3] <= prev[:3] * (1 + 1e-12))  # more modes, never worse
        prev = red
        assert all(r["passed"] for r in cb_check(cb, K, M))


def test_distributing_interface_row_adds_no_stiffness():
    # interface = average of two DOFs (an RBE3-like patch): a static load through it gives
    # the full model's static response, so the reduction adds no stiffness.
    K, M = spring_chain(20, seed=3)
    T = np.zeros((1, 20))
    T[0, [9, 10]] = 0.5
    cb = craig_bampton(K, M, T, n_modes=4)
    u_full = np.linalg.solve(K, T[0])  # 1 N on u_b is T^T (1 N): half on each patch DOF
    flex_full = T[0] @ u_full
    flex_red = np.linalg.inv(cb.K)[0, 0]
    assert flex_red == pytest.approx(flex_full, rel=1e-12)


def test_sparse_path_matches_dense():
    K, M = spring_chain(60, seed=5)
    T = np.zeros((2, 60))
    T[0, 10], T[1, 50] = 1.0, 1.0
    dense = craig_bampton(K, M, T, n_modes=5)
    from reduced.models import craig_bampton as cbmod

    sparse = cbmod.craig_bampton(sp.csr_matrix(K), sp.csr_matrix(M), T, n_modes=5)
    assert np.allclose(sparse.omega_fixed, dense.omega_fixed, rtol=1e-10)
    assert np.allclose(sparse.frequencies_hz(), dense.frequencies_hz(), rtol=1e-10)


def test_dependent_interface_rows_refused():
    K, M = spring_chain(5)
    with pytest.raises(ValueError, match="linearly dependent"):
        craig_bampton(K, M, np.ones((2, 5)))
