"""Exact frequency-energy relation of NNM 2 (the antisymmetric mode x1 = -x3, x2 = 0).

On NNM 2 of a model with m1 = m3, Eq. (9) reduces to the piecewise-linear oscillator

    m1 x'' + 2 k_s x + f(x) = 0                                   (paper, Eq. 11)

with f the two-sided gap force of Eq. (10). Let omega_0 = sqrt(2 k_s / m1),
K = k_g / (2 k_s), omega_c = omega_0 sqrt(1 + K), chi_0 = x0 / g and
R = chi_0 (1 + K) - K. Starting from rest at x0 > g, the closed-gap motion is a cosine
about x* = g K / (1 + K) and meets x = g when cos(omega_c t) = 1 / R, so the time spent
in |x| > g per period is

    T_g = (4 / omega_c) arccos(1 / R).                            (paper's Eq. 12, with
                                                                   its omega = omega_c)

The speed at x = g is omega_c (x0 - x*) sqrt(1 - 1/R^2), and the free flight from g to 0
takes arctan(omega_0 g / v) / omega_0, so

    T_s = (4 / omega_0) arccot( sqrt((R^2 - 1) / (1 + K)) ).

The paper's Eq. (13) prints arccot(R / sqrt(1 + K)) instead: it drops the "- 1" under the
root and so misses the grazing limit (T_s must tend to 2 pi / omega_0 as R -> 1; the
printed form gives (4 / omega_0) arccot(1 / sqrt(1 + K))). Both are implemented; the tests
check which one a direct integration of Eq. (9) confirms (ours, to 1e-12).

The energy on NNM 2 (both outer masses, from rest at x0) is
E = 2 k_s x0^2 + k_g (x0 - g)^2 for x0 > g, and the frequency is
omega = 2 pi / (T_g + T_s) above the grazing energy 2 k_s g^2, omega_0 below it.

Only the symmetric 3-DOF model has this relation. A reduced 3-D model has none: its NNM
study (scene rom-fep, :mod:`bearingshaft.stages.nnm_fep`) takes shooting on the exact flow as
the reference.
"""

from __future__ import annotations

import numpy as np

from reduced.models.discrete import DiscreteParams


def _require_symmetric(p: DiscreteParams) -> None:
    if p.m1 != p.m3:
        raise ValueError(
            f"the exact NNM 2 relation needs m1 == m3 (antisymmetric mode), got m1={p.m1}, m3={p.m3}"
        )


def amplitude_from_energy(p: DiscreteParams, energy_J: np.ndarray) -> np.ndarray:
    """m, turning-point amplitude x0 of NNM 2 with total energy E (inverts E(x0)).

    Parameters
    ----------
    p : DiscreteParams
        The three-mass model (k_s, k_g, g).
    energy_J : float or array_like of float
        J, total energy E >= 0.

    Returns
    -------
    ndarray of float
        m, x0 >= 0, the shape of ``energy_J``: sqrt(E / (2 k_s)) up to the grazing energy
        2 k_s g^2, the positive root of E(x0) above it.
    """
    E = np.asarray(energy_J, dtype=float)
    below = np.sqrt(E / (2.0 * p.k_s))
    kt = 2.0 * p.k_s + p.k_g
    disc = kt * E - 2.0 * p.k_s * p.k_g * p.gap**2
    above = (p.k_g * p.gap + np.sqrt(np.maximum(disc, 0.0))) / kt
    return np.where(E <= p.grazing_energy_nnm2, below, above)


def energy_from_amplitude(p: DiscreteParams, x0: np.ndarray) -> np.ndarray:
    """J, total energy of NNM 2 at rest at amplitude x0: 2 k_s x0^2 + k_g (x0 - g)_+^2.

    Parameters
    ----------
    p : DiscreteParams
        The three-mass model (k_s, k_g, g).
    x0 : float or array_like of float
        m, turning-point amplitude (its absolute value is used).

    Returns
    -------
    ndarray of float
        J, the shape of ``x0``.
    """
    x0 = np.abs(np.asarray(x0, dtype=float))
    return 2.0 * p.k_s * x0**2 + p.k_g * np.maximum(x0 - p.gap, 0.0) ** 2


