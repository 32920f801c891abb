"""The frc stage's drawn curve (bearingshaft.stages.frc.converged_curve): HB where it no longer moves
with H, with the lightly damped resonances it steps over refined, against the closed-form receptance."""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import minimize_scalar

from bearingshaft.scenes import load_scene
from bearingshaft.stages.frc import _curve, converged_curve
from bearingshaft.stages.frc_files import _spliced
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas


def _receptance(system, b, rows, f):
    """m/N, max over the output points of the open-gap linear response at f."""
    w = 2 * np.pi * f
    return float(np.max(np.abs(rows @ np.linalg.solve(system.K - w**2 * system.M + 1j * w * system.C, b))))


def test_the_drawn_curve_at_0p1_N_holds_the_700_Hz_peak_of_the_closed_form_receptance():
    # 0.1 N: the stops stay open, the response is linear; the 700 Hz bending mode (zeta 5.4e-4, a
    # half-power band of 0.76 Hz) is stepped over by the continuation over 10-900 Hz (its scaled
    # unknowns barely bend there): the drawn curve refines that band and holds its peak
    scene = load_scene("discrete-frc")
    spec = scene.frc
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = rows[names.index(spec.point)]
    P = 0.1
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        br = _curve(system, b, P, spec, spec.harmonics, rows, names, hill_points=0)
        cc = converged_curve(system, b, P, spec, br, rows, names)
    assert cc.method == "hb" and not cc.contact and cc.hb_change < 1e-10  # linear: every H alike
    peak = minimize_scalar(lambda f: -_receptance(system, b, rows, f), bounds=(695.0, 705.0), method="bounded",
                           options={"xatol": 1e-6})
    exact = -peak.fun * P
    band = (br.freq_hz > 650) & (br.freq_hz < 750)
    assert np.max(br.amplitude_m[band]) < 0.1 * exact  # the HB curve alone misses it (measured 0.037)
    assert len(cc.refined) == 1 and abs(np.mean(cc.refined[0].freq_hz) - peak.x) < 1.0
    d = _spliced(br, cc.refined)
    assert np.all(np.diff(d.freq_hz) > 0)  # spliced in frequency order, one piece
    # the drawn maximum is a sample of the curve: its points ~0.06 Hz apart, so within
    # (0.03 / 0.38)^2 = 0.6 % of the peak (a quadratic top of half-width zeta f = 0.38 Hz)
    got = np.max(d.amplitude_m[(d.freq_hz > 690) & (d.freq_hz < 710)])
    assert abs(got / exact - 1.0) < 6e-3, got / exact
    # every drawn point of the refined band is the closed-form receptance (linear: HB is exact)
    sub = cc.refined[0]
    lin = np.array([[abs(r @ np.linalg.solve(system.K - w**2 * system.M + 1j * w * system.C, b)) * P for r in rows]
                    for w in sub.omega])
    assert np.max(np.abs(sub.amplitude_m / lin - 1.0)) < 1e-8  # Newton's tolerance of the curve's points
