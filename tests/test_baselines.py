"""The benchmark's peer trackers: the OpenCV per-frame baseline and the Stone Soup UKF."""

from __future__ import annotations

import numpy as np

from wristtrack.baselines.opencv_pnp import OpenCVPnPTracker
from wristtrack.geometry import rotation_distance
from wristtrack.measurements import Detections
from wristtrack.sim.detections import CLUTTER, NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.tracker import Status


def _noiseless(n_frames=12, p_miss=0.0, seed=0):
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario("flexion", rng=rng)
    noise = NoiseModel(pixel_sigma=0.0, depth_sigma_coeff=0.0, p_miss=p_miss, clutter_mean=3.0)
    frames = simulate_detections(truth, camera, layout, noise, rng)
    step = len(frames) // n_frames
    return truth, camera, layout, frames[::step][:n_frames], step


def test_opencv_baseline_is_exact_on_noiseless_frames():
    truth, camera, layout, frames, step = _noiseless()
    tracker = OpenCVPnPTracker(camera, layout)
    assert any((f.labels == CLUTTER).any() for f in frames)  # the labelling has work to do
    for k, f in enumerate(frames):
        r = tracker.step(f.detections)
        assert r.status == Status.TRACKING
        np.testing.assert_array_equal(r.labels, f.labels)
        i = k * step
        assert rotation_distance(r.R_ch, truth.R_ch[i]) < 1e-6
        np.testing.assert_allclose(r.t_ch, truth.t_ch[i], atol=1e-6)


def test_opencv_baseline_labels_with_missing_markers_and_refuses_too_few():
    truth, camera, layout, frames, step = _noiseless(n_frames=20, p_miss=0.25, seed=3)
    tracker = OpenCVPnPTracker(camera, layout)
    partial = 0
    for f in frames:
        n_markers = int((f.labels >= 0).sum())
        r = tracker.step(f.detections)
        if n_markers >= 4:
            np.testing.assert_array_equal(r.labels, f.labels)
            partial += n_markers < 6
        else:
            assert r.status == Status.LOST and not r.has_estimate
    assert partial > 0
    # three blobs cannot give a pose
    r = tracker.step(Detections(99.0, frames[0].detections.uv[:3], frames[0].detections.depth[:3]))
    assert not r.has_estimate and np.isnan(r.t_ch).all()
