"""Test-model correlation of a hammer test (bearingshaft.correlate): matching, errors, figures."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from bearingshaft.correlate import ChannelError, channel_errors, default_channels, match_channels, write_errors_csv
from bearingshaft.stages.hammer_files import comparison_figure, spectrogram_pair_figure
from fem.uff import QUANTITIES, TimeHistory, UffError, read_uff58, write_uff58

FS = 2000.0  # Hz: 2 Hz Welch bins are 1000-sample segments, two of them in a 1 s record
DT = 1.0 / FS
N = 2000


def ringdown(freq_hz: float, amp: float = 1.0, zeta: float = 0.01, phase: float = 0.0, n: int = N,
             t0: float = 0.0) -> np.ndarray:
    """A damped sine starting at t = 0 (zero before)."""
    t = t0 + np.arange(n) * DT
    w = 2 * np.pi * freq_hz
    y = amp * np.exp(-zeta * w * t) * np.sin(w * np.sqrt(1 - zeta**2) * t + phase)
    return np.where(t >= 0.0, y, 0.0)


def rig() -> list[TimeHistory]:
    """A few channels of the rig's model: beam and tube accelerometers, two tip load cells, the hammer."""
    out = []
    for s in (1, 2):
        for d, axis in enumerate("xyz", start=1):
            y = ringdown(40.0 * s + 13.0 * d, amp=1.0 + d) + ringdown(310.0 + 7 * s, amp=0.3, phase=0.4 * d)
            out.append(TimeHistory(f"beam_s{s}:{axis}", s, d, "acceleration", y, DT))
    out.append(TimeHistory("tube_s1:z", 101, 3, "acceleration", ringdown(77.0, amp=2.0), DT))
    out.append(TimeHistory("tip_left_top", 201, 3, "reaction_force", ringdown(150.0, amp=40.0), DT))
    out.append(TimeHistory("tip_left_bottom", 202, -3, "reaction_force", ringdown(150.0, amp=-25.0), DT))
    t = np.arange(N) * DT
    hammer = np.where(t < 2e-3, 100.0 * np.sin(np.pi * t / 2e-3), 0.0)
    out.append(TimeHistory("hammer", 300, -3, "force", hammer, DT))
    return out


def replaced(ch: TimeHistory, **kw) -> TimeHistory:
    args = dict(name=ch.name, node=ch.node, direction=ch.direction, quantity=ch.quantity, data=ch.data,
                dt_s=ch.dt_s, t0_s=ch.t0_s)
    args.update(kw)
    return TimeHistory(**args)


def refusal(exc_info) -> str:
    msg = str(exc_info.value)
    assert "\n" not in msg, msg
    return msg


# --- matching -----------------------------------------------------------------------------------


def test_identical_channels_have_zero_error_and_equal_frequencies():
    model = rig()
    pairs = match_channels(model, rig())
    assert [p.name for p in pairs] == [c.name for c in model if c.name != "hammer"]  # the hammer drives the model
    rows = channel_errors(pairs)
    for r in rows:
        assert r["rms_rel_error"] == 0.0
        assert r["f_dominant_model_hz"] == r["f_dominant_test_hz"]
        assert r["f_rel_error"] == 0.0
        assert r["flipped"] is False
        assert r["n_samples"] == N and r["rms_test"] > 0
    by = {r["name"]: r for r in rows}
    assert by["beam_s1:x"]["unit"] == "m/s^2" and by["tip_left_top"]["unit"] == "N"
    assert by["tip_left_bottom"]["direction"] == -3


def test_opposite_direction_code_with_negated_data_matches_exactly():
    model = rig()
    test = [replaced(c, name=f"T{i}", direction=-c.direction, data=-c.data) for i, c in enumerate(model)]
    pairs = match_channels(model, test[::-1])  # order in the file does not matter
    assert all(p.flipped for p in pairs)
    for p in pairs:
        assert p.test.direction == p.model.direction
        np.testing.assert_array_equal(p.test.data, p.model.data)
    assert all(r["rms_rel_error"] == 0.0 for r in channel_errors(pairs))
    # same sense, same data: not flipped
    assert not any(p.flipped for p in match_channels(model, rig()))


