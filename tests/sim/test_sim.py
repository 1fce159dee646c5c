"""Tests of the measurement-level simulator against independent truth (cv2, scipy, algebra)."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.sim import (
    SCENARIOS,
    NoiseModel,
    acceptance_noise,
    min_jerk_reach,
    neutral_camera_pose,
    sample,
    scenario,
    scenario_motion,
    simulate_detections,
    still,
    timestamps,
)

CLEAN = NoiseModel(pixel_sigma=0.0, clutter_mean=0.0, p_miss=0.0, depth_sigma_coeff=0.0)


def _by_label(frame):
    """uv (6,2) and depth (6,) of the labelled markers, NaN where not detected."""
    uv, z = np.full((6, 2), np.nan), np.full(6, np.nan)
    lab = frame.labels
    uv[lab[lab >= 0]] = frame.detections.uv[lab >= 0]
    z[lab[lab >= 0]] = frame.detections.depth[lab >= 0]
    return uv, z


@pytest.fixture(scope="module")
def scenarios():
    return {name: scenario(name, rng=7) for name in SCENARIOS}


def test_neutral_camera_pose_looks_at_back_of_hand():
    R, t = neutral_camera_pose()
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, -1])
    cam, lay = Camera.default(), HandLayout.default()
    uv = cam.project(lay.points @ R.T + t)
    assert uv[3, 1] < uv[0, 1] - 50  # MCP3 (fingers) well above the WRIST in the image
    assert uv[1, 0] < uv[5, 0]  # thumb side (CMC1) on the image left for a right hand


@pytest.mark.parametrize("name", SCENARIOS)
def test_scenarios_in_view_and_clean_projection(scenarios, name):
    traj, cam, lay = scenarios[name]
    assert 4.0 <= traj.t[-1] <= 10.0 and len(traj) >= 100
    frames = simulate_detections(traj, cam, lay, CLEAN, rng=0)
    # Independent truth: scipy/cv2 pose each marker and project it.
    for k in range(0, len(traj), 7):
        rvec = Rotation.from_matrix(traj.R_ch[k]).as_rotvec()
        uv_cv, _ = cv2.projectPoints(lay.points, rvec, traj.t_ch[k], cam.K, None)
        z_true = (traj.R_ch[k] @ lay.points.T).T[:, 2] + traj.t_ch[k, 2]
        uv, z = _by_label(frames[k])
        assert sorted(frames[k].labels) == list(range(6)), "every marker visible, no clutter"
        np.testing.assert_allclose(uv, uv_cv[:, 0], atol=1e-7)
        np.testing.assert_allclose(z, z_true, atol=1e-12)
        assert np.all(cam.in_image(uv))


def test_velocities_match_sample_differences_to_second_order(scenarios):
    traj = scenarios["mix"][0]
    times = traj.t[(traj.t > 0.5) & (traj.t < 7.5)]
    motion, (R_c0, t_c0) = scenario_motion("mix")
    mid = sample(motion, times, R_c0, t_c0)
    np.testing.assert_allclose(mid.v, traj.v[(traj.t > 0.5) & (traj.t < 7.5)], atol=1e-12)
    errors = []
    for dt in (1 / 30, 1 / 60):
        a, b = (sample(motion, times + s * dt, R_c0, t_c0) for s in (-0.5, 0.5))
        v_fd = (b.p_rel - a.p_rel) / dt
        w_fd = Rotation.from_matrix(b.R_rel @ np.swapaxes(a.R_rel, 1, 2)).as_rotvec() / dt
        errors.append((np.abs(v_fd - mid.v).max(), np.abs(w_fd - mid.w).max()))
    (ev30, ew30), (ev60, ew60) = errors
    assert ev30 < 1e-3 and ew30 < 5e-3
    assert 3.0 < ev30 / ev60 < 5.0 and 3.0 < ew30 / ew60 < 5.0  # central differences: O(dt^2)


def test_angular_velocity_is_exact_not_a_sample_difference(scenarios):
    traj = scenarios["pronation"][0]
    dt = traj.t[1] - traj.t[0]
    # Over a frame interval, the rotation log agrees with the mean w to O(dt^2) ...
    w_log = Rotation.from_matrix(traj.R_rel[1:] @ np.swapaxes(traj.R_rel[:-1], 1, 2)).as_rotvec()
    np.testing.assert_allclose(w_log / dt, 0.5 * (traj.w[1:] + traj.w[:-1]), atol=0.02)
    # ... and over a 1 ms interval to ~1e-6: w comes from the continuous motion.
    motion, (R_c0, t_c0) = scenario_motion("pronation")
    a, b = (sample(motion, traj.t + s, R_c0, t_c0) for s in (0.0, 1e-3))
    w_log = Rotation.from_matrix(b.R_rel @ np.swapaxes(a.R_rel, 1, 2)).as_rotvec() / 1e-3
    np.testing.assert_allclose(w_log, 0.5 * (a.w + b.w), atol=1e-5)
    np.testing.assert_allclose(a.w, traj.w, atol=1e-9)


def test_min_jerk_reach_profile(scenarios):
    D, T, rest = 0.3, 1.2, 1.5
    traj = scenarios["reach"][0]
    speed = np.linalg.norm(traj.v, axis=1)
    k = int(np.argmax(speed))
    assert traj.t[k] == pytest.approx(rest + T / 2)
    assert speed[k] == pytest.approx(1.875 * D / T, rel=1e-6)
    assert np.linalg.norm(traj.p_rel[-1]) == pytest.approx(D, abs=1e-12)
    assert speed[0] == pytest.approx(0.0, abs=1e-9) and speed[-1] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(np.degrees(traj.angles[-1]), [0.0, -20.0, 0.0], atol=1e-9)
    # Central differences of the samples: error <= dt^2/6 max|x'''| = dt^2/6 * 60 D/T^3.
    dt = traj.t[1] - traj.t[0]
    v_fd = (traj.p_rel[2:] - traj.p_rel[:-2]) / (2 * dt)
    assert np.abs(v_fd - traj.v[1:-1]).max() <= 1.01 * dt**2 / 6 * 60 * D / T**3
    # Any direction, straight line: positions stay on the direction's line.
    d = np.array([0.0, 2.0, -1.0]) / np.sqrt(5.0)
    reach = sample(
        min_jerk_reach(0.25, 0.8, tuple(d), 0.2),
        np.linspace(0, 1.2, 61),
        *neutral_camera_pose(),
    )
    np.testing.assert_allclose(np.cross(reach.p_rel, d), 0.0, atol=1e-12)
    np.testing.assert_allclose(reach.p_rel[-1], 0.25 * d, atol=1e-12)
    np.testing.assert_allclose(reach.v[30], 1.875 * 0.25 / 0.8 * d, rtol=1e-7)


@pytest.mark.parametrize(
    ("name", "axis", "amplitude"),
    [("deviation", 0, 25.0), ("flexion", 1, 50.0), ("pronation", 2, 45.0)],
)
def test_rom_scenarios_reach_amplitude_on_their_axis(scenarios, name, axis, amplitude):
    traj = scenarios[name][0]
    deg = np.degrees(traj.angles)
    assert deg[:, axis].max() == pytest.approx(amplitude, abs=0.2)
    assert deg[:, axis].min() == pytest.approx(-amplitude, abs=0.2)
    others = np.delete(deg, axis, axis=1)
    np.testing.assert_allclose(others, 0.0, atol=1e-9)
    np.testing.assert_allclose(deg[[0, -1]], 0.0, atol=1e-9)  # starts and ends in neutral
    np.testing.assert_allclose(traj.w[[0, -1]], 0.0, atol=1e-9)  # at rest
    # Angular speed about the one axis only, rotating with the hand for pronation.
    w_hand = np.einsum("nji,nj->ni", traj.R_rel, traj.w)
    np.testing.assert_allclose(np.delete(w_hand, [2, 1, 0][axis], axis=1), 0.0, atol=1e-7)


def test_noise_statistics_clutter_misses_shuffling():
    n = 2000
    traj = sample(still(n / 30), np.arange(n) / 30.0, *neutral_camera_pose())
    cam, lay = Camera.default(), HandLayout.default()
    frames = simulate_detections(traj, cam, lay, NoiseModel(), rng=11)
    labels = [f.labels for f in frames]
    n_clutter = np.array([np.sum(lab == -1) for lab in labels])
    assert abs(n_clutter.mean() - 3.0) < 5 * np.sqrt(3.0 / n)
    assert abs(n_clutter.var() - 3.0) < 0.4  # Poisson: variance = mean
    detected = np.array([np.isin(np.arange(6), lab) for lab in labels])
    assert abs(1 - detected.mean() - 0.1) < 5 * np.sqrt(0.09 / detected.size)
    for f in frames:
        assert np.unique(f.labels[f.labels >= 0]).size == np.sum(f.labels >= 0)
        assert np.all(cam.in_image(f.detections.uv))
    clutter_z = np.concatenate([f.detections.depth[f.labels == -1] for f in frames])
    assert clutter_z.min() >= 0.3 and clutter_z.max() <= 2.0
    # Shuffled: the WRIST blob is not always first, orderings vary.
    first = [f.labels[0] for f in frames]
    assert len(set(first)) == 7
    # Markers near their true projections; depth noise sigma = 1.425e-3 z^2.
    uv, z = zip(*(_by_label(f) for f in frames), strict=True)
    rvec = Rotation.from_matrix(traj.R_ch[0]).as_rotvec()
    truth = cv2.projectPoints(lay.points, rvec, traj.t_ch[0], cam.K, None)[0][:, 0]
    err = np.array(uv) - truth
    assert np.nanstd(err) == pytest.approx(0.3, rel=0.05)
    z_err = np.array(z) - traj.t_ch[0, 2]
    assert np.nanstd(z_err) == pytest.approx(1.425e-3 * 0.65**2, rel=0.05)


def test_acceptance_noise_occludes_two_markers_mid_recording():
    traj, cam, lay = scenario("deviation", rng=1)
    noise = acceptance_noise(len(traj))
    ((start, stop, hidden),) = noise.occlusions
    assert stop - start == 10 and {MARKER_NAMES[i] for i in hidden} == {"MCP4", "MCP5"}
    assert abs((start + stop) / 2 - len(traj) / 2) <= 1
    assert noise.pixel_sigma == 0.3 and noise.clutter_mean == 3.0 and noise.p_miss == 0.1
    frames = simulate_detections(traj, cam, lay, noise, rng=5)
    for k, f in enumerate(frames):
        if start <= k < stop:
            assert not np.isin(hidden, f.labels).any()
    seen_outside = [np.isin(hidden, f.labels).all() for f in frames[:start] + frames[stop:]]
    assert np.mean(seen_outside) > 0.7


def test_depth_options():
    traj = sample(still(1.0), np.arange(30) / 30.0, *neutral_camera_pose())
    cam, lay = Camera.default(), HandLayout.default()
    frames = simulate_detections(traj, cam, lay, NoiseModel(depth=False), rng=1)
    assert all(f.detections.depth is None for f in frames)
    frames = simulate_detections(traj, cam, lay, NoiseModel(p_depth_hole=1.0), rng=1)
    assert all(np.isnan(f.detections.depth).all() for f in frames)


@pytest.mark.parametrize(("pronation", "visible"), [(0.0, 6), (60.0, 6), (100.0, 0), (180.0, 0)])
def test_markers_hidden_when_back_of_hand_turns_away(pronation, visible):
    traj = sample(still(0.2, (0.0, 0.0, pronation)), np.arange(3) / 30.0, *neutral_camera_pose())
    noise = NoiseModel(clutter_mean=0.0, p_miss=0.0)
    frames = simulate_detections(traj, Camera.default(), HandLayout.default(), noise, rng=2)
    assert all(f.labels.size == visible for f in frames)
    wrapped = np.angle(np.exp(1j * (traj.angles[0, 2] - np.radians(pronation))))
    assert abs(wrapped) < 1e-12


def test_timestamps():
    t = timestamps(90, fps=30.0)
    np.testing.assert_allclose(t, np.arange(90) / 30.0)
    rng = np.random.default_rng(3)
    t = timestamps(3000, fps=30.0, jitter=0.01, drop_prob=0.1, rng=rng)
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    assert 0.85 * 3000 < t.size < 0.95 * 3000
    assert np.diff(t).min() < 0.5 / 30 and np.diff(t).max() > 2 / 30  # jitter and drops
    assert t[-1] < 3000 / 30.0
    mix = scenario("mix", rng=4)[0]
    assert np.all(np.diff(mix.t) > 0) and np.ptp(np.diff(mix.t)) > 0.01


def test_unknown_scenario_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown scenario"):
        scenario("juggling")


def test_near_clutter_lands_next_to_the_markers():
    from wristtrack.sim.detections import NoiseModel, simulate_detections
    from wristtrack.sim.motion import scenario

    truth, camera, layout = scenario("deviation", rng=0)
    noise = NoiseModel(clutter_mean=0.0, p_miss=0.0, near_clutter_mean=2.0, near_clutter_px=8.0)
    frames = simulate_detections(truth, camera, layout, noise, 1)
    n_near = np.array([(f.labels < 0).sum() for f in frames])
    assert abs(n_near.mean() - 2.0) < 4 * np.sqrt(2.0 / len(frames))
    for f in frames[:20]:
        markers = f.detections.uv[f.labels >= 0]
        for blob in f.detections.uv[f.labels < 0]:
            assert np.linalg.norm(markers - blob, axis=1).min() < 8.0 * 6


def test_mirrored_movement_is_the_other_hands_movement_seen_in_a_mirror():
    """A right hand making the mirrored movement is, marker for marker, the mirror image across
    the hand's XZ plane of the left hand making the original one; and the ISB angles (signed per
    side) are the same anatomical angles."""
    from wristtrack.geometry import wrist_angles
    from wristtrack.sim.scenes import make_scene, mirrored

    motion = make_scene("no_hand", 0).motion
    t = np.linspace(0.0, motion.duration, 97)
    right, left = HandLayout.default(), HandLayout.default().mirrored()
    M = np.diag([1.0, -1.0, 1.0])
    R, p = motion.pose(t)
    Rm, pm = mirrored(motion).pose(t)
    left_pts = np.einsum("nij,kj->nki", R, left.points) + p[:, None]
    right_pts = np.einsum("nij,kj->nki", Rm, right.points) + pm[:, None]
    np.testing.assert_allclose(right_pts, left_pts @ M, atol=1e-12)
    np.testing.assert_allclose(wrist_angles(Rm, "right"), wrist_angles(R, "left"), atol=1e-9)
    assert np.ptp(wrist_angles(R, "right")[:, 2]) > np.radians(20)  # it does pronate
