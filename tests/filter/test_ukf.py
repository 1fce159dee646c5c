"""The generic UKF against independent oracles: the linear Kalman filter and FilterPy."""

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from wristtrack.filter import ukf


def _kalman_filter(x, P, F, Q, H, R, zs):
    """Textbook linear Kalman filter, written out independently of the UKF."""
    out = []
    for z in zs:
        x = F @ x
        P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (z - H @ x)
        P = (np.eye(len(x)) - K @ H) @ P
        out.append((x, P))
    return out


@pytest.mark.parametrize("mode", ["additive", "augmented", "fused"])
def test_ukf_reduces_to_kalman_filter_on_linear_gaussian_problem(mode):
    rng = np.random.default_rng(1)
    n, m, q = 4, 2, 2
    F = np.eye(n) + 0.1 * rng.standard_normal((n, n))
    G = rng.standard_normal((n, q))
    Qn = np.diag([0.3, 0.1])
    Q = G @ Qn @ G.T
    H = rng.standard_normal((m, n))
    R = np.diag([0.2, 0.5])
    x0, P0 = rng.standard_normal(n), np.eye(n)
    zs = rng.standard_normal((15, m))

    if mode != "additive":
        model = ukf.EuclideanModel(n, lambda X, N, dt: X @ F.T + N @ G.T, noise_dim=q)
        kw = {"Q_noise": Qn}
    else:
        model = ukf.EuclideanModel(n, lambda X, N, dt: X @ F.T)
        kw = {"Q_additive": Q}
    x, P = x0, P0
    params = ukf.UKFParams(alpha=0.7, beta=2.0, kappa=1.0)
    for z, (x_kf, P_kf) in zip(zs, _kalman_filter(x0, P0, F, Q, H, R, zs), strict=True):
        if mode == "fused":  # measurement sigma points = the propagated ones
            x, P, pred = ukf.predict_with_measurement(
                model, x, P, 1.0, Qn, lambda X: X @ H.T, params=params
            )
        else:
            x, P = ukf.predict(model, x, P, 1.0, params=params, **kw)
            pred = ukf.predict_measurement(model, x, P, lambda X: X @ H.T, params=params)
        res = ukf.update(model, x, P, pred, z, R)
        x, P = res.x, res.P
        np.testing.assert_allclose(x, x_kf, atol=1e-9, rtol=0)
        np.testing.assert_allclose(P, P_kf, atol=1e-9, rtol=0)


def test_ukf_matches_filterpy_on_nonlinear_additive_noise_problem():
    # A 2-D constant-velocity target seen through range and bearing from the origin.
    dt = 0.1

    def fx(x, dt):
        x = np.atleast_2d(x)
        out = x.copy()
        out[:, 0] += x[:, 2] * dt + 0.05 * np.sin(x[:, 1])
        out[:, 1] += x[:, 3] * dt
        return out

    def hx(x):
        x = np.atleast_2d(x)
        return np.stack((np.hypot(x[:, 0], x[:, 1]), np.arctan2(x[:, 1], x[:, 0])), axis=1)

    alpha, beta, kappa = 0.5, 2.0, -1.0
    points = MerweScaledSigmaPoints(4, alpha=alpha, beta=beta, kappa=kappa)
    ref = UnscentedKalmanFilter(
        dim_x=4, dim_z=2, dt=dt, points=points,
        fx=lambda x, dt: fx(x, dt)[0], hx=lambda x: hx(x)[0],
    )
    ref.x = np.array([10.0, 5.0, 1.0, -0.5])
    ref.P = np.diag([1.0, 1.0, 0.3, 0.3])
    ref.Q = np.diag([1e-3, 1e-3, 1e-2, 1e-2])
    ref.R = np.diag([0.05, 1e-3])

    model = ukf.EuclideanModel(4, lambda X, N, dt: fx(X, dt))
    params = ukf.UKFParams(alpha, beta, kappa)
    x, P = ref.x.copy(), ref.P.copy()
    rng = np.random.default_rng(2)
    truth = ref.x.copy()
    for _ in range(25):
        truth = fx(truth, dt)[0]
        z = hx(truth)[0] + rng.normal(0, [0.2, 0.03])
        ref.predict()
        x, P = ukf.predict(model, x, P, dt, Q_additive=ref.Q, params=params)
        np.testing.assert_allclose(x, ref.x, atol=1e-8, rtol=0)
        np.testing.assert_allclose(P, ref.P, atol=1e-8, rtol=0)
        # We redraw sigma points from the predicted (x, P); so must FilterPy for a like comparison.
        ref.sigmas_f = points.sigma_points(ref.x, ref.P)
        ref.update(z)
        pred = ukf.predict_measurement(model, x, P, hx, params=params)
        res = ukf.update(model, x, P, pred, z, ref.R)
        x, P = res.x, res.P
        np.testing.assert_allclose(x, ref.x, atol=1e-8, rtol=0)
        np.testing.assert_allclose(P, ref.P, atol=1e-8, rtol=0)


