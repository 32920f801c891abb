"""Isolated families of the forced exact flow (reduced.periodic.exact_frc, issue 25): the orbits of
the contact band that the main family does not reach, started from guesses at frequencies no family
covers, against independent checks.

The three-mass model at 10 N (the discrete-frc scene): the main family found at 27.5 Hz turns at a
fold at 26.82 Hz and leaves the band upwards, so nothing below 26.82 Hz is on it (discrete-frc's
frc.md before isolated families: 10-26.8 Hz, 41 HB points in contact, not drawn). A guess of an
orbit at 22.41 Hz (the nodes of a discrete-frc run, to 4 digits: Newton converges from it, nothing
below is compared with it) starts an isolated family over 21-28 Hz, checked here:

- its orbits are fixed points of the map over T of the library's exact integrator (another kernel
  than the shooting residual's), at frequencies below the main family's fold;
- it is not the main family: where both exist its orbits differ from the main family's;
- a guess whose orbit lies on a family already found (or its half-wave image) starts no family.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.exact_frc import ExactFRCOptions, _isolated, covered, exact_frc
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.transient.flow import Flow

P = 10.0  # N
B = np.array([0.0, 1.0, 0.0])
X_REF = 2.8287e-4  # m, the discrete-frc curve's displacement scale at 10 N
BAND = (21.0, 28.0)  # Hz
F_MAIN, F_ISO = 27.521742541076105, 22.408047475928637  # Hz
SEED_MAIN = np.array([  # (8, 6) nodes [x; v] of the main family's orbit at F_MAIN, 4 digits (a guess only)
    [-2.538e-04, -2.546e-04, -2.538e-04, 2.306e-03, 5.288e-03, 2.306e-03],
    [-1.677e-04, -1.674e-04, -1.677e-04, 3.023e-02, 3.478e-02, 3.023e-02],
    [1.254e-05, 1.360e-05, 1.254e-05, 4.260e-02, 4.358e-02, 4.260e-02],
    [1.861e-04, 1.867e-04, 1.861e-04, 3.126e-02, 2.764e-02, 3.126e-02],
    [2.538e-04, 2.546e-04, 2.538e-04, -2.306e-03, -5.288e-03, -2.306e-03],
    [1.677e-04, 1.674e-04, 1.677e-04, -3.023e-02, -3.478e-02, -3.023e-02],
    [-1.254e-05, -1.360e-05, -1.254e-05, -4.260e-02, -4.358e-02, -4.260e-02],
    [-1.861e-04, -1.867e-04, -1.861e-04, -3.126e-02, -2.764e-02, -3.126e-02]])
SEED_ISO = np.array([  # (8, 6) nodes of the orbit at F_ISO of discrete-frc's isolated family, 4 digits (a guess)
    [2.570e-04, 2.637e-04, 2.570e-04, -1.313e-02, 2.823e-02, -1.313e-02],
    [1.261e-04, 1.258e-04, 1.261e-04, -2.663e-02, -2.123e-02, -2.663e-02],
    [8.455e-06, 7.125e-06, 8.455e-06, -2.092e-02, -1.850e-02, -2.092e-02],
    [-1.095e-04, -1.114e-04, -1.095e-04, -2.325e-02, -2.457e-02, -2.325e-02],
    [-2.570e-04, -2.637e-04, -2.570e-04, 1.313e-02, -2.823e-02, 1.313e-02],
    [-1.261e-04, -1.258e-04, -1.261e-04, 2.663e-02, 2.123e-02, 2.663e-02],
    [-8.455e-06, -7.125e-06, -8.455e-06, 2.092e-02, 1.850e-02, 2.092e-02],
    [1.095e-04, 1.114e-04, 1.095e-04, 2.325e-02, 2.457e-02, 2.325e-02]])


@functools.cache
def _run():
    s = DiscreteParams().system()
    opts = ExactFRCOptions(branch_switching=False, cover_families=1)
    with single_thread_blas():
        out = exact_frc(s, B, P, *BAND, [(F_MAIN, SEED_MAIN)], x_ref=X_REF, options=opts,
                        cover=[(F_ISO, SEED_ISO), (F_MAIN, SEED_MAIN)])
    return s, out


def test_isolated_family_covers_the_band_below_the_main_familys_fold():
    _, out = _run()
    main = out.families[0]
    assert main.kind == "main" and main.freq_hz.min() > 26.8, main.freq_hz.min()  # the fold at 26.82 Hz
    iso = [f for f in out.families if f.kind == "isolated"]
    assert len(iso) == 1, [f.kind for f in out.families]
    # continued down to the band's edge (21 Hz) from 22.41 Hz, and up past the main family's fold
    assert iso[0].freq_hz.min() < 21.05 and iso[0].freq_hz.max() > 26.82, (iso[0].freq_hz.min(), iso[0].freq_hz.max())
    f = np.linspace(21.1, 26.7, 15)
    assert not covered([main], f).any() and covered(out.families, f).all()
    # only the uncovered guess was tried (the one at 27.5 Hz lies on the main family's range)
    assert [r["freq_hz"] for r in out.cover] == [F_ISO] and out.cover[0]["family"] == 1
    assert out.uncovered_bands() == []


def test_isolated_orbits_are_fixed_points_of_the_exact_period_map():
    # the library's exact integrator (its own kernel, Taylor-polynomial load) marches orbits of the
    # isolated family below the main family's fold from their first node: back on it after T to the
    # shooting tolerance (1e-11, scaled) amplified by the orbit's instability (|mu| up to ~1e3 here) and
    # the integrator's round-off: 1e-7 leaves 3 decades of margin over the defects measured (5e-13 to 3e-10)
    s, out = _run()
    fam = next(f for f in out.families if f.kind == "isolated")
    below = np.flatnonzero(fam.freq_hz < 26.5)
    for j in below[np.linspace(0, len(below) - 1, 4).astype(int)]:
        f = float(fam.freq_hz[j])
        y0 = fam.nodes[j][0]
        fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, f),)))
        scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * math.pi * f * X_REF)])
        y1 = fl(y0[:3], y0[3:], 1.0 / f).y
        d1 = float(np.max(np.abs(y1 - y0) / scale))
        assert d1 < 1e-7 * max(1.0, float(np.abs(fam.multipliers[j, 0])) / 1e3), (f, d1, fam.multipliers[j, 0])
        yh = fl(y0[:3], y0[3:], 0.5 / f).y  # half-wave symmetric orbit or not, it is not a fixed point over T/2
        assert float(np.max(np.abs(yh - y0) / scale)) > 1e-3


def test_isolated_family_is_not_the_main_family():
    # over 26.82-28 Hz both exist: at each main point the isolated family's orbit (Newton from its nearest
    # point, at that frequency) is another orbit (nodes differ by far more than the shooting tolerance)
    s, out = _run()
    main, iso = out.families[0], next(f for f in out.families if f.kind == "isolated")
    res = ShootingResidual(ForcedFlow(s, B, P), 8, 1, X_REF, 2 * math.pi * BAND[1])
    for j in np.linspace(0, len(main.freq_hz) - 1, 4).astype(int):
        f = float(main.freq_hz[j])
        if not iso.freq_hz.min() < f < iso.freq_hz.max():
            continue
        k = int(np.argmin(np.abs(iso.freq_hz - f)))
        other = res.nodes(shoot_at(res, iso.nodes[k], 2 * math.pi * f))[0]
        assert float(np.max(np.abs(other[:, :3] - main.nodes[j][:, :3]))) > 1e-3 * X_REF, f


def test_a_guess_on_a_known_family_starts_no_family():
    # the orbit of the main family at one of its points, and its half-wave image (x -> -x, shifted by T/2),
    # given as guesses: Newton lands on the main family's orbit, which is recognised, and nothing is followed
    s, out = _run()
    main = out.families[0]
    res = ShootingResidual(ForcedFlow(s, B, P), 8, 1, X_REF, 2 * math.pi * BAND[1])
    families, residuals = list(out.families), {k: (res, None) for k in range(len(out.families))}
    j = len(main.freq_hz) // 2
    f = float(main.freq_hz[j])
    for guess in (main.nodes[j], -np.roll(main.nodes[j], -4, axis=0)):
        with single_thread_blas():
            note = _isolated(families, [], residuals, (f, guess), res, out.options, (math.log(BAND[0] / BAND[1]), 0.0),
                             np.eye(3), out.symmetry, _Budget(), False)
        assert "one of family 0" in note, note
        assert len(families) == len(out.families)


class _Budget:
    def left(self) -> bool:
        return True


@functools.cache
def _found_with_switching(max_new: int):
    """The isolated family from the guess at F_ISO (60 points each way) as a family found late is: with its
    own allowance of ``max_new`` switched families (``_switch_all(max_new=)``, 40 points each way), the main
    family (20 points) having no switches at all."""
    from dataclasses import replace

    from reduced.periodic.exact_frc import _Budget as Budget
    from reduced.periodic.uncovered import _residuals

    s = DiscreteParams().system()
    with single_thread_blas():
        ex = exact_frc(s, B, P, *BAND, [(F_MAIN, SEED_MAIN)], x_ref=X_REF,
                       options=ExactFRCOptions(branch_switching=False, cover_families=0, max_steps=20))
        res, residuals, band, _ = _residuals(ex, ForcedFlow(s, B, P), BAND)
        opts = replace(ex.options, cover_steps=60, family_steps=40, period_doubling_steps=40)
        note = _isolated(ex.families, ex.switches, residuals, (F_ISO, SEED_ISO), res, opts, band, ex.point_rows,
                         ex.symmetry, Budget(math.inf), True, max_new)
    assert note == "", note
    return s, ex


def test_a_family_found_late_switches_within_its_own_allowance():
    # the main family's switching is off, so the level's max_families plays no part: the isolated family's
    # first pitchfork in path order (its 30th point, near 21.7 Hz, breaking the mirror symmetry x1 = x3 of
    # a half-wave symmetric orbit) gets the one family allowed; every later one is listed, not followed
    from reduced.periodic.exact_frc import SWITCHED

    s, ex = _found_with_switching(1)
    iso, child = ex.families[1], ex.families[2]
    assert [f.kind for f in ex.families] == ["main", "isolated", "asymmetric_half_wave"]
    recs = [r for r in ex.switches if r["family"] == 1]
    assert len(recs) == sum(k in SWITCHED for _, k in iso.bifurcations) >= 5  # each branch point has its record
    first, rest = recs[0], recs[1:]
    assert first["child"] == 2 and child.parent == (1, first["index"], first["kind"]) and not first["note"]
    assert SWITCHED[first["kind"]] == child.kind and 21.5 < first["freq_hz"] < 22.0, first
    assert all(r["child"] == -1 and "the 1 switched family allowed from family 1" in r["note"] for r in rest)
    # the switched family's orbits: fixed points of the library integrator's map over T (as the isolated
    # family's, same tolerance and reason), and not mirror symmetric (x1 != x3 by far more than round-off)
    fl_scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * math.pi * 22.0 * X_REF)])
    asym = []
    for j in np.linspace(1, len(child.freq_hz) - 1, 4).astype(int):
        f, y0 = float(child.freq_hz[j]), child.nodes[j][0]
        fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, f),)))
        d1 = float(np.max(np.abs(fl(y0[:3], y0[3:], 1.0 / f).y - y0) / fl_scale))
        assert d1 < 1e-7 * max(1.0, float(np.abs(child.multipliers[j, 0])) / 1e3), (f, d1)
        asym.append(float(np.max(np.abs(child.nodes[j][:, 0] - child.nodes[j][:, 2]))) / X_REF)
    assert max(asym) > 0.05, asym  # measured 0.02-0.17 along the 40 points; the parent has 0 (round-off)


def test_an_allowance_of_none_lists_the_branch_points_and_follows_none():
    _, ex = _found_with_switching(0)
    assert [f.kind for f in ex.families] == ["main", "isolated"]
    recs = [r for r in ex.switches if r["family"] == 1]
    assert len(recs) >= 5 and all(r["child"] == -1 and "the 0 switched families allowed" in r["note"] for r in recs)
