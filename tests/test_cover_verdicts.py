"""Verdicts at HB points in contact that no exact family covers (reduced.periodic.uncovered.cover_verdicts,
issue 25), against the library's exact integrator.

The three-mass model at 10 N (discrete-frc). The context is a short piece of the main family near
27.5 Hz (20 steps from the orbit of tests/test_frc_cover.py), so 22.41 Hz and 10 Hz are uncovered:

- at 22.41 Hz the guess is the orbit of discrete-frc's isolated family (4 digits, tests/test_frc_cover.py,
  marched to the verdict's nodes by the library's integrator): the verdict is ``orbit``, a family starts
  there, and its orbit at 22.41 Hz is a fixed point of the library's integrator over T;
- at 10 Hz the guess is the HB orbit (H = 15) in hard contact, where discrete-frc's stepped sine is
  chaotic: no orbit of the exact flow near it, with the best defect met, which is the defect of no
  point closer than the HB guess's own (Newton only lowers it);
- points of the band between the judged ones are ``not_judged`` or, in the new family's range, ``covered``.
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
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc, hb_start
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.uncovered import cover_verdicts
from reduced.transient.flow import Flow

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_frc_cover import F_ISO, F_MAIN, SEED_ISO, SEED_MAIN, X_REF, B, P  # noqa: E402

BAND = (10.0, 28.0)  # Hz


def _marched(s, seed: np.ndarray, f: float):
    """nodes_of(S): the orbit through seed[0] at t_j = j T / S by the library's integrator (a guess)."""
    def nodes_of(S: int) -> np.ndarray:
        fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, f),)))
        h = 1.0 / f / S
        out, y = [], seed[0]
        for j in range(S):
            out.append(y)
            y = fl(y[:3], y[3:], h, t0=j * h).y
        return np.array(out)
    return nodes_of


@functools.cache
def _run():
    s = DiscreteParams().system()
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ex = exact_frc(s, B, P, *BAND, [(F_MAIN, SEED_MAIN)], x_ref=X_REF,
                       options=ExactFRCOptions(branch_switching=False, max_steps=20, cover_families=0))
        hb10 = _hb10(s)  # (32, 6): at the phases of 16 and 8 nodes too
        guesses = [(10.0, float(np.max(np.abs(hb10[:, 0]))), lambda S: hb10[:: 32 // S]),
                   (15.0, 0.0, None),  # between: not judged (2 a band), its guess never asked for
                   (F_ISO, float(np.max(np.abs(SEED_ISO[:, 0]))), _marched(s, SEED_ISO, F_ISO))]
        out = cover_verdicts(ex, s, B, guesses, points_per_band=2, f_band=BAND, family_steps=30)
    return s, ex, out


def test_the_guess_near_an_exact_orbit_starts_a_family_whose_orbit_the_integrator_closes():
    s, ex, out = _run()
    v = next(v for v in out if v.freq_hz == F_ISO)
    assert v.verdict == "orbit" and v.family >= 1 and v.defect < 1e-12, v
    fam = ex.families[v.family]
    assert fam.kind == "isolated" and fam.freq_hz.min() <= F_ISO <= fam.freq_hz.max()
    res = ShootingResidual(ForcedFlow(s, B, P), fam.nodes.shape[1], 1, X_REF, 2 * np.pi * BAND[1])
    y0 = res.nodes(shoot_at(res, fam.nodes[int(np.argmin(np.abs(fam.freq_hz - F_ISO)))], 2 * np.pi * F_ISO))[0][0]
    fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, F_ISO),)))
    scale = np.concatenate([np.full(3, X_REF), np.full(3, 2 * np.pi * F_ISO * X_REF)])
    # the shooting tolerance (1e-11 scaled) times the orbit's multipliers (<= 1e3 here), plus two kernels' round-off
    assert float(np.max(np.abs(fl(y0[:3], y0[3:], 1.0 / F_ISO).y - y0) / scale)) < 1e-7


def test_the_hb_guess_in_the_chaotic_band_has_no_orbit_near_it():
    s, ex, out = _run()
    v = out[0]
    assert v.freq_hz == 10.0 and v.verdict == "no_orbit" and v.family == -1, v
    assert v.iterations > 10 and v.segments == 32  # both node counts tried (16, then 32)
    # the defect of the HB guess itself on 32 nodes, by the library's integrator: Newton's best is no larger
    nodes = _hb10(s)
    fl = Flow(s, loads=Loads(B[None, :], (Harmonic(P, 10.0),)))
    h = 0.1 / 32
    res = ShootingResidual(ForcedFlow(s, B, P), 32, 1, X_REF, 2 * np.pi * BAND[1], _fastest(s))
    Y = res.point(nodes, 2 * np.pi * 10.0)
    d_hb = float(np.max(np.abs(res.value(Y)))) / float(np.max(np.abs(Y[:-1])))
    marched = np.array([fl(nodes[j, :3], nodes[j, 3:], h, t0=j * h).y for j in range(32)])
    gap = np.max(np.abs((marched - np.roll(nodes, -1, axis=0)) / res.scale(2 * np.pi * 10.0))) / np.max(
        np.abs(Y[:-1]))
    assert abs(gap / d_hb - 1.0) < 1e-6  # the residual is the integrator's defect (the same flow, two kernels)
    assert 1e-3 < v.defect <= d_hb, (v.defect, d_hb)


def test_points_between_are_not_judged_or_covered():
    _, ex, out = _run()
    assert [v.freq_hz for v in out] == [10.0, 15.0, F_ISO]
    mid = out[1]
    assert mid.verdict == "not_judged" and mid.segments == 0, mid
    assert all(v.band_hz == (10.0, F_ISO) for v in out)


@functools.cache
def _hb10(s) -> np.ndarray:
    return hb_start(s, B, P, 10.0, 32)


def _fastest(s) -> float:
    return float(np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(s.M, s.K)).real)))
