"""Run small dense linear algebra on one BLAS thread.

HB, Hill and shooting factor many matrices of a few hundred rows. Multithreaded OpenBLAS
on such sizes, on a machine whose cores are busy, is hundreds of times slower than one
thread (an LU of 156 x 156 took 57 ms instead of 0.15 ms with load 4.8 on 2 cores), so
the NNM solvers run inside :func:`single_thread_blas`. Works on the OpenBLAS builds that
NumPy and SciPy wheels ship (symbols ``scipy_openblas_*``); elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager

_NAMES = (
    ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
    ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
)


def _libraries() -> list:
    libs = []
    try:
        import numpy
        import scipy
    except ImportError:  # pragma: no cover
        return libs
    for mod, sub in ((numpy, "numpy.libs"), (scipy, "scipy.libs")):
        for path in glob.glob(os.path.join(os.path.dirname(mod.__file__), "..", sub, "*openblas*")):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for set_name, get_name in _NAMES:
                if hasattr(lib, set_name) and hasattr(lib, get_name):
                    libs.append((getattr(lib, set_name), getattr(lib, get_name)))
                    break
    return libs


_LIBS = None


@contextmanager
def single_thread_blas():
    """Context in which NumPy's and SciPy's OpenBLAS use one thread (restored on exit)."""
    global _LIBS
    if _LIBS is None:
        _LIBS = _libraries()
    old = []
    for set_n, get_n in _LIBS:
        old.append(get_n())
        set_n(1)
    try:
        yield
    finally:
        for (set_n, _), k in zip(_LIBS, old, strict=True):
            set_n(k)
