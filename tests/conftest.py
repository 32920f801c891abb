"""Fixtures shared by several test files: models built once per test session (issue 28).

Under pytest-xdist each worker is its own process, so a session fixture alone would still be built once per
worker. :func:`_once` builds the value in the first worker that asks for it and pickles it into the session's
common temporary folder; the other workers wait on a file lock and load it (pickle gives back the same arrays bit
for bit, so a test sees exactly the model it would have built itself).
"""

from __future__ import annotations

import csv
import fcntl
import os
import pickle
import sys
from collections import defaultdict
from pathlib import Path

import pytest


def _once(tmp_path_factory, worker_id: str, name: str, build):
    if worker_id == "master":  # no xdist (-n 0): one process, the session fixture is enough
        return build()
    root = tmp_path_factory.getbasetemp().parent  # common to every worker of this session
    path = root / f"{name}.pickle"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if path.exists():
                return pickle.loads(path.read_bytes())
            value = build()
            part = path.with_suffix(".part")
            part.write_bytes(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))
            part.replace(path)
            return value
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def assembly_rom20(tmp_path_factory, worker_id):
    """(rom, fe): the 3-D apparatus (assembly layout, every mode: planar = false, hex20) reduced to 20
    fixed-interface modes, as test_hammer.py, test_hammer_oblique.py and test_frf.py use it; built once instead
    of once per file. The reduced model comes from the model cache ($BEARINGSHAFT_CACHE, as rom-fep's does in
    test_rom_fep.py), built and stored there if absent (~11 s CPU to mesh, assemble and reduce); the 3-D model is
    meshed (mesh cache) and assembled again (~2 s). A cached model is the build's bits
    (reduced.models.rom.reduction; test_cache.py). Both are frozen dataclasses: no test can change them."""

    def build():
        from reduced.models.rom import RomSpec, build_fe, build_rom, from_cache, store_in_cache

        spec = RomSpec(layout="assembly", planar=False, n_modes=20)
        rom = from_cache(spec)
        if rom is not None:
            return rom, build_fe(spec)
        rom, fe = build_rom(spec)
        store_in_cache(rom, spec)
        return rom, fe

    return _once(tmp_path_factory, worker_id, "assembly_rom20", build)


# --- Bytecode kept between runs (issue 28) ---------------------------------------------------------------------
# Python compiles a module's source on every import unless a current .pyc sits in its __pycache__, and pytest does
# the same for the assertion-rewritten test files. With PYTHONDONTWRITEBYTECODE set (this machine's environment
# sets it) none is ever written: each xdist worker, and each process a test starts (the forked command-line server,
# Dask workers, `python -m bearingshaft.cli` children), compiles the four packages and the test files again,
# every run. Measured on this machine: collecting the suite 13.3 -> 7.5 s CPU a worker, importing the command line
# 2.4 -> 1.7 s a process. So the suite writes bytecode (into __pycache__, which git ignores; Python checks a .pyc
# against its source's mtime and size, so an edit is never hidden by a stale one): here for this process, which
# imports the test files after this one, and through the environment for every process it starts, the xdist
# workers included (they are started after this file is read). SUITE_WRITES_BYTECODE = False keeps the user's
# setting.
SUITE_WRITES_BYTECODE = True
if SUITE_WRITES_BYTECODE:
    sys.dont_write_bytecode = False
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)


# --- One BLAS thread a worker (issue 28) -------------------------------------------------------------------------
# With a pytest-xdist worker on every core, each worker's OpenBLAS (and MKL, pypardiso's) would start a thread per
# core as well: 2 x 2 threads on 2 busy cores, whose spinning waits cost CPU time and gain nothing. The controller
# sets these before it starts the workers (a library reads them when it loads), unless the user set them; the
# workers and every process they start (Dask workers, command-line children) inherit them. The stages that do
# dense algebra run on one BLAS thread already (reduced._blas.single_thread_blas); this reaches the rest (model
# builds, the tests' own references). With -n 0 nothing changes: one process may use every core.
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def pytest_configure(config):
    workers = getattr(config.option, "numprocesses", None) or 0  # an int by now (xdist's pytest_cmdline_main)
    if hasattr(config, "workerinput") or not isinstance(workers, int) or workers < (os.cpu_count() or 1):
        return
    for name in BLAS_THREAD_VARS:
        os.environ.setdefault(name, "1")


# --- Scheduling: the longest files first (issue 28) --------------------------------------------------------------
# With --dist loadfile a file is one unit of work and xdist hands the units out in collection order (with
# --no-loadscope-reorder; its default reorders by the number of tests, which has little to do with time). The wall
# time of the suite is the busier worker's: a 40 s file handed out last leaves the other worker idle for 40 s. So
# the files are collected longest first (greedy longest-processing-time scheduling, within a few seconds of the
# best split on 2 workers), by the seconds each took in a recorded run: tests/file_seconds.csv, rewritten by
#     PYTHONPATH=. python -m pytest --file-seconds tests/file_seconds.csv
# A file missing from it (a new one) counts as 0 s: it runs after the recorded ones, in name order.
FILE_SECONDS = Path(__file__).with_name("file_seconds.csv")


def pytest_addoption(parser):
    parser.addoption("--file-seconds", metavar="CSV", default=None,
                     help="write the seconds (setup + call + teardown) each test file took to CSV (issue 28)")


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(session, config, items):
    try:
        rows = csv.DictReader(FILE_SECONDS.open())
        seconds = {r["file"]: float(r["seconds"]) for r in rows}
    except FileNotFoundError:
        return
    items.sort(key=lambda item: -seconds.get(_file_of(item.nodeid), 0.0))  # stable: name order otherwise


_spent: dict[str, float] = defaultdict(float)


def pytest_runtest_logreport(report):
    _spent[_file_of(report.nodeid)] += report.duration  # under xdist, the controller sees every worker's reports


def pytest_sessionfinish(session, exitstatus):
    path = session.config.getoption("--file-seconds")
    if not path or hasattr(session.config, "workerinput"):  # the controller writes it, not each worker
        return
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["file", "seconds"])
        for name, s in sorted(_spent.items(), key=lambda kv: (-kv[1], kv[0])):
            w.writerow([name, f"{s:.2f}"])
