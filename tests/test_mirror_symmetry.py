"""The tip mirror of a gap system in any coordinates (reduced.models.symmetry).

The three-mass model is written in Craig-Bampton-like coordinates q = [x1, x3, eta] (x2 = psi1 x1 +
psi3 x3 + eta, the interior DOF on its constraint modes), as the reduced 3-D model is. There the mirror
is no longer the reversal of the DOFs; :func:`tip_mirror` must find it, and the forced-response
continuation must then see the same bifurcations, of the same symmetry kinds, as in the physical
coordinates, where the reversal is the mirror (without the mirror, it sees no pitchfork breaking x1 = x3).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_frc_cover import BAND, F_ISO, SEED_ISO, X_REF, P  # noqa: E402

from reduced._blas import single_thread_blas  # noqa: E402
from reduced.models.discrete import DiscreteParams  # noqa: E402
from reduced.models.gaps import GapSystem, two_sided_stops  # noqa: E402
from reduced.models.symmetry import mirror_error, symmetrized, tip_mirror  # noqa: E402
from reduced.periodic.exact_frc import ExactFRCOptions, exact_frc, find_symmetry  # noqa: E402

B = np.array([0.0, 1.0, 0.0])


def _cb():
    """(system in q = [x1, x3, eta], b in q, T with x = T q)."""
    s = DiscreteParams().system()
    T = np.zeros((3, 3))
    T[0, 0] = T[2, 1] = T[1, 2] = 1.0
    T[1, :2] = -s.K[1, [0, 2]] / s.K[1, 1]  # the constraint modes' x2

    def tr(A):
        return T.T @ A @ T

    cb = replace(s, M=tr(s.M), K=tr(s.K), C=tr(s.C), B=s.B @ T, dof_names=("x1", "x3", "eta1"))
    return cb, T.T @ B, T


def test_the_mirror_of_the_three_mass_model_is_the_reversal():
    s = DiscreteParams().system()
    R, err = tip_mirror(s, B)
    assert np.array_equal(R, np.eye(3)[::-1]) and err == 0.0


def test_the_mirror_in_craig_bampton_coordinates_swaps_the_tips_and_keeps_eta():
    cb, b, _ = _cb()
    R, err = tip_mirror(cb, b)
    assert np.array_equal(R, np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, 1]])) and err < 1e-15
    assert find_symmetry(cb, b).mirror is None  # the reversal is not the mirror here
    assert find_symmetry(cb, b, R).mirror is not None


def _chain_cb():
    """A symmetric chain x1 - a - c - x3 (springs 1e6, 2e6, 1e6, ground 5e4 at every mass) in q = [x1, x3,
    eta_1, eta_2], the interior (a, c) on its fixed-interface modes (one symmetric, one antisymmetric)
    and its constraint modes; and those two modes' signs under a <-> c (from their shapes)."""
    m = np.array([0.5, 1.0, 1.0, 0.5])  # x1, a, c, x3
    k = np.array([1e6, 2e6, 1e6])
    K = np.diag(np.full(4, 5e4))
    for i, kk in enumerate(k):
        K[i:i + 2, i:i + 2] += kk * np.array([[1.0, -1.0], [-1.0, 1.0]])
    M = np.diag(m)
    bnd, inner = [0, 3], [1, 2]
    w2, Phi = np.linalg.eigh(K[np.ix_(inner, inner)])  # M_ii = I
    Psi = -np.linalg.solve(K[np.ix_(inner, inner)], K[np.ix_(inner, bnd)])
    T = np.zeros((4, 4))
    T[0, 0] = T[3, 1] = 1.0
    T[np.ix_(inner, [0, 1])] = Psi
    T[np.ix_(inner, [2, 3])] = Phi
    signs = np.sign(np.einsum("ij,ij->j", Phi[::-1], Phi))  # a <-> c maps each mode to +-itself
    rows = np.zeros((2, 4))
    rows[0, 0] = rows[1, 1] = 1.0
    def sym(A):
        A = T.T @ A @ T
        return (A + A.T) / 2

    s = GapSystem(M=sym(M), C=1e-4 * sym(K), K=sym(K), dof_names=("x1", "x3", "eta1", "eta2"),
                  **two_sided_stops(rows, 1e8, 1e-4, ("x1", "x3")))
    return s, T, signs


def test_an_antisymmetric_mode_changes_sign_under_the_mirror():
    # the signs come from the coordinates' coupling to the tips; the modes' shapes say the same
    s, T, signs = _chain_cb()
    assert sorted(signs) == [-1.0, 1.0]
    b = T.T @ np.array([0.0, 1.0, 1.0, 0.0])  # equal forces on a and c: symmetric
    R, err = tip_mirror(s, b)
    assert R is not None and err < 1e-14
    assert np.array_equal(np.diag(R)[2:], signs) and R[0, 1] == R[1, 0] == 1.0
    # a load on a alone breaks the mirror
    assert tip_mirror(s, T.T @ np.array([0.0, 1.0, 0.0, 0.0])) == (None, np.inf)


