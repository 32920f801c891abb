"""Hill's method against Floquet multipliers from shooting on the exact flow."""

from __future__ import annotations

import numpy as np
import pytest

import reduced.periodic.stability as st
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.periodic.backbones import nnm_branch
from reduced.periodic.shooting import conservative, shoot
from reduced.periodic.stability import compare, hill
from reduced.transient.flow import Flow

P = DiscreteParams()
SYS = conservative(P.system())


@pytest.fixture(scope="module")
def nnm2_h15():
    return nnm_branch(SYS, 1, H=15, energy_max_J=200.0)


def _at(b, E):
    i = int(np.argmin(np.abs(np.log(b.energy_J / E))))
    X, w = b.X[i], b.omega[i]
    x, v = b.residual.hb.time_series(X, w)
    orb = shoot(Flow(SYS), x[0], v[0], 2 * np.pi / w, b.energy_J[i])
    return hill(b.residual.hb, X, w), orb


def test_hill_and_floquet_agree_on_an_unstable_orbit(nnm2_h15):
    # NNM 2 near 2.6 J: one real multiplier pair off the unit circle (|mu| ~ 1.7)
    h, orb = _at(nnm2_h15, 2.6)
    assert not orb.stable and not h.stable
    assert 1.3 < orb.max_multiplier < 2.5
    # Hill on 15 harmonics of a kinked force against the exact orbit: the difference is HB's truncation
    # (measured on this orbit: 3.1e-3 at H = 15, 1.4e-3 at H = 25, 1.3e-4 at H = 35), so twice the H = 15 value
    assert h.max_multiplier == pytest.approx(orb.max_multiplier, rel=6e-3)


def test_hill_and_floquet_agree_on_a_stable_orbit(nnm2_h15):
    h, orb = _at(nnm2_h15, 50.0)
    assert orb.stable and h.stable
    # a conservative orbit: all multipliers on the unit circle
    assert np.allclose(np.abs(orb.multipliers), 1.0, atol=1e-4)  # trivial pair splits ~sqrt(eps |Phi|)
    assert np.allclose(np.abs(orb.nontrivial), 1.0, atol=1e-9)
    # Hill: the nontrivial multipliers on the unit circle (the trivial pair, split by the
    # AFT Jacobian's error, is dropped). Hill's problem of a conservative orbit is Hamiltonian (J0
    # symmetric, J1 skew in the weighted Fourier basis), so a simple exponent on the imaginary axis stays
    # there under truncation (it can leave only through a collision): |mu| = 1 to round-off, not to HB's
    # accuracy (measured 1 + 3e-14 at H = 15, 1 + 2e-12 at H = 25)
    assert h.max_multiplier == pytest.approx(1.0, abs=1e-9)


def test_compare_flags_disagreements():
    c = compare(
        [1.0, 2.0, 3.0], [1.0, 2.0, np.nan], [True, False, False], [1.0, 1.0, 1.0], [True, True, True]
    )
    assert list(c.agree) == [True, False, True] and c.n_disagree == 1


# Hill's "shift-invert" solver against the dense eigenvalues of the same problem (an independent
# LAPACK solve), on NNM 2 at H = 15 (companion matrix of 186 rows: the Arnoldi path, not the small-
# problem fallback). Tolerance on lam T: the two solves differ by round-off times Hill's ill-conditioning,
# measured below 1e-9 on rom-fep's 697 points; 1e-7 leaves room for another BLAS.
@pytest.mark.parametrize("E", [0.05, 2.6, 50.0])
def test_shift_invert_keeps_the_dense_exponents(nnm2_h15, E):
    b = nnm2_h15
    i = int(np.argmin(np.abs(np.log(b.energy_J / E))))
    hb, X, w = b.residual.hb, b.X[i], b.omega[i]
    T = 2 * np.pi / w
    J0, J1, J2 = hb.hill_matrices(X, w)
    near = st._nearest_exponents(J0, J1, J2, hb.n, w, strict_zone=False)
    assert near is not None  # the Arnoldi path, certified
    dense = st._dense_eigenvalues(hb, J0, J1, J2, "standard")
    k = 2 * hb.n + st.EXTRA_EIGENVALUES
    nearest = dense[np.argsort(np.abs(dense - st.SHIFT * w))[:k]]  # the k nearest the shift, by the dense solve
    assert near.size == k
    assert max(np.min(np.abs(nearest - x)) for x in near) * T < 1e-7
    for strict in (False, True):
        ref = hill(hb, X, w, solver="standard", strict_zone=strict)
        si = hill(hb, X, w, solver="shift-invert", strict_zone=strict)
        assert si.exponents.size == ref.exponents.size and si.stable == ref.stable
        assert max(np.min(np.abs(si.exponents - x)) for x in ref.exponents) * T < 1e-7
        assert si.max_multiplier == pytest.approx(ref.max_multiplier, rel=1e-7)


