"""Period-doubled families of the forced exact flow (reduced.periodic.exact_frc, issue 25): the 2 T
orbits the branch switching finds, against independent checks.

The three-mass model at 1 N (the discrete-frc scene): on the family that breaks the half-wave
symmetry at 16.90 Hz (x1 = x3, three contact events a period) a real multiplier passes -1 at
17.156 Hz away from any grazing. The family is continued here over 17.14-17.17 Hz from a guess of
its orbit at 17.152 Hz (the nodes of the discrete-frc run, to 4 digits: Newton converges from it,
nothing below is compared with it), and the period-doubled family switched onto there is checked:

- its orbits are fixed points of the map over 2 T of the library's exact integrator (another
  kernel than the shooting residual's), and not of the map over T;
- the part that breaks the period T grows like sqrt(f_PD - f) (the normal form of a period
  doubling), with f_PD where the parent's multiplier equals -1, found on the parent alone.

Its 2 T orbits are unstable (the parent's other multipliers are 3-5 there); so is every 2 T family of
discrete-frc at 1 and 10 N (frc_families.csv). Where a 2 T orbit is stable, a long integration must
settle on it: checked on the gap oscillator of tests/test_exact_frc.py (a stable 2 T window at
8.129-8.142 Hz), whose 2 T family the same switching finds, by the response map's classifier.

A cascade (``period_doubling_depth`` = 2): the gap oscillator's 2 T family loses its stability at
8.12867 Hz, the lower end of its stable window, where its multiplier passes -1 (away from any
grazing: 6 contact events per 2 T on both sides); the 4 T family born there is stable just below
and doubles again at 8.122-8.125 Hz (an 8 T family, not followed at depth 2). Checked on the 4 T family
like the 2 T one above: fixed points over 4 T of the library's integrator and not over 2 T, the
square-root law with f_PD found on the 2 T parent alone, and the depth key (depth 1 stops at 2 T).
"""

from __future__ import annotations

import functools
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc, hb_start
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.hb import newton
from reduced.periodic.response_map import MapOptions, response_map
from reduced.transient.flow import Flow

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_exact_frc import B1, GAP, LOAD, impact_oscillator  # noqa: E402

P = 1.0  # N
B = np.array([0.0, 1.0, 0.0])
X_REF = 2.5689e-4  # m, the discrete-frc curve's displacement scale at 1 N
F_SEED = 17.152093  # Hz
SEED = np.array([  # (8, 6) nodes [x; v] of the half-wave-broken orbit at F_SEED, 4 digits (a guess only)
    [2.401e-04, 2.397e-04, 2.401e-04, 9.820e-03, 7.615e-03, 9.820e-03],
    [2.292e-04, 2.286e-04, 2.292e-04, -1.171e-02, -1.143e-02, -1.171e-02],
    [8.774e-05, 8.715e-05, 8.774e-05, -2.660e-02, -2.402e-02, -2.660e-02],
    [-1.041e-04, -1.045e-04, -1.041e-04, -2.657e-02, -2.275e-02, -2.657e-02],
    [-2.370e-04, -2.370e-04, -2.370e-04, -1.172e-02, -8.135e-03, -1.172e-02],
    [-2.245e-04, -2.241e-04, -2.245e-04, 1.415e-02, 1.138e-02, 1.415e-02],
    [-7.676e-05, -7.661e-05, -7.676e-05, 2.778e-02, 2.364e-02, 2.778e-02],
    [1.143e-04, 1.141e-04, 1.143e-04, 2.600e-02, 2.209e-02, 2.600e-02]])


@functools.cache
def _three_mass():
    s = DiscreteParams().system()
    opts = ExactFRCOptions(max_families=0, period_doubling_families=1)
    with single_thread_blas():
        out = exact_frc(s, B, P, 17.14, 17.17, [(F_SEED, SEED)], x_ref=X_REF, options=opts)
    return s, out


def _residual(s, S: int, periods: int) -> ShootingResidual:
    return ShootingResidual(ForcedFlow(s, B, P), S, periods, X_REF, 2 * np.pi * 17.17)


def _pd_family(out):
    pd = [r for r in out.switches if r["kind"] == "period_doubling" and r["child"] >= 0]
    assert pd, out.switches
    return pd[0], out.families[pd[0]["child"]]


