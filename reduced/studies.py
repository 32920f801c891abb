"""Accuracy studies of the ringdown integrators: work-precision, stiff/extreme cases, and
the reduced model's convergence with its number of fixed-interface modes.

Every public function checks its arguments before any work and raises
:class:`reduced._checks.InvalidArgument` (a :class:`ValueError`, as in the rest of
:mod:`reduced`) with one line naming the function, the argument, the value given and what is allowed
(a NaN, a negative stiffness, an empty list, a tolerance >= 1 or a number given as a bool
or a string never reaches a solver). Results hold no wall-clock time except in the
``runtime_s``/``*_s`` timing entries that :mod:`bearingshaft.stages.study` writes to
``*_timing.*`` files, so a rerun reproduces the science files byte for byte.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from itertools import product
from numbers import Integral, Real

import numpy as np

from reduced._checks import InvalidArgument
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.initial import initial_state
from reduced.models.modes import linear_modes
from reduced.models.rom import ReducedModel, RomSpec
from reduced.transient.dop853 import integrate_dop853
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.explicit import STEP_BASES, SWITCHING_SAFETY, StepTooLargeError, default_step
from reduced.transient.integrate import METHODS, ringdown

MAX_SAMPLES = 10_000_000  # samples of one study run (window x rate): 0.05 s at 20 kHz is 1000
EXPLICIT_OMEGA_DT_MAX = 2.0 * SWITCHING_SAFETY  # rad: the explicit integrator refuses larger steps


# -- argument checks: one line naming the function, the argument, its value and what is allowed --
def _show(value) -> str:
    text = np.array2string(value, threshold=8) if isinstance(value, np.ndarray) else repr(value)
    text = " ".join(text.split())
    return text if len(text) <= 80 else text[:77] + "..."


def _refuse(func: str, name: str, value, allowed: str) -> InvalidArgument:
    """The one-line refusal (reduced._checks.InvalidArgument, a ValueError) naming function, argument, value."""
    return InvalidArgument(f"{func}: {name} = {_show(value)} is not allowed; {allowed}")


def _is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def _number(func: str, name: str, value, allowed: str, ok=lambda v: True, finite: bool = True) -> float:
    """A real number (not a bool or a string), finite unless ``finite`` is False, with ``ok(value)``."""
    if not _is_number(value) or math.isnan(value) or (finite and math.isinf(value)) or not ok(float(value)):
        raise _refuse(func, name, value, allowed)
    return float(value)


def _positive(func: str, name: str, value, unit: str = "") -> float:
    return _number(func, name, value, f"must be a finite number > 0{unit}", lambda v: v > 0)


def _count(func: str, name: str, value, minimum: int = 1) -> int:
    if not isinstance(value, Integral) or isinstance(value, bool) or value < minimum:
        raise _refuse(func, name, value, f"must be an integer >= {minimum}")
    return int(value)


def _numbers(func: str, name: str, values, allowed: str, ok, min_len: int = 1) -> tuple[float, ...]:
    """A non-empty list/tuple/1-D array of finite numbers each satisfying ``ok``."""
    if isinstance(values, np.ndarray) and values.ndim == 1:
        values = values.tolist()
    if not isinstance(values, (list, tuple)):
        raise _refuse(func, name, values, f"must be a list of numbers {allowed}")
    if len(values) < min_len:
        raise _refuse(func, name, values, f"needs at least {min_len} value{'s' if min_len > 1 else ''} {allowed}")
    for i, v in enumerate(values):
        _number(func, f"{name}[{i}]", v, f"each must be a finite number {allowed}", ok)
    return tuple(float(v) for v in values)


def _choices(func: str, name: str, values, allowed: tuple[str, ...]) -> tuple[str, ...]:
    what = f"must be a non-empty list of distinct names from {', '.join(allowed)}"
    if not isinstance(values, (list, tuple)) or not values or len(set(values)) != len(values):
        raise _refuse(func, name, values, what)
    for i, v in enumerate(values):
        if v not in allowed:
            raise _refuse(func, f"{name}[{i}]", v, f"must be one of {', '.join(allowed)}")
    return tuple(values)


def _choice(func: str, name: str, value, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise _refuse(func, name, value, f"must be one of {', '.join(allowed)}")
    return value


def _vector(func: str, name: str, value, n: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise _refuse(func, name, value, f"must be {n} finite numbers") from None
    if a.shape != (n,) or not np.all(np.isfinite(a)) or isinstance(value, (str, bytes)) or (
            isinstance(value, (list, tuple)) and any(isinstance(v, bool) for v in value)):
        raise _refuse(func, name, value, f"must be {n} finite numbers")
    return a


def _callable_or_none(func: str, name: str, value) -> None:
    if value is not None and not callable(value):
        raise _refuse(func, name, value, "must be None or a callable taking the fraction done")


def _samples(func: str, duration_s: float, sample_rate_hz: float, what: str = "duration_s") -> None:
    n = duration_s * sample_rate_hz
    if n < 1:
        raise _refuse(func, "sample_rate_hz", sample_rate_hz,
                      f"{what} x sample_rate_hz must give at least one sample after t = 0 ({what} = {duration_s:g} s)")
    if n > MAX_SAMPLES:
        raise _refuse(func, "sample_rate_hz", sample_rate_hz,
                      f"{what} x sample_rate_hz must be <= {MAX_SAMPLES:.0e} samples ({what} = {duration_s:g} s "
                      f"gives {n:.3g}); lower the rate or the duration")


def relative_error(x: np.ndarray, x_ref: np.ndarray) -> float:
    """max over samples and DOFs of |x - x_ref|, over max |x_ref| (relative max-norm).

    ``x`` may hold NaN (a run that failed shows as NaN); ``x_ref`` must be finite, not all
    zero, and of the same shape.

    Parameters
    ----------
    x : array_like of float
        The values compared (NaN allowed).
    x_ref : array_like of float
        The reference, same shape.

    Returns
    -------
    float
        max |x - x_ref| / max |x_ref| (NaN if x holds NaN).

    Raises
    ------
    InvalidArgument
        Shapes that differ, an empty x, or an x_ref not finite or all zero.
    """
    x, x_ref = np.asarray(x, dtype=float), np.asarray(x_ref, dtype=float)
    if x.shape != x_ref.shape or x.size == 0:
        raise _refuse("relative_error", "x", x, f"must be non-empty and have the shape of x_ref {x_ref.shape}")
    scale = np.max(np.abs(x_ref))
    if not np.isfinite(scale) or scale == 0:
        raise _refuse("relative_error", "x_ref", x_ref, "must be finite and not all zero (it scales the error)")
    return float(np.max(np.abs(x - x_ref)) / scale)


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
    """Slope of log(err) against log(h) over the points with lo < err < hi (asymptotic range).

    NaN when fewer than two points lie in that range (the arguments were valid, but the
    steps never reached the asymptotic range: the caller says so).

    Parameters
    ----------
    h : (k,) sequence of float
        The steps, > 0, at least two.
    err : (k,) array_like of float
        The error at each step, >= 0 (NaN for a failed run).
    lo, hi : float
        The asymptotic range of the error, 0 < lo < hi.

    Returns
    -------
    float
        The fitted order (least-squares slope), or NaN.

    Raises
    ------
    InvalidArgument
        lo or hi out of range, fewer than two steps or a step <= 0, or errors not one per step,
        negative or infinite.
    """
    func = "fit_order"
    lo = _number(func, "lo", lo, "must be a finite number > 0", lambda v: v > 0)
    hi = _number(func, "hi", hi, f"must be a finite number > lo = {lo:g}", lambda v: v > lo)
    h = np.asarray(_numbers(func, "h", h, "> 0", lambda v: v > 0, min_len=2))
    try:
        err = np.asarray(err, dtype=float)
    except (TypeError, ValueError):
        raise _refuse(func, "err", err, f"must be {h.size} numbers >= 0 (NaN for a failed run)") from None
    if err.shape != h.shape or np.any(err < 0) or np.any(np.isinf(err)):
        raise _refuse(func, "err", err, f"must be {h.size} numbers >= 0, one per step h (NaN for a failed run)")
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

    Arguments are checked first (ValueError, one line): ``window_s`` and ``sample_rate_hz``
    > 0 with 1 to ``MAX_SAMPLES`` samples, at least two distinct ``explicit_omega_dt`` in
    (0, ``EXPLICIT_OMEGA_DT_MAX``], ``dop853_rtol`` in (0, 1) (at rtol >= 1 DOP853 controls
    no digit), ``repeats`` >= 1, x0 and v0 finite with one value per DOF, not both zero.

    Parameters
    ----------
    system : the gap system run
    x0, v0 : (n,) m and m/s, its initial state
    window_s, sample_rate_hz : s and Hz of each run
    explicit_omega_dt : rad, the explicit steps as omega_max dt
    dop853_rtol : DOP853's relative tolerances (may be empty)
    repeats : runs timed per setting, the best kept (one for DOP853)
    progress : None or a callable taking the fraction done

    Returns
    -------
    rows, order : list of dict, float
        Rows ``method``, ``setting``, ``runtime_s`` (s), ``error`` (relative max-norm against the
        exact run; the exact run's against DOP853 with events), ``n_steps``, and ``dt`` (s) for the
        explicit rows; the explicit method's fitted order (:func:`fit_order`, NaN outside its range).
    """
    func = "work_precision"
    if not isinstance(system, GapSystem):
        raise _refuse(func, "system", system, "must be a reduced.GapSystem")
    v0_given = v0
    x0, v0 = _vector(func, "x0", x0, system.n), _vector(func, "v0", v0, system.n)
    if not (np.any(x0) or np.any(v0)):
        raise _refuse(func, "v0", v0_given, "x0 and v0 must not both be zero (the error is relative to the motion)")
    window_s = _positive(func, "window_s", window_s, " s")
    sample_rate_hz = _positive(func, "sample_rate_hz", sample_rate_hz, " Hz")
    _samples(func, window_s, sample_rate_hz, "window_s")
    explicit_omega_dt = _numbers(func, "explicit_omega_dt", explicit_omega_dt,
                                 f"in (0, {EXPLICIT_OMEGA_DT_MAX:g}] rad (central difference is unstable past 2)",
                                 lambda v: 0 < v <= EXPLICIT_OMEGA_DT_MAX, min_len=2)
    if len(set(explicit_omega_dt)) < 2:
        raise _refuse(func, "explicit_omega_dt", explicit_omega_dt, "needs two distinct steps to fit an order")
    dop853_rtol = _numbers(func, "dop853_rtol", dop853_rtol,
                           "in (0, 1) (a relative tolerance >= 1 controls no digit)", lambda v: 0 < v < 1, min_len=0)
    repeats = _count(func, "repeats", repeats)
    _callable_or_none(func, "progress", progress)
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
    """Cases of the three-mass model: v(0) = [0, 0, speed] on its coordinates.

    Parameters
    ----------
    base : DiscreteParams
        The model; each case replaces its k_g, g and c.

    Returns
    -------
    callable
        ``make(k_g, gap, speed, c) -> (system, x0, v0)``, N/m, m, m/s, N s/m.

    Raises
    ------
    InvalidArgument
        ``base`` not a DiscreteParams.
    """
    if not isinstance(base, DiscreteParams):
        raise _refuse("discrete_case", "base", base, "must be a reduced.DiscreteParams")

    def make(k_g: float, gap: float, speed: float, c: float):
        system = replace(base, k_g=k_g, gap=gap, c=c).system()
        return system, np.zeros(3), np.array([0.0, 0.0, speed])

    return make