def test_shift_invert_falls_back_to_the_dense_solve(nnm2_h15, monkeypatch):
    b = nnm2_h15
    hb, X, w = b.residual.hb, b.X[5], b.omega[5]
    ref = hill(hb, X, w, solver="standard")
    # a disc that cannot certify the selection, and a problem too small for Arnoldi: the dense solve, bit for bit
    monkeypatch.setattr(st, "MU_MISSABLE", 1e300)
    assert st._nearest_exponents(*hb.hill_matrices(X, w), hb.n, w, False) is None
    assert np.array_equal(hill(hb, X, w, solver="shift-invert").exponents, ref.exponents)
    monkeypatch.undo()
    monkeypatch.setattr(st, "DENSE_BELOW", 100)
    assert st._nearest_exponents(*hb.hill_matrices(X, w), hb.n, w, False) is None
    assert np.array_equal(hill(hb, X, w, solver="shift-invert").exponents, ref.exponents)


# hill_screened (the fep study's verdicts off the written points): the same verdict as QZ at every point of
# NNM 2 at H = 15 up to 200 J (stable and unstable stretches), shift-invert's multipliers where the
# verdict is clear, QZ's bits where shift-invert's max |mu| is within SCREEN_MARGIN of 1 + tol.
def test_hill_screened_gives_qz_verdicts(nnm2_h15):
    b = nnm2_h15
    hb = b.residual.hb
    verdicts = set()
    with single_thread_blas():  # as the stage runs it (threaded BLAS on 186 rows is slow on a shared machine)
        for i in range(0, len(b.energy_J), 8):
            qz = hill(hb, b.X[i], b.omega[i])
            sc = st.hill_screened(hb, b.X[i], b.omega[i])
            si = hill(hb, b.X[i], b.omega[i], solver="shift-invert")
            assert sc.stable == qz.stable
            assert np.array_equal(sc.multipliers, si.multipliers)  # clear verdicts here: shift-invert's
            verdicts.add(qz.stable)
    assert verdicts == {True, False}


def test_hill_screened_takes_qz_near_the_threshold(nnm2_h15):
    b = nnm2_h15
    i = int(np.argmin(np.abs(np.log(b.energy_J / 2.6))))  # |mu| ~ 1.7
    hb, X, w = b.residual.hb, b.X[i], b.omega[i]
    with single_thread_blas():
        m = hill(hb, X, w, solver="shift-invert").max_multiplier
        for tol in (m - 1.0, m - 1.0 + 0.5 * st.SCREEN_MARGIN, m - 1.0 - 0.5 * st.SCREEN_MARGIN):  # at the threshold
            sc = st.hill_screened(hb, X, w, tol=tol)
            qz = hill(hb, X, w, tol=tol)
            assert np.array_equal(sc.multipliers, qz.multipliers) and sc.stable == qz.stable
        far = st.hill_screened(hb, X, w, tol=m - 1.0 - 3 * st.SCREEN_MARGIN)  # clear: unstable by shift-invert
    assert not far.stable and far.max_multiplier == m


def test_hill_matrices_j0_is_the_residual_jacobian_bit_for_bit(nnm2_h15):
    # hill_matrices builds J0 = A + dF/dX without R and dR/domega: residual()'s dR/dX, the same bits
    b = nnm2_h15
    hb = b.residual.hb
    for i in (0, len(b.energy_J) // 2, len(b.energy_J) - 1):
        J0, J1, J2 = hb.hill_matrices(b.X[i], b.omega[i])
        assert np.array_equal(J0, hb.residual(b.X[i], b.omega[i])[1])
        assert np.array_equal(J2, np.kron(np.eye(2 * hb.H + 1), hb.M))
