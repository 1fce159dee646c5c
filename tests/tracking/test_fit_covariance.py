"""The covariance a fresh fit starts its track with (generic_step.fit_covariance): the Gaussian
posterior of a wide prior and the frame's markers under the filter's measurement model, against
the same posterior built from a finite-difference Jacobian (information form). On rendered
frames: tests/tracking/test_manoeuvre.py (a fit after a long gap under every effect)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.hand import HandLayout
from wristtrack.sim.motion import neutral_camera_pose
from wristtrack.tracking import generic_step
from wristtrack.tracking.config import TrackerConfig
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import MarkerObservation


def test_fit_covariance_is_the_information_form_posterior():
    camera, layout = Camera.default(), HandLayout.default()
    R_c0, t_c0 = neutral_camera_pose()
    model = ConstantRateModel()
    obs = MarkerObservation(camera, layout.points, R_c0, t_c0, model.pose, True)
    R = Rotation.from_euler("xyz", [20, -30, 10], degrees=True).as_matrix()
    x = model.initial_state(R, np.array([0.02, -0.01, 0.04]))
    y = obs(x[None])[0].reshape(6, 3)
    labels = np.array([3, -1, 0, 1, 2, 4, 5])  # one clutter blob; marker order shuffled
    blobs = np.vstack([y[3], [100.0, 100.0, 0.5], y[0], y[1], y[2], y[4], y[5]])
    det = Detections(0.0, blobs[:, :2], blobs[:, 2])
    config = TrackerConfig()
    P = generic_step.fit_covariance(model, obs, x, det, labels, config)

    # oracle: h linearised by central differences on the tangent, posterior in information form
    n = model.dim
    J = np.zeros((18, n))
    for i in range(n):
        d = np.zeros(n)
        d[i] = 1e-6
        J[:, i] = (obs(model.retract(x, d[None]))[0] - obs(model.retract(x, -d[None]))[0]) / 2e-6
    order = np.concatenate([np.arange(j * 3, j * 3 + 3) for j in (3, 0, 1, 2, 4, 5)])
    Rn = np.diag(obs.noise_variance(x, obs(x[None])[0])) + obs.shared_covariance(x)
    P0 = generic_step.fit_covariance(model, obs, x, Detections(0.0, np.zeros((0, 2)),
                                                                 np.zeros(0)), labels[:0], config)
    Jo, Ro = J[order], Rn[np.ix_(order, order)]
    oracle = np.linalg.inv(np.linalg.inv(P0) + Jo.T @ np.linalg.solve(Ro, Jo))
    sd, sd_oracle = np.sqrt(np.diag(P)), np.sqrt(np.diag(oracle))
    np.testing.assert_allclose(sd, sd_oracle, rtol=0.02)
    assert np.linalg.norm(P - oracle) < 0.02 * np.linalg.norm(oracle)
    # the velocities keep the prior's spread; the pose is far tighter than the prior's
    np.testing.assert_allclose(np.diag(P)[6:], np.diag(P0)[6:], rtol=1e-6)
    assert (sd[:6] < 0.2 * np.sqrt(np.diag(P0))[:6]).all()
