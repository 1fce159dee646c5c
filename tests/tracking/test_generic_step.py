"""The generic step's update where the paper's per-blob rule gives two blobs to one marker.

Two blobs measuring one marker with independent errors are, for a Kalman update, one blob at
their mean with half the independent noise (the noise the markers share is not halved: both
blobs carry it), and the joint NIS is that blob's NIS plus the NIS of their difference, whose
covariance is the sum of the two blobs' own. Both identities are exact for one unscented update
(linear in the measurements given the sigma points), so they are the oracle here.
"""

from __future__ import annotations

import numpy as np
import pytest

from wristtrack.detect.detections import Detections
from wristtrack.filter import ukf
from wristtrack.tracking.generic_step import _labelled_update
from wristtrack.tracking.merged import measurement_map

from .test_compiled import _initialised_tracker


def _setup():
    """A tracker initialised on a simulated recording, its state, the state's measurement
    prediction and a random generator."""
    rng = np.random.default_rng(5)
    tracker = _initialised_tracker(seed=7)
    obs = tracker._observation(True)
    x, P = tracker._track.x, tracker._track.P
    pred = ukf.predict_measurement(tracker.model, x, P, obs, tracker.config.ukf)
    return tracker, obs, x, P, pred, rng


def test_two_blobs_of_one_marker_are_independent_measurements():
    tracker, obs, x, P, pred, rng = _setup()
    y = pred.y.reshape(6, 3)
    # markers 0-5 seen once, marker 2 twice: 4 mm apart in depth, 1.5 px in the image
    z = np.vstack((y, y[2] + [0.8, -0.7, 0.002])) + rng.normal(0, 1, (7, 3)) * [0.3, 0.3, 1e-3]
    det = Detections(1.0, z[:, :2].copy(), z[:, 2].copy())
    labels = np.array([0, 1, 2, 3, 4, 5, 2])
    own, shared = obs.noise_variance(x, pred.y), obs.shared_covariance(x)
    cfg = tracker.config
    both = _labelled_update(tracker.model, obs, (x, P), pred, (own, shared), det, z, labels,
                            cfg, 0)

    # the oracle: marker 2 once, at the mean of its two blobs, its own noise halved
    mean = z[:6].copy()
    mean[2] = 0.5 * (z[2] + z[6])
    A, values, blob, component = measurement_map(np.arange(6), mean, 3, 6)
    added = obs.blob_variance(None, 6)[blob] * (component < 2)
    halved = np.where(np.repeat(np.arange(6), 3) == 2, 0.5, 1.0)
    R = shared + np.diag(own * halved + added * halved)
    single = ukf.update(tracker.model, x, P, pred.mapped(A), values, R)

    np.testing.assert_allclose(both.x, single.x, rtol=0, atol=1e-9 * np.linalg.norm(x))
    np.testing.assert_allclose(both.P, single.P, rtol=0, atol=1e-9 * np.linalg.norm(P))
    diff = z[2] - z[6]
    diff_var = 2 * (own.reshape(6, 3)[2] + added.reshape(6, 3)[2])
    assert both.dof == 21
    assert both.nis == pytest.approx(single.nis + diff @ (diff / diff_var), rel=1e-9)
    assert both.nis < 100  # the old update's innovation covariance was singular: NIS ~1e12


def test_without_a_shared_marker_the_update_is_the_full_covariance_one():
    """A diag(own) A^T and the rows' own variances are the same matrix when no marker has two
    blobs: the one-to-one update is the plain full-noise one."""
    tracker, obs, x, P, pred, rng = _setup()
    y = pred.y.reshape(6, 3)
    z = y + rng.normal(0, 1, (6, 3)) * [0.3, 0.3, 1e-3]
    det = Detections(1.0, z[:, :2].copy(), z[:, 2].copy())
    labels = np.array([3, 1, -1, 0, 5, 4])
    own, shared = obs.noise_variance(x, pred.y), obs.shared_covariance(x)
    res = _labelled_update(tracker.model, obs, (x, P), pred, (own, shared), det, z, labels,
                           tracker.config, 0)
    A, values, blob, component = measurement_map(labels, z, 3, 6)
    added = obs.blob_variance(None, 6)[blob] * (component < 2)
    R = A @ (np.diag(own) + shared) @ A.T + np.diag(added)
    ref = ukf.update(tracker.model, x, P, pred.mapped(A), values, R)
    np.testing.assert_allclose(res.x, ref.x, rtol=0, atol=1e-12 * np.linalg.norm(x))
    np.testing.assert_allclose(res.P, ref.P, rtol=0, atol=1e-12 * np.linalg.norm(P))
