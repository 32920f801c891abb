"""Forced-response curves (reduced.periodic.frc): closed forms, folds and jumps, stability three
ways, the exact projection of the stop forces, the stepped sine, bad arguments, the stage."""

from __future__ import annotations

import csv
import math
import tomllib
from importlib import resources

import numpy as np
import pytest
import tomli_w

from reduced._checks import InvalidArgument
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.backbones import nnm_branch
from reduced.periodic.exact_hb import ExactGapBalance, contact_intervals
from reduced.periodic.forced_balance import ForcedBalance
from reduced.periodic.forced_stability import bifurcations, floquet_by_shooting, hb_states
from reduced.periodic.frc import frc, linear_frf, max_abs_over_period, solution_at_frequency
from reduced.periodic.hb import HarmonicBalance, _derivative_matrix
from reduced.periodic.stepped_sine import stepped_sine
from reduced.transient.flow import Flow

P = DiscreteParams()
B2 = np.array([0.0, 1.0, 0.0])  # the load at x2


def oscillator(c: float = 2.5, gap: float = 1e-3) -> GapSystem:
    """1 DOF, m = 1 kg, k = (2 pi 10 Hz)^2, a two-sided stop |x| <= gap of stiffness 3 k: a
    hardening gap oscillator (zeta = 0.02 open, closed-gap frequency 20 Hz)."""
    k = (2 * np.pi * 10.0) ** 2
    return GapSystem(M=np.eye(1), C=c * np.eye(1), K=k * np.eye(1), dof_names=("x",),
                     **two_sided_stops(np.eye(1), 3.0 * k, gap, ("x",)))


# -- the linear limit -------------------------------------------------------------------------------
def test_hb_equals_the_linear_frf_when_the_stops_never_close():
    # a gap of 1 m is never reached: HB with one harmonic is the FRF |(K - w^2 M + i w C)^-1 b P|
    s = DiscreteParams(gap=1.0).system()
    br = frc(s, B2, 2.0, 10.0, 900.0, H=1, stability=False)
    ref = linear_frf(s, B2, 2.0, br.freq_hz)
    err = np.max(np.abs(br.amplitude_m / ref - 1.0))
    assert err < 1e-10, f"HB against the FRF: {err:.2e}"
    assert len(br.freq_hz) > 100 and br.status == "stop" and br.folds == []
    # every harmonic but the first is zero, to round-off
    assert np.max(br.harmonic_amplitude_m[:, :, 0]) < 1e-14 * np.max(br.amplitude_m)


def test_more_harmonics_change_nothing_on_a_linear_curve():
    s = DiscreteParams(gap=1.0).system()
    br = frc(s, B2, 1.0, 15.0, 30.0, H=7, stability=False)
    assert np.max(np.abs(br.amplitude_m / linear_frf(s, B2, 1.0, br.freq_hz) - 1.0)) < 1e-10


# -- the exact projection of the stop forces ---------------------------------------------------------
@pytest.mark.parametrize("H", [1, 5])
def test_exact_projection_is_the_limit_of_aft(H):
    # AFT of a kinked force errs like N^-2: the exact projection is its limit
    rng = np.random.default_rng(H)
    ex = ExactGapBalance.for_system(P.system(), H, damped=True)
    X = 5 * P.gap * rng.standard_normal(ex.size) / np.arange(1, ex.size + 1)
    F = ex.aft(X)[0]
    Ns = [2**10, 2**12, 2**14]
    errs = [np.max(np.abs(HarmonicBalance.for_system(P.system(), H, N).aft(X)[0] - F)) / np.max(np.abs(F))
            for N in Ns]
    rate = -np.polyfit(np.log(Ns), np.log(errs), 1)[0]
    assert 1.7 < rate < 2.4, f"AFT error rate {rate:.2f} ({errs})"
    assert errs[-1] < 1e-7


