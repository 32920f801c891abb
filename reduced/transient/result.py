"""What the ringdown integrators return: in memory, as a stream of chunks, or on disk.

- :class:`RingdownStream`: the samples of a run as they are computed, chunk by chunk
  (single pass, memory independent of the run length); every integrator produces one.
- :class:`RingdownResult`: the whole run in memory (``res.t``, ``res.x``, ...), collected
  from a stream: the API of short runs.
- :class:`~reduced.transient.store.RingdownFile`: the run streamed into ``ringdown.npz``
  and read back lazily: the API of long runs.

All three offer ``chunks()``, ``energy_balance_error``, ``tolerance`` and ``stats``, so code
that reads a run chunk by chunk (figures, spectrograms, comparisons) works for any of them.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reduced._checks import integer, number
from reduced.models.gaps import GapSystem
from reduced.transient.store import DERIVED, HISTORIES, OPTIONAL, Chunk, NpzStreamWriter, RingdownFile

TIMING_STATS = ("wall_s",)  # wall-clock stats: provenance only, never written into a science file


def zeros_view(N: int) -> np.ndarray:
    """(N,) read-only zeros that take no memory: the work of the loads of a free run.

    Parameters
    ----------
    N : int
        Length.

    Returns
    -------
    (N,) ndarray of float
        A read-only broadcast view of one 0.0.
    """
    return np.broadcast_to(np.float64(0.0), (N,))


@dataclass(eq=False)
class RingdownResult:
    """Free or forced response of a :class:`GapSystem` sampled on a uniform grid.

    Attributes
    ----------
    t : (N,) s
    x, v : (N, n) m and m/s
    dissipated : (N,) J, work done by the damping forces, int_0^t v^T C v dt
    method : name of the integrator
    tolerance : m, the displacement accuracy the method aims at (used to judge when
        symmetric motions have split "by more than the solver tolerance")
    stats : solver diagnostics (n_steps, n_events, wall_s, dt, ...)
    external : (N,) J, work done by the loads, W_ext(t) = int_0^t v^T f_ext dt (read-only
        zeros for a free run)
    loads : the :class:`~reduced.models.loads.Loads` of a forced run, None for a free one
    w : (N, p) m, the friction sliders' positions (None without friction)
    friction : (N,) J, the part of ``dissipated`` done by friction (None without friction)
    events : the event log of an exact run with friction (:class:`reduced.transient.friction.FrictionEvents`),
        or None
    """

    system: GapSystem
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    dissipated: np.ndarray
    method: str
    tolerance: float
    stats: dict = field(default_factory=dict)
    external: np.ndarray | None = None
    loads: object = None
    w: np.ndarray | None = None
    friction: np.ndarray | None = None
    events: object = None

    def __post_init__(self) -> None:
        if self.external is None:
            self.external = zeros_view(self.t.shape[0])

    @property
    def energy(self) -> np.ndarray:
        """J, mechanical energy at each sample (with the tangential springs' with friction)."""
        return self.system.energy(self.x, self.v) if self.w is None else self.system.energy(self.x, self.v, self.w)

    @property
    def energy0(self) -> float:
        """J, energy of the first sample."""
        if not self.t.size:
            return 0.0
        if self.w is None:
            return float(self.system.energy(self.x[0], self.v[0]))
        return float(self.system.energy(self.x[0], self.v[0], self.w[0]))

    @property
    def energy_balance_error(self) -> float:
        """max_t |E(0) + W_ext(t) - W(t) - E(t)| / scale: how well the run keeps the energy balance.

        scale = max(E(0), max_t E(t), max_t |W_ext(t)|) for a forced run (a run from rest is
        not divided by zero), E(0) for a free one (whose energy never exceeds E(0)).
        """
        E = self.energy
        return balance_error(E, self.dissipated, self.external, self.loads is not None)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / float(self.t[1] - self.t[0]) if self.t.size > 1 else float("inf")

    def chunks(self, chunk_samples: int | None = None, start: int = 0, stop: int | None = None) -> Iterator[Chunk]:
        """Views of consecutive samples, as :meth:`RingdownFile.chunks` reads them."""
        from reduced.transient import store

        chunk_samples = integer("chunk_samples", store.READ_CHUNK_SAMPLES if chunk_samples is None else chunk_samples)
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        for i in range(start, stop, chunk_samples):
            j = min(i + chunk_samples, stop)
            yield Chunk(i, self.t[i:j], self.x[i:j], self.v[i:j], self.dissipated[i:j], self.system,
                        external=self.external[i:j], w=None if self.w is None else self.w[i:j],
                        friction=None if self.friction is None else self.friction[i:j])

    def save(self, path: str | Path) -> None:
        """Write t, x, v, energy, dissipated, the tolerance and the stats to an .npz file
        (the format of :mod:`reduced.transient.store`; wall-clock stats are left out)."""
        n, N = self.system.n, self.n_samples
        forced = self.loads is not None
        p = 0 if self.w is None else self.w.shape[1]
        with NpzStreamWriter(path, _history_shapes(N, n, forced, self.system.m, p)) as w:
            summary = _Summary(forced=forced, loads=self.loads)
            for c in self.chunks():
                _write_chunk(w, c, summary)
            w.close(_small_members(self.system, self.method, self.tolerance, summary, self.sample_rate_hz,
                                   self.stats))


class RingdownStream:
    """The samples of one ringdown, produced chunk by chunk as the integrator runs.

    Iterate it once: each item is a :class:`Chunk` (fresh arrays, yours to keep). Memory is
    that of one chunk (``chunk_samples`` samples) and the integrator's state, whatever the
    length of the run. ``tolerance`` and the final ``stats`` (``wall_s``: time spent
    integrating, not in the consumer) are set when the last chunk has been produced.
    The chunking never changes the samples: each integrator carries its full state from
    one chunk to the next (see their docstrings). ``blocks`` yields (start, x, v, W) for a free
    run and (start, x, v, W, W_ext) for a forced one (``loads`` given); a run with friction yields
    (start, x, v, W, W_ext, w, W_friction) (W_ext zeros when free), W all the dissipated work.

    Parameters
    ----------
    system : GapSystem
        The system reported (the chunks compute their energies with it).
    method : str
        Integrator name.
    n_samples : int
        Samples of the whole run.
    sample_rate_hz : float
        Hz.
    chunk_samples : int
        Samples a chunk (the last may be shorter).
    blocks : iterator of tuple
        (start, x, v, W[, W_ext]) of each chunk, as the integrator produces them.
    tolerance : callable
        ``tolerance(max |x|) -> m``, the run's displacement accuracy.
    stats : dict
        The integrator's statistics (completed as the run ends).
    loads : Loads, optional
        The loads of a forced run.
    events : callable, optional
        ``events() -> log``: the integrator's event log once the run is over (friction, exact), or None.

    Attributes
    ----------
    tolerance : float
        m, set once the last chunk has been produced (nan before).
    finished : bool
        The stream has produced its last chunk.
    max_abs_x : float
        m, largest |x| produced so far.
    """

    def __init__(self, system: GapSystem, method: str, n_samples: int, sample_rate_hz: float, chunk_samples: int,
                 blocks: Iterator[tuple[np.ndarray, ...]],
                 tolerance: Callable[[float], float], stats: dict, loads=None,
                 events: Callable[[], object] | None = None) -> None:
        self.system = system
        self.method = method
        self.n_samples = n_samples
        self.sample_rate_hz = sample_rate_hz
        self.chunk_samples = chunk_samples
        self.stats = stats
        self.tolerance = float("nan")
        self.finished = False
        self._blocks = blocks
        self._tolerance = tolerance
        self._used = False
        self.max_abs_x = 0.0
        self.loads = loads
        self._events = events

    @property
    def events(self):
        """The integrator's event log (friction, exact) once the run is over, else None."""
        return self._events() if self._events is not None and self.finished else None

    def __iter__(self) -> Iterator[Chunk]:
        if self._used:
            raise RuntimeError("a RingdownStream can be iterated once; start a new one")
        self._used = True
        wall = 0.0
        t0 = time.perf_counter()
        for start, x, v, W, *ext in self._blocks:
            wall += time.perf_counter() - t0
            if x.size:
                self.max_abs_x = max(self.max_abs_x, float(x.max()), -float(x.min()))  # no |x| array (MBs)
            t = np.arange(start, start + x.shape[0]) / self.sample_rate_hz
            yield Chunk(start, t, x, v, W, self.system, external=ext[0] if ext else zeros_view(x.shape[0]),
                        w=ext[1] if len(ext) > 1 else None, friction=ext[2] if len(ext) > 2 else None)
            t0 = time.perf_counter()
        wall += time.perf_counter() - t0
        self.tolerance = float(self._tolerance(self.max_abs_x))
        self.stats["wall_s"] = wall
        self.finished = True

    def close(self) -> None:
        """Stop the integrator early (the stream ends; ``finished`` stays False)."""
        close = getattr(self._blocks, "close", None)
        if close is not None:
            close()

    def collect(self) -> RingdownResult:
        """The whole run in memory."""
        n, N = self.system.n, self.n_samples
        forced = self.loads is not None
        t = np.arange(N) / self.sample_rate_hz
        x = v = W = Wext = w = Wf = None
        for c in self:
            if c.start == 0 and len(c) == N:  # one chunk: keep its arrays, no copy
                x, v, W = c.x, c.v, c.dissipated
                Wext = c.external if forced else None
                w, Wf = c.w, c.friction
                continue
            if x is None:
                x, v, W = np.empty((N, n)), np.empty((N, n)), np.empty(N)
                Wext = np.empty(N) if forced else None
                if c.w is not None:
                    w, Wf = np.empty((N, c.w.shape[1])), np.empty(N)
            x[c.start : c.start + len(c)] = c.x
            v[c.start : c.start + len(c)] = c.v
            W[c.start : c.start + len(c)] = c.dissipated
            if forced:
                Wext[c.start : c.start + len(c)] = c.external
            if w is not None:
                w[c.start : c.start + len(c)] = c.w
                Wf[c.start : c.start + len(c)] = c.friction
        return RingdownResult(system=self.system, t=t, x=x, v=v, dissipated=W, method=self.method,
                              tolerance=self.tolerance, stats=self.stats, external=Wext, loads=self.loads, w=w,
                              friction=Wf, events=self.events)

    def save(self, path: str | Path) -> RingdownFile:
        """Write the run into an .npz as it is computed; the file, read lazily."""
        n, N = self.system.n, self.n_samples
        forced = self.loads is not None
        summary = _Summary(forced=forced, loads=self.loads)
        with NpzStreamWriter(path, _history_shapes(N, n, forced, self.system.m, self.system.p)) as w:
            for c in self:
                _write_chunk(w, c, summary)
            w.close(_small_members(self.system, self.method, self.tolerance, summary, self.sample_rate_hz,
                                   self.stats))
        f = RingdownFile(path, self.system)
        f.stats = dict(self.stats)  # with the wall time, which the file leaves out
        return f


def balance_error(E: np.ndarray, W: np.ndarray, Wext: np.ndarray, forced: bool) -> float:
    """max_t |E(0) + W_ext - W - E| / scale, scale = max(E(0), max E, max |W_ext|) for a forced run
    and E(0) for a free one (see :attr:`RingdownResult.energy_balance_error`); 0 for a zero scale.

    Parameters
    ----------
    E : (N,) ndarray of float
        J, mechanical energy at each sample.
    W : (N,) ndarray of float
        J, work dissipated by the damping since t = 0.
    Wext : (N,) ndarray of float
        J, work of the loads since t = 0.
    forced : bool
        Scale as for a forced run.

    Returns
    -------
    float
        Relative energy-balance error.
    """
    if not E.size:
        return 0.0
    scale = max(float(E[0]), float(np.max(E)), float(np.max(np.abs(Wext)))) if forced else float(E[0])
    if scale == 0.0:
        return 0.0
    return float(np.max(np.abs(E[0] - E - W + Wext)) / scale)


def _history_shapes(N: int, n: int, forced: bool = False, m: int = 0, p: int = 0) -> dict:
    shapes = {"t": (N,), "x": (N, n), "v": (N, n), "energy": (N,), "dissipated": (N,), "external": (N,),
              "stop_force": (N, m), "a": (N, n)}
    out = {k: (shapes[k], np.float64) for k in (*HISTORIES, *DERIVED) if forced or k not in OPTIONAL}
    if p:  # friction: the sliders' positions and the friction work
        out.update({"w": ((N, p), np.float64), "friction": ((N,), np.float64)})
    return out


@dataclass
class _Summary:
    """Running energy-balance error while chunks are written (see :func:`balance_error`), and the
    loads the accelerations need."""

    forced: bool = False
    E0: float | None = None
    balance: float = 0.0
    scale: float = 0.0
    loads: object = None


def accelerations(system: GapSystem, t: np.ndarray, x: np.ndarray, v: np.ndarray, loads=None,
                  w: np.ndarray | None = None) -> np.ndarray:
    """m/s^2 (or the coordinates' units / s^2), the accelerations the equation of motion gives at samples:
    a = M^-1 (f_ext(t) - C v - K x - B^T f(B x) - Bt^T k_t (Bt x - w)).

    The friction term: a slider's force is k_t (t - w) in every state (sticking: the spring; slipping: the
    spring held on the cone, = +-mu N; open: w = t, 0).

    Parameters
    ----------
    system : GapSystem
        The system run.
    t : (k,) ndarray of float
        s, sample times (for the loads).
    x, v : (k, n) ndarray of float
        m and m/s at those times.
    loads : Loads, optional
        The loads of a forced run.
    w : (k, p) ndarray of float, optional
        m, the friction sliders' positions of a run with friction.

    Returns
    -------
    (k, n) ndarray of float
    """
    rhs = -(v @ system.C + x @ system.K + system.contact_force(x))  # C, K symmetric: v @ C = (C v)^T
    if w is not None and system.friction is not None:
        fr = system.friction
        rhs -= ((x @ fr.Bt.T - w) * fr.k_t) @ fr.Bt
    if loads is not None:
        rhs += loads.force(t)
    # times M^-1 by a product, row by row as the energies are: the same bits whatever the chunking (a
    # multi-right-hand-side solve blocks its columns by their number)
    return rhs @ np.linalg.inv(system.M)  # M symmetric: (M^-1 r)^T = r^T M^-1


def _write_chunk(w: NpzStreamWriter, c: Chunk, s: _Summary) -> None:
    E = c.energy
    if s.E0 is None and len(c):
        s.E0 = float(E[0])
        s.scale = s.E0
    if len(c):
        s.balance = max(s.balance, float(np.max(np.abs(s.E0 - E - c.dissipated + c.external))))
        if s.forced:
            s.scale = max(s.scale, float(np.max(E)), float(np.max(np.abs(c.external))))
    w.append("t", c.t)
    w.append("x", c.x)
    w.append("v", c.v)
    w.append("energy", E)
    w.append("dissipated", c.dissipated)
    if s.forced:
        w.append("external", c.external)
    w.append("stop_force", np.ascontiguousarray(c.system.stop_force(c.x)) if c.system is not None
             else np.zeros((len(c), 0)))
    w.append("a", accelerations(c.system, c.t, c.x, c.v, s.loads, c.w))
    if c.w is not None:
        w.append("w", c.w)
        w.append("friction", c.friction)


def _small_members(system: GapSystem, method: str, tolerance: float, s: _Summary, sample_rate_hz: float,
                   stats: dict) -> dict:
    balance = 0.0 if not s.scale else s.balance / s.scale
    return {"dof_names": np.array(system.dof_names), "stop_names": np.array(system.stop_names, dtype=str),
            "method": method, "tolerance": tolerance,
            "energy_balance_error": balance, "sample_rate_hz": sample_rate_hz,
            **{f"stat_{k}": v for k, v in stats.items() if np.isscalar(v) and k not in TIMING_STATS}}


def sample_count(duration_s: float, sample_rate_hz: float) -> int:
    """Samples on the grid 0, 1/fs, ..., up to duration (inclusive when it falls on the grid).

    Parameters
    ----------
    duration_s : float
        s, > 0.
    sample_rate_hz : float
        Hz, > 0.

    Returns
    -------
    int
        floor(duration_s sample_rate_hz (1 + 1e-12)) + 1.

    Raises
    ------
    InvalidArgument
        A duration or rate that is not a finite number > 0.
    """
    duration_s = number("duration_s", duration_s, lo=0.0, unit="s")
    sample_rate_hz = number("sample_rate_hz", sample_rate_hz, lo=0.0, unit="Hz")
    return int(np.floor(duration_s * sample_rate_hz * (1.0 + 1e-12))) + 1


def sample_times(duration_s: float, sample_rate_hz: float) -> np.ndarray:
    """s, the output grid 0, 1/fs, ..., up to duration (inclusive when it falls on the grid).

    Parameters
    ----------
    duration_s : float
        s, > 0.
    sample_rate_hz : float
        Hz, > 0.

    Returns
    -------
    (N,) ndarray of float
        s, j / sample_rate_hz for j < :func:`sample_count`.

    Raises
    ------
    InvalidArgument
        As :func:`sample_count`.
    """
    return np.arange(sample_count(duration_s, sample_rate_hz)) / sample_rate_hz
