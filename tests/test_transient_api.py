"""The Python API of reduced.transient refuses bad arguments before any work.

Every refusal is a ValueError whose one-line message names the argument, shows the value
given and says what is allowed.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.transient.compare import compare_runs, largest_lyapunov, separation_exponent
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.exact import integrate_exact, state_table
from reduced.transient.explicit import contact_omega, default_step, integrate_explicit, stability_limit
from reduced.transient.flow import Flow
from reduced.transient.integrate import (
    default_chunk_samples,
    ringdown,
    ringdown_disk_bytes,
    ringdown_peak_bytes,
    ringdown_stream,
)
from reduced.transient.result import sample_times
from reduced.transient.spectrogram import curve_in_time, spectrogram, spectrogram_chunks
from reduced.transient.store import RingdownFile

SYS = DiscreteParams().system()
X0, V0 = np.zeros(3), np.array([0.0, 0.0, 200.0])
NAN, INF = float("nan"), float("inf")


def refused(fn, name: str, shown: str | None = None, allowed: str | None = None) -> str:
    """Call fn, expect a one-line ValueError naming ``name`` (and ``shown``, ``allowed``)."""
    t0 = time.perf_counter()
    with pytest.raises(ValueError) as info:
        fn()
    msg = str(info.value)
    assert time.perf_counter() - t0 < 5.0, "refused only after doing work"
    assert "\n" not in msg
    assert msg.startswith(name) or f" {name} " in msg or f"{name} =" in msg or f"{name}:" in msg, msg
    if shown is not None:
        assert shown in msg, msg
    if allowed is not None:
        assert allowed in msg, msg
    return msg


RINGDOWN_CASES = [
    # (keyword changes, argument named, value shown, what is allowed)
    ({"method": "dop853", "atol": NAN}, "atol", "nan", "> 0"),  # used to hang for minutes
    ({"method": "dop853", "atol": -1e-9}, "atol", "-1e-09", "> 0"),
    ({"method": "dop853", "atol": INF}, "atol", "inf", "finite"),
    ({"method": "dop853", "rtol": NAN}, "rtol", "nan", "< 1"),
    ({"method": "dop853", "rtol": 0.0}, "rtol", "0.0", "> 0"),
    ({"method": "dop853", "rtol": 1.0}, "rtol", "1.0", "< 1"),
    ({"method": "dop853", "rtol": True}, "rtol", "True", "finite number"),
    ({"method": "exact", "rtol": -1.0}, "rtol", "-1.0", "> 0"),  # checked whatever the method
    ({"method": "explicit", "dt": NAN}, "dt", "nan", "> 0"),
    ({"method": "explicit", "dt": -1e-6}, "dt", "-1e-06", "> 0"),
    ({"method": "explicit", "omega_dt": 0.0}, "omega_dt", "0.0", "(0, 1.6]"),
    ({"method": "explicit", "omega_dt": -0.1}, "omega_dt", "-0.1", "(0, 1.6]"),
    ({"method": "explicit", "omega_dt": NAN}, "omega_dt", "nan", "(0, 1.6]"),
    ({"method": "explicit", "omega_dt": 3.0}, "omega_dt", "3.0", "unstable"),
    ({"method": "exact", "omega_dt": -1.0}, "omega_dt", "-1.0", "> 0"),
    ({"method": "explicit", "step_basis": "bottom"}, "step_basis", "'bottom'", "top, contact"),
    ({"method": "rk4"}, "method", "'rk4'", "exact, explicit, dop853"),
    ({"method": None}, "method", "None", "exact, explicit, dop853"),
    ({"progress": "yes"}, "progress", "'yes'", "callable"),
    ({"progress": 1}, "progress", "1", "callable"),
    ({"duration_s": NAN}, "duration_s", "nan", "> 0"),
    ({"duration_s": 0.0}, "duration_s", "0.0", "> 0"),
    ({"duration_s": "2"}, "duration_s", "'2'", "finite number"),
    ({"sample_rate_hz": -1.0}, "sample_rate_hz", "-1.0", "> 0"),
    ({"sample_rate_hz": INF}, "sample_rate_hz", "inf", "finite"),
    ({"x0": [0.0, NAN, 0.0]}, "x0", "nan", "finite"),
    ({"x0": np.zeros(4)}, "x0", "(4,)", "3 values"),
    ({"v0": "fast"}, "v0", "'fast'", "3 finite numbers"),
    ({"system": "discrete"}, "system", "str", "GapSystem"),
    ({"chunk_samples": 0, "out": "ignored.npz"}, "chunk_samples", "0", ">= 1"),
    ({"chunk_samples": 2.5}, "chunk_samples", "2.5", "integer"),
    ({"out": 3}, "out", "3", "file path"),
    ({"out": "/no/such/folder/r.npz"}, "out", "/no/such/folder", "existing folder"),
    ({"max_memory_bytes": NAN}, "max_memory_bytes", "nan", "> 0"),
]


@pytest.mark.parametrize("change, name, shown, allowed", RINGDOWN_CASES)
def test_ringdown_refuses(change, name, shown, allowed):
    kw = {"system": SYS, "x0": X0, "v0": V0, "duration_s": 0.01, "sample_rate_hz": 20000.0, "method": "exact"}
    kw.update(change)
    refused(lambda: ringdown(**kw), name, shown, allowed)
    if "out" not in change and "max_memory_bytes" not in change:  # the stream checks the same
        kw.pop("out", None)
        refused(lambda: ringdown_stream(**kw), name, shown, allowed)


@pytest.mark.parametrize(
    "fn, name, shown",
    [
        (lambda: integrate_exact(SYS, X0, V0, 0.01, 2e4, chunks=0), "chunks", "0"),
        (lambda: integrate_exact(SYS, X0, V0, 0.01, 2e4, max_events=-5), "max_events", "-5"),
        (lambda: integrate_exact(SYS, X0, V0, 0.01, 2e4, progress=object()), "progress", "object"),
        (lambda: integrate_explicit(SYS, X0, V0, 0.01, 2e4, dt=NAN), "dt", "nan"),
        (lambda: integrate_explicit(SYS, X0, V0, 0.01, 2e4, omega_dt=0.0), "omega_dt", "0.0"),
        (lambda: integrate_explicit(SYS, X0, V0, 0.01, 2e4, chunks=1.0), "chunks", "1.0"),
        (lambda: integrate_dop853(SYS, X0, V0, 0.01, 2e4, atol=NAN), "atol", "nan"),
        (lambda: integrate_dop853(SYS, X0, V0, 0.01, 2e4, rtol=1.5), "rtol", "1.5"),
        (lambda: integrate_dop853(SYS, X0, V0, 0.01, 2e4, events="yes"), "events", "'yes'"),
        (lambda: default_step(SYS, omega_dt=NAN), "omega_dt", "nan"),
        (lambda: default_step(SYS, step_basis="middle"), "step_basis", "'middle'"),
        (lambda: stability_limit(np.eye(3)), "system", "ndarray"),
        (lambda: state_table("x"), "system", "str"),
        (lambda: contact_omega(SYS, n=0), "n", "0"),
        (lambda: Flow(SYS)(X0, V0, NAN), "T", "nan"),
        (lambda: Flow(SYS)(X0, V0, -1.0), "T", "-1.0"),
        (lambda: Flow(SYS)(np.zeros(2), V0, 1e-3), "x0", "(2,)"),
        (lambda: Flow(SYS)(X0, V0, 1e-3, t0=-1.0), "t0", "-1.0"),
        (lambda: sample_times(NAN, 1e3), "duration_s", "nan"),
        (lambda: ringdown_peak_bytes(0, 1.0, 2e4), "n_dofs", "0"),
        (lambda: ringdown_peak_bytes(3, 1.0, 2e4, method="euler"), "method", "'euler'"),
        (lambda: ringdown_peak_bytes(3, 1.0, 2e4, n_stops=-1), "n_stops", "-1"),
        (lambda: ringdown_peak_bytes(3, 1.0, NAN), "sample_rate_hz", "nan"),
        (lambda: ringdown_peak_bytes(3, 1.0, 2e4, streamed="no"), "streamed", "'no'"),
        (lambda: ringdown_peak_bytes(3, 1.0, 2e4, forced=1), "forced", "1"),
        (lambda: ringdown_disk_bytes(3, -1.0, 2e4), "duration_s", "-1.0"),
        (lambda: ringdown_disk_bytes(3, 1.0, 2e4, forced="yes"), "forced", "'yes'"),
        (lambda: default_chunk_samples(2.0), "n_dofs", "2.0"),
        (lambda: RingdownFile("/no/such/ringdown.npz"), "path", "/no/such/ringdown.npz"),
        (lambda: largest_lyapunov(SYS, X0, V0, 0.01, 2e4, delta=0.0), "delta", "0.0"),
        (lambda: largest_lyapunov(SYS, X0, V0, 0.01, 2e4, saturation=NAN), "saturation", "nan"),
        (lambda: largest_lyapunov(SYS, X0, V0, 0.01, 2e4, window_s=-1.0), "window_s", "-1.0"),
        (lambda: largest_lyapunov(SYS, X0, np.zeros(3), 0.01, 2e4), "x0, v0", None),
        (lambda: separation_exponent(np.arange(3.0), np.ones(4)), "D", "(4,)"),
        (lambda: compare_runs(SYS, [], [], 10, 2e4, np.eye(2)), "points", "(2, 2)"),
    ],
)
def test_functions_refuse(fn, name, shown):
    refused(fn, name, shown)


@pytest.mark.parametrize(
    "kw, name, shown",
    [
        ({"window_s": NAN}, "window_s", "nan"),
        ({"window_s": 10.0}, "window_s", "10.0"),  # longer than the record
        ({"overlap": 1.0}, "overlap", "1.0"),
        ({"overlap": -0.5}, "overlap", "-0.5"),
        ({"fmax_hz": 0.0}, "fmax_hz", "0.0"),
        ({"max_frames": 0}, "max_frames", "0"),
        ({"y": np.ones(5)}, "y", "(5,)"),
        ({"t": np.zeros(100)}, "t", "0.0"),
        ({"y": np.full(100, np.nan)}, "y", None),
    ],
)
def test_spectrogram_refuses(kw, name, shown):
    args = {"t": np.arange(100) / 1e3, "y": np.sin(np.arange(100.0)), "window_s": 0.02, "overlap": 0.5}
    args.update(kw)
    refused(lambda: spectrogram(**args), name, shown)


def test_spectrogram_chunks_must_be_consecutive():
    with pytest.raises(ValueError, match="consecutive: expected sample 0, got 5"):
        spectrogram_chunks([(5, np.ones(100))], 105, 1e3, 0.02, 0.5)


def test_curve_in_time_refuses_mismatched_curve():
    refused(lambda: curve_in_time(np.ones(3), np.ones(4), np.ones(5)), "freq_hz", "(5,)")


def test_nan_tolerance_no_longer_hangs():
    # issue 10: method="dop853", atol=nan ran for minutes; now refused at once
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"^atol must be a finite number > 0 \(m\), got nan$"):
        ringdown(SYS, X0, V0, 2.0, 20000.0, "dop853", atol=math.nan)
    assert time.perf_counter() - t0 < 1.0


def test_good_arguments_of_every_kind_are_accepted(tmp_path):
    # numpy scalars and integers are numbers; a path may be a str or a Path
    r = ringdown(SYS, [0, 0, 0], (0, 0, 200), np.float64(0.002), 20000, "explicit", omega_dt=np.float32(0.05),
                 out=str(tmp_path / "r.npz"), chunk_samples=np.int64(7))
    assert r.n_samples == 41
    r = ringdown(SYS, X0, V0, 0.002, 20000.0, "dop853", rtol=1e-6, atol=np.float64(1e-9))
    assert r.stats["atol"] == 1e-9
