"""tracking.offset_model: the depth map's offset from the colour image in the filter's state.

Truth: the depth of a tilted plane along a pixel's ray intersected by hand; the misregistration
the renderer applies to its structured-light depth (sim/depth_sensor.py's ``sl_shift``: the
depth image rolled by it, so its pixel (u, v) shows the surface at (u - dx, v - dy)).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.hand import HandLayout, fit_pose
from wristtrack.tracking.neutral import reanchor
from wristtrack.tracking.observation import REGISTRATION_PX, depth_offset_change
from wristtrack.tracking.offset_model import (
    OFFSET_DRIFT,
    DepthOffsetModel,
    carry_offset,
    registration_estimate,
)
from wristtrack.tracking.slide_model import SlidingSkinModel
from wristtrack.tracking.tracker import Tracker, TrackerConfig


def test_the_depth_change_is_the_tilted_surfaces_depth_a_pixel_away():
    """A plane turned 60 deg from the line of sight: the depth where the ray of the pixel
    (u + du, v + dv) meets it, minus the depth at (u, v), to the first order in the offset."""
    camera = Camera.default()
    n = Rotation.from_euler("xy", [50.0, -35.0], degrees=True).apply([0.0, 0.0, -1.0])
    p = np.array([0.03, -0.02, 0.65])  # on the plane n . X = n . p
    uv = camera.project(p[None])[0]

    def depth_at(pixel: np.ndarray) -> float:
        ray = np.append(camera.normalize(pixel[None])[0], 1.0)
        return float(n @ p / (n @ ray))

    for offset in ([0.5, 0.0], [0.0, -0.5], [0.4, 0.3]):
        exact = depth_at(uv + offset) - depth_at(uv)
        change = depth_offset_change(p[None, None], n[None, None], np.array([offset]), camera.fx,
                                     camera.fy)[0, 0]
        assert abs(exact) > 2e-4  # steep: tenths of a millimetre for half a pixel
        assert change == pytest.approx(exact, rel=0.02)


def test_the_offset_stays_put_and_the_rest_moves_as_the_sliding_model():
    rng = np.random.default_rng(1)
    model, sliding = DepthOffsetModel(), SlidingSkinModel()
    R = Rotation.random(random_state=3).as_matrix()
    x = model.initial_state(R, rng.normal(size=3), rng.normal(size=3), rng.normal(size=3),
                            s=[1e-3, -4e-4], o=[1.2, -0.7])
    X, noise = np.repeat(x[None], 3, 0), rng.normal(size=(3, model.noise_dim)) * 0.01
    out = model.propagate(X, noise, 0.03)
    np.testing.assert_array_equal(out[:, :20], sliding.propagate(X[:, :20], noise[:, :8], 0.03))
    np.testing.assert_allclose(out[:, 20:], X[:, 20:] + noise[:, 8:])
    np.testing.assert_array_equal(model.depth_offset(out), out[:, 20:])
    Q = model.process_noise(0.03)
    np.testing.assert_array_equal(Q[:8, :8], sliding.process_noise(0.03))
    np.testing.assert_allclose(np.diag(Q)[8:], OFFSET_DRIFT * 0.03)
    P = model.initial_covariance(np.eye(6) * 1e-4)
    np.testing.assert_array_equal(P[:14, :14], sliding.initial_covariance(np.eye(6) * 1e-4))
    np.testing.assert_allclose(P[14:, 14:], np.eye(2) * REGISTRATION_PX**2)
    assert not P[14:, :14].any()


def test_a_fresh_fit_takes_the_offset_of_the_track_before():
    model = DepthOffsetModel()
    x = model.initial_state(np.eye(3), np.zeros(3))
    P = np.full((16, 16), 1e-6) + np.eye(16) * 1e-4
    before_x = x.copy()
    before_x[20:] = [1.8, -0.9]
    before_P = np.eye(16) * 2e-4
    before_P[14:, 14:] = [[0.04, 0.01], [0.01, 0.05]]
    x1, P1 = carry_offset(model, x, P, before_x, before_P)
    np.testing.assert_array_equal(x1[20:], [1.8, -0.9])
    np.testing.assert_array_equal(x1[:20], x[:20])
    np.testing.assert_array_equal(P1[14:, 14:], before_P[14:, 14:])
    assert not P1[14:, :14].any() and not P1[:14, 14:].any()
    np.testing.assert_array_equal(P1[:14, :14], P[:14, :14])
    # nothing to carry: no track before, or a model without the offset
    assert carry_offset(model, x, P, None, None)[0] is x
    assert carry_offset(SlidingSkinModel(), x[:20], P[:14, :14], before_x, before_P)[0] is not None


def test_the_estimate_reported_is_the_states_offset_and_its_sigma():
    """summary.json's depth_registration: the state's (du, dv) and the roots of their variances;
    nothing for a model without the offset or before any track."""
    model = DepthOffsetModel()
    x = model.initial_state(np.eye(3), np.zeros(3), o=[1.25, -0.5])
    P = np.eye(16) * 1e-4
    P[14:, 14:] = [[0.09, 0.02], [0.02, 0.16]]
    got = registration_estimate(model, x, P)
    assert (got["du_px"], got["dv_px"]) == (1.25, -0.5)
    np.testing.assert_allclose(got["sd_px"], [0.3, 0.4])
    assert got["prior_sd_px"] == REGISTRATION_PX
    assert registration_estimate(model, None, None) is None
    assert registration_estimate(SlidingSkinModel(), x[:20], P[:14, :14]) is None


def test_a_new_hand_frame_turns_the_slide_and_leaves_the_offset():
    """The offset is the camera's: a change of W0 and layout (the end of the still start)
    keeps it and its variance; the slide turns with the hand frame as it did."""
    rng = np.random.default_rng(0)
    old = HandLayout.default()
    points = old.points.copy()
    points[:, 2] = [0.0, -0.0045, 0.006, 0.007, 0.006, 0.0045]
    new = HandLayout(points @ Rotation.from_rotvec([0.0, 0.0, 0.1]).as_matrix().T + 0.003)
    model = DepthOffsetModel()
    x = model.initial_state(np.eye(3), rng.normal(scale=0.02, size=3), s=[1e-3, 5e-4],
                            o=[1.5, -0.5])
    P = np.diag(rng.uniform(1e-6, 1e-4, 16))
    xn, Pn, *_ = reanchor(x, P, np.eye(3), np.array([0.0, 0.0, 0.6]), old, new, None, 2)
    T_R = fit_pose(old, new.points)[0]
    np.testing.assert_allclose(xn[18:20], T_R.T[:2, :2] @ x[18:20], atol=1e-15)
    np.testing.assert_array_equal(xn[20:], x[20:])
    np.testing.assert_allclose(Pn[14:, 14:], P[14:, 14:], atol=1e-20)
    assert np.allclose(Pn[14:, :14], 0.0)


@pytest.fixture(scope="module")
def misregistered(tmp_path_factory):
    """A rendered recording with structured-light depth alone (benchmarks.robustness'
    "structured_light", seed 0, its first 150 frames), its detections, truth, the offset it
    was rendered with (the filter's convention: minus the sensor's roll) and its folder."""
    from benchmarks.accuracy import recorded_detections
    from benchmarks.robustness import BASE_SCENARIO, render_condition
    from wristtrack.sim.renderer import Renderer
    from wristtrack.sim.scenes import make_scene

    folder = render_condition(tmp_path_factory.mktemp("sl"), "structured_light", 0, 150)
    camera, hand, detections, truth = recorded_detections(folder)
    shift = Renderer(make_scene(BASE_SCENARIO, 0, effects=["structured_light"]), 0).depth.sl_shift
    return camera, hand, detections, truth, -np.asarray(shift, dtype=float), folder


def test_the_tracker_finds_the_rendered_misregistration_and_keeps_it(misregistered):
    """Over 5 s the estimate comes within 0.35 px of the rendered offset on each axis, and
    the position error falls by more than a third against the offset taken as noise (0.53 ->
    0.21 mm over the whole recording when measured). A track lost to a gap and fitted afresh
    starts from the offset found."""
    from benchmarks.accuracy import score

    camera, hand, detections, truth, offset, _ = misregistered
    assert 1 <= abs(offset[0]) <= 2 and abs(offset[1]) <= 1
    errors = []
    for config in (TrackerConfig(), TrackerConfig(follow_offset=True)):
        tracker = Tracker(camera, hand, config)
        results = [tracker.step(d) for d in detections[:120]]
        errors.append(score(results, truth)["pos"])  # (the truth of the frames tracked)
    assert isinstance(tracker.model, DepthOffsetModel)
    found, sd = tracker._track.x[20:], np.sqrt(np.diag(tracker._track.P)[14:])
    np.testing.assert_allclose(found, offset, atol=0.35)
    assert np.all(sd < 0.4)
    assert errors[1] < 0.67 * errors[0], errors
    # 20 frames missing (0.67 s, past max_gap): lost, then fitted afresh on the next frame
    P_before = tracker._track.P[14:, 14:].copy()
    again = tracker.step(detections[140])
    assert again.has_estimate and tracker._initialisations == 2
    np.testing.assert_array_equal(tracker._track.x[20:], found)
    np.testing.assert_array_equal(tracker._track.P[14:, 14:], P_before)


def test_track_reports_the_offset_found_in_its_summary_and_report(misregistered, tmp_path):
    """``track --follow-offset``: summary.json's depth_registration is the rendered offset to
    0.35 px, and the report says it; without the option there is no estimate to report."""
    from wristtrack.cli import main

    offset, folder = misregistered[4], misregistered[5]
    out = tmp_path / "run"
    assert main(["track", str(folder), "--out", str(out), "--no-progress",
                 "--follow-offset"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    found = summary["depth_registration"]
    np.testing.assert_allclose([found["du_px"], found["dv_px"]], offset, atol=0.35)
    assert max(found["sd_px"]) < 0.4 and found["prior_sd_px"] == REGISTRATION_PX
    text = (out / "report.html").read_text(encoding="utf-8")
    assert (f"the depth map sits ({found['du_px']:.2f}, {found['dv_px']:.2f}) px (sd "
            f"{found['sd_px'][0]:.2f}, {found['sd_px'][1]:.2f}) from the colour image") in text
    assert main(["track", str(folder), "--out", str(tmp_path / "plain"), "--no-progress",
                 "--no-report"]) == 0
    plain = json.loads((tmp_path / "plain" / "summary.json").read_text())
    assert plain["depth_registration"] is None
