"""The measures that survive chaos (bearingshaft.measures), on signals whose answers are known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bearingshaft import measures
from bearingshaft.correlate import ChannelError, channel_floors, match_channels
from fem.uff import TimeHistory

FS = 4000.0
DT = 1.0 / FS


def pair(model: np.ndarray, test: np.ndarray, name: str = "a:z", quantity: str = "acceleration"):
    m = TimeHistory(name, 1, 3, quantity, model, DT)
    x = TimeHistory(name, 1, 3, quantity, test, DT)
    return match_channels([m], [x], [name])[0]


def tone(f_hz, n=8000, amp=1.0, decay=0.0):
    t = np.arange(n) * DT
    return amp * np.exp(-decay * t) * np.sin(2 * np.pi * f_hz * t)


def test_ridges_of_two_tones_are_their_frequencies():
    """A 203 Hz and a 207 Hz tone in 50 ms Hann frames (20 Hz bins): the parabola through the log
    power places each within 2 % of a bin (a Hann main lobe is near a Gaussian, not one: measured
    0.22 Hz at 0.15 bin from a bin), so the ridge error is |203 - 207| / 207 to 2e-3 and the frames
    agree within one bin."""
    r = measures.ridges(pair(tone(203.0), tone(207.0)), None, 0.05, 0.5)
    assert r.bin_hz == pytest.approx(20.0)
    assert np.all(np.abs(r.f_model - 203.0) < 0.4) and np.all(np.abs(r.f_test - 207.0) < 0.4)
    assert r.error == pytest.approx(4.0 / 207.0, abs=2e-3)
    assert r.agreement == 1.0
    same = measures.ridges(pair(tone(203.0), tone(203.0)), None, 0.05, 0.5)
    assert same.error == 0.0 and same.residuals().size == same.t.size


def test_ridges_leave_out_frames_below_the_floor():
    y = np.concatenate([tone(100.0, 4000), np.zeros(4000)])
    r = measures.ridges(pair(y, y), None, 0.05, 0.5, floor=0.1)
    assert 0 < np.count_nonzero(r.valid) < r.t.size  # the silent second half is noise, not a ridge
    assert np.all(r.t[r.valid] < 1.05)
    assert measures.ridges(pair(y, y), (0.0, 0.02), 0.05) is None  # shorter than a frame


def test_envelope_of_a_scaled_signal_is_off_by_the_scale():
    """model = k test in every window: sqrt(sum (k - 1)^2 e^2 / sum e^2) = |k - 1|, whatever the decay."""
    x = tone(50.0, decay=2.0)
    env = measures.envelope(pair(1.3 * x, x), None, 0.1)
    assert env.t.size == 20
    assert env.error == pytest.approx(0.3, rel=1e-12)
    np.testing.assert_allclose(env.residuals(), 0.3, rtol=1e-12)
    # the floor: a test window below it is judged against the floor
    env = measures.envelope(pair(1.3 * x, x), None, 0.1, floor=10.0)
    assert env.error == pytest.approx(0.3 * math.sqrt(np.sum(env.test**2) / (env.t.size * 100.0)), rel=1e-12)


def test_impacts_are_counted_with_hysteresis():
    """Five half-sine pulses of 100, 80, 60, 40 and 5 N on a 3 N ripple: with the threshold at 10 % of
    the test's largest (10 N) four are impacts, the ripple and the 5 N touch are not."""
    t = np.arange(4000) * DT
    y = 3.0 * np.sin(2 * np.pi * 900 * t)
    for k, peak in enumerate([100.0, 80.0, 60.0, 40.0, 5.0]):
        on = (t >= 0.1 + 0.2 * k) & (t < 0.1 + 0.2 * k + 0.002)
        y[on] += peak * np.sin(np.pi * (t[on] - 0.1 - 0.2 * k) / 0.002)
    c = measures.impact_comparison(pair(y, y, "tip", "reaction_force"), None)
    assert c.sense == 1.0 and c.test.threshold_N == pytest.approx(0.1 * np.max(y))
    assert c.test.count == 4 and c.model.count == 4
    np.testing.assert_allclose(c.test.start_s, [0.1, 0.3, 0.5, 0.7], atol=0.002)
    np.testing.assert_allclose(c.test.peak_N, [100.0, 80.0, 60.0, 40.0], atol=3.5)  # the ripple on the crest
    assert c.test.rate_per_s == pytest.approx(4 / 1.0)
    assert c.test.last_s == pytest.approx(0.702, abs=1e-3)
    # a contact that compresses the cell the other way: the sense follows the test's largest reading
    assert measures.impact_comparison(pair(-y, -y, "tip", "reaction_force"), None).sense == -1.0


