"""Accuracy studies of the ringdown integrators: work-precision and stiff/extreme cases."""

from __future__ import annotations

import time
from dataclasses import replace
from itertools import product

import numpy as np

from reduced.discrete import DiscreteParams
from reduced.dop853 import integrate_dop853
from reduced.exact import ExactIntegratorError
from reduced.explicit import StepTooLargeError
from reduced.gaps import GapSystem
from reduced.integrate import ringdown


def relative_error(x: np.ndarray, x_ref: np.ndarray) -> float:
    """max over samples and DOFs of |x - x_ref|, over max |x_ref| (relative max-norm)."""
    return float(np.max(np.abs(x - x_ref)) / np.max(np.abs(x_ref)))


def _best_of(repeats: int, fn):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def fit_order(h: np.ndarray, err: np.ndarray, lo: float = 1e-12, hi: float = 1e-2) -> float:
    """Slope of log(err) against log(h) over the points with lo < err < hi (asymptotic range)."""
    h, err = np.asarray(h), np.asarray(err)
    sel = (err > lo) & (err < hi)
    if np.count_nonzero(sel) < 2:
        return float("nan")
    return float(np.polyfit(np.log(h[sel]), np.log(err[sel]), 1)[0])


def work_precision(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    window_s: float,
    sample_rate_hz: float,
    explicit_omega_dt: tuple[float, ...],
    dop853_rtol: tuple[float, ...],
    repeats: int = 3,
    progress=None,
) -> tuple[list[dict], float]:
    """Rows (method, setting, runtime_s, error) and the explicit method's fitted order.

    The reference is the exact integrator; its own error is measured against DOP853 with
    every stop crossing located as an event (rtol = 1e-13), an independent method whose
    error (~1e-11 here) bounds what that comparison can show.
    """
    run = lambda method, **kw: ringdown(system, x0, v0, window_s, sample_rate_hz, method, **kw)  # noqa: E731
    run("exact")  # compile the kernels before timing
    run("explicit", omega_dt=0.5)
    rows: list[dict] = []
    t_exact, ref = _best_of(repeats, lambda: run("exact"))
    check = integrate_dop853(system, x0, v0, window_s, sample_rate_hz, rtol=1e-13, events=True)
    rows.append({"method": "exact", "setting": "events", "runtime_s": t_exact,
                 "error": relative_error(ref.x, check.x), "n_steps": ref.stats["n_events"]})
    total = len(explicit_omega_dt) + len(dop853_rtol)
    for i, wdt in enumerate(explicit_omega_dt):
        t, res = _best_of(repeats, lambda wdt=wdt: run("explicit", omega_dt=wdt))
        rows.append({"method": "explicit", "setting": f"omega_dt={wdt:g}", "runtime_s": t,
                     "error": relative_error(res.x, ref.x), "n_steps": res.stats["n_steps"],
                     "dt": res.stats["dt"]})
        if progress:
            progress((i + 1) / total)
    for i, rtol in enumerate(dop853_rtol):
        t, res = _best_of(1, lambda rtol=rtol: run("dop853", rtol=rtol))
        rows.append({"method": "dop853", "setting": f"rtol={rtol:g}", "runtime_s": t,
                     "error": relative_error(res.x, ref.x), "n_steps": res.stats["nfev"]})
        if progress:
            progress((len(explicit_omega_dt) + i + 1) / total)
    exp_rows = [r for r in rows if r["method"] == "explicit"]
    order = fit_order([r["dt"] for r in exp_rows], [r["error"] for r in exp_rows])
    return rows, order


def stiff_cases(
    base: DiscreteParams,
    k_g: tuple[float, ...],
    gap: tuple[float, ...],
    speed: tuple[float, ...],
    c: tuple[float, ...],
    duration_s: float,
    sample_rate_hz: float,
    methods: tuple[str, ...],
    progress=None,
) -> list[dict]:
    """Run every combination; each row has a result or the reason it was refused.

    The impulse is v(0) = [0, 0, speed]. A missed contact event would show in the energy
    balance: the sampled energy counts the penalty energy of every penetration, so a
    stop that was crossed without switching leaves E(0) != E(t) + W(t).
    """
    rows = []
    combos = list(product(k_g, gap, speed, c, methods))
    for i, (kg, g, v, cc, method) in enumerate(combos):
        row = {"k_g": kg, "gap": g, "speed": v, "c": cc, "method": method}
        try:
            p = replace(base, k_g=kg, g=g, c=cc)
            system = p.system()
            t0 = time.perf_counter()
            res = ringdown(system, np.zeros(3), np.array([0.0, 0.0, v]), duration_s, sample_rate_hz, method)
            wall = time.perf_counter() - t0
            ok = np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.v))
            row.update({
                "status": "ok" if ok else "non-finite",
                "energy_J": float(res.energy[0]),
                "energy_balance_error": res.energy_balance_error,
                "n_steps": res.stats.get("n_steps"),
                "n_events": res.stats.get("n_events", ""),
                "runtime_s": wall,
                "max_penetration_m": float(np.max(res.system.penetration(res.x))),
                "reason": "",
            })
        except (ExactIntegratorError, StepTooLargeError, FloatingPointError, ValueError) as exc:
            row.update({"status": "refused", "energy_J": "", "energy_balance_error": "", "n_steps": "",
                        "n_events": "", "runtime_s": "", "max_penetration_m": "", "reason": str(exc)})
        rows.append(row)
        if progress:
            progress((i + 1) / len(combos))
    return rows