def rom_case(rom: ReducedModel, spec: RomSpec) -> CaseFactory:
    """Cases of a reduced model: the dashpots c at x1, x2, x3 (``c_points``), v(x3) = speed.

    The velocity is given at the points and realized in the three lowest open-gap modes
    (:func:`reduced.models.initial.initial_state`), which do not depend on the contact, so the
    unit-speed state is formed once and scaled.

    Parameters
    ----------
    rom : ReducedModel
        The reduced model.
    spec : RomSpec
        Its specification; each case replaces its k_g, gap and c_points.

    Returns
    -------
    callable
        ``make(k_g, gap, speed, c) -> (system, x0, v0)``, N/m, m, m/s, N s/m (x0 = 0).

    Raises
    ------
    InvalidArgument
        ``rom`` or ``spec`` of the wrong type.
    """
    if not isinstance(rom, ReducedModel):
        raise _refuse("rom_case", "rom", rom, "must be a reduced.ReducedModel")
    if not isinstance(spec, RomSpec):
        raise _refuse("rom_case", "spec", spec, "must be a reduced.RomSpec")
    _, v_unit = initial_state(rom.M, rom.K, rom.P, np.zeros(3), np.array([0.0, 0.0, 1.0]))

    def make(k_g: float, gap: float, speed: float, c: float):
        system = rom.with_contact(replace(spec, k_g=k_g, gap=gap, c_points=c)).system()
        return system, np.zeros(rom.n), speed * v_unit

    return make


