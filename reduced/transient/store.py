"""Ringdowns on disk: an .npz written while the integrator runs, and read back in chunks.

Format
------
``ringdown.npz`` is an ordinary NumPy ``.npz`` (a zip archive of ``.npy`` members), so
``np.load("ringdown.npz")["x"]`` works as before. It is written in one pass with memory
independent of the run length:

- the five histories ``t`` (N,), ``x`` (N, n), ``v`` (N, n), ``energy`` (N,) and
  ``dissipated`` (N,), and for a forced run (``loads``) a sixth, ``external`` (N,) (the work
  of the loads, int v^T f_ext dt; a file without it, a free run or an older file, reads it
  as zeros), then what follows from each sample's state: ``stop_force`` (N, m), the force in
  each stop (N, >= 0 in compression, the stops' order of the system: for the tips, the tip load
  cells' contact force) and ``a`` (N, n), the accelerations M^-1 (f_ext - C v - K x - B^T f)
  (m/s^2 on displacement coordinates; files written before issue 24 lack both), are zip64
  members *stored* (not deflated): their sizes are known
  from N before the run starts, so each member's region is laid out up front and every
  chunk of samples is written at its place in all regions as it arrives (a CRC-32
  per member is carried along and patched into the headers at the end);
- the small members (``dof_names``, ``method``, ``tolerance``, ``energy_balance_error``,
  ``sample_rate_hz``, ``stat_*``) follow, then the zip64 central directory.

Stored members cost about 10 % more disk than deflated ones (float64 trajectories
barely compress) and buy what a long run needs: each array can be read at any offset
(:class:`RingdownFile` reads chunks with ``np.fromfile`` or maps them with ``np.memmap``)
without inflating the archive. Every timestamp in the archive is 1980-01-01 00:00 and no
wall-clock time is stored, so the same run writes the same bytes. The file is written
under a temporary name beside ``path`` and renamed into place when complete.

Reference: PKWARE, *APPNOTE.TXT - .ZIP File Format Specification*, 6.3.x, sections 4.3
(local and central headers) and 4.5.3 (zip64 extended information).
"""

from __future__ import annotations

import io
import math
import os
import struct
import zipfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reduced._checks import InvalidArgument, integer, show

HISTORIES = ("t", "x", "v", "energy", "dissipated", "external")  # the per-sample members, in file order
OPTIONAL = ("external",)  # histories a file may lack (free runs, older files): read as zeros
DERIVED = ("stop_force", "a")  # per-sample members computed from the state as it is written (older files lack them)
FRICTION_HISTORIES = ("w", "friction")  # a run with friction: slider positions (N, p), friction work (N,)
READ_CHUNK_SAMPLES = 1 << 16  # samples a chunk when a run is read back (about 4.7 MB for 3 DOFs)
DOS_TIME, DOS_DATE = 0, (0 << 9) | (1 << 5) | 1  # 1980-01-01 00:00:00: no wall clock in the file
ZIP64_VERSION = 45  # "version needed to extract" for zip64 (APPNOTE 4.4.3)
UNIX = 3  # "version made by" host system
MASK32 = 0xFFFFFFFF
_LOCAL = struct.Struct("<4s2B4HL2L2H")  # local file header without name and extra (30 bytes)
_CENTRAL = struct.Struct("<4s4B4HL2L5H2L")  # central directory header (46 bytes)
_Z64_LOCAL = struct.Struct("<2H2Q")  # zip64 extra in a local header: sizes
_Z64_CENTRAL = struct.Struct("<2H3Q")  # zip64 extra in the central directory: sizes, offset
_EOCD64 = struct.Struct("<4sQ2H2L4Q")
_LOCATOR64 = struct.Struct("<4sLQL")
_EOCD = struct.Struct("<4s4H2LH")


def _npy_header(shape: tuple[int, ...], dtype: np.dtype) -> bytes:
    """The .npy header (format 2.0) of a C-ordered array."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_2_0(
        buf, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False, "shape": shape}
    )
    return buf.getvalue()


def _npy_bytes(value) -> bytes:
    """A small value as a whole .npy file (as ``np.savez`` stores it)."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=False)
    return buf.getvalue()


