"""The reduced model's stiff and extreme cases with the stiffest contact (opt-in: ~2 min).

    PYTHONPATH=. python benchmarks/rom_stiff_cases.py [--k-g 3.502e7 1e9 1e11] [--out results/rom-stiff-cases]

The ``study`` stage of ``rom-impulse`` runs its ``[stiff_cases]`` sweep in the main job.
With k_g = 1e11 N/m the exact integrator spends ~80 % of that sweep in six runs of 0.2 s
(up to 210 000 contact events each, and ~240 iterations of its root march per event at
200 m/s, where the march's curvature bound is set by the stiff contact mode at
1.2e6 rad/s): about 110 s of a 135 s sweep on the 2-core development machine. So the
stiffest contact is run here, on demand, with the scene's own model, initial state,
explicit step basis and long runs: this script takes ``rom-impulse`` as built in, keeps
its ``[model]``, ``[initial]`` and ``[ringdown]`` (the step basis), drops the ringdown's
other tables and ``[rom_convergence]``, sets ``[stiff_cases] k_g`` to ``--k-g`` and runs
the ``study`` stage into ``--out``: ``rom_stiff_cases.csv`` (science),
``rom_stiff_cases_timing.csv``, ``study.md``, ``study_timing.md``. The 10 s long runs are of
the first k_g (the nominal 3.502e7 N/m: keep it first; at 1e9 N/m the undamped 10 s run
alone has 1.2 million events).
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from importlib import resources
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import tomli_w  # noqa: E402

from bearingshaft.pipeline import run_stage  # noqa: E402
from bearingshaft.scenes import parse_scene  # noqa: E402

BASE = "rom-impulse"
KEEP = ("description", "model", "initial", "ringdown", "stiff_cases")  # ringdown: its explicit step basis


def scene_text(k_g: list[float]) -> str:
    """The built-in rom-impulse scene with only its stiff cases (k_g replaced) and what they need."""
    data = tomllib.loads((resources.files("bearingshaft") / "scenes" / f"{BASE}.toml").read_text("utf-8"))
    data = {k: v for k, v in data.items() if k in KEEP}
    data["description"] = f"{BASE} stiff and extreme cases with k_g = {k_g} N/m (benchmarks/rom_stiff_cases.py)"
    data["stiff_cases"]["k_g"] = list(k_g)
    return tomli_w.dumps(data)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k-g", type=float, nargs="+", default=[3.502e7, 1e9, 1e11], help="N/m, contact stiffnesses")
    ap.add_argument("--out", default="results/rom-stiff-cases")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    scene = parse_scene(scene_text(args.k_g), "rom-stiff-cases", "benchmarks/rom_stiff_cases.py")
    run_stage(scene, "study", args.out, progress=not args.no_progress)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
