"""Step control from the tangent's turn (ContinuationOptions.angle_step) against the closed form of a circle:
on R(y) = |y|^2 - r^2 a step ds turns the tangent by ds / r exactly (the corrector lands on the circle at the
chord's angle), so the step that aims at 0.8 max_angle is 0.8 max_angle r (radians)."""

import math

import numpy as np
import pytest

from reduced.periodic.continuation import ContinuationOptions, _angle_factor, continue_branch

R0 = 2.0


def _circle(y):
    return np.array([y @ y - R0 ** 2]), 2.0 * y[None, :]


def _run(angle_step: bool):
    opt = ContinuationOptions(ds=0.01, ds_max=5.0, ds_min=1e-9, max_steps=60, max_angle_deg=15.0,
                              corner_ds=1e-12, tol=1e-12, angle_step=angle_step)
    return continue_branch(_circle, np.array([R0, 0.0]), param=1, direction=1.0, options=opt)


def _turns_deg(br):
    return np.degrees(np.arccos(np.clip(np.sum(br.tangent[1:] * br.tangent[:-1], axis=1), -1.0, 1.0)))


def test_angle_factor_closed_form():
    opt = ContinuationOptions(max_angle_deg=15.0, growth=1.5)
    assert _angle_factor(1.0, opt) == 1.5  # no turn: the usual growth
    assert _angle_factor(math.cos(math.radians(6.0)), opt) == pytest.approx(1.5)
    assert _angle_factor(math.cos(math.radians(10.0)), opt) == pytest.approx(1.2)
    assert _angle_factor(math.cos(math.radians(24.0)), opt) == pytest.approx(0.5)


def test_angle_step_on_a_circle_aims_at_the_closed_form_step():
    br = _run(True)
    assert np.allclose(np.linalg.norm(br.y, axis=1), R0, atol=1e-10)
    turns = _turns_deg(br)
    assert turns.max() <= 15.0 + 1e-9
    target = math.radians(0.8 * 15.0) * R0  # the step whose turn is 0.8 max_angle
    # the steps settle on it (the step the corrector took is a chord-projected arclength: within 1 %)
    assert np.allclose(br.ds[-20:], target, rtol=1e-2)
    assert np.allclose(turns[-20:], 12.0, rtol=2e-2)


def test_angle_step_refuses_fewer_correctors_than_halving():
    old, new = _run(False), _run(True)
    # the old rule grows the step by 1.5 until the 15 deg test refuses it, then halves: it refuses
    # a converged corrector every few steps; the turn-based step refuses none once settled
    assert new.n_rejected < old.n_rejected
    assert new.n_rejected <= 3
    # and reaches farther round the circle in the same number of points
    assert _turns_deg(new).sum() > _turns_deg(old).sum()
