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


def test_a_flow_jacobian_made_later_is_the_marched_one(attractor):
    """Flow.jacobian_of: the Jacobian of a march made without it, from its recorded segments, is the bits of
    ``jacobian=True`` (forced: the product of the segment exponentials; free: the modal kernel's)."""
    from reduced.transient.flow import Flow

    _, y = attractor
    n = SYSTEM.n
    forced = Flow(SYSTEM, loads=Loads(LOAD[None, :], (Harmonic(1.0, 19.0),)))
    free = Flow(SYSTEM)
    for flow, T in ((forced, 1.0 / 19.0), (free, 0.2)):
        a = flow(y[:n], y[n:], T, jacobian=True, t0=0.013)
        b = flow(y[:n], y[n:], T, t0=0.013)
        assert b.jacobian is None and a.n_events == b.n_events > 2  # through contacts
        assert np.array_equal(flow.jacobian_of(b), a.jacobian) and np.array_equal(a.y, b.y)
        assert flow.jacobian_of(a) is a.jacobian


def _floquet_eager(flow, Y, period_s, tol=1e-11, max_iter=30):
    """floquet_by_shooting as it was: every trial point marched with its Jacobian (Y, Phi, rn, iterations)."""
    from scipy.linalg import lu_factor, lu_solve

    n = flow.system.n
    Y = np.atleast_2d(np.array(Y, float))
    S = Y.shape[0]
    h = period_s / S
    w = 2.0 * np.pi / period_s
    xs = max(float(np.max(np.abs(Y[:, :n]))), 1e-300)
    sc = np.concatenate([np.full(n, xs), np.full(n, w * xs)])

    def evaluate(Y):
        segs = [flow(Y[k, :n], Y[k, n:], h, jacobian=True, t0=k * h) for k in range(S)]
        return segs, np.concatenate([(segs[k].y - Y[(k + 1) % S]) / sc for k in range(S)])

    segs, r = evaluate(Y)
    rn = float(np.max(np.abs(r)))
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        if rn <= tol:
            break
        J = np.zeros((2 * n * S, 2 * n * S))
        for k in range(S):
            rows = slice(2 * n * k, 2 * n * (k + 1))
            J[rows, rows] = segs[k].jacobian * (sc[None, :] / sc[:, None])
            kk = (k + 1) % S
            J[rows, 2 * n * kk:2 * n * (kk + 1)] -= np.eye(2 * n)
        dY = -lu_solve(lu_factor(J), r).reshape(S, 2 * n) * sc
        lam = 1.0
        for _ in range(10):
            segn, rnew = evaluate(Y + lam * dY)
            if float(np.max(np.abs(rnew))) < rn:
                break
            lam *= 0.5
        Y, segs, r = Y + lam * dY, segn, rnew
        rn = float(np.max(np.abs(r)))
    Phi = np.eye(2 * n)
    for sg in segs:
        Phi = sg.jacobian @ Phi
    return Y, Phi, rn, it


def test_floquet_by_shooting_with_later_jacobians_is_the_eager_one():
    """The forced orbit in contact (1 N, 17 Hz, 8 segments from the HB orbit, as the frc stage's point checks) by
    shooting whose trial points are marched without Jacobians: the same nodes, monodromy, closure and
    iterations as when every trial point had its Jacobian."""
    from reduced.periodic.forced_stability import floquet_by_shooting
    from reduced.periodic.frc import frc
    from reduced.transient.flow import Flow

    f = 17.0
    br = frc(SYSTEM, LOAD, 1.0, 16.5, 17.5, 5, point_rows=PARAMS.point_rows, stability=False)
    i = int(np.argmin(np.abs(br.freq_hz - f)))
    f = float(br.freq_hz[i])
    flow = Flow(SYSTEM, loads=Loads(LOAD[None, :], (Harmonic(1.0, f),)))
    guess = hb_states(br.X[i], 2 * np.pi * f, 8)
    Y, Phi, rn, it = _floquet_eager(flow, guess, 1.0 / f)
    orb = floquet_by_shooting(flow, guess, 1.0 / f)
    assert it > 1 and rn <= 1e-11  # Newton iterated to the orbit
    assert np.array_equal(orb.x0, Y[0, :SYSTEM.n]) and np.array_equal(orb.v0, Y[0, SYSTEM.n:])
    assert np.array_equal(orb.monodromy, Phi) and orb.n_iter == it


