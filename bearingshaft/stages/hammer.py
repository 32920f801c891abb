"""Stage ``hammer``: the virtual hammer test of the apparatus, channel for channel (issue 12).

The reduced apparatus (:class:`reduced.models.rig.VirtualRig`: the scene's reduced model of
the whole assembly, every fixed-interface mode up to its count, planar or not) is struck by
the scene's blow and recorded on every rig channel (:mod:`fem.rig`): six triaxial beam
accelerometers, four triaxial tube sensors, four tip load cells and the hammer. The record
is [ringdown]'s (duration, sampling, integrator: ``exact`` by default, whose crossings are
found with a guarantee, :mod:`reduced.transient.exact`).

:func:`compute` runs it and returns what it found (:mod:`bearingshaft.stages.hammer_results`);
:func:`write` hands that to :mod:`bearingshaft.stages.hammer_files`, which writes (:data:`DESCRIPTION`):

- ``hammer.npz``: ``t`` and ``data`` (channels x samples) of the nominal blow, with the
  channels' ``names``, ``nodes``, ``directions``, ``units``; ``channels.csv`` says which is which;
- ``hammer.uff``: every channel as UFF 58 (:func:`fem.uff.write_uff58`);
- ``fig10.png``: the hammer force and a tip load cell against time (the paper's Fig. 10);
- ``fig11.png``: spectrogram of a beam accelerometer (Fig. 11) with the six pseudo-rigid
  open-gap frequencies and the NNM backbones (HB, H = 1) overlaid;
- ``levels.csv``, ``levels.png``: the level sweep, one spectrogram per blow level;
- ``hammer.md``: what happens, in numbers (peak tip forces, impacts, when the gaps stay
  open, which modes carry the energy at the end, energy balance);
- ``lyapunov.csv``: the nominal record's largest Lyapunov exponent, from exact runs displaced by
  1e-9 (:func:`record_lyapunov`): how long its chaotic numbers are comparable between two machines
  (the reproduction report's horizon, :mod:`bearingshaft.reproduction`);
- with ``[hammer] linear_check``: ``linear_check.csv`` and ``linear_check.png``, the
  open-gap response against the full 3-D model's modal superposition
  (:mod:`bearingshaft.stages.hammer_linear`);
- with a measured test (``bearingshaft hammer --test FILE.uff``) instead of all the above: the
  model driven by the measured hammer force (through a force window) at the test's sampling
  (:mod:`bearingshaft.stages.hammer_compare`, :mod:`bearingshaft.correlate`), the predictability
  horizon, pointwise errors up to it and the measures that survive chaos past it
  (:mod:`bearingshaft.measures`): ``test_errors.csv``, ``test_measures.csv``, ``test_horizon.csv``,
  ``test_compare.md``, ``test_compare.png``, ``test_spectrogram.png``, ``test_horizon.png``,
  ``test_measures.png``, ``test_backbone.png`` and ``model.uff``.

Numbers in the science files are written to 6 significant digits (to 4 for the quantities
that depend on where the exact integrator lands a crossing), :mod:`bearingshaft.stages.hammer_files`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from bearingshaft import measured
from bearingshaft.estimates import COPIES, FLOAT, MATPLOTLIB_BYTES, Estimate, n_dofs, sliders
from bearingshaft.fanout import fan_out
from bearingshaft.progress import bar as progress_bar
from bearingshaft.reproduction import Reproduction, chaotic, exact, record, roundoff
from bearingshaft.scenes import HammerSpec, Scene, SceneError
from bearingshaft.stages import hammer_compare, hammer_linear
from bearingshaft.stages.hammer_results import (
    ChannelBackbone,
    Comparison,
    FrictionComparison,
    LinearCheck,
    Record,
    VirtualTest,
)
from bearingshaft.systems import solver_options
from fem.rig import TIP_CELLS
from reduced.models.loads import HalfSine, Tabulated
from reduced.models.rig import VirtualRig, virtual_rig

LABEL_MAX_HZ = 100.0  # Hz, the pseudo-rigid modes are searched below this (Table 2: 10.9 to 33.7 Hz)
END_SHARE_S = 0.1  # s, the energy "at the end" is the mean over the record's last 0.1 s
OPEN_GAP_M = 1.0  # m, the linear check's gap: too large to close
LYAPUNOV_SEEDS = 3  # exact runs of the nominal blow displaced by LYAPUNOV_DELTA after it: the record's largest Lyapunov
# exponent (lyapunov.csv), from which the reproduction report computes how long its chaotic numbers are comparable;
# as many as the ringdown stage's reference check (hammer-test: 300-380 /s, about 3.5 s a run, each stopped once the
# separation saturates, ~0.05 s into the record)
LYAPUNOV_DELTA = 1e-9  # relative (energy norm) size of the displacement, as the ringdown stage's reference check
LYAPUNOV_SATURATION = 1e-3  # the separation has saturated at this fraction of the state's norm
LYAPUNOV_WINDOW_S = 0.01  # s, windows over which the separation is maximized (a few periods of the 1737 Hz mode)
DECAY_FLOOR = 1e-2  # a motion has decayed when its modal energy stays below this share of its peak


# -- the run ------------------------------------------------------------------------------
def blow(spec: HammerSpec, level_N: float):
    """The hammer's force history at peak ``level_N``: the half-sine, or the measured history of
    ``force_file`` scaled to that peak.

    Parameters
    ----------
    spec : the scene's [hammer] (half-sine duration and start, or ``force_file``)
    level_N : N, the blow's peak

    Returns
    -------
    HalfSine or Tabulated, a force signal p(t) in N
    """
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
    force). The state (x, v) and the energies are the exact ones at the record's samples. At the fine
    rate the integrator evaluates only the channels' rows of the state (:class:`ChannelRows`,
    :func:`reduced.transient.integrate.ringdown_rows`: the exact method sums r rows over its terms
    instead of the whole state and its work), the whole state at the record's samples; the energy
    balance error is over those.

    Parameters
    ----------
    rig : the virtual rig, from rest
    signal : the hammer's force p(t), N (:func:`blow`, or a measured history)
    scene : the scene ([ringdown]: duration, sampling, integrator and its options)
    level_N : N, the blow's peak, as the record is labelled
    duration_s, sample_rate_hz : s, Hz, the record (default: [ringdown]'s)

    Returns
    -------
    Record
    """
    from reduced.models.daq import Acquisition, oversampling
    from reduced.transient.integrate import ringdown_rows
    from reduced.transient.result import balance_error, sample_count

    rd = scene.ringdown
    n = rig.system.n
    fs = sample_rate_hz or rd.sample_rate_hz
    n_out = sample_count(duration_s or rd.duration_s, fs)
    acq = Acquisition(fs, oversampling(rig.system.omega_max() / (2 * math.pi), fs))
    q = acq.oversample
    fine_duration = (q * (n_out - 1) + acq.tail_samples) / acq.fine_rate_hz
    rows = ChannelRows.of(rig)
    res, z = ringdown_rows(rig.system, np.zeros(n), np.zeros(n), fine_duration, acq.fine_rate_hz, rows.R, q,
                           rd.method, loads=rig.loads(signal), **solver_options(rd))
    t_fine = np.arange(z.shape[0]) / acq.fine_rate_hz
    fine = rows.channels(z, signal(t_fine))
    data = np.vstack([acq.acquire(fine[:-1], n_out), fine[-1:, : q * (n_out - 1) + 1: q]])  # the hammer: the force
    stats = {**res.stats, "acquisition": acq.describe(), "oversample": q}
    fr = rig.system.friction is not None
    E = res.energy
    balance = balance_error(E, res.dissipated, res.external, res.loads is not None)
    keep = slice(0, n_out)
    return Record(level_N, res.t[keep], data, res.x[keep], res.v[keep], E[keep], res.dissipated[keep],
                  res.external[keep], stats, balance, res.w[keep] if fr else None, res.friction[keep] if fr else None)