def test_update_with_selected_rows_equals_update_with_reduced_function():
    rng = np.random.default_rng(3)
    H = rng.standard_normal((5, 3))
    model = ukf.EuclideanModel(3, lambda X, N, dt: X)
    x, P = rng.standard_normal(3), np.diag([1.0, 2.0, 0.5])
    rows = np.array([0, 3, 4])
    z = rng.standard_normal(3)
    full = ukf.predict_measurement(model, x, P, lambda X: np.sin(X @ H.T))
    sub = ukf.predict_measurement(model, x, P, lambda X: np.sin(X @ H[rows].T))
    a = ukf.update(model, x, P, full, z, np.full(3, 0.1), rows=rows)
    b = ukf.update(model, x, P, sub, z, np.full(3, 0.1))
    np.testing.assert_allclose(a.x, b.x, atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, atol=1e-12)
    # NIS equals the innovation's squared Mahalanobis distance under S
    S = sub.Pyy + 0.1 * np.eye(3)
    nu = z - sub.y
    assert a.nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-10)


def test_safe_cholesky_survives_indefinite_and_singular_matrices():
    A = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    L = ukf.safe_cholesky(A)
    assert np.all(np.isfinite(L))
    # the factor reproduces the positive part of the spectrum
    np.testing.assert_allclose(L @ L.T, [[1.5, 1.5], [1.5, 1.5]], atol=1e-6)
    singular = np.outer([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    L = ukf.safe_cholesky(singular)
    np.testing.assert_allclose(L @ L.T, singular, atol=1e-6)


def test_sigma_weights_match_filterpy():
    for n, a, b, k in [(3, 1e-3, 2.0, 0.0), (18, 1.0, 2.0, 0.0), (6, 0.5, 2.0, 3.0 - 6)]:
        pts = MerweScaledSigmaPoints(n, a, b, k)
        w = ukf.sigma_weights(n, a, b, k)
        np.testing.assert_allclose(w.mean, pts.Wm, rtol=1e-12)
        np.testing.assert_allclose(w.cov, pts.Wc, rtol=1e-12)


def test_the_iterated_update_reaches_the_map_estimate_that_one_update_stops_short_of():
    """A far prior met by a strongly nonlinear measurement (bearing and range of a point seen
    from the origin; the prior 60 deg off): iterated posterior linearisation converges to the
    maximum a posteriori estimate, found independently by SciPy's least squares on the MAP
    cost; one unscented correction stops short of it. On a linear measurement the iteration
    changes nothing (the Kalman filter's answer)."""
    from scipy.optimize import least_squares

    model = ukf.EuclideanModel(2, lambda X, N, dt: X)

    def h(X):
        return np.column_stack((np.arctan2(X[:, 1], X[:, 0]), np.hypot(X[:, 0], X[:, 1])))

    x0, P0 = np.array([1.0, 0.0]), np.diag([0.6, 0.6]) ** 2
    R = np.diag([0.01, 0.02]) ** 2
    z = h(np.array([[np.cos(1.05), np.sin(1.05)]]) * 1.1)[0]
    rows = np.arange(2)

    def map_residuals(x):
        cost_prior = np.linalg.cholesky(np.linalg.inv(P0)).T @ (x - x0)
        return np.concatenate((cost_prior, (z - h(x[None])[0]) / np.sqrt(np.diag(R))))

    x_map = least_squares(map_residuals, x0 + [0.0, 0.5]).x
    pred = ukf.predict_measurement(model, x0, P0, h)
    once = ukf.update(model, x0, P0, pred, z, R)
    again = ukf.iterated_update(model, (x0, P0), (once.x, once.P), h, z, R, rows, iterations=5)
    assert np.linalg.norm(once.x - x_map) > 0.05
    np.testing.assert_allclose(again.x, x_map, atol=1e-4)

    H = np.array([[1.0, 0.5], [-0.3, 2.0]])

    def linear(X):
        return X @ H.T

    pred = ukf.predict_measurement(model, x0, P0, linear)
    once = ukf.update(model, x0, P0, pred, z, R)
    again = ukf.iterated_update(model, (x0, P0), (once.x, once.P), linear, z, R, rows, iterations=3)
    K = P0 @ H.T @ np.linalg.inv(H @ P0 @ H.T + R)
    np.testing.assert_allclose(again.x, x0 + K @ (z - H @ x0), atol=1e-10)
    np.testing.assert_allclose(again.P, P0 - K @ H @ P0, atol=1e-10)


def test_a_linear_map_of_a_prediction_is_the_prediction_of_the_mapped_measurement():
    """Averaging or selecting predicted measurements (merged blobs, associated markers) needs no
    second unscented transform: the mapped prediction equals the transform of A h, and so does
    the update with it (the iterated update with rows=None taking A h as its h)."""
    rng = np.random.default_rng(3)
    model = ukf.EuclideanModel(3, lambda X, N, dt: X)

    def h(X):
        return np.column_stack((np.sin(X[:, 0]) * X[:, 1], X[:, 2] ** 2, X[:, 0] + X[:, 1]))

    A = np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]])
    x0, P0 = rng.standard_normal(3), np.diag([0.2, 0.3, 0.1])

    def mapped_h(X):
        return h(X) @ A.T

    direct = ukf.predict_measurement(model, x0, P0, mapped_h)
    mapped = ukf.predict_measurement(model, x0, P0, h).mapped(A)
    for a, b in ((mapped.y, direct.y), (mapped.Pyy, direct.Pyy), (mapped.Pxy, direct.Pxy)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)
    z, R = direct.y + [0.05, -0.02], np.diag([0.01, 0.02])
    once = ukf.update(model, x0, P0, mapped, z, R)
    np.testing.assert_allclose(once.x, ukf.update(model, x0, P0, direct, z, R).x, rtol=1e-12)
    again = ukf.iterated_update(model, (x0, P0), (once.x, once.P), mapped_h, z, R, None)
    rows_again = ukf.iterated_update(model, (x0, P0), (once.x, once.P), mapped_h, z, R,
                                     np.arange(2))
    np.testing.assert_array_equal(again.x, rows_again.x)


