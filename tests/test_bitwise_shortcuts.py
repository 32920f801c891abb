"""The speed shortcuts of the exact kernels give the same bits as the paths they shortcut (issue 28).

Each shortcut is an exact rewrite, so each is checked for equality to the last bit against the path it
replaces, run independently: e^{conj(lam) tau} taken as conj(e^{lam tau}) in the march's series sums
(cos is even and sin odd in the C library), the response map's record blocks marched without sampling and
replayed from their segments, the exact integrator without its energy integrals, the shooting residual
marched without its Jacobian, and Newton asking for the Jacobian only at the points it takes. A changed bit
would move a continuation's step path (its files are compared digit for digit with the committed results),
so no tolerance is allowed.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

import reduced.transient.lyapunov as lyapunov
from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual
from reduced.periodic.forced_stability import hb_states
from reduced.periodic.hb import newton
from reduced.periodic.response_map import MapOptions, PointResponse, _defer_after, classify
from reduced.transient._exact_kernels import _exponentials, _series_at
from reduced.transient.exact import integrate_exact
from reduced.transient.integrate import ringdown
from reduced.transient.lyapunov import PeriodMap

PARAMS = DiscreteParams()
SYSTEM = PARAMS.system()
LOAD = PARAMS.point_rows[1]  # x2, as discrete-frc


@nb.njit(cache=True)
def _exp_each(lam, tau):
    """e^{lam_i tau} term by term (the kernels' form before the pairing)."""
    out = np.empty(lam.shape[0], np.complex128)
    for i in range(lam.shape[0]):
        out[i] = np.exp(lam[i] * tau)
    return out


@nb.njit(cache=True)
def _series_each(coef, lam, tau, q, d, dscale, Q2):
    """The march's series sums term by term (the kernels' form before the pairing)."""
    for i in range(lam.shape[0]):
        e = coef[i] * np.exp(lam[i] * tau)
        q += e.real
        d += (lam[i] * e).real
        dscale += abs(e) * abs(lam[i])
        Q2 += abs(e) * abs(lam[i]) ** 2
    return q, d, dscale, Q2


def _exponents(rng) -> np.ndarray:
    """Conjugate pairs as LAPACK orders them (lightly and heavily damped, fast), real ones (a repeated one
    too: two equal reals are not a conjugate pair) and a harmonic load's +-i omega."""
    pairs = [complex(-rng.uniform(0.1, 50.0), rng.uniform(1.0, 4e5)) for _ in range(5)]
    lam = [v for p in pairs for v in (p, p.conjugate())]
    lam += [-3.0 + 0.0j, -3.0 + 0.0j, -700.0 + 0.0j, 2j * np.pi * 37.0, -2j * np.pi * 37.0]
    return np.array(lam)


def test_conjugate_exponentials_are_the_bits_of_each_term():
    rng = np.random.default_rng(5)
    lam = _exponents(rng)
    coef = rng.standard_normal(lam.size) + 1j * rng.standard_normal(lam.size)
    e = np.empty(lam.size, complex)
    for tau in (0.0, 1e-9, 3.7e-6, 1.3e-3, 0.21, 7.9):
        _exponentials(lam, tau, e)
        ref = _exp_each(lam, tau)
        assert np.array_equal(e.view(float), ref.view(float))  # every real and imaginary part, signs of zeros too
        assert _series_at(coef, lam, tau, 0.3, 0.0, 0.0, 0.0) == _series_each(coef, lam, tau, 0.3, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def attractor():
    """The 1 N, 19 Hz period map on its chaotic attractor (contact every period: many segments)."""
    pm = PeriodMap(SYSTEM, LOAD, 1.0, 19.0, rows=np.vstack([PARAMS.point_rows, PARAMS.point_rows[0]
                                                            - PARAMS.point_rows[2]]))
    y = np.zeros(6)
    y[0] = y[2] = 2.6e-4
    return pm, pm.run(y, 150, samples_per_period=0, inner_samples=0).y


@pytest.mark.parametrize("record", [True, False])
def test_deferred_samples_replay_the_sampling_march(attractor, record):
    pm, y = attractor
    W = np.full((6, 1), 0.4)
    kw = dict(tangent=W, samples_per_period=64, inner_samples=8, record_samples=record)
    ref = pm.run(y, 64, **kw)
    lazy = pm.run(y, 64, defer_samples=True, **kw)
    assert lazy.peak is None and lazy.samples is None and lazy.n_events > 64  # in contact: several events a period
    got = pm.sampled(lazy)
    for a, b in ((ref.peak, got.peak), (ref.poincare, got.poincare), (ref.log_growth, got.log_growth),
                 (ref.tangent, got.tangent), (ref.active, got.active)):
        assert np.array_equal(a, b)
    assert (got.samples is None) if not record else np.array_equal(ref.samples, got.samples)
    assert pm.sampled(ref) is ref  # a sampled run is returned as it is


def test_a_record_too_small_is_marched_again(attractor, monkeypatch):
    pm, y = attractor
    monkeypatch.setattr(lyapunov, "REPLAY_SEGMENTS", 1)  # fewer than a period's segments: the record overflows
    kw = dict(samples_per_period=32, inner_samples=4, record_samples=True)
    ref = pm.run(y, 16, **kw)
    lazy = pm.run(y, 16, defer_samples=True, **kw)
    assert lazy.deferred[0][3][0] == -1
    got = pm.sampled(lazy)
    assert np.array_equal(ref.peak, got.peak) and np.array_equal(ref.samples, got.samples)


def test_the_exact_integrator_without_work_gives_the_same_samples(attractor):
    _, y = attractor
    loads = Loads(LOAD[None, :], (Harmonic(1.0, 19.0),))
    n = SYSTEM.n
    ref = ringdown(SYSTEM, y[:n], y[n:], 3 / 19.0, 512 * 19.0, method="exact", loads=loads)
    got = integrate_exact(SYSTEM, y[:n], y[n:], 3 / 19.0, 512 * 19.0, loads=loads, work=False)
    assert ref.stats["n_events"] > 3  # a run in contact
    assert np.array_equal(ref.x, got.x) and np.array_equal(ref.v, got.v)
    assert ref.stats["n_events"] == got.stats["n_events"] and ref.stats["n_march"] == got.stats["n_march"]
    assert np.all(np.isnan(got.dissipated)) and np.all(np.isnan(got.external))  # not integrated: not made up
    assert np.isfinite(ref.energy_balance_error)


def test_the_shooting_residual_without_its_jacobian_is_the_residual(attractor):
    _, y = attractor
    f, S = 19.0, 8
    flow = ForcedFlow(SYSTEM, LOAD, 1.0)
    res = ShootingResidual(flow, S, 1, 1e-4, 2 * np.pi * f, None)
    # nodes off any orbit (a state on the attractor, spread over the period as harmonics would): R != 0
    X = np.zeros((3, SYSTEM.n))
    X[0], X[1] = y[:SYSTEM.n], y[SYSTEM.n:] / (2 * np.pi * f)
    Y = res.point(hb_states(X, 2 * np.pi * f, S), 2 * np.pi * f)
    alone = res.value(Y)
    R, J = res(Y)
    assert np.max(np.abs(R)) > 1e-3 and J.shape == (R.size, R.size + 1)
    assert np.array_equal(alone, R)
    assert res.value(Y) is R  # memoised: not marched again


def test_the_lazy_jacobian_is_the_marched_one(attractor):
    _, y = attractor
    f, S = 19.0, 8
    res = ShootingResidual(ForcedFlow(SYSTEM, LOAD, 1.0), S, 1, 1e-4, 2 * np.pi * f, None)
    X = np.zeros((3, SYSTEM.n))
    X[0], X[1] = y[:SYSTEM.n], y[SYSTEM.n:] / (2 * np.pi * f)
    Y = res.point(hb_states(X, 2 * np.pi * f, S), 2 * np.pi * f)
    R, jac = res.lazy(Y)
    J = jac()
    # the segments' monodromies of the Jacobian against those of the flow's own march of the nodes (another kernel)
    assert np.array_equal(res.last_segment_monodromies(Y), res.segment_monodromies(Y))
    n2 = 2 * SYSTEM.n
    d = res.scale(2 * np.pi * f)
    Js = res.last_segment_monodromies(Y)
    assert np.array_equal(J[:n2, :n2], Js[0] * d[None, :] / d[:, None])  # the first block, as the kernel scales it
    assert np.array_equal(res(Y)[1], J) and np.array_equal(res(Y)[0], R)


def test_newton_asks_for_the_jacobian_only_where_it_steps():
    # arctan from 2: the full Newton step overshoots, so the halving refuses trial points on R alone
    asked, calls = [], []

    def eager(y):
        return np.arctan(y), np.diag(1.0 / (1.0 + y * y))

    def lazy(y):
        at = y.copy()
        calls.append(at)

        def jac():
            asked.append(at)
            return np.diag(1.0 / (1.0 + at * at))
        return np.arctan(y), jac

    y0 = np.array([2.0, -1.7])
    a, b = newton(eager, y0, tol=1e-12), newton(lazy, y0, tol=1e-12)
    assert np.array_equal(a.y, b.y) and a.n_iter == b.n_iter and np.array_equal(a.jacobian, b.jacobian)
    assert abs(a.y).max() < 1e-12  # the root 0
    assert len(asked) == b.n_iter + 1 < len(calls)  # the start and each point taken, none of the refused trials


def _strict(fun):
    """``fun`` without its ``lazy`` method: continue_branch then asks for R and dR/dy together."""
    return lambda y: fun(y)


def test_the_nnm_residual_deferred_is_the_residual():
    """NNMResidual.lazy: R now, dR/dy when asked, the bits of ``res(y)`` (signed zeros too), whatever other
    frequencies the residual was evaluated at in between (A and dA/domega live in buffers shared by calls)."""
    from reduced.periodic.hb import HarmonicBalance, NNMResidual
    from reduced.periodic.shooting import conservative

    system = conservative(SYSTEM)
    rng = np.random.default_rng(3)
    for H in (1, 5):
        hb = HarmonicBalance.for_system(system, H)
        res = NNMResidual(hb, 2 * np.pi * 20.0, 0)
        ys = []
        for k in range(6):
            y = rng.normal(size=res.size) * 1e-2
            y[hb.size] = (1.0 + rng.random()) * (-1.0 if k == 2 else 1.0)
            y[hb.size + 1] = 0.0 if k % 2 else 1e-3 * rng.normal()
            y[hb.size + 2] = -4.0 + 2.0 * rng.random()  # amplitudes up to ~1e-2 m: the stops close
            ys.append(y)
        lazies = [res.lazy(y) for y in ys]  # every R first, the Jacobians after
        for y, (R, jac) in zip(ys[::-1], lazies[::-1], strict=True):
            R0, J0 = res(y)
            assert np.array_equal(R.view(np.int64), R0.view(np.int64))
            assert np.array_equal(jac().view(np.int64), J0.view(np.int64))


def test_an_nnm_branch_continued_lazily_is_the_strict_one():
    """The backbone continued through the lazy residual (Newton's refused trial points without dR/dy) takes
    the same steps, to the bit, as the one continued with R and dR/dy at every trial point."""
    from reduced.periodic.backbones import NNM_STEPS, _nnm_start
    from reduced.periodic.continuation import continue_branch
    from reduced.periodic.shooting import conservative

    res, y0, _ = _nnm_start(conservative(SYSTEM), 1, 5, None, None)
    i_a = res.hb.size + 2
    counts = {"R": 0, "J": 0}

    class Counted:
        """res, counting the residuals made and the Jacobians asked for."""

        def __call__(self, y):
            return res(y)

        def lazy(self, y):
            counts["R"] += 1
            R, jac = res.lazy(y)

            def asked():
                counts["J"] += 1
                return jac()
            return R, asked

    a, b = (continue_branch(f, y0, param=i_a, options=NNM_STEPS, max_steps=120, monitor=(res.hb.size,))
            for f in (Counted(), _strict(res)))
    assert np.array_equal(a.y, b.y) and np.array_equal(a.tangent, b.tangent) and np.array_equal(a.ds, b.ds)
    assert a.n_rejected == b.n_rejected and a.folds == b.folds
    assert a.y[-1, i_a] > y0[i_a] + 0.7  # past grazing (its amplitude is 1 / 0.3 that of the start) into contact
    assert counts["J"] < counts["R"]  # some trial points were refused on R alone


def test_nnm_newtons_asking_lazily_are_the_eager_ones(monkeypatch):
    """The backbone's point at a given energy (hb_point_at_energy) and its corrector at a fixed frequency
    (the tongue step-over's) ask NNMResidual for dR/dy only where Newton steps: the same points to the bit
    as with dR/dy made at every trial point."""
    from reduced.periodic import backbones
    from reduced.periodic.hb import NNMResidual
    from reduced.periodic.shooting import conservative

    br = backbones.nnm_branch(conservative(SYSTEM), 1, H=5, energy_max_J=1e-1)
    res = br.residual
    i_w = res.hb.size
    k = len(br.energy_J) // 2
    y0 = br.branches[0].y[k]

    def both():
        E = float(br.energy_J[k]) * 1.3
        return (backbones.hb_point_at_energy(res, y0, E),
                backbones._correct_at_frequency(res, y0, y0[i_w] * 1.01))

    lazy = both()
    lazily = NNMResidual.lazy

    def eager(self, y):  # dR/dy made at once; ``below`` (a corrector's row) stacked as np.vstack would
        R, jac = lazily(self, y)
        J = jac()
        return R, lambda below=None: J if below is None else np.vstack([J, below])

    monkeypatch.setattr(NNMResidual, "lazy", eager)
    ref = both()
    assert ref[1] is not None and br.energy_J[-1] > 1e-2  # a branch into contact, a corrector that converged
    assert np.array_equal(lazy[0], ref[0]) and np.array_equal(lazy[1], ref[1])


def test_the_map_samples_on_the_march_or_after_it_with_the_same_bits(attractor):
    """classify's ``defer`` (the sweep's guess from the previous frequency) changes no number of a chaotic point."""
    pm, y = attractor
    opts = MapOptions(n_transient=4, n_record=32, max_blocks=1)
    got = [classify(pm, y, 1.0, opts, (0, 2, 3), np.random.default_rng(0), defer=d) for d in (True, False)]
    assert got[0].regime == "chaotic"  # a point that reads its samples: the deferred one replays them
    for f in PointResponse.__dataclass_fields__:
        a, b = getattr(got[0], f), getattr(got[1], f)
        assert np.array_equal(a, b, equal_nan=isinstance(a, float) or np.asarray(a).dtype.kind == "f"), f


def test_a_sweep_samples_on_the_march_after_a_response_that_read_its_samples():
    def point(regime, settled=True):
        return PointResponse(regime, 0, 0.0, 0.0, 0.0, settled, *[None] * 8)
    assert _defer_after([]) and _defer_after([point("periodic")]) and _defer_after([point("subharmonic")])
    assert not _defer_after([point("chaotic")]) and not _defer_after([point("quasi_periodic")])
    assert not _defer_after([point("periodic", settled=False)])  # unsettled: its record's samples were read
