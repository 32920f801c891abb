"""Accuracy studies of the ringdown integrators: work-precision, stiff/extreme cases, and
the reduced model's convergence with its number of fixed-interface modes."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from itertools import product

import numpy as np

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.initial import initial_state
from reduced.models.modes import linear_modes
from reduced.models.rom import ReducedModel, RomSpec
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.explicit import StepTooLargeError, default_step
from reduced.transient.integrate import ringdown


def relative_error(x: np.ndarray, x_ref: np.ndarray) -> float:
    """max over samples and DOFs of |x - x_ref|, over max |x_ref| (relative max-norm)."""
    return float(np.max(np.abs(x - x_ref)) / np.max(np.abs(x_ref)))


def _best_of(repeats: int, fn, budget_s: float = math.inf):
    """(best wall time, last result) of up to ``repeats`` calls, stopping once ``budget_s`` is spent."""
    best, out, spent = np.inf, None, 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        best, spent = min(best, dt), spent + dt
        if spent > budget_s:
            break
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


# -- stiff and extreme cases -------------------------------------------------------------
# A case factory makes (system, x0, v0) from (k_g [N/m], gap [m], speed [m/s], c [N s/m]).
CaseFactory = Callable[[float, float, float, float], tuple[GapSystem, np.ndarray, np.ndarray]]
NOMINAL_GAP = 2.54e-4  # m, Table-1 clearance of the long runs
NOMINAL_SPEED = 200.0  # m/s, v3(0) of the long runs (the impulse-like start of Fig. 3)
STIFF_FIELDS = ["k_g", "gap", "speed", "c", "method", "status", "energy_J", "energy_balance_error",
                "n_steps", "n_events", "runtime_s", "max_penetration_m", "reason"]  # discrete CSV columns


def discrete_case(base: DiscreteParams) -> CaseFactory:
    """Cases of the three-mass model: v(0) = [0, 0, speed] on its coordinates."""

    def make(k_g: float, gap: float, speed: float, c: float):
        system = replace(base, k_g=k_g, g=gap, c=c).system()
        return system, np.zeros(3), np.array([0.0, 0.0, speed])

    return make


def rom_case(rom: ReducedModel, spec: RomSpec) -> CaseFactory:
    """Cases of a reduced model: the dashpots c at x1, x2, x3 (``c_points``), v(x3) = speed.

    The velocity is given at the points and realized in the three lowest open-gap modes
    (:func:`reduced.models.initial.initial_state`), which do not depend on the contact, so the
    unit-speed state is formed once and scaled.
    """
    _, v_unit = initial_state(rom.M, rom.K, rom.P, np.zeros(3), np.array([0.0, 0.0, 1.0]))

    def make(k_g: float, gap: float, speed: float, c: float):
        system = rom.with_contact(replace(spec, k_g=k_g, gap=gap, c_points=c)).system()
        return system, np.zeros(rom.n), speed * v_unit

    return make


def _stiff_row(make: CaseFactory, kg: float, g: float, v: float, cc: float, method: str, duration_s: float,
               sample_rate_hz: float, max_steps: float, step_basis: str = "top") -> dict:
    row = {"k_g": kg, "gap": g, "speed": v, "c": cc, "method": method, "duration_s": duration_s}
    empty = dict.fromkeys(STIFF_FIELDS[6:-1], "")
    try:
        system, x0, v0 = make(kg, g, v, cc)
        if method == "explicit":  # refuse before running what would take too long
            dt = default_step(system, step_basis=step_basis)[0]
            n_pred = duration_s / dt
            if n_pred > max_steps:
                raise StepTooLargeError(
                    f"{n_pred:.3g} explicit steps (dt = {dt:.3g} s, step basis {step_basis!r}) exceed the "
                    f"study's budget of {max_steps:.3g} steps")
        t0 = time.perf_counter()
        res = ringdown(system, x0, v0, duration_s, sample_rate_hz, method, step_basis=step_basis)
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
        row.update({"status": "refused", **empty, "reason": str(exc)})
    return row


def stiff_cases(
    base: DiscreteParams | CaseFactory,
    k_g: tuple[float, ...],
    gap: tuple[float, ...],
    speed: tuple[float, ...],
    c: tuple[float, ...],
    duration_s: float,
    sample_rate_hz: float,
    methods: tuple[str, ...],
    progress=None,
    *,
    long_duration_s: float = 0.0,
    long_methods: tuple[str, ...] | None = None,
    max_steps: float = math.inf,
    step_basis: str = "top",
) -> list[dict]:
    """Run every combination; each row has a result or the reason it was refused.

    ``base`` is the three-mass model (impulse v(0) = [0, 0, speed]) or a case factory
    (:func:`rom_case`). A missed contact event would show in the energy balance: the
    sampled energy counts the penalty energy of every penetration, so a stop that was
    crossed without switching leaves E(0) != E(t) + W(t).

    With ``long_duration_s`` > 0 the nominal case (first k_g, gap ``NOMINAL_GAP``, speed
    ``NOMINAL_SPEED``) is also run that long for every c by ``long_methods`` (default
    ``methods``). Explicit runs predicted to need more than ``max_steps`` steps are refused
    without running; ``step_basis`` is the explicit integrator's (:mod:`reduced.transient.explicit`).
    Rows carry ``duration_s`` besides the :data:`STIFF_FIELDS`.
    """
    make = discrete_case(base) if isinstance(base, DiscreteParams) else base
    combos = [(kg, g, v, cc, m, duration_s) for kg, g, v, cc, m in product(k_g, gap, speed, c, methods)]
    if long_duration_s > 0:
        combos += [(k_g[0], NOMINAL_GAP, NOMINAL_SPEED, cc, m, long_duration_s)
                   for cc, m in product(c, long_methods or methods)]
    rows = []
    for i, (kg, g, v, cc, method, dur) in enumerate(combos):
        rows.append(_stiff_row(make, kg, g, v, cc, method, dur, sample_rate_hz, max_steps, step_basis))
        if progress:
            progress((i + 1) / len(combos))
    return rows


# -- the reduced model against its number of modes ------------------------------------------
def rom_convergence(
    roms: dict[int, ReducedModel],
    full_freq_hz: dict[str, np.ndarray],
    x0_points,
    v0_points,
    window_s: float,
    sample_rate_hz: float,
    n_compare: int = 4,
    repeats: int = 3,
    budget_s: float = 2.0,
    progress=None,
    step_basis: str = "top",
) -> list[dict]:
    """One row per mode count: frequency errors, ringdown error, build and run times.

    Parameters
    ----------
    roms : {n_modes: ReducedModel}, the same 3-D model reduced with n fixed-interface modes
        (``info["timing_s"]["craig_bampton"]`` is the build time reported).
    full_freq_hz : {"open", "closed": (k,) Hz}, the full model's contact-coupled frequencies.
    x0_points, v0_points : (3,) m and m/s at the points x1, x2, x3 (:func:`initial_state`).

    Frequency error = max over the first min(n_compare, n, k) modes of |f_r - f| / f (open
    and closed gap). Ringdown error = relative max-norm (:func:`relative_error`) of the
    point motion x P^T over the window against the largest mode count, all by the exact
    integrator (``explicit_ringdown_error``: the explicit run against the same reference).
    Run times are the best of ``repeats`` (fewer once ``budget_s`` is spent
    on one setting); the explicit run uses its default step for ``step_basis``.
    """
    counts = sorted(roms)
    runs, rows = {}, []
    for i, n in enumerate(counts):
        rom = roms[n]
        system = rom.system()
        x0, v0 = initial_state(rom.M, rom.K, rom.P, x0_points, v0_points)
        run = lambda method, s=system, x0=x0, v0=v0: ringdown(  # noqa: E731
            s, x0, v0, window_s, sample_rate_hz, method, step_basis=step_basis)
        if i == 0:
            run("exact"), run("explicit")  # compile the kernels before timing
        t_exact, ref = _best_of(repeats, lambda run=run: run("exact"), budget_s)
        t_expl, exp = _best_of(repeats, lambda run=run: run("explicit"), budget_s)
        row = {"n_modes": n, "n_dofs": rom.n}
        for state in ("open", "closed"):
            f_r = linear_modes(system, state).freq_hz
            f = np.asarray(full_freq_hz[state])
            k = min(n_compare, f_r.size, f.size)
            err = np.abs(f_r[:k] - f[:k]) / f[:k]
            row[f"{state}_freq_error"] = float(np.max(err))
            row[f"{state}_freq_errors"] = " ".join(f"{e:.3g}" for e in err)
        row.update({
            "n_freq_compared": k,
            "build_s": float(rom.info.get("timing_s", {}).get("craig_bampton", float("nan"))),
            "exact_s": t_exact,
            "exact_events": ref.stats.get("n_events"),
            "explicit_s": t_expl,
            "explicit_steps": exp.stats["n_steps"],
            "omega_max": exp.stats["omega_max"],
            "explicit_error": relative_error(exp.x @ rom.P.T, ref.x @ rom.P.T),
            "energy_J": float(ref.energy[0]),
        })
        runs[n] = (ref.x @ rom.P.T, exp.x @ rom.P.T)
        rows.append(row)
        if progress:
            progress((i + 1) / len(counts))
    top = runs[counts[-1]][0]
    for row in rows:
        row["ringdown_error"] = relative_error(runs[row["n_modes"]][0], top)
        row["explicit_ringdown_error"] = relative_error(runs[row["n_modes"]][1], top)
    return rows
