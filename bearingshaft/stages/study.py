"""Stage ``study``: error against run time, the stiff and extreme cases, and (reduced model)
the convergence with the number of fixed-interface modes.

Files. Science files hold no wall-clock time, so a rerun of the same code on the same
machine writes them byte for byte; run times go to files whose name ends in ``_timing``
(the project's convention, tests/test_reproducible.py):

- ``[work_precision]``: ``work_precision.csv`` (method, setting, error, n_steps, dt_s),
  ``work_precision_timing.csv`` (method, setting, runtime_s) and
  ``work_precision_timing.png`` (error against run time);
- ``[stiff_cases]``: ``stiff_cases.csv`` (``rom_stiff_cases.csv`` for a reduced model) and
  ``stiff_cases_timing.csv`` (``rom_stiff_cases_timing.csv``): the run time of each case;
- ``[rom_convergence]``: ``rom_convergence.csv``, ``rom_convergence_timing.csv`` (Craig-Bampton
  build and run times) and ``rom_convergence_timing.png`` (its second panel is error against
  run time);
- ``study.md`` (the findings) and ``study_timing.md`` (the run-time tables).

Digits (the constants are in :mod:`bearingshaft.stages.study_files`). A rerun on another
machine picks other SIMD kernels in NumPy and OpenBLAS (chosen at run time from the CPU), which
changes the last bits of every sum. Numbers are therefore written to the digits that survive
that change, measured by rerunning this stage with OpenBLAS's Sandy Bridge kernels and NumPy's
AVX2/FMA paths disabled: the exact reference moved by 3e-11 (relative), so explicit errors keep
``ERROR_DIGITS`` significant digits; quantities at round-off level (the exact integrator's
energy balance, the exact reference against DOP853) are written as the power of ten that bounds
them, at least :data:`~bearingshaft.digits.ROUNDOFF_FLOOR` (:func:`~bearingshaft.digits.roundoff_bound`:
their size moved by up to 6x on the other CPU); DOP853's own error stepping over the contact
switches without events changed by up to 3x and is written to ``SENSITIVE_DIGITS`` digits.
Event counts and penetrations of long impacting runs are sensitive by nature (the motion is
chaotic): study.md says so.

:func:`compute` runs the studies (on one BLAS thread); :mod:`bearingshaft.stages.study_files`
writes their files.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bearingshaft.estimates import Estimate, history_bytes, n_dofs
from bearingshaft.gap_modes import full_gap_modes
from bearingshaft.progress import CaseBar, ProgressBar
from bearingshaft.reproduction import Reproduction, chaotic, roundoff, within
from bearingshaft.scenes import Scene
from bearingshaft.stages.study_results import CONVERGENCE_BUDGET_S, StudyResult, step_basis
from reduced._blas import single_thread_blas
from reduced.studies import STIFF_FIELDS, rom_case, rom_convergence, stiff_cases, work_precision

__all__ = ["DESCRIPTION", "StudyResult", "compute", "estimate"]

ROM_MAX_EXPLICIT_STEPS = 1e8  # explicit stiff-case runs of the reduced model predicted beyond this
# are refused (~20 s at 7 DOFs; a 10 s run at k_g = 1e11 would need ~1.2e8)


def compute(scene: Scene, progress: bool, workdir) -> StudyResult:
    """Run the studies the scene asks for (module docstring).

    Small dense linear algebra runs on one BLAS thread: faster on busy cores, and the same sums
    whatever the machine's core count.

    Parameters
    ----------
    scene : Scene
        A scene with a ``[work_precision]``, ``[rom_convergence]`` or ``[stiff_cases]`` table.
    progress : bool
        Show progress bars.
    workdir : Path
        The stage's scratch folder (unused: the studies keep rows, not histories).

    Returns
    -------
    StudyResult
        The rows of each study asked for.
    """
    out: dict = {}
    with single_thread_blas():
        if scene.work_precision is not None:
            out["work_precision"], out["explicit_order"] = _work_precision(scene, progress)
        if scene.rom_convergence is not None:
            out["rom_convergence"], out["n_full_dofs"] = _rom_convergence(scene, progress)
        if scene.stiff_cases is not None:
            out["stiff_cases"] = _stiff_cases(scene, progress)
            out["stiff_fields"] = tuple(STIFF_FIELDS)
    return StudyResult(scene, **out)


def _work_precision(scene: Scene, progress: bool) -> tuple[list[dict], float]:
    """(rows, observed order of the explicit integrator) of the scene's [work_precision]."""
    wp = scene.work_precision
    bar = ProgressBar(f"{scene.name}: work-precision", progress)
    rows, order = work_precision(
        scene.model.system(), np.array(scene.initial.x0_m), np.array(scene.initial.v0_m_s), wp.window_s,
        wp.sample_rate_hz, wp.explicit_omega_dt, wp.dop853_rtol, wp.repeats, progress=bar,
    )
    bar.close()
    return rows, order


def _stiff_cases(scene: Scene, progress: bool) -> list[dict]:
    """The rows of the scene's [stiff_cases], of its discrete or reduced model."""
    sc = scene.stiff_cases
    bar = CaseBar(f"{scene.name}: stiff cases", progress)
    if scene.model_kind == "rom":
        spec = scene.model
        base = rom_case(spec.reduced(progress), spec)
        extra = {"long_duration_s": sc.long_duration_s, "max_steps": ROM_MAX_EXPLICIT_STEPS,
                 "step_basis": step_basis(scene)}
    else:
        base, extra = scene.model, {"long_duration_s": sc.long_duration_s}
    rows = stiff_cases(base, sc.k_g, sc.gap, sc.speed, sc.c, sc.duration_s, sc.sample_rate_hz, sc.methods,
                       progress=bar, **extra)
    bar.close()
    return rows


