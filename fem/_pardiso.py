"""MKL PARDISO Cholesky through ctypes, with its threads and the BLAS threads under control.

pypardiso locates ``mkl_rt`` by a recursive glob of the Python prefix each time a solver is
made (~2 s here); the library is located once per process (:func:`libmkl`) and reused.
On a shared 2-core machine two thread pools fighting for the cores cost more than the
arithmetic: MKL's OpenMP threads and numpy's/scipy's OpenBLAS threads both spin-wait, and a
112629 x 32 Gram product that takes 0.012 s on one thread took 6 s beside a PARDISO solve.
:func:`blas_threads` pins OpenBLAS to one thread while the eigensolver runs (its dense work
is tall-skinny and memory-bound), and PARDISO runs on a fixed number of threads
(:func:`solver_threads`: one, unless ``BEARINGSHAFT_THREADS`` says otherwise), so that a run
gives the same bits whatever the machine's load and core count (1 and 2 threads round
differently); :func:`fixed_threads` holds OpenBLAS to the same count around the model builds
(modal analysis, Craig-Bampton reduction) whose bits depend on it. The solves of a one-thread factor
on two threads change the bits too (1 to 16 right-hand sides, 112,629 DOFs). On this AMD EPYC (AVX-512)
MKL 2026.2 loads its generic kernels (libmkl_def); MKL_CBWR and MKL_ENABLE_INSTRUCTIONS do not change
that, and its dgemm there runs at 35-44 GFLOP/s against OpenBLAS's 46 on one core: nothing to gain.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os

import numpy as np
import scipy.sparse as sp

MTYPE_SPD = 2  # real symmetric positive definite: Cholesky
# iparm (zero-based), see the MKL PARDISO reference; iparm[0] = 1: the values below are used
IPARM = {
    0: 1,  # no defaults: use this table
    1: 2,  # fill-in reducing ordering: nested dissection (METIS)
    9: 13,  # pivot perturbation 1e-13 (not used by Cholesky, kept at MKL's default)
    17: -1,  # report the factor's non-zeros in iparm[17]
    18: -1,  # report the factorization's MFLOP in iparm[18]
    34: 1,  # zero-based ia/ja
    23: 1,  # two-level parallel factorization: 112,629-DOF apparatus on one thread, analysis +
    # factor 0.6 + 4.5-4.9 CPU s instead of 0.8-1.0 + 5.4-5.7 (the default), same solve times
    36: -90,  # variable block rows (VBSR): the 3 DOFs of a node and their like are factorized as
    # blocks; 112,629-DOF apparatus on one thread: analysis 2.4 s instead of 6.5 s, same factor
}


@functools.cache
def libmkl() -> ctypes.CDLL:
    """The mkl_rt shared library: ``PYPARDISO_MKL_RT``, then ``<prefix>/lib`` (where the mkl
    wheel puts it), then pypardiso's own search (a recursive glob of the prefix, ~2 s); once."""
    import sys
    from pathlib import Path

    lib = None
    candidates = [os.environ.get("PYPARDISO_MKL_RT", "")] + sorted(
        (str(p) for p in Path(sys.prefix, "lib").glob("libmkl_rt.so*")), key=len)
    for path in filter(None, candidates):
        with contextlib.suppress(OSError):
            lib = ctypes.CDLL(path)
            break
    if lib is None:
        import pypardiso

        lib = pypardiso.PyPardisoSolver(mtype=MTYPE_SPD).libmkl
    lib.pardiso.argtypes = [ctypes.c_void_p] * 16  # every argument by pointer
    lib.pardiso.restype = None
    return lib


def has_pardiso() -> bool:
    """MKL PARDISO can be used: pypardiso (the dependency that brings MKL) is installed and mkl_rt loads.

    pypardiso is looked up, not imported: its import builds a solver, which globs the whole Python
    prefix for mkl_rt (1.1-1.5 s per process here), although :func:`libmkl` finds it in ``<prefix>/lib``.
    """
    import importlib.util

    try:
        if importlib.util.find_spec("pypardiso") is None:
            return False
        libmkl()
    except (ImportError, OSError, ValueError):
        return False
    return True


