"""The stage registry: every stage of the pipeline, declared once.

A stage is what one subcommand runs on a scene: its entry says which tables ask for it, how to
compute it, how to write what it computed, what it will hold in memory (checked before any
work) and how the command line offers it. The pipeline (:mod:`bearingshaft.pipeline`),
``bearingshaft check``, the budget (:mod:`bearingshaft.budget`) and the command line
(:mod:`bearingshaft.cli`) read this table and nothing else.

The contract of a stage module (``bearingshaft/stages/<name>.py``)::

    compute(scene, progress, workdir, **options) -> result   # a frozen dataclass: arrays, numbers,
                                                             # solver statistics; no file is written
                                                             # but arrays streamed into ``workdir``
    estimate(scene) -> list[Estimate]                        # peak memory and disk, from the scene
    DESCRIPTION                                              # what the subcommand does and writes
    REPRODUCTION                                             # how its files compare with the reference

with the result dataclasses in ``<name>_results.py`` and the writers and figures in
``<name>_files.py``, whose ``write(result, writer)`` writes CSV/NPZ/UFF/Markdown and figures from the
result and runs no solver. It is the only part that loads matplotlib, and the registry imports it
only when a stage's files are written (:meth:`Stage.write`), so computing never loads it.
Bigger stages have more parts (``hammer_linear.py``, ``nnm_fep.py``); a stage imports no other
stage's parts: what two stages share goes in a helper module named for it.

To add a stage: write those modules, add one :class:`Stage` below in pipeline order; its
subcommand, its budget check and its place in ``bearingshaft run`` follow from the entry
(tests/test_architecture.py checks the imports).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import import_module

from bearingshaft.reproduction import Reproduction
from bearingshaft.scenes import Scene
from bearingshaft.stages import frc, frf, hammer, modal, nnm, reduce, ringdown, study, verify


@dataclass(frozen=True, slots=True)
class Option:
    """A command-line option of a stage's subcommand, passed to its compute as ``name=value``.

    Parameters
    ----------
    flag : str
        The option on the command line (``"--method"``).
    name : str
        Keyword of the stage's compute.
    help : str
        One line for ``--help``.
    metavar : str, optional
        Placeholder of its value in ``--help``.
    choices : tuple of str, optional
        The values allowed.
    """

    flag: str  # "--method"
    name: str  # keyword of compute
    help: str
    metavar: str | None = None
    choices: tuple[str, ...] | None = None


@dataclass(frozen=True, slots=True)
class Stage:
    """One stage: the tables that ask for it, its compute, its writer, its estimate, its subcommand.

    Parameters
    ----------
    name : str
        The stage's name and subcommand.
    asked_by : str
        The tables (or keys) that ask for it, as a refusal names them.
    wanted : callable
        ``wanted(scene) -> bool``: does the scene ask for it?
    compute : callable
        ``compute(scene, progress, workdir, **options) -> result``.
    estimate : callable
        ``estimate(scene) -> list[Estimate]``.
    help : str
        One line in ``bearingshaft --help``.
    description : str
        What the subcommand does and writes (``bearingshaft NAME --help``).
    options : tuple of Option
        Its command-line options.
    reproduction : Reproduction
        How its files compare with the committed reference (:mod:`bearingshaft.reproduction`).
    files : str
        The module of ``bearingshaft.stages`` that writes its files (default ``"<name>_files"``).
    """

    name: str
    asked_by: str  # the tables (or keys) that ask for it, as a refusal names them
    wanted: Callable[[Scene], bool]  # does the scene ask for it?
    compute: Callable  # compute(scene, progress, workdir, **options) -> result
    estimate: Callable  # estimate(scene) -> list[Estimate]
    help: str  # one line in `bearingshaft --help`
    description: str  # what the subcommand does and writes (`bearingshaft NAME --help`)
    options: tuple[Option, ...] = field(default=())
    reproduction: Reproduction = field(default=Reproduction())  # how its files compare with the reference
    files: str = ""  # bearingshaft.stages.<files>.write(result, writer); "" is "<name>_files"

    def write(self, result, writer) -> None:
        """Write ``result``'s files with ``bearingshaft.stages.<files>.write``, imported only now.

        Parameters
        ----------
        result : object
            What the stage's compute returned.
        writer : bearingshaft.output.StageWriter
            Where the files go (its ``stats`` are filled for provenance.json).

        Returns
        -------
        None
        """
        import_module(f"bearingshaft.stages.{self.files or self.name + '_files'}").write(result, writer)


STAGES: tuple[Stage, ...] = (
    Stage("modal", "[modal]", lambda s: s.modal is not None, modal.compute, modal.estimate,
          help="build the mesh and run the modal analysis of a 3-D scene",
          description=modal.DESCRIPTION,
          reproduction=modal.REPRODUCTION),
    Stage("reduce", '[model] kind = "rom"', lambda s: s.model_kind == "rom", reduce.compute,
          reduce.estimate, help="reduce the 3-D model to its tips (Craig-Bampton): rom.npz, cb_check.csv",
          description=reduce.DESCRIPTION,
          reproduction=reduce.REPRODUCTION),
    Stage("ringdown", "[ringdown]", lambda s: s.ringdown is not None and s.hammer is None,  # [hammer] records its own
          ringdown.compute, ringdown.estimate,
          help="free (or forced) response from the scene's initial state",
          description=ringdown.DESCRIPTION,
          options=(Option("--method", "method", "integrator (default: the scene's, else exact)",
                          choices=("exact", "explicit", "dop853")),),
          reproduction=ringdown.REPRODUCTION),
    Stage("hammer", "[hammer]", lambda s: s.hammer is not None, hammer.compute, hammer.estimate,
          help="virtual hammer test of the apparatus, every rig channel (UFF 58 out); --test FILE.uff compares a "
               "measured test",
          description=hammer.DESCRIPTION,
          options=(Option("--test", "test_file", "a measured test (UFF 58 time histories): the model is run at its "
                          "sampling, driven by its hammer channel, and compared channel for channel (default results "
                          "folder: runs/<scene>/test-<file name>/)", metavar="FILE.uff"),
                   Option("--window", "window", "with --test: the compared window in seconds (default [hammer] "
                          "compare_window_s, else the record)", metavar="START:END"),
                   Option("--measures", "measures", "with --test: the measures, comma separated, among time, ridges, "
                          "envelope, impacts, open, backbone (default all)", metavar="LIST")),
          reproduction=hammer.REPRODUCTION),
    Stage("frf", "[frf]", lambda s: s.frf is not None, frf.compute, frf.estimate,
          help="FRFs (H1, H2, coherence) and modal parameters (pLSCF, LSFD, MAC) of a hammer test; --test FILE.uff "
               "for a measured one",
          description=frf.DESCRIPTION,
          options=(Option("--test", "test_file", "a measured test (UFF 58 time histories of repeated blows: each force "
                          "record opens a blow) instead of the virtual one (default results folder: "
                          "runs/<scene>/test-<file name>/)", metavar="FILE.uff"),),
          reproduction=frf.REPRODUCTION),
    Stage("nnm", "[nnm]", lambda s: s.nnm is not None or s.fep is not None, nnm.compute,
          nnm.estimate, help="frequency-energy relations of the nonlinear normal modes",
          description=nnm.DESCRIPTION,
          reproduction=nnm.REPRODUCTION),
    Stage("study", "[work_precision], [stiff_cases] or [rom_convergence]",
          lambda s: s.work_precision is not None or s.stiff_cases is not None or s.rom_convergence is not None,
          study.compute, study.estimate, help="error against run time, stiff and extreme cases",
          description=study.DESCRIPTION,
          reproduction=study.REPRODUCTION),
    Stage("verify", "[verify]", lambda s: s.verify is not None, verify.compute, verify.estimate,
          help="verify the reduced model against the discrete model", description=verify.DESCRIPTION,
          reproduction=verify.REPRODUCTION),
    Stage("frc", "[frc]", lambda s: s.frc is not None, frc.compute, frc.estimate,
          help="forced-response curves by harmonic balance, stepped sine and stability",
          description=frc.DESCRIPTION,
          reproduction=frc.REPRODUCTION),
)

BY_NAME: dict[str, Stage] = {s.name: s for s in STAGES}


def stages_of(scene: Scene) -> tuple[str, ...]:
    """The stages ``scene`` asks for, in pipeline order.

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    tuple of str
    """
    return tuple(s.name for s in STAGES if s.wanted(scene))


def stage(name: str) -> Stage:
    """The registry entry of stage ``name`` (KeyError if there is none).

    Parameters
    ----------
    name : str
        The stage's name.

    Returns
    -------
    Stage

    Raises
    ------
    KeyError
        An unknown stage.
    """
    return BY_NAME[name]
