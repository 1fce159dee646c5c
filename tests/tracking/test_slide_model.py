"""The skin slide in the filter state (tracking/slide_model.py): its prediction against the
Ornstein-Uhlenbeck process it is, the markers it moves, the change of hand frame at the end of
the still start, the variance learned on hands whose skin slides and does not, and the tracker
following the slide the markers were moved by."""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.cli.options import add_tracker_options, tracker_config
from wristtrack.filter import ukf
from wristtrack.hand import HandLayout, fit_pose
from wristtrack.sim import realism
from wristtrack.sim.motion import neutral_camera_pose
from wristtrack.tracking.models import ConstantRateModel, ProcessNoise
from wristtrack.tracking.neutral import reanchor
from wristtrack.tracking.observation import SLIDING_MARKERS, MarkerObservation, MeasurementNoise
from wristtrack.tracking.offset_model import DepthOffsetModel
from wristtrack.tracking.slide_model import INITIAL_SHARE, SlidingSkinModel
from wristtrack.tracking.tracker import Tracker, TrackerConfig

from .test_neutral import arched
from .test_noise_scale import _rigid_frames
from .test_skin_slide import _sliding_skin_frames


def test_the_slide_is_predicted_as_an_ornstein_uhlenbeck_process():
    """Over T s the slide's mean decays by exp(-T/tau) and its variance goes to the stationary
    one as exp(-2T/tau) (closed form), whatever the hand does; retract and lift are inverse."""
    model = SlidingSkinModel(ProcessNoise(), (0.0015, 0.0005, 0.0005), time_constant=2.0)
    model.slide_scale = 0.5
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    x = model.initial_state(R, np.zeros(3), w=np.array([0.5, 0.0, 0.2]),
                            s=np.array([0.002, -0.0005]))
    assert x.size == 20 and model.dim == 14 and model.noise_dim == 8
    P = np.eye(14) * 1e-8
    P[12:, 12:] = np.diag([4e-7, 1e-7])
    xi = np.random.default_rng(0).normal(scale=1e-3, size=(5, 14))
    np.testing.assert_allclose(model.lift(x, model.retract(x, xi)), xi, atol=1e-12)
    dt, steps = 1 / 30, 45
    x0_slide, P0 = x[18:].copy(), np.diag(P)[12:].copy()
    for _ in range(steps):
        x, P = ukf.predict(model, x, P, dt, model.process_noise(dt))
    keep = math.exp(-dt * steps / 2.0)
    np.testing.assert_allclose(x[18:], keep * x0_slide, rtol=1e-9)
    expected = keep**2 * P0 + (1 - keep**2) * 0.5 * np.array([0.0015, 0.0005]) ** 2
    np.testing.assert_allclose(np.diag(P)[12:], expected, rtol=1e-6)
    np.testing.assert_allclose(P[12:, :12], 0.0, atol=1e-18)  # nothing couples them yet


def test_the_observation_moves_the_mcp_markers_by_the_slide():
    """The four MCP markers sit at their layout point plus the state's slide (hand frame,
    distal and lateral); WRIST and CMC1 do not move. The slide the state carries is shared as
    noise no more; the palmar slide, which it does not carry, still is."""
    camera, layout = Camera.default(), HandLayout.default()
    R_c0, t_c0 = neutral_camera_pose()
    model = SlidingSkinModel()
    noise = MeasurementNoise()
    obs = MarkerObservation(camera, layout.points, R_c0, t_c0, model.pose, True, noise,
                            slide_of=model.skin_slide)
    R = Rotation.from_rotvec([0.2, 0.4, -0.1]).as_matrix()
    p, slide = np.array([0.01, -0.02, 0.03]), np.array([0.002, -0.001])
    x = model.initial_state(R, p, s=slide)
    moved = layout.points.copy()
    moved[list(SLIDING_MARKERS), :2] += slide
    R_ch, t_ch = R_c0 @ R, R_c0 @ p + t_c0
    np.testing.assert_allclose(obs.marker_points(x[None])[0], moved @ R_ch.T + t_ch, atol=1e-12)
    mcp = list(SLIDING_MARKERS)
    np.testing.assert_array_equal(obs.slide[mcp], [[0.0, 0.0, noise.skin_slide[2]]] * 4)
    assert not np.delete(obs.slide, mcp, axis=0).any()
    rigid = MarkerObservation(camera, layout.points, R_c0, t_c0, model.pose, True, noise)
    np.testing.assert_array_equal(rigid.slide[mcp], [noise.skin_slide] * 4)


