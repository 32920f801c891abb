"""Stage ``hammer``: the virtual hammer test of the apparatus, channel for channel (issue 12).

The reduced apparatus (:class:`reduced.models.rig.VirtualRig`: the scene's reduced model of
the whole assembly, every fixed-interface mode up to its count, planar or not) is struck by
the scene's blow and recorded on every rig channel (:mod:`fem.rig`): six triaxial beam
accelerometers, four triaxial tube sensors, four tip load cells and the hammer. The record
is [ringdown]'s (duration, sampling, integrator: ``exact`` by default, whose crossings are
found with a guarantee, :mod:`reduced.transient.exact`). Files:

- ``hammer.npz``: ``t`` and ``data`` (channels x samples) of the nominal blow, with the
  channels' ``names``, ``nodes``, ``directions``, ``units``; ``channels.csv`` says which is which;
- ``hammer.uff``: every channel as UFF 58 (:func:`fem.uff.write_uff58`);
- ``fig10.png``: the hammer force and a tip load cell against time (the paper's Fig. 10);
- ``fig11.png``: spectrogram of a beam accelerometer (Fig. 11) with the six pseudo-rigid
  open-gap frequencies and the NNM backbones (HB, H = 1) overlaid;
- ``levels.csv``, ``levels.png``: the level sweep, one spectrogram per blow level;
- ``hammer.md``: what happens, in numbers (peak tip forces, impacts, when the gaps stay
  open, which modes carry the energy at the end, energy balance);
- with ``[hammer] linear_check``: ``linear_check.csv`` and ``linear_check.png``, the
  open-gap response against the full 3-D model's modal superposition (:func:`linear_check`);
- with a measured test (``bearingshaft hammer --test FILE.uff``): the model driven by the
  measured hammer force at the test's sampling, ``test_errors.csv``, ``test_compare.png``
  and ``test_spectrogram.png`` (:mod:`bearingshaft.correlate`).

Numbers in the science files are written to 6 significant digits (to 4 for the quantities
that depend on where the exact integrator lands a crossing), :mod:`bearingshaft.hammer_report`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from bearingshaft.estimates import COPIES, FLOAT, MATPLOTLIB_BYTES, Estimate, n_dofs
from bearingshaft.output import StageWriter
from bearingshaft.scenes import HammerSpec, Scene
from bearingshaft.systems import solver_options
from fem.rig import TIP_CELLS
from reduced.models.loads import HalfSine, Tabulated
from reduced.models.rig import VirtualRig, virtual_rig

LABEL_MAX_HZ = 100.0  # Hz, the pseudo-rigid modes are searched below this (Table 2: 10.9 to 33.7 Hz)


# -- the run ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Record:
    """One virtual test: every channel at the sample times, and what the integrator reported."""

    level_N: float  # N, the blow's peak
    t: np.ndarray  # (N,) s
    data: np.ndarray  # (n_channels, N)
    x: np.ndarray  # (N, n) reduced state (for the modal energy at the end)
    v: np.ndarray
    energy: np.ndarray  # (N,) J
    dissipated: np.ndarray  # (N,) J
    external: np.ndarray  # (N,) J, work of the hammer
    stats: dict
    balance_error: float


def blow(spec: HammerSpec, level_N: float):
    """The hammer's force history at peak ``level_N``: the half-sine, or the measured history of
    ``force_file`` scaled to that peak."""
    if spec.force_file:
        tab = Tabulated.from_file(spec.force_file)
        peak = float(np.max(np.abs(tab.force_N)))
        return Tabulated(tab.t_s, tab.force_N * (level_N / peak), source=tab.source)
    return HalfSine(peak_N=level_N, duration_s=spec.duration_s, start_s=spec.start_s)


def run_record(rig: VirtualRig, signal, scene: Scene, level_N: float, duration_s: float | None = None,
               sample_rate_hz: float | None = None) -> Record:
    """The rig from rest under ``signal``, on [ringdown]'s record (or the duration and rate given).

    The channels are acquired as a test's DAQ does (:class:`reduced.models.daq.Acquisition`):
    computed from the exact state at q times the rate, q from the rig's highest frequency
    over its contact states, low-passed by a linear-phase anti-alias filter (flat to 0.4 fs,
    -100 dB from fs/2) and decimated; the integration runs on past the record by the
    filter's half length so its last samples are exact too. The hammer channel is the force
    applied, sampled as it is (the model's input: a record drives the model again with the same
    force). The state (x, v) and the energies are the exact ones at the record's samples."""
    from reduced.models.daq import Acquisition, oversampling
    from reduced.transient.integrate import ringdown
    from reduced.transient.result import sample_count

    rd = scene.ringdown
    n = rig.system.n
    fs = sample_rate_hz or rd.sample_rate_hz
    n_out = sample_count(duration_s or rd.duration_s, fs)
    acq = Acquisition(fs, oversampling(rig.system.omega_max() / (2 * math.pi), fs))
    q = acq.oversample
    fine_duration = (q * (n_out - 1) + acq.tail_samples) / acq.fine_rate_hz
    res = ringdown(rig.system, np.zeros(n), np.zeros(n), fine_duration, acq.fine_rate_hz, rd.method,
                   loads=rig.loads(signal), **solver_options(rd))
    keep = slice(0, q * (n_out - 1) + 1, q)
    fine = rig.channel_data(res.x, res.v, signal(res.t))
    data = np.vstack([acq.acquire(fine[:-1], n_out), fine[-1:, keep]])  # the hammer: the applied force itself
    stats = {**res.stats, "acquisition": acq.describe(), "oversample": q}
    return Record(level_N, res.t[keep], data, res.x[keep], res.v[keep], res.energy[keep], res.dissipated[keep],
                  res.external[keep], stats, float(res.energy_balance_error))


