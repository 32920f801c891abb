"""Memory before allocation: what each stage of a scene will hold, checked before any work.

Each estimate counts the arrays a stage keeps at its peak, from the scene alone (no model
is built): samples x channels x 8 bytes for time histories held in memory, ((2H + 1) n)^2
x 8 bytes for harmonic-balance Jacobians; a ringdown streams its samples to disk in chunks
(:func:`bearingshaft.stages.ringdown.stage_estimate`), so its memory does not grow with
its duration and its disk use is checked against the space free where it writes. A scene
whose estimate exceeds the memory available (Linux ``MemAvailable``, less a margin) is
refused in one line that gives the estimate and the key to change. The estimates are upper
bounds within a small factor (``COPIES``), not a profile: their job is to stop a 149 GiB
request before numpy makes it.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from bearingshaft.scenes import Scene, SceneError

COPIES = 3  # a stage holds its result, a derived series (energy, points) and a plotting copy
HEADROOM = 0.8  # of the available memory a scene may plan to use
JACOBIAN_COPIES = 4  # HB: Jacobian, its LU factors, the AFT blocks and a continuation copy
FLOAT = 8  # bytes
HILL_COPIES = 6  # FRC Hill: the real matrix, its Hessenberg/Schur work copies, complex eigenvalue output


@dataclass(frozen=True, slots=True)
class Estimate:
    """Peak bytes one stage will hold, what they are, and the scene key that sizes them."""

    stage: str
    bytes: float
    what: str
    key: str  # "[table] key"
    disk: float = 0.0  # bytes written to the results folder
    advice: str = ""  # what to do when it does not fit (default: "lower <key>")


def available_bytes() -> int:
    """Bytes of memory available to a new allocation (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")


def human(n: float) -> str:
    """Bytes in B, KiB, MiB, GiB or TiB."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"


def n_dofs(scene: Scene) -> int:
    """DOFs of the scene's gap system, known before it is built (3-D models: 0)."""
    if scene.model_kind == "discrete":
        return 3
    if scene.model_kind == "rom":
        return scene.model.n_modes + 2
    return 0


def _history(samples: float, n: int, runs: int = 1) -> float:
    """Bytes of ``runs`` sampled histories: t, x (n), v (n), dissipated, energy per sample."""
    return runs * COPIES * samples * (2 * n + 3) * FLOAT


def estimates(scene: Scene) -> list[Estimate]:
    """What each stage of ``scene`` will hold at its peak."""
    n = n_dofs(scene)
    out: list[Estimate] = []
    if scene.hammer is not None:  # every level's record in memory: state, channels, energies
        from bearingshaft.stages.ringdown import MATPLOTLIB_BYTES
        from fem.rig import channel_names

        r, h = scene.ringdown, scene.hammer
        samples = r.duration_s * r.sample_rate_hz + 1
        levels = len({*h.levels_N, h.peak_N}) + int(h.linear_check)
        per = (2 * n + len(channel_names()) + 4) * FLOAT
        exact = 3 * 2**4 * (2 * n) ** 2 * 16  # the exact integrator's state table (4 stops)
        out.append(Estimate("hammer", int(MATPLOTLIB_BYTES + COPIES * samples * per + levels * samples * per + exact),
                            f"{levels} records of {samples:.3g} samples x {n} DOFs",
                            "[ringdown] duration_s or sample_rate_hz, or [hammer] levels_N"))
    elif scene.ringdown is not None:
        from bearingshaft.stages.ringdown import stage_estimate

        r = scene.ringdown
        est = stage_estimate(scene, n)
        samples = r.duration_s * r.sample_rate_hz + 1
        out.append(Estimate("ringdown", est["memory"], f"{samples:.3g} samples streamed to disk in chunks",
                            "[ringdown] duration_s or sample_rate_hz", disk=est["disk"]))
    if scene.modal is not None:  # a 3-D model: mesh, K and M, the sparse Cholesky factor, Krylov basis
        out.append(modal_estimate(scene.model, scene.modal.n_modes))
    if scene.fep is not None:
        H = max(scene.fep.harmonics + scene.fep.convergence_harmonics + (scene.fep.samples_study_harmonics,))
        size = (2 * H + 1) * n
        out.append(Estimate("nnm", JACOBIAN_COPIES * size**2 * FLOAT,
                            f"HB Jacobians of {size} x {size} (H = {H})", "[fep] harmonics"))
    if scene.nnm is not None:
        out.append(Estimate("nnm", COPIES * scene.nnm.n_energy * 64 * FLOAT,
                            f"{scene.nnm.n_energy} energies", "[nnm] n_energy"))
    if scene.frc is not None:
        f = scene.frc
        H = max((f.harmonics, *f.convergence_harmonics))
        size = 2 * (2 * H + 1) * n  # Hill's method: the first-order form of the quadratic eigenproblem
        out.append(Estimate("frc", HILL_COPIES * size**2 * FLOAT,
                            f"Hill matrices of {size} x {size} (H = {H}, {n} DOFs)",
                            "[frc] harmonics or convergence_harmonics"))
    if scene.work_precision is not None:
        w = scene.work_precision
        runs = len(w.explicit_omega_dt) + len(w.dop853_rtol) + 1
        samples = w.window_s * w.sample_rate_hz + 1
        out.append(Estimate("study", _history(samples, n, runs),
                            f"{runs} runs of {samples:.3g} samples", "[work_precision] window_s or sample_rate_hz"))
    if scene.stiff_cases is not None:
        s = scene.stiff_cases
        samples = max(s.duration_s, s.long_duration_s) * s.sample_rate_hz + 1
        out.append(Estimate("study", _history(samples, n, len(s.methods)),
                            f"{len(s.methods)} runs of {samples:.3g} samples",
                            "[stiff_cases] duration_s, long_duration_s or sample_rate_hz"))
    if scene.rom_convergence is not None:
        c = scene.rom_convergence
        samples = c.window_s * c.sample_rate_hz + 1
        out.append(Estimate("study", _history(samples, max(c.modes) + 2, len(c.modes)),
                            f"{len(c.modes)} models of up to {max(c.modes) + 2} DOFs, {samples:.3g} samples",
                            "[rom_convergence] window_s or sample_rate_hz"))
    if scene.verify is not None:
        v = scene.verify
        samples = v.duration_s * v.sample_rate_hz + 1
        out.append(Estimate("verify", _history(samples, n, 3 * 3),
                            f"3 models x 3 ringdowns of {samples:.3g} samples",
                            "[verify] duration_s or sample_rate_hz"))
    return out


def modal_estimate(model, n_modes: int) -> Estimate:
    """Peak bytes of meshing, assembling and solving ``model`` (fem.model.AssemblyModel) for
    ``n_modes`` modes; the DOFs are counted from the block grid, before any gmsh call
    (:mod:`fem._modal_cost`, whose factor term is checked against measured peaks in
    ``results/performance/modal_scaling.csv``)."""
    from fem._modal_cost import count_dofs, modal_bytes

    n = count_dofs(model.geometry(), model.element)
    b = modal_bytes(n, n_modes)
    # the key that sizes the largest term: the mesh (factor, matrices) or the modes (Krylov basis)
    by_modes = b["krylov"] > b["factor"] + b["matrices"]
    return Estimate("modal", int(b["total"]),
                    f"{n:,} DOFs ({model.element}): K and M {human(b['matrices'])}, Cholesky factor "
                    f"{human(b['factor'])}, Krylov basis {human(b['krylov'])} for {n_modes} modes",
                    "[modal] n_modes" if by_modes else "[model] element_size",
                    advice="lower n_modes" if by_modes else "raise element_size")


def free_disk_bytes(out_dir: str | Path) -> int:
    """Bytes free on the file system that holds (or will hold) ``out_dir``."""
    probe = Path(out_dir).absolute()
    while not probe.exists():
        probe = probe.parent
    return shutil.disk_usage(probe).free


def check_budget(scene: Scene, out_dir: str | Path | None = None, available: int | None = None) -> list[Estimate]:
    """The scene's estimates, or :class:`SceneError` naming the key if one does not fit in
    memory (or, given ``out_dir``, on its disk)."""
    avail = available_bytes() if available is None else available
    ests = estimates(scene)
    if out_dir is not None:
        free = free_disk_bytes(out_dir)
        for e in ests:
            if e.disk > HEADROOM * free:
                raise SceneError(f"{scene.origin or scene.name} {e.key}: the {e.stage} stage would write "
                                 f"{human(e.disk)} ({e.what}), more than the {human(free)} free for {out_dir}; "
                                 f"lower {e.key.split('] ')[1]}")
    for e in ests:
        if e.bytes > HEADROOM * avail:
            raise SceneError(f"{scene.origin or scene.name} {e.key}: the {e.stage} stage would hold "
                             f"{human(e.bytes)} ({e.what}), more than the {human(HEADROOM * avail)} it may use "
                             f"of {human(avail)} available; {e.advice or 'lower ' + e.key.split('] ')[1]}")
    return ests
