"""The frc stage's ``[frc] period_doubling_depth`` (bearingshaft.stages.frc.converged_curve, issue 25), at scene level.

The gap oscillator of tests/test_exact_frc.py (1 DOF, stops at +-1 mm, 20 times stiffer than the
spring, 2 N) over 7.0-7.1 Hz, drawn by shooting (``curve = "shooting"``) as the stage draws a level: its
symmetric family loses the half-wave symmetry at 7.039 Hz and the half-wave-broken family born there
has a Floquet multiplier passing -1 at 7.044 Hz. Through the [frc] table alone:

- depth 0: the doubling is met and not followed (no period-doubled family);
- depth 1: a 2 T family is born there, and where it is born the period-1 parent's multiplier passes -1,
  found independently: the parent's orbit shot on a residual of its own (16 nodes, not the stage's 8) at
  fixed frequencies, Brent on min Re(mu) + 1 of its monodromy; its orbits are fixed points of the library's
  exact integrator (another kernel) over 2 T and not over T.
"""

from __future__ import annotations

import functools
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from bearingshaft.scenes.tables import FRCSpec
from bearingshaft.stages.frc import converged_curve
from reduced._blas import single_thread_blas
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.transient.flow import Flow

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_exact_frc import B1, GAP, LOAD, impact_oscillator  # noqa: E402

BAND = (7.0, 7.1)  # Hz


@functools.cache
def _level(depth: int):
    spec = FRCSpec(levels_N=(LOAD,), freq_min_hz=BAND[0], freq_max_hz=BAND[1], curve="shooting", max_families=1,
                   period_doubling_families=1, period_doubling_depth=depth, cover_families=0)
    s = impact_oscillator()
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # no HB curve (an exception in its place): the stage starts the families from the HB orbit at f_min
        return s, converged_curve(s, B1, LOAD, spec, RuntimeError("no HB curve"), np.eye(1), ("x",))


def _doubling(ex):
    recs = [r for r in ex.switches if r["kind"] == "period_doubling"]
    assert len(recs) == 1, ex.switches
    return recs[0]


def test_depth_zero_follows_no_period_doubled_family():
    _, cc = _level(0)
    ex = cc.exact
    assert cc.method == "shooting" and ex is not None, cc.error
    assert ex.options.period_doubling_depth == 0  # the table's key reached the options
    assert all(f.periods == 1 for f in ex.families) and not any(f.kind == "period_doubled" for f in ex.families)
    rec = _doubling(ex)  # the doubling is met on the half-wave-broken family, not followed
    assert ex.families[rec["family"]].kind == "half_wave_broken"
    assert rec["child"] < 0 and "period_doubling_depth = 0" in rec["note"], rec


def test_depth_one_family_is_born_where_the_parents_multiplier_passes_minus_one():
    s, cc = _level(1)
    ex = cc.exact
    rec = _doubling(ex)
    assert rec["child"] >= 0, rec
    fam, parent = ex.families[rec["child"]], ex.families[rec["family"]]
    assert fam.kind == "period_doubled" and fam.periods == 2 and parent.periods == 1
    # the parent's multiplier at -1, independently: its own 16-node residual, Brent in frequency
    res = ShootingResidual(ForcedFlow(s, B1, LOAD), 16, 1, GAP, 2 * np.pi * BAND[1])
    f0 = rec["located_hz"]
    fl = Flow(s, loads=Loads(B1[None, :], (Harmonic(LOAD, f0),)))
    y, nodes16 = parent.nodes[int(np.argmin(np.abs(parent.freq_hz - f0)))][0], []
    for j in range(16):  # the parent's orbit marched from its first node at 16 phases (a guess: Newton below)
        nodes16.append(y)
        y = fl(y[:1], y[1:], 1.0 / f0 / 16, t0=j / f0 / 16).y

    def mu_plus_one(f):
        Y = shoot_at(res, np.array(nodes16), 2 * np.pi * f)
        return float(np.min(np.linalg.eigvals(res.monodromy(Y)).real) + 1.0)

    lo, hi = rec["located_hz"] - 2e-3, rec["located_hz"] + 2e-3
    assert mu_plus_one(lo) * mu_plus_one(hi) < 0.0  # one crossing of -1 within +-2 mHz
    f_pd = brentq(mu_plus_one, lo, hi, xtol=1e-10)
    # the stage's bisection locates the crossing to its bracket: 12 halvings of a chord of the parent
    # (points ~5 mHz apart here: ~1e-6 Hz); 1e-5 Hz leaves a margin of ten
    assert abs(rec["located_hz"] - f_pd) < 1e-5, (rec["located_hz"], f_pd)
    assert abs(rec["critical"] + 1.0) < 1e-2  # the multiplier located is -1 (a smooth crossing)
    # the 2 T orbits: fixed points over 2 T of the library's exact integrator, not over T (measured: 2 T
    # closes to the shooting tolerance amplified by the orbit's multipliers; T misses by > 1e-4 of the gap)
    for j in range(len(fam.freq_hz)):
        f = float(fam.freq_hz[j])
        y0 = fam.nodes[j][0]
        fl = Flow(s, loads=Loads(B1[None, :], (Harmonic(LOAD, f),)))
        scale = np.array([GAP, 2 * np.pi * f * GAP])
        d2, d1 = (float(np.max(np.abs(fl(y0[:1], y0[1:], p / f).y - y0) / scale)) for p in (2, 1))
        assert d2 < 1e-8, (f, d2)
        assert d1 > 1e-4, (f, d1)

