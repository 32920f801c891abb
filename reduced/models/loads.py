"""External loads on a gap system: f_ext(t) = sum_l b_l p_l(t).

A load is a force time function p_l(t) [N] applied along a vector b_l (n,) on the
model's coordinates, so the equation of motion becomes

    M x'' + C x' + K x + B^T f(B x) = sum_l b_l p_l(t).

For a force at a point whose displacement is ``r^T x`` (a row of the model's
``point_rows``), the virtual work p r^T dx gives b = r.

Three time functions, each zero before ``start_s``:

- :class:`HalfSine` (a hammer blow): p = P sin(pi (t - t0) / d) on [t0, t0 + d], zero after;
- :class:`Harmonic` (a shaker): p = A cos(Omega (t - t0) + phi) for t >= t0;
- :class:`Tabulated` (a measured force): piecewise linear between samples (t_k, p_k), zero
  outside [t_0, t_K).

Every p is right-continuous: at a breakpoint it takes the value of the piece that starts there.

Between two consecutive *breakpoints* (a start, an end, a tabulated sample) every load is
one smooth piece of the form

    p(t_a + s) = Re(F e^{i Omega s}) + p0 + p1 s,      0 <= s < t_b - t_a,

(:meth:`Signal.piece`), which has a closed-form particular solution in every linear
contact state: that is what keeps the exact integrator exact under forcing.
:meth:`Loads.piece_table` lays the pieces of all loads on one merged breakpoint grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LOAD_KINDS = ("half_sine", "harmonic", "tabulated")
MAX_TABLE_SAMPLES = 10_000_000  # a measured force history longer than this is refused


class LoadError(ValueError):
    """A load that cannot be used; the message is one line naming the field."""


def _finite(name: str, v, *, lo: float | None = None, lo_open: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise LoadError(f"{name} must be a finite number, got {v!r}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise LoadError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class Piece:
    """p(t_a + s) = Re(F e^{i omega s}) + p0 + p1 s on one interval between breakpoints.

    Parameters
    ----------
    F : complex
        N, complex amplitude of the harmonic term at s = 0.
    omega : float
        rad/s, its frequency (0: none).
    p0 : float
        N, constant term.
    p1 : float
        N/s, slope.
    """

    F: complex = 0.0j  # N
    omega: float = 0.0  # rad/s
    p0: float = 0.0  # N
    p1: float = 0.0  # N/s


ZERO = Piece()


@dataclass(frozen=True)
class HalfSine:
    """A hammer blow: p = peak sin(pi (t - start) / duration) on [start, start + duration].

    Parameters
    ----------
    peak_N : float
        N, P, finite (either sign).
    duration_s : float
        s, d > 0.
    start_s : float
        s, t0 >= 0.

    Raises
    ------
    LoadError
        A value that is not a finite number, or outside its range.
    """

    peak_N: float
    duration_s: float
    start_s: float = 0.0
    kind = "half_sine"

    def __post_init__(self) -> None:
        _finite("peak_N", self.peak_N)
        _finite("duration_s", self.duration_s, lo=0.0, lo_open=True)
        _finite("start_s", self.start_s, lo=0.0)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    @property
    def omega(self) -> float:
        return math.pi / self.duration_s

    def breakpoints(self) -> np.ndarray:
        return np.array([self.start_s, self.end_s])

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        on = (t >= self.start_s) & (t < self.end_s)
        return np.where(on, self.peak_N * np.sin(self.omega * (t - self.start_s)), 0.0)

    def piece(self, t: float) -> Piece:
        if not self.start_s <= t < self.end_s:
            return ZERO
        # P sin(w (t - t0 + s)) = Re(-i P e^{i w (t - t0)} e^{i w s})
        return Piece(F=-1j * self.peak_N * np.exp(1j * self.omega * (t - self.start_s)), omega=self.omega)

    def pieces(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(F, omega, p0, p1) of :meth:`piece` at every time of ``ts`` at once."""
        ts = np.asarray(ts, float)
        on = (ts >= self.start_s) & (ts < self.end_s)
        F = np.where(on, -1j * self.peak_N * np.exp(1j * self.omega * np.where(on, ts - self.start_s, 0.0)), 0.0)
        return F, np.where(on, self.omega, 0.0), np.zeros(ts.shape), np.zeros(ts.shape)

    def work_scale(self) -> float:
        """N, the largest |p|."""
        return abs(self.peak_N)


