"""The hammer stage's linear check: the reduced rig with open gaps against the full 3-D model.

The full 3-D model's response to the scene's half-sine blow is its modal superposition in
closed form (:func:`full_reference`), on the rig's channels but the hammer, acquired as the
rig's are; the reduced rig's record of the same blow with gaps too large to close is compared
with it channel for channel (:func:`linear_check`), both low-passed alike (:func:`band_limited`)
and raw, by :func:`rms_errors`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearingshaft.scenes import Scene
from bearingshaft.stages.hammer_results import LinearCheck, Record
from fem.rig import TIP_CELLS
from reduced.models.rig import VirtualRig
from reduced.models.rom import modal_ratios

BAND_HZ = 2000.0  # Hz, the band of the comparisons: both signals low-passed alike (zero phase)
CHECK_WINDOW_S = 0.05  # s, the linear check's window after the blow (as the mode-count study's)
NEAR_ZERO = 0.01  # an accelerometer axis below this share of its sensor's largest is judged against that one
LINEAR_CHECK_MAX = 0.01  # the bound: 1 % RMS per channel


def band_limited(y: np.ndarray, sample_rate_hz: float, band_hz: float = BAND_HZ) -> np.ndarray:
    """y low-passed at ``band_hz`` (8th-order Butterworth run forward and back: zero phase), along the
    last axis; y itself when the band reaches the Nyquist frequency.

    Parameters
    ----------
    y : (..., N) samples
    sample_rate_hz : Hz, their rate
    band_hz : Hz, the filter's corner

    Returns
    -------
    ndarray, the same shape as ``y``
    """
    from scipy.signal import butter, sosfiltfilt

    if band_hz >= 0.5 * sample_rate_hz:
        return y
    return sosfiltfilt(butter(8, band_hz, fs=sample_rate_hz, output="sos"), y, axis=-1)


FULL_MODES_FIRST = 24  # full_modes asks for this many modes first, then doubles the count
FULL_MODES_SHIFT_HZ = 0.1  # Hz, its shift (below the assembly's bungee modes)


def full_modes(fe, max_hz: float, progress: bool):
    """The full 3-D model's open-gap modes up to ``max_hz`` (at least one above it), shift-invert Lanczos,
    kept in the reduced-model cache (``fullmodes-<key>.npz``, :func:`_full_modes_key`).

    A loaded entry holds the frequencies and shapes the search below returns, bit for bit (ARPACK's start
    vector is seeded and SuperLU single-threaded); the search costs 4 factorizations and 4 eigensolutions of
    the 15,087-DOF hammer-test model (24, 48, 96, 192 modes), about half the hammer stage's CPU: measured
    (2026-11-27, load 8-10 on 2 cores) 62-64 s of CPU for the stage solving them, 28-29 s loading them.

    Parameters
    ----------
    fe : the assembled full model (:func:`fem.model.build_system`)
    max_hz : Hz, the highest frequency wanted
    progress : print the number of modes asked for at each try

    Returns
    -------
    fem.modal.ModalResult with its lowest 24, 48, ... modes, the first count whose top passes
    ``max_hz`` (or a quarter of the DOFs); only ``freq_hz``, ``omega2`` and ``phi`` are kept in the
    cache, so only they are set (``n_op`` is -1), whether solved or loaded
    """
    from fem.modal import ModalResult
    from reduced.cache import cached_arrays
    from reduced.models.rom import cache_dir

    solved = False

    def solve() -> dict:
        nonlocal solved
        solved = True
        res = _search_full_modes(fe, max_hz, progress)
        return {"freq_hz": res.freq_hz, "omega2": res.omega2, "phi": res.phi}

    key = _full_modes_key(fe, max_hz)
    z = cached_arrays(cache_dir() / f"fullmodes-{key[:20]}.npz", key, solve,
                      info={"kind": "full model's modes of the hammer linear check", "max_hz": max_hz})
    if progress and not solved:
        print(f"  full 3-D modes: the lowest {z['freq_hz'].size} (cached)", flush=True)
    return ModalResult(freq_hz=z["freq_hz"], phi=z["phi"], omega2=z["omega2"], solver="superlu/lanczos",
                       shift_hz=FULL_MODES_SHIFT_HZ, n_op=-1, n_iter=0)


def _search_full_modes(fe, max_hz: float, progress: bool):
    """:func:`full_modes` solved: 24, 48, ... modes until the top passes ``max_hz``."""
    from fem.modal import modal_analysis

    k = FULL_MODES_FIRST
    while True:
        if progress:
            print(f"  full 3-D modes: the lowest {k}", flush=True)
        res = modal_analysis(fe.K, fe.M, n_modes=k, shift_hz=FULL_MODES_SHIFT_HZ, method="lanczos",
                             solver="superlu")
        if res.freq_hz[-1] > max_hz or k >= fe.n_dofs // 4:
            return res
        k *= 2


def _full_modes_key(fe, max_hz: float) -> str:
    """sha256 (hex) of what :func:`full_modes` depends on: K, M, ``max_hz``, the search's start, shift and
    solver, and the code that builds and solves the model (:func:`reduced.models.rom.source_hash`)."""
    import hashlib

    from reduced.cache import hash_sparse
    from reduced.models.rom import source_hash

    h = hashlib.sha256(f"full_modes {max_hz!r} {FULL_MODES_FIRST} {FULL_MODES_SHIFT_HZ!r} superlu lanczos "
                       f"{source_hash()}".encode())
    hash_sparse(h, fe.K, fe.M)
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class FullReference:
    """The full 3-D model's open-gap response to a blow, on the rig's channels but the hammer.

    Attributes
    ----------
    names : list of str
        Accelerometer axes, then ``TIP_CELLS`` (their seismic inertia only: the gaps never close).
    data : (len(names), N) ndarray of float
        m/s^2 and N, acquired at the scene's rate as the rig's channels.
    n_dofs : int
        DOFs of the full model.
    n_modes : int
        Its modes in the superposition.
    top_hz : float
        Hz, the highest of them.
    cond_V : float
        Condition number of the damped modal basis.
    """

    names: list[str]  # accelerometer axes, then TIP_CELLS (their seismic inertia only: the gaps never close)
    data: np.ndarray  # (len(names), N) acquired at the scene's rate, as the rig's channels
    n_dofs: int
    n_modes: int
    top_hz: float
    cond_V: float


def full_reference(scene: Scene, rig: VirtualRig, level_N: float, n_out: int, progress: bool) -> FullReference:
    """The full 3-D model's response to the scene's half-sine blow of peak ``level_N`` at the rig's
    location and direction, on ``n_out`` samples at [ringdown]'s rate, by modal superposition.

    Its modes up to ``[hammer] linear_check_max_hz`` with the same damping (the dashpots
    c_points at x1, x2, x3 and alpha M projected on the modes, plus the modal damping zeta_r of
    :func:`reduced.models.rom.damping_matrix`: Cm = c Phi^T P^T P Phi + alpha I + diag(2 zeta_r omega_r),
    not diagonal), in closed form from the pole-residue FRF (:class:`fem.modal_response.ModalModel`),
    acquired through the same anti-alias filter as the rig's channels (:mod:`reduced.models.daq`:
    computed at q fs with q from the top mode, so no mode above fs/2 folds into the band).

    Parameters
    ----------
    scene : the scene ([model], [hammer], [ringdown])
    rig : the reduced rig: where the blow lands, its direction, its channels and seismic mass
    level_N : N, the blow's peak
    n_out : samples of the record, from t = 0 at [ringdown] sample_rate_hz
    progress : print what is being built

    Returns
    -------
    FullReference
    """
    from fem.contact import point_rows
    from fem.modal_response import ModalModel
    from fem.model import build_system
    from fem.rig import point_load_vector, seat_rows, sensor_rows
    from reduced.models.daq import Acquisition, oversampling
    from reduced.models.mesh_cache import cached_mesh

    spec, model = scene.hammer, scene.model
    if progress:
        print(f"[{scene.name}] linear check: building the full 3-D model", flush=True)
    fem_model = model.fe_model()
    fe = build_system(fem_model, mesh=cached_mesh(fem_model.geometry()))  # the mesh gmsh gives, cached
    modes = full_modes(fe, spec.linear_check_max_hz, progress)
    keep = modes.freq_hz <= spec.linear_check_max_hz
    phi, omega = modes.phi[:, keep], 2 * np.pi * modes.freq_hz[keep]
    Pr = np.vstack(list(point_rows(fe).values())) @ phi  # (3, m): x1, x2, x3 on the modes
    Cm = model.c_points * Pr.T @ Pr + model.alpha * np.eye(phi.shape[1])
    Cm += np.diag(2.0 * modal_ratios(model.modal_damping, omega.size) * omega)  # the reduced model's modal damping
    b_full = point_load_vector(fe.mesh.points, fe.mesh.hexes, fe.solid.element, fe.mesh.cell_part,
                               fe.mesh.part_names.index("beam"), rig.location, rig.direction, fe.n_dofs)
    b_modal = np.asarray(b_full @ phi).ravel()
    acc = sensor_rows(fe, ("beam", "tube"))
    names = [c.name for c in rig.channels if c.kind == "accelerometer"]
    R = np.vstack([phi[acc[n]] for n in names] + [r @ phi for r in seat_rows(fe).values()])
    fs = scene.ringdown.sample_rate_hz
    acq = Acquisition(fs, oversampling(float(omega.max()) / (2 * np.pi), fs))
    t_fine = np.arange(acq.oversample * (n_out - 1) + 1 + acq.tail_samples) / acq.fine_rate_hz
    ref = ModalModel(omega, 0.5 * (Cm + Cm.T)).half_sine_response(t_fine, b_modal, R, level_N, spec.duration_s,
                                                                  spec.start_s)
    a_ref = acq.acquire(ref.acceleration, n_out)
    sign = np.array([1.0 if c.endswith("top") else -1.0 for c in TIP_CELLS])[:, None]
    data = np.vstack([a_ref[: len(names)], -sign * rig.seismic_mass_kg * a_ref[len(names):]])
    return FullReference([*names, *TIP_CELLS], data, fe.n_dofs, int(phi.shape[1]), float(omega.max() / (2 * np.pi)),
                         float(ref.cond_V))


def rms_errors(a: np.ndarray, ref: np.ndarray, names: list[str], mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """rms(a - ref) / rms(ref) per channel over the samples ``mask``, and which axes were near zero:
    an accelerometer axis (``sensor:axis``) whose RMS is below NEAR_ZERO of its sensor's largest
    (zero by symmetry for a blow on the plane of symmetry) is judged against that largest axis.

    Parameters
    ----------
    a, ref : (n_channels, N) the compared and the reference channels
    names : the channels' names (``sensor:axis`` for an accelerometer axis)
    mask : (N,) bool, the samples compared

    Returns
    -------
    (errors, near_zero) : (n_channels,) relative RMS errors and (n_channels,) bool
    """
    rms_ref = np.sqrt(np.mean(ref[:, mask] ** 2, axis=1))
    scale, near_zero = rms_ref.copy(), np.zeros(len(names), bool)
    sensor = np.array([n.split(":")[0] if ":" in n else n for n in names])
    for i, name in enumerate(names):
        if ":" not in name:
            continue
        top = rms_ref[sensor == sensor[i]].max()
        if rms_ref[i] < NEAR_ZERO * top:
            scale[i], near_zero[i] = top, True
    return np.sqrt(np.mean((a[:, mask] - ref[:, mask]) ** 2, axis=1)) / scale, near_zero


def linear_check(scene: Scene, rig: VirtualRig, rec: Record, progress: bool) -> LinearCheck:
    """The open-gap record ``rec`` of the reduced rig against the full 3-D model's modal superposition.

    ``rec`` is the reduced model's exact integration with gaps too large to close (the reduced
    model's gap set to 1 m) under the scene's nominal half-sine blow; every channel but the
    hammer is compared with the full model's response to the same blow (:func:`full_reference`;
    load cells read only their seismic inertia here). Both are compared low-passed alike at
    BAND_HZ (and raw), the error rms(a_rom - a_full) / rms(a_full) over the first
    CHECK_WINDOW_S after the blow (and over the whole record after it, where the phase of lightly
    damped kHz modes makes a 1e-5 frequency difference an O(1) RMS one), axes near zero by
    symmetry against their sensor's largest (:func:`rms_errors`).

    Parameters
    ----------
    scene : the scene ([hammer], [ringdown], [model])
    rig : the rig with the scene's gaps (its size is quoted; the full model has no gap)
    rec : the open-gap rig's record of the nominal blow
    progress : print what is being built

    Returns
    -------
    LinearCheck
    """
    spec = scene.hammer
    level = rec.level_N
    full = full_reference(scene, rig, level, rec.t.size, progress)
    ref_data = full.data
    rom_data = rec.data[: len(full.names)]
    fs = scene.ringdown.sample_rate_hz
    chan = full.names
    windows = {"50ms": (rec.t >= spec.start_s) & (rec.t < spec.start_s + CHECK_WINDOW_S),
               "record": rec.t >= spec.start_s}
    bands = {"band": (band_limited(rom_data, fs), band_limited(ref_data, fs)), "raw": (rom_data, ref_data)}
    errors, near_zero = {}, np.zeros(len(chan), bool)
    for (b, (r_rom, r_ref)), (w, mask) in ((x, y) for x in bands.items() for y in windows.items()):
        errors[(b, w)], nz = rms_errors(r_rom, r_ref, chan, mask)
        near_zero |= nz
    band, raw = errors[("band", "50ms")], errors[("raw", "50ms")]
    i = int(np.argmax(band))  # the first of equal largest, as max() over the rows
    j = int(np.argmax(raw))
    keep = (rec.t >= spec.start_s) & (rec.t <= spec.start_s + CHECK_WINDOW_S)
    text = _text(scene, rig, full, level, band, chan[i], raw, chan[j], float(np.max(errors[("band", "record")])))
    return LinearCheck(names=chan, errors=errors, near_zero=near_zero, worst=float(band[i]), worst_channel=chan[i],
                       worst_raw=float(raw[j]), n_full_modes=full.n_modes, cond_V=full.cond_V, t=rec.t[keep],
                       rom_band=band_limited(rom_data[i], fs)[keep], full_band=band_limited(ref_data[i], fs)[keep],
                       band_hz=BAND_HZ, window_s=CHECK_WINDOW_S, bound=LINEAR_CHECK_MAX, text=text)


def _text(scene: Scene, rig: VirtualRig, full: FullReference, level: float, band: np.ndarray, worst_channel: str,
          raw: np.ndarray, worst_raw_channel: str, rec_worst: float) -> str:
    """The linear check's paragraph of hammer.md."""
    worst, worst_raw = float(np.max(band)), float(np.max(raw))
    return (f"Gaps too large to close; {len(band)} channels of the reduced model ({rig.system.n} coordinates) "
            f"against the full 3-D model ({full.n_dofs} DOFs) by modal superposition of its {full.n_modes} modes up "
            f"to {scene.hammer.linear_check_max_hz:g} Hz (top {full.top_hz:.5g} Hz) with the same damping "
            f"(closed form, pole-residue FRF), {level:g} N blow, RMS over the first {1e3 * CHECK_WINDOW_S:g} ms after "
            f"the blow (axes near zero by symmetry against their sensor's largest axis). In the "
            f"{BAND_HZ:g} Hz band (both low-passed alike): worst {100 * worst:.3g} % "
            f"({worst_channel}), median "
            f"{100 * float(np.median(band)):.3g} %; "
            f"{'within' if worst <= LINEAR_CHECK_MAX else 'OUTSIDE'} the 1 % bound. Raw samples "
            f"(to the Nyquist frequency, where the full model has modes the reduced one does not keep): worst "
            f"{100 * worst_raw:.3g} % ({worst_raw_channel}). Over the whole record in the band: "
            f"worst {100 * rec_worst:.3g} % (the phase of lightly damped kHz modes: see linear_check.csv).")
