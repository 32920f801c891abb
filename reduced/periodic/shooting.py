"""Periodic orbits of a conservative gap system by shooting on the exact flow.

Unknowns z = (x0, v0, T); equations (Peeters et al. 2009, with a Moore-Penrose
Gauss-Newton because they are one more than the unknowns and consistent):

    y(T; x0, v0) - (x0, v0) = 0          (2n: periodicity, on the exact event-driven flow)
    v0[ref] = 0                          (phase: start at a turning point of DOF ref)
    E(x0, v0) - E* = 0                   (the energy picks the orbit in the family)

The Jacobian of the first block is [Phi(T) - I, f(y(T))] with Phi the monodromy from
:class:`reduced.transient.flow.Flow` (saltation matrices are identities for penalty stops). The
orbit closes to machine precision; the Floquet multipliers are the eigenvalues of Phi.
For a conservative system two are 1 (time shift and energy) and the others come in
reciprocal, conjugate quadruples: the orbit is unstable when one leaves the unit circle.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.flow import Flow

FLOQUET_TOL = 1e-6  # |mu| - 1 above this is unstable. The trivial pair at +1 is a Jordan
# block whose eigenvalues split by ~sqrt(eps |Phi|) under round-off (1.5e-5 seen at
# |Phi| ~ 7e3), so it is removed before the test (drop_trivial_pair), not thresholded.


def drop_trivial_pair(mu: np.ndarray) -> np.ndarray:
    """mu without the two multipliers nearest +1 (a conservative autonomous orbit has them).

    Parameters
    ----------
    mu : (2n,) array_like of complex
        Floquet multipliers.

    Returns
    -------
    (2n - 2,) ndarray of complex
        The others, in their original order (empty when 2n <= 2).
    """
    mu = np.asarray(mu)
    if mu.size <= 2:
        return mu[:0]
    keep = np.argsort(np.abs(mu - 1.0), kind="stable")[2:]
    return mu[np.sort(keep)]


MULTIPLE_SEGMENTS = 8  # segments of the multiple-shooting fallback
MULTIPLE_MAC = 0.9999  # shape test for orbits found by the fallback


class ShootingError(RuntimeError):
    """Shooting found no periodic orbit: (Gauss-)Newton on the periodicity equations of the exact
    flow did not converge (the free orbits of :func:`shoot` and :func:`shoot_multiple`, the forced
    ones of :func:`reduced.periodic.forced_stability.floquet_by_shooting`)."""


@dataclass(frozen=True, eq=False)
class PeriodicOrbit:
    """One periodic orbit of the exact flow and its Floquet multipliers.

    Attributes
    ----------
    x0 : (n,) ndarray of float
        m, displacement at t = 0 (a turning point of DOF ``ref``).
    v0 : (n,) ndarray of float
        m/s, velocity at t = 0.
    period_s : float
        s, T.
    energy_J : float
        J, total energy of the orbit.
    monodromy : (2n, 2n) ndarray of float
        d y(T) / d y(0), y = [x; v].
    multipliers : (2n,) ndarray of complex
        Its eigenvalues, by decreasing modulus.
    closure : float
        Scaled residual |y(T) - y(0)| (relative to the orbit's scale) at the solution.
    n_iter : int
        Gauss-Newton iterations.
    n_events : int
        Contact events over one period.
    wall_s : float
        s, wall time.
    """

    x0: np.ndarray  # m, (n,)
    v0: np.ndarray  # m/s, (n,)
    period_s: float
    energy_J: float
    monodromy: np.ndarray  # (2n, 2n)
    multipliers: np.ndarray  # (2n,) complex, sorted by decreasing modulus
    closure: float  # |y(T) - y(0)| relative to the orbit's scale
    n_iter: int
    n_events: int
    wall_s: float

    @property
    def freq_hz(self) -> float:
        return 1.0 / self.period_s

    @property
    def nontrivial(self) -> np.ndarray:
        """The multipliers without the trivial pair at +1 (time shift and energy)."""
        return drop_trivial_pair(self.multipliers)

    @property
    def max_multiplier(self) -> float:
        """Largest |mu| over the nontrivial multipliers."""
        return float(np.max(np.abs(self.nontrivial), initial=1.0))

    @property
    def stable(self) -> bool:
        return self.max_multiplier <= 1.0 + FLOQUET_TOL


def conservative(system: GapSystem) -> GapSystem:
    """The same system with C = 0 (NNMs are orbits of the undamped system).

    Parameters
    ----------
    system : GapSystem
        Any gap system.

    Returns
    -------
    GapSystem
        A copy with C = 0.
    """
    return replace(system, C=np.zeros_like(system.C))


def energy_gradient(system: GapSystem, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """dE/d[x; v] = [K x + B^T f(B x); M v].

    Parameters
    ----------
    system : GapSystem
        The system.
    x : (n,) ndarray of float
        m, displacement.
    v : (n,) ndarray of float
        m/s, velocity.

    Returns
    -------
    (2n,) ndarray of float
        N and kg m/s.
    """
    return np.concatenate([system.K @ x + system.contact_force(x), system.M @ v])


def shoot(
    flow: Flow,
    x0: np.ndarray,
    v0: np.ndarray,
    period_s: float,
    energy_J: float,
    *,
    ref: int | None = None,
    tol: float = 1e-14,
    max_iter: int = 30,
    stall: int | None = None,
    max_events: int | None = None,
) -> PeriodicOrbit:
    """The periodic orbit of energy ``energy_J`` nearest the guess (x0, v0, period_s).

    ``flow`` must be the exact flow of an undamped system (see :func:`conservative`).
    Raises :class:`ShootingError` if Gauss-Newton fails, or, with ``stall``, as soon as
    ``stall`` iterations have not halved the residual (a guess outside the basin: on a
    reduced model each iteration of a hopeless start costs up to 0.2 s). With
    ``max_events``, an iterate whose period holds more contact events counts as a failed
    flow (a chattering iterate far from any NNM orbit, which has a few impacts per period:
    its flow costs ~1 ms an event).

    Parameters
    ----------
    flow : Flow
        The exact flow of the undamped system.
    x0 : (n,) array_like of float
        m, guessed displacement at t = 0.
    v0 : (n,) array_like of float
        m/s, guessed velocity (its ``ref`` entry is set to zero).
    period_s : float
        s, guessed period.
    energy_J : float
        J, E*, the energy of the orbit wanted.
    ref : int, optional
        DOF whose velocity is zero at t = 0 (default: the largest |x0|).
    tol : float
        Scaled residual at which the iterations stop early; an orbit is accepted at a residual
        <= 1e-9 whatever ``tol`` is.
    max_iter : int
        Gauss-Newton iterations at most.
    stall : int, optional
        Give up when this many iterations have not halved the residual.
    max_events : int, optional
        Most contact events allowed in one period of an iterate.

    Returns
    -------
    PeriodicOrbit

    Raises
    ------
    ValueError
        A damped system.
    ShootingError
        As above, or the flow fails at the initial guess.
    """
    with single_thread_blas():
        return _shoot(flow, x0, v0, period_s, energy_J, ref=ref, tol=tol, max_iter=max_iter, stall=stall,
                      max_events=max_events)


def _shoot(flow, x0, v0, period_s, energy_J, *, ref, tol, max_iter, stall=None, max_events=None) -> PeriodicOrbit:
    t0 = time.perf_counter()
    system = flow.system
    if not system.undamped:
        raise ValueError("shooting for NNMs needs the undamped system: use conservative(system)")
    n = system.n
    x = np.array(x0, float)
    v = np.array(v0, float)
    T = float(period_s)
    if ref is None:
        ref = int(np.argmax(np.abs(x)))
    v[ref] = 0.0
    # scales: displacement, velocity, period and energy rows of order one
    xs = max(float(np.max(np.abs(x))), 1e-300)
    w = 2.0 * np.pi / T
    D = np.concatenate([np.full(n, xs), np.full(n, w * xs), [T]])
    rs = np.concatenate([np.full(n, xs), np.full(n, w * xs)])

    def evaluate(x, v, T):
        fl = flow(x, v, T)  # the Jacobian only for the iterates taken (flow.jacobian_of below)
        if max_events is not None and fl.n_events > max_events:
            raise ExactIntegratorError(f"{fl.n_events} contact events in one period (more than {max_events})")
        y0 = np.concatenate([x, v])
        r = np.concatenate(
            [(fl.y - y0) / rs, [v[ref] / (w * xs)], [(system.energy(x, v) - energy_J) / energy_J]]
        )
        return fl, r

    try:
        fl, r = evaluate(x, v, T)
    except ExactIntegratorError as exc:
        raise ShootingError(f"the flow failed at the initial guess: {exc}") from None
    best = None
    history = []
    for it in range(1, max_iter + 1):
        fl = replace(fl, jacobian=flow.jacobian_of(fl))
        J = np.zeros((2 * n + 2, 2 * n + 1))
        J[: 2 * n, : 2 * n] = (fl.jacobian - np.eye(2 * n)) / rs[:, None]
        J[: 2 * n, 2 * n] = flow.vector_field(fl.y) / rs
        J[2 * n, n + ref] = 1.0 / (w * xs)
        J[2 * n + 1, : 2 * n] = energy_gradient(system, x, v) / energy_J
        J = J * D  # columns in scaled unknowns
        rn = float(np.max(np.abs(r)))
        if best is None or rn < best[0]:
            best = (rn, x.copy(), v.copy(), T, fl, it)
        if rn < tol * 10.0:
            break
        history.append(rn)
        if stall is not None and len(history) > stall and rn > 0.5 * history[-1 - stall]:
            raise ShootingError(f"stalled: residual {rn:.3g} after {it} iterations ({stall} without halving it)")
        dz = -np.linalg.lstsq(J, r, rcond=None)[0] * D
        if np.max(np.abs(dz[:n])) < 1e-16 * xs and it > 2:
            break
        # damped Gauss-Newton: halve the step while the flow fails (e.g. chattering on a
        # grazing iterate) or the residual grows
        lam = 1.0
        for _ in range(10):
            xn, vn, Tn = x + lam * dz[:n], v + lam * dz[n : 2 * n], T + lam * dz[2 * n]
            if Tn > 0 and np.all(np.isfinite(xn)):
                try:
                    fln, rnew = evaluate(xn, vn, Tn)
                    if float(np.max(np.abs(rnew))) < max(rn, 1e-300) or lam < 0.01:
                        break
                except ExactIntegratorError:
                    pass
            lam *= 0.5
        else:
            raise ShootingError(f"no acceptable step at iteration {it}")
        x, v, T, fl, r = xn, vn, Tn, fln, rnew
    rn, x, v, T, fl, it = best
    if rn > 1e-9:
        raise ShootingError(f"no periodic orbit: closure residual {rn:.3g} after {max_iter} iterations")
    mu = np.linalg.eigvals(fl.jacobian)
    mu = mu[np.argsort(-np.abs(mu), kind="stable")]
    return PeriodicOrbit(
        x, v, T, float(system.energy(x, v)), fl.jacobian, mu, rn, it, fl.n_events, time.perf_counter() - t0
    )


def mirror_mode(orbit: PeriodicOrbit) -> str:
    """"antisymmetric" or "symmetric": the eigenvector of the largest Floquet multiplier of an orbit of a
    mirror-symmetric 3-DOF model (state [x1, x2, x3, v1, v2, v3], mirror x1 <-> x3), by which part is
    larger: |e_x1 - e_x3| + |e_v1 - e_v3| (antisymmetric) or |e_x1 + e_x3| + |e_v1 + e_v3| + 2 |e_x2, e_v2|
    (symmetric). An orbit unstable with an antisymmetric eigenvector is one a symmetric motion leaves.

    Parameters
    ----------
    orbit : PeriodicOrbit
        An orbit of a mirror-symmetric three-DOF model.

    Returns
    -------
    {'antisymmetric', 'symmetric'}
    """
    lam, vec = np.linalg.eig(orbit.monodromy)
    e = vec[:, int(np.argmax(np.abs(lam)))]
    anti = float(np.linalg.norm(e[[0, 3]] - e[[2, 5]]))
    sym = float(np.linalg.norm(e[[0, 3]] + e[[2, 5]]) + 2 * np.linalg.norm(e[[1, 4]]))
    return "antisymmetric" if anti > sym else "symmetric"


def floquet_scan(system: GapSystem, modes, energies_J: np.ndarray) -> dict[int, list]:
    """{mode: [PeriodicOrbit or None per energy]}: shooting along NNM ``mode`` (0-based) of the undamped
    ``system`` at each energy (:func:`shooting_branch` on the exact flow, guided by the HB branch with
    one harmonic), on one BLAS thread.

    Parameters
    ----------
    system : GapSystem
        The system (made undamped here).
    modes : iterable of int
        0-based NNMs.
    energies_J : (k,) array_like of float
        J, the energies, increasing.

    Returns
    -------
    dict of int to list
        Mode -> a :class:`PeriodicOrbit` or None per energy.
    """
    from reduced.periodic.backbones import nnm_branch

    cons = conservative(system)
    flow = Flow(cons)
    out = {}
    for mode in modes:
        guide = nnm_branch(cons, int(mode), H=1)
        with single_thread_blas():
            out[int(mode)] = shooting_branch(flow, np.asarray(energies_J, float), [guide])
    return out


__all__ = [
    "drop_trivial_pair",
    "floquet_scan",
    "mirror_mode",
    "PeriodicOrbit",
    "ShootingError",
    "shoot",
    "shooting_branch", "shoot_multiple",
    "conservative",
    "energy_gradient",
    "FLOQUET_TOL",
]


def shoot_multiple(
    flow: Flow,
    Y: np.ndarray,
    period_s: float,
    energy_J: float,
    *,
    ref: int | None = None,
    tol: float = 1e-13,
    max_iter: int = 40,
) -> PeriodicOrbit:
    """Multiple shooting: the orbit through states Y (M, 2n) at t = k T / M, k = 0..M-1.

    Unknowns Y and T; equations phi_{T/M}(Y_k) - Y_{k+1} = 0 (cyclic), v0[ref] = 0 and
    E(Y_0) = E*, solved by damped Gauss-Newton. Each segment sees only the M-th root of the
    monodromy's amplification, so the basin is much wider than single shooting's where the
    orbit is very unstable (near grazing). The monodromy is the product of the segment
    Jacobians at the solution. Raises :class:`ShootingError` on failure.

    Parameters
    ----------
    flow : the exact flow of the undamped system (:func:`conservative`)
    Y : (M, 2n) guessed states [x; v] at t = k T / M
    period_s, energy_J : s, the guessed period T; J, the energy E* of the orbit wanted
    ref : DOF whose velocity is zero at t = 0 (default: the largest |x| of Y[0])
    tol, max_iter : scaled residual to reach (accepted at <= 1e-9), Gauss-Newton iterations at most

    Returns
    -------
    PeriodicOrbit
    """
    t0 = time.perf_counter()
    system = flow.system
    n = system.n
    Y = np.array(Y, float)
    M = Y.shape[0]
    T = float(period_s)
    if ref is None:
        ref = int(np.argmax(np.abs(Y[0, :n])))
    xs = max(float(np.max(np.abs(Y[:, :n]))), 1e-300)
    w = 2.0 * np.pi / T
    sc = np.concatenate([np.full(n, xs), np.full(n, w * xs)])
    nu = 2 * n * M + 1

    def evaluate(Y, T):
        segs, r = [], []
        for k in range(M):
            fl = flow(Y[k, :n], Y[k, n:], T / M, jacobian=True)
            segs.append(fl)
            r.append((fl.y - Y[(k + 1) % M]) / sc)
        r.append([Y[0, n + ref] / (w * xs)])
        r.append([(system.energy(Y[0, :n], Y[0, n:]) - energy_J) / energy_J])
        return segs, np.concatenate(r)

    try:
        segs, r = evaluate(Y, T)
    except ExactIntegratorError as exc:
        raise ShootingError(f"the flow failed at the initial guess: {exc}") from None
    D = np.concatenate([np.tile(sc, M), [T]])
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        rn = float(np.max(np.abs(r)))
        if rn < tol:
            break
        J = np.zeros((2 * n * M + 2, nu))
        for k in range(M):
            rows = slice(2 * n * k, 2 * n * (k + 1))
            J[rows, 2 * n * k : 2 * n * (k + 1)] = segs[k].jacobian / sc[:, None]
            kk = (k + 1) % M
            J[rows, 2 * n * kk : 2 * n * (kk + 1)] -= np.diag(1.0 / sc)
            J[rows, -1] = flow.vector_field(segs[k].y) / sc / M
        J[-2, n + ref] = 1.0 / (w * xs)
        J[-1, : 2 * n] = energy_gradient(system, Y[0, :n], Y[0, n:]) / energy_J
        J = J * D
        dz = -np.linalg.lstsq(J, r, rcond=None)[0] * D
        lam = 1.0
        for _ in range(12):
            Yn = Y + lam * dz[:-1].reshape(M, 2 * n)
            Tn = T + lam * dz[-1]
            if Tn > 0:
                try:
                    segn, rnew = evaluate(Yn, Tn)
                    if float(np.max(np.abs(rnew))) < rn or lam < 1e-3:
                        break
                except ExactIntegratorError:
                    pass
            lam *= 0.5
        else:
            raise ShootingError(f"multiple shooting: no acceptable step at iteration {it}")
        Y, T, segs, r = Yn, Tn, segn, rnew
    rn = float(np.max(np.abs(r)))
    if rn > 1e-9:
        raise ShootingError(f"multiple shooting: residual {rn:.3g} after {max_iter} iterations")
    Phi = np.eye(2 * n)
    for fl in segs:
        Phi = fl.jacobian @ Phi
    mu = np.linalg.eigvals(Phi)
    mu = mu[np.argsort(-np.abs(mu), kind="stable")]
    x0, v0 = Y[0, :n].copy(), Y[0, n:].copy()
    return PeriodicOrbit(x0, v0, T, float(system.energy(x0, v0)), Phi, mu, rn, it,
                         sum(fl.n_events for fl in segs), time.perf_counter() - t0)


def _guide_point(g, E: float, at_energy: bool) -> tuple[np.ndarray, float]:
    """(X, omega) of HB branch g nearest energy E in log; with ``at_energy`` corrected onto E
    within the same piece of branch (kept if Newton converges within 5 % of its frequency)."""
    i = int(np.argmin(np.abs(np.log(g.energy_J / E))))
    if at_energy:
        from reduced.periodic.backbones import hb_point_at_energy
        from reduced.periodic.hb import NewtonError

        seg = g.segment[i]
        j = i - int(np.flatnonzero(g.segment == seg)[0])  # a piece keeps a prefix of its Branch's points
        y0 = g.branches[seg].y[j]
        try:
            y = hb_point_at_energy(g.residual, y0, float(E))
        except NewtonError:
            y = None
        if y is not None:
            X, omega = g.residual.X_omega(y)
            if abs(omega / g.omega[i] - 1.0) < 0.05:
                return X, omega
    return g.X[i], g.omega[i]


def _mac(M, a, b) -> float:
    return float((a @ M @ b) ** 2 / ((a @ M @ a) * (b @ M @ b)))


def shooting_branch(
    flow: Flow,
    energies_J: np.ndarray,
    guides: list,
    *,
    max_rel_jump: float = 0.25,
    min_mac: float = 0.995,
    max_iter: int = 25,
    max_substeps: int = 2,
    use_multiple: bool = False,
    stall: int | None = None,
    max_events: int | None = None,
    pick: str = "first",
    guide_at_energy: bool = False,
) -> list[PeriodicOrbit | None]:
    """Orbits at increasing energies along an NNM: natural-parameter continuation in energy.

    ``guides`` are HB branches (:class:`reduced.periodic.backbones.NNMBranch`, best first) of the
    same NNM. At each energy the guesses tried are the previous orbit scaled to the new
    energy (a secant prediction from the last two orbits first; its period scaled by the
    first guide's frequency ratio, then unscaled), then
    each guide's point nearest in log energy. An orbit is accepted only if its frequency is
    within ``max_rel_jump`` of the first guide's and its shape has a MAC above ``min_mac``
    with the previous orbit's (the guide's for the first), so a guess that converges onto
    another orbit family is refused, not silently kept. Near grazing the orbits are very
    unstable (|mu| ~ 1e2) and single shooting has a small basin: when every guess fails,
    multiple shooting (:func:`shoot_multiple`) is tried from the guides' orbits if
    ``use_multiple`` (off by default, see the code), then the energy step from the
    previous orbit is halved (in log) up to ``max_substeps`` times. ``stall`` and
    ``max_events`` are passed to :func:`shoot` (give up a guess that does not halve the
    residual in that many iterations; refuse iterates with more events per period).
    ``pick = "nearest"`` tries every guess and keeps, of the accepted orbits, the one
    nearest the first guide's frequency, instead of the first accepted ("first"): a reduced
    model's exact flow has neighbouring orbit families that pass the shape test (seen on
    rom-fep: NNM 3 at 65 J continued onto an orbit 0.3 % below the one every converged HB
    branch agrees with to 1e-6). With ``guide_at_energy`` each guide's guess is its point
    nearest in log energy corrected onto the energy E by Newton
    (:func:`reduced.periodic.backbones.hb_point_at_energy`), not the point itself: on a
    sparse branch (a few tens of points over nine decades) the nearest point can lie a
    factor 2 away in energy; the first guide's frequency there is then the reference of
    the frequency test and of ``pick``.

    Parameters
    ----------
    flow : the exact flow of the undamped system (:func:`conservative`)
    energies_J : J, increasing
    guides : HB branches of the NNM, best first
    max_rel_jump, min_mac, pick : the acceptance of an orbit (above)
    max_iter, stall, max_events : passed to :func:`shoot`
    max_substeps, use_multiple, guide_at_energy : the fallbacks and guesses (above)

    Returns
    -------
    list
        A :class:`PeriodicOrbit` or None per energy.
    """
    g0 = guides[0]
    order = np.argsort(g0.energy_J)
    march = _March(flow, guides, np.log(g0.energy_J[order]), g0.freq_hz[order], max_rel_jump, min_mac, max_iter,
                   stall, max_events, pick, guide_at_energy, use_multiple)
    out = []
    prev = prev2 = None
    for E in np.asarray(energies_J, float):
        orbit = _attempt(march, E, prev, prev2)
        if orbit is None and prev is not None and E > prev.energy_J:
            orbit, prev2 = _substeps(march, E, prev, prev2, max_substeps)
        elif orbit is not None:
            prev2 = prev
        out.append(orbit)
        if orbit is not None:
            prev = orbit
    return out


@dataclass(frozen=True, eq=False)
class _March:
    """What :func:`shooting_branch` tries at each energy: its flow, its guides (the first one's
    frequency against log energy, ``lgE`` and ``fg``) and its acceptance options."""

    flow: Flow
    guides: list
    lgE: np.ndarray  # ln J, the first guide's energies, sorted
    fg: np.ndarray  # Hz, its frequencies there
    max_rel_jump: float
    min_mac: float
    max_iter: int
    stall: int | None
    max_events: int | None
    pick: str
    guide_at_energy: bool
    use_multiple: bool

    def f_guide(self, E: float) -> float:
        """Hz, the first guide's frequency at energy E (interpolated in log energy)."""
        return float(np.interp(np.log(E), self.lgE, self.fg))


