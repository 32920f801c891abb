"""Linear elastic isotropic materials and their scikit-fem weak forms."""

from __future__ import annotations

import math
from dataclasses import dataclass

from skfem import BilinearForm
from skfem.helpers import ddot, dot, sym_grad, trace


@dataclass(frozen=True, slots=True)
class Material:
    """Isotropic linear elastic material.

    Parameters
    ----------
    E : float
        Pa, Young's modulus, > 0.
    nu : float
        Poisson's ratio, in (-1, 0.5).
    rho : float
        kg/m^3, density, > 0.

    Raises
    ------
    ValueError
        A value outside those ranges.
    """

    E: float = 200e9  # Pa, Young's modulus (steel)
    nu: float = 0.3  # Poisson's ratio
    rho: float = 7850.0  # kg/m^3, density

    def __post_init__(self) -> None:
        if not (self.E > 0 and math.isfinite(self.E)):
            raise ValueError(f"E must be > 0, got {self.E!r}")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"nu must be in (-1, 0.5), got {self.nu!r}")
        if not (self.rho > 0 and math.isfinite(self.rho)):
            raise ValueError(f"rho must be > 0, got {self.rho!r}")

    @property
    def G(self) -> float:
        """Pa, shear modulus E / (2 (1 + nu))."""
        return self.E / (2 * (1 + self.nu))


def lame_parameters(E: float, nu: float) -> tuple[float, float]:
    """(lambda, mu) = (E nu / ((1 + nu)(1 - 2 nu)), E / (2 (1 + nu))).

    Parameters
    ----------
    E : float
        Pa, Young's modulus.
    nu : float
        Poisson's ratio, in (-1, 0.5).

    Returns
    -------
    lam, mu : float
        Pa, the Lame parameters (mu = G).
    """
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def stiffness_form(material: Material) -> BilinearForm:
    """a(u, v) = int 2 mu eps(u):eps(v) + lambda div u div v dx.

    Parameters
    ----------
    material : Material
        E and nu give lambda and mu.

    Returns
    -------
    skfem.BilinearForm
        The form (N/m once assembled with lengths in m).
    """
    lam, mu = lame_parameters(material.E, material.nu)

    @BilinearForm
    def form(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return 2.0 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev)

    return form


def mass_form(material: Material) -> BilinearForm:
    """m(u, v) = int rho u . v dx (consistent mass).

    Parameters
    ----------
    material : Material
        rho is used.

    Returns
    -------
    skfem.BilinearForm
        The form (kg once assembled).
    """
    rho = material.rho

    @BilinearForm
    def form(u, v, w):
        return rho * dot(u, v)

    return form
