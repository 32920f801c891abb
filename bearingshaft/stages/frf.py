"""Stage ``frf``: FRFs and modal parameters of a hammer test, as a test lab gets them (issue 26).

Repeated blows (the virtual test's, :mod:`bearingshaft.stages.frf_virtual`, or a measured
UFF 58 file's with ``--test``) are windowed (a force window on the hammer channel, an
exponential window on every channel from the same origin), transformed and averaged per
reference into H1, H2 and the ordinary coherence (:mod:`fem.frf`). The accelerometers' H1 in
the band ``[frf] band_hz``, divided by s^2, go to the poly-reference least-squares complex
frequency estimator (:func:`fem.lscf.lscf`) at every order up to ``max_order``; the poles stable
in frequency, damping and participation over enough orders are the modes
(:func:`fem.lscf.select_modes`), corrected for the exponential window's added damping
(:func:`fem.frf.exponential_correction`), and their shapes follow by least-squares
frequency-domain fitting with fixed poles (:func:`fem.lscf.lsfd`). The shapes are compared by
MAC with the 3-D model's modes at the same accelerometers (the modal stage's shapes,
:func:`fem.analysis.analyse`; ``mac_reference = "rom"``: the reduced rig's), on the beam
accelerometers and on all of them (the paper's Table 3 and Fig. 9), and the poles with the
model's: the reduced rig's open-gap complex poles (its modal damping).

:func:`compute` returns :class:`bearingshaft.stages.frf_results.FRFResult`; :func:`write`
hands it to :mod:`bearingshaft.stages.frf_files` (:data:`DESCRIPTION`).

A measured file holds the blows as records in file order: each force (hammer) record opens a
blow, and the k-th record of every response channel (node, direction, quantity) belongs to the
k-th blow; the references are the distinct DOFs of the force records. Every record has the
same sampling and length.
"""

from __future__ import annotations

import math
import time

import numpy as np

from bearingshaft.estimates import FLOAT, MATPLOTLIB_BYTES, Estimate
from bearingshaft.reproduction import Reproduction, record, within
from bearingshaft.scenes import Scene, SceneError
from bearingshaft.stages.frf_results import Blows, Dof, FRFResult, ModelModes, Windows
from fem.frf import exponential_correction, exponential_window, force_window, frf_estimates, tau_for_end_value
from fem.lscf import lscf, lsfd, real_shapes, receptance, select_modes
from fem.mac import mac
from fem.rig import AXES, BEAM_SENSORS, TIP_CELLS, TUBE_NODE0, TUBE_SENSORS, sensor_node, tip_node
from fem.uff_frf import SensorGeometry

TRIGGER_SHARE = 0.05  # the trigger: the force's first sample at 5 % of its peak
PRE_SHARE = 0.1  # the windows start this share of the force window before the trigger
ACC_DOFS = tuple(f"{s}:{a}" for s in (*BEAM_SENSORS, *TUBE_SENSORS) for a in AXES)  # the MAC's rows
N_BEAM_DOFS = 3 * len(BEAM_SENSORS)  # the first rows of ACC_DOFS: the beam accelerometers (Table 3, beam only)


# -- the blows of a measured test ----------------------------------------------------------
def read_blows(test_file: str) -> Blows:
    """The blows of a measured UFF 58 file (SceneError, one line, if they cannot be).

    Parameters
    ----------
    test_file : path of a UFF 58 file of time histories: per blow a force record and the
        response records (the k-th record of a response DOF belongs to the k-th force record's blow)

    Returns
    -------
    Blows
    """
    from fem.uff import UffError, read_uff58

    try:
        chans = read_uff58(test_file)
    except UffError as exc:
        raise SceneError(f"--test: {exc}") from None
    where = f"--test {test_file!r}"
    forces = [c for c in chans if c.quantity == "force"]
    if not forces:
        raise SceneError(f"{where}: no force (hammer) record; an FRF needs the force")
    first = forces[0]
    for c in chans:
        if c.dt_s != first.dt_s or c.data.size != first.data.size:
            raise SceneError(f"{where}: record {c.name!r} has {c.data.size} samples at {c.dt_s:g} s, the hammer's "
                             f"{first.data.size} at {first.dt_s:g} s; every record of a blow needs the same sampling")
    keys: dict[tuple, list] = {}
    for c in chans:
        if c.quantity != "force":
            keys.setdefault((c.node, c.direction, c.quantity), []).append(c)
    n = len(forces)
    for recs in keys.values():
        if len(recs) != n:
            raise SceneError(f"{where}: channel {recs[0].name!r} has {len(recs)} records for {n} blows (force records)")
    refs: list[tuple[int, int]] = []
    for f in forces:
        if (f.node, f.direction) not in refs:
            refs.append((f.node, f.direction))
    outputs = tuple(Dof(r[0].name, *k) for k, r in keys.items())
    references = tuple(Dof(f"hammer {node}:{d}", node, d, "force") for node, d in refs)
    return Blows(sample_rate_hz=1.0 / first.dt_s, force=np.array([f.data for f in forces]),
                 responses=np.array([[recs[k].data for recs in keys.values()] for k in range(n)]),
                 reference=np.array([refs.index((f.node, f.direction)) for f in forces]), outputs=outputs,
                 references=references, source=f"measured test {test_file}", info={"test_file": str(test_file)})


