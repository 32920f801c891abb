"""The exact families' per-point shortcuts (issue 25, session 14) against the slower ways they replace.

- The test signs of a point (fold, pitchfork and period-doubling channels) are the signs of det(A - I) and
  det(A + I) on each symmetry block, taken by elimination (:func:`reduced.periodic.exact_frc._det_signs`)
  instead of from the eigenvalues (:func:`reduced.periodic.exact_frc._real_signs_pm`, the old way).
- The peaks of an orbit skip a contact-state stretch whose closed form is bounded inside the extremes already
  found (:func:`reduced.periodic.forced_shooting._node_peaks`): the largest and smallest values over all
  nodes are those of each node alone (no skip across nodes), bit for bit, and those of a dense sampling of
  the flow (an independent march) to its resolution.
"""

import math
from dataclasses import replace

import numpy as np
import pytest

import reduced.periodic.exact_frc as ef
from bearingshaft.scenes import load_scene
from bearingshaft.stages.frc_friction import load_vector
from bearingshaft.systems import model_system
from reduced.periodic.forced_shooting import ForcedFlow


def test_det_signs_are_the_eigenvalue_signs():
    rng = np.random.default_rng(0)
    for i in range(1500):
        m = int(rng.integers(1, 25))  # up to the reduced beam's state blocks
        A = rng.standard_normal((m, m)) * 10 ** rng.uniform(-2, 2)
        if i % 3 == 0:  # multipliers near the unit circle, real and complex, on both sides of +-1
            A *= rng.uniform(0.5, 2.0) / np.max(np.abs(np.linalg.eigvals(A)))
        assert ef._det_signs(A) == ef._real_signs_pm(np.linalg.eigvals(A))
    # a real eigenvalue on the other side of +1 and of -1 flips the sign; a complex pair never does
    assert ef._det_signs(np.diag([1.5, 0.5])) == (-1.0, 1.0)
    assert ef._det_signs(np.diag([-1.5, 0.5])) == (1.0, -1.0)
    assert ef._det_signs(np.array([[0.0, -2.0], [2.0, 0.0]])) == (1.0, 1.0)
    assert ef._det_signs(np.eye(3)) == (0.0, 1.0)


@pytest.fixture(scope="module")
def flow_nodes():
    """The discrete model at 10 N and 8 node states of twice its linear orbit at 30 Hz (the stops close)."""
    scene = load_scene("discrete-frc")
    spec = replace(scene.frc, branch_switching=False, cover_families=0)
    system, rows = model_system(scene.model)
    b = load_vector(spec, rows, tuple(scene.model.point_names))
    flow = ForcedFlow(system, b, 10.0)
    w = 2 * math.pi * 30.0
    S = 8
    t0 = np.arange(S) * (2 * math.pi / w / S)
    Yc = flow.particular(w)[0][0, :, 0]  # the open state's [H b; i Omega H b]
    Y0 = 2.0 * 10.0 * (Yc[None, :] * np.exp(1j * w * t0)[:, None]).real
    assert np.max(np.abs(Y0[:, : system.n] @ system.B.T)) > np.max(np.abs(system.offset))  # in contact
    return flow, Y0, t0, w, np.ascontiguousarray(rows, float)


def test_peaks_skip_keeps_every_extreme(flow_nodes):
    flow, Y0, t0, w, rows = flow_nodes
    h = 2 * math.pi / w / len(t0)
    pmax, pmin = flow.peaks(Y0, t0, h, w, rows)
    alone = [flow.peaks(Y0[k:k + 1], t0[k:k + 1], h, w, rows) for k in range(len(t0))]
    assert np.array_equal(pmax, np.max([a[0] for a in alone], axis=0))
    assert np.array_equal(pmin, np.min([a[1] for a in alone], axis=0))
    # an independent march: each segment from its own node, 4000 samples a segment
    x = flow.sample(Y0, w, 1, 4000)[:, : flow.n] @ rows.T
    scale = np.max(np.abs(x))
    assert np.all(x.max(axis=0) <= pmax + 1e-12 * scale) and np.all(x.min(axis=0) >= pmin - 1e-12 * scale)
    assert np.allclose(x.max(axis=0), pmax, rtol=0, atol=1e-6 * scale)
    assert np.allclose(x.min(axis=0), pmin, rtol=0, atol=1e-6 * scale)
