"""Friction orbits continued in frequency by shooting on the exact friction flow
(reduced/periodic/friction_continuation.py, issue 27): against Den Hartog's closed-form continuous-slip response
along the branch, and against a long direct run of the exact integrator settling on a continued orbit."""

from __future__ import annotations

import math

import numpy as np
from test_friction import K_X, M_X, N_REST, Z_REST, coulomb, den_hartog

from reduced.models.loads import Harmonic, Loads
from reduced.periodic.friction_continuation import (
    SWITCH_SAME,
    bifurcations,
    continue_friction,
    joined,
    switch_branch,
)
from reduced.periodic.friction_shooting import shoot_friction
from reduced.transient.friction import integrate_exact_friction

MU, BETA0 = 0.3, 0.6
F = MU * N_REST  # N, the slip force
P = 4 * F  # N: continuous slip (two stops a period) over beta = 0.6 .. 0.8 (Den Hartog's condition holds)
FN = math.sqrt(K_X / M_X) / (2 * math.pi)  # Hz, the tangential natural frequency


def start(system, beta: float = BETA0):
    """A converged orbit at beta from a pure harmonic of Den Hartog's amplitude (as tests/test_friction_shooting)."""
    X, psi, _ = den_hartog(P, F, K_X, M_X, beta)
    w = 2 * math.pi * beta * FN
    tk = np.arange(8) / 8 / (beta * FN)
    g = np.zeros((8, 5))
    g[:, 0] = -X * np.cos(w * tk)
    g[:, 1] = Z_REST
    g[:, 2] = X * w * np.sin(w * tk)
    g[:, 4] = g[:, 0]
    r = shoot_friction(system, [1.0, 0.0], P, beta * FN, g, phase_deg=math.degrees(psi), multipliers=False)
    assert r.converged, r.message
    return r


def test_the_continued_coulomb_oscillator_follows_den_hartog():
    # Den Hartog's X(beta) = sqrt(a^2 - (F U / k)^2), a = P / (k (1 - beta^2)), at every continued frequency.
    # The Jenkins slider of stiffness kt = 1e10 N/m delays each reversal by ~sqrt(m / kt): the exact orbit differs
    # from Den Hartog's by ~2e-4 X (tests/test_friction_shooting.py fits the kt^-1/2 rate); measured 1.0e-4 ..
    # 1.6e-4 over beta = 0.6 .. 0.75 (6 steps), 3e-4 allowed. The orbits are stable (the tangential pair inside the unit
    # circle, the undamped normal pair on it: 1 + STABLE_TOL), the branch has no fold nor bifurcation, and every
    # point is a shooting solution to the corrector's tolerance.
    br = continue_friction(start(coulomb(MU, 1e10)), 0.5 * FN, 0.8 * FN, ds=0.5, max_steps=6,
                           point_rows=np.array([[1.0, 0.0]]))
    assert br.freq_hz[-1] > 0.7 * FN, (br.status, br.freq_hz)
    assert np.all(np.diff(br.freq_hz) > 0) and np.all(br.tangent_f > 0)
    X = np.array([den_hartog(P, F, K_X, M_X, f / FN)[0] for f in br.freq_hz])
    err = np.abs(br.amplitude_m[:, 0] / X - 1.0)
    assert np.max(err) < 3e-4, err
    assert np.all(br.stable) and br.bifurcations == []
    assert np.max(br.defect) < 1e-10