def test_exact_projection_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    ex = ExactGapBalance.for_system(P.system(), 4, damped=True)
    X = 5 * P.gap * rng.standard_normal(ex.size) / np.arange(1, ex.size + 1)
    F, dF = ex.aft(X)
    h = 1e-9 * P.gap
    J = np.column_stack([(ex.aft(X + h * e)[0] - ex.aft(X - h * e)[0]) / (2 * h) for e in np.eye(ex.size)])
    # no kinks to step over: the exact projection is C^1 in X (round-off of F / h ~ 1e-7)
    assert np.max(np.abs(J - dF)) / np.max(np.abs(dF)) < 5e-6


def test_contact_intervals_of_a_cosine():
    # p = cos(tau) - cos(0.3): positive on (-0.3, 0.3) (one interval across tau = 0)
    H = 3
    a = np.zeros(2 * H + 1)
    a[0], a[1] = -math.cos(0.3), 1.0
    alpha, beta = contact_intervals(a, _derivative_matrix(H), 64)
    assert alpha.size == 1
    assert alpha[0] == pytest.approx(2 * np.pi - 0.3, abs=1e-14)
    assert beta[0] == pytest.approx(2 * np.pi + 0.3, abs=1e-14)
    # and a sin(3 tau) - 0.5: three intervals of equal length
    b = np.zeros(2 * H + 1)
    b[0], b[6] = -0.5, 1.0
    alpha, beta = contact_intervals(b, _derivative_matrix(H), 64)
    assert alpha.size == 3 and np.allclose(beta - alpha, 2 * (np.pi / 2 - math.asin(0.5)) / 3, atol=1e-13)


def test_condensed_balance_solves_the_full_balance():
    # the condensed unknowns (the contact coordinates) give an X that solves the full HB residual
    br = frc(P.system(), B2, 1.0, 10.0, 21.0, H=5, stability=False)
    X, w = br.X[-1], br.omega[-1]
    ex = ExactGapBalance.for_system(P.system(), 5, damped=True)
    F_ext = np.zeros_like(X)
    F_ext[1] = B2
    R = ex.residual(X.ravel(), w)[0] - F_ext.ravel()
    assert np.max(np.abs(R)) < 1e-9  # N, against a 1 N load
    assert np.max(max_abs_over_period(X, P.system().B)) > P.gap  # in contact: the test means something


def test_condensed_jacobian_matches_finite_differences():
    fb = ForcedBalance(P.system(), B2, 1.0, 0.0, 3, 64, False)
    br = frc(P.system(), B2, 1.0, 10.0, 20.0, H=3, stability=False)
    z, w = br.z[-1], br.omega[-1]
    R, J, dw = fb.residual(z, w)
    h = 1e-10
    Jf = np.column_stack([(fb.residual(z + h * e, w)[0] - fb.residual(z - h * e, w)[0]) / (2 * h)
                          for e in np.eye(z.size)])
    assert np.max(np.abs(Jf - J)) / np.max(np.abs(J)) < 1e-6
    dwf = (fb.residual(z, w * (1 + 1e-7))[0] - fb.residual(z, w * (1 - 1e-7))[0]) / (2e-7 * w)
    assert np.max(np.abs(dwf - dw)) / np.max(np.abs(dw)) < 1e-6


# -- folds, the jump and stability ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def jump():
    """The gap oscillator's curve at 1 N (amplitude up to 3.7 gaps): it bends right and folds twice."""
    return frc(oscillator(), np.ones(1), 1.0, 5.0, 40.0, H=9, hill_points=None)


