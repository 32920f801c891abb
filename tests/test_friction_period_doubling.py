"""The period-doubled family of a forced orbit with friction (reduced/periodic/friction_continuation.py,
switch_branch at a period doubling; issue 27): against direct integration.

The system: a normal coordinate x (1 Hz) against a soft stop (gap 0.05 m, stiffness 10 k) and a tangential
coordinate y (1.5 Hz) whose slider (mu = 0.3, k_t = 50 k_x) the stop engages, 5 % damping, forced along
(1, 0.5) with P = 40 N. Its T-periodic orbit in contact loses stability near 2.3 Hz through -1 (a complex pair
of multipliers meets on the negative real axis, one leaves through -1: measured -0.83 +- 0.26j at 2.275 Hz,
-1.29 at 2.326 Hz), and a long run of the exact integrator beyond it settles on a motion of period 2T (its state
at t and t + 2T equal, at t and t + T not: measured 1e-9 and 2 m/s at 2.4 Hz)."""

from __future__ import annotations

import math

import numpy as np

from reduced.models.gaps import Friction, GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.periodic.friction_continuation import continue_friction, switch_branch
from reduced.periodic.friction_shooting import shoot_friction
from reduced.transient.friction import integrate_exact_friction, reference_dop853

W1 = 2 * math.pi  # rad/s, the normal coordinate's natural frequency
P = 40.0  # N
B = np.array([1.0, 0.5])  # the load's direction


def system() -> GapSystem:
    """The normal-tangential oscillator with a soft stop and a slider (module docstring)."""
    w = np.array([W1, 1.5 * W1])
    return GapSystem(M=np.eye(2), C=np.diag(2 * 0.05 * w), K=np.diag(w ** 2), B=np.array([[1.0, 0.0]]),
                     k=np.array([10.0 * W1 ** 2]), offset=np.array([0.05]), side=np.array([1.0]),
                     tip=np.array([0]), dof_names=("x", "y"), stop_names=("s",),
                     friction=Friction(np.array([[0.0, 1.0]]), [0], 50.0 * W1 ** 2, 0.3, ("t",)))


def loads(f: float) -> Loads:
    return Loads(np.atleast_2d(B), (Harmonic(P, f),))


def settled(s: GapSystem, f: float, periods: int, S: int = 8, q: int = 1) -> np.ndarray:
    """(q S, 5) the states [x; v; w] at t_k = k T / S of the last q periods of a run from rest."""
    r = integrate_exact_friction(s, np.zeros(2), np.zeros(2), periods / f, S * f, loads=loads(f))
    return np.hstack([r.x, r.v, r.w])[-q * S - 1:-1]


def test_the_period_doubled_orbit_is_a_fixed_point_over_2T_not_over_T_and_a_long_run_settles_on_it():
    # The T orbit shot at 2.0 Hz (stable, from a settled run) and continued up: a period doubling (a real
    # multiplier through -1). switch_branch there: Newton over 2T from the T orbit perturbed along the critical
    # eigenvector finds an orbit whose two halves differ (the new family, periods = 2), continued both ways, stable
    # by its multipliers over 2T. Against DOP853 restarted at every state change (an independent integrator): from
    # the 2T orbit's first node the state returns after 2T (within 1e-7 of the amplitude: DOP853 at rtol 1e-12 and
    # its event location) and not after T (by more than 1e-2). Against a long exact run: from the unstable T orbit
    # beside the bifurcation, perturbed by 1e-6, 150 periods later the state is on the 2T orbit (at one of its two
    # phases), within 1e-6 of the amplitude.
    s = system()
    f0 = 2.0
    t_orbit = shoot_friction(s, B, P, f0, settled(s, f0, 150))
    assert t_orbit.converged and t_orbit.stable, t_orbit.message
    br = continue_friction(t_orbit, 1.0, 2.6, ds=0.05, ds_max=0.5, max_steps=12)
    pd = [i for i, k in br.bifurcations if k == "period_doubling"]
    assert pd, br.bifurcations
    sw = switch_branch(t_orbit, br, pd[0], "period_doubling", continue_kw=dict(max_steps=1, band=(2.0, 2.6)))
    assert sw.outcome == "new family", sw.outcome
    assert sw.multiplier.real < -1.0 and abs(sw.multiplier + 1.0) < 0.5, sw.multiplier  # the T orbit: unstable
    o = sw.orbit
    assert o.periods == 2 and o.converged and o.defect < 1e-10 and o.period_defect < 1e-9
    assert sw.branch is not None and sw.branch.periods == 2 and len(sw.branch.freq_hz) == 3
    assert np.all(sw.branch.stable) and np.max(sw.branch.defect) < 1e-10
    f = o.freq_hz
    T = 1.0 / f
    y0 = o.nodes[0]
    n = s.n
    amp = float(np.max(np.abs(o.orbit(20)[1][:, :2 * n]) / o.scale[:2 * n]))

    def dop(duration):
        r = reference_dop853(s, y0[:n], y0[n:2 * n], duration, 2 / duration, w0=y0[2 * n:], loads=loads(f), rtol=1e-12)
        return np.concatenate([r.x[-1], r.v[-1]])

    two, one = (float(np.max(np.abs(dop(k * T) - y0[:2 * n]) / o.scale[:2 * n])) / amp for k in (2, 1))
    assert two < 1e-7, two
    assert one > 1e-2, one

    y_t = br.nodes[sw.at][0]
    assert float(br.freq_hz[sw.at]) == f
    k_run = 150
    r = integrate_exact_friction(s, y_t[:n] * (1 + 1e-6), y_t[n:2 * n], k_run * T, f, w0=y_t[2 * n:], loads=loads(f))
    end = np.concatenate([r.x[-1], r.v[-1]])
    S = o.nodes.shape[0]
    off = min(float(np.max(np.abs(end - o.nodes[j, :2 * n]) / o.scale[:2 * n])) for j in (0, S // 2)) / amp
    assert off < 1e-6, off
    assert float(np.max(np.abs(end - y_t[:2 * n]) / o.scale[:2 * n])) / amp > 1e-2  # it left the T orbit


def test_the_exact_jacobian_shoots_the_same_orbit_as_the_differences():
    # shoot_friction with jacobian="exact" (state transition and saltation matrices) against the forward
    # differences on the integrator: the same orbit in contact (stick, slip and gap events on it) to 1e-10 of the
    # amplitude, the same multipliers to 1e-6 (central differences' truncation ~1e-12, round-off ~1e-10, grown by
    # the segments), in no more Newton steps; over one and over two periods
    s = system()
    for f, q in ((2.0, 1), (2.35, 2)):
        g = settled(s, f, 150, q=q)  # at 2.35 Hz the run settles on the period-doubled motion
        fd = shoot_friction(s, B, P, f, g, periods=q)
        ex = shoot_friction(s, B, P, f, g, periods=q, jacobian="exact")
        assert fd.converged and ex.converged and ex.n_iter <= fd.n_iter, (fd.message, ex.message)
        assert np.max(np.abs(fd.nodes - ex.nodes) / fd.scale) < 1e-10
        assert np.max(np.abs(np.sort_complex(fd.multipliers) - np.sort_complex(ex.multipliers))) < 1e-6
        if q == 2:  # a genuine 2T orbit: its two halves differ
            assert np.max(np.abs(ex.nodes[:8, :4] - ex.nodes[8:, :4]) / ex.scale[:4]) > 1e-2
