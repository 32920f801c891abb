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
wall time goes to ``provenance.json`` only.
The ringdowns start from the paper's three initial conditions, read from the built-in scenes
``discrete-antisymmetric``, ``discrete-impulse`` and ``discrete-symmetric``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from bearingshaft.digits import cells
from bearingshaft.estimates import Estimate, history_bytes, n_dofs
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.plots import plt
from bearingshaft.progress import ProgressBar
from bearingshaft.scenes import Scene, VerifySpec, load_scene
from bearingshaft.stages.reduce import GapModeComparison, compare_all, full_gap_modes, left_out_summary
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.identify import RESIDUAL_MEANING, identify_discrete
from reduced.models.initial import initial_state
from reduced.models.modes import linear_modes
from reduced.models.rom import build_rom
from reduced.periodic.backbones import hb_backbones
from reduced.transient.integrate import ringdown
from reduced.transient.spectrogram import curve_in_time, spectrogram

N_COMPARE = 3  # coupled modes compared per contact state (the three-mass model has three)
STARTS = (("antisymmetric", "discrete-antisymmetric"), ("impulse", "discrete-impulse"),
          ("symmetric", "discrete-symmetric"))  # the paper's Section 3.2 initial conditions
MODELS = ("reduced", "identified", "table1")
LABELS = {"full": "full 3-D", "reduced": "reduced (CB)", "identified": "identified 3-mass", "table1": "Table 1"}
COLORS = {"full": "k", "reduced": "C0", "identified": "C2", "table1": "C3"}
UNITS = {"k_s": "N/m", "kappa": "N m/rad", "k_g": "N/m", "L": "m", "g": "m", "m1": "kg", "m2": "kg", "m3": "kg",
         "c": "N s/m"}
SPECTROGRAM_OVERLAP = 0.9
DB_RANGE = 80.0  # dB shown below each spectrogram's peak
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