def test_switching_finds_a_period_doubled_family_at_the_multiplier_minus_one():
    _, out = _three_mass()
    rec, fam = _pd_family(out)
    # a smooth crossing: the located multiplier is -1 to the bisection's bracket (12 halvings of a step)
    assert abs(rec["critical"] + 1.0) < 1e-2 and not rec["grazing"]
    assert fam.kind == "period_doubled" and fam.periods == 2 and fam.nodes.shape[1] == 2 * out.main.nodes.shape[1]
    assert abs(rec["located_hz"] - 17.156) < 1e-3


def test_period_doubled_orbit_is_a_fixed_point_over_2T_not_over_T():
    # the library's exact integrator (its own kernel, Taylor-polynomial load) marches the family's
    # last orbit from its first node: back on it after 2 T to round-off amplified by the orbit's
    # instability (|mu| ~ 1e4: 1e-13 x 1e4), far from it after T
    s, out = _three_mass()
    _, fam = _pd_family(out)
    for j in (len(fam.freq_hz) // 2, len(fam.freq_hz) - 1):
        f = float(fam.freq_hz[j])
        y0 = fam.nodes[j][0]
        fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, f),)))
        scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * np.pi * f * X_REF)])
        y2 = fl(y0[:3], y0[3:], 2.0 / f).y
        y1 = fl(y0[:3], y0[3:], 1.0 / f).y
        d2 = float(np.max(np.abs(y2 - y0) / scale))
        d1 = float(np.max(np.abs(y1 - y0) / scale))
        assert d2 < 1e-8, (f, d2)
        assert d1 > 1e-4, (f, d1)  # the shooting tolerance is 1e-11: period T is excluded by 7 decades


def test_period_doubled_amplitude_grows_like_the_square_root_of_the_distance():
    # f_PD from the parent alone: the frequency where its multiplier nearest -1 is -1 (Newton at each
    # frequency from the seed, Brent on mu + 1). The 2 T orbits: R(Y) = 0 of the 2 T residual with
    # e . (Y - Y_PD) = h along the critical eigenvector propagated over 2 T (the pseudo-arclength
    # condition of the switching, built here again); their T-breaking part b = max |x(t + T) - x(t)|
    # against f_PD - f on a log-log fit: the normal form's exponent 1/2 within 0.05 (the next
    # order of the normal form moves the slope by O(h^2) over these h)
    s, _ = _three_mass()
    r1 = _residual(s, 8, 1)

    def parent(f):
        return shoot_at(r1, SEED, 2 * np.pi * f)

    def mu_plus_one(f):
        mu = np.linalg.eigvals(r1.monodromy(parent(f)))
        mu = mu[np.abs(mu.imag) < 1e-9]
        return float(mu[np.argmin(np.abs(mu + 1.0))].real + 1.0)

    f_pd = brentq(mu_plus_one, 17.153, 17.159, xtol=1e-13, rtol=1e-15)
    y1 = parent(f_pd)
    nodes1, w = r1.nodes(y1)
    Js = r1.segment_monodromies(y1)
    Phi = np.eye(6)
    for J in Js:
        Phi = J @ Phi
    lam, V = np.linalg.eig(Phi)
    e = V[:, int(np.argmin(np.abs(lam + 1.0)))].real
    dY = [e]
    for J in list(Js) * 2:
        dY.append(J @ dY[-1])
    dY = np.array(dY[:-1])
    assert np.allclose(dY[8], -e, atol=1e-6)  # the eigenvector changes sign after T
    r2 = _residual(s, 16, 2)
    y_pd = r2.point(np.concatenate([nodes1, nodes1]), w)
    d = r2.point(np.concatenate([nodes1, nodes1]) + dY, w) - y_pd
    d[-1] = 0.0
    d /= np.linalg.norm(d)
    df, br = [], []
    y = y_pd
    for h in (2e-5, 5e-5, 1.2e-4, 3e-4):
        def fun(z, h=h):
            R, J = r2(z)
            return np.concatenate([R, [d @ (z - y_pd) - h]]), np.vstack([J, d])

        y = newton(fun, y_pd + h * d, tol=1e-12, max_iter=30).y
        nodes, w2 = r2.nodes(y)
        df.append(abs(w2 / (2 * np.pi) - f_pd))
        br.append(float(np.max(np.abs(nodes[8:, :3] - nodes[:8, :3]))) / X_REF)
    slope = np.polyfit(np.log(df), np.log(br), 1)[0]
    assert abs(slope - 0.5) < 0.05, (slope, df, br)


