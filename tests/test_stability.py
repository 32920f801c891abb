"""Hill's method against Floquet multipliers from shooting on the exact flow."""

from __future__ import annotations

import numpy as np
import pytest

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
