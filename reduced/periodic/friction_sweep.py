"""Exact friction orbits on a grid of frequencies: Newton at each fixed frequency with the exact Jacobian.

Where the continued branches (:mod:`reduced.periodic.friction_continuation`) leave parts of the contact band
uncovered (in contact a branch advances 0.02-0.04 Hz a point between folds), the orbits are shot at fixed
frequencies f_j of a grid instead: at each, Newton on the multiple-shooting equations of
:mod:`reduced.periodic.friction_shooting` (S nodes y_k = [x; v; w] at t_k = k T / S, unknowns z = [x; v; d],
d = Bt x - w, residual in units of D)

    G(z; f_j) = (phi(y_k; t_k, T / S) - y_{k+1}) / D = 0,

each step the minimum-norm least-squares solution of dG/dz dz = -G (a slider open or stuck the whole period leaves
a null direction), dG/dz **exact** (:meth:`reduced.periodic.friction_continuation._Continuation.blocks`: the state
transition matrices and the saltation matrix at every stick, slip and gap event), the step halved while ||G||_2
does not fall (at most ``MAX_HALVINGS`` times). The starts, in order: the orbit at the grid's previous frequency
extrapolated linearly from the two before it (where they are the grid's last two points), else that orbit itself;
then, where Newton does not converge from it in ``MAX_ITER`` steps, the caller's start at f_j (e.g. the HB orbit
there, :func:`reduced.periodic.friction_shooting.hb_nodes`). Each converged orbit's Floquet multipliers from the
exact monodromy (its stability), its amplitudes from the flow sampled ``SAMPLES_PER_SEGMENT`` a segment.

A grid point where neither start converges is reported as such (its defect): past a fold the orbit of the
previous frequency has no continuation at the next, and a start far from every orbit (HB not converged in H) does
not converge either; the grid is a sample of the band, one orbit a frequency (where several coexist, the one
Newton reaches).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from reduced import _checks as _check
from reduced.periodic.friction_continuation import SAMPLES_PER_SEGMENT, _Continuation
from reduced.periodic.friction_shooting import RANK_RTOL, STABLE_TOL, FrictionShootingResult
from reduced.transient.exact import ExactIntegratorError

TOL = 1e-10  # max |G| in units of D at a converged orbit (as the continuation's)
MAX_ITER = 8  # Newton steps from each start (measured on discrete-friction-frc: 2-6 where it converges from the
# previous frequency's orbit 0.1 Hz away, 7-11 from far; a start that needs more is past a fold)
MAX_HALVINGS = 3  # halvings of a step before the start is given up
MAX_FAIL = 3  # frequencies in a row without an orbit that end a sweep (measured on discrete-friction-frc above 21 Hz:
# neither the previous orbit nor HB's (not converged in H there) converges over 21-26 and 27-30 Hz, 0.2-1.5 s of
# CPU a frequency)


@dataclass(eq=False)
class FrictionSweep:
    """Exact friction orbits at fixed frequencies (:func:`sweep_friction`).

    Attributes
    ----------
    freq_hz : (k,) Hz, the grid
    converged : (k,) bool
    start : (k,) str, the start Newton converged from: "previous", "given" or "" (none)
    nodes : (k, S, 2n + p) the orbits' states [x; v; w] at t_j = j T / S (NaN where not converged)
    amplitude_m : (k, q) m, max |x| over the period at the output points (NaN where not converged)
    multipliers : (k, 2n + p) complex Floquet multipliers (NaN where not converged)
    stable : (k,) bool, max |mu| <= 1 + STABLE_TOL
    defect : (k,) max |G| reached, units of D
    n_iter : (k,) Newton steps, both starts together
    cpu_s : s of CPU time of the sweep
    step_hz, max_iter, max_fail : the sweep's rule (:func:`sweep_friction`)
    """

    freq_hz: np.ndarray
    converged: np.ndarray
    start: np.ndarray
    nodes: np.ndarray
    amplitude_m: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    defect: np.ndarray
    n_iter: np.ndarray
    cpu_s: float = 0.0
    step_hz: float = math.nan
    max_iter: int = MAX_ITER
    max_fail: int = MAX_FAIL


def newton_at(cont: _Continuation, z0: np.ndarray, f: float, tol: float = TOL,
              max_iter: int = MAX_ITER) -> tuple[bool, np.ndarray, float, int, tuple]:
    """(converged, z / D, max |G|, steps, (res, Y, blocks at z)): Newton at fixed f from z0 / D (module docstring);
    ``blocks`` None unless converged.

    Parameters
    ----------
    cont : the friction continuation's residual (its G at [z; f])
    z0 : (N,) the start, in units D
    f : Hz, the fixed load frequency
    tol : max |G| at convergence
    max_iter : Newton steps at most
    """
    z = np.asarray(z0, float).copy()
    it = 0
    try:
        G, res, Y, _ = cont.G(np.concatenate([z, [f]]))
        r = float(np.max(np.abs(G)))
        for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
            if r <= tol:
                return True, z, r, it - 1, (res, Y, cont.blocks(f, Y))
            dz = np.linalg.lstsq(res.jacobian(cont.blocks(f, Y)), -G, rcond=RANK_RTOL)[0]
            lam, norm = 1.0, float(np.linalg.norm(G))
            for _ in range(MAX_HALVINGS + 1):
                Gt, rt, Yt, _ = cont.G(np.concatenate([z + lam * dz, [f]]))
                if float(np.linalg.norm(Gt)) < norm:
                    break
                lam *= 0.5
            else:
                return False, z, r, it, (res, Y, None)
            z, G, res, Y = z + lam * dz, Gt, rt, Yt
            r = float(np.max(np.abs(G)))
        if r <= tol:
            return True, z, r, it, (res, Y, cont.blocks(f, Y))
    except (ExactIntegratorError, np.linalg.LinAlgError, ValueError):
        return False, z, math.inf, it, (None, None, None)
    return False, z, r, it, (res, Y, None)


def sweep_friction(like: FrictionShootingResult, f_from: float, f_to: float, step: float, *,
                   max_step: float | None = None, max_fail: int = MAX_FAIL, first: np.ndarray | None = None,
                   given=None, point_rows: np.ndarray | None = None, tol: float = TOL,
                   max_iter: int = MAX_ITER) -> FrictionSweep:
    """The exact friction orbits at frequencies from f_from towards f_to (module docstring): f_from, then each
    ``step`` beyond the last; after a frequency where no start converges the next is twice as far (up to
    ``max_step``), after one that converges ``step`` again; the sweep ends past f_to or after ``max_fail``
    frequencies in a row where no start converges (the CPU of a stretch with no orbit near the starts, past a fold,
    bounded).

    Parameters
    ----------
    like : FrictionShootingResult
        An orbit of the system and load (its system, load, phase, S and scale D are used; its nodes are the first
        frequency's start unless ``first`` is given).
    f_from, f_to : Hz, the stretch swept, either way (f_to included where the grid reaches it)
    step : Hz, the grid's step (> 0; measured on discrete-friction-frc: 0.05-0.1 Hz march well between folds)
    max_step : Hz, the step's bound after failures (default 4 ``step``)
    max_fail : frequencies in a row without an orbit that end the sweep
    first : (S, 2n + p) the first frequency's start [x; v; w] (default ``like.nodes``)
    given : callable, optional
        ``given(f) -> (S, 2n + p) nodes or None``: the second start at f where the previous orbit's fails
    point_rows : (q, n) the output points' rows (default every DOF)
    tol : max |G| at a converged orbit, units of D
    max_iter : Newton steps from each start

    Returns
    -------
    FrictionSweep
    """
    c0 = time.process_time()
    f_from = _check.positive("f_from", f_from, "Hz")
    f_to = _check.positive("f_to", f_to, "Hz")
    step = _check.positive("step", step, "Hz")
    sgn = 1.0 if f_to >= f_from else -1.0
    max_step = 4.0 * step if max_step is None else _check.positive("max_step", max_step, "Hz")
    system = like.system
    n = system.n
    rows = np.eye(n) if point_rows is None else np.asarray(point_rows, float)
    S, N = like.nodes.shape
    D = like.scale
    cont = _Continuation(system, like.b, like.amplitude_N, like.phase_deg, S, D, like.periods)
    res0 = cont.res(f_from)
    prev: list = [(None, math.nan, (res0.z_of(like.nodes if first is None else first) / D).ravel())]
    rows_out: list = []
    f, h, fails = f_from, step, 0
    while sgn * (f - f_to) <= 1e-12 * f_to and fails < max_fail:
        j = len(rows_out)
        zp = prev[-1][2]
        if len(prev) >= 2 and prev[-2][0] == j - 2 and prev[-1][0] == j - 1:  # the grid's last two: extrapolated
            zp = prev[-1][2] + (f - prev[-1][1]) / (prev[-1][1] - prev[-2][1]) * (prev[-1][2] - prev[-2][2])
        ok, z, r, it, (res, Y, blocks) = newton_at(cont, zp, f, tol, max_iter)
        row = {"f": f, "ok": ok, "start": "previous" if ok else "", "it": it}
        if not ok and given is not None:
            g = given(f)
            if g is not None:
                ok, z, r2, it2, (res, Y, blocks) = newton_at(cont, (cont.res(f).z_of(g) / D).ravel(), f, tol,
                                                             max_iter)
                row["it"] += it2
                r = min(r, r2)
                row.update(ok=ok, start="given" if ok else "")
        row["defect"] = r
        if ok:
            prev.append((j, f, z))
            mu = np.linalg.eigvals(cont.monodromy(res, blocks))
            hs = like.periods / f / S
            xs = np.vstack([cont.flows(f, Y[m], m * hs, hs, SAMPLES_PER_SEGMENT, like.phase_deg)[:, :n]
                            for m in range(S)])
            row.update(Y=Y, mu=mu, amp=np.max(np.abs(xs @ rows.T), axis=0))
        rows_out.append(row)
        h = step if ok else min(2.0 * h, max_step)
        fails = 0 if ok else fails + 1
        f = f + sgn * h
    k = len(rows_out)
    out = FrictionSweep(np.array([w["f"] for w in rows_out]), np.array([w["ok"] for w in rows_out], bool),
                        np.array([w["start"] for w in rows_out], dtype=object), np.full((k, S, N), np.nan),
                        np.full((k, rows.shape[0]), np.nan), np.full((k, N), np.nan, complex), np.zeros(k, bool),
                        np.array([w["defect"] for w in rows_out]), np.array([w["it"] for w in rows_out], int),
                        step_hz=step, max_iter=max_iter, max_fail=max_fail)
    for j, w in enumerate(rows_out):
        if w["ok"]:
            out.nodes[j], out.multipliers[j], out.amplitude_m[j] = w["Y"], w["mu"], w["amp"]
            out.stable[j] = bool(np.max(np.abs(w["mu"])) <= 1.0 + STABLE_TOL)
    out.cpu_s = time.process_time() - c0
    return out


__all__ = ["FrictionSweep", "newton_at", "sweep_friction"]
