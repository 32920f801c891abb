"""The NNM study's shortcuts (issue 28): the same numbers as the paths they shortcut, or, for the block
elimination of the bordered HB systems, the same solution as the dense LU to round-off.

Exact shortcuts are checked for equality to the last bit (``np.array_equal``; the buffered dF/dX may differ
from the contraction only in the sign of its zeros, which ``array_equal`` does not see and which no sum with
a nonzero term keeps): a continuation's step path follows the last bits of its solves, so any other change
would move the committed results of discrete-fep and rom-fep.
"""

from __future__ import annotations

import numpy as np
import pytest

import reduced.periodic.hb as hbm
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem, two_sided_stops
from reduced.periodic.backbones import _nnm_start, nnm_branch
from reduced.periodic.continuation import _corrector_tangent, tangent
from reduced.periodic.hb import _lu_solve, newton
from reduced.periodic.shooting import conservative
from reduced.transient.flow import Flow

DISCRETE = conservative(DiscreteParams().system())


def _chain(n: int = 8) -> GapSystem:
    """A free-free chain of n unit masses on springs to ground, two-sided stops on its end masses (unit rows,
    as a reduced model's tips): the structure the block elimination needs (n - 2 >= 2 x 2 coordinates free)."""
    k = 1e4
    K = np.diag(np.full(n, 2 * k + 1e3)) - k * (np.eye(n, k=1) + np.eye(n, k=-1))
    rows = np.zeros((2, n))
    rows[0, 0] = rows[1, n - 1] = 1.0
    stops = two_sided_stops(rows, 1e7, 1e-3, ("a", "b"))
    return GapSystem(M=np.diag(np.linspace(1.0, 2.0, n)), C=np.zeros((n, n)), K=K,
                     dof_names=tuple(f"x{i}" for i in range(n)), **stops)


CHAIN = _chain()


def _in_contact(system: GapSystem, H: int, mode: int = 0):
    """(residual, y, J = [dR/dy; t], r) at a point well past grazing (a tenth of the samples in contact or
    more), with a fixed random t and r, and a small artificial damping d so that every term is there."""
    res, y, _ = _nnm_start(system, mode, H, None, None)
    y = y.copy()
    y[-1] += 1.0  # 10 x the start amplitude: 3 x the grazing one
    y[res.hb.size + 1] = 1e-7
    R, jac = res.lazy(y)
    rng = np.random.default_rng(3)
    t = rng.standard_normal(y.size)
    return res, y, np.vstack([jac(), t / np.linalg.norm(t)]), rng.standard_normal(y.size)


@pytest.mark.parametrize("system", [CHAIN, DISCRETE], ids=["chain", "3-dof"])
def test_buffered_force_jacobian_is_the_contraction(system):
    res, y, _, _ = _in_contact(system, 9)
    Psi, _, _, a = res.split(y)
    _, w = res.hb.force(res.hb.E @ res.hb.unpack(a * Psi))
    assert w.any() and res._force_pattern is not None
    ref = res.hb._aft_jacobian(w)
    assert np.array_equal(res._force_jacobian(w), ref)
    assert np.array_equal(res._force_jacobian(np.zeros_like(w)), np.zeros_like(ref))  # and cleared again
    assert np.array_equal(res._force_jacobian(w), ref)


def test_stops_on_combined_coordinates_take_the_contraction():
    rows = np.zeros((2, 8))
    rows[0, :2] = 0.5, 0.5  # a tip between two masses: Q holds 0.25, not only zeros and ones
    rows[1, 7] = 1.0
    s = CHAIN
    chain = GapSystem(M=s.M, C=s.C, K=s.K, dof_names=s.dof_names, **two_sided_stops(rows, 1e7, 1e-3, ("a", "b")))
    res, _, _, _ = _in_contact(chain, 3)
    assert res._force_pattern is None and res.bordered_solver is None


def test_omega_blocks_are_made_again_only_for_a_new_omega():
    res, y, _, _ = _in_contact(CHAIN, 5)
    fresh, _, _ = _nnm_start(CHAIN, 0, 5, None, None)
    w = y[res.hb.size] * res.omega_ref
    for omega in (w, 1.3 * w, 1.3 * w, w):
        A, dA = (m.copy() for m in res._linear_parts(omega))
        assert np.array_equal(A, res.hb.linear_operator(omega))
        assert np.array_equal(dA, res.hb._linear_operator_domega(omega))
        A2, dA2 = fresh._linear_parts(omega)
        assert np.array_equal(A, A2) and np.array_equal(dA, dA2)
        fresh = _nnm_start(CHAIN, 0, 5, None, None)[0]  # a new residual each time: its buffers start empty


def test_energy_from_the_residual_samples_is_the_energy():
    res, y, _, _ = _in_contact(CHAIN, 5)
    _, _, x, f = res._lazy(y)
    E, grad = res._energy_lazy(y, x, f)
    E_ref, g_ref = res.energy_and_gradient(y)
    assert E == E_ref and np.array_equal(grad(), g_ref)


def test_block_elimination_solves_the_bordered_system(monkeypatch):
    res, y, J, r = _in_contact(CHAIN, 15)
    dense = np.linalg.solve(J, r)
    assert res._block_plan is not None and res.bordered_solver is not None

    def no_dense(*_):
        raise AssertionError("the dense LU was taken")

    monkeypatch.setattr(hbm, "_lu_solve", no_dense)
    z = res.solve_bordered(J, r)
    # both are backward stable: residuals at round-off (1e-14 of |J| |z|), and the solutions agree to within
    # the condition number times that
    assert np.max(np.abs(J @ z - r)) <= 1e-14 * np.max(np.abs(J)) * np.max(np.abs(z))
    cond = np.linalg.cond(J)
    assert np.max(np.abs(z - dense)) <= 1e-14 * cond * np.max(np.abs(dense)), cond


