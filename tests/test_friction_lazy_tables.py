"""The friction tables built state by state as a run enters the states (issue 27's speed).

:class:`reduced.transient.friction_tables.LazyFrictionTables` builds a state's closed form, terms and work
tables the first time a run enters it; the kernels return ``NEW_STATE`` there and resume. Checked against
the tables of every state built at once (:func:`friction_table`, :func:`friction_modal_table`), entry by entry
and bit for bit, and a run on tables built as it goes against the same run on tables all built before it,
sample for sample, free and forced, with a state that keeps more terms than the first (the arrays grow).
"""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.discrete import DiscreteFrictionParams
from reduced.models.gaps import Friction, GapSystem
from reduced.models.loads import Harmonic, Loads
from reduced.transient import friction as friction_module
from reduced.transient.friction import clear_tables, integrate_exact_friction
from reduced.transient.friction_tables import (
    STICK,
    LazyFrictionTables,
    friction_modal_table,
    friction_table,
)

K_X, K_Z, K_G, DELTA = 1.0e4, 1.0e5, 1.0e7, 1.0e-4


def overdamped_coulomb(c: float = 500.0) -> GapSystem:
    """A mass on a spring k = 1e4 N/m rubbing on a pressed contact (tests/test_friction.py's Coulomb oscillator)
    with a dashpot c = 500 N s/m on x: overdamped (critical 200) when the slider is free or slips, so two real
    eigenvalues there (4 kept terms with the slider's zero), underdamped when it sticks (k + kt: 3 terms)."""
    return GapSystem(M=np.diag([1.0, 0.5]), C=np.diag([c, 0.0]), K=np.diag([K_X, K_Z]), B=np.array([[0.0, 1.0]]),
                     k=np.array([K_G]), offset=np.array([-DELTA]), side=np.array([1.0]), tip=np.array([0]),
                     dof_names=("x", "z"), stop_names=("n",),
                     friction=Friction(Bt=np.array([[1.0, 0.0]]), tip=[0], k_t=1e7, mu=0.3, names=("t",)))


