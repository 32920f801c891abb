"""Output rows of a ringdown (reduced.transient.integrate.ringdown_rows): the whole state at every q-th sample, rows
R y at every sample, as the virtual hammer test acquires its channels at q times the record's rate (issue 27's speed).

Against the code path it replaces: the samples held whole are the same bits as ringdown's at those times (the
kernels' arithmetic there is unchanged), and the rows are the same R y to round-off (summed over the closed form's
terms instead of over the state); the hammer's channels from the rows (bearingshaft.stages.hammer.ChannelRows)
are VirtualRig.channel_data's.
"""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.discrete import DiscreteFrictionParams
from reduced.models.loads import Harmonic, Loads
from reduced.transient.integrate import ringdown, ringdown_rows

FS = 60000.0  # Hz, the fine rate (the hammer records at 20 kHz x 3)
T = 0.03  # s: ~20 impacts of the discrete model


def _system(friction: bool):
    s = DiscreteFrictionParams().system()
    return s if friction else s.with_friction(None)


def _loads(forced: bool):
    # a harmonic force on the middle mass and the beam's axial motion (the forced kernel, the whole state at every
    # sample, its rows from it), or none (the free kernels, the rows alone between the whole states)
    return Loads(b=np.array([[0.0, 1.0, 0.0, 0.3]]), signals=(Harmonic(amplitude_N=40.0, freq_hz=30.0),)) \
        if forced else None


@pytest.mark.parametrize("friction", [False, True])
@pytest.mark.parametrize("every", [1, 3])
@pytest.mark.parametrize("forced", [False, True])
def test_rows_and_kept_samples_are_the_runs(friction, every, forced):
    sys = _system(friction)
    N = 2 * sys.n + sys.p
    R = np.random.default_rng(1).standard_normal((5, N))
    args = (np.zeros(sys.n), [0.0, 0.0, 0.3, 0.2], T, FS)
    full = ringdown(sys, *args, loads=_loads(forced))
    kept, z = ringdown_rows(sys, *args, R, every, loads=_loads(forced))
    assert full.stats["n_events"] > 10 and kept.stats["n_events"] == full.stats["n_events"]
    if friction:
        assert full.friction[-1] > 0.0  # the sliders slip
    k = slice(0, None, every)
    # the samples held whole: the same bits
    assert np.array_equal(kept.t, full.t[k])
    assert np.array_equal(kept.x, full.x[k]) and np.array_equal(kept.v, full.v[k])
    assert np.array_equal(kept.dissipated, full.dissipated[k]) and np.array_equal(kept.external, full.external[k])
    if friction:
        assert np.array_equal(kept.w, full.w[k]) and np.array_equal(kept.friction, full.friction[k])
    assert kept.energy_balance_error < 1e-11
    # the rows: R y to round-off (each a sum over ~2n + p terms of the state's size; 1e-12 of the rows' scale,
    # measured ~1e-15)
    y = np.hstack([full.x, full.v] + ([full.w] if friction else []))
    ref = y @ R.T
    assert z.shape == ref.shape
    assert np.max(np.abs(z - ref)) < 1e-12 * np.max(np.abs(ref))


def test_other_methods_take_the_rows_of_every_sample():
    sys = _system(True)
    R = np.eye(2 * sys.n + sys.p)[:3]
    args = (np.zeros(sys.n), [0.0, 0.0, 0.3, 0.2], 0.01, FS)
    full = ringdown(sys, *args, "explicit")
    kept, z = ringdown_rows(sys, *args, R, 2, "explicit")
    assert np.array_equal(z, full.x[:, :3]) and np.array_equal(kept.x, full.x[::2])


def test_rows_off_the_state_are_refused():
    sys = _system(True)
    with pytest.raises(ValueError, match="rows must be"):
        ringdown_rows(sys, np.zeros(sys.n), np.zeros(sys.n), 0.01, FS, np.zeros((2, 2 * sys.n)), 2)
    with pytest.raises(ValueError, match="every"):
        ringdown_rows(sys, np.zeros(sys.n), np.zeros(sys.n), 0.01, FS, np.zeros((2, 2 * sys.n + sys.p)), 0)


# -- the hammer's channels from the rows ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def rig20(assembly_rom20):
    from bearingshaft.stages.hammer import default_location
    from reduced.models.rig import virtual_rig

    rom, _ = assembly_rom20
    return virtual_rig(rom, default_location(rom), (0.0, 0.0, -1.0))