def default_location(rom) -> tuple[float, float, float]:
    """m, the beam's top face at mid-span (x = 0, y = 0): where the tube's hole lets the hammer in."""
    pts, part = rom.mesh["points"], rom.mesh["cell_part"]
    beam_nodes = np.unique(rom.mesh["hexes"][part == int(rom.mesh["beam_part"])])
    return 0.0, 0.0, float(pts[beam_nodes, 2].max())


# -- what happens: impacts, peak forces, energy by mode --------------------------------------
def impacts(rig: VirtualRig, rec: Record) -> dict:
    """Per stop (tip load cell): number of impacts (closures seen in the samples), peak contact
    force, time the last contact ends; and the exact integrator's crossing count."""
    pen = rig.system.penetration(rec.x)  # (N, 4) > 0 closed
    closed = pen > 0
    out = {}
    for j, cell in enumerate(TIP_CELLS):
        c = closed[:, j]
        starts = np.flatnonzero(c[1:] & ~c[:-1]) + 1
        n_imp = int(starts.size + (1 if c[0] else 0))
        last = float(rec.t[np.flatnonzero(c)[-1]]) if c.any() else math.nan
        out[cell] = {"impacts": n_imp, "peak_contact_N": float(rig.system.k[j] * max(pen[:, j].max(), 0.0)),
                     "last_contact_s": last}
    return out