def test_shooting_at_a_frequency_lazily_is_the_eager_newton():
    """shoot_at asks for the Jacobian of its deflated residual only where Newton steps: the orbit found is the
    bits of Newton on R and dR/dv made together at every trial point, with a known orbit deflated too."""
    from reduced.periodic.forced_shooting import shoot_at
    from reduced.periodic.frc import frc

    br = frc(SYSTEM, LOAD, 1.0, 16.5, 17.5, 5, point_rows=PARAMS.point_rows, stability=False)
    i = len(br.freq_hz) // 2
    w = float(br.omega[i])
    res = ShootingResidual(ForcedFlow(SYSTEM, LOAD, 1.0), 8, 1, 1e-4, w, None)
    guess = hb_states(br.X[i], w, 8)
    Y0 = res.point(guess, w)
    nz = res.size
    for known in ([], [Y0 + 0.3]):  # a point far from the orbit deflated: R and dR/dv scaled and shifted

        def eager(v, known=known):
            R, J = res(np.append(v, Y0[nz]))
            J = J[:, :nz]
            for ks in known:
                d = v - ks[:nz]
                dd = float(d @ d)
                m = 1.0 / dd + 1.0
                J = m * J + np.outer(R, -2.0 * d / dd**2)
                R = m * R
            return R, J

        ref = newton(eager, Y0[:nz], tol=1e-11, max_iter=40)
        Y = shoot_at(res, guess, w, known=known)
        assert ref.n_iter > 1 and np.array_equal(Y[:nz], ref.y) and Y[nz] == Y0[nz]


def test_the_load_residual_deferred_is_the_residual():
    """The first orbit's load continuation (exact_frc._LoadResidual): R now, and the Jacobian with its forward
    difference in the load when asked, are the bits of R and dR/dy made together."""
    from reduced.periodic.exact_frc import _LoadResidual

    w = 2 * np.pi * 17.0
    res = ShootingResidual(ForcedFlow(SYSTEM, LOAD, 1.0), 8, 1, 1e-4, w, None)
    lr = _LoadResidual(res, w, 0.05)
    X = np.zeros((3, SYSTEM.n))
    X[1] = 1e-4 * np.array([1.0, 0.5, -0.2])
    base = np.append(res.point(hb_states(X, w, 8), w)[: res.size], 0.0)
    points = [base + k * np.linspace(0.0, 0.2, base.size) for k in range(3)]  # the last load 0.05 e^0.4 N
    lazies = [lr.lazy(y) for y in points]  # every R first, then the Jacobians (the flow's load moved between)
    for y, (R, jac) in zip(points, lazies, strict=True):
        R0, J0 = lr(y)
        assert np.array_equal(R, R0) and np.array_equal(jac(), J0)


def _forced_residual_reference(fb, z, omega):
    """ForcedBalance.residual as it was, R and its derivatives made together (issue 28)."""
    u, kp = fb.u, fb.keep
    q = fb.full_q(z)
    phi, dphi, _ = fb.contact(q)
    ks = fb._harmonics_kept
    W, dW = fb.receptances(omega, derivative=True, harmonics=ks)
    UW, UdW = np.einsum("rn,knc->krc", fb.U, W), np.einsum("rn,knc->krc", fb.U, dW)
    Rc, qlin = UW[:, :, :u], UW[:, :, u]
    dRc, dqlin = UdW[:, :, :u], UdW[:, :, u]
    phic = fb._complex(phi)[ks]
    R = q[kp] - fb._rows_of(qlin - np.einsum("krc,kc->kr", Rc, phic), ks)
    dRdw = -fb._rows_of(dqlin - np.einsum("krc,kc->kr", dRc, phic), ks)
    nk, S = kp.size, fb.size
    D = np.zeros((nk, u, nk, u))
    r = np.arange(u)
    D[:, r, :, r] = dphi[:, kp][:, :, kp]
    D = D.reshape(S, S)
    RD = np.empty((S, S))
    o = 0
    if ks[0] == 0:
        RD[:u] = Rc[0].real @ D[:u]
        o = 1
    Rk = Rc[o:]
    blk = np.empty((Rk.shape[0], 2 * u, 2 * u))
    blk[:, :u, :u] = blk[:, u:, u:] = Rk.real
    blk[:, :u, u:] = Rk.imag
    blk[:, u:, :u] = -Rk.imag
    RD[o * u:] = np.einsum("bij,bjs->bis", blk, D[o * u:].reshape(Rk.shape[0], 2 * u, S)).reshape(-1, S)
    RD[np.diag_indices(S)] += 1.0
    return R.ravel(), RD, dRdw.ravel()


