"""The frf stage's virtual hammer test: repeated blows on the reduced apparatus with its gaps open.

At a level that leaves every gap open the rig is the linear system M q'' + C q' + K q = b p(t)
(no stop force), so a half-sine blow's response is known in closed form and no integrator is
needed. In the rig's mass-normalised open-gap modes (q = Phi eta, Cm = Phi^T C Phi,
:class:`fem.modal_response.ModalModel`) with first-order poles lambda_k and eigenvectors V:

- during the blow (t0 <= t < t0 + d) the outputs are :meth:`ModalModel.half_sine_response`'s
  (the convolution with the pulse, exact);
- after it the state decays freely, z(t) = V diag(exp(lambda (t - t1))) V^-1 z(t1), t1 = t0 + d,
  so an output row r (on eta) is Re(sum_k (r V)_k c_k exp(lambda_k (t - t1))), c = V^-1 z(t1),
  summed over the poles with Im > 0 twice (conjugate pairs) and the real ones once;
  accelerations use eta'' = V_bottom (lambda c exp(..)).

The channels are those of :class:`reduced.models.rig.VirtualRig`: accelerometers R q'', tip
load cells -+ m_a times the seat's vertical acceleration (the stop force is zero while the
gap is open), the hammer's force. They are computed at q fs and acquired as a DAQ does
(:class:`reduced.models.daq.Acquisition`: the same linear-phase anti-alias filter on every
channel, the hammer's included, as a test lab records it, then decimated). The penetration
of every stop is computed at the fine samples: a blow that closes a gap is refused (one
line), since then the system is not linear and its FRFs are not what this stage estimates.

The rig is linear, so a blow of peak P is P times the unit blow's response: the blows of
one reference differ by their peak (``peak_spread``) and by independent noise (``noise``, a
fraction of each channel's RMS), as repeated blows of a test do.
"""

from __future__ import annotations

import math

import numpy as np

from bearingshaft.scenes import Scene, SceneError
from bearingshaft.stages.frf_results import Blows, Dof
from fem.modal_response import ModalModel
from fem.rig import HAMMER_NODE, TIP_CELLS, dominant_axis
from reduced.models.rig import VirtualRig, virtual_rig

CHUNK = 1 << 21  # complex (pole x time) entries per block of the free decay: 32 MB per temporary


def default_references(rom) -> tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]:
    """Three references that together excite the six pseudo-rigid modes: (location m, direction).

    On the beam's faces, read from the reduced model's mesh: the top face at (0.35 l, 0.3 b)
    struck down (bounce, pitch, roll), the -y side face at (0.35 l, 0.25 h) struck along +y
    (lateral, yaw, roll), the -x end face at (0.3 b, 0.25 h) struck along +x (longitudinal,
    pitch, yaw); l, b, h the beam's extent along x, y, z.

    Parameters
    ----------
    rom : a reduced assembly model built with its mesh

    Returns
    -------
    tuple of ((x, y, z), (dx, dy, dz))
    """
    pts, part = rom.mesh["points"], rom.mesh["cell_part"]
    nodes = np.unique(rom.mesh["hexes"][part == int(rom.mesh["beam_part"])])
    lo, hi = pts[nodes].min(axis=0), pts[nodes].max(axis=0)
    c, ext = 0.5 * (lo + hi), hi - lo
    return (((float(c[0] + 0.35 * ext[0]), float(c[1] + 0.3 * ext[1]), float(hi[2])), (0.0, 0.0, -1.0)),
            ((float(c[0] + 0.35 * ext[0]), float(lo[1]), float(c[2] + 0.25 * ext[2])), (0.0, 1.0, 0.0)),
            ((float(lo[0]), float(c[1] + 0.3 * ext[1]), float(c[2] + 0.25 * ext[2])), (1.0, 0.0, 0.0)))


def references(scene: Scene, rom) -> list[VirtualRig]:
    """The rig struck at each reference of [frf] (or :func:`default_references`); SceneError if one is off the beam.

    Parameters
    ----------
    scene : the scene ([frf] locations_m and directions, [hammer] seismic_mass_kg)
    rom : its reduced model

    Returns
    -------
    list of VirtualRig, one per reference
    """
    spec = scene.frf
    pairs = tuple(zip(spec.locations_m, spec.directions, strict=True)) or default_references(rom)
    rigs = []
    for k, (loc, d) in enumerate(pairs):
        try:
            rigs.append(virtual_rig(rom, loc, d, scene.hammer.seismic_mass_kg))
        except ValueError as exc:
            raise SceneError(f"{scene.origin} [frf] reference {k + 1}: {exc}") from None
    return rigs