def pseudo_rigid(rig: VirtualRig, geometry, lm) -> dict[str, tuple[int, float, float]]:
    """{label: (mode index, freq_hz, score)} of the six pseudo-rigid open-gap modes of the rig.

    Each mode's beam-sensor motion (6 triaxial points) is fitted by a rigid motion about the
    beam's centre (least squares), likewise the tube sensors', and the relative rigid motion
    q = q_beam - q_tube is scored against x, y, z, theta_x, theta_y, theta_z by its share of
    the beam's rigid kinetic energy (diag of its rigid mass: m, m, m, I_x, I_y, I_z of the bar);
    a linear assignment gives each label one mode below LABEL_MAX_HZ (the sensor version of
    :mod:`fem.labels`, on the 10 measured points as the paper's beam MAC).
    """
    from scipy.optimize import linear_sum_assignment

    from fem.labels import COMPONENT_LABELS

    names = list(rig.names)
    sensors = {"beam": geometry.beam_sensors(), "tube": geometry.tube_sensors()}
    q = {}
    for part, pts in sensors.items():
        G, rows = [], []
        for s, (x, y, z) in pts.items():
            for c, axis in enumerate("xyz"):
                g = np.zeros(6)
                g[c] = 1.0
                g[3:] = {0: (0.0, z, -y), 1: (-z, 0.0, x), 2: (y, -x, 0.0)}[c]  # (theta x r)_c
                G.append(g)
                rows.append(rig.acc_rows[names.index(f"{s}:{axis}")])
        u = np.vstack(rows) @ lm.phi  # (3 s, k)
        q[part] = np.linalg.lstsq(np.array(G), u, rcond=None)[0]  # (6, k)
    rel = q["beam"] - q["tube"]
    b, h, L = geometry.beam_width, geometry.beam_height, geometry.beam_length
    inertia = np.array([1.0, 1.0, 1.0, (b**2 + h**2) / 12, (L**2 + h**2) / 12, (L**2 + b**2) / 12])
    e = rel**2 * inertia[:, None]
    beam_e = np.sum(q["beam"] ** 2 * inertia[:, None], axis=0)
    score = (e / np.maximum(e.sum(axis=0), 1e-300)) * np.clip(e.sum(axis=0) / np.maximum(beam_e, 1e-300), 0, 1)
    cand = np.flatnonzero(lm.freq_hz < LABEL_MAX_HZ)
    if cand.size < 6:
        return {}
    r, c = linear_sum_assignment(-score[:, cand].T)
    return {COMPONENT_LABELS[j]: (int(cand[i]), float(lm.freq_hz[cand[i]]), float(score[j, cand[i]]))
            for i, j in zip(r, c, strict=True)}


def modal_energy_end(rig: VirtualRig, rec: Record, lm, last_s: float = 0.1) -> np.ndarray:
    """J, mean energy of each open-gap linear mode over the last ``last_s`` of the record:
    E_k = (p_k'^2 + omega_k^2 p_k^2) / 2 with p = Phi^T M q (modes mass-normalised)."""
    k = max(1, int(round(last_s / (rec.t[1] - rec.t[0]))))
    M = rig.system.M
    p = rec.x[-k:] @ M @ lm.phi
    pd = rec.v[-k:] @ M @ lm.phi
    omega = 2 * np.pi * lm.freq_hz
    return np.mean(0.5 * (pd**2 + (omega * p) ** 2), axis=0)


def coupled_subsystem(system, tol: float = 1e-6):
    """The rig restricted to x1, x3 and the fixed-interface modes that couple to them (|M_bq| >
    tol sqrt(max M_bb)): the others have no mass or stiffness coupling to anything (K_bq = 0,
    M_qq = I, K_qq diagonal) and no damping coupling (dashpots on the symmetric points), so the
    free motion of the gaps, hence every NNM that moves them, lives in this subsystem exactly."""
    from reduced.models.gaps import GapSystem

    Mbq = system.M[:2, 2:]
    scale = math.sqrt(float(np.max(np.diag(system.M[:2, :2]))))
    keep = np.concatenate([[0, 1], 2 + np.flatnonzero(np.linalg.norm(Mbq, axis=0) > tol * scale)])
    sub = np.ix_(keep, keep)
    return GapSystem(M=system.M[sub], C=system.C[sub], K=system.K[sub], B=system.B[:, keep], k=system.k,
                     offset=system.offset, side=system.side, tip=system.tip,
                     dof_names=tuple(system.dof_names[i] for i in keep), stop_names=system.stop_names)


# -- the stage ------------------------------------------------------------------------------
def hammer_stage(scene: Scene, writer: StageWriter, progress: bool, test_file: str | None = None) -> None:
    """Run the virtual test (and the level sweep, the linear check, a test comparison), write its files."""
    from reduced._blas import single_thread_blas

    with single_thread_blas():
        _hammer_stage(scene, writer, progress, test_file)


