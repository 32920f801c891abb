"""SciPy's DOP853 (``solve_ivp``) on a gap system: the independent baseline.

The first-order state is z = [x, v, W] with W' = v^T C v the dissipated work, so the
energy balance is checked against an independently integrated W. With ``events=True``
every stop crossing is located by ``solve_ivp``'s event search and the integration is
restarted there, so each leg integrates a smooth (linear) vector field: this is the
reference mode used to check the exact integrator. Without it, DOP853 steps over the
discontinuity of the force's derivative as a user of ``solve_ivp`` would.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.integrate import solve_ivp

from reduced.models.gaps import GapSystem
from reduced.transient.result import RingdownResult, sample_times


def _rhs_factory(system: GapSystem):
    n = system.n
    Minv = np.linalg.inv(system.M)
    K, C = system.K, system.C

    def rhs(t, z):
        x, v = z[:n], z[n : 2 * n]
        a = Minv @ (-(K @ x) - C @ v - system.contact_force(x))
        return np.concatenate([v, a, [v @ C @ v]])

    return rhs


def integrate_dop853(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
    events: bool = False,
    progress=None,
) -> RingdownResult:
    """DOP853 free response; ``atol`` defaults to rtol x (largest stop offset or 1e-3 m)."""
    t_wall = time.perf_counter()
    n = system.n
    ts = sample_times(duration_s, sample_rate_hz)
    x_scale = max(float(np.max(np.abs(system.offset), initial=0.0)), 1e-3)
    if atol is None:
        atol = rtol * x_scale
    rhs = _rhs_factory(system)
    z0 = np.concatenate([np.asarray(x0, float), np.asarray(v0, float), [0.0]])
    nfev = 0
    n_events = 0
    if not events:
        sol = solve_ivp(rhs, (0.0, ts[-1]), z0, method="DOP853", t_eval=ts, rtol=rtol, atol=atol)
        if sol.status != 0:
            raise RuntimeError(f"DOP853 failed: {sol.message}")
        Z = sol.y.T
        nfev = sol.nfev
        n_steps = sol.t.size
    else:
        Z = np.empty((ts.size, 2 * n + 1))
        Minv = np.linalg.inv(system.M)
        active = system.penetration(z0[:n]) > 0.0
        t0, z, i = 0.0, z0, 0
        n_steps = 0
        while True:
            Ks, Fs = system.state_matrices(active)

            def leg(t, zz, Ks=Ks, Fs=Fs):
                x, v = zz[:n], zz[n : 2 * n]
                a = Minv @ (Fs - Ks @ x - system.C @ v)
                return np.concatenate([v, a, [v @ system.C @ v]])

            funcs = system.crossing_events(active)
            t_eval = ts[i:]
            sol = solve_ivp(leg, (t0, ts[-1]), z, method="DOP853", t_eval=t_eval[t_eval >= t0],
                            rtol=rtol, atol=atol, events=funcs)
            k = len(sol.t)
            if k:
                Z[i : i + k] = np.asarray(sol.y).T
            i += k
            nfev += sol.nfev
            n_steps += 1
            if sol.status == 1:
                je = int(np.argmin([e[0] if e.size else np.inf for e in sol.t_events]))
                t0 = float(sol.t_events[je][0])
                z = sol.y_events[je][0].copy()
                active = system.state_after_crossing(active, je, z[:n], z[n : 2 * n], 1e-9 * x_scale)
                n_events += 1
                if progress is not None:
                    progress(t0 / ts[-1])
                continue
            if sol.status != 0:
                raise RuntimeError(f"DOP853 failed: {sol.message}")
            break
    if progress is not None:
        progress(1.0)
    x, v, W = Z[:, :n], Z[:, n : 2 * n], Z[:, 2 * n]
    return RingdownResult(
        system=system,
        t=ts,
        x=x,
        v=v,
        dissipated=W,
        method="dop853",
        tolerance=float(atol + rtol * np.max(np.abs(x))),
        stats={"nfev": nfev, "n_events": n_events, "rtol": rtol, "atol": atol,
               "wall_s": time.perf_counter() - t_wall, "n_steps": n_steps},
    )
