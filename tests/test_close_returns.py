"""Unstable periodic orbits from close returns of a chaotic stepped sine (reduced.periodic.uncovered,
issue 25; Lathrop & Kostelich 1989), against the library's exact integrator.

The three-mass model at 10 N, 13 Hz (discrete-frc): the stepped sine is chaotic there (response_map.csv).
Three consecutive Poincare samples y_70, y_71, y_72 of the response map's up sweep at 13 Hz (states at
t = n T, full precision: the trajectory through them is the sweep's own) return within 2.5 % after two
periods; multiple shooting from the trajectory through y_70 (16 nodes over 2 T) converges to an
asymmetric 2 T orbit with multipliers ~1e4 (a saddle of the chaotic attractor), continued over
12.98-13.01 Hz (20 steps each way). Checked with the library's integrator (another kernel than the
shooting residual's, :class:`reduced.transient.flow.Flow`):

- the orbit is a fixed point of its map over 2 T and not over T;
- the Floquet multipliers of the family equal the eigenvalues of the map's Jacobian by central finite
  differences of that integrator;
- started a little off the orbit along its unstable direction, the integrator's motion leaves it by the
  largest multiplier each 2 T.
"""

from __future__ import annotations

import functools
import sys
import warnings
from pathlib import Path

import numpy as np

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.uncovered import close_return_families
from reduced.transient.flow import Flow

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_frc_cover import F_ISO, SEED_ISO, X_REF, B, P  # noqa: E402

F = 13.0  # Hz
BAND = (12.5, 22.5)  # Hz: the families' band (13 Hz inside)
SAMPLES = np.array([  # y_70..y_72 of discrete-frc's 10 N up sweep at 13 Hz, [x (m); v (m/s)]
    [0.00017771516918045448, 0.000187239768611045, 0.0001924334473829576, 0.06523942925979404,
     0.007358578722211783, 0.06139865604023897],
    [0.00020601205683148157, 0.00019881385277804655, 0.00021806196646630482, -0.02470509300500614,
     0.0006614171112467974, -0.021420990756093144],
    [0.00017489077708753248, 0.00019395480027269065, 0.00018875788586034223, 0.04795234364469588,
     0.01823311968512588, 0.06135763035441041]])


@functools.cache
def _run():
    s = DiscreteParams().system()
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the context: a period-1 family (the isolated one of tests/test_frc_cover.py, 20 steps; not at 13 Hz)
        ex = exact_frc(s, B, P, *BAND, [(F_ISO, SEED_ISO)], x_ref=X_REF,
                       options=ExactFRCOptions(branch_switching=False, max_steps=20, cover_families=0))
        out = close_return_families(ex, s, B, [(F, "up", SAMPLES)], f_band=BAND, families=1, tries=2,
                                    family_steps=20)
    return s, ex, out


@functools.cache
def _orbit():
    """(system, the 2 T orbit's state at t = 0 exactly at 13 Hz, its multipliers by the shooting residual by
    decreasing modulus, the monodromy's eigenvector of the largest)."""
    s, ex, out = _run()
    fam = ex.families[out[0].family]
    rk = ShootingResidual(ForcedFlow(s, B, P), fam.nodes.shape[1], 2, X_REF, 2 * np.pi * BAND[1])
    Y = shoot_at(rk, fam.nodes[int(np.argmin(np.abs(fam.freq_hz - F)))], 2 * np.pi * F)
    mu, V = np.linalg.eig(rk.monodromy(Y))
    order = np.argsort(-np.abs(mu))
    return s, rk.nodes(Y)[0][0], mu[order], np.real(V[:, order[0]])


def _map(s, y: np.ndarray, periods: int) -> np.ndarray:
    fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, F),)))
    return fl(y[:3], y[3:], periods / F).y


def test_a_close_return_starts_an_unstable_asymmetric_2T_family():
    _, ex, out = _run()
    # the distance is relative to the largest sample given (0.025 among the sweep's 128, 0.031 among these 3)
    assert out[0].period_k == 2 and out[0].distance < 0.05 and out[0].family >= 0, out
    fam = ex.families[out[0].family]
    assert fam.kind == "close_return" and fam.periods == 2 and fam.nodes.shape[1] == 16
    assert fam.freq_hz.min() < F < fam.freq_hz.max()
    assert not fam.stable.any() and np.min(fam.max_multiplier) > 100.0  # a saddle: what chaos shadows
    assert np.min(fam.asymmetry) > 0.01  # x1 != x3 (measured 0.1-0.2)


def test_the_orbit_is_a_fixed_point_over_2T_of_the_library_integrator_not_over_T():
    s, y0, _, _ = _orbit()
    scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * np.pi * F * X_REF)])
    d2 = float(np.max(np.abs(_map(s, y0, 2) - y0) / scale))
    d1 = float(np.max(np.abs(_map(s, y0, 1) - y0) / scale))
    # 2 T: the shooting tolerance (1e-11 of the scaled nodes) times the orbit's multipliers (~1e4), plus the two
    # kernels' round-off; T: the other half of the orbit (measured ~1)
    assert d2 < 1e-6, d2
    assert d1 > 0.1, d1


def test_multipliers_equal_finite_differences_of_the_library_integrator():
    s, y0, mu, _ = _orbit()
    # central differences over 2 T, step 1e-9 of each coordinate's scale: truncation ~ (1e-9)^2 |d3 phi|, round-off
    # ~ 1e-16 |mu| / 1e-9 = 1e-3 of the largest (mu ~ 1e4); no contact switch is moved across by 1e-9
    scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * np.pi * F * X_REF)])
    J = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = 1e-9 * scale[j]
        J[:, j] = (_map(s, y0 + e, 2) - _map(s, y0 - e, 2)) / (2 * e[j])
    lam = np.linalg.eigvals(J)
    lam = lam[np.argsort(-np.abs(lam))]
    # the two real multipliers beyond the unit circle (the saddle's), relative 1e-4
    assert np.allclose(lam[:2], mu[:2], rtol=1e-4), (lam[:2], mu[:2])
    assert abs(mu[0]) > 1e3 and abs(mu[1]) > 1e2


def test_a_perturbed_start_leaves_the_orbit_by_the_largest_multiplier_each_2T():
    s, y0, mu, v = _orbit()
    scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * np.pi * F * X_REF)])
    v = v / float(np.linalg.norm(v / scale))
    # starts off the orbit along the unstable eigenvector of the shooting's monodromy by 1e-9 and 1e-8 of the
    # scale: after 2 T 1e-5 and 1e-4 (still linear to ~1e-4), far above y0's own error (~1e-11, which grows
    # to ~1e-7 after 2 T: the 1 % tolerance); the separation is the largest multiplier times the start's
    y_orbit = _map(s, y0, 2)  # the orbit after 2 T by the same integrator (y0 to its error)
    for eps in (1e-9, 1e-8):
        g = float(np.linalg.norm((_map(s, y0 + eps * v, 2) - y_orbit) / scale)) / eps
        assert abs(g / abs(mu[0]) - 1.0) < 1e-2, (eps, g, mu[0])
    # many periods: from 1e-12 off, the motion stays within 1e-3 of the scale for about ln(1e9) / ln|mu| = 2.2
    # times 2 T and leaves it after 3 (|mu|^3 1e-12 = 1.5): the time a test would see the saddle for
    y = y0 + 1e-12 * v
    dist = []
    for _ in range(4):
        y = _map(s, y, 2)
        dist.append(float(np.linalg.norm((y - y0) / scale)))
    assert dist[1] < 1e-3 < dist[2], dist

