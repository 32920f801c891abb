"""Stage ``reduce``: the 3-D model reduced onto its tips (``rom.npz``), with its checks.

Writes ``rom.npz`` (reduced matrices, DOF map, provenance), ``cb_check.csv`` (pyyeti-style
identities, rigid-body mass and inertia, upper bounds on the full model's frequencies),
``gap_modes.csv`` (the open- and closed-gap (tied) modes of the full 3-D model that the
reduction represents, each beside the reduced mode it pairs with by MAC; see
:func:`compare_gap_modes`), ``gap_modes.vtu`` (the reduced model's lowest open- and
closed-gap modes expanded to the mesh, unit peak, for ParaView) and ``gap_modes.png`` (the
three of each that move the gaps, rendered off screen), and prints a summary.

Numbers are written to the digits that are converged, so that a rerun writes the same
bytes: frequencies to 6 significant digits, errors in percent to 4 decimals (1e-6
relative: the full solver's eigenvalues are good to ~1e-9 above 100 Hz; below 1 Hz, the
assembly's bungee modes, only to a few 1e-5, so their last digit and errors below 0.005 % are
the solver's, not the reduction's), MAC and basis fractions to 6 decimals, check residuals
to 3 significant digits. The full modes come from a single-threaded factorization
(fem.contact.gap_modes), so a rerun writes the same bytes. Timings go to
``provenance.json`` and ``rom.npz`` only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import UTC, datetime

import numpy as np

from bearingshaft import __version__
from bearingshaft.estimates import Estimate
from bearingshaft.output import StageWriter, git_commit, write_rows
from bearingshaft.scenes import Scene
from reduced.models.modes import LinearModes, linear_modes
from reduced.models.rom import ReducedModel, build_rom, store_in_cache

N_FULL_MODES = 24  # full-model modes computed per contact state (all of them, coupled or not)
ELASTIC_HZ = 100.0  # Hz, the upper-bound check starts here (the beam's first bending mode is ~730 Hz)
MAC_PAIR = 0.9  # a full mode is in the reduced basis, and a reduced mode its partner, above this (see below)
STATES = ("open", "closed")


def full_gap_modes(fe, spec, n_modes: int = N_FULL_MODES, Psi: np.ndarray | None = None) -> dict:
    """{state: GapModes} of the full model with the spec's contact (``Psi``: see fem.contact.gap_modes)."""
    from fem.contact import contact_pairs, gap_modes

    pairs = contact_pairs(fe, gap=spec.gap, k_g=spec.k_g)
    return {s: gap_modes(fe, pairs, s, n_modes, Psi=Psi) for s in STATES}


def expand(rom: ReducedModel, q: np.ndarray) -> np.ndarray:
    """(N, ...) full displacements u = Psi q_b + Phi eta of reduced coordinates q = [x1, x3, eta] (n, ...)."""
    return rom.Psi @ q[:2] + rom.Phi @ q[2:]


@dataclass(frozen=True, eq=False)
class GapModeComparison:
    """The full model's modes of one contact state against the reduced model's, by mass-weighted MAC."""

    state: str
    full_hz: np.ndarray  # (m,) Hz, the full model's lowest modes
    reduced: LinearModes  # the reduced model's modes (n of them)
    mac: np.ndarray  # (m, n) MAC_ij = (v_i^T M u_j)^2 / ((v_i^T M v_i)(u_j^T M u_j))
    basis_fraction: np.ndarray  # (m,) share of full mode i in span[Psi, Phi] (M-norm); = sum_j MAC_ij
    rows: list[dict]  # one per full mode in the basis: its reduced partner, error, MAC
    left_out: list[dict]  # one per full mode not in the basis: why
    unpaired: np.ndarray  # (k,) reduced modes that are no full mode's partner (index into ``reduced``)


