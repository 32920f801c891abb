"""The suite's own set-up (tests/conftest.py, issue 28): under pytest-xdist with a worker per core, each worker
runs BLAS on one thread."""

from __future__ import annotations

import os

import pytest


def test_an_xdist_worker_runs_blas_on_one_thread(request):
    workers = getattr(request.config, "workerinput", {}).get("workercount", 0)  # 0: no xdist
    if workers < (os.cpu_count() or 1):
        pytest.skip("one process, or fewer workers than cores: BLAS keeps its threads")
    from fem._pardiso import _openblas_calls, _openblas_libs

    assert os.environ["OPENBLAS_NUM_THREADS"] == "1" and os.environ["MKL_NUM_THREADS"] == "1"
    libs = [c for c in map(_openblas_calls, _openblas_libs()) if c is not None]
    assert libs, "no OpenBLAS found to ask"
    assert all(int(get()) == 1 for get, _ in libs)  # read when OpenBLAS loaded: the worker started with them
