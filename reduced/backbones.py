"""Backbones (frequency-energy curves) of the nonlinear normal modes of a gap system by HB.

:func:`nnm_branch` continues one NNM from its open-gap linear mode, below the energy at
which the mode first touches a stop, up to ``energy_max_J``; :func:`hb_backbones` gives
the paper's Fig. 2 curves (one harmonic) for every mode, for the spectrogram overlays.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced.continuation import Branch, continue_branch
from reduced.discrete import linear_modes
from reduced.gaps import GapSystem
from reduced.hb import HarmonicBalance, NNMResidual, default_samples

START_FRACTION = 0.3  # start amplitude as a fraction of the grazing amplitude (open gap)


def grazing_amplitude(system: GapSystem, phi: np.ndarray) -> float:
    """Modal amplitude a (phi mass-normalised) at which mode phi first reaches a stop."""
    s = np.abs(system.B @ phi)
    with np.errstate(divide="ignore"):
        a = np.where(s > 1e-12 * np.max(s), np.abs(system.offset) / s, np.inf)
    return float(np.min(a))


@dataclass(eq=False)
class NNMBranch:
    """One HB backbone: energy [J] and frequency [Hz] per point, with the continuation data."""

    mode: int  # 0-based index of the linear mode it starts from
    H: int
    N: int
    energy_J: np.ndarray
    freq_hz: np.ndarray
    X: np.ndarray  # (n_points, n (2H+1)) HB coefficients [m]
    omega: np.ndarray  # rad/s
    branch: Branch
    residual: NNMResidual
    wall_s: float
    notes: list = field(default_factory=list)


def nnm_branch(
    system: GapSystem,
    mode: int,
    *,
    H: int = 1,
    N: int | None = None,
    energy_max_J: float = 1e5,
    energy_start_J: float | None = None,
    ds: float = 0.05,
    ds_max: float = 0.3,
    max_steps: int = 3000,
    max_angle_deg: float = 15.0,
    progress=None,
) -> NNMBranch:
    """Continue NNM ``mode`` (0-based) by HB with H harmonics until energy >= energy_max_J.

    The branch starts at START_FRACTION of the amplitude at which the linear mode first
    touches a stop (or lower, at ``energy_start_J``), continued in log10 of the modal
    amplitude (:class:`reduced.hb.NNMResidual`).
    """
    t0 = time.perf_counter()
    lin = linear_modes(system, "open")
    phi = lin.phi[:, mode]
    omega0 = float(lin.omega[mode])
    hb = HarmonicBalance.for_system(system, H, N or default_samples(H))
    ref = int(np.argmax(np.abs(phi)))
    res = NNMResidual(hb, omega0, ref)
    a_g = grazing_amplitude(system, phi)
    if not math.isfinite(a_g):  # the mode never touches a stop: any amplitude will do
        a_g = 1.0
    a0 = START_FRACTION * a_g
    if energy_start_J is not None:  # linear energy 1/2 omega0^2 a^2
        a0 = min(a0, math.sqrt(2.0 * energy_start_J) / omega0)
    y0 = res.start(phi, omega0, math.log10(a0))
    nX = hb.size
    branch = continue_branch(
        res, y0, param=nX + 2, direction=1.0, ds=ds, ds_max=ds_max, max_steps=max_steps,
        max_angle_deg=max_angle_deg, stop=lambda y: res.energy(y) >= energy_max_J,
        monitor=(nX,), callback=res.energy, progress=progress,
    )
    X = np.array([res.X_omega(y)[0] for y in branch.y])
    omega = branch.y[:, nX] * omega0
    E = np.array(branch.data)
    notes = []
    if branch.status != "stop":
        notes.append(f"stopped early ({branch.status}) at E = {E[-1]:.3g} J")
    return NNMBranch(mode, H, hb.N, E, omega / (2 * np.pi), X, omega, branch, res,
                     time.perf_counter() - t0, notes)


def hb_backbones(
    system: GapSystem, harmonics: int = 1, energy_max_J: float = 1e5
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{"NNM 1": (energy_J, freq_hz), ...} of every NNM by HB, sorted by energy.

    The paper's Fig. 2 curves with ``harmonics = 1``. Where a branch folds back in energy
    (an internal resonance at H > 1) the points are still returned sorted by energy, so
    use a one-harmonic branch for overlays.
    """
    out = {}
    for mode in range(system.n):
        b = nnm_branch(system, mode, H=harmonics, energy_max_J=energy_max_J)
        order = np.argsort(b.energy_J, kind="stable")
        out[f"NNM {mode + 1}"] = (b.energy_J[order], b.freq_hz[order])
    return out


__all__ = ["NNMBranch", "nnm_branch", "hb_backbones", "grazing_amplitude"]
