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

from reduced.models.gaps import GapSystem, two_sided_stops


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
