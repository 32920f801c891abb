"""The exact FRC's continuation with its Python overhead cut (issues 25 and 28) gives the numbers it gave before.

Newton's LU by LAPACK's getrf/getrs directly (``reduced.periodic.hb._lu_solve``), the symmetry's state
mirror built once, the shooting scales filled in place and the image points of a family made for all its
points at once (``reduced.periodic.exact_frc._image_points``) are the same arithmetic as before, so the
families are the same to the last bit on one machine: each piece is checked against the code it replaced,
and the families of the gap oscillator of tests/test_exact_frc.py against the numbers the code before the
change wrote (main at 4c06275).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import lu_factor, lu_solve

from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.periodic.exact_frc import ExactFRCOptions, Symmetry, _image_points, _images, exact_frc, hb_start
from reduced.periodic.forced_shooting import ForcedFlow, ShootingResidual
from reduced.periodic.hb import _lu_solve

K = (2 * np.pi * 10.0) ** 2  # N/m, m = 1 kg: 10 Hz (the gap oscillator of tests/test_exact_frc.py)
ZETA, RATIO, GAP, LOAD = 0.02, 20.0, 1e-3, 2.0

# (kind, points, frequency Hz, largest |mu| and amplitude m at the middle point, status) of each family, as the
# code before the change computed them (main at 4c06275, this machine)
BEFORE = [("main", 346, 36.96341925247597, 0.9754112235441645, 0.003475119567766879, "stop"),
          ("half_wave_broken", 32, 8.141217618326332, 1.6497541946192527, 0.0010867677044211323, "rejoined"),
          ("period_doubled", 15, 7.899547864033774, 7.0187701145373325, 0.0010717007852601938, "rejoined")]
# another CPU's SIMD kernels round sums differently (~1e-15 relative per operation): points of the same path
# agree to ~1e-12 after hundreds of steps, while a path that took another step differs by the step (~1e-3)
PATH_RTOL = 1e-9


@pytest.mark.parametrize("p", [1, 6, 49, 193])
def test_lu_solve_is_scipys_lu_solve_bit_for_bit(p):
    rng = np.random.default_rng(p)
    J = rng.standard_normal((p, p))
    R = rng.standard_normal(p)
    ref = lu_solve(lu_factor(J, check_finite=False), R, check_finite=False)
    assert np.array_equal(_lu_solve(J, R), ref)
    assert np.array_equal(_lu_solve(np.asfortranarray(J), R), ref)  # the layout does not matter
    # the residual of the solve is at round-off (a wrong solve would not be)
    assert np.max(np.abs(J @ ref - R)) < 1e-10 * np.max(np.abs(J)) * np.max(np.abs(ref)) * p


def test_lu_solve_of_a_singular_jacobian_is_not_finite_and_bad_shapes_raise():
    # Newton reads a non-finite step as a singular Jacobian (NewtonError), as before
    assert not np.all(np.isfinite(_lu_solve(np.zeros((3, 3)), np.ones(3))))
    with pytest.raises(ValueError):
        _lu_solve(np.eye(3), np.ones(2))
    # complex or 2-D right-hand sides go through scipy as before
    J = np.eye(2) * (1 + 1j)
    assert np.allclose(_lu_solve(J, np.ones(2, complex)), np.ones(2) / (1 + 1j))


def test_state_mirror_is_built_once_and_read_only():
    R = np.eye(3)[::-1].copy()
    sym = Symmetry(R, True)
    Rs = sym.state_mirror()
    assert Rs is sym.state_mirror()
    assert np.array_equal(Rs, np.kron(np.eye(2), R))
    assert not Rs.flags.writeable
    assert Symmetry(None, True).state_mirror() is None


class _Flow:
    n = 3


@pytest.mark.parametrize("periods, S, omega_v", [(1, 8, None), (2, 16, None), (1, 8, 5000.0)])
def test_image_points_are_the_images_point_by_point(periods, S, omega_v):
    res = ShootingResidual(_Flow(), S, periods, 2.5e-4, 120.0, omega_v)
    sym = Symmetry(np.eye(3)[::-1].copy(), True)
    rng = np.random.default_rng(S + periods)
    nodes = rng.standard_normal((7, S, 6))
    omega = rng.uniform(60.0, 200.0, 7)
    new = _image_points(res, nodes, omega, periods, sym)
    per_point = [_images(nd, periods, sym) for nd in nodes]
    old = [np.array([res.point(p[m], w) for p, w in zip(per_point, omega, strict=True)])
           for m in range(len(per_point[0]))]
    assert len(new) == len(old) == 4 * periods  # shifts x half-wave x mirror
    for a, b in zip(new, old, strict=True):
        assert np.array_equal(a, b)


def test_scale_is_the_concatenated_scale():
    res = ShootingResidual(_Flow(), 8, 1, 2.5e-4, 120.0)
    for w in (100.0, 100.0, 150.0):
        c = math.sqrt(8) * 2.5e-4
        assert np.array_equal(res.scale(w), np.concatenate([np.full(3, c), np.full(3, w * c)]))


def test_gap_oscillator_families_are_those_before_the_change():
    s = GapSystem(M=np.eye(1), C=2 * ZETA * math.sqrt(K) * np.eye(1), K=K * np.eye(1), dof_names=("x",),
                  **two_sided_stops(np.eye(1), RATIO * K, GAP, ("x",)))
    b = np.ones(1)
    opts = ExactFRCOptions(max_families=3, depth=2)
    with single_thread_blas():
        ex = exact_frc(s, b, LOAD, 3.0, 40.0, hb_start(s, b, LOAD, 3.0, opts.segments), x_ref=GAP, options=opts)
    assert len(ex.families) == len(BEFORE)
    for fam, (kind, k, f, mu, amp, status) in zip(ex.families, BEFORE, strict=True):
        assert (fam.kind, len(fam.freq_hz), fam.status) == (kind, k, status)
        i = k // 2
        got = np.array([fam.freq_hz[i], np.abs(fam.multipliers[i, 0]), fam.amplitude_m[i, 0]])
        assert np.allclose(got, [f, mu, amp], rtol=PATH_RTOL, atol=0.0), (kind, got)
    # the orbit of the middle point closes on itself on the exact flow (a periodic orbit, not just the old numbers)
    fam = ex.main
    res = ShootingResidual(ForcedFlow(s, b, LOAD), fam.nodes.shape[1], 1, GAP, 2 * np.pi * 40.0)
    i = len(fam.freq_hz) // 2
    assert np.max(np.abs(res(res.point(fam.nodes[i], fam.omega[i]))[0])) < 1e-9


def _gap_residual():
    s = GapSystem(M=np.eye(1), C=2 * ZETA * math.sqrt(K) * np.eye(1), K=K * np.eye(1), dof_names=("x",),
                  **two_sided_stops(np.eye(1), RATIO * K, GAP, ("x",)))
    return ShootingResidual(ForcedFlow(s, np.ones(1), LOAD), 8, 1, GAP, 2 * np.pi * 40.0)


def test_jacobian_made_in_the_bordered_matrix_is_the_stacked_one():
    # the corrector's [dR/dY; t] made in place (stacks_below) has the bits of np.vstack([dR/dY, t]), and the
    # memoised dR/dY (its top rows) is the one a plain call gives
    res = _gap_residual()
    rng = np.random.default_rng(3)
    Y = np.append(rng.standard_normal(res.size) * 0.3, math.log(0.5))  # 20 Hz, orbits through the stops
    t = rng.standard_normal(res.size + 1)
    ref = _gap_residual()(Y)[1]
    R, jac = res.lazy(Y)
    assert jac.stacks_below
    Jb = jac(below=t)
    assert Jb.shape == (res.size + 1, res.size + 1)
    assert np.array_equal(Jb, np.vstack([ref, t]))
    assert np.array_equal(res(Y)[1], ref)  # memoised: the top rows, unchanged
    hit = res.lazy(Y)[1]  # memo hit: dR/dY alone, which the corrector stacks itself as before
    assert not getattr(hit, "stacks_below", False) and np.array_equal(hit(), ref)
    assert np.any(ref[:, :-1] != 0.0) and np.all(np.isfinite(ref))  # a real Jacobian, not an empty buffer


def _retrace_brute(Y, T, s, y, t, s_y):
    """The retrace test of _Retrace.add over every earlier point (no tree, no prefilter)."""
    from reduced.periodic.exact_frc import RETRACE_ARC, RETRACE_DIST

    far = s_y - s > RETRACE_ARC
    return bool(np.any(far & (np.linalg.norm(Y - y, axis=1) < RETRACE_DIST) & (T @ t > 0.9)))


def test_retrace_prefilter_finds_what_the_full_distances_find():
    # a path in 49 dimensions that goes out, turns and comes back over itself, then runs along its start again:
    # the unit-projection prefilter may only drop points the full distance would drop, so every answer is the
    # brute-force answer (the tree's random projections are the same as before: only the direct check changed)
    from reduced.periodic.exact_frc import _Retrace

    rng = np.random.default_rng(5)
    dim = 49
    u = rng.standard_normal(dim)
    u /= np.linalg.norm(u)
    w = rng.standard_normal(dim)
    w -= (w @ u) * u
    w /= np.linalg.norm(w)
    ang = np.linspace(0.0, 2.2 * np.pi, 1400)  # a circle of radius 2 (arclength ~27.6), passed over again
    Y = 2.0 * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w) + 1e-3 * rng.standard_normal((ang.size, dim))
    T = -np.sin(ang)[:, None] * u + np.cos(ang)[:, None] * w
    r = _Retrace(dim)
    s = np.zeros(len(Y))
    got, want = [], []
    for i, (y, t) in enumerate(zip(Y, T, strict=True)):
        s[i] = s[i - 1] + float(np.linalg.norm(y - Y[i - 1])) if i else 0.0
        want.append(_retrace_brute(Y[:i], T[:i], s[:i], y, t, s[i]))
        got.append(r.add(y, t))
    assert got == want
    assert sum(want) > 50 and not any(want[:1200])  # the second pass is seen, the first is not


def test_retrace_partial_sums_drop_only_points_beyond_the_distance():
    # _within keeps every candidate whose full squared distance is within r2 (whatever the order of its sum) and
    # drops only those beyond it: distances spread around the threshold, in 193 dimensions (rom-frc's unknowns)
    from reduced.periodic.exact_frc import RETRACE_DIST, RETRACE_MARGIN, _within

    rng = np.random.default_rng(11)
    dim, k = 193, 3000
    y = rng.standard_normal(dim)
    dirs = rng.standard_normal((k, dim))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dist = RETRACE_DIST * np.concatenate([rng.uniform(0.0, 3.0, k - 4), [1.0, 1.0 - 1e-14, 1.0 + 1e-14, 0.0]])
    Y = y + dist[:, None] * dirs
    cand = rng.permutation(k)[: k // 2 + 2]
    cand = np.concatenate([cand, [k - 4, k - 3, k - 2, k - 1]])
    kept = _within(Y, cand, y, (RETRACE_DIST + RETRACE_MARGIN) ** 2)
    full = np.linalg.norm(Y[cand] - y, axis=1)
    assert np.array_equal(kept, cand[full <= RETRACE_DIST + RETRACE_MARGIN])  # in the candidates' order
    assert set(cand[full < RETRACE_DIST]) <= set(kept) and not set(cand[full > 1.01 * RETRACE_DIST]) & set(kept)


def test_switch_tries_give_up_beyond_the_largest_step(monkeypatch):
    # every first-orbit Newton of a switch is bounded by SWITCH_MAX_STEP (a try that wanders off is given up), the
    # switched families of the gap oscillator are still found (the bound is far above their steps)
    import reduced.periodic.exact_frc as ef

    s = GapSystem(M=np.eye(1), C=2 * ZETA * math.sqrt(K) * np.eye(1), K=K * np.eye(1), dof_names=("x",),
                  **two_sided_stops(np.eye(1), RATIO * K, GAP, ("x",)))
    b = np.ones(1)
    seen, newton = [], ef.newton

    def bounded(fun, y0, **kw):
        seen.append(kw.get("max_step"))
        return newton(fun, y0, **kw)

    monkeypatch.setattr(ef, "_switch", lambda *a, **k: _switch_recording(ef, bounded, *a, **k))
    opts = ExactFRCOptions(max_families=1, depth=1, family_steps=20, period_doubling=False)
    with single_thread_blas():
        ex = exact_frc(s, b, LOAD, 3.0, 12.0, hb_start(s, b, LOAD, 3.0, opts.segments), x_ref=GAP, options=opts)
    assert seen and all(m == ef.SWITCH_MAX_STEP for m in seen)
    assert [f.kind for f in ex.families] == ["main", "half_wave_broken"]
    assert 0.1 < ef.SWITCH_MAX_STEP <= 1.0  # above the largest converged step seen (0.15), below the orbit's size


def _switch_recording(ef, bounded, *args, **kw):
    """ef._switch with its module's newton replaced by ``bounded`` for the call."""
    saved = ef.newton
    ef.newton = bounded
    try:
        return _SWITCH(*args, **kw)
    finally:
        ef.newton = saved


from reduced.periodic.exact_frc import _switch as _SWITCH  # noqa: E402  (the function itself, before any patch)