def _stiff_row(make: CaseFactory, kg: float, g: float, v: float, cc: float, method: str, duration_s: float,
               sample_rate_hz: float, max_steps: float, step_basis: str = "top", progress=None) -> dict:
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
        res = ringdown(system, x0, v0, duration_s, sample_rate_hz, method, step_basis=step_basis,
                       progress=progress)
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

    ``progress`` is called with the fraction done, also inside each run (the integrator
    reports its chunks), so a long case moves the bar instead of stalling it; if it has a
    ``describe`` method, that is called with a short label of the case being run.

    Arguments are checked first (ValueError, one line): k_g > 0, gap >= 0, speed != 0
    (the energy balance is relative to E(0)), c >= 0, each a non-empty list of finite
    numbers; duration_s and sample_rate_hz > 0 with 1 to ``MAX_SAMPLES`` samples a run;
    methods (and long_methods) non-empty lists from :data:`reduced.transient.integrate.METHODS`;
    long_duration_s >= 0; max_steps > 0 (inf allowed); step_basis "top" or "contact".

    Parameters
    ----------
    base : DiscreteParams or a case factory ``make(k_g, gap, speed, c) -> (system, x0, v0)``
    k_g, gap, speed, c : N/m, m, m/s, N s/m: the values combined (every combination is run)
    duration_s, sample_rate_hz : s and Hz of each run
    methods : the integrators run on every case
    progress : None or a callable taking the fraction done (above)
    long_duration_s, long_methods : s, the long nominal runs (0: none), and their integrators
    max_steps : most steps an explicit run may take
    step_basis : the explicit integrator's step basis

    Returns
    -------
    list of dict
        One row per run: the :data:`STIFF_FIELDS` and ``duration_s``.
    """
    func = "stiff_cases"
    if isinstance(base, DiscreteParams):
        make = discrete_case(base)
    elif callable(base):
        make = base
    else:
        raise _refuse(func, "base", base, "must be a reduced.DiscreteParams or a case factory (rom_case)")
    k_g = _numbers(func, "k_g", k_g, "> 0 N/m", lambda v: v > 0)
    gap = _numbers(func, "gap", gap, ">= 0 m", lambda v: v >= 0)
    speed = _numbers(func, "speed", speed, "!= 0 m/s (the energy balance is relative to E(0))", lambda v: v != 0)
    c = _numbers(func, "c", c, ">= 0 N s/m", lambda v: v >= 0)
    duration_s = _positive(func, "duration_s", duration_s, " s")
    sample_rate_hz = _positive(func, "sample_rate_hz", sample_rate_hz, " Hz")
    _samples(func, duration_s, sample_rate_hz)
    methods = _choices(func, "methods", methods, METHODS)
    long_duration_s = _number(func, "long_duration_s", long_duration_s, "must be a finite number >= 0 s (0: none)",
                              lambda v: v >= 0)
    if long_duration_s > 0:
        _samples(func, long_duration_s, sample_rate_hz, "long_duration_s")
    if long_methods is not None:
        long_methods = _choices(func, "long_methods", long_methods, METHODS)
    max_steps = _number(func, "max_steps", max_steps, "must be a number > 0 (inf: no budget)", lambda v: v > 0,
                        finite=False)
    step_basis = _choice(func, "step_basis", step_basis, STEP_BASES)
    _callable_or_none(func, "progress", progress)

    combos = [(kg, g, v, cc, m, duration_s) for kg, g, v, cc, m in product(k_g, gap, speed, c, methods)]
    if long_duration_s > 0:
        combos += [(k_g[0], NOMINAL_GAP, NOMINAL_SPEED, cc, m, long_duration_s)
                   for cc, m in product(c, long_methods or methods)]
    describe = getattr(progress, "describe", None)
    rows = []
    for i, (kg, g, v, cc, method, dur) in enumerate(combos):
        if describe:
            describe(f"{method}, k_g={kg:.3g}, g={g:.3g}, v={v:.3g}, c={cc:.3g}, {dur:g} s")
        inner = (lambda f, i=i: progress((i + f) / len(combos))) if progress else None
        rows.append(_stiff_row(make, kg, g, v, cc, method, dur, sample_rate_hz, max_steps, step_basis, inner))
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
    window_s, sample_rate_hz : s and Hz of each ringdown.
    n_compare : frequencies compared per state (below).
    repeats, budget_s : runs timed per setting, and s spent on one setting (below).
    progress : None or a callable taking the fraction done.
    step_basis : "top" or "contact", the explicit run's step basis.

    Frequency error = max over the first min(n_compare, n, k) modes of |f_r - f| / f (open
    and closed gap). Ringdown error = relative max-norm (:func:`relative_error`) of the
    point motion x P^T over the window against the largest mode count, all by the exact
    integrator (``explicit_ringdown_error``: the explicit run against the same reference).
    Run times are the best of ``repeats`` (fewer once ``budget_s`` is spent
    on one setting); the explicit run uses its default step for ``step_basis``.

    Arguments are checked first (ValueError, one line): at least two mode counts (the
    largest is the reference), each an integer >= 0 mapped to a ReducedModel; full_freq_hz
    with "open" and "closed" arrays of positive frequencies; three finite point values in
    x0_points and v0_points, not all zero; window_s, sample_rate_hz > 0 with 1 to
    ``MAX_SAMPLES`` samples; n_compare, repeats >= 1; budget_s > 0 (inf allowed).

    Returns
    -------
    list of dict
        Per mode count, ascending: ``n_modes``, ``n_dofs``, ``open_freq_error`` and
        ``closed_freq_error`` (with the per-mode ``*_freq_errors``), ``n_freq_compared``,
        ``build_s``, ``exact_s``, ``exact_events``, ``explicit_s``, ``explicit_steps``,
        ``omega_max``, ``explicit_error``, ``energy_J``, ``ringdown_error`` and
        ``explicit_ringdown_error``.
    """
    x0_points, v0_points, window_s, sample_rate_hz, n_compare, repeats, budget_s, step_basis = (
        _rom_convergence_args(roms, full_freq_hz, x0_points, v0_points, window_s, sample_rate_hz, n_compare,
                              repeats, budget_s, progress, step_basis))
    counts = sorted(roms)
    runs, rows = {}, []
    for i, n in enumerate(counts):
        rom = roms[n]
        row, runs[n] = _rom_convergence_row(n, rom, full_freq_hz, x0_points, v0_points, window_s, sample_rate_hz,
                                            n_compare, repeats, budget_s, step_basis, compile_first=i == 0)
        rows.append(row)
        if progress:
            progress((i + 1) / len(counts))
    top = runs[counts[-1]][0]
    for row in rows:
        row["ringdown_error"] = relative_error(runs[row["n_modes"]][0], top)
        row["explicit_ringdown_error"] = relative_error(runs[row["n_modes"]][1], top)
    return rows


