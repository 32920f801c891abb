"""Central-difference ringdown (velocity form) with penalty stops.

With half-step velocities v_{n+1/2} the scheme is

    x_{n+1}     = x_n + dt v_{n+1/2}
    v_{n+3/2}   = (M + dt/2 C)^-1 [ (M - dt/2 C) v_{n+1/2} - dt (K x_{n+1} + B^T f(B x_{n+1})) ]

i.e. M (x_{n+1} - 2 x_n + x_{n-1}) / dt^2 + C (x_{n+1} - x_{n-1}) / (2 dt) + K x_n + f_n = 0:
second-order accurate, damping centred, and explicit because (M + dt/2 C)^-1 is a constant
matrix formed once (diagonal for the discrete model). It is started with
v_{1/2} = v_0 + dt/2 a_0 and reports v_n = (v_{n-1/2} + v_{n+1/2}) / 2.

External loads (``loads``) add dt (M + dt/2 C)^-1 f_ext(t_{n+1}) to the velocity update, i.e.
f_n -> f_n - f_ext(t_n) with f_ext(t) = sum_l b_l p_l(t) evaluated by the signals themselves
(right-continuous at a breakpoint: a jump in a load costs first order locally). Their work
W_ext = int v^T f_ext dt is integrated by the trapezoidal rule on v_n^T f_ext(t_n), like the
dissipated work. The stability rule is that of the free system (the loads do not depend on x).

Stability: this scheme (damping at the mean of the two half-step velocities, Newmark gamma =
1/2, beta = 0) is stable for omega_max dt < 2 whatever the damping (its recurrence
(1 + xi W) z^2 - (2 - W^2) z + (1 - xi W) = 0 has |z| < 1 for W < 2: tests/test_integrators.py).
The refusal uses the smaller bound dt < (2 / omega_max) (sqrt(1 + xi^2) - xi) of the variant with
the damping at the lagged velocity (Belytschko, Liu & Moran 2000, Sec. 6.2), xi the damping ratio
of the stiffest (closed) state's top mode: conservative here. Switching penalty contact has been seen to go
unstable near omega_max dt = 1.6 - 1.8, so a user step is refused beyond
``SWITCHING_SAFETY`` times that limit. The default step is chosen for accuracy, not
stability: omega_max dt = ``DEFAULT_OMEGA_DT``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.linalg import eigh

from reduced import _checks as _check
from reduced.cache import call_numba_kernel
from reduced.models.gaps import GapSystem
from reduced.transient import _cd, _cd_block, _cd_lumped, _cd_modal
from reduced.transient import stepper as _stepper
from reduced.transient.result import RingdownResult, RingdownStream

SWITCHING_SAFETY = 0.8  # of the textbook limit: CD with switching contact fails near 1.6
DEFAULT_OMEGA_DT = 0.05  # rad: 2.6e-2 relative error over the 0.05 s work-precision window
# and 0.3 % energy-balance error over the 2 s discrete-impulse ringdown (results/README.md)
TOP_CAP = 1.0  # rad, omega_max dt with step_basis "contact": the top mode still gets 6 steps a period
STEP_BASES = ("top", "contact")
MAX_STEPS = 2_000_000_000  # refuse runs that would take more steps than this
LOAD_BLOCK_STEPS = 1 << 16  # steps per kernel call of a forced run: the loads' values are tabulated per call
PIECES = 50  # progress is reported this many times a run
LUMPED = True  # lumped small models run reduced.transient._cd_lumped (False: the register kernel, for tests)


class StepTooLargeError(ValueError):
    """A user time step beyond the stability limit of central difference."""


def stability_limit(system: GapSystem) -> tuple[float, float]:
    """(omega_max [rad/s], dt_crit [s]) of the closed state, with damping in the top mode: the damped
    bound of the lagged-velocity variant, conservative for this scheme (module docstring).

    Parameters
    ----------
    system : GapSystem
        The system; its closed-gap stiffness and damping are used.

    Returns
    -------
    omega_max : float
        rad/s, top frequency of the closed state.
    dt_crit : float
        s, 2 / omega (sqrt(1 + xi^2) - xi), xi the damping ratio of the top mode (inf if omega = 0).

    Raises
    ------
    InvalidArgument
        Not a GapSystem.
    """
    _check.gap_system(system)
    lam, phi = eigh(system.closed_stiffness(), system.M)
    omega = math.sqrt(max(lam[-1], 0.0))
    top = phi[:, -1]
    xi = float(top @ system.C @ top) / (2.0 * omega) if omega > 0 else 0.0
    dt_crit = 2.0 / omega * (math.sqrt(1.0 + xi * xi) - xi) if omega > 0 else math.inf
    return omega, dt_crit


def default_step(system: GapSystem, omega_dt: float = DEFAULT_OMEGA_DT, step_basis: str = "top"
                 ) -> tuple[float, float, float, float]:
    """(dt, omega_max, omega_ref, dt_limit): the step :func:`integrate_explicit` takes unless given one,
    before it is rounded to the output interval (see its docstring for ``step_basis``).

    Parameters
    ----------
    system : GapSystem
        The system.
    omega_dt : float
        rad, the step as omega_ref dt, in (0, 2 SWITCHING_SAFETY].
    step_basis : {'top', 'contact'}
        omega_ref: omega_max, or :func:`contact_omega` capped at omega_max dt = ``TOP_CAP``.

    Returns
    -------
    dt : float
        s, min(omega_dt / omega_ref, dt_limit), and at most TOP_CAP / omega_max for 'contact'
        (inf if omega_max is 0).
    omega_max, omega_ref : float
        rad/s.
    dt_limit : float
        s, ``SWITCHING_SAFETY`` x the stability limit.

    Raises
    ------
    InvalidArgument
        Not a GapSystem, or an unknown basis.
    StepTooLargeError
        ``omega_dt`` out of range.
    """
    _check.gap_system(system)
    step_basis = _check.choice("step_basis", step_basis, STEP_BASES)
    omega_dt = _checked_omega_dt(omega_dt)
    omega, dt_crit = stability_limit(system)
    limit = SWITCHING_SAFETY * dt_crit
    if omega <= 0:
        return math.inf, omega, omega, limit
    if step_basis == "top":
        return min(omega_dt / omega, limit), omega, omega, limit
    omega_ref = contact_omega(system)
    return min(omega_dt / omega_ref, TOP_CAP / omega, limit), omega, omega_ref, limit


def _checked_omega_dt(omega_dt):
    """``omega_dt`` as given, or StepTooLargeError unless it is a finite number in (0, 2 SWITCHING_SAFETY] rad."""
    if not (_check._is_number(omega_dt) and 0.0 < omega_dt <= SWITCHING_SAFETY * 2.0):
        raise StepTooLargeError(f"omega_dt must be a finite number in (0, {2 * SWITCHING_SAFETY:g}] rad "
                                f"(central difference is unstable past omega dt = 2), got {_check.show(omega_dt)}")
    return omega_dt


def contact_omega(system: GapSystem, n: int = 3) -> float:
    """rad/s, the top closed-gap frequency of the system seen through its ``n`` lowest open-gap
    modes that move the gaps (Phi_n: for the discrete model all its modes):
    omega^2 = max eig(Phi_n^T K_closed Phi_n), with Phi_n mass-normalized. It grows with k_g as
    the discrete model's omega_max does, so a stiff penalty is still resolved.

    Parameters
    ----------
    system : GapSystem
        The system.
    n : int
        Lowest gap-moving open-gap modes used, in [1, system.n].

    Returns
    -------
    float
        rad/s.

    Raises
    ------
    InvalidArgument
        Not a GapSystem, or n out of range.
    """
    from reduced.models.modes import moving_modes

    _check.gap_system(system)
    n = _check.integer("n", n, lo=1, hi=system.n)
    _, phi, _ = moving_modes(system.K, system.M, system.B, n)
    lam = np.linalg.eigvalsh(phi.T @ system.closed_stiffness() @ phi)
    return float(np.sqrt(max(lam[-1], 0.0)))


@nb.njit(cache=True)
def _cd_kernel(AT, dtGKT, dtGBT, LT, Bidx, Bval, offset, side, k, x, vh, dt, n_steps, every, out_x, out_v, out_W,
               W, pw_old, i0, dtGbT, b, P, out_E, E, pe_old):
    """Advance n_steps; x = x_n, vh = v_{n+1/2} on entry and exit; stores every `every` steps.

    v_{n+3/2} = A v_{n+1/2} - dt G K x_{n+1} - dt G B^T f(B x_{n+1}) + dt G b^T p(t_{n+1}) with
    G = (M + dt/2 C)^-1 and A = G (M - dt/2 C), all formed once and passed transposed (AT = A^T,
    dtGKT = (dt G K)^T, dtGBT = (dt G B^T)^T, dtGbT = (dt G b^T)^T): two n x n products a step,
    accumulated column by column so that the loop over the rows is contiguous (SIMD) while each
    row still sums its terms in the order c = 0, 1, ..., n - 1 (the same bits as the row-by-row
    dot products). The stops' rows B_j x run over their nonzero entries only (Bval[j, t] at columns
    Bidx[j, t], padded with zeros): a zero entry adds an exact 0. W accumulates the dissipated work by
    the trapezoidal rule on p_n = v_n^T C v_n = |LT v_n|^2 (C = L L^T, LT = L^T; pw_old is p_n at
    entry), each |(L^T v)_q| summed i = 0 .. n - 1 as before. With loads (b (L, n),
    P[i] the loads at the i-th step's end), E accumulates their work likewise on
    v_n^T b^T p(t_n) (pe_old at entry).
    """
    n = x.shape[0]
    m = Bidx.shape[0]
    nz = Bidx.shape[1]
    r = LT.shape[0]
    nl = b.shape[0]
    f = np.empty(m)
    acc = np.empty(n)
    v_int = np.empty(n)
    io = i0
    left = every  # steps to the next stored sample
    for step in range(1, n_steps + 1):
        for i in range(n):
            x[i] += dt * vh[i]
        for j in range(m):
            s = -offset[j]
            for t in range(nz):
                s += Bval[j, t] * x[Bidx[j, t]]
            f[j] = k[j] * s if side[j] * s > 0.0 else 0.0
        for i in range(n):
            acc[i] = 0.0
        for c in range(n):
            vc = vh[c]
            xc = x[c]
            for i in range(n):
                acc[i] += AT[c, i] * vc - dtGKT[c, i] * xc
        for j in range(m):
            fj = f[j]
            if fj != 0.0:  # an open stop adds exactly 0
                for i in range(n):
                    acc[i] -= dtGBT[j, i] * fj
        for q in range(nl):
            pq = P[step - 1, q]
            for i in range(n):
                acc[i] += dtGbT[q, i] * pq
        for i in range(n):
            v_int[i] = 0.5 * (vh[i] + acc[i])
            vh[i] = acc[i]
        pw_new = 0.0
        for q in range(r):
            s = 0.0
            for i in range(n):
                s += LT[q, i] * v_int[i]
            pw_new += s * s
        W += 0.5 * dt * (pw_old + pw_new)
        pw_old = pw_new
        if nl:
            pe_new = 0.0
            for q in range(nl):
                s = 0.0
                for i in range(n):
                    s += b[q, i] * v_int[i]
                pe_new += s * P[step - 1, q]
            E += 0.5 * dt * (pe_old + pe_new)
            pe_old = pe_new
        left -= 1
        if left == 0:
            left = every
            for i in range(n):
                out_x[io, i] = x[i]
                out_v[io, i] = v_int[i]
            out_W[io] = W
            if nl:
                out_E[io] = E
            io += 1
    return W, pw_old, io, E, pe_old


def _sparse_rows(B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Bidx, Bval) (m, p): the nonzero entries of each row of B and their columns, p the most in a row
    (shorter rows padded with the value 0 at column 0)."""
    nnz = [np.flatnonzero(row) for row in B]
    p = max(1, max(len(c) for c in nnz))
    Bidx = np.zeros((B.shape[0], p), np.int64)
    Bval = np.zeros((B.shape[0], p))
    for j, c in enumerate(nnz):
        Bidx[j, :len(c)] = c
        Bval[j, :len(c)] = B[j, c]
    return Bidx, Bval


def _damping_factor(C: np.ndarray) -> np.ndarray:
    """(n, r) L with C = L L^T (r = rank of C, 0 for no damping)."""
    lam, U = np.linalg.eigh(0.5 * (C + C.T))
    keep = lam > 1e-14 * max(lam.max(initial=0.0), 1e-300)
    return np.ascontiguousarray(U[:, keep] * np.sqrt(lam[keep]))


def _physical_arrays(system: GapSystem, dt: float, b: np.ndarray, small: bool) -> tuple:
    """(kernel, its leading arrays, L, dt G b^T (transposed), b) of the physical kernels: A^T, (dt G K)^T,
    (dt G B^T)^T, the damping factor L (C = L L^T), the stops' rows, G = (M + dt/2 C)^-1, A = G (M - dt/2 C);
    for ``small`` models zero-padded to ``_cd.SMALL_N`` DOFs (the register kernel, or the lumped one where it
    applies)."""
    M, C, K = system.M, system.C, system.K
    G = np.linalg.inv(M + 0.5 * dt * C)
    A = G @ (M - 0.5 * dt * C)
    dtGK = dt * (G @ K)
    AT, dtGKT = np.ascontiguousarray(A.T), np.ascontiguousarray(dtGK.T)
    dtGBT = np.ascontiguousarray((dt * (G @ system.B.T)).T)
    L = _damping_factor(C)
    dtGbT = np.ascontiguousarray((dt * (G @ b.T)).T)
    if not small:
        return _cd_kernel, (AT, dtGKT, dtGBT, np.ascontiguousarray(L.T), *_sparse_rows(system.B)), L, dtGbT, b
    S = _cd.SMALL_N
    mats = (_cd.pad(AT, S, S), _cd.pad(dtGKT, S, S), _cd.pad(dtGBT, None, S), _cd.pad(L, S, None),
            _cd.pad(system.B, None, S))
    kernel = _cd._cd_small
    lumped = _cd_lumped.lumped_form(*mats, system.offset, system.side, system.k) if LUMPED else None
    if lumped is not None:  # diagonal M and C, one coordinate a stop: the zero terms left out, same bits
        kernel, mats = _cd_lumped.cd_lumped, lumped
    return kernel, mats, L, _cd.pad(dtGbT, None, S), _cd.pad(b, None, S)


_SETUP: dict = {}  # a run's set-up worked out from the model alone (a few entries): see _cached
SETUP_KEPT = 8  # entries _SETUP keeps


def _system_key(system: GapSystem) -> tuple:
    """The bytes of a system's arrays and of its friction's (its sliders stiffen the closed state): a key that
    changes with any of them."""
    arrays = [system.M, system.C, system.K, system.B, system.k, system.offset, system.side, system.tip]
    fr = system.friction
    unset = ()
    if fr is not None:
        values = {f.name: getattr(fr, f.name) for f in dataclasses.fields(fr)}
        arrays += [v for v in values.values() if isinstance(v, np.ndarray)]
        unset = tuple(name for name, v in values.items() if v is None)
    return (fr is not None, unset, *((a.tobytes(), a.shape, a.dtype.str) for a in arrays))


def _cached(key: tuple, make):
    """make() the first time ``key`` is asked for, then the same object (kept for the last ``SETUP_KEPT`` keys):
    a run's set-up (the stability limit, the step's reference frequency, the kernel's matrices) costs more than
    the kernel on a short run. The objects are read, never changed, by the runs. The keys hold the functions
    that make the values, as found when asked (so a function replaced, as tests replace stability_limit, makes
    and keeps its own values, and never hands them to the original)."""
    if key in _SETUP:
        return _SETUP[key]
    if len(_SETUP) >= SETUP_KEPT:
        _SETUP.pop(next(iter(_SETUP)))
    _SETUP[key] = out = make()
    return out


COORDINATES = ("auto", "physical", "modal", "blocked")  # ExplicitOptions.coordinates


@dataclass(frozen=True, slots=True)
class ExplicitOptions:
    """Options of the central-difference integrator (see :func:`integrate_explicit`).

    Parameters
    ----------
    dt : s, the step (refused beyond ``SWITCHING_SAFETY`` x the stability limit), or None
    omega_dt : rad, the step as omega_ref dt when ``dt`` is None, in (0, 2 SWITCHING_SAFETY]
    step_basis : omega_ref, "top" (omega_max) or "contact" (:func:`contact_omega`)
    chunks : progress is reported this many times a run
    coordinates : "physical" (the kernel of n x n products, the reference), "modal" (the same scheme in the
        open-gap modes, :mod:`reduced.transient._cd_modal`: equal to round-off, not bit for bit; a system
        with friction, of at most ``_cd.SMALL_N`` DOFs or whose modal damping is no diagonal plus low rank
        runs the physical kernel), "blocked" (the modal scheme jumped in blocks of steps while the contact
        state holds, :mod:`reduced.transient._cd_block`, equal to round-off; a forced run, or one with fewer
        than ``_cd_block.BLOCK_MIN`` steps between samples, runs the modal kernel) or "auto" (the default:
        "blocked" where the block kernel applies, else "physical"); ``stats["coordinates"]`` says which ran
    """

    dt: float | None = None
    omega_dt: float = DEFAULT_OMEGA_DT
    step_basis: str = "top"
    chunks: int = PIECES
    coordinates: str = "auto"

    def checked(self, system: GapSystem) -> ExplicitOptions:
        """These options validated (ValueError naming the first bad one)."""
        step_basis = _check.choice("step_basis", self.step_basis, STEP_BASES)
        omega_dt = _checked_omega_dt(self.omega_dt)
        chunks = _check.integer("chunks", self.chunks)
        dt = None if self.dt is None else _check.positive("dt", self.dt, "s")
        coordinates = _check.choice("coordinates", self.coordinates, COORDINATES)
        return ExplicitOptions(dt, omega_dt, step_basis, chunks, coordinates)


class ExplicitStepper(_stepper.Stepper):
    """The central-difference step: one kernel call of whole output intervals (:mod:`reduced.transient.stepper`).

    The scheme's whole state is carried from call to call: x_n, the half-step velocity
    v_{n+1/2}, the dissipated work W and the dissipation rate p_n of its trapezoidal rule (and
    the loads' work and power), so the samples are the same bits however the calls are cut. A
    call stops at the buffer's end, at the next progress mark (when progress is reported) and,
    under loads, after ``LOAD_BLOCK_STEPS`` steps (the loads at each step are tabulated a call).
    Models of at most ``_cd.SMALL_N`` DOFs run the register kernel :func:`reduced.transient._cd._cd_small`, or,
    lumped ones (diagonal M and C, each stop on one coordinate), :func:`reduced.transient._cd_lumped.cd_lumped`,
    the same bits; free frictionless larger ones, by default, the block kernel
    :func:`reduced.transient._cd_block.cd_block`
    (``ExplicitOptions.coordinates``), whose calls also start and end on samples, so its samples do not
    depend on the cuts either.

    Parameters
    ----------
    system, n_samples, sample_rate_hz, loads, report
        As :class:`reduced.transient.stepper.Stepper`.
    x0 : (n,) ndarray of float
        m, initial displacement.
    v0 : (n,) ndarray of float
        m/s, initial velocity.
    duration_s : float
        s, length of the run (the grid is set by ``n_samples``).
    options : ExplicitOptions
        dt or omega_dt with step_basis, and chunks, checked.

    Raises
    ------
    StepTooLargeError
        A ``dt`` beyond ``SWITCHING_SAFETY`` x the stability limit, or more than ``MAX_STEPS``
        steps.
    """

    method = "explicit"

    def __init__(self, system: GapSystem, x0: np.ndarray, v0: np.ndarray, duration_s: float, n_samples: int,
                 sample_rate_hz: float, options: ExplicitOptions, loads, report: bool) -> None:
        super().__init__(system, n_samples, sample_rate_hz, loads, report)
        N = n_samples
        self.dt, self.every, omega, omega_ref, limit = self._step_size(options)
        n_steps = (N - 1) * self.every
        if n_steps > MAX_STEPS:
            raise StepTooLargeError(
                f"{n_steps:.3g} steps needed (dt = {self.dt:.3g} s): more than {MAX_STEPS:.0e}; "
                "shorten the run (duration_s) or soften the contact"
            )
        dt = self.dt
        self.stats.update({"n_steps": n_steps, "dt": dt, "omega_max": omega, "omega_dt": omega * dt,
                           "step_basis": options.step_basis, "omega_ref": omega_ref, "omega_ref_dt": omega_ref * dt,
                           "dt_stable": limit})
        if self.forced:
            self.stats["n_loads"] = loads.n_loads
        self.modal = None  # the open-gap modal form (reduced.transient._cd_modal) when it runs
        self.jump = None  # the block form (reduced.transient._cd_block) when it runs
        coordinates = getattr(options, "coordinates", "physical")
        mb = _cd_block.block_steps(self.every)
        blocks = not self.forced and mb > 0  # the block kernel applies (given the modal form)
        if (coordinates in ("modal", "blocked") or (coordinates == "auto" and blocks)) and not self.friction \
                and self.n > _cd.SMALL_N:
            b = np.ascontiguousarray(loads.b) if self.forced else np.zeros((0, self.n))
            self.modal = _cached(("modal", _cd_modal.modal_form, _system_key(system), b.tobytes(), b.shape, dt),
                                 lambda: _cd_modal.modal_form(system.M, system.K, system.C, system.B, b, dt))
        if coordinates in ("blocked", "auto") and self.modal is not None and blocks:
            self.jump = _cd_block.block_form(self.modal["mats"], self.modal["om2"], system.offset, system.side,
                                             system.k, dt, mb)
        if coordinates == "auto" and self.jump is None:
            self.modal = None  # "auto" runs the block kernel or the physical one
        self._matrices()
        self._first_state(x0, v0)
        self.stats["coordinates"] = "physical" if self.modal is None else "modal" if self.jump is None else "blocked"
        # samples between progress reports (without them a buffer is filled in one kernel call)
        self.per_piece = max(1, (N - 1) // options.chunks) if report else max(1, N - 1)
        self.done = 0  # samples filled after the first

    def _step_size(self, options: ExplicitOptions) -> tuple[float, int, float, float, float]:
        """(dt, every, omega_max, omega_ref, dt_stable): the step, shortened so that the output
        interval is ``every`` steps."""
        system = self.system
        if options.dt is not None:
            omega, dt_crit = _cached(("limit", stability_limit, _system_key(system)), lambda: stability_limit(system))
            omega_ref, limit = omega, SWITCHING_SAFETY * dt_crit
            if options.dt > limit:
                raise StepTooLargeError(
                    f"dt = {options.dt:.3g} s exceeds the stable step {limit:.3g} s "
                    f"({SWITCHING_SAFETY} x 2/omega_max with damping; omega_max = {omega:.4g} rad/s "
                    "in the closed-gap state)"
                )
            dt_target = options.dt
        else:
            dt_target, omega, omega_ref, limit = _cached(
                ("step", default_step, stability_limit, contact_omega, _system_key(system), options.omega_dt,
                 options.step_basis),
                lambda: default_step(system, options.omega_dt, options.step_basis))
            if omega <= 0:
                dt_target = 1.0 / self.sample_rate_hz
        h_out = 1.0 / self.sample_rate_hz
        every = max(1, math.ceil(h_out / dt_target * (1.0 - 1e-12)))
        return h_out / every, every, omega, omega_ref, limit

    def _matrices(self) -> None:
        """The kernel and its matrices (:func:`_physical_arrays` for the physical kernels, the modal and block
        forms for theirs) and the damping factor L (C = L L^T)."""
        system, n, dt = self.system, self.n, self.dt
        b = np.ascontiguousarray(self.loads.b) if self.forced else np.zeros((0, n))
        self.small = n <= _cd.SMALL_N  # state in registers (reduced.transient._cd), zero-padded to SMALL_N DOFs
        if self.jump is not None:
            self.L = _cached(("L", _damping_factor, system.C.tobytes(), system.C.shape),
                             lambda: _damping_factor(system.C))
            self.kernel = _cd_block.cd_block
            self.mats = (*self.modal["mats"], *(self.jump[key] for key in _cd_block.KEYS),
                         np.ascontiguousarray(self.modal["Phi"].T),  # the kernel stores physical samples
                         _cd_block.new_carry(self.modal["mats"][10].shape[0]))  # the blocks' carry, this run's
            self.dtGbT, self.b = None, self.modal["bm"]
        elif self.modal is not None:
            self.L = _cached(("L", _damping_factor, system.C.tobytes(), system.C.shape),
                             lambda: _damping_factor(system.C))
            self.kernel = _cd_modal.cd_modal
            self.mats = self.modal["mats"]
            self.dtGbT, self.b = None, self.modal["bm"]  # the kernel's a (set by _first_state) and the loads' rows
        else:
            key = ("physical", _system_key(system), dt, b.tobytes(), b.shape, self.small, LUMPED, _damping_factor,
                   _cd._cd_small, _cd_lumped.lumped_form, _cd_lumped.cd_lumped)
            self.kernel, self.mats, self.L, self.dtGbT, self.b = _cached(
                key, lambda: _physical_arrays(system, dt, b, self.small))


    def _first_state(self, x0: np.ndarray, v0: np.ndarray) -> None:
        """x_0, v_{1/2} = v_0 + dt/2 a_0, and the work sums' first terms (p_0 = v_0^T C v_0, v_0^T f_ext(0))."""
        system, dt = self.system, self.dt
        x, v = x0.copy(), v0.copy()
        self.x0, self.v0 = x0.copy(), v0.copy()
        rhs0 = -(system.K @ x) - system.contact_force(x) - system.C @ v
        if self.forced:
            f0 = self.loads.force(0.0)
            rhs0 = rhs0 + f0
        a0 = np.linalg.solve(system.M, rhs0)
        vh = v + 0.5 * dt * a0
        S = _cd.SMALL_N
        self.x, self.vh = (_cd.pad(x, S, None), _cd.pad(vh, S, None)) if self.small else (x, vh)
        if self.modal is not None:  # z, zd and a = U^T zd of the modal kernel (carried in the dtGbT slot)
            self.x, self.vh = self.modal["PhiTM"] @ x, self.modal["PhiTM"] @ vh
            self.dtGbT = self.modal["a_of"] @ self.vh
        self.W, self.pw = 0.0, float(np.sum((v @ self.L) ** 2))
        self.E, self.pe = 0.0, (float(v @ f0) if self.forced else 0.0)

    def arrays(self, k: int) -> tuple[np.ndarray, ...]:
        return np.empty((k, self.n)), np.empty((k, self.n)), np.empty(k), np.empty(k if self.forced else 0)

    def block(self, buf: _stepper.Buffer) -> tuple[np.ndarray, ...]:
        return buf.arrays if self.forced else buf.arrays[:3]

    def step(self, buf: _stepper.Buffer) -> float | None:
        """Sample 0 (the initial state) or one kernel call of whole output intervals."""
        out_x, out_v, out_W, out_E = buf.arrays
        N = self.n_samples
        if buf.j0 == 0 and buf.filled == 0:
            out_x[0], out_v[0], out_W[0] = self.x0, self.v0, 0.0
            if self.forced:
                out_E[0] = 0.0
            buf.filled = 1
            if N == 1:
                self.finished = True
                return 1.0
            if buf.full:
                return None
        # stop at the buffer's end and at the next progress mark, whichever comes first
        nout = min(buf.k - buf.filled, self.per_piece - self.done % self.per_piece)
        P = _NO_LOADS
        if self.forced:  # and after LOAD_BLOCK_STEPS steps: the loads at each step are tabulated
            nout = min(nout, max(1, LOAD_BLOCK_STEPS // self.every))
            steps = self.done * self.every + np.arange(1, nout * self.every + 1)  # global step numbers
            P = np.ascontiguousarray(self.loads.values(steps * self.dt))
        sy = self.system
        lo = buf.filled
        self.W, self.pw, buf.filled, self.E, self.pe = call_numba_kernel(
            self.kernel, *self.mats, sy.offset, sy.side, sy.k, self.x, self.vh, self.dt, nout * self.every,
            self.every, out_x, out_v, out_W, self.W, self.pw, buf.filled, self.dtGbT, self.b, P, out_E, self.E,
            self.pe)
        if self.modal is not None and self.jump is None:  # the samples of this call from modal to physical
            for out in (out_x, out_v):
                _cd_modal.to_physical(self.modal["Phi"], out, lo, buf.filled)
        self.done += nout
        if not np.all(np.isfinite(self.x)):
            raise FloatingPointError(
                f"central difference diverged before t = {self.done * (1.0 / self.sample_rate_hz):.4g} s "
                f"(dt = {self.dt:.3g} s)"
            )
        self.finished = self.done == N - 1
        if self.done % self.per_piece == 0 or self.finished:
            return self.done / (N - 1)
        return None

    def tolerance(self, amp: float) -> float:
        return float(np.finfo(float).eps * amp)


_NO_LOADS = np.zeros((0, 0))


def stream_explicit(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    dt: float | None = None,
    omega_dt: float = DEFAULT_OMEGA_DT,
    step_basis: str = "top",
    loads=None,
    chunks: int = PIECES,
    chunk_samples: int | None = None,
    progress=None,
    coordinates: str = "auto",
) -> RingdownStream:
    """Central-difference response, free or forced, chunk by chunk.

    See :func:`integrate_explicit` for the arguments; the samples come in chunks of at most
    ``chunk_samples`` (default: the whole run in one), the same bits as those of an unchunked
    run (:class:`ExplicitStepper`).

    Parameters
    ----------
    system, x0, v0, duration_s, sample_rate_hz, dt, omega_dt, step_basis, loads, chunks, progress, coordinates : as
        :func:`integrate_explicit`
    chunk_samples : samples a chunk (default: the whole run in one)

    Returns
    -------
    RingdownStream : the run, computed as it is read
    """
    return _stepper.run(ExplicitStepper, system, x0, v0, duration_s, sample_rate_hz,
                        ExplicitOptions(dt, omega_dt, step_basis, chunks, coordinates), loads, progress,
                        chunk_samples)


def integrate_explicit(
    system: GapSystem,
    x0: np.ndarray,
    v0: np.ndarray,
    duration_s: float,
    sample_rate_hz: float,
    *,
    dt: float | None = None,
    omega_dt: float = DEFAULT_OMEGA_DT,
    step_basis: str = "top",
    loads=None,
    chunks: int = PIECES,
    progress=None,
    coordinates: str = "auto",
) -> RingdownResult:
    """Central-difference response of ``system`` from (x0, v0), free or under ``loads``.

    M x'' + C x' + K x + B^T f(B x) = f_ext(t) = sum_l b_l p_l(t) (0 without loads); ``loads`` is
    None or a :class:`~reduced.models.loads.Loads` on the system's n coordinates, and its work
    int v^T f_ext dt is ``result.external`` (module docstring).

    The step is ``dt`` if given (refused beyond ``SWITCHING_SAFETY`` x the stability
    limit), else ``omega_dt / omega_ref`` with omega_ref by ``step_basis``:

    - ``"top"``: omega_max, the top closed-gap frequency (for the discrete model: its
      stiffest contact mode);
    - ``"contact"``: the top closed-gap frequency of the three lowest modes that move the gaps
      (:func:`contact_omega`: the modes the discrete model has), so that a reduced model is
      stepped to the discrete model's accuracy on its contact dynamics instead of resolving
      fixed-interface modes the contact hardly excites; capped at omega_max dt = ``TOP_CAP``.
      For the discrete model both bases give the same step.

    It is then shortened so that the output interval 1 / sample_rate_hz is a whole number of steps.
    ``progress`` (a callable taking the fraction done) is called ``chunks`` times.
    The whole run is held in memory; :func:`stream_explicit` gives it chunk by chunk.

    Parameters
    ----------
    system : the gap system
    x0, v0 : (n,) initial displacement [m] and velocity [m/s]
    duration_s : s, length of the run (> 0)
    sample_rate_hz : Hz, output sampling (> 0)
    dt : s, the step, or None for ``omega_dt / omega_ref``
    omega_dt : rad, in (0, 2 ``SWITCHING_SAFETY``]
    step_basis : "top" or "contact" (above)
    loads : None or a :class:`~reduced.models.loads.Loads` (above)
    chunks : progress reports a run
    progress : None or a callable taking the fraction done
    coordinates : "auto" (default), "physical", "modal" or "blocked": :class:`ExplicitOptions`

    Returns
    -------
    RingdownResult : the run, with the statistics (n_steps, dt, omega_max, omega_dt, omega_ref, dt_stable,
        coordinates)

    Raises
    ------
    StepTooLargeError
        A step beyond the stability margin, or more than ``MAX_STEPS`` steps.
    """
    return stream_explicit(system, x0, v0, duration_s, sample_rate_hz, dt=dt, omega_dt=omega_dt,
                           step_basis=step_basis, loads=loads, chunks=chunks, progress=progress,
                           coordinates=coordinates).collect()
