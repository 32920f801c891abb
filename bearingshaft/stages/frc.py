"""Stage ``frc``: forced-response curves by harmonic balance under a harmonic load (issue 11).

For each load level P of ``[frc] levels_N`` the load P cos(2 pi f t) acts at ``[frc] point``
and the HB curve (:func:`reduced.periodic.frc.frc`: condensed onto the contact coordinates,
stop forces projected exactly, H = ``harmonics``) is continued in frequency over
[freq_min_hz, freq_max_hz] through its folds. Then:

- stability of every point by the monodromy of the variational equation along the HB orbit,
  by Hill's method at ``hill_points`` points and by the Floquet multipliers of the exact
  periodic orbit, found by multiple shooting on the forced exact flow from the HB orbit, at
  ``shooting_points`` points; folds, branch points, period doublings and Neimark-Sacker
  points where multipliers leave the unit circle;
- the reference: a stepped sine by the exact integrator, swept up and down over
  ``stepped_sine_points`` frequencies (half spread over the band, half over the region
  where the curve folds or is unstable, i.e. the jump region), each settled to
  ``stepped_sine_tol`` before the amplitude is read (:func:`reduced.periodic.frc.stepped_sine`);
  every settled point is compared with the HB solution at exactly its frequency on the
  stable branch it landed on;
- convergence in H at ``convergence_level_N``: each H's curve against the stepped sine
  and against the exact orbits of the shooting points, and its run time;
- the backbone check: with damping and load scaled down together (``backbone_scales``) the
  peak of each curve (H = 1) approaches the NNM backbone computed as the nnm stage does
  (:func:`reduced.periodic.backbones.nnm_branch`, H = 1, AFT with 4096 samples).

Files: ``frc.csv`` (level, method, harmonics, freq_hz, point, amplitude_m, stable,
bifurcation, response: one row per curve point or stepped-sine frequency and per output
point), ``frc.png``, ``frc_harmonics.csv`` (amplitude per harmonic along each curve),
``frc_bifurcations.csv``, ``frc_stability.csv`` (monodromy, Hill and shooting side by side),
``stepped_sine.csv`` (each sweep point: how it settled, its amplitude against HB),
``frc_convergence.csv`` and ``frc_convergence_timing.csv`` / ``.png`` (run times: the
project's ``_timing`` convention, tests/test_reproducible.py), ``frc_backbone.csv`` and
``frc_backbone.png``. Amplitudes are written to :data:`DIGITS` significant digits.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from bearingshaft.digits import sig
from bearingshaft.estimates import FLOAT, HILL_COPIES, Estimate, n_dofs
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.loads import Harmonic, Loads
from reduced.models.modes import linear_modes
from reduced.periodic.backbones import nnm_branch
from reduced.periodic.continuation import ContinuationError
from reduced.periodic.frc import (
    HILL_TOL,
    ShootingError,
    _synthesis,
    floquet_by_shooting,
    forced_hill,
    frc,
    hb_states,
    max_abs_over_period,
    solution_at_frequency,
)
from reduced.periodic.frc import stepped_sine as run_stepped_sine
from reduced.periodic.hb import NewtonError, _derivative_matrix
from reduced.transient.flow import Flow
from reduced.transient.integrate import ringdown

DIGITS = 10  # significant digits of frequencies and amplitudes (a rerun on this machine: identical)
ERR_DIGITS = 3  # relative errors
JUMP_FRACTION = 0.5  # of the stepped-sine frequencies, the part spread over the jump region
JUMP_MARGIN = 1.1  # the jump region: folds and unstable points, widened by this factor on each side
BACKBONE_SAMPLES = 4096  # AFT samples of the H = 1 backbone (its AFT error near grazing ~ N^-2)
BACKBONE_ENERGY_FACTOR = 4.0  # backbones run to this many times the energy of the most energetic peak drawn
BACKBONE_DS = 0.01  # continuation step of the backbones (log10 amplitude): polyline error ~1e-7 at the peaks
ORBIT_SAMPLES = 2048  # samples of one period of an exact orbit for its amplitude


def frc_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Write the frc files (module docstring). Dense algebra on one BLAS thread."""
    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps
        _frc_stage(scene, writer, progress)


def _bool(v) -> str:
    return "true" if v else "false"


def _curve(system, b, P, spec, H, rows, names, **kw):
    """One FRC with the scene's settings; a start that fails is reported, not raised."""
    try:
        return frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, H,
                   harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                   max_steps=spec.max_steps, **kw)
    except ContinuationError as exc:
        return exc


def _evenly(k: int, count: int) -> np.ndarray:
    if count <= 0 or k == 0:
        return np.zeros(0, int)
    return np.unique(np.round(np.linspace(0, k - 1, min(count, k))).astype(int))


