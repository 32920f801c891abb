"""CPU of the fep study (``compute_fep``) with Hill's method by QZ at every point (before issue 28's screen)
against the screened path (QZ where stability.csv writes the multipliers, ``hill_screened`` elsewhere),
interleaved in one process.

    PYTHONPATH=. python benchmarks/fep_stage_cpu.py [discrete-fep] [repeats]

The "before" path is this code with ``nnm_fep.hill_screened`` replaced by ``stability.hill`` (QZ at every
point, as before); prints CPU (time.process_time) and wall of each run.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bearingshaft.scenes.parse import load_scene  # noqa: E402
from bearingshaft.stages import nnm_fep  # noqa: E402
from reduced.periodic import stability  # noqa: E402


def main() -> None:
    scene = load_scene(sys.argv[1] if len(sys.argv) > 1 else "discrete-fep")
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    screened = nnm_fep.hill_screened
    res = {}
    for rep in range(repeats):
        for name in ("old", "new"):
            nnm_fep.hill_screened = stability.hill if name == "old" else screened
            c, w = time.process_time(), time.perf_counter()
            nnm_fep.compute_fep(scene, False)
            res.setdefault(name, []).append((time.process_time() - c, time.perf_counter() - w))
            cpu, wall = res[name][-1]
            print(name, rep, f"cpu {cpu:.2f} s, wall {wall:.2f} s", flush=True)
    nnm_fep.hill_screened = screened
    print(res)


if __name__ == "__main__":
    main()