def test_stable_period_doubled_orbit_is_what_a_long_integration_settles_on():
    # the gap oscillator: its half-wave-broken family doubles its period at 7.05 and 8.14 Hz; the 2 T
    # family is stable over 8.137-8.142 Hz. The response map's classifier (Poincare samples of the
    # exact period map, its own Newton on the p-period map) started from the unstable period-1 orbit
    # (a kick of 1e-4 of the gap) finds a subharmonic of period 2 there, whose per-period peaks are
    # those of the 2 T orbit
    s = impact_oscillator()
    opts = ExactFRCOptions(max_families=1, period_doubling_families=1)
    with single_thread_blas():
        out = exact_frc(s, B1, LOAD, 7.0, 8.3, hb_start(s, B1, LOAD, 7.0, opts.segments), x_ref=GAP, options=opts)
    fam = next(f for f in out.families if f.kind == "period_doubled")
    st = np.flatnonzero(fam.stable)
    assert st.size and fam.periods == 2
    i = int(st[np.argmin(fam.max_multiplier[st])])  # its most stable orbit: the transient is shortest there
    f = float(fam.freq_hz[i])
    parent = out.families[fam.parent[0]]
    res1 = ShootingResidual(ForcedFlow(s, B1, LOAD), parent.nodes.shape[1], 1, GAP, 2 * np.pi * 8.3)
    j = int(np.argmin(np.abs(parent.freq_hz - f)))
    y1 = res1.nodes(shoot_at(res1, parent.nodes[j], 2 * np.pi * f))[0][0].copy()
    assert not parent.stable[j]
    y1[0] += 1e-4 * GAP
    rm = response_map(s, B1, LOAD, [f], y0=y1, mirror=("x", "none"), options=MapOptions())
    p = rm.points[0]
    assert (p.regime, p.period_k) == ("subharmonic", 2), (p.regime, p.period_k)
    res2 = ShootingResidual(ForcedFlow(s, B1, LOAD), fam.nodes.shape[1], 2, GAP, 2 * np.pi * 8.3)
    x = res2.flow.sample(res2.nodes(shoot_at(res2, fam.nodes[i], 2 * np.pi * f))[0], 2 * np.pi * f, 2, 512)[:, 0]
    # the two periods' peaks |x| of the 2 T orbit (exact, 1024 samples), against the envelope of the
    # settled response: the classifier samples 64 times a period, so its peak is low by up to
    # 1 - cos(pi / 64) = 1.2e-3
    half = len(x) // 2
    peaks = sorted([np.max(np.abs(x[: half + 1])), np.max(np.abs(x[half:]))])
    got = sorted([float(p.peak[:, 0].min()), float(p.peak[:, 0].max())])
    assert all(-2e-3 < g / q - 1.0 <= 1e-9 for g, q in zip(got, peaks, strict=True)), (got, peaks)
    assert math.isfinite(p.lyapunov_per_s) and p.lyapunov_per_s < 0.0


# -- depth 2: the 4 T family of the gap oscillator's cascade -----------------------------------------
# the half-wave-broken orbit of the gap oscillator at F_HW (4 digits, a guess only): found once by
# exact_frc over 7.0-8.3 Hz from hb_start at 7.0 Hz (max_families=1, period_doubling_depth=2, 47 s),
# which switched main -> half_wave_broken (7.039 Hz) -> 2 T (7.044 Hz) -> 4 T (8.1287 Hz) -> an 8 T
# doubling at 8.122-8.125 Hz (not followed at depth 2). Started here on that orbit, the main family is
# the half-wave-broken one and the band 8.11-8.15 Hz holds the rest of the cascade: a second
# of continuation instead of 47
F_HW = 8.1281269  # Hz
HW_SEED = np.array([  # (8, 2) nodes [x, v] (m, m/s) at F_HW
    [9.9650e-04, 3.0620e-03],
    [8.1558e-04, -2.6081e-02],
    [2.3745e-04, -4.6747e-02],
    [-5.2092e-04, -4.7797e-02],
    [-1.0807e-03, -9.7599e-03],
    [-6.3025e-04, 4.4830e-02],
    [1.0974e-04, 4.7502e-02],
    [7.2983e-04, 3.0600e-02]])