def test_hardening_curve_folds_twice_and_its_middle_branch_is_unstable(jump):
    br = jump
    assert len(br.folds) == 2, br.folds
    hi, lo = br.folds
    assert br.freq_hz[hi] > br.freq_hz[lo] > 10.0  # the upper fold to the right of the lower one
    kinds = dict(br.bifurcations)
    assert [kinds.get(i) or kinds.get(i + 1) for i in (hi, lo)] == ["fold", "fold"]
    # stable up to the upper fold, unstable between the folds, stable after the lower one
    assert br.stable[:hi - 1].all() and not br.stable[hi + 1:lo - 1].any() and br.stable[lo + 1:].all()
    # a fold: one real multiplier through +1
    mu = br.multipliers[(hi + lo) // 2]
    assert mu[0].real > 1.0 and abs(mu[0].imag) < 1e-9


def test_hill_and_monodromy_agree_on_the_gap_oscillator(jump):
    br = jump
    assert np.array_equal(br.hill_index, np.arange(len(br.freq_hz)))
    mono, hill = np.abs(br.multipliers), np.abs(br.hill)
    # Liouville: mu_1 mu_2 = det Phi = exp(-c T / m) on any orbit, so where the two multipliers are a
    # complex pair (90 of the 121 points: all the stable ones but the fold's neighbours) both have
    # |mu| = exp(-c T / 2m) exactly, and elsewhere their product is exp(-c T / m)
    T = 1.0 / br.freq_hz
    pair = np.abs(br.multipliers[:, 0].imag) > 1e-9
    assert pair.sum() > 50 and (~pair).sum() > 20
    for mu in (mono, hill):
        assert np.allclose(mu[pair], np.exp(-2.5 * T[pair] / 2)[:, None], rtol=1e-12, atol=0.0)
        assert np.allclose(np.prod(mu, axis=1), np.exp(-2.5 * T), rtol=1e-12, atol=0.0)
    # on the real pairs (the unstable middle branch and the fold's neighbours) Hill truncates the
    # perturbation's series at H = 9 while the monodromy is exact for the HB orbit: measured 2.5e-3
    # at most between the two, against a distance of |mu| from 1 of at least 0.013 at every point, so
    # the verdicts agree at every point (before: 97 % of them)
    assert np.max(np.abs(hill[:, 0] / mono[:, 0] - 1.0)) < 5e-3
    assert np.min(np.abs(mono[:, 0] - 1.0)) > 0.01
    assert np.array_equal(br.hill_stable, br.stable)


def test_shooting_on_the_exact_flow_confirms_stability(jump):
    br = jump
    s = oscillator()
    for i in (5, (br.folds[0] + br.folds[1]) // 2, len(br.freq_hz) - 5):
        f = float(br.freq_hz[i])
        flow = Flow(s, loads=Loads(np.ones((1, 1)), (Harmonic(1.0, f),)))
        orb = floquet_by_shooting(flow, hb_states(br.X[i], br.omega[i], 4), 1.0 / f)
        assert orb.stable == bool(br.stable[i])
        # on the two stable points the multipliers are a complex pair, |mu| = exp(-c T / 2m) for the
        # exact and the HB orbit alike (1e-14); on the unstable one the HB orbit's truncation at H = 9
        # shows: measured 9.4e-4
        assert orb.max_multiplier == pytest.approx(np.abs(br.multipliers[i, 0]), rel=2e-3)


def test_stepped_sine_up_and_down_land_on_the_two_stable_branches(jump):
    br = jump
    f_hi, f_lo = br.freq_hz[br.folds[0]], br.freq_hz[br.folds[1]]
    f_mid = 0.5 * (f_hi + f_lo)
    up = stepped_sine(oscillator(), np.ones(1), 1.0, np.linspace(8.0, f_mid, 12), settle_tol=1e-7,
                      max_settle_s=30.0)
    down = stepped_sine(oscillator(), np.ones(1), 1.0, np.linspace(30.0, f_mid, 12), settle_tol=1e-7,
                        max_settle_s=30.0)
    assert up.response[-1] == down.response[-1] == "periodic"
    a_up, a_down = up.amplitude_m[-1, 0], down.amplitude_m[-1, 0]
    assert a_up > 2 * a_down  # the jump: two stable responses at one frequency
    for a in (a_up, a_down):
        hb, _, _ = solution_at_frequency(br, f_mid, a)
        # H = 9 against the exact flow: the error of the truncation, not of the sweep
        assert hb[0] == pytest.approx(a, rel=2e-3)


def test_bifurcation_kinds_from_multipliers():
    inside = np.array([0.5, 0.4])
    mu = np.array([inside, [1.5, 0.4], [-1.5, 0.4], [1.2 * np.exp(1j), 1.2 * np.exp(-1j)]], dtype=complex)
    # point 1: +1 crossing, no fold near -> branch point; point 2 none (count unchanged); 3 none
    assert bifurcations(mu[:2], 1e-6) == [(1, "branch_point")]
    assert bifurcations(mu[:2], 1e-6, folds=[1]) == [(1, "fold")]
    assert bifurcations(np.array([inside, mu[2]]), 1e-6) == [(1, "period_doubling")]
    assert bifurcations(np.array([inside, mu[3]]), 1e-6) == [(1, "neimark_sacker")]


def test_forced_hill_on_a_linear_orbit_is_the_damped_modes():
    # linear system: the multipliers are exp(lam_r T) of the damped modes, whatever the forcing.
    # Hill folds an exponent into the first zone only if H Omega exceeds its frequency: the
    # 700 Hz mode at 30 Hz needs H >= 24
    s = DiscreteParams(gap=1.0).system()
    br = frc(s, B2, 1.0, 30.0, 31.0, H=25, stability=True, hill_points=None)
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(s.M, s.K), -np.linalg.solve(s.M, s.C)]])
    lam = np.linalg.eigvals(A)
    T = 1.0 / br.freq_hz[0]
    ref = np.sort(np.abs(np.exp(lam * T)))
    assert np.allclose(np.sort(np.abs(br.hill[0])), ref, rtol=1e-8)
    assert np.allclose(np.sort(np.abs(br.multipliers[0])), ref, rtol=1e-10)


