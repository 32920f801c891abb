"""The ``reduce`` stage's files, from what :func:`bearingshaft.stages.reduce.compute` found.

``gap_modes.csv`` (the full model's modes in the reduction basis, each with its MAC partner),
``gap_modes.vtu`` and ``gap_modes.png`` (the reduced model's modes expanded to the mesh),
``cb_check.csv`` (the reduction's checks) and ``rom.npz`` (the model with its provenance; also
stored in the reduced-model cache). Numbers go to their converged digits (the stage's module
docstring says which); no solver runs here.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

from bearingshaft import __version__
from bearingshaft.digits import roundoff_bound
from bearingshaft.gap_modes import MAC_PAIR
from bearingshaft.output import StageWriter, git_commit, write_rows
from bearingshaft.stages.reduce_results import ReduceResult  # noqa: F401  (re-exported)
from reduced.models.rom import store_in_cache

GAP_FIELDS = ["state", "full_mode", "full_hz", "reduced_mode", "reduced_hz", "error_pct", "mac", "basis_fraction"]
CHECK_FIELDS = ["check", "value", "tolerance", "passed"]


def gap_rows_text(rows: list[dict]) -> list[dict]:
    """The rows of ``gap_modes.csv`` formatted to their converged digits.

    Parameters
    ----------
    rows : list of dict
        ``state``, ``full_mode``, ``full_hz``, ``reduced_mode``, ``reduced_hz``, ``error_pct``,
        ``mac``, ``basis_fraction`` per row.

    Returns
    -------
    list of dict
        The same keys, the numbers as text (other keys dropped).

    Examples
    --------
    >>> gap_rows_text([{"state": "open", "full_mode": 3, "full_hz": 731.3612345, "reduced_mode": 3,
    ...                 "reduced_hz": 731.3651, "error_pct": -0.000004, "mac": 0.99999991,
    ...                 "basis_fraction": 0.9999999}])[0]
    ... # doctest: +NORMALIZE_WHITESPACE
    {'state': 'open', 'full_mode': 3, 'full_hz': '731.361', 'reduced_mode': 3, 'reduced_hz': '731.365',
     'error_pct': '+0.0000', 'mac': '1.000000', 'basis_fraction': '1.000000'}
    """
    return [{"state": r["state"], "full_mode": r["full_mode"], "full_hz": f"{r['full_hz']:.6g}",
             "reduced_mode": r["reduced_mode"], "reduced_hz": f"{r['reduced_hz']:.6g}",
             "error_pct": f"{round(r['error_pct'], 4) + 0.0:+.4f}", "mac": f"{r['mac']:.6f}",
             "basis_fraction": f"{r['basis_fraction']:.6f}"} for r in rows]


def check_rows_text(checks: list[dict]) -> list[dict]:
    """The rows of ``cb_check.csv``: a passed check's residual is round-off (the identities hold exactly in
    exact arithmetic), so it is written as the power of ten that bounds it
    (:func:`bearingshaft.digits.roundoff_bound`: its digits, and even its sign, change from one CPU to
    another); a failed one to 3 significant digits.

    Parameters
    ----------
    checks : list of dict
        :func:`reduced.models.craig_bampton.cb_check` rows.

    Returns
    -------
    list of dict
        The rows with ``value`` and ``tolerance`` as text.

    Examples
    --------
    >>> check_rows_text([{"check": "M symmetric", "value": 1.234567e-16, "tolerance": 1e-9, "passed": True},
    ...                  {"check": "K", "value": 2.345e-3, "tolerance": 1e-9, "passed": False}])
    ... # doctest: +NORMALIZE_WHITESPACE
    [{'check': 'M symmetric', 'value': '1e-10', 'tolerance': '1e-09', 'passed': True},
     {'check': 'K', 'value': '0.00234', 'tolerance': '1e-09', 'passed': False}]
    """
    return [{**c, "value": f"{roundoff_bound(abs(c['value'])):g}" if c["passed"] else f"{c['value']:.3g}",
             "tolerance": f"{c['tolerance']:g}"} for c in checks]


def _mode_files(result: ReduceResult, writer: StageWriter) -> str:
    """``gap_modes.vtu`` (every expanded mode) and ``gap_modes.png`` (the gap-moving ones); the renderer used."""
    from bearingshaft.render import render_shapes
    from fem.vtu import write_vtu

    write_vtu(result.fe, result.mode_fields, writer.path("gap_modes.vtu"))
    return render_shapes(result.fe, result.mode_shapes, writer.path("gap_modes.png"))


def _summary(result: ReduceResult, writer: StageWriter) -> str:
    """The stage's summary lines: the reduction, the checks, each state's pairs and what is left out."""
    scene, rom, failed = result.scene, result.rom, result.failed
    lines = [f"[{scene.name}] reduced {rom.info['n_full_dofs']} DOFs to {rom.n} "
             f"({rom.n_modes} fixed-interface modes, up to {rom.omega_fixed.max() / (2 * np.pi):.6g} Hz); "
             f"checks {'all passed' if not failed else 'FAILED: ' + '; '.join(failed)}"
             if rom.n_modes else f"[{scene.name}] reduced {rom.info['n_full_dofs']} DOFs to the 2 gap coordinates"]
    for state, c in result.comparisons.items():
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


def write(result: ReduceResult, writer: StageWriter) -> None:
    """Write the ``reduce`` stage's files, put its statistics in ``writer.stats``, print its summary.

    Parameters
    ----------
    result : ReduceResult
        What :func:`bearingshaft.stages.reduce.compute` returned.
    writer : StageWriter
        Where the files go.
    """
    scene, comps = result.scene, result.comparisons
    rows = [r for c in comps.values() for r in c.rows]
    write_rows(writer.path("gap_modes.csv"), gap_rows_text(rows), GAP_FIELDS)
    writer.stats["pictures"] = _mode_files(result, writer)
    write_rows(writer.path("cb_check.csv"), check_rows_text(result.rom.checks), CHECK_FIELDS)
    provenance = {"scene": scene.name, "package_version": __version__, "git_commit": git_commit(),
                  "created_utc": datetime.now(UTC).isoformat(timespec="seconds")}
    rom = replace(result.rom, info={**result.rom.info, "provenance": provenance})
    rom.save(writer.path("rom.npz"))
    store_in_cache(rom, scene.model)  # the ringdowns of this scene then load it instead of rebuilding
    writer.stats.update({"n_full_dofs": rom.info["n_full_dofs"], "n_modes": rom.n_modes,
                         "timing_s": rom.info["timing_s"], "checks_failed": result.failed, "gap_modes": rows,
                         "left_out": [r for c in comps.values() for r in c.left_out],
                         "reduced_modes_unpaired": {s: (c.unpaired + 1).tolist() for s, c in comps.items()}})
    print(_summary(result, writer), flush=True)
