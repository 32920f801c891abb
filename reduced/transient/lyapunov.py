"""Lyapunov exponents of a harmonically forced gap system by its exact flow and tangent.

The forced system M x'' + C x' + K x + B^T f(B x) = b P cos(2 pi f t) is sampled once per forcing
period T = 1/f: the *period map* y_{k+1} = F(y_k), y = [x; v], is the exact forced flow over one
period (:mod:`reduced.transient.flow`: closed-form segments between stop crossings, the load's
particular solution in each), and its derivative dF/dy is the product of the segment exponentials.

**The saltation matrix is the identity** (Mueller 1995, Leine & Nijmeijer 2004). Let a stop be the
surface h(y) = n^T y - c = 0 (n^T y = side_j B_j x, c = side_j o_j) and let the flow reach it at time
t_c with vector fields f_- before and f_+ after. A perturbation dy of the state just before the
crossing moves the crossing time by dt_c = -n^T dy / (n^T f_-) (first order, transversal crossing
n^T f_- != 0); during dt_c the perturbed motion is already (or still) in the other state, so just
after the crossing the perturbation is dy + (f_- - f_+) dt_c:

    dy_+ = S dy_-,   S = I + (f_+ - f_-) n^T / (n^T f_-).

Here f_+/- = [v; M^-1 (F(t) - C v - K x - B^T f_+/-(B x))] differ only in the stop's force, which
is k_j (s_j - o_j) on the closed side and 0 on the open side: both vanish on the surface s_j = o_j.
So f_+ = f_- at the crossing, S = I whatever n^T f_- is, and the derivative of the flow is the plain
product of the segment exponentials exp(A_s tau) (the particular solution of the load does not
depend on y(0)). The same continuity keeps the volume: det S = n^T f_+ / n^T f_- = 1, so the
exponents sum to the trace of the (state-independent) damping part, sum_i lambda_i = -tr(M^-1 C)
(Liouville), which the tests check. (An impact law, with a velocity jump, or a force step
would give S != I; a penalty stop does not.) :func:`crossing_saltation` evaluates S at a crossing
from the formula; it is I to round-off.

**Exponents** (Benettin et al. 1980, Wolf et al. 1985): q tangent vectors W (2n, q) are carried
through each period, W <- dF/dy W, then re-orthonormalised by QR, W = Q R; the exponents are the
time averages of log |R_ii|,

    lambda_i = 1 / (K T) sum_{k<K} log |R_ii^(k)|   (1/s),

with one vector (q = 1) the largest, by the growth of its norm. A periodic attractor has
lambda_1 = log max |mu| / T (mu its Floquet multipliers), a quasi-periodic one lambda_1 = 0, a
chaotic one lambda_1 > 0; a linear damped system lambda_1 = -(its slowest decay rate).
:func:`lyapunov_two_runs` is the independent check (Benettin's original method): the growth of
the distance between two exact runs started 1e-8 apart, renormalised each period, with no
tangent at all.

The march of each period (:func:`_march_period`) is the forced flow's (the exact integrator's
segment set-up and root search, :mod:`reduced.transient._exact_kernels`), run by one numba kernel
over many periods (:func:`_periods_kernel`), which also records the state at every period start
(the Poincare samples), the largest |r . x| of each period over uniform samples and points inside
each contact segment, and the tangent.

References: R. Mueller, "Calculation of Lyapunov exponents for dynamic systems with
discontinuities", Chaos, Solitons & Fractals 5 (1995) 1671-1681; R. I. Leine, H. Nijmeijer,
*Dynamics and Bifurcations of Non-Smooth Mechanical Systems* (Springer, 2004), ch. 3;
G. Benettin, L. Galgani, A. Giorgilli, J.-M. Strelcyn, Meccanica 15 (1980) 9-20;
A. Wolf, J. B. Swift, H. L. Swinney, J. A. Vastano, Physica D 16 (1985) 285-317.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba as nb
import numpy as np

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient._exact_kernels import (
    _add_poly,
    _eval_state,
    _exponentials,
    _next_crossing,
    _segment_arrays,
    _start_segment,
)
from reduced.transient._modal import _state_of, _terms
from reduced.transient.exact_tables import ExactIntegratorError, StateTable, forced_arrays, modal_table, state_table
from reduced.transient.flow import MAX_SEGMENTS, Flow, _against_its_rate, _check_status, _settle

REPLAY_SEGMENTS = 32  # segments a period recorded by a run that defers its samples (more: it is marched again)
TWO_RUN_SEPARATION = 1e-8  # relative start distance of the two-run method: far above round-off, far below the attractor


# -- numba kernels ------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _peak_rows(R, y, peak, row_out):
    """peak[r] = max(peak[r], |R[r] . x|); row_out <- R x (x = y[:n])."""
    n = R.shape[1]
    for r in range(R.shape[0]):
        acc = 0.0
        for c in range(n):
            acc += R[r, c] * y[c]
        row_out[r] = acc
        if abs(acc) > peak[r]:
            peak[r] = abs(acc)


@nb.njit(cache=True)
def _eval_x(yp, X, e, out, n):
    """x = the first n rows of y = y_p + Re sum_i X[:, i] e_i (:func:`reduced.transient._exact_kernels._eval_with`
    row by row: the same numbers; the peaks read x only)."""
    K = e.shape[0]
    for r in range(n):
        acc = 0.0
        for i in range(K):
            acc += (X[r, i] * e[i]).real
        out[r] = yp[r] + acc


@nb.njit(cache=True)
def _segment_samples(yp_s, X, z, P, poly, t, t_next, tau_ev, closed, R, n_uniform, n_inner, h, i_u, peak, row,
                     samples, record, e, yq, n):
    """The peaks inside one segment of :func:`_march_period` (set up at t, ending at t_next after tau_ev):
    ``peak`` <- max |R x| at the uniform times i_u h < t_next (each written to ``samples`` when ``record``)
    and, when a stop is ``closed``, at ``n_inner`` evenly spaced points inside it. Returns the next i_u.
    The march and its replay (:func:`_replay_kernel`) both sample here: the same numbers."""
    p = R.shape[0]
    while i_u < n_uniform and i_u * h < t_next:  # the uniform samples in this segment
        tau_u = max(i_u * h - t, 0.0)
        _exponentials(z, tau_u, e)
        _eval_x(yp_s, X, e, yq, n)
        if poly:
            _add_poly(P, tau_u, n, yq)
        _peak_rows(R, yq, peak, row)
        if record:
            for r in range(p):
                samples[i_u, r] = row[r]
        i_u += 1
    if closed:
        for i in range(n_inner):  # inside a contact segment: its peak is short and sharp
            tau_i = tau_ev * (i + 1) / (n_inner + 1)
            _exponentials(z, tau_i, e)
            _eval_x(yp_s, X, e, yq, n)
            if poly:
                _add_poly(P, tau_i, n, yq)
            _peak_rows(R, yq, peak, row)
    return i_u


@nb.njit(cache=True)
def _march_period(lam, V, Vinv, yp, valid, B, offset, side, y, active, T, hmin, seg_state, seg_tau, fz, fY, fU, fb,
                  pstarts, pF, pp0, pp1, R, n_uniform, n_inner, peak, samples, rec_i, rec_f, rec_y, rec_n):
    """March the forced flow over one period [0, T] (the march of :func:`reduced.transient.flow._flow_kernel`);
    y and active are updated in place. Returns (n_seg, status).

    On the way: ``peak`` (p,) <- max |R x| over the states at every segment end, at ``n_uniform``
    uniform times j T / n_uniform (written to ``samples`` (n_uniform, p) when it has that many rows)
    and at ``n_inner`` evenly spaced points inside each segment with a stop closed
    (:func:`_segment_samples`). With a record (rec_i (cap, 2) int: state, a stop closed; rec_f (cap, 3):
    t, tau, t_next; rec_y (cap, 2n): the state at its start; rec_n[0] segments recorded, -1 once cap is
    exceeded) each segment is recorded for :func:`_replay_kernel` (cap 0: none)."""
    n = B.shape[1]
    N = 2 * n
    p = R.shape[0]
    X, z, coef, werr, ytmp, ypart, P, Qp, Fs, phi, gam = _segment_arrays(n, fb.shape[0])
    yq = np.empty(N)
    row = np.empty(p)
    e = np.empty(z.shape[0], np.complex128)
    record = samples.shape[0] == n_uniform
    h = T / n_uniform if n_uniform > 0 else T
    i_u = 0
    ip = 0
    t = 0.0
    n_seg = 0
    n_zero = 0
    max_seg = seg_state.shape[0]
    _peak_rows(R, y, peak, row)
    while True:
        s = _state_of(active)
        if not valid[s]:
            return n_seg, -2
        ip, t_lim, poly = _start_segment(s, t, T, ip, pstarts, y, yp[s], lam[s], V[s], Vinv[s], fz, fY, fU, pF, pp0,
                                         pp1, n, X, z, P, Fs, phi, gam, werr, ypart, False)
        tau_ev, j_ev, _, status = _next_crossing(B, offset, side, active, yp[s], V[s], X, z, werr, poly, P, Qp, coef,
                                                 t_lim - t, hmin, 0.0, False)
        if status != 0:
            return n_seg, -3
        _eval_state(yp[s], X, z, tau_ev, ytmp)
        if poly:
            _add_poly(P, tau_ev, N, ytmp)
        if j_ev >= 0 and _against_its_rate(B, side, active, j_ev, ytmp):
            tau_ev = min(tau_ev + hmin, t_lim - t)  # a round-off root next to a crossing just made (the flow's rule)
            _eval_state(yp[s], X, z, tau_ev, ytmp)
            if poly:
                _add_poly(P, tau_ev, N, ytmp)
            j_ev = -2
        t_next = t_lim if j_ev == -1 else t + tau_ev
        closed = False
        for j in range(active.shape[0]):
            closed = closed or active[j]
        i_u = _segment_samples(yp[s], X, z, P, poly, t, t_next, tau_ev, closed, R, n_uniform, n_inner, h, i_u, peak,
                               row, samples, record, e, yq, n)
        if rec_i.shape[0] > 0 and rec_n[0] >= 0:
            g = rec_n[0]
            if g < rec_i.shape[0]:
                rec_i[g, 0] = s
                rec_i[g, 1] = 1 if closed else 0
                rec_f[g, 0] = t
                rec_f[g, 1] = tau_ev
                rec_f[g, 2] = t_next
                for r in range(N):
                    rec_y[g, r] = y[r]
                rec_n[0] = g + 1
            else:
                rec_n[0] = -1  # more segments than the record holds: replayed by marching again
        for r in range(N):
            y[r] = ytmp[r]
        _peak_rows(R, y, peak, row)
        if n_seg >= max_seg:
            return n_seg, -1
        seg_state[n_seg] = s
        seg_tau[n_seg] = tau_ev
        n_seg += 1
        t = t_next
        if j_ev == -2:
            if t >= T:
                break
            continue
        if j_ev < 0:
            if t_lim < T:
                continue  # a load breakpoint: the same contact state, a new piece
            break
        active[j_ev] = not active[j_ev]
        n_zero = n_zero + 1 if tau_ev == 0.0 else 0
        if n_zero > 64:
            return n_seg, -1
        _settle(B, offset, side, active, y, j_ev, n_zero > 4)
    return n_seg, 0


@nb.njit(cache=True)
def _tangent(tb, seg_s, seg_tau, n_seg, W):
    """W <- exp(A_{s_k} tau_k) ... exp(A_{s_1} tau_1) W over the recorded segments, in place, W (2n, q):
    :func:`reduced.transient._modal.flow_jacobian` for q columns (the kept-term form of each exponential)."""
    nK, lam, UT, Uinv = tb[0], tb[1], tb[3], tb[4]
    N = W.shape[0]
    q = W.shape[1]
    Kmax = lam.shape[1]
    Z = np.empty((Kmax, q), np.complex128)
    e = np.empty(Kmax, np.complex128)
    ea = np.empty(Kmax)
    for k in range(n_seg):
        s = seg_s[k]
        K = nK[s]
        _terms(lam[s], K, seg_tau[k], e, ea)
        for i in range(K):
            for c in range(q):
                acc = 0.0 + 0.0j
                for r in range(N):
                    acc += Uinv[s, i, r] * W[r, c]
                Z[i, c] = acc * e[i]
        for r in range(N):
            for c in range(q):
                acc = 0.0
                for i in range(K):
                    acc += UT[s, 0, i, r] * Z[i, c].real - UT[s, 1, i, r] * Z[i, c].imag
                W[r, c] = acc


@nb.njit(cache=True)
def _periods_kernel(lam, V, Vinv, yp, valid, B, offset, side, y, active, T, hmin, seg_state, seg_tau, fz, fY, fU, fb,
                    pstarts, pF, pp0, pp1, tb, R, n_uniform, n_inner, n_periods, W, renorm, D, Dinv, out_y,
                    out_peak, out_samples, out_log, rec_i, rec_f, rec_y, rec_n, rec_start):
    """``n_periods`` periods of the forced flow from y (updated in place, with active): out_y[k + 1] the state
    after period k, out_peak[k] its largest |R x|, out_samples[k] its uniform samples (when out_samples has
    n_periods rows), and the tangent W carried through each period (q = W.shape[1] columns, none if 0),
    re-orthonormalised by QR when ``renorm`` with out_log[k, i] = log |R_ii| (the QR of D W: lengths in
    the norm |D w|, D = ``D``, its inverse ``Dinv``); with a record (:func:`_march_period`) rec_start[k] its
    first segment of period k (rec_start[n_periods] the end). Returns (periods done, segments, status)."""
    q = W.shape[1]
    N = W.shape[0]
    record = out_samples.shape[0] == n_periods
    n_seg_total = 0
    for k in range(n_periods):
        for r in range(out_peak.shape[1]):
            out_peak[k, r] = 0.0
        smp = out_samples[k] if record else out_samples[0]
        if rec_start.shape[0] > 0:
            rec_start[k] = rec_n[0]
        n_seg, status = _march_period(lam, V, Vinv, yp, valid, B, offset, side, y, active, T, hmin, seg_state, seg_tau,
                                      fz, fY, fU, fb, pstarts, pF, pp0, pp1, R, n_uniform, n_inner, out_peak[k], smp,
                                      rec_i, rec_f, rec_y, rec_n)
        if rec_start.shape[0] > 0:
            rec_start[k + 1] = rec_n[0]
        if status != 0:
            return k, n_seg_total, status
        n_seg_total += n_seg
        for r in range(N):
            out_y[k + 1, r] = y[r]
        if q == 0:
            continue
        _tangent(tb, seg_state, seg_tau, n_seg, W)
        if not renorm:
            continue
        Ws = D @ W  # in the energy norm (PeriodMap.norm_matrix)
        if q == 1:
            nrm = 0.0
            for r in range(N):
                nrm += Ws[r, 0] * Ws[r, 0]
            nrm = math.sqrt(nrm)
            out_log[k, 0] = math.log(nrm)
            for r in range(N):
                W[r, 0] /= nrm
        else:
            Q, Rm = np.linalg.qr(Ws)
            for i in range(q):
                d = Rm[i, i]
                out_log[k, i] = math.log(abs(d))
                if d < 0.0:
                    for r in range(N):
                        Q[r, i] = -Q[r, i]
            W[:, :] = Dinv @ np.ascontiguousarray(Q)
    return n_periods, n_seg_total, 0


@nb.njit(cache=True)
def _replay_kernel(lam, V, Vinv, yp, T, fz, fY, fU, fb, pstarts, pF, pp0, pp1, R, n_uniform, n_inner, out_y, rec_i,
                   rec_f, rec_y, rec_start, out_peak, out_samples):
    """The peaks and samples of a run recorded by :func:`_periods_kernel` (whose march sampled none), from its
    record: each segment set up again from its recorded start (:func:`_start_segment`, the same closed form)
    and sampled by :func:`_segment_samples` as the march samples, its end state evaluated at its recorded tau;
    out_peak[k] and out_samples[k] (when it has a row per period) as a sampling march writes them, without
    searching a crossing again."""
    n = V.shape[1] // 2
    N = 2 * n
    p = R.shape[0]
    X, z, coef, werr, ytmp, ypart, P, Qp, Fs, phi, gam = _segment_arrays(n, fb.shape[0])
    yq = np.empty(N)
    row = np.empty(p)
    e = np.empty(z.shape[0], np.complex128)
    K = out_peak.shape[0]
    record = out_samples.shape[0] == K and out_samples.shape[1] == n_uniform
    h = T / n_uniform if n_uniform > 0 else T
    for k in range(K):
        peak = out_peak[k]
        for r in range(p):
            peak[r] = 0.0
        smp = out_samples[k] if record else out_samples[0]
        _peak_rows(R, out_y[k], peak, row)
        ip = 0
        i_u = 0
        for g in range(rec_start[k], rec_start[k + 1]):
            s = rec_i[g, 0]
            t = rec_f[g, 0]
            tau_ev = rec_f[g, 1]
            ip, t_lim, poly = _start_segment(s, t, T, ip, pstarts, rec_y[g], yp[s], lam[s], V[s], Vinv[s], fz, fY, fU,
                                             pF, pp0, pp1, n, X, z, P, Fs, phi, gam, werr, ypart, False)
            i_u = _segment_samples(yp[s], X, z, P, poly, t, rec_f[g, 2], tau_ev, rec_i[g, 1] != 0, R, n_uniform,
                                   n_inner, h, i_u, peak, row, smp, record, e, yq, n)
            _exponentials(z, tau_ev, e)  # the end state (its x: the peak reads no more)
            _eval_x(yp[s], X, e, ytmp, n)
            if poly:
                _add_poly(P, tau_ev, n, ytmp)
            _peak_rows(R, ytmp, peak, row)


# -- the period map --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PeriodRun:
    """Periods of the forced flow (:meth:`PeriodMap.run`).

    Attributes
    ----------
    poincare : (K + 1, 2n) ndarray of float
        [x; v] at the start of each period and at the end (m, m/s): the Poincare samples.
    peak : (K, p) ndarray of float
        m, largest |r . x| of each period for each monitored row r.
    samples : (K, S, p) ndarray of float or None
        m, r . x at S uniform times of each period (when asked).
    log_growth : (K, q) ndarray of float
        log |R_ii| of each period's QR of the tangent (renormalised runs), else empty.
    tangent : (2n, q) ndarray of float
        The tangent vectors at the end (orthonormal after a renormalised run, else the product
        dF^K/dy applied to the start's).
    active : (m,) ndarray of bool
        Contact state at the end.
    n_segments : int
        Closed-form segments marched (events + period ends).
    n_events : int
        Stop crossings (a period without one is one segment).
    deferred : tuple or None
        A run made with ``defer_samples`` (peak and samples None): its segments' record, from which
        :meth:`PeriodMap.sampled` gives them.
    """

    poincare: np.ndarray
    peak: np.ndarray | None
    samples: np.ndarray | None
    log_growth: np.ndarray
    tangent: np.ndarray
    active: np.ndarray
    n_segments: int
    n_events: int
    deferred: tuple | None = None

    @property
    def y(self) -> np.ndarray:
        """(2n,) the state at the end."""
        return self.poincare[-1]


def energy_norm_matrix(system: GapSystem, omega: float) -> np.ndarray:
    """D (2n, 2n) with |D dy|^2 = dx^T Kw dx + dv^T M dv: twice the energy of a perturbation of the open
    structure, Kw = K (or K + omega^2 M when K is singular: a free structure), D = blockdiag(L_K^T, L_M^T)
    with Kw = L_K L_K^T, M = L_M L_M^T.

    The exponents do not depend on the norm, but their finite-time estimates do: in this norm the
    modes of the open structure are orthogonal, so the growth of a tangent vector over a period does
    not oscillate with the phase of a lightly damped mode pair (in [x; v] with x in m and v in m/s it
    oscillates by a factor of the order of omega, i.e. log(omega) / t in the estimate).

    Parameters
    ----------
    system : the gap system
    omega : rad/s, the forcing frequency (used only when K is singular)

    Returns
    -------
    ndarray
        (2n, 2n) upper block-triangular.
    """
    n = system.n
    try:
        LK = np.linalg.cholesky(system.K)
    except np.linalg.LinAlgError:
        LK = np.linalg.cholesky(system.K + omega**2 * system.M)
    D = np.zeros((2 * n, 2 * n))
    D[:n, :n] = LK.T
    D[n:, n:] = np.linalg.cholesky(system.M).T
    return D


class PeriodMap:
    """The exact period map of a gap system under b P cos(2 pi f t): ``PeriodMap(system, b, P, f).run(y0, K)``.

    The load's pieces at t = 0 serve every period (the forcing is T-periodic, so the map is the same
    each period, without round-off growth of the absolute time). The state table and the modal
    table of the tangent depend only on the system: pass them to reuse them across frequencies.

    Parameters
    ----------
    system : GapSystem
        Damped or not; every contact state a stable oscillator (as for the exact integrator).
    load : (n,) array_like of float
        The force direction b.
    amplitude_N : float
        N, P > 0.
    freq_hz : float
        Hz, f > 0.
    rows : (p, n) array_like of float, optional
        Monitored rows r (the peaks and samples of r . x); default the DOFs.
    table : StateTable, optional
        The system's state table, if already decomposed.
    modal : tuple, optional
        Its modal table (:func:`reduced.transient.exact_tables.modal_table`), if already built.
    norm : tuple, optional
        (D, D^-1): :func:`energy_norm_matrix` at this frequency and its inverse, if already worked out
        (they do not depend on the frequency when K is positive definite: a sweep works them out once).

    Raises
    ------
    InvalidArgument
        An argument of the wrong kind or out of range.
    ExactIntegratorError
        A system or load the closed form cannot treat.
    """

    def __init__(self, system: GapSystem, load, amplitude_N: float, freq_hz: float, *, rows=None,
                 table: StateTable | None = None, modal: tuple | None = None, norm: tuple | None = None) -> None:
        _check.gap_system(system)
        b = _check.vector("load", load, system.n)
        P = _check.positive("amplitude_N", amplitude_N, "N")
        f = _check.positive("freq_hz", freq_hz, "Hz")
        self.system = system
        self.freq_hz = float(f)
        self.period_s = 1.0 / self.freq_hz
        self.loads = Loads(b[None, :], (Harmonic(P, self.freq_hz),))
        self.table = table if table is not None else state_table(system)
        self.flow = Flow(system, table=self.table, loads=self.loads)
        self.modal = modal if modal is not None else modal_table(system, self.table)
        self.rows = np.eye(system.n) if rows is None else np.ascontiguousarray(np.atleast_2d(np.asarray(rows, float)))
        if self.rows.shape[1] != system.n:
            raise _check.InvalidArgument(f"rows must have {system.n} columns, got shape {self.rows.shape}")
        self._fargs = forced_arrays(self.flow._forced, self.loads.pieces_at(np.array([0.0])))
        self._seg_state = np.empty(MAX_SEGMENTS, np.int64)
        self._seg_tau = np.empty(MAX_SEGMENTS)
        if norm is None:
            D = energy_norm_matrix(system, 2.0 * np.pi * self.freq_hz)
            norm = (D, np.linalg.inv(D))
        self.norm_matrix, self._norm_inv = norm

    @property
    def norm_inverse(self) -> np.ndarray:
        """(2n, 2n) D^-1, the inverse of :attr:`norm_matrix` (np.linalg.inv of it)."""
        return self._norm_inv

    def norm(self, dy: np.ndarray) -> float:
        """The energy norm |D dy| of a state difference (J^(1/2)): :func:`energy_norm_matrix`."""
        return float(np.linalg.norm(self.norm_matrix @ dy))

    def run(self, y0, n_periods: int, *, tangent=None, renormalise: bool = True, samples_per_period: int = 64,
            inner_samples: int = 8, record_samples: bool = False, active=None, defer_samples: bool = False
            ) -> PeriodRun:
        """``n_periods`` periods from y0 = [x0; v0] at a period start (phase 0 of the load).

        Parameters
        ----------
        y0 : (2n,) m and m/s
        n_periods : periods to run, >= 1
        tangent : (2n, q) tangent vectors to carry (None: none)
        renormalise : QR each period (Benettin) and record log |R_ii|; else the product dF^K/dy W
        samples_per_period : uniform samples of each period for the peaks (and ``record_samples``)
        inner_samples : samples inside each contact segment for the peaks
        record_samples : keep the uniform samples of r . x
        active : (m,) the contact state at y0 (default: from y0)
        defer_samples : march without sampling, recording each segment instead: the run's peak and samples
            are None until :meth:`sampled` gives them (the same numbers); a run whose peaks are not read then
            costs the march alone

        Returns
        -------
        PeriodRun

        Raises
        ------
        ExactIntegratorError
            The march failed (too many events, an infeasible state, an event search that did not end).
        """
        sy = self.system
        N = 2 * sy.n
        y = _check.vector("y0", y0, N).copy()
        K = _check.integer("n_periods", n_periods, lo=1)
        S = _check.integer("samples_per_period", samples_per_period, lo=0)
        inner = _check.integer("inner_samples", inner_samples, lo=0)
        act = self.flow.initial_state(y[: sy.n], y[sy.n :]) if active is None else np.array(active, bool)
        W = np.zeros((N, 0)) if tangent is None else np.array(tangent, float, order="C", ndmin=2)
        if W.shape[0] != N:
            raise _check.InvalidArgument(f"tangent must have {N} rows, got shape {W.shape}")
        p = self.rows.shape[0]
        out_y = np.empty((K + 1, N))
        out_y[0] = y
        out_peak = np.zeros((K, p))
        out_samples = np.zeros((K, S, p)) if record_samples and not defer_samples else np.zeros((1, 0, p))
        out_log = np.zeros((K, W.shape[1] if renormalise else 0))
        if defer_samples:
            cap = REPLAY_SEGMENTS * K
            rec = (np.empty((cap, 2), np.int64), np.empty((cap, 3)), np.empty((cap, N)), np.zeros(1, np.int64),
                   np.zeros(K + 1, np.int64))
            deferred = (rec, act.copy(), S, inner, bool(record_samples))
        else:
            rec = (np.empty((0, 2), np.int64), np.empty((0, 3)), np.empty((0, N)), np.zeros(1, np.int64),
                   np.zeros(0, np.int64))
            deferred = None
        tb = self.table
        done, n_seg, status = call_numba_kernel(
            _periods_kernel, tb.lam, tb.V, tb.Vinv, tb.yp, tb.valid, sy.B, sy.offset, sy.side, y, act,
            self.period_s, self.flow.hmin, self._seg_state, self._seg_tau, *self._fargs, self.modal, self.rows,
            0 if defer_samples else S, 0 if defer_samples else inner, K, W, bool(renormalise and W.shape[1] > 0),
            self.norm_matrix, self._norm_inv, out_y, out_peak, out_samples,
            out_log if renormalise else np.zeros((K, 0)), *rec)
        if status != 0:
            _check_status(status, MAX_SEGMENTS, self.period_s)
            raise ExactIntegratorError(f"the period map failed (status {status}) after {done} periods")
        if defer_samples:
            return PeriodRun(out_y, None, None, out_log, W, act, int(n_seg), int(n_seg) - K, deferred)
        return PeriodRun(out_y, out_peak, out_samples if record_samples else None, out_log, W, act, int(n_seg),
                         int(n_seg) - K)

    def sampled(self, run: PeriodRun) -> PeriodRun:
        """``run`` with its peaks (and samples, if it was to record them) when it was made with
        ``defer_samples``: the numbers :meth:`run` would have given sampling on its march, from the
        segments it recorded (:func:`_replay_kernel`; a run with more than REPLAY_SEGMENTS segments a
        period on average is marched again from its start). Any other run is returned as it is.

        Parameters
        ----------
        run : PeriodRun
            A run of this period map.

        Returns
        -------
        PeriodRun
        """
        if run.deferred is None:
            return run
        (rec_i, rec_f, rec_y, rec_n, rec_start), act0, S, inner, record = run.deferred
        K = run.poincare.shape[0] - 1
        if rec_n[0] < 0:  # the record overflowed: the same march again, sampling (no tangent: it moves no state)
            again = self.run(run.poincare[0], K, samples_per_period=S, inner_samples=inner, record_samples=record,
                             active=act0)
            return replace(run, peak=again.peak, samples=again.samples, deferred=None)
        p = self.rows.shape[0]
        out_peak = np.zeros((K, p))
        out_samples = np.zeros((K, S, p)) if record else np.zeros((1, 0, p))
        fz, fY, fU, fb, pstarts, pF, pp0, pp1 = self._fargs
        tb = self.table
        call_numba_kernel(_replay_kernel, tb.lam, tb.V, tb.Vinv, tb.yp, self.period_s, fz, fY, fU, fb, pstarts, pF,
                          pp0, pp1, self.rows, S, inner, run.poincare, rec_i, rec_f, rec_y, rec_start, out_peak,
                          out_samples)
        return replace(run, peak=out_peak, samples=out_samples if record else None, deferred=None)

    def jacobian(self, y0, n_periods: int = 1, active=None) -> PeriodRun:
        """The run of ``n_periods`` from y0 whose ``tangent`` is d y / d y0 of those periods (2n, 2n): the
        product of the segment exponentials (saltation = I, module docstring)."""
        N = 2 * self.system.n
        return self.run(y0, n_periods, tangent=np.eye(N), renormalise=False, samples_per_period=0, inner_samples=0,
                        active=active)


# -- exponents -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LyapunovResult:
    """Lyapunov exponents from a run of the period map.

    Attributes
    ----------
    exponents : (q,) ndarray of float
        1/s, by decreasing value.
    running : (K,) ndarray of float
        1/s, the estimate of the largest after each recorded period (its convergence).
    blocks : (4,) ndarray of float
        1/s, the largest from each quarter of the recorded periods (their spread: the estimate's error).
    period_s : float
        s, the forcing period T.
    n_periods : int
        Periods averaged over (after the transient).
    method : str
        ``tangent`` (QR of the tangent) or ``two_runs`` (distance of two exact runs).
    final_state : (2n,) ndarray of float
        Where the run ended.
    """

    exponents: np.ndarray
    running: np.ndarray
    blocks: np.ndarray
    period_s: float
    n_periods: int
    method: str
    final_state: np.ndarray

    @property
    def largest(self) -> float:
        """1/s, the largest exponent."""
        return float(self.exponents[0])

    @property
    def spread(self) -> float:
        """1/s, max - min of the quarter estimates: a measure of the finite-time error."""
        return float(np.max(self.blocks) - np.min(self.blocks))


def _blocks(logs: np.ndarray, T: float) -> np.ndarray:
    """The mean growth rate (1/s) of each quarter of the per-period logs (4 values; fewer periods: repeated)."""
    parts = np.array_split(logs, 4) if logs.size >= 4 else [logs] * 4
    return np.array([float(np.mean(p)) / T for p in parts])


def lyapunov_exponents(pm: PeriodMap, y0, n_periods: int, *, n_transient: int = 0, n_exponents: int = 1,
                       seed: int = 0) -> LyapunovResult:
    """The ``n_exponents`` largest Lyapunov exponents by the tangent of the exact flow (module docstring).

    lambda_i = 1 / (K T) sum_k log |R_ii^(k)| over K = ``n_periods`` periods after ``n_transient``
    periods that bring y0 onto its attractor and align the tangent vectors (seeded random start).

    Parameters
    ----------
    pm : PeriodMap
    y0 : (2n,) the start, at phase 0 of the load
    n_periods : periods averaged over, >= 1
    n_transient : periods run first, not averaged
    n_exponents : q, 1 <= q <= 2n
    seed : of the random tangent start

    Returns
    -------
    LyapunovResult
    """
    N = 2 * pm.system.n
    q = _check.integer("n_exponents", n_exponents, lo=1, hi=N)
    K = _check.integer("n_periods", n_periods, lo=1)
    n_transient = _check.integer("n_transient", n_transient, lo=0)
    # orthonormal in the energy norm: no normalisation growth in the first period's logs
    W = np.linalg.solve(pm.norm_matrix, np.linalg.qr(np.random.default_rng(seed).standard_normal((N, q)))[0])
    y = _check.vector("y0", y0, N)
    active = None
    if n_transient:
        r0 = pm.run(y, n_transient, tangent=W, samples_per_period=0, inner_samples=0)
        y, W, active = r0.y, r0.tangent, r0.active
    r = pm.run(y, K, tangent=W, samples_per_period=0, inner_samples=0, active=active)
    logs = r.log_growth
    T = pm.period_s
    running = np.cumsum(logs[:, 0]) / (T * np.arange(1, K + 1))
    return LyapunovResult(np.sort(logs.mean(axis=0) / T)[::-1], running, _blocks(logs[:, 0], T), T, K, "tangent",
                          r.y.copy())


def lyapunov_two_runs(pm: PeriodMap, y0, n_periods: int, *, n_transient: int = 0,
                      separation: float = TWO_RUN_SEPARATION, seed: int = 0) -> LyapunovResult:
    """The largest Lyapunov exponent from two exact runs, no tangent (Benettin et al. 1980).

    A second run starts at distance d0 = ``separation`` |y| (in a seeded random direction; distances
    in the energy norm, :func:`energy_norm_matrix`) from the first; after each period the distance
    d_k is measured and the second run is put back at d0 along the separation:
    lambda = 1 / (K T) sum_k log(d_k / d0). Both runs are the exact flow; the result agrees with
    :func:`lyapunov_exponents` to the finite-difference error of a separation d0 (relative ~d0 /
    (attractor size) for a smooth flow; larger where a run pair straddles a crossing within d0, the
    flow being C^1 but not C^2 there) and to the finite-time error of each (:attr:`LyapunovResult.spread`).

    Parameters
    ----------
    pm : PeriodMap
    y0 : (2n,) the start
    n_periods : periods averaged over
    n_transient : periods run first
    separation : d0 relative to the state's size
    seed : of the random direction

    Returns
    -------
    LyapunovResult
        method ``two_runs``, one exponent.
    """
    sy = pm.system
    N = 2 * sy.n
    K = _check.integer("n_periods", n_periods, lo=1)
    y = _check.vector("y0", y0, N)
    if n_transient:
        y = pm.run(y, n_transient, samples_per_period=0, inner_samples=0).y
    norm = pm.norm
    size = max(norm(y), 1e-300)
    d0 = separation * size
    u = np.linalg.solve(pm.norm_matrix, np.random.default_rng(seed).standard_normal(N))
    z = y + d0 * u / norm(u)
    logs = np.empty(K)
    for k in range(K):
        y = pm.run(y, 1, samples_per_period=0, inner_samples=0).y
        z = pm.run(z, 1, samples_per_period=0, inner_samples=0).y
        d = norm(z - y)
        logs[k] = math.log(d / d0)
        z = y + (z - y) * (d0 / d)
    T = pm.period_s
    running = np.cumsum(logs) / (T * np.arange(1, K + 1))
    return LyapunovResult(np.array([logs.mean() / T]), running, _blocks(logs, T), T, K, "two_runs", y.copy())


# -- the saltation matrix at a crossing ----------------------------------------------------------------------
def saltation_matrix(f_minus, f_plus, normal) -> np.ndarray:
    """S = I + (f_+ - f_-) n^T / (n^T f_-) (module docstring; Leine & Nijmeijer 2004, eq. 3.71).

    Parameters
    ----------
    f_minus, f_plus : (N,) the vector fields just before and after the switching surface
    normal : (N,) its normal n (h(y) = n^T y - c)

    Returns
    -------
    ndarray
        (N, N). The identity when f_+ = f_-.

    Examples
    --------
    >>> saltation_matrix([1.0, 2.0], [1.0, 2.0], [1.0, 0.0]).tolist()
    [[1.0, 0.0], [0.0, 1.0]]
    >>> saltation_matrix([1.0, 0.0], [1.0, -3.0], [1.0, 0.0]).tolist()
    [[1.0, 0.0], [-3.0, 1.0]]
    """
    fm = np.asarray(f_minus, float)
    fp = np.asarray(f_plus, float)
    n = np.asarray(normal, float)
    den = float(n @ fm)
    if den == 0.0:
        raise _check.InvalidArgument("the crossing is grazing (n^T f_- = 0): S is not defined by the formula")
    return np.eye(fm.size) + np.outer(fp - fm, n) / den


def crossing_saltation(system: GapSystem, y, stop: int, force_N: float | np.ndarray = 0.0) -> np.ndarray:
    """S at a crossing of stop ``stop`` at state y (on its surface), from the vector fields with the
    stop open and closed: the identity up to the round-off of k_j (s_j - o_j) (module docstring).

    Parameters
    ----------
    system : the gap system
    y : (2n,) the state at the crossing
    stop : the stop's index j
    force_N : (n,) or scalar, the external force there (it does not depend on the contact state)

    Returns
    -------
    ndarray
        (2n, 2n).
    """
    n = system.n
    y = _check.vector("y", y, 2 * n)
    x, v = y[:n], y[n:]
    pen = system.penetration(x)
    closed = pen > 0.0
    closed[stop] = False
    f_other = system.k * np.where(closed, x @ system.B.T - system.offset, 0.0) @ system.B
    s_j = system.B[stop] @ x - system.offset[stop]
    rhs = np.broadcast_to(np.asarray(force_N, float), (n,)) - system.C @ v - system.K @ x - f_other
    f_open = np.concatenate([v, np.linalg.solve(system.M, rhs)])
    f_closed = np.concatenate([v, np.linalg.solve(system.M, rhs - system.k[stop] * s_j * system.B[stop])])
    normal = np.concatenate([system.side[stop] * system.B[stop], np.zeros(n)])
    closing = normal @ f_open > 0.0
    return saltation_matrix(f_open, f_closed, normal) if closing else saltation_matrix(f_closed, f_open, normal)


__all__ = ["LyapunovResult", "PeriodMap", "PeriodRun", "crossing_saltation", "energy_norm_matrix", "lyapunov_exponents",
           "lyapunov_two_runs", "saltation_matrix"]
