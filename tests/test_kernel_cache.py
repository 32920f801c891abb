"""numba's disk cache kept fresh across files (reduced._kernel_cache).

A two-file package: ``inner.py`` defines a cached kernel, ``outer.py`` a cached kernel that calls
it. After ``inner.py`` changes, numba alone loads ``outer``'s stale machine code (the first run below
shows it, so the test would fail if numba ever fixed that and the guard became dead weight without
anyone noticing); :func:`refresh` run before the import makes the new code run.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from reduced._kernel_cache import STAMP_NAME, cache_dirs, refresh, sources_digest

OUTER = textwrap.dedent("""
    from numba import njit
    from kpkg.inner import g

    @njit(cache=True)
    def f(x):
        return g(x) + 1.0
""")


def _inner(value: float) -> str:
    return f"from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return x * 0.0 + {value!r}\n"


def _run(tmp: Path, guard: bool) -> float:
    """f(0.0) in a fresh process, with or without :func:`refresh` of the package before its import."""
    code = (f"import sys; sys.path.insert(0, {str(tmp)!r}); from pathlib import Path\n"
            + (f"from reduced._kernel_cache import refresh; refresh(Path({str(tmp / 'kpkg')!r}))\n" if guard else "")
            + "from kpkg.outer import f; print(repr(f(0.0)))")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parents[1]), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def test_a_callers_cache_is_stale_without_the_guard_and_fresh_with_it(tmp_path):
    pkg = tmp_path / "kpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "outer.py").write_text(OUTER)
    (pkg / "inner.py").write_text(_inner(1.0))
    assert _run(tmp_path, guard=True) == 2.0  # compiles and caches outer with inner = 1
    assert any(pkg.glob("__pycache__/outer.f-*.nbc"))
    (pkg / "inner.py").write_text(_inner(5.0))
    assert _run(tmp_path, guard=False) == 2.0  # numba alone: outer's cache still holds inner = 1
    assert _run(tmp_path, guard=True) == 6.0  # the guard cleared it: inner = 5 compiled in
    assert (pkg / "__pycache__" / STAMP_NAME).read_text() == sources_digest(pkg)


def test_refresh_clears_only_a_directory_whose_stamp_differs(tmp_path):
    pkg = tmp_path / "p"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cache = pkg / "sub" / "__pycache__"
    files = [cache / "b.k-3.py311.nbi", cache / "b.k-3.py311.1.nbc", cache / "b.cpython-311.pyc"]
    for f in files:
        f.write_bytes(b"x")
    assert cache_dirs(pkg) == [cache]  # p/__pycache__ does not exist: nothing to stamp there
    assert refresh(pkg) == [cache]
    assert [f.exists() for f in files] == [False, False, True]  # Python's own bytecode is left
    files[0].write_bytes(b"x")
    assert refresh(pkg) == [] and files[0].exists()  # same sources: kept
    (pkg / "a.py").write_text("x = 3\n")  # a change anywhere in the package (a constant a kernel freezes)
    assert refresh(pkg) == [cache] and not files[0].exists()
    assert sources_digest(pkg) != sources_digest(pkg / "sub")
