"""Stage ``verify``: the reduced 3-D model against the paper's three-mass model.

The scene's reduced model (Craig-Bampton on the tips' gap coordinates x1, x3 and, for the
comparison to be one to one, one fixed-interface mode: the first bending mode) is read as a
three-mass model (:func:`reduced.models.identify.identify_discrete`). Four models are then compared:
the full 3-D model, the reduced model, the identified three-mass model and Table 1's.

Writes ``identified.csv`` (parameters: Table 1, identified, relative difference),
``residuals.csv`` (what the three-mass form cannot carry), ``verify.csv`` (open- and
closed-gap frequencies of the lowest full modes in the reduction basis, paired with the
reduced model's by MAC as in the reduce stage, relative differences against the full
model), ``nnm_backbones.csv`` (HB, H = 1, of the three NNMs of the reduced, identified and
Table-1 models), ``verify.png`` and ``verify.md`` (the numbers, explained, and the full
modes the reduction leaves out, with the reason), and prints a summary.
Numbers are written to their converged digits (a rerun writes the same bytes); the stage's
wall time goes to ``provenance.json`` only. :func:`compute` builds, identifies and integrates;
:mod:`bearingshaft.stages.verify_files` writes and draws.
The ringdowns start from the paper's three initial conditions, read from the built-in scenes
``discrete-antisymmetric``, ``discrete-impulse`` and ``discrete-symmetric``.
"""

from __future__ import annotations

import time

import numpy as np

from bearingshaft.estimates import Estimate, history_bytes, n_dofs
from bearingshaft.gap_modes import GapModeComparison, compare_all, full_gap_modes
from bearingshaft.progress import ProgressBar
from bearingshaft.reproduction import Reproduction, roundoff, sensitive, within
from bearingshaft.scenes import Scene, VerifySpec, load_scene
from bearingshaft.stages.verify_results import MODELS, STARTS, VerifyResult
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.identify import identify_discrete
from reduced.models.initial import initial_state
from reduced.models.modes import linear_modes
from reduced.models.rom import ReducedModel, reduction
from reduced.periodic.backbones import hb_backbones
from reduced.transient.integrate import ringdown
from reduced.transient.spectrogram import spectrogram

__all__ = ["DESCRIPTION", "VerifyResult", "compute", "estimate"]

N_COMPARE = 3  # coupled modes compared per contact state (the three-mass model has three)
UNITS = {"k_s": "N/m", "kappa": "N m/rad", "k_g": "N/m", "L": "m", "gap": "m", "m1": "kg", "m2": "kg", "m3": "kg",
         "c": "N s/m"}
SPECTROGRAM_OVERLAP = 0.9
PERTURBATION = 1e-12  # relative change of the initial state that probes the ringdowns' sensitivity


def _rel(a: float, b: float) -> float:
    return float((a - b) / b)


def _frequency_rows(comps: dict[str, GapModeComparison], systems: dict[str, GapSystem]) -> list[dict]:
    """The lowest N_COMPARE full modes in the reduction basis, each against its MAC partner in the
    reduced model and against the three-mass models' modes of the same rank (they have no 3-D shape)."""
    rows = []
    for state, c in comps.items():
        f = {k: linear_modes(s, state).freq_hz for k, s in systems.items()}
        for i, pair in enumerate(c.rows[:N_COMPARE]):
            ff = pair["full_hz"]
            row = {"state": state, "mode": i + 1, "full_mode": pair["full_mode"], "full_hz": ff,
                   "reduced_hz": pair["reduced_hz"], "identified_hz": float(f["identified"][i]),
                   "table1_hz": float(f["table1"][i]), "reduced_mac": pair["mac"]}
            row |= {f"{k}_rel": _rel(row[f"{k}_hz"], ff) for k in MODELS}
            rows.append(row)
    return rows


def _backbones(systems: dict[str, GapSystem], energy_max_J: float, progress: bool) -> dict:
    """{model: {nnm: (energy_J, freq_hz)}}, HB with one harmonic, sorted by energy."""
    out: dict = {}
    bar = ProgressBar("NNM backbones", progress)
    try:
        for i, (name, system) in enumerate(systems.items()):
            curves = hb_backbones(system, 1, energy_max_J, modes=range(N_COMPARE))
            out[name] = {int(key.split()[1]): c for key, c in curves.items()}
            bar((i + 1) / len(systems))
    finally:
        bar.close()
    return out