@dataclass
class _Member:
    name: str
    header_offset: int
    data_offset: int  # first byte of the .npy data (after the .npy header)
    size: int  # bytes of the member (the .npy header and data)
    rows: int  # rows expected (histories) or -1 (small members)
    row_bytes: int
    written: int = 0  # rows written so far
    crc: int = 0
    npy_header: bytes = field(default=b"", repr=False)


class NpzStreamWriter:
    """Write an .npz whose large arrays arrive in row chunks (see the module docstring).

    ``arrays`` maps each large member to (shape, dtype); :meth:`append` adds rows to one
    member in order; :meth:`close` takes the small members and finishes the archive.
    Used as a context manager, an exception removes the partial file.

    Parameters
    ----------
    path : str or Path
        The .npz written (in place only when :meth:`close` completes).
    arrays : dict of str to (tuple of int, dtype)
        Each large member's shape and dtype, in file order.
    """

    def __init__(self, path: str | Path, arrays: dict[str, tuple[tuple[int, ...], np.dtype]]) -> None:
        self.path = Path(path)
        self._tmp = self.path.with_name(f".{self.path.name}.partial-{os.getpid()}")
        self._fh = open(self._tmp, "wb")  # noqa: SIM115 (closed in close/abort)
        self._members: list[_Member] = []
        self._by_name: dict[str, _Member] = {}
        offset = 0
        for name, (shape, dtype) in arrays.items():
            dtype = np.dtype(dtype)
            header = _npy_header(tuple(int(s) for s in shape), dtype)
            row_bytes = dtype.itemsize * int(np.prod(shape[1:], dtype=np.int64))
            size = len(header) + row_bytes * int(shape[0])
            local = self._local_header(name, size, 0)
            m = _Member(name, offset, offset + len(local) + len(header), size, int(shape[0]), row_bytes,
                        crc=zlib.crc32(header), npy_header=header)
            self._fh.seek(offset)
            self._fh.write(local + header)
            offset = m.data_offset + row_bytes * m.rows
            self._members.append(m)
            self._by_name[name] = m
        self._end = offset

    @staticmethod
    def _local_header(name: str, size: int, crc: int) -> bytes:
        raw = (name + ".npy").encode("ascii")
        extra = _Z64_LOCAL.pack(1, 16, size, size)
        return _LOCAL.pack(b"PK\x03\x04", ZIP64_VERSION, 0, 0, zipfile.ZIP_STORED, DOS_TIME, DOS_DATE, crc,
                           MASK32, MASK32, len(raw), len(extra)) + raw + extra

    def append(self, name: str, rows: np.ndarray) -> None:
        """Write the next rows of member ``name`` (C-contiguous, the member's dtype)."""
        m = self._by_name[name]
        data = np.ascontiguousarray(rows)
        k = data.shape[0] if data.ndim else 1
        if data.nbytes != k * m.row_bytes or m.written + k > m.rows:
            raise ValueError(f"{name}: {k} rows of {data.nbytes} bytes do not fit the member "
                             f"({m.rows - m.written} rows of {m.row_bytes} bytes left)")
        buf = memoryview(data).cast("B")
        self._fh.seek(m.data_offset + m.written * m.row_bytes)
        self._fh.write(buf)
        m.crc = zlib.crc32(buf, m.crc)
        m.written += k

    def close(self, small: dict[str, object]) -> None:
        """Finish: the small members, the CRCs, the central directory; rename into place."""
        for m in self._members:
            if m.written != m.rows:
                raise ValueError(f"{m.name}: {m.written} of {m.rows} rows written")
        fh = self._fh
        offset = self._end
        for name, value in small.items():
            data = _npy_bytes(value)
            local = self._local_header(name, len(data), zlib.crc32(data))
            fh.seek(offset)
            fh.write(local + data)
            m = _Member(name, offset, offset + len(local), len(data), -1, 0, crc=zlib.crc32(data))
            self._members.append(m)
            offset += len(local) + len(data)
        for m in self._members[: len(self._members) - len(small)]:
            fh.seek(m.header_offset + 14)  # the CRC-32 field of the local header
            fh.write(struct.pack("<L", m.crc))
        cd_start = offset
        fh.seek(cd_start)
        for m in self._members:
            raw = (m.name + ".npy").encode("ascii")
            extra = _Z64_CENTRAL.pack(1, 24, m.size, m.size, m.header_offset)
            fh.write(_CENTRAL.pack(b"PK\x01\x02", ZIP64_VERSION, UNIX, ZIP64_VERSION, 0, 0, zipfile.ZIP_STORED,
                                   DOS_TIME, DOS_DATE, m.crc, MASK32, MASK32, len(raw), len(extra), 0, 0, 0,
                                   0o644 << 16, MASK32) + raw + extra)
        cd_end = fh.tell()
        count = len(self._members)
        fh.write(_EOCD64.pack(b"PK\x06\x06", _EOCD64.size - 12, (UNIX << 8) | ZIP64_VERSION, ZIP64_VERSION,
                              0, 0, count, count, cd_end - cd_start, cd_start))
        fh.write(_LOCATOR64.pack(b"PK\x06\x07", 0, cd_end, 1))
        fh.write(_EOCD.pack(b"PK\x05\x06", 0, 0, min(count, 0xFFFF), min(count, 0xFFFF),
                            min(cd_end - cd_start, MASK32), min(cd_start, MASK32), 0))
        fh.close()
        os.replace(self._tmp, self.path)

    def abort(self) -> None:
        """Drop the partial file."""
        if not self._fh.closed:
            self._fh.close()
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> NpzStreamWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