# -- signal processing -----------------------------------------------------------------------
def windowed(blows: Blows, force_window_s: float, exp_end: float) -> tuple[Windows, np.ndarray, np.ndarray]:
    """The windows of every blow and the windowed force (n_blows, N) and responses (n_blows, n_out, N).

    Each blow's trigger is the force's first sample at ``TRIGGER_SHARE`` of its peak; both windows
    start ``PRE_SHARE`` of the force window before it (at the record's start at the latest), so
    the force is inside the force window and the exponential window starts before the force
    does (the pole shift is then exact, :mod:`fem.frf`). The exponential window's time constant
    makes it ``exp_end`` at the end of the record of the latest trigger.

    Parameters
    ----------
    blows : the blows
    force_window_s : s, the force window after the trigger
    exp_end : the exponential window's value at the record's end (1: none)

    Returns
    -------
    windows : Windows
    x, y : the windowed force and responses
    """
    fs, N = blows.sample_rate_hz, blows.n_samples
    peak = np.max(np.abs(blows.force), axis=1, keepdims=True)
    if np.any(peak[:, 0] <= 0):
        raise SceneError(f"blow {int(np.argmin(peak[:, 0])) + 1}: the force is zero; no blow to process")
    trig = np.argmax(np.abs(blows.force) >= TRIGGER_SHARE * peak, axis=1) / fs
    origin = np.maximum(trig - PRE_SHARE * force_window_s, 0.0)
    tau = tau_for_end_value(N, fs, float(origin.max()), exp_end)
    x = np.empty_like(blows.force)
    y = np.empty_like(blows.responses)
    for a in range(blows.force.shape[0]):
        ew = exponential_window(N, fs, float(origin[a]), tau)
        fw = force_window(N, fs, float(trig[a]), force_window_s, pre_s=float(trig[a] - origin[a]))
        x[a] = blows.force[a] * fw * ew
        y[a] = blows.responses[a] * ew[None]
    return Windows(trig, origin, force_window_s, tau, 0.0 if math.isinf(tau) else 1.0 / tau), x, y