def period_from_amplitude(p: DiscreteParams, x0: np.ndarray, *, paper: bool = False) -> np.ndarray:
    """s, period of NNM 2 at amplitude x0 (exact; ``paper=True`` uses the printed Eq. 13).

    Parameters
    ----------
    p : DiscreteParams
        The three-mass model, m1 == m3.
    x0 : float or array_like of float
        m, turning-point amplitude (its absolute value is used).
    paper : bool
        T_s by the paper's printed Eq. (13) instead of the corrected form.

    Returns
    -------
    ndarray of float
        s, T_g + T_s for x0 > g, 2 pi / omega_0 at and below it (with g = 0: 2 pi / omega_c for
        any x0 > 0).

    Raises
    ------
    ValueError
        m1 != m3.
    """
    _require_symmetric(p)
    x0 = np.abs(np.asarray(x0, dtype=float))
    w0 = np.sqrt(2.0 * p.k_s / p.m1)
    K = p.k_g / (2.0 * p.k_s)
    wc = w0 * np.sqrt(1.0 + K)
    T_open = 2.0 * np.pi / w0
    if p.gap == 0.0:
        return np.where(x0 > 0.0, 2.0 * np.pi / wc, T_open)
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.maximum(x0 / p.gap * (1.0 + K) - K, 1.0)
        Tg = 4.0 / wc * np.arccos(1.0 / R)
        if paper:
            Ts = 4.0 / w0 * np.arctan2(np.sqrt(1.0 + K), R)
        else:
            Ts = 4.0 / w0 * np.arctan2(np.sqrt(1.0 + K), np.sqrt(R * R - 1.0))
    return np.where(x0 > p.gap, Tg + Ts, T_open)


def frequency_from_energy(p: DiscreteParams, energy_J: np.ndarray, *, paper: bool = False) -> np.ndarray:
    """Hz, frequency of NNM 2 at total energy E (exact unless ``paper=True``).

    Parameters
    ----------
    p : DiscreteParams
        The three-mass model, m1 == m3.
    energy_J : float or array_like of float
        J, total energy.
    paper : bool
        As :func:`period_from_amplitude`.

    Returns
    -------
    ndarray of float
        Hz, 1 / period, the shape of ``energy_J``.

    Raises
    ------
    ValueError
        m1 != m3.
    """
    x0 = amplitude_from_energy(p, energy_J)
    return 1.0 / period_from_amplitude(p, x0, paper=paper)


def period_by_integration(p: DiscreteParams, x0: float, rtol: float = 1e-13) -> float:
    """s, period of NNM 2 measured by integrating the full Eq. (9) with DOP853.

    Starts undamped from x = [x0, 0, -x0], v = 0 and integrates leg by leg, restarting at
    every stop crossing (so each leg is smooth), until x1' next crosses zero from above
    after a minimum of x1 (one full period). Independent of the closed form above and of
    the event-driven integrator. SciPy looks for events only at step ends, so a contact
    shorter than a step would be missed: the step is capped at 0.05 / omega_closed, which
    resolves contacts down to x0 = (1 + 1e-6) g.

    Parameters
    ----------
    p : DiscreteParams
        The three-mass model, m1 == m3 (its damping c is set to zero).
    x0 : float
        m, turning-point amplitude of x1 (x3 = -x0).
    rtol : float
        DOP853's relative tolerance (the absolute one is rtol g).

    Returns
    -------
    float
        s, the time of the next maximum of x1.

    Raises
    ------
    ValueError
        m1 != m3 (from :func:`period_from_amplitude`, used for the time span).
    RuntimeError
        No period within three periods of the closed form's guess.
    """
    from dataclasses import replace

    from scipy.integrate import solve_ivp

    system = replace(p, c=0.0).system()
    n = system.n
    Minv = np.linalg.inv(system.M)
    z = np.array([x0, 0.0, -x0, 0.0, 0.0, 0.0])
    active = system.penetration(z[:n]) > 0.0
    w_guess = 2.0 * np.pi / period_from_amplitude(p, x0)
    t0, t_end = 0.0, 3.0 * 2.0 * np.pi / w_guess
    passed_minimum = False
    max_step = 0.05 / system.omega_max()
    while True:
        Ks, Fs = system.state_matrices(active)

        def rhs(t, y, Ks=Ks, Fs=Fs):
            return np.concatenate([y[n:], Minv @ (Fs - Ks @ y[:n])])

        events = system.crossing_events(active)
        turn = lambda t, y: y[n]  # noqa: E731  x1' = 0
        turn.terminal, turn.direction = True, (-1.0 if passed_minimum else 1.0)
        events.append(turn)
        sol = solve_ivp(rhs, (t0, t_end), z, method="DOP853", rtol=rtol, atol=rtol * p.gap,
                        events=events, max_step=max_step)
        if sol.status != 1:
            raise RuntimeError(f"no period found by t = {t_end:.4g} s ({sol.message})")
        times = [e[0] if e.size else np.inf for e in sol.t_events]
        je = int(np.argmin(times))
        t0, z = times[je], sol.y_events[je][0]
        if je == system.m:
            if passed_minimum:
                return t0
            passed_minimum = True
        else:
            active = system.state_after_crossing(active, je, z[:n], z[n:], 1e-10 * x0)
