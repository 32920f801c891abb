"""The central difference in the open-gap modal coordinates (reduced.transient._cd_modal, issue 28) against the
physical-coordinate kernel (the reference, an independent implementation of the same scheme) and closed forms."""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient import _cd_modal
from reduced.transient.explicit import integrate_explicit, stream_explicit

N = 8
FS = 20000.0


def _beam_like(gap: float = 2e-4, dashpots: bool = True, c_full: bool = False) -> GapSystem:
    """An 8-DOF structure shaped like the reduced beam: two tip coordinates (0, 1), each between an upper
    and a lower stop (one row, two stops), damping c P^T P (two dashpots) + alpha M + modal damping
    (rom.damping_matrix's form), or a full-rank random C (c_full)."""
    rng = np.random.default_rng(7)
    A = rng.standard_normal((N, N))
    M = A @ A.T / N + np.eye(N)
    Bk = rng.standard_normal((N, N))
    K = 1e6 * (Bk @ Bk.T / N + 0.5 * np.eye(N))
    if c_full:
        Cr = rng.standard_normal((N, N))
        C = Cr @ Cr.T
    else:
        w2, Phi = eigh(K, M)
        MPhi = M @ Phi
        P = rng.standard_normal((2, N)) if dashpots else np.zeros((2, N))
        C = 5.0 * P.T @ P + 3.0 * M + (MPhi * (2.0 * 1e-3 * np.sqrt(w2))) @ MPhi.T
        C = 0.5 * (C + C.T)
    B = np.zeros((4, N))
    B[0, 0] = B[1, 0] = 1.0
    B[2, 1] = B[3, 1] = 1.0
    return GapSystem(M=M, C=C, K=K, B=B, k=np.full(4, 3e7), offset=np.array([gap, -gap, gap, -gap]),
                     side=np.array([1.0, -1.0, 1.0, -1.0]), tip=np.array([0, 0, 1, 1]),
                     dof_names=tuple(f"q{i}" for i in range(N)), stop_names=("u0", "l0", "u1", "l1"))


