"""The result object every ringdown integrator returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reduced.models.gaps import GapSystem


@dataclass(eq=False)
class RingdownResult:
    """Free response of a :class:`GapSystem` sampled on a uniform grid.

    Attributes
    ----------
    t : (N,) s
    x, v : (N, n) m and m/s
    dissipated : (N,) J, work done by the damping forces, int_0^t v^T C v dt
    method : name of the integrator
    tolerance : m, the displacement accuracy the method aims at (used to judge when
        symmetric motions have split "by more than the solver tolerance")
    stats : solver diagnostics (n_steps, n_events, wall_s, dt, ...)
    """

    system: GapSystem
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    dissipated: np.ndarray
    method: str
    tolerance: float
    stats: dict = field(default_factory=dict)

    @property
    def energy(self) -> np.ndarray:
        """J, mechanical energy at each sample."""
        return self.system.energy(self.x, self.v)

    @property
    def energy_balance_error(self) -> float:
        """max_t |E(0) - E(t) - W(t)| / E(0): how well the run conserves energy."""
        E = self.energy
        if E[0] == 0.0:
            return 0.0
        return float(np.max(np.abs(E[0] - E - self.dissipated)) / E[0])

    def save(self, path: str | Path) -> None:
        """Write t, x, v, energy, dissipated and the stats to an .npz file."""
        np.savez_compressed(
            path,
            t=self.t,
            x=self.x,
            v=self.v,
            energy=self.energy,
            dissipated=self.dissipated,
            dof_names=np.array(self.system.dof_names),
            method=self.method,
            tolerance=self.tolerance,
            energy_balance_error=self.energy_balance_error,
            **{f"stat_{k}": v for k, v in self.stats.items() if np.isscalar(v)},
        )


def sample_times(duration_s: float, sample_rate_hz: float) -> np.ndarray:
    """s, the output grid 0, 1/fs, ..., up to duration (inclusive when it falls on the grid)."""
    n = int(np.floor(duration_s * sample_rate_hz * (1.0 + 1e-12))) + 1
    return np.arange(n) / sample_rate_hz
