"""One entry point for the three ringdown integrators, in memory or streamed to disk.

- :func:`ringdown` returns a :class:`RingdownResult` (short runs, held in memory) or, with
  ``out=path``, writes the run into an .npz as it is computed and returns a
  :class:`~reduced.transient.store.RingdownFile` read lazily (long runs: memory
  independent of the duration);
- :func:`ringdown_stream` gives the run as a :class:`RingdownStream` of chunks, for
  analyses that need no file (two runs compared sample by sample);
- :func:`ringdown_rows` gives a run's whole state at every ``every``-th sample and chosen
  rows of it at every sample (a DAQ's channels computed at an oversampled rate: the exact
  integrator then evaluates the rows alone between the whole states);
- :func:`ringdown_peak_bytes` and :func:`ringdown_disk_bytes` say beforehand what a run
  will allocate and write, so a caller can refuse it before any work.

Each method is a :class:`~reduced.transient.stepper.Stepper` (``STEPPERS``) with a frozen options
dataclass (:func:`method_options` builds it from the keywords of :func:`ringdown`), run by the one
driver :func:`reduced.transient.stepper.run`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.transient import friction as _friction  # noqa: F401 (registers the steppers of systems with friction)
from reduced.transient import stepper as _stepper
from reduced.transient.dop853 import Dop853Options, Dop853Stepper
from reduced.transient.exact import ExactIntegratorError, ExactOptions, ExactStepper
from reduced.transient.explicit import DEFAULT_OMEGA_DT, ExplicitOptions, ExplicitStepper
from reduced.transient.methods import METHODS
from reduced.transient.result import RingdownResult, RingdownStream, sample_count
from reduced.transient.store import RingdownFile, npz_disk_bytes

STEPPERS = {"exact": ExactStepper, "explicit": ExplicitStepper, "dop853": Dop853Stepper}
FLOAT = 8  # bytes
CHUNK_BYTES = 8 * 2**20  # bytes of samples (t, x, v, W) in one chunk of a streamed run
MIN_CHUNK_SAMPLES = 1024
IN_MEMORY_MAX_BYTES = 4 * 2**30  # default cap of an in-memory ringdown; beyond it, stream with out=
# Peak = fixed + per-sample bytes x samples held. Measured with tracemalloc
# (tests/test_long_ringdown.py) and rounded up: besides the samples (t, x, v, W: 2n + 2 floats)
# the energy E(x, v) of a chunk makes temporaries of about 3 m + 6 floats a sample (penetration,
# its square, the kinetic and elastic terms, E0 - E - W), and a stream holds two chunks at once
# (the consumer's and the one being filled).
ENERGY_TEMPORARIES = (3, 6)  # floats a sample: 3 x stops + 6
STREAM_CHUNKS_HELD = 2
FIXED_BYTES = 2 * 2**20  # imports aside: kernels' scratch, the DOP853 stages, the writer


def default_chunk_samples(n_dofs: int) -> int:
    """Samples in a chunk of a streamed run of ``n_dofs`` DOFs: ``CHUNK_BYTES`` of t, x, v, W.

    Parameters
    ----------
    n_dofs : int
        DOFs of the model, >= 1.

    Returns
    -------
    int
        max(``MIN_CHUNK_SAMPLES``, ``CHUNK_BYTES`` // (8 (2 n + 2))).

    Raises
    ------
    InvalidArgument
        n_dofs not an integer >= 1.
    """
    n_dofs = _check.integer("n_dofs", n_dofs)
    return max(MIN_CHUNK_SAMPLES, CHUNK_BYTES // (FLOAT * (2 * n_dofs + 2)))  # the module's value at call time


def ringdown_peak_bytes(n_dofs: int, duration_s: float, sample_rate_hz: float, method: str = "exact", *,
                        n_stops: int = 4, streamed: bool = True, chunk_samples: int | None = None,
                        forced: bool = False) -> int:
    """Bytes a ringdown allocates at its peak (an upper estimate; the interpreter, NumPy, SciPy
    and numba themselves, about 200 MB, are not counted).

    peak = FIXED + bytes_per_sample x samples_held + state tables, with
    bytes_per_sample = 8 (2 n + 2 + 3 m + 6) (the samples t, x, v, W and the temporaries of
    their energy), samples_held = N = floor(duration_s sample_rate_hz) + 1 in memory, or two
    chunks (``chunk_samples``, default :func:`default_chunk_samples`) when ``streamed``
    (``ringdown(..., out=path)``); the exact method adds its state table,
    3 x 2^m (2n)^2 complex numbers. ``n_stops`` is m (4 for two two-sided tips). A ``forced``
    run (``loads``) holds one float more a sample: the work of the loads.

    Parameters
    ----------
    n_dofs : int
        n.
    duration_s : float
        s.
    sample_rate_hz : float
        Hz.
    method : {'exact', 'explicit', 'dop853'}
        The integrator (the explicit and DOP853 ones count 4 n^2 floats of matrices instead of the
        state table).
    n_stops : int
        m, in [0, 16].
    streamed : bool
        Two chunks held rather than the whole run.
    chunk_samples : int, optional
        Samples a chunk when streamed.
    forced : bool
        The run has loads.

    Returns
    -------
    int
        bytes.

    Raises
    ------
    InvalidArgument
        An argument out of range (a run without samples included).
    """
    n = _check.integer("n_dofs", n_dofs)
    N = sample_count(duration_s, sample_rate_hz)
    method = _check.choice("method", method, METHODS)
    m = _check.integer("n_stops", n_stops, lo=0, hi=16)
    streamed = _check.flag("streamed", streamed)
    forced = _check.flag("forced", forced)
    # the accelerations and stop forces written with a chunk are temporaries of the chunk being written,
    # fewer than the two chunks' energy temporaries counted here (measured: 25.6 MiB traced for 14 s
    # of the 3-DOF model at 20 kHz, streamed, against 56 MiB estimated)
    per_sample = FLOAT * (2 * n + 2 + int(forced) + ENERGY_TEMPORARIES[0] * m + ENERGY_TEMPORARIES[1])
    if streamed:
        k = default_chunk_samples(n) if chunk_samples is None else _check.integer("chunk_samples", chunk_samples)
        held = STREAM_CHUNKS_HELD * min(k, N)
    else:
        held = N
    table = 3 * 2**m * (2 * n) ** 2 * 16 if method == "exact" else 4 * n * n * FLOAT
    return int(FIXED_BYTES + table + per_sample * held)


def ringdown_disk_bytes(n_dofs: int, duration_s: float, sample_rate_hz: float, *, forced: bool = False,
                        n_stops: int = 4) -> int:
    """Bytes of ``ringdown.npz`` for a run: 8 (3 n + m + 3) N (t, x, v, energy, dissipated, the stop
    forces and the accelerations, stored uncompressed, see :mod:`reduced.transient.store`; 8 N more for
    ``external`` in a ``forced`` run) plus about 5 kB of headers and small members.

    Parameters
    ----------
    n_dofs : int
        n.
    duration_s : float
        s.
    sample_rate_hz : float
        Hz.
    forced : bool
        The run has loads (``external`` is stored).
    n_stops : int
        m, the system's stops (the tips' two-sided clearances: 4).

    Returns
    -------
    int
        bytes (:func:`reduced.transient.store.npz_disk_bytes`).

    Raises
    ------
    InvalidArgument
        An argument out of range.
    """
    n = _check.integer("n_dofs", n_dofs)
    N = sample_count(duration_s, sample_rate_hz)
    forced = _check.flag("forced", forced)
    m = _check.integer("n_stops", n_stops, lo=0, hi=16)
    shapes = {"t": (N,), "x": (N, n), "v": (N, n), "energy": (N,), "dissipated": (N,)}
    if forced:
        shapes["external"] = (N,)
    shapes.update({"stop_force": (N, m), "a": (N, n)})
    return npz_disk_bytes(shapes)


def method_options(method: str, *, dt: float | None = None, omega_dt: float | None = None, step_basis: str = "top",
                   rtol: float = 1e-10, atol: float | None = None) -> ExactOptions | ExplicitOptions | Dop853Options:
    """The options dataclass of ``method`` from the keywords of :func:`ringdown`.

    Parameters
    ----------
    method : "exact", "explicit" or "dop853" (checked by the caller)
    dt, omega_dt, step_basis : the explicit method's step (omega_dt None: ``DEFAULT_OMEGA_DT``)
    rtol, atol : DOP853's tolerances

    Returns
    -------
    ExactOptions, ExplicitOptions or Dop853Options : validated when the run starts
        (:func:`reduced.transient.stepper.run`); the options of the other methods are checked here,
        so a typo is not ignored.
    """
    if method != "explicit":
        if dt is not None:
            _check.positive("dt", dt, "s")
        if omega_dt is not None:
            _check.positive("omega_dt", omega_dt, "rad")
        _check.choice("step_basis", step_basis, ("top", "contact"))
    if method != "dop853":
        _check.number("rtol", rtol, lo=0.0, hi=1.0)
        if atol is not None:
            _check.positive("atol", atol, "m")
    if method == "explicit":
        return ExplicitOptions(dt, DEFAULT_OMEGA_DT if omega_dt is None else omega_dt, step_basis)
    if method == "dop853":
        return Dop853Options(rtol, atol)
    return ExactOptions()


def ringdown_stream(
    system: GapSystem,
    x0,
    v0,
    duration_s: float,
    sample_rate_hz: float,
    method: str = "exact",
    *,
    dt: float | None = None,
    omega_dt: float | None = None,
    step_basis: str = "top",
    rtol: float = 1e-10,
    atol: float | None = None,
    loads=None,
    progress=None,
    chunk_samples: int | None = None,
) -> RingdownStream:
    """The response of ``system`` from (x0, v0) by ``method``, as chunks.

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz, method : as :func:`ringdown`
    dt, omega_dt, step_basis, rtol, atol, loads, progress : as :func:`ringdown`
    chunk_samples : samples a chunk (default :func:`default_chunk_samples`)

    Returns
    -------
    RingdownStream : the run, computed as it is read (iterate it once)
    """
    method = _check.choice("method", method, METHODS)
    _check.gap_system(system)
    loads = _check.loads(loads, system.n)
    if chunk_samples is None:
        chunk_samples = default_chunk_samples(system.n)
    chunk_samples = _check.integer("chunk_samples", chunk_samples)
    options = method_options(method, dt=dt, omega_dt=omega_dt, step_basis=step_basis, rtol=rtol, atol=atol)
    return _stepper.run(STEPPERS[method], system, x0, v0, duration_s, sample_rate_hz, options, loads, progress,
                        chunk_samples)


def ringdown(
    system: GapSystem,
    x0,
    v0,
    duration_s: float,
    sample_rate_hz: float,
    method: str = "exact",
    *,
    dt: float | None = None,
    omega_dt: float | None = None,
    step_basis: str = "top",
    rtol: float = 1e-10,
    atol: float | None = None,
    loads=None,
    progress=None,
    out: str | Path | None = None,
    chunk_samples: int | None = None,
    max_memory_bytes: float = IN_MEMORY_MAX_BYTES,
) -> RingdownResult | RingdownFile:
    """Response of ``system`` from (x0, v0) by ``method`` (exact | explicit | dop853), free or forced.

    M x'' + C x' + K x + B^T f(B x) = f_ext(t) = sum_l b_l p_l(t), zero without ``loads``.

    Parameters
    ----------
    system : the gap system
    x0, v0 : (n,) m and m/s
    duration_s : s (> 0)
    sample_rate_hz : Hz (> 0), output grid t_k = k / sample_rate_hz
    method : "exact", "explicit" or "dop853" (:data:`reduced.transient.methods.METHODS`)
    dt, omega_dt, step_basis : explicit step (:func:`~reduced.transient.explicit.integrate_explicit`)
    rtol, atol : DOP853 tolerances, rtol in (0, 1), atol > 0 m
    loads : None (free response) or a :class:`~reduced.models.loads.Loads` on the system's n
        coordinates; the work of the loads, int_0^t v^T f_ext dt, is the result's ``external``
        and enters ``energy_balance_error``
    progress : None or a callable taking the fraction done
    out : None: the run is returned in memory (:class:`RingdownResult`), refused when
        :func:`ringdown_peak_bytes` exceeds ``max_memory_bytes``; a path: the run is written
        there as an .npz while it is computed (memory independent of the duration) and
        returned as a :class:`~reduced.transient.store.RingdownFile`
    chunk_samples : samples a chunk when streaming (default :func:`default_chunk_samples`);
        it never changes the samples, only the memory
    max_memory_bytes : bytes, the largest peak allowed a run held in memory (``out`` None)

    Returns
    -------
    RingdownResult or RingdownFile : in memory, or the file written

    Every argument is checked before any work (a ValueError naming it).
    """
    method = _check.choice("method", method, METHODS)
    _check.gap_system(system)
    loads = _check.loads(loads, system.n)
    N = sample_count(duration_s, sample_rate_hz)
    if chunk_samples is not None:
        chunk_samples = _check.integer("chunk_samples", chunk_samples)
    if out is None:
        max_memory_bytes = _check.positive("max_memory_bytes", max_memory_bytes)
        need = ringdown_peak_bytes(system.n, duration_s, sample_rate_hz, method, n_stops=min(system.m, 16),
                                   streamed=False, forced=loads is not None)
        if need > max_memory_bytes:
            raise _check.InvalidArgument(
                f"duration_s x sample_rate_hz = {N:.3g} samples: held in memory the ringdown needs "
                f"{need / 2**30:.3g} GiB, more than max_memory_bytes = {max_memory_bytes / 2**30:.3g} GiB; "
                "pass out='ringdown.npz' to stream it to disk, or lower duration_s or sample_rate_hz")
    elif not isinstance(out, (str, Path)) or not str(out):
        raise _check.InvalidArgument(f"out must be None or a file path, got {_check.show(out)}")
    else:
        parent = Path(out).parent
        if not parent.is_dir():
            raise _check.InvalidArgument(f"out must be a path in an existing folder, got {_check.show(str(out))}")
    stream = ringdown_stream(system, x0, v0, duration_s, sample_rate_hz, method, dt=dt, omega_dt=omega_dt,
                             step_basis=step_basis, rtol=rtol, atol=atol, loads=loads, progress=progress,
                             chunk_samples=N if out is None else chunk_samples)
    if out is None:
        return stream.collect()
    return stream.save(out)


def ringdown_rows(
    system: GapSystem,
    x0,
    v0,
    duration_s: float,
    sample_rate_hz: float,
    rows,
    every: int,
    method: str = "exact",
    *,
    loads=None,
    **options,
) -> tuple[RingdownResult, np.ndarray]:
    """The run of :func:`ringdown` held whole at every ``every``-th sample, and ``rows`` of its state at every sample.

    The exact method samples the rows alone between the whole states (:meth:`reduced.transient.exact.ExactStepper.
    sample_rows`: R U w e^{lam tau}, r products a term instead of the state's 2n and the work's K): a DAQ's
    channels, linear in the state, at an oversampled rate cost little more than the record at its own rate.
    The samples held whole are the same bits as :func:`ringdown`'s at those times; the rows are R y to round-off
    (summed over the terms instead of over y). The other methods run :func:`ringdown` and take R y of every sample.

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz, method, loads : as :func:`ringdown` (the rate of the rows)
    rows : (r, N) array_like of float
        R, on the state y = [x; v] (N = 2n), or [x; v; w] with friction (N = 2n + p, w the sliders' positions).
    every : int
        >= 1: the state is held at the samples j = 0, every, 2 every, ... of the N samples of the run.
    **options : the method's options of :func:`ringdown` (dt, omega_dt, step_basis, rtol, atol)

    Returns
    -------
    (RingdownResult, (N_samples, r) ndarray)
        The run at t = j / sample_rate_hz for j = 0, every, ... (its ``energy_balance_error`` over those
        samples), and R y at every sample.

    Raises
    ------
    InvalidArgument
        An argument out of range (as :func:`ringdown`; ``rows`` not (r, N) finite, ``every`` not >= 1).
    """
    method = _check.choice("method", method, METHODS)
    _check.gap_system(system)
    loads = _check.loads(loads, system.n)
    every = _check.integer("every", every, lo=1)
    R = np.asarray(rows, dtype=float)
    N_state = 2 * system.n + system.p
    if R.ndim != 2 or R.shape[1] != N_state or not np.all(np.isfinite(R)):
        raise _check.InvalidArgument(f"rows must be a finite (r, {N_state}) array on the state [x; v"
                                     f"{'; w' if system.p else ''}], got shape {R.shape}")
    opts = method_options(method, **options)
    if method != "exact":
        res = ringdown(system, x0, v0, duration_s, sample_rate_hz, method, loads=loads, **options)
        y = np.hstack([res.x, res.v] + ([res.w] if res.w is not None else []))
        return _kept(res, every), y @ R.T
    stepper = _stepper.setup(STEPPERS[method], system, x0, v0, duration_s, sample_rate_hz, opts, loads)
    stepper.sample_rows(every, R)
    N = stepper.n_samples
    buf = _stepper.Buffer(0, N, N, sample_rate_hz, stepper.arrays(N))
    t0 = time.perf_counter()
    while not stepper.finished:
        stepper.step(buf)
    if not buf.full:
        raise RuntimeError(f"internal: {N - buf.filled} exact samples not filled")
    stepper.stats["wall_s"] = time.perf_counter() - t0
    keep = slice(0, N, every)
    n, fr = system.n, system.friction is not None
    y, W, z = buf.arrays[0][keep], buf.arrays[1][keep], buf.arrays[-1]
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
        raise ExactIntegratorError("non-finite state: the contact states are ill-conditioned")
    Wf = buf.arrays[2][keep] if fr else None
    Wext = buf.arrays[3 if fr else 2][keep] if loads is not None else None
    x = y[:, :n]
    res = RingdownResult(system=system, t=np.arange(0, N, every) / sample_rate_hz, x=x, v=y[:, n:2 * n], dissipated=W,
                         method=method, tolerance=float(stepper.tolerance(float(np.max(np.abs(x), initial=0.0)))),
                         stats=stepper.stats, external=Wext, loads=loads, w=y[:, 2 * n:] if fr else None, friction=Wf,
                         events=getattr(stepper, "events", None))
    return res, z


def _kept(res: RingdownResult, every: int) -> RingdownResult:
    """``res`` at its samples 0, every, 2 every, ..."""
    k = slice(0, None, every)
    return RingdownResult(system=res.system, t=res.t[k], x=res.x[k], v=res.v[k], dissipated=res.dissipated[k],
                          method=res.method, tolerance=res.tolerance, stats=res.stats,
                          external=res.external[k] if res.loads is not None else None, loads=res.loads,
                          w=None if res.w is None else res.w[k],
                          friction=None if res.friction is None else res.friction[k], events=res.events)