def _start(system: GapSystem, speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    v0 = np.zeros(N)
    v0[0], v0[1] = speed, -0.5 * speed
    return np.zeros(N), v0


def test_diagonal_plus_low_rank_finds_the_split():
    # A made-up diag(d) + U U^T of rank 2 (n = 10): the split has rank 2 and rebuilds the matrix to round-off
    # (1e-13 of its largest entry: the alternating projections stop at SPLIT_TOL = 1e-14 on the off-diagonal).
    rng = np.random.default_rng(3)
    U = rng.standard_normal((10, 2))
    d = rng.uniform(1.0, 5.0, 10)
    Cm = np.diag(d) + U @ U.T
    dd, UU = _cd_modal.diagonal_plus_low_rank(Cm, 3)
    assert UU.shape == (10, 2)
    assert np.abs(np.diag(dd) + UU @ UU.T - Cm).max() <= 1e-13 * np.abs(Cm).max()
    # a full-rank off-diagonal part has no such split of rank <= 3
    R = rng.standard_normal((10, 10))
    assert _cd_modal.diagonal_plus_low_rank(R @ R.T, 3) is None


def test_pure_mode_undamped_is_the_cd_closed_form():
    # Undamped, gaps never reached: CD's discrete solution of one mode from rest is x0 cos(n theta),
    # cos theta = 1 - (omega dt)^2 / 2 (exact for the scheme). Tolerance 1e-11 of the amplitude: round-off of
    # 2e5 steps (each ~1e-16, a random walk in the phase of an undamped oscillator).
    s = _beam_like(gap=1.0)
    s = GapSystem(M=s.M, C=np.zeros((N, N)), K=s.K, B=s.B, k=s.k, offset=s.offset, side=s.side, tip=s.tip,
                  dof_names=s.dof_names, stop_names=s.stop_names)
    w2, Phi = eigh(s.K, s.M)
    x0 = 1e-3 * Phi[:, 2] / np.abs(Phi[:, 2]).max()
    r = integrate_explicit(s, x0, np.zeros(N), 0.5, FS, coordinates="modal")
    assert r.stats["coordinates"] == "modal"
    dt = r.stats["dt"]
    every = round(1.0 / (FS * dt))
    theta = 2.0 * np.arcsin(0.5 * np.sqrt(w2[2]) * dt)  # cos theta = 1 - (omega dt)^2 / 2, well conditioned
    n = np.arange(r.x.shape[0]) * every
    want = np.cos(n * theta)[:, None] * x0
    assert np.abs(r.x - want).max() <= 1e-11 * np.abs(x0).max()


def test_linear_damped_run_equals_the_physical_kernel_to_round_off():
    # Gaps never reached: both kernels run the same linear recurrence, which damps round-off instead of
    # amplifying it; 1e-11 of max |x| is ~1e5 x eps, the accumulated rounding of 1e5 steps.
    s = _beam_like(gap=1.0)
    x0, v0 = _start(s)
    ph = integrate_explicit(s, x0, v0, 0.5, FS, coordinates="physical")
    mo = integrate_explicit(s, x0, v0, 0.5, FS, coordinates="modal")
    assert mo.stats["coordinates"] == "modal" and ph.stats["coordinates"] == "physical"
    assert mo.stats["n_steps"] == ph.stats["n_steps"]
    assert np.abs(mo.x - ph.x).max() <= 1e-11 * np.abs(ph.x).max()
    assert np.abs(mo.v - ph.v).max() <= 1e-11 * np.abs(ph.v).max()
    assert abs(mo.dissipated[-1] - ph.dissipated[-1]) <= 1e-11 * ph.dissipated[-1]


def test_impacting_run_equals_the_physical_kernel_before_round_off_grows():
    # Through repeated impacts on both stops of both tips: over the first 20 ms the two kernels agree to
    # 1e-9 of max |x| (round-off amplified by the contact switching, ~1e-12 a few ms in; the 2 s run of the
    # reduced beam agrees to 1e-10 over 0.5 s, benchmarks/integrator_speed.py); the energy balance of the
    # whole run is the scheme's, equal in both to 1e-6 of it.
    s = _beam_like()
    x0, v0 = _start(s)
    ph = integrate_explicit(s, x0, v0, 0.2, FS, coordinates="physical")
    mo = integrate_explicit(s, x0, v0, 0.2, FS, coordinates="modal")
    assert np.abs(ph.x[:, 0]).max() > 2e-4 and np.abs(ph.x[:, 1]).max() > 2e-4  # the stops are hit
    k = int(0.02 * FS) + 1
    assert np.abs(mo.x[:k] - ph.x[:k]).max() <= 1e-9 * np.abs(ph.x[:k]).max()
    assert abs(mo.energy_balance_error - ph.energy_balance_error) <= 1e-6 * abs(ph.energy_balance_error) + 1e-14


def test_forced_run_equals_the_physical_kernel():
    # A harmonic load on q3, gaps not reached: linear, so equal to round-off as above; the loads' work too.
    s = _beam_like(gap=1.0)
    b = np.zeros((1, N))
    b[0, 3] = 1.0
    loads = Loads(b, (Harmonic(50.0, 300.0),), ("q3",))
    ph = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.1, FS, loads=loads, coordinates="physical")
    mo = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.1, FS, loads=loads, coordinates="modal")
    assert np.abs(mo.x - ph.x).max() <= 1e-12 * np.abs(ph.x).max()
    assert abs(mo.external[-1] - ph.external[-1]) <= 1e-11 * np.abs(ph.external).max()


def test_samples_do_not_depend_on_how_the_run_is_cut():
    s = _beam_like()
    x0, v0 = _start(s)
    whole = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="modal")
    parts = list(stream_explicit(s, x0, v0, 0.05, FS, coordinates="modal", chunk_samples=137))
    x = np.concatenate([c.x for c in parts])
    assert np.array_equal(x, whole.x)
    reported = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="modal", progress=lambda f: None, chunks=7)
    assert np.array_equal(reported.x, whole.x) and np.array_equal(reported.dissipated, whole.dissipated)


def test_falls_back_to_the_physical_kernel():
    # Damping with no diagonal + low-rank split, and a model small enough for the register kernel: the
    # physical kernels run, bit for bit as without the option.
    s = _beam_like(c_full=True)
    x0, v0 = _start(s)
    mo = integrate_explicit(s, x0, v0, 0.01, FS, coordinates="modal")
    ph = integrate_explicit(s, x0, v0, 0.01, FS, coordinates="physical")
    assert mo.stats["coordinates"] == "physical"
    assert np.array_equal(mo.x, ph.x)
    K3 = 1e4 * np.array([[2.0, -1, 0], [-1, 2, -1], [0, -1, 1]])
    three = GapSystem(M=np.diag([1.0, 2.0, 3.0]), C=np.eye(3), K=K3,
                      B=np.array([[1.0, 0, 0], [1.0, 0, 0]]), k=np.full(2, 1e6), offset=np.array([1e-3, -1e-3]),
                      side=np.array([1.0, -1.0]), tip=np.array([0, 0]), dof_names=("a", "b", "c"),
                      stop_names=("u", "l"))
    v3 = np.array([0.5, 0.0, 0.0])
    mo = integrate_explicit(three, np.zeros(3), v3, 0.05, FS, coordinates="modal")
    assert mo.stats["coordinates"] == "physical"
    assert np.array_equal(mo.x, integrate_explicit(three, np.zeros(3), v3, 0.05, FS, coordinates="physical").x)
