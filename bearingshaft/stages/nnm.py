"""Stage ``nnm``: linear modes (open and closed gap) and the exact NNM 2 relation.

Runs on the 3-DOF model and on a reduced 3-D model (``[model] kind = "rom"``: its linear
modes over the coordinates x1, x3, eta_i); only the symmetric 3-DOF model has the exact
NNM 2 relation, so a reduced model writes linear_modes.csv and the [fep] files. The [fep]
part: :mod:`bearingshaft.stages.nnm_fep`. :func:`compute` runs everything into an
:class:`~bearingshaft.stages.nnm_files.NNMResult`; :func:`write`
(:mod:`bearingshaft.stages.nnm_files`, which also says to how many digits each number is
written) writes the files listed in :data:`DESCRIPTION`.
"""

from __future__ import annotations

import numpy as np

from bearingshaft.estimates import COPIES, FLOAT, JACOBIAN_COPIES, Estimate, n_dofs
from bearingshaft.output import StageWriter
from bearingshaft.progress import bar as progress_bar
from bearingshaft.reproduction import Reproduction, exact, sensitive, within
from bearingshaft.scenes import Scene
from bearingshaft.stages.nnm_fep import compute_fep
from bearingshaft.stages.nnm_results import NNM2Exact, NNMResult
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2

CHECK_CHI = (1.000001, 1.0001, 1.01, 1.1, 2.0, 10.0, 100.0, 1000.0)  # x0 / g checked by integration


def compute(scene: Scene, progress: bool, workdir=None) -> NNMResult:
    """The linear modes, the exact NNM 2 relation with its check, and the [fep] study.

    Parameters
    ----------
    scene : a scene with an [nnm] or [fep] table
    progress : draw progress bars
    workdir : unused (nothing is streamed to disk)

    Returns
    -------
    NNMResult
        Dense linear algebra on one BLAS thread: the same sums whatever the machine's core count.
    """
    with single_thread_blas():
        p = scene.model
        system, _ = model_system(p, progress)  # the 3-DOF model, or a reduced model from rom.npz / the cache
        modes = {s: linear_modes(system, s) for s in ("open", "closed")}
        exact, skipped = None, ""
        if not isinstance(p, DiscreteParams):
            skipped = ("skipped: the exact NNM 2 relation is the symmetric 3-DOF model's; a reduced model has no "
                       "closed form (the [fep] study's reference is shooting)")
        elif p.m1 != p.m3:
            skipped = "skipped: the exact NNM 2 relation needs m1 == m3"
        else:
            exact = _nnm2_exact(scene, progress)
        fep = compute_fep(scene, progress) if scene.fep is not None else None
    return NNMResult(scene.name, tuple(system.dof_names), modes, exact, skipped, fep)


def _nnm2_exact(scene: Scene, progress: bool) -> NNM2Exact:
    """The exact relation on the [nnm] energy grid, the paper's, and both against periods
    integrated by DOP853 at the amplitudes :data:`CHECK_CHI` x the gap."""
    p = scene.model
    spec = scene.nnm
    E = np.logspace(np.log10(spec.energy_min_J), np.log10(spec.energy_max_J), spec.n_energy)
    f_exact = nnm2.frequency_from_energy(p, E)
    f_paper = nnm2.frequency_from_energy(p, E, paper=True)
    checks = []
    if p.gap > 0:
        for chi in progress_bar(CHECK_CHI, desc=f"{scene.name}: NNM 2 periods by DOP853", enabled=progress):
            x0 = chi * p.gap
            T = nnm2.period_by_integration(p, x0)
            f_int = 1.0 / T
            f_ex = 1.0 / nnm2.period_from_amplitude(p, x0)
            f_pa = 1.0 / nnm2.period_from_amplitude(p, x0, paper=True)
            checks.append({"x0_over_g": chi, "energy_J": float(nnm2.energy_from_amplitude(p, x0)),
                           "freq_integrated_hz": f_int, "freq_exact_hz": f_ex, "freq_paper_eq13_hz": f_pa,
                           "rel_err_exact": (f_ex - f_int) / f_int, "rel_err_paper": (f_pa - f_int) / f_int})
    return NNM2Exact(E, f_exact, f_paper, checks, p.gap > 0)


def nnm_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Compute and write the stage in one call (the pipeline calls :func:`compute` and :func:`write`).

    Parameters
    ----------
    scene : Scene
        A scene with an [nnm] or [fep] table.
    writer : StageWriter
        Where the files go.
    progress : bool
        Show progress bars.

    Returns
    -------
    None
    """
    from bearingshaft.stages import nnm_files  # matplotlib: loaded only when files are written

    nnm_files.write(compute(scene, progress, writer.scratch), writer)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Linear modes of the open and closed gaps, the exact NNM 2 relation of the symmetric 3-DOF
model checked against integrated periods, and with [fep] the frequency-energy plots of the
NNMs by harmonic balance and shooting with their stability. Writes linear_modes.csv,
nnm2_exact.csv, nnm2_check.csv and nnm2.png (the symmetric 3-DOF model) and, with [fep],
fep.csv, fep.png, stability.csv, tongues.csv, hb_convergence.csv and .png,
hb_convergence_timing.csv and .png, and fep.md (a reduced model)."""


def estimate(scene: Scene) -> list[Estimate]:
    """HB Jacobians of the [fep] study and the [nnm] energy grid.

    Parameters
    ----------
    scene : Scene
        A scene with an [nnm] or [fep] table.

    Returns
    -------
    list of Estimate
        One per table present: HB Jacobians at the largest H of [fep], the [nnm] energy grid.
    """
    n = n_dofs(scene)
    out = []
    if scene.fep is not None:
        H = max(scene.fep.harmonics + scene.fep.convergence_harmonics + (scene.fep.samples_study_harmonics,))
        size = (2 * H + 1) * n
        out.append(Estimate("nnm", JACOBIAN_COPIES * size**2 * FLOAT,
                            f"HB Jacobians of {size} x {size} (H = {H})", "[fep] harmonics"))
    if scene.nnm is not None:
        out.append(Estimate("nnm", COPIES * scene.nnm.n_energy * 64 * FLOAT,
                            f"{scene.nnm.n_energy} energies", "[nnm] n_energy"))
    return out


__all__ = ["CHECK_CHI", "DESCRIPTION", "compute", "estimate", "nnm_stage"]




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
CONTINUATION = ("the points of an HB continuation: its step path (accepted and rejected steps, the tongues it meets) "
                "is set by the last bits of each Newton solve, which another CPU changes")
REPRODUCTION = Reproduction(rules=(
    # a reduced model's matrices are reproducible across machines to ~1e-8 (the BLAS's rounding in the reduction);
    # its linear modes are written to 10 digits (the 3-DOF model's are exact to them)
    within("linear_modes.csv", rtol=1e-7, atol=1e-7,
           why="linear modes of a reduced model, reproducible to ~1e-8 (its matrices)"),
    sensitive("fep.csv", why=CONTINUATION),
    sensitive("stability.csv", why=CONTINUATION + " (stability at those points)"),
    sensitive("tongues.csv", why=CONTINUATION + " (where it meets the tongues)"),
    sensitive("hb_convergence.csv", why=CONTINUATION + " (its points, reach and the errors at them)"),
    exact("fep.md", why="the stage's conclusions, written to the digits that reproduce"),
))