@dataclass(frozen=True, eq=False)
class ChannelRows:
    """The rig's channels as rows of the state y = [x; v] ([x; v; w] with friction) and the stops' forces
    (:meth:`reduced.models.rig.VirtualRig.channel_data`, rewritten so that the integrator can evaluate the rows
    alone at the DAQ's fine rate, :func:`reduced.transient.integrate.ringdown_rows`).

    With Wr = [acc_rows; seat_rows] M^-1, each accelerometer axis and seat is
    a = Wr (b p - C v - K x - B^T f(B x) - Bt^T k_t (Bt x - w)) = L y + (Wr b) p - (Wr B^T) f(B x),
    L = [-Wr K - Wr Bt^T k_t Bt, -Wr C, Wr Bt^T k_t]; the stops' forces f need only s = B x. So R = [L; B 0 0].

    Attributes
    ----------
    R : (n_acc + 4 + m, N) ndarray of float
        L (m/s^2 per unit of y) for the accelerometer axes and the seats, then B (the stops' coordinates, m).
    Wb : (n_acc + 4,) ndarray of float
        m/s^2 per N: Wr b.
    WB : (n_acc + 4, m) ndarray of float
        m/s^2 per N: Wr B^T.
    rig : VirtualRig
    """

    R: np.ndarray
    Wb: np.ndarray
    WB: np.ndarray
    rig: VirtualRig

    @classmethod
    def of(cls, rig: VirtualRig) -> ChannelRows:
        """The rows of ``rig``'s channels.

        Parameters
        ----------
        rig : VirtualRig

        Returns
        -------
        ChannelRows
        """
        s = rig.system
        n, p = s.n, s.p
        W = np.linalg.solve(s.M, np.vstack([rig.acc_rows, rig.seat_rows]).T).T  # rows of R M^-1 (M symmetric)
        L = np.zeros((W.shape[0], 2 * n + p))
        L[:, :n] = -(W @ s.K)
        L[:, n:2 * n] = -(W @ s.C)
        if p:
            WBt = (W @ s.friction.Bt.T) * s.friction.k_t  # (rows, p): Wr Bt^T k_t
            L[:, :n] -= WBt @ s.friction.Bt
            L[:, 2 * n:] = WBt
        B = np.zeros((s.m, 2 * n + p))
        B[:, :n] = s.B
        return cls(np.vstack([L, B]), W @ rig.b, W @ s.B.T, rig)

    def channels(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(n_channels, N) every channel from the rows z (N, r) = y @ R^T under the hammer force p (N,), N;
        the same channels as :meth:`reduced.models.rig.VirtualRig.channel_data` of those states, to round-off.

        Parameters
        ----------
        z : (N, r) ndarray of float
            R y at N samples.
        p : (N,) ndarray of float
            N, the hammer's force at them.

        Returns
        -------
        (n_channels, N) ndarray of float
            m/s^2 (accelerometers), N (load cells, the hammer).
        """
        rig = self.rig
        s = rig.system
        k = self.Wb.shape[0]
        d = z[:, k:] - s.offset  # (N, m): B x - o
        f = np.where(s.side * d > 0.0, s.k * d, 0.0)  # the stops' forces along their rows
        a = z[:, :k].T + np.outer(self.Wb, p) - self.WB @ f.T
        n_acc = len(rig.acc_rows)
        stop = (s.k * np.maximum(s.side * d, 0.0)).T  # (4, N) compression of x1+, x1-, x3+, x3-: TIP_CELLS order
        sign = np.array([1.0 if c.endswith("top") else -1.0 for c in TIP_CELLS])[:, None]
        cells = stop - sign * rig.seismic_mass_kg * a[n_acc:]
        return np.vstack([a[:n_acc], cells, p[None, :]])


def default_location(rom) -> tuple[float, float, float]:
    """m, the beam's top face at mid-span (x = 0, y = 0): where the tube's hole lets the hammer in.

    Parameters
    ----------
    rom : a reduced assembly model built with its mesh

    Returns
    -------
    (x, y, z), m
    """
    pts, part = rom.mesh["points"], rom.mesh["cell_part"]
    beam_nodes = np.unique(rom.mesh["hexes"][part == int(rom.mesh["beam_part"])])
    return 0.0, 0.0, float(pts[beam_nodes, 2].max())


# -- what happens: impacts, peak forces, energy by mode --------------------------------------
def impacts(rig: VirtualRig, rec: Record) -> dict:
    """Per stop (tip load cell): number of impacts (closures seen in the samples), peak contact
    force, time the last contact ends.

    Parameters
    ----------
    rig : the virtual rig
    rec : a record of it (its states ``x`` at the times ``t``)

    Returns
    -------
    dict {tip load cell: {"impacts": int, "peak_contact_N": N, "last_contact_s": s (NaN: never closed)}}
    """
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

    Parameters
    ----------
    rig : the virtual rig
    geometry : the apparatus's geometry (sensor positions, beam dimensions)
    lm : the rig's open-gap linear modes (:func:`reduced.models.modes.linear_modes`)

    Returns
    -------
    dict {label: (mode index, freq_hz, score)}; empty when fewer than six modes lie below LABEL_MAX_HZ
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
    E_k = (p_k'^2 + omega_k^2 p_k^2) / 2 with p = Phi^T M q (modes mass-normalised).

    Parameters
    ----------
    rig : the virtual rig
    rec : a record of it
    lm : the rig's open-gap linear modes
    last_s : s, the end of the record averaged over

    Returns
    -------
    (n_modes,) ndarray, J
    """
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
    free motion of the gaps, hence every NNM that moves them, lives in this subsystem exactly.

    Parameters
    ----------
    system : the rig's GapSystem
    tol : coupling below which a mode is left out, relative to sqrt(max M_bb)

    Returns
    -------
    GapSystem on x1, x3 and the coupled modes
    """
    from reduced.models.gaps import GapSystem

    Mbq = system.M[:2, 2:]
    scale = math.sqrt(float(np.max(np.diag(system.M[:2, :2]))))
    keep = np.concatenate([[0, 1], 2 + np.flatnonzero(np.linalg.norm(Mbq, axis=0) > tol * scale)])
    sub = np.ix_(keep, keep)
    return GapSystem(M=system.M[sub], C=system.C[sub], K=system.K[sub], B=system.B[:, keep], k=system.k,
                     offset=system.offset, side=system.side, tip=system.tip,
                     dof_names=tuple(system.dof_names[i] for i in keep), stop_names=system.stop_names)


def backbones(rig: VirtualRig, n_modes: int, energy_max_J: float) -> dict:
    """HB (H = 1) backbones of the lowest ``n_modes`` NNMs that move the gaps, on the rig's coupled
    subsystem (exact for them: :func:`coupled_subsystem`).

    Parameters
    ----------
    rig : the virtual rig
    n_modes : how many backbones (0: none)
    energy_max_J : J, the record's largest energy: the backbones reach ten times it (at least 1 mJ)

    Returns
    -------
    dict {label: (energy_J, freq_hz)}, label ``"NNM at f Hz (HB, H=1)"``
    """
    if n_modes == 0:
        return {}
    from reduced.models.modes import gap_moving_modes
    from reduced.periodic.backbones import hb_backbones

    sub = coupled_subsystem(rig.system)
    curves = hb_backbones(sub, 1, energy_max_J=max(10.0 * energy_max_J, 1e-3),
                          modes=gap_moving_modes(sub, "open", n_modes))
    return {f"NNM at {f[0]:.1f} Hz (HB, H=1)": (E, f) for E, f in curves.values()}


LINEAR_REACH = 1e-4  # an NNM backbone is drawn flat (the open-gap mode) down to this share of its first amplitude
BAND_BELOW = 0.7  # a ringdown's NNM component is band-passed from this x its open-gap frequency ...
BAND_ABOVE = 1.2  # ... to this x the backbone's frequency at the free decay's largest energy


def channel_backbones(rig: VirtualRig, n_modes: int, energy_max_J: float, sample_rate_hz: float,
                      channels: list[str] | None = None) -> list[ChannelBackbone]:
    """HB (H = 1) backbones of the lowest ``n_modes`` NNMs that move the gaps, each seen on the
    accelerometer axis where it shows most, for the ringdown backbones of a measured test.

    Along a backbone x(tau) = c_0 + c_1 cos tau + s_1 sin tau (on the coupled subsystem,
    :func:`coupled_subsystem`), an accelerometer axis r moves with the fundamental displacement
    amplitude sqrt((r . c_1)^2 + (r . s_1)^2) (its acceleration's is omega^2 that); the axis
    chosen is the one (among ``channels``) where it is largest at the backbone's lowest energy. The
    band of its ringdown component is BAND_BELOW x the open-gap frequency to BAND_ABOVE x the
    backbone's frequency at ``energy_max_J`` (at most 0.45 sample_rate_hz).

    Parameters
    ----------
    rig : VirtualRig
        The rig.
    n_modes : int
        Backbones (0: none).
    energy_max_J : float
        J, the free decay's largest energy: the backbones reach ten times it (at least 1 mJ).
    sample_rate_hz : float
        Hz, the test's sampling.
    channels : list of str or None
        The accelerometer axes allowed (default every one).

    Returns
    -------
    list of ChannelBackbone
    """
    from reduced.models.modes import gap_moving_modes
    from reduced.periodic.backbones import nnm_branch

    if n_modes == 0:
        return []
    sub = coupled_subsystem(rig.system)
    keep = [rig.system.dof_names.index(d) for d in sub.dof_names]
    acc = [c.name for c in rig.channels][: len(rig.acc_rows)]
    use = [i for i, name in enumerate(acc) if channels is None or name in channels]
    if not use:
        return []
    R = rig.acc_rows[np.ix_(use, keep)]
    out = []
    for mode in gap_moving_modes(sub, "open", n_modes):
        b = nnm_branch(sub, int(mode), H=1, energy_max_J=max(10.0 * energy_max_J, 1e-3))
        order = np.argsort(b.energy_J, kind="stable")
        E, f, X = b.energy_J[order], b.freq_hz[order], b.X[order]
        n = sub.n
        c1, s1 = X[:, n:2 * n], X[:, 2 * n:3 * n]
        amp = np.hypot(c1 @ R.T, s1 @ R.T).T  # (channels, points), m
        # below its first point an NNM is the open-gap mode (the branch starts where the gaps still stay
        # open): the curve goes on flat down to LINEAR_REACH of that amplitude
        amp = np.hstack([LINEAR_REACH * amp[:, :1], amp])
        E, f = np.concatenate([[LINEAR_REACH**2 * E[0]], E]), np.concatenate([[f[0]], f])
        k = int(np.argmax(amp[:, 0]))
        f_top = float(np.interp(np.log(energy_max_J), np.log(E), f)) if energy_max_J > 0 else float(f[0])
        band = (BAND_BELOW * float(f[0]), min(BAND_ABOVE * max(f_top, float(f[0])), 0.45 * sample_rate_hz))
        out.append(ChannelBackbone(f"NNM at {f[0]:.1f} Hz", acc[use[k]], amp[k], f, E, band))
    return out


def mode_classes(freq_hz, labels: dict) -> list[str]:
    """A name for every open-gap mode: its pseudo-rigid label, "bungee" for the whole assembly
    swinging on its bungees (below half the lowest pseudo-rigid frequency), else "elastic".

    Parameters
    ----------
    freq_hz : Hz, the open-gap modes' frequencies
    labels : {label: (mode index, freq_hz, score)} from :func:`pseudo_rigid`

    Returns
    -------
    list of str, one per mode

    Examples
    --------
    >>> mode_classes([0.4, 11.0, 20.0, 900.0], {"bounce": (2, 20.0, 0.9), "roll": (1, 11.0, 0.8)})
    ['bungee', 'roll', 'bounce', 'elastic']
    """
    name_of = {v[0]: k for k, v in labels.items()}
    f_low = 0.5 * min((v[1] for v in labels.values()), default=0.0)
    return [name_of.get(k, "bungee" if f < f_low else "elastic") for k, f in enumerate(freq_hz)]


def level_summary(rig: VirtualRig, rec: Record, lm, labels: dict) -> dict:
    """Peak tip forces, impacts, when the gaps stay open, energy shares at the end, energy balance.

    Parameters
    ----------
    rig : the virtual rig
    rec : one level's record
    lm : the rig's open-gap linear modes (:func:`reduced.models.modes.linear_modes`)
    labels : the pseudo-rigid modes, from :func:`pseudo_rigid`

    Returns
    -------
    dict: ``level_N``, ``impacts`` (per tip load cell), ``impacts_total``, ``crossings_found``,
    ``peak_contact_N`` and ``peak_load_cell_N`` (per cell), ``gaps_open_after_s``,
    ``end_energy_J``, ``end_bungee_share``, ``end_modes`` (the three beam modes carrying most of
    the energy at the end), ``hammer_work_J`` (the integrator's), ``hammer_work_trapezoid_J``
    (from the hammer channel), ``energy_balance_error``, ``wall_s``
    """
    imp = impacts(rig, rec)
    E_end = modal_energy_end(rig, rec, lm, END_SHARE_S)
    total = float(E_end.sum())
    kinds = mode_classes(lm.freq_hz, labels)
    bungee = float(sum(E for E, k in zip(E_end, kinds, strict=True) if k == "bungee"))
    beam = [k for k in np.argsort(E_end)[::-1] if kinds[k] != "bungee"][:3]
    rest = total - bungee
    names = list(rig.names)
    hammer = rec.data[names.index("hammer")]
    # the hammer's work from its own channel: int p d.u'(X) dt, with d.u'(X) = b^T q' (trapezoid)
    work = float(np.trapezoid(hammer * (rec.v @ rig.b), rec.t))
    last = [v["last_contact_s"] for v in imp.values() if not math.isnan(v["last_contact_s"])]
    return {
        "level_N": rec.level_N,
        "impacts": {k: v["impacts"] for k, v in imp.items()},
        "impacts_total": int(sum(v["impacts"] for v in imp.values())),
        "crossings_found": int(rec.stats.get("n_events", -1)),
        "peak_contact_N": {k: v["peak_contact_N"] for k, v in imp.items()},
        "peak_load_cell_N": {c: float(np.max(np.abs(rec.data[names.index(c)]))) for c in TIP_CELLS},
        "gaps_open_after_s": max(last) if last else 0.0,
        "end_energy_J": total,
        "end_bungee_share": bungee / total if total > 0 else 0.0,
        "end_modes": [{"mode": int(k + 1), "freq_hz": float(lm.freq_hz[k]), "label": kinds[k],
                       "share": float(E_end[k] / rest) if rest > 0 else 0.0} for k in beam],
        "hammer_work_J": float(rec.external[-1]),
        "hammer_work_trapezoid_J": work,
        "energy_balance_error": rec.balance_error,
        "wall_s": rec.stats.get("wall_s"),
    }


# -- the stage ------------------------------------------------------------------------------
def compute(scene: Scene, progress: bool, workdir: Path | None = None, test_file: str | None = None,
            window: str | None = None, measures: str | None = None) -> VirtualTest | Comparison:
    """Run the virtual test: every level, the backbones, the linear check; or compare a measured test.

    Parameters
    ----------
    scene : a scene with [hammer], [ringdown] and a reduced assembly model
    progress : show progress bars and what is being built
    workdir : the stage's scratch folder (unused: nothing is streamed to disk)
    test_file : a measured test (UFF 58): the model is run at its sampling, driven by its hammer
        channel, and compared with it instead of the virtual test
    window : ``"START:END"``, s, the window compared with the test (default [hammer] compare_window_s)
    measures : comma-separated measures of the comparison (default all:
        :data:`bearingshaft.measures.MEASURES`)

    Returns
    -------
    VirtualTest, or Comparison with ``test_file``
    """
    from reduced._blas import single_thread_blas
    from reduced.models.modes import linear_modes

    test = None
    if test_file is not None:  # the test file and the options are checked before the model is built
        options = (hammer_compare.parse_window(window), hammer_compare.parse_measures(measures))
        test = measured.read_test(scene, test_file)
    elif window is not None or measures is not None:
        raise SceneError("--window and --measures choose what a comparison with a test measures: give --test FILE.uff")
    with single_thread_blas():
        rom = scene.model.reduced(progress)
        rig = _rig(scene, rom)
        lm = linear_modes(rig.system, "open")
        labels = pseudo_rigid(rig, scene.model.fe_model().geometry(), lm)
        stats = {"n_dofs": rig.system.n, "location_m": list(rig.location), "direction": list(rig.direction),
                 "pseudo_rigid_hz": {k: v[1] for k, v in labels.items()}}
        if test is not None:
            return _compare(scene, rig, test, test_file, stats, *options)
        return _virtual_test(scene, rom, rig, lm, labels, stats, progress)


def _rig(scene: Scene, rom) -> VirtualRig:
    """The rig of ``rom`` struck at the scene's point (SceneError, one line, if it cannot be)."""
    spec = scene.hammer
    location = tuple(spec.location_m) if spec.location_m else default_location(rom)
    try:
        return virtual_rig(rom, location, spec.direction, spec.seismic_mass_kg)
    except ValueError as exc:
        raise SceneError(f"{scene.origin} [hammer]: {exc}") from None


def _virtual_test(scene: Scene, rom, rig: VirtualRig, lm, labels: dict, stats: dict, progress: bool) -> VirtualTest:
    """Every level's record, their summaries, the backbones and (if asked) the linear check."""
    spec = scene.hammer
    levels = sorted({*spec.levels_N, spec.peak_N})
    # the levels are independent pieces (on the job's cluster when there is one), in this order either way
    bar = progress_bar(total=len(levels), desc=f"{scene.name}: virtual tests", unit="level", enabled=progress)
    records = dict(zip(levels, fan_out(_level_record, [(rig, scene, level) for level in levels]), strict=True))
    bar.update(len(levels))
    bar.close()
    nominal = records[spec.peak_N]
    # with friction the sliders' states are not in the record, so a displaced run could not start 1e-9 from it:
    # no exponent (the report then says no horizon was measured)
    lyapunov = record_lyapunov(rig, blow(spec, spec.peak_N), scene, nominal) if rig.system.friction is None else []
    curves = backbones(rig, spec.backbone_modes, float(np.max(nominal.energy)))
    summary = {level: level_summary(rig, rec, lm, labels) for level, rec in records.items()}
    linear = _linear_check(scene, rom, rig, progress) if spec.linear_check else None
    if linear is not None:
        stats["linear_check"] = {"worst": linear.worst, "worst_channel": linear.worst_channel,
                                 "worst_raw": linear.worst_raw, "n_full_modes": linear.n_full_modes,
                                 "cond_V": linear.cond_V}
    stats.update({"levels": {str(k): v for k, v in summary.items()},
                  "wall_s": {str(k): r.stats.get("wall_s") for k, r in records.items()}})
    line = _summary_line(scene, rig, nominal, summary[spec.peak_N], linear)
    stats["lyapunov_exponent_per_s"] = [e.exponent_per_s for e in lyapunov]
    friction = None
    if rig.system.friction is not None:
        friction = friction_comparison(scene, rom, rig, nominal, lm, labels, summary[spec.peak_N])
        stats["friction"] = {"mu": friction.mu, "k_t": friction.k_t, "friction_work_J": friction.friction_work_J,
                             "impacts": list(friction.impacts), "frictionless_wall_s":
                                 friction.frictionless.stats.get("wall_s")}
    return VirtualTest(scene=scene, rig=rig, labels=labels, records=records, summary=summary, backbones=curves,
                       linear=linear, end_share_s=END_SHARE_S, stats=stats, lines=(line,), friction=friction,
                       lyapunov=tuple(lyapunov))


def _level_record(job: tuple) -> Record:
    """The record of one level: ``job = (rig, scene, level_N)``."""
    rig, scene, level = job
    return run_record(rig, blow(scene.hammer, level), scene, level)


def record_lyapunov(rig: VirtualRig, signal, scene: Scene, rec: Record, seeds: int = LYAPUNOV_SEEDS) -> list:
    """The largest Lyapunov exponent of a record's motion after the blow, from exact runs started
    ``LYAPUNOV_DELTA`` away.

    Once the hammer has let go (the first sample at or after the force's end, ``signal.end_s``) the
    rig moves freely: each displaced run starts there, LYAPUNOV_DELTA (relative, energy norm) from the
    record's state, and is run without force on the record's samples by the same integrator; the
    separation of its state from the record's is fitted
    (:class:`reduced.transient.compare.LyapunovAccumulator`). (From the start, at rest, the separation
    would be measured against a state of zero norm.)

    Parameters
    ----------
    rig : the virtual rig
    signal : the hammer's force p(t), N (its ``end_s``: when it lets go)
    scene : the scene ([ringdown]: integrator and options)
    rec : the record (its exact states at its samples)
    seeds : displaced runs (directions 0 .. seeds - 1)

    Returns
    -------
    list of LyapunovEstimate, one per seed (none when the force lasts the whole record)
    """
    from reduced.transient.compare import LyapunovAccumulator, aligned, displaced_state
    from reduced.transient.integrate import ringdown_stream
    from reduced.transient.store import Chunk

    system, rd = rig.system, scene.ringdown
    fs = 1.0 / float(rec.t[1] - rec.t[0])
    k0 = int(np.searchsorted(rec.t, float(signal.end_s) - 0.5 / fs))
    if k0 >= len(rec.t) - 2 or not (np.any(rec.x[k0]) or np.any(rec.v[k0])):
        return []
    n = len(rec.t) - k0
    after = [Chunk(0, rec.t[k0:] - rec.t[k0], rec.x[k0:], rec.v[k0:], rec.dissipated[k0:], system)]
    out = []
    for k in range(seeds):
        x, v = displaced_state(system, rec.x[k0], rec.v[k0], LYAPUNOV_DELTA, k)
        run = ringdown_stream(system, x, v, (n - 1) / fs, fs, rd.method, **solver_options(rd))
        acc = LyapunovAccumulator(system, n, fs, LYAPUNOV_DELTA, LYAPUNOV_SATURATION, LYAPUNOV_WINDOW_S)
        try:
            for a, b in aligned(after, run):
                if not acc.feed(a, b):
                    break
        finally:
            run.close()
        out.append(acc.result())
    return out


def motion_decay(rig: VirtualRig, rec: Record, lm, labels: dict, after_s: float, open_after_s: float = 0.0) -> dict:
    """How each pseudo-rigid motion's energy decays in a record: its open-gap mode's energy
    E_r = (eta_r'^2 + omega_r^2 eta_r^2) / 2, eta_r = phi_r^T M q (mass-normalised modes).

    Once the gaps stay open the motion is linear and each lightly damped mode's energy falls as
    exp(-rate t), rate = phi_r^T C phi_r (= 2 zeta_r omega_r, the closed form; exact for modal damping,
    to first order in the damping when the dashpots couple the modes): ``rate_per_s`` is the least-squares
    slope of -ln E_r over the record from ``open_after_s`` (or the blow's end if later) to its end, and
    ``t_1pct_est_s`` the 1 % time, measured when the record reaches it, else extrapolated along that slope
    (the motions friction leaves alone decay for tens of seconds on the modal damping alone: hammer-friction-oblique's
    lateral mode, 2 zeta omega = 0.149 /s, reaches 1 % after 31 s).

    Parameters
    ----------
    rig : the rig that made ``rec``
    rec : a record
    lm : the rig's open-gap modes (:func:`reduced.models.modes.linear_modes`)
    labels : {label: (mode index, freq_hz, score)} (:func:`pseudo_rigid`)
    after_s : s, the blow's end: the peak is taken after it
    open_after_s : s, the gaps stay open after this (``level_summary``'s ``gaps_open_after_s``)

    Returns
    -------
    dict {label: {"peak_J", "end_J" (mean over the last ``END_SHARE_S``), "t_1pct_s" (the time after which it
    stays below ``DECAY_FLOOR`` of its peak; NaN if it does not by the record's end), "rate_per_s" (the fitted
    decay rate once the gaps stay open), "rate_modal_per_s" (phi_r^T C phi_r), "t_1pct_est_s" (t_1pct_s, or
    extrapolated along rate_per_s; NaN if that does not decay), "energy_J" (the record's E_r, for the figure)}}
    """
    M, C = rig.system.M, rig.system.C
    after = rec.t >= after_s
    end = rec.t >= rec.t[-1] - END_SHARE_S
    tail = (rec.t >= max(after_s, open_after_s)) & (rec.t > rec.t[0])
    out = {}
    for label, (i, _, _) in labels.items():
        mphi = M @ lm.phi[:, i]
        E = 0.5 * ((rec.v @ mphi) ** 2 + (lm.omega[i] * (rec.x @ mphi)) ** 2)
        peak = float(E[after].max())
        above = np.flatnonzero(E > DECAY_FLOOR * peak)
        t_low = float(rec.t[above[-1] + 1]) if above.size and above[-1] + 1 < rec.t.size else math.nan
        fit = tail & (E > 0.0)
        rate, t_est = math.nan, t_low
        if np.count_nonzero(fit) > 2 and peak > 0.0:
            slope, icpt = np.polyfit(rec.t[fit], np.log(E[fit]), 1)
            rate = float(-slope)
            if math.isnan(t_low) and rate > 0.0:
                t_est = float((icpt - math.log(DECAY_FLOOR * peak)) / rate)
        out[label] = {"peak_J": peak, "end_J": float(E[end].mean()), "t_1pct_s": t_low, "rate_per_s": rate,
                      "rate_modal_per_s": float(lm.phi[:, i] @ C @ lm.phi[:, i]), "t_1pct_est_s": t_est,
                      "energy_J": E}
    return out


def _band_power(rig: VirtualRig, rec: Record, channel: str, after_s: float, split_hz: float) -> tuple[float, float]:
    """(power below split_hz, above) of one channel after the blow (periodogram sums)."""
    x = rec.data[list(rig.names).index(channel), rec.t >= after_s]
    spec = np.abs(np.fft.rfft(x - x.mean())) ** 2
    f = np.fft.rfftfreq(x.size, float(rec.t[1] - rec.t[0]))
    return float(spec[f < split_hz].sum()), float(spec[f >= split_hz].sum())


def friction_comparison(scene: Scene, rom, rig: VirtualRig, rec: Record, lm, labels: dict,
                        summary: dict) -> FrictionComparison:
    """The nominal blow again without friction (mu = 0 on the same reduction and rig), beside ``rec``: how
    fast the pseudo-rigid motions decay, the friction work per impact, how the spectrogram's channel changes.

    Parameters
    ----------
    scene : the scene (its model with mu > 0)
    rom : its reduced model (with the tangential coordinates)
    rig : the rig with friction
    rec : the nominal blow's record with friction
    lm, labels : the rig's open-gap modes and pseudo-rigid labels (the same without friction: same M, K)
    summary : ``rec``'s :func:`level_summary`

    Returns
    -------
    FrictionComparison
    """
    spec = scene.hammer
    plain = virtual_rig(rom.with_contact(replace(scene.model, mu=0.0)), rig.location, rig.direction,
                        rig.seismic_mass_kg)
    other = run_record(plain, blow(spec, spec.peak_N), scene, spec.peak_N)
    other_summary = level_summary(plain, other, lm, labels)
    after = spec.start_s + spec.duration_s
    with_f = motion_decay(rig, rec, lm, labels, after, summary["gaps_open_after_s"])
    without = motion_decay(plain, other, lm, labels, after, other_summary["gaps_open_after_s"])
    decay = {k: {"freq_hz": labels[k][1], "with": with_f[k], "without": without[k]} for k in labels}
    channel = scene.spectrogram.dof if scene.spectrogram is not None else "beam_s3:z"
    pw, pwo = _band_power(rig, rec, channel, after, LABEL_MAX_HZ), _band_power(plain, other, channel, after,
                                                                              LABEL_MAX_HZ)
    bands = {f"below {LABEL_MAX_HZ:g} Hz": (pw[0], pwo[0]), f"above {LABEL_MAX_HZ:g} Hz": (pw[1], pwo[1])}
    fr = rig.system.friction
    return FrictionComparison(mu=float(fr.mu.max()), k_t=float(fr.k_t.max()), directions=rom.friction_directions,
                              frictionless=other, decay=decay,
                              gaps_open_after_s=(float(summary["gaps_open_after_s"]),
                                                 float(other_summary["gaps_open_after_s"])),
                              impacts=(int(summary["impacts_total"]), int(other_summary["impacts_total"])),
                              friction_work_J=float(rec.friction[-1]), hammer_work_J=float(rec.external[-1]),
                              spectrum_change=bands)


def _linear_check(scene: Scene, rom, rig: VirtualRig, progress: bool) -> LinearCheck:
    """The nominal half-sine on the rig with gaps too large to close, against the full 3-D model."""
    spec = scene.hammer
    level = spec.peak_N
    open_rig = virtual_rig(replace(rom, gap=OPEN_GAP_M), rig.location, rig.direction, rig.seismic_mass_kg)
    rec = run_record(open_rig, HalfSine(level, spec.duration_s, spec.start_s), scene, level)
    return hammer_linear.linear_check(scene, rig, rec, progress)


def _compare(scene: Scene, rig: VirtualRig, test, test_file: str, stats: dict, window_s, wanted) -> Comparison:
    """The model at a measured test's sampling, driven by its hammer channel (force-windowed), compared."""
    spec = scene.hammer
    rec = run_record(rig, test.signal, scene, test.level_N, duration_s=test.duration_s,
                     sample_rate_hz=test.sample_rate_hz)
    curves = []
    if "backbone" in wanted and spec.backbone_modes:
        i = int(np.searchsorted(rec.t, test.free_after_s))
        curves = channel_backbones(rig, spec.backbone_modes, float(np.max(rec.energy[i:])), test.sample_rate_hz,
                                   list(spec.compare) or None)
    return hammer_compare.compare(scene, rig, rec, test, test_file, {**stats, **_run_stats(rec)}, window_s=window_s,
                                  wanted=wanted, backbones=curves)


def _run_stats(rec: Record) -> dict:
    keep = ("wall_s", "n_events", "n_breakpoints", "oversample")
    return {f"model_{k}": rec.stats[k] for k in keep if k in rec.stats}


def _summary_line(scene: Scene, rig: VirtualRig, rec: Record, s: dict, linear: LinearCheck | None) -> str:
    text = (f"[{scene.name}] virtual hammer test: {len(rig.channels)} channels, {rec.level_N:g} N blow: "
            f"{s['impacts_total']} impacts, peak tip force {max(s['peak_contact_N'].values()):.4g} N, gaps open after "
            f"{s['gaps_open_after_s']:.4g} s; balance {s['energy_balance_error']:.1e}")
    if linear is not None:
        text += f"; linear check worst {100 * linear.worst:.3g} % RMS ({linear.worst_channel})"
    return text




# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Strike the reduced apparatus with the scene's blow at every level and record every rig channel
as a test's DAQ would (six triaxial beam accelerometers, four triaxial tube sensors, four tip
load cells, the hammer). Writes hammer.npz, hammer.uff (UFF 58), channels.csv, fig10.png,
fig11.png, levels.csv, levels.png, hammer.md, lyapunov.csv (the record's largest Lyapunov
exponent) and, with [hammer] linear_check, linear_check.csv
and linear_check.png. With --test FILE.uff, instead, a measured test drives the model by its
hammer channel (through a force window) at the test's sampling and every channel is compared:
where chaos starts (the predictability horizon, from two exact runs of the model and its largest
Lyapunov exponent), the pointwise errors up to it, and past it what survives chaos (spectrogram
ridges, RMS envelope, impacts, the open-gap time, backbones of the free decay over the model's
NNM backbones); --window START:END and --measures LIST choose what. Writes test_errors.csv,
test_measures.csv, test_horizon.csv, test_compare.md, test_compare.png, test_spectrogram.png,
test_horizon.png, test_measures.png, test_backbone.png and model.uff (the model's channels, UFF 58).
With friction at the tips ([model] mu > 0), the nominal blow is run again with mu = 0 on the same reduction:
friction.csv and friction.png (how the longitudinal, lateral and yaw motions decay, the spectrogram with and
without) and a section of hammer.md (friction work per impact)."""


def estimate(scene: Scene) -> list[Estimate]:
    """Every level's record in memory: state, channels, energies; the exact integrator's table.

    Parameters
    ----------
    scene : a scene with [hammer] and [ringdown]

    Returns
    -------
    list of one Estimate, the stage's peak memory
    """
    from fem.rig import channel_names

    n = n_dofs(scene)
    r, h = scene.ringdown, scene.hammer
    samples = r.duration_s * r.sample_rate_hz + 1
    levels = len({*h.levels_N, h.peak_N}) + int(h.linear_check)
    per = (2 * n + len(channel_names()) + 4) * FLOAT
    exact = 3 * 2**4 * (2 * n) ** 2 * 16  # the exact integrator's state table (4 stops)
    p = sliders(scene)
    if p:  # with friction, tables for the friction states the records enter: of 1 + 2 3^d a tip (open, or a stop
        states = (1 + 2 * 3 ** (p // 4)) ** 2  # closed with its d sliders each sticking or slipping either way)
        N = 2 * n + p  # [x; v; w]
        # a built state holds V, V^-1 (complex), the friction power's form, its stiffness (40 N^2 + 8 n^2 bytes)
        # and its terms (U^T, U^-1, |U^-1|, two work tables: ~36 N^2 with ~N/2 terms kept). The states built
        # (those entered for an instant are passed through without tables, reduced.transient.friction_probe):
        # 4.2 % of them in the first record, 1.5 % more a further level (hammer-friction's 200, 500 and 1000 N
        # records built 15, 24 and 26 of 361 in all); x 2.7 and each level's record held twice (the run with
        # sliders and its histories): calibrated on hammer-friction (3 levels, 1660 MiB measured, estimate
        # 1.15 x) and hammer-friction-oblique (1 level, 1230 MiB, 1.13 x)
        built = min(states, (0.042 + 0.015 * (levels - 1)) * states)
        exact += 2.7 * built * (76 * N**2 + 8 * n**2)
        levels *= 2
    return [Estimate("hammer", int(MATPLOTLIB_BYTES + COPIES * samples * per + levels * samples * per + exact),
                     f"{levels} records of {samples:.3g} samples x {n} DOFs",
                     "[ringdown] duration_s or sample_rate_hz, or [hammer] levels_N"
                     + (", or [model] n_modes" if hasattr(scene.model, "element_size") else ""))]  # rom: n ~ modes


__all__ = ["compute", "estimate", "DESCRIPTION", "run_record", "blow", "Record", "pseudo_rigid",
           "coupled_subsystem", "default_location", "impacts", "modal_energy_end", "backbones", "level_summary",
           "channel_backbones"]


# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
IMPACTING = "of the impacting record, a chaotic motion"
REPRODUCTION = Reproduction(lyapunov=("lyapunov.csv",), rules=(
    record("hammer.uff", "not committed (.gitignore): the channels of hammer.npz"),
    roundoff("levels.csv", "energy_balance_error"),
    chaotic("levels.csv", "impacts*", "peak_contact_*", "gaps_open_after_s", "end_*",
            why=f"impacts, peak tip forces, when the gaps stay open and where the energy ends {IMPACTING}"),
    chaotic("hammer.md", r"^- (Impacts|Peak contact forces|The gaps stay open|Peak load-cell|Energy in the last|Chaos)",
            r"^\| [0-9.]+ \| [0-9]+ \| ",
            why=f"impacts, peak tip forces, when the gaps stay open and where the energy ends {IMPACTING}"),
    exact("lyapunov.csv", "seed", "delta", "saturation", "window_s"),
    chaotic("lyapunov.csv", why="Lyapunov exponents fitted to the separation of chaotic records 1e-9 apart"),
    # with friction at the tips (friction.csv, hammer.md's friction section): both records impact
    # the decay rates and the 1 % times estimated from them are fitted to the chaotic records too: a change of
    # round-off in the friction tables (one factorization of K_s for all sliders) moved t_1pct_est_s 14.6 -> 7.5 s
    chaotic("friction.csv", "peak_J_*", "end_J_*", "t_1pct_s_*", "rate_per_s_*", "t_1pct_est_s_*",
            why=f"energies, decay rates and decay times {IMPACTING}"),
    chaotic("hammer.md", r"^The nominal blow again with mu = 0", r"^\| [a-z]+ \| [0-9.]+ \| [0-9.e+-]+ / ",
            r"^The spectrogram's channel after the blow", r"^The gaps stay open after",
            why=f"impacts, friction work, energies and decay times with and without friction {IMPACTING}"),
))
