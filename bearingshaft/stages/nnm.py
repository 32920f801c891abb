"""Stage ``nnm``: linear modes (open and closed gap) and the exact NNM 2 relation.

Runs on the 3-DOF model and on a reduced 3-D model (``[model] kind = "rom"``: its linear
modes over the coordinates x1, x3, eta_i); only the symmetric 3-DOF model has the exact
NNM 2 relation, so a reduced model writes linear_modes.csv and the [fep] files.

Numbers go to the digits that a rerun on another machine reproduces (its CPU picks other
SIMD kernels in NumPy and OpenBLAS, which moves the last bits; measured by rerunning with
OpenBLAS's Sandy Bridge kernels and NumPy's AVX2/FMA paths disabled): closed-form and
eigenvalue frequencies and energies to :data:`VALUE_DIGITS` significant digits, frequencies
integrated by DOP853 (rtol 1e-13, moved by 1e-13) to :data:`INTEGRATED_DIGITS`, relative
errors to 3 digits and 0 below :data:`CHECK_RESOLUTION` (what the integrated reference
resolves), mode shapes to :data:`SHAPE_DECIMALS` decimals with the sign of their first
largest entry positive. The [fep] part: :mod:`bearingshaft.stages.fep`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from bearingshaft import plots
from bearingshaft.digits import sig, to_resolution
from bearingshaft.estimates import COPIES, FLOAT, JACOBIAN_COPIES, Estimate, n_dofs
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2

CHECK_CHI = (1.000001, 1.0001, 1.01, 1.1, 2.0, 10.0, 100.0, 1000.0)  # x0 / g checked by integration
VALUE_DIGITS = 12  # closed forms and 3 x 3 eigenvalues: exact to ~1e-15, moved by 1e-16 on another CPU
INTEGRATED_DIGITS = 11  # DOP853 periods at rtol 1e-13: moved by up to 1e-13 on another CPU
CHECK_RESOLUTION = 1e-12  # relative errors against the integrated periods: below this, 0 (seen <= 2e-13)
SHAPE_DECIMALS = 10  # mode shapes scaled to a largest entry of 1: round-off zeros (~1e-13) written 0
TIE = 1e-8  # entries within this of the largest are equal (x1 = -x3 in antisymmetric modes)


def unit_shape(phi: np.ndarray) -> np.ndarray:
    """``phi`` scaled so that its first largest entry (by magnitude, ties within :data:`TIE`) is 1.

    ``argmax |phi|`` alone picks between x1 and -x3 of an antisymmetric mode by round-off, which
    flips the sign of the written shape from one machine to another.
    """
    mag = np.abs(phi)
    k = int(np.flatnonzero(mag >= (1.0 - TIE) * mag.max())[0])
    return phi / phi[k]


def _shape_value(v: float) -> float:
    return round(float(v), SHAPE_DECIMALS) + 0.0  # + 0.0: no "-0.0"


def nnm_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """linear_modes.csv, nnm2_exact.csv, nnm2_check.csv, nnm2.png (and the [fep] files). Dense linear
    algebra on one BLAS thread: the same sums whatever the machine's core count."""
    with single_thread_blas():
        _nnm_stage(scene, writer, progress)


def _nnm_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    p = scene.model
    system, _ = model_system(p, progress)  # the 3-DOF model, or a reduced model from rom.npz / the cache
    modes = {s: linear_modes(system, s) for s in ("open", "closed")}
    rows = []
    for state, lm in modes.items():
        for r in range(system.n):
            shape = unit_shape(lm.phi[:, r])
            rows.append({"state": state, "mode": r + 1, "freq_hz": sig(lm.freq_hz[r], VALUE_DIGITS),
                         **{f"phi_{d}": _shape_value(shape[i]) for i, d in enumerate(system.dof_names)}})
    write_rows(writer.path("linear_modes.csv"), rows)
    writer.stats["open_hz"] = modes["open"].freq_hz.tolist()
    writer.stats["closed_hz"] = modes["closed"].freq_hz.tolist()

    if not isinstance(p, DiscreteParams):
        writer.stats["nnm2_exact"] = ("skipped: the exact NNM 2 relation is the symmetric 3-DOF model's; a reduced "
                                      "model has no closed form (the [fep] study's reference is shooting)")
    elif p.m1 != p.m3:
        writer.stats["nnm2_exact"] = "skipped: the exact NNM 2 relation needs m1 == m3"
    else:
        _nnm2_exact(scene, writer, progress, modes)
    if scene.fep is not None:
        from bearingshaft.stages.fep import fep_stage

        fep_stage(scene, writer, progress)


