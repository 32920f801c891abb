"""Forced periodic orbits of a system with friction at the tips, by shooting on the exact friction flow.

The system (:class:`reduced.models.gaps.GapSystem` with :class:`~reduced.models.gaps.Friction`) under one
harmonic load along b,

    M x'' + C x' + K x + B^T f(B x) + Bt^T f_t = b P cos(Omega t + phi),

moves in the augmented state y = [x; v; w] (w the sliders' positions, each slider's force
f_t = k_t (Bt x - w) in stick, +-mu N in slip, 0 while its tip is open), and the exact friction integrator
(:func:`reduced.transient.friction.integrate_exact_friction`: stick, slip and gaps as events, each state in
closed form) is its flow phi. A periodic orbit of the load's period T = 2 pi / Omega is a fixed point of the
period map, y(T) = y(0). It is found by **multiple shooting**: with S nodes y_k at t_k = k T / S,

    R_k(Y) = (phi(y_k; t_k, T / S) - y_{k+1}) / D = 0,   k = 0..S-1 (y_S = y_0),

(2n + p) S equations in as many unknowns, scaled by D = [x_ref (n), Omega x_ref (n), x_ref (p)]. S = 1 is
single shooting on y(T) - y(0); the default S = :data:`reduced.periodic.forced_shooting.SEGMENTS` (8) for the
reason the frictionless forced shooting uses it: each node sees only the S-th root of the orbit's growth per
period, and the orbits in contact here have Floquet multipliers of 10-1000 (measured: from the HB orbits of
the discrete friction model at 14.3, 17.4 and 26.9 Hz single shooting stalls where S = 8 converges in 5-7
Newton steps). A segment starts the load at its own phase, phi + Omega t_k.

**Jacobian.** dR_k/dy_k = Phi_k, the segment's monodromy, by finite differences on the integrator (forward,
step ``FD_STEP`` D, in Newton; central, ``FD_STEP_CENTRAL`` D, for the multipliers): the exact integrator has
no variational equations with friction (the stick-slip switches have non-identity saltation matrices, a
closing resets w), and (2n + p) + 1 runs of T / S per node cost the same as single shooting's. The orbit's
monodromy is Phi = Phi_{S-1} ... Phi_0; its eigenvalues are the Floquet multipliers. Newton's unknowns are
z = [x; v; d], d = Bt x - w the sliders' stretches (a linear change of variables, its residual rows in the
same units D): a stiff slider holds its whole cone mu N within a stretch mu N / k_t far below the amplitude
(3e-10 m for k_t = 1e10 N/m and 3 N), so a difference step in x at fixed w, or in w of 1e-7 of the
amplitude, would throw it across the cone; in z a step in x moves w with it, and the stretch's own step is
at most ``FD_SLIDER`` of the slider's elastic range at the nodes.

**The sliders' memory, and rank deficiency.** w is a hysteretic state, and two cases make the periodicity
equations singular:

- a slider whose tip is **open the whole period**: the integrator keeps it unloaded (w follows t = Bt x while
  open, and is reset to w = t at a closing), so its w moves nothing and is periodic whenever x is; the
  equations hold for any shift of it (a null vector of dR/dY; the multiplier 1);
- a slider **stuck the whole period**: any w inside the cone |k_t (t - w)| < mu N is periodic, a family of
  orbits (the HB loop picks f(tau_0) = 0 for it, :func:`reduced.periodic.friction_aft.jenkins_loop`).

A slider open at a node but closing later in the period is well posed: its w there is fixed by its reset
(the row w_{k+1} = ... holds, the column of w_k is zero). Rather than detect the two singular cases from the
events, each Newton step is the **minimum-norm least-squares** solution of dR/dY dY = -R (SVD, singular
values below ``RANK_RTOL`` times the largest dropped): it leaves a null direction where the start put it
(the HB loop's w), and the result reports the numerical rank (``rank`` < ``size``: that many free
directions, each with a multiplier 1, marginal, not unstable).

**Start.** :func:`hb_nodes`: the HB orbit (x, v synthesised from its harmonics at t_k) and each slider's w
from its stationary Jenkins loop by AFT on a fine grid (w = t - f / k_t; w = t where the tip is open).

**Period q T.** With ``periods`` = q the orbit is sought over q forcing periods (the nodes at t_k = k q T / S, the
residual as above with q T / S segments, the multipliers over q T): q = 2 is the period-doubled family born where a
multiplier of the T orbit passes -1 (:func:`reduced.periodic.friction_continuation.switch_branch`); its orbit is a
fixed point of the flow over 2T and not over T.

Newton is damped (the step halved while ||R||_2 does not fall) and stops when max |R| <= ``tol``, or reports
why not (:class:`FrictionShootingResult`, ``converged`` False with the defect reached): after ``max_iter``
steps, when no halved step lowers ||R||, when the defect has not halved over ``STALL_STEPS`` steps, or when
the integrator fails. It never raises for a non-converging orbit: a caller checks ``converged``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced import _checks as _check
from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.forced_shooting import SEGMENTS
from reduced.periodic.friction_aft import FrictionBalance, jenkins_loop
from reduced.periodic.hb import _derivative_matrix, _phases, _synthesis_matrix
from reduced.transient.exact import ExactIntegratorError
from reduced.transient.friction import FrictionFlow, integrate_exact_friction

FD_STEP = 1e-7  # x D: forward differences in Newton (truncation ~1e-7 of the Jacobian, round-off ~eps / 1e-7)
FD_STEP_CENTRAL = 1e-6  # x D: central differences for the multipliers (truncation ~1e-12, round-off ~1e-10;
# small enough that no event changes order in a contact of ~100 segments of the period: measured the same
# Jacobian to 1e-7 for steps 1e-6 .. 1e-8 on the discrete friction model in contact)
FD_SLIDER = 1e-4  # x a slider's elastic range mu N / k_t: its stretch's difference step at most (module docstring)
FD_FLOOR = 1e-2  # x the step in x: the least step of a stretch (an open slider's d is 0: no elastic range)
RANK_RTOL = 1e-8  # singular values below this x the largest are null directions (a free slider's: ~1e-13)
TOL = 1e-11  # max |R| in units of D at convergence (the integrator is exact to ~1e-13 of the amplitude)
MAX_ITER = 30  # Newton steps at most
MAX_HALVINGS = 10  # halvings of a Newton step before giving up on it (1/1024 of it)
STALL_STEPS = 8  # stop when the defect has not halved over this many steps (a Newton that creeps: no orbit near)
STABLE_TOL = 1e-6  # |mu| <= 1 + this counts as stable: a free slider's multiplier is 1 (1 + 5e-9 measured in contact)
HB_LOOP_SAMPLES = 64  # AFT samples a segment for the HB start's Jenkins loops


def _load(b: np.ndarray, amplitude_N: float, freq_hz: float, phase_deg: float) -> Loads:
    return Loads(np.atleast_2d(b), (Harmonic(amplitude_N, freq_hz, phase_deg),))


def flow(system: GapSystem, b: np.ndarray, amplitude_N: float, freq_hz: float, y: np.ndarray, t0: float,
         duration_s: float, samples: int = 1, phase_deg: float = 0.0) -> np.ndarray:
    """(samples + 1, 2n + p) the exact friction flow from y = [x; v; w] at time t0 over ``duration_s``.

    The load b P cos(2 pi f t + phi) from t0 on (a load of phase phi + 360 f t0 in the integrator's own
    clock), ``samples`` equal steps, the start included.

    Parameters
    ----------
    system : GapSystem
        With friction.
    b : (n,) the load direction
    amplitude_N : N, P
    freq_hz : Hz, f
    y : (2n + p,) m, m/s, m, the state at t0
    t0 : s, the start time
    duration_s : s
    samples : output steps
    phase_deg : degrees, phi

    Returns
    -------
    ndarray
        (samples + 1, 2n + p): [x, v, w] at t0 + j duration_s / samples.
    """
    n = system.n
    loads = _load(b, amplitude_N, freq_hz, phase_deg + 360.0 * freq_hz * t0)
    r = integrate_exact_friction(system, y[:n], y[n:2 * n], duration_s, samples / duration_s, w0=y[2 * n:],
                                 loads=loads, chunks=1)
    if r.t.size != samples + 1:
        raise ExactIntegratorError(f"{r.t.size} samples where {samples + 1} were asked")
    return np.hstack([r.x, r.v, r.w])


@dataclass(eq=False)
class FrictionShootingResult:
    """A forced periodic orbit with friction by multiple shooting (:func:`shoot_friction`).

    Attributes
    ----------
    system, b, amplitude_N, freq_hz, phase_deg : the system and its load
    nodes : (S, 2n + p) the states [x; v; w] at t_k = k T / S (the last Newton iterate if not converged)
    scale : (2n + p,) D, the units of the defect
    converged : max |R| <= tol
    defect : max |R|, the multiple-shooting defect in units of D (relative to the amplitude)
    period_defect : |phi(y_0; 0, T) - y_0| / D, max over the components, from one run over the whole period
        (the fixed point of the period map; NaN if not converged)
    n_iter : Newton steps
    rank : numerical rank of dR/dY at the last step (``size`` - rank free directions)
    size : unknowns, (2n + p) S
    multipliers : (2n + p,) complex Floquet multipliers (central differences; None if not converged)
    monodromy : (2n + p, 2n + p) the orbit's monodromy (None if not converged)
    history : max |R| at each Newton step
    message : how Newton ended
    wall_s : s
    periods : the orbit's period in forcing periods (1: T; 2: the period-doubled orbit, nodes at t_k = k 2T / S,
        ``period_defect`` and the multipliers over 2T)
    """

    system: GapSystem
    b: np.ndarray
    amplitude_N: float
    freq_hz: float
    phase_deg: float
    nodes: np.ndarray
    scale: np.ndarray
    converged: bool
    defect: float
    period_defect: float
    n_iter: int
    rank: int
    size: int
    multipliers: np.ndarray | None = None
    monodromy: np.ndarray | None = None
    history: list = field(default_factory=list)
    message: str = ""
    wall_s: float = 0.0
    periods: int = 1

    @property
    def max_abs_multiplier(self) -> float:
        """The largest |mu| (NaN without multipliers)."""
        return math.nan if self.multipliers is None else float(np.max(np.abs(self.multipliers)))

    @property
    def stable(self) -> bool | None:
        """max |mu| <= 1 + STABLE_TOL (None without multipliers)."""
        return None if self.multipliers is None else bool(self.max_abs_multiplier <= 1.0 + STABLE_TOL)

    def orbit(self, samples_per_segment: int = 200) -> tuple[np.ndarray, np.ndarray]:
        """(t (S m + 1,) s, y (S m + 1, 2n + p)): the orbit over one period, each segment run from its own node
        (no growth of the defect along the period), m = ``samples_per_segment``; the first node again at T (over
        ``periods`` T)."""
        S = self.nodes.shape[0]
        h = self.periods / self.freq_hz / S
        m = int(samples_per_segment)
        y = np.empty((S * m + 1, self.nodes.shape[1]))
        for k in range(S):
            y[k * m:(k + 1) * m] = flow(self.system, self.b, self.amplitude_N, self.freq_hz, self.nodes[k], k * h, h,
                                        m, self.phase_deg)[:-1]
        y[-1] = self.nodes[0]
        return np.arange(S * m + 1) * (h / m), y


def hb_nodes(balance: FrictionBalance, X: np.ndarray, freq_hz: float, segments: int = SEGMENTS,
             samples: int = HB_LOOP_SAMPLES) -> np.ndarray:
    """(S, 2n + p) the HB orbit's augmented states at t_k = k T / S, the start of :func:`shoot_friction`.

    x(tau) = E(tau) X and v = Omega E(tau) Nab X from the harmonics X (rows 1, cos tau, sin tau, ...,
    :func:`reduced.periodic.hb._synthesis_matrix`); each slider's w = t - f / k_t at the node from its
    stationary Jenkins loop (:func:`reduced.periodic.friction_aft.jenkins_loop`, the return map of the AFT)
    marched on S ``samples`` points a period under the HB orbit's t = Bt x and normal force N
    (:meth:`FrictionBalance.normal_force`); w = t where the tip is open (f = 0: the integrator's unloaded
    slider).

    Parameters
    ----------
    balance : FrictionBalance
        The balance X solves (its system, sliders and contact rows).
    X : (2H+1, n) m, the HB solution's harmonics (:meth:`FrictionBalance.response`)
    freq_hz : Hz, the load's frequency
    segments : S, nodes a period
    samples : AFT samples a segment for the loops

    Returns
    -------
    ndarray
        (S, 2n + p).
    """
    X = np.asarray(X, float)
    S = _check.integer("segments", segments)
    m = _check.integer("samples", samples)
    H = (X.shape[0] - 1) // 2
    fr = balance.system.friction
    tau = _phases(S * m)
    E = _synthesis_matrix(H, tau)
    xs = E @ X
    vs = 2.0 * math.pi * freq_hz * (E @ (_derivative_matrix(H) @ X))
    qs = xs @ balance.U.T
    ws = np.empty((S * m, fr.p))
    for k in range(fr.p):
        loop = jenkins_loop(qs[:, balance.trow[k]], balance.normal_force(qs, k)[0], fr.k_t[k], fr.mu[k])
        ws[:, k] = xs @ fr.Bt[k] - loop.f / fr.k_t[k]
    return np.hstack([xs, vs, ws])[::m].copy()


def hb_at_frequency(balance: FrictionBalance, X: np.ndarray, freq_hz: float, H: int, *,
                    max_iter: int = 60) -> tuple[FrictionBalance, np.ndarray]:
    """(balance, X (2H+1, n)): the HB solution with H harmonics at ``freq_hz``, by Newton at fixed frequency
    from X (another H's harmonics, padded with zeros or cut), the balance otherwise as ``balance`` (its load,
    harmonic set, normal load; the default AFT and root samples of H). A start for :func:`hb_nodes` nearer the
    exact orbit than a low H's, and HB's convergence in H at one frequency.

    Parameters
    ----------
    balance : FrictionBalance
        The balance X solves.
    X : (2H'+1, n) m, its harmonics
    freq_hz : Hz
    H : harmonics of the new balance
    max_iter : Newton iterations at most

    Returns
    -------
    tuple
        (FrictionBalance, X (2H+1, n) m).

    Raises
    ------
    reduced.periodic.hb.NewtonError
        No HB solution found from X.
    """
    from reduced._blas import single_thread_blas
    from reduced.periodic.exact_hb import default_root_samples
    from reduced.periodic.hb import newton

    H = _check.integer("H", H)
    fb = FrictionBalance(balance.system, balance.b, balance.amplitude_N, balance.phase_deg, H,
                         default_root_samples(H), balance.odd, balance.normal_N, 0)
    X = np.asarray(X, float)
    q = np.zeros((2 * H + 1, fb.u))
    k = min(q.shape[0], X.shape[0])
    q[:k] = X[:k] @ fb.U.T
    omega = 2.0 * math.pi * freq_hz
    x_ref = float(np.max(np.abs(q))) or 1.0

    def fun(v):
        R, J, _ = fb.residual(v * x_ref, omega)
        return R / x_ref, J

    with single_thread_blas():
        z = newton(fun, q[fb.keep].ravel() / x_ref, tol=1e-12, max_iter=max_iter).y * x_ref
        return fb, fb.response(z, omega)


def hb_displacements(X: np.ndarray, freq_hz: float, t: np.ndarray) -> np.ndarray:
    """(len(t), n) m, x(t) = X_0 + sum_k X_ck cos(k Omega t) + X_sk sin(k Omega t) of the HB harmonics X (2H+1, n).

    Parameters
    ----------
    X : (2H+1, n) m, rows 1, cos, sin, ... (:func:`reduced.periodic.hb._synthesis_matrix`)
    freq_hz : Hz, Omega / (2 pi)
    t : (k,) s

    Returns
    -------
    ndarray
        (k, n) m.
    """
    X = np.asarray(X, float)
    return _synthesis_matrix((X.shape[0] - 1) // 2, 2.0 * math.pi * freq_hz * np.asarray(t, float)) @ X


class _Residual:
    """R(Y) and its finite-difference Jacobian for the multiple-shooting equations, in the coordinates
    z = [x; v; d], d = Bt x - w the sliders' stretches (module docstring)."""

    def __init__(self, system, b, P, f, phase_deg, S, D, flows: FrictionFlow | None = None, periods: int = 1):
        self.args = (system, b, P, f)
        self.phase, self.S, self.D = phase_deg, S, D
        self.h = periods / f / S  # the orbit's period is ``periods`` forcing periods
        self.n, self.Bt = system.n, system.friction.Bt
        # the lean flow (its set-up once for all the runs of the system and load; the same bits as flow())
        self.flows = FrictionFlow(system, b, P) if flows is None else flows

    def z_of(self, Y: np.ndarray) -> np.ndarray:
        """[x; v; Bt x - w] of states [x; v; w] (..., N)."""
        Z = np.array(Y, float)
        Z[..., 2 * self.n:] = Y[..., :self.n] @ self.Bt.T - Y[..., 2 * self.n:]
        return Z

    def y_of(self, Z: np.ndarray) -> np.ndarray:
        """[x; v; w] of [x; v; d] (..., N)."""
        Y = np.array(Z, float)
        Y[..., 2 * self.n:] = Z[..., :self.n] @ self.Bt.T - Z[..., 2 * self.n:]
        return Y

    def end(self, y: np.ndarray, k: int) -> np.ndarray:
        """z of phi(y; t_k, h)."""
        return self.z_of(self.flows(self.args[3], y, k * self.h, self.h, 1, self.phase)[-1])

    def ends(self, Y: np.ndarray) -> np.ndarray:
        """(S, N) z of phi(y_k; t_k, h)."""
        return np.array([self.end(Y[k], k) for k in range(self.S)])

    def residual(self, Y: np.ndarray, ends: np.ndarray) -> np.ndarray:
        return ((ends - self.z_of(np.roll(Y, -1, axis=0))) / self.D).ravel()

    def steps(self, Y: np.ndarray, rel: float) -> np.ndarray:
        """(N,) the difference steps in z: rel D for x and v; for a slider's stretch rel x_ref, but at most
        FD_SLIDER / FD_STEP x rel of its elastic range at the nodes, max(|d|, mu N / k_t) (a stiff slider's
        cone is narrower than the amplitude's 1e-7: k_t = 1e10 N/m holds 3 N within 3e-10 m), and at least
        FD_FLOOR of the step in x (w is known to eps x_ref: its round-off stays below 2e-7 of the step)."""
        s = self.args[0]
        fr, n = s.friction, self.n
        step = rel * self.D.copy()
        x = Y[:, :n]
        d = np.abs(x @ fr.Bt.T - Y[:, 2 * n:])
        N = s.stop_force(x) @ fr.engages(s.tip).T.astype(float)  # (S, p) the normal force of the slider's stops
        elastic = np.max(np.maximum(d, fr.mu * np.abs(N) / fr.k_t), axis=0)
        cap = rel * (FD_SLIDER / FD_STEP) * elastic
        step[2 * n:] = np.maximum(np.minimum(step[2 * n:], cap), FD_FLOOR * step[0])
        return step

    def blocks(self, Y: np.ndarray, ends: np.ndarray | None, rel: float) -> np.ndarray:
        """(S, N, N) the segments' monodromies in z, in units of D: forward differences from ``ends``, or
        central if ``ends`` is None."""
        S, N = Y.shape
        out = np.empty((S, N, N))
        Z = self.z_of(Y)
        step = self.steps(Y, rel)
        for k in range(S):
            for j in range(N):
                dz = np.zeros(N)
                dz[j] = step[j]
                up = self.end(self.y_of(Z[k] + dz), k)
                lo = ends[k] if ends is not None else self.end(self.y_of(Z[k] - dz), k)
                out[k, :, j] = (up - lo) / ((1.0 if ends is not None else 2.0) * step[j]) * (self.D[j] / self.D)
        return out

    def jacobian(self, blocks: np.ndarray) -> np.ndarray:
        """(S N, S N) dR/dZ: Phi_k on the diagonal blocks, -I on the next node's."""
        S, N, _ = blocks.shape
        J = np.zeros((S * N, S * N))
        for k in range(S):
            J[k * N:(k + 1) * N, k * N:(k + 1) * N] = blocks[k]
            kk = (k + 1) % S
            J[k * N:(k + 1) * N, kk * N:(kk + 1) * N] -= np.eye(N)
        return J

    def monodromy(self, Y: np.ndarray) -> np.ndarray:
        """(N, N) dy(T)/dy(0) in [x; v; w] (central differences)."""
        return monodromy_of(self.blocks(Y, None, FD_STEP_CENTRAL), self.D, self.Bt)


def monodromy_of(blocks: np.ndarray, D: np.ndarray, Bt: np.ndarray) -> np.ndarray:
    """(N, N) the orbit's monodromy dy(qT)/dy(0) in y = [x; v; w] from its segments' blocks (S, N, N) in
    z = [x; v; Bt x - w] and units D: Phi_z = Phi_{S-1} ... Phi_0 back in physical units, then
    Phi_y = T Phi_z T with T = [[I, 0, 0], [0, I, 0], [Bt, 0, -I]] (T^-1 = T).

    Parameters
    ----------
    blocks : (S, N, N) the segments' state transition matrices in z and units D
    D : (N,) the units of z
    Bt : (p, n) the sliders' tangential rows
    """
    N = D.size
    n = (N - Bt.shape[0]) // 2
    Phi = np.eye(N)
    for Jk in blocks:
        Phi = Jk * (D[:, None] / D[None, :]) @ Phi  # units of D back to physical
    Tm = np.eye(N)
    Tm[2 * n:, :n] = Bt
    Tm[2 * n:, 2 * n:] = -np.eye(Bt.shape[0])
    return Tm @ Phi @ Tm


def _newton(res: _Residual, Y: np.ndarray, tol: float, max_iter: int, blocks=None) -> tuple:
    """(Y, converged, defect, n_iter, rank, history, message): damped Gauss-Newton with minimum-norm steps in
    the scaled z / D; ``blocks(Y, ends)`` the segments' monodromies (default forward differences)."""
    S, N = Y.shape
    ends = res.ends(Y)
    R = res.residual(Y, ends)
    history, rank = [float(np.max(np.abs(R)))], S * N
    for it in range(max_iter + 1):
        r = history[-1]
        if r <= tol:
            return Y, True, r, it, rank, history, f"converged in {it} Newton steps"
        if it == max_iter:
            return Y, False, r, it, rank, history, f"defect {r:.3g} after {it} Newton steps"
        if len(history) > STALL_STEPS and r > 0.5 * history[-1 - STALL_STEPS]:
            return Y, False, r, it, rank, history, (f"defect {r:.3g} after {it} Newton steps (stalled: not halved "
                                                    f"over {STALL_STEPS} steps)")
        J = res.jacobian(res.blocks(Y, ends, FD_STEP) if blocks is None else blocks(Y, ends))
        du, _, rank, _ = np.linalg.lstsq(J, -R, rcond=RANK_RTOL)
        lam, norm, Z = 1.0, float(np.linalg.norm(R)), res.z_of(Y)
        for _ in range(MAX_HALVINGS + 1):
            Yt = res.y_of(Z + lam * du.reshape(S, N) * res.D)
            ends_t = res.ends(Yt)
            Rt = res.residual(Yt, ends_t)
            if float(np.linalg.norm(Rt)) < norm:
                break
            lam *= 0.5
        else:
            return Y, False, r, it, int(rank), history, (f"defect {r:.3g} after {it} Newton steps (no step down to "
                                                         f"1/{2 ** MAX_HALVINGS} of Newton's lowers it)")
        Y, ends, R = Yt, ends_t, Rt
        history.append(float(np.max(np.abs(R))))
    raise AssertionError("unreachable")


def shoot_friction(system: GapSystem, load: np.ndarray, amplitude_N: float, freq_hz: float, nodes: np.ndarray, *,
                   phase_deg: float = 0.0, x_ref: float | None = None, tol: float = TOL, max_iter: int = MAX_ITER,
                   multipliers: bool = True, periods: int = 1, jacobian: str = "fd") -> FrictionShootingResult:
    """The forced periodic orbit with friction nearest the guessed nodes, by multiple shooting (module docstring).

    Solves R_k = (phi(y_k; t_k, T / S) - y_{k+1}) / D = 0 for the S nodes y_k = [x; v; w] at t_k = k T / S
    (S = len(nodes); S = 1 is single shooting, y(T) = y(0)) by damped Gauss-Newton with minimum-norm
    least-squares steps (a slider open or stuck the whole period leaves a null direction), the Jacobian by
    forward differences on the exact friction integrator; at convergence the monodromy by central differences
    and its eigenvalues, the Floquet multipliers.

    Parameters
    ----------
    system : GapSystem
        With friction.
    load : (n,) the load direction b
    amplitude_N : N, P of b P cos(2 pi f t + phi)
    freq_hz : Hz, f
    nodes : (S, 2n + p) the start, e.g. :func:`hb_nodes`
    phase_deg : degrees, phi
    x_ref : m, the displacement unit of D (default: the largest |x| of the nodes)
    tol : max |R| at convergence, in units of D
    max_iter : Newton steps at most
    multipliers : compute the monodromy and the multipliers at convergence
    periods : the orbit's period in forcing periods, q T (q = 2: the period-doubled family; the nodes at
        t_k = k q T / S, the residual R_k = (phi(y_k; t_k, q T / S) - y_{k+1}) / D, the multipliers over q T)
    jacobian : "fd" (the segments' monodromies by forward differences in Newton, central for the multipliers) or
        "exact" (both from the state transition and saltation matrices along the integrator's events,
        :mod:`reduced.periodic.friction_sensitivity`, as the continuation's: 8 runs a Newton step where the
        differences take 8 (2n + p + 1))

    Returns
    -------
    FrictionShootingResult
        ``converged`` False (with the defect reached and why in ``message``) where Newton stops short.

    Examples
    --------
    A linear oscillator (its stop never reached) forced at 1 Hz: one node, the closed-form steady state.

    >>> from reduced.models.gaps import Friction
    >>> s = GapSystem(M=np.eye(1), C=0.5 * np.eye(1), K=np.eye(1) * 100.0, B=np.eye(1), k=np.array([1e6]),
    ...               offset=np.array([1.0]), side=np.array([1.0]), tip=np.array([0]), dof_names=("x",),
    ...               stop_names=("s",), friction=Friction(np.eye(1), [0], 1e6, 0.3, ("t",)))
    >>> r = shoot_friction(s, [1.0], 1.0, 1.0, np.array([[0.0, 0.0, 0.0]]))
    >>> x_closed = (1.0 / (100.0 - (2 * np.pi) ** 2 + 0.5j * 2 * np.pi)).real
    >>> bool(r.converged), bool(abs(r.nodes[0, 0] - x_closed) < 1e-12), r.rank   # w free: rank 2 of 3
    (True, True, 2)
    """
    _check.gap_system(system)
    if system.friction is None:
        raise _check.InvalidArgument("system has no friction: use reduced.periodic.forced_shooting")
    n, p = system.n, system.p
    b = _check.vector("load", load, n)
    P = _check.number("amplitude_N", amplitude_N)
    f = _check.positive("freq_hz", freq_hz, "Hz")
    Y = np.array(nodes, float)
    if Y.ndim != 2 or Y.shape[1] != 2 * n + p or not np.all(np.isfinite(Y)):
        raise _check.InvalidArgument(f"nodes must be finite, of shape (S, {2 * n + p}), got {Y.shape}")
    max_iter = _check.integer("max_iter", max_iter, lo=0)
    q = _check.integer("periods", periods, lo=1)
    if x_ref is None:
        x_ref = float(np.max(np.abs(Y[:, :n]))) or 1.0
    x_ref = _check.positive("x_ref", x_ref, "m")
    S = Y.shape[0]
    omega = 2.0 * math.pi * f
    D = np.concatenate([np.full(n, x_ref), np.full(n, omega * x_ref), np.full(p, x_ref)])
    res = _Residual(system, b, P, f, float(phase_deg), S, D, periods=q)
    if jacobian not in ("fd", "exact"):
        raise _check.InvalidArgument(f"jacobian must be 'fd' or 'exact', got {jacobian!r}")
    exact = None
    if jacobian == "exact":
        from reduced.periodic.friction_sensitivity import LOG_EVENTS, segment_blocks

        logged = FrictionFlow(system, b, P, log_events=LOG_EVENTS)  # the event log the sensitivity reads

        def exact(Yk, _ends):
            return segment_blocks(system, b, P, f, float(phase_deg), Yk, D, q, logged)
    t0 = time.perf_counter()
    try:
        Y, ok, r, it, rank, history, msg = _newton(res, Y, float(tol), max_iter, exact)
    except ExactIntegratorError as exc:
        return FrictionShootingResult(system, b, P, f, float(phase_deg), Y, D, False, math.nan, math.nan, 0, 0,
                                      S * (2 * n + p), message=f"the exact integrator failed: {exc}",
                                      wall_s=time.perf_counter() - t0, periods=q)
    out = FrictionShootingResult(system, b, P, f, float(phase_deg), Y, D, ok, r, math.nan, it, int(rank),
                                 S * (2 * n + p), history=history, message=msg, periods=q)
    if ok:
        end = flow(system, b, P, f, Y[0], 0.0, q / f, 1, float(phase_deg))[-1]
        out.period_defect = float(np.max(np.abs(end - Y[0]) / D))
        if multipliers:
            out.monodromy = res.monodromy(Y) if exact is None else monodromy_of(exact(Y, None), D, res.Bt)
            out.multipliers = np.linalg.eigvals(out.monodromy)
    out.wall_s = time.perf_counter() - t0
    return out


__all__ = ["FD_STEP", "FD_STEP_CENTRAL", "RANK_RTOL", "FrictionShootingResult", "flow", "hb_at_frequency",
           "hb_displacements", "hb_nodes", "monodromy_of", "shoot_friction"]
