"""The ``verify`` stage's files, from what :func:`bearingshaft.stages.verify.compute` found.

``identified.csv`` (Table 1 against the identified three-mass parameters), ``residuals.csv``
(what the three-mass form cannot carry), ``verify.csv`` (the coupled frequencies of the four
models), ``nnm_backbones.csv`` (HB, H = 1), ``verify.png`` (frequency differences, backbones,
spectrograms with the backbones mapped onto time) and ``verify.md`` (the numbers, explained).
Numbers go to their converged digits; no solver runs here.
"""

from __future__ import annotations

import numpy as np

from bearingshaft.digits import cells, roundoff_bound
from bearingshaft.gap_modes import GapModeComparison, left_out_summary
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.plots import plt
from bearingshaft.scenes import Scene, VerifySpec
from bearingshaft.stages.verify_results import MODELS, STARTS, VerifyResult  # noqa: F401  (re-exported)
from reduced.models.identify import RESIDUAL_MEANING
from reduced.transient.spectrogram import curve_in_time

LABELS = {"full": "full 3-D", "reduced": "reduced (CB)", "identified": "identified 3-mass", "table1": "Table 1"}
COLORS = {"full": "k", "reduced": "C0", "identified": "C2", "table1": "C3"}
DB_RANGE = 80.0  # dB shown below each spectrogram's peak
# residuals that vanish by the model's mirror symmetry (x1 and x3 mirror each other) or by the Craig-Bampton form
# (K_bq, mass-normalized M_qq): what is computed is round-off, whose digits change from one CPU to another (K_bb_diag
# 4.8e-9 on one machine, 3.3e-9 on another), so below ROUNDOFF_MAX it is written as the power of ten that bounds it
ROUNDOFF_RESIDUALS = ("K_bb_diag", "M_bq", "K_bq", "M_qq")
ROUNDOFF_MAX = 1e-6  # above this such a residual is real (an asymmetric model) and written to 4 digits


def residual_text(name: str, value: float, spec: str = ".4g", below: str = "") -> str:
    """A residual of the identification as written: the power-of-ten bound of a round-off one, else ``spec``.

    Parameters
    ----------
    name : str
        Its key (``reduced.models.identify.RESIDUAL_MEANING``).
    value : float
        Its value.
    spec : str
        Format of a residual that is not round-off.
    below : str
        Put before a bound (Markdown: ``"< "``; a CSV cell stays a number).

    Returns
    -------
    str

    Examples
    --------
    >>> residual_text("M_qq", -6.661e-16), residual_text("K_bb_diag", 4.789e-9, below="< ")
    ('1e-10', '< 1e-08')
    >>> residual_text("M_bb01", 0.03282)
    '0.03282'
    """
    if name in ROUNDOFF_RESIDUALS and abs(value) < ROUNDOFF_MAX:
        return f"{below}{roundoff_bound(abs(value)):g}"
    return format(value, spec)


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


def _intro(scene: Scene, f: dict) -> str:
    """verify.md: the title and the models compared."""
    return f"""# {scene.name}: reduced 3-D model against the three-mass model

{scene.description}

Full 3-D model: {f['n_full_dofs']} DOFs ({f['layout']}), reduced by Craig-Bampton onto the tips' gap
coordinates x1, x3 and {f['n_modes']} contact-coupled fixed-interface mode(s) (first: {f['f_fixed_hz']:.2f} Hz).
Numbers from `bearingshaft verify --scene {scene.name}`.

"""


def _identification(f: dict, id_rows: list[dict], residuals: dict) -> str:
    """verify.md: the identified parameters, the residuals and what the differences mean."""
    ident = _table(["parameter", "unit", "Table 1", "identified", "relative difference"],
                   [[r["parameter"], r["unit"], f"{r['table1']:.6g}", f"{r['identified']:.6g}",
                     f"{100 * r['relative_difference']:+.2f} %"] for r in id_rows])
    res = _table(["residual", "value", "meaning"],
                 [[k, residual_text(k, v, "+.3e", "< "), RESIDUAL_MEANING[k]] for k, v in residuals.items()])
    return f"""## Identified three-mass parameters

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

"""