def npz_disk_bytes(shapes: dict[str, tuple[int, ...]], small_bytes: int = 4096) -> int:
    """Bytes of an .npz written by :class:`NpzStreamWriter` with float64 members ``shapes``
    (headers included) and about ``small_bytes`` of small members.

    Parameters
    ----------
    shapes : dict of str to tuple of int
        Shape of each float64 member.
    small_bytes : int
        bytes allowed for the small members.

    Returns
    -------
    int
        bytes, an estimate of the file's size (from above for the headers).
    """
    total = small_bytes + 200  # central directory end records
    for name, shape in shapes.items():
        total += 2 * (_LOCAL.size + len(name) + 4 + _Z64_CENTRAL.size) + 128  # headers and .npy header
        total += 8 * math.prod(shape)  # Python ints: no int64 overflow for absurd requests
    return total


@dataclass(frozen=True)
class _Array:
    """Where one stored .npy member's data sits in the archive file."""

    offset: int
    shape: tuple[int, ...]
    dtype: np.dtype
    stored: bool  # False: deflated, readable only sequentially


def _index(path: Path) -> dict[str, _Array]:
    out = {}
    with zipfile.ZipFile(path) as zf, open(path, "rb") as fh:
        for info in zf.infolist():
            name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            if info.compress_type == zipfile.ZIP_STORED:
                fh.seek(info.header_offset)
                head = _LOCAL.unpack(fh.read(_LOCAL.size))
                fh.seek(info.header_offset + _LOCAL.size + head[10] + head[11])
                version = np.lib.format.read_magic(fh)
                read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                shape, fortran, dtype = read(fh)
                out[name] = _Array(fh.tell(), shape, dtype, not fortran)
            else:
                with zf.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, fortran, dtype = read(member)
                out[name] = _Array(-1, shape, dtype, False)
    return out


@dataclass(eq=False)
class Chunk:
    """Consecutive samples ``start .. start + len(t)`` of a ringdown.

    Attributes
    ----------
    start : int
        Index of the first sample in the run.
    t : (k,) ndarray of float
        s.
    x, v : (k, n) ndarray of float
        m and m/s.
    dissipated : (k,) ndarray of float
        J, work dissipated by the damping since t = 0.
    system : GapSystem or None
        Computes ``energy`` from x and v when it is not given.
    energy : (k,) ndarray of float
        J (a property; given as ``_energy``, or computed once by ``system``).
    external : (k,) ndarray of float or None
        J, the work of the loads int_0^t v^T f_ext dt (zeros for a free run; None when not read).
    w : (k, p) ndarray of float or None
        m, the friction sliders' positions (None: no friction, or not read).
    friction : (k,) ndarray of float or None
        J, the part of ``dissipated`` done by friction (None: no friction, or not read).
    """

    start: int
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    dissipated: np.ndarray
    system: object = None
    _energy: np.ndarray | None = None
    external: np.ndarray | None = None
    w: np.ndarray | None = None
    friction: np.ndarray | None = None

    @property
    def energy(self) -> np.ndarray:
        if self._energy is None:
            self._energy = (self.system.energy(self.x, self.v) if self.w is None else
                            self.system.energy(self.x, self.v, self.w))
        return self._energy

    def __len__(self) -> int:
        return self.t.shape[0]