def _events(br, load_col: int) -> np.ndarray:
    """Hz, where the sweeps must jump: the folds of the curve, the end of its first stable piece
    (an up sweep leaves it there) and the start of its last (a down sweep leaves it there);
    the peak if there is none of these."""
    if isinstance(br, Exception):
        return np.zeros(0)
    st, f = br.stable, br.freq_hz
    ev = list(f[br.folds])
    for idx in br.pieces():
        change = np.flatnonzero(st[idx][1:] != st[idx][:-1])
        if change.size:
            ev += [f[idx][change[0]], f[idx][change[-1] + 1]]
    if not ev:
        ev = [f[int(np.argmax(br.amplitude_m[:, load_col]))]]
    return np.unique(ev)


def _sweep_freqs(spec, br, load_col: int) -> np.ndarray:
    """Stepped-sine frequencies: half log-spaced over the band; half in the jump region, first just
    below and above each end of a stable piece of the curve (+-1 %, nearest events first), the rest
    spread evenly over the region between the lowest and highest end, widened by JUMP_MARGIN."""
    n = spec.stepped_sine_points
    ev = _events(br, load_col)
    n_jump = int(round(JUMP_FRACTION * n)) if ev.size else 0
    pts = list(np.geomspace(spec.freq_min_hz, spec.freq_max_hz, n - n_jump))
    if n_jump:
        near = []
        for f in ev:  # +-1 % of each event, dropping those within 0.3 % of one already taken
            for g in (0.99 * f, 1.01 * f):
                if all(abs(g / h - 1.0) > 3e-3 for h in near):
                    near.append(g)
        near = near[:n_jump]
        lo, hi = ev.min() / JUMP_MARGIN, ev.max() * JUMP_MARGIN
        rest = n_jump - len(near)
        fill = list(np.linspace(lo, hi, rest + 2)[1:-1]) if rest > 0 else []
        pts += near + fill
    pts = np.array([f for f in pts if spec.freq_min_hz <= f <= spec.freq_max_hz])
    return np.unique(np.round(pts, 9))


def orbit_amplitude(system, loads, orbit, rows) -> np.ndarray:
    """(p,) m, max |r . x| over one period of an exact periodic orbit (sampled, ORBIT_SAMPLES)."""
    r = ringdown(system, orbit.x0, orbit.v0, orbit.period_s, ORBIT_SAMPLES / orbit.period_s, method="exact",
                 loads=loads)
    return np.max(np.abs(r.x @ rows.T), axis=0)


def shooting_error(system, loads, X: np.ndarray, amplitude: np.ndarray, freq_hz: float, rows: np.ndarray,
                   segments: int) -> float | None:
    """max |a_HB / a_exact - 1| over the points ``rows``: the exact forced orbit is found by multiple
    shooting (``segments`` segments) from the HB orbit X at ``freq_hz``; None if shooting fails."""
    try:
        orb = floquet_by_shooting(Flow(system, loads=loads), hb_states(X, 2 * np.pi * freq_hz, segments),
                                  1.0 / freq_hz, tol=1e-10)
    except (ShootingError, RuntimeError):
        return None
    return float(np.max(np.abs(amplitude / orbit_amplitude(system, loads, orb, rows) - 1.0)))


