"""Command line: ``bearingshaft <subcommand> --scene NAME_OR_TOML [--out DIR]``.

Subcommands follow the pipeline (geometry -> fem -> reduced -> results):
``modal`` (mesh and modal analysis), ``reduce`` (Craig-Bampton onto the tips),
``ringdown``, ``hammer`` (the virtual hammer test, ``--test FILE.uff`` to compare a measured
one), ``nnm``, ``study`` (error against run time, stiff cases), ``verify``
(reduction against the discrete model), ``frc`` (forced-response curves), ``run`` (every
stage of one or more scenes; all built-in scenes when none is named), ``check`` (validate scenes, their memory and the
results folder without running anything), ``sweep`` (a scene over a design of parameter values, on Dask),
``scenes`` (``--show NAME`` prints one) and ``keys`` (every table and key of a scene).
Bad input gives a one-line message and exit code 2, before any work starts; nothing
half-written is left behind. Every command ends with a summary naming the results folder.

Results go to ``runs/<scene>/`` (a folder the repository ignores); the committed ``results/<scene>/``
folders are the reference, written only with ``--update-reference``. ``run`` ends with the
reproduction report (:mod:`bearingshaft.reproduction`): ``runs/reproduction.md`` and ``.csv``, and
exit code 1 if a deterministic number did not reproduce the reference.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from bearingshaft import __version__
from bearingshaft.budget import available_bytes, check_budget, job_bytes, job_peaks
from bearingshaft.digits import human
from bearingshaft.output import check_out_dir
from bearingshaft.progress import run_total
from bearingshaft.registry import BY_NAME, STAGES, stages_of
from bearingshaft.scenes import Scene, SceneError, builtin_names, load_scene
from reduced._checks import one_line

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
RUNS = Path("runs")  # where results go by default (.gitignore'd)
REFERENCE = Path("results")  # the committed reference, written only with --update-reference


class UserError(Exception):
    """An error the user can fix; printed as one line, exit code 2."""


def _add_common(p: argparse.ArgumentParser, scene_required: bool = True) -> None:
    p.add_argument("--scene", required=scene_required, metavar="NAME_OR_TOML",
                   help="built-in scene name or path to a scene TOML file")
    p.add_argument("--out", metavar="DIR", help="results folder (default: runs/<scene>/)")
    _add_update_reference(p)
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")


def _workers(text: str) -> int:
    """``--workers``: a whole number >= 1 (argparse turns the ValueError into a usage error)."""
    n = int(text)
    if n < 1:
        raise ValueError(text)
    return n


def _add_update_reference(p: argparse.ArgumentParser) -> None:
    p.add_argument("--update-reference", action="store_true",
                   help="write into results/<scene>/, the committed reference, instead of runs/<scene>/ "
                   "(review the change with git diff before committing it)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bearingshaft",
        description="Nonlinear dynamics of bearing-and-shaft assemblies with clearance contact.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    for stage in STAGES:  # one subcommand per stage, as the registry declares it
        p = sub.add_parser(stage.name, help=stage.help, description=stage.description,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        _add_common(p)
        for opt in stage.options:
            p.add_argument(opt.flag, dest=opt.name, metavar=opt.metavar, choices=opt.choices, help=opt.help)
    p = sub.add_parser("run", help="every stage of the named scenes (all built-in scenes if none)",
                       description="Run every stage of the named scenes (all built-in scenes if none is named), every "
                       "scene validated first. Writes each stage's files, as its subcommand would, into the results "
                       "folder <out>/<scene>/ (default runs/, which git ignores; --update-reference: results/) and "
                       "prints a summary line per stage; then compares every stage's files with the reference "
                       "results/<scene>/, writes the reproduction report <out>/reproduction.md and .csv and prints "
                       "its summary (exit 1 if a deterministic number did not reproduce); a total line last (stages, "
                       "wall time, peak memory). Several scenes run side by side on Dask (a local cluster of one "
                       "worker per core, as many as the memory estimates allow, or --scheduler), the longest first; "
                       "a scene's stages run in order.")
    p.add_argument("scenes", nargs="*", metavar="SCENE", help="scene names or TOML files")
    p.add_argument("--out", metavar="DIR", help="parent folder of the results (default: runs/); the reproduction "
                   "report goes there too")
    _add_update_reference(p)
    p.add_argument("--reference", metavar="DIR", help="parent folder of the reference results (default: ./results/, "
                   "else the checkout's results/)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.add_argument("--workers", metavar="N", type=_workers, help="worker processes of the local cluster (default: "
                   "one per core, fewer if the memory estimates say so; 1: one scene after the other in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask scheduler (tcp://host:8786) instead")
    p.add_argument("--fan-out", action="store_true", help="split long stages (FRC levels, FEP branches, hammer "
                   "levels) into tasks of their own: for a cluster with more workers than long stages (on 2 "
                   "cores it is slower)")
    p = sub.add_parser("check", help="validate scenes, their memory estimates and --out without running",
                       description="Validate scenes (all built-in scenes if none is named): every key, the memory "
                       "each stage would need against the memory available, every case of a [sweep], and that "
                       "the results folder can be written. Runs nothing and writes nothing; a line per scene.")
    p.add_argument("scenes", nargs="*", metavar="SCENE", help="scene names or TOML files (all built-in if none)")
    p.add_argument("--scene", dest="scene_opt", metavar="NAME_OR_TOML", help="one scene (as for the stages)")
    p.add_argument("--out", metavar="DIR", help="results folder to check (default: runs/<scene>/)")
    p = sub.add_parser("scenes", help="list the built-in scenes, or print one (--show NAME)",
                       description="List the built-in scenes with their stages and descriptions, or print one "
                       "scene's TOML (--show NAME) to start a scene of your own from. Writes nothing.")
    p.add_argument("--show", metavar="NAME", help="print this built-in scene's TOML")
    p = sub.add_parser("keys", help="list every table and key of a scene: type, unit, default, allowed values",
                       description="List the tables of a scene and each key's type, unit, default, allowed values "
                       "and meaning, generated from the dataclasses that read them (units and meanings are their "
                       "field comments, allowed values what their checks refuse). Writes nothing.")
    p.add_argument("table", nargs="?", metavar="TABLE", help="one table (ringdown, model, model.rom, load, ...)")
    p.add_argument("--csv", action="store_true", help="print CSV (table,key,type,unit,default,allowed,meaning)")
    # -- parameter sweeps on Dask (bearingshaft/sweep/) --
    p = sub.add_parser("sweep", help="run a scene over a design of parameter values on Dask (a local cluster, "
                       "or --scheduler ADDRESS); sweep.parquet, sweep.csv, sweep.png",
                       description="Run a scene over a design of parameter values ([sweep] or --vary) on Dask, every "
                       "case validated first. Writes a folder per case, sweep.parquet and sweep.csv (a row per "
                       "case: its values, metrics and status), sweep.png, sweep_provenance.json and "
                       "sweep_scene.toml into runs/<scene>/sweep/ (--update-reference: results/, or --out); "
                       "finished cases are resumed.")
    p.add_argument("--scene", required=True, metavar="NAME_OR_TOML", help="built-in scene name or scene TOML file")
    p.add_argument("--out", metavar="DIR", help="folder of the case folders and tables (default: "
                   "runs/<scene>/sweep/)")
    _add_update_reference(p)
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.add_argument("--vary", action="append", metavar="KEY=VALUES",
                   help="a varied scene key and its values, repeatable: model.gap=1e-4:1e-3:9:log (N values, log or "
                   "lin), model.k_g=1e7,1e8,1e9 (a list), random design: model.c=0:8 (a range); replaces the "
                   "scene's [sweep.vary]")
    p.add_argument("--design", metavar="grid|zip|random", help="grid (product, default), zip, random (Latin "
                   "hypercube)")
    p.add_argument("--samples", metavar="N", help="cases of a random design")
    p.add_argument("--seed", metavar="S", help="seed of a random design (default 0)")
    p.add_argument("--workers", metavar="N", help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask scheduler (tcp://host:8786) instead")
    # -- end issue 13 --
    from bearingshaft.identify.command import add_parser as add_identify  # issue 26: fit the model to a test

    add_identify(sub)
    return parser


def default_parent(update_reference: bool = False) -> Path:
    """The parent of the results folders: ``runs/``, or ``results/`` (the reference) with ``--update-reference``.

    Parameters
    ----------
    update_reference : bool
        Write the committed reference.

    Returns
    -------
    Path
    """
    return REFERENCE if update_reference else RUNS


def reference_root() -> Path:
    """The reference the report reads: ``./results`` (where ``--update-reference`` writes), else the
    ``results/`` of the checkout this package runs from."""
    if REFERENCE.is_dir():
        return REFERENCE
    here = Path(__file__).resolve().parent.parent / "results"
    return here if here.is_dir() else REFERENCE


def _out_dir(arg: str | None, scene_name: str, parent: bool = False, update_reference: bool = False) -> Path:
    if arg is None:
        return default_parent(update_reference) / scene_name
    if update_reference:
        raise UserError("--update-reference writes results/<scene>/: give it or --out, not both")
    return Path(arg) / scene_name if parent else Path(arg)


def _validated(name: str, out_arg: str | None, parent: bool, update_reference: bool = False,
               stage: str | None = None) -> tuple[Scene, Path]:
    """A scene, its memory estimates (of ``stage`` alone when given) and its results folder checked, before any work."""
    scene = load_scene(name)
    out = _out_dir(out_arg, scene.name, parent, update_reference)
    check_out_dir(out)
    check_budget(scene, out, stage=stage if stage in stages_of(scene) else None)
    return scene, out


def _check(args) -> int:
    names = ([args.scene_opt] if args.scene_opt else []) + args.scenes or builtin_names()
    single = len(names) == 1 and args.scene_opt is not None
    scenes = []
    for name in names:
        scene, out = _validated(name, args.out, parent=not single)
        scenes.append(scene)
        peaks = job_peaks([scene])
        each = ", ".join(f"{p.stage} {human(p.bytes)}" + (" (builds the 3-D model)" if p.builds_model else "")
                         for p in peaks)
        peak = f"peak memory about {human(job_bytes(peaks))} ({each})" if peaks else "no stage"
        cases = _check_sweep(scene, out / "sweep") if scene.sweep is not None and scene.sweep.vary else None
        print(f"{scene.name}: valid; stages {', '.join(stages_of(scene)) or 'none'}; {peak} "
              f"of {human(available_bytes())} available; results in {out}")
        if cases:
            print(cases)
    if len(scenes) > 1:
        print(job_line(scenes))
    return 0


def job_line(scenes: list[Scene]) -> str:
    """The whole job's estimate: its stages in one process, as ``bearingshaft run`` runs them.

    Parameters
    ----------
    scenes : list of Scene
        In the order they run.

    Returns
    -------
    str
        One line: stages, scenes, the job's peak (:func:`bearingshaft.budget.job_bytes`) and the largest stage's.
    """
    peaks = job_peaks(scenes)
    return (f"job: {len(peaks)} stages of {len(scenes)} scenes in one process: peak memory about "
            f"{human(job_bytes(peaks))} (largest stage {human(max((p.bytes for p in peaks), default=0))}, with what "
            f"the stages before it leave resident; bearingshaft.budget.job_bytes)")


def _check_sweep(scene: Scene, out: Path) -> str:
    """Every case of the scene's [sweep] (its table already checked by the scene parser) written,
    parsed and budget-checked as ``bearingshaft sweep`` does before it starts a cluster
    (SweepError, one line, at the first case refused)."""
    from bearingshaft.sweep import build_plan, local_cores, sweep_source

    plan = build_plan(scene, scene.sweep, sweep_source(scene), out, local_cores())
    return (f"{scene.name} [sweep]: {len(plan.cases)} cases valid ({scene.sweep.design} over "
            f"{', '.join(v.key for v in scene.sweep.vary)}), each within the memory of one of "
            f"{local_cores()} workers; tables in {out}")


def _builtin(name: str) -> str:
    """``name`` if it is a built-in scene, else a UserError naming the nearest."""
    from bearingshaft.scenes import suggest

    if name not in builtin_names():
        raise UserError(f"--show: no built-in scene {name!r}{suggest(name, builtin_names())} "
                        f"(built-in: {', '.join(builtin_names())})")
    return name


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 success, 1 solver failure, 2 bad input)."""
    parser = build_parser()
    if argv is None:  # as a command: a kill is an interrupt, so scratch folders are removed
        signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse already printed its one-line usage error
        return int(exc.code or 0) and EXIT_BAD_INPUT
    from bearingshaft import pipeline

    try:
        if args.command == "scenes" and args.show:
            print(load_scene(_builtin(args.show)).source, end="")
            return 0
        if args.command == "keys":
            from bearingshaft.scenes.keys import format_keys, keys_csv, select_tables, table_keys

            try:
                keys = [k for t, c in select_tables(args.table).items() for k in table_keys(t, c)]
            except KeyError as exc:
                raise UserError(exc.args[0]) from None
            print((keys_csv if args.csv else format_keys)(keys), end="")
            return 0
        if args.command == "scenes":
            for name in builtin_names():
                scene = load_scene(name)
                print(f"{name:28s} {', '.join(stages_of(scene)) or '-':24s} {scene.description}")
            return 0
        if args.command == "check":
            return _check(args)
        if args.command == "sweep":  # issue 13
            from bearingshaft.sweep import sweep_command

            return sweep_command(args, load_scene)
        if args.command == "identify":  # issue 26
            from bearingshaft.identify.command import identify_command

            return identify_command(args, load_scene)
        progress = not args.no_progress
        if args.command == "run":
            names = args.scenes or builtin_names()
            runs = [_validated(n, args.out, True, args.update_reference) for n in names]  # all before any runs
            n_stages = sum(len(stages_of(s)) for s, _ in runs)
            if len(runs) > 1 and (args.workers != 1 or args.scheduler):
                from bearingshaft.jobs import run_job

                given = [(n, s, o) for n, (s, o) in zip(names, runs, strict=True)]
                job = run_job(given, stages_of, workers=args.workers, scheduler=args.scheduler, progress=progress,
                              fan_out=args.fan_out)
                code = _reproduction(args, runs)
                print(run_total(n_stages, len(runs), job.wall_s, job.peak_bytes, job.workers))  # the last line
                return EXIT_FAILED if job.failed else code
            print(job_line([s for s, _ in runs]), flush=True)  # in this one process
            t_run = time.perf_counter()
            for scene, out in runs:
                pipeline.run_scene(scene, out, progress=progress)
            wall_s = time.perf_counter() - t_run
            code = _reproduction(args, runs)
            print(run_total(n_stages, len(runs), wall_s))  # the last line
            return code
        test = getattr(args, "test_file", None)
        if test is not None and args.out is None:  # a comparison never mixes with the scene's own files
            args.out = str(default_parent(args.update_reference) / load_scene(args.scene).name
                           / f"test-{Path(test).stem}")
            args.update_reference = False
        scene, out = _validated(args.scene, args.out, False, args.update_reference, stage=args.command)
        if test is not None and not Path(test).is_file():
            raise UserError(f"--test: no such file {test!r}")
        options = {o.name: getattr(args, o.name) for o in BY_NAME[args.command].options
                   if getattr(args, o.name) is not None}
        pipeline.run_stage(scene, args.command, out, progress=progress, **options)
        return 0
    except (SceneError, UserError, ValueError) as exc:
        print(f"bearingshaft: error: {one_line(exc, typed=False)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except pipeline.StageUnavailable as exc:
        print(f"bearingshaft: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print("bearingshaft: failed: out of memory (see `bearingshaft check` for the estimates)", file=sys.stderr)
        return EXIT_FAILED
    except (RuntimeError, FloatingPointError, ArithmeticError, OSError) as exc:
        print(f"bearingshaft: failed: {one_line(exc, typed=False)}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("bearingshaft: interrupted; results folder left as it was", file=sys.stderr)
        return 130




def _reproduction(args, runs: list[tuple[Scene, Path]]) -> int:
    """The reproduction report of ``run`` (none when it rewrote the reference); the exit code."""
    from bearingshaft import reproduction

    if args.update_reference:
        print(f"reference updated: {', '.join(str(out) for _, out in runs)} (review with git diff)", flush=True)
        return 0
    reference = Path(args.reference) if args.reference else reference_root()
    specs = {s.name: s.reproduction for s in STAGES}
    rows = []
    for scene, out in runs:
        rows += reproduction.compare_scene(scene.name, out, reference / scene.name, specs, stages_of(scene))
    parent = Path(args.out) if args.out else default_parent()
    path = reproduction.write_report(rows, parent, reference)
    print(reproduction.summary(rows, path), flush=True)
    return EXIT_FAILED if reproduction.failed(rows) else 0


if __name__ == "__main__":
    sys.exit(main())