def _figure(path, title: str, freq_rows: list[dict], backbones: dict, runs: dict, spectra: dict,
            vs: VerifySpec) -> None:
    fig = plt.figure(figsize=(16, 19), constrained_layout=True)
    grid = fig.add_gridspec(4, 3, height_ratios=[1.15, 1, 1, 1])
    ax = fig.add_subplot(grid[0, 0])
    labels = [f"{r['state']} {r['mode']}\n{r['full_hz']:.1f} Hz" for r in freq_rows]
    x = np.arange(len(freq_rows))
    for j, name in enumerate(MODELS):
        ax.bar(x + (j - 1) * 0.27, [100 * r[f"{name}_rel"] for r in freq_rows], 0.27, color=COLORS[name],
               label=LABELS[name])
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("frequency - full 3-D [%]")
    ax.set_title("coupled modes, open and closed gap (tied tips)\n(tick: mode and full 3-D frequency)", fontsize=10)
    ax.legend(fontsize=8)
    ax = fig.add_subplot(grid[0, 1:])
    styles = ("-", "--", ":")
    for name in MODELS:
        for k, (E, f) in backbones[name].items():
            ax.semilogx(E, f, color=COLORS[name], ls=styles[k - 1], lw=3.0 if name == "reduced" else 1.3,
                        alpha=0.5 if name == "reduced" else 1.0, label=f"{LABELS[name]}, NNM {k}")
    for r in freq_rows:
        ax.axhline(r["full_hz"], color="k", lw=0.5, ls=(0, (1, 3)))
    ax.set_xlim(1e-4, vs.energy_max_J)
    ax.set_ylim(0, vs.fmax_hz)
    ax.set_xlabel("energy [J]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title("NNM frequency-energy curves (HB, H = 1); dotted: full 3-D open and closed-gap frequencies",
                 fontsize=10)
    ax.legend(fontsize=7, ncol=3, loc="upper left")
    colors = ("w", "r", "orange")
    for i, (start, _) in enumerate(STARTS):
        for j, name in enumerate(MODELS):
            ax = fig.add_subplot(grid[i + 1, j])
            res = runs[start, name]
            S = spectra[start, name]
            keep = S.freq_hz <= vs.fmax_hz
            db = 10.0 * np.log10(np.maximum(S.power[keep], 1e-300))
            top = float(np.max(db))
            ax.pcolormesh(S.t, S.freq_hz[keep], db, shading="nearest", cmap="viridis", vmin=top - DB_RANGE,
                          vmax=top, rasterized=True)
            for k, (E, f) in backbones[name].items():
                ax.plot(res.t, curve_in_time(res.energy, E, f), color=colors[k - 1], lw=0.9, ls="--",
                        label=f"NNM {k}")
            ax.set_ylim(0, vs.fmax_hz)
            ax.set_xlim(S.t[0], S.t[-1])
            ax.set_title(f"{start}: {LABELS[name]}, x1 (E0 = {res.energy[0]:.3g} J)", fontsize=10)
            if j == 0:
                ax.set_ylabel("frequency [Hz]")
            if i == len(STARTS) - 1:
                ax.set_xlabel("time [s]")
            if i == 0 and j == 0:
                ax.legend(fontsize=7, loc="upper right", framealpha=0.6)
    fig.suptitle(title)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _left_out_text(comps: dict[str, GapModeComparison], planar: bool) -> str:
    """verify.md's account of the full modes outside the reduction basis, by state and reason."""
    parts = []
    for state, c in comps.items():
        items = [f"  * {why}: {', '.join(f'{f:.6g}' for f in hz)} Hz" for why, hz in left_out_summary(c)]
        kept = ", ".join(f"{r['full_hz']:.6g}" for r in c.rows)
        head = (f"* **{state} gap**: of the {len(c.full_hz)} lowest full modes ({c.full_hz[0]:.4g} to "
                f"{c.full_hz[-1]:.6g} Hz), the basis holds {kept} Hz (MAC >= {min(r['mac'] for r in c.rows):.4f})"
                if c.rows else f"* **{state} gap**: none of the {len(c.full_hz)} lowest full modes is in the basis")
        parts.append(head + "; it leaves out\n" + "\n".join(items) if items else head)
        if len(c.unpaired):
            parts.append(f"  * and the reduced model has {len(c.unpaired)} mode(s) with no full partner: "
                         + ", ".join(f"{c.reduced.freq_hz[j]:.6g}" for j in c.unpaired) + " Hz")
    return "\n".join(parts)


