"""Stage ``frc`` on a model with friction at the tips (issue 27): HB by AFT with the Jenkins sliders.

When the scene's model has friction (``[model] mu > 0``), :func:`bearingshaft.stages.frc.compute` hands the
stage to :func:`compute` here. For each level of ``[frc] levels_N`` the load P cos(2 pi f t) at ``point``
(plus ``also_weights`` P at each of ``also_points``: a slanted load, whose axial part the tips' friction
resists while they touch) is continued in frequency by :func:`reduced.periodic.friction_aft.friction_frc`
(condensed HB, the stops projected exactly, each slider by AFT, H = ``harmonics``), its stability by Hill's
method on the consistent AFT Jacobian at every point (stick-slip included), its bifurcations from the
multipliers. The response map (:mod:`bearingshaft.stages.frc_friction_map`): a stepped sine up and down by the
exact friction flow, 0.1 Hz steps over the contact band, each frequency classified (periodic, subharmonic,
quasi-periodic, chaotic) with its largest Lyapunov exponent by the exact tangent. The check: at
``stepped_sine_points`` frequencies spread over the band (on the map's grid), from the state the map's up sweep
ended in there, 20 periods by the exact friction integrator
(:func:`reduced.transient.friction.integrate_exact_friction`, stick, slip and gaps as events); settled where the
map found a periodic response, and then against the HB solution at its frequency on the stable piece nearest it
(without a map, ``[frc] map_step_hz = 0``: a stepped sine of its own, each frequency settled until its last
period's amplitudes move by less than ``stepped_sine_tol`` or ``stepped_sine_max_s``). Where it is not settled (in
contact, where the response is not periodic or the periodic orbit not attracting), the periodic orbit is shot for on
the exact friction flow with the sliders' positions among the unknowns
(:func:`reduced.periodic.friction_shooting.shoot_friction`, 8 nodes, Newton from the HB orbit at that
frequency, then from HB with 2H + 1 and 4H + 1 harmonics there while it does not converge): its distance to
the curve's HB orbit, its defect and its Floquet multipliers (an unstable orbit is why the sine does not
settle), or the defect reached where Newton stops short.

What the frictionless stage does and this one does not (frc.md says so too): the converged curve by multiple
shooting continued in frequency (the continued shooting runs the exact flow without sliders), the Floquet
multipliers and monodromy along the curve (Hill's method instead), the convergence study in H and the backbone
check (NNMs of a system with friction are not conservative; and each H's curve costs a continuation with AFT).
"""

from __future__ import annotations

import math
import time

import numpy as np

from bearingshaft.scenes import Scene
from bearingshaft.stages import frc_friction_map
from bearingshaft.stages.frc_friction_bands import clip, complement, contact_band
from bearingshaft.stages.frc_friction_results import (  # noqa: F401
    SKIPPED,
    BranchVerdict,
    FrictionCheck,
    FrictionFRCResult,
    ShootCheck,
    ShootingCurve,
)
from bearingshaft.systems import model_system
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.continuation import ContinuationError
from reduced.periodic.frc import FRC_STEPS, linear_frf, solution_at_frequency
from reduced.periodic.friction_aft import friction_frc
from reduced.periodic.friction_continuation import continue_friction, joined, on_branch, switch_branch
from reduced.periodic.friction_shooting import flow, hb_at_frequency, hb_displacements, hb_nodes, shoot_friction
from reduced.periodic.friction_sweep import sweep_friction
from reduced.periodic.hb import NewtonError, _phases, _projection_matrix
from reduced.transient.friction import integrate_exact_friction, reference_dop853

