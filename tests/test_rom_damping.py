"""Damping of the reduced model (issue 25): modal damping on every mode with its closed form, and Hill's
method seeing the multipliers of modes far above H Omega (the lightly damped ones the dashpots miss)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.models.rom import MODAL_DAMPING, RomSpec, damping_matrix, modal_ratios
from reduced.periodic.frc import frc
from reduced.periodic.stepped_sine import slowest_decay_rate, stepped_sine

B2 = np.array([0.0, 1.0, 0.0])


def _chain():
    """A free-fixed chain of 3 masses on springs, dashpots only at the middle mass: its antisymmetric
    mode (x1 = -x3, x2 = 0) has a node at the dashpot and is undamped, as the reduced beam's 2029 Hz mode."""
    M = np.diag([0.6, 1.2, 0.6])
    k = 2e6  # N/m: the antisymmetric mode at 411 Hz (the reduced beam's are at 731 and 2029 Hz)
    K = np.array([[2 * k, -k, 0.0], [-k, 3 * k, -k], [0.0, -k, 2 * k]])
    P = np.eye(3)
    return M, K, P


def test_modal_damping_is_its_closed_form_on_every_mode():
    M, K, P = _chain()
    ratios = (0.02, 0.005)  # the first mode 2 %, every higher one 0.5 %
    C = damping_matrix(M, K, P, RomSpec(c_points=0.0, modal_damping=ratios))
    from scipy.linalg import eigh

    w2, Phi = eigh(K, M)
    Cm = Phi.T @ C @ Phi
    target = np.diag(2 * np.array([0.02, 0.005, 0.005]) * np.sqrt(w2))
    assert np.allclose(Cm, target, rtol=0, atol=1e-12 * np.abs(target).max())  # diagonal: classical damping
    assert modal_ratios((0.02, 0.005), 3).tolist() == [0.02, 0.005, 0.005]


def test_the_default_damps_every_mode_the_dashpots_miss():
    M, K, P = _chain()
    dash = np.zeros((3, 3))
    dash[1, 1] = 1.0  # a dashpot at x2 only
    n = 3
    rates = {}
    for md in ((0.0,), (MODAL_DAMPING,)):
        C = damping_matrix(M, K, dash, RomSpec(c_points=4.0, modal_damping=md))
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
        lam = np.linalg.eigvals(A)
        rates[md[0]] = np.sort(-lam.real)
    assert rates[0.0][0] < 1e-9  # the antisymmetric mode: undamped by the dashpot
    from scipy.linalg import eigh

    w = np.sqrt(eigh(K, M, eigvals_only=True))
    # with the default every mode decays at least at zeta omega (the dashpot only adds: C is a sum of
    # positive semi-definite parts; exactly zeta omega on the mode with a node at the dashpot)
    assert rates[MODAL_DAMPING][0] == pytest.approx(MODAL_DAMPING * w[1], rel=1e-9)
    assert np.all(rates[MODAL_DAMPING] >= MODAL_DAMPING * w.min() * (1 - 1e-12))


def test_modal_damping_is_checked():
    for bad in ((), (-0.1,), (1.0,), (float("nan"),), (True,)):
        with pytest.raises(ValueError, match="modal_damping"):
            RomSpec(modal_damping=bad)


@pytest.mark.parametrize("H", [1, 3])
def test_hill_sees_modes_far_above_h_omega(H):
    # a linear orbit: the multipliers are exp(lam_r T) of the damped modes, whatever the forcing. At 30 Hz
    # with H = 1 or 3, H Omega is far below the 700 Hz bending mode, whose exponent has no copy in the first
    # zone |Im lam| <= Omega / 2; the eigenvector centroid picks its unshifted copy (Lazarus & Thomas 2010)
    s = DiscreteParams(gap=1.0).system()
    br = frc(s, B2, 1.0, 30.0, 31.0, H=H, stability=True, hill_points=None)
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(s.M, s.K), -np.linalg.solve(s.M, s.C)]])
    mu = np.exp(np.linalg.eigvals(A) / br.freq_hz[0])
    order = np.lexsort((mu.imag, np.abs(mu)))
    got = br.hill[0][np.lexsort((br.hill[0].imag, np.abs(br.hill[0])))]
    assert np.allclose(got, mu[order], rtol=0, atol=1e-10), (got, mu[order])  # the eigenvalues to round-off


def test_hill_sees_a_nearly_undamped_mode():
    # the reduced beam's trouble in miniature: a mode with a node at every dashpot, zeta 1e-7, far above
    # H Omega. Its multiplier exp(-zeta omega T) = 1 - 3e-5 is what Hill must return (it returned the
    # dashpot-damped modes' 0.79 before)
    M, K, P = _chain()
    dash = np.zeros((3, 3))
    dash[1, 1] = 1.0
    C = damping_matrix(M, K, dash, RomSpec(c_points=4.0, modal_damping=(0.0,)))
    from scipy.linalg import eigh

    w2, Phi = eigh(K, M)
    MPhi = M @ Phi
    C = C + (MPhi * (2e-7 * np.sqrt(w2))) @ MPhi.T  # zeta = 1e-7 on every mode
    stops = two_sided_stops(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), 1e7, 1.0, ("x1", "x3"))
    s = GapSystem(M=M, K=K, C=0.5 * (C + C.T), dof_names=("x1", "x2", "x3"), **stops)
    br = frc(s, B2, 1.0, 10.0, 10.5, H=3, stability=True, hill_points=None)
    n = 3
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, s.K), -np.linalg.solve(M, s.C)]])
    mu = np.sort(np.abs(np.exp(np.linalg.eigvals(A) / br.freq_hz[0])))
    assert mu[-1] > 1 - 1e-4  # the nearly undamped mode
    assert np.allclose(np.sort(np.abs(br.hill[0])), mu, rtol=1e-9)
    assert np.allclose(np.sort(np.abs(br.multipliers[0])), mu, rtol=1e-9)


def test_a_stepped_sine_settles_once_every_mode_is_damped():
    # the reduced model's 0.1 N failure in miniature: a 0.1 N load at x1 moves the antisymmetric mode, which
    # the dashpot at x2 leaves undamped; with the default modal damping every frequency settles in the
    # time set by the slowest rate (4.6 s at most here), below stepped_sine's 10 s limit
    M, K, P = _chain()
    dash = np.zeros((3, 3))
    dash[1, 1] = 1.0
    stops = two_sided_stops(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), 1e7, 1.0, ("x1", "x3"))
    load = np.array([1.0, 0.0, 0.0])
    bare = GapSystem(M=M, K=K, C=damping_matrix(M, K, dash, RomSpec(c_points=4.0, modal_damping=(0.0,))),
                     dof_names=("x1", "x2", "x3"), **stops)
    assert slowest_decay_rate(bare, load) < 1e-9  # undamped to round-off: it would never settle
    s = GapSystem(M=M, K=K, C=damping_matrix(M, K, dash, RomSpec(c_points=4.0)), dof_names=("x1", "x2", "x3"),
                  **stops)
    t_settle = math.log(1e6) / slowest_decay_rate(s, load)
    assert t_settle < 10.0
    ss = stepped_sine(s, load, 0.1, [20.0, 60.0, 120.0], settle_tol=1e-6)
    assert ss.response == ["periodic"] * 3, ss.response
