"""Hill's method on a half-wave symmetric orbit splits into the even and the odd harmonics
(:func:`reduced.periodic.forced_stability._parity_blocks`): the two half-size eigenproblems give the
multipliers of the full one to round-off (an independent computation: the full 2n (2H+1) eigenproblem)."""

from __future__ import annotations

import numpy as np
import pytest

import reduced.periodic.forced_stability as fs
from reduced.models.discrete import DiscreteParams
from reduced.periodic.exact_hb import default_root_samples
from reduced.periodic.forced_balance import ForcedBalance


def _balance(H: int, odd: bool) -> ForcedBalance:
    system = DiscreteParams().system()
    b = np.zeros(system.n)
    b[1] = 1.0
    return ForcedBalance(system, b, 1.0, 0.0, H, default_root_samples(H), odd)


def _odd_orbit(fb: ForcedBalance, scale: float, rng) -> np.ndarray:
    """z of an odd-harmonic orbit reaching ``scale`` times the largest stop offset (in contact when > 1)."""
    z = rng.standard_normal(fb.size) / np.repeat(np.arange(1, fb.keep.size + 1), fb.u) ** 1.5
    q = fb.full_q(z)
    return z * scale * float(np.max(np.abs(fb.system.offset))) / float(np.max(np.abs(q).sum(axis=0)))


def _full_hill(fb, z, omega, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(fs, "_hill_blocks", lambda fb, J0, size: [np.arange(size)])
        return fs.forced_hill(fb, z, omega)


@pytest.mark.parametrize(("H", "scale", "f_hz"), [(3, 0.5, 15.0), (5, 1.3, 20.0), (7, 3.0, 30.0), (9, 1.05, 60.0)])
def test_the_parity_split_gives_the_full_hill_multipliers(H, scale, f_hz, monkeypatch):
    fb = _balance(H, odd=True)
    z = _odd_orbit(fb, scale, np.random.default_rng(H))
    w = 2 * np.pi * f_hz
    split = fs.forced_hill(fb, z, w)
    full = _full_hill(fb, z, w, monkeypatch)
    assert split.shape == full.shape == (2 * fb.n,)
    np.testing.assert_allclose(np.sort_complex(split), np.sort_complex(full), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.abs(split), np.abs(full), rtol=1e-9)


def test_the_force_derivative_of_an_odd_orbit_keeps_the_parity():
    """Why the split holds: dF/dX couples harmonics of one parity only (to round-off), an orbit in contact."""
    fb = _balance(7, odd=True)
    z = _odd_orbit(fb, 2.0, np.random.default_rng(1))
    dF = fb.force_jacobian(fb.full_q(z))
    even, odd = fs._parity_blocks(fb.H, fb.n)
    assert np.max(np.abs(dF)) > 0.0
    assert np.max(np.abs(dF[np.ix_(even, odd)])) <= 1e-13 * np.max(np.abs(dF))


def test_an_orbit_with_even_harmonics_breaks_the_parity():
    """The split would be wrong off the half-wave symmetric orbits: their force derivative mixes the parities
    (forced_hill splits only when the balance keeps odd harmonics alone)."""
    fb = _balance(5, odd=False)
    rng = np.random.default_rng(2)
    z = rng.standard_normal(fb.size) * float(np.max(np.abs(fb.system.offset)))
    dF = fb.force_jacobian(fb.full_q(z))
    even, odd = fs._parity_blocks(fb.H, fb.n)
    assert np.max(np.abs(dF[np.ix_(even, odd)])) > 1e-3 * np.max(np.abs(dF))


def test_a_balance_not_marked_for_the_split_is_solved_whole(monkeypatch):
    """A balance whose class does not say its derivative keeps the parity (the friction balance) gets the full
    eigenproblem: the very bits of the unsplit method."""
    fb = _balance(5, odd=True)
    z = _odd_orbit(fb, 1.3, np.random.default_rng(3))
    w = 2 * np.pi * 20.0
    full = _full_hill(fb, z, w, monkeypatch)
    monkeypatch.setattr(ForcedBalance, "HILL_PARITY_SPLIT", False)
    assert fs.forced_hill(fb, z, w).tobytes() == full.tobytes()


def test_the_friction_balance_is_not_split():
    from reduced.periodic.friction_aft import FrictionBalance

    assert ForcedBalance.HILL_PARITY_SPLIT and not FrictionBalance.HILL_PARITY_SPLIT
