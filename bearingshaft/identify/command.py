"""``bearingshaft identify --scene S --test FILE.uff``: the arguments checked, the fit run, the files written.

Everything is checked before a cluster starts or a model runs: the scene's [identify] table and its
parameters (:func:`bearingshaft.identify.parameters.parameters_of`), ``--workers``, ``--scheduler``
and ``--window``, the results folder, the test file (:func:`bearingshaft.measured.read_test`: a
truncated file, NaN samples, channels sampled differently, no hammer channel, units that do not
match, two records for one channel) and its channels against the model's; a refusal is one line
with exit code 2 and nothing written. The files are written whole or not at all
(:func:`bearingshaft.output.staged_output`), into ``runs/<scene>/identify-<test file>/`` by default (git ignores runs/).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from bearingshaft import correlate, measured
from bearingshaft.identify.fit import SerialEvaluator, identify
from bearingshaft.identify.parameters import parameters_of
from bearingshaft.identify.problem import make_problem
from bearingshaft.identify.results import Identified, Overlay
from bearingshaft.identify.virtual import scene_rig
from bearingshaft.output import check_out_dir, staged_output
from bearingshaft.scenes import Scene, SceneError
from fem.uff import TimeHistory

STAGE = "identify"  # its entry in provenance.json


def add_parser(sub) -> None:
    """The ``identify`` subcommand's arguments (added to the command line's subparsers).

    Parameters
    ----------
    sub : argparse subparsers
    """
    p = sub.add_parser(STAGE, help="fit the scene's uncertain parameters ([identify]: gap, contact stiffness, damping) "
                       "to a measured hammer test, on Dask; identified.csv with 95 %% intervals",
                       description="Fit the parameters the scene's [identify] table names (by default the gap, the "
                       "contact stiffness and the modal damping) to a measured hammer test (UFF 58), by least squares "
                       "on the measures that survive chaos ([identify] measures: by default each load cell's first "
                       "impact, the RMS envelopes, the impact statistics; optionally pointwise up to the "
                       "predictability horizon), the model runs on Dask (a LocalCluster, or --scheduler ADDRESS). "
                       "Writes "
                       "identified.csv (parameter, unit, initial, value, ci_low, ci_high), correlation.csv, "
                       "weights.csv, misfit_history.csv, identify.md, identified_overlay.png and misfit_history.png "
                       "into runs/<scene>/identify-<test file>/ (or --out).")
    p.add_argument("--scene", required=True, metavar="NAME_OR_TOML", help="built-in scene name or scene TOML file")
    p.add_argument("--test", required=True, dest="test_file", metavar="FILE.uff",
                   help="the measured test (UFF 58 time histories, its hammer channel drives the model)")
    p.add_argument("--out", metavar="DIR", help="results folder (default: runs/<scene>/identify-<test file>/)")
    p.add_argument("--no-progress", action="store_true", help="print no line per pass")
    p.add_argument("--window", metavar="START:END", help="s, the part of the test fitted (default [identify] "
                   "window_s, else the record)")
    p.add_argument("--workers", metavar="N", help="worker processes of the local cluster (default: one per core; 0: "
                   "no cluster, the runs one after another in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask scheduler (tcp://host:8786) instead")


def _workers(text: str | None) -> int | None:
    """--workers as an int (None: not given); SceneError for anything but an integer >= 0.

    >>> _workers("2"), _workers(None), _workers("0")
    (2, None, 0)
    """
    if text is None:
        return None
    if not str(text).strip().isdigit():
        raise SceneError(f"--workers: expected an integer >= 0, got {text!r}")
    return int(text)


def _window(scene: Scene, text: str | None, test: measured.MeasuredTest, test_file: str) -> tuple[float, float]:
    from bearingshaft.stages.hammer_compare import parse_window

    w = parse_window(text) or (tuple(scene.identify.window_s) if scene.identify.window_s else None)
    if w is None:
        return 0.0, float(test.duration_s)
    a, b = float(w[0]), float(w[1])
    if b > test.duration_s + 0.5 / test.sample_rate_hz:
        raise SceneError(f"--window / [identify] window_s: ends at {b!r} s, after the test's record "
                         f"({test.duration_s:.6g} s in {test_file!r})")
    if a > test.pulse_start_s:
        raise SceneError(f"--window / [identify] window_s: starts at {a!r} s, after the blow ({test.pulse_start_s:.6g} "
                         f"s): the model starts at rest before it")
    return a, b


def _names(scene: Scene, rig, test: measured.MeasuredTest, test_file: str) -> tuple[str, ...]:
    """The compared channels, checked against the test's ([hammer] compare, else all but the hammer)."""
    t = test.channels[0]
    dummy = [TimeHistory(c.name, c.node, c.direction, c.quantity, np.zeros(t.data.size), t.dt_s, t.t0_s)
             for c in rig.channels]
    try:
        pairs = correlate.match_channels(dummy, test.channels, list(scene.hammer.compare) or None,
                                         source=repr(test_file))
    except correlate.ChannelError as exc:
        raise SceneError(f"--test: {exc}") from None
    return tuple(p.name for p in pairs)


