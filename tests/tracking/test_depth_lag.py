"""A depth frame captured before or after its colour frame (Camera.depth_delay).

Truth: the depth along a marker's ray to its skin plane moved rigidly over the delay, worked
out here with SciPy's rotations; the rendered recording's ground truth (``simulate
--depth-lag`` renders the depth at the later instant, tests/sim/test_realism.py).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.hand import HandLayout
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import sample, scenario_motion
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import MarkerObservation
from wristtrack.tracking.results import Status
from wristtrack.tracking.tracker import Tracker, TrackerConfig


def test_a_lagged_depth_is_the_depth_of_the_moved_skin_along_the_markers_ray():
    """A hand 40 deg from facing the camera, moving at 0.6 m/s and turning at 3 rad/s; the
    depth frame 15 ms late. Each marker's predicted depth is where its ray (through where the
    colour frame sees it) meets its skin plane after the rigid motion over the delay: to the
    second order in the delay (0.2 mm here), where the lag itself moves the depth by mm."""
    camera = replace(Camera.default(), depth_delay=0.015)
    layout = HandLayout.default()
    R_c0, t_c0 = np.eye(3), np.array([0.0, 0.0, 0.6])
    R = Rotation.from_euler("xy", [40.0, 15.0], degrees=True).as_matrix()
    p, v, w = np.array([0.02, -0.01, 0.05]), np.array([0.3, -0.2, 0.45]), np.array([1.5, -2.0, 1.6])
    x = ConstantRateModel.initial_state(R, p, v, w)
    lagged = MarkerObservation(camera, layout.points, R_c0, t_c0, ConstantRateModel.pose, True,
                               rates_of=ConstantRateModel.rates)
    still = MarkerObservation(replace(camera, depth_delay=0.0), layout.points, R_c0, t_c0,
                              ConstantRateModel.pose, True, rates_of=ConstantRateModel.rates)
    y, y0 = lagged(x[None]).reshape(6, 3), still(x[None]).reshape(6, 3)
    np.testing.assert_array_equal(y[:, :2], y0[:, :2])  # the pixels are the colour frame's

    turn = Rotation.from_rotvec(w * camera.depth_delay).as_matrix()
    R1, p1 = turn @ R, p + v * camera.depth_delay
    markers, normal = layout.points @ R.T + p + t_c0, R[:, 2]
    moved, normal1 = layout.points @ R1.T + p1 + t_c0, R1[:, 2]
    rays = markers / markers[:, 2:]
    truth = (moved @ normal1) / (rays @ normal1)
    assert np.abs(truth - y0[:, 2]).min() > 2e-3  # the lag moves each reading by mm
    np.testing.assert_allclose(y[:, 2], truth, atol=2e-4)
    assert np.allclose(markers @ normal, (markers @ normal)[0])  # one plane: the flat layout


def test_a_stated_depth_delay_brings_a_rendered_reach_back_to_the_truth(tmp_path,
                                                                        stated_against_unsaid):
    """A fast reach rendered with its depth 16.6 ms after the colour (the longest the pairing
    allows at 30 fps). Tracked with camera.json's depth_delay_s, then with it removed: the
    stated delay halves the position error and cuts the orientation's by a third
    (0.19 against 0.43 mm and 0.25 against 0.37 deg when written)."""
    rec, errors = stated_against_unsaid("--depth-lag", "depth_delay_s")
    assert Camera.load(rec / "camera.json").depth_delay > 0.016
    assert main(["report", str(tmp_path / "run_stated")]) == 0  # and says when depth was read
    delay_ms = 1e3 * Camera.load(rec / "camera.json").depth_delay
    assert (f"each depth frame captured {delay_ms:.1f} ms after its colour frame (camera.json), "
            "read where the hand had moved" in (tmp_path / "run_stated" / "report.html")
            .read_text(encoding="utf-8"))
    stated, unsaid = errors["stated"], errors["unsaid"]
    assert stated["position_rmse_mm"] < 0.6 * unsaid["position_rmse_mm"]
    assert stated["orientation_rmse_deg"] < 0.8 * unsaid["orientation_rmse_deg"]


def _lagged_reach(delays: np.ndarray) -> tuple:
    """The first frames of the reach scenario as a detector would see them, each frame's depths
    read ``delays[k]`` s after its colour (the skin's depth along each marker's ray then); the
    scenario's camera (no delay stated) and hand."""
    motion, (R_c0, t_c0) = scenario_motion("reach")
    times = np.arange(len(delays)) / 30.0
    truth, later = sample(motion, times, R_c0, t_c0), sample(motion, times + delays, R_c0, t_c0)
    camera, layout = Camera.default(), HandLayout.default()
    noise = NoiseModel(clutter_mean=0.0, p_miss=0.0)
    frames = []
    for k, sim in enumerate(simulate_detections(truth, camera, layout, noise, rng=3)):
        det, points = sim.detections, layout.points[sim.labels]
        now = points @ truth.R_ch[k].T + truth.t_ch[k]
        moved, normal = points @ later.R_ch[k].T + later.t_ch[k], later.R_ch[k][:, 2]
        lagged = (moved @ normal) / ((now / now[:, 2:]) @ normal) + (det.depth - now[:, 2])
        frames.append(replace(det, depth=lagged))
    return frames, camera, layout