def _free_decay(W: np.ndarray, lam: np.ndarray, tau0: float, dtau: float, nt: int) -> np.ndarray:
    """Re(sum_k W[:, k] exp(lam_k tau)) at tau = tau0 + j dtau, j < nt, (rows, nt).

    Conjugate pairs are summed once (the Im > 0 pole twice, real poles once). The exponentials
    of one block, exp(lam j dtau), are formed once and each block is scaled by exp(lam tau_start),
    so the work is a matrix product per block."""
    scale = np.pi * 1e-12 * np.abs(lam).max()
    weight = np.where(lam.imag > scale, 2.0, np.where(np.abs(lam.imag) <= scale, 1.0, 0.0))
    keep = weight > 0
    Wc, lk = W[:, keep] * weight[keep][None], lam[keep]
    step = min(nt, max(1, CHUNK // max(lk.size, 1)))
    base = np.exp(lk[:, None] * (dtau * np.arange(step))[None])  # (k, step)
    out = np.empty((W.shape[0], nt))
    for i in range(0, nt, step):
        m = min(step, nt - i)
        A = Wc * np.exp(lk * (tau0 + i * dtau))[None]
        out[:, i:i + m] = A.real @ base.real[:, :m] - A.imag @ base.imag[:, :m]
    return out


def unit_blows(rigs: list[VirtualRig], mm: ModalModel, phi: np.ndarray, t: np.ndarray, duration_s: float,
               start_s: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every channel of each rig (rig order, the hammer last) and every stop's penetration under a 1 N half-sine.

    Parameters
    ----------
    rigs : the rig struck at each reference (the same system, other load vectors)
    mm : the rig's open-gap modal model (omega, Phi^T C Phi)
    phi : (n, m) its mass-normalised modes
    t : (nt,) s, uniform (fine) sample times
    duration_s, start_s : s, the half-sine's length d and start t0

    Returns
    -------
    list of (channels, penetration), one per rig: channels (n_channels, nt) per N of peak force,
    penetration (n_stops, nt) m per N, side B q (the offsets not subtracted)
    """
    s = rigs[0].system
    rows_acc = np.vstack([rigs[0].acc_rows, rigs[0].seat_rows]) @ phi  # accelerations
    rows_gap = s.B @ phi  # displacements
    na, ng = rows_acc.shape[0], rows_gap.shape[0]
    p = mm.poles()
    if p.n_rigid:
        raise ValueError("the rig has free rigid-body modes: a blow would drift it; no FRF to estimate")
    n, E = p.elastic_basis.shape[1], p.elastic_basis
    t1 = start_s + duration_s
    during = (t >= start_s) & (t < t1)
    after = np.flatnonzero(t >= t1)
    W_acc = (rows_acc @ E) @ p.V[n:] * p.lam[None]
    W_gap = (rows_gap @ E) @ p.V[:n]
    blocks, pulses = [], []
    for rig in rigs:
        b = phi.T @ rig.b
        acc = np.zeros((na, t.size))
        gap = np.zeros((ng, t.size))
        if during.any():
            r = mm.half_sine_response(t[during], b, np.vstack([rows_acc, rows_gap]), 1.0, duration_s, start_s)
            acc[:, during] = r.acceleration[:na]
            gap[:, during] = r.displacement[na:]
        end = mm.half_sine_response(np.array([t1]), b, np.eye(b.size), 1.0, duration_s, start_s)
        c = p.V_inv @ np.concatenate([E.T @ end.displacement[:, 0], E.T @ end.velocity[:, 0]])
        blocks.append(np.vstack([W_acc, W_gap]) * c[None])
        pulses.append((acc, gap))
    if after.size:
        dt = float(t[1] - t[0]) if t.size > 1 else 0.0
        decay = _free_decay(np.vstack(blocks), p.lam, float(t[after[0]] - t1), dt, after.size)
    a = math.pi / duration_s
    force = np.where(during, np.sin(a * np.where(during, t - start_s, 0.0)), 0.0)
    sign = np.array([1.0 if cell.endswith("top") else -1.0 for cell in TIP_CELLS])[:, None]
    n_acc = rigs[0].acc_rows.shape[0]
    out = []
    for k, (rig, (acc, gap)) in enumerate(zip(rigs, pulses, strict=True)):
        if after.size:
            rows = decay[k * (na + ng):(k + 1) * (na + ng)]
            acc[:, after], gap[:, after] = rows[:na], rows[na:]
        cells = -sign * rig.seismic_mass_kg * acc[n_acc:]  # f_c = 0: the gaps are open
        out.append((np.vstack([acc[:n_acc], cells, force[None]]), s.side[:, None] * gap))
    return out


def virtual_blows(scene: Scene, rom, progress: bool = False) -> Blows:
    """The [frf] blows on the scene's rig: ``blows`` per reference, recorded as a DAQ does.

    Parameters
    ----------
    scene : a scene with [hammer] (half-sine length and start, seismic mass), [ringdown] (the
        record: sample_rate_hz, duration_s) and [frf] (blows, level, spread, noise, references)
    rom : the scene's reduced model
    progress : unused (the blows take about a second)

    Returns
    -------
    Blows

    Raises
    ------
    SceneError
        A reference off the beam, or blows that close a gap.
    """
    from reduced.models.daq import Acquisition, oversampling
    from reduced.models.modes import linear_modes
    from reduced.transient.result import sample_count

    spec, h, rd = scene.frf, scene.hammer, scene.ringdown
    rigs = references(scene, rom)
    system = rigs[0].system
    lm = linear_modes(system, "open")
    mm = ModalModel(lm.omega, lm.phi.T @ system.C @ lm.phi)
    fs = rd.sample_rate_hz
    n_out = sample_count(rd.duration_s, fs)
    acq = Acquisition(fs, oversampling(lm.freq_hz.max(), fs))
    q = acq.oversample
    t_fine = np.arange(q * (n_out - 1) + 1 + acq.tail_samples) / acq.fine_rate_hz
    rng = np.random.default_rng(spec.seed)
    n_ref = len(rigs)
    peaks = spec.peak_N * (1.0 + spec.peak_spread * rng.uniform(-1.0, 1.0, size=(n_ref, spec.blows)))
    force, resp, ref, closest = [], [], [], -math.inf
    for k, (unit, pen) in enumerate(unit_blows(rigs, mm, lm.phi, t_fine, h.duration_s, h.start_s)):
        gap = (system.offset * system.side)[None, :, None]  # m, each stop's clearance
        worst = float(np.max(peaks[k][:, None, None] * pen[None] - gap))
        closest = max(closest, worst)
        if worst > 0:
            raise SceneError(f"{scene.origin} [frf] peak_N: a {peaks[k].max():.3g} N blow at reference {k + 1} "
                             f"closes a gap (by {worst:.3g} m); FRFs need the gaps open: lower peak_N")
        rec = acq.acquire(unit, n_out)  # (n_channels, N) per N
        for P in peaks[k]:
            chans = P * rec
            if spec.noise > 0:
                rms = np.sqrt(np.mean(chans**2, axis=1, keepdims=True))
                chans = chans + spec.noise * rms * rng.standard_normal(chans.shape)
            force.append(chans[-1])
            resp.append(chans[:-1])
            ref.append(k)
    outputs = tuple(Dof(c.name, c.node, c.direction, c.quantity) for c in rigs[0].channels[:-1])
    refs = tuple(Dof(f"hammer_{k + 1}", HAMMER_NODE + k + 1, dominant_axis(r.direction), "force")
                 for k, r in enumerate(rigs))
    info = {"peaks_N": peaks.round(6).tolist(), "noise": spec.noise, "seed": spec.seed,
            "references": [{"location_m": list(r.location), "direction": list(r.direction)} for r in rigs],
            "closest_gap_m": -closest, "acquisition": acq.describe(), "oversample": q,
            "model": f"reduced rig, {system.n} DOFs, open gaps: closed-form response (no integrator)"}
    return Blows(sample_rate_hz=fs, force=np.array(force), responses=np.array(resp), reference=np.array(ref),
                 outputs=outputs, references=refs, source=f"virtual test ({n_ref} references x {spec.blows} blows, "
                 f"{spec.peak_N:g} N +-{100 * spec.peak_spread:g} %, noise {100 * spec.noise:g} % of RMS)", info=info)


__all__ = ["virtual_blows", "unit_blows", "references", "default_references"]
