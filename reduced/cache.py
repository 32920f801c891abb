"""Checked on-disk cache entries: a data file and its JSON manifest, each written atomically.

An entry is two files in one folder::

    <name>          the data, in whatever format the caller writes (``rom-<key>.npz``)
    <name>.json     the manifest: {"format": 1, "inputs_sha256": ..., "sha256": ..., "size": ...,
                    "created_utc": ..., "info": {...}}

``inputs_sha256`` is the hash of everything the data was computed from (for a reduced model:
the specification and the source that builds it); ``sha256`` and ``size`` are those of the
data file's bytes. :func:`write_entry` writes the data, then the manifest, each to a
uniquely named temporary sibling moved into place by ``os.replace``, and moves the pair in
under an exclusive lock on the folder (``.cache.lock``, POSIX ``flock``), so that any number
of processes writing the same entry at once leave one consistent pair; a process killed
mid-write leaves at most a stray ``.<name>.*.tmp``.

:func:`load_entry` accepts an entry only if its manifest reads, names the same inputs, and
the data's bytes have the recorded size and sha256; the caller's decoder then runs on
exactly those bytes. A missing manifest, a mismatch, or any exception from the decoder
(BadZipFile, zlib.error, EOFError, UnicodeDecodeError, struct.error, ...) is looked at
again under the lock (a writer may have been between its two renames), and if the entry
is still bad it is removed and reported in one line on the ``reduced.cache`` logger
(stderr when logging is not configured): ``cache entry <path> is corrupt (<reason>);
rebuilding``. The caller then rebuilds and writes the entry again.

This module imports no solver (and nothing from this package): a mesh or mode cache can
use it as the reduced-model cache (:mod:`reduced.models.rom`) does. numba's own cache of
``cache=True`` kernels is not checked by numba; :func:`call_numba_kernel` recovers from a
corrupt one by recompiling.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import os
import sys
import tempfile
import traceback
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO, TypeVar

import numpy as np

from reduced._checks import one_line

try:
    import fcntl
except ImportError:  # Windows: no flock; concurrent writers of one entry may then leave a mismatch
    fcntl = None  # that the next read reports and rebuilds

MANIFEST_FORMAT = 1
MANIFEST_SUFFIX = ".json"
LOCK_NAME = ".cache.lock"

log = logging.getLogger(__name__)
T = TypeVar("T")


def manifest_path(path: str | Path) -> Path:
    """The manifest of the entry whose data file is ``path``: ``<path>.json``.

    Parameters
    ----------
    path : str or Path
        The entry's data file.

    Returns
    -------
    Path
    """
    path = Path(path)
    return path.with_name(path.name + MANIFEST_SUFFIX)




@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """Hold the exclusive lock of a cache folder (no lock where flock or the folder is unusable)."""
    if fcntl is None:
        yield
        return
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:  # a read-only cache: nothing can be written there to race with
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def current_umask() -> int:
    """The process's umask, read without changing it (``/proc/self/status``; elsewhere by setting it
    and putting it back, which another thread creating a file at that moment could notice).

    Returns
    -------
    int
        The mask, e.g. 0o022.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _write_temp(path: Path, write: Callable[[BinaryIO], None]) -> tuple[Path, str, int]:
    """Write a uniquely named temporary sibling of ``path``; (its path, sha256 hex, size in bytes).
    It gets the mode a plain ``open`` would give (mkstemp's is 0600: colleagues could not read it)."""
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.fchmod(fd, 0o666 & ~current_umask())
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w+b") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())  # the data is on disk before its name is
            f.seek(0)
            h = hashlib.sha256()
            size = 0
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
                size += len(chunk)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp, h.hexdigest(), size


def atomic_write(path: str | Path, write: Callable[[BinaryIO], None]) -> str:
    """Write a file by ``write(f)`` to a unique temporary sibling and move it into place; its sha256.

    Readers see the old file or the new one, never a part; concurrent writers do not collide.

    Parameters
    ----------
    path : str or Path
        The file written (its folder must exist).
    write : callable
        ``write(f)`` writes the whole content to the binary file object ``f``.

    Returns
    -------
    str
        sha256 (hex) of the bytes written.
    """
    path = Path(path)
    tmp, digest, _ = _write_temp(path, write)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return digest


