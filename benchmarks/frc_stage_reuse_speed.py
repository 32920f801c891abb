"""CPU the frc stage's cuts of issue 28 save, per scene, measured in one process (before and after alternating).

    PYTHONPATH=. python benchmarks/frc_stage_reuse_speed.py [--scene rom-frc] [--level 10] [--repeats 3]
        [--out /tmp/frc-stage-reuse-speed]

- ``first orbit``: :func:`reduced.periodic.exact_frc.first_orbit` of the level from its HB orbit at f_min (the
  stage's first guess), the load residual eager (R at P e^h, then R and J at P at every trial point: the code
  before) and lazy (J and the load difference only at points Newton takes), alternating, medians of
  ``--repeats``; the continuation's points (or the orbit) are checked equal to the bit.
- ``convergence H = harmonics`` and ``backbone H = 1``: the CPU of the two curves without stability at
  ``convergence_level_N`` the stage no longer computes (the level's own curve, and the study's, are taken), and
  of :func:`bearingshaft.stages.frc._without_stability` that replaces the first.

CPU seconds (``time.process_time``), BLAS on one thread; the 1-minute load is recorded with each row. Writes
``frc_stage_reuse_speed.csv`` into ``--out``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bearingshaft.output import write_rows  # noqa: E402
from bearingshaft.scenes import load_scene  # noqa: E402
from bearingshaft.stages.frc import _curve, _without_stability  # noqa: E402
from bearingshaft.stages.frc_friction import load_vector  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.periodic import exact_frc as E  # noqa: E402
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual  # noqa: E402
from reduced.periodic.forced_stability import hb_states  # noqa: E402


def _load() -> float:
    try:
        return float(Path("/proc/loadavg").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return float("nan")


class _Eager(E._LoadResidual):
    """The load residual as it was before (main at b7c21d3): every trial point with its Jacobian."""

    lazy = None  # continue_branch then calls __call__ at every trial point

    def __call__(self, y):
        h = 1e-7
        Rp = self._at(y, y[self.size] + h, jacobian=False)
        R, J = self._at(y, y[self.size])
        Jy = J.copy()
        Jy[:, self.size] = (Rp - R) / h
        return R, Jy


def _first_orbit(system, b, P, spec, br, cls) -> np.ndarray:
    """The stage's first orbit of level P with the load residual ``cls``: its point, or the points of the load
    continuation that failed (the stage then tries its next guess)."""
    seen = []
    orig_lr, orig_cb = E._LoadResidual, E.continue_branch

    def cb(*a, **k):
        out = orig_cb(*a, **k)
        seen.append(out)
        return out

    E._LoadResidual, E.continue_branch = cls, cb
    try:
        S = spec.shooting_segments + spec.shooting_segments % 2
        opts = E.ExactFRCOptions(segments=S)
        omega_v = None
        if opts.velocity_scale == "fastest":
            omega_v = float(np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(system.M, system.K)).real)))
        res = ShootingResidual(ForcedFlow(system, b, P), S, 1, br.x_ref, 2 * math.pi * spec.freq_max_hz, omega_v)
        try:
            return E.first_orbit(res, hb_states(br.X[0], float(br.omega[0]), S), float(br.omega[0]))
        except E.ShootingError:
            return seen[-1].y.ravel() if seen else np.zeros(0)
    finally:
        E._LoadResidual, E.continue_branch = orig_lr, orig_cb


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="rom-frc")
    ap.add_argument("--level", type=float, default=10.0, help="N, the level of the first orbit")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="/tmp/frc-stage-reuse-speed")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    spec = scene.frc
    system, rows = model_system(scene.model)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)  # the stage's own load direction
    out = []
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps, as the stage
        br = _curve(system, b, args.level, spec, spec.harmonics, rows, names, hill_points=0)
        _first_orbit(system, b, args.level, spec, br, E._LoadResidual)  # numba's kernels loaded
        cpu = {"eager": [], "lazy": []}
        got = {}
        for r in range(args.repeats):
            order = (("eager", _Eager), ("lazy", E._LoadResidual))
            for name, cls in order if r % 2 == 0 else order[::-1]:
                c0 = time.process_time()
                y = _first_orbit(system, b, args.level, spec, br, cls)
                cpu[name].append(time.process_time() - c0)
                got.setdefault(name, y)
        same = bool(np.array_equal(got["eager"], got["lazy"]))
        before, after = float(np.median(cpu["eager"])), float(np.median(cpu["lazy"]))
        out.append({"scene": scene.name, "what": f"first orbit at {args.level:g} N", "before_cpu_s": round(before, 3),
                    "after_cpu_s": round(after, 3), "saved_cpu_s": round(before - after, 3),
                    "ratio": round(before / after, 3), "identical": same,
                    "load": _load()})
        Pc = spec.convergence_level_N
        own = _curve(system, b, Pc, spec, spec.harmonics, rows, names, hill_points=0)
        for what, H in (("convergence H = harmonics", spec.harmonics), ("backbone H = 1", 1)):
            c0 = time.process_time()
            bc = _curve(system, b, Pc, spec, H, rows, names, stability=False)
            before = time.process_time() - c0
            c0 = time.process_time()
            st = _without_stability(own) if H == spec.harmonics else bc  # the backbone takes the study's curve
            after = time.process_time() - c0
            same = H != spec.harmonics or bool(np.array_equal(st.z, bc.z) and np.array_equal(st.stable, bc.stable))
            out.append({"scene": scene.name, "what": f"{what} at {Pc:g} N", "before_cpu_s": round(before, 3),
                        "after_cpu_s": round(after, 4), "saved_cpu_s": round(before - after, 3), "ratio": "",
                        "identical": same, "load": _load()})
    for row in out:
        print(row, flush=True)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    write_rows(Path(args.out) / "frc_stage_reuse_speed.csv", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