@functools.cache
def _cascade(depth: int):
    s = impact_oscillator()
    # period_doubling_families above what the band holds: only the depth key can stop the 4 T family
    opts = ExactFRCOptions(max_families=0, period_doubling_families=4, period_doubling_depth=depth)
    with single_thread_blas():
        return s, exact_frc(s, B1, LOAD, 8.11, 8.15, [(F_HW, HW_SEED)], x_ref=GAP, options=opts)


def _doubling_of(out, periods: int):
    """(switch record, child family) of the period doubling on the family of ``periods`` load periods."""
    recs = [r for r in out.switches if r["kind"] == "period_doubling" and out.families[r["family"]].periods == periods]
    assert len(recs) == 1, out.switches
    rec = recs[0]
    return rec, (out.families[rec["child"]] if rec["child"] >= 0 else None)


def test_depth_two_follows_the_4T_family_and_depth_one_does_not():
    _, out1 = _cascade(1)
    _, out2 = _cascade(2)
    assert out2.main.kind == "main" and np.min(out2.main.half_wave) > 0.1  # the half-wave-broken orbits
    for out in (out1, out2):
        rec, fam2 = _doubling_of(out, 1)
        assert fam2 is not None and fam2.periods == 2
    # depth 1: the 2 T family's doubling is found, and not followed because of the depth key
    rec, child = _doubling_of(out1, 2)
    assert child is None and "period_doubling_depth = 1" in rec["note"], rec
    assert max(f.periods for f in out1.families) == 2
    # depth 2: followed, a 4 T family on 4 S nodes; a smooth crossing (the located multiplier is -1 to
    # the bisection's bracket), and its orbits near the doubling go twice round the parent's contacts
    rec, fam4 = _doubling_of(out2, 2)
    parent = out2.families[rec["family"]]
    assert fam4 is not None and fam4.kind == "period_doubled" and fam4.periods == 4
    assert fam4.nodes.shape[1] == 2 * parent.nodes.shape[1] == 4 * HW_SEED.shape[0]
    assert fam4.parent[:1] == (rec["family"],)
    assert abs(rec["critical"] + 1.0) < 1e-2 and not rec["grazing"]
    assert fam4.events[0] == 2 * parent.events[rec["index"]] == 2 * parent.events[rec["index"] - 1]
    # its own doubling (to 8 T) is found, and not followed at depth 2
    rec8, child8 = _doubling_of(out2, 4)
    assert child8 is None and "period_doubling_depth = 2" in rec8["note"], rec8
    assert sum(f.periods == 4 for f in out2.families) == 1


def test_4T_orbit_is_a_fixed_point_over_4T_not_over_2T():
    # the library's exact integrator (its own kernel, Taylor-polynomial load) marches each orbit of the
    # 4 T family from its first node: back on it after 4 T to the shooting tolerance (1e-11) amplified
    # by the orbit's instability (|mu| <= 16 here; measured <= 9e-13), far from it after 2 T and T
    # (measured 2.2e-3 to 6.8e-3 of the gap after 2 T: the family starts 1e-3 off the doubling)
    s, out = _cascade(2)
    rec, fam = _doubling_of(out, 2)
    assert fam is not None, rec
    for j in range(len(fam.freq_hz)):
        f = float(fam.freq_hz[j])
        y0 = fam.nodes[j][0]
        fl = Flow(s, loads=Loads(B1[None, :], (Harmonic(LOAD, f),)))
        scale = np.array([GAP, 2 * np.pi * f * GAP])
        d4, d2, d1 = (float(np.max(np.abs(fl(y0[:1], y0[1:], p / f).y - y0) / scale)) for p in (4, 2, 1))
        assert d4 < 1e-9, (f, d4)
        assert min(d2, d1) > 1e-5, (f, d2, d1)  # 6 decades above the shooting tolerance


