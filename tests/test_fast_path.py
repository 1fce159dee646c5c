"""The tracker's fast path (sigma points as columns, quaternions, block-Cholesky gating) against
the reference code it replaces on the hot path: same numbers to rounding, same associations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack import associate as assoc
from wristtrack import ukf
from wristtrack.motion import QUAT_TO_MATRIX, ConstantRateModel, quat_of_matrix, quat_to_matrix
from wristtrack.sim.run import track_scenario
from wristtrack.tracker import Tracker, TrackerConfig, _FastStep


def test_sigma_propagator_matches_retract_propagate_lift():
    rng = np.random.default_rng(0)
    model = ConstantRateModel()
    R = Rotation.random(random_state=1).as_matrix()
    x = ConstantRateModel.initial_state(R, *rng.standard_normal((3, 3)))
    A = rng.standard_normal((12, 12)) * 0.1
    P = A @ A.T + np.eye(12) * 1e-3
    dt = 1 / 30
    sigma = ukf.SigmaColumns(model.dim, model.noise_dim)
    sigma.set_covariance(P)
    prop = model.sigma_propagator()
    out = np.empty((prop.ROWS, sigma.offsets.shape[1]))
    q_centre = prop.propagate(x, sigma.offsets, dt, quat_of_matrix(x[:9].tolist()), out)

    # the reference: the same offsets as rows, the noise scaled by its standard deviation
    offsets = sigma.offsets[:18].T.copy()
    offsets[:, 12:] *= np.sqrt(np.diag(model.process_noise(dt)))
    X = model.propagate(model.retract(x, offsets[:, :12]), offsets[:, 12:], dt)
    xi = model.lift(X[0], X)
    np.testing.assert_allclose(out[prop.LIFTS].T, xi, atol=1e-14)
    features = out[prop.FEATURES]
    np.testing.assert_allclose(features[1:10].T, X[:, 9:], atol=1e-14)
    # vec(q q^T) of each sigma point's orientation gives its rotation matrix
    np.testing.assert_allclose((QUAT_TO_MATRIX @ features[10:]).T, X[:, :9], atol=1e-14)
    centre = np.array(quat_to_matrix(q_centre)).reshape(3, 3) @ R
    np.testing.assert_allclose(centre.reshape(9), X[0, :9], atol=1e-14)


def test_quaternion_of_matrix_round_trips_at_every_angle():
    for R in Rotation.random(200, random_state=3).as_matrix():
        q = quat_of_matrix(R.reshape(9).tolist())
        np.testing.assert_allclose(np.array(quat_to_matrix(q)).reshape(3, 3), R, atol=1e-15)
    for angle in (np.pi, np.pi - 1e-9, 1e-12, 0.0):  # the branches of Shepperd's method
        for axis in np.eye(3):
            R = Rotation.from_rotvec(angle * axis).as_matrix()
            q = quat_of_matrix(R.reshape(9).tolist())
            np.testing.assert_allclose(np.array(quat_to_matrix(q)).reshape(3, 3), R, atol=1e-15)


def _random_problem(rng, J=6, M=9, spread=40.0):
    y = np.column_stack((rng.uniform(100, 500, (J, 2)), rng.uniform(0.5, 1.0, J)))
    A = rng.standard_normal((J, 3, 3)) * np.array([2.0, 2.0, 2e-3])[:, None]
    S = A @ A.swapaxes(1, 2) + np.diag([0.5, 0.5, 1e-6])
    z = y[rng.integers(0, J, M)] + rng.standard_normal((M, 3)) * np.array([spread, spread, 0.01])
    return y, S, z


def _gate_inputs(y, S, z):
    """The axis-major (3J, 3J) covariance and (3J, M) differences BlockGate takes."""
    J = len(y)
    S_full = np.zeros((3 * J, 3 * J))
    idx = np.arange(3)[:, None] * J  # row of (axis a, marker j) is a J + j
    for j in range(J):
        S_full[np.ix_((idx + j).ravel(), (idx + j).ravel())] = S[j]
    D = (z.T[:, None, :] - y.T[:, :, None]).reshape(3 * J, -1)
    return S_full, D


@pytest.mark.parametrize("spread", [0.5, 3.0, 40.0])
def test_block_gate_gives_the_reference_gnn_pairs(spread):
    params = assoc.AssociationParams()
    gate = assoc.BlockGate(6, params)
    rng = np.random.default_rng(11)
    clashes = 0
    for _ in range(200):
        y, S, z = _random_problem(rng, spread=spread)
        llr, d2 = assoc.log_likelihood_ratios(z, y, S, params)
        labels = assoc.associate_gnn(assoc.pair_scores(llr, params), assoc.gate(d2, z, params))
        expected = sorted((int(j), b) for b, j in enumerate(labels) if j >= 0)
        half_m2, constants = gate.distances(*_gate_inputs(y, S, z))
        np.testing.assert_allclose(2 * half_m2.T, d2, rtol=1e-9, atol=1e-9)
        nearest = half_m2.argmin(axis=1)
        clashes += len(set(nearest)) < len(nearest)
        assert gate.assign(half_m2, constants) == expected
    assert spread < 1 or clashes  # the clash (solver) branch was exercised


def test_block_gate_treats_a_nan_distance_as_never_gated():
    params = assoc.AssociationParams()
    gate = assoc.BlockGate(6, params)
    rng = np.random.default_rng(5)
    y, S, z = _random_problem(rng, spread=0.5)
    z[2] = np.nan
    llr, d2 = assoc.log_likelihood_ratios(z, y, S, params)
    labels = assoc.associate_gnn(assoc.pair_scores(llr, params), assoc.gate(d2, z, params))
    expected = sorted((int(j), b) for b, j in enumerate(labels) if j >= 0)
    assert gate.assign(*gate.distances(*_gate_inputs(y, S, z))) == expected


def test_block_gate_declines_a_block_that_is_not_positive_definite():
    gate = assoc.BlockGate(6, assoc.AssociationParams())
    rng = np.random.default_rng(2)
    y, S, z = _random_problem(rng)
    S[3] = -S[3]
    assert gate.distances(*_gate_inputs(y, S, z)) is None


@pytest.mark.parametrize("name", ["pronation", "mix"])
def test_tracker_fast_path_matches_the_generic_path(monkeypatch, name):
    """Acceptance noise: clutter, misses, an occlusion, irregular frame intervals."""
    steps = []
    step = _FastStep.step

    def counted(self, *args):
        out = step(self, *args)
        steps.append(out is not None)
        return out

    monkeypatch.setattr(_FastStep, "step", counted)
    fast = track_scenario(name, TrackerConfig(), seed=2)
    assert sum(steps) > 0.9 * len(fast.results)
    monkeypatch.setattr(Tracker, "_fast_step", lambda self, det: None)
    generic = track_scenario(name, TrackerConfig(), seed=2)
    for a, b in zip(fast.results, generic.results, strict=True):
        assert a.status == b.status
        np.testing.assert_array_equal(a.labels, b.labels)
        if a.has_estimate:
            np.testing.assert_allclose(a.R_ch, b.R_ch, atol=1e-12)
            np.testing.assert_allclose(a.t_ch, b.t_ch, atol=1e-12)
            np.testing.assert_allclose(a.w, b.w, atol=1e-10)
            np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(a.nis, b.nis, rtol=1e-9)
            assert a.nis_dof == b.nis_dof