def _with_sliders(rig):
    """``rig`` with four sliders on random tangential rows at its two tips (the channels' formula with friction)."""
    from dataclasses import replace

    from reduced.models.gaps import Friction

    n = rig.system.n
    Bt = np.random.default_rng(2).standard_normal((4, n)) * 1e-2
    fr = Friction(Bt=Bt, tip=[0, 0, 1, 1], k_t=np.array([1e7, 2e7, 3e7, 4e7]), mu=0.3, names=("a", "b", "c", "d"))
    return replace(rig, system=rig.system.with_friction(fr))


@pytest.mark.parametrize("friction", [False, True])
def test_channels_from_rows_are_the_rigs(rig20, friction):
    # random states with the gaps closed and open: the channels from z = R y are channel_data's to round-off
    # (accelerations of sums of terms ~1e3 larger than the channel: 1e-12 of the channel's scale allowed)
    from bearingshaft.stages.hammer import ChannelRows

    rig = _with_sliders(rig20) if friction else rig20
    s = rig.system
    rng = np.random.default_rng(3)
    x = rng.standard_normal((50, s.n)) * 1e-4
    v = rng.standard_normal((50, s.n)) * 1e-2
    w = x @ s.friction.Bt.T + rng.standard_normal((50, s.p)) * 1e-6 if friction else None
    p = rng.standard_normal(50) * 100.0
    assert np.any(s.penetration(x) > 0.0) and np.any(s.penetration(x) < 0.0)
    rows = ChannelRows.of(rig)
    y = np.hstack([x, v] + ([w] if friction else []))
    got = rows.channels(y @ rows.R.T, p)
    ref = rig.channel_data(x, v, p, w)
    assert got.shape == ref.shape
    scale = np.max(np.abs(ref), axis=1, keepdims=True)
    assert np.all(np.abs(got - ref) <= 1e-12 * scale)
    assert np.array_equal(got[-1], p)


def test_record_is_the_fine_runs_record(rig20):
    # run_record (the rows at 3 x 20 kHz, the state at 20 kHz) against the code it replaced: the fine run's
    # whole state, channel_data of every fine sample, the DAQ's filter. The states, energies and works are the
    # same bits, the channels the same to round-off (1e-11 of each channel's scale: the filter's 193 taps sum
    # the rows' round-off), the energy balance over the record's samples at most the fine run's.
    import math

    from bearingshaft.scenes import load_scene
    from bearingshaft.stages.hammer import blow, run_record
    from bearingshaft.systems import solver_options
    from reduced.models.daq import MARGIN, Acquisition, oversampling
    from reduced.transient.result import sample_count

    scene = load_scene("hammer-test")
    rd = scene.ringdown
    sig = blow(scene.hammer, 500.0)
    # the 20-mode rig's top frequency is below the scene's 20 kHz / 2.4 (q = 1): a rate with q = 3 instead
    f_max = rig20.system.omega_max() / (2 * math.pi)
    duration, fs = 0.03, round(2.0 * MARGIN * f_max / 2.5)
    rec = run_record(rig20, sig, scene, 500.0, duration_s=duration, sample_rate_hz=fs)
    # the replaced code
    n_out = sample_count(duration, fs)
    acq = Acquisition(fs, oversampling(rig20.system.omega_max() / (2 * math.pi), fs))
    q = acq.oversample
    res = ringdown(rig20.system, np.zeros(rig20.system.n), np.zeros(rig20.system.n),
                   (q * (n_out - 1) + acq.tail_samples) / acq.fine_rate_hz, acq.fine_rate_hz, rd.method,
                   loads=rig20.loads(sig), **solver_options(rd))
    keep = slice(0, q * (n_out - 1) + 1, q)
    fine = rig20.channel_data(res.x, res.v, sig(res.t), res.w)
    data = np.vstack([acq.acquire(fine[:-1], n_out), fine[-1:, keep]])
    assert q == 3 and res.stats["n_events"] > 4
    assert np.array_equal(rec.t, res.t[keep]) and np.array_equal(rec.x, res.x[keep])
    assert np.array_equal(rec.v, res.v[keep]) and np.array_equal(rec.energy, res.energy[keep])
    assert np.array_equal(rec.dissipated, res.dissipated[keep]) and np.array_equal(rec.external, res.external[keep])
    assert rec.balance_error <= res.energy_balance_error
    scale = np.max(np.abs(data), axis=1, keepdims=True)
    assert np.all(np.abs(rec.data - data) <= 1e-11 * scale)
