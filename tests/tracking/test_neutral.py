"""tracking.neutral: W0 and the layout from the still start, and the change of frame.

Truth: the measurement-level simulator (0.3 px blobs, Kinect-like depth) on a still hand whose
pose is known; the change of frame is checked against the marker positions it must keep.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.geometry import wrist_angles
from wristtrack.hand import HandLayout, estimate_layout, fit_pose
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import Trajectory, scenario
from wristtrack.tracking.neutral import (
    STILL_FRAMES,
    STILL_GAP_S,
    STILL_PX,
    StillStart,
    reanchor,
    still_pixel_sigma,
)
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.pose_fit import initial_guess, refine_pose
from wristtrack.tracking.tracker import Tracker, TrackerConfig


def arched() -> HandLayout:
    p = HandLayout.default().points.copy()
    p[:, 2] = [0.0, -0.0045, 0.006, 0.007, 0.006, 0.0045]
    return estimate_layout(p @ np.diag([1.0, -1.0, -1.0]) + [0.0, 0.0, 0.6])[0]


def still_frames(layout: HandLayout, rng: np.random.Generator, n: int = 15):
    R = (Rotation.from_rotvec(rng.normal(scale=0.2, size=3))
         * Rotation.from_euler("X", np.pi)).as_matrix()
    t = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(0.5, 0.7)])
    zeros = np.zeros((n, 3))
    traj = Trajectory(t=np.arange(n) / 30.0, R_ch=np.repeat(R[None], n, 0),
                      t_ch=np.repeat(t[None], n, 0), R_rel=np.repeat(np.eye(3)[None], n, 0),
                      p_rel=zeros, v=zeros, w=zeros, angles=zeros)
    noise = NoiseModel(clutter_mean=0.0, p_miss=0.0)
    return R, t, simulate_detections(traj, Camera.default(), layout, noise, rng)


def angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(A.T @ B).magnitude()))


def test_still_start_w0_and_layout_beat_one_frame():
    """Over 15 still frames, W0 fitted to all of them is ~sqrt(15) times closer to the true pose
    than the one-frame fit, and the averaged layout's heights much closer to the true ones."""
    cam, layout = Camera.default(), arched()
    rng = np.random.default_rng(4)
    one_rot, many_rot, one_h, many_h = [], [], [], []
    for _ in range(12):
        R, t, frames = still_frames(layout, rng)
        still = StillStart(cam)
        zero = np.zeros(3)
        for f in frames:
            assert not still.add(f.detections, f.labels, zero, zero)
        assert still.add(frames[-1].detections, frames[-1].labels, zero, zero)  # 15: over
        first = frames[0]
        uv = first.detections.uv[np.argsort(first.labels)]
        z = first.detections.depth[np.argsort(first.labels)]
        R0, t0 = initial_guess(uv, z, cam, layout)
        noise = MeasurementNoise()  # weighted as the still start weighs them
        fit = refine_pose(uv, z, cam, layout, R0, t0, noise.pixel_sigma,
                          noise.depth_sigma(z))
        one_rot.append(angle_deg(fit.R_ch, R))
        R_w, t_w, cov = still.w0(layout, R0, t0)
        many_rot.append(angle_deg(R_w, R))
        assert cov.shape == (6, 6) and np.all(np.linalg.eigvalsh(cov) > 0)
        assert np.trace(cov[:3, :3]) < np.trace(fit.cov[:3, :3]) / 8  # ~1/15 of one frame's
        one = estimate_layout(cam.backproject(uv, z))[0]
        averaged = still.layout()
        one_h.append(one.points[:, 2] - layout.points[:, 2])
        many_h.append(averaged.points[:, 2] - layout.points[:, 2])
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    assert rms(many_rot) < rms(one_rot) / 2.5, (rms(one_rot), rms(many_rot))
    assert rms(many_h) < rms(one_h) / 2.5, (rms(one_h), rms(many_h))


def _still_start(frames, offsets: np.ndarray | None = None) -> StillStart:
    """A StillStart over simulated ``frames``, each marker's blob moved by the same
    ``offsets`` (6, 2) px in every frame (None: as drawn)."""
    still = StillStart(Camera.default())
    zero = np.zeros(3)
    for f in frames:
        det = f.detections
        if offsets is not None:
            marker = f.labels >= 0
            det.uv[marker] += offsets[f.labels[marker]]
        still.add(det, f.labels, zero, zero)
    return still


