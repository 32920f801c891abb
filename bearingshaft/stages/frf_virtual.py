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


def _modal_start(rigs: list[VirtualRig], mm: ModalModel, phi: np.ndarray, t: np.ndarray, duration_s: float,
                 start_s: float):
    """The outputs during the blow at the times ``t`` inside it, and the free decay's rows and amplitudes.

    Returns (rows_acc, rows_gap, W_acc, W_gap, pulses, cs, poles): for each rig, pulses[k] =
    (acc, gap) at every time of ``t`` (zero before the blow, filled inside it) and cs[k] = V^-1 z(t1).
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
    W_acc = (rows_acc @ E) @ p.V[n:] * p.lam[None]
    W_gap = (rows_gap @ E) @ p.V[:n]
    pulses, cs = [], []
    for rig in rigs:
        b = phi.T @ rig.b
        acc = np.zeros((na, t.size))
        gap = np.zeros((ng, t.size))
        if during.any():
            r = mm.half_sine_response(t[during], b, np.vstack([rows_acc, rows_gap]), 1.0, duration_s, start_s)
            acc[:, during] = r.acceleration[:na]
            gap[:, during] = r.displacement[na:]
        end = mm.half_sine_response(np.array([t1]), b, np.eye(b.size), 1.0, duration_s, start_s)
        cs.append(p.V_inv @ np.concatenate([E.T @ end.displacement[:, 0], E.T @ end.velocity[:, 0]]))
        pulses.append((acc, gap))
    return W_acc, W_gap, pulses, cs, p


def _channels(rig: VirtualRig, acc: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The rig's channels from its accelerometer and seat accelerations: tip cells -+ m_a a_seat, the hammer last."""
    n_acc = rig.acc_rows.shape[0]
    sign = np.array([1.0 if cell.endswith("top") else -1.0 for cell in TIP_CELLS])[:, None]
    cells = -sign * rig.seismic_mass_kg * acc[n_acc:]  # f_c = 0: the gaps are open
    return np.vstack([acc[:n_acc], cells, np.broadcast_to(force, (1, acc.shape[1]))])


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
    W_acc, W_gap, pulses, cs, p = _modal_start(rigs, mm, phi, t, duration_s, start_s)
    na = W_acc.shape[0]
    t1 = start_s + duration_s
    after = np.flatnonzero(t >= t1)
    if after.size:
        dt = float(t[1] - t[0]) if t.size > 1 else 0.0
        rows = np.vstack([np.vstack([W_acc, W_gap]) * c[None] for c in cs])
        decay = _free_decay(rows, p.lam, float(t[after[0]] - t1), dt, after.size)
    a = math.pi / duration_s
    during = (t >= start_s) & (t < t1)
    force = np.where(during, np.sin(a * np.where(during, t - start_s, 0.0)), 0.0)
    out = []
    for k, (rig, (acc, gap)) in enumerate(zip(rigs, pulses, strict=True)):
        if after.size:
            block = decay[k * (na + W_gap.shape[0]):(k + 1) * (na + W_gap.shape[0])]
            acc[:, after], gap[:, after] = block[:na], block[na:]
        out.append((_channels(rig, acc, force[None]), rig.system.side[:, None] * gap))
    return out


def recorded_unit_blows(rigs: list[VirtualRig], mm: ModalModel, phi: np.ndarray, acq, n_out: int,
                        duration_s: float, start_s: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The channels of :func:`unit_blows` as the DAQ records them, and each stop's largest penetration.

    The same as ``acq.acquire`` of :func:`unit_blows` at the fine rate, computed at the record's
    rate where it can be: once the anti-alias filter (taps h, half length D, fine step delta)
    sees only the free decay, a pole's filtered output is the pole's own times the filter's
    response to it, H_f(lambda) = sum_j h[j] exp(lambda (D - j) delta), so those samples are the
    free decay with amplitudes scaled by H_f, at the record's times (half the work, no filtering).
    The penetration is checked at the fine samples up to there and at the record's after.

    Parameters
    ----------
    rigs, mm, phi : as :func:`unit_blows`
    acq : reduced.models.daq.Acquisition, the DAQ
    n_out : samples of the record
    duration_s, start_s : s, the half-sine's length and start

    Returns
    -------
    list of (channels (n_channels, n_out) per N, largest penetration (n_stops,) m per N), one per rig
    """
    q, h = acq.oversample, acq.taps()
    D = (len(h) - 1) // 2
    delta = 1.0 / acq.fine_rate_hz
    t1 = start_s + duration_s
    n1 = math.ceil(t1 / delta - 1e-9)  # first fine sample of the free decay
    k0 = min(n_out, math.ceil((n1 + D) / q))  # first record sample whose filter sees only the free decay
    head = unit_blows(rigs, mm, phi, np.arange(q * max(k0 - 1, 0) + 1 + D) * delta, duration_s, start_s)
    out = [(np.zeros((ch.shape[0], n_out)), pen.max(axis=1)) for ch, pen in head]
    for (rec, _pen), (ch, _p) in zip(out, head, strict=True):
        rec[:, :k0] = acq.acquire(ch, k0) if k0 else rec[:, :0]
    if k0 < n_out:
        W_acc, W_gap, _pulses, cs, p = _modal_start(rigs, mm, phi, np.zeros(0), duration_s, start_s)
        Hf = np.exp(np.outer(p.lam, (D - np.arange(len(h))) * delta)) @ h
        rows = np.vstack([np.vstack([W_acc * Hf[None], W_gap]) * c[None] for c in cs])
        tail = _free_decay(rows, p.lam, k0 / acq.sample_rate_hz - t1, 1.0 / acq.sample_rate_hz, n_out - k0)
        na, ng = W_acc.shape[0], W_gap.shape[0]
        for k, (rig, (rec, pen)) in enumerate(zip(rigs, out, strict=True)):
            block = tail[k * (na + ng):(k + 1) * (na + ng)]
            rec[:, k0:] = _channels(rig, block[:na], np.zeros((1, 1)))
            pen[:] = np.maximum(pen, (rig.system.side[:, None] * block[na:]).max(axis=1))
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
    rng = np.random.default_rng(spec.seed)
    n_ref = len(rigs)
    peaks = spec.peak_N * (1.0 + spec.peak_spread * rng.uniform(-1.0, 1.0, size=(n_ref, spec.blows)))
    force, resp, ref, closest = [], [], [], -math.inf
    recorded = recorded_unit_blows(rigs, mm, lm.phi, acq, n_out, h.duration_s, h.start_s)
    for k, (rec, pen) in enumerate(recorded):  # rec: (n_channels, N) per N of peak
        worst = float(np.max(peaks[k].max() * pen - system.offset * system.side))
        closest = max(closest, worst)
        if worst > 0:
            raise SceneError(f"{scene.origin} [frf] peak_N: a {peaks[k].max():.3g} N blow at reference {k + 1} "
                             f"closes a gap (by {worst:.3g} m); FRFs need the gaps open: lower peak_N")
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


__all__ = ["virtual_blows", "unit_blows", "recorded_unit_blows", "references", "default_references"]