def _report(scene: Scene, facts: dict, id_rows: list[dict], residuals: dict, freq_rows: list[dict],
            ring_rows: list[dict], comps: dict[str, GapModeComparison], planar: bool, sens: list[dict]) -> str:
    f = facts
    ident = _table(["parameter", "unit", "Table 1", "identified", "relative difference"],
                   [[r["parameter"], r["unit"], f"{r['table1']:.6g}", f"{r['identified']:.6g}",
                     f"{100 * r['relative_difference']:+.2f} %"] for r in id_rows])
    res = _table(["residual", "value", "meaning"],
                 [[k, f"{v:+.3e}", RESIDUAL_MEANING[k]] for k, v in residuals.items()])
    freq = _table(["state", "mode", "full 3-D mode", "full 3-D [Hz]", "reduced [Hz]", "MAC", "identified [Hz]",
                   "Table 1 [Hz]", "reduced", "identified", "Table 1"],
                  [[r["state"], r["mode"], r["full_mode"], f"{r['full_hz']:.2f}", f"{r['reduced_hz']:.2f}",
                    f"{r['reduced_mac']:.4f}", f"{r['identified_hz']:.2f}", f"{r['table1_hz']:.2f}",
                    f"{100 * r['reduced_rel']:+.2f} %", f"{100 * r['identified_rel']:+.2f} %",
                    f"{100 * r['table1_rel']:+.2f} %"] for r in freq_rows])
    ring = _table(["start", "model", "E0 [J]", "E(end) [J]", "x1 peak, first window [Hz]",
                   "x1 peak, last window [Hz]", "contact events", "energy balance error"],
                  [[r["start"], LABELS[r["model"]], f"{r['energy_J_initial']:.4g}", f"{r['energy_J_final']:.3g}",
                    f"{r['peak_hz_first']:.0f}", f"{r['peak_hz_last']:.0f}", r["n_events"],
                    f"{r['energy_balance_error']:.1e}"] for r in ring_rows])
    return f"""# {scene.name}: reduced 3-D model against the three-mass model

{scene.description}

Full 3-D model: {f['n_full_dofs']} DOFs ({f['layout']}), reduced by Craig-Bampton onto the tips' gap
coordinates x1, x3 and {f['n_modes']} contact-coupled fixed-interface mode(s) (first: {f['f_fixed_hz']:.2f} Hz).
Numbers from `bearingshaft verify --scene {scene.name}`.

## Identified three-mass parameters

From the reduced matrices (`reduced/models/identify.py`): k_s = trace(K_bb)/4, m2 = (|M_bq[0]| + |M_bq[1]|)^2,
m1,3 = M_bb[i,i] - m2/4, a = m2 omega_1^2/4, kappa = a L^2 with L = {f['L']:.6g} m the half-distance
between the contact centres; k_g, g, c are the scene's.

{ident}

Residuals the three-mass form cannot carry (all zero for a three-mass model):

{res}

What the differences mean:

* **Mass.** The in-plane rigid mass of the 3-D model is {f['heave_mass']:.4f} kg, the same as Table 1's
  m1 + m2 + m3 = {f['table1_mass']:.4f} kg, but it is not lumped m/4, m/2, m/4 at x = -L, 0, +L: the beam is
  {f['beam_length']:.4f} m long, {f['beam_length'] / (2 * f['L']):.2f} times 2L, so its overhangs carry mass
  outside the tips. The pitch inertia about the centre is {f['pitch_inertia']:.5f} kg m^2 against
  (m1 + m3) L^2 = {f['table1_pitch']:.5f} kg m^2 for Table 1
  ({100 * (f['pitch_inertia'] / f['table1_pitch'] - 1):+.1f} %):
  the tips need more mass (identified m1 = m3 = {f['m1']:.4f} kg) and the first bending mode has less modal
  mass at mid-span (m2 = {f['m2']:.4f} kg). The boundary mass coupling M_bb[0,1] is
  {100 * residuals['M_bb01']:+.2f} % off m2/4: the constraint modes of a continuum are not the straight line
  x2 = (x1 + x3)/2 of the three-mass model, so the sum m1 + m2 + m3 of the identified model is
  {f['id_mass']:.4f} kg, not {f['heave_mass']:.4f} kg.
* **Springs.** The heave stiffness sum(K_bb)/4 = {f['k_heave']:.2f} N/m per spring is Table 1's k_s to
  {100 * (f['k_heave'] / f['table1_k_s'] - 1):+.3f} %. What trace(K_bb)/4 ({f['k_s']:.2f} N/m) adds on top is the
  coupling K_bb[0,1] = {f['K01']:.2f} N/m, which stiffens pitch only (K_bb[0,0] - K_bb[0,1] = {f['k_pitch']:.1f} N/m
  against 2 k_s = {2 * f['table1_k_s']:.0f} N/m): the 3-D springs, glued to the beam, resist its rotation by
  their bending and lateral stiffness, a rotational stiffness 4 L^2 |K_bb[0,1]| = {f['k_rot']:.2f} N m/rad in all
  that the point springs of the three-mass model do not have. The three-mass form has one k_s for heave and
  pitch; trace(K_bb)/4 splits the difference (sum(K_bb)/4 would give heave exactly and pitch
  {100 * f['pitch_k_miss']:+.2f} % in stiffness).
* **Bending.** The first fixed-interface mode (tips held) at {f['f_fixed_hz']:.2f} Hz fixes a = m2 omega_1^2/4;
  kappa = a L^2 = {f['kappa']:.1f} N m/rad against Table 1's {f['table1_kappa']:.0f}
  ({100 * (f['kappa'] / f['table1_kappa'] - 1):+.2f} %). The 3-D beam's EI was set from kappa by matching the
  *static* mid-span stiffness 4 kappa / L^2 of a simply supported span 2L (`fem/model.py`); the identification
  reads a *dynamic* one, m2 omega_1^2, with the beam's distributed mass (and its overhangs) in the mode.
* **Points.** x1, x3 are the mean vertical motion of each tip's contact patch (the gap coordinate, a
  distributing average), x2 the mean vertical motion of the mid-span sensors. In the reduced model x2 =
  (x1 + x3)/2 + {f['P_x2_eta']:.4f} eta, in the identified model x2 = (x1 + x3)/2 + 1/sqrt(m2) eta =
  (x1 + x3)/2 + {1 / np.sqrt(f['m2']):.4f} eta: the mid-span sensors are not the identified m2's coordinate, so
  the same point velocity v2 starts the reduced and identified models with different energies (symmetric start).

## Frequencies of the lowest coupled modes

Open gap: tips free; closed gap: both tips tied to the ground by k_g (the HB backbones' limits).
Relative differences against the full 3-D model. Each full mode ("full 3-D mode": its number among the
full model's modes) is one the reduction basis [Psi, Phi] holds (at least 90 % of it in the mass norm) and
is paired with the reduced mode of largest mass-weighted MAC (`bearingshaft/stages/reduce.py`,
`gap_modes.csv`); the three-mass models, which have no 3-D shape, are taken rank for rank.

{freq}

The reduced model bounds the full one from above (Rayleigh-Ritz) and is close to it in the open gap; its
closed-gap error comes from keeping one fixed-interface mode (a tied tip needs the higher bending
modes). The identified three-mass model repeats the reduced model up to the residuals above: in heave
(open 1) its stiffness 4 k_s = trace(K_bb) = {4 * f['k_s']:.0f} N/m holds the rotation coupling that heave
does not see (sum(K_bb) = {4 * f['k_heave']:.0f} N/m) and its mass m1 + m2 + m3 misses
2 M_bb[0,1] - m2/2 = {f['heave_mass'] - f['id_mass']:.4f} kg;
in pitch (open 2) it has 2 k_s = {2 * f['k_s']:.0f} N/m against K_bb[0,0] - K_bb[0,1] = {f['k_pitch']:.0f} N/m and
m1 = {f['m1']:.4f} kg against M_bb[0,0] - M_bb[0,1] = {f['m_pitch']:.4f} kg. Table 1's model differs from the 3-D
beam mostly through its mass distribution: pitch {100 * f['t1_pitch_rel']:+.1f} % (tip mass 0.629 kg against
{f['m_pitch']:.4f} kg), closed-gap mode 1 (bending against tied tips) {100 * f['t1_closed1_rel']:+.1f} %, near
sqrt(m2 identified / m2 Table 1) - 1 = {100 * (np.sqrt(f['m2'] / 1.258) - 1):+.1f} %.

## Full-model modes the reduction leaves out

The reduction keeps the two gap coordinates and {f['n_modes']} fixed-interface mode(s), {f['kept_rule']}.
Of the full model's lowest modes (open and tied tips) it therefore represents only those listed above;
the others (the basis holds at most {max(r['basis_fraction'] for c in comps.values() for r in c.left_out):.1e}
of any of them; each with its share in `provenance.json`, `left_out`):

{_left_out_text(comps, planar)}

Out-of-plane modes (lateral, yaw, roll, bending in y, torsion) cannot be excited by the tips, which act
in z on the plane y = 0; neither can the in-plane modes that do not move the tips (surge, axial and the
modes antisymmetric in z). The modes moved by the tips but above the kept fixed-interface mode(s) would
need more of them (the `rom-*` scenes keep 10: see their `gap_modes.csv`).

## Ringdowns from the paper's three starts ({f['method']}, {f['duration_s']} s)

Point values x0, v0 of Section 3 at x1, x2, x3, realized in the three lowest modes of each model
(`reduced/models/initial.py`); damping: c = {f['c']} N s/m at each point. Peaks: the strongest line of x1's
spectrogram ({f['window_s']} s windows) in the first and last window, against the closed- and open-gap
frequencies above (contact persists to the end of every run: E(end) is above the grazing energy of NNM 2,
2 k_s g^2 = {f['grazing_J']:.3g} J).

{ring}

The end-of-run columns (E(end), the last window's peak, the number of contact events) are sensitive to
round-off by nature: thousands of impacts amplify it. Started {PERTURBATION:.0e} (relative) away from the same
initial state, the reduced model ends at
{'; '.join(f"{r['start']}: E(end) {r['energy_J_final']:.3g} J and {r['n_events']} events (against "
           f"{r['base_energy_J_final']:.3g} J and {r['base_n_events']})" for r in sens)}.
Read them as orders of magnitude; E0, the first window's peak and the energy balance are the robust columns.

`verify.png`: frequency differences; the NNM frequency-energy curves of the three models; spectrograms of x1
with each model's own HB backbones mapped onto time through its energy, f(E(t)). The same point values
start the three models with different energies where the models' masses differ (impulse at x3: m3; symmetric
start at x2: the mid-span's modal mass), and the reduced model's dashpots act at its points x1, x2, x3
(C = c P^T P), not on its coordinates, so its decay differs from the three-mass models' c I.
"""