DEFAULT_THREADS = 1  # PARDISO's and the model builds' OpenBLAS threads unless BEARINGSHAFT_THREADS is set: a count
# that followed the machine's load (PARDISO) or its cores (OpenBLAS) made the results depend on them (assembly-modal:
# the bungee modes' frequencies moved by 3e-4 between 1 and 2 PARDISO threads; the reduced apparatus's matrices by
# 2e-10 of their largest entry between 1 and 2 OpenBLAS threads, which a chaotic hammer record magnifies); one thread
# gives the same bits on every run: at load 6-7 on this 2-core machine it was 2-2.5x faster than two, on a quiet one
# the 112,629-DOF modal analysis 6 % faster (results/fixed-threads/, results/performance/modal_speed.csv)


def solver_threads() -> int:
    """Threads of PARDISO and of the model builds' BLAS: ``BEARINGSHAFT_THREADS`` if set, else
    :data:`DEFAULT_THREADS` (fixed, so that a run does not depend on the machine's load or cores)."""
    env = os.environ.get("BEARINGSHAFT_THREADS")
    return max(1, int(env)) if env else DEFAULT_THREADS


def free_cores() -> int:
    """Cores not busy with other work now: cpu_count - 1-minute load average, at least 1.

    ``BEARINGSHAFT_THREADS`` overrides. OpenMP threads that share a core with another busy
    process spin at every barrier: on this 2-core machine with four other jobs running, PARDISO
    factorized the 112,629-DOF matrix in 10.0 s on one thread and 21.4 s on two.
    """
    env = os.environ.get("BEARINGSHAFT_THREADS")
    if env:
        return max(1, int(env))
    n = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = 0.0
    return int(max(1, min(n, round(n - load + 0.5))))


def _openblas_libs() -> list[ctypes.CDLL]:
    """The OpenBLAS libraries loaded in this process (numpy's and scipy's are separate)."""
    libs = []
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower() and ".so" in line.split()[-1]}
    except OSError:
        return libs
    for p in sorted(paths):
        with contextlib.suppress(OSError):
            libs.append(ctypes.CDLL(p))
    return libs


def _openblas_calls(lib: ctypes.CDLL):
    for prefix in ("scipy_openblas", "openblas"):
        for suffix in ("64_", ""):
            try:
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}")
                return get, getattr(lib, f"{prefix}_set_num_threads{suffix}")
            except AttributeError:
                continue
    return None


@contextlib.contextmanager
def blas_threads(n: int):
    """OpenBLAS (numpy's and scipy's) limited to ``n`` threads inside the block.

    Parameters
    ----------
    n : int
        Threads allowed to every OpenBLAS library loaded in the process (numpy's and scipy's); the
        previous counts come back on leaving the block. Libraries without the thread calls are left
        alone.

    Yields
    ------
    None
    """
    import scipy.linalg  # noqa: F401  (loads scipy's OpenBLAS so that it is found)

    saved = []
    for lib in _openblas_libs():
        calls = _openblas_calls(lib)
        if calls is None:
            continue
        get, set_ = calls
        saved.append((set_, int(get())))
        set_(ctypes.c_int(n))
    try:
        yield
    finally:
        for set_, old in saved:
            set_(ctypes.c_int(old))


