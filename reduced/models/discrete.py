"""The paper's three-mass model of the bearing-and-shaft assembly (Section 3, Eq. 9, Table 1).

Masses m1, m2, m3 move vertically; the outer two hang on pairs of suspension springs k_s
and meet two-sided stops of stiffness k_g after a clearance g (the field ``gap``); a torsional spring kappa at
the middle mass gives the shaft's bending stiffness (half-length L):

    M = diag(m1, m2, m3),  C = c I,
    K = [[2k_s + a, -2a, a], [-2a, 4a, -2a], [a, -2a, 2k_s + a]],  a = kappa / L^2,

and the gap force f(x) = k_g (x - g) for x > g, 0 for |x| <= g, k_g (x + g) for x < -g
acts on x1 and x3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from reduced.models.gaps import GapSystem, tip_friction, two_sided_stops


@dataclass(frozen=True, slots=True)
class DiscreteParams:
    """Three-mass model of the bearing-and-shaft assembly (SI units, Table 1 defaults).

    Parameters
    ----------
    k_s : float
        N/m, one suspension spring (a pair at each outer mass), > 0.
    kappa : float
        N m/rad, torsional spring emulating the shaft's bending, >= 0.
    k_g : float
        N/m, gap (impact tip) spring, >= 0.
    L : float
        m, half-length of the shaft, > 0.
    gap : float
        m, radial clearance at each tip, >= 0.
    m1, m2, m3 : float
        kg, left, middle and right masses, > 0.
    c : float
        N s/m, viscous damping on every mass (C = c I), >= 0.

    Raises
    ------
    ValueError
        A value that is not a finite number (a bool included), or outside its range.
    """

    k_s: float = 8.03e3  # N/m, one suspension spring (a pair at each outer mass)
    kappa: float = 79161.0  # N m/rad, torsional spring emulating the shaft's bending
    k_g: float = 3.502e7  # N/m, gap (impact tip) spring
    L: float = 0.1614  # m, half-length of the shaft
    gap: float = 2.54e-4  # m, radial clearance at each tip
    m1: float = 0.629  # kg, left mass
    m2: float = 1.258  # kg, middle mass
    m3: float = 0.629  # kg, right mass
    c: float = 4.0  # N s/m, viscous damping on every mass (C = c I)

    def __post_init__(self) -> None:
        positive = ("k_s", "L", "m1", "m2", "m3")
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"{f.name} must be a number, got {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"{f.name} must be finite, got {v!r}")
            if f.name in positive and not v > 0.0:
                raise ValueError(f"{f.name} must be > 0, got {v!r}")
            if not v >= 0.0:
                raise ValueError(f"{f.name} must be >= 0, got {v!r}")

    @property
    def a(self) -> float:
        """N/m, kappa / L^2: the bending spring seen by the masses."""
        return self.kappa / self.L**2

    @property
    def point_names(self) -> tuple[str, ...]:
        """The points a scene's initial state refers to: the three masses."""
        return ("x1", "x2", "x3")

    @property
    def point_rows(self) -> np.ndarray:
        """(3, 3) the points as rows of the coordinates: the identity."""
        return np.eye(3)

    @property
    def grazing_energy_nnm2(self) -> float:
        """J, energy at which NNM 2 first touches the stops: 2 k_s gap^2."""
        return 2.0 * self.k_s * self.gap**2

    def system(self) -> GapSystem:
        """The model as a :class:`GapSystem` (stops on x1 and x3, two-sided)."""
        a = self.a
        K = np.array(
            [[2 * self.k_s + a, -2 * a, a], [-2 * a, 4 * a, -2 * a], [a, -2 * a, 2 * self.k_s + a]]
        )
        stops = two_sided_stops(
            np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), self.k_g, self.gap, ("x1", "x3")
        )
        return GapSystem(
            M=np.diag([self.m1, self.m2, self.m3]),
            C=self.c * np.eye(3),
            K=K,
            dof_names=("x1", "x2", "x3"),
            **stops,
        )


MINDLIN_NU = 0.3  # Poisson's ratio of the steel tips and beam, for the default tangential stiffness
MINDLIN_RATIO = 2.0 * (1.0 - MINDLIN_NU) / (2.0 - MINDLIN_NU)  # k_t / k_n of an elastic contact of like materials


