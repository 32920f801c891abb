"""The misfit's profile along each parameter: how far the intervals reach where the local planes cannot see.

The local intervals (:mod:`bearingshaft.identify.fit`: the sandwich on the planes' slopes over a
cloud within -+ CLOUD_STEPS finite-difference steps) hold where the misfit is a paraboloid at
that scale. Past the first impacts it is not: the apparatus' hammer test
(benchmarks/identify_speed.py) gives a misfit whose first-impact block is a long narrow valley
in (gap, k_g) (a larger gap is fitted as well with a stiffer contact: along the valley floor the
block changes by less than its scatter from k_g = 5e7 to 6.6e7) and whose envelope and impact
blocks vary with the parameters only as a new realisation of the chaos would. The planes'
slopes in those blocks are then the chaos over the cloud's width, which J^T J counts as
information (over a 13-run cloud of -+3 % about as much as the slopes' own noise: n_eff_b
(X_c^T X_c)^-1 for a block of n_eff_b unit-scatter residuals, X_c the cloud's centred points),
and the least squares stop wherever the scan put them on the valley floor: the fit's k_g was
6.6e7 or 5.7e7, its 95 % interval -+5 % about it, for a test made with 5e7, with the 40-mode
fit model and with the test's own 120 modes alike.

So each parameter's interval is checked by its profile (:func:`profile`): probes at
PROFILE_MULTIPLES times its local half-width on either side, each moved onto the valley floor
(the other parameters by the local planes' regression of theta_j's column on theirs, then one
Gauss-Newton step in them from finite differences at the probe, the lower of the two kept).
A probe whose cost exceeds the optimum's by at most chi2_{confidence, p} s^2 is one the test
cannot reject against the optimum (the criterion of the rival minima,
:func:`bearingshaft.identify.fit.rival_minima`), and every interval reaches it
(:func:`reach`): towards the first probe rejected beyond it, linearly in the cost excess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bearingshaft.identify.residuals import stacked

PROFILE_MULTIPLES = (1.0, 2.0, 3.0, 5.0, 8.0)  # probes at these multiples of a parameter's local half-width


@dataclass(frozen=True, eq=False)
class Probe:
    """One point of a parameter's profile.

    Attributes
    ----------
    index : int
        The profiled parameter's position.
    side : int
        -1 or +1.
    multiple : float
        Of its local half-width.
    theta : (p,) ndarray of float
        Where (the others on the valley floor).
    excess : float
        Its cost less the optimum's (the fit's final weights).
    accepted : bool
        excess <= the limit.
    """

    index: int
    side: int
    multiple: float
    theta: np.ndarray
    excess: float
    accepted: bool


def conditional_slopes(J: np.ndarray, j: int, others: list[int]) -> np.ndarray:
    """d theta_o / d theta_j along the local valley floor: minus the regression of J's column j on the others'.

    Parameters
    ----------
    J : (N, p) ndarray of float
        The weighted Jacobian.
    j : int
    others : list of int

    Examples
    --------
    >>> J = np.array([[1.0, 2.0], [0.0, 0.0]])  # one residual: theta_0 + 2 theta_1 fixed
    >>> conditional_slopes(J, 1, [0]).tolist()
    [-2.0]
    """
    if not others:
        return np.zeros(0)
    return -np.linalg.lstsq(J[:, others], J[:, j], rcond=None)[0]


def _cost(runs, ev) -> float:
    r = stacked(ev.blocks, runs.weights)
    return float(r @ r)


def profile(runs, theta: np.ndarray, J: np.ndarray, half: np.ndarray, seen: np.ndarray, cost0: float,
            limit: float) -> list[Probe]:
    """The probes of every seen parameter's profile (module docstring), in three batches of runs.

    Long because the three batches (the probes on the regression line, their finite-difference neighbours
    in the other parameters, the Gauss-Newton points) share their bookkeeping; each step is a few lines.

    Parameters
    ----------
    runs : bearingshaft.identify.fit._Runs
        With the final weights and target (``run``, ``step``, ``lo``, ``hi``, ``weights``).
    theta : (p,) ndarray of float
        The optimum.
    J : (N, p) ndarray of float
        The weighted Jacobian there (the local planes' slopes).
    half : (p,) ndarray of float
        The local intervals' half-widths in theta.
    seen : (p,) ndarray of bool
        The parameters the residuals change with (the others are held).
    cost0 : float
        The cost at the optimum.
    limit : float
        The cost excess a probe may have and be accepted.

    Returns
    -------
    list of Probe
    """
    p = theta.size
    lo, hi = runs.lo, runs.hi
    plan = []  # (j, side, multiple, others, point on the regression line)
    for j in range(p):
        if not seen[j] or not math.isfinite(half[j]) or half[j] <= 0:
            continue
        others = [i for i in range(p) if i != j and seen[i]]
        slope = conditional_slopes(J, j, others)
        for side in (-1, 1):
            last = None
            for m in PROFILE_MULTIPLES:
                q = theta.copy()
                q[j] = float(np.clip(theta[j] + side * m * half[j], lo[j], hi[j]))
                if last is not None and q[j] == last:
                    break  # at a bound
                last = q[j]
                q[others] = theta[others] + slope * (q[j] - theta[j])
                plan.append((j, side, m, others, np.clip(q, lo, hi)))
    if not plan:
        return []
    base = runs.run([q for *_, q in plan], ["profile"] * len(plan))
    # one Gauss-Newton step in the others from each probe, by forward differences (backward at an upper bound)
    nbrs, index = [], []
    for k, (*_, others, q) in enumerate(plan):
        for i in others:
            h = runs.step if q[i] + runs.step <= hi[i] else -runs.step
            t = q.copy()
            t[i] += h
            nbrs.append(t)
            index.append((k, i, h))
    evs = runs.run(nbrs, ["profile"] * len(nbrs)) if nbrs else []
    cols: dict[int, dict[int, np.ndarray]] = {}
    for (k, i, h), ev in zip(index, evs, strict=True):
        cols.setdefault(k, {})[i] = (stacked(ev.blocks, runs.weights) - stacked(base[k].blocks, runs.weights)) / h
    moved, which = [], []
    for k, (*_, others, q) in enumerate(plan):
        if not others:
            continue
        Jo = np.column_stack([cols[k][i] for i in others])
        step = -np.linalg.lstsq(Jo, stacked(base[k].blocks, runs.weights), rcond=None)[0]
        # a step no longer than the others' own reach in the profile (a chaotic column can ask for any step)
        cap = PROFILE_MULTIPLES[-1] * np.where(np.isfinite(half[others]), half[others], 0.0)
        t = q.copy()
        t[others] = q[others] + np.clip(step, -cap, cap)
        moved.append(np.clip(t, lo, hi))
        which.append(k)
    better = dict(zip(which, runs.run(moved, ["profile"] * len(moved)), strict=True)) if moved else {}
    out = []
    for k, (j, side, m, _, q) in enumerate(plan):
        point, cost = q, _cost(runs, base[k])
        if k in better and _cost(runs, better[k]) < cost:
            point, cost = better[k].theta, _cost(runs, better[k])
        excess = cost - cost0
        out.append(Probe(j, side, m, np.asarray(point, float).copy(), excess, bool(excess <= limit)))
    return out


def reach(probes: list[Probe], theta: np.ndarray, limit: float) -> list[np.ndarray]:
    """The points the intervals must reach: on each profile's side its farthest accepted probe, moved towards
    the next probe (rejected) by the share of the limit left, linearly in the cost excess.

    Parameters
    ----------
    probes : list of Probe
    theta : (p,) ndarray of float
        The optimum.
    limit : float

    Returns
    -------
    list of (p,) ndarray

    Examples
    --------
    >>> z = np.zeros(1)
    >>> ps = [Probe(0, 1, 1.0, z + 1, 1.0, True), Probe(0, 1, 2.0, z + 2, 5.0, False)]
    >>> [float(t[0]) for t in reach(ps, z, 3.0)]  # excess 1 at 1, 5 at 2: the limit 3 half-way
    [1.5]
    """
    out = []
    sides = sorted({(pr.index, pr.side) for pr in probes})
    for j, side in sides:
        line = sorted((pr for pr in probes if pr.index == j and pr.side == side), key=lambda pr: pr.multiple)
        far = max((k for k, pr in enumerate(line) if pr.accepted), default=None)
        if far is None:
            continue
        a = line[far]
        point = a.theta
        if far + 1 < len(line):
            b = line[far + 1]
            f = (limit - a.excess) / (b.excess - a.excess) if b.excess > a.excess else 0.0
            point = a.theta + min(max(f, 0.0), 1.0) * (b.theta - a.theta)
        out.append(np.asarray(point, float))
    return out


def open_ends(probes: list[Probe]) -> list[Probe]:
    """The profiles' last probes that are accepted (the misfit still within the limit there: the interval may
    reach further than the profile looked).

    Parameters
    ----------
    probes : list of Probe
    """
    out = []
    for j, side in sorted({(pr.index, pr.side) for pr in probes}):
        line = sorted((pr for pr in probes if pr.index == j and pr.side == side), key=lambda pr: pr.multiple)
        if line[-1].accepted:
            out.append(line[-1])
    return out


__all__ = ["profile", "reach", "open_ends", "conditional_slopes", "Probe", "PROFILE_MULTIPLES"]