class PardisoCholesky:
    """A = L L^T of a sparse symmetric positive definite matrix by MKL PARDISO (mtype 2).

    The upper triangle in zero-based CSR is handed over once; blocks of right-hand sides are
    solved together (column-major, BLAS-3). ``stats``: factor non-zeros, MFLOP, phase times.

    Parameters
    ----------
    A : (n, n) sparse matrix
        Symmetric positive definite; only its upper triangle is read (duplicates summed).
    n_threads : int, optional
        MKL threads (default: :func:`solver_threads`, fixed: the same bits whatever the load).
    iparm : dict of int to int, optional
        PARDISO control entries (zero-based index: value) that override ``IPARM``.
    upper : bool
        A is already its upper triangle in canonical CSR (sorted columns, no duplicates), as
        :func:`fem._assembly.upper_sum` makes it: handed over as it is.

    Attributes
    ----------
    n : int
        Order of A.
    n_threads : int
        MKL threads used.
    stats : dict
        ``factor_nnz`` (non-zeros of L), ``factor_mflop``, ``analyse_s`` and ``factor_s`` (s, the
        reordering and the numerical factorization; ``analyse_cpu_s`` and ``factor_cpu_s`` their CPU
        seconds, all threads), ``n_threads``, ``peak_analysis_kib`` and
        ``peak_factor_kib`` (KiB, PARDISO's own memory peaks).

    Raises
    ------
    RuntimeError
        PARDISO reports an error (A not positive definite: error -4; out of memory: -2 or -9).
    """

    def __init__(self, A: sp.spmatrix, n_threads: int | None = None, iparm: dict | None = None,
                 upper: bool = False) -> None:
        import time

        self._lib = libmkl()
        self.n_threads = solver_threads() if n_threads is None else int(n_threads)
        if upper:  # already the upper triangle, canonical CSR (fem._assembly.upper_sum)
            U = sp.csr_matrix(A)
        else:
            U = sp.triu(A, format="csr")
            U.sum_duplicates()
            U.sort_indices()
        self.n = U.shape[0]
        self._data = np.ascontiguousarray(U.data, dtype=np.float64)
        self._ia = np.ascontiguousarray(U.indptr, dtype=np.int32)
        self._ja = np.ascontiguousarray(U.indices, dtype=np.int32)
        del U
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)
        for k, v in {**IPARM, **(iparm or {})}.items():
            self._iparm[k] = v
        self._perm = np.zeros(1, dtype=np.int32)
        self._alive = False
        c0, t0 = time.process_time(), time.perf_counter()
        self._call(11, np.zeros((self.n, 1), order="F"))
        self._alive = True
        c1, t1 = time.process_time(), time.perf_counter()
        self._call(22, np.zeros((self.n, 1), order="F"))
        c2, t2 = time.process_time(), time.perf_counter()
        self.stats = {"factor_nnz": int(self._iparm[17]), "factor_mflop": int(self._iparm[18]),
                      "analyse_s": t1 - t0, "factor_s": t2 - t1, "analyse_cpu_s": c1 - c0, "factor_cpu_s": c2 - c1,
                      "n_threads": self.n_threads,
                      "peak_analysis_kib": int(self._iparm[14]), "peak_factor_kib": int(self._iparm[15])
                      + int(self._iparm[16])}

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        ct, lib = ctypes, self._lib
        x = np.zeros_like(b)
        err = ct.c_int32(0)
        one = ct.byref(ct.c_int32(1))
        lib.MKL_Set_Num_Threads(ct.c_int(self.n_threads))
        lib.pardiso(self._pt.ctypes.data_as(ct.c_void_p), one, one,
                    ct.byref(ct.c_int32(MTYPE_SPD)), ct.byref(ct.c_int32(phase)), ct.byref(ct.c_int32(self.n)),
                    self._data.ctypes.data_as(ct.c_void_p), self._ia.ctypes.data_as(ct.c_void_p),
                    self._ja.ctypes.data_as(ct.c_void_p), self._perm.ctypes.data_as(ct.c_void_p),
                    ct.byref(ct.c_int32(b.shape[1])), self._iparm.ctypes.data_as(ct.c_void_p),
                    ct.byref(ct.c_int32(0)), b.ctypes.data_as(ct.c_void_p), x.ctypes.data_as(ct.c_void_p),
                    ct.byref(err))
        if err.value != 0:
            raise RuntimeError(f"PARDISO failed in phase {phase} with error {err.value}"
                               + (" (matrix not positive definite)" if err.value == -4 else "")
                               + (" (not enough memory)" if err.value in (-2, -9) else ""))
        return x

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x = A^-1 b for a vector or an (n, k) block."""
        vec = b.ndim == 1
        B = np.asfortranarray(b.reshape(self.n, -1), dtype=np.float64)
        x = self._call(33, B)
        return x.ravel() if vec else x

    def free(self) -> None:
        if self._alive:
            self._alive = False
            self._call(-1, np.zeros((self.n, 1), order="F"))

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.free()


@contextlib.contextmanager
def fixed_threads():
    """OpenBLAS held to :func:`solver_threads` inside the block: a model build (factorizations,
    ARPACK, dense products) then gives the same bits whatever the machine's core count.

    Yields
    ------
    None
    """
    with blas_threads(solver_threads()):
        yield