@dataclass(frozen=True, slots=True)
class DiscreteFrictionParams:
    """The three-mass model with the beam's longitudinal motion and Coulomb friction at the tips (SI units).

    The paper's masses m1, m2, m3 (Eq. 9, Table 1) move vertically as in :class:`DiscreteParams`; a fourth
    coordinate u is the beam's axial motion as a rigid body, of mass m1 + m2 + m3 on the suspension's axial
    stiffness k_u, set so that this longitudinal pseudo-rigid mode is at ``f_long_hz`` (10.92 Hz, the
    test's mode 1 in Table 2). Each tip pair (at x1 and at x3) rubs on the beam along u: a slider
    (:class:`reduced.models.gaps.Friction`) of tangential stiffness k_t and coefficient mu, its normal force
    that of the closed stop, N = k_g (|x| - g). So the longitudinal motion is free between impacts and is
    braked by friction while a tip touches:

        M = diag(m1, m2, m3, m1 + m2 + m3),  C = c I,
        K = [[K_3, 0], [0, k_u]],  k_u = (m1 + m2 + m3) (2 pi f_long)^2,

    K_3 the paper's stiffness (:class:`DiscreteParams`). The default k_t is Mindlin's ratio of the tangential
    to the normal stiffness of an elastic contact of like materials, k_t = 2 (1 - nu) / (2 - nu) k_g
    (nu = ``MINDLIN_NU`` = 0.3, steel on steel: k_t = 0.82 k_g), the tips' own contact stiffness being k_g.
    The default mu = 0.3 is an assumption (dry steel on steel; the paper does not give one); mu = 0 gives
    the system without friction.

    Parameters
    ----------
    k_s, kappa, k_g, L, gap, m1, m2, m3, c : float
        As :class:`DiscreteParams` (Table 1 defaults).
    f_long_hz : float
        Hz, the open-gap longitudinal mode, > 0.
    mu : float
        Coulomb coefficient at the tips, >= 0.
    k_t : float or None
        N/m, tangential stiffness at the tips, > 0; None: ``MINDLIN_RATIO`` k_g.

    Raises
    ------
    ValueError
        A value that is not a finite number (a bool included), or outside its range.
    """

    k_s: float = 8.03e3  # N/m, one suspension spring (a pair at each outer mass)
    kappa: float = 79161.0  # N m/rad, torsional spring emulating the shaft's bending
    k_g: float = 3.502e7  # N/m, gap (impact tip) spring
    L: float = 0.1614  # m, half-length of the shaft
    gap: float = 2.54e-4  # m, radial clearance at each tip
    m1: float = 0.629  # kg, left mass
    m2: float = 1.258  # kg, middle mass
    m3: float = 0.629  # kg, right mass
    c: float = 4.0  # N s/m, viscous damping on every coordinate (C = c I)
    f_long_hz: float = 10.92  # Hz, longitudinal pseudo-rigid mode (Table 2, test)
    mu: float = 0.3  # Coulomb coefficient at the tips (assumed: dry steel on steel)
    k_t: float | None = None  # N/m, tangential stiffness at the tips; None: MINDLIN_RATIO x k_g

    def __post_init__(self) -> None:
        positive = ("k_s", "L", "m1", "m2", "m3", "f_long_hz", "k_t")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "k_t" and v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"{f.name} must be a number, got {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"{f.name} must be finite, got {v!r}")
            if f.name in positive and not v > 0.0:
                raise ValueError(f"{f.name} must be > 0, got {v!r}")
            if not v >= 0.0:
                raise ValueError(f"{f.name} must be >= 0, got {v!r}")

    @property
    def vertical(self) -> DiscreteParams:
        """The paper's three-mass model of the vertical motion."""
        return DiscreteParams(k_s=self.k_s, kappa=self.kappa, k_g=self.k_g, L=self.L, gap=self.gap, m1=self.m1,
                              m2=self.m2, m3=self.m3, c=self.c)

    @property
    def m_beam(self) -> float:
        """kg, the beam's mass m1 + m2 + m3, moving axially."""
        return self.m1 + self.m2 + self.m3

    @property
    def k_u(self) -> float:
        """N/m, axial stiffness of the suspension: m_beam (2 pi f_long)^2."""
        return self.m_beam * (2.0 * math.pi * self.f_long_hz) ** 2

    @property
    def tangential_stiffness(self) -> float:
        """N/m, k_t, or ``MINDLIN_RATIO`` k_g when not given."""
        return MINDLIN_RATIO * self.k_g if self.k_t is None else float(self.k_t)

    @property
    def point_names(self) -> tuple[str, ...]:
        """The points a scene's initial state refers to: the three masses and the axial motion u."""
        return ("x1", "x2", "x3", "u")

    @property
    def point_rows(self) -> np.ndarray:
        """(4, 4) the points as rows of the coordinates: the identity."""
        return np.eye(4)

    def system(self) -> GapSystem:
        """The model as a :class:`GapSystem` with friction along u at both tips (none when mu = 0)."""
        s3 = self.vertical.system()
        M = np.zeros((4, 4))
        K = np.zeros((4, 4))
        M[:3, :3], K[:3, :3] = s3.M, s3.K
        M[3, 3], K[3, 3] = self.m_beam, self.k_u
        B = np.zeros((s3.m, 4))
        B[:, :3] = s3.B
        friction = None
        if self.mu > 0.0:
            rows = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]])  # t = u at both tips (tips grounded)
            friction = tip_friction(rows, self.tangential_stiffness, self.mu, ("u@x1", "u@x3"))
        return GapSystem(M=M, C=self.c * np.eye(4), K=K, B=B, k=s3.k, offset=s3.offset, side=s3.side, tip=s3.tip,
                         dof_names=("x1", "x2", "x3", "u"), stop_names=s3.stop_names, friction=friction)