def compare_gap_modes(rom: ReducedModel, fe, gm, planar: bool) -> GapModeComparison:
    """Pair the reduced model's modes with the full model's ``gm`` (a fem.contact.GapModes) by MAC.

    The reduced modes, expanded to the full DOFs (u = Psi q_b + Phi eta), are M-orthonormal
    and span the reduction basis V = [Psi, Phi]. With the mass-weighted MAC (the kinetic-energy
    inner product: independent of how finely the mesh samples a region, and exactly 0 between
    two distinct full modes), a full mode v_i splits as

        sum_j MAC_ij = v_i^T M V (V^T M V)^-1 V^T M v_i / (v_i^T M v_i) = basis_fraction_i <= 1.

    A full mode is one the reduced model is meant to keep when the basis holds at least
    ``MAC_PAIR`` = 0.9 of it; its partner is the reduced mode of largest MAC. Above 0.5 a
    partner is unique both ways (by Bessel's inequality at most one reduced mode can hold more
    than half of a full mode, and at most one full mode more than half of a reduced mode); 0.9,
    the usual test-analysis correlation threshold, asks that the pair share 90 % of their
    kinetic energy. On the impact beam the pairs measure >= 0.998 and every other full mode
    <= 1e-3 of the basis, so nothing depends on where between the threshold sits.

    Full modes outside the basis are listed with the reason: antisymmetric in y (out of
    plane: the tips act in y = 0 and ``planar`` keeps no such mode), symmetric but not moved by
    the tips (no coupling M_bq: surge, axial, z-antisymmetric modes), or moved by the tips but
    beyond the fixed-interface modes kept. Reduced modes that are no full mode's partner (those
    above the highest full mode computed, which cannot be checked) are in ``unpaired``.
    """
    red = linear_modes(rom.system(), gm.state)
    U = expand(rom, red.phi)
    MU = fe.M @ U
    Mv = fe.M @ gm.phi
    vv = np.einsum("ij,ij->j", gm.phi, Mv)
    uu = np.einsum("ij,ij->j", U, MU)
    mac = (gm.phi.T @ MU) ** 2 / np.outer(vv, uu)
    V = np.hstack([rom.Psi, rom.Phi])
    p = V.T @ Mv  # (n, m)
    fraction = np.einsum("ij,ij->j", p, np.linalg.solve(rom.M, p)) / vv
    f_fixed_max = float(rom.omega_fixed.max() / (2 * np.pi)) if rom.n_modes else 0.0
    rows, left_out = [], []
    for i, f in enumerate(gm.freq_hz):
        if fraction[i] >= MAC_PAIR:
            j = int(np.argmax(mac[i]))
            rows.append({"state": gm.state, "full_mode": i + 1, "full_hz": float(f), "reduced_mode": j + 1,
                         "reduced_hz": float(red.freq_hz[j]), "error_pct": float(100 * (red.freq_hz[j] - f) / f),
                         "mac": float(mac[i, j]), "basis_fraction": float(fraction[i])})
            continue
        if gm.symmetric[i] < 0:
            kind, why = "out of plane", "antisymmetric in y (out of plane): the tips cannot excite it" + (
                "; planar keeps no such mode" if planar else "")
        elif not gm.coupled[i]:
            kind, why = "not moved by the tips", "symmetric in y but not moved by the tips (no coupling to x1, x3)"
        else:
            kind, why = "beyond the basis", (f"moved by the tips, beyond the {rom.n_modes} fixed-interface "
                                             f"mode(s) kept (highest {f_fixed_max:.6g} Hz)")
        left_out.append({"state": gm.state, "full_mode": i + 1, "full_hz": float(f), "kind": kind, "reason": why,
                         "basis_fraction": float(fraction[i])})
    paired = {r["reduced_mode"] - 1 for r in rows}
    unpaired = np.array([j for j in range(len(red.freq_hz)) if j not in paired], dtype=int)
    return GapModeComparison(gm.state, gm.freq_hz, red, mac, fraction, rows, left_out, unpaired)


def compare_all(rom: ReducedModel, fe, spec, full: dict | None = None) -> dict[str, GapModeComparison]:
    """{state: GapModeComparison} of the reduced model against the full one (computed unless given)."""
    full = full_gap_modes(fe, spec, Psi=rom.Psi) if full is None else full
    return {s: compare_gap_modes(rom, fe, full[s], spec.planar) for s in STATES}


def left_out_summary(comp: GapModeComparison) -> list[tuple[str, list[float]]]:
    """[(reason, [full_hz, ...])] of the full modes outside the basis, grouped by reason in order."""
    groups: dict[str, list[float]] = {}
    for r in comp.left_out:
        groups.setdefault(r["reason"], []).append(r["full_hz"])
    return list(groups.items())


GAP_FIELDS = ["state", "full_mode", "full_hz", "reduced_mode", "reduced_hz", "error_pct", "mac", "basis_fraction"]


def gap_rows_text(rows: list[dict]) -> list[dict]:
    """The rows of ``gap_modes.csv`` formatted to their converged digits."""
    return [{"state": r["state"], "full_mode": r["full_mode"], "full_hz": f"{r['full_hz']:.6g}",
             "reduced_mode": r["reduced_mode"], "reduced_hz": f"{r['reduced_hz']:.6g}",
             "error_pct": f"{round(r['error_pct'], 4) + 0.0:+.4f}", "mac": f"{r['mac']:.6f}",
             "basis_fraction": f"{r['basis_fraction']:.6f}"} for r in rows]


def _mode_files(rom, fe, system, writer: StageWriter, n: int = 6) -> str:
    """The reduced model's lowest open- and closed-gap modes expanded to the 3-D mesh (unit peak):
    ``gap_modes.vtu`` (n of each) and ``gap_modes.png`` (the three lowest that move the gaps)."""
    from bearingshaft.render import render_shapes
    from fem.vtu import write_vtu
    from reduced.models.modes import gap_moving_modes

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
    write_vtu(fe, fields, writer.path("gap_modes.vtu"))
    return render_shapes(fe, shapes, writer.path("gap_modes.png"))


