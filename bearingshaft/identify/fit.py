"""The fit: weighted least squares on the residual blocks, passes, the intervals from the Jacobian.

The fit (:func:`identify`) minimises

    S(theta) = sum_b w_b^2 |r_b(theta)|^2

over the scaled parameters theta within their bounds (:mod:`bearingshaft.identify.parameters`) by
SciPy's trust-region reflective least squares (``scipy.optimize.least_squares``, ``method="trf"``),
with r_b the residual blocks and w_b their weights (:mod:`bearingshaft.identify.residuals`). A
pass fixes the target (floors, the predictability horizon and the spans at its starting point,
:func:`bearingshaft.identify.problem.define_target`) and the weights (the blocks' RMS and effective
sizes there); the next pass starts from the last optimum with the target and weights taken there,
so the pointwise block grows to the horizon of the fitted model and each block is weighted by the
misfit that is left (a first guess's horizon can end at the blow: the pointwise block then
covers at least MIN_TIME_SPAN_S past it).

The least squares find the nearest minimum, and a pointwise misfit has one wherever the model's first
impacts fall a period early or late (and a misfit past the horizon has many, a chaotic motion's). So
the fit starts where a scan puts it (``[identify] scan`` points, 0: none), with the target and
weights at the scene's values: a Latin hypercube of LHS_PER_PARAMETER points per parameter over the
whole box (one batch), then each parameter in turn over ``scan`` evenly spaced scaled values across
its bounds, the others at the best found so far. The first pass runs from the MULTI_STARTS cheapest
points at least 1.5 scan spacings apart (:func:`starts_from`), each with the target and weights of the
cheapest, and keeps the lowest end. Past the horizon the misfit can have several minima the test cannot
tell apart (the damping's, ~10 % apart on a short record); an end whose cost is within the chi-square
quantile (p degrees of freedom, times s^2) of the lowest is such a rival, and the intervals are widened
to reach it (:func:`rival_minima`; an identifiability note names it).

The Jacobian is by finite differences of ``step`` in theta (forward, backward at an upper
bound), run with the point itself: a trial point and its p neighbours are one batch of p + 1 model
runs in parallel (:class:`SerialEvaluator` here, :class:`bearingshaft.identify.run.DaskEvaluator`
on Dask); a step the trust region rejects wastes its p neighbours, which accepted steps repay in
time. Each pass takes its weights at its start from the residuals' scatter there
(:mod:`bearingshaft.identify.scatter`: the test's noise redrawn on the model's record, the roughness
about local planes over a cloud of cloud_size(p) runs within -+ CLOUD_STEPS steps, each with the
hammer force redrawn within its noise). At the optimum the same is done again, and the intervals come
from a sandwich (:func:`sandwich`):

    C = s^2 A^-1 B A^-1,   A = J^T J,   B = sum_k g_k g_k^T,   s^2 = max(1, S(theta*) / (N_eff - p)),

J the weighted slopes of the local planes over the cloud (a regression over -+ CLOUD_STEPS steps, not a
difference of two runs: past the horizon the latter is mostly chaos over the step), g_k = J^T e_k the
realisations e_k of the scatter (each noise draw's residuals, each cloud run's residuals about its
planes) projected on J (:func:`gradient_scatter`): what the noise and the chaos do to the gradient,
with their correlations across channels, windows and blocks, which per-residual weights cannot
carry; a block whose draws are not kept (a long pointwise block) adds J_b^T J_b, as its weights assume.
s^2 > 1 is misfit that neither explains (model error). With the weighted residuals independent with
unit variance C is the textbook s^2 (J^T J)^-1 (:func:`covariance`). The 100 (1 - a) % interval of
parameter i is theta*_i -+ t_{1-a/2, dof} sqrt(C_ii) in theta, dof the realisations' degrees of
freedom, mapped to
the parameter (a log-scaled one's interval is p* exp(-+ ...): asymmetric in p). The correlations
are C_ij / sqrt(C_ii C_jj). Two parameters cannot be told apart when |corr| >= CORRELATION_LIMIT;
J^T J is near-singular when the condition number of its correlation form (J scaled to unit
columns) passes CONDITION_LIMIT, and the eigenvector of its smallest eigenvalue names the
combination the test does not fix.

The local intervals hold where the misfit is a paraboloid at the cloud's scale; past the first impacts
it is not (the apparatus' (gap, k_g) misfit is a long flat valley, its chaotic blocks' slopes over the
cloud mostly chaos, and the least squares stop wherever the scan put them on its floor). So each
parameter's profile is probed out to several half-widths (:mod:`bearingshaft.identify.profile`), the
others on the valley floor, and every interval reaches the probes whose cost the test cannot reject
against the optimum's (within chi2_{confidence, p} s^2, as the rival minima); ``Fit.local_ci`` keeps
the local intervals. A probe cheaper than the least squares' end (they stop on such a misfit where the
trust region sees no descent) is reported as the estimate (:func:`estimate`; ``Fit.optimum`` keeps the
end, where J and C were taken). On a flat valley that point is the cheapest of costs that differ by
less than the chaos does: the estimate says no more than its interval (identify.md's Estimate section).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from bearingshaft.identify.problem import Evaluation, Problem, channels_at, define_target, evaluate, horizon_text
from bearingshaft.identify.profile import open_ends, profile, reach
from bearingshaft.identify.residuals import BlockWeight, block_weights, stacked

CORRELATION_LIMIT = 0.95  # |corr| at or above which two parameters are reported as not told apart
CONDITION_LIMIT = 1e6  # condition number of the scaled J^T J above which it is reported as near-singular
XTOL = 1e-3  # stop when a step changes theta by less than this (relative): 0.1 %, far below any interval
FTOL = 1e-4  # ... or the cost by less than this share
CLOUD_STEPS = 3.0  # the cloud's half-width in finite-difference steps (module docstring)
MULTI_STARTS = 3  # the first pass runs from this many of the scan's points (module docstring)
LHS_PER_PARAMETER = 8  # the scan's Latin hypercube: this many points per parameter (24 for three)


class SerialEvaluator:
    """Model runs in this process, one after another (the interface the fit uses).

    Parameters
    ----------
    problem : Problem
    """

    workers = 1
    where = "this process"

    def __init__(self, problem: Problem) -> None:
        self.problem = problem

    def put(self, target):
        """The target as the runs take it (here: itself)."""
        return target

    def map(self, target, thetas) -> list[Evaluation]:
        """The evaluations at ``thetas``, in order."""
        return [evaluate(self.problem, target, th) for th in thetas]

    def records(self, thetas) -> list:
        """(t, data) of the compared channels at ``thetas`` (:func:`bearingshaft.identify.problem.channels_at`)."""
        return [channels_at(self.problem, th) for th in thetas]

    def scatter(self, target, theta, points, draws: int) -> list[Evaluation]:
        """The point with its noise variances from ``draws`` draws, then the cloud's ``points``, the k-th with the
        force redrawn by seed k + 1 (:mod:`bearingshaft.identify.scatter`)."""
        return [evaluate(self.problem, target, theta, noise_draws=draws),
                *[evaluate(self.problem, target, q, force_seed=k + 1) for k, q in enumerate(points)]]


@dataclass(frozen=True, eq=False)
class Pass:
    """One least-squares pass.

    Attributes
    ----------
    start : (p,) ndarray of float
        theta where it started (its target and weights were taken there).
    end : (p,) ndarray of float
        Its optimum.
    weights : dict
        {block: BlockWeight} at ``start``.
    span : str
        The pointwise block's span, in words.
    horizon_s : float
        s, the horizon at ``start`` (inf: none).
    status : str
        SciPy's message.
    n_iterations : int
        Trial points (function evaluations of least_squares).
    cost_start, cost_end : float
        S at start and end (with this pass's weights).
    """

    start: np.ndarray
    end: np.ndarray
    weights: dict
    span: str
    horizon_s: float
    status: str
    n_iterations: int
    cost_start: float
    cost_end: float


@dataclass(frozen=True, eq=False)
class Fit:
    """What :func:`identify` found.

    Attributes
    ----------
    problem : Problem
    theta : (p,) ndarray of float
        The estimate, scaled: the least squares' end, or the profile's cheapest probe where it is cheaper
        (:func:`estimate`).
    values : dict
        {key: value} there.
    ci : dict
        {key: (low, high)} the intervals, in the parameters' units.
    covariance : (p, p) ndarray of float
        C, in theta.
    correlation : (p, p) ndarray of float
    jacobian : (N, p) ndarray of float
        J of the weighted residuals at the optimum (the local planes' slopes over the cloud).
    sigma_theta : (p,) ndarray of float
        sqrt(C_ii).
    s2 : float
        The residual variance S / (N_eff - p).
    n_eff : float
        N_eff.
    dof : float
        N_eff - p.
    t_quantile : float
        t_{1-a/2, dof}.
    condition : float
        Condition number of the scaled J^T J.
    weakest : (p,) ndarray of float
        Eigenvector of its smallest eigenvalue (scaled parameters).
    notes : list of str
        The identifiability notes.
    weights : dict
        {block: BlockWeight} at the optimum.
    passes : list of Pass
    history : list of dict
        Every model run: ``pass``, ``kind`` (point, fd, final), ``run``, the values, ``cost`` and each
        block's mean square (NaN for the finite-difference neighbours' cost), ``wall_s``.
    target : Target
        The last pass's target.
    stats : dict
        ``n_runs``, ``wall_s``, ``workers``, ``where``, CPU seconds of the runs.
    probes : list of Probe
        The profile's probes (:mod:`bearingshaft.identify.profile`).
    local_ci : dict
        {key: (low, high)} the local planes' intervals, before the profile and the rival minima widened them.
    profile_limit : float
        The cost excess a probe (and a rival minimum) may have: chi2_{confidence, p} s^2.
    optimum : (p,) ndarray of float or None
        The least squares' end, scaled, where the Jacobian, the covariance and the profile were taken (None: the
        same as ``theta``).
    """

    problem: Problem
    theta: np.ndarray
    values: dict
    ci: dict
    covariance: np.ndarray
    correlation: np.ndarray
    jacobian: np.ndarray
    sigma_theta: np.ndarray
    s2: float
    n_eff: float
    dof: float
    t_quantile: float
    condition: float
    weakest: np.ndarray
    notes: list
    weights: dict
    passes: list
    history: list
    target: object
    stats: dict = field(default_factory=dict)
    probes: list = field(default_factory=list)
    local_ci: dict = field(default_factory=dict)
    profile_limit: float = math.nan
    optimum: np.ndarray | None = None

    @property
    def from_profile(self) -> bool:
        """The estimate is a profile's probe, not the least squares' end."""
        return self.optimum is not None and not np.array_equal(self.optimum, self.theta)


class _Runs:
    """The model runs of one pass: a trial point and its finite-difference neighbours in one batch, cached."""

    def __init__(self, evaluator, handle, problem: Problem, weights: dict, step: float, bounds, pass_no: int,
                 history: list) -> None:
        self.evaluator, self.handle, self.problem, self.weights = evaluator, handle, problem, weights
        self.step, self.lo, self.hi = step, bounds[0], bounds[1]
        self.pass_no, self.history = pass_no, history
        self.cache: dict[bytes, Evaluation] = {}

    def neighbours(self, theta: np.ndarray, sign: float = 1.0) -> list[np.ndarray]:
        out = []
        for j in range(theta.size):
            h = sign * self.step
            if not self.lo[j] <= theta[j] + h <= self.hi[j]:
                h = -h
            t = theta.copy()
            t[j] += h
            out.append(t)
        return out

    def run(self, thetas: list[np.ndarray], kinds: list[str]) -> list[Evaluation]:
        todo = [(t, k) for t, k in zip(thetas, kinds, strict=True) if t.tobytes() not in self.cache]
        if todo:
            evs = self.evaluator.map(self.handle, [t for t, _ in todo])
            for (t, kind), ev in zip(todo, evs, strict=True):
                self.cache[t.tobytes()] = ev
                self._log(ev, kind)
        return [self.cache[t.tobytes()] for t in thetas]

    def _log(self, ev: Evaluation, kind: str) -> None:
        r = stacked(ev.blocks, self.weights)
        row = {"pass": self.pass_no, "kind": kind, "run": len(self.history) + 1,
               **self.problem.values(ev.theta), "cost": float(r @ r) if self.weights else math.nan,
               **{f"ms_{m}": float(np.mean(ev.blocks[m] ** 2)) if ev.blocks[m].size else math.nan
                  for m in ev.blocks}, "wall_s": ev.stats["wall_s"], "cpu_s": ev.stats["cpu_s"]}
        self.history.append(row)

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, float).copy()
        ev = self.run([theta, *self.neighbours(theta)], ["point"] + ["fd"] * theta.size)[0]
        return stacked(ev.blocks, self.weights)

    def jacobian(self, theta: np.ndarray, central: bool = False) -> np.ndarray:
        theta = np.asarray(theta, float).copy()
        plus = self.neighbours(theta)
        if central:  # the other side of each step; at a bound (both steps would be one point) theta itself
            minus = [m if not np.array_equal(m, q) else theta.copy()
                     for m, q in zip(self.neighbours(theta, -1.0), plus, strict=True)]
            evs = self.run([*plus, *minus], ["final"] * (2 * theta.size))
            cols = [(stacked(a.blocks, self.weights) - stacked(b.blocks, self.weights)) / (pa[j] - mb[j])
                    for j, (a, b, pa, mb) in enumerate(zip(evs[:theta.size], evs[theta.size:], plus, minus,
                                                           strict=True))]
        else:
            r0 = stacked(self.run([theta], ["point"])[0].blocks, self.weights)
            evs = self.run(plus, ["fd"] * theta.size)
            cols = [(stacked(e.blocks, self.weights) - r0) / (t[j] - theta[j])
                    for j, (e, t) in enumerate(zip(evs, plus, strict=True))]
        return np.column_stack(cols)


def _weights_at(runs: _Runs, theta, kind: str) -> tuple[dict[str, BlockWeight], dict, dict]:
    """The blocks' weights at ``theta`` from their scatters there, the slopes of their local planes and the
    realisations of the scatter (:mod:`bearingshaft.identify.scatter`: the point with K_NOISE noise draws and
    the cloud around it, one batch); the point joins the cache. Returns (weights, {block: (n_b, p) slopes},
    {"noise": {block: (draws, n_b)}, "chaos": {block: (runs, n_b)}})."""
    from bearingshaft.identify.scatter import K_NOISE, cloud, local_fit, sigmas

    theta = np.asarray(theta, float).copy()
    points = cloud(theta, CLOUD_STEPS * runs.step, (runs.lo, runs.hi), seed=len(runs.history))
    evs = runs.evaluator.scatter(runs.handle, theta, points, K_NOISE)
    base = evs[0]
    runs.cache.setdefault(theta.tobytes(), base)
    for ev in evs:
        runs._log(ev, kind)
    slopes, rough, about = local_fit(theta, [theta, *points], [e.blocks for e in evs])
    weights = block_weights(base.blocks, sigmas(base.noise_var, rough, base.blocks))
    return weights, slopes, {"noise": base.noise_draws, "chaos": about}


def _target(problem: Problem, theta):
    spec, sp = problem.scene.identify, problem.scene.spectrogram
    return define_target(problem, theta, spec.measures, envelope_window_s=spec.envelope_window_s,
                         frame_s=sp.window_s if sp else 0.05, fmax_hz=sp.fmax_hz if sp else None)[0]


def _scan(problem: Problem, evaluator, theta: np.ndarray, bounds, history: list, say) -> list[np.ndarray]:
    """The least squares' starts: each parameter in turn over ``[identify] scan`` points across its bounds, the
    others at the best so far, the target and weights at ``theta``; the MULTI_STARTS cheapest points apart
    (:func:`starts_from`; module docstring)."""
    spec = problem.scene.identify
    target = _target(problem, theta)
    handle = evaluator.put(target)
    probe = _Runs(evaluator, handle, problem, {}, spec.step, bounds, 0, history)
    weights, _, _ = _weights_at(probe, theta, "scan")
    # the pointwise block is left out of the scan: a model a period early or late misfits it more than one that
    # never closes a gap, while the envelopes see the impacts' energy whatever their phase
    weights = {m: (w if m != "time" else replace(w, weight=0.0)) for m, w in weights.items()}
    if not any(w.weight > 0 for w in weights.values()):
        return [np.asarray(theta, float)]
    runs = _Runs(evaluator, handle, problem, weights, spec.step, bounds, 0, history)
    runs.cache.update(probe.cache)
    seen: dict[bytes, tuple[float, np.ndarray]] = {}
    # a Latin hypercube over the whole box first (one batch): the coordinate scan alone moves one parameter at a
    # time from the scene's values and can pin the gap where the others' wrong values put its best
    pts = [np.asarray(theta, float).copy(), *latin_hypercube(bounds, LHS_PER_PARAMETER * theta.size, seed=0)]
    evs = runs.run(pts, ["scan"] * len(pts))
    for t, e in zip(pts, evs, strict=True):
        seen[t.tobytes()] = (float(np.sum(stacked(e.blocks, weights) ** 2)), t.copy())
    best = min(seen.values(), key=lambda ct: ct[0])[1].copy()
    say(f"Latin hypercube of {len(pts) - 1} points: the cheapest at "
        + ", ".join(f"{key} = {v:.4g}" for key, v in problem.values(best).items()))
    for j, par in enumerate(problem.parameters):
        trial = []
        for v in np.linspace(bounds[0][j], bounds[1][j], spec.scan):
            t = best.copy()
            t[j] = v
            trial.append(t)
        evs = runs.run([best, *trial], ["scan"] * (len(trial) + 1))
        costs = [float(np.sum(stacked(e.blocks, weights) ** 2)) for e in evs]
        for c, t in zip(costs, [best, *trial], strict=True):
            seen[t.tobytes()] = (c, t.copy())
        best = [best, *trial][int(np.argmin(costs))].copy()
        say(f"scan of {par.key}: {par.value(best[j]):.4g} (cost {min(costs):.4g})")
    return starts_from([v for v in seen.values()], (bounds[1] - bounds[0]) / max(spec.scan - 1, 1), MULTI_STARTS)


def rival_minima(ends: list, confidence: float, p: int, s2: float) -> list:
    """The ends (cost, theta) other than the cheapest whose cost exceeds its by at most chi2_{confidence, p} s^2.

    Parameters
    ----------
    ends : list of (cost, theta), the ends of the fit's starts
    confidence : the intervals' level, e.g. 0.95
    p : the number of parameters (the chi-square's degrees of freedom)
    s2 : the residuals' variance factor (floored at 1)

    Examples
    --------
    >>> [c for c, _ in rival_minima([(5.0, 0), (7.0, 1), (60.0, 2)], 0.95, 3, 1.0)]  # chi2_{0.95, 3} = 7.81
    [7.0]
    """
    from scipy.stats import chi2

    if len(ends) < 2:
        return []
    best = min(c for c, _ in ends)
    limit = float(chi2.ppf(confidence, p)) * max(s2, 1.0)
    cheapest = min(range(len(ends)), key=lambda i: ends[i][0])
    return [e for i, e in enumerate(ends) if i != cheapest and e[0] - best <= limit]


def latin_hypercube(bounds, n: int, seed: int = 0) -> list[np.ndarray]:
    """``n`` points in the box ``bounds`` (scaled parameters), one in each of n equal strata of every parameter.

    Parameters
    ----------
    bounds : (low (p,), high (p,))
    n : the number of points (and strata)
    seed : the generator's seed (the same points on every run)

    Examples
    --------
    >>> pts = latin_hypercube((np.zeros(2), np.ones(2)), 4)
    >>> sorted(int(4 * q[0]) for q in pts)
    [0, 1, 2, 3]
    """
    lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    rng = np.random.default_rng(seed)
    u = (np.array([rng.permutation(n) for _ in range(lo.size)]).T + rng.random((n, lo.size))) / n
    return [lo + (hi - lo) * q for q in u]


def starts_from(scanned: list, spacing: np.ndarray, n: int) -> list[np.ndarray]:
    """The ``n`` cheapest scanned points at least 1.5 scan spacings apart in some parameter (the first the cheapest).

    Parameters
    ----------
    scanned : list of (cost, theta)
    spacing : (p,) ndarray of float
        The scan's spacing in each scaled parameter.
    n : int

    Examples
    --------
    >>> pts = [(1.0, np.array([0.0])), (1.1, np.array([0.1])), (2.0, np.array([1.0]))]
    >>> [float(t[0]) for t in starts_from(pts, np.array([0.1]), 2)]
    [0.0, 1.0]
    """
    out: list[np.ndarray] = []
    for _, t in sorted(scanned, key=lambda ct: ct[0]):
        if all(np.max(np.abs(t - u) / np.maximum(spacing, 1e-300)) >= 1.5 for u in out):
            out.append(t)
        if len(out) == n:
            break
    return out


def identify(problem: Problem, evaluator=None, progress=None) -> Fit:
    """Fit ``problem``'s parameters to its test (module docstring).

    Long because the passes, the batches of runs and the final covariance share one history and
    one set of counters; each piece is a few lines.

    Parameters
    ----------
    problem : Problem
    evaluator : SerialEvaluator or DaskEvaluator, optional
        Where the model runs (default: here, one after another).
    progress : callable, optional
        ``progress(text)``: one line per pass and per trial point.

    Returns
    -------
    Fit
    """
    from scipy.optimize import least_squares

    spec = problem.scene.identify
    evaluator = evaluator or SerialEvaluator(problem)
    say = progress or (lambda text: None)
    t_start = time.perf_counter()
    bounds = (np.array([p.theta_bounds[0] for p in problem.parameters]),
              np.array([p.theta_bounds[1] for p in problem.parameters]))
    theta = problem.theta0.copy()
    history: list[dict] = []
    passes: list[Pass] = []
    runs = None
    target = None
    starts = [theta]
    ends: list[tuple[float, np.ndarray]] = []  # the first pass's ends from each start: (cost, theta)
    if spec.scan:
        starts = _scan(problem, evaluator, theta, bounds, history, say)
        theta = starts[0]
    for k in range(spec.passes):
        target = _target(problem, theta)
        handle = evaluator.put(target)
        probe = _Runs(evaluator, handle, problem, {}, spec.step, bounds, k + 1, history)
        weights, _, _ = _weights_at(probe, theta, "scatter")
        best = None
        # the first pass runs from each of the scan's starts with the target and weights of the cheapest (so that
        # their costs compare) and keeps the lowest end; later passes from the last optimum alone
        for start in (starts if k == 0 else [theta]):
            runs = _Runs(evaluator, handle, problem, weights, spec.step, bounds, k + 1, history)
            runs.cache.update(probe.cache)
            r0 = runs.residuals(start)
            say(f"pass {k + 1}: {horizon_text(target)}; cost {float(r0 @ r0):.4g} at the start "
                + ", ".join(f"{key} = {v:.4g}" for key, v in problem.values(start).items()))
            res = least_squares(runs.residuals, start, jac=runs.jacobian, bounds=bounds, method="trf",
                                x_scale=1.0, xtol=XTOL, ftol=FTOL, max_nfev=spec.max_iterations)
            end = np.clip(res.x, *bounds)
            say(f"pass {k + 1}: {res.nfev} trial points, cost {2.0 * res.cost:.4g}: "
                + ", ".join(f"{key} = {v:.4g}" for key, v in problem.values(end).items()))
            if k == 0:
                ends.append((float(2.0 * res.cost), end.copy()))
            if best is None or res.cost < best[1].cost:
                best = (start.copy(), res, end, float(r0 @ r0), runs)
            probe.cache.update(runs.cache)
        start, res, theta, cost0, runs = best
        hz = target.horizon.horizon_s if target.horizon is not None else math.inf
        message = res.message + (f" (the best of {len(starts)} starts)" if k == 0 and len(starts) > 1 else "")
        passes.append(Pass(start, theta.copy(), weights, horizon_text(target), hz, message, int(res.nfev),
                           cost0, float(2.0 * res.cost)))
        if k > 0 and np.max(np.abs(theta - start)) < XTOL:
            break
    # the covariance at the optimum, with the weights (and target) taken there
    # the covariance at the optimum: the weights, the Jacobian (the local planes' slopes over the cloud, a
    # regression over the step rather than a difference of two runs) and the scatter's realisations, taken there
    p = theta.size
    runs.weights = {}
    weights, slopes, draws = _weights_at(runs, theta, "final")
    runs.weights = weights
    r = stacked(runs.run([theta], ["point"])[0].blocks, weights)
    J = np.vstack([weights[m].apply_rows(slopes[m]) if m in slopes else np.zeros((weights[m].n, p))
                   for m in weights])
    n_eff = float(sum(w.n_eff for w in weights.values()))
    # a parameter the residuals do not see has no information (an unbounded interval): its finite-difference
    # column is exactly zero (runs with the test's own force: the cloud's slopes hold the redrawn forces' scatter)
    seen = np.linalg.norm(runs.jacobian(theta), axis=0) > 0
    J[:, ~seen] = 0.0
    norms = np.linalg.norm(J, axis=0)
    cov = np.full((p, p), math.nan)
    G = gradient_scatter(J[:, seen], weights, draws)
    cov_seen, s2, dof, tq = sandwich(J[:, seen], r, n_eff, spec.confidence, G)
    cov[np.ix_(seen, seen)] = cov_seen
    sig = np.where(seen, np.sqrt(np.maximum(np.diag(cov), 0.0)), math.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sig, sig)
    ci = {}
    for i, par in enumerate(problem.parameters):
        ci[par.key] = interval(par, float(theta[i]), float(tq * sig[i]))
    # another start's end the test cannot reject against the best (a cost within the chi-square quantile of p
    # degrees of freedom times s^2, costs taken with one set of weights): a minimum as good as the one reported
    # as far as the test can tell, which a local interval about the best cannot see; the intervals reach it
    # the profile: each parameter probed out to PROFILE_MULTIPLES of its half-width, the others on the valley floor;
    # a probe the test cannot reject against the optimum (the rivals' criterion) is reached by every interval
    # (bearingshaft.identify.profile: past the first impacts the local planes' slopes are mostly chaos)
    from scipy.stats import chi2

    limit = float(chi2.ppf(spec.confidence, p)) * max(s2, 1.0)
    local = dict(ci)
    probes = profile(runs, theta, J, tq * sig, seen, float(r @ r), limit)
    for i, par in enumerate(problem.parameters):
        lo, hi = ci[par.key]
        for t in reach(probes, theta, limit):
            v = par.value(float(t[i]))
            lo, hi = min(lo, v), max(hi, v)
        ci[par.key] = (lo, hi)
    rivals = rival_minima(ends, spec.confidence, p, s2)
    for i, par in enumerate(problem.parameters):
        lo, hi = ci[par.key]
        for _, t in rivals:
            v = par.value(float(t[i]))
            lo, hi = min(lo, v), max(hi, v)
        ci[par.key] = (lo, hi)
    # the estimate: the cheapest point the fit has seen with the final weights (a profile's probe below the least
    # squares' end: they stop where the trust region cannot see a descent on a rough misfit); every interval holds it
    est = estimate(theta, probes)
    for i, par in enumerate(problem.parameters):
        lo, hi = ci[par.key]
        v = par.value(float(est[i]))
        ci[par.key] = (min(lo, v), max(hi, v))
    Js = J / np.where(norms > 0, norms, 1.0)
    ev, vec = np.linalg.eigh(Js.T @ Js)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
    notes = identifiability_notes(problem, corr, cond, vec[:, 0], ci, norms)
    notes += profile_notes(problem, probes, local, ci, limit)
    for c, t in rivals:
        notes.append("another minimum the test cannot tell from the best (cost " + f"{c:.4g} against "
                     f"{min(e[0] for e in ends):.4g}, within the {round(100 * spec.confidence)} % chi-square quantile "
                     f"of {p} degrees of freedom): " + ", ".join(f"{key} = {v:.4g}" for key, v in
                                                              problem.values(t).items()) + "; the intervals reach it")
    stats = {"n_runs": len(history), "wall_s": time.perf_counter() - t_start, "workers": evaluator.workers,
             "where": evaluator.where, "cpu_s_runs": float(sum(h["cpu_s"] for h in history)),
             "passes": len(passes)}
    return Fit(problem, est, problem.values(est), ci, cov, corr, J, sig, s2, n_eff, dof, tq, cond, vec[:, 0],
               notes, weights, passes, history, target, stats, probes, local, limit, theta.copy())


def estimate(theta: np.ndarray, probes: list) -> np.ndarray:
    """The reported estimate: the profile's cheapest probe if its cost is below the least squares' end's (negative
    excess), else the end ``theta``.

    Parameters
    ----------
    theta : (p,) ndarray of float
        The least squares' end, scaled.
    probes : list of Probe
        The profile (:func:`bearingshaft.identify.profile.profile`), excesses over the end's cost.

    Returns
    -------
    (p,) ndarray of float

    Examples
    --------
    >>> from bearingshaft.identify.profile import Probe
    >>> ps = [Probe(0, 1, 1.0, np.array([0.1]), -0.5, True), Probe(0, -1, 1.0, np.array([-0.1]), 2.0, True)]
    >>> estimate(np.zeros(1), ps).tolist(), estimate(np.zeros(1), ps[1:]).tolist()
    ([0.1], [0.0])
    """
    lower = [pr for pr in probes if pr.excess < 0]
    if not lower:
        return np.asarray(theta, float).copy()
    return np.asarray(min(lower, key=lambda pr: pr.excess).theta, float).copy()


def profile_notes(problem: Problem, probes: list, local: dict, ci: dict, limit: float) -> list[str]:
    """The notes of the profile (:mod:`bearingshaft.identify.profile`): a probe cheaper than the optimum (the
    least squares stopped short of it), an interval the profile widened, a profile still within the limit at its
    last probe.

    Parameters
    ----------
    problem : Problem
    probes : list of Probe
    local : dict
        {key: (low, high)} the local planes' intervals.
    ci : dict
        {key: (low, high)} after the profile.
    limit : float
        The cost excess a probe may have.

    Returns
    -------
    list of str
    """
    def where(t):
        return ", ".join(f"{key} = {v:.4g}" for key, v in problem.values(t).items())

    notes = []
    lower = [pr for pr in probes if pr.excess < 0]
    if lower:
        best = min(lower, key=lambda pr: pr.excess)
        notes.append(f"the profile found a lower misfit than the least squares' end ({len(lower)} probe(s), the "
                     f"lowest {best.excess:+.4g} at {where(best.theta)}): the least squares stopped short on a rough "
                     "misfit; that probe is reported as the estimate (the Jacobian, correlations and local intervals "
                     "are the end's), and the intervals reach it")
    for i, par in enumerate(problem.parameters):
        (a, b), (lo, hi) = local[par.key], ci[par.key]
        if (lo < a or hi > b) and any(pr.index == i for pr in probes):
            notes.append(f"{par.key}: the misfit's profile stays within the limit (chi-square quantile times s^2 = "
                         f"{limit:.4g}) farther than the local planes' interval [{a:.4g}, {b:.4g}] says: the interval "
                         "reaches the profile (the planes' slopes past the first impacts are mostly chaos, counted "
                         "as information)")
    for pr in open_ends(probes):
        par = problem.parameters[pr.index]
        if par.theta_bounds[0] < pr.theta[pr.index] < par.theta_bounds[1]:
            notes.append(f"{par.key}: the misfit is still within the limit at the profile's last probe "
                         f"({par.value(float(pr.theta[pr.index])):.4g}, {pr.multiple:g} half-widths out): the "
                         "interval may reach further")
    return notes


def covariance(J: np.ndarray, r: np.ndarray, n_eff: float, confidence: float,
               min_s2: float = 0.0) -> tuple[np.ndarray, float, float, float]:
    """C = s^2 (J^T J)^+ of the scaled parameters, s^2 = max(min_s2, |r|^2 / (N_eff - p)), and the t quantile
    (the textbook intervals, as :func:`sandwich` has them when the weighted residuals are independent with unit
    variance).

    Parameters
    ----------
    J : (N, p) ndarray of float
        Jacobian of the weighted residuals at the optimum.
    r : (N,) ndarray of float
        The weighted residuals there.
    n_eff : float
        Their effective number of independent values.
    confidence : float
        In (0, 1).
    min_s2 : float
        s^2 at least this: 1 when the residuals are weighted by their scatters (a fit closer than the noise
        and chaos allow is luck, not precision); 0: the textbook s^2.

    Returns
    -------
    (C, s2, dof, t): dof = N_eff - p (at least 1), t = t_{(1 + confidence)/2, dof}.
    """
    from scipy.stats import t as student_t

    p = J.shape[1]
    dof = max(n_eff - p, 1.0)
    s2 = max(float(min_s2), float(r @ r) / dof)
    cov = s2 * np.linalg.pinv(J.T @ J)
    return cov, s2, dof, float(student_t.ppf(0.5 + 0.5 * confidence, dof))


def gradient_scatter(J: np.ndarray, weights: dict, draws: dict) -> dict:
    """{kind: (k, p) g}: each realisation of the scatter (:mod:`bearingshaft.identify.scatter`) weighted as the
    residuals and projected on J, g = J^T e; a block without realisations of a kind adds J_b^T e for the
    e its weights assume (unit variance, n_eff independent: ``{"assumed": (p, p) J_b^T J_b summed}``).

    Parameters
    ----------
    J : (N, p) ndarray of float
        The weighted Jacobian, blocks in ``weights``' order.
    weights : dict
        {block: BlockWeight}.
    draws : dict
        {"noise": {block: (k, n_b)}, "chaos": {block: (k, n_b)}}, each realisation's residuals (the chaos ones
        already over sqrt(dof)).

    Returns
    -------
    dict
        {"noise": (k, p), "chaos": (k, p), "assumed": (p, p)}.
    """
    p = J.shape[1]
    out = {}
    assumed = np.zeros((p, p))
    off = {}
    i = 0
    for m, w in weights.items():
        off[m] = slice(i, i + w.n)
        i += w.n
    for kind in ("noise", "chaos"):
        real = draws.get(kind, {})
        k = max((v.shape[0] for v in real.values()), default=0)
        g = np.zeros((k, p))
        for m, w in weights.items():
            Jb = J[off[m]]
            if m in real and real[m].shape == (k, w.n):
                g += np.array([Jb.T @ w.apply(e) for e in real[m]])
            elif kind == "noise":  # no draws kept (a long pointwise block): as its weights assume
                assumed += Jb.T @ Jb
        if kind == "noise" and k > 1:
            g = g / math.sqrt(k - 1)  # the draws' deviations from their mean: k - 1 degrees of freedom
        out[kind] = g
    out["assumed"] = assumed
    return out


def sandwich(J: np.ndarray, r: np.ndarray, n_eff: float, confidence: float, G: dict) -> tuple[np.ndarray, float,
                                                                                            float, float]:
    """C = s^2 A^-1 B A^-1, A = J^T J, B = sum_k g_k g_k^T + the assumed part (:func:`gradient_scatter`): the
    covariance of the estimate from what the noise and chaos do to the gradient, with all their
    correlations; s^2 = max(1, |r|^2 / (N_eff - p)) the misfit beyond them (model error), and the t quantile
    with the realisations' degrees of freedom (the noise draws' less one and the cloud's about its planes).

    Parameters
    ----------
    J : (N, p) ndarray of float
    r : (N,) ndarray of float
        The weighted residuals at the optimum.
    n_eff : float
    confidence : float
    G : dict
        From :func:`gradient_scatter` (columns of the parameters seen).

    Returns
    -------
    (C, s2, dof, t)
    """
    from scipy.stats import t as student_t

    p = J.shape[1]
    A_inv = np.linalg.pinv(J.T @ J)
    B = G["assumed"].copy()
    dof = 0.0
    for kind in ("noise", "chaos"):
        g = G.get(kind)
        if g is not None and g.shape[0]:
            B += g.T @ g
            dof += g.shape[0] - (1 if kind == "noise" else 0)
    chaos = G.get("chaos")
    if chaos is not None and chaos.shape[0]:
        dof -= p + 1  # the cloud's runs less the planes' p + 1 coefficients
    dof = max(dof, 1.0)
    s2 = max(1.0, float(r @ r) / max(n_eff - p, 1.0))
    return s2 * A_inv @ B @ A_inv, s2, dof, float(student_t.ppf(0.5 + 0.5 * confidence, dof))


UNBOUNDED = 50.0  # a half-width in theta past this (a factor e^50 on a log scale): the interval is unbounded


def interval(par, theta: float, half: float) -> tuple[float, float]:
    """(low, high) of ``par`` for theta -+ half (unbounded: -inf or 0 for a log scale, and inf, past UNBOUNDED).

    Parameters
    ----------
    par : Parameter
    theta : its scaled value at the optimum
    half : the interval's half width in the scaled parameter

    Examples
    --------
    >>> from bearingshaft.identify.parameters import Parameter
    >>> interval(Parameter("model.gap", "m", 1e-4, 1e-5, 1e-3, "log"), 0.0, 1e9)
    (0.0, inf)
    """
    if not math.isfinite(half) or half > UNBOUNDED:
        return (0.0 if par.scale == "log" else -math.inf), math.inf
    lo, hi = par.value(theta - half), par.value(theta + half)
    return min(lo, hi), max(lo, hi)


def interval_half_widths(J: np.ndarray, r: np.ndarray, n_eff: float, confidence: float) -> np.ndarray:
    """t sqrt(C_ii): the intervals' half widths in the scaled parameters (:func:`covariance`).

    Parameters
    ----------
    J : (N, p) ndarray of float
        Jacobian of the weighted residuals.
    r : (N,) ndarray of float
        The weighted residuals.
    n_eff : float
        Their effective number.
    confidence : float
        In (0, 1).
    """
    cov, _, _, tq = covariance(J, r, n_eff, confidence)
    return tq * np.sqrt(np.maximum(np.diag(cov), 0.0))


def identifiability_notes(problem: Problem, corr: np.ndarray, cond: float, weakest: np.ndarray, ci: dict,
                          norms: np.ndarray) -> list[str]:
    """The identifiability notes: pairs that cannot be told apart, a near-singular J^T J, a parameter
    the residuals do not see, an interval that reaches a bound.

    Parameters
    ----------
    problem : Problem
    corr : (p, p) ndarray of float
    cond : float
        Condition number of the scaled J^T J.
    weakest : (p,) ndarray of float
        Its eigenvector of the smallest eigenvalue.
    ci : dict
        {key: (low, high)}.
    norms : (p,) ndarray of float
        Column norms of J.

    Returns
    -------
    list of str (empty: every parameter identified)

    Examples
    --------
    >>> from bearingshaft.identify.parameters import Parameter
    >>> from types import SimpleNamespace
    >>> ps = (Parameter("model.gap", "m", 1e-4, 1e-5, 1e-3, "log"), Parameter("model.k_g", "N/m", 1e7, 1e6, 1e8, "log"))
    >>> prob = SimpleNamespace(parameters=ps)
    >>> notes = identifiability_notes(prob, np.array([[1, -0.99], [-0.99, 1]]), 3e3, np.array([0.7, 0.7]),
    ...                               {"model.gap": (9e-5, 1.1e-4), "model.k_g": (9e6, 1.1e7)}, np.ones(2))
    >>> notes[0].startswith("model.gap and model.k_g cannot be told apart")
    True
    """
    notes = []
    ps = problem.parameters
    p = len(ps)
    for i in range(p):
        if norms[i] == 0:
            notes.append(f"{ps[i].key}: the residuals do not change with it (zero Jacobian column): not identified")
    for i in range(p):
        for j in range(i + 1, p):
            c = corr[i, j]
            if math.isfinite(c) and abs(c) >= CORRELATION_LIMIT:
                notes.append(f"{ps[i].key} and {ps[j].key} cannot be told apart: correlation {c:+.3f} "
                             f"(|corr| >= {CORRELATION_LIMIT}): the test fixes a combination of them, not each")
    if cond > CONDITION_LIMIT:
        combo = " ".join(f"{w:+.2f} {par.key}" for w, par in zip(weakest, ps, strict=True) if abs(w) > 0.1)
        notes.append(f"J^T J is near-singular (condition number {cond:.3g} > {CONDITION_LIMIT:g} with its columns "
                     f"scaled): the combination {combo} (scaled parameters) is not fixed by the test")
    for par in ps:
        lo, hi = ci[par.key]
        if lo <= par.lower or hi >= par.upper:
            notes.append(f"{par.key}: its interval [{lo:.4g}, {hi:.4g}] reaches a bound [{par.lower:.4g}, "
                         f"{par.upper:.4g}]: the test hardly constrains it")
    return notes


__all__ = ["identify", "estimate", "covariance", "interval_half_widths", "Fit", "Pass", "SerialEvaluator",
           "identifiability_notes", "CORRELATION_LIMIT", "CONDITION_LIMIT"]