def _substeps(march: _March, E: float, prev: PeriodicOrbit, prev2, max_substeps: int):
    """(orbit at E, the orbit before it) marched from ``prev`` in 2, 4, ... log-spaced energy steps
    (up to 2^max_substeps), or (None, prev2) when no march reaches E."""
    for depth in range(1, max_substeps + 1):
        cur, cur2 = prev, prev2
        for Es in np.geomspace(prev.energy_J, E, 2**depth + 1)[1:]:
            nxt = _attempt(march, Es, cur, cur2)
            if nxt is None:
                break
            cur, cur2 = nxt, cur
        else:
            return cur, cur2
    return None, prev2


def _guesses(march: _March, E: float, prev, prev2) -> tuple[list, float, np.ndarray]:
    """(guesses (x0, v0, T) in the order tried, the reference frequency [Hz], the reference shape)
    at energy E (:func:`shooting_branch`)."""
    guesses = []
    if prev is not None and prev2 is not None and E / prev.energy_J < 3.0 and prev.energy_J > prev2.energy_J:
        # secant predictor in log energy from the last two orbits
        s_ = np.log(E / prev.energy_J) / np.log(prev.energy_J / prev2.energy_J)
        guesses.append((prev.x0 + s_ * (prev.x0 - prev2.x0), prev.v0 + s_ * (prev.v0 - prev2.v0),
                        prev.period_s + s_ * (prev.period_s - prev2.period_s)))
    if prev is not None and E / prev.energy_J < 3.0:
        sc = np.sqrt(E / prev.energy_J)
        ratio = march.f_guide(prev.energy_J) / march.f_guide(E)
        guesses.append((prev.x0 * sc, prev.v0 * sc, prev.period_s * ratio))
        guesses.append((prev.x0 * sc, prev.v0 * sc, prev.period_s))
    f_ref = march.f_guide(E)
    for k, g in enumerate(march.guides):
        X, omega = _guide_point(g, E, march.guide_at_energy)
        x, v = g.residual.hb.time_series(X, omega)
        guesses.append((x[0], v[0], 2 * np.pi / omega))
        if k == 0 and march.guide_at_energy:
            f_ref = omega / (2 * np.pi)  # the first guide at exactly E, not interpolated
    if prev is not None and E / prev.energy_J < 3.0:
        shape_ref = prev.x0  # the last exact orbit of this branch is the better shape
    else:
        g0 = march.guides[0]
        i0 = int(np.argmin(np.abs(np.log(g0.energy_J / E))))
        shape_ref = g0.residual.hb.time_series(g0.X[i0])[0]
    return guesses, f_ref, shape_ref