@pytest.mark.parametrize("odd", [True, False])
def test_the_forced_balance_deferred_is_the_residual(odd):
    """ForcedBalance.residual_lazy (and ForcedResidual.lazy on it): R now and its derivatives when asked are the
    bits of the residual as it was, in contact (1 N at the 17.98 Hz heave resonance: a stop closes)."""
    from reduced.periodic.exact_hb import default_root_samples
    from reduced.periodic.forced_balance import ForcedBalance, ForcedResidual

    rng = np.random.default_rng(2)
    fb = ForcedBalance(SYSTEM, LOAD, 1.0, 0.0, 5, default_root_samples(5), odd)
    w = 2 * np.pi * 17.9
    z0 = fb.linear_z(w)
    res = ForcedResidual(fb, float(np.max(np.abs(z0))), w)
    for k in range(4):
        z = z0 * (1.0 + 0.2 * k) + 1e-5 * rng.standard_normal(z0.size)
        assert np.any(np.abs(fb.full_q(z)) > 0.0)
        R0, J0, d0 = _forced_residual_reference(fb, z, w)
        R, derivatives = fb.residual_lazy(z, w)
        J, d = derivatives()
        assert np.array_equal(R, R0) and np.array_equal(J, J0) and np.array_equal(d, d0)
        y = res.y_of(z, w)
        zy, wy = res.z_omega(y)  # the round trip through the scaled unknowns moves the last bits
        Ry0, Jy0, dy0 = _forced_residual_reference(fb, zy, wy)
        Ry, jac = res.lazy(y)
        Jy = jac()
        assert np.array_equal(Ry, Ry0 / res.x_ref) and np.array_equal(Jy[:, :-1], Jy0)
        assert np.array_equal(Jy[:, -1], dy0 * (wy / res.x_ref))
    assert np.any(J0 != np.eye(J0.shape[0]))  # the stops' force derivative entered: contact


def test_an_frc_continued_lazily_is_the_strict_one(monkeypatch):
    """The HB forced-response curve through contact, its correctors asking for dR/dy only where Newton steps,
    takes the same points, to the bit, as when every trial point had its Jacobian."""
    from reduced.periodic.forced_balance import ForcedResidual
    from reduced.periodic.frc import frc

    def curve():
        return frc(SYSTEM, LOAD, 1.0, 15.0, 21.0, 5, point_rows=PARAMS.point_rows, stability=False)

    lazy = curve()
    lazily = ForcedResidual.lazy

    def strict(self, y):
        R, jac = lazily(self, y)
        J = jac()
        return R, lambda: J

    monkeypatch.setattr(ForcedResidual, "lazy", strict)
    ref = curve()
    from reduced.periodic.frc import max_abs_over_period

    closes = [np.any(max_abs_over_period(X, SYSTEM.B) > np.abs(SYSTEM.offset)) for X in ref.X]
    assert len(ref.freq_hz) > 20 and 0 < sum(closes) < len(closes)  # into contact and out
    assert np.array_equal(lazy.z, ref.z) and np.array_equal(lazy.freq_hz, ref.freq_hz)
    assert lazy.n_rejected == ref.n_rejected


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

    def eager(self, y):
        R, jac = lazily(self, y)
        J = jac()
        return R, lambda: J

    monkeypatch.setattr(NNMResidual, "lazy", eager)
    ref = both()
    assert ref[1] is not None and br.energy_J[-1] > 1e-2  # a branch into contact, a corrector that converged
    assert np.array_equal(lazy[0], ref[0]) and np.array_equal(lazy[1], ref[1])