def test_round_off_asymmetry_is_accepted_and_averaged_out():
    cb, b, _ = _cb()
    R, _ = tip_mirror(cb, b)
    rng = np.random.default_rng(1)
    E = rng.standard_normal((3, 3))
    noisy = replace(cb, K=cb.K + 3e-11 * np.max(np.abs(cb.K)) * (E + E.T) / 2)
    R2, err = tip_mirror(noisy, b)
    assert np.array_equal(R2, R) and 1e-12 < err < 1e-10  # a reduced 3-D model's round-off: 4e-11
    assert find_symmetry(noisy, b, R).mirror is None  # at round-off (1e-12) the mirror is not seen ...
    s2, b2 = symmetrized(noisy, b, R)
    assert mirror_error(s2, b2, R) == 0.0 and find_symmetry(s2, b2, R).mirror is not None  # ... averaged, it is
    assert np.max(np.abs(s2.K - noisy.K)) < 1e-10 * np.max(np.abs(cb.K))
    # a real asymmetry (a tip mass 0.1 % heavier) is refused
    M = cb.M.copy()
    M[0, 0] *= 1.001
    assert tip_mirror(replace(cb, M=M), b) == (None, np.inf)


@pytest.mark.parametrize("with_mirror", [True, False])
def test_continuation_in_craig_bampton_coordinates_sees_the_mirror_pitchforks(with_mirror):
    # the family through the isolated orbit of discrete-frc at 10 N (21.4-23.1 Hz): 9 pitchforks, 6 of
    # them breaking x1 = x3; the same family in q = [x1, x3, eta] with the mirror tip_mirror finds has the
    # same pitchforks in the same order, each between points that bracket the same frequency
    s = DiscreteParams().system()
    cb, b, T = _cb()
    n = 3
    Ti = np.linalg.inv(T)
    seed_q = np.hstack([SEED_ISO[:, :n] @ Ti.T, SEED_ISO[:, n:] @ Ti.T])
    opts = ExactFRCOptions(branch_switching=False, cover_families=0, max_steps=40)
    with single_thread_blas():
        phys = exact_frc(s, B, P, *BAND, [(F_ISO, SEED_ISO)], x_ref=X_REF, point_rows=np.eye(3), options=opts)
        q = exact_frc(cb, b, P, *BAND, [(F_ISO, seed_q)], x_ref=X_REF, point_rows=T, options=opts,
                      mirror=tip_mirror(cb, b)[0] if with_mirror else None)
    fp, fq = phys.families[0], q.families[0]
    kp, kq = [k for _, k in fp.bifurcations], [k for _, k in fq.bifurcations]
    mirror_kinds = {"pitchfork_mirror", "pitchfork_mirror_half_wave"}
    assert sum(k in mirror_kinds for k in kp) == 6
    if not with_mirror:  # the old call: the reversal is no symmetry of q, so no pitchfork breaks x1 = x3
        assert q.symmetry.mirror is None and not mirror_kinds & set(kq)
        return
    # the pitchforks (the Neimark-Sacker points, where a pair of multipliers sits on the unit circle within the
    # stability tolerance, come and go with the sampling; a fold and a pitchfork at one point are either order)
    pk = [(i, k) for i, k in fp.bifurcations if k.startswith("pitchfork")]
    qk = [(i, k) for i, k in fq.bifurcations if k.startswith("pitchfork")]
    assert [k for _, k in pk] == [k for _, k in qk], (kp, kq)
    # each found between two points whose frequencies bracket it: the brackets meet (within 0.04 Hz)
    for (i, _), (j, _) in zip(pk, qk, strict=True):
        a = sorted(fp.freq_hz[[i - 1, i]])
        c = sorted(fq.freq_hz[[j - 1, j]])
        assert a[0] - 0.04 <= c[1] and c[0] - 0.04 <= a[1], (a, c)


def test_committed_rom_frc_has_families_breaking_the_mirror():
    # results/rom-frc (the reduced beam, averaged over its tip mirror): pitchforks breaking x1 = x3 are classified
    # and followed at both contact levels, and frc.md says how the model was made exactly symmetric
    import csv

    root = Path(__file__).resolve().parents[1] / "results" / "rom-frc"
    fams = list(csv.DictReader(open(root / "frc_families.csv")))
    for level in ("1.0", "10.0"):
        kinds = {r["kind"] for r in fams if r["level"] == level}
        assert {"asymmetric", "asymmetric_half_wave"} <= kinds, (level, kinds)
    bif = {r["kind"] for r in csv.DictReader(open(root / "frc_bifurcations.csv"))}
    assert {"pitchfork_mirror", "pitchfork_mirror_half_wave"} <= bif
    assert "The model is mirror symmetric (x1 <-> x3, with eta2, eta4, eta6, eta8, eta10 -> minus itself)" in (
        root / "frc.md").read_text("utf-8")