class RingdownFile:
    """A ringdown saved as ``ringdown.npz``, read lazily: memory independent of its length.

    ``chunks()`` reads consecutive samples; ``t``, ``x``, ``v``, ``energy``, ``dissipated`` and
    ``external`` are read-only ``np.memmap`` views (pages are read as they are touched; a file
    without ``external`` gives a read-only view of zeros);
    the summaries (``energy_balance_error``, ``tolerance``, ``stats``) are the small members.
    A file written by ``np.savez_compressed`` (older runs) is read too, sequentially.

    Parameters
    ----------
    path : str or Path
        A ringdown .npz (written by :meth:`RingdownStream.save` or ``np.savez_compressed``).
    system : GapSystem, optional
        The system run: its energies for chunks that lack them.

    Attributes
    ----------
    method : str
        Integrator name.
    tolerance, energy_balance_error : float
        m and relative (nan when the file lacks them).
    dof_names : tuple of str
        Names of the coordinates.
    stats : dict
        The integrator's statistics (``stat_*`` members).
    n_samples, n : int
        Samples and DOFs.
    sample_rate_hz : float
        Hz (from the member, or from t[1] - t[0] in older files).

    Raises
    ------
    InvalidArgument
        No such file, not a readable .npz, or a file without the histories of a ringdown.
    """

    def __init__(self, path: str | Path, system=None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InvalidArgument(f"path must be an existing ringdown .npz file, got {show(str(path))}")
        try:
            self._arrays = _index(self.path)
        except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
            raise InvalidArgument(f"path {show(str(path))} is not a readable .npz file ({exc})") from None
        missing = [k for k in HISTORIES if k not in self._arrays and k not in OPTIONAL]
        if missing:
            raise InvalidArgument(f"path {show(str(path))} is not a ringdown file: no {', '.join(missing)}")
        self.system = system
        with np.load(self.path, allow_pickle=False) as z:
            small = {k: z[k] for k in z.files if k not in (*HISTORIES, *DERIVED, *FRICTION_HISTORIES)}
        self.method = str(small.get("method", ""))
        self.tolerance = float(small.get("tolerance", np.nan))
        self.energy_balance_error = float(small.get("energy_balance_error", np.nan))
        self.dof_names = tuple(str(s) for s in small.get("dof_names", ()))
        self.stats = {k[5:]: v.item() for k, v in small.items() if k.startswith("stat_")}
        self.n_samples = int(self._arrays["t"].shape[0])
        self.n = int(self._arrays["x"].shape[1])
        if "sample_rate_hz" in small:
            self.sample_rate_hz = float(small["sample_rate_hz"])
        else:
            t01 = self.read("t", 0, min(2, self.n_samples))
            self.sample_rate_hz = 1.0 / float(t01[1] - t01[0]) if t01.size > 1 else float("inf")

    # -- reading ---------------------------------------------------------------------------
    def has(self, name: str) -> bool:
        """Whether the file holds the history ``name`` (a run without sliders has no ``friction``)."""
        return name in self._arrays

    def read(self, name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Rows start:stop of history ``name`` (a new array; zeros for an optional history the file lacks)."""
        if name in OPTIONAL and name not in self._arrays:
            stop = self.n_samples if stop is None else min(stop, self.n_samples)
            return np.zeros(max(0, stop - max(0, min(start, stop))))
        if name in DERIVED and name not in self._arrays:
            raise InvalidArgument(f"{self.path.name} has no {name} (written before they were stored); run it again")
        a = self._arrays[name]
        stop = a.shape[0] if stop is None else min(stop, a.shape[0])
        start = max(0, min(start, stop))
        row = int(np.prod(a.shape[1:], dtype=np.int64))
        count = (stop - start) * row
        if a.stored:
            with open(self.path, "rb") as fh:
                fh.seek(a.offset + start * row * a.dtype.itemsize)
                data = np.fromfile(fh, dtype=a.dtype, count=count)
        else:
            with zipfile.ZipFile(self.path) as zf, zf.open(name + ".npy") as member:
                version = np.lib.format.read_magic(member)
                (np.lib.format.read_array_header_1_0 if version == (1, 0) else
                 np.lib.format.read_array_header_2_0)(member)
                skip = start * row * a.dtype.itemsize
                while skip:
                    skip -= len(member.read(min(skip, 1 << 24)))
                data = np.frombuffer(member.read(count * a.dtype.itemsize), dtype=a.dtype).copy()
        if data.size != count:
            raise OSError(f"{self.path}: member {name} is truncated")
        return data.reshape((stop - start, *a.shape[1:]))

    def _memmap(self, name: str) -> np.ndarray:
        if name in OPTIONAL and name not in self._arrays:
            return np.broadcast_to(np.float64(0.0), (self.n_samples,))
        if name in DERIVED and name not in self._arrays:
            raise InvalidArgument(f"{self.path.name} has no {name} (written before they were stored); run it again")
        a = self._arrays[name]
        if not a.stored:
            raise InvalidArgument(f"{self.path.name}: member {name} is compressed; read it with chunks()")
        if a.shape[0] == 0:
            return np.empty(a.shape, a.dtype)
        return np.memmap(self.path, dtype=a.dtype, mode="r", offset=a.offset, shape=a.shape)

    t = property(lambda self: self._memmap("t"), doc="s, (N,) memory-mapped")
    x = property(lambda self: self._memmap("x"), doc="m, (N, n) memory-mapped")
    stop_force = property(lambda self: self._memmap("stop_force"), doc="N, (N, m) memory-mapped: force in each stop")
    a = property(lambda self: self._memmap("a"), doc="m/s^2, (N, n) memory-mapped: accelerations")
    v = property(lambda self: self._memmap("v"), doc="m/s, (N, n) memory-mapped")
    energy = property(lambda self: self._memmap("energy"), doc="J, (N,) memory-mapped")
    dissipated = property(lambda self: self._memmap("dissipated"), doc="J, (N,) memory-mapped")
    external = property(lambda self: self._memmap("external"), doc="J, (N,) memory-mapped (zeros: a free run)")
    w = property(lambda self: self._memmap("w") if "w" in self._arrays else None,
                 doc="m, (N, p) memory-mapped slider positions (None: no friction)")
    friction = property(lambda self: self._memmap("friction") if "friction" in self._arrays else None,
                        doc="J, (N,) memory-mapped friction work (None: no friction)")

    @property
    def forced(self) -> bool:
        """Whether the file holds the work of loads (a forced run)."""
        return "external" in self._arrays

    def chunks(self, chunk_samples: int | None = None, start: int = 0, stop: int | None = None,
               fields: tuple[str, ...] = HISTORIES + FRICTION_HISTORIES) -> Iterator[Chunk]:
        """Consecutive :class:`Chunk` of at most ``chunk_samples`` (default ``READ_CHUNK_SAMPLES``)
        samples from ``start`` to ``stop``; only the histories in ``fields`` are read (the others are None,
        as are the friction histories of a run without friction)."""
        chunk_samples = integer("chunk_samples", READ_CHUNK_SAMPLES if chunk_samples is None else chunk_samples)
        allowed = HISTORIES + FRICTION_HISTORIES
        for name in fields:
            if name not in allowed:
                raise InvalidArgument(f"fields must name histories among {', '.join(allowed)}, got {show(name)}")
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        for i in range(start, stop, chunk_samples):
            j = min(i + chunk_samples, stop)
            a = {k: self.read(k, i, j) if k in fields else None for k in HISTORIES}
            for k in FRICTION_HISTORIES:
                a[k] = self.read(k, i, j) if k in fields and k in self._arrays else None
            t = a["t"] if a["t"] is not None else np.arange(i, j) / self.sample_rate_hz
            yield Chunk(i, t, a["x"], a["v"], a["dissipated"], self.system, a["energy"], a["external"], a["w"],
                        a["friction"])

    @property
    def energy0(self) -> float:
        """J, energy of the first sample."""
        return float(self.read("energy", 0, 1)[0]) if self.n_samples else 0.0

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        return (f"RingdownFile({str(self.path)!r}, method={self.method!r}, n_samples={self.n_samples}, "
                f"n={self.n}, sample_rate_hz={self.sample_rate_hz:g})")