def _rom_convergence_args(roms, full_freq_hz, x0_points, v0_points, window_s, sample_rate_hz, n_compare, repeats,
                          budget_s, progress, step_basis) -> tuple:
    """The arguments of :func:`rom_convergence`, checked (one-line ValueError) and converted:
    (x0_points, v0_points, window_s, sample_rate_hz, n_compare, repeats, budget_s, step_basis)."""
    func = "rom_convergence"
    if not isinstance(roms, dict) or len(roms) < 2:
        raise _refuse(func, "roms", roms, "must be a dict {n_modes: ReducedModel} with at least two mode counts "
                      "(the largest is the reference)")
    for n, rom in roms.items():
        if not isinstance(n, Integral) or isinstance(n, bool) or n < 0:
            raise _refuse(func, "roms key", n, "mode counts must be integers >= 0")
        if not isinstance(rom, ReducedModel):
            raise _refuse(func, f"roms[{n}]", rom, "must be a reduced.ReducedModel")
    if not isinstance(full_freq_hz, dict):
        raise _refuse(func, "full_freq_hz", full_freq_hz, 'must be a dict with "open" and "closed" frequencies [Hz]')
    for state in ("open", "closed"):
        _numbers(func, f"full_freq_hz[{state!r}]", full_freq_hz.get(state), "> 0 Hz", lambda v: v > 0)
    v0_given = v0_points
    x0_points = _vector(func, "x0_points", x0_points, 3)
    v0_points = _vector(func, "v0_points", v0_points, 3)
    if not (np.any(x0_points) or np.any(v0_points)):
        raise _refuse(func, "v0_points", v0_given, "x0_points and v0_points must not both be zero")
    window_s = _positive(func, "window_s", window_s, " s")
    sample_rate_hz = _positive(func, "sample_rate_hz", sample_rate_hz, " Hz")
    _samples(func, window_s, sample_rate_hz, "window_s")
    n_compare = _count(func, "n_compare", n_compare)
    repeats = _count(func, "repeats", repeats)
    budget_s = _number(func, "budget_s", budget_s, "must be a number > 0 s (inf: no budget)", lambda v: v > 0,
                       finite=False)
    step_basis = _choice(func, "step_basis", step_basis, STEP_BASES)
    _callable_or_none(func, "progress", progress)
    return x0_points, v0_points, window_s, sample_rate_hz, n_compare, repeats, budget_s, step_basis


def _rom_convergence_row(n: int, rom: ReducedModel, full_freq_hz: dict, x0_points: np.ndarray,
                         v0_points: np.ndarray, window_s: float, sample_rate_hz: float, n_compare: int,
                         repeats: int, budget_s: float, step_basis: str, compile_first: bool
                         ) -> tuple[dict, tuple[np.ndarray, np.ndarray]]:
    """One mode count of :func:`rom_convergence`: its row (without the ringdown errors, which need the
    reference) and the point motion x P^T of its exact and explicit runs."""
    system = rom.system()
    x0, v0 = initial_state(rom.M, rom.K, rom.P, x0_points, v0_points)
    run = lambda method, s=system, x0=x0, v0=v0: ringdown(  # noqa: E731
        s, x0, v0, window_s, sample_rate_hz, method, step_basis=step_basis)
    if compile_first:
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
    return row, (ref.x @ rom.P.T, exp.x @ rom.P.T)
