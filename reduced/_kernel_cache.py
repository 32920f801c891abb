"""numba's disk cache of this package's kernels kept fresh across files.

numba (0.68 here) stamps a ``cache=True`` kernel's cache with the content of the one file that
defines it. A kernel that calls a kernel of another file (the shooting march of
:mod:`reduced.periodic.forced_shooting` calls :mod:`reduced.transient._exact_kernels`, the
friction kernels call the exact march, ...) is compiled with its callee inlined, so after a
change to the callee's file the caller's cache still loads the old code: a stale answer (or a
stale speed) with no warning (numba issue 6845).

:func:`refresh` closes that hole for the whole package. The stamp is the SHA-256 of every
``.py`` file under ``reduced/`` (relative path and bytes, sorted by path). Each directory
where numba keeps caches of this package's files carries the stamp it was compiled against
(``kernel-sources.sha256``); where the stamp differs, every ``*.nbi`` index and ``*.nbc``
data file there is removed before any kernel is loaded, and the new stamp is written. The
directories are numba's own choices for a source directory ``D`` (numba.core.caching):
``D/__pycache__`` (in tree), ``$NUMBA_CACHE_DIR/<name of D>_<sha1 of D>`` (user provided)
and the user-wide cache directory with the same sub-path (worked out here as numba does, from
the environment, so that ``import reduced`` does not import numba; a directory set only in a
``.numba_config.yaml`` is not seen). Two processes that start at once
may both clear; the worst outcome is a kernel compiled twice (numba recompiles a data file
that is gone).

Called once on ``import reduced``: it reads ~1.3 MB of sources, ~4 ms.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
STAMP_NAME = "kernel-sources.sha256"


def sources_digest(root: Path = ROOT) -> str:
    """SHA-256 hex digest of every ``.py`` file under ``root`` (relative path and bytes, sorted).

    Parameters
    ----------
    root : Path
        The package directory.

    Returns
    -------
    str
        The digest.
    """
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _numba_subpath(directory: Path) -> str:
    """numba's cache sub-path of a source directory outside the tree: ``<name>_<sha1 of the path>``."""
    path = os.path.abspath(directory)
    return "_".join([os.path.split(path)[-1], hashlib.sha1(path.encode()).hexdigest()])


def _user_wide() -> str:
    """numba's user-wide cache directory (``appdirs.user_cache_dir("numba")``), without importing numba."""
    if sys.platform == "win32":
        return os.path.join(os.environ.get("LOCALAPPDATA", os.path.expanduser("~")), "numba", "Cache")
    if sys.platform == "darwin":
        return os.path.expanduser("~/Library/Caches/numba")
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "numba")


def cache_dirs(root: Path = ROOT) -> list[Path]:
    """The existing directories where numba may keep caches of the kernels of ``root``'s files.

    Parameters
    ----------
    root : Path
        The package directory.

    Returns
    -------
    list of Path
        ``D/__pycache__`` for every directory ``D`` of ``root`` with Python files, and their
        ``$NUMBA_CACHE_DIR`` and user-wide counterparts, the ones that exist.
    """
    dirs = sorted({p.parent for p in root.rglob("*.py")})
    outside = [Path(d) for d in (os.environ.get("NUMBA_CACHE_DIR"), _user_wide()) if d]
    found = []
    for d in dirs:
        for c in [d / "__pycache__", *(o / _numba_subpath(d) for o in outside)]:
            if c.is_dir():
                found.append(c)
    return found


def refresh(root: Path = ROOT) -> list[Path]:
    """Remove numba's cache files compiled against other sources of ``root``; stamp the directories.

    Parameters
    ----------
    root : Path
        The package directory.

    Returns
    -------
    list of Path
        The cache directories that were cleared (their stamp was missing or different).
    """
    dirs = cache_dirs(root)
    if not dirs:  # nothing compiled yet (a fresh clone): no sources to read
        return []
    digest = sources_digest(root)
    cleared = []
    for c in dirs:
        stamp = c / STAMP_NAME
        with contextlib.suppress(OSError):
            if stamp.read_text() == digest:
                continue
        with contextlib.suppress(OSError):  # a read-only directory: numba does not write there either
            for f in [*c.glob("*.nbi"), *c.glob("*.nbc")]:
                with contextlib.suppress(FileNotFoundError):
                    f.unlink()
            tmp = c / f".{STAMP_NAME}.{os.getpid()}"
            tmp.write_text(digest)
            os.replace(tmp, stamp)
            cleared.append(c)
    return cleared


__all__ = ["STAMP_NAME", "cache_dirs", "refresh", "sources_digest"]