def write_entry(path: str | Path, write: Callable[[BinaryIO], None], inputs_sha256: str,
                info: dict | None = None) -> None:
    """Store a cache entry: the data by ``write(f)`` at ``path``, then its manifest (module docstring).

    Raises OSError where the folder cannot be written (the caller decides whether that matters).

    Parameters
    ----------
    path : str or Path
        The data file; its folder is created if needed.
    write : callable
        ``write(f)`` writes the data to the binary file object ``f``.
    inputs_sha256 : str
        Hash of everything the data was computed from, recorded in the manifest.
    info : dict, optional
        JSON-serialisable description kept in the manifest's ``info``.

    Returns
    -------
    None

    Raises
    ------
    OSError
        The folder or a file cannot be written (no temporary file is left behind).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp, digest, size = _write_temp(path, write)
    manifest = {"format": MANIFEST_FORMAT, "inputs_sha256": inputs_sha256, "sha256": digest, "size": size,
                "created_utc": datetime.now(UTC).isoformat(timespec="seconds"), "info": info or {}}
    text = json.dumps(manifest, indent=1, sort_keys=True).encode()
    try:
        tmp_manifest, _, _ = _write_temp(path, lambda f: f.write(text))
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    try:
        with _locked(path.parent):  # the pair moves in together: data first, manifest last
            os.replace(tmp, path)
            os.replace(tmp_manifest, manifest_path(path))
    except BaseException:
        tmp.unlink(missing_ok=True)
        tmp_manifest.unlink(missing_ok=True)
        raise


def _check(path: Path, inputs_sha256: str, load: Callable[[BinaryIO], T]) -> tuple[T | None, str | None]:
    """(value, None) for a good entry, (None, None) for none at all, (None, reason) for a bad one."""
    try:
        manifest_bytes = manifest_path(path).read_bytes()
    except FileNotFoundError:
        return (None, None) if not path.exists() else (None, "no manifest")
    except OSError as exc:
        return None, f"manifest unreadable: {one_line(exc, typed=True)}"
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None, "manifest without its data file"
    except OSError as exc:
        return None, f"data unreadable: {one_line(exc, typed=True)}"
    try:
        manifest = json.loads(manifest_bytes)
        fmt, inputs = manifest["format"], manifest["inputs_sha256"]
        digest, size = manifest["sha256"], manifest["size"]
    except Exception as exc:  # bad UTF-8, bad JSON, a list, a missing key: all corrupt
        return None, f"manifest unreadable: {one_line(exc, typed=True)}"
    if fmt != MANIFEST_FORMAT:
        return None, f"manifest format {fmt!r}, expected {MANIFEST_FORMAT}"
    if inputs != inputs_sha256:
        return None, "input hash differs from the manifest's"
    if len(data) != size:
        return None, f"{len(data)} bytes, manifest says {size}"
    if hashlib.sha256(data).hexdigest() != digest:
        return None, "sha256 differs from the manifest's"
    try:
        return load(io.BytesIO(data)), None
    except Exception as exc:  # whatever the decoder raises on bytes it cannot read
        return None, f"cannot be read: {one_line(exc, typed=True)}"


def remove_entry(path: str | Path) -> None:
    """Remove an entry's data and manifest (either may be absent).

    Parameters
    ----------
    path : str or Path
        The entry's data file.

    Returns
    -------
    None
    """
    path = Path(path)
    for p in (manifest_path(path), path):
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


def load_entry(path: str | Path, inputs_sha256: str, load: Callable[[BinaryIO], T]) -> T | None:
    """The decoded entry at ``path`` if it is intact and was made from ``inputs_sha256``, else None.

    ``load(f)`` decodes the data from a binary file object holding exactly the checked bytes.
    None means: no entry, or a bad one that was removed and reported (module docstring);
    the caller rebuilds.

    Parameters
    ----------
    path : str or Path
        The entry's data file.
    inputs_sha256 : str
        Hash the manifest must name.
    load : callable
        ``load(f) -> T``; any exception it raises marks the entry corrupt.

    Returns
    -------
    T or None
        What ``load`` returned, or None.
    """
    path = Path(path)
    value, reason = _check(path, inputs_sha256, load)
    if reason is None:
        return value
    with _locked(path.parent):  # a writer may have been between its two renames: look again
        value, reason = _check(path, inputs_sha256, load)
        if reason is None:
            return value
        try:
            remove_entry(path)
        except OSError as exc:  # a read-only cache: rebuild all the same
            reason += f"; not removed: {one_line(exc, typed=True)}"
    log.warning("cache entry %s is corrupt (%s); rebuilding", path, reason)
    return None


# -- arrays computed once: an npz entry -------------------------------------------------------
def hash_sparse(h, *matrices) -> None:
    """Feed the CSR arrays (indptr, indices, data) of each sparse matrix to the hash object ``h``.

    Parameters
    ----------
    h : hashlib hash object
        Updated in place.
    *matrices : scipy.sparse matrices or arrays
        Each is converted to CSR; two matrices hash alike only if their CSR arrays are equal bit for bit.

    Returns
    -------
    None
    """
    for A in matrices:
        A = A.tocsr()
        for a in (A.indptr, A.indices, A.data):
            h.update(np.ascontiguousarray(a).tobytes())


def _load_arrays(f) -> dict[str, np.ndarray]:
    with np.load(f) as z:
        return {k: z[k] for k in z.files}


def cached_arrays(path: str | Path, inputs_sha256: str, compute: Callable[[], dict[str, np.ndarray]],
                  info: dict | None = None) -> dict[str, np.ndarray]:
    """The named arrays of the ``.npz`` entry at ``path`` made from ``inputs_sha256``; else ``compute()``'s,
    stored there (:func:`write_entry`) and returned.

    A loaded entry holds the bits ``compute()`` returned when it was made (``np.savez`` stores them
    unchanged), so a caller that builds its result from the arrays alone gets the same result from a
    hit as from a miss. A folder that cannot be written costs a solve next time, nothing else.

    Parameters
    ----------
    path : str or Path
        The entry's data file (``<folder>/<prefix>-<key>.npz``).
    inputs_sha256 : str
        Hash of everything ``compute`` depends on.
    compute : callable
        ``compute() -> {name: array}`` on a miss.
    info : dict, optional
        JSON-serialisable description kept in the manifest.

    Returns
    -------
    dict of str to ndarray
        From the entry, or from ``compute()`` (values as it returned them).
    """
    hit = load_entry(path, inputs_sha256, _load_arrays)
    if hit is not None:
        return hit
    arrays = compute()
    with contextlib.suppress(OSError):  # a read-only cache: solved again next time
        write_entry(path, lambda f: np.savez(f, **arrays), inputs_sha256, info)
    return arrays


# -- numba's own on-disk cache ---------------------------------------------------------------
def _raised_by_numba_cache(exc: BaseException) -> bool:
    """Whether an exception came out of numba's cache loader (numba/core/caching.py)."""
    return any(f.filename.replace("\\", "/").endswith("numba/core/caching.py")
               for f in traceback.extract_tb(exc.__traceback__))