# -- odd harmonics, the backbone -----------------------------------------------------------------------
def test_odd_harmonics_give_the_same_curve_on_a_symmetric_system():
    s = P.system()
    a = frc(s, B2, 1.0, 10.0, 30.0, H=5, harmonics="all", stability=False)
    b = frc(s, B2, 1.0, 10.0, 30.0, H=5, harmonics="odd", stability=False)
    for f in (12.0, 20.0, 25.0):
        amp_a = solution_at_frequency(a, f, None, 1, stable_only=False)[0]
        amp_b = solution_at_frequency(b, f, amp_a[1], 1, stable_only=False)[0]
        assert np.allclose(amp_a, amp_b, rtol=1e-9)


def test_peaks_approach_the_backbone_as_damping_and_load_vanish_together():
    # P / c fixed: the peak amplitude stays ~3.7 gaps while the peak moves onto the NNM backbone
    s0 = oscillator()
    nb = nnm_branch(s0, 0, H=1, N=4096, energy_max_J=10.0, ds=0.01, ds_max=0.01, max_steps=20000)
    a_bb = np.array([max_abs_over_period(x.reshape(3, 1), np.eye(1))[0] for x in nb.X])
    dist = []
    for eps in (1.0, 0.1, 0.01):
        br = frc(oscillator(c=2.5 * eps), np.ones(1), 1.0 * eps, 5.0, 40.0, H=1, stability=False)
        i = int(np.argmax(br.amplitude_m[:, 0]))
        f_bb = np.interp(br.amplitude_m[i, 0], a_bb, nb.freq_hz)  # the backbone at the peak's amplitude
        dist.append(abs(br.freq_hz[i] / f_bb - 1.0))
    assert dist[0] > dist[1] > dist[2] and dist[2] < 1e-3, dist


# -- the stepped sine ------------------------------------------------------------------------------------
def test_stepped_sine_of_a_linear_system_is_the_frf():
    s = DiscreteParams(gap=1.0).system()
    f = np.array([12.0, 17.9, 25.0, 700.0])
    ss = stepped_sine(s, B2, 1.0, f, settle_tol=1e-8)
    assert all(r == "periodic" for r in ss.response)
    err = np.max(np.abs(ss.amplitude_m / linear_frf(s, B2, 1.0, f) - 1.0))
    assert err < 3e-6, err  # settle tolerance + the sampled maximum, (pi / 2048)^2 / 2
    assert np.max(ss.asymmetry) < 1e-9