def _frequencies(f: dict, freq_rows: list[dict]) -> str:
    """verify.md: the coupled frequencies of the four models."""
    freq = _table(["state", "mode", "full 3-D mode", "full 3-D [Hz]", "reduced [Hz]", "MAC", "identified [Hz]",
                   "Table 1 [Hz]", "reduced", "identified", "Table 1"],
                  [[r["state"], r["mode"], r["full_mode"], f"{r['full_hz']:.2f}", f"{r['reduced_hz']:.2f}",
                    f"{r['reduced_mac']:.4f}", f"{r['identified_hz']:.2f}", f"{r['table1_hz']:.2f}",
                    f"{100 * r['reduced_rel']:+.2f} %", f"{100 * r['identified_rel']:+.2f} %",
                    f"{100 * r['table1_rel']:+.2f} %"] for r in freq_rows])
    return f"""## Frequencies of the lowest coupled modes

Open gap: tips free; closed gap: both tips tied to the ground by k_g (the HB backbones' limits).
Relative differences against the full 3-D model. Each full mode ("full 3-D mode": its number among the
full model's modes) is one the reduction basis [Psi, Phi] holds (at least 90 % of it in the mass norm) and
is paired with the reduced mode of largest mass-weighted MAC (`bearingshaft/gap_modes.py`,
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

"""


def _left_out(f: dict, comps: dict[str, GapModeComparison], planar: bool) -> str:
    """verify.md: the full model's modes the reduction leaves out, with the reason."""
    return f"""## Full-model modes the reduction leaves out

The reduction keeps the two gap coordinates and {f['n_modes']} fixed-interface mode(s), {f['kept_rule']}.
Of the full model's lowest modes (open and tied tips) it therefore represents only those listed above;
the others (the basis holds at most {max(r['basis_fraction'] for c in comps.values() for r in c.left_out):.1e}
of any of them; each with its share in `provenance.json`, `left_out`):

{_left_out_text(comps, planar)}

Out-of-plane modes (lateral, yaw, roll, bending in y, torsion) cannot be excited by the tips, which act
in z on the plane y = 0; neither can the in-plane modes that do not move the tips (surge, axial and the
modes antisymmetric in z). The modes moved by the tips but above the kept fixed-interface mode(s) would
need more of them (the `rom-*` scenes keep 10: see their `gap_modes.csv`).

"""


