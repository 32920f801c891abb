"""CPU of the Jenkins element's return map (AFT of the friction HB): the numba kernel against the Python loop.

    PYTHONPATH=. python benchmarks/jenkins_loop_speed.py [--samples 512] [--repeats 5] [--calls 2000]

:func:`reduced.periodic.friction_aft.jenkins_loop` marches the return map over two periods in a numba kernel
(session 13); before, the same loop ran in Python (kept in tests/test_friction_aft.py as the bit-for-bit
reference). Both run in this process, interleaved, ``repeats`` times ``calls`` loops on the same input (a
slider that opens, sticks and slips over the period); the medians of CPU time per loop and their ratio are
printed, and the two results are checked to be the same bits. At the discrete-friction-frc scene's 512 samples
(H = 5) the loop ran 42530 times in its stage (cProfile), 0.69 ms each in Python.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_friction_aft import _jenkins_loop_python  # noqa: E402

from reduced.periodic.friction_aft import jenkins_loop  # noqa: E402


def main(argv=None) -> None:
    """Print the CPU per loop of both ways and their ratio (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--calls", type=int, default=2000)
    a = ap.parse_args(argv)
    tau = 2 * np.pi * np.arange(a.samples) / a.samples
    t, N = np.cos(tau) + 0.3 * np.sin(3 * tau), 10.0 * (np.cos(tau + 0.4) + 0.2)
    new = jenkins_loop(t, N, 20.0, 0.3)
    old = _jenkins_loop_python(t, N, 20.0, 0.3)
    same = all(np.array_equal(x, y) for x, y in zip((new.f, new.state, new.anchor, new.sign), old, strict=True))
    cpu = {"python": [], "numba": []}
    for _ in range(a.repeats):
        for name, fn in (("python", _jenkins_loop_python), ("numba", jenkins_loop)):
            c0 = time.process_time()
            for _ in range(a.calls):
                fn(t, N, 20.0, 0.3)
            cpu[name].append((time.process_time() - c0) / a.calls)
    py, nb_ = float(np.median(cpu["python"])), float(np.median(cpu["numba"]))
    print(f"samples {a.samples}: python {py * 1e6:.1f} us, numba {nb_ * 1e6:.1f} us CPU a loop (medians of "
          f"{a.repeats}), ratio {py / nb_:.1f}x; the same bits: {same}")


if __name__ == "__main__":
    main()
