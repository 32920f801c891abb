"""The main exact family's path against a perturbed corrector and another start (issue 25, sessions 12-13).

At 10 N the discrete model's main family passes the lower folds of the bending mode's superharmonic
tongues, where the contact events per period change several times within 1e-4 of arclength (a cluster
of grazings: 12, 14, 12, 14, 6 events). With a step of up to ``grazing_ds`` = 2e-2 allowed across any change
of the events, a step could cross several grazings at once and which sheet it landed on depended on
round-off: stopping the corrector one Newton step earlier turned the family 26.8-953 Hz into 17.1-38.2 Hz.
The default now refuses a step that changes the events by more than one grazing while it is longer than
``multi_grazing_ds`` = 1e-3 (one grazing: ``grazing_ds`` = 2e-2 as before): the family is the same under a
corrector tolerance ten times looser and from another start (the linear orbit at the band's top instead of
an HB orbit at 34.9 Hz): its extent, its 36 folds (the lower folds of the tongues to 2e-5 Hz, the upper ones,
amid grazings at every step, to the steps' resolution), the stable stretch up to the band's top.
"""

import functools
from dataclasses import replace

import numpy as np
import pytest

import bearingshaft.stages.frc as sf
import reduced.periodic.exact_frc as ef
from bearingshaft.scenes import load_scene
from bearingshaft.stages.frc_friction import load_vector
from bearingshaft.systems import model_system


def test_corrector_tol_reaches_the_continuation():
    opts = ef.ExactFRCOptions(corrector_tol=3e-7)
    assert opts.continuation(10).tol == 3e-7
    assert ef.ExactFRCOptions().continuation(10).tol == ef.CORRECTOR_TOL
    with pytest.raises(Exception, match="corrector_tol"):
        ef.ExactFRCOptions(corrector_tol=0.0)


def test_multi_grazing_radius_reaches_the_guard():
    opts = ef.ExactFRCOptions()
    assert opts.multi_grazing_ds < opts.grazing_ds
    with pytest.raises(Exception, match="multi_grazing_ds"):
        ef.ExactFRCOptions(multi_grazing_ds=0.0)


def _setup(P):
    scene = load_scene("discrete-frc")
    spec = replace(scene.frc, branch_switching=False, cover_families=0)
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    return spec, system, rows, names, load_vector(spec, rows, names)


def _main_family(monkeypatch, P, **opts):
    """The stage's main family of discrete-frc at P N (its HB guesses, no switching) with these options."""
    spec, system, rows, names, b = _setup(P)
    br = sf._curve(system, b, P, spec, spec.harmonics, rows, names, hill_points=0)
    monkeypatch.setattr(sf, "ExactFRCOptions", functools.partial(ef.ExactFRCOptions, **opts))
    return sf.converged_curve(system, b, P, spec, br, rows, names).exact.families[0]


def _from_the_top(P):
    """The same family started from the linear orbit at the band's top (no HB guess), the stage's options."""
    spec, system, rows, names, b = _setup(P)
    return sf.linear_start_families(system, b, P, spec, rows, names).families[0]


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore")
def test_main_family_at_10N_does_not_move_with_the_corrector_tolerance_or_the_start(monkeypatch):
    fams = [_main_family(monkeypatch, 10.0), _main_family(monkeypatch, 10.0, corrector_tol=10 * ef.CORRECTOR_TOL),
            _from_the_top(10.0)]
    for f in fams:  # the whole main family: from the lowest tongue to the band's top
        assert f.freq_hz.min() == pytest.approx(17.1333, abs=1e-4)
        assert f.freq_hz.max() >= 900.0 - 1e-6
    folds = [f.freq_hz[f.folds] for f in fams]
    assert [len(x) for x in folds] == [36, 36, 36]
    for fb in folds[1:]:
        # the folds are the points where the frequency turns (not located): the upper folds of the tongues lie
        # amid grazings at every step, equal to the steps' resolution; the lower ones (every other fold, the
        # last but one included) to 2e-5 Hz
        assert np.max(np.abs(folds[0] - fb)) < 1e-2
        assert np.max(np.abs(folds[0][1:-1:2] - fb[1:-1:2])) < 2e-5
    # the stable stretch up to the band's top starts at the same fold (the single stable points at the lower
    # folds, where the largest |mu| is within the stability tolerance of 1, come and go with the sampling)
    starts = []
    for f in fams:
        s = f.stable.astype(bool)
        top = np.flatnonzero(~s & (f.freq_hz < 900.0))[-1] + 1  # first point of the last stable run
        assert np.all(s[top:]) and np.sum(s[top:]) > 90
        starts.append(f.freq_hz[top])
    assert starts[0] == pytest.approx(26.8204, abs=1e-2) and np.ptp(starts) < 1e-2