def test_a_long_direct_run_settles_on_the_continued_orbit():
    # With viscous damping (c = 2, zeta = 1 % on x) the continued orbit is attracting: the exact friction
    # integrator run from rest (the normal coordinate on its stop, the slider unloaded) for 60 periods at the
    # branch's last frequency (0.68 w_n) ends on it, an independent check of the continued orbit (one long run,
    # no shooting). The transient decays much faster than zeta alone would give (friction damps it): measured
    # 3e-7 of the amplitude after 20 periods, 2e-13 after 60; 1e-9 allowed for max |x| over the last period
    # (sampled on 400 points: the same samples of the orbit's own run would differ by (pi / 400)^2 / 2 = 3e-5 from
    # the continuous maximum, but both read the same grid phase) and for the state at t = 60 T against the
    # orbit's node at t = 0.
    s = coulomb(MU, 1e9, c=2.0)
    r = start(s)
    down = continue_friction(r, 0.5 * FN, 0.8 * FN, direction=-1.0, ds=0.5, max_steps=1)
    up = continue_friction(r, 0.5 * FN, 0.8 * FN, ds=0.5, max_steps=3)
    br = joined(down, up)
    assert len(br.freq_hz) == 5 and np.all(np.diff(br.freq_hz) > 0) and np.all(br.stable)
    f = float(br.freq_hz[-1])
    periods, spp = 60, 400
    run = integrate_exact_friction(s, np.array([0.0, Z_REST]), np.zeros(2), periods / f, spp * f,
                                   loads=Loads(np.array([[1.0, 0.0]]), (Harmonic(P, f, r.phase_deg),)))
    last = run.x[-spp - 1:, 0]
    A = br.amplitude_m[-1, 0]
    assert abs(np.max(np.abs(last)) / A - 1.0) < 1e-9, (np.max(np.abs(last)), A)
    y0 = br.nodes[-1, 0]  # the orbit's state at t = 0 mod T against the run's at its end (t = 60 T)
    assert abs(run.x[-1, 0] - y0[0]) < 1e-9 * A and abs(run.v[-1, 0] - y0[2]) < 1e-9 * A * 2 * math.pi * f


def test_the_bifurcations_are_read_from_the_multipliers():
    # a real multiplier through +1 with df/ds changing sign: a fold; without: a branch point; through -1: a
    # period doubling; a complex pair: Neimark-Sacker; any change where the rank moves (a tip opens for the
    # whole period): grazing, not a smooth bifurcation
    mu = np.array([[0.5, 0.2, 0.1], [1.5, 0.2, 0.1], [1.5, 0.2, 0.1], [2.5, 0.2, 0.1], [2.5, -1.2, 0.1],
                   [2.5, -1.2, 0.1], [0.5, 0.2, 0.1]], complex)
    mu[5, 1:] = [0.3 + 1.1j, 0.3 - 1.1j]
    tf = np.array([1.0, -1.0, -1.0, -1.0, -1.0, -1.0, -1.0])
    rank = np.array([9, 9, 9, 9, 9, 9, 8])
    assert bifurcations(mu[:4], tf[:4]) == [(1, "fold")]
    mu[3, 0] = 0.5
    got = bifurcations(mu, tf, rank)
    assert got == [(1, "fold"), (3, "branch_point"), (4, "branch_point"), (4, "period_doubling"),
                   (5, "period_doubling"), (5, "neimark_sacker"), (6, "grazing")], got
    # two real multipliers outside the circle meeting and leaving the axis as a pair outside it (and back): the
    # number outside does not change, nothing crosses: no bifurcation (on discrete-friction-frc such collisions
    # near 20.42 and 20.72 Hz were read as branch points before)
    pair = np.array([[3.0, 2.0, 0.1], [2.5 + 1j, 2.5 - 1j, 0.1], [3.0, 2.0, 0.1], [-3.0, -2.0, 0.1],
                     [-2.5 + 1j, -2.5 - 1j, 0.1]], complex)
    assert bifurcations(pair[:3], np.ones(3)) == [] and bifurcations(pair[3:], np.ones(2)) == []
    # a real one outside and one inside forming a pair outside: the number outside changes, reported
    assert bifurcations(np.array([[3.0, 0.5, 0.1], [2.5 + 1j, 2.5 - 1j, 0.1]]), np.ones(2)) == [
        (1, "branch_point"), (1, "neimark_sacker")]


