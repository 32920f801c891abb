"""The central difference jumped in blocks of steps while the contact state holds (reduced.transient._cd_block,
issue 28) against the step-by-step modal kernel and the physical-coordinate kernel (the references: independent
implementations of the same scheme) and the scheme's closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh

from reduced.models.gaps import GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient import _cd_block, _cd_modal
from reduced.transient.explicit import integrate_explicit, stream_explicit

N = 8
FS = 20000.0


def _beam_like(gap: float = 2e-4, c_scale: float = 1.0) -> GapSystem:
    """An 8-DOF structure shaped like the reduced beam (tests/test_explicit_modal.py): two tip coordinates, each
    between an upper and a lower stop, damping of two dashpots + alpha M + modal damping (a diagonal plus rank 2
    in the modal coordinates)."""
    rng = np.random.default_rng(7)
    A = rng.standard_normal((N, N))
    M = A @ A.T / N + np.eye(N)
    Bk = rng.standard_normal((N, N))
    K = 1e6 * (Bk @ Bk.T / N + 0.5 * np.eye(N))
    w2, Phi = eigh(K, M)
    MPhi = M @ Phi
    P = rng.standard_normal((2, N))
    C = c_scale * (5.0 * P.T @ P + 3.0 * M + (MPhi * (2.0 * 1e-3 * np.sqrt(w2))) @ MPhi.T)
    C = 0.5 * (C + C.T)
    B = np.zeros((4, N))
    B[0, 0] = B[1, 0] = 1.0
    B[2, 1] = B[3, 1] = 1.0
    return GapSystem(M=M, C=C, K=K, B=B, k=np.full(4, 3e7), offset=np.array([gap, -gap, gap, -gap]),
                     side=np.array([1.0, -1.0, 1.0, -1.0]), tip=np.array([0, 0, 1, 1]),
                     dof_names=tuple(f"q{i}" for i in range(N)), stop_names=("u0", "l0", "u1", "l1"))


def _start(speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    v0 = np.zeros(N)
    v0[0], v0[1] = speed, -0.5 * speed
    return np.zeros(N), v0


def test_step_map_is_one_step_of_the_modal_kernel():
    # The affine map of each contact state against one call of cd_modal from a state in that state (both stops
    # of tip 0 probed: the upper closed, then the lower): equal to round-off (1e-13 of the state's size, a few
    # eps of sums of 8 terms).
    s = _beam_like()
    dt = 2e-6
    form = _cd_modal.modal_form(s.M, s.K, s.C, s.B, np.zeros((0, N)), dt)
    mats = form["mats"]
    rng = np.random.default_rng(1)
    for tip0, mask in ((3e-4, 0b0001), (-3e-4, 0b0010), (0.0, 0)):
        x = 1e-5 * rng.standard_normal(N)
        x[0] = tip0
        z = form["PhiTM"] @ x
        zd = rng.standard_normal(N)
        A = _cd_block.step_map(mats, s.offset, s.k, dt, mask)
        want = A @ np.concatenate([z, zd, [1.0]])
        z1, zd1, a = z.copy(), zd.copy(), form["a_of"] @ zd
        buf = np.empty((1, N))
        _cd_modal.cd_modal(*mats, s.offset, s.side, s.k, z1, zd1, dt, 1, 2, buf, buf.copy(), np.empty(1), 0.0, 0.0, 0,
                           a, np.zeros((0, N)), np.zeros((0, 0)), np.empty(0), 0.0, 0.0)
        assert want[-1] == 1.0
        assert np.abs(want[:N] - z1).max() <= 1e-13 * np.abs(z1).max()
        assert np.abs(want[N:2 * N] - zd1).max() <= 1e-13 * np.abs(zd1).max()


def test_end_state_rows_give_the_stop_rows_the_energy_and_the_next_state():
    # Issue 28, session 14: the end-state table of a block (length L, contact state c) gives, besides z and zd
    # after L steps, the stop rows g0 = Bu z and g1 = Bu (z + dt zd) there; the kernel takes the block's energy and
    # the next block's contact state from them. Against the L-th power of the one-step map and the energy's closed
    # form E = (|zd|^2 + z^T om2 (z + dt zd) + sum over closed stops k (g1 - offset) (g0 - offset)) / 2 formed in
    # numpy (to round-off: 1e-12 of each quantity's scale), and the contact state by the kernel's rule
    # side (g1 - offset) > 0 (states drawn away from the offsets: no tie).
    s = _beam_like()
    dt = 2e-6
    form = _cd_modal.modal_form(s.M, s.K, s.C, s.B, np.zeros((0, N)), dt)
    mats = form["mats"]
    bf = _cd_block.block_form(mats, form["om2"], s.offset, s.side, s.k, dt, 25)
    Bu, umap, nu = mats[10], mats[12], mats[10].shape[0]
    om2 = form["om2"]
    rng = np.random.default_rng(3)
    checked = set()
    for trial in range(60):
        ic = trial % len(bf["masks"])
        il = int(rng.integers(len(bf["Ls"])))
        L, mask = int(bf["Ls"][il]), int(bf["masks"][ic])
        st = np.concatenate([form["PhiTM"] @ (3e-4 * rng.standard_normal(N)), 0.3 * rng.standard_normal(N), [1.0]])
        want = np.linalg.matrix_power(_cd_block.step_map(mats, s.offset, s.k, dt, mask), L) @ st
        nxt = bf["TS"][il, ic].T @ st  # the kernel's product (the table column by column)
        z, zd = want[:N], want[N:2 * N]
        assert np.abs(nxt[:2 * N] - want[:2 * N]).max() <= 1e-12 * np.abs(want[:2 * N]).max()
        g0, g1 = Bu @ z, Bu @ (z + dt * zd)
        assert np.abs(nxt[3 * N:3 * N + nu] - g0).max() <= 1e-12 * np.abs(g0).max()
        assert np.abs(nxt[3 * N + nu:3 * N + 2 * nu] - g1).max() <= 1e-12 * np.abs(g1).max()
        closed = [j for j in range(len(s.k)) if mask >> j & 1]
        e = 0.5 * (zd @ zd + z @ (om2 * (z + dt * zd))
                   + sum(s.k[j] * (g1[umap[j]] - s.offset[j]) * (g0[umap[j]] - s.offset[j]) for j in closed))
        rows = _cd_block._modal_energy(nxt, om2, dt) + _cd_block._stop_energy(nxt, 3 * N, nu, umap, s.offset, s.k,
                                                                               mask)
        of_state = _cd_block._modal_energy(want, om2, dt) + _cd_block._stop_energy_of(want, dt, Bu, umap, s.offset,
                                                                                         s.k, mask)
        scale = 0.5 * (zd @ zd + z @ (om2 * z)) + abs(e)
        assert abs(rows - e) <= 1e-12 * scale and abs(of_state - e) <= 1e-12 * scale
        nxt_mask = sum(1 << j for j in range(len(s.k)) if s.side[j] * (g1[umap[j]] - s.offset[j]) > 0.0)
        assert min(abs(g1[umap[j]] - s.offset[j]) for j in range(len(s.k))) > 1e-9
        assert _cd_block._row_state(nxt, 3 * N + nu, umap, s.offset, s.side, bf["lut"]) == bf["lut"][nxt_mask]
        checked.add(mask)
    assert len(checked) == len(bf["masks"]) and any(checked)  # every contact state, closed stops among them


def test_bounds_are_the_kernels_rule():
    # [lo, hi] of each closed-stop pattern of a row against side (g - offset) > 0 at the offsets, their
    # neighbours and between: the same answer everywhere (exact: the bounds are offsets or their neighbours).
    offset = np.array([2.54e-4, -2.54e-4])
    side = np.array([1.0, -1.0])
    stops = np.array([0, 1])
    probes = [o + d for o in offset for d in (0.0, 1e-20, -1e-20)]
    probes += [np.nextafter(o, s) for o in offset for s in (np.inf, -np.inf)] + [0.0, 1.0, -1.0]
    for mask in _cd_block._row_states(offset, side, stops):
        lo, hi = _cd_block._bounds(offset, side, stops, mask)
        for g in probes:
            closed = sum(1 << j for j in stops if side[j] * (g - offset[j]) > 0.0)
            assert (lo <= g <= hi) == (closed == mask), (mask, g)
    assert sorted(_cd_block._row_states(offset, side, stops)) == [0, 1, 2]


def test_pure_mode_undamped_is_the_cd_closed_form():
    # Undamped, gaps never reached: CD's discrete solution of one mode from rest is x0 cos(n theta),
    # cos theta = 1 - (omega dt)^2 / 2 (exact for the scheme), and the blocked run jumps it with powers of the
    # step's map. Tolerance 1e-11 of the amplitude: round-off of 2e5 steps, as for the modal kernel.
    s = _beam_like(gap=1.0, c_scale=0.0)
    w2, Phi = eigh(s.K, s.M)
    x0 = 1e-3 * Phi[:, 2] / np.abs(Phi[:, 2]).max()
    r = integrate_explicit(s, x0, np.zeros(N), 0.5, FS, coordinates="blocked")
    assert r.stats["coordinates"] == "blocked"
    dt = r.stats["dt"]
    every = round(1.0 / (FS * dt))
    theta = 2.0 * np.arcsin(0.5 * np.sqrt(w2[2]) * dt)
    n = np.arange(r.x.shape[0]) * every
    assert np.abs(r.x - np.cos(n * theta)[:, None] * x0).max() <= 1e-11 * np.abs(x0).max()
    # no damping, no work: the work is a sum of 1e4 differences of the discrete energy (one a block), each rounded
    # to a few eps of the energy, so 1e-10 of it (3e-12 seen)
    assert np.abs(r.dissipated).max() <= 1e-10 * 0.5 * float(x0 @ s.K @ x0)


def test_linear_damped_run_equals_the_stepping_kernels_to_round_off():
    # Gaps never reached: all three kernels run the same linear recurrence, which damps round-off; 1e-11 of
    # max |x| (v) is ~1e5 eps, the rounding of 1e5 steps. The dissipated work, here from the scheme's discrete
    # energy balance instead of the trapezoidal sum of v^T C v, agrees to 1e-11 of it (an exact identity of the
    # recurrence: only rounding differs).
    s = _beam_like(gap=1.0)
    x0, v0 = _start()
    ph = integrate_explicit(s, x0, v0, 0.5, FS, coordinates="physical")
    bl = integrate_explicit(s, x0, v0, 0.5, FS, coordinates="blocked")
    assert bl.stats["coordinates"] == "blocked" and bl.stats["n_steps"] == ph.stats["n_steps"]
    assert np.abs(bl.x - ph.x).max() <= 1e-11 * np.abs(ph.x).max()
    assert np.abs(bl.v - ph.v).max() <= 1e-11 * np.abs(ph.v).max()
    assert np.abs(bl.dissipated - ph.dissipated).max() <= 1e-11 * ph.dissipated[-1]
    assert ph.dissipated[-1] > 0.5 * 0.5 * float(v0 @ s.M @ v0)  # most of the energy is dissipated: a real check


def test_impacting_run_equals_the_stepping_kernels_before_round_off_grows():
    # Through repeated impacts on both stops of both tips (many switches of the contact state inside blocks):
    # over the first 20 ms the blocked run agrees with the modal and the physical kernels to 1e-9 of max |x| (as
    # the modal kernel does with the physical one, tests/test_explicit_modal.py); the dissipated work there to
    # 1e-9 of it; the energy balance of the whole run is the scheme's (1e-6 of it).
    s = _beam_like()
    x0, v0 = _start()
    ph = integrate_explicit(s, x0, v0, 0.2, FS, coordinates="physical")
    mo = integrate_explicit(s, x0, v0, 0.2, FS, coordinates="modal")
    bl = integrate_explicit(s, x0, v0, 0.2, FS, coordinates="blocked")
    g = ph.x[:, :2]
    assert g.max(axis=0).min() > 2e-4 and g.min(axis=0).max() < -2e-4  # all four stops are hit
    k = int(0.02 * FS) + 1
    for ref in (ph, mo):
        assert np.abs(bl.x[:k] - ref.x[:k]).max() <= 1e-9 * np.abs(ref.x[:k]).max()
        assert np.abs(bl.v[:k] - ref.v[:k]).max() <= 1e-9 * np.abs(ref.v[:k]).max()
        assert abs(bl.dissipated[k - 1] - ref.dissipated[k - 1]) <= 1e-9 * ref.dissipated[k - 1]
        assert abs(bl.energy_balance_error - ref.energy_balance_error) <= 1e-6 * abs(ref.energy_balance_error) + 1e-14


def test_samples_do_not_depend_on_how_the_run_is_cut():
    # The block pattern depends only on the state (a call starts at a sample and tries the blocks in the same
    # order), so cutting the run into chunks or progress pieces gives the same bits.
    s = _beam_like()
    x0, v0 = _start()
    whole = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="blocked")
    parts = list(stream_explicit(s, x0, v0, 0.05, FS, coordinates="blocked", chunk_samples=137))
    assert np.array_equal(np.concatenate([c.x for c in parts]), whole.x)
    reported = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="blocked", progress=lambda f: None, chunks=7)
    assert np.array_equal(reported.x, whole.x) and np.array_equal(reported.dissipated, whole.dissipated)


def test_forced_and_short_interval_runs_step():
    # Asked for blocks under loads, the modal kernel runs (bit for bit); fewer than BLOCK_MIN steps between
    # samples make no block.
    s = _beam_like(gap=1.0)
    b = np.zeros((1, N))
    b[0, 3] = 1.0
    loads = Loads(b, (Harmonic(50.0, 300.0),), ("q3",))
    bl = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.02, FS, loads=loads, coordinates="blocked")
    mo = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.02, FS, loads=loads, coordinates="modal")
    assert bl.stats["coordinates"] == "modal" and np.array_equal(bl.x, mo.x)
    # the default ("auto"): the block kernel on a free run, the physical kernel, bit for bit, on a forced one
    auto = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.02, FS, loads=loads)
    ph = integrate_explicit(s, np.zeros(N), np.zeros(N), 0.02, FS, loads=loads, coordinates="physical")
    assert auto.stats["coordinates"] == "physical" and np.array_equal(auto.x, ph.x)
    assert integrate_explicit(s, *_start(), 0.01, FS).stats["coordinates"] == "blocked"
    assert _cd_block.block_steps(3) == 0 and _cd_block.block_steps(25) == 25 and _cd_block.block_steps(60) == 25


@pytest.mark.slow
def test_rom_impulse_equals_the_physical_kernel_over_the_predictable_window():
    # The scene's 2 s ringdown of the 10-mode reduced beam: over the first 0.2 s (before round-off is amplified by
    # the chaotic motion) the blocked run equals the modal kernel's (the one it falls back on) to 1e-11 of max |x|
    # (6e-13 seen) and the physical kernel's to 3e-10 (the modal kernel itself is 1.0e-10 from it,
    # results/performance/README.md); the energy balance is the scheme's, equal to 1e-6 of it.
    from bearingshaft.scenes import load_scene
    from bearingshaft.systems import model_system, scene_initial_state

    sc = load_scene("rom-impulse")
    system, P = model_system(sc.model)
    x0, v0 = scene_initial_state(sc, system, P)
    ph = integrate_explicit(system, x0, v0, 2.0, FS, step_basis="contact", coordinates="physical")
    mo = integrate_explicit(system, x0, v0, 2.0, FS, step_basis="contact", coordinates="modal")
    bl = integrate_explicit(system, x0, v0, 2.0, FS, step_basis="contact", coordinates="blocked")
    assert bl.stats["coordinates"] == "blocked"
    k = int(0.2 * FS) + 1
    assert np.abs(bl.x[:k] - mo.x[:k]).max() <= 1e-11 * np.abs(mo.x[:k]).max()
    assert np.abs(bl.x[:k] - ph.x[:k]).max() <= 3e-10 * np.abs(ph.x[:k]).max()
    assert abs(bl.energy_balance_error - ph.energy_balance_error) <= 1e-6 * abs(ph.energy_balance_error)


def test_every_block_length_and_powers_of_two_agree_to_round_off(monkeypatch):
    # Issue 28: a form with every length up to the longest jumps the steps held before a switch and the rest of
    # the interval as one block each; past EVERY_LENGTH_BYTES the form keeps the powers of two. Both cover the
    # same steps with the same recurrence, so through the impacts they agree with each other and with the modal
    # kernel to round-off over the first 20 ms (1e-9 of max |x|, as above), and the every-length run needs fewer
    # blocks (its form has every length).
    s = _beam_like()
    x0, v0 = _start()
    mo = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="modal")
    every = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="blocked")
    form = next(iter(_cd_block._FORMS.values()))
    mb = form["mb"]
    assert list(form["Ls"]) == list(range(mb, 0, -1))
    with monkeypatch.context() as m:
        m.setattr(_cd_block, "EVERY_LENGTH_BYTES", 0)
        m.setattr(_cd_block, "_FORMS", {})
        pow2 = integrate_explicit(s, x0, v0, 0.05, FS, coordinates="blocked")
        assert list(next(iter(_cd_block._FORMS.values()))["Ls"]) == list(_cd_block.block_lengths(mb))
    assert not np.array_equal(every.x, pow2.x)  # the blocks differ around the switches: round-off apart
    k = int(0.02 * FS) + 1
    for a, b in ((every, pow2), (every, mo), (pow2, mo)):
        assert np.abs(a.x[:k] - b.x[:k]).max() <= 1e-9 * np.abs(b.x[:k]).max()
        assert abs(a.dissipated[k - 1] - b.dissipated[k - 1]) <= 1e-9 * b.dissipated[k - 1]
