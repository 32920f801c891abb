"""Stage ``nnm``: linear modes (open and closed gap) and the exact NNM 2 relation."""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from bearingshaft import plots
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from reduced.models.modes import linear_modes
from reduced.periodic import nnm2

CHECK_CHI = (1.000001, 1.0001, 1.01, 1.1, 2.0, 10.0, 100.0, 1000.0)  # x0 / g checked by integration


def nnm_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    p = scene.model
    system = p.system()
    modes = {s: linear_modes(system, s) for s in ("open", "closed")}
    rows = []
    for state, lm in modes.items():
        for r in range(system.n):
            shape = lm.phi[:, r] / lm.phi[np.argmax(np.abs(lm.phi[:, r])), r]
            rows.append({"state": state, "mode": r + 1, "freq_hz": lm.freq_hz[r],
                         **{f"phi_{d}": shape[i] for i, d in enumerate(system.dof_names)}})
    write_rows(writer.path("linear_modes.csv"), rows)
    writer.stats["open_hz"] = modes["open"].freq_hz.tolist()
    writer.stats["closed_hz"] = modes["closed"].freq_hz.tolist()

    if p.m1 != p.m3:
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
               header="energy_J,freq_hz", comments="", fmt="%.17g")
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
        write_rows(writer.path("nnm2_check.csv"), checks)
        writer.stats["nnm2_max_rel_err_exact"] = max(abs(c["rel_err_exact"]) for c in checks)
        writer.stats["nnm2_max_rel_err_paper_eq13"] = max(abs(c["rel_err_paper"]) for c in checks)
    plots.nnm2_figure(E, f_exact, f_paper, checks, modes["open"].freq_hz, modes["closed"].freq_hz,
                      writer.path("nnm2.png"))
