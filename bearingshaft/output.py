"""Results folders: written whole or not at all, each with its case and provenance.

A stage writes into a scratch folder beside the results folder; only when the stage
finishes are its files moved in and ``provenance.json`` updated (PyFR keeps the config
and statistics with each solution in the same way). A failed stage leaves the results
folder as it was, never a half-written set of files that looks complete.
"""

from __future__ import annotations

import csv
import ctypes
import fcntl
import json
import os
import platform
import shutil
import signal
import subprocess
import tempfile
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from bearingshaft import __version__
from reduced.cache import current_umask


def git_commit() -> str:
    """The commit of the source tree this package runs from ('unknown' outside git)."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
        # changes under results/ (the tool's own output) do not make the source dirty
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results"],
            cwd=here.parent, capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def machine_rows(**extra) -> list[dict]:
    """The machine a benchmark ran on, as ``key, value`` rows for a CSV: CPU model, cores,
    Python and library versions, commit, UTC date and 1-minute load, then ``extra``.

    Parameters
    ----------
    **extra
        Further ``key=value`` rows, appended in order (a key already present is replaced in place).

    Returns
    -------
    list of dict
        ``{"key": ..., "value": ...}`` per item.
    """
    from importlib.metadata import PackageNotFoundError, version

    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                   if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    info = {"platform": platform.platform(), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version()}
    for pkg in ("numpy", "scipy", "numba", "scikit-fem"):
        try:
            info[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    info.update(git_commit=git_commit(), date_utc=datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
                load_1min=round(os.getloadavg()[0], 2), **extra)
    return [{"key": k, "value": v} for k, v in info.items()]


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return str(obj)
    return obj


def write_rows(path: str | Path, rows: list[dict], fields: list[str] | None = None,
               float_format: str | None = None) -> None:
    """CSV of dict rows; columns ``fields`` (default: the first row's keys; others dropped);
    floats written with ``float_format`` (e.g. ".4g") if given, else in full.

    Parameters
    ----------
    path : str or Path
        The CSV file, replaced.
    rows : list of dict
        The rows.
    fields : list of str, optional
        The columns, in order.
    float_format : str, optional
        Format specification of the float cells.

    Returns
    -------
    None
        With neither rows nor ``fields`` the file is left empty (no header).
    """
    with open(path, "w", newline="") as fh:
        if not rows and fields is None:
            return
        w = csv.DictWriter(fh, fieldnames=fields or list(rows[0]), extrasaction="ignore")
        w.writeheader()
        if float_format is None:
            w.writerows(rows)
        else:
            w.writerows({k: format(v, float_format) if isinstance(v, float) else v for k, v in r.items()}
                        for r in rows)


class StageWriter:
    """Where a stage puts its files (``path(name)``) and its solver statistics (``stats``).

    Parameters
    ----------
    scratch : Path
        The scratch folder the stage writes into.

    Attributes
    ----------
    scratch : Path
        As given.
    stats : dict
        Solver statistics, written to ``provenance.json`` under the stage.
    """

    def __init__(self, scratch: Path) -> None:
        self.scratch = scratch
        self.stats: dict = {}

    def path(self, name: str) -> Path:
        return self.scratch / name


def check_out_dir(out_dir: str | Path) -> Path:
    """``out_dir`` as a results folder that can be written, or ValueError in one line.

    It must not be a file (nor /dev/null), nor lie under a file, and the nearest folder that
    exists on its path must be writable (the results folder and its scratch siblings are
    created there). Checked before any work starts.

    Parameters
    ----------
    out_dir : str or Path
        The results folder asked for (it need not exist).

    Returns
    -------
    Path
        ``Path(out_dir)``.

    Raises
    ------
    ValueError
        A file, a path under a file, or a folder that cannot be written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {str(out_dir)!r}: is a file, not a folder")
    parent = out.absolute().parent
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"--out {str(out_dir)!r}: {str(probe)!r} is a file, so no folder can be made under it")
    if not os.access(probe, os.W_OK | os.X_OK) or (out.is_dir() and not os.access(out, os.W_OK | os.X_OK)):
        raise ValueError(f"--out {str(out_dir)!r}: {str(out if out.is_dir() else probe)!r} is not writable")
    try:  # access() says yes on read-only mounts and for root: try it
        probe_file = tempfile.NamedTemporaryFile(dir=probe, prefix=".bearingshaft-probe-", delete=True)
        probe_file.close()
    except OSError as exc:
        raise ValueError(f"--out {str(out_dir)!r}: cannot write in {str(probe)!r} ({exc.strerror})") from None
    return out


_RENAME_EXCHANGE = 2  # renameat2 flag (Linux >= 3.15): swap two paths in one atomic step


def _exchange(a: Path, b: Path) -> bool:
    """Swap folders ``a`` and ``b`` atomically (Linux renameat2); False where not supported
    (or turned off by ``$BEARINGSHAFT_NO_RENAME_EXCHANGE``, which the tests of the fallback use)."""
    if os.environ.get("BEARINGSHAFT_NO_RENAME_EXCHANGE"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    at_fdcwd = -100
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE) == 0