def _hammer_stage(scene: Scene, writer: StageWriter, progress: bool, test_file: str | None) -> None:
    from bearingshaft import hammer_report as report
    from reduced.models.modes import linear_modes

    spec = scene.hammer
    rom = scene.model.reduced(progress)
    location = tuple(spec.location_m) if spec.location_m else default_location(rom)
    try:
        rig = virtual_rig(rom, location, spec.direction, spec.seismic_mass_kg)
    except ValueError as exc:
        from bearingshaft.scenes import SceneError

        raise SceneError(f"{scene.origin} [hammer]: {exc}") from None
    geometry = scene.model.fe_model().geometry()
    lm = linear_modes(rig.system, "open")
    labels = pseudo_rigid(rig, geometry, lm)
    writer.stats.update({"n_dofs": rig.system.n, "location_m": list(location), "direction": list(rig.direction),
                         "pseudo_rigid_hz": {k: v[1] for k, v in labels.items()}})

    if test_file is not None:
        report.compare_test(scene, rig, writer, test_file, progress)
        return

    levels = sorted({*spec.levels_N, spec.peak_N})
    records = {}
    bar = tqdm(levels, desc=f"{scene.name}: virtual tests", unit="level", disable=not progress, leave=False)
    for level in bar:
        records[level] = run_record(rig, blow(spec, level), scene, level)
    nominal = records[spec.peak_N]
    report.write_record(writer, rig, nominal, scene)
    backbones = report.backbones(rig, spec.backbone_modes, float(np.max(nominal.energy)))
    report.fig10(writer.path("fig10.png"), rig, nominal, spec)
    report.fig11(writer.path("fig11.png"), rig, nominal, scene, labels, backbones)
    summary = {level: report.level_summary(rig, rec, lm, labels) for level, rec in records.items()}
    report.levels_files(writer, rig, records, summary, scene)
    linear = report.linear_check(scene, rom, rig, writer, progress) if spec.linear_check else None
    report.write_markdown(writer.path("hammer.md"), scene, rig, nominal, summary, labels, linear, backbones)
    writer.stats.update({"levels": {str(k): v for k, v in summary.items()},
                         "wall_s": {str(k): r.stats.get("wall_s") for k, r in records.items()}})
    print(report.summary_line(scene, rig, nominal, summary[spec.peak_N], linear), flush=True)



# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Strike the reduced apparatus with the scene's blow at every level and record every rig channel
as a test's DAQ would (six triaxial beam accelerometers, four triaxial tube sensors, four tip
load cells, the hammer). Writes hammer.npz, hammer.uff (UFF 58), channels.csv, fig10.png,
fig11.png, levels.csv, levels.png, hammer.md and, with [hammer] linear_check, linear_check.csv
and .png. With --test FILE.uff, a measured test drives the model by its hammer channel and every
channel is compared: test_errors.csv, test_compare.png, test_spectrogram.png, model.uff."""


def estimate(scene: Scene) -> list[Estimate]:
    """Every level's record in memory: state, channels, energies; the exact integrator's table."""
    from fem.rig import channel_names

    n = n_dofs(scene)
    r, h = scene.ringdown, scene.hammer
    samples = r.duration_s * r.sample_rate_hz + 1
    levels = len({*h.levels_N, h.peak_N}) + int(h.linear_check)
    per = (2 * n + len(channel_names()) + 4) * FLOAT
    exact = 3 * 2**4 * (2 * n) ** 2 * 16  # the exact integrator's state table (4 stops)
    return [Estimate("hammer", int(MATPLOTLIB_BYTES + COPIES * samples * per + levels * samples * per + exact),
                     f"{levels} records of {samples:.3g} samples x {n} DOFs",
                     "[ringdown] duration_s or sample_rate_hz, or [hammer] levels_N")]


@dataclass(frozen=True, eq=False)
class _Pending:  # transitional (issue 23): the stage computes while it writes, until split
    scene: Scene
    progress: bool
    options: dict


def compute(scene: Scene, progress: bool, workdir, test_file: str | None = None) -> _Pending:
    return _Pending(scene, progress, {"test_file": test_file})


def write(result: _Pending, writer: StageWriter) -> None:
    hammer_stage(result.scene, writer, result.progress, **result.options)

__all__ = ["hammer_stage", "run_record", "blow", "Record", "pseudo_rigid", "coupled_subsystem", "default_location"]
