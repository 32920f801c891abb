"""What the exact flow has where no family of :mod:`reduced.periodic.exact_frc` reaches (issue 25).

Two searches on an :class:`reduced.periodic.exact_frc.ExactFRC` already computed, each adding the
families it finds to it:

**Verdicts on the uncovered HB points** (:func:`cover_verdicts`). An HB orbit in contact at a
frequency no family covers is a guess of an exact orbit that the continuation never reached. Its
verdict: multiple shooting on the exact flow at that frequency (Newton on
R_k = phi(y_k; t_k, T / S) - y_{k+1} = 0, :func:`reduced.periodic.forced_shooting.shoot_at`) from
the HB orbit's states at S m nodes, m = ``multiples`` in turn (more segments: each node sees
|mu|^(1 / (S m)) of the orbit's growth, so orbits with |mu| ~ 1e5 converge); either Newton converges
(``orbit``: the orbit starts an ``isolated`` family, continued both ways with its multipliers; where
it is a known family's orbit or an image of one, Newton runs once more with that orbit deflated,
Farrell, Birkisson & Funke 2015, and ``known`` if it finds nothing else), or ``no_orbit`` with the best relative defect
max |R| / max |Y| met (both in the scaled unknowns: displacements in x_ref, velocities in
omega_v x_ref, the same scale for both) over all the Newton iterations (``stalled`` where that best is
below ``STALLED_DEFECT``: next to an orbit Newton could not close, e.g. at a grazing). A point a family started
by an earlier verdict covers is ``covered``.

**Unstable periodic orbits from chaos** (:func:`close_return_families`; Lathrop & Kostelich 1989, Phys. Rev. A
40, 4028). The Poincare samples y_n (the state at t = n T) of a chaotic stepped-sine response come close to
the unstable periodic orbits embedded in the attractor: a close return |y_{n+k} - y_n| small (relative, in the
same scaled norm) for k = 1..4 seeds multiple shooting of a k T orbit (2 S k nodes marched from y_n along the
recorded trajectory itself). A converged orbit of period k that is new (not a known family's nor an image of
it) is continued as a family of kind ``close_return`` (period k, its symmetry, its multipliers over k T), each
way until it leaves the band, retraces its path or runs onto a known family; one of a shorter period or a
known family's is deflated (Newton once more from the seed, that orbit deflated). The seeds are tried from the
closest return up, the smallest period first among equal distances. Deflating every known orbit up front (the
tens of families of a contact band, each multiplying R by 1 / |Y - Y*|^2 + 1) bends Newton's path enough to
lose orbits it finds otherwise (discrete-frc at 1 N: a 4 T orbit at 17 Hz), so only the orbit Newton actually
fell onto is deflated.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from reduced._blas import single_thread_blas
from reduced.periodic.exact_frc import (
    SYMMETRY_TOL,
    ExactFRC,
    _Analyser,
    _Budget,
    _family,
    _follow,
    _isolated,
    _join,
    _Joined,
    _known,
    _runs,
    _switch_all,
    covered,
)
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual, shoot_at
from reduced.periodic.hb import NewtonError, newton
from reduced.periodic.shooting import ShootingError

VERDICT_MULTIPLES = (2, 4)  # nodes per period tried, as multiples of the families' S (more segments: less growth)
VERDICT_ITER = 12  # Newton steps per try at most (a converging orbit needs 3-8 from a guess it converges from)
CLOSE_PERIODS = (1, 2, 3, 4)  # k of the close returns |P^k y_n - y_n|
CLOSE_TOL = 0.1  # relative distance of a close return used as a seed at most
CLOSE_ITER = 30  # Newton steps per close return at most
CLOSE_MULTIPLE = 2  # nodes per load period of a close return's shooting, as a multiple of the families' S
STALLED_DEFECT = 1e-6  # relative: a verdict's Newton that stopped below this defect stalled next to an orbit
SAME_PERIOD_TOL = 1e-6  # relative: an orbit whose nodes repeat after k / d periods within this has period k / d


@dataclass(frozen=True, slots=True)
class Verdict:
    """The verdict at one HB point in contact that no family covered (:func:`cover_verdicts`).

    Attributes
    ----------
    freq_hz : float
        Hz.
    hb_amplitude_m : float
        m, the HB orbit's amplitude at the load point.
    verdict : str
        ``orbit`` (a new family started), ``known`` (the orbit is a known family's), ``orbit_not_followed``
        (found, its continuation failed), ``stalled`` (Newton stopped below a defect of ``STALLED_DEFECT``: an
        orbit within reach, not converged), ``no_orbit``, ``covered`` (a family started by a verdict covers the
        frequency) or ``not_judged`` (outside the sample).
    defect : float
        Relative defect max |R| / max |Y| of the orbit found, else the best met over every Newton step.
    segments : int
        Nodes per period of the last try.
    iterations : int
        Newton steps (residual evaluations) spent.
    family : int
        Index of the family started or covering it (-1: none).
    note : str
    band_hz : (float, float)
        Hz, the uncovered band (a run of consecutive uncovered HB points in contact) it lies in.
    """

    freq_hz: float
    hb_amplitude_m: float
    verdict: str
    defect: float
    segments: int
    iterations: int
    family: int
    note: str
    band_hz: tuple


@dataclass(frozen=True, slots=True)
class CloseReturn:
    """A seed tried by :func:`close_return_families`.

    Attributes
    ----------
    freq_hz : float
        Hz, the stepped sine's frequency.
    direction : str
        The sweep (``up``/``down``) whose samples it came from.
    period_k : int
        k of the return.
    index : int
        n of the sample y_n.
    distance : float
        Relative |y_{n+k} - y_n|.
    family : int
        Family started (-1: none).
    note : str
        Why none (or the family's kind and period).
    defect : float
        Relative defect of the orbit found, else the best met.
    """

    freq_hz: float
    direction: str
    period_k: int
    index: int
    distance: float
    family: int
    note: str
    defect: float


def _nodes_scale(res: ShootingResidual, omega: float) -> np.ndarray:
    return res.scale(omega) / math.sqrt(res.segments)  # the scaled norm without the sqrt(S) of a step's length


def _shoot(res: ShootingResidual, nodes: np.ndarray, omega: float, known: list, max_iter: int) -> tuple:
    """(scaled point Y or None, best relative defect, residual evaluations): Newton at fixed Omega from the
    nodes, deflated from ``known`` (scaled points of res), as :func:`shoot_at`, watching the defect."""
    Y0 = res.point(nodes, omega)
    nz = res.size
    lw = Y0[nz]
    best = [math.inf, 0]

    def fun(v):
        R, jac = res.lazy(np.append(v, lw))
        best[0] = min(best[0], float(np.max(np.abs(R))) / max(float(np.max(np.abs(v))), 1e-300))
        best[1] += 1
        if not known:
            return R, lambda: jac()[:, :nz]

        def J():
            Jm, Rm = jac()[:, :nz], R
            for ks in known:  # deflation, as shoot_at
                d = v - ks[:nz]
                dd = float(d @ d)
                m = 1.0 / dd + 1.0
                Jm = m * Jm + np.outer(Rm, -2.0 * d / dd**2)
                Rm = m * Rm
            return Jm
        m_all = 1.0
        for ks in known:
            d = v - ks[:nz]
            m_all *= 1.0 / float(d @ d) + 1.0
        return m_all * R, J

    try:
        out = newton(fun, Y0[:nz], tol=1e-11, max_iter=max_iter)
    except (NewtonError, ShootingError):
        return None, best[0], best[1]
    Y = np.append(out.y, lw)
    r = float(np.max(np.abs(res.value(Y))))
    d = r / max(float(np.max(np.abs(out.y))), 1e-300)
    if r > 1e-9:
        return None, min(best[0], d), best[1]
    return Y, d, best[1]


def cover_verdicts(ex: ExactFRC, system, load: np.ndarray, guesses: list, *, points_per_band: int,
                   f_band: tuple[float, float], multiples: tuple = VERDICT_MULTIPLES, max_iter: int = VERDICT_ITER,
                   family_steps: int = 300, switch_families: int = 0) -> list[Verdict]:
    """Verdicts at the HB points in contact no family of ``ex`` covers (module docstring), adding the
    families found to ``ex.families``, and the families switched onto at their branch points.

    Parameters
    ----------
    ex : ExactFRC
        The families of the level (mutated: new ``isolated`` families appended, then those switched onto from
        them; every branch point of theirs gets a record in ``ex.switches``).
    system : GapSystem
        The system ``ex`` was computed on.
    load : (n,) the force direction b
    guesses : list of (freq_hz, hb_amplitude_m, nodes_of)
        The HB points in contact; ``nodes_of(S)`` gives the HB orbit's states (S, 2n) at S equally spaced phases.
    points_per_band : int
        Points given a verdict per run of consecutive uncovered points (in frequency), spread evenly in frequency (the
        cost: a verdict is up to ``len(multiples) * max_iter`` residuals with their Jacobians).
    f_band : (Hz, Hz) the band ``ex`` was computed over
    multiples : nodes per period tried, as multiples of the families' S
    max_iter : Newton steps per try at most
    family_steps : points of a new family at most, each way (and of a family switched onto from it)
    switch_families : int
        Families switched onto at the branch points of each new family (and its children) at most
        (:func:`reduced.periodic.exact_frc._switch_all` with ``max_new``): its own allowance, beside the level's
        ``max_families`` that the main curve's switches use; 0 records the branch points without following them.

    Returns
    -------
    list of Verdict
        One per HB point of ``guesses`` no family covered at the start, in increasing frequency.
    """
    with single_thread_blas():
        flow = ForcedFlow(system, load, ex.amplitude_N)
        res, residuals, band, omega_v = _residuals(ex, flow, f_band)
        opts = replace(ex.options, cover_steps=family_steps, family_steps=family_steps,
                       period_doubling_steps=family_steps)
        f = np.array([g[0] for g in guesses], float)
        order = np.argsort(f, kind="stable")
        runs = [order[r] for r in _runs(~covered(ex.families, f[order]))]  # the uncovered bands
        picks = {int(r[i]) for r in runs for i in _spread(f[r], points_per_band)}
        band_of = {int(j): (float(f[r[0]]), float(f[r[-1]])) for r in runs for j in r}
        judged = {}
        for j in sorted(picks, key=lambda j: f[j]):
            fq, amp, nodes_of = guesses[j]
            cov = _covering(ex, fq)
            if cov >= 0:
                judged[j] = ("covered", math.nan, 0, 0, cov, f"in the range of family {cov}")
                continue
            judged[j] = _judge(ex, flow, res, residuals, band, omega_v, opts, fq, nodes_of, multiples, max_iter,
                               switch_families)
        out = []
        for j in sorted(band_of, key=lambda j: f[j]):
            fq, amp, _ = guesses[j]
            if j in judged:
                out.append(Verdict(fq, amp, *judged[j], band_of[j]))
                continue
            cov = _covering(ex, fq)
            out.append(Verdict(fq, amp, "covered" if cov >= 0 else "not_judged", math.nan, 0, 0, cov,
                               f"in the range of family {cov}" if cov >= 0 else
                               f"not judged ({points_per_band} points per band, spread evenly in frequency)",
                               band_of[j]))
    return out


def _covering(ex: ExactFRC, freq_hz: float) -> int:
    """The first family whose range covers the frequency (-1: none)."""
    return next((k for k, fam in enumerate(ex.families) if covered([fam], [freq_hz])[0]), -1)


def _judge(ex, flow, res, residuals, band, omega_v, opts, fq, nodes_of, multiples, max_iter,
           switch_families: int) -> tuple:
    """(verdict, defect, segments, residuals spent, family, note) at one uncovered HB point (module docstring)."""
    S = res.segments
    w = 2 * math.pi * fq
    best, n_ev, seg, Y, r_m, d = math.inf, 0, 0, None, None, math.inf
    for m in multiples:
        seg = S * m
        r_m = ShootingResidual(flow, seg, 1, ex.x_ref, res.omega_ref, omega_v)
        Y, d, n = _shoot(r_m, nodes_of(seg), w, [], max_iter)
        best, n_ev = min(best, d), n_ev + n
        if Y is not None:
            break
    if Y is None and best < STALLED_DEFECT:
        return ("stalled", best, seg, n_ev, -1, f"Newton stalled at defect {best:.2g} ({n_ev} Newton residuals on "
                f"{', '.join(str(S * m) for m in multiples)} nodes): an orbit is within reach but not converged "
                "(a contact grazing near it stops Newton's quadratic convergence), no family started")
    if Y is None:
        return ("no_orbit", best, seg, n_ev, -1, f"no orbit of the exact flow near this HB point (best defect "
                f"{best:.2g} after {n_ev} Newton residuals on {', '.join(str(S * m) for m in multiples)} nodes)")
    nodes_S = r_m.nodes(Y)[0][:: seg // S]  # the exact orbit's states at the families' S nodes
    k = len(ex.families)  # the new family's index (those switched onto from it follow it)
    note = _isolated(ex.families, ex.switches, residuals, (fq, nodes_S), res, opts, band, ex.point_rows,
                     ex.symmetry, _Budget(math.inf), True, switch_families)
    if "one of family" in note:  # a known orbit: once more with it deflated
        Y2, d2, n = _shoot(r_m, nodes_of(seg), w, [Y], max_iter)
        n_ev += n
        if Y2 is not None:
            d = d2
            nodes_S = r_m.nodes(Y2)[0][:: seg // S]
            note = _isolated(ex.families, ex.switches, residuals, (fq, nodes_S), res, opts, band, ex.point_rows,
                             ex.symmetry, _Budget(math.inf), True, switch_families)
    if note:
        return ("known" if "one of family" in note else "orbit_not_followed", d, seg, n_ev, -1, note)
    ex.families[k].notes.insert(0, f"started from the verdict at the HB point {fq:.6g} Hz ({seg} nodes)")
    return ("orbit", d, seg, n_ev, k, f"an orbit of the exact flow (defect {d:.2g}, {seg} nodes): family {k}")


def _spread(f: np.ndarray, count: int) -> list[int]:
    """Indices of at most ``count`` of the sorted frequencies f, spread evenly in frequency over [f_0, f_-1]: the
    nearest to each of ``count`` equally spaced targets (the middle one for count 1); a continuation crowds its
    points near folds, so an even spread of indices would judge the folds only.

    >>> _spread(np.array([1.0, 2.0, 2.1, 2.2, 2.3, 5.0]), 3), _spread(np.array([1.0, 2.0, 4.0]), 1)
    ([0, 4, 5], [1])
    """
    if count <= 0 or not len(f):
        return []
    targets = [0.5 * (f[0] + f[-1])] if count == 1 else np.linspace(f[0], f[-1], count)
    return sorted({int(np.argmin(np.abs(f - t))) for t in targets})


def _residuals(ex: ExactFRC, flow: ForcedFlow, f_band: tuple[float, float]):
    """(the period-1 residual of S nodes, {family: (residual, analyser)}, band in ln(Omega / omega_ref),
    omega_v) for new work on ``ex``'s families over f_band (Hz, Hz): the same scaled unknowns as exact_frc's."""
    sy = flow.system
    S = ex.main.nodes.shape[1]
    omega_ref = 2 * math.pi * f_band[1]  # exact_frc's: the top of its band
    omega_v = None
    if ex.options.velocity_scale == "fastest":
        omega_v = float(np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(sy.M, sy.K)).real)))
    res = ShootingResidual(flow, S, 1, ex.x_ref, omega_ref, omega_v)
    residuals = {}
    for j, fam in enumerate(ex.families):
        r = res if fam.periods == 1 and fam.nodes.shape[1] == S else ShootingResidual(
            flow, fam.nodes.shape[1], fam.periods, ex.x_ref, omega_ref, omega_v)
        a, hw = _Analyser(r, ex.symmetry, False, False, ex.point_rows).measures(fam.nodes[0])
        residuals[j] = (r, _Analyser(r, ex.symmetry, bool(ex.symmetry.mirror is not None and a < SYMMETRY_TOL),
                                     bool(ex.symmetry.half_wave and r.periods == 1 and hw < SYMMETRY_TOL),
                                     ex.point_rows))
    return res, residuals, (math.log(f_band[0] / f_band[1]), 0.0), omega_v


def close_return_families(ex: ExactFRC, system, load: np.ndarray, samples: list, *, f_band: tuple[float, float],
                          families: int, tries: int, family_steps: int = 200, periods: tuple = CLOSE_PERIODS,
                          tol: float = CLOSE_TOL, max_iter: int = CLOSE_ITER,
                          nodes_multiple: int = CLOSE_MULTIPLE, switch_families: int = 0) -> list[CloseReturn]:
    """Unstable periodic orbits from the close returns of chaotic Poincare samples (module docstring),
    appended to ``ex.families`` as families of kind ``close_return``.

    Parameters
    ----------
    ex : ExactFRC
        The families of the level (mutated).
    system, load : the gap system and the force direction (n,)
    samples : list of (freq_hz, direction, poincare (K, 2n))
        The Poincare samples (states at t = n T, m and m/s) of chaotic stepped-sine responses.
    f_band : (Hz, Hz) the band ``ex`` was computed over
    families : int
        New families at most.
    tries : int
        Seeds shot at most.
    family_steps : points of a new family at most, each way
    periods : the k of the returns looked for
    tol : relative distance of a close return at most
    max_iter : Newton steps per seed at most
    nodes_multiple : nodes per load period, as a multiple of the families' S (the orbit is then continued
        on S k nodes, as the families are)
    switch_families : int
        Families switched onto at the branch points of each new family (and its children) at most, each of
        ``family_steps`` points each way (as :func:`cover_verdicts`); 0 records the branch points only.

    Returns
    -------
    list of CloseReturn
        The seeds tried, in order.
    """
    fam0 = ex.main
    S = fam0.nodes.shape[1]
    out = []
    with single_thread_blas():
        flow = ForcedFlow(system, load, ex.amplitude_N)
        res1, residuals, band, omega_v = _residuals(ex, flow, f_band)
        opts = ex.options
        sc = _nodes_scale(res1, 1.0)[: system.n]
        cand = []
        for fq, direction, Yp in samples:
            w = 2 * math.pi * fq
            scl = np.concatenate([sc, _nodes_scale(res1, w)[system.n:]])
            Z = np.asarray(Yp, float) / scl
            size = max(float(np.max(np.abs(Z))), 1e-300)
            for k in periods:
                if len(Z) <= k:
                    continue
                dist = np.max(np.abs(Z[k:] - Z[:-k]), axis=1) / size
                n = int(np.argmin(dist))
                if dist[n] <= tol:
                    cand.append((float(dist[n]), k, fq, direction, n, Yp[n]))
        cand.sort(key=lambda c: (round(c[0], 3), c[1], c[2]))
        made = 0
        for dist, k, fq, direction, n, y0 in cand[:tries]:
            if made >= families:
                break
            w = 2 * math.pi * fq
            t0 = time.perf_counter()
            m = nodes_multiple
            rm = ShootingResidual(flow, S * k * m, k, ex.x_ref, res1.omega_ref, omega_v)
            nodes = _march(flow, y0, w, S * k * m, k)
            if nodes is None:
                out.append(CloseReturn(fq, direction, k, n, dist, -1, "the flow failed from the seed", math.nan))
                continue
            Y, d, n_ev = _shoot(rm, nodes, w, [], max_iter)
            if Y is None:
                out.append(CloseReturn(fq, direction, k, n, dist, -1, f"no orbit (best defect {d:.2g} after {n_ev} "
                                       f"Newton residuals on {S * k * m} nodes)", d))
                continue
            rk = ShootingResidual(flow, S * k, k, ex.x_ref, res1.omega_ref, omega_v)
            idx = len(ex.families)  # the new family's index (those switched onto from it follow it)
            first = (f"started from a close return (k = {k}, distance {dist:.2g}) of the {direction} stepped sine "
                     f"at {fq:.6g} Hz")
            note = _new_family(ex, residuals, rk, rm.nodes(Y)[0][::m], w, band, opts, family_steps, first, t0,
                               switch_families)
            if note.startswith(("the orbit has period", "the orbit is one of")):  # once more, that orbit deflated
                Y2, d2, n2 = _shoot(rm, nodes, w, [Y], max_iter)
                if Y2 is not None:
                    d = d2
                    note = _new_family(ex, residuals, rk, rm.nodes(Y2)[0][::m], w, band, opts, family_steps,
                                       first + " (with the orbit first found deflated)", t0, switch_families)
            made += not note
            out.append(CloseReturn(fq, direction, k, n, dist, -1 if note else idx,
                                   note or f"family {idx} ({k} T)", d))
    return out


def _new_family(ex: ExactFRC, residuals: dict, rk: ShootingResidual, nodes: np.ndarray, w: float, band, opts,
                family_steps: int, first_note: str, t0: float, switch_families: int = 0) -> str:
    """Shoot the k T orbit on rk (S k nodes) from ``nodes`` (exact: Newton converges at once) and, if it has
    period k and is new, follow it both ways as a ``close_return`` family appended to ``ex``, then switch at its
    branch points (up to ``switch_families`` families, :func:`cover_verdicts`) ('' done, else why not)."""
    k = rk.periods
    try:
        Y = shoot_at(rk, nodes, w)
    except ShootingError:
        return "no orbit on S k nodes"
    nd = rk.nodes(Y)[0]
    p = _smallest_period(nd, k)
    if p < k:
        return f"the orbit has period {p} T"
    same = _known(ex.families, residuals, rk, Y, ex.symmetry)
    if same is not None:
        return f"the orbit is one of family {same} (or an image of it)"
    a, hw = _Analyser(rk, ex.symmetry, False, False, ex.point_rows).measures(nd)
    an = _Analyser(rk, ex.symmetry, bool(ex.symmetry.mirror is not None and a < SYMMETRY_TOL),
                   bool(ex.symmetry.half_wave and k == 1 and hw < SYMMETRY_TOL), ex.point_rows)
    parts = []
    try:
        for sgn in (-1.0, 1.0):
            if sgn < 0 and Y[rk.size] <= band[0] + 1e-12 or sgn > 0 and Y[rk.size] >= band[1] - 1e-12:
                continue
            watch = _Joined(ex.families, rk, ex.symmetry, own=(parts[0][1][0], parts[0][1][3]) if parts else None)
            part = _follow(rk, Y, rk.size, sgn, opts, family_steps, band, an, stop_extra=watch)
            if watch.family != -1:
                part[4][-1] = "joined" if watch.family >= 0 else "closed"
            parts.append((sgn, part))
    except Exception as exc:  # noqa: BLE001 -- ContinuationError, ShootingError, NewtonError: reported
        return f"continuation failed: {' '.join(str(exc).split())[:100]}"
    Yf, data, folds, seg, st, notes = _join(parts)
    fam = _family("close_return", k, rk, Yf, data, folds, seg, st, [first_note] + notes, None,
                  time.perf_counter() - t0, an)
    fam.start_hz = w / (2 * math.pi)
    ex.families.append(fam)
    residuals[len(ex.families) - 1] = (rk, an)
    sw_opts = replace(opts, family_steps=family_steps, period_doubling_steps=family_steps)
    _switch_all(ex.families, ex.switches, residuals, sw_opts, band, ex.point_rows, ex.symmetry,
                _Budget(opts.deadline_s), root=len(ex.families) - 1, max_new=switch_families)
    return ""


def _march(flow: ForcedFlow, y0: np.ndarray, omega: float, nodes: int, periods: int) -> np.ndarray | None:
    """(nodes, 2n) the trajectory from y0 at t = 0 at t_j = j p T / nodes, or None if the flow fails."""
    h = periods * 2 * math.pi / omega / nodes
    out = np.empty((nodes, len(y0)))
    cur = np.asarray(y0, float)[None, :]
    try:
        for j in range(nodes):
            out[j] = cur[0]
            cur = flow.march(cur, np.array([j * h]), h, omega)[0]
    except ShootingError:
        return None
    return out


def _smallest_period(nodes: np.ndarray, k: int) -> int:
    """The smallest p | k with the orbit's nodes (S k, 2n) repeating after p periods (SAME_PERIOD_TOL)."""
    per = nodes.shape[0] // k
    sc = np.max(np.abs(nodes), axis=0)
    sc[sc == 0] = 1.0
    for p in range(1, k):
        if k % p == 0 and np.max(np.abs(np.roll(nodes, -p * per, axis=0) - nodes) / sc) < SAME_PERIOD_TOL:
            return p
    return k


__all__ = ["CLOSE_PERIODS", "CloseReturn", "Verdict", "close_return_families", "cover_verdicts"]
