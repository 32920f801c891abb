"""The Python API of reduced.transient refuses bad arguments before any work.

Every refusal is a ValueError whose one-line message names the argument, shows the value
given and says what is allowed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.transient import dop853 as _dop853_mod
from reduced.transient import exact as _exact_mod
from reduced.transient import exact_tables as _exact_tables_mod
from reduced.transient import explicit as _explicit_mod
from reduced.transient import flow as _flow_mod
from reduced.transient import spectrogram as _spectrogram_mod
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


TABLE = state_table(SYS)  # built once, outside the tripwire: Flow(SYS, TABLE) then does no work until called


class WorkStarted(Exception):
    """Raised by the tripwire when a refused call reached the integration (not a ValueError)."""


@pytest.fixture
def no_work(monkeypatch):
    """Replace every place where the work of a call starts with a tripwire that records and raises.

    "Refused before any work" is shown by the work never starting, not by a clock (an absolute
    time bound is flaky on a loaded machine and blind to cheap work): every numba kernel of the
    three integrators and the flow runs through ``call_numba_kernel`` (patched where each module
    imported it), the exact integrator starts with ``state_table`` (the state decompositions, with the
    kept tables forgotten),
    DOP853 with SciPy's ``DOP853`` stepper, a spectrogram with ``rfft``.
    test_tripwire_catches_the_work_of_every_integrator shows each wire fires on a valid call.
    """
    calls: list[str] = []

    def wire(name):
        def tripped(*args, **kwargs):
            calls.append(name)
            raise WorkStarted(name)
        return tripped

    for mod in (_exact_mod, _explicit_mod, _flow_mod):
        monkeypatch.setattr(mod, "call_numba_kernel", wire(f"{mod.__name__}.call_numba_kernel"))
    monkeypatch.setattr(_exact_mod, "state_table", wire("exact.state_table"))
    monkeypatch.setattr(_exact_tables_mod, "state_table", wire("exact.state_table"))  # via run_tables
    _exact_tables_mod.clear_table_cache()  # tables kept from earlier runs would let a run skip its set-up
    monkeypatch.setattr(_dop853_mod, "DOP853", wire("scipy DOP853"))
    monkeypatch.setattr(_spectrogram_mod, "rfft", wire("spectrogram rfft"))
    return calls


def refused(fn, name: str, shown: str | None = None, allowed: str | None = None, *, work: list) -> str:
    """Call fn, expect a one-line ValueError naming ``name`` (and ``shown``, ``allowed``) and no work
    started (``work`` is the :func:`no_work` fixture's record)."""
    with pytest.raises(ValueError) as info:
        fn()
    msg = str(info.value)
    assert work == [], f"refused only after the work started: {work}"
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
def test_ringdown_refuses(change, name, shown, allowed, no_work):
    kw = {"system": SYS, "x0": X0, "v0": V0, "duration_s": 0.01, "sample_rate_hz": 20000.0, "method": "exact"}
    kw.update(change)
    refused(lambda: ringdown(**kw), name, shown, allowed, work=no_work)
    if "out" not in change and "max_memory_bytes" not in change:  # the stream checks the same
        kw.pop("out", None)
        refused(lambda: ringdown_stream(**kw), name, shown, allowed, work=no_work)


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
        (lambda: Flow(SYS, TABLE)(X0, V0, NAN), "T", "nan"),
        (lambda: Flow(SYS, TABLE)(X0, V0, -1.0), "T", "-1.0"),
        (lambda: Flow(SYS, TABLE)(np.zeros(2), V0, 1e-3), "x0", "(2,)"),
        (lambda: Flow(SYS, TABLE)(X0, V0, 1e-3, t0=-1.0), "t0", "-1.0"),
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
def test_functions_refuse(fn, name, shown, no_work):
    refused(fn, name, shown, work=no_work)


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
def test_spectrogram_refuses(kw, name, shown, no_work):
    args = {"t": np.arange(100) / 1e3, "y": np.sin(np.arange(100.0)), "window_s": 0.02, "overlap": 0.5}
    args.update(kw)
    refused(lambda: spectrogram(**args), name, shown, work=no_work)


def test_spectrogram_chunks_must_be_consecutive():
    with pytest.raises(ValueError, match="consecutive: expected sample 0, got 5"):
        spectrogram_chunks([(5, np.ones(100))], 105, 1e3, 0.02, 0.5)


def test_curve_in_time_refuses_mismatched_curve(no_work):
    refused(lambda: curve_in_time(np.ones(3), np.ones(4), np.ones(5)), "freq_hz", "(5,)", work=no_work)


def test_nan_tolerance_no_longer_hangs(no_work):
    # issue 10: method="dop853", atol=nan ran for minutes; now refused before DOP853 takes a step
    with pytest.raises(ValueError, match=r"^atol must be a finite number > 0 \(m\), got nan$"):
        ringdown(SYS, X0, V0, 2.0, 20000.0, "dop853", atol=math.nan)
    assert no_work == []


@pytest.mark.parametrize(
    "fn, wire",
    [
        (lambda: ringdown(SYS, X0, V0, 0.01, 2e4, "exact"), "exact.state_table"),
        (lambda: integrate_exact(SYS, X0, V0, 0.01, 2e4), "exact.state_table"),
        (lambda: ringdown(SYS, X0, V0, 0.01, 2e4, "explicit"), "reduced.transient.explicit.call_numba_kernel"),
        (lambda: ringdown(SYS, X0, V0, 0.01, 2e4, "dop853"), "scipy DOP853"),
        (lambda: Flow(SYS, TABLE)(X0, V0, 1e-3), "reduced.transient.flow.call_numba_kernel"),
        (lambda: spectrogram(np.arange(100) / 1e3, np.sin(np.arange(100.0)), 0.02, 0.5), "spectrogram rfft"),
    ],
)
def test_tripwire_catches_the_work_of_every_integrator(fn, wire, no_work):
    # the refusal tests above can fail: a valid call under the same tripwire reaches the work
    with pytest.raises(WorkStarted, match=wire):
        fn()
    assert no_work == [wire]


def test_good_arguments_of_every_kind_are_accepted(tmp_path):
    # numpy scalars and integers are numbers; a path may be a str or a Path
    r = ringdown(SYS, [0, 0, 0], (0, 0, 200), np.float64(0.002), 20000, "explicit", omega_dt=np.float32(0.05),
                 out=str(tmp_path / "r.npz"), chunk_samples=np.int64(7))
    assert r.n_samples == 41
    r = ringdown(SYS, X0, V0, 0.002, 20000.0, "dop853", rtol=1e-6, atol=np.float64(1e-9))
    assert r.stats["atol"] == 1e-9