def _sharpen(frames, layout: HandLayout, R: np.ndarray, t: np.ndarray, share: float) -> None:
    """Each drawn blob's error scaled by ``share`` (0: exactly on its marker), in place."""
    truth = Camera.default().project(layout.points @ R.T + t)
    for f in frames:
        marker = f.labels >= 0
        uv = f.detections.uv[marker]
        f.detections.uv[marker] = truth[f.labels[marker]] + (uv - truth[f.labels[marker]]) * share


def _sigma_at(still: StillStart, layout: HandLayout, R: np.ndarray, t: np.ndarray) -> float:
    R_w, t_w, _ = still.w0(layout, R, t)
    at_fit = still.camera.project(layout.points @ R_w.T + t_w)
    return still_pixel_sigma(np.array(still.uv) - at_fit)


def test_the_still_starts_pixels_are_worth_their_fresh_noise_or_sqrt_n_their_constant_one():
    """White blob noise (the simulator's 0.3 px), fresh in every frame: the pixels are worth
    that each (the scatter of the markers' means over 15 frames, times sqrt(15)). Errors of
    0.08 px the same in every frame (and 0.005 px fresh): worth sqrt(15) x 0.08 = 0.31 px each,
    not 0.08. Mean of the variance over 40 still starts (one start has 6 degrees of freedom)."""
    layout = arched()
    rng = np.random.default_rng(7)
    drawn = NoiseModel().pixel_sigma  # what still_frames draws
    white, constant = [], []
    for _ in range(40):
        R, t, frames = still_frames(layout, rng)
        white.append(_sigma_at(_still_start(frames), layout, R, t) ** 2)
        R2, t2, sharp = still_frames(layout, rng)
        _sharpen(sharp, layout, R2, t2, 0.005 / drawn)  # the drawn noise taken to 0.005 px
        offsets = rng.normal(0.0, 0.08, (6, 2))
        constant.append(_sigma_at(_still_start(sharp, offsets), layout, R2, t2) ** 2)
    # the fit gives up fewer than 6 degrees of freedom to the pixels where depth carries part
    # of the pose: the sigma errs large, by up to sqrt(12 / 6) where depth carries all of it
    assert drawn <= np.sqrt(np.mean(white)) < drawn * np.sqrt(2)
    worth = 0.08 * np.sqrt(STILL_FRAMES)
    assert worth * 0.9 <= np.sqrt(np.mean(constant)) < worth * np.sqrt(2)


def test_errors_that_drift_over_the_still_start_count_as_not_averaging():
    """Residuals built by hand: fresh noise alone gives its sigma back; the four MCP markers
    drifting together by 0.6 px over 15 frames (a skin slide) on top count as the drift's mean
    and its spread about it, sqrt(n) times, not as fresh noise the frames average."""
    rng = np.random.default_rng(2)
    n = STILL_FRAMES
    fresh = rng.normal(0.0, 0.05, (2000, n, 6, 2))
    white = np.mean([still_pixel_sigma(r) ** 2 for r in fresh])
    # 12 coordinates less 6: the 6 of a fit these residuals did not have give back 12/6 of it;
    # the slow part's estimate, kept at 0 or more, errs large by about a tenth on fresh noise
    assert 1.0 <= np.sqrt(white * 6 / 12) / 0.05 < 1.15
    drift = np.zeros((n, 6, 2))
    drift[:, 2:, 0] = np.linspace(0.0, 0.6, n)[:, None]  # MCPs, along u
    sigma = still_pixel_sigma(fresh[0] + drift)
    mean = drift.mean(axis=0)
    # n |mean|^2 over 12 - 6, and n times the drift's spread about its mean over 12 (n - 1)
    by_hand = n * np.sum(mean**2) / 6 + n * np.sum((drift - mean) ** 2) / (12 * (n - 1))
    assert sigma**2 == pytest.approx(by_hand, rel=0.05)
    averaged = n * np.sum(mean**2) / 6 + np.sum((drift - mean) ** 2) / (12 * (n - 1))
    assert sigma**2 > 1.1 * averaged  # more than were the drift fresh noise
    assert still_pixel_sigma(np.full((n, 6, 2), np.nan)) is None
    three = fresh[0].copy()
    three[:, 3:] = np.nan
    assert still_pixel_sigma(three) is None  # 3 markers: 6 coordinates, all the pose's


