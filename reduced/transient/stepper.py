"""One driver for the three ringdown integrators: each method supplies its step, :func:`stream` does the rest.

In the spirit of SciPy's ``OdeSolver`` (``scipy/integrate/_ivp/base.py``), where each method
implements its step and ``solve_ivp`` drives them all: a method here is a :class:`Stepper` that
sets itself up (tables, matrices, the scheme's first state; in ``__init__``, so a bad case is
refused before any work) and advances (:meth:`Stepper.step`), writing every output sample its
advance passes into the :class:`Buffer` it is handed and returning as soon as that buffer is
full. :func:`stream` does the streaming, sampling and buffering for all three: buffers of
``chunk_samples`` samples on the grid t_j = j / fs, each handed on as a block once full, the
progress calls, the check that every sample was written, and the :class:`RingdownStream`.

The exact and explicit methods sample inside their numba kernels (the closed form at t_j; every
``every``-th step), DOP853 from SciPy's dense output: each method writes its buffer in its own
layout (:meth:`Stepper.arrays`, :meth:`Stepper.block`), the one its kernels fill, so the samples
are the same bits as before the driver was shared. Whatever ``chunk_samples`` is, a stepper
carries its whole state from one buffer to the next, so the samples do not depend on it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.transient.result import RingdownStream, sample_count

FRICTION_STEPPERS: dict[str, type] = {}  # method -> its Stepper for systems with friction (reduced.transient.friction)


class Buffer:
    """Samples j0 .. j0 + k - 1 of a run of N at fs Hz, in the arrays of a stepper's layout.

    ``t`` are their times, ``t_after`` the time of the first sample after them (inf at the end of
    the run), ``filled`` how many are written (a stepper writes them in order).

    Parameters
    ----------
    j0 : int
        Index of its first sample in the run.
    k : int
        Samples it holds.
    n_samples : int
        Samples of the whole run.
    sample_rate_hz : float
        Hz.
    arrays : tuple of ndarray
        Storage in the stepper's layout (:meth:`Stepper.arrays`).

    Attributes
    ----------
    t : (k,) ndarray of float
        s, times of its samples.
    t_after : float
        s, time of the next sample (inf at the end of the run).
    filled : int
        Samples written so far.
    """

    __slots__ = ("j0", "k", "t", "t_after", "arrays", "filled")

    def __init__(self, j0: int, k: int, n_samples: int, sample_rate_hz: float, arrays: tuple) -> None:
        self.j0 = j0
        self.k = k
        self.t = np.arange(j0, j0 + k) / sample_rate_hz
        self.t_after = (j0 + k) / sample_rate_hz if j0 + k < n_samples else np.inf
        self.arrays = arrays
        self.filled = 0

    @property
    def full(self) -> bool:
        return self.filled == self.k


class Stepper(ABC):
    """A ringdown method: its set-up in ``__init__``, its advance in :meth:`step`.

    Parameters
    ----------
    system : the system the stream reports (a method may run on an equivalent one)
    n_samples, sample_rate_hz : the output grid t_j = j / sample_rate_hz, j < n_samples
    loads : None (free run) or the :class:`~reduced.models.loads.Loads` of a forced one
    report : whether progress is reported (a method may then advance in smaller calls)

    A subclass sets ``method`` (its name), fills ``stats`` (solver diagnostics) and sets
    ``finished`` when the run has reached its end.
    """

    method: str = ""
    friction: bool = False  # the method runs systems with friction (reduced.transient.friction)

    def __init__(self, system: GapSystem, n_samples: int, sample_rate_hz: float, loads, report: bool) -> None:
        self.system = system
        self.n = system.n
        self.n_samples = n_samples
        self.sample_rate_hz = sample_rate_hz
        self.loads = loads
        self.forced = loads is not None
        self.report = report
        self.stats: dict = {}
        self.finished = False

    @abstractmethod
    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        """Storage for k samples, in the layout :meth:`step` writes."""

    @abstractmethod
    def block(self, buf: Buffer) -> tuple[np.ndarray, ...]:
        """(x, v, W) of a full buffer, and W_ext for a forced run (views of its arrays)."""

    @abstractmethod
    def step(self, buf: Buffer) -> float | None:
        """Advance, writing samples buf.filled, ... into ``buf``; return once it is full or the run ended.

        Returns the fraction of the run done when there is one to report, else None. Called with
        a full buffer only when it holds the last samples of the run (the run goes on to its end).
        """

    @abstractmethod
    def tolerance(self, amp: float) -> float:
        """m, the displacement accuracy of the run, given the largest |x| seen."""


def run(stepper_class: type[Stepper], system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, options,
        loads=None, progress: Callable[[float], None] | None = None, chunk_samples: int | None = None
        ) -> RingdownStream:
    """The response of ``system`` from (x0, v0) by ``stepper_class`` with its ``options``, as a stream.

    Parameters
    ----------
    stepper_class : the method's :class:`Stepper`, built as
        ``stepper_class(system, x0, v0, duration_s, n_samples, sample_rate_hz, options, loads, report)``
    system : the gap system
    x0, v0 : (n,) m and m/s
    duration_s, sample_rate_hz : s (> 0) and Hz (> 0)
    options : the method's frozen options dataclass; its ``checked(system)`` validates it
    loads : None or a :class:`~reduced.models.loads.Loads` on the system's n coordinates
    progress : None or a callable taking the fraction done
    chunk_samples : samples a block (default: the whole run in one)

    Returns
    -------
    RingdownStream : the samples, computed as the stream is read

    The arguments are checked in this order, before any work: the run's, the loads, the method's
    options, ``progress``, ``chunk_samples``.
    """
    stepper = setup(stepper_class, system, x0, v0, duration_s, sample_rate_hz, options, loads, progress,
                    chunk_samples)
    N = stepper.n_samples
    return stream(stepper, N if chunk_samples is None else _check.integer("chunk_samples", chunk_samples), progress)


def setup(stepper_class: type[Stepper], system: GapSystem, x0, v0, duration_s: float, sample_rate_hz: float, options,
          loads=None, progress: Callable[[float], None] | None = None, chunk_samples: int | None = None) -> Stepper:
    """:func:`run`'s checks and its stepper, set up for the run (the stepper of systems with friction for one),
    not yet stepped: for a caller that drives it itself (:func:`reduced.transient.integrate.ringdown_rows`).

    Parameters
    ----------
    stepper_class, system, x0, v0, duration_s, sample_rate_hz, options, loads, progress, chunk_samples
        As :func:`run` (``progress`` and ``chunk_samples`` only checked).

    Returns
    -------
    Stepper
    """
    n, x0, v0, duration_s, sample_rate_hz = _check.run_args(system, x0, v0, duration_s, sample_rate_hz)
    if system.friction is not None and not stepper_class.friction:
        if stepper_class.method not in FRICTION_STEPPERS:
            raise _check.InvalidArgument(
                f"the system has friction, which the {stepper_class.method!r} method of this module does not "
                "treat: run it with reduced.transient.integrate.ringdown (or import reduced.transient.friction)")
        stepper_class = FRICTION_STEPPERS[stepper_class.method]
    loads = _check.loads(loads, n)
    options = options.checked(system)
    _check.callback("progress", progress)
    N = sample_count(duration_s, sample_rate_hz)
    if chunk_samples is not None:
        _check.integer("chunk_samples", chunk_samples)
    return stepper_class(system, x0, v0, duration_s, N, sample_rate_hz, options, loads, progress is not None)


def stream(stepper: Stepper, chunk_samples: int, progress: Callable[[float], None] | None = None) -> RingdownStream:
    """The run of ``stepper`` as a stream of blocks.

    Parameters
    ----------
    stepper : a method set up for the run (:class:`Stepper`)
    chunk_samples : samples a block (the last may be shorter)
    progress : None or a callable taking the fraction done, called when the stepper reports one

    Returns
    -------
    RingdownStream : the samples, computed as the stream is read (once)
    """
    return RingdownStream(stepper.system, stepper.method, stepper.n_samples, stepper.sample_rate_hz, chunk_samples,
                          _blocks(stepper, chunk_samples, progress), stepper.tolerance, stepper.stats,
                          loads=stepper.loads, events=lambda: getattr(stepper, "events", None))


def _blocks(stepper: Stepper, chunk_samples: int, progress) -> Iterator[tuple]:
    """(start, x, v, W[, W_ext]) of each full buffer, as the stepper fills them."""
    N, fs = stepper.n_samples, stepper.sample_rate_hz

    def new(j0: int) -> Buffer:
        k = min(chunk_samples, N - j0)
        return Buffer(j0, k, N, fs, stepper.arrays(k))

    buf = new(0)
    while not stepper.finished:
        fraction = stepper.step(buf)
        if fraction is not None and progress is not None:
            progress(fraction)
        if buf.full and buf.j0 + buf.k < N:
            yield (buf.j0, *stepper.block(buf))
            buf = new(buf.j0 + buf.k)
    if not buf.full or buf.j0 + buf.k != N:
        raise RuntimeError(f"internal: {N - buf.j0 - buf.filled} {stepper.method} samples not filled")
    yield (buf.j0, *stepper.block(buf))
