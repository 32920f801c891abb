"""Pseudo-arclength continuation: folds, corners, stop rule, tongues."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.models.modes import linear_modes
from reduced.periodic.backbones import nnm_branch
from reduced.periodic.continuation import continue_branch

SYS = DiscreteParams().system()


def circle(y):
    return np.array([y[0] ** 2 + y[1] ** 2 - 1.0]), np.array([[2 * y[0], 2 * y[1]]])


def test_circle_folds_are_detected_and_points_stay_on_it():
    br = continue_branch(
        circle,
        np.array([0.0, 1.0]),
        param=0,
        ds=0.1,
        ds_max=0.2,
        max_steps=200,
        stop=lambda y: y[0] < -0.5 and y[1] > 0,
    )
    assert br.status == "stop"
    assert np.allclose(np.hypot(br.y[:, 0], br.y[:, 1]), 1.0, atol=1e-12)
    # y0 turns at (1, 0) and (-1, 0): two folds of coordinate 0, in that order
    fold_x = [br.y[i, 0] for i, c in br.folds if c == 0]
    assert len(fold_x) == 2 and fold_x[0] > 0.95 and fold_x[1] < -0.95


def test_reject_that_takes_the_tangent_gets_the_unit_tangent_of_the_new_point():
    # on the unit circle the tangent at (x, y) is +-(-y, x) in closed form: the tangent handed to a
    # reject with ``takes_tangent`` is that, to round-off (1e-14: a 3 x 3 solve of entries O(1)),
    # and the path is the one a plain reject (which accepts every step) gives, to the bit
    seen = []

    def reject(yo, yn, tn=None):
        seen.append((yn.copy(), None if tn is None else tn.copy()))
        return False

    reject.takes_tangent = True
    kw = dict(param=0, ds=0.1, ds_max=0.2, max_steps=40)
    br = continue_branch(circle, np.array([0.0, 1.0]), reject=reject, **kw)
    plain = continue_branch(circle, np.array([0.0, 1.0]), reject=lambda yo, yn: False, **kw)
    assert np.array_equal(br.y, plain.y)
    assert len(seen) == len(br.y) - 1 and all(tn is not None for _, tn in seen)
    for (yn, tn), t_branch in zip(seen, br.tangent[1:], strict=True):
        exact = np.array([-yn[1], yn[0]]) / np.hypot(*yn)
        assert abs(abs(float(tn @ exact)) - 1.0) < 1e-14
        assert np.allclose(tn, t_branch, rtol=0, atol=1e-15)  # the one the branch records


@pytest.mark.parametrize("kind, c", [("sqrt", 0.1), ("kink", 10.0)])
def test_corners_are_passed(kind, c):
    # y1 = c sqrt(y0 - 1) (a vertical tangent, like a backbone at grazing) or
    # y1 = c (y0 - 1) (an 84 degree kink, like an AFT sample entering contact) for y0 > 1,
    # y1 = 0 before: the branch must turn the corner and go on to y0 = 2
    def f(y):
        d = y[0] - 1.0
        if d <= 0:
            return np.array([y[1]]), np.array([[0.0, 1.0]])
        if kind == "sqrt":
            return np.array([y[1] - c * math.sqrt(d)]), np.array([[-0.5 * c / math.sqrt(d), 1.0]])
        return np.array([y[1] - c * d]), np.array([[-c, 1.0]])

    br = continue_branch(
        f,
        np.array([0.0, 0.0]),
        param=0,
        ds=0.1,
        ds_max=0.2,
        max_steps=400,
        stop=lambda y: y[0] >= 2.0,
        monitor=(1,),
    )
    assert br.status == "stop" and br.y[-1, 0] >= 2.0
    assert all(abs(f(y)[0][0]) < 1e-9 for y in br.y)
    assert np.all(np.diff(br.y[:, 0]) > 0)  # never turned back


def test_stop_on_energy_and_grazing_corner_with_harmonics():
    b = nnm_branch(SYS, 1, H=3, energy_max_J=1e3)
    assert b.status == "stop" and 1e3 <= b.energy_J[-1] < 1e4
    # the branch keeps rising in frequency through the grazing corner
    assert b.freq_hz[-1] > 3 * b.freq_hz[0]


def test_nnm1_tongues_are_reported_not_jumped():
    b = nnm_branch(SYS, 0, H=5, energy_max_J=1e5)
    assert b.tongues, "H = 5 meets the 5:1 resonance with NNM 3 near 140 Hz"
    for t in b.tongues:
        assert t["action"] in ("stepped over", "stopped")
        assert t["harmonic"] >= 2
    # every continued piece is itself continuous (no jump larger than the step control
    # allows) and pieces are reported in `segment`
    assert b.segment.max() == sum(t["action"] == "stepped over" for t in b.tongues)
    for s in np.unique(b.segment):
        f = b.freq_hz[b.segment == s]
        assert np.all(np.abs(np.diff(np.log(f))) < 0.3)


def _crosses_its_tongues(H: int) -> None:
    """Every NNM continued with H harmonics to >= 1e5 J; NNM 1 crosses each k:1 tongue on the way
    by stepping over it (or following it round), none stopped.

    Independent reference for where the tongues are: a k:1 internal resonance of NNM 1 with
    NNM 3 needs k f_1 = f_3, and the frequency of a motion in NNM 3 lies between its open- and
    closed-gap linear frequencies (699.9 and 1302.7 Hz: the piecewise-linear stiffness is
    bounded by the two states'), so each tongue's k f_1 must fall in that range. NNM 1's orbit
    is symmetric (half a period later it is mirrored: x(t + T/2) = -x(t)), so only odd harmonics
    are excited: the tongues are at odd k from 3 to H, met in falling k as the energy rises (k f_1
    = f_3 at a higher f_1 for a smaller k); f_1 rises from 18.0 to 451.1 Hz (open and closed),
    so 3 f_1 and 5 f_1 certainly sweep past 700 Hz. High-k tongues are narrow and may never raise
    a harmonic above the fundamental (H = 15 reports none at 13 and 15). Measured, H = 15:
    k f_1 = 743, 756, 763, 804, 894 Hz for k = 11, 9, 7, 5, 3.
    """
    f_open, f_closed = linear_modes(SYS, "open").freq_hz, linear_modes(SYS, "closed").freq_hz
    for mode in range(3):
        b = nnm_branch(SYS, mode, H=H, energy_max_J=1e5)
        assert b.status == "stop" and b.energy_J[-1] >= 1e5, (mode, b.status, b.energy_J[-1])
        assert all(t["action"] in ("stepped over", "followed") for t in b.tongues), (mode, b.tongues)
        if mode != 0:
            continue
        ks = [t["harmonic"] for t in b.tongues]
        assert ks == sorted(ks, reverse=True) and all(k % 2 == 1 for k in ks), ks
        assert {3, 5} <= set(ks) <= set(range(3, H + 1, 2)), ks
        for t in b.tongues:
            assert f_open[2] < t["harmonic"] * t["freq_hz"] < f_closed[2], t
        assert np.all(np.diff([t["energy_J"] for t in b.tongues]) > 0)


def test_branches_cross_the_tongues_to_1e5_joules_with_7_harmonics():
    """Fast variant of the H = 15 study below: with H = 7 NNM 1 meets its 7:1, 5:1 and 3:1
    tongues (measured k f_1 = 757, 815, 898 Hz) and crosses every one (3 s)."""
    _crosses_its_tongues(7)


@pytest.mark.slow
def test_converged_branches_reach_1e5_joules():
    # H = 15: every NNM to >= 1e5 J; NNM 1 crosses its 11:1 ... 3:1 tongues by stepping over
    _crosses_its_tongues(15)