def _swap_in(new: Path, out: Path) -> None:
    """Put the complete folder ``new`` at ``out``; the old ``out`` (if any) is removed.

    With renameat2 the swap is one atomic step: a reader, or a kill at any moment, sees the
    old folder or the new one. Elsewhere two renames leave a moment with no folder at all
    (never a mixed one); the old folder is then kept aside under a dot name until removed.
    """
    if not out.exists():
        new.rename(out)
        return
    if _exchange(new, out):
        shutil.rmtree(new, ignore_errors=True)  # it now holds the old folder
        return
    aside = out.with_name(f".{out.name}.old-{os.getpid()}")
    out.rename(aside)
    _crash_point("aside")
    new.rename(out)
    shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def folder_lock(out: Path):
    """Hold an exclusive lock on results folder ``out`` (a ``.<name>.lock`` file beside it, removed
    when released).

    Writers of one folder take turns only while they merge their files in; the work itself
    runs in parallel. A lock dies with its process, so a killed run never blocks the next (its
    file stays until the next writer of the folder takes and releases the lock).

    Parameters
    ----------
    out : Path
        The results folder.

    Yields
    ------
    None
    """
    lock_path = out.with_name(f".{out.name}.lock")
    while True:
        fh = open(lock_path, "a+b")  # noqa: SIM115 (closed below, after the unlink)
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:  # the file we locked may have been removed by the holder before us: then lock the new one
            same = os.path.samestat(os.fstat(fh.fileno()), os.stat(lock_path))
        except FileNotFoundError:
            same = False
        if same:
            break
        fh.close()
    try:
        yield
    finally:
        # removed while still held, so no lock file stays behind; a waiter on the removed file
        # finds it gone (above) and takes a new one, so two holders never overlap
        lock_path.unlink(missing_ok=True)
        fh.close()


def _remove_stale_scratch(out: Path) -> None:
    """Clear what killed runs left beside ``out`` (called under the folder lock only).

    Their scratch folders are removed; an old folder set aside by a two-rename swap that
    was cut between its renames is put back if ``out`` is missing, else removed.
    """
    for p in out.parent.glob(f".{out.name}.*"):
        kind, _, rest = p.name[len(out.name) + 2:].partition("-")
        if not p.is_dir() or not (kind.endswith("partial") or kind == "old"):
            continue
        try:
            pid = int(rest.split("-")[0])
        except ValueError:
            continue
        if pid == os.getpid() or _alive(pid):
            continue
        if kind == "old" and not out.exists():
            p.rename(out)
        else:
            shutil.rmtree(p, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


CRASH_ENV = "BEARINGSHAFT_CRASH_AT"  # tests only: SIGKILL this process at the named point of a commit


def _crash_point(name: str) -> None:
    """Die here as a power cut or ``kill -9`` would, if the tests ask for it (see tests/test_results_folder.py)."""
    if os.environ.get(CRASH_ENV) == name:
        os.kill(os.getpid(), signal.SIGKILL)


@contextmanager
def staged_output(out_dir: str | Path, scene_name: str, scene_source: str, stage: str):
    """Yield a :class:`StageWriter`; on success swap a complete new results folder in.

    The stage writes into a scratch folder beside ``out_dir`` (``.<name>.<stage>.partial-<pid>-*``).
    When it finishes, under the folder's lock, the files of the current ``out_dir`` that the
    stage did not write are linked into the scratch folder, ``scene.toml`` (the case as read)
    and, last, ``provenance.json`` (package version, git commit, platform, per-stage
    statistics and file lists, merged with the folder's) are written, and the scratch folder
    is swapped in for ``out_dir`` atomically. A failure, an interrupt or a SIGKILL at any
    moment leaves ``out_dir`` as it was (or absent, if it did not exist): never a mix of old
    and new files under a provenance that looks complete.

    Parameters
    ----------
    out_dir : str or Path
        The results folder (checked by :func:`check_out_dir`).
    scene_name : str
        Recorded in ``provenance.json``.
    scene_source : str
        The case as read, written to ``scene.toml``.
    stage : str
        The stage's name: its entry in ``provenance.json`` and its scratch folder's name.

    Yields
    ------
    StageWriter

    Raises
    ------
    ValueError
        As :func:`check_out_dir`.
    """
    out = check_out_dir(out_dir).absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{out.name}.{stage}.partial-{os.getpid()}-", dir=out.parent))
    scratch.chmod(0o777 & ~current_umask())  # mkdtemp makes it drwx------; a results folder is the user's usual mode
    writer = StageWriter(scratch)
    try:
        yield writer
        files = sorted(p.name for p in scratch.iterdir())
        _crash_point("written")
        with folder_lock(out):
            _remove_stale_scratch(out)
            prov = {}
            if out.is_dir():
                for p in out.iterdir():
                    if p.name in files or p.name in ("provenance.json", "scene.toml"):
                        continue
                    if p.is_dir():
                        shutil.copytree(p, scratch / p.name, copy_function=_link_or_copy)
                    else:
                        _link_or_copy(p, scratch / p.name)
                    _crash_point("linking")
                try:
                    prov = json.loads((out / "provenance.json").read_text())
                except (OSError, ValueError):
                    prov = {}
            (scratch / "scene.toml").write_text(scene_source, encoding="utf-8")
            _crash_point("scene")
            prov.update(
                {
                    "scene": scene_name,
                    "package": "bearingshaft",
                    "version": __version__,
                    "git_commit": git_commit(),
                    "python": platform.python_version(),
                    "numpy": np.__version__,
                    "machine": platform.machine(),
                }
            )
            prov.setdefault("stages", {})[stage] = {
                "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "files": files,
                "stats": _jsonable(writer.stats),
            }
            (scratch / "provenance.json").write_text(json.dumps(prov, indent=2, sort_keys=True) + "\n",
                                                     encoding="utf-8")
            _fsync_tree(scratch)
            _crash_point("provenance")
            _swap_in(scratch, out)
            _crash_point("swapped")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _link_or_copy(src, dst) -> None:
    """A hard link (the files are never changed in place), a copy where links are not allowed."""
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _fsync_tree(folder: Path) -> None:
    """Flush the folder's files to disk before it is swapped in (a crash then finds them whole)."""
    for p in folder.rglob("*"):
        if p.is_file():
            with open(p, "rb") as fh:
                os.fsync(fh.fileno())