def call_numba_kernel(kernel, *args):
    """``kernel(*args)`` for a numba ``cache=True`` kernel, recompiling if its disk cache is corrupt.

    numba (0.68 here) does not check its cache files (``__pycache__/*.nbi`` index, ``*.nbc``
    data): a truncated, empty or garbled one makes every call, in every later process, raise
    EOFError, UnpicklingError, UnicodeDecodeError or an LLVM bitcode parsing error. Such an
    error (one raised from numba's caching module; any other propagates) is reported in one
    line, the cache index of every cached kernel in the kernel's module is emptied (callees
    are there as imported names, and a caller's recompilation loads theirs), and the call is
    made again: numba recompiles and overwrites the bad files. Uses numba's private
    ``Dispatcher._cache.flush()``; without it the error propagates.

    Parameters
    ----------
    kernel : numba Dispatcher
        A compiled ``@njit(cache=True)`` function.
    *args
        Its arguments.

    Returns
    -------
    object
        What the kernel returns.

    Raises
    ------
    Exception
        Whatever the kernel raises that is not a numba cache error, or a cache error when the
        kernel's cache cannot be flushed.
    """
    try:
        return kernel(*args)
    except Exception as exc:
        if not _raised_by_numba_cache(exc):
            raise
        module = sys.modules.get(getattr(getattr(kernel, "py_func", None), "__module__", None))
        candidates = [kernel, *(vars(module).values() if module is not None else ())]
        cached = {id(k): k for k in candidates if hasattr(getattr(k, "_cache", None), "flush")}
        if id(kernel) not in cached:
            raise
        log.warning("numba cache of %s in %s is corrupt (%s); recompiling", kernel.py_func.__qualname__,
                    getattr(kernel._cache, "cache_path", "?"), one_line(exc, typed=True))
        for k in cached.values():
            k._cache.flush()
    return kernel(*args)


__all__ = ["current_umask", "atomic_write", "write_entry", "load_entry", "remove_entry", "manifest_path",
           "call_numba_kernel", "cached_arrays", "hash_sparse"]
