"""Fixtures shared by several test files: models built once per test session (issue 28).

Under pytest-xdist each worker is its own process, so a session fixture alone would still be built once per
worker. :func:`_once` builds the value in the first worker that asks for it and pickles it into the session's
common temporary folder; the other workers wait on a file lock and load it (pickle gives back the same arrays bit
for bit, so a test sees exactly the model it would have built itself).
"""

from __future__ import annotations

import fcntl
import pickle

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
    fixed-interface modes, as test_hammer.py and test_frf.py both use it (~10 CPU s to mesh, assemble and
    reduce; built once instead of once per file). Both are frozen dataclasses: no test can change them."""

    def build():
        from reduced.models.rom import RomSpec, build_rom

        return build_rom(RomSpec(layout="assembly", planar=False, n_modes=20))

    return _once(tmp_path_factory, worker_id, "assembly_rom20", build)
