"""Stage ``ringdown``: free response, its spectrogram with NNM overlays, symmetry breaking."""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from bearingshaft import plots
from bearingshaft.output import StageWriter, write_rows
from bearingshaft.scenes import Scene
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.initial import initial_state
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.transient.integrate import ringdown
from reduced.transient.result import RingdownResult
from reduced.transient.spectrogram import spectrogram


class _Bar:
    """A progress callback (fraction done) drawing a tqdm bar."""

    def __init__(self, desc: str, enabled: bool) -> None:
        self.bar = tqdm(total=1000, desc=desc, disable=not enabled, leave=False,
                        bar_format="{l_bar}{bar}| {elapsed}<{remaining}")
        self.done = 0

    def __call__(self, fraction: float) -> None:
        new = int(round(1000 * min(max(fraction, 0.0), 1.0)))
        if new > self.done:
            self.bar.update(new - self.done)
            self.done = new

    def close(self) -> None:
        self.bar.close()


def model_system(model, progress: bool = False) -> tuple[GapSystem, np.ndarray]:
    """(system, P): a scene model's gap system and its points x1, x2, x3 as rows P of its DOFs."""
    if hasattr(model, "reduced"):  # a reduced 3-D model: from rom.npz or the cache
        rom = model.reduced(progress)
        return rom.system(), rom.point_rows
    return model.system(), model.point_rows


def scene_initial_state(scene: Scene, system: GapSystem, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x0, v0) on the system's DOFs from the scene's point values (:mod:`reduced.models.initial`)."""
    init = scene.initial
    return initial_state(system.M, system.K, P, init.x0_m, init.v0_m_s)


def run_ringdown(scene: Scene, system: GapSystem, P: np.ndarray, method: str, progress: bool) -> RingdownResult:
    """The scene's ringdown of ``system`` (points P) from its initial state, by ``method``, with a progress bar."""
    spec = scene.ringdown
    x0, v0 = scene_initial_state(scene, system, P)
    bar = _Bar(f"{scene.name}: {method}", progress)
    try:
        return ringdown(
            system, x0, v0, spec.duration_s, spec.sample_rate_hz, method, dt=spec.dt_s, omega_dt=spec.omega_dt,
            step_basis=spec.step_basis, rtol=spec.rtol, atol=spec.atol, progress=bar,
        )
    finally:
        bar.close()


def point_series(x: np.ndarray, P: np.ndarray, names: tuple[str, ...], name: str) -> np.ndarray:
    """The displacement of point ``name`` over time from DOF histories x (n_t, n)."""
    return x @ P[names.index(name)]