def _frc_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    spec = scene.frc
    system, rows = model_system(scene.model, progress)
    names = tuple(scene.model.point_names)
    load_col = names.index(spec.point)
    b = rows[load_col]
    H = spec.harmonics
    levels = list(spec.levels_N)
    conv_H = [h for h in spec.convergence_harmonics]
    n_tasks = 3 * len(levels) + len(conv_H) + len(levels) * len(spec.backbone_scales) + 1
    bar = tqdm(total=n_tasks, desc=f"{scene.name}: forced response", disable=not progress, unit="task")
    stats = {"curves": {}, "stepped_sine": {}, "stability": {}}

    # -- the curves -----------------------------------------------------------------------
    curves = {}
    for P in levels:
        bar.set_postfix_str(f"HB {P:g} N, H={H}")
        br = _curve(system, b, P, spec, H, rows, names, hill_points=0)
        if isinstance(br, Exception):
            stats["curves"][f"{P:g} N"] = f"failed: {br}"
        else:
            stats["curves"][f"{P:g} N"] = {
                "points": len(br.freq_hz), "status": br.status, "notes": br.notes,
                "folds_hz": [sig(f, 6) for f in br.freq_hz[br.folds]],
                "unstable_points": int(np.sum(~br.stable)), "wall_s": round(br.wall_s, 3),
                "stability_wall_s": round(br.stability_wall_s, 3)}
        curves[P] = br
        bar.update()

    # -- Hill and shooting at selected points -------------------------------------------------
    checks = {}
    for P in levels:
        br = curves[P]
        bar.set_postfix_str(f"Hill and shooting {P:g} N")
        if isinstance(br, Exception):
            checks[P] = []
            bar.update()
            continue
        k = len(br.freq_hz)
        contact_mask = _in_contact(system, br)
        contact = np.flatnonzero(contact_mask)
        shoot_idx = np.unique(np.concatenate([_evenly(k, (spec.shooting_points + 1) // 2),
                                              contact[_evenly(contact.size, spec.shooting_points // 2)]]))
        hill_idx = np.unique(np.concatenate([_evenly(k, spec.hill_points), shoot_idx if spec.hill_points else []])
                             ).astype(int)
        loads_of = {}
        rows_out = []
        for i in sorted(set(hill_idx) | set(shoot_idx)):
            f, w = float(br.freq_hz[i]), float(br.omega[i])
            row = {"index": int(i), "contact": bool(contact_mask[i]), "shot_at": set(shoot_idx.tolist()),
                   "freq_hz": f, "mono": float(np.abs(br.multipliers[i, 0])),
                   "mono_stable": bool(br.stable[i]), "hill": np.nan, "hill_stable": None, "shoot": np.nan,
                   "shoot_stable": None, "shoot_amp": None, "shoot_note": ""}
            if i in hill_idx:
                mu = forced_hill(br.balance, br.z[i], w)
                row["hill"] = float(np.max(np.abs(mu)))
                row["hill_stable"] = row["hill"] <= 1.0 + HILL_TOL
            if i in shoot_idx:
                loads = loads_of.setdefault(f, Loads(b[None, :], (Harmonic(P, f),)))
                try:
                    orb = floquet_by_shooting(Flow(system, loads=loads), hb_states(br.X[i], w, spec.shooting_segments),
                                              1.0 / f, tol=1e-10)
                    row["shoot"] = orb.max_multiplier
                    row["shoot_stable"] = orb.stable
                    row["shoot_amp"] = orbit_amplitude(system, loads, orb, rows)
                except (ShootingError, RuntimeError) as exc:
                    row["shoot_note"] = " ".join(str(exc).split())[:120]
            rows_out.append(row)
        checks[P] = rows_out
        bar.update()

    # -- stepped sine ------------------------------------------------------------------------
    sweeps = {}
    for P in levels:
        bar.set_postfix_str(f"stepped sine {P:g} N")
        if spec.stepped_sine_points == 0:
            sweeps[P] = {}
            bar.update()
            continue
        fr = _sweep_freqs(spec, curves[P], load_col)
        sw = {}
        for direction, freqs in (("up", fr), ("down", fr[::-1])):
            sw[direction] = run_stepped_sine(system, b, P, freqs, point_rows=rows, point_names=names,
                                             settle_tol=spec.stepped_sine_tol, max_settle_s=spec.stepped_sine_max_s)
        sweeps[P] = sw
        bar.update()

    # -- stepped sine against HB ---------------------------------------------------------------
    ss_rows = []
    for P in levels:
        br = curves[P]
        for direction, ss in sweeps[P].items():
            for j, f in enumerate(ss.freq_hz):
                amp_ss = ss.amplitude_m[j]
                row = {"level": P, "direction": direction, "freq_hz": sig(f, DIGITS), "response": ss.response[j],
                       "settle_error": sig(float(ss.settle_error[j]), 3), "settle_s": sig(float(ss.settle_s[j]), 6),
                       "asymmetry": sig(float(ss.asymmetry[j]), 3)}
                for c, nm in enumerate(names):
                    row[f"amplitude_{nm}_m"] = sig(float(amp_ss[c]), DIGITS)
                err, hb_amp = "", ""
                if ss.response[j] in ("periodic", "settling") and not isinstance(br, Exception):
                    a, _, _ = solution_at_frequency(br, float(f), float(amp_ss[load_col]), load_col)
                    if a is not None:
                        hb_amp = sig(float(a[load_col]), DIGITS)
                        err = sig(float(np.max(np.abs(a / amp_ss - 1.0))), ERR_DIGITS)
                row["hb_amplitude_m"] = hb_amp  # at the load point, on the stable branch it landed on
                row["rel_err_hb"] = err  # max over the points of |A_hb / A_stepped - 1|
                ss_rows.append(row)
        if sweeps[P]:
            errs = [r["rel_err_hb"] for r in ss_rows if r["level"] == P and r["rel_err_hb"] != ""]
            stats["stepped_sine"][f"{P:g} N"] = {
                "periodic": sum(r["response"] == "periodic" for r in ss_rows if r["level"] == P),
                "settling": sum(r["response"] == "settling" for r in ss_rows if r["level"] == P),
                "not_settled": sum(r["response"] == "not_settled" for r in ss_rows if r["level"] == P),
                "compared_with_hb": len(errs), "max_rel_err_hb": max(errs) if errs else None,
                "wall_s": {d: round(float(np.sum(s.wall_s)), 3) for d, s in sweeps[P].items()}}
    write_rows(writer.path("stepped_sine.csv"), ss_rows)

    # -- frc.csv, frc_harmonics.csv, frc_bifurcations.csv, frc_stability.csv ---------------------
    rows_csv, harm_rows, bif_rows, stab_rows = [], [], [], []
    for P in levels:
        br = curves[P]
        if not isinstance(br, Exception):
            labels = br.bifurcation_labels()
            for i in range(len(br.freq_hz)):
                for c, nm in enumerate(names):
                    rows_csv.append({"level": P, "method": "hb", "harmonics": H, "freq_hz": sig(br.freq_hz[i], DIGITS),
                                     "point": nm, "amplitude_m": sig(float(br.amplitude_m[i, c]), DIGITS),
                                     "stable": _bool(br.stable[i]), "bifurcation": labels[i], "response": "",
                                     "segment": int(br.segment[i])})
                    for kk in range(min(br.H, 9) + 1):
                        a = float(br.harmonic_amplitude_m[i, c, kk])
                        if spec.odd_harmonics and kk % 2 == 0:
                            continue
                        harm_rows.append({"level": P, "harmonics": H, "index": i, "freq_hz": sig(br.freq_hz[i], DIGITS),
                                          "point": nm, "harmonic": kk, "amplitude_m": sig(a, DIGITS)})
            for i, kind in br.bifurcations:
                bif_rows.append({"level": P, "harmonics": H, "kind": kind, "index": int(i),
                                 "freq_hz": sig(br.freq_hz[i], DIGITS),
                                 "amplitude_m": sig(float(br.amplitude_m[i, load_col]), DIGITS),
                                 "max_abs_mu_before": sig(float(np.abs(br.multipliers[i - 1, 0])), 6),
                                 "max_abs_mu_after": sig(float(np.abs(br.multipliers[i, 0])), 6)})
            for r in checks[P]:
                amp_hb = br.amplitude_m[r["index"]]
                stab_rows.append({
                    "level": P, "harmonics": H, "index": r["index"], "freq_hz": sig(r["freq_hz"], DIGITS),
                    "amplitude_m": sig(float(amp_hb[load_col]), DIGITS),
                    "monodromy_max_abs_mu": sig(r["mono"], 6), "monodromy_stable": _bool(r["mono_stable"]),
                    "hill_max_abs_mu": sig(r["hill"], 6) if r["hill_stable"] is not None else "",
                    "hill_stable": _bool(r["hill_stable"]) if r["hill_stable"] is not None else "",
                    "shooting_max_abs_mu": sig(r["shoot"], 6) if r["shoot_stable"] is not None else "",
                    "shooting_stable": _bool(r["shoot_stable"]) if r["shoot_stable"] is not None else "",
                    "shooting_amplitude_m": sig(float(r["shoot_amp"][load_col]), DIGITS) if r["shoot_amp"] is not None
                    else "",
                    "hb_rel_err_vs_shooting": sig(float(np.max(np.abs(amp_hb / r["shoot_amp"] - 1.0))), ERR_DIGITS)
                    if r["shoot_amp"] is not None else "",
                    "note": r["shoot_note"]})
            st = [r for r in stab_rows if r["level"] == P]
            stats["stability"][f"{P:g} N"] = {
                "hill_points": sum(r["hill_stable"] != "" for r in st),
                "hill_disagree": sum(r["hill_stable"] not in ("", r["monodromy_stable"]) for r in st),
                "shooting_points": sum(r["shooting_stable"] != "" for r in st),
                "shooting_disagree": sum(r["shooting_stable"] not in ("", r["monodromy_stable"]) for r in st),
                "shooting_failed": sum(r["note"] != "" for r in st)}
        for direction, ss in sweeps[P].items():
            for j, f in enumerate(ss.freq_hz):
                for c, nm in enumerate(names):
                    rows_csv.append({"level": P, "method": f"stepped_sine_{direction}", "harmonics": "",
                                     "freq_hz": sig(float(f), DIGITS), "point": nm,
                                     "amplitude_m": sig(float(ss.amplitude_m[j, c]), DIGITS),
                                     "stable": _bool(ss.response[j] != "not_settled"), "bifurcation": "",
                                     "response": ss.response[j], "segment": ""})
    write_rows(writer.path("frc.csv"), rows_csv)
    write_rows(writer.path("frc_harmonics.csv"), harm_rows)
    write_rows(writer.path("frc_bifurcations.csv"), bif_rows,
               fields=["level", "harmonics", "kind", "index", "freq_hz", "amplitude_m", "max_abs_mu_before",
                       "max_abs_mu_after"])
    write_rows(writer.path("frc_stability.csv"), stab_rows)

    # -- convergence in H ---------------------------------------------------------------------
    Pc = spec.convergence_level_N
    targets = []  # (freq, amplitude at the load point) of the contact shooting points at that level
    if Pc in curves and not isinstance(curves[Pc], Exception):
        br = curves[Pc]
        targets = [(r["freq_hz"], float(br.amplitude_m[r["index"], load_col])) for r in checks[Pc]
                   if r["contact"] and r["index"] in r["shot_at"]]
    ref_ss = []
    if Pc in sweeps:
        for ss in sweeps[Pc].values():
            ref_ss += [(float(f), ss.amplitude_m[j]) for j, f in enumerate(ss.freq_hz) if ss.response[j] == "periodic"]
    conv_rows, timing_rows = [], []
    loads_c = {}
    for Hc in conv_H:
        bar.set_postfix_str(f"convergence H={Hc}")
        t0 = time.perf_counter()
        bc = _curve(system, b, Pc, spec, Hc, rows, names, stability=False)
        wall = time.perf_counter() - t0
        row = {"level": Pc, "harmonics": Hc}
        if isinstance(bc, Exception):
            row.update({"status": "failed", "n_points": 0})
        else:  # computed without stability: every piece counts, the nearest in amplitude is taken
            e_ss = [np.max(np.abs(a / amp - 1.0)) for f, amp in ref_ss
                    for a in [solution_at_frequency(bc, f, float(amp[load_col]), load_col)[0]] if a is not None]
            # the exact orbit nearest this H's orbit at each target frequency: multiple shooting from it
            e_sh, fails = [], 0
            for f, a_ref in targets:
                a, _, X = solution_at_frequency(bc, f, a_ref, load_col)
                if a is None:
                    fails += 1
                    continue
                loads = loads_c.setdefault(f, Loads(b[None, :], (Harmonic(Pc, f),)))
                e = shooting_error(system, loads, X, a, f, rows, spec.shooting_segments)
                if e is None:
                    fails += 1
                    continue
                e_sh.append(e)
            fo = bc.freq_hz[bc.folds] if bc.folds else np.zeros(0)
            row.update({
                "status": bc.status, "n_points": len(bc.freq_hz),
                "f_reached_hz": sig(float(bc.freq_hz[bc.segment == 0][-1]), DIGITS),
                "n_folds": len(bc.folds),
                "highest_fold_hz": sig(float(fo.max()), DIGITS) if fo.size else "",
                "lowest_fold_hz": sig(float(fo.min()), DIGITS) if fo.size else "",
                "n_vs_stepped_sine": len(e_ss),
                "max_rel_err_vs_stepped_sine": sig(float(max(e_ss)), ERR_DIGITS) if e_ss else "",
                "n_vs_shooting": len(e_sh), "n_shooting_failed": fails,
                "max_rel_err_vs_shooting": sig(float(max(e_sh)), ERR_DIGITS) if e_sh else "",
                "median_rel_err_vs_shooting": sig(float(np.median(e_sh)), ERR_DIGITS) if e_sh else ""})
        conv_rows.append(row)
        timing_rows.append({"level": Pc, "what": f"hb curve H={Hc}", "harmonics": Hc,
                            "points": row["n_points"], "wall_s": round(wall, 4)})
        bar.update()
    for P in levels:
        for d, ss in sweeps.get(P, {}).items():
            timing_rows.append({"level": P, "what": f"stepped sine {d}", "harmonics": "", "points": len(ss.freq_hz),
                                "wall_s": round(float(np.sum(ss.wall_s)), 4)})
        br = curves[P]
        if not isinstance(br, Exception):
            timing_rows.append({"level": P, "what": f"hb curve H={H} with monodromy stability", "harmonics": H,
                                "points": len(br.freq_hz), "wall_s": round(br.wall_s, 4)})
    write_rows(writer.path("frc_convergence.csv"), conv_rows,
               fields=["level", "harmonics", "status", "n_points", "f_reached_hz", "n_folds", "highest_fold_hz",
                       "lowest_fold_hz", "n_vs_stepped_sine", "max_rel_err_vs_stepped_sine", "n_vs_shooting",
                       "n_shooting_failed", "max_rel_err_vs_shooting", "median_rel_err_vs_shooting"])
    write_rows(writer.path("frc_convergence_timing.csv"), timing_rows)
    if Pc in sweeps and sweeps[Pc]:
        t_ss = sum(float(np.sum(s.wall_s)) for s in sweeps[Pc].values())
        t_hb = {r["harmonics"]: r["wall_s"] for r in timing_rows if r["what"].startswith("hb curve H=")
                and r["level"] == Pc and "monodromy" not in r["what"]}
        stats["speed_ratio_stepped_sine_over_hb"] = {f"H={h}": round(t_ss / t, 2) for h, t in t_hb.items() if t > 0}

    # -- the backbone check ---------------------------------------------------------------
    bb_rows, bb_curves = [], {}
    for P in levels:
        for eps in spec.backbone_scales:
            bar.set_postfix_str(f"backbone {P:g} N x {eps:g}")
            bc = _curve(_scaled_damping(system, eps), b, P * eps, spec, 1, rows, names, stability=False)
            if not isinstance(bc, Exception):
                bb_curves[(P, eps)] = bc
            bar.update()
    # the backbones up to a little past the most energetic orbit drawn
    E_top = max([_orbit_energy(system, br.X[i], br.omega[i]) for br in [*curves.values(), *bb_curves.values()]
                 if not isinstance(br, Exception) for i in [int(np.argmax(br.amplitude_m[:, load_col]))]],
                default=1.0)
    bar.set_postfix_str("backbones")
    bb = _backbones(system, b, rows, spec, BACKBONE_ENERGY_FACTOR * E_top)
    bar.update()
    for P in levels:
        for eps in spec.backbone_scales:
            row = {"level": P, "scale": eps, "load_N": sig(P * eps, DIGITS)}
            bc = bb_curves.get((P, eps))
            if bc is None or not bb:
                row["note"] = "no curve" if bc is None else "no backbone"
                bb_rows.append(row)
                continue
            fp, A = _peak(bc, load_col)
            dist = {m: _log_distance(fp, A, c, load_col) for m, c in bb.items()}
            mode = min(dist, key=dist.get)
            row.update({"nnm": mode + 1, "peak_freq_hz": sig(fp, DIGITS), "peak_amplitude_m": sig(A, DIGITS),
                        "log_distance": sig(dist[mode], ERR_DIGITS), "note": ""})
            bb_rows.append(row)
    write_rows(writer.path("frc_backbone.csv"), bb_rows,
               fields=["level", "scale", "load_N", "nnm", "peak_freq_hz", "peak_amplitude_m", "log_distance",
                       "note"])
    bar.close()

    writer.stats["frc"] = stats
    _plot_frc(writer.path("frc.png"), curves, sweeps, bb, names, spec, scene.name, load_col)
    _plot_backbone(writer.path("frc_backbone.png"), bb_curves, bb, names, load_col, spec)
    _plot_convergence(writer.path("frc_convergence_timing.png"), conv_rows, timing_rows, Pc)


# -- helpers ---------------------------------------------------------------------------------
def _in_contact(system, br) -> np.ndarray:
    """(k,) whether a stop closes somewhere along each point's orbit."""
    out = np.zeros(len(br.freq_hz), bool)
    for i, X in enumerate(br.X):
        out[i] = bool(np.any(max_abs_over_period(X, system.B) > np.abs(system.offset)))
    return out


def _scaled_damping(system, eps: float):
    from dataclasses import replace

    return replace(system, C=system.C * eps)


def _orbit_energy(system, X: np.ndarray, omega: float) -> float:
    """J, mean over one period of the kinetic, elastic and stop energy of the HB orbit X (2H+1, n)."""
    H = (X.shape[0] - 1) // 2
    E = _synthesis(H, max(64, 8 * (2 * H + 1)))
    x = E @ X
    v = omega * (E @ (_derivative_matrix(H) @ X))
    return float(np.mean(system.energy(x, v)))


def _backbones(system, b, rows, spec, energy_max_J: float) -> dict:
    """{mode: (freq_hz, amplitudes (k, p))} of the NNMs the load excites with an open-gap frequency in
    the band, by :func:`reduced.periodic.backbones.nnm_branch` (H = 1 as the nnm stage, N = 4096,
    short steps: the peaks are compared with the polyline through its points)."""
    lm = linear_modes(system, "open")
    part = np.abs(lm.phi.T @ b)
    out = {}
    for r in range(system.n):
        if not (spec.freq_min_hz <= lm.freq_hz[r] <= spec.freq_max_hz) or part[r] < 1e-6 * part.max():
            continue
        try:
            nb = nnm_branch(system, r, H=1, N=BACKBONE_SAMPLES, energy_max_J=energy_max_J, ds=BACKBONE_DS,
                            ds_max=BACKBONE_DS, max_steps=20000)
        except (NewtonError, ContinuationError, ValueError):
            continue
        amps = np.array([max_abs_over_period(x.reshape(3, system.n), rows) for x in nb.X])
        out[r] = (nb.freq_hz, amps)
    return out


def _peak(bc, col: int) -> tuple[float, float]:
    """(Hz, m): the peak of a curve at point ``col``: the largest amplitude, refined by a parabola
    through it and its two neighbours along the curve (amplitude and log frequency against the
    point index)."""
    a = bc.amplitude_m[:, col]
    i = int(np.argmax(a))
    if 0 < i < len(a) - 1:
        y0, y1, y2 = a[i - 1], a[i], a[i + 1]
        den = y0 - 2 * y1 + y2
        if den < 0.0:
            t = 0.5 * (y0 - y2) / den  # vertex offset in (-1, 1)
            lf = np.log(bc.freq_hz[i - 1 : i + 2])
            f = math.exp(lf[1] + 0.5 * t * (lf[2] - lf[0]) + 0.5 * t * t * (lf[0] - 2 * lf[1] + lf[2]))
            return f, float(y1 - 0.25 * (y0 - y2) * t)
    return float(bc.freq_hz[i]), float(a[i])


def _log_distance(f: float, A: float, curve, col: int) -> float:
    """Distance from (ln f, ln A) to the backbone polyline in (ln frequency, ln amplitude): the
    relative distance of a peak from the backbone, in frequency and amplitude alike. Below its
    first point the backbone is the linear mode (its frequency, any smaller amplitude)."""
    fb, amps = curve
    x = np.log(np.concatenate([[fb[0]], fb]))
    y = np.log(np.concatenate([[amps[0, col] * 1e-6], amps[:, col]]))
    px, py = math.log(f), math.log(A)
    dx, dy = np.diff(x), np.diff(y)
    L2 = dx * dx + dy * dy
    t = np.clip(np.where(L2 > 0, ((px - x[:-1]) * dx + (py - y[:-1]) * dy) / np.where(L2 > 0, L2, 1.0), 0.0), 0.0, 1.0)
    return float(np.min(np.hypot(x[:-1] + t * dx - px, y[:-1] + t * dy - py)))


def _plot_frc(path, curves, sweeps, bb, names, spec, title, load_col) -> None:
    """frc.png: top row, every output point over the band (log-log); bottom row, the jump region
    (linear axes): curves per level, stable solid, unstable dashed, stepped sine, backbones dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = len(names)
    fig, axs = plt.subplots(2, p, figsize=(5.2 * p, 8.6), squeeze=False)
    colors = {P: f"C{i}" for i, P in enumerate(curves)}
    ev = np.concatenate([_events(br, load_col) for br in curves.values()] + [np.zeros(0)])
    zoom = (max(ev.min() / 1.15, spec.freq_min_hz), min(ev.max() * 1.15, spec.freq_max_hz)) if ev.size else None
    for row in range(2):
        for c in range(p):
            ax = axs[row][c]
            for P, br in curves.items():
                col = colors[P]
                if isinstance(br, Exception):
                    continue
                for idx in br.pieces():
                    a, fr, stb = br.amplitude_m[idx, c], br.freq_hz[idx], br.stable[idx]
                    ax.plot(fr, np.where(stb, a, np.nan), "-", color=col, lw=1.1, label=f"{P:g} N, HB H={br.H}")
                    uns = ~stb
                    edge = uns | np.roll(uns, 1) | np.roll(uns, -1)  # join the dashed pieces to the solid ones
                    ax.plot(fr, np.where(edge, a, np.nan), "--", color=col, lw=0.7)
                for d, mk in (("up", "^"), ("down", "v")):
                    ss = sweeps.get(P, {}).get(d)
                    if ss is None:
                        continue
                    per = np.array([r in ("periodic", "settling") for r in ss.response])
                    ax.plot(ss.freq_hz[per], ss.amplitude_m[per, c], mk, mfc="none", mec=col, ms=6, mew=0.9,
                            label=f"{P:g} N, stepped sine {d}")
                    ax.plot(ss.freq_hz[~per], ss.amplitude_m[~per, c], mk, mfc="k", mec=col, ms=4, mew=0.6)
            for r, (f, amps) in bb.items():
                ax.plot(f, amps[:, c], ":", color="k", lw=1.2, label=f"NNM {r + 1} backbone (H=1)")
            if row == 0:
                ax.set_xscale("log")
                ax.set_yscale("log")
                ax.set_xlim(spec.freq_min_hz, spec.freq_max_hz)
                good = [br.amplitude_m[:, c] for br in curves.values() if not isinstance(br, Exception)]
                if good:
                    ax.set_ylim(min(np.min(g) for g in good) / 2, max(np.max(g) for g in good) * 3)
            elif zoom is not None:
                ax.set_xlim(*zoom)
                top = max((np.max(br.amplitude_m[(br.freq_hz >= zoom[0]) & (br.freq_hz <= zoom[1]), c], initial=0.0)
                           for br in curves.values() if not isinstance(br, Exception)), default=1e-3)
                ax.set_ylim(0.0, 1.15 * top)
            ax.set_xlabel("excitation frequency [Hz]")
            ax.set_ylabel(f"max |{names[c]}| over a period [m]")
            ax.grid(True, which="both", alpha=0.2)
    handles, labels = axs[0][0].get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    axs[0][0].legend(uniq.values(), uniq.keys(), fontsize=6, loc="lower left")
    fig.suptitle(f"{title}: forced response to a load at {spec.point} (solid: stable, dashed: unstable; open "
                 "markers: stepped sine settled, filled: not settled; dotted: backbone); bottom: the jump region",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_backbone(path, bb_curves, bb, names, load_col, spec) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {eps: (w, a) for eps, w, a in zip(sorted(spec.backbone_scales, reverse=True), (1.4, 1.0, 0.7, 0.5),
                                               (1.0, 0.8, 0.6, 0.5), strict=False)}
    levels = sorted({P for P, _ in bb_curves})
    for i, P in enumerate(levels):
        for eps in spec.backbone_scales:
            bc = bb_curves.get((P, eps))
            if bc is None:
                continue
            lw, al = styles.get(eps, (0.5, 0.5))
            ax.plot(bc.freq_hz, bc.amplitude_m[:, load_col], "-", color=f"C{i}", lw=lw, alpha=al,
                    label=f"{P:g} N, damping and load x {eps:g}")
            k = int(np.argmax(bc.amplitude_m[:, load_col]))
            ax.plot(bc.freq_hz[k], bc.amplitude_m[k, load_col], "o", color=f"C{i}", ms=4)
    for r, (f, amps) in bb.items():
        ax.plot(f, amps[:, load_col], ":", color="k", lw=1.5, label=f"NNM {r + 1} backbone (nnm stage, H=1)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    peaks = [_peak(bc, load_col) for bc in bb_curves.values()]
    if peaks:  # around the peaks: off resonance the scaled load only shifts each curve down
        ax.set_xlim(spec.freq_min_hz, min(1.5 * max(f for f, _ in peaks), spec.freq_max_hz))
        ax.set_ylim(0.3 * min(a for _, a in peaks), 3.0 * max(a for _, a in peaks))
    ax.set_xlabel("excitation frequency [Hz]")
    ax.set_ylabel(f"max |{names[load_col]}| [m]")
    ax.set_title("FRC peaks (dots) approach the backbones as damping and load go to zero together (HB H=1)",
                 fontsize=8)
    ax.grid(True, which="both", alpha=0.2)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _plot_convergence(path, conv_rows, timing_rows, Pc) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wall = {r["harmonics"]: r["wall_s"] for r in timing_rows if r["what"].startswith("hb curve H=")
            and "monodromy" not in r["what"]}
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for key, mk, label in (("max_rel_err_vs_shooting", "o-", "max error vs exact orbits (shooting)"),
                           ("median_rel_err_vs_shooting", "s--", "median error vs exact orbits"),
                           ("max_rel_err_vs_stepped_sine", "^:", "max error vs stepped sine (settled points)")):
        pts = [(wall[r["harmonics"]], r[key], r["harmonics"]) for r in conv_rows
               if r.get(key) not in (None, "") and r["harmonics"] in wall]
        if not pts:
            continue
        t, e, h = zip(*pts, strict=True)
        ax.loglog(t, np.maximum(np.array(e, float), 1e-16), mk, label=label)
        for ti, ei, hi in pts:
            ax.annotate(f"H={hi}", (ti, max(float(ei), 1e-16)), fontsize=6)
    ax.set_xlabel("HB curve run time [s] (this run; varies with machine load)")
    ax.set_ylabel("relative amplitude error")
    ax.set_title(f"HB forced response at {Pc:g} N: error against run time", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.2)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)



# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Forced-response curves under P cos(2 pi f t) at one point, by harmonic balance continued
through folds, with stability (monodromy, Hill, shooting), bifurcations, a stepped sine up and
down by the exact integrator, the error against H and run time, and the backbone check.
Writes frc.csv, frc.png, frc_stability.csv, stepped_sine.csv, frc_convergence*.csv,
frc_backbone.csv and .png, and frc.md."""


def estimate(scene: Scene) -> list[Estimate]:
    """Hill's method: the first-order form of the quadratic eigenproblem at the largest H."""
    f = scene.frc
    n = n_dofs(scene)
    H = max((f.harmonics, *f.convergence_harmonics))
    size = 2 * (2 * H + 1) * n
    return [Estimate("frc", HILL_COPIES * size**2 * FLOAT, f"Hill matrices of {size} x {size} (H = {H}, {n} DOFs)",
                     "[frc] harmonics or convergence_harmonics")]


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir) -> _Pending:
    return _Pending(scene, progress, {})


def write(result: _Pending, writer: StageWriter) -> None:
    frc_stage(result.scene, writer, result.progress, **result.options)

__all__ = ["frc_stage", "orbit_amplitude"]