def test_reanchor_keeps_the_slid_markers_where_they_are():
    """The still start's new layout frame (and new W0): the MCP markers moved by the slide
    stay where they are in the camera but for the slide's share along the new palmar axis,
    which the state does not carry; the slide is turned into the new frame."""
    rng = np.random.default_rng(1)
    old, new = HandLayout.default(), arched()
    R_c0, t_c0 = Rotation.random(random_state=3).as_matrix(), np.array([0.0, 0.01, 0.6])
    R = Rotation.from_rotvec(rng.normal(scale=0.3, size=3)).as_matrix()
    slide = np.array([0.002, 0.0003, 0.0])
    x = SlidingSkinModel.initial_state(R, rng.normal(scale=0.05, size=3),
                                       rng.normal(scale=0.1, size=3), rng.normal(size=3),
                                       slide[:2])
    P = np.diag(rng.uniform(1e-6, 1e-4, 14))
    T_R, T_t = fit_pose(old, new.points)
    turned = T_R.T @ slide  # the slide in the new hand frame
    assert abs(turned[2]) > 1e-6  # the frames differ: some of it is dropped
    mcp = list(SLIDING_MARKERS)
    R_ch, t_ch = R_c0 @ R, R_c0 @ x[9:12] + t_c0
    # where the markers are, less the dropped palmar share
    before = ((new.points[mcp] @ T_R.T + T_t) + slide - T_R[:, 2] * turned[2]) @ R_ch.T + t_ch
    W = Rotation.from_rotvec([0.01, -0.02, 0.005]).as_matrix() @ R_c0 @ T_R
    for w0 in (None, (W, t_c0 + [0.001, 0.0, -0.002], np.eye(6) * 1e-6)):
        xn, Pn, R_c0n, t_c0n, _ = reanchor(x, P, R_c0, t_c0, old, new, w0)
        R_chn, t_chn = R_c0n @ xn[:9].reshape(3, 3), R_c0n @ xn[9:12] + t_c0n
        np.testing.assert_allclose(xn[18:], turned[:2], atol=1e-15)
        np.testing.assert_allclose(
            (new.points[mcp] + [*xn[18:], 0.0]) @ R_chn.T + t_chn, before, atol=1e-12)
        np.testing.assert_allclose(Pn[12:, 12:], T_R.T[:2, :2] @ P[12:, 12:] @ T_R[:2, :2],
                                   atol=1e-18)
        assert np.allclose(Pn, Pn.T) and np.all(np.linalg.eigvalsh(Pn) > 0)


def _slide_run(frames, camera, layout, **kw):
    tracker = Tracker(camera, layout, TrackerConfig(follow_slide=True, **kw))
    slides = []
    for f in frames:
        result = tracker.step(f.detections)
        slides.append(result.x[18:20] if result.has_estimate else np.full(2, np.nan))
    return tracker, np.array(slides)


def test_the_tracker_follows_the_slide_the_markers_were_moved_by():
    """Detections whose MCP markers slide as the renderer's soft tissue moves them (up to
    2.3 mm distally, fingers flexing every 3.3 s): after the first second the state's distal
    slide goes with the true one (correlation 0.9 here) and is within 0.5 mm rms of it, where
    the slide swings by 0.85 mm rms; the slide's variance is learned near the model's."""
    truth, camera, layout, frames = _sliding_skin_frames("flexion", 1)
    tracker, slides = _slide_run(frames, camera, layout)
    assert isinstance(tracker.model, SlidingSkinModel)
    flex = realism.finger_flexion_deg(truth.t, truth.t[0])
    true = realism.SKIN_SLIDE_AT_90[0] * flex / 90.0
    late = (truth.t - truth.t[0] > 1.0) & np.isfinite(slides[:, 0])
    assert late.sum() > 0.8 * (len(frames) - 30)
    followed = slides[late, 0]
    assert true[late].std() > 0.7e-3
    assert np.corrcoef(followed, true[late])[0, 1] > 0.8
    assert np.sqrt(np.mean((followed - true[late]) ** 2)) < 0.5e-3
    assert tracker.model.slide_scale > 0.5


def test_a_rigid_hand_learns_that_its_skin_does_not_slide():
    """Rigid markers: the slide's variance falls to its floor and the state's slide stays
    within a few tenths of a millimetre of none."""
    truth, camera, layout, frames = _rigid_frames("flexion", 2)
    tracker, slides = _slide_run(frames, camera, layout)
    assert tracker.model.slide_scale < 0.05
    assert np.nanmax(np.abs(slides[len(frames) // 2:, 0])) < 0.3e-3


def test_a_fresh_fit_starts_the_slide_narrow_and_the_option_asks_for_the_model():
    """initial_covariance: the pose's block as the constant-rate model's, the slide at
    INITIAL_SHARE of its stationary sigmas; the sliding model is the default (--follow-slide),
    with the depth offset after the slide where asked for and depth is used (--follow-offset,
    not with --no-depth); --no-follow-slide gives the constant-rate model alone, and without a
    modelled slide (or with the paper's model) there is none to follow."""
    model = SlidingSkinModel(slide_sigma=(0.002, 0.001, 0.001))
    model.slide_scale = 0.25
    pose = np.diag([1e-4] * 3 + [1e-6] * 3)
    P = model.initial_covariance(pose)
    np.testing.assert_allclose(P[:12, :12], ConstantRateModel().initial_covariance(pose))
    np.testing.assert_allclose(np.diag(P)[12:],
                               0.25 * INITIAL_SHARE**2 * np.array([0.002, 0.001]) ** 2)
    parser = argparse.ArgumentParser()
    add_tracker_options(parser)
    for args in ([], ["--follow-slide"], ["--no-follow-offset"],
                 ["--follow-offset", "--no-depth"]):
        assert type(tracker_config(parser.parse_args(args)).make_model()) is SlidingSkinModel
    assert type(tracker_config(parser.parse_args(["--follow-offset"])).make_model()) is \
        DepthOffsetModel
    assert type(tracker_config(parser.parse_args(["--no-follow-slide"])).make_model()) is \
        ConstantRateModel
    rigid = TrackerConfig(follow_slide=True, measurement=MeasurementNoise(skin_slide=(0, 0, 0)))
    assert type(rigid.make_model()) is ConstantRateModel
    assert not isinstance(TrackerConfig.paper(follow_slide=True).make_model(),
                          ConstantRateModel)