def test_a_branch_that_turns_back_onto_its_own_path_ends_there():
    # _retrace: a new point within RETRACE_STEP x ds of an earlier point of its own (not its last RETRACE_SKIP
    # neighbours) ends the branch with the reason; a point a step away from all of them does not
    from reduced.periodic.friction_continuation import RETRACE_SKIP, RETRACE_STEP, _retrace

    path = [np.array([0.0, float(k)]) for k in range(6)]  # a straight path, one unit a step
    assert _retrace(path + [np.array([0.0, 6.0])], np.array([0.0, 6.0]), 1.0) is None
    back = np.array([0.2 * RETRACE_STEP, 1.0])  # past a fold, back near point 1
    why = _retrace(path + [back], back, 1.0)
    assert why is not None and "turned back onto its own orbit" in why and "point 1" in why
    # the last RETRACE_SKIP points are its own neighbours: no retrace on them
    near = np.array([0.0, 5.0 + 0.1])
    assert RETRACE_SKIP >= 2 and _retrace(path + [near], near, 1.0) is None


def test_branch_switching_finds_the_stuck_contact_s_other_orbits_and_none_beside_a_unique_one():
    # switch_branch: direct shooting at a point's frequency from the orbit perturbed along the critical eigenvector.
    # (1) A contact stuck the whole period (P = 0.05 mu N, far below the slip force) has a continuum of periodic
    # orbits: the stuck position w is set by the history, and each w is an orbit offset by
    # x - x0 = kt / (k + kt) (w - w0), constant over the period (closed form: the stuck system is linear), the
    # normal coordinate unchanged; its multiplier 1 (eigenvector moving x and w together) is the direction. The
    # switch must find an orbit off the branch (a "new family"), exact (defect at round-off) and offset as above:
    # measured spread of x - x0 over the period 1e-22 m against an offset 1e-9 m; 1e-6 of the offset allowed (the
    # exact flow's round-off on a 1e-10 m motion riding on a 1e-4 m normal coordinate). (2) Continuous slip (Den
    # Hartog) of a damped oscillator has one orbit at each frequency and no real multiplier through +1 or -1: the
    # switch is not run; a Neimark-Sacker point is not one to switch at.
    import dataclasses

    s = coulomb(MU, 1e9, c=2.0)
    g = np.zeros((8, 5))
    g[:, 1] = Z_REST
    stuck = shoot_friction(s, [1.0, 0.0], 0.05 * F, 0.6 * FN, g)
    assert stuck.converged and stuck.rank == stuck.size - 1
    br = continue_friction(stuck, 0.5 * FN, 0.8 * FN, ds=0.5, max_steps=2)
    sw = switch_branch(stuck, br, 1, "branch_point", continue_kw=dict(max_steps=1))
    assert sw.outcome == "new family", sw.outcome
    assert abs(sw.multiplier - 1.0) < 1e-9 and sw.distance > SWITCH_SAME
    assert sw.orbit.converged and sw.orbit.defect < 1e-12
    assert sw.branch is not None and len(sw.branch.freq_hz) == 3 and np.max(sw.branch.defect) < 1e-10
    prim = dataclasses.replace(stuck, nodes=br.nodes[sw.at], freq_hz=float(br.freq_hz[sw.at]))
    _, ya = sw.orbit.orbit(50)
    _, yb = prim.orbit(50)
    dx, dw = ya[:, 0] - yb[:, 0], ya[:, 4] - yb[:, 4]
    offset = float(np.mean(dx))
    assert abs(offset) > 1e-3 * np.max(np.abs(yb[:, 0])), offset  # a distinct orbit, not round-off
    assert np.ptp(dx) < 1e-6 * abs(offset) and np.ptp(dw) < 1e-6 * abs(offset)
    kt, k = 1e9, K_X
    assert abs(offset / float(np.mean(dw)) - kt / (k + kt)) < 1e-6
    assert np.max(np.abs(ya[:, 1] - yb[:, 1])) < 1e-6 * abs(offset)

    r = start(s)
    slip = continue_friction(r, 0.5 * FN, 0.8 * FN, ds=0.5, max_steps=2)
    for kind in ("fold", "period_doubling"):
        assert switch_branch(r, slip, 1, kind).outcome.startswith("not run: no real multiplier"), kind
    assert switch_branch(r, slip, 1, "neimark_sacker").outcome.startswith("not run")
