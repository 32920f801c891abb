"""The periodic-solution entry points refuse unusable arguments at once, in one line naming them."""

from __future__ import annotations

import pytest

from reduced import DiscreteParams, HarmonicBalance, hb_backbones, nnm_branch

SYSTEM = DiscreteParams().system()


@pytest.mark.parametrize(("call", "named"), [
    (lambda: nnm_branch(SYSTEM, 3), "mode"),
    (lambda: nnm_branch(SYSTEM, -1), "mode"),
    (lambda: nnm_branch(SYSTEM, 0, H=2.5), "H"),
    (lambda: nnm_branch(SYSTEM, 0, H=True), "H"),
    (lambda: nnm_branch(SYSTEM, 0, H=5000), "H"),
    (lambda: nnm_branch(SYSTEM, 0, H=3, N=6), "N"),
    (lambda: nnm_branch(SYSTEM, 0, energy_max_J=float("nan")), "energy_max_J"),
    (lambda: nnm_branch(SYSTEM, 0, energy_start_J=-1.0), "energy_start_J"),
    (lambda: nnm_branch(SYSTEM, 0, ds=0.0), "ds"),
    (lambda: nnm_branch(SYSTEM, 0, max_steps=0), "max_steps"),
    (lambda: nnm_branch(SYSTEM, 0, progress="yes"), "progress"),
    (lambda: nnm_branch(SYSTEM, 0, energy_maxJ=1.0), "energy_maxJ"),
    (lambda: nnm_branch("not a system", 0), "system"),
    (lambda: hb_backbones(SYSTEM, 0), "harmonics"),
    (lambda: hb_backbones(SYSTEM, 1, energy_max_J=float("inf")), "energy_max_J"),
    (lambda: HarmonicBalance.for_system(SYSTEM, 3, 4), "N"),
    (lambda: HarmonicBalance.for_system(SYSTEM, -1), "H"),
])
def test_bad_argument_is_refused_naming_it(call, named):
    with pytest.raises(ValueError) as info:
        call()
    msg = str(info.value)
    assert len(msg.splitlines()) == 1 and named in msg, msg


def test_good_arguments_still_run():
    b = nnm_branch(SYSTEM, 1, H=1, energy_max_J=1.0)
    assert b.energy_J[-1] >= 1.0