def test_w0_weighs_pixels_that_do_not_average_at_their_worth():
    """Blob errors of 0.04 px the same in every still frame, depth with its fresh noise: W0
    with the pixels at their worth over the frames is closer to the true pose than with the
    filter's 0.3 px (which leaves the tilt to the depth) and than with the blobs' own 0.04 px
    taken as fresh in every frame (which leaves it to the pixels' fixed errors). The depth is
    taken at the noise it is drawn with."""
    cam, layout = Camera.default(), arched()
    rng = np.random.default_rng(11)
    depth_model = MeasurementNoise(depth_coeff=NoiseModel().depth_sigma_coeff, depth_offset=0.0,
                                   depth_z0=0.0)
    errors = {"worth": [], "model": [], "fresh": []}
    for _ in range(30):
        R, t, frames = still_frames(layout, rng)
        _sharpen(frames, layout, R, t, 0.0)
        still = _still_start(frames, rng.normal(0.0, 0.04, (6, 2)))
        errors["worth"].append(angle_deg(still.w0(layout, R, t, depth_model)[0], R))
        uv, depth = np.concatenate(still.uv), np.concatenate(still.depth)
        stacked = HandLayout(np.tile(layout.points, (len(still.uv), 1)))
        sz = depth_model.depth_sigma(np.nan_to_num(depth, nan=1.0))
        for name, sigma in (("model", 0.3), ("fresh", 0.04)):
            fit = refine_pose(uv, depth, cam, stacked, R, t, sigma, sz)
            errors[name].append(angle_deg(fit.R_ch, R))
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in errors.items()}
    assert rms["worth"] < 0.9 * min(rms["model"], rms["fresh"]), rms


def test_still_start_ends_when_the_hand_moves_and_needs_enough_frames():
    cam, layout = Camera.default(), arched()
    _, _, frames = still_frames(layout, np.random.default_rng(1), n=5)
    still = StillStart(cam)
    for f in frames[:3]:
        assert not still.add(f.detections, f.labels, np.zeros(3), np.zeros(3))
    # the markers shifted by more than STILL_PX: the hand has started to move
    det = frames[3].detections
    moved = type(det)(det.timestamp, det.uv + [STILL_PX + 1.0, 0.0], det.depth)
    assert still.add(moved, frames[3].labels, np.zeros(3), np.zeros(3))
    assert still.layout() is None  # 3 frames: too few to replace the one-frame layout
    assert still.w0(layout, np.eye(3), np.array([0, 0, 0.6])) is None
    # or the filter sees it move fast
    other = StillStart(cam)
    other.add(frames[0].detections, frames[0].labels, np.zeros(3), np.zeros(3))
    assert other.add(frames[1].detections, frames[1].labels, np.array([0.3, 0, 0]), np.zeros(3))


def test_a_frame_long_after_the_last_ends_the_still_start():
    """A still hand's frames: one STILL_GAP_S after the last taken (a run that dropped frames)
    is not part of the still start, which ends without it; frames nearly as far apart (a slow
    camera) are."""
    cam, layout = Camera.default(), arched()
    _, _, frames = still_frames(layout, np.random.default_rng(3), n=4)
    t0 = frames[0].detections.timestamp
    still = StillStart(cam, t0)
    for k in (1, 2):
        det = frames[k].detections
        slow = type(det)(t0 + k * 0.9 * STILL_GAP_S, det.uv, det.depth)
        assert not still.add(slow, frames[k].labels, np.zeros(3), np.zeros(3))
    det = frames[3].detections
    late = type(det)(t0 + 1.8 * STILL_GAP_S + STILL_GAP_S + 0.01, det.uv, det.depth)
    assert still.add(late, frames[3].labels, np.zeros(3), np.zeros(3))
    assert len(still.uv) == 2


def test_a_velocity_within_the_filters_own_uncertainty_is_not_motion():
    """A fresh track's angular velocity is uncertain (~0.6 rad/s after its first update): a
    value above STILL_RATE but within that uncertainty does not end the still start; the same
    value, known to 0.05 rad/s, does."""
    cam, layout = Camera.default(), arched()
    _, _, frames = still_frames(layout, np.random.default_rng(2), n=3)
    w = np.array([0.0, 0.0, 0.3])
    zero, cov_v = np.zeros(3), np.eye(3) * 0.05**2
    fresh = StillStart(cam)
    for f in frames:
        assert not fresh.add(f.detections, f.labels, zero, w, cov_v, np.eye(3) * 0.6**2)
    settled = StillStart(cam)
    settled.add(frames[0].detections, frames[0].labels, zero, zero, cov_v, np.eye(3) * 0.05**2)
    assert settled.add(frames[1].detections, frames[1].labels, zero, w, cov_v,
                       np.eye(3) * 0.05**2)