def _equal(a, b, name: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, (name, a.shape, b.shape)
    assert np.array_equal(a, b), (name, np.max(np.abs(a - b)))


@pytest.mark.parametrize("which", ["discrete", "overdamped"])
def test_tables_built_state_by_state_equal_those_built_at_once(which):
    # Every state built, in reverse order (on the overdamped oscillator the stick state, with fewer terms,
    # comes first, so the term arrays grow when a slip state is built): every array the kernels read equals
    # the one built for all states at once, bit for bit (the same arithmetic on each state's slice).
    system = DiscreteFrictionParams().system() if which == "discrete" else overdamped_coulomb()
    om = system.omega_max()
    eager = friction_table(system, om)
    groups = friction_modal_table(system, eager)
    lazy = LazyFrictionTables(system, om)
    S = lazy.S
    if which == "overdamped":
        stick = eager.states.index([True], [STICK])
        order = [stick] + [s for s in range(S) if s != stick]
        assert groups[0][0][stick] < groups[0][0].max()  # the stick state keeps fewer terms: a growth follows
    else:
        order = list(range(S - 1, -1, -1))
    built = []
    for s in order:
        assert lazy.ensure(s) and not lazy.ensure(s)
        built.append(s)
        assert set(np.flatnonzero(lazy.arrays()[4])) == set(built)
    for f in ("lam", "V", "Vinv", "yp", "cond", "Ks", "R", "erow", "ec", "eact", "succ", "reset", "ekind", "Df", "LF"):
        _equal(getattr(lazy.table, f), getattr(eager, f), f)
    mine = lazy.arrays()
    for g, group in enumerate(groups):
        for i, a in enumerate(group):
            _equal(mine[g][i], a, f"group {g} array {i}")


def test_a_run_enters_few_states_and_moves_as_on_all_the_tables():
    # The discrete friction model struck on the beam (free) and driven at 30 Hz (forced: the forced kernel's
    # NEW_STATE path): with the tables built as the run goes, it builds only the states it enters (its event
    # log's, and the start), and the motion, the sliders and the works equal, sample for sample and bit for
    # bit, those of the same run on tables all built before it (no NEW_STATE return then).
    system = DiscreteFrictionParams().system()
    loads = Loads(b=np.array([[0.0, 1.0, 0.0, 0.3]]), signals=(Harmonic(amplitude_N=40.0, freq_hz=30.0),))
    for kw in ({}, {"loads": loads}):
        clear_tables()
        args = (system, np.zeros(4), [0.0, 0.0, 0.3, 0.2], 0.3, 20000.0)
        first = integrate_exact_friction(*args, log_events=100_000, **kw)
        start = first.events.table.states.index(np.zeros(system.m, bool), np.zeros(system.p, np.int8))
        entered = set(np.unique(first.events.state)) | {start}
        assert first.stats["n_states_built"] <= len(entered) + 1 < first.stats["n_states"]  # + 1: the forced
        # run's scales read the all-open state's static deflections
        assert len(first.events) == first.stats["n_events"] > 100
        tables, reused = friction_module.friction_tables(system.fold_zero_gap_tips(), system.omega_max())
        assert reused and set(np.flatnonzero(tables.built)) >= entered
        for s in range(tables.S):
            tables.ensure(s)
        again = integrate_exact_friction(*args, log_events=100_000, **kw)
        assert again.stats["n_states_built"] == again.stats["n_states"]
        for f in ("x", "v", "w", "friction", "dissipated", "external"):
            _equal(getattr(again, f), getattr(first, f), f)
        _equal(again.events.t, first.events.t, "event times")
        assert first.energy_balance_error < 1e-11


def test_the_condition_bound_brackets_the_2_norm_condition():
    # condition_bound(V, V^-1) = sqrt(|V|_1 |V|_inf |V^-1|_1 |V^-1|_inf) replaces an SVD: by Hoelder
    # (|A|_2 <= sqrt(|A|_1 |A|_inf), |A|_1, |A|_inf <= sqrt(N) |A|_2) cond_2 <= bound <= N cond_2 for every
    # state of the discrete friction model (N = 10; measured 1.7-2.4 x cond_2); 1e-12 of slack for round-off
    from reduced.transient.friction_tables import condition_bound, friction_table

    t = friction_table(DiscreteFrictionParams(mu=0.3).system(), 100.0)
    N = t.V.shape[1]
    for V, Vi, c in zip(t.V, t.Vinv, t.cond, strict=True):
        sv = np.linalg.svd(V, compute_uv=False)
        c2 = sv[0] / sv[-1]
        assert c == condition_bound(V, Vi)
        assert c2 * (1 - 1e-12) <= c <= N * c2, (c, c2)


def test_work_tables_over_the_power_rows_equal_the_full_quadratic_form():
    """work_tables forms U^T D U over the coordinates D involves (its nonzero rows) with real products; on
    random kept terms and a D with a zero block it equals the full complex product U^T D U (the old form) to
    round-off: G and H are sums of at most N products of O(1) terms, so 1e-13 relative is ~100 ulps."""
    from reduced.transient.friction_tables import work_tables

    rng = np.random.default_rng(7)
    S, N, K = 3, 12, 5
    lk = -rng.uniform(0.1, 1.0, (S, K)) + 1j * rng.uniform(1.0, 10.0, (S, K))
    Uk = rng.standard_normal((S, N, K)) + 1j * rng.standard_normal((S, N, K))
    kappa = np.full((S, K), 2.0)
    D = np.zeros((S, N, N))
    Q = rng.standard_normal((S, 3, 3))
    D[0, 4:7, 4:7] = Q[0] + Q[0].T  # the power on three coordinates only, other ones in each state
    D[1, 8:11, 8:11] = Q[1] + Q[1].T
    D[2] = 0.0  # a state without power: its G, H vanish
    Wm, Hd = work_tables(lk, Uk, kappa, D)[:2]
    G = 0.5 * np.matmul(Uk.transpose(0, 2, 1), np.matmul(D.astype(complex), Uk))
    H = 0.5 * np.matmul(Uk.transpose(0, 2, 1), np.conj(np.matmul(D.astype(complex), Uk)))
    zG, zH = lk[:, :, None] + lk[:, None, :], lk[:, :, None] + np.conj(lk)[:, None, :]
    off = ~np.eye(K, dtype=bool)
    Gz, Hz = G / zG, np.where(off, H / np.where(off, zH, 1.0), 0.0)
    ref = np.stack([Gz.real + Hz.real, Hz.imag - Gz.imag, Gz.imag + Hz.imag, Gz.real - Hz.real],
                   axis=1).transpose(0, 1, 3, 2)
    hd = np.diagonal(H, axis1=1, axis2=2).real / (2.0 * lk.real)
    scale = np.max(np.abs(ref))
    assert scale > 0.1
    assert np.max(np.abs(Wm - ref)) < 1e-13 * scale, np.max(np.abs(Wm - ref)) / scale
    assert np.max(np.abs(Hd[:, 0] - hd)) < 1e-13 * np.max(np.abs(hd))
    assert not np.any(Wm[2]) and not np.any(Hd[2])