def _attempt(march: _March, E: float, prev, prev2) -> PeriodicOrbit | None:
    """The orbit at energy E from the guesses (:func:`_guesses`) that passes the frequency and shape
    tests, then (opt-in) by multiple shooting from the guides; None if none does."""
    guesses, f_ref, shape_ref = _guesses(march, E, prev, prev2)
    M = march.flow.system.M
    found = []
    for x0, v0, T in guesses:
        if not T > 0.0:
            continue
        try:
            o = shoot(march.flow, x0, v0, T, E, max_iter=march.max_iter, stall=march.stall,
                      max_events=march.max_events)
        except (ShootingError, RuntimeError):
            continue
        # the same NNM: near the guide's frequency and the same shape (mass-weighted
        # MAC of the turning-point displacement; NNM 2 and NNM 3 are orthogonal)
        if abs(o.freq_hz / f_ref - 1.0) < march.max_rel_jump and _mac(M, o.x0, shape_ref) > march.min_mac:
            if march.pick == "first":
                return o
            found.append(o)
    if found:
        return min(found, key=lambda o: abs(o.freq_hz / f_ref - 1.0))
    return _attempt_multiple(march, E, f_ref, shape_ref) if march.use_multiple else None


def _attempt_multiple(march: _March, E: float, f_ref: float, shape_ref: np.ndarray) -> PeriodicOrbit | None:
    """Multiple shooting from each guide's orbit nearest E, under a stricter shape test; or None.

    Opt-in (near grazing single shooting's basin is too small). Off by default: in the
    discrete-fep run it also converged to a neighbouring family 4.5 % off NNM 2 that passed even
    the strict shape test, and the branch then followed it.
    """
    for g in march.guides:
        i = int(np.argmin(np.abs(np.log(g.energy_J / E))))
        x, v = g.residual.hb.time_series(g.X[i], g.omega[i], N=MULTIPLE_SEGMENTS)
        try:
            o = shoot_multiple(march.flow, np.hstack([x, v]), 2 * np.pi / g.omega[i], E)
        except (ShootingError, RuntimeError):
            continue
        # a wider basin also reaches neighbouring orbit families (seen: an asymmetric
        # orbit 6 % below NNM 2 at MAC 0.998), hence a stricter shape test here
        M = march.flow.system.M
        if abs(o.freq_hz / f_ref - 1.0) < march.max_rel_jump and _mac(M, o.x0, shape_ref) > MULTIPLE_MAC:
            return o
    return None