@dataclass(frozen=True)
class Harmonic:
    """A shaker: p = amplitude cos(2 pi freq (t - start) + phase) for t >= start.

    Parameters
    ----------
    amplitude_N : float
        N, A, finite (either sign).
    freq_hz : float
        Hz, Omega / (2 pi), > 0.
    phase_deg : float
        degrees, phi.
    start_s : float
        s, t0 >= 0.

    Raises
    ------
    LoadError
        A value that is not a finite number, or outside its range.
    """

    amplitude_N: float
    freq_hz: float
    phase_deg: float = 0.0
    start_s: float = 0.0
    kind = "harmonic"

    def __post_init__(self) -> None:
        _finite("amplitude_N", self.amplitude_N)
        _finite("freq_hz", self.freq_hz, lo=0.0, lo_open=True)
        _finite("phase_deg", self.phase_deg)
        _finite("start_s", self.start_s, lo=0.0)

    @property
    def omega(self) -> float:
        return 2.0 * math.pi * self.freq_hz

    @property
    def end_s(self) -> float:
        return math.inf

    def breakpoints(self) -> np.ndarray:
        return np.array([self.start_s])

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        phase = math.radians(self.phase_deg)
        return np.where(t >= self.start_s, self.amplitude_N * np.cos(self.omega * (t - self.start_s) + phase), 0.0)

    def piece(self, t: float) -> Piece:
        if t < self.start_s:
            return ZERO
        phase = math.radians(self.phase_deg)
        return Piece(F=self.amplitude_N * np.exp(1j * (self.omega * (t - self.start_s) + phase)), omega=self.omega)

    def pieces(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(F, omega, p0, p1) of :meth:`piece` at every time of ``ts`` at once."""
        ts = np.asarray(ts, float)
        on = ts >= self.start_s
        phase = math.radians(self.phase_deg)
        F = np.where(on, self.amplitude_N * np.exp(1j * (self.omega * np.where(on, ts - self.start_s, 0.0) + phase)),
                     0.0)
        return F, np.where(on, self.omega, 0.0), np.zeros(ts.shape), np.zeros(ts.shape)

    def work_scale(self) -> float:
        return abs(self.amplitude_N)


@dataclass(frozen=True, eq=False)
class Tabulated:
    """A measured force: piecewise linear through (t_s[k], force_N[k]), zero outside.

    Parameters
    ----------
    t_s : (K,) array_like of float
        s, sample times, >= 0 and strictly increasing, 2 to ``MAX_TABLE_SAMPLES`` of them.
    force_N : (K,) array_like of float
        N, the force at each time.
    source : str
        The file it was read from, for messages and provenance.

    Raises
    ------
    LoadError
        Columns of unequal length or not 1-D, too few or too many samples, non-finite values, or
        times that do not increase strictly from >= 0.
    """

    t_s: np.ndarray
    force_N: np.ndarray
    source: str = ""  # the file it was read from, for messages and provenance
    kind = "tabulated"

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, float)
        p = np.asarray(self.force_N, float)
        where = f" ({self.source})" if self.source else ""
        if t.ndim != 1 or t.shape != p.shape:
            raise LoadError(f"times and forces must be two columns of equal length{where}")
        if t.size < 2:
            raise LoadError(f"a tabulated load needs at least 2 samples, got {t.size}{where}")
        if t.size > MAX_TABLE_SAMPLES:
            raise LoadError(f"{t.size} samples is too many (at most {MAX_TABLE_SAMPLES}){where}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
            raise LoadError(f"times and forces must be finite numbers{where}")
        bad = np.flatnonzero(np.diff(t) <= 0.0)
        if bad.size:
            k = int(bad[0])
            raise LoadError(f"times must increase strictly: t[{k + 1}] = {t[k + 1]!r} s after "
                            f"t[{k}] = {t[k]!r} s{where}")
        if t[0] < 0.0:
            raise LoadError(f"times must be >= 0 s, got t[0] = {t[0]!r}{where}")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "force_N", p)

    @property
    def start_s(self) -> float:
        return float(self.t_s[0])

    @property
    def end_s(self) -> float:
        return float(self.t_s[-1])

    def breakpoints(self) -> np.ndarray:
        return self.t_s

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        return np.where(t < self.t_s[-1], np.interp(t, self.t_s, self.force_N, left=0.0, right=0.0), 0.0)

    def piece(self, t: float) -> Piece:
        if not self.t_s[0] <= t < self.t_s[-1]:
            return ZERO
        k = int(np.searchsorted(self.t_s, t, side="right")) - 1
        slope = (self.force_N[k + 1] - self.force_N[k]) / (self.t_s[k + 1] - self.t_s[k])
        return Piece(p0=float(self.force_N[k] + slope * (t - self.t_s[k])), p1=float(slope))

    def pieces(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(F, omega, p0, p1) of :meth:`piece` at every time of ``ts`` at once."""
        ts = np.asarray(ts, float)
        on = (ts >= self.t_s[0]) & (ts < self.t_s[-1])
        k = np.clip(np.searchsorted(self.t_s, ts, side="right") - 1, 0, self.t_s.size - 2)
        slope = (self.force_N[k + 1] - self.force_N[k]) / (self.t_s[k + 1] - self.t_s[k])
        p0 = self.force_N[k] + slope * (ts - self.t_s[k])
        zero = np.zeros(ts.shape)
        return zero.astype(complex), zero, np.where(on, p0, 0.0), np.where(on, slope, 0.0)

    def work_scale(self) -> float:
        return float(np.max(np.abs(self.force_N)))

    @classmethod
    def from_file(cls, path: str | Path) -> Tabulated:
        """Read a force history: a CSV of time [s], force [N] (a header line is skipped) or a UFF 58 record."""
        t, p = read_force_history(path)
        return cls(t, p, source=str(path))


Signal = HalfSine | Harmonic | Tabulated


def read_force_history(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], p [N]) from a CSV (two columns, optional header) or a UFF file with a 58 record.

    A UFF file must have exactly one 58 record whose ordinate is an excitation force (specific
    data type 13), taken beside any reaction forces (9), or else exactly one force record of
    either type.

    Parameters
    ----------
    path : str or Path
        A ``.uff`` / ``.unv`` universal file, or a text file: two numbers a line separated by a
        comma, semicolon, tab or spaces; blank lines, ``#`` comments and header lines before the
        first sample are skipped.

    Returns
    -------
    t : (K,) ndarray of float
        s, sample times (checked by :class:`Tabulated`, not here).
    p : (K,) ndarray of float
        N, the force.

    Raises
    ------
    LoadError
        No such file, unreadable text, a line after the first sample that is not two numbers,
        no samples; for a UFF file: a record refused by :func:`fem.uff.read_uff58`, or not
        exactly one force record (one excitation force, type 13, is taken among reaction-force
        records of type 9).
    """
    path = Path(path)
    if not path.is_file():
        raise LoadError(f"file: no such file {str(path)!r}")
    if path.suffix.lower() in (".uff", ".unv"):
        return _read_uff58_force(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LoadError(f"file: cannot read {str(path)!r} as text ({exc})") from None
    rows = []
    for i, line in enumerate(text.splitlines()):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = [s for s in line.replace(";", ",").replace("\t", ",").split(",")]
        if len(parts) == 1:
            parts = line.split()
        try:
            vals = [float(s) for s in parts if s.strip() != ""]
        except ValueError:
            if not rows:
                continue  # a header line
            raise LoadError(f"file {str(path)!r} line {i + 1}: not two numbers: {line[:60]!r}") from None
        if len(vals) != 2:
            raise LoadError(f"file {str(path)!r} line {i + 1}: expected two columns (time, force), "
                            f"got {len(vals)}")
        rows.append(vals)
    if not rows:
        raise LoadError(f"file {str(path)!r}: no samples (expected two columns: time [s], force [N])")
    a = np.asarray(rows)
    return a[:, 0], a[:, 1]


def _read_uff58_force(path: Path) -> tuple[np.ndarray, np.ndarray]:
    from fem.uff import UffError, read_uff58

    try:
        channels = read_uff58(path)
    except UffError as exc:
        raise LoadError(f"file {exc}") from None
    forces = [c for c in channels if c.quantity in ("force", "reaction_force")]
    excitation = [c for c in forces if c.quantity == "force"]
    if len(excitation) == 1:
        forces = excitation  # the hammer or shaker force among load-cell records
    if len(forces) != 1:
        raise LoadError(f"file {str(path)!r}: {len(channels)} UFF 58 records and {len(forces)} of them are "
                        "forces (ordinate type 13 or 9); keep exactly one force record")
    return forces[0].t, forces[0].data


@dataclass(frozen=True, eq=False)
class Loads:
    """Several loads on one model: f_ext(t) = sum_l b[l] p_l(t).

    Attributes
    ----------
    b : (L, n) force directions on the model's coordinates
    signals : the L time functions
    points : name of the point each load acts at (for messages and plots)
    """

    b: np.ndarray
    signals: tuple
    points: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        b = np.atleast_2d(np.asarray(self.b, float))
        if b.shape[0] != len(self.signals):
            raise LoadError(f"b has {b.shape[0]} rows for {len(self.signals)} loads")
        if not np.all(np.isfinite(b)):
            raise LoadError("load directions b must be finite")
        object.__setattr__(self, "b", b)
        if not self.points:
            object.__setattr__(self, "points", tuple(f"load{l}" for l in range(len(self.signals))))

    @property
    def n_loads(self) -> int:
        return len(self.signals)

    @property
    def n(self) -> int:
        return self.b.shape[1]

    def values(self, t) -> np.ndarray:
        """(..., L) N, p_l(t)."""
        t = np.asarray(t, float)
        return np.stack([s(t) for s in self.signals], axis=-1)

    def force(self, t) -> np.ndarray:
        """(..., n) N, f_ext(t) = sum_l b_l p_l(t)."""
        return self.values(t) @ self.b

    def power(self, t, v) -> np.ndarray:
        """W, v^T f_ext(t) for v of shape (..., n)."""
        return np.einsum("...i,...i->...", np.asarray(v), self.force(t))

    def start_s(self) -> float:
        return min(s.start_s for s in self.signals)

    def breakpoints(self, t_end: float) -> np.ndarray:
        """Sorted distinct breakpoints of every load in (0, t_end)."""
        if not self.signals:
            return np.zeros(0)
        bp = np.unique(np.concatenate([s.breakpoints() for s in self.signals]))
        return bp[(bp > 0.0) & (bp < t_end)]

    def piece_table(self, t_end: float) -> PieceTable:
        """Every load's piece on the merged breakpoint grid of [0, t_end]."""
        starts = np.concatenate([[0.0], self.breakpoints(t_end)])
        P, L = starts.size, self.n_loads
        F = np.zeros((P, L), complex)
        omega = np.zeros((P, L))
        p0 = np.zeros((P, L))
        p1 = np.zeros((P, L))
        for i, ta in enumerate(starts):
            for l, s in enumerate(self.signals):
                pc = s.piece(float(ta))
                F[i, l], omega[i, l], p0[i, l], p1[i, l] = pc.F, pc.omega, pc.p0, pc.p1
        return PieceTable(starts, F, omega, p0, p1)

    def max_abs(self) -> float:
        """N, the largest |p_l| of any load."""
        return max((s.work_scale() for s in self.signals), default=0.0)

    def omegas(self) -> np.ndarray:
        """(L,) rad/s, the frequency of each load's harmonic term Re(F e^{i omega s}) (0: none)."""
        return np.array([float(getattr(s, "omega", 0.0)) for s in self.signals])

    def pieces_at(self, starts) -> PieceTable:
        """The pieces that start at the times ``starts`` (increasing; each a breakpoint or the
        start of a run), vectorized: what :meth:`piece_table` builds on its grid, for any grid
        (a window [t_a, t_b) of a long run: ``starts = [t_a, *breakpoints in (t_a, t_b)]``)."""
        starts = np.atleast_1d(np.asarray(starts, float))
        P, L = starts.size, self.n_loads
        F = np.zeros((P, L), complex)
        omega = np.zeros((P, L))
        p0 = np.zeros((P, L))
        p1 = np.zeros((P, L))
        for l, s in enumerate(self.signals):
            F[:, l], omega[:, l], p0[:, l], p1[:, l] = s.pieces(starts)
        return PieceTable(starts, F, omega, p0, p1)