def _ringdowns(systems: dict, vs: VerifySpec, progress: bool) -> dict:
    """{(start, model): RingdownResult} from the paper's three initial conditions."""
    out = {}
    bar = ProgressBar("ringdowns", progress)
    jobs = [(start, scene, name) for start, scene in STARTS for name in MODELS]
    try:
        for j, (start, scene_name, name) in enumerate(jobs):
            init = load_scene(scene_name).initial
            system, P = systems[name]
            x0, v0 = initial_state(system.M, system.K, P, init.x0_m, init.v0_m_s)
            out[start, name] = ringdown(system, x0, v0, vs.duration_s, vs.sample_rate_hz, vs.method)
            bar((j + 1) / len(jobs))
    finally:
        bar.close()
    return out


def _sensitivity(models: dict, vs: VerifySpec, runs: dict) -> list[dict]:
    """The reduced model's ringdowns again from initial states scaled by 1 + PERTURBATION: how much of the
    end-of-run columns (E(end), last-window peak, contact events) is round-off amplified by the impacts."""
    system, P = models["reduced"]
    rows = []
    for start, scene_name in STARTS:
        init = load_scene(scene_name).initial
        x0, v0 = initial_state(system.M, system.K, P, init.x0_m, init.v0_m_s)
        r = ringdown(system, x0 * (1 + PERTURBATION), v0 * (1 + PERTURBATION), vs.duration_s, vs.sample_rate_hz,
                     vs.method)
        base = runs[start, "reduced"]
        rows.append({"start": start, "energy_J_final": float(r.energy[-1]), "n_events": r.stats.get("n_events", ""),
                     "base_energy_J_final": float(base.energy[-1]), "base_n_events": base.stats.get("n_events", "")})
    return rows


def _spectrograms(runs: dict, models: dict, vs: VerifySpec) -> dict:
    """{(start, model): Spectrogram of x1}."""
    return {(start, name): spectrogram(r.t, r.x @ models[name][1][0], vs.window_s, SPECTROGRAM_OVERLAP)
            for (start, name), r in runs.items()}


def _peak_hz(S, fmax_hz: float, frame: int) -> float:
    """Hz, the strongest frequency below fmax_hz in one frame of a spectrogram."""
    keep = S.freq_hz <= fmax_hz
    return float(S.freq_hz[keep][np.argmax(S.power[keep, frame])])


def _ringdown_rows(runs: dict, spectra: dict, vs: VerifySpec) -> list[dict]:
    """One row per ringdown: energies, x1's peak in the first and last window, events, energy balance."""
    return [{"start": s, "model": m, "energy_J_initial": float(r.energy[0]),
             "energy_J_final": float(r.energy[-1]), "n_events": r.stats.get("n_events", ""),
             "peak_hz_first": _peak_hz(spectra[s, m], vs.fmax_hz, 0),
             "peak_hz_last": _peak_hz(spectra[s, m], vs.fmax_hz, -1),
             "energy_balance_error": float(r.energy_balance_error), "wall_s": r.stats.get("wall_s")}
            for (s, m), r in runs.items()]


def _facts(scene: Scene, rom: ReducedModel, fe, ident: DiscreteParams, table1: DiscreteParams, L: float,
           freq_rows: list[dict]) -> dict:
    """The numbers verify.md explains the differences with: rigid mass and pitch inertia of the 3-D
    model, the reduced stiffness blocks, Table 1's values, the run settings."""
    spec, vs = scene.model, scene.verify
    R = fe.rigid_modes(np.arange(fe.n_dofs), (0.0, 0.0, 0.0))[:, [2, 4]]  # heave, pitch about the centre
    rigid = R.T @ (fe.M @ R)
    geom = spec.fe_model()  # the 3-D model's parameters (beam length)
    Kbb = rom.K[:2, :2]
    t1_pitch = next(r for r in freq_rows if r["state"] == "open" and r["mode"] == 2)["table1_rel"]
    return {"n_full_dofs": rom.info["n_full_dofs"], "layout": spec.layout, "n_modes": rom.n_modes,
            "f_fixed_hz": float(rom.omega_fixed[0] / (2 * np.pi)), "L": L, "heave_mass": float(rigid[0, 0]),
            "pitch_inertia": float(rigid[1, 1]), "table1_mass": table1.m1 + table1.m2 + table1.m3,
            "table1_pitch": (table1.m1 + table1.m3) * table1.L**2, "beam_length": float(geom.beam_length),
            "m1": ident.m1, "m2": ident.m2, "id_mass": ident.m1 + ident.m2 + ident.m3,
            "k_heave": float(np.sum(Kbb) / 4), "k_s": ident.k_s, "table1_k_s": table1.k_s,
            "K01": float(Kbb[0, 1]), "k_rot": float(-4 * L**2 * Kbb[0, 1]), "kappa": ident.kappa,
            "k_pitch": float(Kbb[0, 0] - Kbb[0, 1]), "m_pitch": float(rom.M[0, 0] - rom.M[0, 1]),
            "pitch_k_miss": float(np.sum(Kbb) / 2 / (Kbb[0, 0] - Kbb[0, 1]) - 1),
            "t1_closed1_rel": next(r for r in freq_rows if r["state"] == "closed" and r["mode"] == 1)["table1_rel"],
            "table1_kappa": table1.kappa, "P_x2_eta": float(rom.P[1, 2]), "t1_pitch_rel": t1_pitch,
            "method": vs.method, "duration_s": vs.duration_s, "c": spec.c_points, "window_s": vs.window_s,
            "grazing_J": table1.grazing_energy_nnm2,
            "kept_rule": "chosen among the modes symmetric in y that the tips move (`planar`)" if spec.planar
            else "the lowest ones, whether the tips move them or not"}