def test_backbone_of_a_softening_decay_is_its_frequency_amplitude_law():
    """y = a(t) cos(phi), a = e^(-2 t), f = 40 (1 + 0.5 a^2) Hz (a hardening backbone in amplitude),
    over 10 s, down to a = 1e-3 of the start (the blocks kept): the backbone recovers f(a) and a(t)
    within 0.5 % (measured 0.22 %: a block averages a frequency that changes 0.3 % a period at the
    start), also integrated twice (read as a displacement, amplitude a / (2 pi f)^2). A plain Hilbert
    transform would not: its 1 / t tail of the record's start is 3e-3 of it 3 s later, where the
    decay is at 2.5e-3 (measured: 2.6 % (periodic) to 5.9 % (zero-padded) frequency error at 3.4 s)."""
    t = np.arange(40000) * DT
    a = np.exp(-2.0 * t)
    f = 40.0 * (1 + 0.5 * a**2)
    y = a * np.cos(2 * np.pi * np.cumsum(f) * DT)
    for k in (0, 2):
        bb = measures.ringdown_backbone(t, y, (25.0, 90.0), integrate=k)
        acc_amp = bb.amplitude * (2 * np.pi * bb.freq_hz) ** k
        assert bb.t.size > 35 and bb.t[-1] > 3.0  # the blocks down to 1e-3 of the largest
        assert np.max(np.abs(bb.freq_hz / (40.0 * (1 + 0.5 * acc_amp**2)) - 1)) < 5e-3, k
        assert np.max(np.abs(acc_amp / np.exp(-2.0 * bb.t) - 1)) < 5e-3, k
    with pytest.raises(ChannelError):
        measures.ringdown_backbone(t, y, (90.0, 25.0))


def test_backbones_compared_at_equal_amplitude():
    """The model's law 2 % stiffer than the test's: the error at equal amplitude is 2 %; the distance of
    the test's backbone to the test's own law (as a curve) is 0 to the estimate's accuracy."""
    t = np.arange(40000) * DT

    def decay(k):
        a = np.exp(-2.0 * t)
        return a * np.cos(2 * np.pi * np.cumsum(k * 40.0 * (1 + 0.5 * a**2)) * DT)

    c = measures.backbone_comparison(pair(decay(1.02), decay(1.0)), None, (25.0, 90.0), "NNM")
    assert c.error == pytest.approx(0.02, abs=2e-3)
    amp = np.geomspace(1e-3, 1.0, 50)
    assert measures.distance_to_curve(c.test, amp, 40.0 * (1 + 0.5 * amp**2)) < 3e-3


def test_compare_measures_past_the_horizon_and_names_each_row():
    x = tone(60.0, decay=1.0)
    m = tone(61.0, decay=1.2)
    p = pair(m, x)
    floors = channel_floors([p])
    ms = measures.compare([p], (0.0, 2.0), 0.5, floors, ("ridges", "envelope"), frame_s=0.1, overlap=0.5)
    assert ms.spans == {"ridges": (0.5, 2.0), "envelope": (0.0, 2.0)}
    assert np.all(ms.ridges["a:z"].t >= 0.5)
    assert {r["measure"] for r in ms.rows} == {"ridges", "envelope"}
    assert all(set(r) == set(measures.MEASURE_FIELDS) for r in ms.rows)
    assert ms.summary("ridges") == pytest.approx(1.0 / 60.0, abs=2e-3)
    assert math.isnan(ms.summary("impacts"))
    # no horizon within the window: the ridges span it all
    assert measures.compare([p], (0.0, 2.0), math.inf, floors, ("ridges",), frame_s=0.1).spans["ridges"] == (0.0, 2.0)


def test_measures_are_parsed_and_refused_in_one_line():
    assert measures.parse_measures("backbone,time") == ("time", "backbone")
    assert measures.parse_measures("all") == measures.MEASURES
    with pytest.raises(ChannelError) as e:
        measures.parse_measures("ridge, envelope")
    msg = str(e.value)
    assert "\n" not in msg and "'ridge'" in msg and "did you mean 'ridges'" in msg