def _acc_rows(outputs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(output index, row of ACC_DOFS, sign) of every accelerometer output at a known sensor axis."""
    node_name = {sensor_node(s): s for s in (*BEAM_SENSORS, *TUBE_SENSORS)}
    idx, rows, sign = [], [], []
    for k, d in enumerate(outputs):
        if d.quantity != "acceleration" or d.node not in node_name or not 1 <= abs(d.direction) <= 3:
            continue
        idx.append(k)
        rows.append(ACC_DOFS.index(f"{node_name[d.node]}:{AXES[abs(d.direction) - 1]}"))
        sign.append(float(np.sign(d.direction)))
    return np.array(idx, int), np.array(rows, int), np.array(sign)


# -- the model -----------------------------------------------------------------------------
def model_modes(scene: Scene, rom, band_hz) -> ModelModes:
    """The reduced rig's open-gap complex poles in the band, and the MAC reference shapes at ACC_DOFS.

    Parameters
    ----------
    scene : the scene ([frf] mac_reference and fe_modes; [model] for the 3-D model)
    rom : its reduced model
    band_hz : Hz, (low, high)

    Returns
    -------
    ModelModes
    """
    from fem.modal_response import ModalModel
    from reduced.models.modes import linear_modes

    system = rom.system()
    lm = linear_modes(system, "open")
    poles = ModalModel(lm.omega, lm.phi.T @ system.C @ lm.phi).poles().lam
    poles = poles[poles.imag > 0]
    f = np.abs(poles) / (2 * np.pi)
    keep = np.argsort(f)[(np.sort(f) >= band_hz[0]) & (np.sort(f) <= band_hz[1])]
    freq, zeta = f[keep], -poles[keep].real / np.abs(poles[keep])
    spec = scene.frf
    if spec.mac_reference == "fe":
        from fem.labels import TABLE2_ORDER

        fe_freq, shapes, n_dofs = fe_reference(scene.model.fe_model(), spec.fe_modes)
        return ModelModes(freq, zeta, tuple(TABLE2_ORDER), fe_freq, shapes, ACC_DOFS,
                          f"3-D FE model ({n_dofs} DOFs, {spec.fe_modes} modes; the modal stage's solve), "
                          "its six pseudo-rigid modes (Table 2 labels)")
    rows = np.vstack([rom.output(n) for n in ACC_DOFS])
    band = np.flatnonzero((lm.freq_hz >= band_hz[0]) & (lm.freq_hz <= band_hz[1]))
    names = tuple(f"mode {k + 1} ({lm.freq_hz[k]:.2f} Hz)" for k in band)
    return ModelModes(freq, zeta, names, lm.freq_hz[band], rows @ lm.phi[:, band], ACC_DOFS,
                      f"reduced rig ({system.n} DOFs), its open-gap modes in the band")


def fe_reference(fe_model, n_modes: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The MAC reference of the 3-D model (:func:`fem.analysis.analyse`: mesh, assembly, ``n_modes`` modes,
    labels): its labelled pseudo-rigid modes' frequencies and shapes at the accelerometers, kept in the
    reduced-model cache (``frfref-<key>.npz``; solved, it was 4.0 s of the stage's 7.1 s of compute CPU,
    provenance ``cpu_s``). The key is what the
    solve depends on, as a cached reduction's (:func:`reduced.models.rom.source_hash`): the model's parameters,
    ``n_modes``, the code of geometry/ and fem/, the thread count asked for (``BEARINGSHAFT_THREADS``); a loaded
    entry holds the bits of the solve (the factorization's thread count is fixed, :mod:`fem._pardiso`).

    Parameters
    ----------
    fe_model : fem.model.AssemblyModel
        The 3-D model (the scene's ``[model]`` ``fe_model()``).
    n_modes : int
        Modes solved ([frf] fe_modes).

    Returns
    -------
    freq_hz, shapes, n_dofs : (6,) ndarray (Hz, Table 2 order), (len(ACC_DOFS), 6) ndarray (mass-normalised
        shapes at ACC_DOFS), int (the model's DOFs)
    """
    import hashlib
    import os

    from reduced.cache import cached_arrays
    from reduced.models.rom import cache_dir, source_hash

    sensors = [*BEAM_SENSORS, *TUBE_SENSORS]

    def solve() -> dict:
        from fem.analysis import analyse

        a = analyse(fe_model, n_modes=n_modes)
        idx = a.labelled_indices()
        return {"freq_hz": np.asarray(a.modes.freq_hz)[idx], "shapes": a.sensor_shapes(sensors, idx),
                "n_dofs": np.int64(a.system.n_dofs)}

    key = hashlib.sha256(f"frf fe_reference {fe_model!r} {n_modes} {sensors} {source_hash()} "
                         f"{os.environ.get('BEARINGSHAFT_THREADS', '')}".encode()).hexdigest()
    z = cached_arrays(cache_dir() / f"frfref-{key[:20]}.npz", key, solve,
                      info={"kind": "frf stage's MAC reference", "model": repr(fe_model), "n_modes": n_modes})
    return z["freq_hz"], z["shapes"], int(z["n_dofs"])


def test_geometry(scene: Scene, rom, ref_locations) -> SensorGeometry:
    """Nodes of the test (sensors, tip load cells, hammer references) and the wireframe's trace lines.

    Parameters
    ----------
    scene : the scene (its 3-D model's geometry places the sensors and tip seats)
    rom : its reduced model (unused: the geometry is the 3-D model's)
    ref_locations : m, the hammer references' points (nodes 301, 302, ...)

    Returns
    -------
    SensorGeometry
    """
    g = scene.model.fe_model().geometry()
    nodes, xyz, names = [], [], []
    for s, p in {**g.beam_sensors(), **g.tube_sensors()}.items():
        nodes.append(sensor_node(s))
        xyz.append(p)
        names.append(s)
    seats = g.seat_centres("tube")
    for cell in TIP_CELLS:
        nodes.append(tip_node(cell)[0])
        xyz.append(seats[cell[4:]])
        names.append(cell)
    for k, loc in enumerate(ref_locations):
        nodes.append(300 + k + 1)
        xyz.append(loc)
        names.append(f"hammer_{k + 1}")
    t = TUBE_NODE0
    lines = (("beam top edges", (1, 3, 5, 6, 4, 2, 1)), ("tube", (t + 1, t + 2, t + 4, t + 3, t + 1)),
             ("tips", (201, 202, 0, 203, 204)))
    return SensorGeometry(np.array(nodes), np.array(xyz, float), tuple(names), lines)


# -- the stage ---------------------------------------------------------------------------------
def compute(scene: Scene, progress: bool, workdir, test_file: str | None = None) -> FRFResult:
    """Blows (virtual, or ``test_file``'s), FRFs, stabilization diagram, modes, MAC.

    Parameters
    ----------
    scene : a scene with [hammer], [ringdown] and [frf]
    progress : show progress (the steps take seconds)
    workdir : the stage's scratch folder (unused)
    test_file : a measured UFF 58 file of repeated blows (default: the virtual test)

    Returns
    -------
    FRFResult
    """
    from bearingshaft.stages import frf_virtual
    from reduced._blas import single_thread_blas

    spec = scene.frf
    wall, cpu = {}, {}
    with single_thread_blas():  # the products are small; threads only contend on a shared machine
        t0, c0 = time.perf_counter(), time.process_time()
        rom = scene.model.reduced(progress)
        wall["model_s"], cpu["model_s"] = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        if test_file is None:
            blows = frf_virtual.virtual_blows(scene, rom, progress)
            ref_locations = [r["location_m"] for r in blows.info["references"]]
        else:
            blows = read_blows(test_file)
            pairs = tuple(zip(spec.locations_m, spec.directions, strict=True)) or frf_virtual.default_references(rom)
            ref_locations = [loc for loc, _ in pairs][: len(blows.references)]
        wall["blows_s"], cpu["blows_s"] = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        windows, x, y = windowed(blows, spec.force_window_s, spec.exp_end)
        est = frf_estimates(x, y, blows.sample_rate_hz, blows.reference)
        wall["frf_s"], cpu["frf_s"] = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        acc_idx, acc_rows, acc_sign = _acc_rows(blows.outputs)
        if acc_idx.size == 0:
            raise SceneError("no accelerometer channel at a known sensor (beam_s1..6, tube_s1..4): no mode shapes")
        f = est.freq_hz
        inband = np.flatnonzero((f >= spec.band_hz[0]) & (f <= spec.band_hz[1]))
        if inband.size < 2 * len(blows.references) + 4:
            raise SceneError(f"[frf] band_hz {spec.band_hz}: {inband.size} frequency lines at {f[1]:.3g} Hz spacing; "
                             "widen the band or lengthen the record")
        band = slice(int(inband[0]), int(inband[-1]) + 1)
        Hd = receptance(f[band], est.H1[acc_idx][:, :, band] * acc_sign[:, None, None], "acceleration")
        diagram = lscf(f[band], Hd, range(1, spec.max_order + 1))
        selected = select_modes(diagram, min_share=spec.min_share, near_hz=spec.modes_hz)
        lam, added = exponential_correction(selected.lam, windows.tau_s)
        fit = lsfd(f[band], Hd, selected.lam, selected.participation)
        shapes, complexity = real_shapes(fit.psi)
        wall["identification_s"], cpu["identification_s"] = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        model = model_modes(scene, rom, spec.band_hz)
        full = np.zeros((len(ACC_DOFS), shapes.shape[1]))
        full[acc_rows] = shapes
        have = np.zeros(len(ACC_DOFS), bool)
        have[acc_rows] = True
        beam = have & (np.arange(len(ACC_DOFS)) < N_BEAM_DOFS)
        mac_beam = mac(full[beam], model.ref_shapes[beam])
        mac_assembly = mac(full[have], model.ref_shapes[have])
        fid = np.abs(lam) / (2 * np.pi)
        match = np.array([int(np.argmin(np.abs(model.freq_hz - v))) for v in fid], int) if model.freq_hz.size else \
            np.zeros(fid.size, int)
        wall["mac_s"], cpu["mac_s"] = time.perf_counter() - t0, time.process_time() - c0
    geometry = test_geometry(scene, rom, ref_locations)
    err = [100 * (fid[k] - model.freq_hz[match[k]]) / model.freq_hz[match[k]] for k in range(fid.size)] \
        if model.freq_hz.size else []
    stats = {"source": blows.source, "blows": int(blows.force.shape[0]), "references": len(blows.references),
             "outputs": len(blows.outputs), "sample_rate_hz": blows.sample_rate_hz, "n_samples": blows.n_samples,
             "tau_s": windows.tau_s, "sigma_1_s": windows.sigma, "band_lines": int(inband.size),
             "orders": spec.max_order, "modes": int(fid.size), "freq_hz": fid.tolist(),
             "zeta": (-lam.real / np.abs(lam)).tolist(), "freq_error_pct": err, "wall_s": wall, "cpu_s": cpu,
             "mac_reference": model.source, **{f"blows_{k}": v for k, v in blows.info.items()}}
    worst = f"{max(abs(e) for e in err):.3g} %" if err else "n/a"
    line = (f"[{scene.name}] frf: {blows.force.shape[0]} blows at {len(blows.references)} references, "
            f"{len(blows.outputs)} channels; {fid.size} modes in {spec.band_hz[0]:g}-{spec.band_hz[1]:g} Hz "
            f"({', '.join(f'{v:.2f}' for v in fid)} Hz), worst frequency error against the model {worst} "
            f"(modes.csv, mac.csv)")
    return FRFResult(scene=scene, blows=blows, windows=windows, estimate=est, band=band, diagram=diagram,
                     selected=selected, lam=lam, added_zeta=added, fit=fit, acc_index=acc_idx,
                     shapes=shapes, shape_dofs=tuple(ACC_DOFS[r] for r in acc_rows),
                     complexity=complexity, model=model, mac_beam=mac_beam,
                     mac_assembly=mac_assembly, match=match, geometry=geometry, stats=stats, lines=(line,))




# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """FRFs and modal parameters of a hammer test, as a test lab gets them. Repeated blows (the
virtual test's: the reduced apparatus struck [frf] blows times at each reference, at a level
that leaves the gaps open, recorded through the DAQ's anti-alias filter, with optional noise;
or, with --test FILE.uff, a measured file's) get a force window and an exponential window, and
are averaged per reference into H1, H2 and the coherence. pLSCF (PolyMAX) gives the
stabilization diagram, its stable poles the modes (damping corrected for the exponential
window), LSFD their shapes, compared by MAC with the 3-D model's modes (Table 3). Writes
frf.uff (UFF 58: FRFs, function type 4, and coherences, type 6), frf.npz, frf.png,
stabilization.png, modes.csv, modes.uff (UFF 55 shapes), mac.csv, mac.png, geometry.uff (UFF 15
nodes and 82 trace lines), geometry_2411.uff (the same nodes as 2411), geometry.csv and frf.md."""


def estimate(scene: Scene) -> list[Estimate]:
    """The blows, their windowed copies and spectra in memory.

    Parameters
    ----------
    scene : a scene with [hammer], [ringdown] and [frf]

    Returns
    -------
    list of one Estimate
    """
    from fem.rig import channel_names

    r, spec = scene.ringdown, scene.frf
    samples = r.duration_s * r.sample_rate_hz + 1
    n_ref = max(1, len(spec.locations_m)) if spec.locations_m else 3
    blows = n_ref * spec.blows
    chans = len(channel_names())
    fine = 4 * samples * chans * n_ref * FLOAT  # the unit blows at the DAQ's oversampling (q <= 2) and their filter
    return [Estimate("frf", int(MATPLOTLIB_BYTES + fine + 3 * blows * chans * samples * FLOAT
                                + 4 * chans * n_ref * samples * FLOAT),
                     f"{blows} blows of {samples:.3g} samples x {chans} channels",
                     "[ringdown] duration_s or sample_rate_hz, or [frf] blows")]


__all__ = ["compute", "estimate", "DESCRIPTION", "read_blows", "windowed", "model_modes", "test_geometry",
           "TRIGGER_SHARE", "PRE_SHARE"]


# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
# the virtual blows leave the gaps open (a linear, seeded test: its noise from [frf] seed), so every number is
# deterministic and compared to the digits written: the modes and MAC (modes.csv, mac.csv, frf.md), the geometry
# (geometry.csv, geometry.uff, geometry_2411.uff); the shapes in modes.uff are written to 6 digits of each component,
# more than the small ones reproduce: on 1 and 2 threads (a reduction rounded otherwise) they moved by up to 3e-8 of
# the shape's largest component, which is 1 (fem.lscf.real_shapes); frf.npz and frf.uff are arrays, not committed
REPRODUCTION = Reproduction(rules=(
    record("frf.uff", "not committed (.gitignore): the FRFs and coherences of frf.npz"),
    within("modes.uff", r"^ +[-0-9]", atol=1e-6,
           why="LSFD shapes scaled to a largest component of 1, written to 6 digits of each component: the small "
           "ones move by ~3e-8 with the reduced model's rounding"),
))