def test_scaled_test_gives_the_closed_form_rms_error():
    model = rig()
    test = [replaced(c, data=1.1 * c.data) for c in model]
    for r in channel_errors(match_channels(model, test)):
        # rms(m - 1.1 m) / rms(1.1 m) = 0.1 / 1.1 whatever m is
        assert r["rms_rel_error"] == pytest.approx(0.1 / 1.1, rel=1e-12, abs=0)
        assert r["peak_abs_test"] == pytest.approx(1.1 * r["peak_abs_model"], rel=1e-12)
        assert r["rms_test"] == pytest.approx(1.1 * r["rms_model"], rel=1e-12)


def test_frequency_shift_is_found_within_the_welch_resolution():
    m = TimeHistory("beam_s1:z", 1, 3, "acceleration", ringdown(100.0), DT)
    x = TimeHistory("acc1z", 1, 3, "acceleration", ringdown(105.0), DT)
    (r,) = channel_errors(match_channels([m], [x]))
    df = r["f_resolution_hz"]
    assert df == pytest.approx(2.0)
    assert abs(r["f_dominant_model_hz"] - 100.0) < df / 2
    assert abs(r["f_dominant_test_hz"] - 105.0) < df / 2
    assert abs(r["f_rel_error"] - (100.0 - 105.0) / 105.0) < df / 105.0
    # the band limits which peak is dominant: a weaker 400 Hz tone wins above 200 Hz
    two = TimeHistory("beam_s1:z", 1, 3, "acceleration", ringdown(100.0) + ringdown(400.0, amp=0.2), DT)
    (r,) = channel_errors(match_channels([two], [two]), fmin_hz=200.0)
    assert abs(r["f_dominant_model_hz"] - 400.0) < df / 2


def test_common_grid_and_window():
    # the test record starts 0.1 s earlier and ends earlier: compared on the common samples only
    n_pre = 200
    y = ringdown(100.0, n=N + n_pre, t0=-n_pre * DT)
    model = [TimeHistory("beam_s1:z", 1, 3, "acceleration", y[n_pre:], DT)]
    test = [TimeHistory("a", 1, 3, "acceleration", y[:N + n_pre - 300], DT, t0_s=-n_pre * DT)]
    (p,) = match_channels(model, test)
    a = p.aligned()
    assert a.t.size == N - 300 and a.t[0] == 0.0
    np.testing.assert_array_equal(a.model, a.test)
    # a difference after 0.5 s is outside the window (0, 0.4) s
    data = model[0].data.copy()
    data[1000:] *= 2.0
    (p,) = match_channels(model, [replaced(model[0], data=data)])
    (r,) = channel_errors([p], window_s=(0.0, 0.4))
    assert r["rms_rel_error"] == 0.0 and r["n_samples"] == 801 and r["t_end_s"] == pytest.approx(0.4)
    assert channel_errors([p])[0]["rms_rel_error"] > 0.0
    with pytest.raises(ChannelError) as e:
        channel_errors([p], window_s=(5.0, 6.0))
    assert "fewer than 2" in refusal(e)


def test_zero_test_channel_gives_inf_not_a_crash():
    m = TimeHistory("beam_s1:z", 1, 3, "acceleration", ringdown(100.0), DT)
    x = replaced(m, data=np.zeros(N))
    (r,) = channel_errors(match_channels([m], [x]))
    assert r["rms_rel_error"] == math.inf
    assert math.isnan(r["f_dominant_test_hz"]) and math.isnan(r["f_rel_error"])
    (r,) = channel_errors(match_channels([x], [x]))  # both zero: they agree
    assert r["rms_rel_error"] == 0.0


# --- refusals -----------------------------------------------------------------------------------


def _without(name):
    return [c for c in rig() if c.name != name]


def _named(name):
    return next(c for c in rig() if c.name == name)


def _swap(name, **kw):
    return [replaced(c, **kw) if c.name == name else c for c in rig()]