@dataclass(frozen=True, eq=False)
class PieceTable:
    """Piece i holds on [starts[i], starts[i+1]) (the last one to the end of the run):
    p_l(starts[i] + s) = Re(F[i, l] e^{i omega[i, l] s}) + p0[i, l] + p1[i, l] s.

    Attributes
    ----------
    starts : (P,) ndarray of float
        s, start of each piece, increasing.
    F : (P, L) ndarray of complex
        N, complex amplitude of each load's harmonic term at the piece's start.
    omega : (P, L) ndarray of float
        rad/s, its frequency.
    p0 : (P, L) ndarray of float
        N, constant term.
    p1 : (P, L) ndarray of float
        N/s, slope.
    """

    starts: np.ndarray  # (P,) s
    F: np.ndarray  # (P, L) complex, N
    omega: np.ndarray  # (P, L) rad/s
    p0: np.ndarray  # (P, L) N
    p1: np.ndarray  # (P, L) N/s

    def evaluate(self, t) -> np.ndarray:
        """(..., L) the loads from the table (a check of the pieces against the signals)."""
        t = np.asarray(t, float)
        i = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, self.starts.size - 1)
        s = (t - self.starts[i])[..., None]
        return (self.F[i] * np.exp(1j * self.omega[i] * s)).real + self.p0[i] + self.p1[i] * s


def point_loads(signals, points, point_rows: np.ndarray, point_names) -> Loads:
    """Loads acting at named points: b_l = the row of ``point_rows`` of point ``points[l]``.

    Parameters
    ----------
    signals : sequence of HalfSine, Harmonic or Tabulated
        The L time functions p_l(t).
    points : sequence of str
        The point each load acts at, one per signal.
    point_rows : (r, n) array_like of float
        The model's points as rows of its coordinates.
    point_names : sequence of str
        Name of each row of ``point_rows``.

    Returns
    -------
    Loads
        b of shape (L, n).

    Raises
    ------
    LoadError
        An unknown point, or rows that do not match the signals.
    """
    names = tuple(point_names)
    rows = []
    for l, p in enumerate(points):
        if p not in names:
            raise LoadError(f"load {l + 1}: unknown point {p!r} (known: {', '.join(names)})")
        rows.append(np.asarray(point_rows)[names.index(p)])
    n = np.asarray(point_rows).shape[1]
    return Loads(np.array(rows).reshape(len(rows), n), tuple(signals), tuple(points))


__all__ = ["HalfSine", "Harmonic", "Tabulated", "Loads", "PieceTable", "Piece", "LoadError", "LOAD_KINDS",
           "point_loads", "read_force_history"]
