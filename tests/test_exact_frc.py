"""Forced periodic orbits on the exact flow (reduced.periodic.forced_shooting, reduced.periodic.exact_frc):
the lean flow against the library's, the shooting Jacobian against finite differences, the exact
peaks, closed forms of the gap oscillator, HB at high H, and branch switching against direct
shooting and long integrations from perturbed orbits.

The gap oscillator here (1 DOF, 10 Hz, a two-sided stop of 20 k at 1 mm, zeta = 0.02, 2 N): its
symmetric orbit first touches the stops at 7.030 Hz, loses its half-wave symmetry at a pitchfork at
7.040 Hz and regains it at 8.191 Hz; on the asymmetric family a period doubling bubble (7.047-8.144
Hz) holds period-2 orbits, stable between 8.129 and 8.142 Hz (8.134 by this continuation's point spacing;
8.1287 located by tests/test_period_doubling.py, where the 2T orbit doubles again to 4T).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc, find_symmetry, hb_start
from reduced.periodic.exact_hb import default_root_samples
from reduced.periodic.forced_balance import ForcedBalance
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.forced_stability import floquet_by_shooting, hb_states, multipliers_of
from reduced.periodic.frc import frc, max_abs_over_period, solution_at_frequency
from reduced.periodic.hb import newton
from reduced.periodic.stepped_sine import stepped_sine
from reduced.transient.flow import Flow

K = (2 * np.pi * 10.0) ** 2  # N/m, m = 1 kg: 10 Hz
ZETA, RATIO, GAP, LOAD = 0.02, 20.0, 1e-3, 2.0
B1 = np.ones(1)


def impact_oscillator() -> GapSystem:
    return GapSystem(M=np.eye(1), C=2 * ZETA * math.sqrt(K) * np.eye(1), K=K * np.eye(1), dof_names=("x",),
                     **two_sided_stops(np.eye(1), RATIO * K, GAP, ("x",)))


@functools.cache
def _families():
    s = impact_oscillator()
    opts = ExactFRCOptions(max_families=3, depth=2)
    with single_thread_blas():
        return exact_frc(s, B1, LOAD, 3.0, 40.0, hb_start(s, B1, LOAD, 3.0, opts.segments), x_ref=GAP, options=opts)


def _at(res: ShootingResidual, fam, f: float) -> np.ndarray:
    """The scaled point of ``fam`` exactly at f: Newton at fixed frequency from its nearest point."""
    i = int(np.argmin(np.abs(fam.freq_hz - f)))
    return shoot_at(res, fam.nodes[i], 2 * np.pi * f)


def _residual(fam, P: float = LOAD) -> ShootingResidual:
    S = fam.nodes.shape[1]
    return ShootingResidual(ForcedFlow(impact_oscillator(), B1, P), S, fam.periods, GAP, 2 * np.pi * 40.0)


# -- the lean flow and the residual -----------------------------------------------------------------
def test_lean_flow_matches_the_library_flow():
    # the same closed forms marched by two kernels (the lean one keeps a slow harmonic load in
    # exponential form, the library's as a Taylor polynomial): equal to round-off, states and Jacobians
    s = DiscreteParams().system()
    b = np.array([0.0, 1.0, 0.0])
    ff = ForcedFlow(s, b, 10.0, phase_deg=30.0)
    rng = np.random.default_rng(4)
    for f in (12.0, 300.0):
        w = 2 * np.pi * f
        fl = Flow(s, loads=Loads(b[None, :], (Harmonic(10.0, f, 30.0),)))
        Y0 = np.column_stack([rng.normal(size=(4, 3)) * 3e-4, rng.normal(size=(4, 3)) * 3e-4 * w])
        t0 = rng.uniform(0.0, 0.1, 4)
        Ye, J, _, n_ev = ff.march(Y0, t0, 0.125 / f, w, True)
        assert n_ev.sum() > 0  # in contact
        for k in range(4):
            r = fl(Y0[k, :3], Y0[k, 3:], 0.125 / f, jacobian=True, t0=t0[k])
            # a few contact events in 1/8 period: round-off, amplified by the contacts' growth
            assert np.max(np.abs(r.y - Ye[k])) < 1e-10 * np.max(np.abs(r.y))
            # Jacobians: 1e-16 to 2e-12 with 1-3 events (300 Hz); at 12 Hz these states chatter, 37-52
            # events in 1/8 period, each event time a root found to round-off whose error grows through
            # the saltations: measured 1e-10 to 9.2e-9 (both kernels are within 1e-8 of central
            # differences there, which cannot tell them apart)
            assert np.max(np.abs(r.jacobian - J[k])) < 3e-8 * np.max(np.abs(r.jacobian))


def test_shooting_jacobian_matches_finite_differences():
    fam = _families().main
    res = _residual(fam)
    i = int(np.argmin(np.abs(fam.freq_hz - 7.6)))  # in contact, unstable
    assert fam.events[i] > 0
    Y = res.point(fam.nodes[i] * 1.001, 2 * np.pi * 7.6)  # off the orbit: every term of R counts
    R, J = res(Y)
    for j in (0, 1, 5, res.size):  # a displacement, a velocity, another node, ln Omega
        h = 1e-6
        Yp, Ym = Y.copy(), Y.copy()
        Yp[j] += h
        Ym[j] -= h
        fd = (res(Yp)[0] - res(Ym)[0]) / (2 * h)
        # central differences: truncation ~h^2 |R'''|, round-off ~eps |R| / h: 1e-8 of the column
        assert np.max(np.abs(fd - J[:, j])) < 1e-6 * np.max(np.abs(J[:, j])), j


def test_peaks_bound_the_dense_samples_and_are_their_limit():
    fam = _families().main
    res = _residual(fam)
    for f in (5.0, 7.6, 20.0):
        Y = _at(res, fam, f)
        nodes, w = res.nodes(Y)
        t0, h = res.times(w)
        pmax, pmin = res.flow.peaks(nodes, t0, h, w, np.eye(1))
        x = res.flow.sample(nodes, w, 1, 512)[:, 0]  # 4096 samples a period
        dt = 2 * np.pi / w / 4096
        # never below the largest sample; above it by at most max|x''| dt^2 / 8 (the sample spacing)
        bound = (K * (1 + RATIO) * max(abs(x.max()), abs(x.min())) + LOAD) * dt**2 / 8
        assert 0.0 <= pmax[0] - x.max() <= bound and 0.0 <= x.min() - pmin[0] <= bound, (f, pmax - x.max())


# -- closed forms of the gap oscillator ---------------------------------------------------------------
def test_below_the_stops_the_family_is_the_linear_response_and_contact_starts_where_it_reaches_the_gap():
    fam = _families().main
    c = 2 * ZETA * math.sqrt(K)
    w = fam.omega
    lin = LOAD / np.abs(K - w**2 + 1j * w * c)
    free = fam.events == 0
    assert free.sum() > 20
    # exact orbits of the linear system: the receptance to the corrector's tolerance (it stops when its
    # last step is below CORRECTOR_TOL = 1e-8 of the scaled unknowns: measured up to 4.9e-12, at the
    # longest steps, far above resonance) ...
    err = np.abs(fam.amplitude_m[:, 0] / lin - 1.0)
    assert np.max(err[free]) < 1e-10
    # ... and to round-off once Newton at fixed frequency has converged (peaks refined exactly)
    res = _residual(fam)
    for i in np.flatnonzero(free)[np.argsort(err[free])[-3:]]:
        nodes, w_i = res.nodes(_at(res, fam, float(fam.freq_hz[i])))
        t0, h = res.times(w_i)
        pmax, pmin = res.flow.peaks(nodes, t0, h, w_i, np.eye(1))
        assert abs(max(pmax[0], -pmin[0]) / (LOAD / abs(K - w_i**2 + 1j * w_i * c)) - 1.0) < 1e-13
    # contact starts where |H(w)| P = g: (K - w^2)^2 + (c w)^2 = (P / g)^2, the root below resonance
    u = np.roots([1.0, c**2 - 2 * K, K**2 - (LOAD / GAP) ** 2])
    f_g = math.sqrt(min(u.real[u.real > 0])) / (2 * np.pi)
    first = int(np.argmax(~free))
    assert fam.freq_hz[first - 1] < f_g <= fam.freq_hz[first], (fam.freq_hz[first - 1], f_g, fam.freq_hz[first])
    assert fam.amplitude_m[first - 1, 0] < GAP <= fam.amplitude_m[first, 0]


def test_exact_orbit_is_the_limit_of_hb():
    # HB (odd harmonics, exact projection) at the exact orbit's frequency, by Newton from the exact
    # orbit's own series: its error falls with H and at H = 255 is ~1e-7 of the penetration
    fam = _families().main
    res = _residual(fam)
    f = 20.0
    Y = _at(res, fam, f)
    nodes, w = res.nodes(Y)
    t0, h = res.times(w)
    peak = float(res.flow.peaks(nodes, t0, h, w, np.eye(1))[0][0])
    assert peak > 1.1 * GAP  # in contact
    x = res.flow.sample(nodes, w, 1, 1024)[:-1, 0]
    C = np.fft.rfft(x) / x.size
    errs = {}
    for H in (15, 63, 255):
        fb = ForcedBalance(impact_oscillator(), B1, LOAD, 0.0, H, default_root_samples(H), True)
        q = np.zeros((2 * H + 1, 1))
        q[1::2, 0], q[2::2, 0] = 2 * C[1:H + 1].real, -2 * C[1:H + 1].imag

        def fun(v, fb=fb):
            R, J, _ = fb.residual(v * GAP, w)
            return R / GAP, J

        z = newton(fun, q[fb.keep].ravel() / GAP, tol=1e-13, max_iter=30).y * GAP
        a = float(max_abs_over_period(fb.response(z, w), np.eye(1))[0])
        errs[H] = abs((a - GAP) / (peak - GAP) - 1.0)  # the penetration's relative error
    # measured 2.7e-3, 1.9e-5, 3.9e-7: the error falls ~ H^-3 (the stop force is C1, its series decays
    # like k^-3 in contact); the truncation bounds the difference, the exact orbit is the limit
    assert errs[255] < 2e-6 and errs[255] < 0.1 * errs[63] < 0.1 * errs[15], errs


# -- symmetry, branch switching ----------------------------------------------------------------------
def test_symmetries_of_the_models():
    s = DiscreteParams().system()
    sym = find_symmetry(s, np.array([0.0, 1.0, 0.0]))
    assert sym.mirror is not None and np.array_equal(sym.mirror, np.eye(3)[::-1]) and sym.half_wave
    assert find_symmetry(s, np.array([1.0, 0.0, 0.0])).mirror is None  # a load at x1 breaks the mirror
    assert find_symmetry(impact_oscillator(), B1).mirror is None and find_symmetry(impact_oscillator(), B1).half_wave


def test_pitchfork_is_found_and_its_family_rejoins_the_symmetric_orbit():
    out = _families()
    main = out.main
    pf = [(i, k) for i, k in main.bifurcations if k == "pitchfork_half_wave"]
    assert len(pf) == 2
    first = out.switches[0]
    assert first["kind"] == "pitchfork_half_wave" and first["child"] == 1
    # located where a multiplier of the half-period map G = -Phi(T/2) crosses -1 (Phi's crosses +1)
    assert abs(first["critical"] + 1.0) < 2e-3 and 7.03 < first["located_hz"] < 7.05
    fam = out.families[1]
    assert fam.kind == "half_wave_broken" and fam.status == "rejoined"
    assert np.min(fam.half_wave[1:-1]) > 1e-3  # the family's orbits are not half-wave symmetric
    # ... and rejoins at the second pitchfork (8.19 Hz), whose switch is not made again
    assert out.switches[1]["child"] == -1 and "reached" in out.switches[1]["note"]
    assert abs(fam.freq_hz[-1] - main.freq_hz[pf[1][0]]) < 0.05 * fam.freq_hz[-1] or fam.freq_hz[-1] > 8.18


def test_switched_family_is_the_orbit_direct_shooting_finds_from_a_perturbed_symmetric_orbit():
    # at 7.6 Hz both orbits are unstable; Newton from the symmetric orbit pushed off its symmetry
    # (a static offset of 0.05 g: the zeroth harmonic, absent from every half-wave symmetric orbit)
    # lands on the switched family's orbit or its half-wave image, not found by the switch's
    # predictor but by a generic perturbation (offsets of 0.2-1 g fall back onto the symmetric orbit,
    # and with that orbit deflated Newton does not converge from any of them: measured)
    out = _families()
    res = _residual(out.main)
    f = 7.6
    y_sym = _at(res, out.main, f)
    nodes = res.nodes(y_sym)[0].copy()
    nodes[:, 0] += 0.05 * GAP
    y_d = shoot_at(res, nodes, 2 * np.pi * f)
    y_f = _at(res, out.families[1], f)
    S = res.segments
    n_d, n_f = res.nodes(y_d)[0], res.nodes(y_f)[0]
    image = -np.roll(n_f, S // 2, axis=0)  # x(t + T/2) -> -x: the other half of the pitchfork
    err = min(np.max(np.abs(n_d - n_f)), np.max(np.abs(n_d - image))) / np.max(np.abs(n_f))
    assert err < 1e-9, err
    assert np.max(np.abs(n_d - res.nodes(y_sym)[0])) > 0.05 * np.max(np.abs(n_d))


def test_transient_from_the_unstable_symmetric_orbit_settles_on_the_switched_family():
    # 8.17 Hz: the symmetric orbit is unstable, the asymmetric one stable (|mu| = 0.857); the exact
    # integrator started 1e-3 g off the symmetric orbit settles on the asymmetric one (or its image)
    out = _families()
    fam = out.families[1]
    res = _residual(out.main)
    f = 8.17
    i = int(np.argmin(np.abs(fam.freq_hz - f)))
    assert fam.stable[i] and not out.main.stable[int(np.argmin(np.abs(out.main.freq_hz - 8.0)))]
    y_sym = _at(res, out.main, f)
    y0 = res.nodes(y_sym)[0][0].copy()
    y0[0] += 1e-3 * GAP
    ss = stepped_sine(impact_oscillator(), B1, LOAD, [f], settle_tol=1e-9, max_settle_s=60.0, y0=y0)
    assert ss.response == ["periodic"]
    nodes = res.nodes(_at(res, fam, f))[0]
    x = res.flow.sample(nodes, 2 * np.pi * f, 1, 256)[:, 0]
    # the sweep's amplitude is the largest of its samples: within the sampling error of the orbit's
    assert abs(ss.amplitude_m[0, 0] / max(x.max(), -x.min()) - 1.0) < 1e-4


def test_period_doubling_family_is_the_period_2_attractor():
    # on the asymmetric family a multiplier passes -1 at 8.144 Hz; the period-2 family switched onto
    # there is stable between 8.129 and 8.142 Hz, where a long integration from the (unstable)
    # asymmetric orbit settles on a period-2 motion of the same amplitude
    out = _families()
    pd = [r for r in out.switches if r["kind"] == "period_doubling" and r["child"] >= 0]
    assert pd and abs(pd[0]["critical"] + 1.0) < 1e-2
    fam2 = out.families[pd[0]["child"]]
    assert fam2.kind == "period_doubled" and fam2.periods == 2
    i = int(np.flatnonzero(fam2.stable)[len(np.flatnonzero(fam2.stable)) // 2])
    f = float(fam2.freq_hz[i])
    nodes = fam2.nodes[i]
    S = nodes.shape[0]
    assert np.max(np.abs(nodes[S // 2:] - nodes[: S // 2])) > 1e-3 * np.max(np.abs(nodes))  # not period 1
    fam1 = out.families[1]
    res1 = _residual(fam1)
    y1 = _at(res1, fam1, f)
    assert not fam1.stable[int(np.argmin(np.abs(fam1.freq_hz - f)))]
    y0 = res1.nodes(y1)[0][0].copy()
    y0[0] += 1e-4 * GAP
    ss = stepped_sine(impact_oscillator(), B1, LOAD, [f], settle_tol=1e-8, max_settle_s=120.0, y0=y0)
    assert ss.response == ["period_2"], ss.response
    res2 = _residual(fam2)
    x = res2.flow.sample(res2.nodes(shoot_at(res2, nodes, 2 * np.pi * f))[0], 2 * np.pi * f, 2, 256)[:, 0]
    assert abs(ss.amplitude_m[0, 0] / max(x.max(), -x.min()) - 1.0) < 1e-4


def test_the_response_map_classifies_the_period_2_attractor_as_subharmonic():
    # the response map's classifier (reduced.periodic.response_map.classify: Poincare returns, Newton on the
    # period-p map, the largest Lyapunov exponent) started where the long integration above settles on the
    # period-2 motion: a subharmonic of period 2 load periods, with a negative exponent and the amplitude of
    # the period-2 family's orbit (the maps of discrete-frc and rom-frc meet no such attractor on their grids)
    from reduced.periodic.response_map import MapOptions, classify
    from reduced.transient.lyapunov import PeriodMap

    out = _families()
    pd = [r for r in out.switches if r["kind"] == "period_doubling" and r["child"] >= 0]
    fam2 = out.families[pd[0]["child"]]
    i = int(np.flatnonzero(fam2.stable)[len(np.flatnonzero(fam2.stable)) // 2])
    f = float(fam2.freq_hz[i])
    fam1 = out.families[1]
    res1 = _residual(fam1)
    y0 = res1.nodes(_at(res1, fam1, f))[0][0].copy()
    y0[0] += 1e-4 * GAP
    s = impact_oscillator()
    sigma = ZETA * math.sqrt(K)  # the open system's decay rate, 1/s
    pm = PeriodMap(s, B1, LOAD, f, rows=np.eye(1))
    pt = classify(pm, y0, sigma, MapOptions())
    assert pt.regime == "subharmonic" and pt.period_k == 2, (pt.regime, pt.period_k)
    assert pt.lyapunov_per_s < 0.0 and pt.contact
    mu = float(np.max(np.abs(fam2.multipliers[i])))
    assert math.isclose(pt.lyapunov_per_s, f * math.log(mu) / 2, rel_tol=1e-3), (pt.lyapunov_per_s, mu)


# -- the three-mass model ------------------------------------------------------------------------------
def test_three_mass_family_holds_the_orbit_shooting_finds_from_hb():
    # 1 N, 17 Hz (tests/test_frc_contact.py): the symmetric contact orbit shot from the H = 15 curve by
    # floquet_by_shooting (library flow, its own Newton) is a point of the exact family continued from
    # 10 Hz; the same orbit to 1e-9 and the same multipliers
    s = DiscreteParams().system()
    b = np.array([0.0, 1.0, 0.0])
    g = float(np.max(np.abs(s.offset)))
    with single_thread_blas():
        br = frc(s, b, 1.0, 10.0, 22.0, H=15, harmonics="odd", hill_points=0, stability=False)
        _, _, X = solution_at_frequency(br, 17.0, g, 0, stable_only=False)
        loads = Loads(b[None, :], (Harmonic(1.0, 17.0),))
        orb = floquet_by_shooting(Flow(s, loads=loads), hb_states(X, 2 * np.pi * 17.0, 8), 1.0 / 17.0)
        ex = exact_frc(s, b, 1.0, 10.0, 17.05, hb_states(br.X[0], br.omega[0], 8), x_ref=br.x_ref,
                       options=ExactFRCOptions(branch_switching=False))
    fam = ex.main
    res = ShootingResidual(ForcedFlow(s, b, 1.0), 8, 1, br.x_ref, 2 * np.pi * 17.05)
    cand = [i for i in range(1, len(fam.freq_hz)) if (fam.freq_hz[i - 1] - 17.0) * (fam.freq_hz[i] - 17.0) <= 0]
    assert cand
    best = math.inf
    for i in cand:
        y = shoot_at(res, fam.nodes[i], 2 * np.pi * 17.0)
        n0 = res.nodes(y)[0][0]
        d = max(np.max(np.abs(n0[:3] - orb.x0)) / g, np.max(np.abs(n0[3:] - orb.v0)) / (2 * np.pi * 17.0 * g))
        if d < best:
            best, mu = d, multipliers_of(res.monodromy(y))
    assert best < 1e-9, best
    assert np.max(np.abs(np.log(np.abs(mu)) - np.log(np.abs(orb.multipliers)))) < 1e-6
