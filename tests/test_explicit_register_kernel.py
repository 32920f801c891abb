"""The central difference's register kernel for models of at most three DOFs (reduced.transient._cd._cd_small)
against the generic kernel (reduced.transient.explicit._cd_kernel): the same operations in the same order, so the
same bits, the signs of zeros included (the register kernel adds no padded fourth column since issue 28: a padded
term adds an exact 0 only if no sum is ever -0.0, which these runs check by their zeros' signs)."""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient import _cd
from reduced.transient.explicit import integrate_explicit

FS = 20000.0


def _chain(n: int) -> GapSystem:
    """n masses in a chain (grounded at the first), stops above and below the first and the last mass."""
    M = np.diag(np.linspace(1.0, 2.0, n))
    K = np.zeros((n, n))
    for i in range(n):
        K[i, i] += 1e4 * (i + 1)
        if i + 1 < n:
            K[i, i] += 5e3
            K[i + 1, i + 1] += 5e3
            K[i, i + 1] = K[i + 1, i] = -5e3
    C = 1e-3 * K + 0.5 * M
    C[0, 0] += 2.0  # a dashpot at the first mass: C is not proportional
    tips = [0, n - 1]
    B = np.zeros((4, n))
    for j, t in enumerate((0, 0, 1, 1)):
        B[j, tips[t]] = 1.0
    gap = 2e-4
    return GapSystem(M=M, C=C, K=K, B=B, k=np.full(4, 3e6), offset=np.array([gap, -gap, gap, -gap]),
                     side=np.array([1.0, -1.0, 1.0, -1.0]), tip=np.array([0, 0, 1, 1]),
                     dof_names=tuple(f"q{i}" for i in range(n)), stop_names=("u0", "l0", "u1", "l1"))


def _both(monkeypatch, *args, **kw):
    """(register kernel's run, generic kernel's run) of integrate_explicit(*args, **kw)."""
    small = integrate_explicit(*args, **kw)
    assert small.stats.get("coordinates", "physical") == "physical"
    with monkeypatch.context() as m:
        m.setattr(_cd, "SMALL_N", 0)  # no model is small: the generic kernel runs
        generic = integrate_explicit(*args, **kw)
    return small, generic


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("n", [1, 2, 3])
def test_register_kernel_is_the_generic_kernel_bit_for_bit(monkeypatch, n):
    # A blow at the last mass from rest (x0 = 0 exactly: zeros whose signs must match), through impacts at both
    # tips (asserted, so the stops' terms are exercised), 0.1 s.
    s = _chain(n)
    v0 = np.zeros(n)
    v0[-1] = 0.5
    small, generic = _both(monkeypatch, s, np.zeros(n), v0, 0.1, FS)
    assert np.abs(small.x[:, -1]).max() > 2e-4  # the last mass's stops are hit
    for name in ("x", "v", "dissipated"):
        assert _same_bits(getattr(small, name), getattr(generic, name)), name


def test_forced_register_kernel_is_the_generic_kernel_bit_for_bit(monkeypatch):
    # The loads' terms and their work: a harmonic force on the middle mass of three, through contact.
    s = _chain(3)
    b = np.zeros((1, 3))
    b[0, 1] = 1.0
    loads = Loads(b, (Harmonic(300.0, 40.0),), ("q1",))
    small, generic = _both(monkeypatch, s, np.zeros(3), np.zeros(3), 0.1, FS, loads=loads)
    assert np.abs(small.x).max() > 2e-4
    for name in ("x", "v", "dissipated", "external"):
        assert _same_bits(getattr(small, name), getattr(generic, name)), name


def test_four_dofs_run_the_generic_kernel(monkeypatch):
    # Four DOFs are past the register kernel since it holds three columns: the generic kernel runs, so
    # forcing it changes nothing (the test fails if a 4-DOF model reached _cd_small with its 3 columns).
    s = _chain(4)
    v0 = np.array([0.0, 0.0, 0.0, 0.5])
    small, generic = _both(monkeypatch, s, np.zeros(4), v0, 0.05, FS)
    assert _same_bits(small.x, generic.x)
    assert np.abs(small.x[:, -1]).max() > 2e-4
