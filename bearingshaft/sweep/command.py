"""``bearingshaft sweep``: the subcommand's arguments turned into a design, checked, then run.

Everything is validated before a cluster starts: ``--vary`` and the scene's ``[sweep]``
(:func:`spec_from_args`), ``--workers`` and ``--scheduler``, the output folder and every case
(:func:`bearingshaft.sweep.plan.build_plan`); a refusal is one :class:`SweepError` line.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from bearingshaft.output import check_out_dir
from bearingshaft.scenes import Scene
from bearingshaft.scenes.sweep import INT_PATTERN, SweepError, SweepSpec, check_spec, parse_vary_option
from bearingshaft.sweep.plan import build_plan, case_stages, show_values
from bearingshaft.sweep.run import local_cores, run_sweep


def _positive_int(text: str | None, option: str, allow_zero: bool = False) -> int | None:
    """An integer option's value (None when not given); SweepError naming the option otherwise.

    >>> _positive_int("4", "--workers"), _positive_int(None, "--workers"), _positive_int("0", "--seed", True)
    (4, None, 0)
    >>> _positive_int("0", "--workers")
    Traceback (most recent call last):
    ...
    bearingshaft.scenes.errors.SweepError: --workers: expected an integer >= 1, got '0'
    """
    if text is None:
        return None
    if not INT_PATTERN.match(str(text).strip()) or int(text) < (0 if allow_zero else 1):
        raise SweepError(f"{option}: expected an integer >= {0 if allow_zero else 1}, got {text!r}")
    return int(text)


def sweep_source(scene: Scene) -> str:
    """Where a scene's own [sweep] design comes from, as refusals name it.

    Parameters
    ----------
    scene : the scene

    Returns
    -------
    ``"<origin or name> [sweep]"``.
    """
    return f"{scene.origin or scene.name} [sweep]"


def spec_from_args(scene: Scene, args) -> tuple[SweepSpec, str]:
    """The sweep's design: the scene's [sweep], with --vary replacing its keys and --design,
    --samples, --seed replacing its options.

    Parameters
    ----------
    scene : the base scene
    args : the parsed command line (``vary``, ``design``, ``samples``, ``seed``)

    Returns
    -------
    (the checked design, where it came from: "--vary" or the scene's [sweep]).
    """
    base = scene.sweep if scene.sweep is not None else SweepSpec()
    source = sweep_source(scene)
    vary = base.vary
    if args.vary:
        vary = tuple(parse_vary_option(v) for v in args.vary)
        source = "--vary"
    elif scene.sweep is None:
        raise SweepError(f"{scene.origin or scene.name}: the scene has no [sweep] table; give --vary KEY=VALUES "
                         "(e.g. --vary model.gap=1e-4:1e-3:9:log)")
    samples = _positive_int(args.samples, "--samples")
    seed = _positive_int(args.seed, "--seed", allow_zero=True)
    spec = dataclasses.replace(base, vary=vary, design=args.design or base.design,
                               samples=base.samples if samples is None else samples,
                               seed=base.seed if seed is None else seed)
    return check_spec(spec, source), source


def sweep_command(args, load_scene) -> int:
    """``bearingshaft sweep``: validate everything, then run.

    Parameters
    ----------
    args : the parsed command line (``scene``, ``vary``, ``workers``, ``scheduler``, ``out``, ...)
    load_scene : name or path -> :class:`~bearingshaft.scenes.Scene`

    Returns
    -------
    The exit code: 0 if every case ran, 1 if any failed (a refusal raises SweepError first).
    """
    scene = load_scene(args.scene)
    spec, source = spec_from_args(scene, args)
    workers = _positive_int(args.workers, "--workers")
    if workers is not None and args.scheduler:
        raise SweepError("--workers sizes the local cluster; with --scheduler the cluster's own workers run")
    update_reference = getattr(args, "update_reference", False)
    if update_reference and args.out:
        raise SweepError("--update-reference writes results/<scene>/sweep/: give it or --out, not both")
    # runs/<scene>/sweep/ by default; the committed results/<scene>/sweep/ tables are the reference
    out = Path(args.out) if args.out else Path("results" if update_reference else "runs") / scene.name / "sweep"
    check_out_dir(out)
    plan = build_plan(scene, spec, source, out, None if args.scheduler else workers or local_cores())
    progress = not args.no_progress
    print(f"[{scene.name}] sweep: {len(plan.cases)} cases ({spec.design} over "
          f"{', '.join(v.key for v in spec.vary)}), stages {', '.join(case_stages(scene))}", flush=True)
    result = run_sweep(plan, out, scheduler=args.scheduler, workers=workers, progress=progress)
    n = len(result.rows)
    print(f"[{scene.name}] sweep: {n - result.n_failed} of {n} cases ok ({result.n_resumed} already done, "
          f"{result.n_failed} failed) in {out} ({result.wall_s:.1f} s on {result.where})", flush=True)
    for r in result.rows:
        if r["status"] != "ok":
            print(f"  failed {r['case_id']} ({show_values([(v.key, r.get(v.key)) for v in spec.vary])}): "
                  f"{r['message']}", flush=True)
            break
    return 1 if result.n_failed else 0
