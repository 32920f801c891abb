"""Linear structures with penalty gap stops: the system every nonlinear solver works on.

The equation of motion is

    M x'' + C x' + K x + B^T f(B x) = 0,

where ``s = B x`` (m,) are the *contact coordinates* (a DOF, or a difference of DOFs
such as tip minus face) and each row ``j`` of ``B`` carries one penalty stop:

    f_j(s) = k_j (s_j - o_j)   if side_j (s_j - o_j) > 0   (stop closed)
             0                 otherwise                   (stop open).

``side = +1`` is an upper stop at ``s = o`` (contact when s > o), ``side = -1`` a lower
stop (contact when s < o). A two-sided clearance ``|s| <= g`` is a pair of stops sharing
one *tip*: (o = +g, side = +1) and (o = -g, side = -1). Stops of one tip exclude each
other, so a system with T two-sided tips has 3**T linear contact states.

The energy is ``E = 1/2 v^T M v + 1/2 x^T K x + sum_j 1/2 k_j max(0, side_j (s_j - o_j))^2``.

**Friction** (optional, :class:`Friction`): a stop may carry sliders (Jenkins elements), each with a
tangential relative coordinate ``t_k = Bt_k x``, a tangential penalty stiffness ``kt_k`` and a Coulomb
coefficient ``mu_k``; its normal force is that of its stop, ``N_j = k_j max(0, side_j (s_j - o_j))``.
The slider position ``w_k`` is a state of its own, and the tangential force on the structure is
``Bt^T f_t`` with, by the state of the slider,

    stick (stop closed, |f| < mu N):  f_k = kt_k (t_k - w_k),     w_k' = 0,
    slip +/- (stop closed, |f| = mu N): f_k = +-mu_k N_j,         w_k = t_k -+ mu_k N_j / kt_k (w_k' >< 0),
    open (stop open):                  f_k = 0,                   w_k = t_k (the slider follows, unloaded).

Every one of these is linear in (x, v, w) because N_j is, so the motion stays piecewise linear. The
energy adds ``sum_k 1/2 kt_k (t_k - w_k)^2`` (the tangential springs; zero on an open stop), and the
friction dissipates ``int f_k w_k' dt = int mu_k N_j |w_k'| dt >= 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import product

import numpy as np

MAX_STOPS = 16  # 2**16 contact states is the most the exact integrator tabulates


@dataclass(frozen=True, eq=False)
class Friction:
    """Coulomb friction with a tangential penalty stiffness at the tips of a :class:`GapSystem`.

    Slider k acts along the tangential relative coordinate ``t_k = Bt[k] @ x`` at tip ``tip[k]``; the
    normal force of whichever stop of that tip is closed, N = k_j max(0, side_j (B_j x - o_j)), bounds
    its force: |f_k| <= mu_k N (the module docstring gives the states). A slider serves both stops
    of a two-sided tip (they are never closed together) unless ``stop`` ties it to one of them: the
    3-D model's upper and lower tips touch two different faces of the beam, whose tangential motions
    differ (the beam's pitch moves its top and bottom faces apart along its axis), so each stop has
    sliders of its own there, engaged only while that stop is closed. A slider starts unloaded
    (w = t) each time a stop that engages it closes. Two sliders on one contact (along and across the
    beam) are two independent Coulomb laws (a square friction cone), which keeps every state linear.

    Attributes
    ----------
    Bt : (p, n) array
        Rows mapping x to the tangential relative coordinates t = Bt x [m].
    tip : (p,) int array
        The tip each slider acts at (a value of :attr:`GapSystem.tip`).
    k_t : (p,) array
        N/m, tangential penalty stiffness of each slider, > 0.
    mu : (p,) array
        Coulomb coefficient of each slider, >= 0.
    names : tuple of str
        One name a slider.
    stop : (p,) int array or None
        The stop (row of :attr:`GapSystem.B`) that engages each slider, -1 for either stop of its tip
        (None: -1 for every slider).
    """

    Bt: np.ndarray
    tip: np.ndarray
    k_t: np.ndarray
    mu: np.ndarray
    names: tuple[str, ...]
    stop: np.ndarray | None = None

    def __post_init__(self) -> None:
        Bt = np.atleast_2d(np.asarray(self.Bt, float))
        p = Bt.shape[0]
        object.__setattr__(self, "Bt", Bt)
        object.__setattr__(self, "tip", np.asarray(self.tip, np.int64).reshape(-1))
        for name in ("k_t", "mu"):
            object.__setattr__(self, name, np.broadcast_to(np.asarray(getattr(self, name), float), (p,)).copy())
        if self.tip.shape != (p,):
            raise ValueError(f"tip must have shape ({p},), got {self.tip.shape}")
        stop = np.full(p, -1, np.int64) if self.stop is None else np.asarray(self.stop, np.int64).reshape(-1)
        if stop.shape != (p,):
            raise ValueError(f"stop must have shape ({p},), got {stop.shape}")
        object.__setattr__(self, "stop", stop)
        if len(self.names) != p:
            raise ValueError(f"names must hold {p} names, got {len(self.names)}")
        for name in ("Bt", "k_t", "mu"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"friction {name} has non-finite entries")
        if np.any(self.k_t <= 0.0):
            raise ValueError(f"friction k_t must be > 0 N/m, got {self.k_t!r}")
        if np.any(self.mu < 0.0):
            raise ValueError(f"friction mu must be >= 0, got {self.mu!r}")

    @property
    def p(self) -> int:
        """Number of sliders."""
        return self.Bt.shape[0]

    def engages(self, tip: np.ndarray) -> np.ndarray:
        """(p, m) bool: stop j engages slider k (stops of tip numbers ``tip`` (m,)): j is of the slider's tip and
        is its stop, or the slider serves either stop of its tip."""
        j = np.arange(len(tip))
        return (np.asarray(tip)[None, :] == self.tip[:, None]) & ((self.stop[:, None] < 0) | (self.stop[:, None] == j))

    def engaged_by(self, tip: np.ndarray, closed: np.ndarray) -> np.ndarray:
        """(p,) int: the closed stop that engages each slider, -1 where none does (``closed`` (m,) bool)."""
        eng = self.engages(tip) & np.asarray(closed, bool)[None, :]
        return np.where(eng.any(axis=1), np.argmax(eng, axis=1), -1)

    def force(self, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """N, tangential force of each slider kt (Bt x - w) for x (..., n), w (..., p)."""
        return self.k_t * (np.asarray(x) @ self.Bt.T - np.asarray(w))

    def energy(self, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """J, energy of the tangential springs, sum_k 1/2 kt_k (t_k - w_k)^2, for x (..., n), w (..., p)."""
        d = np.asarray(x) @ self.Bt.T - np.asarray(w)
        return 0.5 * (d * d) @ self.k_t


@dataclass(frozen=True, eq=False)
class GapSystem:
    """An n-DOF linear structure with m penalty stops (SI units).

    Attributes
    ----------
    M, C, K : (n, n) arrays
        Mass [kg], viscous damping [N s/m] and stiffness [N/m] matrices, symmetric.
    B : (m, n) array
        Rows map x to the contact coordinates s = B x [m].
    k : (m,) array
        N/m, penalty stiffness of each stop.
    offset : (m,) array
        m, position of each stop in s (+g for an upper stop, -g for a lower one).
    side : (m,) array of +1 / -1
        Upper (+1) or lower (-1) stop.
    tip : (m,) int array
        Stops with the same tip number exclude each other (one clearance).
    dof_names, stop_names : tuples of str
    friction : Friction or None
        Sliders at the stops (None: frictionless, the stops push normal to their rows only).
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    B: np.ndarray
    k: np.ndarray
    offset: np.ndarray
    side: np.ndarray
    tip: np.ndarray
    dof_names: tuple[str, ...]
    stop_names: tuple[str, ...]
    friction: Friction | None = None

    def __post_init__(self) -> None:
        n = self.M.shape[0]
        for name in ("M", "C", "K"):
            A = getattr(self, name)
            if A.shape != (n, n):
                raise ValueError(f"{name} must be {n}x{n}, got shape {A.shape}")
            if not np.all(np.isfinite(A)):
                raise ValueError(f"{name} has non-finite entries")
            if not np.allclose(A, A.T, rtol=1e-12, atol=0.0):
                raise ValueError(f"{name} must be symmetric")
        m = self.B.shape[0]
        if self.B.shape != (m, n):
            raise ValueError(f"B must be (m, {n}), got {self.B.shape}")
        if m > MAX_STOPS:
            raise ValueError(f"at most {MAX_STOPS} stops are supported, got {m}")
        for name in ("k", "offset", "side", "tip"):
            a = getattr(self, name)
            if a.shape != (m,):
                raise ValueError(f"{name} must have shape ({m},), got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} has non-finite entries")
        if np.any(self.k < 0):
            raise ValueError("stop stiffness k must be >= 0")
        if not np.all(np.isin(self.side, (-1.0, 1.0))):
            raise ValueError("side must be +1 or -1")
        if np.any(np.linalg.eigvalsh(self.M) <= 0):
            raise ValueError("M must be positive definite")
        fr = self.friction
        if fr is not None:
            if not isinstance(fr, Friction):
                raise ValueError(f"friction must be a Friction or None, got {type(fr).__name__}")
            if fr.Bt.shape[1] != n:
                raise ValueError(f"friction Bt must be (p, {n}), got {fr.Bt.shape}")
            if not np.all(np.isin(fr.tip, self.tip)):
                raise ValueError(f"friction tips must be tips of the stops {np.unique(self.tip)!r}, got {fr.tip!r}")
            tied = fr.stop >= 0
            if np.any(fr.stop >= m) or np.any(self.tip[fr.stop[tied]] != fr.tip[tied]):
                raise ValueError(f"friction stops must be stops of the sliders' tips, got {fr.stop!r}")

    # -- sizes -------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.M.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[0]

    @property
    def undamped(self) -> bool:
        return not np.any(self.C)

    @property
    def p(self) -> int:
        """Number of friction sliders (0 without friction)."""
        return 0 if self.friction is None else self.friction.p

    def with_friction(self, friction: Friction | None) -> GapSystem:
        """The same system with ``friction`` at its tips (None: frictionless; ``self`` when that is no change)."""
        if friction is None and self.friction is None:
            return self
        return replace(self, friction=friction)

    # -- forces and energy -------------------------------------------------------------
    def penetration(self, x: np.ndarray) -> np.ndarray:
        """m, ``side_j (s_j - o_j)`` for x of shape (..., n); positive where a stop is closed."""
        return self.side * (np.asarray(x) @ self.B.T - self.offset)

    def contact_force(self, x: np.ndarray) -> np.ndarray:
        """N, generalized stop force ``B^T f(B x)`` for x of shape (..., n)."""
        s = np.asarray(x) @ self.B.T - self.offset
        f = np.where(self.side * s > 0.0, self.k * s, 0.0)
        return f @ self.B

    def stop_force(self, x: np.ndarray) -> np.ndarray:
        """N, force in each stop (m,) for x of shape (..., n); >= 0 is compression."""
        return self.k * np.maximum(self.penetration(x), 0.0)

    def energy(self, x: np.ndarray, v: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        """J, total mechanical energy for x, v of shape (..., n); with friction and the slider positions
        w (..., p), the tangential springs' energy is added (an open stop's slider follows t, so its
        spring holds none)."""
        x = np.asarray(x)
        v = np.asarray(v)
        kin = 0.5 * np.sum((v @ self.M) * v, axis=-1)  # a BLAS product: einsum's three-operand loop is ~50x slower
        lin = 0.5 * np.sum((x @ self.K) * x, axis=-1)
        pen = np.maximum(self.penetration(x), 0.0)
        E = kin + lin + 0.5 * (pen**2) @ self.k
        if w is not None and self.p:
            E = E + self.friction.energy(x, w)
        return E

    # -- linear contact states ---------------------------------------------------------
    def contact_state(self, x: np.ndarray, v: np.ndarray, atol: float = 0.0) -> np.ndarray:
        """(m,) bool, which stops are closed at (x, v).

        A stop within ``atol`` of its threshold counts as closed when it is closing
        (penetration rate > 0): this settles stops that cross at the same instant.
        """
        pen = self.penetration(x)
        rate = self.side * (self.B @ np.asarray(v))
        return (pen > atol) | ((np.abs(pen) <= atol) & (rate > 0.0))

    def crossing_events(self, active: np.ndarray) -> list:
        """``solve_ivp`` events, one per stop, on a state y with y[:n] = x: terminal, firing when
        an open stop closes or a closed one opens (the restart points of a leg-by-leg integration)."""
        events = []
        for j in range(self.m):
            ev = lambda t, y, j=j: self.side[j] * (self.B[j] @ y[: self.n] - self.offset[j])  # noqa: E731
            ev.terminal, ev.direction = True, (-1.0 if active[j] else 1.0)
            events.append(ev)
        return events

    def state_after_crossing(self, active: np.ndarray, j: int, x: np.ndarray, v: np.ndarray,
                             atol: float) -> np.ndarray:
        """The contact state after stop ``j`` crossed at (x, v): stop j flipped, whatever
        round-off says at the threshold, the others by :meth:`contact_state` with ``atol``."""
        flipped = not active[j]
        new = self.contact_state(x, v, atol=atol)
        new[j] = flipped
        return new

    def state_matrices(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K_s, F_s): with the stops in ``active`` closed, M x'' + C x' + K_s x = F_s."""
        Ks = self.K.copy()
        Fs = np.zeros(self.n)
        for j in np.flatnonzero(active):
            Ks += self.k[j] * np.outer(self.B[j], self.B[j])
            Fs += self.k[j] * self.offset[j] * self.B[j]
        return Ks, Fs

    def feasible_states(self) -> list[np.ndarray]:
        """Every active-set a motion can reach: at most one closed stop per tip."""
        tips = np.unique(self.tip)
        choices = [[-1, *np.flatnonzero(self.tip == t)] for t in tips]
        states = []
        for combo in product(*choices):
            a = np.zeros(self.m, dtype=bool)
            for j in combo:
                if j >= 0:
                    a[j] = True
            states.append(a)
        return states

    def fold_zero_gap_tips(self) -> GapSystem:
        """The same system with every zero-gap, two-sided tip of equal stiffness made linear.

        Such a tip pushes k s on both sides of s = 0, so it is a linear spring; folding it
        into K removes a threshold that a decaying motion would otherwise cross forever.
        """
        keep = np.ones(self.m, bool)
        K = self.K.copy()
        rubbing = set() if self.friction is None else set(self.friction.tip.tolist())
        for t in np.unique(self.tip):
            j = np.flatnonzero(self.tip == t)
            if t in rubbing:
                continue  # a tip with friction is not a linear spring
            if (len(j) == 2 and np.all(self.offset[j] == 0.0) and self.k[j[0]] == self.k[j[1]]
                    and np.array_equal(self.B[j[0]], self.B[j[1]]) and self.side[j].sum() == 0.0):
                K += self.k[j[0]] * np.outer(self.B[j[0]], self.B[j[0]])
                keep[j] = False
        if keep.all():
            return self
        friction = self.friction
        if friction is not None and np.any(friction.stop >= 0):  # the stops kept are numbered anew
            new = np.cumsum(keep) - 1
            friction = replace(friction, stop=np.where(friction.stop >= 0, new[friction.stop], -1))
        return GapSystem(
            M=self.M, C=self.C, K=K, B=self.B[keep], k=self.k[keep], offset=self.offset[keep],
            side=self.side[keep], tip=self.tip[keep], dof_names=self.dof_names,
            stop_names=tuple(n for n, k in zip(self.stop_names, keep, strict=True) if k), friction=friction,
        )

    def closed_stiffness(self) -> np.ndarray:
        """N/m, stiffness with one stop of every tip closed (the stiffest contact state; of equal stops, the
        first, the upper one); with friction, the sliders that stop engages sticking (their tangential springs
        kt Bt^T Bt added)."""
        Ks = self.K.copy()
        eng = None if self.friction is None else self.friction.engages(self.tip)
        for t in np.unique(self.tip):
            j = np.flatnonzero(self.tip == t)
            jmax = j[np.argmax(self.k[j])]
            Ks += self.k[jmax] * np.outer(self.B[jmax], self.B[jmax])
            if eng is not None:
                fr = self.friction
                for q in np.flatnonzero(eng[:, jmax]):
                    Ks += fr.k_t[q] * np.outer(fr.Bt[q], fr.Bt[q])
        return Ks

    def omega_max(self) -> float:
        """rad/s, highest natural frequency over all contact states (the closed state)."""
        from scipy.linalg import eigh

        return float(np.sqrt(max(eigh(self.closed_stiffness(), self.M, eigvals_only=True)[-1], 0.0)))


def two_sided_stops(
    rows: np.ndarray, k: np.ndarray, gap: np.ndarray, names: tuple[str, ...]
) -> dict[str, np.ndarray | tuple[str, ...]]:
    """B, k, offset, side, tip, stop_names for clearances ``|rows[i] @ x| <= gap[i]``.

    Each row gives an upper stop (offset +gap, side +1) followed by a lower one
    (offset -gap, side -1) with the same tip number.

    Parameters
    ----------
    rows : (T, n) array_like of float
        One gap coordinate per row, s_i = rows[i] @ x (m).
    k : float or (T,) array_like of float
        N/m, contact stiffness of each tip (broadcast).
    gap : float or (T,) array_like of float
        m, clearance of each tip, >= 0 (broadcast).
    names : tuple of str
        T tip names; the stops are named ``<name>+`` and ``<name>-``.

    Returns
    -------
    dict
        Keyword arguments of :class:`GapSystem`: ``B`` (2T, n), ``k`` (2T,), ``offset`` (2T,),
        ``side`` (2T,), ``tip`` (2T,) and ``stop_names`` (2T names).

    Raises
    ------
    ValueError
        A negative or NaN gap.
    """
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    T = rows.shape[0]
    k = np.broadcast_to(np.asarray(k, dtype=float), (T,))
    gap = np.broadcast_to(np.asarray(gap, dtype=float), (T,))
    if np.any(~(gap >= 0.0)):
        raise ValueError(f"gap must be >= 0 m, got {gap!r}")
    return {
        "B": np.repeat(rows, 2, axis=0),
        "k": np.repeat(k, 2),
        "offset": np.column_stack([gap, -gap]).ravel(),
        "side": np.tile([1.0, -1.0], T),
        "tip": np.repeat(np.arange(T), 2),
        "stop_names": tuple(f"{nm}{s}" for nm in names for s in ("+", "-")),
    }


def tip_friction(rows_t, k_t, mu, names: tuple[str, ...], tips=None, stops=None) -> Friction:
    """Sliders at tips: along each tangential row of each tip.

    Parameters
    ----------
    rows_t : (T, n) or (T, d, n) array_like of float
        Tangential relative coordinate(s) of each tip, t = rows_t[i] @ x (m); d directions a tip
        (along the beam, across it) are d independent sliders.
    k_t : float or (T,) array_like of float
        N/m, tangential stiffness of each tip's sliders (broadcast), > 0.
    mu : float or (T,) array_like of float
        Coulomb coefficient of each tip (broadcast), >= 0.
    names : tuple of str
        T * d slider names, tip-major.
    tips : (T,) array_like of int, optional
        The tip numbers (default 0 .. T - 1, those of :func:`two_sided_stops`).
    stops : (T,) array_like of int, optional
        The stop that engages each row's sliders (a row of B), -1 for either stop of its tip (the default);
        a stop's sliders, of its tip, are then rows of their own (give the tip twice, once a stop).

    Returns
    -------
    Friction
        T d sliders.

    Raises
    ------
    ValueError
        Names of the wrong count, or a bad k_t or mu (:class:`Friction`).
    """
    R = np.asarray(rows_t, float)
    if R.ndim == 2:
        R = R[:, None, :]
    T, d, n = R.shape
    if len(names) != T * d:
        raise ValueError(f"names must hold {T * d} names (tips x directions), got {len(names)}")
    tips = np.arange(T) if tips is None else np.asarray(tips, np.int64)
    k_t = np.broadcast_to(np.asarray(k_t, float), (T,))
    mu = np.broadcast_to(np.asarray(mu, float), (T,))
    stops = np.full(T, -1, np.int64) if stops is None else np.asarray(stops, np.int64)
    return Friction(Bt=R.reshape(T * d, n), tip=np.repeat(tips, d), k_t=np.repeat(k_t, d), mu=np.repeat(mu, d),
                    names=tuple(names), stop=np.repeat(stops, d))
