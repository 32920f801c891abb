"""Speed of ``bearingshaft frf`` (issue 26): FRFs and modal parameters from averaged blows.

    python benchmarks/frf_speed.py [--repeats 3] [--out results/frf-speed]

Cases, each a child process timed from start to exit (imports, the cached reduced model's load,
the files and figures included; CPU time beside it, as the machine may be shared):

- ``virtual``: ``bearingshaft frf --scene hammer-test``, the virtual test as the scene has it
  (3 references x 5 blows of 2 s at 20 kHz, DAQ and 0.5 % noise, MAC against the 3-D model);
- ``virtual-rom-mac``: the same with ``mac_reference = "rom"`` (no 3-D solve);
- ``test-5-blows``: ``--test`` on a UFF 58 file of 5 blows at one reference (written once from
  the virtual test's blows), MAC against the 3-D model;
- ``test-5-blows-rom-mac``: the same with the reduced rig as MAC reference.

The stage's own step times (provenance.json: model, blows, FRFs, identification, MAC; wall and
CPU) are kept beside the process's wall and CPU time. The target (the issue): FRFs and modal
parameters from 5 averaged blows in under 10 s on 2 cores; ``met`` compares the median wall time
of each case with it; on a shared machine (``load_avg_1min`` above the 2 cores) the CPU times say
what an idle machine would take.

Writes frf_speed.csv (every run), frf_headline.csv (median per case) and frf_machine.csv.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import machine_rows, write_rows  # noqa: E402

TARGET_S = 10.0
STEPS = ("model_s", "blows_s", "frf_s", "identification_s", "mac_s")  # the stage's steps (provenance.json)


def _scene(folder: Path, mac_reference: str) -> Path:
    text = (ROOT / "bearingshaft" / "scenes" / "hammer-test.toml").read_text()
    path = folder / f"hammer-test-{mac_reference}.toml"
    path.write_text(text.replace("max_order = 30", f"max_order = 30\nmac_reference = \"{mac_reference}\""))
    return path


def _test_file(folder: Path) -> Path:
    """5 blows at the first reference of the virtual test, as a measured UFF 58 file."""
    from bearingshaft.scenes import load_scene
    from bearingshaft.stages.frf_virtual import virtual_blows
    from fem.uff import TimeHistory, write_uff58

    scene = load_scene("hammer-test")
    b = virtual_blows(scene, scene.model.reduced(False))
    dt = 1.0 / b.sample_rate_hz
    chans = []
    for a in np.flatnonzero(b.reference == 0)[:5]:
        ref = b.references[0]
        chans.append(TimeHistory(f"hammer blow {a + 1}", ref.node, ref.direction, "force", b.force[a], dt))
        chans += [TimeHistory(o.name, o.node, o.direction, o.quantity, b.responses[a, k], dt)
                  for k, o in enumerate(b.outputs)]
    path = folder / "five-blows.uff"
    write_uff58(path, chans)
    return path


def _run(args: list[str], out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "bearingshaft.cli", "frf", *args, "--out", str(out),
                           "--no-progress"], cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip())
    stats = json.loads((out / "provenance.json").read_text())["stages"]["frf"]["stats"]
    return {"wall_s": wall, "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "load_avg_1min": os.getloadavg()[0], **{k: v for k, v in stats["wall_s"].items()},
            **{f"cpu_{k}": v for k, v in stats.get("cpu_s", {}).items()},
            "blows": stats["blows"], "references": stats["references"], "modes": stats["modes"],
            "worst_freq_error_pct": max(abs(e) for e in stats["freq_error_pct"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", default=str(ROOT / "results" / "frf-speed"))
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        test = _test_file(tmp)
        cases = {"virtual": ["--scene", "hammer-test"],
                 "virtual-rom-mac": ["--scene", str(_scene(tmp, "rom"))],
                 "test-5-blows": ["--scene", "hammer-test", "--test", str(test)],
                 "test-5-blows-rom-mac": ["--scene", str(_scene(tmp, "rom")), "--test", str(test)]}
        _run(cases["virtual-rom-mac"], tmp / "warm-up")  # untimed: the first run of a fresh checkout compiles
        for k in range(a.repeats):
            for name, args in cases.items():
                r = _run(args, tmp / f"{name}-{k}")
                rows.append({"case": name, "repeat": k + 1, **{key: (round(v, 3) if isinstance(v, float) else v)
                                                               for key, v in r.items()}})
                print(name, k + 1, f"{r['wall_s']:.2f} s", flush=True)
    write_rows(out / "frf_speed.csv", rows)
    head = []
    for name in dict.fromkeys(r["case"] for r in rows):
        sel = [r for r in rows if r["case"] == name]
        wall = float(np.median([r["wall_s"] for r in sel]))
        head.append({"case": name, "blows": sel[0]["blows"], "references": sel[0]["references"],
                     "median_wall_s": round(wall, 2),
                     "median_cpu_s": round(float(np.median([r["cpu_s"] for r in sel])), 2),
                     "median_compute_s": round(float(np.median([sum(r[k] for k in STEPS) for r in sel])), 2),
                     "median_compute_cpu_s": round(float(np.median([sum(r.get(f"cpu_{k}", np.nan) for k in STEPS)
                                                                    for r in sel])), 2),
                     "median_frf_and_modes_cpu_s": round(float(np.median([sum(r.get(f"cpu_{k}", np.nan) for k in STEPS
                                                                              if k != "mac_s") for r in sel])), 2),
                     "target_s": TARGET_S, "met": wall < TARGET_S,
                     "worst_freq_error_pct": sel[0]["worst_freq_error_pct"]})
    write_rows(out / "frf_headline.csv", head)
    write_rows(out / "frf_machine.csv", machine_rows())
    for h in head:
        print(h)
    return 0


if __name__ == "__main__":
    sys.exit(main())