def _summary(scene: Scene, rom: ReducedModel, comps: dict[str, GapModeComparison], failed: list[str],
             writer: StageWriter) -> str:
    lines = [f"[{scene.name}] reduced {rom.info['n_full_dofs']} DOFs to {rom.n} "
             f"({rom.n_modes} fixed-interface modes, up to {rom.omega_fixed.max() / (2 * np.pi):.6g} Hz); "
             f"checks {'all passed' if not failed else 'FAILED: ' + '; '.join(failed)}"
             if rom.n_modes else f"[{scene.name}] reduced {rom.info['n_full_dofs']} DOFs to the 2 gap coordinates"]
    for state, c in comps.items():
        if c.rows:
            worst = max(c.rows, key=lambda r: abs(r["error_pct"]))
            text = (f"  {state} gap: {len(c.rows)} of the {len(c.full_hz)} lowest full modes in the basis, worst "
                    f"{worst['error_pct']:+.4f} % (full mode {worst['full_mode']}, {worst['full_hz']:.6g} Hz), "
                    f"lowest MAC {min(r['mac'] for r in c.rows):.6f}")
        else:
            text = f"  {state} gap: none of the {len(c.full_hz)} lowest full modes is in the basis"
        kinds: dict[str, int] = {}
        for r in c.left_out:
            kinds[r["kind"]] = kinds.get(r["kind"], 0) + 1
        text += "; left out: " + (", ".join(f"{n} {k}" for k, n in kinds.items()) or "none")
        if len(c.unpaired):
            above = int(np.sum(c.reduced.freq_hz[c.unpaired] > c.full_hz.max()))
            text += (f"; {len(c.unpaired)} reduced mode(s) without a full partner ({above} above the highest full "
                     f"mode computed, {c.full_hz.max():.6g} Hz)")
        unpaired = [r for r in c.rows if r["mac"] < MAC_PAIR]
        if unpaired:
            text += f"; WARNING: {len(unpaired)} full mode(s) in the basis without a reduced partner of MAC >= 0.9"
        lines.append(text)
    lines.append("  files: " + ", ".join(sorted(p.name for p in writer.scratch.iterdir())))
    return "\n".join(lines)


def reduce_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Reduce the scene's 3-D model, compare it with the full one, write its files, print a summary."""
    spec = scene.model
    rom, fe = build_rom(spec, progress=progress)
    comps = compare_all(rom, fe, spec)
    rows = [r for c in comps.values() for r in c.rows]
    write_rows(writer.path("gap_modes.csv"), gap_rows_text(rows), GAP_FIELDS)
    system = rom.system()
    writer.stats["pictures"] = _mode_files(rom, fe, system, writer)
    # Rayleigh-Ritz: the planar basis lies in the full model's invariant subspace of the modes the
    # tips move, so its k-th frequency bounds the k-th of those from above, and the MAC pairs are
    # rank for rank. Checked on the elastic modes: below ELASTIC_HZ (springs, bungees) the full
    # solver's eigenvalues carry ~1e-5.
    bound = [(r["reduced_hz"] - r["full_hz"]) / r["full_hz"] for r in comps["open"].rows if r["full_hz"] > ELASTIC_HZ]
    checks = list(rom.checks) + [{
        "check": f"min(f_reduced - f_full) / f_full, open-gap MAC pairs above {ELASTIC_HZ:g} Hz "
                 "(>= 0: upper bounds)",
        "value": float(min(bound, default=0.0)), "tolerance": -1e-9}]
    checks[-1]["passed"] = checks[-1]["value"] >= checks[-1]["tolerance"]
    write_rows(writer.path("cb_check.csv"),
               [{**c, "value": f"{c['value']:.3g}", "tolerance": f"{c['tolerance']:g}"} for c in checks],
               ["check", "value", "tolerance", "passed"])
    provenance = {"scene": scene.name, "package_version": __version__, "git_commit": git_commit(),
                  "created_utc": datetime.now(UTC).isoformat(timespec="seconds")}
    rom = replace(rom, checks=checks, info={**rom.info, "provenance": provenance})
    rom.save(writer.path("rom.npz"))
    store_in_cache(rom, spec)  # the ringdowns of this scene then load it instead of rebuilding
    failed = [c["check"] for c in checks if not c["passed"]]
    writer.stats.update({"n_full_dofs": rom.info["n_full_dofs"], "n_modes": rom.n_modes,
                         "timing_s": rom.info["timing_s"], "checks_failed": failed, "gap_modes": rows,
                         "left_out": [r for c in comps.values() for r in c.left_out],
                         "reduced_modes_unpaired": {s: (c.unpaired + 1).tolist() for s, c in comps.items()}})
    print(_summary(scene, rom, comps, failed, writer), flush=True)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Reduce the scene's 3-D model onto the tips by Craig-Bampton: the two gap coordinates as
boundary and the fixed-interface modes the scene keeps. Writes rom.npz (matrices, DOF map,
modes, checks; also stored in the reduced-model cache), cb_check.csv (pyyeti-style checks),
gap_modes.csv (full and reduced modes, open and tied tips, paired by MAC), gap_modes.png and
gap_modes.vtu."""


def estimate(scene: Scene) -> list[Estimate]:
    """Nothing beyond the 3-D model's own build, which the reduced-model cache bounds (no estimate)."""
    return []


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir) -> _Pending:
    return _Pending(scene, progress, {})


def write(result: _Pending, writer: StageWriter) -> None:
    reduce_stage(result.scene, writer, result.progress, **result.options)
