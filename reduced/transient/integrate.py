"""One entry point for the three ringdown integrators."""

from __future__ import annotations

import numpy as np

from reduced.models.gaps import GapSystem
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.exact import integrate_exact
from reduced.transient.explicit import integrate_explicit
from reduced.transient.result import RingdownResult

METHODS = ("exact", "explicit", "dop853")


def ringdown(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    method: str = "exact",
    *,
    dt: float | None = None,
    omega_dt: float | None = None,
    step_basis: str = "top",
    rtol: float = 1e-10,
    atol: float | None = None,
    progress=None,
) -> RingdownResult:
    """Free response of ``system`` from (x0, v0) by ``method`` (exact | explicit | dop853)."""
    x0 = np.asarray(x0, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    for name, a in (("x0", x0), ("v0", v0)):
        if a.shape != (system.n,):
            raise ValueError(f"{name} must have {system.n} values, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite, got {a.tolist()}")
    if not (duration_s > 0 and np.isfinite(duration_s)):
        raise ValueError(f"duration_s must be > 0, got {duration_s!r}")
    if not (sample_rate_hz > 0 and np.isfinite(sample_rate_hz)):
        raise ValueError(f"sample_rate_hz must be > 0, got {sample_rate_hz!r}")
    if method == "exact":
        return integrate_exact(system, x0, v0, duration_s, sample_rate_hz, progress=progress)
    if method == "explicit":
        kw = {} if omega_dt is None else {"omega_dt": omega_dt}
        return integrate_explicit(system, x0, v0, duration_s, sample_rate_hz, dt=dt, step_basis=step_basis,
                                  progress=progress, **kw)
    if method == "dop853":
        return integrate_dop853(system, x0, v0, duration_s, sample_rate_hz, rtol=rtol, atol=atol,
                                progress=progress)
    raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
