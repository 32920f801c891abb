"""``bearingshaft`` command lines in child processes that start with the package already imported, for tests (not a
test module; issue 28).

A child started by ``python -c "from bearingshaft.cli import main; ..."`` spends ~1.3 s of CPU importing before it
runs a 0.01 s ringdown; tests/test_results_folder.py starts 23 of them. Here the children are forked from a small
server: a fresh single-threaded interpreter (started once per test process, with the test process's ``sys.path``,
so it imports the same code) that imports :data:`PRELOAD` and then forks one child per command line. Each child is
a process of its own with its own pid, environment, stdout and stderr, run from the top of
``bearingshaft.cli.main`` and killable by SIGKILL at any moment, as a fresh ``bearingshaft`` process is; only the
imports are shared. The server reaps the children and reports how each ended.

Protocol (one JSON line each way, requests answered in order): ``{"start": [argv, env, out, err]}`` -> ``{"pid":
N}``; ``{"wait": [pid, timeout_s]}`` -> ``{"status": S}`` (the exit code, or minus the signal's number as in
:class:`subprocess.Popen`) or ``{"status": null}`` if the child is still running after the timeout.
"""

from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
from pathlib import Path

PRELOAD = ("bearingshaft.cli", "bearingshaft.stages.ringdown_files")  # the CLI, a ringdown's files and figure

_SERVER = r"""
import json, os, sys, time, traceback
sys.path[:] = json.loads(sys.argv[1])
for name in json.loads(sys.argv[2]):
    __import__(name)
from bearingshaft.cli import main


def child(argv, env, out, err):
    os.environ.update(env)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    for fd, path in ((1, out), (2, err)):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(f, fd)
        os.close(f)
    code = 1
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def status(pid, timeout):
    end = time.monotonic() + timeout
    while True:
        done, st = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(st)
        if time.monotonic() > end:
            return None
        time.sleep(0.01)


for line in sys.stdin:
    req = json.loads(line)
    if "start" in req:
        pid = os.fork()
        if pid == 0:
            child(*req["start"])
        reply = {"pid": pid}
    else:
        reply = {"status": status(*req["wait"])}
    sys.stdout.write(json.dumps(reply) + "\n")
    sys.stdout.flush()
while True:  # input closed: reap what is left
    try:
        os.wait()
    except ChildProcessError:
        break
"""

_server: subprocess.Popen | None = None


def _ask(request: dict) -> dict:
    global _server
    if _server is None or _server.poll() is not None:
        _server = subprocess.Popen([sys.executable, "-c", _SERVER, json.dumps(sys.path), json.dumps(PRELOAD)],
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        atexit.register(_stop, _server)
    _server.stdin.write(json.dumps(request) + "\n")
    _server.stdin.flush()
    line = _server.stdout.readline()
    if not line:
        raise RuntimeError(f"the fork server of tests/forked_cli.py died (exit status {_server.wait()})")
    return json.loads(line)


def _stop(server: subprocess.Popen) -> None:
    """The server ends at the end of its input, after reaping its children (so that their CPU time is counted in
    this process's, as a subprocess's is)."""
    server.stdin.close()
    try:
        server.wait(timeout=60)
    except subprocess.TimeoutExpired:
        server.kill()


class Child:
    """A started command line, with the part of :class:`subprocess.Popen` the tests use."""

    def __init__(self, argv: list[str], env: dict[str, str] | None, logs: Path) -> None:
        n = len(list(logs.glob("child-*.out")))
        self._out, self._err = logs / f"child-{n}.out", logs / f"child-{n}.err"
        self._out.touch()
        self.argv = argv
        self.returncode: int | None = None
        self.pid = _ask({"start": [argv, env or {}, str(self._out), str(self._err)]})["pid"]

    def send_signal(self, sig: int) -> None:
        if self.returncode is None:
            os.kill(self.pid, sig)  # a zombie until the server reaps it in wait(): never another process

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            self.returncode = _ask({"wait": [self.pid, 1e9 if timeout is None else timeout]})["status"]
            if self.returncode is None:
                os.kill(self.pid, 9)
                self.returncode = _ask({"wait": [self.pid, 1e9]})["status"]
                raise subprocess.TimeoutExpired(self.argv, timeout)
        return self.returncode

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        self.wait(timeout)
        return self._out.read_text(), self._err.read_text() if self._err.exists() else ""


def start(argv: list[str], logs: Path, env: dict[str, str] | None = None) -> Child:
    """Start ``bearingshaft ARGV`` in a forked child; its stdout and stderr go to files in ``logs``."""
    logs.mkdir(parents=True, exist_ok=True)
    return Child(argv, env, logs)
