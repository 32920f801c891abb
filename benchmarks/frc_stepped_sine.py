"""Forced response: the dense stepped-sine reference and the speed of HB against it (~5-10 min).

    PYTHONPATH=. python benchmarks/frc_stepped_sine.py [--scene discrete-frc] [--points 100]
        [--out results/frc-stepped-sine]

The ``frc`` stage of the built-in ``discrete-frc`` (or ``rom-frc``) scene runs a stepped sine
of 24 frequencies per level and direction; this benchmark runs the dense one, for the same
model, load point and levels:

- ``frc_stepped_sine.csv`` (science): every level swept up and down over ``--points``
  frequencies (60 % log-spaced over the band, 40 % over the jump region 15-50 Hz where the
  contact levels fold), settled to 1e-6, each settled point against the HB solution at
  exactly its frequency on the stable branch it landed on (H = the scene's ``harmonics``);
- ``frc_stepped_sine_work_timing.csv``: the stepped sine's error against the settle tolerance
  and its run time (the sweep of every level at each tolerance; the error against HB at H = 1
  on the stable branches, where the settled points lie and HB is exact: they do not touch the
  stops), and HB's error against H and its run time (the curve of every level; ``max_rel_err``
  against the settled stepped-sine points, ``*_vs_shooting`` against the exact periodic
  orbits found by multiple shooting from each H's own orbits at contact points, the unstable
  orbits no sweep can reach);
- ``frc_speed_timing.csv`` and ``frc_speed_timing.png``: for each accuracy, the time of the
  cheapest stepped sine and of the cheapest HB curve that reach it on what both give (the
  stable branches), and their ratio.

Written through the same staged output as the stages (``bearingshaft.output.staged_output``):
the folder is swapped in whole, with the scene and provenance.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bearingshaft.digits import sig  # noqa: E402
from bearingshaft.output import staged_output, write_rows  # noqa: E402
from bearingshaft.scenes import load_scene  # noqa: E402
from bearingshaft.stages.frc import _in_contact, shooting_error  # noqa: E402
from bearingshaft.systems import model_system  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.models.loads import Harmonic, Loads  # noqa: E402
from reduced.periodic.frc import frc, solution_at_frequency  # noqa: E402
from reduced.periodic.stepped_sine import stepped_sine  # noqa: E402

TOLERANCES = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8)  # stepped-sine settle tolerances of the work study
HARMONICS = (1, 3, 5, 9, 15, 21, 25, 31)  # HB orders of the work study
JUMP_BAND_HZ = (15.0, 50.0)  # where the contact levels of discrete-frc fold
JUMP_SHARE = 0.4
ACCURACIES = (1e-2, 1e-3, 1e-4, 1e-5)  # relative amplitude errors of the speed comparison
CONTACT_TARGETS = 8  # contact frequencies per level at which HB is checked against exact orbits


def frequencies(fmin: float, fmax: float, n: int) -> np.ndarray:
    n_jump = int(round(JUMP_SHARE * n))
    lo, hi = max(JUMP_BAND_HZ[0], fmin), min(JUMP_BAND_HZ[1], fmax)
    jump = np.linspace(lo, hi, n_jump) if hi > lo else np.zeros(0)
    return np.unique(np.round(np.concatenate([np.geomspace(fmin, fmax, n - jump.size), jump]), 9))


def hb_error(br, ss, load_col: int) -> list[float]:
    """Relative errors of HB against the settled points of a stepped sine (max over the points)."""
    out = []
    for j, f in enumerate(ss.freq_hz):
        if ss.response[j] != "periodic":
            continue
        a, _, _ = solution_at_frequency(br, float(f), float(ss.amplitude_m[j, load_col]), load_col)
        if a is not None:
            out.append(float(np.max(np.abs(a / ss.amplitude_m[j] - 1.0))))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discrete-frc")
    ap.add_argument("--points", type=int, default=100, help="frequencies per level and direction")
    ap.add_argument("--out", default="results/frc-stepped-sine")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    spec = scene.frc
    t_start = time.perf_counter()
    with single_thread_blas(), staged_output(args.out, "frc-stepped-sine", scene.source, "frc_stepped_sine") as w:
        system, rows = model_system(scene.model)
        names = tuple(scene.model.point_names)
        col = names.index(spec.point)
        b = rows[col]
        fr = frequencies(spec.freq_min_hz, spec.freq_max_hz, args.points)
        levels = list(spec.levels_N)
        bar = tqdm(total=len(levels) * (2 + len(TOLERANCES) + len(HARMONICS)), disable=args.no_progress,
                   desc="frc stepped sine", unit="task")
        opts = dict(harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                    max_steps=spec.max_steps)
        science, work = [], []
        for P in levels:
            ref = frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, spec.harmonics, hill_points=0, **opts)
            sweeps = {}
            for d, freqs in (("up", fr), ("down", fr[::-1])):
                bar.set_postfix_str(f"{P:g} N {d}")
                sweeps[d] = stepped_sine(system, b, P, freqs, point_rows=rows, point_names=names, settle_tol=1e-6,
                                         max_settle_s=spec.stepped_sine_max_s)
                ss = sweeps[d]
                for j, f in enumerate(ss.freq_hz):
                    r = {"level": P, "direction": d, "freq_hz": sig(float(f), 10), "response": ss.response[j],
                         "settle_error": sig(float(ss.settle_error[j]), 3), "asymmetry": sig(float(ss.asymmetry[j]), 3)}
                    for c, nm in enumerate(names):
                        r[f"amplitude_{nm}_m"] = sig(float(ss.amplitude_m[j, c]), 10)
                    a = None
                    if ss.response[j] in ("periodic", "settling"):
                        a, _, _ = solution_at_frequency(ref, float(f), float(ss.amplitude_m[j, col]), col)
                    r["hb_amplitude_m"] = sig(float(a[col]), 10) if a is not None else ""
                    r["rel_err_hb"] = (sig(float(np.max(np.abs(a / ss.amplitude_m[j] - 1.0))), 3)
                                       if a is not None else "")
                    science.append(r)
                bar.update()
            # the stepped sine's own accuracy against its run time (HB is exact off contact)
            for tol in TOLERANCES:
                bar.set_postfix_str(f"{P:g} N tol {tol:g}")
                t0 = time.perf_counter()
                ups = stepped_sine(system, b, P, fr, point_rows=rows, point_names=names, settle_tol=tol,
                                   max_settle_s=spec.stepped_sine_max_s)
                dns = stepped_sine(system, b, P, fr[::-1], point_rows=rows, point_names=names, settle_tol=tol,
                                   max_settle_s=spec.stepped_sine_max_s)
                wall = time.perf_counter() - t0
                errs = hb_error(ref, ups, col) + hb_error(ref, dns, col)
                work.append({"level": P, "method": "stepped_sine", "setting": f"tol={tol:g}", "points": 2 * fr.size,
                             "max_rel_err": sig(max(errs), 3) if errs else "", "n_compared": len(errs),
                             "wall_s": round(wall, 3)})
                bar.update()
            # HB against H: the exact orbits nearest each H's orbits at contact frequencies
            contact = np.flatnonzero(_in_contact(system, ref))
            pick = np.unique(np.round(np.linspace(0, max(contact.size - 1, 0), min(CONTACT_TARGETS, contact.size))))
            targets = [(float(ref.freq_hz[i]), float(ref.amplitude_m[i, col])) for i in contact[pick.astype(int)]]
            for H in HARMONICS:
                bar.set_postfix_str(f"{P:g} N H={H}")
                t0 = time.perf_counter()
                br = frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, H, stability=False, **opts)
                wall = time.perf_counter() - t0
                e_ss = hb_error(br, sweeps["up"], col) + hb_error(br, sweeps["down"], col)
                e_sh, fails = [], 0
                for f, a_ref in targets:
                    a, _, X = solution_at_frequency(br, f, a_ref, col, stable_only=False)
                    if a is None:
                        fails += 1
                        continue
                    e = shooting_error(system, Loads(b[None, :], (Harmonic(P, f),)), X, a, f, rows,
                                       spec.shooting_segments)
                    if e is None:
                        fails += 1
                        continue
                    e_sh.append(e)
                work.append({"level": P, "method": "hb", "setting": f"H={H}", "points": len(br.freq_hz),
                             "max_rel_err": sig(max(e_ss), 3) if e_ss else "", "n_compared": len(e_ss),
                             "max_rel_err_vs_shooting": sig(max(e_sh), 3) if e_sh else "",
                             "median_rel_err_vs_shooting": sig(float(np.median(e_sh)), 3) if e_sh else "",
                             "n_vs_shooting": len(e_sh), "n_shooting_failed": fails, "status": br.status,
                             "wall_s": round(wall, 3)})
                bar.update()
        bar.close()
        write_rows(w.path("frc_stepped_sine.csv"), science)
        fields = ["level", "method", "setting", "points", "n_compared", "max_rel_err", "n_vs_shooting",
                  "max_rel_err_vs_shooting", "median_rel_err_vs_shooting", "n_shooting_failed", "status", "wall_s"]
        write_rows(w.path("frc_stepped_sine_work_timing.csv"), work, fields=fields)
        speed = []
        for P in levels:
            for acc in ACCURACIES:
                def cheapest(method, P=P, acc=acc):
                    ok = [r for r in work if r["level"] == P and r["method"] == method and r["max_rel_err"] != ""
                          and float(r["max_rel_err"]) <= acc]
                    return min(ok, key=lambda r: r["wall_s"]) if ok else None
                s_, h_ = cheapest("stepped_sine"), cheapest("hb")
                speed.append({"level": P, "accuracy": acc,
                              "stepped_sine": s_["setting"] if s_ else "not reached",
                              "stepped_sine_s": s_["wall_s"] if s_ else "",
                              "hb": h_["setting"] if h_ else "not reached", "hb_s": h_["wall_s"] if h_ else "",
                              "ratio": round(s_["wall_s"] / h_["wall_s"], 2) if s_ and h_ and h_["wall_s"] > 0 else ""})
        write_rows(w.path("frc_speed_timing.csv"), speed)
        _plot(w.path("frc_speed_timing.png"), work, levels)
        w.stats["frc_stepped_sine"] = {"points": int(fr.size), "levels": levels,
                                       "wall_s": round(time.perf_counter() - t_start, 1)}
    print(f"[frc-stepped-sine] {args.out} ({time.perf_counter() - t_start:.1f} s)")
    return 0


def _plot(path, work, levels) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.8))
    for i, P in enumerate(levels):
        for method, mk in (("stepped_sine", "s--"), ("hb", "o-")):
            r = [x for x in work if x["level"] == P and x["method"] == method and x["max_rel_err"] != ""]
            if not r:
                continue
            ax.loglog([x["wall_s"] for x in r], [max(float(x["max_rel_err"]), 1e-16) for x in r], mk, color=f"C{i}",
                      label=f"{P:g} N, {'stepped sine (tol)' if method == 'stepped_sine' else 'HB (H)'}")
            for x in r:
                ax.annotate(x["setting"].split("=")[1], (x["wall_s"], max(float(x["max_rel_err"]), 1e-16)), fontsize=5)
    ax.set_xlabel("run time of the whole curve [s] (this run; varies with machine load)")
    ax.set_ylabel("max relative amplitude error")
    ax.set_title("Forced response: HB against a stepped sine by the exact integrator", fontsize=9)
    ax.grid(True, which="both", alpha=0.2)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
