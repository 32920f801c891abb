"""The main exact family's path against a perturbed corrector (issue 25, session 12).

At 10 N the discrete model's main family passes the lower folds of the bending mode's superharmonic
tongues, where the contact events per period change several times within 1e-4 of arclength (a cluster
of grazings: 12, 14, 12, 14, 6 events). With the default ``grazing_ds`` = 2e-2 a step may cross several
grazings at once and which sheet it lands on depends on round-off: stopping the corrector one Newton
step earlier turns the family 26.8-953 Hz into 17.1-38.2 Hz. With ``grazing_ds`` = 1e-3 each grazing is
crossed in a short step and the family is the same under a corrector tolerance ten times looser (its
extent, its folds to the resolution of the steps, its stability changes), at 3-4x the CPU time.
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


def _main_family(monkeypatch, P, grazing_ds, **opts):
    """The stage's main family of discrete-frc at P N (its HB guesses, no switching) with these options."""
    scene = load_scene("discrete-frc")
    spec = replace(scene.frc, branch_switching=False, cover_families=0)
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)
    br = sf._curve(system, b, P, spec, spec.harmonics, rows, names, hill_points=0)
    monkeypatch.setattr(sf, "ExactFRCOptions", functools.partial(ef.ExactFRCOptions, grazing_ds=grazing_ds, **opts))
    return sf.converged_curve(system, b, P, spec, br, rows, names).exact.families[0]


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore")
def test_main_family_at_10N_does_not_move_with_the_corrector_tolerance(monkeypatch):
    a = _main_family(monkeypatch, 10.0, 1e-3)
    b = _main_family(monkeypatch, 10.0, 1e-3, corrector_tol=10 * ef.CORRECTOR_TOL)
    for f in (a, b):  # the whole main family: from the lowest tongue to past the band's top
        assert f.freq_hz.min() == pytest.approx(17.1333, abs=1e-4)
        assert f.freq_hz.max() > 900.0
    fa, fb = a.freq_hz[a.folds], b.freq_hz[b.folds]
    assert len(fa) == len(fb) == 36
    # the folds are the points where the frequency turns (not located): equal to the steps' resolution there
    assert np.max(np.abs(fa - fb)) < 3e-3
    # the stable stretch up to the band's top starts at the same fold (the single stable points at the lower
    # folds, where the largest |mu| is within the stability tolerance of 1, come and go with the sampling)
    starts = []
    for f in (a, b):
        s = f.stable.astype(bool)
        top = np.flatnonzero(~s & (f.freq_hz < 900.0))[-1] + 1  # first point of the last stable run
        assert np.all(s[top:]) and np.sum(s[top:]) > 100
        starts.append(f.freq_hz[top])
    assert starts[0] == pytest.approx(26.8204, abs=1e-3) and abs(starts[0] - starts[1]) < 1e-3
