"""Beam-theory frequencies of a free-free prismatic bar of rectangular section.

The references the ``beam-free`` scene checks the 3-D model against. Section ``b x h`` (b
along y, h along z), length ``l``, isotropic E, nu, rho, G = E / (2 (1 + nu)); A = b h.
Bending "in z" (the bounce direction) bends about y with I = b h^3 / 12, bending "in y"
about z with I = h b^3 / 12.

* **Euler-Bernoulli bending**: f_n = (beta_n l)^2 / (2 pi l^2) sqrt(E I / (rho A)), with
  cos(beta l) cosh(beta l) = 1 (:func:`euler_bernoulli_roots`).
* **Timoshenko bending** (shear deformation and rotary inertia; the right reference for a
  stocky bar, l / h = 17 for the impact beam): the free-free frequency equation solved
  numerically (:func:`timoshenko_free_free_hz`) with Cowper's shear coefficient of a
  rectangle, k = 10 (1 + nu) / (12 + 11 nu).
* **St-Venant torsion**: f_n = n c / (2 l), c = sqrt(G J / (rho I_p)), I_p = (b h^3 + h b^3) / 12
  and J the torsion constant of the rectangle (:func:`rectangle_torsion_constant`).
* **Axial (rod)**: f_n = n / (2 l) sqrt(E / rho).

References: S. P. Timoshenko, Phil. Mag. 41 (1921) 744; T. C. Huang, J. Appl. Mech. 28 (1961)
579 (frequency equations of the Timoshenko beam, free ends among them); G. R. Cowper, J. Appl.
Mech. 33 (1966) 335 (shear coefficient); S. P. Timoshenko and J. N. Goodier, *Theory of
Elasticity*, 3rd ed. (1970), Sec. 109 (torsion of a rectangular bar); S. S. Rao, *Vibration of
Continuous Systems* (2007), Ch. 8 (longitudinal and torsional vibration of bars) and Ch. 11
(Euler-Bernoulli and Timoshenko beams).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

N_TORSION_TERMS = 50  # odd terms of the torsion-constant series: the tail is below 1e-10 of J
SCAN_POINTS_PER_ROOT = 400  # log-spaced samples of the Timoshenko frequency equation per root sought


def cowper_shear_coefficient(nu: float) -> float:
    """Cowper's shear coefficient of a rectangular section, k = 10 (1 + nu) / (12 + 11 nu).

    Parameters
    ----------
    nu : float
        Poisson's ratio.

    Returns
    -------
    float
        The shear coefficient k (dimensionless, 0.85 at nu = 0.3).
    """
    return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)


def rectangle_torsion_constant(b: float, h: float, n_terms: int = N_TORSION_TERMS) -> float:
    """m^4, St-Venant torsion constant of a b x h rectangle (Timoshenko and Goodier, Sec. 109).

    With a >= c the long and short sides,

        J = a c^3 / 3 [1 - (192 / pi^5) (c / a) sum_{n = 1, 3, 5, ..} tanh(n pi a / (2 c)) / n^5],

    the series solution of Prandtl's stress function, -lap(phi) = 2 on the section, phi = 0 on
    its edge, J = 2 int phi dA. A square gives J = 0.1406 a^4, a 2:1 rectangle 0.2287 a c^3.

    Parameters
    ----------
    b, h : float
        m, sides of the rectangle (either order).
    n_terms : int
        Odd terms n = 1, 3, .., 2 n_terms - 1 kept of the series.

    Returns
    -------
    float
        m^4, J.
    """
    a, c = max(b, h), min(b, h)
    n = np.arange(1, 2 * n_terms, 2, dtype=float)
    series = float(np.sum(np.tanh(n * np.pi * a / (2 * c)) / n**5))
    return a * c**3 / 3.0 * (1.0 - 192.0 / np.pi**5 * (c / a) * series)


def euler_bernoulli_roots(n_modes: int) -> np.ndarray:
    """beta_n l, n = 1 .. n_modes, of the free-free Euler-Bernoulli beam: cos(x) cosh(x) = 1.

    Written cos(x) = 1 / cosh(x), the n-th root lies within pi/4 of (2 n + 1) pi / 2, where
    cos(x) takes opposite signs (+-0.707) at the two ends and 1 / cosh(x) < 0.02; Brent's method
    refines it to round-off (4.730041, 7.853205, 10.995608, 14.137165, ...).

    Parameters
    ----------
    n_modes : int
        Number of elastic roots.

    Returns
    -------
    (n_modes,) ndarray of float
        beta_n l, increasing (dimensionless).
    """
    out = []
    for n in range(1, n_modes + 1):
        mid = (2 * n + 1) * np.pi / 2
        out.append(brentq(lambda x: math.cos(x) - 1.0 / math.cosh(x), mid - np.pi / 4, mid + np.pi / 4,
                          xtol=1e-14, rtol=1e-15))
    return np.array(out)


def euler_bernoulli_free_free_hz(E: float, rho: float, length: float, A: float, I: float,
                                 n_modes: int = 4) -> np.ndarray:
    """Hz, f_n = (beta_n l)^2 / (2 pi l^2) sqrt(E I / (rho A)), n = 1 .. n_modes (elastic modes only).

    Parameters
    ----------
    E : float
        Pa, Young's modulus.
    rho : float
        kg/m^3, density.
    length : float
        m, l.
    A : float
        m^2, cross-section area.
    I : float
        m^4, second moment of area about the bending axis.
    n_modes : int
        Number of elastic modes.

    Returns
    -------
    (n_modes,) ndarray of float
        Hz, f_1 .. f_n.
    """
    bl = euler_bernoulli_roots(n_modes)
    return bl**2 / (2 * np.pi * length**2) * math.sqrt(E * I / (rho * A))


def _timoshenko_wavenumbers(omega: float, EI: float, kGA: float, rhoA: float, rhoI: float) -> tuple[float, float]:
    """(alpha, beta): w ~ exp(+-alpha x), exp(+-i beta x) at omega, below the cut-off sqrt(kGA / rhoI).

    w = W exp(s x), psi = Psi exp(s x) in the field equations give
    kGA EI s^4 + omega^2 (kGA rhoI + rhoA EI) s^2 + rhoA omega^2 (rhoI omega^2 - kGA) = 0,
    a quadratic in s^2 with one positive root alpha^2 and one negative root -beta^2.
    """
    a = kGA * EI
    b = omega**2 * (kGA * rhoI + rhoA * EI)
    c = rhoA * omega**2 * (rhoI * omega**2 - kGA)
    if c >= 0.0:
        raise ValueError("frequency above the Timoshenko cut-off sqrt(kGA / rhoI) (second spectrum): not handled")
    s2_neg = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
    s2_pos = c / (a * s2_neg)  # from the product of the roots: no cancellation as in -b + sqrt(...)
    return math.sqrt(s2_pos), math.sqrt(-s2_neg)


def timoshenko_frequency_function(omega: float, length: float, EI: float, kGA: float, rhoA: float,
                                  rhoI: float, symmetric: bool) -> float:
    """D(omega) of the free-free Timoshenko beam; its roots are the natural frequencies (rad/s).

    On x in [-l/2, l/2] the modes are even or odd in w. Even: w = A cosh(alpha x) + B cos(beta x),
    psi = A P sinh(alpha x) + B Q sin(beta x); odd: w = A sinh(alpha x) + B sin(beta x),
    psi = A P cosh(alpha x) - B Q cos(beta x); the shear equation kGA (w'' - psi') + rhoA omega^2 w = 0
    fixes P = alpha + r / alpha, Q = -beta + r / beta, r = rhoA omega^2 / kGA. The free ends carry no
    moment (psi' = 0) and no shear (w' - psi = 0); by symmetry the end x = l/2 suffices. Its 2 x 2
    determinant, divided by r and by cosh(alpha l/2) to stay finite, is

        even: D = -P alpha sin(beta l/2) / beta + Q beta cos(beta l/2) tanh(alpha l/2) / alpha,
        odd:  D =  P alpha tanh(alpha l/2) cos(beta l/2) / beta + Q beta sin(beta l/2) / alpha.

    Without shear and rotary inertia (P = alpha, Q = -beta, alpha = beta) these become
    Euler-Bernoulli's tan(beta l/2) = -tanh(beta l/2) and tan(beta l/2) = tanh(beta l/2), the two
    halves of cos(beta l) cosh(beta l) = 1.

    Parameters
    ----------
    omega : float
        rad/s, below the cut-off sqrt(kGA / rhoI).
    length : float
        m, l.
    EI : float
        N m^2, bending stiffness.
    kGA : float
        N, shear stiffness (shear coefficient times G A).
    rhoA : float
        kg/m, mass per length.
    rhoI : float
        kg m, rotary inertia per length.
    symmetric : bool
        True for the modes even in w, False for the odd ones.

    Returns
    -------
    float
        D(omega) (dimensionless scale); it changes sign at each natural frequency of the family.
    """
    al, be = _timoshenko_wavenumbers(omega, EI, kGA, rhoA, rhoI)
    r = rhoA * omega**2 / kGA
    P, Q = al + r / al, -be + r / be
    x = length / 2
    if symmetric:
        return -P * al * math.sin(be * x) / be + Q * be * math.cos(be * x) * math.tanh(al * x) / al
    return P * al * math.tanh(al * x) * math.cos(be * x) / be + Q * be * math.sin(be * x) / al


def timoshenko_free_free_hz(E: float, nu: float, rho: float, length: float, A: float, I: float,
                            k_shear: float | None = None, n_modes: int = 4) -> np.ndarray:
    """Hz, the lowest ``n_modes`` elastic bending frequencies of a free-free Timoshenko beam.

    Field equations (w deflection, psi rotation of the section, G = E / (2 (1 + nu)))::

        rho A w_tt   = kGA (w_x - psi)_x
        rho I psi_tt = EI psi_xx + kGA (w_x - psi)

    with free ends psi_x = 0, w_x - psi = 0 (Huang 1961). The roots of the frequency equation
    (:func:`timoshenko_frequency_function`, even and odd modes) are bracketed on a log-spaced scan
    starting at a twentieth of the first Euler-Bernoulli frequency (shear and rotary inertia only
    lower the frequencies) and refined by Brent's method. ``k_shear`` defaults to Cowper's
    coefficient of a rectangle (Cowper 1966). For a free-free steel bar 0.2 m long, 20 x 20 mm,
    E = 210 GPa, nu = 0.3, rho = 7850 kg/m^3 this gives 2568.1 Hz against Euler-Bernoulli's
    2658.3 Hz (beta_1 l = 4.730041: R. D. Blevins, *Formulas for Natural Frequency and Mode
    Shape* (1979), free-free beam).

    Parameters
    ----------
    E : float
        Pa, Young's modulus.
    nu : float
        Poisson's ratio (for G and Cowper's k).
    rho : float
        kg/m^3, density.
    length : float
        m, l.
    A : float
        m^2, cross-section area.
    I : float
        m^4, second moment of area about the bending axis.
    k_shear : float, optional
        Shear coefficient (default :func:`cowper_shear_coefficient` of ``nu``).
    n_modes : int
        Number of elastic modes, even and odd together.

    Returns
    -------
    (n_modes,) ndarray of float
        Hz, increasing.

    Raises
    ------
    ValueError
        Fewer than ``n_modes`` roots below the top of the scan (the Euler-Bernoulli frequency of
        mode n_modes + 1, or the cut-off sqrt(kGA / rhoI) if lower).
    """
    k = cowper_shear_coefficient(nu) if k_shear is None else k_shear
    G = E / (2 * (1 + nu))
    EI, kGA, rhoA, rhoI = E * I, k * G * A, rho * A, rho * I
    f_eb = euler_bernoulli_free_free_hz(E, rho, length, A, I, n_modes + 1)
    w_lo = 2 * np.pi * f_eb[0] / 20
    w_hi = min(2 * np.pi * f_eb[-1], 0.999 * math.sqrt(kGA / rhoI))
    grid = np.geomspace(w_lo, w_hi, SCAN_POINTS_PER_ROOT * (n_modes + 1))
    roots = []
    for symmetric in (True, False):
        args = (length, EI, kGA, rhoA, rhoI, symmetric)
        D = np.array([timoshenko_frequency_function(w, *args) for w in grid])
        for i in np.flatnonzero(D[:-1] * D[1:] < 0):
            roots.append(brentq(timoshenko_frequency_function, grid[i], grid[i + 1], args=args,
                                xtol=1e-12 * grid[i], rtol=1e-14))
    roots = np.sort(roots)
    if len(roots) < n_modes:
        raise ValueError(f"found {len(roots)} Timoshenko roots below {w_hi / (2 * np.pi):.6g} Hz, "
                         f"asked for {n_modes}")
    return roots[:n_modes] / (2 * np.pi)


def torsion_free_free_hz(G: float, rho: float, length: float, b: float, h: float, n_modes: int = 1) -> np.ndarray:
    """Hz, St-Venant torsion of a free-free bar: f_n = n c / (2 l), c = sqrt(G J / (rho I_p)).

    rho I_p theta_tt = G J theta_xx with theta_x = 0 at both free ends gives theta_n = cos(n pi x / l);
    I_p = (b h^3 + h b^3) / 12 is the polar moment of area, J the torsion constant
    (:func:`rectangle_torsion_constant`). Warping is free at the ends; its stiffness and inertia
    are left out: the 3-D impact beam converges to this (+2e-5 with 8 elements across each section
    block, tests/test_fem.py).

    Parameters
    ----------
    G : float
        Pa, shear modulus.
    rho : float
        kg/m^3, density.
    length : float
        m, l.
    b, h : float
        m, sides of the rectangular section.
    n_modes : int
        Number of torsion modes.

    Returns
    -------
    (n_modes,) ndarray of float
        Hz, f_1 .. f_n.
    """
    J = rectangle_torsion_constant(b, h)
    Ip = (b * h**3 + h * b**3) / 12.0
    c = math.sqrt(G * J / (rho * Ip))
    return np.arange(1, n_modes + 1) * c / (2 * length)


def axial_free_free_hz(E: float, rho: float, length: float, n_modes: int = 1) -> np.ndarray:
    """Hz, longitudinal modes of a free-free rod: f_n = n / (2 l) sqrt(E / rho) (rho u_tt = E u_xx, u_x = 0
    at the ends). A 3-D bar sits lower by Love's lateral inertia, -nu^2 (n pi r_p / l)^2 / 2 relative with
    r_p^2 = I_p / A (-2.8e-4 for the first mode of the impact beam).

    Parameters
    ----------
    E : float
        Pa, Young's modulus.
    rho : float
        kg/m^3, density.
    length : float
        m, l.
    n_modes : int
        Number of axial modes.

    Returns
    -------
    (n_modes,) ndarray of float
        Hz, f_1 .. f_n (without Love's correction, :func:`love_axial_correction`).
    """
    return np.arange(1, n_modes + 1) / (2 * length) * math.sqrt(E / rho)


def love_axial_correction(nu: float, length: float, b: float, h: float, n: int = 1) -> float:
    """Relative shift of the n-th axial frequency by lateral inertia (Love's rod theory, first order):
    -nu^2 (n pi r_p / l)^2 / 2, r_p^2 = (b^2 + h^2) / 12.

    Parameters
    ----------
    nu : float
        Poisson's ratio.
    length : float
        m, l.
    b, h : float
        m, sides of the rectangular section.
    n : int
        Axial mode number.

    Returns
    -------
    float
        Relative shift (f_Love - f_rod) / f_rod, negative.
    """
    rp2 = (b * b + h * h) / 12.0
    return -0.5 * nu**2 * (n * np.pi / length) ** 2 * rp2


FAMILIES = ("bending z", "bending y", "torsion", "axial")


def free_beam_references(E: float, nu: float, rho: float, length: float, b: float, h: float,
                         counts: dict[str, int]) -> dict[str, list[tuple[str, float, float]]]:
    """{family: [(theory, f_theory_hz, f_euler_bernoulli_hz or nan)] for n = 1 .. counts[family]}.

    Bending against Timoshenko (Euler-Bernoulli beside it), torsion against St-Venant, axial
    against the rod; ``counts`` says how many modes of each family (see :data:`FAMILIES`).

    Parameters
    ----------
    E : float
        Pa, Young's modulus.
    nu : float
        Poisson's ratio.
    rho : float
        kg/m^3, density.
    length : float
        m, l.
    b, h : float
        m, section sides along y and z.
    counts : dict of str to int
        Family (a member of ``FAMILIES``: 'bending z', 'bending y', 'torsion', 'axial') -> number of
        modes wanted (0 or less: none).

    Returns
    -------
    dict of str to list of (str, float, float)
        Per family of ``counts``: (theory name, Hz of that theory, Hz of Euler-Bernoulli for the
        bending families, else nan), mode 1 first.

    Raises
    ------
    ValueError
        A family not in ``FAMILIES``.
    """
    A, G = b * h, E / (2 * (1 + nu))
    out: dict[str, list[tuple[str, float, float]]] = {}
    for family, n in counts.items():
        if n <= 0:
            out[family] = []
            continue
        if family.startswith("bending"):
            I = b * h**3 / 12 if family == "bending z" else h * b**3 / 12
            ft = timoshenko_free_free_hz(E, nu, rho, length, A, I, n_modes=n)
            fe = euler_bernoulli_free_free_hz(E, rho, length, A, I, n)
            out[family] = [("Timoshenko", float(x), float(y)) for x, y in zip(ft, fe, strict=True)]
        elif family == "torsion":
            out[family] = [("St-Venant torsion", float(x), math.nan) for x in torsion_free_free_hz(G, rho, length,
                                                                                                     b, h, n)]
        elif family == "axial":
            out[family] = [("rod", float(x), math.nan) for x in axial_free_free_hz(E, rho, length, n)]
        else:
            raise ValueError(f"unknown family {family!r}: one of {', '.join(FAMILIES)}")
    return out


__all__ = ["cowper_shear_coefficient", "rectangle_torsion_constant", "euler_bernoulli_roots",
           "euler_bernoulli_free_free_hz", "timoshenko_free_free_hz", "timoshenko_frequency_function",
           "torsion_free_free_hz", "axial_free_free_hz", "love_axial_correction", "free_beam_references",
           "FAMILIES"]
