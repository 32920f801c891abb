"""A guard of the residual (reduced.periodic.hb.GuardRefusal) and ContinuationOptions.resume_after_guard, on the
circle |y|^2 = r^2 with a 'grazing' line x = X0 that a step may cross only when it is at most RADIUS long; and the
multiple-shooting residual's guard with a second radius for a change of more than one grazing."""

import types

import numpy as np
import pytest

from reduced.periodic.continuation import ContinuationOptions, continue_branch
from reduced.periodic.forced_shooting import GRAZING_EVENTS, ShootingResidual
from reduced.periodic.hb import GuardRefusal, NewtonError

R0, X0, RADIUS = 2.0, 1.0, 1e-3


class _GuardedCircle:
    """R(y) = |y|^2 - R0^2; a trial point on the other side of x = X0 from the last accepted point and farther
    than RADIUS from it is refused (GuardRefusal), as ShootingResidual refuses a grazing crossed in a long step."""

    def __init__(self):
        self.ref = None
        self.refused = 0

    def __call__(self, y):
        if self.ref is not None and (y[0] - X0) * (self.ref[0] - X0) < 0 and np.linalg.norm(y - self.ref) > RADIUS:
            self.refused += 1
            raise GuardRefusal("crossed in a long step")
        return np.array([y @ y - R0 ** 2]), 2.0 * y[None, :]


def _run(resume: bool):
    fun = _GuardedCircle()
    opt = ContinuationOptions(ds=0.05, ds_max=0.05, ds_min=1e-9, max_steps=200, max_angle_deg=15.0, corner_ds=1e-12,
                              tol=1e-12, resume_after_guard=resume)
    fun.ref = np.array([R0, 0.0])
    br = continue_branch(fun, fun.ref.copy(), param=1, direction=1.0, options=opt,
                         progress=lambda y: setattr(fun, "ref", y.copy()), stop=lambda y: y[0] < 0.5)
    return br, fun


def test_guard_refusal_is_a_newton_error():
    assert issubclass(GuardRefusal, NewtonError)


@pytest.mark.parametrize("resume", [False, True])
def test_the_line_is_crossed_in_a_short_step_and_the_points_stay_on_the_circle(resume):
    br, fun = _run(resume)
    assert fun.refused > 0
    assert np.allclose(np.linalg.norm(br.y, axis=1), R0, atol=1e-10)
    side = np.sign(br.y[:, 0] - X0)
    k = int(np.flatnonzero(side[1:] != side[:-1])[0]) + 1  # the point past the line
    assert np.linalg.norm(br.y[k] - br.y[k - 1]) <= RADIUS
    # resumed: the next step is the full step the guard refused (0.05, at ds_max), not the short one grown by 1.5
    if resume:
        assert br.ds[k + 1] == pytest.approx(0.05)
    else:
        assert br.ds[k + 1] == pytest.approx(1.5 * br.ds[k]) and br.ds[k + 1] < 2 * RADIUS


def test_resuming_takes_fewer_points_to_the_same_end():
    old, new = _run(False)[0], _run(True)[0]
    assert len(new.y) < len(old.y) - 5
    assert old.status == new.status == "stop"


def _stub(events_ref, events_new, radius, *multi):
    st = types.SimpleNamespace(guard=(np.zeros(3), events_ref, radius, *multi), _events={b"k": events_new})
    return st


@pytest.mark.parametrize("change, dist, multi, refused", [
    (0, 1.0, (), False),                      # no change: any step
    (GRAZING_EVENTS, 0.01, (), False),        # one grazing within the radius
    (GRAZING_EVENTS, 0.03, (), True),         # one grazing beyond it
    (GRAZING_EVENTS, 0.01, (1e-3,), False),   # one grazing: the multi radius does not apply
    (3 * GRAZING_EVENTS, 0.01, (1e-3,), True),   # several grazings beyond the multi radius
    (3 * GRAZING_EVENTS, 5e-4, (1e-3,), False),  # several grazings within it
    (3 * GRAZING_EVENTS, 0.01, (), False),    # without a multi radius: the radius alone
])
def test_shooting_guard_radii(change, dist, multi, refused):
    st = _stub(10, 10 - change, 2e-2, *multi)
    Y = np.array([dist, 0.0, 0.0])
    if refused:
        with pytest.raises(GuardRefusal):
            ShootingResidual._check_guard(st, Y, b"k")
    else:
        ShootingResidual._check_guard(st, Y, b"k")
