"""Tests made by the tool: the virtual hammer test of a model with other parameters, with noise.

To verify an identification, the rig is run with known parameter values (a changed gap, contact
stiffness, damping) as ``bearingshaft hammer`` runs it (:func:`bearingshaft.stages.hammer.run_record`:
the exact integrator, the channels through the DAQ's anti-alias filter), and noise is added to
every channel as a test's sensors add it before their DAQ (the blow itself is the half-sine as the record
samples it, :func:`virtual_test`): white noise at the fine rate, through
the same anti-alias filter and decimation (:class:`reduced.models.daq.Acquisition`), scaled to
``noise`` times the channel's RMS over the record. The channels are written as UFF 58 (a
"measured" file), from which ``bearingshaft identify`` is to find the values back.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from bearingshaft.identify.parameters import with_values
from bearingshaft.scenes import Scene
from bearingshaft.stages.hammer import blow, default_location, run_record
from bearingshaft.stages.hammer_results import Record, histories
from fem.uff import TimeHistory, write_uff58
from reduced.models.loads import Tabulated
from reduced.models.rig import VirtualRig, virtual_rig


def scene_rig(scene: Scene, rom) -> VirtualRig:
    """The rig of ``rom`` struck where the scene's [hammer] strikes it.

    Parameters
    ----------
    scene : Scene
        With [hammer].
    rom : ReducedModel
        Of the whole assembly.
    """
    spec = scene.hammer
    location = tuple(spec.location_m) if spec.location_m else default_location(rom)
    return virtual_rig(rom, location, spec.direction, spec.seismic_mass_kg)


def daq_noise(shape: tuple[int, int], sample_rate_hz: float, oversample: int, rng: np.random.Generator) -> np.ndarray:
    """(channels, n) unit-RMS noise as a DAQ records a sensor's broadband noise: white at the fine
    rate, anti-alias filtered and decimated (:class:`reduced.models.daq.Acquisition`).

    Parameters
    ----------
    shape : (int, int)
        Channels and samples.
    sample_rate_hz : float
        Hz, the record's rate.
    oversample : int
        The DAQ's fine-rate factor q.
    rng : numpy Generator

    Returns
    -------
    (channels, n) ndarray of float, each row of RMS 1
    """
    from reduced.models.daq import Acquisition

    acq = Acquisition(sample_rate_hz, oversample)
    k, n = shape
    fine = rng.standard_normal((k, oversample * (n - 1) + 1 + acq.tail_samples))
    y = acq.acquire(fine, n)
    return y / np.sqrt(np.mean(y**2, axis=1, keepdims=True))


def virtual_test(scene: Scene, rom, values: dict, noise: float, seed: int = 0, level_N: float | None = None,
                 duration_s: float | None = None) -> tuple[list[TimeHistory], Record]:
    """The channels of the scene's blow on the rig with ``values`` set, with noise.

    Parameters
    ----------
    scene : Scene
        A hammer scene ([hammer] blow and point, [ringdown] record).
    rom : ReducedModel
        Its reduced apparatus.
    values : dict
        {"model.KEY": value}: the parameters that differ from the scene's.
    noise : float
        Noise on every channel, hammer included, a fraction of the channel's RMS over the record.
    seed : int
        Seed of the noise.
    level_N : float, optional
        N, the blow (default [hammer] peak_N).
    duration_s : float, optional
        s, the record (default [ringdown] duration_s).

    Returns
    -------
    (list of TimeHistory, Record): the noisy channels and the clean record.
    """
    from reduced.models.daq import oversampling
    from reduced.transient.result import sample_count

    level = level_N or scene.hammer.peak_N
    rig = scene_rig(scene, rom.with_contact(with_values(scene.model, values)))
    fs = scene.ringdown.sample_rate_hz
    t = np.arange(sample_count(duration_s or scene.ringdown.duration_s, fs)) / fs
    force = blow(scene.hammer, level)
    # the blow as the file samples it (linear between samples): the force a fit drives its model with, so
    # the test and the fit differ only in the parameters, the noise and the DAQ filter (a 1 ms half-sine
    # sampled at 20 kHz drives the kHz modes otherwise, which a fit of the damping takes for ~5 % more of it)
    sampled = Tabulated(t, force(t), source=f"{type(force).__name__} sampled at {fs:g} Hz")
    rec = run_record(rig, sampled, scene, level, duration_s=duration_s)
    data = rec.data.copy()
    if noise > 0:
        fs = 1.0 / float(rec.t[1] - rec.t[0])
        q = oversampling(rig.system.omega_max() / (2 * math.pi), fs)
        e = daq_noise(data.shape, fs, q, np.random.default_rng(seed))
        data += noise * np.sqrt(np.mean(data**2, axis=1, keepdims=True)) * e
    return histories(rig, rec.t, data), replace(rec, data=data)


def write_virtual_test(path: str | Path, scene: Scene, rom, values: dict, noise: float, seed: int = 0,
                       **kw) -> Record:
    """:func:`virtual_test` written to ``path`` as UFF 58; returns the noisy record.

    Parameters
    ----------
    path : str or Path
    scene, rom, values, noise, seed, **kw
        As :func:`virtual_test`.

    Returns
    -------
    Record
    """
    channels, rec = virtual_test(scene, rom, values, noise, seed, **kw)
    write_uff58(path, channels, model="bearingshaft virtual test")
    return rec


__all__ = ["virtual_test", "write_virtual_test", "daq_noise", "scene_rig"]
