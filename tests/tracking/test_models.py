"""Motion models: retractions, propagation against closed-form motion, the paper's singularity."""

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.filter import ukf
from wristtrack.tracking.models import ConstantRateModel, PaperModel, ProcessNoise


def _random_state(rng):
    R = Rotation.random(random_state=rng).as_matrix()
    return ConstantRateModel.initial_state(R, *rng.standard_normal((3, 3)))


def test_retract_and_lift_are_inverse_on_so3():
    rng = np.random.default_rng(0)
    model = ConstantRateModel()
    x = _random_state(rng)
    xi = rng.standard_normal((20, 12)) * 0.5
    X = model.retract(x, xi)
    np.testing.assert_allclose(model.lift(x, X), xi, atol=1e-10)
    R = X[:, :9].reshape(-1, 3, 3)
    np.testing.assert_allclose(R @ R.swapaxes(1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)


def test_constant_rate_propagation_matches_closed_form_rotation():
    model = ConstantRateModel()
    w = np.array([0.3, -1.2, 0.8])
    R0 = Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix()
    x = ConstantRateModel.initial_state(R0, np.zeros(3), np.array([0.1, 0.0, -0.2]), w)
    dt, steps = 1 / 30, 60
    for _ in range(steps):
        x = model.propagate(x[None], np.zeros((1, 6)), dt)[0]
    T = dt * steps
    # spatial constant rate: R(T) = exp(w T) R0 (scipy as the oracle)
    expected = Rotation.from_rotvec(w * T).as_matrix() @ R0
    np.testing.assert_allclose(x[:9].reshape(3, 3), expected, atol=1e-12)
    np.testing.assert_allclose(x[9:12], np.array([0.1, 0.0, -0.2]) * T, atol=1e-12)


def test_angular_acceleration_noise_integrates_like_constant_acceleration():
    model = ConstantRateModel()
    x = ConstantRateModel.initial_state(np.eye(3), np.zeros(3))
    a = np.array([[1.0, 2.0, 3.0, 0.0, 0.0, 0.5]])
    dt = 0.1
    out = model.propagate(x[None], a, dt)[0]
    np.testing.assert_allclose(out[9:12], 0.5 * a[0, :3] * dt**2)
    np.testing.assert_allclose(out[12:15], a[0, :3] * dt)
    angle = Rotation.from_matrix(out[:9].reshape(3, 3)).as_rotvec()
    np.testing.assert_allclose(angle, [0, 0, 0.5 * 0.5 * dt**2], atol=1e-15)


def test_manifold_ukf_predict_keeps_mean_rotation_and_grows_uncertainty_as_random_walk():
    """With no rate, the orientation covariance must grow by the integrated acceleration noise."""
    model = ConstantRateModel(ProcessNoise(angular_accel=0.3))
    x = ConstantRateModel.initial_state(Rotation.from_rotvec([0.4, 0, 0]).as_matrix(), np.zeros(3))
    P = np.eye(12) * 1e-8
    dt, steps = 1 / 30, 30
    for _ in range(steps):
        x, P = ukf.predict(model, x, P, dt, model.process_noise(dt))
    T = dt * steps
    q = model.noise.angular_accel
    # integrated random-walk acceleration: var(angle) = q T^3 / 3 (continuous-time white noise)
    expected = q * T**3 / 3
    np.testing.assert_allclose(np.diag(P)[:3], expected, rtol=0.05)
    np.testing.assert_allclose(np.diag(P)[9:], q * T, rtol=1e-6)
    np.testing.assert_allclose(
        Rotation.from_matrix(x[:9].reshape(3, 3)).as_rotvec(), [0.4, 0, 0], atol=1e-9
    )


def test_paper_model_is_singular_at_the_neutral_pose():
    """Z-Y-Z Euler angles at identity: a small pronation is not a small change of the state."""
    model = PaperModel()
    x = PaperModel.initial_state(np.eye(3), np.zeros(3))
    turned = PaperModel.initial_state(Rotation.from_euler("X", -0.01).as_matrix(), np.zeros(3))
    # a 0.6 degree rotation about X moves the Euler state by about pi/2 in two angles
    assert np.linalg.norm(model.lift(x, turned[None])[0][6:]) > 2.0
    # while the default model's error state moves by exactly the rotation
    d = ConstantRateModel()
    a = ConstantRateModel.initial_state(np.eye(3), np.zeros(3))
    b = ConstantRateModel.initial_state(Rotation.from_euler("X", -0.01).as_matrix(), np.zeros(3))
    np.testing.assert_allclose(d.lift(a, b[None])[0][:3], [-0.01, 0, 0], atol=1e-15)


def test_paper_model_propagation_follows_paper_equations():
    model = PaperModel()
    R0 = Rotation.from_euler("ZYZ", [0.3, 0.5, -0.2]).as_matrix()
    x = PaperModel.initial_state(R0, np.array([0.1, 0.2, 0.3]), np.array([1.0, 0.0, -1.0]))
    n = np.array([[0.5, 0.0, 0.0, 0.2, -0.1, 0.3]])
    dt = 0.05
    out = model.propagate(x[None], n, dt)[0]
    np.testing.assert_allclose(out[:3], [0.1 + 0.05, 0.2, 0.3 - 0.05])
    np.testing.assert_allclose(out[3:6], [1.0 + 0.5 * dt, 0.0, -1.0])
    expected = R0 @ Rotation.from_rotvec(n[0, 3:] * dt).as_matrix()
    got = Rotation.from_euler("ZYZ", out[6:]).as_matrix()
    np.testing.assert_allclose(got, expected, atol=1e-12)