def backbone_curves(model, system: GapSystem | None = None, n_modes: int = 3
                    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Frequency-energy curves to overlay: HB (H = 1) of the lowest ``n_modes`` NNMs whose linear
    modes move the gaps (an assembly's swinging on its bungees does not), and the exact NNM 2 of
    a symmetric discrete model."""
    from reduced.periodic import nnm2
    from reduced.periodic.backbones import hb_backbones

    system = model.system() if system is None else system
    curves = {f"{name}, HB H=1": c
              for name, c in hb_backbones(system, 1, modes=gap_moving_modes(system, "open", n_modes)).items()}
    if isinstance(model, DiscreteParams) and model.m1 == model.m3:
        E = np.logspace(-4, 5, 400)
        curves["NNM 2, exact"] = (E, nnm2.frequency_from_energy(model, E))
    return curves


REFERENCE_WINDOW_S = 0.05  # s, before the chaotic divergence of impacting orbits dominates


def reference_check(scene: Scene, res: RingdownResult, P: np.ndarray, writer: StageWriter, progress: bool) -> None:
    """The run against the exact integrator on the same reduced model: ``reference.csv``.

    Error = max over samples and the points x1, x2, x3 of |x P^T - x_ref P^T| / max |x_ref P^T|,
    over the first REFERENCE_WINDOW_S and over the whole run (where impacting orbits diverge).
    """
    from reduced.studies import relative_error

    ref = run_ringdown(scene, res.system, P, "exact", progress)
    pts, pts_ref = res.x @ P.T, ref.x @ P.T
    rows = []
    for window in (REFERENCE_WINDOW_S, scene.ringdown.duration_s):
        n = int(np.searchsorted(res.t, window, side="right"))
        rows.append({"window_s": window, "error": relative_error(pts[:n], pts_ref[:n]),
                     "method": res.method, "runtime_s": res.stats["wall_s"],
                     "energy_balance_error": res.energy_balance_error, "exact_runtime_s": ref.stats["wall_s"],
                     "exact_events": ref.stats.get("n_events"), "exact_energy_balance_error": ref.energy_balance_error})
    write_rows(writer.path("reference.csv"), rows)
    writer.stats["reference"] = rows
    if progress:
        print(f"[{scene.name}] against the exact integrator: {rows[0]['error']:.2g} over the first "
              f"{REFERENCE_WINDOW_S:g} s, {rows[1]['error']:.2g} over the run; exact took "
              f"{ref.stats['wall_s']:.3g} s", flush=True)


def first_exceedance(t: np.ndarray, d: np.ndarray, threshold: float) -> float | None:
    """s, first time d exceeds threshold (None if never)."""
    idx = np.flatnonzero(d > threshold)
    return float(t[idx[0]]) if idx.size else None


def growth_rate(t: np.ndarray, d: np.ndarray, lo: float, hi: float) -> float:
    """1/s, least-squares slope of ln d over the samples with lo < d < hi (NaN if too few)."""
    sel = (d > lo) & (d < hi)
    if np.count_nonzero(sel) < 10:
        return float("nan")
    return float(np.polyfit(t[sel], np.log(d[sel]), 1)[0])


def ringdown_stage(scene: Scene, writer: StageWriter, progress: bool, method: str | None = None) -> None:
    spec = scene.ringdown
    method = method or spec.method
    system, P = model_system(scene.model, progress)
    res = run_ringdown(scene, system, P, method, progress)
    res.save(writer.path("ringdown.npz"))
    plots.ringdown_figure(res, writer.path("ringdown.png"), f"{scene.name}: {scene.description}")
    writer.stats.update(
        {"method": method, "duration_s": spec.duration_s, "energy_J_initial": float(res.energy[0]),
         "energy_balance_error": res.energy_balance_error, **res.stats}
    )
    if progress:
        print(f"[{scene.name}] {method}: {res.stats.get('n_steps', res.stats.get('n_events'))} "
              f"{'steps' if 'n_steps' in res.stats else 'events'} in {res.stats['wall_s']:.3g} s, "
              f"energy-balance error {res.energy_balance_error:.2g}", flush=True)
    if scene.model_kind == "rom" and method != "exact":
        reference_check(scene, res, P, writer, progress)
    if scene.spectrogram is not None:
        sp = scene.spectrogram
        S = spectrogram(res.t, point_series(res.x, P, scene.model.point_names, sp.dof), sp.window_s, sp.overlap)
        f_open = linear_modes(system, "open").freq_hz[gap_moving_modes(system, "open", 3)]
        plots.spectrogram_figure(
            S, (res.t, res.energy), backbone_curves(scene.model, system), writer.path("spectrogram.png"),
            f"{scene.name}: spectrogram of {sp.dof} ({method}); open-gap "
            f"{', '.join(f'{f:.1f}' for f in f_open)} Hz",
            sp.fmax_hz, sp.db_range,
        )
    if scene.symmetry is not None:
        symmetry_stage(scene, res, P, writer, progress)


def symmetry_stage(scene: Scene, res: RingdownResult, P: np.ndarray, writer: StageWriter, progress: bool) -> None:
    """Fig. 4: when does |x_a - x_b| first exceed each method's tolerance?"""
    names = scene.symmetry.dofs
    pa, pb = (P[scene.model.point_names.index(n)] for n in names)
    runs = {res.method: res}
    for other in scene.symmetry.methods:
        if other not in runs:
            runs[other] = run_ringdown(scene, res.system, P, other, progress)
    rows, table = [], {}
    for method, r in runs.items():
        d = np.abs(r.x @ (pa - pb))
        t_break = first_exceedance(r.t, d, r.tolerance)
        rate = growth_rate(r.t, d, 1e3 * max(np.min(d[d > 0], initial=1e-300), 1e-30), 1e-3 * np.max(np.abs(r.x)))
        table[method] = (r, t_break)
        rows.append({"method": method, "tolerance_m": r.tolerance, "t_break_s": t_break,
                     "growth_rate_per_s": rate, "max_abs_diff_m": float(np.max(d)),
                     "runtime_s": r.stats.get("wall_s")})
    write_rows(writer.path("symmetry.csv"), rows)
    plots.symmetry_figure(table, (pa, pb), names, writer.path("symmetry.png"),
                          f"{scene.name}: symmetry breaking of {names[0]} and {names[1]}")
    writer.stats["symmetry"] = rows