def _nnm2_exact(scene: Scene, writer: StageWriter, progress: bool, modes: dict) -> None:
    """nnm2_exact.csv, the check against integrated periods (nnm2_check.csv) and nnm2.png."""
    p = scene.model
    spec = scene.nnm
    E = np.logspace(np.log10(spec.energy_min_J), np.log10(spec.energy_max_J), spec.n_energy)
    f_exact = nnm2.frequency_from_energy(p, E)
    f_paper = nnm2.frequency_from_energy(p, E, paper=True)
    np.savetxt(writer.path("nnm2_exact.csv"), np.column_stack([E, f_exact]), delimiter=",",
               header="energy_J,freq_hz", comments="", fmt=f"%.{VALUE_DIGITS}g")
    checks = []
    if p.g > 0:
        for chi in tqdm(CHECK_CHI, desc=f"{scene.name}: NNM 2 periods by DOP853", disable=not progress,
                        leave=False):
            x0 = chi * p.g
            T = nnm2.period_by_integration(p, x0)
            f_int = 1.0 / T
            f_ex = 1.0 / nnm2.period_from_amplitude(p, x0)
            f_pa = 1.0 / nnm2.period_from_amplitude(p, x0, paper=True)
            checks.append({"x0_over_g": chi, "energy_J": float(nnm2.energy_from_amplitude(p, x0)),
                           "freq_integrated_hz": f_int, "freq_exact_hz": f_ex, "freq_paper_eq13_hz": f_pa,
                           "rel_err_exact": (f_ex - f_int) / f_int, "rel_err_paper": (f_pa - f_int) / f_int})
        digits = {"energy_J": VALUE_DIGITS, "freq_integrated_hz": INTEGRATED_DIGITS, "freq_exact_hz": VALUE_DIGITS,
                  "freq_paper_eq13_hz": VALUE_DIGITS}
        write_rows(writer.path("nnm2_check.csv"),
                   [{k: (to_resolution(v, CHECK_RESOLUTION, 3) if k.startswith("rel_err") else
                         sig(v, digits[k]) if k in digits else v) for k, v in c.items()} for c in checks])
        writer.stats["nnm2_max_rel_err_exact"] = max(abs(c["rel_err_exact"]) for c in checks)
        writer.stats["nnm2_max_rel_err_paper_eq13"] = max(abs(c["rel_err_paper"]) for c in checks)
    plots.nnm2_figure(E, f_exact, f_paper, checks, modes["open"].freq_hz, modes["closed"].freq_hz,
                      writer.path("nnm2.png"))


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Linear modes of the open and closed gaps, the exact NNM 2 relation of the symmetric 3-DOF
model checked against integrated periods, and with [fep] the frequency-energy plots of the
NNMs by harmonic balance and shooting with their stability. Writes linear_modes.csv,
nnm2_exact.csv, nnm2_check.csv, nnm2.png and, with [fep], fep.csv, fep.png, stability.csv,
tongues.csv, hb_convergence*.csv and fep.md."""


def estimate(scene: Scene) -> list[Estimate]:
    """HB Jacobians of the [fep] study and the [nnm] energy grid."""
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


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir) -> _Pending:
    return _Pending(scene, progress, {})


def write(result: _Pending, writer: StageWriter) -> None:
    nnm_stage(result.scene, writer, result.progress, **result.options)
