"""The hammer stage against a measured test (``bearingshaft hammer --test FILE.uff``).

The test file's channels (UFF 58 time histories) are read and checked (:func:`read_test`); the
stage runs the model at the test's sampling, driven by the test's hammer channel, and the two
are matched and compared channel for channel by :mod:`bearingshaft.correlate` (:func:`compare`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearingshaft import correlate
from bearingshaft.scenes import Scene, SceneError
from bearingshaft.stages.hammer_results import Comparison, Record, histories
from fem.uff import TimeHistory, UffError, read_uff58
from reduced.models.loads import Tabulated
from reduced.models.rig import VirtualRig


@dataclass(frozen=True, eq=False)
class MeasuredTest:
    """A measured test's channels and how the model is to be driven to compare with it.

    Attributes
    ----------
    channels : list of TimeHistory
        Every channel of the test file.
    signal : Tabulated or None
        The test's hammer force; None: no force channel, the scene's blow is used.
    level_N : float or None
        N, the peak of that force.
    driven : str
        What drives the model, as the summary says it.
    duration_s : float
        s, the test's longest channel.
    sample_rate_hz : float
        Hz, the test's sampling.
    """

    channels: list[TimeHistory]
    signal: Tabulated | None  # the test's hammer force (Tabulated), None: no force channel, use the scene's blow
    level_N: float | None  # N, the peak of that force
    driven: str  # what drives the model, as the summary says it
    duration_s: float  # s, the test's longest channel
    sample_rate_hz: float  # Hz, the test's sampling


def read_test(scene: Scene, test_file: str) -> MeasuredTest:
    """The channels of ``test_file`` and the force that drives the model (SceneError, one line, if unusable).

    Parameters
    ----------
    scene : the scene ([hammer] peak_N names the blow used when the test has no force channel)
    test_file : path of a UFF 58 file of time histories starting at t = 0

    Returns
    -------
    MeasuredTest
    """
    spec = scene.hammer
    try:
        test = read_uff58(test_file)
    except UffError as exc:
        raise SceneError(f"--test: {exc}") from None
    forces = [c for c in test if c.quantity == "force"]
    if len(forces) > 1:
        raise SceneError(f"--test {test_file!r}: {len(forces)} force channels; a hammer test has one hammer")
    ref = forces[0] if forces else test[0]
    dt, t0 = ref.dt_s, ref.t0_s
    if abs(t0) > 1e-12:
        raise SceneError(f"--test {test_file!r}: the record starts at t0 = {t0!r} s; the model starts at rest at 0")
    duration = (max(c.data.size for c in test) - 1) * dt
    if forces:
        signal = Tabulated(forces[0].t, forces[0].data, source=f"{test_file} ({forces[0].name})")
        level = float(np.max(np.abs(forces[0].data)))
        driven = f"the test's hammer channel {forces[0].name!r} (peak {level:.4g} N)"
    else:
        signal, level = None, None
        driven = f"the scene's blow ({spec.peak_N:g} N): the test file has no force channel"
    return MeasuredTest(test, signal, level, driven, duration, 1.0 / dt)


def compare(scene: Scene, rig: VirtualRig, rec: Record, test: MeasuredTest, test_file: str, stats: dict) -> Comparison:
    """The model's record ``rec`` (run at the test's sampling) matched and compared with ``test``.

    Parameters
    ----------
    scene : the scene ([hammer] compare, compare_window_s)
    rig : the rig that made ``rec``
    rec : the model's record, driven as ``test.driven`` says
    test : from :func:`read_test`
    test_file : the test file's path, as the files and messages name it
    stats : the stage's statistics so far (the rig's); the comparison's are added

    Returns
    -------
    Comparison (SceneError, one line, when the channels cannot be compared)
    """
    spec = scene.hammer
    model = histories(rig, rec.t, rec.data)
    try:
        pairs = correlate.match_channels(model, test.channels, list(spec.compare) or None, source=repr(test_file))
        window = tuple(spec.compare_window_s) or None
        rows = correlate.channel_errors(pairs, window_s=window)
    except correlate.ChannelError as exc:
        raise SceneError(f"--test: {exc}") from None
    worst = max(rows, key=lambda r: r["rms_rel_error"])
    stats = {**stats, "test_file": str(test_file), "driven_by": test.driven, "n_compared": len(rows),
             "worst_channel": worst["name"], "worst_rms_rel_error": worst["rms_rel_error"]}
    line = (f"[{scene.name}] compared {len(rows)} channels with {test_file}: model driven by {test.driven}; worst "
            f"{worst['name']} {100 * worst['rms_rel_error']:.3g} % RMS (test_errors.csv)")
    return Comparison(scene=scene, test_file=str(test_file), driven=test.driven, model=model, pairs=pairs, rows=rows,
                      window_s=window, stats=stats, lines=(line,))