@pytest.mark.parametrize("test, wanted, needles", [
    (_without("beam_s2:y"), None, ["'beam_s2:y'", "node 2", "+2 (+Y)", "acceleration", "[hammer] compare"]),
    (rig(), ["hammer", "beam_s1:x"], None),  # the hammer is compared only when wanted; filled below
    (_swap("beam_s1:x", quantity="velocity"), None, ["'beam_s1:x'", "acceleration", "velocity"]),
    (_swap("tube_s1:z", dt_s=DT * (1 + 1e-6)), None, ["'tube_s1:z'", "2000 Hz", "1999.998"]),
    (rig() + [replaced(_named("beam_s2:y"), name="dup", direction=-2)], None, ["ambiguous", "'beam_s2:y'", "'dup'"]),
    (rig(), ["beam_s1:zz"], ["unknown", "did you mean 'beam_s1:z'"]),
    (_swap("beam_s1:x", t0_s=10.0), None, ["'beam_s1:x'", "fewer than 2 common samples"]),
    (_swap("beam_s1:x", t0_s=0.3 * DT), None, ["'beam_s1:x'", "of a sample apart"]),
])
def test_refusals_are_one_line(test, wanted, needles):
    if needles is None:  # the wanted hammer is missing from a file without one
        test, needles = _without("hammer"), ["'hammer'", "node 300", "-3 (-Z)", "force", "compare"]
    with pytest.raises(ChannelError) as e:
        match_channels(rig(), test, wanted)
    msg = refusal(e)
    for needle in needles:
        assert needle in msg, msg


def test_duplicate_of_another_quantity_is_not_ambiguous():
    # a file may hold a sensor's acceleration and its integrated velocity at one node and axis
    model = rig()
    extra = TimeHistory("v1x", 1, 1, "velocity", np.zeros(N), DT)
    pairs = match_channels(model, rig() + [extra])
    assert {p.test.quantity for p in pairs if p.node == 1} == {"acceleration"}


# --- UFF files ----------------------------------------------------------------------------------


def test_uff_round_trip_matches_and_flips(tmp_path):
    model = rig()
    test = []
    for i, c in enumerate(model):
        if c.name.startswith("beam_s2"):  # mounted upside down: opposite direction code, negated data
            test.append(replaced(c, name=f"acc{i}", direction=-c.direction, data=-c.data))
        elif c.name == "tube_s1:z":
            test.append(replaced(c, name=f"acc{i}", data=1.1 * c.data))
        else:
            test.append(replaced(c, name=f"ch{i}"))
    write_uff58(tmp_path / "model.uff", model)
    write_uff58(tmp_path / "test.uff", test)
    pairs = match_channels(read_uff58(tmp_path / "model.uff"), read_uff58(tmp_path / "test.uff"),
                           source=str(tmp_path / "test.uff"))
    rows = {r["name"]: r for r in channel_errors(pairs)}
    assert len(rows) == len(model) - 1
    for name, r in rows.items():
        assert r["flipped"] == name.startswith("beam_s2")
        expected = 0.1 / 1.1 if name == "tube_s1:z" else 0.0
        assert r["rms_rel_error"] == pytest.approx(expected, rel=1e-12, abs=0), name


def test_uff_with_a_non_si_unit_is_refused_in_one_line(tmp_path):
    import pyuff

    y = ringdown(100.0) / 9.81
    rec = pyuff.prepare_58(
        binary=1, id1="acc in g", id2="lab", id3="NONE", id4="NONE", id5="NONE", func_type=1, ver_num=0,
        load_case_id=0, rsp_ent_name="acc", rsp_node=1, rsp_dir=3, ref_ent_name="NONE", ref_node=0, ref_dir=0,
        ord_data_type=4, num_pts=N, abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=DT, z_axis_value=0.0,
        abscissa_spec_data_type=17, abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
        abscissa_axis_units_lab="s", ordinate_spec_data_type=QUANTITIES["acceleration"][0], ordinate_len_unit_exp=1,
        ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0, ordinate_axis_units_lab="g", orddenom_spec_data_type=0,
        orddenom_len_unit_exp=0, orddenom_force_unit_exp=0, orddenom_temp_unit_exp=0,
        orddenom_axis_units_lab="NONE", z_axis_spec_data_type=0, z_axis_len_unit_exp=0, z_axis_force_unit_exp=0,
        z_axis_temp_unit_exp=0, z_axis_axis_units_lab="NONE", data=y, x=np.arange(N) * DT)
    path = tmp_path / "g.uff"
    pyuff.UFF(str(path)).write_sets([rec], mode="add")
    with pytest.raises(UffError) as e:
        read_uff58(path)
    msg = refusal(e)
    assert "'g'" in msg and "m/s^2" in msg