def test_stepped_sine_reports_the_unsettled_symmetric_contact():
    # at 1 N near 17-20 Hz the symmetric orbit is unstable once the tips touch (shown by shooting in
    # tests/test_frc_contact.py: |mu| = 720 at 17 Hz)
    ss = stepped_sine(P.system(), B2, 1.0, [14.0, 16.0, 17.5, 19.0], settle_tol=1e-6, max_settle_s=10.0)
    assert ss.response[:2] == ["periodic", "periodic"]
    assert ss.response[3] == "not_settled" and ss.asymmetry[3] > 0.05


# -- bad arguments ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, name", [
    ({"load": [0.0, 1.0]}, "load"),
    ({"load": [0.0, 0.0, 0.0]}, "load"),
    ({"amplitude_N": 0.0}, "amplitude_N"),
    ({"amplitude_N": float("nan")}, "amplitude_N"),
    ({"f_min_hz": -1.0}, "f_min_hz"),
    ({"f_max_hz": 5.0}, "f_max_hz"),
    ({"H": 0}, "H"),
    ({"H": True}, "H"),
    ({"harmonics": "even"}, "harmonics"),
    ({"N": 2}, "N"),
    ({"point_rows": np.eye(2)}, "point_rows"),
    ({"ds": -0.1}, "ds"),
    ({"stability": "yes"}, "stability"),
    ({"hill_points": -1}, "hill_points"),
    ({"progress": 3}, "progress"),
])
def test_bad_arguments_are_refused_in_one_line(kwargs, name):
    args = {"system": P.system(), "load": B2, "amplitude_N": 1.0, "f_min_hz": 10.0, "f_max_hz": 20.0, "H": 1}
    args.update(kwargs)
    with pytest.raises(InvalidArgument) as exc:
        frc(**args)
    msg = str(exc.value)
    assert name in msg and "\n" not in msg


def test_a_system_without_stops_is_refused():
    s = DiscreteParams().system()
    bare = GapSystem(M=s.M, C=s.C, K=s.K, B=np.zeros((0, 3)), k=np.zeros(0), offset=np.zeros(0),
                     side=np.zeros(0), tip=np.zeros(0, int), dof_names=s.dof_names, stop_names=())
    with pytest.raises(InvalidArgument, match="no stops"):
        frc(bare, B2, 1.0, 10.0, 20.0)


def test_stepped_sine_refuses_an_undamped_system():
    s = DiscreteParams(c=0.0).system()
    with pytest.raises(InvalidArgument, match="damped"):
        stepped_sine(s, B2, 1.0, [10.0])


# -- the stage ----------------------------------------------------------------------------------------------
def _quick_scene() -> str:
    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / "discrete-frc.toml").read_text("utf-8"))
    data["frc"].update({"levels_N": [1.0], "freq_max_hz": 40.0, "harmonics": 3,
                        "convergence_harmonics": [1, 3], "hill_points": 3, "shooting_points": 2,
                        "stepped_sine_points": 6, "stepped_sine_max_s": 9.0, "backbone_scales": [1.0],
                        "map_step_hz": 0.0,  # the response map: tests/test_response_map.py
                        "verdict_points": 0, "close_return_families": 0,  # tests/test_cover_verdicts.py and
                        # tests/test_close_returns.py judge uncovered HB points and shoot close returns
                        # three switched families and one period-doubled (of the 12 + 4 the defaults follow here:
                        # half the stage's CPU, issue 28) still take two pitchfork kinds and a doubling into the
                        # files and the rerun (asserted below); the families themselves are checked by
                        # tests/test_exact_frc.py and tests/test_period_doubling.py
                        "max_families": 3, "period_doubling_families": 1,
                        # the families are born near the start of the main one (its points 25, 37 and 50; the
                        # doubling at point 1 of family 2, whose 110 points are all kept): 200 points of the main
                        # and of each switched family instead of 2219 and 1738 (the main one reaches 40 Hz, the
                        # asymmetric one wanders over 17-21 Hz) take the same births into the files at 45 % of
                        # the stage's CPU (issue 28). The main family then ends at 19.1 Hz, so the contact band
                        # above is not covered: the isolated families that would start there (cover_families)
                        # are tests/test_frc_cover.py's
                        "shooting_steps": 200, "family_steps": 200, "cover_families": 0})
    return tomli_w.dumps(data)