def test_the_tracker_keeps_the_whole_still_start_under_realistic_depth_noise():
    """A hand still for 18 frames, depth noise of a structured-light sensor (1.4 mm at 0.6 m):
    the still start gathers its 15 frames before W0 is refined (it ended after 1-3 frames on
    the noise of the fresh track's velocity estimate, leaving W0 a one-frame fit)."""
    for seed in range(3):
        truth, camera, layout = scenario("flexion", rng=seed)
        assert np.degrees(np.abs(truth.angles[:18])).max() < 0.05  # still
        noise = NoiseModel(depth_sigma_coeff=4e-3, clutter_mean=0.0)
        frames = simulate_detections(truth, camera, layout, noise, np.random.default_rng(seed))
        tracker = Tracker(camera, layout, TrackerConfig())
        ids = [tracker.step(f.detections).track_id for f in frames[:30]]
        assert ids.index(1) >= STILL_FRAMES, ids


def test_the_still_starts_rows_are_reported_against_w0_as_refined_so_far():
    """Rows written during the still start (true angles 0) are centred on zero: they are
    reported against W0 fitted to the still frames so far, not against the first frame's fit,
    which sits 1-3 deg off under structured-light depth noise (the filter's own state)."""
    reported, one_frame = [], []
    for seed in range(6):
        truth, camera, layout = scenario("flexion", rng=seed)
        noise = NoiseModel(depth_sigma_coeff=4e-3, clutter_mean=0.0)
        frames = simulate_detections(truth, camera, layout, noise, np.random.default_rng(seed))
        tracker = Tracker(camera, layout, TrackerConfig())
        results = [tracker.step(f.detections) for f in frames[:20]]
        end = [r.track_id for r in results].index(1)
        still = [r for r in results[:end] if r.has_estimate]
        reported.append(wrist_angles(np.stack([r.R for r in still])).mean(axis=0))
        states = np.stack([tracker.model.pose(r.x[None])[0][0] for r in still])
        one_frame.append(wrist_angles(states).mean(axis=0))
    rms = lambda a: float(np.degrees(np.sqrt(np.mean(np.square(a)))))  # noqa: E731
    assert rms(reported) < 0.5 and rms(one_frame) > 2 * rms(reported), (rms(reported),
                                                                         rms(one_frame))


def test_reanchor_keeps_the_markers_where_they_are():
    """Moving to a new layout's hand frame (and to a new W0) changes the numbers, never where
    the state puts the markers in the camera; the velocities of the markers are kept too."""
    rng = np.random.default_rng(0)
    old, new = HandLayout.default(), arched()
    R_c0 = Rotation.random(random_state=2).as_matrix()
    t_c0 = np.array([0.01, 0.02, 0.6])
    R = Rotation.from_rotvec(rng.normal(scale=0.3, size=3)).as_matrix()
    p, v, w = rng.normal(scale=0.05, size=3), rng.normal(scale=0.1, size=3), rng.normal(size=3)
    x = np.concatenate([R.reshape(9), p, v, w])
    P = np.diag(rng.uniform(1e-6, 1e-4, 12))
    T_R, T_t = fit_pose(old, new.points)
    # where the old state puts the new layout's markers, and how fast they move (camera frame)
    R_ch, t_ch = R_c0 @ R, R_c0 @ p + t_c0
    pts = (new.points @ T_R.T + T_t) @ R_ch.T + t_ch
    vel = R_c0 @ v + np.cross(R_c0 @ w, pts - t_ch)
    W = Rotation.from_rotvec([0.01, -0.02, 0.005]).as_matrix() @ R_c0 @ T_R
    for w0 in (None, (W, t_c0 + [0.001, 0.0, -0.002], np.eye(6) * 1e-6)):
        xn, Pn, R_c0n, t_c0n, w0_cov = reanchor(x, P, R_c0, t_c0, old, new, w0)
        Rn, pn, vn, wn = xn[:9].reshape(3, 3), xn[9:12], xn[12:15], xn[15:18]
        R_chn, t_chn = R_c0n @ Rn, R_c0n @ pn + t_c0n
        np.testing.assert_allclose(new.points @ R_chn.T + t_chn, pts, atol=1e-12)
        vel_n = R_c0n @ vn + np.cross(R_c0n @ wn, pts - t_chn)
        np.testing.assert_allclose(vel_n, vel, atol=1e-12)
        np.testing.assert_allclose(Rn.T @ Rn, np.eye(3), atol=1e-12)
        assert np.allclose(Pn, Pn.T) and np.all(np.linalg.eigvalsh(Pn) > 0)
        if w0 is None:
            np.testing.assert_array_equal(w0_cov, 0.0)
        else:
            np.testing.assert_allclose(R_c0n, W)
            np.testing.assert_allclose(np.trace(w0_cov), 6e-6)  # rotated, not scaled