# --- outputs ------------------------------------------------------------------------------------


def test_errors_csv_is_byte_identical_on_rerun(tmp_path):
    model = rig()
    test = [replaced(c, data=c.data * (1 + 1e-3 * np.sin(np.arange(N)))) for c in model]
    test[0] = replaced(model[0], data=np.zeros(N))  # an inf in the table
    rows = channel_errors(match_channels(model, test))
    write_errors_csv(rows, tmp_path / "a.csv")
    write_errors_csv(channel_errors(match_channels(model, test)), tmp_path / "b.csv")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    with open(tmp_path / "a.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == len(rows) and table[0]["rms_rel_error"] == "inf"
    for r in table:
        mantissa = r["rms_model"].split("e")[0].replace(".", "").replace("-", "").lstrip("0")
        assert len(mantissa) <= 6, r["rms_model"]
        assert float(r["rms_model"]) == pytest.approx(float(next(x for x in rows if x["name"] == r["name"])
                                                            ["rms_model"]), rel=1e-5)


def test_default_channels_prefer_hammer_tip_cell_and_beam():
    model = rig()
    pairs = match_channels(model, rig(), wanted=[c.name for c in model])
    chosen = default_channels(pairs)
    assert len(chosen) == 6
    assert chosen[0] == "hammer" and chosen[1] == "tip_left_top"  # the load cell of larger rms
    assert all(n.startswith("beam_") for n in chosen[2:])


def test_figures_are_written(tmp_path):
    model = rig()
    test = [replaced(c, data=1.05 * c.data) for c in model]
    pairs = match_channels(model, test, wanted=[c.name for c in model])
    comparison_figure(pairs, tmp_path / "cmp.png", "hammer test: model against test " * 5)
    comparison_figure(pairs, tmp_path / "cmp2.png", "two channels", channels=["tip_left_bottom", "beam_s1:z"],
                      window_s=(0.0, 0.3))
    by = {p.name: p for p in pairs}
    spectrogram_pair_figure(by["beam_s1:z"], tmp_path / "spec.png", window_s=0.05, overlap=0.75, fmax_hz=500.0)
    for name in ("cmp.png", "cmp2.png", "spec.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    with pytest.raises(ChannelError) as e:
        comparison_figure(pairs, tmp_path / "x.png", "x", channels=["beam_s1:q"])
    assert "did you mean" in refusal(e)
    with pytest.raises(ChannelError) as e:
        spectrogram_pair_figure(by["beam_s1:z"], tmp_path / "y.png", window_s=5.0, overlap=0.5, fmax_hz=500.0)
    assert "beam_s1:z" in refusal(e)


# --- a test file is user input: its records checked as one test (issue 26) -----------------------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from bearingshaft.correlate import (  # noqa: E402
    NEAR_ZERO,
    NOISE_FACTOR,
    channel_floors,
    check_test_channels,
    force_window,
)

CORRUPTIONS = ("nan", "duplicate name", "duplicate axis", "no hammer", "two hammers", "zero hammer", "sampling",
               "start", "length")


@st.composite
def measured_files(draw):
    """A valid test's records (a hammer and 1-6 accelerometer axes at distinct nodes and axes), in a random
    order; the index of the hammer."""
    n = draw(st.integers(8, 64))
    dt = draw(st.sampled_from([1e-4, 5e-5, 1.953125e-5]))
    axes = draw(st.lists(st.tuples(st.integers(1, 6), st.integers(1, 3)), min_size=1, max_size=6, unique=True))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    chans = [TimeHistory(f"s{node}:{'xyz'[d - 1]}", node, d * draw(st.sampled_from([1, -1])), "acceleration",
                         rng.standard_normal(n), dt) for node, d in axes]
    hammer = np.zeros(n)
    hammer[n // 4] = draw(st.floats(1.0, 1e4))
    h = draw(st.integers(0, len(chans)))
    chans.insert(h, TimeHistory("hammer", 300, -3, "force", hammer, dt))
    return chans, h


@settings(max_examples=60, deadline=None)
@given(measured_files())
def test_a_valid_test_file_is_accepted(case):
    chans, h = case
    assert check_test_channels(chans) == h


@settings(max_examples=150, deadline=None)
@given(measured_files(), st.sampled_from(CORRUPTIONS), st.integers(0, 2**16))
def test_a_corrupt_test_file_is_refused_in_one_line_naming_the_record(case, kind, seed):
    """Each corruption of one record of a valid test is refused (ChannelError, one line) naming that
    record as the file numbers it (1-based), with the word that says what is wrong."""
    chans, h = case
    rng = np.random.default_rng(seed)
    others = [k for k in range(len(chans)) if k != h]
    k = int(rng.choice(others))
    c = chans[k]
    needles = [f"record {k + 1} ({c.name!r})"]
    if kind == "nan":
        data = c.data.copy()
        data[int(rng.integers(c.data.size))] = [np.nan, np.inf, -np.inf][int(rng.integers(3))]
        chans[k] = replaced(c, data=data)
        needles.append("not finite")
    elif kind == "duplicate name":
        chans.insert(k + 1, replaced(c, node=c.node + 100))
        needles = [f"record {k + 2} ({c.name!r})", f"record {k + 1} is named", "two records for one channel"]
    elif kind == "duplicate axis":
        chans.insert(k + 1, replaced(c, name="again", direction=-c.direction))
        needles = [f"record {k + 2} ('again')", f"record {k + 1} ({c.name!r})", "two records for one channel"]
    elif kind == "no hammer":
        del chans[h]
        needles = ["no hammer channel", "force"]
    elif kind == "two hammers":
        chans[k] = replaced(c, quantity="force")
        j = max(h, k)
        needles = [f"record {j + 1}", "second force channel", f"record {min(h, k) + 1} is one"]
    elif kind == "zero hammer":
        chans[h] = replaced(chans[h], data=np.zeros(chans[h].data.size))
        needles = [f"record {h + 1} ('hammer')", "zero throughout"]
    elif kind == "sampling":
        chans[k] = replaced(c, dt_s=c.dt_s * 2)
        needles += ["sampled at", "Hz, the hammer channel"]
    elif kind == "start":
        chans[k] = replaced(c, t0_s=c.t0_s + 3 * c.dt_s)
        needles += ["starts at", "start together"]
    else:
        chans[k] = replaced(c, data=c.data[:-1])
        needles += [f"has {c.data.size - 1} samples", "cut short"]
    with pytest.raises(ChannelError) as e:
        check_test_channels(chans)
    msg = refusal(e)
    for needle in needles:
        assert needle in msg, (kind, msg)


def _half_sine(n=2000, dt=1e-5, start=500, width=100, peak=500.0):
    t = np.arange(n) * dt
    f = np.zeros(n)
    k = np.arange(width + 1)
    f[start:start + width + 1] = peak * np.sin(np.pi * k / width)
    return t, f


def test_force_window_keeps_the_pulse_and_zeroes_the_rest():
    """A 1 ms half-sine of 500 N sampled at 100 kHz with 0.5 % noise and a 2 N offset: the pulse is
    the run of samples above 2 % of the peak (sin(pi k / 100) >= 0.02: k = 1 .. 99, noise of 2.5 N
    moves an edge by at most a sample), kept as recorded less the offset; a half-cosine over the
    1 ms margins; zero outside."""
    t, f = _half_sine()
    rng = np.random.default_rng(1)
    noisy = f + 2.0 + 2.5 * rng.standard_normal(f.size)
    w = force_window(TimeHistory("hammer", 300, -3, "force", noisy, 1e-5), 1e-3)
    assert w.offset_N == pytest.approx(2.0, abs=0.2)  # the median of 1900 noise samples: 2.5 N / sqrt(1900) x 1.25
    assert w.noise_N == pytest.approx(2.5, rel=0.1)  # 1.4826 MAD of Gaussian noise
    a, b = (round(x / 1e-5) for x in w.pulse_s)
    assert abs(a - 501) <= 1 and abs(b - 599) <= 1
    out = w.channel.data
    np.testing.assert_array_equal(out[a:b + 1], noisy[a:b + 1] - w.offset_N)
    m = 100  # the margin in samples
    assert np.all(out[:a - m] == 0.0) and np.all(out[b + m + 1:] == 0.0)
    taper = 0.5 * (1 + np.cos(np.pi * np.arange(1, m + 1) / (m + 1)))
    np.testing.assert_allclose(out[b + 1:b + m + 1], (noisy[b + 1:b + m + 1] - w.offset_N) * taper, rtol=1e-15)
    assert w.window_s == pytest.approx((t[a - m], t[b + m]))
    assert "force window" in w.describe() and "\n" not in w.describe()


def test_a_second_blow_outside_the_window_is_refused():
    t, f = _half_sine()
    f[1500:1520] += 200.0  # a double hit 10 ms later, 40 % of the peak
    with pytest.raises(ChannelError) as e:
        force_window(TimeHistory("hammer", 300, -3, "force", f, 1e-5), 1e-3, source="'x.uff' record 3 ('hammer')")
    msg = refusal(e)
    assert "'x.uff' record 3 ('hammer')" in msg and "double hit" in msg and "t = 0.015 s" in msg
    w = force_window(TimeHistory("hammer", 300, -3, "force", f, 1e-5), 1e-3, double_hit=False)
    assert w.pulse_s == pytest.approx((5.01e-3, 5.99e-3))


@settings(max_examples=40, deadline=None)
@given(st.integers(100, 1500), st.integers(4, 200), st.floats(0.0, 0.01), st.floats(0.0, 2e-3), st.integers(0, 99))
def test_force_window_property(start, width, noise, margin, seed):
    """Whatever the pulse, the noise (up to 1 % of the peak) and the margin: the windowed force is the
    recorded one less the offset over the pulse, and exactly zero farther than the margin from it."""
    t, f = _half_sine(start=start, width=width)
    f = f + noise * 500.0 * np.random.default_rng(seed).standard_normal(f.size)
    w = force_window(TimeHistory("hammer", 300, -3, "force", f, 1e-5), margin, double_hit=False)
    a, b = (round(x / 1e-5) for x in w.pulse_s)
    assert a <= start + width // 2 <= b  # the peak is inside
    np.testing.assert_array_equal(w.channel.data[a:b + 1], f[a:b + 1] - w.offset_N)
    m = int(np.ceil(margin / 1e-5 - 1e-9))
    assert np.all(w.channel.data[:max(a - m, 0)] == 0.0) and np.all(w.channel.data[b + m + 1:] == 0.0)


def test_floors_judge_a_zero_axis_against_its_sensor_and_the_noise():
    """rms(m - x) / max(rms_x, floor): the y axis of a sensor (1e-5 of its z) against 1 % of z; a
    channel whose signal is below 3 x its noise before the blow against that."""
    t = np.arange(N) * DT
    sig = np.where(t > 0.1, np.sin(2 * np.pi * 50 * t), 0.0)
    noise = 1e-3 * np.random.default_rng(2).standard_normal(N)
    z = TimeHistory("a:z", 1, 3, "acceleration", sig, DT)
    y = TimeHistory("a:y", 1, 2, "acceleration", 1e-5 * sig, DT)
    c = TimeHistory("c:z", 2, 3, "acceleration", 1e-4 * sig + noise, DT)
    model = [z, replaced(y, data=2e-5 * sig), replaced(c, data=np.zeros(N))]
    pairs = match_channels(model, [z, y, c])
    floors = channel_floors(pairs, noise_s=(0.0, 0.1))
    rms_z = correlate_rms(sig)
    assert floors["a:y"] == (pytest.approx(NEAR_ZERO * rms_z, rel=1e-12), "sensor")
    assert floors["c:z"][1] == "noise"
    assert floors["c:z"][0] == pytest.approx(NOISE_FACTOR * correlate_rms(noise[t <= 0.1]), rel=1e-9)
    rows = {r["name"]: r for r in channel_errors(pairs, floors=floors)}
    assert rows["a:z"]["rms_rel_error"] == 0.0 and rows["a:z"]["judged_against"] == "itself"
    # the model's y is twice the test's: the error is rms(1e-5 sig) / (0.01 rms(sig)) = 1e-3, not 100 %
    assert rows["a:y"]["rms_rel_error"] == pytest.approx(1e-3, rel=1e-9)
    assert rows["a:y"]["judged_against"] == "sensor"
    assert rows["c:z"]["judged_against"] == "noise" and rows["c:z"]["rms_rel_error"] < 1.0


def correlate_rms(y):
    return float(np.sqrt(np.mean(np.square(y))))
