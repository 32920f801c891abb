"""Command line: ``bearingshaft <subcommand> --scene NAME_OR_TOML [--out DIR]``.

Subcommands follow the pipeline (geometry -> fem -> reduced -> results):
``modal`` (mesh and modal analysis), ``reduce`` (Craig-Bampton onto the tips),
``ringdown``, ``nnm``, ``study`` (error against run time, stiff cases), ``verify``
(reduction against the discrete model), ``run`` (every stage of one or more scenes; all
built-in scenes when none is named) and ``scenes``.
Bad input gives a one-line message and exit code 2; nothing half-written is left behind.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from bearingshaft import __version__
from bearingshaft.scenes import SceneError, builtin_names, load_scene

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


class UserError(Exception):
    """An error the user can fix; printed as one line, exit code 2."""


def _add_common(p: argparse.ArgumentParser, scene_required: bool = True) -> None:
    p.add_argument("--scene", required=scene_required, metavar="NAME_OR_TOML",
                   help="built-in scene name or path to a scene TOML file")
    p.add_argument("--out", metavar="DIR", help="results folder (default: results/<scene>/)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bearingshaft",
        description="Nonlinear dynamics of bearing-and-shaft assemblies with clearance contact.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("modal", help="build the mesh and run the modal analysis of a 3-D scene")
    _add_common(p)
    p = sub.add_parser("reduce", help="reduce the 3-D model to its tips (Craig-Bampton): rom.npz, cb_check.csv")
    _add_common(p)
    p = sub.add_parser("ringdown", help="free response from the scene's initial state")
    _add_common(p)
    p.add_argument("--method", choices=("exact", "explicit", "dop853"),
                   help="integrator (default: the scene's, else exact)")
    p = sub.add_parser("nnm", help="frequency-energy relations of the nonlinear normal modes")
    _add_common(p)
    p = sub.add_parser("study", help="error against run time, stiff and extreme cases")
    _add_common(p)
    p = sub.add_parser("verify", help="verify the reduced model against the discrete model")
    _add_common(p)
    p = sub.add_parser("run", help="every stage of the named scenes (all built-in scenes if none)")
    p.add_argument("scenes", nargs="*", metavar="SCENE", help="scene names or TOML files")
    p.add_argument("--out", metavar="DIR", help="parent folder of the results (default: results/)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    sub.add_parser("scenes", help="list the built-in scenes")
    return parser


def _out_dir(arg: str | None, scene_name: str, parent: bool = False) -> Path:
    if arg is None:
        return Path("results") / scene_name
    return Path(arg) / scene_name if parent else Path(arg)


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
        if args.command == "scenes":
            for name in builtin_names():
                scene = load_scene(name)
                print(f"{name:28s} {', '.join(scene.stages) or '-':24s} {scene.description}")
            return 0
        progress = not args.no_progress
        if args.command == "run":
            names = args.scenes or builtin_names()
            scenes = [load_scene(n) for n in names]  # validate all before running any
            for scene in scenes:
                pipeline.run_scene(scene, _out_dir(args.out, scene.name, parent=True), progress=progress)
            return 0
        scene = load_scene(args.scene)
        out = _out_dir(args.out, scene.name)
        options = {"method": getattr(args, "method", None)}
        pipeline.run_stage(scene, args.command, out, progress=progress, **options)
        return 0
    except (SceneError, UserError, ValueError) as exc:
        print(f"bearingshaft: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except pipeline.StageUnavailable as exc:
        print(f"bearingshaft: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (RuntimeError, FloatingPointError, ArithmeticError) as exc:
        print(f"bearingshaft: failed: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("bearingshaft: interrupted; results folder left as it was", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