def _track(camera: Camera, layout: HandLayout, frames: list, delays=None) -> tuple:
    """Each frame's camera pose (R (N, 3, 3), t (N, 3)), the frames given ``delays[k]`` as
    their own (Detections.depth_delay); and the tracker."""
    tracker = Tracker(camera, layout, TrackerConfig())
    results = [tracker.step(replace(det, depth_delay=None if delays is None else delays[k]))
               for k, det in enumerate(frames)]
    assert all(r.status == Status.TRACKING for r in results[1:])
    return np.array([r.R_ch for r in results]), np.array([r.t_ch for r in results]), tracker


def test_each_frames_stamped_delay_is_read_as_a_stated_one_and_a_stated_one_wins():
    """A camera stamps each depth frame (a RealSense, an OpenNI2 device, a ROS bag), and each
    frame is read at its own delay (Detections.depth_delay) as camera.json's depth_delay_s would
    have it read: the same poses for depth 12 ms late throughout. Where the two clocks' phase
    slips past half a frame, the nearest depth frame becomes the one before: from that frame on
    the poses leave the 12 ms ones. A delay camera.json states wins over the frames' own."""
    n, slip = 75, 60  # the hand starts moving at frame 45
    late = np.full(n, 0.012)
    frames, camera, layout = _lagged_reach(late)
    R_stated, t_stated, _ = _track(replace(camera, depth_delay=0.012), layout, frames)
    R_own, t_own, tracker = _track(camera, layout, frames, late)
    np.testing.assert_allclose(t_own, t_stated, atol=1e-12)
    np.testing.assert_allclose(R_own, R_stated, atol=1e-12)
    assert tracker.depth_timing.to_dict() == {"from": "frame stamps", "frames": n,
                                              "delay_ms": 12.0, "min_ms": 12.0, "max_ms": 12.0}
    _, t_none, _ = _track(camera, layout, frames)
    assert np.abs(t_none - t_own)[50:].max() > 5e-5  # the delay moves the moving hand's poses

    slipped = np.where(np.arange(n) < slip, 0.012, -0.021)
    _, t_slip, tracker = _track(camera, layout, frames, slipped)
    np.testing.assert_allclose(t_slip[:slip], t_own[:slip], atol=1e-12)
    assert np.abs(t_slip[slip] - t_own[slip]).max() > 1e-5
    assert tracker.depth_timing.to_dict()["min_ms"] == -21.0

    stated = replace(camera, depth_delay=-0.005)
    _, t_wins, tracker = _track(stated, layout, frames, late)
    np.testing.assert_array_equal(t_wins, _track(stated, layout, frames)[1])
    assert tracker.depth_timing.to_dict() == {"from": "camera.json", "delay_ms": -5.0}
