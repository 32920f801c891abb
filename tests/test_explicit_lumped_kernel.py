"""The central difference's lumped kernel (reduced.transient._cd_lumped: diagonal M and C, each stop on one
coordinate) against the register kernel (reduced.transient._cd._cd_small) it replaces for such models: the zero
terms left out change no bit, signs of zeros included (from rest, x0 = 0 exactly, the zeros' signs are checked);
and a model that is not lumped keeps the register kernel."""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient import _cd, _cd_lumped, explicit
from reduced.transient.explicit import integrate_explicit

FS = 20000.0


def _lumped(n: int, damped: bool = True, coupled_mass: bool = False) -> GapSystem:
    """n masses in a ring (springs between neighbours, first to last and to ground), diagonal dashpots, stops above
    and below
    the first and the last mass, the lower ones with their rows negated (B_j = -e_i, side +1: the same stop)."""
    M = np.diag(np.linspace(1.0, 2.0, n))
    if coupled_mass and n > 1:
        M[0, 1] = M[1, 0] = 0.1
    K = np.zeros((n, n))
    for i in range(n):
        K[i, i] += 1e4 * (i + 1)
        if i + 1 < n:
            K[i, i] += 5e3
            K[i + 1, i + 1] += 5e3
            K[i, i + 1] = K[i + 1, i] = -5e3
    if n > 2:  # a spring from the first to the last mass: K full, every term of the rows counts
        K[0, 0] += 2e3
        K[-1, -1] += 2e3
        K[0, -1] = K[-1, 0] = -2e3
    C = np.diag(np.linspace(2.0, 3.0, n)) if damped else np.zeros((n, n))
    tips = [0, n - 1]
    B = np.zeros((4, n))
    side = np.ones(4)
    for j, t in enumerate((0, 0, 1, 1)):
        B[j, tips[t]] = 1.0
    B[3, tips[1]] = -1.0  # a lower stop written as an upper one on the negated row
    side[1] = -1.0
    gap = 2e-4
    return GapSystem(M=M, C=C, K=K, B=B, k=np.array([3e6, 2e6, 3e6, 4e6]), offset=np.array([gap, -gap, gap, gap]),
                     side=side, tip=np.array([0, 0, 1, 1]), dof_names=tuple(f"q{i}" for i in range(n)),
                     stop_names=("u0", "l0", "u1", "l1"))


def _both(monkeypatch, *args, **kw):
    """(lumped kernel's run, register kernel's run) of integrate_explicit(*args, **kw), and which kernel ran."""
    ran = []
    real = _cd_lumped.cd_lumped

    def spy(*a):
        ran.append(True)
        return real(*a)

    with monkeypatch.context() as m:
        m.setattr(_cd_lumped, "cd_lumped", spy)
        m.setattr(explicit, "_SETUP", {})  # no kernel kept from another run
        lumped = integrate_explicit(*args, **kw)
    with monkeypatch.context() as m:
        m.setattr(explicit, "LUMPED", False)
        small = integrate_explicit(*args, **kw)
    return lumped, small, bool(ran)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("n, damped", [(2, True), (3, True), (3, False)])
def test_lumped_kernel_is_the_register_kernel_bit_for_bit(monkeypatch, n, damped):
    # Blows at the first and the last mass from x = 0, through impacts on both tips' stops (asserted), 0.1 s.
    s = _lumped(n, damped)
    v0 = np.zeros(n)
    v0[0] = -0.3
    v0[-1] = 0.5
    lumped, small, ran = _both(monkeypatch, s, np.zeros(n), v0, 0.1, FS)
    assert ran
    assert np.abs(small.x[:, -1]).max() > 2e-4 and np.abs(small.x[:, 0]).max() > 2e-4  # both tips' stops hit
    assert np.any(small.x == 0.0)  # zeros whose signs are compared
    for name in ("x", "v", "dissipated"):
        assert _same_bits(getattr(lumped, name), getattr(small, name)), name


def test_forced_lumped_kernel_is_the_register_kernel_bit_for_bit(monkeypatch):
    s = _lumped(3)
    b = np.zeros((1, 3))
    b[0, 1] = 1.0
    loads = Loads(b, (Harmonic(300.0, 40.0),), ("q1",))
    lumped, small, ran = _both(monkeypatch, s, np.zeros(3), np.zeros(3), 0.1, FS, loads=loads)
    assert ran and np.abs(small.x).max() > 2e-4
    for name in ("x", "v", "dissipated", "external"):
        assert _same_bits(getattr(lumped, name), getattr(small, name)), name


def test_a_model_that_is_not_lumped_keeps_the_register_kernel(monkeypatch):
    # A coupled mass matrix makes A and G full: lumped_form refuses it, the register kernel runs.
    s = _lumped(3, coupled_mass=True)
    lumped, small, ran = _both(monkeypatch, s, np.zeros(3), np.array([0.0, 0.0, 0.5]), 0.02, FS)
    assert not ran
    assert _same_bits(lumped.x, small.x)


def test_more_than_two_stops_on_a_coordinate_keep_the_register_kernel(monkeypatch):
    # One mass: all four stops on its coordinate, past the lumped kernel's two slots a column.
    s = _lumped(1)
    lumped, small, ran = _both(monkeypatch, s, np.zeros(1), np.array([0.5]), 0.05, FS)
    assert not ran
    assert _same_bits(lumped.x, small.x) and np.abs(small.x).max() > 2e-4


def test_lumped_form_refuses_a_stop_on_two_coordinates():
    S = _cd.SMALL_N
    B = np.array([[1.0, 0.5, 0.0]])
    args = (np.eye(S), np.eye(S), B.copy(), np.eye(S), B, np.array([1e-4]), np.array([1.0]), np.array([1e6]))
    assert _cd_lumped.lumped_form(*args) is None
    B1 = np.array([[0.0, 2.0, 0.0]])
    form = _cd_lumped.lumped_form(np.eye(S), np.eye(S), 3.0 * B1, np.eye(S), B1, np.array([1e-4]),
                                  np.array([-1.0]), np.array([1e6]))
    bs, ts, os_, ks, gs = form[2:7]
    assert bs[1, 0] == -2.0 and ts[1, 0] == -1e-4 and os_[1, 0] == 1e-4 and gs[1, 0] == -6.0  # on column 1, side in
    assert np.all(np.isinf(ts[[0, 1, 2, 2], [0, 1, 0, 1]]))  # the other slots are empty: never closed
