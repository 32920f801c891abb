"""The reference of the forced-response curves: a stepped sine by the exact integrator.

At each frequency of a sweep (up or down) the harmonic load runs from the state the previous
frequency ended in until the response is periodic (:func:`stepped_sine`), then its amplitude
is read; the HB curves of :mod:`reduced.periodic.frc` are compared with it point by point.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient.exact import ExactIntegratorError, integrate_exact
from reduced.transient.exact_tables import state_table
from reduced.transient.flow import Flow

SETTLE_ROUNDOFF = 1e-10  # relative change over a period below which the exact flow's round-off dominates
SETTLE_BLOCK_PERIODS = 8  # periods between the periodicity checks of the stepped sine (grows x2 up to 64)
RESPONSES = ("periodic", "settling", "period_2", "not_settled")
SETTLING_ERROR = 1e-3  # a response still contracting at the time limit, with a predicted error below this


@dataclass(eq=False)
class SteppedSine:
    """A stepped-sine sweep by the exact integrator: one entry per frequency, in sweep order.

    ``response``: "periodic" (settled to the load's period within the tolerance),
    "settling" (still contracting to a periodic orbit at the time limit, predicted distance
    ``settle_error`` < 1e-3), "period_2" (settled to twice the period) or "not_settled"
    (none of these within ``max_settle_s``: quasi-periodic or chaotic). ``asymmetry``:
    max |x_a - x_b| / max(|x_a|, |x_b|) over the last period for the point pair ``mirror``
    (x1, x3: zero on the symmetric orbit). ``settle_error``: the
    predicted distance of the last state from the periodic orbit (relative), from the
    period-to-period change d and its contraction rho, d rho / (1 - rho).

    Attributes
    ----------
    amplitude_N : float
        N, amplitude of the load.
    freq_hz : (k,) ndarray of float
        Hz, the frequencies in sweep order.
    point_names : tuple of str
        Names of the output points.
    amplitude_m : (k, p) ndarray of float
        m, max |x| of each point over the last period (over the last window if not settled).
    response : list of str
        'periodic', 'settling', 'period_2' or 'not_settled' per frequency.
    settle_error : (k,) ndarray of float
        Predicted relative distance of the last state from the periodic orbit.
    settle_s : (k,) ndarray of float
        s, simulated time spent at each frequency.
    asymmetry : (k,) ndarray of float
        For the ``mirror`` pair.
    wall_s : (k,) ndarray of float
        s, wall time per frequency.
    final_state : (2n,) ndarray of float
        [x; v] where the sweep ended.
    """

    amplitude_N: float
    freq_hz: np.ndarray  # (k,)
    point_names: tuple[str, ...]
    amplitude_m: np.ndarray  # (k, p) max |x| over the last period (over the last window if not settled)
    response: list  # (k,) str
    settle_error: np.ndarray  # (k,)
    settle_s: np.ndarray  # (k,) simulated time spent at each frequency
    asymmetry: np.ndarray  # (k,)
    wall_s: np.ndarray  # (k,)
    final_state: np.ndarray  # (2n,) where the sweep ended

    @property
    def settled(self) -> np.ndarray:
        return np.array([r != "not_settled" for r in self.response])


def slowest_decay_rate(system: GapSystem, load: np.ndarray | None = None) -> float:
    """1/s, the smallest -Re(lam) of the damped modes of the all-open and the closed state (those
    the load moves, modal force above 1e-9 of the largest, if ``load`` is given): the slowest
    linear transient a sweep starts decays like exp(-rate t). (A mode the load leaves
    at rest, such as a reduced beam's antisymmetric bending with a node at every dashpot,
    would otherwise set hours of settling.)

    Parameters
    ----------
    system : the gap system
    load : (n,) force direction b, or None for every mode

    Returns
    -------
    float
        1/s, > 0; an undamped mode is refused (:class:`reduced._checks.InvalidArgument`).
    """
    rates = []
    n = system.n
    Minv = np.linalg.inv(system.M)
    for K in (system.K, system.closed_stiffness()):
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ system.C]])
        lam, V = np.linalg.eig(A)
        keep = np.ones(lam.size, bool)
        if load is not None:
            # the modal force of the load on each eigenvector (left eigenvectors: rows of V^-1)
            part = np.abs(np.linalg.inv(V)[:, n:] @ (Minv @ np.asarray(load, float)))
            keep = part > 1e-9 * part.max()
        rates.append(float(np.min(-lam[keep].real)))
    rate = min(rates)
    if not rate > 0.0:
        raise _check.InvalidArgument("system must be damped for a stepped sine to settle (a linear state has a "
                                     f"mode decaying at {rate:.3g} 1/s)")
    return rate


def stepped_sine(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz, *, point_rows=None,
                 point_names=None, mirror=("x1", "x3"), settle_tol: float = 1e-6, max_settle_s: float = 10.0,
                 samples_per_period: int = 2048, y0=None, progress=None) -> SteppedSine:
    """Stepped sine by the exact flow: at each frequency (in the order given: a sweep up or down)
    the load b P cos(2 pi f t) runs from the state the previous frequency ended in (rest at the
    first, or ``y0``) until the response is periodic, then the amplitude is read.

    Settling: the state is mapped period by period with the exact forced flow
    (:class:`reduced.transient.flow.Flow`, loads included: the exact integrator's march), first
    for ln(1 / settle_tol) / sigma (sigma: :func:`slowest_decay_rate`, the time in which the
    slowest linear transient falls by ``settle_tol``), then in blocks of growing length; after
    each block the change d over one period and its contraction rate rho per period predict
    the remaining distance d rho / (1 - rho) (relative to the orbit's size); settled when it is
    below ``settle_tol`` (else twice the period is tried, else "not_settled" after
    ``max_settle_s`` of simulated time). The amplitude is then max |r . x| over one period
    sampled at ``samples_per_period`` points by the exact integrator
    (:func:`reduced.transient.exact.integrate_exact`, the load on, without its energy integrals):
    relative sampling error about (pi / samples)^2 / 2.

    Parameters
    ----------
    system : the gap system; it must be damped (:func:`slowest_decay_rate`)
    load : (n,) force direction b
    amplitude_N : N, P > 0
    freq_hz : Hz, the frequencies in sweep order
    point_rows, point_names : (p, n) output points (default: the DOFs)
    mirror : two point names whose asymmetry is reported (skipped if either is missing)
    settle_tol, max_settle_s : the settling test and the simulated time allowed per frequency
    samples_per_period : samples of the period whose amplitude is read
    y0 : (2n,) the state the sweep starts from (default: rest)
    progress : None or a callable taking the fraction of the sweep done

    Returns
    -------
    SteppedSine
        One entry per frequency, in sweep order. Arguments are checked before any work
        (one-line :class:`reduced._checks.InvalidArgument`); a failure of the exact flow is a
        RuntimeError naming the frequency.
    """
    _check.gap_system(system)
    b = _check.vector("load", load, system.n)
    P = _check.positive("amplitude_N", amplitude_N, "N")
    freqs = np.atleast_1d(_check.series("freq_hz", freq_hz))
    if np.any(freqs <= 0.0):
        raise _check.InvalidArgument("freq_hz must be > 0 Hz")
    settle_tol = _check.number("settle_tol", settle_tol, lo=0.0, hi=1.0)
    max_settle_s = _check.positive("max_settle_s", max_settle_s, "s")
    samples_per_period = _check.integer("samples_per_period", samples_per_period, lo=8)
    rows = np.eye(system.n) if point_rows is None else np.atleast_2d(np.asarray(point_rows, float))
    names = tuple(point_names or system.dof_names)
    n = system.n
    y = np.zeros(2 * n) if y0 is None else _check.vector("y0", y0, 2 * n)
    pair = [names.index(m) for m in mirror] if all(m in names for m in mirror) else None
    t_min = min(math.log(1.0 / settle_tol) / slowest_decay_rate(system, b), max_settle_s)
    out = {k: [] for k in ("amp", "resp", "err", "settle", "asym", "wall")}
    table = state_table(system)  # decomposed once for the sweep (each Flow would decompose it again: the same bits)
    for i, f in enumerate(freqs):
        t0 = time.perf_counter()
        loads = Loads(b[None, :], (Harmonic(P, float(f)),))
        flow = Flow(system, table=table, loads=loads)
        try:
            y, resp, err, t_sim = _settle(flow, y, f, t_min, settle_tol, max_settle_s)
            xp, y = _last_periods(system, loads, y, f, resp, samples_per_period, rows)
        except ExactIntegratorError as exc:
            raise RuntimeError(f"stepped sine at {f:.6g} Hz, {P:g} N: {exc}") from None
        amp = np.max(np.abs(xp), axis=0)
        asym = _asymmetry(xp[-samples_per_period - 1:], pair)
        for key, v in (("amp", amp), ("resp", resp), ("err", err), ("settle", t_sim), ("asym", asym),
                       ("wall", time.perf_counter() - t0)):
            out[key].append(v)
        if progress is not None:
            progress((i + 1) / freqs.size)
    return SteppedSine(P, freqs, names, np.array(out["amp"]), out["resp"], np.array(out["err"]),
                       np.array(out["settle"]), np.array(out["asym"]), np.array(out["wall"]), y)


def _settle(flow, y: np.ndarray, f, t_min: float, settle_tol: float, max_settle_s: float
            ) -> tuple[np.ndarray, str, float, float]:
    """(state, response, predicted error, simulated time) after mapping ``y`` period by period under
    the forced ``flow`` at ``f`` Hz until it settles (:func:`stepped_sine`): "periodic",
    "settling", "period_2" or "not_settled"."""
    n = flow.system.n
    T = 1.0 / float(f)

    def period(y, k=1):
        return flow(y[:n], y[n:], k * T).y

    t_sim, resp, err = 0.0, "not_settled", np.inf
    # first the time in which the slowest linear transient decays by settle_tol
    k0 = max(int(math.ceil(t_min * f)) - 1, 0)
    if k0:
        y = period(y, k0)
        t_sim += k0 * T
    block, d_prev, checks = 1, None, 0
    while True:
        checks += 1
        y1 = period(y)
        t_sim += T
        d = _period_change(y, y1, f, n, max(float(np.max(np.abs(y[:n]))), float(np.max(np.abs(y1[:n]))), 1e-300))
        y = y1
        if d <= SETTLE_ROUNDOFF:  # periodic to the flow's round-off
            resp, err = "periodic", d
            break
        if d_prev is not None:
            rho = (d / d_prev) ** (1.0 / block)
            err = d * rho / (1.0 - rho) if rho < 1.0 else np.inf
            if err <= settle_tol:
                resp = "periodic"
                break
        if t_sim >= max_settle_s and checks >= 3:
            break
        block = min(2 * block, SETTLE_BLOCK_PERIODS * 8)
        y = period(y, block - 1)
        t_sim += (block - 1) * T
        d_prev = d
    if resp != "periodic" and err < SETTLING_ERROR:
        resp = "settling"  # still contracting at the time limit: the error is err
    if resp == "not_settled":
        y2 = period(period(y))
        d2 = _period_change(y, y2, f, n, max(float(np.max(np.abs(y[:n]))), 1e-300))
        if d2 <= 10.0 * max(settle_tol, 1e-12) and d > 100.0 * d2:
            resp, err = "period_2", d2
    return y, resp, err, t_sim


def _period_change(y: np.ndarray, y1: np.ndarray, f, n: int, xs: float) -> float:
    """max |y1 - y| with displacements scaled by xs [m] and velocities by xs 2 pi f."""
    sc = np.concatenate([np.full(n, xs), np.full(n, xs * 2 * np.pi * f)])
    return float(np.max(np.abs(y1 - y) / sc))


def _last_periods(system: GapSystem, loads: Loads, y: np.ndarray, f, resp: str, samples_per_period: int,
                  rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points over the window read, the state at its end): one period after a settled response,
    two after a period-2 one, ten otherwise, by the exact integrator with the load on."""
    n = system.n
    T = 1.0 / float(f)
    window = 1 if resp in ("periodic", "settling") else (2 if resp == "period_2" else 10)
    # ringdown's exact method without its energy integrals (work=False: the same samples, which are all this reads)
    r = integrate_exact(system, y[:n], y[n:], window * T, samples_per_period * float(f), loads=loads, work=False)
    xp = r.x[-(window * samples_per_period + 1):] @ rows.T
    return xp, np.concatenate([r.x[-1], r.v[-1]])


def _asymmetry(xp: np.ndarray, pair: list | None) -> float:
    """max |x_a - x_b| / max(|x_a|, |x_b|) over the samples xp of the point pair (nan without one)."""
    if pair is None:
        return np.nan
    a, c = xp[:, pair[0]], xp[:, pair[1]]
    return float(np.max(np.abs(a - c)) / max(np.max(np.abs(a)), np.max(np.abs(c)), 1e-300))


__all__ = ["RESPONSES", "SteppedSine", "slowest_decay_rate", "stepped_sine"]