def test_frc_stage_writes_its_files_and_reruns_byte_for_byte(tmp_path, monkeypatch):
    import bearingshaft.stages.frc as stage
    from bearingshaft.pipeline import run_stage
    from bearingshaft.scenes import parse_scene

    monkeypatch.setattr(stage, "BACKBONE_DS", 0.05)  # a coarser backbone: the files, not its accuracy

    scene = parse_scene(_quick_scene(), "discrete-frc", "quick")
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        run_stage(scene, "frc", out, progress=False)
    names = sorted(p.name for p in outs[0].iterdir())
    for f in ("frc.csv", "frc.png", "frc_harmonics.csv", "frc_bifurcations.csv", "frc_stability.csv",
              "stepped_sine.csv", "frc_convergence.csv", "frc_convergence_timing.csv",
              "frc_convergence_timing.png", "frc_backbone.csv", "frc_backbone.png"):
        assert f in names, f
    for name in names:
        if name == "provenance.json" or name.rsplit(".", 1)[0].endswith("_timing"):
            continue
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name
    families = list(csv.DictReader(open(outs[0] / "frc_families.csv")))
    assert {"pitchfork_mirror_half_wave", "pitchfork_half_wave", "period_doubling"} <= {r["born_at"] for r in families}
    rows = list(csv.DictReader(open(outs[0] / "frc.csv")))
    assert list(rows[0])[:8] == ["level", "method", "harmonics", "freq_hz", "point", "amplitude_m", "stable",
                                 "bifurcation"]
    methods = {r["method"] for r in rows}
    # at 1 N a stop closes and HB moves with H: the drawn curve is the exact flow's (shooting)
    assert methods == {"hb", "shooting", "open_gap", "stepped_sine_up", "stepped_sine_down"}
    # beside them, where the HB orbit closes a stop, the open-gap orbit that closes none: the linear FRF there
    og = [r for r in rows if r["method"] == "open_gap"]
    assert og and {r["drawn"] for r in og} == {"true"} and {r["stable"] for r in og} == {"true"}
    col = {"x1": 0, "x2": 1, "x3": 2}
    lin = [linear_frf(P.system(), B2, float(r["level"]), np.array([float(r["freq_hz"])]))[0, col[r["point"]]]
           for r in og]
    # frequency and amplitude written to 10 digits; near the mode (f/A) dA/df reaches ~1e2: 1e-7 bounds it
    assert np.allclose([float(r["amplitude_m"]) for r in og], lin, rtol=1e-7, atol=0.0)
    assert {r["point"] for r in rows} == {"x1", "x2", "x3"}
    assert {r["stable"] for r in rows} <= {"true", "false"}
    hb_kinds = {"", "fold", "branch_point", "period_doubling", "neimark_sacker"}
    assert {r["bifurcation"] for r in rows if r["method"] != "shooting"} <= hb_kinds
    # the exact families tell the symmetry a branch point breaks (reduced.periodic.exact_frc)
    assert {r["bifurcation"] for r in rows if r["method"] == "shooting"} <= hb_kinds | {
        "pitchfork_mirror", "pitchfork_half_wave", "pitchfork_mirror_half_wave"}
    # the settled stepped-sine points sit on the stable HB branches
    sweep = list(csv.DictReader(open(outs[0] / "stepped_sine.csv")))
    ss = [r for r in sweep if r["rel_err_hb"] and r["response"] == "periodic"]
    assert ss and max(float(r["rel_err_hb"]) for r in ss) < 1e-5
    # Contact. At 1 N the tips close from 16.9 Hz up, and there the curve's orbit (symmetric, x1 = x3)
    # is unstable at every frequency sampled (shooting, 17-47 Hz: |mu| from 1.6 to 1.2e3;
    # tests/test_frc_contact.py shoots it at 17 and 21 Hz), so a sweep cannot settle on it and no stepped-sine
    # point in contact can be compared with this curve: every compared point is below the gap. What the
    # stage can show in contact it must show: the sweeps reach contact (17.1 and 20 Hz here), report
    # there a response that left the symmetric orbit (not settled, x1 != x3), and the stage's own
    # shooting finds the symmetric contact orbit unstable. HB against the exact flow in contact, and a
    # settled exact response in contact compared with HB (10 N, 12.25 Hz, where a stable symmetric
    # contact orbit exists), are in test_frc_contact.py.
    g = P.gap
    touching = [r for r in sweep if max(float(r["amplitude_x1_m"]), float(r["amplitude_x3_m"])) > g]
    assert len(touching) >= 2, "the sweeps never reach contact: the checks below would be empty"
    for r in touching:
        assert float(r["asymmetry"]) > 0.05 and r["response"] != "periodic" and r["rel_err_hb"] == "", r
    compared = [r for r in sweep if r["rel_err_hb"]]
    assert all(max(float(r["amplitude_x1_m"]), float(r["amplitude_x3_m"])) < g for r in compared)
    # the drawn curve: the exact families from f_min, and HB beside them only where no stop closes (there
    # the response is linear: HB is the closed-form receptance to Newton's tolerance). Here the families
    # (200 points each) cover 10-18.98 Hz and HB at H = 3 stays in contact up to 40 Hz: above 18.98 Hz
    # only the open-gap orbits are drawn (frc.md says so)
    drawn = [r for r in rows if r["drawn"] == "true" and r["point"] == "x1"]
    assert min(float(r["freq_hz"]) for r in drawn) <= 10.0 * (1 + 1e-9)
    s3 = P.system()
    for r in (r for r in drawn if r["method"] == "hb"):
        w = 2 * np.pi * float(r["freq_hz"])
        lin = abs(np.linalg.solve(s3.K - w**2 * s3.M + 1j * w * s3.C, B2)[0])
        assert float(r["amplitude_m"]) < g and abs(float(r["amplitude_m"]) / lin - 1.0) < 1e-8, r
    hb_x1 = [float(r["amplitude_m"]) for r in rows if r["method"] == "hb" and r["point"] == "x1"]
    shot = [r for r in csv.DictReader(open(outs[0] / "frc_stability.csv")) if r["shooting_stable"]]
    shot_contact = [r for r in shot if hb_x1[int(r["index"])] > g]
    assert shot_contact and all(r["shooting_stable"] == "false" for r in shot_contact), shot