def test_4T_breaking_part_grows_like_the_square_root_of_the_distance():
    # f_PD from the 2 T parent alone: its orbits shot on a 2 T residual of its own (16 nodes) from one
    # orbit of the depth-1 run's 2 T family (a guess only), Brent on the smallest real part of its
    # multipliers + 1 (continuous where the two real multipliers meet and turn complex, at 8.1295 Hz,
    # just above f_PD). The 4 T orbits: R(Y) = 0 of a 4 T residual (32 nodes) with e . (Y - Y_PD) = h
    # along the critical eigenvector propagated over 4 T (the switching's condition, built here again)
    s, out1 = _cascade(1)
    _, fam2 = _doubling_of(out1, 1)
    flow = ForcedFlow(s, B1, LOAD)
    r2 = ShootingResidual(flow, 16, 2, GAP, 2 * np.pi * 8.15)
    r4 = ShootingResidual(flow, 32, 4, GAP, 2 * np.pi * 8.15)
    seed = fam2.nodes[int(np.argmin(np.abs(fam2.freq_hz - 8.1287)))]

    def parent(f):
        return shoot_at(r2, seed, 2 * np.pi * f)

    def mu_plus_one(f):
        return float(np.min(np.linalg.eigvals(r2.monodromy(parent(f))).real) + 1.0)

    f_pd = brentq(mu_plus_one, 8.120, 8.135, xtol=1e-13, rtol=1e-15)
    # the switching's bisection located the same crossing: to its bracket, 12 halvings of the chord
    # between two points of the 2 T family (4e-6 Hz here; 1/1000 of the step allows for the chord's bend)
    _, out2 = _cascade(2)
    rec, fam4 = _doubling_of(out2, 2)
    assert fam4 is not None, rec
    fam2b = out2.families[rec["family"]]
    step = abs(fam2b.freq_hz[rec["index"]] - fam2b.freq_hz[rec["index"] - 1])
    assert abs(rec["located_hz"] - f_pd) < step / 1000, (rec["located_hz"], f_pd, step)
    y1 = parent(f_pd)
    nodes1, w = r2.nodes(y1)
    Js = r2.segment_monodromies(y1)
    Phi = np.eye(2)
    for J in Js:
        Phi = J @ Phi
    lam, V = np.linalg.eig(Phi)
    e = V[:, int(np.argmin(np.abs(lam + 1.0)))].real
    dY = [e]
    for J in list(Js) * 2:
        dY.append(J @ dY[-1])
    dY = np.array(dY[:-1])
    assert np.allclose(dY[16], -e, atol=1e-6)  # the eigenvector changes sign after 2 T
    y_pd = r4.point(np.concatenate([nodes1, nodes1]), w)
    d = r4.point(np.concatenate([nodes1, nodes1]) + dY, w) - y_pd
    d[-1] = 0.0
    d /= np.linalg.norm(d)
    df, br = [], []
    for h in (1e-5, 3e-5, 1e-4, 3e-4):
        def fun(z, h=h):
            R, J = r4(z)
            return np.concatenate([R, [d @ (z - y_pd) - h]]), np.vstack([J, d])

        y = newton(fun, y_pd + h * d, tol=1e-12, max_iter=30).y
        nodes, w4 = r4.nodes(y)
        f = w4 / (2 * np.pi)
        assert f < f_pd  # supercritical: the 4 T orbits lie where the 2 T parent is unstable
        df.append(f_pd - f)
        br.append(float(np.max(np.abs(nodes[16:, 0] - nodes[:16, 0]))) / GAP)
        if h in (3e-5, 1e-4):
            # exchange of stability (the flip normal form x -> -(1 + eps) x + a x^3): the 4 T orbit's
            # multiplier nearest +1 is 1 - 4 eps where the parent's at the same frequency is -(1 + eps),
            # to O(eps) (measured 4.002 and 4.030 at eps = 2.2e-4 and 2.5e-3; 4.30 at eps = 0.02)
            m4 = np.linalg.eigvals(r4.monodromy(y))
            m2 = np.linalg.eigvals(r2.monodromy(parent(f)))
            ratio = (m4[np.argmin(np.abs(m4 - 1.0))] - 1.0) / (m2[np.argmin(np.abs(m2 + 1.0))] + 1.0)
            assert abs(ratio - 4.0) < 0.05, (h, ratio)
    # the normal form's exponent 1/2: its next order moves the slope by O(b^2) over these b = 2e-5 to
    # 6e-4 of the gap (local slopes measured 0.49985-0.50014; 0.498 and 0.482 at h = 1e-3 and 3e-3)
    slope = np.polyfit(np.log(df), np.log(br), 1)[0]
    assert abs(slope - 0.5) < 0.01, (slope, df, br)