def compute(scene: Scene, progress: bool, workdir) -> VerifyResult:
    """Reduce the scene's 3-D model, read it as a three-mass model and compare the four models.

    Parameters
    ----------
    scene : Scene
        A scene with a reduced ``[model]`` and a ``[verify]`` table.
    progress : bool
        Show progress bars.
    workdir : Path
        The stage's scratch folder (unused: the ringdowns are held in memory).

    Returns
    -------
    VerifyResult
        Identified parameters, frequencies, backbones, ringdowns and their spectrograms.
    """
    t0 = time.perf_counter()
    spec, vs = scene.model, scene.verify
    rom, fe = reduction(spec, progress)  # the reduce stage's, from the cache: the bits of a rebuild
    comps = compare_all(rom, fe, spec, full_gap_modes(fe, spec, Psi=rom.Psi))
    centres = np.asarray(rom.info["contact_centres_m"], float)
    L = 0.5 * float(np.linalg.norm(centres[1] - centres[0]))
    ident, residuals = identify_discrete(rom.M, rom.K, L, k_g=spec.k_g, gap=spec.gap, c=spec.c_points)
    table1 = DiscreteParams()
    id_rows = [{"parameter": k, "unit": UNITS[k], "table1": getattr(table1, k), "identified": getattr(ident, k),
                "relative_difference": _rel(getattr(ident, k), getattr(table1, k))} for k in UNITS]
    models = {"reduced": (rom.system(), rom.P), "identified": (ident.system(), np.eye(3)),
              "table1": (table1.system(), np.eye(3))}
    systems = {k: s for k, (s, _) in models.items()}
    freq_rows = _frequency_rows(comps, systems)
    backbones = _backbones(systems, vs.energy_max_J, progress)
    runs = _ringdowns(models, vs, progress)
    sens = _sensitivity(models, vs, runs)
    spectra = _spectrograms(runs, models, vs)
    facts = _facts(scene, rom, fe, ident, table1, L, freq_rows)
    return VerifyResult(scene, ident, id_rows, residuals, freq_rows, backbones, runs, spectra,
                        _ringdown_rows(runs, spectra, vs), sens, PERTURBATION, comps, facts,
                        time.perf_counter() - t0)


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Read the reduced 3-D beam as the paper's 3-DOF model: identify its parameters against Table 1,
compare the coupled frequencies of the full, reduced and identified models, their NNM
backbones and ringdowns from the paper's three initial conditions. Writes identified.csv,
residuals.csv, verify.csv (frequencies), nnm_backbones.csv, verify.png and verify.md."""


def estimate(scene: Scene) -> list[Estimate]:
    """Three models x three ringdowns held at once.

    Parameters
    ----------
    scene : Scene
        A scene with a [verify] table.

    Returns
    -------
    list of Estimate
        One: nine sampled histories (three models x three ringdowns).
    """
    v = scene.verify
    samples = v.duration_s * v.sample_rate_hz + 1
    return [Estimate("verify", history_bytes(samples, n_dofs(scene), 3 * 3),
                     f"3 models x 3 ringdowns of {samples:.3g} samples", "[verify] duration_s or sample_rate_hz")]




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
REPRODUCTION = Reproduction(rules=(
    roundoff("residuals.csv", "value", rows=r"^(K_bb_diag|M_bq|K_bq|M_qq),"),
    roundoff("verify.md", r"^\| (K_bb_diag|M_bq|K_bq|M_qq) \| < "),
    # relative differences of a reduced model's frequencies from the full model's: both reproducible to ~1e-8
    within("verify.csv", "*_rel", atol=1e-8, why="differences of frequencies reproducible to ~1e-8"),
    sensitive("nnm_backbones.csv", why="the points of the HB continuations of the backbones: their step path is set "
              "by the last bits of each Newton solve"),
))