def _rom_convergence(scene: Scene, progress: bool) -> tuple[list[dict], int]:
    """(rows, DOFs of the 3-D model) of the scene's [rom_convergence]: the model reduced with each
    mode count, against the full model's coupled frequencies and the largest count's ringdown."""
    from fem.model import build_system
    from reduced.models.mesh_cache import cached_mesh
    from reduced.models.rom import build_rom

    rc, spec = scene.rom_convergence, scene.model
    fem_model = spec.fe_model()
    fe = build_system(fem_model, mesh=cached_mesh(fem_model.geometry()))  # gmsh's mesh, cached
    full = full_gap_modes(fe, spec)
    full_hz = {s: g.freq_hz[g.coupled] for s, g in full.items()}
    bar = ProgressBar(f"{scene.name}: reduced model vs modes", progress)
    roms = {}
    for i, n in enumerate(sorted(set(rc.modes))):
        roms[n] = build_rom(replace(spec, n_modes=n), fe=fe)[0]
        bar(0.2 * (i + 1) / len(rc.modes))
    rows = rom_convergence(roms, full_hz, scene.initial.x0_m, scene.initial.v0_m_s, rc.window_s,
                           rc.sample_rate_hz, rc.n_compare, rc.repeats, CONVERGENCE_BUDGET_S,
                           progress=lambda f: bar(0.2 + 0.8 * f), step_basis=step_basis(scene))
    bar.close()
    return rows, fe.n_dofs


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """The integrators' error against run time ([work_precision]), stiff and extreme parameters
([stiff_cases]) and, for a reduced model, its convergence with the number of modes
([rom_convergence]). Writes work_precision.csv, work_precision_timing.csv and .png;
stiff_cases.csv and stiff_cases_timing.csv (rom_stiff_cases.csv and rom_stiff_cases_timing.csv
for a reduced model); rom_convergence.csv, rom_convergence_timing.csv and .png; study.md
(every number reproduced by a rerun) and study_timing.md (the run times)."""


def estimate(scene: Scene) -> list[Estimate]:
    """The sampled histories each study holds at once.

    Parameters
    ----------
    scene : Scene
        A scene with [work_precision], [stiff_cases] or [rom_convergence] tables.

    Returns
    -------
    list of Estimate
        One per study table present (:func:`bearingshaft.estimates.history_bytes`).
    """
    n = n_dofs(scene)
    out = []
    if scene.work_precision is not None:
        w = scene.work_precision
        runs = len(w.explicit_omega_dt) + len(w.dop853_rtol) + 1
        samples = w.window_s * w.sample_rate_hz + 1
        out.append(Estimate("study", history_bytes(samples, n, runs),
                            f"{runs} runs of {samples:.3g} samples", "[work_precision] window_s or sample_rate_hz"))
    if scene.stiff_cases is not None:
        s = scene.stiff_cases
        samples = max(s.duration_s, s.long_duration_s) * s.sample_rate_hz + 1
        out.append(Estimate("study", history_bytes(samples, n, len(s.methods)),
                            f"{len(s.methods)} runs of {samples:.3g} samples",
                            "[stiff_cases] duration_s, long_duration_s or sample_rate_hz"))
    if scene.rom_convergence is not None:
        c = scene.rom_convergence
        samples = c.window_s * c.sample_rate_hz + 1
        out.append(Estimate("study", history_bytes(samples, max(c.modes) + 2, len(c.modes)),
                            f"{len(c.modes)} models of up to {max(c.modes) + 2} DOFs, {samples:.3g} samples",
                            "[rom_convergence] window_s or sample_rate_hz"))
    return out




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
STIFF = ("event counts, largest penetration and the explicit scheme's energy error of 0.2-10 s impacting runs, "
         "chaotic (each case has its own parameters; no Lyapunov exponent is measured per case)")
DOP853 = ("DOP853 without events steps over the contact switches: its error depends on where its steps fall, which "
          "round-off moves (another CPU: up to 3x)")
REDUCED = "a reduced model against the full one: their frequencies are reproducible across machines to ~1e-8"
REPRODUCTION = Reproduction(rules=(
    within("work_precision.csv", "error", "n_steps", factor=3.0, rows=r"^dop853,", why=DOP853),
    roundoff("work_precision.csv", "error", rows=r"^exact,"),
    roundoff("*stiff_cases.csv", "energy_balance_error", rows=r",exact,"),
    chaotic("*stiff_cases.csv", "energy_balance_error", "n_steps", "n_events", "max_penetration_m", why=STIFF),
    within("rom_convergence.csv", atol=1e-8, rtol=1e-8, why=REDUCED),
    within("study.md", r"^\| dop853 \|", factor=3.0, why=DOP853),
    roundoff("study.md", r"^\| exact \| < "),
    chaotic("study.md", r"^\| explicit \| [0-9.e+-]+ \| \(", r"^\| (exact|explicit) \| [0-9.]+ \| ok \|", why=STIFF),
    within("study.md", r"^\| [0-9]+ \| [0-9]+ \| ", atol=1e-8, rtol=1e-8, why=REDUCED),
))
