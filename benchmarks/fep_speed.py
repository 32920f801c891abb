"""Speed of the frequency-energy study (``bearingshaft nnm --scene discrete-fep``) against the code
before issue 14, at the accuracy that code reaches.

    python benchmarks/fep_speed.py [--repeats 3] [--baseline-commit fc521a5] [--scene discrete-fep]
        [--out results/performance]

The baseline is the same command on the tree of ``--baseline-commit`` (``git archive`` into a
temporary folder, put first on PYTHONPATH). The two cannot share one process (the same package
names), so each run is a child process: ours and the baseline alternate, ``--repeats`` times each,
after one untimed warm-up of each on a trimmed scene (numba compiles the baseline's kernels on its
first run). Wall time is what a user waits for, imports included; CPU time beside it (children's
rusage), as the machine may be shared. The HB and shooting parts come from each run's own
``hb_convergence_timing.csv``.

Accuracy: every run's ``hb_convergence.csv`` holds HB's frequency error against the exact NNM 2
relation and against shooting on the exact flow; the largest difference between ours and the
baseline's of each error column that does not depend on tongue paths (near grazing, above 10x
grazing against the exact relation, above the last tongue against shooting) is reported, with the
number of points in fep.csv.

Writes fep_speed.csv (every run), fep_headline.csv (the summary row: what, ours_s, baseline,
baseline_s, ratio = baseline_s / ours_s, error, target, met) and fep_machine.csv.
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import machine_rows, write_rows  # noqa: E402

TARGET_S = 30.0
# error columns of hb_convergence.csv that do not depend on where a continuation crossed a tongue
STABLE_COLUMNS = ("max_err_vs_exact", "max_err_vs_exact_near_grazing", "max_err_vs_exact_above_10x_grazing",
                  "max_err_vs_shooting_near_grazing", "max_err_vs_shooting_above_last_tongue")
TRIMMED = """
[nnm]
n_energy = 20
[fep]
harmonics = [1, 3]
convergence_harmonics = [1, 3]
samples_study_harmonics = 3
samples = [16]
energy_max_J = 1.0
n_shooting = 3
"""


def _run(tree: Path, scene_arg: str, out: Path) -> dict:
    """One ``bearingshaft nnm`` in a child process on ``tree``: wall and CPU seconds, its folder."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "bearingshaft.cli", "nnm", "--scene", scene_arg, "--out", str(out),
                           "--no-progress"], cwd=out.parent, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: bearingshaft nnm failed:\n{proc.stdout}\n{proc.stderr}")
    m = re.search(r"\(([\d.]+) s\)", proc.stdout)
    return {"wall_s": wall, "stage_s": float(m.group(1)) if m else np.nan,
            "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)}


def _parts(folder: Path) -> dict:
    """Seconds of HB branches and of shooting from the run's own timing file."""
    rows = list(csv.DictReader(open(folder / "hb_convergence_timing.csv")))
    hb = sum(float(r["wall_s"]) for r in rows if r["what"] == "hb branch")
    sh = sum(float(r["wall_s"]) for r in rows if r["what"] == "shooting")
    return {"hb_branches_s": hb, "shooting_s": sh}


def _accuracy(ours: Path, base: Path) -> dict:
    """Largest |ours - baseline| of each tongue-independent error column, and both largest values."""
    a = {(r["nnm"], r["harmonics"], r["samples"]): r for r in csv.DictReader(open(ours / "hb_convergence.csv"))}
    b = {(r["nnm"], r["harmonics"], r["samples"]): r for r in csv.DictReader(open(base / "hb_convergence.csv"))}
    out = {"rows_compared": len(set(a) & set(b))}
    for col in STABLE_COLUMNS:
        diffs, va, vb = [], [], []
        for k in set(a) & set(b):
            x, y = float(a[k].get(col) or "nan"), float(b[k].get(col) or "nan")
            if np.isfinite(x) and np.isfinite(y):  # a nan in max() would make the answer depend on set order
                diffs.append(abs(x - y))
                va.append(x)
                vb.append(y)
        out[f"{col}_maxdiff"] = max(diffs, default=np.nan)
        out[f"{col}_ours"] = max(va, default=np.nan)
        out[f"{col}_baseline"] = max(vb, default=np.nan)
    for name, folder in (("ours", ours), ("baseline", base)):
        out[f"fep_points_{name}"] = sum(1 for _ in open(folder / "fep.csv")) - 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--baseline-commit", default="fc521a5", help="the code before issue 14")
    ap.add_argument("--scene", default="discrete-fep")
    ap.add_argument("--out", default=str(ROOT / "results" / "performance"))
    args = ap.parse_args()
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="fep-speed-") as tmp:
        tmp = Path(tmp)
        base_tree = tmp / "baseline"
        base_tree.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline_commit], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base_tree)], input=archive, check=True)
        trimmed = tmp / "trimmed.toml"
        trimmed.write_text('[model]\nkind = "discrete"\n' + TRIMMED)
        trees = {"ours": ROOT, "baseline": base_tree}
        for name, tree in trees.items():  # warm-up: numba caches, imports
            _run(tree, str(trimmed), tmp / f"warm-{name}")
            print(f"warm-up {name} done", flush=True)
        runs = []
        for k in range(args.repeats):
            for name, tree in trees.items():
                folder = tmp / f"{name}-{k}"
                r = _run(tree, args.scene, folder)
                r.update(_parts(folder), which=name, repeat=k, load_1min=round(os.getloadavg()[0], 2))
                runs.append(r)
                print(f"{name} #{k}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU "
                      f"(HB {r['hb_branches_s']:.1f} s, shooting {r['shooting_s']:.1f} s)", flush=True)
        acc = _accuracy(tmp / "ours-0", tmp / "baseline-0")
        keep = tmp / "kept"
        shutil.copytree(tmp / "ours-0", keep)
    write_rows(out_dir / "fep_speed.csv", [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}
                                           for r in runs])
    med = {w: {c: float(np.median([r[c] for r in runs if r["which"] == w]))
               for c in ("wall_s", "cpu_s", "hb_branches_s", "shooting_s")} for w in trees}
    o, b = med["ours"], med["baseline"]
    col = "max_err_vs_shooting_above_last_tongue"
    err = (f"HB vs exact NNM 2 relation: ours {acc['max_err_vs_exact_ours']:.2g}, before "
           f"{acc['max_err_vs_exact_baseline']:.2g}; HB vs shooting above the last tongue: "
           f"ours {acc[col + '_ours']:.2g}, before {acc[col + '_baseline']:.2g} "
           f"(largest change of a tongue-independent error "
           f"{max(acc[c + '_maxdiff'] for c in STABLE_COLUMNS):.1g}); fep.csv {acc['fep_points_ours']} points "
           f"(before {acc['fep_points_baseline']})")
    write_rows(out_dir / "fep_headline.csv", [
        {"what": f"bearingshaft nnm --scene {args.scene}, wall time with imports (median of {args.repeats}; "
                 f"HB branches {o['hb_branches_s']:.1f} s vs {b['hb_branches_s']:.1f} s, shooting "
                 f"{o['shooting_s']:.1f} s vs {b['shooting_s']:.1f} s)",
         "ours_s": round(o["wall_s"], 2), "baseline": f"the same command before issue 14 ({args.baseline_commit}), "
                                                      "alternating child processes",
         "baseline_s": round(b["wall_s"], 2), "ratio": round(b["wall_s"] / o["wall_s"], 2), "error": err,
         "target": f"<= {TARGET_S:g} s", "met": bool(o["wall_s"] <= TARGET_S)},
        {"what": f"bearingshaft nnm --scene {args.scene}, CPU seconds (median of {args.repeats})",
         "ours_s": round(o["cpu_s"], 2), "baseline": f"the same command before issue 14 ({args.baseline_commit})",
         "baseline_s": round(b["cpu_s"], 2), "ratio": round(b["cpu_s"] / o["cpu_s"], 2), "error": "", "target": "",
         "met": ""},
    ])
    write_rows(out_dir / "fep_machine.csv", machine_rows(
        baseline_commit=args.baseline_commit, load_1min_start=round(load0, 2), **acc))
    print(f"ours {o['wall_s']:.1f} s, before {b['wall_s']:.1f} s: {b['wall_s'] / o['wall_s']:.2f}x; {err}")


if __name__ == "__main__":
    main()