SAMPLES_PER_PERIOD = 400  # of the exact run's output: the amplitude read on these (error ~ (pi / 400)^2 / 2 = 3e-5)
SETTLE_CHUNK = 10  # periods run at a time between two settling checks
SHOOT_H_FACTORS = (2, 4)  # where shooting from the curve's orbit (H) does not converge, HB at f with 2H + 1, then
# 4H + 1 harmonics is the next start (measured at 20.6 Hz in the scene: from H = 5 and 11 Newton stalls at a defect
# of 2e-2 and 2e-3, from H = 21 it converges in 6 steps)
SHOOT_SAMPLES = 500  # of each of the 8 segments of a shot orbit: its amplitudes read on 4000 points a period
SHOOT_CONTINUATION_DS = 0.3  # the first arclength step of the continued shooting (z / D and Hz: ~0.1 Hz at the
# start's tangent in the scene; measured from 14.29 Hz down, 10 points over 0.9 Hz in 3.9 s CPU, load 4)
SHOOT_CONTINUATION_DS_MAX = 2.0  # its bound: away from the resonances the amplitudes move slowly, the steps grow
HB_CONVERGENCE_H = (5, 9, 15, 25)  # HB at each continued branch's start frequency, each H from the last one found,
# else from the shot orbit's harmonics (measured 0.1-0.7 s of CPU each at H = 25 in the scene)
START_HARMONICS = 41  # of the shot orbit, HB's second start where Newton does not converge from the last H found
VERDICT_SAMPLES = 64  # a segment, where the shot orbit is compared with DOP853 and HB (512 a period at S = 8)
HB_MAX_ITER = 30  # Newton steps of each: from the H before it converges in 5-30 (measured; the AFT residual has kinks)
# a start that needs more is not near an HB solution (60 steps that fail cost 1-4 s of CPU at H = 25)
SWITCH_KINDS = ("fold", "branch_point", "period_doubling")  # the bifurcations branch switching is tried at
SWITCH_STEPS = 6  # points each way of a family switched onto (measured on the scene: 0.4-0.9 s of CPU a switch
# that finds none, 2.3-2.8 s one that finds and continues a family 5 points each way, load 8)
SWEEP_STEP_HZ = 0.1  # the grid of exact orbits where the continued branches leave the contact band uncovered
# (:func:`_swept`; measured on the scene: 14.3-17.1 Hz, 28 of 28 orbits in 3.8 s of CPU, 0.1 Hz apart from the
# previous one in 2-6 Newton steps)
MEET_REL = 2e-2  # a continued orbit within this of a branch before it (interpolated linearly between its points)
# is on it: the interpolation's own error between points ~0.1 Hz apart is below 1e-2 off the folds
def load_vector(spec, rows: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(n,) b: the row of ``[frc] point`` plus ``also_weights`` times the rows of ``also_points``.

    Parameters
    ----------
    spec : the [frc] table
    rows : (p, n) the output points' rows
    names : the output points' names

    Examples
    --------
    >>> import numpy as np
    >>> from bearingshaft.scenes.tables import FRCSpec
    >>> load_vector(FRCSpec(point="x3", also_points=("u",), also_weights=(0.5,)), np.eye(4), ("x1", "x2", "x3", "u"))
    array([0. , 0. , 1. , 0.5])
    """
    b = np.array(rows[names.index(spec.point)], float)
    for p, w in zip(spec.also_points, spec.also_weights, strict=True):
        b = b + w * rows[names.index(p)]
    return b


def settle(system, b: np.ndarray, P: float, f: float, state, tol: float, max_s: float) -> tuple:
    """The exact friction response at f from ``state`` = (x, v, w), run SETTLE_CHUNK periods at a time until the
    last period's amplitudes at the points move by less than ``tol`` (relative) from those SETTLE_CHUNK periods
    before, or ``max_s``.

    Parameters
    ----------
    system : the gap system with sliders
    b : (n,) the load direction
    P : N, the load amplitude
    f : Hz, the load frequency
    state : (x, v, w) the start: positions, velocities, the sliders' positions
    tol : relative change that counts as settled
    max_s : s, the longest run

    Returns
    -------
    (x_last_period (spp + 1, n), friction work of the last period J, change, settled, simulated s, end state)
    """
    spp, T = SAMPLES_PER_PERIOD, 1.0 / f
    loads = Loads(np.atleast_2d(b), (Harmonic(P, f),))
    x, v, w = state
    before, change, t = None, math.inf, 0.0
    while True:
        run = integrate_exact_friction(system, x, v, SETTLE_CHUNK * T, spp * f, w0=w, loads=loads)
        t += SETTLE_CHUNK * T
        last = run.x[-spp - 1:]
        amp = np.max(np.abs(last), axis=0)
        x, v, w = run.x[-1].copy(), run.v[-1].copy(), run.w[-1].copy()
        if before is not None:
            change = float(np.max(np.abs(amp - before)) / max(float(np.max(amp)), 1e-300))
        before = amp
        if change < tol or t >= max_s:
            work = float(run.friction[-1] - run.friction[-spp - 1])
            return last, work, change, change < tol, t, (x, v, w)


def compute(scene: Scene, progress: bool = False) -> FrictionFRCResult:
    """The HB curves with friction, their Hill stability and the stepped sine by the exact friction integrator.

    Parameters
    ----------
    scene : a scene with [frc] whose model has friction
    progress : unused (the curves print nothing)

    Returns
    -------
    FrictionFRCResult
    """
    spec = scene.frc
    system, rows = model_system(scene.model, progress)
    names = tuple(scene.model.point_names)
    b = load_vector(spec, rows, names)
    rows = np.asarray(rows, float)
    curves, checks, linear, shooting, verdicts, sweeps, stats = {}, {}, {}, {}, {}, {}, {"levels": {}}
    maps = {}
    f_lin = np.geomspace(spec.freq_min_hz, spec.freq_max_hz, 400)
    for P in spec.levels_N:
        t0 = time.perf_counter()
        try:
            br = friction_frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, spec.harmonics,
                              harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                              continuation=FRC_STEPS.replace(max_steps=spec.max_steps))
        except ContinuationError as exc:
            br = exc
        wall = time.perf_counter() - t0
        curves[P] = br
        linear[P] = (f_lin, linear_frf(system.with_friction(None), b, P, f_lin, rows))
        tm, cm = time.perf_counter(), time.process_time()
        maps[P] = frc_friction_map.compute_map(system, b, P, spec, br, rows, names, check_frequencies(spec))
        map_st = {"wall_s": time.perf_counter() - tm, "cpu_s": time.process_time() - cm}
        t1 = time.perf_counter()
        checks[P] = _checks(system, b, P, spec, br, rows, maps[P])
        st = {"hb_wall_s": wall, "map": map_st, "check_wall_s": time.perf_counter() - t1,
              "shooting": [{"freq_hz": c.freq_hz, "converged": c.shooting.converged, "start_H": c.shooting.start_H,
                            "wall_s": c.shooting.wall_s} for c in checks[P] if c.shooting is not None]}
        if not isinstance(br, Exception):
            st.update(points=len(br.freq_hz), hill_wall_s=br.stability_wall_s, status=br.status,
                      bifurcations=[[int(i), k] for i, k in br.bifurcations])
        errs = [c.rel_error for c in checks[P] if math.isfinite(c.rel_error)]
        st["worst_check_error"] = max(errs) if errs else math.nan
        t2, c2 = time.perf_counter(), time.process_time()
        verdicts[P] = []
        shooting[P] = _continued(spec, br, checks[P], rows, verdicts[P])
        st["continued_shooting"] = {"wall_s": time.perf_counter() - t2, "cpu_s": time.process_time() - c2}
        if isinstance(shooting[P], list):
            st["continued_shooting"]["branches"] = [
                {"points": len(c.branch.freq_hz), "status": c.branch.status, "origin": c.origin,
                 "bifurcations": [[int(i), k] for i, k in c.branch.bifurcations],
                 "switches": [[int(w.index), w.kind, w.freq_hz, w.outcome] for w in c.switches]}
                for c in shooting[P]]
        t3, c3 = time.perf_counter(), time.process_time()
        sweeps[P] = _swept(spec, br, checks[P], shooting[P], rows)
        st["sweep"] = {"wall_s": time.perf_counter() - t3, "cpu_s": time.process_time() - c3}
        if isinstance(sweeps[P], list):
            st["sweep"]["stretches"] = [[float(a), float(b_), int(sw.converged.sum()), len(sw.freq_hz)]
                                        for a, b_, sw, _ in sweeps[P]]
        stats["levels"][str(P)] = st
    return FrictionFRCResult(scene, names, b, curves, checks, linear, stats, shooting, verdicts, sweeps,
                             response_maps=maps)


def _continued(spec, br, checks: list, rows: np.ndarray, verdicts: list | None = None) -> list | str:
    """The exact orbits continued both ways in frequency from every orbit shot at an unsettled point (in frequency
    order; :func:`reduced.periodic.friction_continuation.continue_friction`), each way for at most ``[frc]
    shooting_steps`` // 2 points, until it leaves the band or meets a branch continued before it (:func:`_meets`);
    a start already on such a branch is not continued again. The up direction also ends where it comes back onto
    its own down half, and either where it turns back onto its own path, fails, or leaves the band
    (:func:`reduced.periodic.friction_continuation.continue_friction`: each end with its reason). Each point against
    the HB curve's solution at its frequency nearest it; each branch's start orbit judged by :func:`_verdict` into
    ``verdicts``. A list of ShootingCurve, or why none (a str)."""
    half = spec.shooting_steps // 2
    if half <= 0:
        return "not run: shooting_steps = 0"
    starts = sorted((c.shooting.orbit for c in checks if c.shooting is not None and c.shooting.orbit is not None),
                    key=lambda o: o.freq_hz)
    if not starts:
        return "not run: no orbit was shot at an unsettled point of the stepped sine"
    done: list = []
    out, switched = [], []
    for start in starts:
        a0 = np.max(np.abs(start.orbit(SHOOT_SAMPLES // 10)[1][:, :rows.shape[1]] @ rows.T), axis=0)
        if _meets(_of_period(done, 1), start.freq_hz, a0):
            continue
        kw = dict(max_steps=half, point_rows=rows, ds=SHOOT_CONTINUATION_DS, ds_max=SHOOT_CONTINUATION_DS_MAX,
                  leave_contact=True)
        down = continue_friction(start, spec.freq_min_hz, spec.freq_max_hz, direction=-1.0,
                                 stop=lambda f, a: _met(_of_period(done, 1), [], f, a), **kw)
        up = continue_friction(start, spec.freq_min_hz, spec.freq_max_hz, direction=1.0,
                               stop=lambda f, a, down=down: _met(_of_period(done, 1), [down], f, a), **kw)
        branch = joined(down, up)
        done.append(branch)
        out.append(_against_hb(branch, br))
        if verdicts is not None:
            verdicts.append(_verdict(start, br, rows))
        switched += _switched(spec, br, start, out[-1], len(out), done, kw)
    return out + switched  # the families switched onto after the continued branches: those keep their numbers


def _swept(spec, br, checks: list, scs, rows: np.ndarray) -> list | str:
    """Exact orbits on a grid (SWEEP_STEP_HZ) over each stretch of the HB curve's contact band the continued branches
    do not reach (:func:`reduced.periodic.friction_sweep.sweep_friction`: Newton at each fixed frequency with the
    exact Jacobian, from the previous frequency's orbit, else from HB's there): from each end of the stretch inwards,
    each from the continued orbit at that end where a branch ends there (else from HB's), the second towards the
    last frequency the first reached; each direction ends after ``MAX_FAIL`` frequencies in a row without an orbit.
    [(f_from, f_to, FrictionSweep, HB's amplitudes (k, q) nearest its orbits)] in the order swept, or why not."""
    curves = [c for c in scs if isinstance(c, ShootingCurve)] if isinstance(scs, list) else []
    if isinstance(br, Exception) or not curves:
        return "not run: no HB curve or no continued branch"
    like = next(c.shooting.orbit for c in checks if c.shooting is not None and c.shooting.orbit is not None)
    band = contact_band(br)
    cov = clip([(float(c.branch.freq_hz.min()), float(c.branch.freq_hz.max())) for c in curves], band)
    ref = float(np.nanmax([np.max(c.branch.amplitude_m[:, 0]) for c in curves]))

    def given(f):
        _, _, X = solution_at_frequency(br, f, ref, 0, stable_only=False)
        return None if X is None else hb_nodes(br.balance, X, f)

    def end_orbit(f):
        """The continued orbit of period T at frequency f (a branch's end), or HB's there."""
        for c in curves:
            if c.branch.periods != 1:
                continue
            j = int(np.argmin(np.abs(c.branch.freq_hz - f)))
            if abs(float(c.branch.freq_hz[j]) - f) <= 1e-9 * f:
                return c.branch.nodes[j]
        return given(f)

    def hb_at(sw):
        """(k, q) HB's amplitudes nearest each grid orbit's (NaN where none)."""
        hb = np.full(sw.amplitude_m.shape, math.nan)
        for j in np.flatnonzero(sw.converged):
            try:
                amp, _, _ = solution_at_frequency(br, float(sw.freq_hz[j]), float(sw.amplitude_m[j, 0]), 0,
                                                  stable_only=False)
            except NewtonError:
                continue
            if amp is not None:
                hb[j] = np.asarray(amp, float)
        return hb

    out = []
    step = SWEEP_STEP_HZ
    for a, b in complement(cov, band):
        if b - a < step:
            continue
        up = sweep_friction(like, a + step, b, step, first=end_orbit(a), given=given, point_rows=rows)
        out.append((a + step, b, up, hb_at(up)))
        reached = float(up.freq_hz[-1]) if len(up.freq_hz) else a
        if b - step > reached + 0.5 * step:
            down = sweep_friction(like, b - step, reached + 0.5 * step, step, first=end_orbit(b), given=given,
                                  point_rows=rows)
            out.append((b - step, reached + 0.5 * step, down, hb_at(down)))
    return out


def _switched(spec, br, start, curve, number: int, done: list, kw: dict) -> list:
    """Branch switching at each fold and branch point of a continued branch (``curve``, number ``number``)
    (:func:`reduced.periodic.friction_continuation.switch_branch`: direct shooting at the point's frequency from
    the orbit perturbed along the critical eigenvector), the attempts kept in ``curve.switches``; each new family
    continued both ways for at most ``SWITCH_STEPS`` points (until it leaves the contact or meets a branch
    continued before it, the one it left included: then it is that branch's other side, not a new family), added
    to ``done``; returns the new families' ShootingCurves. A new family's own bifurcations are not switched at
    (the CPU budget)."""
    out = []
    for i, kind in curve.branch.bifurcations:
        if kind not in SWITCH_KINDS:
            continue
        q = 2 * curve.branch.periods if kind == "period_doubling" else curve.branch.periods  # the new family's period
        cont_kw = dict(kw, max_steps=SWITCH_STEPS, band=(spec.freq_min_hz, spec.freq_max_hz),
                       stop=lambda f, a, q=q: _met(_of_period(done, q), [], f, a))
        sw = switch_branch(start, curve.branch, int(i), kind, continue_kw=cont_kw)
        curve.switches.append(sw)
        if sw.branch is not None and all("met a branch" in w for w in sw.branch.status.split("; up: ")):
            # off the branch's interpolated amplitudes (near a fold they are far from linear in f), but met a
            # branch continued before both ways at once: a stretch of it, not a new family
            sw.outcome, sw.branch = f"same branch: its continuation met a branch both ways ({sw.branch.status})", None
        if sw.branch is not None:
            done.append(sw.branch)
            new = _against_hb(sw.branch, br)
            new.origin = f"switched at branch {number}'s {kind} near {sw.freq_hz:.5g} Hz"
            out.append(new)
    return out


def _of_period(branches: list, periods: int) -> list:
    """The branches whose orbits have period ``periods`` T (a period-doubled family's amplitudes, over 2T, meet its
    T branch's at the bifurcation: it is not that branch)."""
    return [b for b in branches if b.periods == periods]


def _met(done: list, own: list, f: float, a: np.ndarray) -> str | None:
    """Why a continued direction ends at (f, a): on a branch continued before, or back on its own down half (the
    up direction past a fold); None to go on."""
    if _meets(done, f, a):
        return f"met a branch continued before at f = {f:.6g} Hz"
    if _meets(own, f, a):
        return f"turned back onto its own down half at f = {f:.6g} Hz"
    return None


def _meets(branches: list, f: float, a: np.ndarray) -> bool:
    """Whether the orbit of amplitudes ``a`` at f lies on one of ``branches``: between two consecutive points of
    it, within MEET_REL of the amplitudes interpolated linearly in frequency
    (:func:`reduced.periodic.friction_continuation.on_branch`)."""
    return any(on_branch(b.freq_hz, b.amplitude_m, f, a, MEET_REL) for b in branches)


def _verdict(start, br, rows: np.ndarray) -> BranchVerdict:
    """Who is right at a continued branch's start orbit (issue 25's rule: the drawn curve is the converged one).

    Shooting: its defect, one exact run over the period (period defect), and DOP853 restarted at every state change
    over the period from the orbit's first node, sampled VERDICT_SAMPLES a segment, against the exact flow run from
    each node (max |y_DOP853 - y_exact| / D). HB: at the orbit's frequency for each H of HB_CONVERGENCE_H, Newton
    from the last H found (the first from the curve's HB orbit there), else from the shot orbit's START_HARMONICS
    harmonics, its amplitudes and time histories against the shot orbit's."""
    system, f, S = start.system, start.freq_hz, start.nodes.shape[0]
    n = system.n
    m = VERDICT_SAMPLES
    t, y = start.orbit(m)
    x = y[:, :n] @ rows.T
    A = np.max(np.abs(x), axis=0)
    loads = Loads(np.atleast_2d(start.b), (Harmonic(start.amplitude_N, f, start.phase_deg),))
    y0 = start.nodes[0]
    ref = reference_dop853(system, y0[:n], y0[n:2 * n], 1.0 / f, m * S * f, w0=y0[2 * n:], loads=loads, rtol=1e-12)
    yr = np.hstack([ref.x, ref.v, ref.w])
    k = min(len(yr), len(y))
    dop = float(np.max(np.abs(yr[:k] - y[:k]) / start.scale))
    end = flow(system, start.b, start.amplitude_N, f, y0, 0.0, 1.0 / f, 1, start.phase_deg)[-1]
    out = BranchVerdict(f, A, float(start.defect), float(np.max(np.abs(end - y0) / start.scale)), dop,
                        float(start.max_abs_multiplier))
    if isinstance(br, Exception):
        return out
    _, _, X = solution_at_frequency(br, f, float(A[0]), 0, stable_only=False)
    shot_X = _projection_matrix(START_HARMONICS, _phases(len(t) - 1)) @ y[:-1, :n]
    fb, Xc = br.balance, X
    for H in HB_CONVERGENCE_H:
        got = None
        for X0 in (Xc, shot_X):
            if X0 is None:
                continue
            try:
                got = hb_at_frequency(fb, X0, f, H, max_iter=HB_MAX_ITER)
                break
            except NewtonError:
                continue
        if got is None:
            out.hb.append((H, None, None))
            continue
        fb, Xc = got
        xh = hb_displacements(Xc, f, t) @ rows.T
        out.hb.append((H, np.max(np.abs(xh), axis=0) / A - 1.0, np.max(np.abs(xh - x), axis=0) / A))
    return out


def _against_hb(branch, br) -> ShootingCurve:
    """The branch with the HB curve's solution at each point's frequency nearest it (any stability)."""
    hb = np.full(branch.amplitude_m.shape, math.nan)
    hb_stable = [None] * len(branch.freq_hz)
    if not isinstance(br, Exception):
        for i, (f, a) in enumerate(zip(branch.freq_hz, branch.amplitude_m, strict=True)):
            try:
                amp, j, _ = solution_at_frequency(br, float(f), float(a[0]), 0, stable_only=False)
            except NewtonError:
                continue
            if amp is not None:
                hb[i] = np.asarray(amp, float)
                hb_stable[i] = bool(br.stable[j]) if br.stable[j] == br.stable[j + 1] else None
    return ShootingCurve(branch, hb, hb_stable)


def check_frequencies(spec) -> np.ndarray:
    """Hz, the ``stepped_sine_points`` frequencies HB is checked at: linear in the band, its ends excluded.

    Parameters
    ----------
    spec : the [frc] table
    """
    k = spec.stepped_sine_points
    return np.linspace(spec.freq_min_hz, spec.freq_max_hz, k + 2)[1:-1] if k > 0 else np.zeros(0)


def _checks(system, b: np.ndarray, P: float, spec, br, rows: np.ndarray, level=None) -> list[FrictionCheck]:
    """HB checked at each of :func:`check_frequencies`: with a response map (``level``, whose grid holds them), from
    the state its up sweep ended in there, SETTLE_CHUNK periods twice (:func:`settle`: the last period's amplitudes
    and friction work), settled where the map found a periodic response (periodic or subharmonic, settled);
    without one, a stepped sine of its own (:func:`settle` until ``stepped_sine_tol`` or ``stepped_sine_max_s``).
    A settled point against the HB solution at its frequency on the stable piece nearest it; elsewhere the orbit is
    shot for (:func:`_shoot`)."""
    n = system.n
    state = (np.zeros(n), np.zeros(n), None)
    out = []
    for f in check_frequencies(spec):
        got = frc_friction_map.state_at(level, float(f))
        if got is None:
            last, work, change, ok, t, state = settle(system, b, P, float(f), state, spec.stepped_sine_tol,
                                                      spec.stepped_sine_max_s)
        else:
            pt, y = got
            last, work, change, _, t, _ = settle(system, b, P, float(f), (y[:n], y[n:2 * n], y[2 * n:]), 0.0,
                                                 1.5 * SETTLE_CHUNK / f)
            t += pt.n_periods / f
            ok = pt.settled and pt.regime in ("periodic", "subharmonic")
        exact = np.max(np.abs(last @ rows.T), axis=0)
        hb = np.full(len(rows), math.nan)
        if not isinstance(br, Exception):
            amp, _, _ = solution_at_frequency(br, float(f), float(exact[0]), 0, stable_only=True)
            if amp is not None:
                hb = np.asarray(amp, float)
        shot = None if ok else _shoot(system, b, P, float(f), br, float(exact[0]), rows)
        out.append(FrictionCheck(P, float(f), exact, hb, change, ok, t, work, shot))
    return out


def _shoot(system, b: np.ndarray, P: float, f: float, br, amplitude_ref: float, rows: np.ndarray) -> ShootCheck:
    """Shooting from the curve's HB orbit at f (any stability; the piece nearest ``amplitude_ref`` at the first
    point), then from HB at f with more harmonics (SHOOT_H_FACTORS) while it does not converge."""
    if isinstance(br, Exception):
        return ShootCheck(False, "not run: no HB curve")
    amp, i, X = solution_at_frequency(br, f, amplitude_ref, 0, stable_only=False)
    if X is None:
        return ShootCheck(False, "not run: no HB solution at this frequency")
    hb_stable = bool(br.stable[i]) if br.stable[i] == br.stable[i + 1] else None
    H = br.balance.H
    t0 = time.perf_counter()
    fb, Xs, tried = br.balance, X, []
    for factor in (0, *SHOOT_H_FACTORS):
        if factor:
            try:
                fb, Xs = hb_at_frequency(fb, Xs, f, factor * H + 1)
            except NewtonError as exc:
                tried.append(f"HB with H = {factor * H + 1} not found ({exc})")
                break
        r = shoot_friction(system, b, P, f, hb_nodes(fb, Xs, f), jacobian="exact")
        tried.append(f"from H = {fb.H}: {r.message}")
        if r.converged:
            break
    wall = time.perf_counter() - t0
    common = dict(start_H=fb.H, hb_m=np.asarray(amp, float), defect=r.defect, hb_stable=hb_stable, rank=r.rank,
                  size=r.size, n_iter=r.n_iter, wall_s=wall)
    if not r.converged:
        return ShootCheck(False, "; ".join(tried), **common)
    # the continued shooting starts from this orbit (multipliers again along the branch: not kept here)
    t, y = r.orbit(SHOOT_SAMPLES)
    xs = y[:, :system.n] @ rows.T
    xh = hb_displacements(X, f, t) @ rows.T
    A = np.max(np.abs(xs), axis=0)
    return ShootCheck(True, "; ".join(tried), shoot_m=A, amp_rel=np.abs(np.asarray(amp, float) / A - 1.0),
                      history_rel=np.max(np.abs(xh - xs), axis=0) / A, period_defect=r.period_defect,
                      max_abs_multiplier=r.max_abs_multiplier, stable=r.stable, orbit=r, **common)




__all__ = ["SKIPPED", "BranchVerdict", "FrictionCheck", "FrictionFRCResult", "ShootCheck", "ShootingCurve",
           "check_frequencies", "compute", "load_vector", "settle"]
