"""The condensed balance's Omega-free parts made once (:meth:`ForcedBalance._omega_free`) give the bits of the
residual that made them at every call (the previous receptances, verbatim here)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.periodic.exact_hb import default_root_samples
from reduced.periodic.forced_balance import ForcedBalance


def _receptances_each_call(fb, omega, derivative=False, harmonics=None):
    s = fb.system
    n, u = fb.n, fb.u
    k = np.arange(fb.H + 1) if harmonics is None else np.asarray(harmonics)
    Z = (s.K[None] - ((k * omega) ** 2)[:, None, None] * s.M[None]).astype(complex)
    if fb._Cr is not None:
        Z = Z + 1j * (k * omega)[:, None, None] * fb._Cr[None]
    rhs = np.zeros((k.size, n, u + 1), complex)
    rhs[:, :, :u] = fb.U.T[None]
    rhs[k == 1, :, u] = fb.b * fb.amplitude_N * np.exp(1j * math.radians(fb.phase_deg))
    W = np.linalg.solve(Z, rhs)
    if not derivative:
        return W, None
    dZ = (-2.0 * omega * k**2)[:, None, None] * s.M[None] + 0j
    if fb._Cr is not None:
        dZ = dZ + 1j * k[:, None, None] * fb._Cr[None]
    return W, -np.linalg.solve(Z, dZ @ W)


@pytest.mark.parametrize(("H", "odd", "phase"), [(1, False, 0.0), (5, True, 30.0), (8, False, -10.0)])
def test_the_residual_and_receptances_keep_their_bits(H, odd, phase, monkeypatch):
    system = DiscreteParams().system()
    b = np.zeros(system.n)
    b[1] = 1.0
    fb = ForcedBalance(system, b, 2.0, phase, H, default_root_samples(H), odd)
    ref = ForcedBalance(system, b, 2.0, phase, H, default_root_samples(H), odd)
    assert np.array_equal(fb._harmonics_kept, np.unique((fb.keep + 1) // 2))
    rng = np.random.default_rng(H)
    gap = float(np.max(np.abs(system.offset)))
    for f in (5.0, 17.3, 40.0, 123.0):
        w = 2 * np.pi * f
        for harmonics in (None, fb._harmonics_kept):
            for derivative in (False, True):
                new = fb.receptances(w, derivative, harmonics)
                old = _receptances_each_call(ref, w, derivative, harmonics)
                assert new[0].tobytes() == old[0].tobytes()
                assert (new[1] is None and old[1] is None) or new[1].tobytes() == old[1].tobytes()
        z = rng.standard_normal(fb.size) * 2.0 * gap
        with monkeypatch.context() as m:
            m.setattr(ForcedBalance, "receptances", _receptances_each_call)
            old = ref.residual(z, w)
        new = fb.residual(z, w)
        for a, c in zip(new, old, strict=True):
            assert a.tobytes() == c.tobytes()