def test_block_elimination_falls_back_to_the_dense_lu(monkeypatch):
    res, _, J, r = _in_contact(CHAIN, 15)
    monkeypatch.setattr(hbm, "BLOCK_SOLVE_TOL", 0.0)  # no residual is small enough: the check refuses
    assert np.array_equal(res.solve_bordered(J, r), _lu_solve(J, r))
    Js = J.copy()
    F0 = res._block_plan[0]
    Js[np.ix_(F0, F0)] = 0.0  # a singular block (the whole matrix is singular too): the dense LU's answer
    with np.errstate(all="ignore"):
        assert np.array_equal(res.solve_bordered(Js, r), _lu_solve(Js, r), equal_nan=True)


def test_below_the_block_harmonics_and_on_the_3dof_model_the_dense_lu_is_kept():
    assert _in_contact(CHAIN, hbm.BLOCK_SOLVE_MIN_H - 1)[0].bordered_solver is None
    assert _in_contact(DISCRETE, 25)[0].bordered_solver is None  # 1 free coordinate against 2 tips


def test_newton_without_the_final_jacobian_takes_the_same_steps():
    res, y, _, _ = _in_contact(DISCRETE, 3)
    i_a = res.hb.size + 2

    def fixed(z):
        R, jac = res.lazy(z)
        e = np.zeros(z.size)
        e[i_a] = 1.0
        return np.concatenate([R, [z[i_a] - y[i_a]]]), lambda: np.vstack([jac(), e])

    a = newton(fixed, y)
    b = newton(fixed, y, final_jacobian=False)
    assert np.array_equal(a.y, b.y) and a.n_iter == b.n_iter and b.jacobian is None
    assert a.jacobian.shape == (y.size, y.size)


def test_corrector_tangent_is_the_stacked_tangent():
    _, _, J, _ = _in_contact(DISCRETE, 3)
    t = J[-1]
    assert np.array_equal(_corrector_tangent(J, t), tangent(J[:-1], t))
    other = t.copy()
    other[0] += 1.0  # not the corrector's row: stacked as before
    assert np.array_equal(_corrector_tangent(J, other), tangent(J[:-1], other))


def test_flow_jacobian_of_a_flow_without_it_is_its_jacobian():
    flow = Flow(DISCRETE)
    g = DiscreteParams().gap
    x0, v0 = np.array([3 * g, 0.5 * g, -2 * g]), np.zeros(3)
    fl = flow(x0, v0, 0.02)
    assert fl.jacobian is None and fl.n_events >= 4  # impacts: several contact states multiplied
    ref = flow(x0, v0, 0.02, jacobian=True)
    assert np.array_equal(flow.jacobian_of(fl), ref.jacobian)
    assert flow.jacobian_of(ref) is ref.jacobian


def test_a_given_one_harmonic_backbone_is_the_one_continued_at_the_tongue():
    # NNM 1 of the 3-DOF model at H = 3 meets its 3:1 tongue near 1.6 J (results/discrete-fep/tongues.csv)
    one = nnm_branch(DISCRETE, 0, H=1, energy_max_J=10.0)
    a = nnm_branch(DISCRETE, 0, H=3, energy_max_J=10.0)
    b = nnm_branch(DISCRETE, 0, H=3, energy_max_J=10.0, backbone1=one.branches[0].y)
    assert [t["action"] for t in a.tongues] == ["stepped over"]
    assert np.array_equal(a.X, b.X) and np.array_equal(a.energy_J, b.energy_J) and a.tongues == b.tongues
    with pytest.raises(ValueError, match="backbone1"):
        nnm_branch(DISCRETE, 0, H=3, backbone1=one.branches[0].y[:, :4])


def _full_sum_rows(res, y) -> np.ndarray:
    """dR/dy's HB block as the jacobian summed it before :meth:`NNMResidual._hb_rows`: (A + dF - delta omega
    kron(Nab, M) on its blocks) / omega_ref^2 over the whole matrix."""
    hb = res.hb
    Psi, omega, delta, a = res.split(y)
    _, w = hb.force(hb.E @ hb.unpack(a * Psi))
    dF = res._force_jacobian(w).copy()
    A, _, DM = res._linear(omega)
    Jx = A + dF
    if delta != 0.0:
        for rows, cols in res._dm_blocks:
            Jx[rows, cols] -= delta * omega * DM[rows, cols]
    Jx /= res.omega_ref**2
    return Jx


@pytest.mark.parametrize("system", [CHAIN, DISCRETE], ids=["chain", "3-dof"])
def test_hb_rows_summed_where_they_are_not_zero_are_the_full_sums_bits(system):
    # the jacobian's HB block from the sums on the blocks and the pattern alone, against the full sums, to the
    # bit and to the sign of every zero (int64 views): in contact with damping d, the same point without it (the
    # kron(Nab, M) blocks written back), a point with every stop open (dF zero), a new omega, d again
    res, y, _, _ = _in_contact(system, 9)
    nX = res.hb.size
    y_open = y.copy()
    y_open[-1] -= 3.0  # a thousandth of the amplitude: every stop open
    y_far = y.copy()
    y_far[nX] *= 1.07
    y0 = y.copy()
    y0[nX + 1] = 0.0
    points = (y, y0, y_open, y_far, y, y0)
    for z in points:
        got = res.lazy(z)[1]()[:nX, :nX]
        ref = _full_sum_rows(res, z)
        assert np.array_equal(got.view(np.int64), ref.view(np.int64))
    assert getattr(res._scratch, "T", None) is not None  # the summed path was taken
    assert np.any(_full_sum_rows(res, y) != _full_sum_rows(res, y0))  # d changes the kron(Nab, M) blocks
