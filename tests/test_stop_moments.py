"""Every stop's contact intervals and moments in one kernel call (:func:`reduced.periodic.exact_hb.stop_moments`,
used by :meth:`reduced.periodic.forced_balance.ForcedBalance.contact`) give the bits of the stop-by-stop path it
replaced: :func:`series_extrema` per contact coordinate, :func:`contact_intervals` and ``_moments`` per stop."""

from __future__ import annotations

import numpy as np
import pytest

from reduced.cache import call_numba_kernel
from reduced.models.discrete import DiscreteParams
from reduced.periodic.exact_hb import _moments, contact_intervals, default_root_samples, series_extrema
from reduced.periodic.forced_balance import ForcedBalance


def _contact_stop_by_stop(fb: ForcedBalance, q: np.ndarray):
    """The previous ForcedBalance.contact, verbatim: one kernel call per coordinate and per stop."""
    s = fb.system
    h = 2 * fb.H + 1
    phi = np.zeros((h, fb.u))
    dphi = np.zeros((fb.u, h, h))
    ext = [series_extrema(q[:, r], fb.Nab, fb.N) for r in range(fb.u)]
    intervals = []
    G = np.empty((h, h))
    g = np.empty(h)
    for j in range(s.m):
        r = fb.row_of[j]
        p = s.side[j] * q[:, r]
        p[0] -= s.side[j] * s.offset[j]
        alpha, beta = contact_intervals(p, fb.Nab, fb.N, ext[r])
        intervals.append((alpha, beta))
        if alpha.size == 0:
            continue
        call_numba_kernel(_moments, alpha, beta, fb.H, G, g)
        phi[:, r] += s.k[j] * (G @ q[:, r] - s.offset[j] * g)
        dphi[r] += s.k[j] * G
    return phi, dphi, intervals


def _cases(fb: ForcedBalance, rng) -> list[np.ndarray]:
    """q of every kind: open, grazing, deep, one side only, closed all period, constant, zero."""
    gap = float(np.max(np.abs(fb.system.offset)))
    h = 2 * fb.H + 1
    out = [np.zeros((h, fb.u))]
    const = np.zeros((h, fb.u))
    const[0] = 3.0 * gap  # a constant beyond the stop: closed all period, no extrema
    out.append(const)
    for scale in (0.5, 0.999, 1.001, 1.5, 4.0, 30.0):
        for _ in range(6):
            q = rng.standard_normal((h, fb.u)) / np.arange(1, h + 1)[:, None] ** 1.5
            if fb.odd:
                q[np.setdiff1d(np.arange(h), fb.keep)] = 0.0
            q *= scale * gap / np.max(np.abs(q).sum(axis=0))
            out.append(q)
    shifted = out[-1].copy()
    shifted[0] += 10.0 * gap  # offset past the stop: one side closed all period
    out.append(shifted)
    return out


@pytest.mark.parametrize(("H", "odd"), [(1, False), (5, True), (15, True), (4, False)])
def test_stop_moments_are_the_stop_by_stop_bits(H, odd):
    system = DiscreteParams().system()
    b = np.zeros(system.n)
    b[1] = 1.0
    fb = ForcedBalance(system, b, 1.0, 0.0, H, default_root_samples(H), odd)
    for q in _cases(fb, np.random.default_rng(H)):
        phi0, dphi0, iv0 = _contact_stop_by_stop(fb, q)
        phi1, dphi1, iv1 = fb.contact(q)
        assert phi1.tobytes() == phi0.tobytes()
        assert dphi1.tobytes() == dphi0.tobytes()
        assert len(iv1) == len(iv0)
        for (a0, b0), (a1, b1) in zip(iv0, iv1, strict=True):
            assert a1.tobytes() == a0.tobytes() and b1.tobytes() == b0.tobytes()


def test_a_contact_kernel_change_is_seen():
    """The comparison can fail: a force moved by one ulp is not the same bits."""
    system = DiscreteParams().system()
    b = np.zeros(system.n)
    b[1] = 1.0
    fb = ForcedBalance(system, b, 1.0, 0.0, 3, default_root_samples(3), False)
    q = _cases(fb, np.random.default_rng(0))[-2]
    phi0, _, _ = _contact_stop_by_stop(fb, q)
    phi1, _, _ = fb.contact(q)
    assert np.any(phi0 != 0.0)
    assert np.nextafter(phi1, np.inf).tobytes() != phi0.tobytes()
