"""Studies on the reduced 3-D model: stiff cases, explicit against exact, convergence with modes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.models.initial import initial_state
from reduced.models.rom import RomSpec, build_rom
from reduced.studies import STIFF_FIELDS, fit_order, relative_error, rom_case, rom_convergence, stiff_cases
from reduced.transient.explicit import DEFAULT_OMEGA_DT
from reduced.transient.integrate import ringdown

SPEC = RomSpec()  # beam-grounded, planar, Table-1 contact, c = 4 N s/m at the points
MODES = (1, 2, 5, 10)


@pytest.fixture(scope="module")
def reduced_family():
    """({n: ReducedModel} on one mesh, full model's coupled frequencies {state: Hz})."""
    from bearingshaft.gap_modes import full_gap_modes
    from fem.model import build_system

    fe = build_system(SPEC.fe_model())
    full = full_gap_modes(fe, SPEC)
    roms = {n: build_rom(replace(SPEC, n_modes=n), fe=fe)[0] for n in MODES}
    return roms, {s: g.freq_hz[g.coupled] for s, g in full.items()}


def test_stiff_cases_on_the_reduced_model_conserve_energy(reduced_family):
    roms, _ = reduced_family
    rows = stiff_cases(rom_case(roms[5], SPEC), (3.502e7, 1e9), (0.0, 2.54e-4), (200.0,), (0.0, 4.0), 0.02,
                       5000.0, ("exact", "explicit"), long_duration_s=0.04, long_methods=("exact",))
    assert len(rows) == 2 * 2 * 2 * 2 + 2
    assert all(r["status"] == "ok" for r in rows), [r["reason"] for r in rows if r["status"] != "ok"]
    assert any(r["n_events"] and r["n_events"] > 100 for r in rows)  # the runs do impact
    # exact: the closed form conserves E(t) + W(t) to round-off over hundreds of events (seen <= 6e-11)
    exact = max(r["energy_balance_error"] for r in rows if r["method"] == "exact")
    assert exact < 1e-9, f"exact energy-balance error {exact:.3g}"
    # explicit at omega_max dt = 0.05: central difference conserves a shadow energy that differs from E by
    # up to (omega dt)^2 / 4 = 6.3e-4 of the energy in the top mode; impacts switch between steps and add a
    # penalty-energy error of the same order (seen <= 4.3e-4 at k_g = 1e9): bound 3 x (omega dt)^2 / 4
    explicit = max(r["energy_balance_error"] for r in rows if r["method"] == "explicit")
    assert explicit < 3 * DEFAULT_OMEGA_DT**2 / 4, f"explicit energy-balance error {explicit:.3g}"
    long = [r for r in rows if r["duration_s"] == 0.04]
    assert [r["c"] for r in long] == [0.0, 4.0] and all(r["k_g"] == 3.502e7 for r in long)


def test_stiff_cases_refuse_explicit_runs_over_the_step_budget(reduced_family):
    roms, _ = reduced_family
    rows = stiff_cases(rom_case(roms[5], SPEC), (1e11,), (2.54e-4,), (200.0,), (0.0,), 0.01, 5000.0,
                       ("exact", "explicit"), max_steps=1e4)
    by = {r["method"]: r for r in rows}
    assert by["exact"]["status"] == "ok"
    assert by["explicit"]["status"] == "refused" and "budget" in by["explicit"]["reason"]


def test_stiff_cases_keep_the_discrete_behaviour():
    rows = stiff_cases(DiscreteParams(), (3.502e7,), (2.54e-4,), (200.0,), (4.0,), 0.02, 5000.0, ("exact",))
    assert len(rows) == 1 and set(STIFF_FIELDS) <= set(rows[0]) and rows[0]["status"] == "ok"
    ref = ringdown(DiscreteParams().system(), np.zeros(3), np.array([0.0, 0.0, 200.0]), 0.02, 5000.0, "exact")
    assert rows[0]["n_events"] == ref.stats["n_events"]
    assert rows[0]["energy_J"] == pytest.approx(float(ref.energy[0]), rel=1e-14)


def test_explicit_reduced_ringdown_converges_to_the_exact_one_at_second_order(reduced_family):
    roms, _ = reduced_family
    rom = roms[5]
    system = rom.system()
    x0, v0 = initial_state(rom.M, rom.K, rom.P, np.zeros(3), (0.0, 0.0, 200.0))
    window, fs = 0.01, 20000.0
    ref = ringdown(system, x0, v0, window, fs, "exact")
    assert ref.stats["n_events"] > 50  # contact inside the window
    wdt = np.array([0.05, 0.025, 0.0125])
    runs = [ringdown(system, x0, v0, window, fs, "explicit", omega_dt=w) for w in wdt]
    err = np.array([relative_error(r.x @ rom.P.T, ref.x @ rom.P.T) for r in runs])
    order = fit_order([r.stats["dt"] for r in runs], err)
    assert abs(order - 2.0) < 0.2, f"observed order {order:.3f}, errors {err}"
    # The motion is carried by the contact modes (omega_c ~ 7250 rad/s = 0.074 omega_max): at
    # omega_max dt = 0.0125 their phase error omega_c T (omega_c dt)^2 / 24 is 2.6e-6 over T = 0.01 s.
    assert err[-1] < 1e-5, f"error {err[-1]:.3g} at omega_max dt = {wdt[-1]}"


def test_convergence_rows_improve_with_the_mode_count(reduced_family):
    roms, full_hz = reduced_family
    rows = rom_convergence(roms, full_hz, (0.0, 0.0, 0.0), (0.0, 0.0, 200.0), 0.005, 20000.0, n_compare=4,
                           repeats=1)
    assert [r["n_modes"] for r in rows] == list(MODES)
    assert [r["n_freq_compared"] for r in rows] == [3, 4, 4, 4]  # 1 mode: three DOFs, three frequencies
    for key in ("open_freq_error", "closed_freq_error"):
        e = np.array([r[key] for r in rows])
        # non-increasing up to eigensolver round-off (a mode the tips cannot excite changes nothing: 1 -> 2)
        assert np.all(np.diff(e) <= 1e-9 * e[:-1]), f"{key} not decreasing: {e}"
        assert e[-1] < 1e-2 * e[0], f"{key}: {e}"
    assert rows[-1]["closed_freq_error"] < 1e-4
    ring = [r["ringdown_error"] for r in rows]
    assert ring[2] < 0.1 * ring[0], ring
    # The ringdown errors are against the largest mode count's exact run (its own row is 0 by
    # definition, so asserting it checks nothing). Check that reference itself by an independent
    # integrator: SciPy's DOP853 with event location on the same 10-mode model over the same window
    # (measured 2.0e-9 at rtol = 1e-8, i.e. DOP853's own error; the exact run is exact to round-off),
    # and that every other row's error is resolved far above it (measured 0.46, 0.46, 7.5e-3 for 1, 2,
    # 5 modes), so the column measures truncation of the modes, not integration error.
    rom = roms[max(MODES)]
    x0, v0 = initial_state(rom.M, rom.K, rom.P, np.zeros(3), (0.0, 0.0, 200.0))
    exact = ringdown(rom.system(), x0, v0, 0.005, 20000.0, "exact")
    dop = ringdown(rom.system(), x0, v0, 0.005, 20000.0, "dop853", rtol=1e-8)
    ref_err = relative_error(dop.x @ rom.P.T, exact.x @ rom.P.T)
    assert ref_err < 1e-7, f"10-mode exact reference against DOP853: {ref_err:.3g}"  # 50 x the measured 2e-9
    assert exact.stats["n_events"] > 20  # the window has impacts: the reference crosses the gaps
    assert all(e > 100 * ref_err for e in ring[:-1]), (ring, ref_err)