def _ringdowns(f: dict, ring_rows: list[dict], sens: list[dict], perturbation: float) -> str:
    """verify.md: the ringdowns from the paper's three starts and how sensitive their ends are."""
    ring = _table(["start", "model", "E0 [J]", "E(end) [J]", "x1 peak, first window [Hz]",
                   "x1 peak, last window [Hz]", "contact events", "energy balance error"],
                  [[r["start"], LABELS[r["model"]], f"{r['energy_J_initial']:.4g}", f"{r['energy_J_final']:.3g}",
                    f"{r['peak_hz_first']:.0f}", f"{r['peak_hz_last']:.0f}", r["n_events"],
                    f"{r['energy_balance_error']:.1e}"] for r in ring_rows])
    return f"""## Ringdowns from the paper's three starts ({f['method']}, {f['duration_s']} s)

Point values x0, v0 of Section 3 at x1, x2, x3, realized in the three lowest modes of each model
(`reduced/models/initial.py`); damping: c = {f['c']} N s/m at each point. Peaks: the strongest line of x1's
spectrogram ({f['window_s']} s windows) in the first and last window, against the closed- and open-gap
frequencies above (contact persists to the end of every run: E(end) is above the grazing energy of NNM 2,
2 k_s g^2 = {f['grazing_J']:.3g} J).

{ring}

The end-of-run columns (E(end), the last window's peak, the number of contact events) are sensitive to
round-off by nature: thousands of impacts amplify it. Started {perturbation:.0e} (relative) away from the same
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


def report(result: VerifyResult) -> str:
    """The text of ``verify.md``.

    Parameters
    ----------
    result : VerifyResult
        What the stage computed.

    Returns
    -------
    str
        Markdown: identification, frequencies, the modes left out, ringdowns.
    """
    r, f = result, result.facts
    return (_intro(r.scene, f) + _identification(f, r.id_rows, r.residuals) + _frequencies(f, r.freq_rows)
            + _left_out(f, r.comparisons, r.scene.model.planar)
            + _ringdowns(f, r.ring_rows, r.sensitivity, r.perturbation))


def write(result: VerifyResult, writer: StageWriter) -> None:
    """Write the ``verify`` stage's files, put its statistics in ``writer.stats``, print its summary.

    Parameters
    ----------
    result : VerifyResult
        What :func:`bearingshaft.stages.verify.compute` returned.
    writer : StageWriter
        Where the files go.
    """
    r, scene = result, result.scene
    write_rows(writer.path("identified.csv"), cells(r.id_rows, {"relative_difference": ".4g"}))
    write_rows(writer.path("residuals.csv"), [{"residual": k, "value": residual_text(k, v),
                                               "meaning": RESIDUAL_MEANING[k]} for k, v in r.residuals.items()])
    write_rows(writer.path("verify.csv"), cells(r.freq_rows, {"reduced_mac": ".6f", **{f"{k}_rel": ".4g"
                                                                                       for k in MODELS}}))
    write_rows(writer.path("nnm_backbones.csv"),
               [{"model": name, "nnm": k, "energy_J": float(e), "freq_hz": float(fr)}
                for name, curves in r.backbones.items() for k, (E, f) in curves.items()
                for e, fr in zip(E, f, strict=True)], float_format=".6g")
    _figure(writer.path("verify.png"), f"{scene.name}: reduced 3-D model ({r.facts['n_modes']} fixed-interface mode) "
            f"against the three-mass model", r.freq_rows, r.backbones, r.runs, r.spectra, scene.verify)
    writer.path("verify.md").write_text(report(r))
    writer.stats.update({"identified": {row["parameter"]: row["identified"] for row in r.id_rows},
                         "residuals": r.residuals, "frequencies": r.freq_rows, "ringdowns": r.ring_rows,
                         "facts": r.facts, "left_out": [row for c in r.comparisons.values() for row in c.left_out],
                         "sensitivity": r.sensitivity,
                         "wall_s": r.wall_s})
    print(_summary(r, writer), flush=True)


def _summary(r: VerifyResult, writer: StageWriter) -> str:
    """The stage's summary lines: identified parameters, worst frequency errors, modes left out, files."""
    ident, freq_rows, comps = r.identified, r.freq_rows, r.comparisons
    worst = max(freq_rows, key=lambda row: abs(row["reduced_rel"]))
    worst_t1 = max(freq_rows, key=lambda row: abs(row["table1_rel"]))
    n_left = {s: len(c.left_out) for s, c in comps.items()}
    return (f"[{r.scene.name}] identified k_s {ident.k_s:.1f} N/m, kappa {ident.kappa:.0f} N m/rad, "
            f"m = {ident.m1:.3f}, {ident.m2:.3f}, {ident.m3:.3f} kg (Table 1: worst "
            f"{100 * max(abs(row['relative_difference']) for row in r.id_rows):.2f} %)\n"
            f"  reduced against full 3-D: worst {100 * worst['reduced_rel']:+.2f} % ({worst['state']} "
            f"{worst['mode']}) over {len(freq_rows)} frequencies; Table 1 model: worst "
            f"{100 * worst_t1['table1_rel']:+.2f} % ({worst_t1['state']} {worst_t1['mode']})\n"
            f"  full modes outside the reduction (of the {len(comps['open'].full_hz)} lowest): {n_left['open']} "
            f"open, {n_left['closed']} closed gap (verify.md says which and why)\n"
            "  files: " + ", ".join(sorted(p.name for p in writer.scratch.iterdir())))
