"""Stage ``frc``: forced-response curves by harmonic balance under a harmonic load (issue 11).

For each load level P of ``[frc] levels_N`` the load P cos(2 pi f t) acts at ``[frc] point``
and the HB curve (:func:`reduced.periodic.frc.frc`: condensed onto the contact coordinates,
stop forces projected exactly, H = ``harmonics``) is continued in frequency over
[freq_min_hz, freq_max_hz] through its folds. Then:

- stability of every point by the monodromy of the variational equation along the HB orbit,
  by Hill's method at ``hill_points`` points and by the Floquet multipliers of the exact
  periodic orbit, found by multiple shooting on the forced exact flow from the HB orbit, at
  ``shooting_points`` points; folds, branch points, period doublings and Neimark-Sacker
  points where multipliers leave the unit circle (:mod:`reduced.periodic.forced_stability`);
- the reference: a stepped sine by the exact integrator, swept up and down over
  ``stepped_sine_points`` frequencies (half spread over the band, half over the region
  where the curve folds or is unstable, i.e. the jump region), each settled to
  ``stepped_sine_tol`` before the amplitude is read
  (:func:`reduced.periodic.stepped_sine.stepped_sine`); every settled point is compared with
  the HB solution at exactly its frequency on the stable branch it landed on;
- convergence in H at ``convergence_level_N``: each H's curve against the stepped sine
  and against the exact orbits of the shooting points, and its run time;
- the backbone check: with damping and load scaled down together (``backbone_scales``) the
  peak of each curve (H = 1) approaches the NNM backbone computed as the nnm stage does
  (:func:`reduced.periodic.backbones.nnm_branch`, H = 1, AFT with 4096 samples);
- the drawn curve of each level (:func:`converged_curve`): HB where it no longer moves with H, else
  the exact flow's families by shooting (:mod:`reduced.periodic.exact_frc`);
- the response map (:mod:`bearingshaft.stages.frc_map`): a dense stepped sine up and down, each
  frequency classified by the exact flow and its Lyapunov exponent.

:func:`compute` runs all of it into an :class:`FRCResult`; :func:`write`
(:mod:`bearingshaft.stages.frc_files`) writes the files listed in :data:`DESCRIPTION`.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import replace

import numpy as np

from bearingshaft.estimates import FLOAT, HILL_COPIES, Estimate, has_friction, n_dofs
from bearingshaft.fanout import fan_out
from bearingshaft.output import StageWriter
from bearingshaft.progress import bar as progress_bar
from bearingshaft.reproduction import Reproduction, chaotic, exact, sensitive, within
from bearingshaft.scenes import Scene
from bearingshaft.stages.frc_friction import load_vector
from bearingshaft.stages.frc_map import compute_maps
from bearingshaft.stages.frc_results import ConvergedCurve, ConvergenceRun, FRCResult, OpenGapOrbits, PointCheck
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.models.modes import linear_modes
from reduced.models.symmetry import symmetrized, tip_mirror
from reduced.periodic.backbones import NNM_STEPS, nnm_branch
from reduced.periodic.continuation import ContinuationError
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc, hb_start
from reduced.periodic.exact_hb import default_root_samples
from reduced.periodic.forced_balance import ForcedBalance, ForcedResidual
from reduced.periodic.forced_stability import (
    HILL_TOL,
    BranchStability,
    ShootingError,
    floquet_by_shooting,
    forced_hill,
    hb_states,
)
from reduced.periodic.frc import (
    FRC_STEPS,
    FRCBranch,
    _synthesis,
    default_x_ref,
    frc,
    linear_frf,
    max_abs_over_period,
    open_gap_orbits,
    solution_at_frequency,
)
from reduced.periodic.hb import NewtonError, _derivative_matrix, newton
from reduced.periodic.stepped_sine import SteppedSine, stepped_sine
from reduced.periodic.uncovered import close_return_families, cover_verdicts
from reduced.transient.exact import integrate_exact
from reduced.transient.flow import Flow

JUMP_FRACTION = 0.5  # of the stepped-sine frequencies, the part spread over the jump region
JUMP_MARGIN = 1.1  # the jump region: folds and unstable points, widened by this factor on each side
BACKBONE_SAMPLES = 4096  # AFT samples of the H = 1 backbone (its AFT error near grazing ~ N^-2)
BACKBONE_ENERGY_FACTOR = 4.0  # backbones run to this many times the energy of the most energetic peak drawn
BACKBONE_DS = 0.01  # continuation step of the backbones (log10 amplitude): polyline error ~1e-7 at the peaks
ORBIT_SAMPLES = 2048  # samples of one period of an exact orbit for its amplitude
HB_CHECK_POINTS = 200  # points of an HB curve compared with the next lower H at most
START_GUESSES = 12  # HB orbits tried as guesses of the first exact orbit (f_min first)
RESONANCE_SPAN = 6.0  # a lightly damped mode's band: f_r (1 +- RESONANCE_SPAN zeta_r), its peak and flanks
RESONANCE_POINTS = 8  # an HB curve with fewer points in that band has stepped over the peak: refined there
RESONANCE_PEAK = 1.5  # ... where the linear response at f_r is this many times that at the band's edges
OPEN_MARGIN = 1.05  # a refinement band is in contact if its linear response passes a stop by 5 %: its HB points
# around the peak (RESONANCE_POINTS of them within the band) then pass it too


def compute(scene: Scene, progress: bool, workdir=None) -> FRCResult:
    """The curves, their checks, the stepped sine, the convergence study and the backbone check.

    Parameters
    ----------
    scene : a scene with an [frc] table
    progress : draw a progress bar
    workdir : unused (nothing is streamed to disk)

    Returns
    -------
    FRCResult
        Dense algebra on one BLAS thread (the same sums whatever the machine's core count).
    """
    from bearingshaft.stages import frc_friction

    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps
        if has_friction(scene):  # HB by AFT with the sliders (frc_friction: what it skips and why)
            return frc_friction.compute(scene, progress)
        return _compute(scene, progress)


def _compute(scene: Scene, progress: bool) -> FRCResult:
    spec = scene.frc
    system, rows = model_system(scene.model, progress)
    names = tuple(scene.model.point_names)
    load_col = names.index(spec.point)
    b = load_vector(spec, rows, names)  # the point's row, plus [frc] also_points (a slanted load)
    system, b, mirror_note = mirror_symmetric(system, b)
    levels = list(spec.levels_N)
    n_tasks = 4 * len(levels) + len(spec.convergence_harmonics) + len(levels) * len(spec.backbone_scales) + 1
    n_tasks += len(levels) if spec.map_step_hz > 0 else 0  # the response map (frc_map)
    bar = progress_bar(total=n_tasks, desc=f"{scene.name}: forced response", enabled=progress, unit="task")
    # each level's HB curve, then what each level computes from its curve: independent pieces, on the job's
    # cluster when there is one (bearingshaft.fanout), results in the order of the levels either way
    bar.set_postfix_str(f"HB at H={spec.harmonics}")
    curves = dict(zip(levels, fan_out(_level_part, [("curve", system, b, P, spec, None, rows, names, load_col)
                                                     for P in levels]), strict=True))
    bar.update(len(levels))
    parts = [p for p in LEVEL_PARTS if p != "map" or spec.map_step_hz > 0]
    bar.set_postfix_str("converged curves, Hill and shooting, stepped sines" + (", maps" if "map" in parts else ""))
    # the longest pieces first (a cluster starts them in this order): the converged curves and the maps, the
    # highest level first (the most contact), then the stepped sines and the checks
    jobs = [(part, system, b, P, spec, curves[P], rows, names, load_col) for part in parts
            for P in sorted(levels, reverse=True)]
    done = dict(zip([(job[0], job[3]) for job in jobs], fan_out(_level_part, jobs), strict=True))
    bar.update(len(jobs))
    converged = {P: done[("converged", P)] for P in levels}
    checks = {P: done[("checks", P)] for P in levels}
    sweeps = {P: done[("sweeps", P)] for P in levels}
    sweep_hb = {(P, d): _hb_at_sweep(curves[P], ss, load_col) for P in levels for d, ss in sweeps[P].items()}
    convergence = _convergence(system, b, spec, rows, names, load_col, curves, checks, sweeps, bar)
    backbone = _backbone_check(system, b, rows, names, spec, load_col, curves, bar,
                               {(spec.convergence_level_N, r.H): r.curve for r in convergence})
    maps = {P: done[("map", P)] for P in levels} if "map" in parts else {}
    uncovered_orbits(system, b, rows, names, spec, curves, converged, maps)  # needs a level's curve and map together
    bar.close()
    return FRCResult(scene.name, spec, names, load_col, curves, {P: _events(br, load_col) for P, br in curves.items()},
                     checks, sweeps, sweep_hb, convergence, *backbone, converged=converged, response_maps=maps,
                     mirror_note=mirror_note)


def mirror_symmetric(system: GapSystem, b: np.ndarray) -> tuple[GapSystem, np.ndarray, str]:
    """(system, b, note): the system averaged over its tip mirror x1 <-> x3 when it is symmetric only to the
    round-off of its reduction (:mod:`reduced.models.symmetry`, equation (2)), else as it is; the note says
    which (empty: no tip mirror, or an exact one).

    Parameters
    ----------
    system : the model's gap system
    b : (n,) load direction
    """
    R, err = tip_mirror(system, b)
    if R is None or err == 0.0:  # no tip mirror, or an exact one: the system as it is
        return system, b, ""
    flipped = [system.dof_names[k] for k in range(system.n) if R[k, k] < 0]
    system, b = symmetrized(system, b, R)
    signs = f", with {', '.join(flipped)} -> minus itself" if flipped else ""
    return system, b, (f"The model is mirror symmetric (x1 <-> x3{signs}) "
                       f"to {err:.2g} of its largest entries (the round-off of the reduction); the forced response "
                       "uses it averaged over the mirror, so that the pitchforks breaking x1 = x3 are found and "
                       "followed (asymmetric families).")


LEVEL_PARTS = ("converged", "map", "sweeps", "checks")  # what _level_part computes from a level's HB curve


def _level_part(job: tuple):
    """One independent piece of a level: ``job = (part, system, b, P, spec, curve, rows, names, load_col)`` with
    part "curve" (the HB curve at ``harmonics``, ``curve`` unused) or one of :data:`LEVEL_PARTS` of that curve."""
    part, system, b, P, spec, br, rows, names, load_col = job
    if part == "curve":
        return _curve(system, b, P, spec, spec.harmonics, rows, names, hill_points=0)
    if part == "converged":
        return converged_curve(system, b, P, spec, br, rows, names)
    if part == "checks":
        return [] if isinstance(br, Exception) else _point_checks(system, b, P, br, rows, spec)
    if part == "sweeps":
        return _sweeps(system, b, P, spec, br, rows, names, load_col)
    if part == "map":
        return compute_maps(system, b, rows, names, spec, {P: br}, levels=(P,))[P]
    raise ValueError(f"unknown part {part!r}")


def _curve(system, b, P, spec, H, rows, names, f_band=None, **kw):
    """One FRC with the scene's settings (over ``f_band`` = (Hz, Hz) instead of the scene's band if
    given); a start that fails is reported, not raised."""
    f0, f1 = f_band or (spec.freq_min_hz, spec.freq_max_hz)
    try:
        return frc(system, b, P, f0, f1, H,
                   harmonics="odd" if spec.odd_harmonics else "all", point_rows=rows, point_names=names,
                   continuation=FRC_STEPS.replace(max_steps=spec.max_steps), **kw)
    except ContinuationError as exc:
        return exc


def _evenly(k: int, count: int) -> np.ndarray:
    """At most ``count`` indices spread evenly over 0..k-1.

    >>> _evenly(10, 3).tolist(), _evenly(2, 5).tolist(), _evenly(4, 0).tolist()
    ([0, 4, 9], [0, 1], [])
    """
    if count <= 0 or k == 0:
        return np.zeros(0, int)
    return np.unique(np.round(np.linspace(0, k - 1, min(count, k))).astype(int))


# -- the converged curve of each level --------------------------------------------------------------
def check_harmonics(spec) -> int:
    """H of the balance the HB curve is compared with: the largest of ``convergence_harmonics`` below
    ``harmonics`` (odd with odd_harmonics), else the next lower H of the set (0 if H = 1).

    Parameters
    ----------
    spec : FRCSpec
        The ``[frc]`` table.

    Returns
    -------
    int

    Examples
    --------
    >>> from bearingshaft.scenes.tables import FRCSpec
    >>> check_harmonics(FRCSpec()), check_harmonics(FRCSpec(harmonics=3, convergence_harmonics=(3, 5)))
    (9, 1)
    """
    H, step = spec.harmonics, 2 if spec.odd_harmonics else 1
    lower = [h for h in spec.convergence_harmonics if h < H and (h % 2 == 1 or not spec.odd_harmonics)]
    return max(lower) if lower else max(H - step, 0)


def hb_change(br: FRCBranch, H_check: int, max_points: int = HB_CHECK_POINTS) -> float:
    """Largest relative change from the HB curve ``br`` to the balance with ``H_check`` harmonics at
    the same frequencies, of the amplitudes (every output point) and, where a stop closes, of its
    penetration max|B_j x| - |o_j| (relative to the larger of the two; the contact itself, which
    the amplitude hides: a penetration 20 % off changes a 1.01 g amplitude by 0.2 %). Newton at each
    frequency (at most ``max_points`` of the curve's points, evenly spread) from the curve's own
    coefficients cut to H_check; inf where Newton does not converge.

    Parameters
    ----------
    br : the HB curve
    H_check : harmonics of the comparison (>= 1)
    max_points : points compared at most

    Returns
    -------
    float
        The largest change over the points.
    """
    fb0 = br.balance
    s = fb0.system
    fb = ForcedBalance(s, fb0.b, fb0.amplitude_N, fb0.phase_deg, H_check, default_root_samples(H_check), fb0.odd)
    res = ForcedResidual(fb, br.x_ref, float(br.omega.max()))
    n = res.size
    gap = np.abs(s.offset)
    worst = 0.0
    for i in _evenly(len(br.freq_hz), max_points):
        q = fb0.full_q(br.z[i])[: 2 * H_check + 1]
        lw = math.log(br.omega[i] / res.omega_ref)

        def fun(v, lw=lw):
            R, J = res(np.append(v, lw))
            return R, J[:, :n]

        try:
            v = newton(fun, q[fb.keep].ravel() / br.x_ref, tol=1e-12, max_iter=30).y
        except NewtonError:
            return math.inf
        X = fb.response(v * br.x_ref, float(br.omega[i]))
        amp = max_abs_over_period(X, br.point_rows)
        worst = max(worst, float(np.max(np.abs(amp / br.amplitude_m[i] - 1.0))))
        pen = max_abs_over_period(X, s.B) - gap
        pen0 = max_abs_over_period(br.X[i], s.B) - gap
        both = np.maximum(pen, pen0)
        closed = both > 0.0
        if np.any(closed):
            worst = max(worst, float(np.max(np.abs(pen - pen0)[closed] / both[closed])))
    return worst


def converged_curve(system: GapSystem, b: np.ndarray, P: float, spec, br, rows: np.ndarray, names: tuple
                    ) -> ConvergedCurve:
    """The drawn curve of level P (``[frc] curve``): HB at ``harmonics`` where its amplitudes move by no
    more than ``hb_converged_tol`` from the next lower H (:func:`check_harmonics`), else the families
    of exact periodic orbits continued by multiple shooting from the HB orbit at f_min
    (:func:`reduced.periodic.exact_frc.exact_frc`, with branch switching as the table says). If
    shooting fails, HB is drawn and the reason says it is not converged.

    Parameters
    ----------
    system, b, P : the gap system, the load direction (n,) and its amplitude (N)
    spec : the [frc] table
    br : the HB curve of the level (or the ContinuationError of one that could not start)
    rows, names : the output points

    Returns
    -------
    ConvergedCurve
    """
    t0 = time.perf_counter()
    ok = not isinstance(br, Exception)
    in_contact = _in_contact(system, br) if ok else np.zeros(0, bool)  # read twice: worked out once
    contact = bool(np.any(in_contact)) if ok else True
    Hc = check_harmonics(spec)
    change = hb_change(br, Hc) if ok and Hc >= 1 else math.nan
    method = spec.curve
    if method == "auto":
        method = "hb" if ok and change <= spec.hb_converged_tol else "shooting"
    if method == "hb":
        why = (f"HB at H = {spec.harmonics}: its amplitudes{' and penetrations' if contact else ''} move by at most "
               f"{change:.2g} (relative) from H = {Hc} ({'a stop closes' if contact else 'no stop closes'} along it)")
        refined, notes = resonance_refinements(system, b, P, spec, br, rows, names) if ok else ((), [])
        if notes:
            why += "; " + "; ".join(notes)
        return ConvergedCurve(P, "hb", why, spec.harmonics, Hc, change, contact, None, "", time.perf_counter() - t0,
                              refined)
    opts = _exact_options(spec)
    S = opts.segments
    try:
        if ok:  # the HB orbits at f_min, then at points spread over the curve (where HB is far from exact)
            idx = np.concatenate([[0], _evenly(len(br.freq_hz), START_GUESSES)[1:]])
            start = [(float(br.freq_hz[i]), hb_states(br.X[i], float(br.omega[i]), S)) for i in idx
                     if spec.freq_min_hz <= br.freq_hz[i] <= spec.freq_max_hz]
            x_ref = br.x_ref
            # the HB orbits in contact: guesses of the orbits of the contact band no family covers (isolated families)
            cover = [(float(br.freq_hz[i]), hb_states(br.X[i], float(br.omega[i]), S))
                     for i in np.flatnonzero(in_contact) if spec.freq_min_hz <= br.freq_hz[i] <= spec.freq_max_hz]
        else:
            start = hb_start(system, b, P, spec.freq_min_hz, S)
            x_ref = float(np.max(np.abs(start[:, : system.n])))
            cover = []
        ex = exact_frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, start, point_rows=rows, point_names=names,
                       x_ref=x_ref, options=opts, cover=cover, mirror=tip_mirror(system, b)[0])
    except (ShootingError, ContinuationError, NewtonError, RuntimeError) as exc:
        err = " ".join(str(exc).split())[:200]
        why = f"shooting failed ({err}): the HB curve at H = {spec.harmonics} is drawn and is NOT converged"
        return ConvergedCurve(P, "hb", why, spec.harmonics, Hc, change, contact, None, err, time.perf_counter() - t0)
    why = (f"exact flow, by shooting: HB at H = {spec.harmonics} moves by {change:.2g} (relative, amplitudes"
           f"{' and penetrations' if contact else ''}) from H = {Hc}"
           + (" (a stop closes along it: HB in contact needs H ~ 255, tests/test_frc_contact.py)" if contact else ""))
    if spec.curve == "shooting":
        why = "exact flow, by shooting ([frc] curve = \"shooting\")"
    fill, refined = np.zeros(0, bool), ()
    outside = ~ex.covered(br.freq_hz) if ok else np.zeros(0, bool)
    if ok and outside.any():
        # the families end inside the band (they retraced their paths or left it): outside their ranges the
        # HB points whose orbits close no stop are linear, HB exact to round-off there: drawn instead
        fill = outside & ~in_contact
        refined, notes = resonance_refinements(system, b, P, spec, br, rows, names, open_only=True)
        refined = tuple(r for r in refined if not np.any(ex.covered(r.freq_hz)) and not np.any(_in_contact(system, r)))
        why += (f"; the exact families cover {_bands(ex.covered, br.freq_hz)} only: outside them the "
                f"{int(fill.sum())} HB points whose orbits close no stop (linear: exact) are drawn, "
                f"{int(np.sum(outside & ~fill))} in contact are not")
        if refined:
            why += "; " + "; ".join(n for n in notes if "drawn from" in n)
    if ex.cover_freqs_hz.size:
        made = sum(r["family"] >= 0 for r in ex.cover)
        why += (f"; {made} isolated famil{'y' if made == 1 else 'ies'} started from HB orbits in contact no family "
                f"covered ({len(ex.cover)} tried, `[frc] cover_families = {spec.cover_families}`)")
    open_gap = _open_gap(system, b, P, br, rows, in_contact) if ok else None
    if open_gap is not None:
        runs = ", ".join(f"{open_gap.freq_hz[open_gap.segment == k].min():.5g}-"
                         f"{open_gap.freq_hz[open_gap.segment == k].max():.5g} Hz" for k in np.unique(open_gap.segment))
        hot = int(np.sum(np.isin(open_gap.freq_hz, br.freq_hz[in_contact])))
        why += (f"; the orbit of the open-gap (linear) system closes no stop over {runs} ({hot} frequencies where "
                f"the HB orbit closes one; {'stable' if open_gap.stable else 'unstable'}): an exact orbit, drawn")
    return ConvergedCurve(P, "shooting", why, spec.harmonics, Hc, change, contact, ex, "", time.perf_counter() - t0,
                          refined, fill, open_gap)


def linear_start_families(system: GapSystem, b: np.ndarray, P: float, spec, rows: np.ndarray, names: tuple):
    """The exact families of level P as :func:`converged_curve` continues them (its options from the [frc]
    table), started from the linear orbit at the band's top (closed form, every stop open) instead of HB
    guesses: no HB curve is needed. The displacement scale is the HB curve's own
    (:func:`reduced.periodic.frc.default_x_ref`, the largest linear response over the band), so the steps
    are measured alike; the main family is the same one (tests/test_exact_frc_robust.py at 10 N: its
    extent, its 36 folds, its stability), traced from the other end. What benchmarks/converged_curve_speed.py
    times; the stage keeps its HB start (it draws the HB curve, and chooses between HB and shooting, and
    fills outside the families, from it).

    Parameters
    ----------
    system, b, P : the gap system, the load direction (n,) and its amplitude (N)
    spec : the [frc] table
    rows, names : the output points

    Returns
    -------
    reduced.periodic.exact_frc.ExactFRC
        Raises :class:`reduced.periodic.shooting.ShootingError` where the linear orbit at the band's top
        closes a stop (no start).
    """
    fb = ForcedBalance(system, b, P, 0.0, spec.harmonics, default_root_samples(spec.harmonics), True)
    return exact_frc(system, b, P, spec.freq_min_hz, spec.freq_max_hz, [], point_rows=rows, point_names=names,
                     x_ref=default_x_ref(fb, spec.freq_min_hz, spec.freq_max_hz),
                     options=replace(_exact_options(spec), cover_families=0), mirror=tip_mirror(system, b)[0])


def _exact_options(spec) -> ExactFRCOptions:
    """The exact families' options from the [frc] table (an even number of segments)."""
    return ExactFRCOptions(segments=spec.shooting_segments + spec.shooting_segments % 2,
                           branch_switching=spec.branch_switching, max_families=spec.max_families,
                           family_steps=spec.family_steps, max_steps=spec.shooting_steps,
                           period_doubling=spec.period_doubling,
                           period_doubling_families=spec.period_doubling_families,
                           period_doubling_depth=spec.period_doubling_depth,
                           period_doubling_steps=spec.period_doubling_steps, cover_families=spec.cover_families,
                           deadline_s=spec.switching_max_s or math.inf)


def _open_gap(system: GapSystem, b: np.ndarray, P: float, br, rows: np.ndarray, in_contact: np.ndarray
              ) -> OpenGapOrbits | None:
    """The open-gap system's orbits (:func:`reduced.periodic.frc.open_gap_orbits`) at the HB curve's
    frequencies (sorted) that close no stop, from the one before the first frequency where the HB orbit
    closes a stop to the one after the last (so that the line joins the HB points drawn beside it), in
    runs of consecutive frequencies, a run of one frequency left out (no line); None where there is none."""
    if not np.any(in_contact):
        return None
    f = np.unique(br.freq_hz)
    amp, pen, stable = open_gap_orbits(system, b, P, f, rows)
    hot = np.flatnonzero(np.isin(f, br.freq_hz[in_contact]))
    span = np.zeros(f.size, bool)
    span[max(hot[0] - 1, 0): hot[-1] + 2] = True
    keep = span & (pen < 0.0)
    run = np.cumsum(~keep)
    vals, counts = np.unique(run[keep], return_counts=True)
    keep &= np.isin(run, vals[counts >= 2])  # runs of two frequencies or more
    if not np.any(keep[hot]):
        return None
    return OpenGapOrbits(f[keep], amp[keep], -pen[keep], stable, run[keep])


def uncovered_orbits(system: GapSystem, b: np.ndarray, rows: np.ndarray, names: tuple, spec, curves: dict,
                     converged: dict, maps: dict) -> None:
    """What the exact flow has where the families of each level drawn by shooting do not reach, added
    to its :class:`reduced.periodic.exact_frc.ExactFRC` (``verdicts``, ``close_returns``, new families):
    a verdict at ``[frc] verdict_points`` HB points in contact per uncovered band
    (:func:`reduced.periodic.uncovered.cover_verdicts`), then up to ``[frc] close_return_families``
    families of unstable periodic orbits seeded by close returns of the response map's chaotic Poincare
    samples (:func:`reduced.periodic.uncovered.close_return_families`); at the branch points of each family
    found so, up to ``[frc] found_family_switches`` families switched onto.

    Parameters
    ----------
    system, b : the gap system and the load direction (n,)
    rows, names : the output points
    spec : the [frc] table
    curves : P -> the HB curve (or its exception)
    converged : P -> ConvergedCurve (their ExactFRC mutated)
    maps : P -> MapLevel (may be empty)

    Returns
    -------
    None
    """
    col = names.index(spec.point)
    band = (spec.freq_min_hz, spec.freq_max_hz)
    for P, cc in converged.items():
        ex, br = cc.exact, curves.get(P)
        if ex is None or br is None or isinstance(br, Exception):
            continue
        if spec.verdict_points > 0:
            t0 = time.process_time()
            g = [(float(br.freq_hz[i]), float(br.amplitude_m[i, col]),
                  functools.partial(hb_states, br.X[i], float(br.omega[i])))
                 for i in np.flatnonzero(_in_contact(system, br)) if band[0] <= br.freq_hz[i] <= band[1]]
            ex.verdicts = cover_verdicts(ex, system, b, g, points_per_band=spec.verdict_points, f_band=band,
                                         family_steps=spec.close_return_steps,
                                         switch_families=spec.found_family_switches)
            ex.cpu_s["verdicts"] = time.process_time() - t0
        lvl = maps.get(P)
        if spec.close_return_families > 0 and lvl is not None:
            t0 = time.process_time()
            samples = [(float(f), d, p.poincare) for d, rm in lvl.sweeps.items()
                       for f, p in zip(rm.freq_hz, rm.points, strict=True) if p.regime == "chaotic"]
            ex.close_returns = close_return_families(ex, system, b, samples, f_band=band,
                                                     families=spec.close_return_families,
                                                     tries=spec.close_return_tries,
                                                     family_steps=spec.close_return_steps,
                                                     switch_families=spec.found_family_switches)
            ex.cpu_s["close_returns"] = time.process_time() - t0


def _bands(covered, freq_hz: np.ndarray) -> str:
    """'a-b Hz, c-d Hz': the runs of the sorted frequencies that ``covered`` (frequencies -> bool) says are covered.

    >>> _bands(lambda f: (f < 2) | (f > 4), np.array([1.0, 3.0, 5.0, 1.5]))
    '1-1.5 Hz, 5-5 Hz'
    """
    f = np.sort(np.asarray(freq_hz, float))
    mask = np.asarray(covered(f), bool)
    idx = np.flatnonzero(mask)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []
    return ", ".join(f"{f[r[0]]:.5g}-{f[r[-1]]:.5g} Hz" for r in runs) or "no frequency of the HB curve"


def resonance_refinements(system: GapSystem, b: np.ndarray, P: float, spec, br: FRCBranch, rows: np.ndarray,
                          names: tuple, open_only: bool = False) -> tuple[tuple, list[str]]:
    """HB curves over the bands of the lightly damped linear modes that ``br`` steps over.

    The continuation's unknowns are scaled by the largest response over the band (x_ref), so the
    peak of a mode far above it (the 700 Hz bending mode of the three-mass model, zeta = 5.4e-4:
    a half-power band of 0.76 Hz, a peak 1/40 of the 18 Hz one's) bends the scaled curve too little
    for the step control to see it: the curve steps over the peak. For each open-gap mode of
    frequency f_r and damping ratio zeta_r in the band with fewer than ``RESONANCE_POINTS`` points
    of ``br`` in f_r (1 +- ``RESONANCE_SPAN`` zeta_r) whose linear response at the output points
    peaks there (``RESONANCE_PEAK`` times the band's edges: a mode the load excites), the same HB
    curve is continued over that band alone (its own x_ref: the peak is then its largest response),
    with its stability.

    Parameters
    ----------
    system, b, P : the gap system, the load direction (n,) and its amplitude (N)
    spec : the [frc] table
    br : the HB curve of the level
    rows, names : the output points
    open_only : only the bands where no stop closes (the caller draws no band in contact): a band
        whose linear response closes a stop, |B_j X(Omega)| > OPEN_MARGIN |offset_j| at f_r or
        f_r (1 +- zeta_r), is skipped without its curve. Every periodic orbit there is in contact
        (an open one would be the linear response, which closes the stop), so the band's curve
        has points in contact wherever it passes that frequency.

    Returns
    -------
    tuple
        (the FRCBranch of each refined band, in increasing frequency; a note per band).
    """
    n = system.n
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(system.M, system.K),
                                                   -np.linalg.solve(system.M, system.C)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    out, notes = [], []
    for lm in sorted(lam, key=lambda v: v.imag):
        f_r, zeta = abs(lm) / (2 * np.pi), -lm.real / abs(lm)
        lo, hi = f_r * (1 - RESONANCE_SPAN * zeta), f_r * (1 + RESONANCE_SPAN * zeta)
        if not (0 < zeta < 1 / (2 * RESONANCE_SPAN)) or lo < spec.freq_min_hz or hi > spec.freq_max_hz:
            continue
        inside = int(np.sum((br.freq_hz >= lo) & (br.freq_hz <= hi)))
        lin = np.max(linear_frf(system, b, 1.0, [lo, f_r, hi], rows), axis=1)
        if inside >= RESONANCE_POINTS or lin[1] < RESONANCE_PEAK * max(lin[0], lin[2]):
            continue  # resolved, or the load does not excite the mode at the output points (no peak)
        if open_only and np.any(linear_frf(system, b, P, f_r * np.array([1 - zeta, 1.0, 1 + zeta]), system.B)
                                > OPEN_MARGIN * np.abs(system.offset)):
            continue  # the band closes a stop: its curve would be in contact, which the caller does not draw
        sub = _curve(system, b, P, spec, spec.harmonics, rows, names, hill_points=0, f_band=(lo, hi))
        if isinstance(sub, Exception):
            notes.append(f"the mode at {f_r:.5g} Hz (zeta {zeta:.2g}) stepped over ({inside} points) and its "
                         f"band could not be continued: {' '.join(str(sub).split())[:120]}")
            continue
        out.append(sub)
        notes.append(f"the mode at {f_r:.5g} Hz (zeta {zeta:.2g}) was stepped over ({inside} points in "
                     f"{lo:.5g}-{hi:.5g} Hz): that band is drawn from its own HB curve ({len(sub.freq_hz)} points, "
                     f"peak {np.max(sub.amplitude_m):.4g} m)")
    return tuple(out), notes


# -- Hill and shooting at selected points ---------------------------------------------------------
def _point_checks(system: GapSystem, b: np.ndarray, P: float, br: FRCBranch, rows: np.ndarray, spec
                  ) -> list[PointCheck]:
    """Hill's method at ``hill_points`` points and shooting at ``shooting_points`` (half of them
    spread over the points in contact), each beside the monodromy's verdict."""
    k = len(br.freq_hz)
    contact_mask = _in_contact(system, br)
    contact = np.flatnonzero(contact_mask)
    shoot_idx = np.unique(np.concatenate([_evenly(k, (spec.shooting_points + 1) // 2),
                                          contact[_evenly(contact.size, spec.shooting_points // 2)]]))
    hill_idx = np.unique(np.concatenate([_evenly(k, spec.hill_points), shoot_idx if spec.hill_points else []])
                         ).astype(int)
    shot_at = set(shoot_idx.tolist())
    loads_of = {}
    out = []
    for i in sorted(set(hill_idx) | set(shoot_idx)):
        f, w = float(br.freq_hz[i]), float(br.omega[i])
        hill, hill_stable = np.nan, None
        if i in hill_idx:
            mu = forced_hill(br.balance, br.z[i], w)
            hill = float(np.max(np.abs(mu)))
            hill_stable = hill <= 1.0 + HILL_TOL
        shoot, shoot_stable, shoot_amp, note = np.nan, None, None, ""
        if i in shoot_idx:
            loads = loads_of.setdefault(f, Loads(b[None, :], (Harmonic(P, f),)))
            try:
                orb = floquet_by_shooting(Flow(system, loads=loads), hb_states(br.X[i], w, spec.shooting_segments),
                                          1.0 / f, tol=1e-10)
                shoot, shoot_stable = orb.max_multiplier, orb.stable
                shoot_amp = orbit_amplitude(system, loads, orb, rows)
            except (ShootingError, RuntimeError) as exc:
                note = " ".join(str(exc).split())[:120]
        out.append(PointCheck(int(i), bool(contact_mask[i]), int(i) in shot_at, f, float(np.abs(br.multipliers[i, 0])),
                              bool(br.stable[i]), hill, hill_stable, shoot, shoot_stable, shoot_amp, note))
    return out


def _in_contact(system, br) -> np.ndarray:
    """(k,) whether a stop closes somewhere along each point's orbit."""
    out = np.zeros(len(br.freq_hz), bool)
    for i, X in enumerate(br.X):
        out[i] = bool(np.any(max_abs_over_period(X, system.B) > np.abs(system.offset)))
    return out


def orbit_amplitude(system, loads, orbit, rows) -> np.ndarray:
    """(p,) m, max |r . x| over one period of an exact periodic orbit (sampled, ORBIT_SAMPLES).

    Parameters
    ----------
    system : the gap system
    loads : the load the orbit is driven by
    orbit : a periodic orbit (x0, v0, period_s), e.g. a
        :class:`reduced.periodic.forced_stability.ForcedOrbit`
    rows : (p, n) the output points as rows of the DOFs

    Returns
    -------
    ndarray
        (p,) m.
    """
    # ringdown's exact method without its energy integrals (work=False: the same samples)
    r = integrate_exact(system, orbit.x0, orbit.v0, orbit.period_s, ORBIT_SAMPLES / orbit.period_s, loads=loads,
                        work=False)
    return np.max(np.abs(r.x @ rows.T), axis=0)


def shooting_error(system, loads, X: np.ndarray, amplitude: np.ndarray, freq_hz: float, rows: np.ndarray,
                   segments: int) -> float | None:
    """max |a_HB / a_exact - 1| over the points ``rows``: the exact forced orbit is found by multiple
    shooting (``segments`` segments) from the HB orbit X at ``freq_hz``; None if shooting fails.

    Parameters
    ----------
    system, loads : the gap system and its harmonic load at ``freq_hz``
    X : (2H+1, n) m, the HB orbit
    amplitude : (p,) m, its amplitude at the points
    freq_hz : Hz
    rows : (p, n) the output points
    segments : segments of the multiple shooting

    Returns
    -------
    float or None
        The largest relative amplitude error over the points.
    """
    try:
        orb = floquet_by_shooting(Flow(system, loads=loads), hb_states(X, 2 * np.pi * freq_hz, segments),
                                  1.0 / freq_hz, tol=1e-10)
    except (ShootingError, RuntimeError):
        return None
    return float(np.max(np.abs(amplitude / orbit_amplitude(system, loads, orb, rows) - 1.0)))


# -- the stepped sine ---------------------------------------------------------------------------------
def _events(br, load_col: int) -> np.ndarray:
    """Hz, where the sweeps must jump: the folds of the curve, the end of its first stable piece
    (an up sweep leaves it there) and the start of its last (a down sweep leaves it there);
    the peak if there is none of these."""
    if isinstance(br, Exception):
        return np.zeros(0)
    st, f = br.stable, br.freq_hz
    ev = list(f[br.folds])
    for idx in br.pieces():
        change = np.flatnonzero(st[idx][1:] != st[idx][:-1])
        if change.size:
            ev += [f[idx][change[0]], f[idx][change[-1] + 1]]
    if not ev:
        ev = [f[int(np.argmax(br.amplitude_m[:, load_col]))]]
    return np.unique(ev)


def _sweep_freqs(spec, br, load_col: int) -> np.ndarray:
    """Stepped-sine frequencies: half log-spaced over the band; half in the jump region, first just
    below and above each end of a stable piece of the curve (+-1 %, nearest events first), the rest
    spread evenly over the region between the lowest and highest end, widened by JUMP_MARGIN."""
    n = spec.stepped_sine_points
    ev = _events(br, load_col)
    n_jump = int(round(JUMP_FRACTION * n)) if ev.size else 0
    pts = list(np.geomspace(spec.freq_min_hz, spec.freq_max_hz, n - n_jump))
    if n_jump:
        near = []
        for f in ev:  # +-1 % of each event, dropping those within 0.3 % of one already taken
            for g in (0.99 * f, 1.01 * f):
                if all(abs(g / h - 1.0) > 3e-3 for h in near):
                    near.append(g)
        near = near[:n_jump]
        lo, hi = ev.min() / JUMP_MARGIN, ev.max() * JUMP_MARGIN
        rest = n_jump - len(near)
        fill = list(np.linspace(lo, hi, rest + 2)[1:-1]) if rest > 0 else []
        pts += near + fill
    pts = np.array([f for f in pts if spec.freq_min_hz <= f <= spec.freq_max_hz])
    return np.unique(np.round(pts, 9))


def _sweeps(system, b, P: float, spec, br, rows, names, load_col: int) -> dict[str, SteppedSine]:
    """{"up": ..., "down": ...}: the stepped sine over :func:`_sweep_freqs` ({} if switched off)."""
    if spec.stepped_sine_points == 0:
        return {}
    fr = _sweep_freqs(spec, br, load_col)
    return {direction: stepped_sine(system, b, P, freqs, point_rows=rows, point_names=names,
                                    settle_tol=spec.stepped_sine_tol, max_settle_s=spec.stepped_sine_max_s)
            for direction, freqs in (("up", fr), ("down", fr[::-1]))}


def _hb_at_sweep(br, ss: SteppedSine, load_col: int) -> list:
    """Per sweep frequency: the HB amplitudes (p,) exactly there on the stable branch the sweep
    landed on (nearest at the load point), or None (not settled, no curve, no stable piece)."""
    out = []
    for j, f in enumerate(ss.freq_hz):
        a = None
        if ss.response[j] in ("periodic", "settling") and not isinstance(br, Exception):
            a, _, _ = solution_at_frequency(br, float(f), float(ss.amplitude_m[j][load_col]), load_col)
        out.append(a)
    return out


# -- convergence in H ---------------------------------------------------------------------------------
def _convergence(system, b, spec, rows, names, load_col, curves, checks, sweeps, bar) -> list[ConvergenceRun]:
    """Each H of ``convergence_harmonics`` at ``convergence_level_N``: its curve against the periodic
    stepped-sine points and against the exact orbits at the contact shooting points."""
    Pc = spec.convergence_level_N
    targets = []  # (freq, amplitude at the load point) of the contact shooting points at that level
    if Pc in curves and not isinstance(curves[Pc], Exception):
        br = curves[Pc]
        targets = [(r.freq_hz, float(br.amplitude_m[r.index, load_col])) for r in checks[Pc] if r.contact and r.shot]
    ref_ss = []
    if Pc in sweeps:
        for ss in sweeps[Pc].values():
            ref_ss += [(float(f), ss.amplitude_m[j]) for j, f in enumerate(ss.freq_hz) if ss.response[j] == "periodic"]
    runs = []
    loads_c = {}
    for Hc in spec.convergence_harmonics:
        bar.set_postfix_str(f"convergence H={Hc}")
        t0 = time.perf_counter()
        own = curves.get(Pc) if Hc == spec.harmonics else None
        if own is not None:  # the level's own curve: the same continuation (stability does not steer it)
            bc, wall = _without_stability(own), (own.wall_s if not isinstance(own, Exception) else 0.0)
        else:
            bc = _curve(system, b, Pc, spec, Hc, rows, names, stability=False)
            wall = time.perf_counter() - t0
        e_ss, e_sh, fails = [], [], 0
        if not isinstance(bc, Exception):  # computed without stability: every piece counts, the nearest taken
            e_ss = [np.max(np.abs(a / amp - 1.0)) for f, amp in ref_ss
                    for a in [solution_at_frequency(bc, f, float(amp[load_col]), load_col)[0]] if a is not None]
            # the exact orbit nearest this H's orbit at each target frequency: multiple shooting from it
            for f, a_ref in targets:
                a, _, X = solution_at_frequency(bc, f, a_ref, load_col)
                if a is None:
                    fails += 1
                    continue
                loads = loads_c.setdefault(f, Loads(b[None, :], (Harmonic(Pc, f),)))
                e = shooting_error(system, loads, X, a, f, rows, spec.shooting_segments)
                if e is None:
                    fails += 1
                    continue
                e_sh.append(e)
        runs.append(ConvergenceRun(Hc, bc, e_ss, e_sh, fails, wall))
        bar.update()
    return runs


def _without_stability(br):
    """The curve ``br`` as :func:`_curve` with ``stability=False`` gives it: the same points (the continuation
    does not depend on the stability computed along it), the stability skipped (every point stable, the
    folds as its only bifurcations); a ContinuationError as it is.

    >>> _without_stability(ValueError("no start")).args
    ('no start',)
    """
    if isinstance(br, Exception):
        return br
    st = BranchStability.skipped(len(br.z), 2 * br.balance.n, br.folds)
    return replace(br, multipliers=st.multipliers, stable=st.stable, hill_index=st.hill_index, hill=st.hill,
                   bifurcations=st.bifurcations, stability_wall_s=0.0, notes=list(br.notes))


# -- the backbone check -------------------------------------------------------------------------------
def _backbone_check(system, b, rows, names, spec, load_col, curves, bar, done=None) -> tuple[dict, dict, dict, dict]:
    """(curves with damping and load scaled, the NNM backbones, each curve's peak, the backbone
    nearest each peak with its log distance). ``done``: {(P, H): curve without stability} already computed
    (the convergence study's): at scale 1 the H = 1 curve of such a level is taken from it (the same call)."""
    bb_curves = {}
    done = done or {}
    for P in spec.levels_N:
        for eps in spec.backbone_scales:
            bar.set_postfix_str(f"backbone {P:g} N x {eps:g}")
            if eps == 1.0 and (P, 1) in done:  # C * 1 and P * 1 are C and P to the bit: the same curve
                bc = done[(P, 1)]
            else:
                bc = _curve(_scaled_damping(system, eps), b, P * eps, spec, 1, rows, names, stability=False)
            if not isinstance(bc, Exception):
                bb_curves[(P, eps)] = bc
            bar.update()
    # the backbones up to a little past the most energetic orbit drawn
    E_top = max([_orbit_energy(system, br.X[i], br.omega[i]) for br in [*curves.values(), *bb_curves.values()]
                 if not isinstance(br, Exception) for i in [int(np.argmax(br.amplitude_m[:, load_col]))]],
                default=1.0)
    bar.set_postfix_str("backbones")
    bb = _backbones(system, b, rows, spec, BACKBONE_ENERGY_FACTOR * E_top)
    bar.update()
    peaks = {key: _peak(bc, load_col) for key, bc in bb_curves.items()}
    nearest = {}
    if bb:
        for key, (fp, A) in peaks.items():
            dist = {m: _log_distance(fp, A, c, load_col) for m, c in bb.items()}
            mode = min(dist, key=dist.get)
            nearest[key] = (mode, dist[mode])
    return bb_curves, bb, peaks, nearest


def _scaled_damping(system, eps: float):
    return replace(system, C=system.C * eps)


def _orbit_energy(system, X: np.ndarray, omega: float) -> float:
    """J, mean over one period of the kinetic, elastic and stop energy of the HB orbit X (2H+1, n)."""
    H = (X.shape[0] - 1) // 2
    E = _synthesis(H, max(64, 8 * (2 * H + 1)))
    x = E @ X
    v = omega * (E @ (_derivative_matrix(H) @ X))
    return float(np.mean(system.energy(x, v)))


def _backbones(system, b, rows, spec, energy_max_J: float) -> dict:
    """{mode: (freq_hz, amplitudes (k, p))} of the NNMs the load excites with an open-gap frequency in
    the band, by :func:`reduced.periodic.backbones.nnm_branch` (H = 1 as the nnm stage, N = 4096,
    short steps: the peaks are compared with the polyline through its points)."""
    lm = linear_modes(system, "open")
    part = np.abs(lm.phi.T @ b)
    steps = NNM_STEPS.replace(ds=BACKBONE_DS, ds_max=BACKBONE_DS, max_steps=20000)
    out = {}
    for r in range(system.n):
        if not (spec.freq_min_hz <= lm.freq_hz[r] <= spec.freq_max_hz) or part[r] < 1e-6 * part.max():
            continue
        try:
            nb = nnm_branch(system, r, H=1, N=BACKBONE_SAMPLES, energy_max_J=energy_max_J, continuation=steps)
        except (NewtonError, ContinuationError, ValueError):
            continue
        amps = np.array([max_abs_over_period(x.reshape(3, system.n), rows) for x in nb.X])
        out[r] = (nb.freq_hz, amps)
    return out


def _peak(bc, col: int) -> tuple[float, float]:
    """(Hz, m): the peak of a curve at point ``col``: the largest amplitude, refined by a parabola
    through it and its two neighbours along the curve (amplitude and log frequency against the
    point index)."""
    a = bc.amplitude_m[:, col]
    i = int(np.argmax(a))
    if 0 < i < len(a) - 1:
        y0, y1, y2 = a[i - 1], a[i], a[i + 1]
        den = y0 - 2 * y1 + y2
        if den < 0.0:
            t = 0.5 * (y0 - y2) / den  # vertex offset in (-1, 1)
            lf = np.log(bc.freq_hz[i - 1 : i + 2])
            f = math.exp(lf[1] + 0.5 * t * (lf[2] - lf[0]) + 0.5 * t * t * (lf[0] - 2 * lf[1] + lf[2]))
            return f, float(y1 - 0.25 * (y0 - y2) * t)
    return float(bc.freq_hz[i]), float(a[i])


def _log_distance(f: float, A: float, curve, col: int) -> float:
    """Distance from (ln f, ln A) to the backbone polyline in (ln frequency, ln amplitude): the
    relative distance of a peak from the backbone, in frequency and amplitude alike. Below its
    first point the backbone is the linear mode (its frequency, any smaller amplitude)."""
    fb, amps = curve
    x = np.log(np.concatenate([[fb[0]], fb]))
    y = np.log(np.concatenate([[amps[0, col] * 1e-6], amps[:, col]]))
    px, py = math.log(f), math.log(A)
    dx, dy = np.diff(x), np.diff(y)
    L2 = dx * dx + dy * dy
    t = np.clip(np.where(L2 > 0, ((px - x[:-1]) * dx + (py - y[:-1]) * dy) / np.where(L2 > 0, L2, 1.0), 0.0), 0.0, 1.0)
    return float(np.min(np.hypot(x[:-1] + t * dx - px, y[:-1] + t * dy - py)))


# -- the registry's contract (bearingshaft.registry) -------------------------------------------
DESCRIPTION = """Forced-response curves under P cos(2 pi f t) at one point, by harmonic balance continued
through folds, with stability (monodromy, Hill, shooting), bifurcations, a stepped sine up and
down by the exact integrator, the error against H and run time, and the backbone check. The drawn
curve of each level is converged ([frc] curve): HB where its amplitudes no longer move with H (with
the lightly damped resonances it stepped over refined), else the families of periodic orbits of the
exact flow by multiple shooting, with their stability and branch switching; frc.md says which and
why, frc_families.csv lists the families. Where the families do not reach, frc_cover.csv gives a verdict per HB
point in contact (multiple shooting with more segments from it: an orbit that starts a family, or no orbit near it
with the best defect) and frc_close_returns.csv the unstable periodic orbits seeded by close returns of the chaotic
stepped sine (families of kind close_return, drawn over the bifurcation diagram). Writes frc.csv, frc.md,
frc_families.csv, frc_cover.csv, frc_close_returns.csv, frc.png,
frc_receptance.png (the response per newton, m/N), frc_harmonics.csv,
frc_bifurcations.csv, frc_stability.csv,
stepped_sine.csv, frc_convergence.csv, frc_convergence_timing.csv and .png, frc_backbone.csv
and frc_backbone.png; the response map (each frequency of a dense stepped sine periodic, subharmonic,
quasi-periodic or chaotic, with its Lyapunov exponent): response_map.csv, response_map_jumps.csv,
response_map.png and response_map_spectra.png. With friction at the tips ([model] mu > 0): HB by AFT with the
Jenkins sliders, Hill's stability through stick-slip, the exact orbits by shooting with the sliders, and the
response map by the exact friction flow (frc.csv, frc_friction_checks.csv, frc_friction_shooting.csv,
frc_friction_sweep.csv, response_map.csv, response_map_jumps.csv, frc.png, response_map.png, frc.md; frc.md says
what is skipped and why)."""


def frc_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Compute and write the stage in one call (the pipeline calls :func:`compute` and :func:`write`).

    Parameters
    ----------
    scene : Scene
        A scene with an [frc] table.
    writer : StageWriter
        Where the files go.
    progress : bool
        Show progress bars.

    Returns
    -------
    None
    """
    from bearingshaft.stages import frc_files  # matplotlib: loaded only when files are written

    frc_files.write(compute(scene, progress, writer.scratch), writer)


def estimate(scene: Scene) -> list[Estimate]:
    """Hill's method: the first-order form of the quadratic eigenproblem at the largest H.

    Parameters
    ----------
    scene : Scene
        A scene with an [frc] table.

    Returns
    -------
    list of Estimate
        One: bytes of the Hill matrices at the largest H (``HILL_COPIES`` copies).
    """
    f = scene.frc
    n = n_dofs(scene)
    H = max((f.harmonics, *f.convergence_harmonics))
    size = 2 * (2 * H + 1) * n
    return [Estimate("frc", HILL_COPIES * size**2 * FLOAT, f"Hill matrices of {size} x {size} (H = {H}, {n} DOFs)",
                     "[frc] harmonics or convergence_harmonics")]


__all__ = ["DESCRIPTION", "FRCResult", "check_harmonics", "compute", "converged_curve", "estimate", "frc_stage",
           "hb_change", "orbit_amplitude", "shooting_error"]




# -- the reproduction report (bearingshaft.reproduction): how these files compare with the reference -----
CONTINUATION = ("the points of an HB continuation through folds: its step path is set by the last bits of each Newton "
                "solve, which another CPU changes")
MAP_CHAOS = "the stepped sine's response at a chaotic or quasi-periodic frequency"
MAP_AFTER = ("the stepped sine after a chaotic, quasi-periodic or unsettled frequency: it arrives with a state "
             "round-off set, so which attractor it settles on and its transient are too")
MAP_AMPLITUDE = ("amplitudes of a settled response, written to 10 digits: a reduced model's matrices move by ~1e-8 "
                 "between machines, which a resonance magnifies")
MAP_GRID = ("the response map's fine grid spans the contact band of the HB curve, whose points are set by its step "
            "path (" + CONTINUATION + ")")
REPRODUCTION = Reproduction(rules=(
    sensitive("frc.csv", why=CONTINUATION),
    sensitive("frc_friction_checks.csv", why="the stepped sine by the exact friction integrator, compared with HB at "
              "its frequencies: " + CONTINUATION),
    sensitive("frc_friction_shooting.csv", why="the exact friction orbits continued by shooting, compared with HB at "
              "their frequencies (" + CONTINUATION + "); their own step path is set by the corrector's steps, "
              "which round-off in the finite-difference Jacobians can change"),
    sensitive("frc_harmonics.csv", why=CONTINUATION),
    sensitive("frc_bifurcations.csv", why=CONTINUATION + " (the folds and bifurcations found between its points)"),
    sensitive("frc_cover.csv", why="verdicts at the HB points in contact no family covers: " + CONTINUATION),
    # the close returns come from the response map's chaotic Poincare samples: which returns, which orbits and families
    chaotic("frc_close_returns.csv", "*", why="close returns of a chaotic stepped sine and the orbits they seed"),
    chaotic("frc_families.csv", "*", rows=r"^(?:[^,]*,){2}close_return,", why="families seeded by close returns of a "
            "chaotic stepped sine"),
    chaotic("frc.md", r"close_return|Close-return|^Bifurcations:", why="families seeded by close returns of a chaotic "
            "stepped sine (and the bifurcations counted on them)"),
    # what a test would see (frc_regimes): bands of the response map's frequencies, a chaotic band's numbers chaotic;
    # after a chaotic frequency a sweep's state is set by round-off, so where the bands end moves with it
    chaotic("frc_regimes.csv", "*", rows=r"^(?:[^,]*,){5}(?:chaotic|quasi_periodic),", why=MAP_CHAOS),
    sensitive("frc_regimes.csv", why=MAP_AFTER),
    chaotic("frc.md", r"^\| (?:up|down) \| [^|]*\| [^|]*\| (?:chaotic|quasi_periodic)", why=MAP_CHAOS),
    sensitive("frc.md", r"^\| (?:up|down) \| ", why=MAP_AFTER),
    # with friction (frc_friction_files): the stepped sine's and the shot and continued orbits' tables and lines
    # mirror frc_friction_checks.csv and frc_friction_shooting.csv (a round-off change in the friction tables moved
    # the unsettled points' amplitudes and the branches' ends)
    sensitive("frc.md", r"^\| [0-9.]+ \| [0-9.]+ \|", r"^- [0-9.]+ N, branch [0-9]+:",
              why="the friction stepped sine and the exact friction orbits (frc_friction_checks.csv, "
              "frc_friction_shooting.csv): " + CONTINUATION),
    # with friction, the response map's lines (frc_friction_map.markdown): a chaotic stretch's exponents and envelope
    # chaotic; each sweep's counts and jumps, and where its stretches end, set by the state chaos leaves (MAP_AFTER)
    chaotic("frc.md", r"^  - [^:]*: (?:chaotic|quasi_periodic)", why=MAP_CHAOS),
    sensitive("frc.md", r"^- [0-9.]+ N, sweep (?:up|down): ", r"^  - [0-9.]+(?: -> [0-9.]+)? Hz: ", why=MAP_AFTER),
    sensitive("frc_stability.csv", why=CONTINUATION + " (stability at those points)"),
    sensitive("frc_convergence.csv", why=CONTINUATION + " (points, reach, folds and errors at the points)"),
    sensitive("stepped_sine.csv", why="the stepped sine at the HB curve's points, compared with HB there: "
              + CONTINUATION),
    # each peak is the parabola through the continuation's points around the largest amplitude: it moves with them
    within("frc_backbone.csv", "peak_freq_hz", "peak_amplitude_m", rtol=1e-4,
           why="peaks refined from the continuation's points, which round-off moves (6e-6 between two machines)"),
    within("frc_backbone.csv", "log_distance", atol=1e-5,
           why="distances from the backbone below 1e-5 are the peak's location error"),
    # the response map (frc_map_files): the fine grid covers the contact band the HB curve found (so a continuation
    # that lands elsewhere may add or drop a frequency: the rows are sensitive); at a chaotic, quasi-periodic or
    # unsettled frequency everything is chaotic, and after one the sweep arrives with a state round-off set (which
    # attractor it settles on): sensitive; before, the stepped sine is deterministic: its regimes, periods, exponents
    # and counts exact, its amplitudes to 1e-6 (a reduced model's matrices move by ~1e-8 between machines, which a
    # resonance magnifies)
    chaotic("response_map.csv", "*", rows=r"^(?:[^,]*,){3}(?:chaotic|quasi_periodic),", why=MAP_CHAOS),
    chaotic("response_map.csv", "*", rows=r"^(?:[^,]*,){13}false,", why="an unsettled frequency of the stepped sine "
            "(no return after the longest run: transient chaos)"),
    chaotic("response_map_jumps.csv", "*", rows=r"^(?:[^,]*,){4,5}(?:chaotic|quasi_periodic),", why=MAP_CHAOS),
    sensitive("response_map*.csv", "*", rows=r",true$", why=MAP_AFTER),
    within("response_map.csv", "x1_*", "max_abs_mu", rtol=1e-6, why=MAP_AMPLITUDE),
    within("response_map_jumps.csv", "x1_*", rtol=1e-6, why=MAP_AMPLITUDE),
    exact("response_map*.csv", "*"),
    sensitive("response_map*.csv", why=MAP_GRID),
), lyapunov=("response_map.csv:lyapunov_per_s",))