def identify_command(args, load_scene) -> int:
    """``bearingshaft identify``: check everything, fit, write.

    Parameters
    ----------
    args : the parsed command line
    load_scene : name or path -> Scene

    Returns
    -------
    The exit code, 0 (a refusal raises SceneError first).
    """
    scene = load_scene(args.scene)
    if scene.identify is None:
        raise SceneError(f"{scene.origin or scene.name}: the scene has no [identify] table (the parameters to fit); "
                         f"add one, e.g. [identify] parameters = [\"model.gap\", \"model.k_g\", \"model.c_points\"]")
    if scene.hammer is None:
        raise SceneError(f"{scene.origin or scene.name} [identify]: needs a [hammer] table")
    workers = _workers(args.workers)
    if workers is not None and args.scheduler:
        raise SceneError("--workers sizes the local cluster; with --scheduler the cluster's own workers run")
    params = parameters_of(scene)
    test_file = args.test_file
    if not Path(test_file).is_file():
        raise SceneError(f"--test: no such file {test_file!r}")
    out = Path(args.out) if args.out else Path("runs") / scene.name / f"identify-{Path(test_file).stem}"
    check_out_dir(out)
    test = measured.read_test(scene, test_file)
    window = _window(scene, args.window, test, test_file)
    progress = not args.no_progress
    say = (lambda text: print(f"[{scene.name}] identify: {text}", flush=True)) if progress else None
    t0 = time.perf_counter()
    rom = scene.model.reduced(progress)
    rig = scene_rig(scene, rom)
    names = _names(scene, rig, test, test_file)
    problem = make_problem(scene, rom, rig, test, params, window, names)
    with staged_output(out, scene.name, scene.source, STAGE) as writer:
        result = run(problem, test_file, workers, args.scheduler, say)
        from bearingshaft.identify import report  # matplotlib: loaded only when files are written

        report.write(result, writer)
    for line in result.lines:
        print(line, flush=True)
    print(f"[{scene.name}] identify: files in {out} ({time.perf_counter() - t0:.1f} s)", flush=True)
    return 0


def run(problem, test_file: str, workers: int | None = None, scheduler: str | None = None, say=None) -> Identified:
    """The fit and the overlays, on Dask (``workers`` = 0: in this process).

    Parameters
    ----------
    problem : Problem
    test_file : str
    workers : int or None
        LocalCluster workers (None: one per core; 0: no cluster).
    scheduler : str or None
        A scheduler's address.
    say : callable or None
        One line per pass.

    Returns
    -------
    Identified
    """
    import contextlib

    with contextlib.ExitStack() as stack:
        if workers == 0 and not scheduler:
            ev = SerialEvaluator(problem)
        else:
            from bearingshaft.identify.run import dask_evaluator

            ev = stack.enter_context(dask_evaluator(problem, scheduler, workers))
        fit = identify(problem, ev, progress=say)
        (t, initial), (_, found) = ev.records([problem.theta0, fit.theta])
    tg = fit.target
    test = np.array([h.data[np.round((t - h.t0_s) / h.dt_s).astype(int)] for h in tg.tests])
    units = {c.name: c.unit for c in problem.rig.channels}
    overlay = Overlay(problem.names, t, test, initial, found, tuple(units[n] for n in problem.names))
    vals = ", ".join(f"{p.key} = {fit.values[p.key]:.4g} [{fit.ci[p.key][0]:.3g}, {fit.ci[p.key][1]:.3g}]"
                     for p in problem.parameters)
    note = f"; {len(fit.notes)} identifiability note(s) in identify.md" if fit.notes else ""
    line = (f"[{problem.scene.name}] identify: {vals} ({round(100 * problem.scene.identify.confidence)} % intervals) "
            f"from {fit.stats['n_runs']} model runs on {fit.stats['where']} in {fit.stats['wall_s']:.1f} s{note}")
    stats = {"test_file": str(test_file), "values": fit.values, "ci": {k: list(v) for k, v in fit.ci.items()},
             "notes": fit.notes, "s2": fit.s2, "n_eff": fit.n_eff, "condition": fit.condition, **fit.stats,
             "horizon_s": tg.horizon.horizon_s if tg.horizon is not None else math.inf,
             "time_span_s": list(tg.time_span_s), "n_modes_kept": problem.n_keep - 2}
    return Identified(problem.scene, str(test_file), fit, overlay, problem.test.driven, (line,), stats)


__all__ = ["identify_command", "add_parser", "run", "STAGE"]
