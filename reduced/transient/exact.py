"""Event-driven exact ringdown of a piecewise-linear gap system.

Inside one contact state the motion obeys the linear system y' = A y + b with
y = [x; v], A = [[0, I], [-M^-1 K_s, -M^-1 C]], b = [0; M^-1 F_s], solved in closed form:

    y(tau) = y_p + sum_i V[:, i] w_i exp(lambda_i tau),   w = V^-1 (y(0) - y_p),

with A V = V diag(lambda) and y_p = [K_s^-1 F_s; 0]. Undamped states use the real modes
of (K_s, M), so lambda = +-i omega exactly and energy is conserved to round-off.

The next gap crossing is the first root of q_j(tau) = +-(side_j (B_j x(tau) - o_j)),
signed so that q_j <= 0 until the stop changes state. A root is never stepped over: from
tau_a the march takes the largest h with

    q_j(tau_a) + q_j'(tau_a) h + 1/2 Q2 h^2 < 0,   Q2 = sum_i |c_i| |lambda_i|^2 e^{Re(lambda_i) tau_a}

(Q2 bounds |q''| for every tau >= tau_a, as Re(lambda) <= 0), which is a safe step for
any velocity. Approaching a crossing, h tends to the Newton step, so the event is located
to round-off; a grazing touch (q' -> 0 at q -> 0) is passed by the floor ``hmin``
without a state change. The dissipated work int v^T C v dt is integrated in closed form
(products of exponentials), so the energy balance E(0) = E(t) + W(t) holds to round-off.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.linalg import eig, eigh, solve

from reduced.models.gaps import GapSystem
from reduced.transient.result import RingdownResult, sample_times

EPS = np.finfo(float).eps
QTOL_REL = 64.0 * EPS  # q is a sum of ~2n terms: round-off of its evaluation, relative
HMIN_PERIODS = 1e-9  # the march's smallest step, in units of 1/omega_max (grazing floor)
MAX_MARCH_ITER = 10_000_000  # per stop per segment: a hang guard, never reached in practice
MAX_COND = 1e10  # refuse nearly defective (critically damped) states
NOISE_FACTOR = 4.0  # margin on the propagated round-off bound of q and q'
REST_FLOOR = 1e-15  # motion this small relative to the initial one is round-off at rest


class ExactIntegratorError(RuntimeError):
    """The exact integrator cannot treat this system or run (the message says why)."""


@dataclass(frozen=True, eq=False)
class StateTable:
    """Closed-form data of every contact state, indexed by sum_j active_j 2^j."""

    lam: np.ndarray  # (S, 2n) complex, eigenvalues
    V: np.ndarray  # (S, 2n, 2n) complex, eigenvectors
    Vinv: np.ndarray  # (S, 2n, 2n) complex
    yp: np.ndarray  # (S, 2n), equilibrium [K_s^-1 F_s; 0]
    valid: np.ndarray  # (S,) bool, feasible states
    cond: np.ndarray  # (S,) condition number of V: the closed form loses cond eps |y|


def _decompose(system: GapSystem, Ks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = system.n
    if system.undamped:
        w2, phi = eigh(Ks, system.M)
        if w2[0] <= 1e-12 * w2[-1]:
            raise ExactIntegratorError(
                "a contact state has a zero-frequency mode (stiffness singular); "
                "the exact method needs every state to oscillate: use method 'explicit'"
            )
        w = np.sqrt(w2)
        V = np.block([[phi, phi], [1j * w * phi, -1j * w * phi]]).astype(complex)
        PM = phi.T @ system.M
        Vinv = 0.5 * np.block([[PM, PM / (1j * w)[:, None]], [PM, -PM / (1j * w)[:, None]]])
        lam = np.concatenate([1j * w, -1j * w])
        return lam, V, Vinv
    Minv = np.linalg.inv(system.M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ Ks, -Minv @ system.C]])
    lam, V = eig(A)
    cond = np.linalg.cond(V)
    if not np.isfinite(cond) or cond > MAX_COND:
        raise ExactIntegratorError(
            f"a contact state is nearly defective (eigenvector condition {cond:.1e}, e.g. a "
            "critically damped mode); use method 'explicit' or 'dop853'"
        )
    if np.max(lam.real) > 1e-9 * np.max(np.abs(lam)):
        raise ExactIntegratorError("a contact state is unstable (Re lambda > 0): check K and C")
    return lam, V, np.linalg.inv(V)


def state_table(system: GapSystem) -> StateTable:
    """Decompose every feasible contact state; mirrored states share one decomposition."""
    n, m = system.n, system.m
    S = 2**m
    lam = np.zeros((S, 2 * n), complex)
    V = np.zeros((S, 2 * n, 2 * n), complex)
    Vinv = np.zeros((S, 2 * n, 2 * n), complex)
    yp = np.zeros((S, 2 * n))
    valid = np.zeros(S, bool)
    cache: dict[bytes, tuple] = {}
    cond = np.ones(S)
    for active in system.feasible_states():
        s = int(np.sum(active * (1 << np.arange(m))))
        Ks, Fs = system.state_matrices(active)
        key = Ks.tobytes()
        if key not in cache:
            lam_k, V_k, Vinv_k = _decompose(system, Ks)
            cache[key] = (lam_k, V_k, Vinv_k, float(np.linalg.cond(V_k)))
        lam[s], V[s], Vinv[s], cond[s] = cache[key]
        yp[s, :n] = solve(Ks, Fs, assume_a="sym") if np.any(Fs) else 0.0
        valid[s] = True
    return StateTable(lam, V, Vinv, yp, valid, cond)


@nb.njit(cache=True)
def _phi1(z, tau):
    """int_0^tau exp(z t) dt for complex z, accurate near z = 0."""
    zt = z * tau
    if abs(zt) < 1e-3:
        return tau * (1.0 + zt / 2.0 + zt * zt / 6.0 + zt * zt * zt / 24.0)
    return (np.exp(zt) - 1.0) / z


@nb.njit(cache=True)
def _work(G, lam, tau):
    """int_0^tau v^T C v dt given G[i, k] = a_i^T C a_k (v = sum_i a_i e^{lam_i t})."""
    N = lam.shape[0]
    acc = 0.0 + 0.0j
    for i in range(N):
        for k in range(N):
            if G[i, k] != 0.0:
                acc += G[i, k] * _phi1(lam[i] + lam[k], tau)
    return acc.real


@nb.njit(cache=True)
def _first_root(const, coef, lam, tau_limit, hmin, qnoise, dnoise, floor):
    """First tau in [0, tau_limit) where q = const + Re sum coef e^{lam tau} turns positive.

    q is known to QTOL_REL x the size of its terms plus ``qnoise``, the round-off carried
    in from the modal coordinates w (q' likewise, with ``dnoise``); within that band a
    stop is at its threshold. Returns (tau, n_iter); tau = inf when there is none
    before tau_limit. A motion smaller than ``floor`` is round-off about a state that
    rests on a stop's threshold (zero gap, heavy damping): it triggers no event.
    """
    N = lam.shape[0]
    osc = 0.0
    for i in range(N):
        osc += abs(coef[i])
    if osc < floor and abs(const) < floor:
        return np.inf, 0
    qtol = QTOL_REL * (abs(const) + osc) + NOISE_FACTOR * qnoise
    tau = 0.0
    for it in range(MAX_MARCH_ITER):
        q = const
        d = 0.0
        dscale = 0.0
        Q2 = 0.0
        for i in range(N):
            e = coef[i] * np.exp(lam[i] * tau)
            q += e.real
            d += (lam[i] * e).real
            dscale += abs(e) * abs(lam[i])
            Q2 += abs(e) * abs(lam[i]) ** 2
        if q > -qtol:
            dtol = QTOL_REL * dscale + NOISE_FACTOR * dnoise
            if q > qtol and d >= -dtol:
                return tau, it
            # At the threshold a crossing needs q' > 0 beyond its round-off; otherwise it is a
            # tangential graze. A q just past the threshold but falling back (q' < 0) is the
            # round-off of re-expanding the state right after a switch, not a crossing:
            # deciding either by noise would flip the state back and forth forever.
            if d > dtol:
                return tau + max(-q, 0.0) / d, it
        qn = -min(q, 0.0)
        disc = np.sqrt(d * d + 2.0 * Q2 * qn)
        if d > 0.0:
            h = 2.0 * qn / (d + disc)
        elif Q2 > 0.0:
            h = (disc - d) / Q2
        else:
            return np.inf, it
        tau += max(h, hmin)
        if tau >= tau_limit:
            return np.inf, it
    return -1.0, MAX_MARCH_ITER


@nb.njit(cache=True)
def _state_index(active):
    """Index of a contact state in the tables: sum_j active_j 2^j."""
    s = 0
    for j in range(active.shape[0]):
        if active[j]:
            s += 1 << j
    return s


@nb.njit(cache=True)
def _stop_series(B, j, sgn, offset_j, yp_s, X, coef):
    """q_j(tau) = const + Re sum_i coef_i e^{lam_i tau}: fills coef, returns const."""
    n = B.shape[1]
    const = 0.0
    for r in range(n):
        const += B[j, r] * yp_s[r]
    for i in range(X.shape[1]):
        acc = 0.0 + 0.0j
        for r in range(n):
            acc += B[j, r] * X[r, i]
        coef[i] = sgn * acc
    return sgn * (const - offset_j)


@nb.njit(cache=True)
def _eval_state(yp, X, lam, tau, out):
    N = lam.shape[0]
    for r in range(N):
        acc = 0.0
        for i in range(N):
            acc += (X[r, i] * np.exp(lam[i] * tau)).real
        out[r] = yp[r] + acc


@nb.njit(cache=True)
def _exact_kernel(lam, V, Vinv, yp, valid, B, offset, side, tip, C, damped,
                  y, active, t, t_end, t_samples, i_samp, out_y, out_W, W, hmin, floor, max_events):
    """March events from t to t_end; fills samples from index i_samp. Returns the new state."""
    n = B.shape[1]
    m = B.shape[0]
    N = 2 * n
    ns = t_samples.shape[0]
    X = np.empty((N, N), np.complex128)
    G = np.zeros((N, N), np.complex128)
    coef = np.empty(N, np.complex128)
    werr = np.empty(N)
    ytmp = np.empty(N)
    n_events = 0
    n_iter = 0
    status = 0
    n_stuck = 0  # consecutive events with no progress in time
    while True:
        s = _state_index(active)
        if not valid[s]:
            status = -2
            break
        lam_s = lam[s]
        # w = Vinv (y - yp);  X[:, i] = V[:, i] w_i;  werr bounds the round-off in w
        for i in range(N):
            wi = 0.0 + 0.0j
            err = 0.0
            for r in range(N):
                wi += Vinv[s, i, r] * (y[r] - yp[s, r])
                err += abs(Vinv[s, i, r]) * (abs(y[r]) + abs(yp[s, r]))
            werr[i] = EPS * err
            for r in range(N):
                X[r, i] = V[s, r, i] * wi
        if damped:
            for i in range(N):
                for k in range(N):
                    acc = 0.0 + 0.0j
                    for a in range(n):
                        for b in range(n):
                            if C[a, b] != 0.0:
                                acc += X[n + a, i] * C[a, b] * X[n + b, k]
                    G[i, k] = acc
        tau_ev = t_end - t
        j_ev = -1
        for j in range(m):
            sgn = -side[j] if active[j] else side[j]
            const = _stop_series(B, j, sgn, offset[j], yp[s], X, coef)
            qnoise = 0.0
            dnoise = 0.0
            for i in range(N):
                pv = 0.0 + 0.0j
                for r in range(n):
                    pv += B[j, r] * V[s, r, i]
                qnoise += abs(pv) * werr[i]
                dnoise += abs(pv) * abs(lam_s[i]) * werr[i]
            tj, it = _first_root(const, coef, lam_s, tau_ev, hmin, qnoise, dnoise, floor)
            n_iter += it
            if tj < 0.0:
                status = -3
                break
            if tj < tau_ev:
                tau_ev = tj
                j_ev = j
        if status != 0:
            break
        t_next = t_end if j_ev < 0 else t + tau_ev
        while i_samp < ns and t_samples[i_samp] <= t_next:
            tau = max(t_samples[i_samp] - t, 0.0)
            _eval_state(yp[s], X, lam_s, tau, ytmp)
            for r in range(N):
                out_y[i_samp, r] = ytmp[r]
            out_W[i_samp] = W + (_work(G, lam_s, tau) if damped else 0.0)
            i_samp += 1
        _eval_state(yp[s], X, lam_s, tau_ev, ytmp)
        for r in range(N):
            y[r] = ytmp[r]
        if damped:
            W += _work(G, lam_s, tau_ev)
        n_stuck = n_stuck + 1 if tau_ev == 0.0 else 0
        if n_stuck > 8 * m:
            status = -4
            break
        t = t_next
        if j_ev < 0:
            break
        if active[j_ev]:
            active[j_ev] = False
        else:
            # closing a stop opens its tip's other stop: at zero gap both cross together
            for j in range(m):
                if tip[j] == tip[j_ev]:
                    active[j] = False
            active[j_ev] = True
        n_events += 1
        if n_events >= max_events:
            status = -1
            break
    return t, W, i_samp, n_events, n_iter, status


def integrate_exact(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    chunks: int = 50,
    max_events: int = 50_000_000,
    progress=None,
) -> RingdownResult:
    """Exact (event-driven, closed-form) free response of ``system`` from (x0, v0).

    Parameters
    ----------
    system : the gap system (every contact state must be a stable oscillator)
    x0, v0 : (n,) initial displacement [m] and velocity [m/s]
    duration_s : s, length of the run
    sample_rate_hz : Hz, output sampling (the solution itself is exact between samples)
    chunks : the run is split into this many pieces to drive ``progress`` (a callable
        taking the fraction done)
    """
    t_wall = time.perf_counter()
    n = system.n
    original, system = system, system.fold_zero_gap_tips()
    table = state_table(system)
    omega_max = system.omega_max()
    hmin = HMIN_PERIODS / omega_max
    y = np.concatenate([np.asarray(x0, float), np.asarray(v0, float)])
    active = system.penetration(y[:n]) > 0.0
    # motion below REST_FLOOR of the initial one (in m) is round-off: see _first_root
    x_scale = np.abs(system.B) @ (np.abs(y[:n]) + np.abs(y[n:]) / omega_max)
    floor = REST_FLOOR * float(np.max(x_scale, initial=0.0))
    ts = sample_times(duration_s, sample_rate_hz)
    out_y = np.empty((ts.size, 2 * n))
    out_W = np.empty(ts.size)
    t, W, i_samp, n_events, n_iter = 0.0, 0.0, 0, 0, 0
    bounds = np.linspace(0.0, max(duration_s, ts[-1]), chunks + 1)
    for c in range(chunks):
        t, W, i_samp, ne, ni, status = _exact_kernel(
            table.lam, table.V, table.Vinv, table.yp, table.valid, system.B, system.offset,
            system.side, system.tip, system.C, not system.undamped, y, active, t, bounds[c + 1], ts,
            i_samp, out_y, out_W, W, hmin, floor, max_events - n_events,
        )
        n_events += ne
        n_iter += ni
        if status == -1:
            raise ExactIntegratorError(
                f"more than {max_events} contact events before t = {t:.6g} s: chattering at "
                "a stop; raise max_events or damp the contact"
            )
        if status == -2:
            raise ExactIntegratorError("the motion reached an infeasible contact state")
        if status == -4:
            raise ExactIntegratorError(
                f"contact state flips back and forth at t = {t:.6g} s without progress (round-off "
                "at a stop exceeds the event tolerance); use method 'explicit'"
            )
        if status == -3:
            raise ExactIntegratorError(f"event search did not converge near t = {t:.6g} s")
        if progress is not None:
            progress((c + 1) / chunks)
    if i_samp != ts.size:  # the last sample sits on t_end up to round-off
        raise ExactIntegratorError(f"internal: {ts.size - i_samp} samples not filled")
    if not np.all(np.isfinite(out_y)):
        raise ExactIntegratorError("non-finite state: the contact states are ill-conditioned")
    x, v = out_y[:, :n], out_y[:, n:]
    amp = float(np.max(np.abs(x))) if x.size else 0.0
    return RingdownResult(
        system=original,
        t=ts,
        x=x,
        v=v,
        dissipated=out_W,
        method="exact",
        # evaluating V diag(e^{lam t}) V^-1 y loses cond(V) eps |y| at each event
        tolerance=float(np.max(table.cond)) * EPS * max(amp, float(np.max(np.abs(system.offset), initial=0.0))),
        stats={
            "n_events": n_events,
            "n_steps": n_events + 1,
            "n_march": n_iter,
            "n_states": int(table.valid.sum()),
            "cond_V": float(np.max(table.cond)),
            "wall_s": time.perf_counter() - t_wall,
        },
    )
