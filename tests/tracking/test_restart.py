"""A track restarted inside a running one moves at the two-point difference of the positions
(tracking/restart.py). Oracles: hand-derived values, and the simulated ground truth."""

import numpy as np

from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.tracking.models import ConstantRateModel, PaperModel
from wristtrack.tracking.restart import moving_start
from wristtrack.tracking.slide_model import SlidingSkinModel
from wristtrack.tracking.tracker import Status, Tracker, TrackerConfig


def test_the_velocity_is_the_difference_of_the_positions_and_nothing_else_moves():
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    model = SlidingSkinModel()
    x = model.initial_state(R, np.array([0.10, 0.02, 0.50]), s=np.array([0.001, -0.0005]))
    before = model.initial_state(np.eye(3), np.array([0.09, 0.03, 0.50]),
                                 np.array([5.0, 5.0, 5.0]), np.array([1.0, 2.0, 3.0]))
    moved = moving_start(model, x, before, 0.05)
    v, w = model.velocities(moved)
    np.testing.assert_allclose(v, [0.2, -0.2, 0.0], atol=1e-12)
    np.testing.assert_array_equal(w, np.zeros(3))  # the turn to a replaced orientation: none
    np.testing.assert_array_equal(moved[:12], x[:12])  # the fitted pose
    np.testing.assert_array_equal(moved[18:], x[18:])  # and the slide, as they were


def test_models_without_a_velocity_and_no_interval_keep_the_fit():
    x = PaperModel.initial_state(np.eye(3), np.array([0.1, 0.0, 0.5]))
    assert moving_start(PaperModel(), x, x + 0.01, 0.05) is x
    x = ConstantRateModel.initial_state(np.eye(3), np.zeros(3))
    assert moving_start(ConstantRateModel(), x, x, 0.0) is x


def test_a_fit_taken_afresh_mid_reach_moves_with_the_hand():
    """Mid-reach, the hand at 0.4-0.9 m/s, a frame fitted afresh (as a re-acquisition does)
    starts at the hand's speed, within 15 % (one frame's difference of two positions known to
    a fraction of a millimetre), where a start at rest is 100 % off."""
    rng = np.random.default_rng(3)
    truth, camera, layout = scenario("reach", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(p_miss=0.0), rng)
    speeds = np.linalg.norm(np.diff(truth.t_ch, axis=0), axis=1) / np.diff(truth.t)
    checked = 0
    for k in np.flatnonzero(speeds > 0.4)[::4] + 1:
        tracker = Tracker(camera, layout, TrackerConfig())
        for f in frames[:k]:
            tracker.step(f.detections)
        assert tracker.status == Status.TRACKING
        result = tracker.start_track(frames[k].detections, tracker._fit(frames[k].detections))
        dt = truth.t[k] - truth.t[k - 1]
        true_v = tracker.R_c0.T @ (truth.t_ch[k] - truth.t_ch[k - 1]) / dt
        v = tracker.model.velocities(tracker._track.x)[0]
        assert np.linalg.norm(v - true_v) < 0.15 * np.linalg.norm(true_v), (k, v, true_v)
        assert result.status == Status.TRACKING
        checked += 1
    assert checked >= 3