def test_frc_scene_refusals(tmp_path, capsys):
    from bearingshaft.cli import main

    data = tomllib.loads(_quick_scene())
    path = tmp_path / "bad.toml"
    for change, word in (({"point": "x9"}, "[frc] point"), ({"harmonics": 4}, "harmonics must be odd"),
                         ({"freq_max_hz": 5.0}, "freq_max_hz"), ({"backbone_scales": [2.0]}, "backbone_scales[0]"),
                         ({"model": {"kind": "discrete", "c": 0.0}}, "no damping")):
        d = {**data, **{k: v for k, v in change.items() if k == "model"},
             "frc": {**data["frc"], **{k: v for k, v in change.items() if k != "model"}}}
        path.write_text(tomli_w.dumps(d))
        assert main(["check", "--scene", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and word in err[0], err
    assert not (tmp_path / "o").exists()


# -- slow: the stage's comparison at full size ------------------------------------------------------------
@pytest.mark.slow
def test_stepped_sine_sweeps_land_on_the_stable_hb_branches_at_every_level():
    s = P.system()
    for level in (0.1, 1.0, 10.0):
        br = frc(s, B2, level, 10.0, 900.0, H=15, harmonics="odd", hill_points=0)
        freqs = np.geomspace(10.0, 900.0, 30)
        for ss in (stepped_sine(s, B2, level, freqs), stepped_sine(s, B2, level, freqs[::-1])):
            n = 0
            for j, f in enumerate(ss.freq_hz):
                if ss.response[j] != "periodic":
                    continue
                a, _, _ = solution_at_frequency(br, float(f), float(ss.amplitude_m[j, 1]), 1)
                if a is None:
                    continue
                n += 1
                assert np.max(np.abs(a / ss.amplitude_m[j] - 1.0)) < 1e-5, (level, f)
            assert n >= 20
