"""Stage ``reduce``: the 3-D model reduced onto its tips (``rom.npz``), with its checks.

Writes ``rom.npz`` (reduced matrices, DOF map, provenance), ``cb_check.csv`` (pyyeti-style
identities, rigid-body mass and inertia, upper bounds on the full model's frequencies) and
``gap_modes.csv``: the open- and closed-gap (tied) frequencies of the full 3-D model beside
the reduced model's, for the modes the tips can excite, and ``gap_modes.vtu``: the reduced
model's lowest open- and closed-gap modes expanded to the mesh (unit peak), for ParaView, and
``gap_modes.png``: the three of each that move the gaps, rendered off screen.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

from bearingshaft import __version__
from bearingshaft.output import StageWriter, git_commit, write_rows
from bearingshaft.scenes import Scene
from reduced.models.modes import linear_modes
from reduced.models.rom import build_rom, store_in_cache

N_FULL_MODES = 24  # full-model modes computed per contact state (the coupled ones are compared)
ELASTIC_HZ = 100.0  # Hz, the upper-bound check starts here (the beam's first bending mode is ~730 Hz)


def full_gap_modes(fe, spec, n_modes: int = N_FULL_MODES, Psi: np.ndarray | None = None) -> dict:
    """{state: GapModes} of the full model with the spec's contact (``Psi``: see fem.contact.gap_modes)."""
    from fem.contact import contact_pairs, gap_modes

    pairs = contact_pairs(fe, gap=spec.gap, k_g=spec.k_g)
    return {s: gap_modes(fe, pairs, s, n_modes, Psi=Psi) for s in ("open", "closed")}


def _mode_files(rom, fe, system, writer: StageWriter, n: int = 6) -> str:
    """The reduced model's lowest open- and closed-gap modes expanded to the 3-D mesh (unit peak):
    ``gap_modes.vtu`` (n of each) and ``gap_modes.png`` (the three lowest that move the gaps)."""
    from bearingshaft.render import render_shapes
    from fem.vtu import write_vtu
    from reduced.models.modes import gap_moving_modes

    fields, shapes = {}, []
    for state in ("open", "closed"):
        lm = linear_modes(system, state)
        shown = set(gap_moving_modes(system, state, 3).tolist())
        for i in range(min(n, system.n)):
            u = rom.Psi @ lm.phi[:2, i] + rom.Phi @ lm.phi[2:, i]
            u = u / np.max(np.abs(u))
            fields[f"{state}{i + 1}_{lm.freq_hz[i]:.2f}Hz"] = u
            if i in shown:
                shapes.append((f"{state} gap, mode {i + 1}: {lm.freq_hz[i]:.2f} Hz", u))
    write_vtu(fe, fields, writer.path("gap_modes.vtu"))
    return render_shapes(fe, shapes, writer.path("gap_modes.png"))


def reduce_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    spec = scene.model
    rom, fe = build_rom(spec, progress=progress)
    full = full_gap_modes(fe, spec, Psi=rom.Psi)
    system = rom.system()
    rows, bound = [], []
    for state in ("open", "closed"):
        f_rom = linear_modes(system, state).freq_hz
        g = full[state]
        for i, f in enumerate(g.freq_hz[g.coupled]):
            j = int(np.argmin(np.abs(np.log(f_rom / f))))  # nearest: a reduced model may hold an extra mode
            rows.append({"state": state, "mode": i + 1, "full_hz": float(f), "reduced_hz": float(f_rom[j]),
                         "relative_error": float((f_rom[j] - f) / f)})
            if state == "open" and f > ELASTIC_HZ and j == i:
                bound.append(rows[-1]["relative_error"])
    write_rows(writer.path("gap_modes.csv"), rows)
    writer.stats["pictures"] = _mode_files(rom, fe, system, writer)
    # Rayleigh-Ritz: a reduced frequency bounds the full one of the same rank from above. Checked on
    # the elastic modes: below ELASTIC_HZ (springs, bungees) the full solver's eigenvalues carry ~1e-5.
    checks = list(rom.checks) + [{
        "check": f"min(f_reduced - f_full) / f_full, coupled open-gap modes above {ELASTIC_HZ:g} Hz "
                 "(>= 0: upper bounds)",
        "value": float(min(bound, default=0.0)), "tolerance": -1e-9}]
    checks[-1]["passed"] = checks[-1]["value"] >= checks[-1]["tolerance"]
    write_rows(writer.path("cb_check.csv"), checks, ["check", "value", "tolerance", "passed"])
    provenance = {"scene": scene.name, "package_version": __version__, "git_commit": git_commit(),
                  "created_utc": datetime.now(UTC).isoformat(timespec="seconds")}
    rom = replace(rom, checks=checks, info={**rom.info, "provenance": provenance})
    rom.save(writer.path("rom.npz"))
    store_in_cache(rom, spec)  # the ringdowns of this scene then load it instead of rebuilding
    failed = [c["check"] for c in checks if not c["passed"]]
    writer.stats.update({"n_full_dofs": rom.info["n_full_dofs"], "n_modes": rom.n_modes,
                         "timing_s": rom.info["timing_s"], "checks_failed": failed, "gap_modes": rows})
    if progress:
        print(f"[{scene.name}] reduced {rom.info['n_full_dofs']} DOFs to {rom.n} "
              f"({rom.n_modes} fixed-interface modes) in {rom.info['timing_s']['total']:.1f} s; "
              f"checks {'all passed' if not failed else 'FAILED: ' + '; '.join(failed)}")
