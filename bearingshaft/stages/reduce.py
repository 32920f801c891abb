"""Stage ``reduce``: the 3-D model reduced onto its tips (``rom.npz``), with its checks.

Writes ``rom.npz`` (reduced matrices, DOF map, provenance), ``cb_check.csv`` (pyyeti-style
identities, rigid-body mass and inertia, upper bounds on the full model's frequencies),
``gap_modes.csv`` (the open- and closed-gap (tied) modes of the full 3-D model that the
reduction represents, each beside the reduced mode it pairs with by MAC; see
:func:`bearingshaft.gap_modes.compare_gap_modes`), ``gap_modes.vtu`` (the reduced model's lowest open- and
closed-gap modes expanded to the mesh, unit peak, for ParaView) and ``gap_modes.png`` (the
three of each that move the gaps, rendered off screen), and prints a summary.

Numbers are written to the digits that are converged, so that a rerun writes the same
bytes: frequencies to 6 significant digits, errors in percent to 4 decimals (1e-6
relative: the full solver's eigenvalues are good to ~1e-9 above 100 Hz; below 1 Hz, the
assembly's bungee modes, only to a few 1e-5, so their last digit and errors below 0.005 % are
the solver's, not the reduction's), MAC and basis fractions to 6 decimals, the residuals of the
passed checks, round-off, as the power of ten that bounds them. The full modes come from a single-threaded factorization
(fem.contact.gap_modes), so a rerun writes the same bytes. Timings go to
``provenance.json`` and ``rom.npz`` only.

:func:`compute` reduces the model, pairs its modes with the full model's and expands them to the
mesh; :func:`bearingshaft.stages.reduce_files.write` writes the files. The reduction and the full model's
gap modes come from the reduced-model cache when it holds them (made by the same code from the same inputs:
the bits a rebuild gives), so the scenes of one 3-D model build them once.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bearingshaft.estimates import Estimate
from bearingshaft.gap_modes import STATES, GapModeComparison, compare_all, expand
from bearingshaft.reproduction import Reproduction, roundoff, within
from bearingshaft.scenes import Scene
from bearingshaft.stages.reduce_results import ReduceResult
from reduced.models.mesh_cache import build_fe
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.models.rom import ReducedModel, build_rom, from_cache

__all__ = ["DESCRIPTION", "ReduceResult", "compute", "estimate"]

ELASTIC_HZ = 100.0  # Hz, the upper-bound check starts here (the beam's first bending mode is ~730 Hz)
UPPER_BOUND_TOL = -1e-9  # relative: round-off of the elastic modes' eigenvalues (~1e-9 above 100 Hz)
N_SHOWN = 6  # lowest modes of each state expanded into gap_modes.vtu (with the gap-moving ones)


def _mode_shapes(rom: ReducedModel, n: int = N_SHOWN) -> tuple[dict, list]:
    """The reduced model's lowest open- and closed-gap modes expanded to the 3-D mesh (unit peak):
    ``({name: u}, [(title, u)])``, n of each state and the three lowest that move the gaps, which
    the figure shows."""
    system = rom.system()
    fields, shapes = {}, []
    for state in STATES:
        lm = linear_modes(system, state)
        shown = gap_moving_modes(system, state, 3).tolist()  # not always among the lowest n: an
        # assembly's swinging on its bungees and, without planar, its out-of-plane modes come first
        for i in sorted({*range(min(n, system.n)), *shown}):
            u = expand(rom, lm.phi[:, i])
            u = u / np.max(np.abs(u))
            fields[f"{state}{i + 1}_{lm.freq_hz[i]:.2f}Hz"] = u
            if i in shown:
                shapes.append((f"{state} gap, mode {i + 1}: {lm.freq_hz[i]:.2f} Hz", u))
    return fields, shapes


def _upper_bound_check(open_gap: GapModeComparison) -> dict:
    """The Rayleigh-Ritz check, as a ``cb_check.csv`` row: the planar basis lies in the full model's
    invariant subspace of the modes the tips move, so its k-th frequency bounds the k-th of those
    from above, and the MAC pairs are rank for rank. Checked on the elastic modes: below ELASTIC_HZ
    (springs, bungees) the full solver's eigenvalues carry ~1e-5."""
    bound = [(r["reduced_hz"] - r["full_hz"]) / r["full_hz"] for r in open_gap.rows if r["full_hz"] > ELASTIC_HZ]
    check = {"check": f"min(f_reduced - f_full) / f_full, open-gap MAC pairs above {ELASTIC_HZ:g} Hz "
                      "(>= 0: upper bounds)",
             "value": float(min(bound, default=0.0)), "tolerance": UPPER_BOUND_TOL}
    check["passed"] = check["value"] >= check["tolerance"]
    return check


def compute(scene: Scene, progress: bool, workdir) -> ReduceResult:
    """Reduce the scene's 3-D model (or load the reduction from the cache, which holds the same bits) and compare
    it with the full one.

    Parameters
    ----------
    scene : Scene
        A scene whose ``[model]`` is a reduced model (``kind = "rom"``).
    progress : bool
        Show progress bars.
    workdir : Path
        The stage's scratch folder (unused: nothing is streamed).

    Returns
    -------
    ReduceResult
        The reduced model with its checks, the full model, the open- and closed-gap comparisons
        and the expanded modes.
    """
    spec = scene.model
    rom = from_cache(spec)  # from the cache if it holds it: the bits of a rebuild (reduced.models.rom.reduction)
    rom, fe = build_rom(spec, progress=progress) if rom is None else (rom, build_fe(spec))  # the mesh cached
    comps = compare_all(rom, fe, spec)
    fields, shapes = _mode_shapes(rom)
    bound = _upper_bound_check(comps["open"])  # a cached entry written by this stage holds it already
    rom = replace(rom, checks=[c for c in rom.checks if c["check"] != bound["check"]] + [bound])
    return ReduceResult(scene, rom, fe, comps, fields, shapes)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Reduce the scene's 3-D model onto the tips by Craig-Bampton: the two gap coordinates as
boundary and the fixed-interface modes the scene keeps. Writes rom.npz (matrices, DOF map,
modes, checks; also stored in the reduced-model cache), cb_check.csv (pyyeti-style checks),
gap_modes.csv (full and reduced modes, open and tied tips, paired by MAC), gap_modes.png and
gap_modes.vtu."""


def estimate(scene: Scene) -> list[Estimate]:
    """Nothing beyond the 3-D model's own build, which the reduced-model cache bounds (no estimate).

    Parameters
    ----------
    scene : Scene
        A scene with a reduced model.

    Returns
    -------
    list of Estimate
        Empty: nothing beyond the 3-D model's own build.
    """
    return []




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
REPRODUCTION = Reproduction(rules=(
    roundoff("cb_check.csv", "value"),
    # the assembly's bungee modes (0.4-2.4 Hz) are resolved to a few 1e-5 by the full and the reduced solver (module
    # docstring): their sixth digit and errors below 0.005 % are the solvers', which another CPU or thread count
    # changes (up to 3e-5 in Hz and 0.0033 % in error between two machines, and between 1 and 2 threads); both are
    # compared to 1e-4, the errors in percent to 0.01
    within("gap_modes.csv", "full_hz", "reduced_hz", rtol=1e-4,
           why="frequencies of the bungee modes below 3 Hz are resolved to a few 1e-5"),
    within("gap_modes.csv", "error_pct", atol=0.01,
           why="errors of a few 0.001 % are the solvers' (the bungee modes are resolved to a few 1e-5)"),
))