class _Rotation:
    """A rotation as the state (row-major matrix), its error on the left: R = exp(phi) R_hat
    (SciPy's rotation vectors as the exponential and the logarithm)."""

    dim, noise_dim = 3, 0

    def retract(self, x, xi):
        R = Rotation.from_rotvec(xi) * Rotation.from_matrix(x.reshape(3, 3))
        return R.as_matrix().reshape(-1, 9)

    def lift(self, x, X):
        R_hat = Rotation.from_matrix(x.reshape(3, 3))
        return (Rotation.from_matrix(X.reshape(-1, 3, 3)) * R_hat.inv()).as_rotvec()


def test_the_iterated_update_on_a_rotation_reaches_the_map_estimate(monkeypatch):
    """A rotation's prior, sure about two axes and less about the third, 50 deg from where two
    seen directions put it (a long gap, then the hand seen again). The prior's covariance lives
    in the tangent space at its own mean: carried into the posterior's (ukf.transported), the
    iterated update reaches the maximum a posteriori estimate that SciPy's least squares finds
    on the prior's own cost; taken there as it is, its axes turn with the posterior and the
    update lands 0.2 deg off it."""
    from scipy.optimize import least_squares

    model = _Rotation()
    a = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])

    def h(X):
        return np.einsum("sij,kj->ski", X.reshape(-1, 3, 3), a).reshape(-1, 6)

    x0 = np.eye(3).reshape(9)
    P0 = np.diag([0.9, 0.3, 0.2]) ** 2
    truth = Rotation.from_rotvec([0.5, 0.5, 0.4]).as_matrix().reshape(9)
    R = np.eye(6) * 0.05**2
    z = h(truth[None])[0] + np.array([0.02, -0.03, 0.01, 0.03, 0.0, -0.02])
    L0 = np.linalg.cholesky(np.linalg.inv(P0)).T

    def map_residuals(phi):
        x = model.retract(x0, phi[None])
        return np.concatenate((L0 @ model.lift(x0, x)[0], (z - h(x)[0]) / 0.05))

    x_map = model.retract(x0, least_squares(map_residuals, np.zeros(3), xtol=1e-12).x[None])[0]
    pred = ukf.predict_measurement(model, x0, P0, h)
    once = ukf.update(model, x0, P0, pred, z, R)

    def off(x):  # deg from the MAP estimate
        return np.degrees(np.linalg.norm(model.lift(x_map, x[None])[0]))

    again = ukf.iterated_update(model, (x0, P0), (once.x, once.P), h, z, R, None, iterations=4)
    assert off(once.x) > 5.0 and off(again.x) < 0.01, (off(once.x), off(again.x))
    monkeypatch.setattr(ukf, "transported",
                        lambda m, prior, x1, P1, eps, w: (m.lift(x1, prior[0][None])[0], prior[1]))
    as_it_is = ukf.iterated_update(model, (x0, P0), (once.x, once.P), h, z, R, None, iterations=4)
    assert off(as_it_is.x) > 0.1, off(as_it_is.x)


def test_chi2_quantile_is_scipy_stats_chi2_ppf():
    """The NIS and gate bounds (scipy.special's chdtri, cached) against scipy.stats."""
    for prob in (0.9, 0.99, 0.999, 0.9999):
        for dof in (1, 2, 3, 12, 18):
            assert ukf.chi2_quantile(prob, dof) == pytest.approx(chi2.ppf(prob, dof), rel=1e-10)
