"""The explicit integrator's set-up kept across runs (reduced.transient.explicit._cached, issue 28): a run of a model
seen before is the run of a fresh set-up, bit for bit, and any change of the model (an array changed in place, the
friction's sliders) is a new key."""

from __future__ import annotations

import numpy as np
import pytest

from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import Friction
from reduced.transient import explicit
from reduced.transient.explicit import integrate_explicit


def test_a_kept_set_up_gives_the_fresh_runs_bits(monkeypatch):
    s = DiscreteParams().system()
    v0 = np.array([0.0, 0.0, 200.0])
    first = integrate_explicit(s, np.zeros(3), v0, 0.02, 20000.0)
    again = integrate_explicit(s, np.zeros(3), v0, 0.02, 20000.0)
    with monkeypatch.context() as m:
        m.setattr(explicit, "_SETUP", {})
        fresh = integrate_explicit(s, np.zeros(3), v0, 0.02, 20000.0)
    for name in ("x", "v", "dissipated"):
        assert np.array_equal(getattr(again, name), getattr(fresh, name))
        assert np.array_equal(getattr(first, name), getattr(fresh, name))
    # a stop stiffness changed in place: a new key, so the new step and matrices, as a fresh set-up gives
    s.k[:] *= 4.0
    stiff = integrate_explicit(s, np.zeros(3), v0, 0.02, 20000.0)
    with monkeypatch.context() as m:
        m.setattr(explicit, "_SETUP", {})
        stiff_fresh = integrate_explicit(s, np.zeros(3), v0, 0.02, 20000.0)
    assert stiff.stats["dt"] == stiff_fresh.stats["dt"] < first.stats["dt"]
    assert np.array_equal(stiff.x, stiff_fresh.x)


def test_the_key_sees_the_friction():
    s = DiscreteParams().system()
    f1 = Friction(Bt=np.array([[1.0, 0.0, 0.0]]), tip=[0], k_t=1e7, mu=0.3, names=("t",))
    f2 = Friction(Bt=np.array([[1.0, 0.0, 0.0]]), tip=[0], k_t=2e7, mu=0.3, names=("t",))
    keys = {explicit._system_key(x) for x in (s, s.with_friction(f1), s.with_friction(f2))}
    assert len(keys) == 3


def test_a_replaced_function_keeps_its_values_to_itself(monkeypatch):
    # tests/test_integrators.py bypasses the stability refusal by replacing stability_limit: what the replacement
    # gives is kept under its own key, so the original still refuses a step beyond the limit afterwards.
    s = DiscreteParams().system()
    _, dt_crit = explicit.stability_limit(s)
    args = (s, np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.001, 20000.0)
    with monkeypatch.context() as m:
        m.setattr(explicit, "stability_limit", lambda system: (1.0, np.inf))
        integrate_explicit(*args, dt=0.9 * dt_crit)  # accepted: the limit is gone
    with pytest.raises(explicit.StepTooLargeError):
        integrate_explicit(*args, dt=0.9 * dt_crit)
