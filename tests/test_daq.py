"""The virtual rig's acquisition (reduced.models.daq): anti-alias filter and decimation.

Closed forms: a sine in the kept band comes out as the same sine at the same phase (the
filter is linear phase with its delay compensated, flat to 1e-5 by design: Kaiser, 100 dB);
a sine above fs/2, which plain sampling would fold into the band at full amplitude, comes
out attenuated by the stop band (>= 90 dB, the design's 100 dB less the Kaiser edge).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reduced.models.daq import Acquisition, oversampling

FS = 20000.0


def _sine(acq: Acquisition, f_hz: float, n_out: int, phase: float = 0.3):
    t_fine = np.arange(acq.oversample * (n_out - 1) + 1 + acq.tail_samples) / acq.fine_rate_hz
    return t_fine, np.sin(2 * np.pi * f_hz * t_fine + phase)


@pytest.mark.parametrize("q", [1, 2, 3])
@pytest.mark.parametrize("f_hz", [50.0, 1234.5, 7900.0])
def test_a_sine_in_the_band_passes_unchanged_and_in_phase(q, f_hz):
    acq = Acquisition(FS, q)
    n_out = 4000
    t_fine, u = _sine(acq, f_hz, n_out)
    y = acq.acquire(u, n_out)
    t = t_fine[: acq.oversample * (n_out - 1) + 1: acq.oversample]
    # the input is not at rest before t = 0, so the first half filter length is a start transient
    skip = acq.tail_samples // q + 1
    exact = np.sin(2 * np.pi * f_hz * t + 0.3)
    assert np.max(np.abs(y[skip:] - exact[skip:])) < 3e-5  # the pass-band ripple, 1e-5 by design


@pytest.mark.parametrize("q", [2, 3])
def test_a_sine_above_half_the_rate_does_not_fold_into_the_band(q):
    """(q = 1 has no room above fs/2: the oversampling is chosen so that the model has nothing there.)"""
    acq = Acquisition(FS, q)
    n_out = 4000
    f_hz = acq.fine_rate_hz / 2 - 0.3 * FS  # sampled plainly at fs it would read as a sine at 0.2 or 0.3 fs
    _, u = _sine(acq, f_hz, n_out)
    y = acq.acquire(u, n_out)
    skip = acq.tail_samples // q + 1
    assert np.max(np.abs(y[skip:])) < 10 ** (-90 / 20)  # plain sampling: amplitude 1


def test_the_start_from_rest_is_exact_and_the_length_is_checked():
    acq = Acquisition(FS, 2)
    u = np.zeros((3, 2 * 99 + 1 + acq.tail_samples))
    u[:, 100:] = 1.0  # a step at fine sample 100, after rest: y[k] sees it once 2 k + D >= 100
    y = acq.acquire(u, 100)
    assert y.shape == (3, 100)
    first = -(-(100 - acq.tail_samples) // 2)
    assert np.all(y[:, :first] == 0.0) and np.all(y[:, first] != 0.0)
    assert y[0, -1] == pytest.approx(1.0, abs=1e-5)  # unit DC gain
    with pytest.raises(ValueError, match="fine samples"):
        acq.acquire(u[:, :-1], 100)


def test_the_oversampling_keeps_the_fine_nyquist_above_the_model():
    assert oversampling(8448.7, 20000.0) == 2  # the hammer-test rig: 1.2 x 8.45 kHz > 10 kHz
    assert oversampling(8000.0, 20000.0) == 1
    assert oversampling(0.0, 20000.0) == 1
    assert oversampling(19767.0, 20000.0) == 3  # the full 3-D model's modes to 20 kHz
    with pytest.raises(ValueError):
        oversampling(float("nan"), 20000.0)
    with pytest.raises(ValueError, match="oversample"):
        Acquisition(FS, 0)
    with pytest.raises(ValueError, match="passband"):
        Acquisition(FS, 1, passband=0.5)


@settings(max_examples=40, deadline=None)
@given(f_max=st.floats(0.0, 1e6), fs=st.floats(1.0, 1e6))
def test_oversampling_is_the_smallest_sufficient_integer(f_max, fs):
    q = oversampling(f_max, fs)
    assert q >= 1 and q * fs / 2 >= 1.2 * f_max * (1 - 1e-12)
    assert q == 1 or (q - 1) * fs / 2 < 1.2 * f_max
