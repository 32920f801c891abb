"""The frc stage's CPU cuts of issue 28 give the numbers the code before them gave, to the bit.

- The load continuation of the first exact orbit (``reduced.periodic.exact_frc._LoadResidual``) is lazy: R at a
  trial point now, the Jacobian's products and the march at P e^h of dR/d ln P only when Newton takes the point.
  Its (R, dR/dy) are checked against the formula it replaced (R at P e^h first, then R and J at P), and the first
  orbit it finds against the orbit Newton finds from it.
- The convergence study's curve at H = ``harmonics`` is the level's own curve with its stability stripped
  (:func:`bearingshaft.stages.frc._without_stability`): checked against the curve continued without stability.
- The analyser's test signs from the monodromy product made once a point equal those it makes itself.
"""

from __future__ import annotations

import math

import numpy as np

from bearingshaft.stages.frc import _without_stability
from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.periodic.exact_frc import LOAD_DIFF, _Analyser, _LoadResidual, find_symmetry, first_orbit
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual
from reduced.periodic.frc import frc

K = (2 * np.pi * 10.0) ** 2  # N/m, m = 1 kg: 10 Hz (the gap oscillator of tests/test_exact_frc.py)
ZETA, RATIO, GAP = 0.02, 20.0, 1e-3


def _oscillator() -> GapSystem:
    return GapSystem(M=np.eye(1), C=2 * ZETA * math.sqrt(K) * np.eye(1), K=K * np.eye(1), dof_names=("x",),
                     **two_sided_stops(np.eye(1), RATIO * K, GAP, ("x",)))


def _two_mass() -> GapSystem:
    """Two masses on springs, the first between stops: a 4-state flow with a monodromy that is not diagonal."""
    M = np.diag([1.0, 0.5])
    Ks = np.array([[2.0 * K, -K], [-K, K]])
    return GapSystem(M=M, C=0.01 * Ks / math.sqrt(K), K=Ks, dof_names=("x1", "x2"),
                     **two_sided_stops(np.array([[1.0, 0.0]]), RATIO * K, GAP, ("x1",)))


def _old_load_call(lr: _LoadResidual, y: np.ndarray):
    """(R, dR/dy) as _LoadResidual.__call__ made them before the change (main at b7c21d3)."""
    h = 1e-7
    Rp = lr._at(y, y[lr.size] + h, jacobian=False)
    R, J = lr._at(y, y[lr.size])
    Jy = J.copy()
    Jy[:, lr.size] = (Rp - R) / h
    return R, Jy


def test_lazy_load_residual_is_the_old_call_to_the_bit():
    s = _oscillator()
    b = np.ones(1)
    P, omega = 40.0, 2 * np.pi * 9.0  # hard contact: a few stops closed per period
    with single_thread_blas():
        res = ShootingResidual(ForcedFlow(s, b, P), 8, 1, GAP, omega)
        lr = _LoadResidual(res, omega, 0.5)
        rng = np.random.default_rng(3)
        assert LOAD_DIFF == 1e-7
        for lp in (0.0, 1.3, math.log(P / 0.5)):  # open, grazing and in contact
            t0, _ = res.times(omega)
            nodes = np.column_stack([np.cos(omega * t0), -omega * np.sin(omega * t0)]) * 0.5 * math.exp(lp) / K * 4
            y = np.append(res.point(nodes, omega)[: res.size] + 1e-3 * rng.standard_normal(res.size), lp)
            R0, J0 = _old_load_call(lr, y)
            R1, J1 = lr(y)
            R2, jac = lr.lazy(y)
            J2 = jac()
            for a, c in ((R0, R1), (R0, R2), (J0, J1), (J0, J2)):
                assert np.array_equal(a, c)
            # dR/d ln P is a difference of two marches: it is not zero in contact (the column is really filled)
            assert np.all(np.isfinite(J0[:, res.size]))
            assert float(np.max(np.abs(J0[:, res.size]))) > 0.0


def test_first_orbit_through_the_load_continuation_closes():
    s = _oscillator()
    b = np.ones(1)
    P, omega = 40.0, 2 * np.pi * 9.0
    with single_thread_blas():
        res = ShootingResidual(ForcedFlow(s, b, P), 8, 1, GAP, omega)
        t0, _ = res.times(omega)
        far = np.zeros((8, 2))  # a guess Newton cannot start from: the load continuation finds the orbit
        far[:, 0] = 50 * GAP
        Y = first_orbit(res, far, omega)
        assert res.flow.amplitude_N == P
        # a periodic orbit of the flow at P (residual at round-off, scaled), in contact (beyond the gap)
        assert float(np.max(np.abs(res(Y)[0]))) < 1e-9
        assert float(np.max(np.abs(res.nodes(Y)[0][:, 0]))) > GAP


def test_curve_without_stability_is_the_curve_continued_without_it():
    s = _oscillator()
    b = np.ones(1)
    with single_thread_blas():
        kw = dict(harmonics="odd", point_rows=np.eye(1), point_names=("x",))
        a = frc(s, b, 2.0, 3.0, 30.0, 5, hill_points=0, **kw)
        c = frc(s, b, 2.0, 3.0, 30.0, 5, stability=False, **kw)
    d = _without_stability(a)
    assert not np.all(a.stable)  # the stability stripped was there: unstable points in contact
    for name in ("freq_hz", "omega", "X", "z", "amplitude_m", "harmonic_amplitude_m", "multipliers", "stable",
                 "hill_index", "hill", "segment"):
        assert np.array_equal(getattr(d, name), getattr(c, name)), name
    assert (d.bifurcations, d.folds, d.status, d.n_rejected, d.x_ref) == (c.bifurcations, c.folds, c.status,
                                                                          c.n_rejected, c.x_ref)
    assert d.stability_wall_s == 0.0 and d.wall_s == a.wall_s
    assert a.multipliers.any()  # the original is untouched
    err = ValueError("no start")
    assert _without_stability(err) is err


def test_signs_from_the_maps_made_once_are_the_signs():
    s = _two_mass()
    b = np.array([0.0, 1.0])
    rng = np.random.default_rng(5)
    res = ShootingResidual(ForcedFlow(s, b, 5.0), 8, 1, GAP, 2 * np.pi * 12.0)
    for half in (False, True):
        an = _Analyser(res, find_symmetry(s, b), False, half, np.eye(2))
        for _ in range(3):
            Js = rng.standard_normal((8, 4, 4))
            assert np.array_equal(an.signs(Js, an.maps(Js)), an.signs(Js))