def verify_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    t0 = time.perf_counter()
    spec, vs = scene.model, scene.verify
    rom, fe = build_rom(spec, progress=progress)
    comps = compare_all(rom, fe, spec, full_gap_modes(fe, spec, Psi=rom.Psi))
    centres = np.asarray(rom.info["contact_centres_m"], float)
    L = 0.5 * float(np.linalg.norm(centres[1] - centres[0]))
    ident, residuals = identify_discrete(rom.M, rom.K, L, k_g=spec.k_g, g=spec.gap, c=spec.c_points)
    table1 = DiscreteParams()
    id_rows = [{"parameter": k, "unit": UNITS[k], "table1": getattr(table1, k), "identified": getattr(ident, k),
                "relative_difference": _rel(getattr(ident, k), getattr(table1, k))} for k in UNITS]
    write_rows(writer.path("identified.csv"), cells(id_rows, {"relative_difference": ".4g"}))
    write_rows(writer.path("residuals.csv"), cells([{"residual": k, "value": v, "meaning": RESIDUAL_MEANING[k]}
                                                      for k, v in residuals.items()], {}, ".4g"))

    models = {"reduced": (rom.system(), rom.P), "identified": (ident.system(), np.eye(3)),
              "table1": (table1.system(), np.eye(3))}
    systems = {k: s for k, (s, _) in models.items()}
    freq_rows = _frequency_rows(comps, systems)
    write_rows(writer.path("verify.csv"), cells(freq_rows, {"reduced_mac": ".6f", **{f"{k}_rel": ".4g"
                                                                                     for k in MODELS}}))

    backbones = _backbones(systems, vs.energy_max_J, progress)
    write_rows(writer.path("nnm_backbones.csv"),
               [{"model": name, "nnm": k, "energy_J": float(e), "freq_hz": float(fr)}
                for name, curves in backbones.items() for k, (E, f) in curves.items()
                for e, fr in zip(E, f, strict=True)], float_format=".6g")

    runs = _ringdowns(models, vs, progress)
    sens = _sensitivity(models, vs, runs)
    spectra = _spectrograms(runs, models, vs)
    ring_rows = [{"start": s, "model": m, "energy_J_initial": float(r.energy[0]),
                  "energy_J_final": float(r.energy[-1]), "n_events": r.stats.get("n_events", ""),
                  "peak_hz_first": _peak_hz(spectra[s, m], vs.fmax_hz, 0),
                  "peak_hz_last": _peak_hz(spectra[s, m], vs.fmax_hz, -1),
                  "energy_balance_error": float(r.energy_balance_error), "wall_s": r.stats.get("wall_s")}
                 for (s, m), r in runs.items()]
    _figure(writer.path("verify.png"), f"{scene.name}: reduced 3-D model ({rom.n_modes} fixed-interface mode) "
            f"against the three-mass model", freq_rows, backbones, runs, spectra, vs)

    R = fe.rigid_modes(np.arange(fe.n_dofs), (0.0, 0.0, 0.0))[:, [2, 4]]  # heave, pitch about the centre
    rigid = R.T @ (fe.M @ R)
    geom = spec.fe_model()  # the 3-D model's parameters (beam length)
    Kbb = rom.K[:2, :2]
    t1_pitch = next(r for r in freq_rows if r["state"] == "open" and r["mode"] == 2)["table1_rel"]
    facts = {"n_full_dofs": rom.info["n_full_dofs"], "layout": spec.layout, "n_modes": rom.n_modes,
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
    writer.path("verify.md").write_text(_report(scene, facts, id_rows, residuals, freq_rows, ring_rows, comps,
                                                spec.planar, sens))
    writer.stats.update({"identified": {r["parameter"]: r["identified"] for r in id_rows},
                         "residuals": residuals, "frequencies": freq_rows, "ringdowns": ring_rows,
                         "facts": facts, "left_out": [r for c in comps.values() for r in c.left_out],
                         "sensitivity": sens,
                         "wall_s": time.perf_counter() - t0})
    worst = max(freq_rows, key=lambda r: abs(r["reduced_rel"]))
    worst_t1 = max(freq_rows, key=lambda r: abs(r["table1_rel"]))
    n_left = {s: len(c.left_out) for s, c in comps.items()}
    print(f"[{scene.name}] identified k_s {ident.k_s:.1f} N/m, kappa {ident.kappa:.0f} N m/rad, "
          f"m = {ident.m1:.3f}, {ident.m2:.3f}, {ident.m3:.3f} kg (Table 1: worst "
          f"{100 * max(abs(r['relative_difference']) for r in id_rows):.2f} %)\n"
          f"  reduced against full 3-D: worst {100 * worst['reduced_rel']:+.2f} % ({worst['state']} {worst['mode']}) "
          f"over {len(freq_rows)} frequencies; Table 1 model: worst {100 * worst_t1['table1_rel']:+.2f} % "
          f"({worst_t1['state']} {worst_t1['mode']})\n"
          f"  full modes outside the reduction (of the {len(comps['open'].full_hz)} lowest): {n_left['open']} open, "
          f"{n_left['closed']} closed gap (verify.md says which and why)\n"
          "  files: " + ", ".join(sorted(p.name for p in writer.scratch.iterdir())), flush=True)



# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Read the reduced 3-D beam as the paper's 3-DOF model: identify its parameters against Table 1,
compare the coupled frequencies of the full, reduced and identified models, their NNM
backbones and ringdowns from the paper's three initial conditions. Writes identified.csv,
frequencies.csv, ringdowns.csv, sensitivity.csv, verify.png and verify.md."""


def estimate(scene: Scene) -> list[Estimate]:
    """Three models x three ringdowns held at once."""
    v = scene.verify
    samples = v.duration_s * v.sample_rate_hz + 1
    return [Estimate("verify", history_bytes(samples, n_dofs(scene), 3 * 3),
                     f"3 models x 3 ringdowns of {samples:.3g} samples", "[verify] duration_s or sample_rate_hz")]


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir) -> _Pending:
    return _Pending(scene, progress, {})


def write(result: _Pending, writer: StageWriter) -> None:
    verify_stage(result.scene, writer, result.progress, **result.options)
