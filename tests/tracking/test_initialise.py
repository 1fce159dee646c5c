"""Tests of the initialisation (tracking/initialise, labelling, pose_fit) against independent
oracles (cv2.solvePnP, cv2.projectPoints, scipy Rotation, known ground truth)."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.depth_noise import KINECT_DEPTH_COEFF
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError
from wristtrack.hand import HandLayout
from wristtrack.tracking.initialise import initialise
from wristtrack.tracking.labelling import label_markers
from wristtrack.tracking.pose_fit import initial_guess, refine_pose

CAM = Camera.default()
LAYOUT = HandLayout.default()
# Neutral pose: camera looking at the back of a right hand, fingers up in the image, 0.65 m away.
R_C0 = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
T_C0 = np.array([0.0, 0.05, 0.65])
PIXEL_SIGMA = 0.7


def _project(R: np.ndarray, t: np.ndarray, points: np.ndarray, cam: Camera = CAM) -> np.ndarray:
    """Oracle projection: cv2.projectPoints (with the camera's distortion)."""
    dist = None if cam.dist is None else np.asarray(cam.dist, float)
    uv, _ = cv2.projectPoints(points, cv2.Rodrigues(R)[0], t, cam.K, dist)
    return uv.reshape(-1, 2)


def _depth(R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ R[2] + t[2]


def _pose(rotvec_cam, t=T_C0) -> tuple[np.ndarray, np.ndarray]:
    """Neutral pose rotated by a camera-frame rotation vector (scipy as the oracle)."""
    return Rotation.from_rotvec(rotvec_cam).as_matrix() @ R_C0, np.asarray(t, float)


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(Rotation.from_matrix(Ra.T @ Rb).magnitude())


def _random_scene(rng, layout, n_clutter, with_depth=True, noise=True):
    """Random initialisation view: any camera roll, tilt <= 30 deg, 0.5-0.8 m, shuffled blobs."""
    while True:
        tilt_axis = rng.normal(size=2)
        tilt = np.append(tilt_axis / np.linalg.norm(tilt_axis) * rng.uniform(0, np.radians(30)), 0)
        roll = Rotation.from_rotvec([0, 0, rng.uniform(-np.pi, np.pi)]).as_matrix()
        R = Rotation.from_rotvec(tilt).as_matrix() @ roll @ R_C0
        t = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08), rng.uniform(0.5, 0.8)])
        uv = _project(R, t, layout.points)
        if CAM.in_image(uv).all() and (uv.min(0) > 20).all():
            break
    z = _depth(R, t, layout.points)
    if noise:
        uv = uv + rng.normal(0, PIXEL_SIGMA, uv.shape)
        z = z + rng.normal(0, KINECT_DEPTH_COEFF * z**2)
    clutter = rng.uniform([0, 0], [CAM.width, CAM.height], (n_clutter, 2))
    cz = np.where(rng.random(n_clutter) < 0.3, np.nan, rng.uniform(0.4, 1.5, n_clutter))
    order = rng.permutation(6 + n_clutter)
    truth = np.append(np.arange(6), np.full(n_clutter, -1))[order]
    det = Detections(
        0.0, np.vstack([uv, clutter])[order], np.append(z, cz)[order] if with_depth else None
    )
    return det, truth, R, t


def test_neutral_pose_convention():
    assert np.allclose(R_C0 @ [0, 0, 1], [0, 0, -1])
    assert np.isclose(np.linalg.det(R_C0), 1.0)
    # The markers project inside the image, WRIST lowest (fingers up).
    uv = _project(R_C0, T_C0, LAYOUT.points)
    assert CAM.in_image(uv).all() and np.argmax(uv[:, 1]) == 0


@pytest.mark.parametrize(
    "rotvec", [(0.2, -0.1, 0.3), (-0.35, 0.25, -1.2), (0.05, 0.4, 2.5)], ids=["a", "b", "c"]
)
@pytest.mark.parametrize("use_depth", [True, False], ids=["depth", "rgb"])
def test_refine_noise_free_matches_truth_and_solvepnp(rotvec, use_depth):
    R, t = _pose(rotvec, T_C0 + [0.03, -0.02, 0.05])
    uv = _project(R, t, LAYOUT.points)
    z = _depth(R, t, LAYOUT.points) if use_depth else None
    R0 = Rotation.from_rotvec([0.08, -0.06, 0.1]).as_matrix() @ R
    fit = refine_pose(uv, z, CAM, LAYOUT, R0, t + [0.02, -0.015, 0.04])
    assert _angle(fit.R_ch, R) < 1e-9 and np.linalg.norm(fit.t_ch - t) < 1e-9
    assert fit.rms_px < 1e-6 and fit.cost < 1e-10
    assert fit.dof == (18 if use_depth else 12) - 6
    for flag in (cv2.SOLVEPNP_ITERATIVE, cv2.SOLVEPNP_IPPE):
        ok, rvec, tvec = cv2.solvePnP(LAYOUT.points, uv, CAM.K, None, flags=flag)
        assert ok
        assert _angle(cv2.Rodrigues(rvec)[0], fit.R_ch) < 1e-6
        assert np.linalg.norm(tvec.ravel() - fit.t_ch) < 1e-6


def test_refine_with_distortion_and_missing_marker():
    cam = Camera(525.0, 525.0, 319.5, 239.5, 640, 480, dist=(0.12, -0.25, 0.001, -0.002, 0.05))
    R, t = _pose((0.3, -0.2, 0.4), (0.08, -0.06, 0.6))
    uv = _project(R, t, LAYOUT.points, cam)
    z = _depth(R, t, LAYOUT.points)
    uv[4] = np.nan  # an occluded marker is simply left out
    R0, t0 = initial_guess(uv, None, cam, LAYOUT, visible=np.isfinite(uv).all(1))
    fit = refine_pose(uv, z, cam, LAYOUT, R0, t0)
    assert _angle(fit.R_ch, R) < 1e-9 and np.linalg.norm(fit.t_ch - t) < 1e-9
    assert fit.dof == 5 * 3 - 6
    # Labelling undistorts the blobs too: shuffled blobs plus clutter, through initialise.
    uv = _project(R, t, LAYOUT.points, cam)
    blobs, order = np.vstack([uv, [[40.0, 400.0]]]), np.array([3, 6, 0, 5, 1, 4, 2])
    res = initialise(Detections(0.0, blobs[order], np.append(z, 1.2)[order]), cam, LAYOUT)
    assert np.array_equal(res.labels, np.where(order < 6, order, -1))
    assert _angle(res.R_ch, R) < 1e-9 and np.linalg.norm(res.t_ch - t) < 1e-9


def test_refine_never_diverges_from_a_bad_start():
    R, t = _pose((0.1, 0.2, 0.0))
    uv = _project(R, t, LAYOUT.points)
    z = _depth(R, t, LAYOUT.points)
    R0 = Rotation.from_rotvec([0.5, -0.4, 0.6]).as_matrix() @ R
    start_cost = refine_pose(uv, z, CAM, LAYOUT, R0, t + [0.05, 0.05, 0.1], max_iter=0).cost
    fit = refine_pose(uv, z, CAM, LAYOUT, R0, t + [0.05, 0.05, 0.1], max_iter=3)
    assert fit.cost <= start_cost  # damped steps only ever lower the cost
    fit = refine_pose(uv, z, CAM, LAYOUT, R0, t + [0.05, 0.05, 0.1], max_iter=50)
    assert _angle(fit.R_ch, R) < 1e-8


def test_initial_guess_depth_and_ippe():
    R, t = _pose((0.25, -0.3, 0.8), (0.05, 0.02, 0.7))
    uv = _project(R, t, LAYOUT.points)
    z = _depth(R, t, LAYOUT.points)
    for d in (z, None):  # Kabsch on back-projected points; IPPE (facing solution) without depth
        R0, t0 = initial_guess(uv, d, CAM, LAYOUT)
        assert _angle(R0, R) < 1e-6 and np.linalg.norm(t0 - t) < 1e-6
    # Only 3 depth readings still suffice for the 3-D alignment.
    R0, t0 = initial_guess(uv, np.where(np.arange(6) < 3, z, np.nan), CAM, LAYOUT)
    assert _angle(R0, R) < 1e-6


def test_monte_carlo_depth_beats_solvepnp():
    """0.7 px blob noise, Kinect depth noise, hand at 0.65 m: projections + depth (ours) against
    cv2.solvePnP on projections only; also the predicted covariance against the scatter."""
    rng = np.random.default_rng(7)
    poses = [(0.0, 0.0, 0.0), (0.3, -0.1, 0.5), (-0.2, 0.35, -0.8), (0.1, 0.45, 2.0)]
    err = {"ours": [], "ours_rgb": [], "solvepnp": []}
    dev, covs = [], []
    for rotvec in poses:
        R, t = _pose(rotvec)
        uv0, z0 = _project(R, t, LAYOUT.points), _depth(R, t, LAYOUT.points)
        for _ in range(25):
            uv = uv0 + rng.normal(0, PIXEL_SIGMA, uv0.shape)
            z = z0 + rng.normal(0, KINECT_DEPTH_COEFF * z0**2)
            fit = refine_pose(uv, z, CAM, LAYOUT, *initial_guess(uv, z, CAM, LAYOUT))
            rgb = refine_pose(uv, None, CAM, LAYOUT, *initial_guess(uv, None, CAM, LAYOUT))
            _, rvec, tvec = cv2.solvePnP(LAYOUT.points, uv, CAM.K, None)
            for name, (Re, te) in {
                "ours": (fit.R_ch, fit.t_ch),
                "ours_rgb": (rgb.R_ch, rgb.t_ch),
                "solvepnp": (cv2.Rodrigues(rvec)[0], tvec.ravel()),
            }.items():
                err[name].append((np.degrees(_angle(Re, R)), 1e3 * np.linalg.norm(te - t)))
            # error in the covariance's coordinates: R_true = exp(dphi) R_est, t_true = t_est + dt
            dphi = Rotation.from_matrix(R @ fit.R_ch.T).as_rotvec()
            dev.append(np.append(dphi, t - fit.t_ch))
            covs.append(fit.cov)
    mean = {k: np.mean(v, axis=0) for k, v in err.items()}
    msg = ", ".join(f"{k}: {m[0]:.3f} deg / {m[1]:.2f} mm" for k, m in mean.items())
    # Depth removes the planar flip ambiguity that projections alone leave near fronto-parallel.
    for other in ("solvepnp", "ours_rgb"):
        assert mean["ours"][0] < mean[other][0] and mean["ours"][1] < mean[other][1], msg
    # Predicted standard deviations agree with the Monte Carlo scatter within ~35%.
    dev = np.asarray(dev)
    ratio = np.sqrt(np.mean(dev**2, axis=0) / np.mean(np.diagonal(covs, axis1=1, axis2=2), 0))
    assert np.all((ratio > 0.65) & (ratio < 1.35)), f"empirical/predicted std {ratio}, {msg}"


@pytest.mark.parametrize("with_depth", [True, False], ids=["depth", "rgb"])
def test_label_markers_random_scenes(with_depth):
    rng = np.random.default_rng(11 if with_depth else 12)
    trials, good, failures = 150, 0, []
    for _ in range(trials):
        det, truth, _, _ = _random_scene(rng, LAYOUT, int(rng.integers(0, 4)), with_depth)
        try:
            labels = label_markers(det, CAM, LAYOUT)
        except InitialisationError as err:
            failures.append(str(err)[:60])
            continue
        if np.array_equal(labels, truth):
            good += 1
        else:
            failures.append("wrong labels")
    assert good >= 0.99 * trials, f"{good}/{trials} correct; failures: {failures}"


def test_label_markers_noise_free_all_rolls():
    for roll in np.linspace(-np.pi, np.pi, 13):
        R, t = _pose((0, 0, roll))
        uv = _project(R, t, LAYOUT.points)
        order = np.random.default_rng(int(roll * 100) % 97).permutation(6)
        labels = label_markers(Detections(0.0, uv[order]), CAM, LAYOUT)
        assert np.array_equal(labels, order)


def test_label_markers_speed():
    rng = np.random.default_rng(3)
    for n_clutter, budget in ((0, 0.5), (3, 0.5)):
        det, truth, _, _ = _random_scene(rng, LAYOUT, n_clutter)
        label_markers(det, CAM, LAYOUT)  # warm-up
        start = time.perf_counter()
        labels = label_markers(det, CAM, LAYOUT)
        elapsed = time.perf_counter() - start
        assert np.array_equal(labels, truth)
        assert elapsed < budget, f"M={6 + n_clutter}: {elapsed:.3f} s"


def test_label_markers_refuses_bad_input():
    R, t = _pose((0.1, -0.1, 0.2))
    uv = _project(R, t, LAYOUT.points)
    z = _depth(R, t, LAYOUT.points)
    with pytest.raises(InitialisationError, match="need all six markers"):
        label_markers(Detections(0.0, uv[:5], z[:5]), CAM, LAYOUT)
    line = np.column_stack([np.linspace(200, 400, 7), np.linspace(100, 300, 7)])
    with pytest.raises(InitialisationError, match="line"):
        label_markers(Detections(0.0, line), CAM, LAYOUT)
    # The mirror image of the hand is the palm side: no physically possible assignment.
    mirrored = uv * [-1, 1] + [2 * CAM.cx, 0]
    with pytest.raises(InitialisationError, match="physically possible|palm towards"):
        label_markers(Detections(0.0, mirrored), CAM, LAYOUT)
    # A clutter blob 0.5 px from MCP4 without depth: either could be the marker.
    twin = np.vstack([uv, uv[4] + [0.5, 0.0]])
    with pytest.raises(InitialisationError, match="ambiguous"):
        label_markers(Detections(0.0, twin, np.append(z, np.nan)), CAM, LAYOUT)
    # A layout for another hand: the best fit is implausible.
    other = HandLayout.from_paper([0.07, 0.06, 0.1, 0.06, 0.09], np.radians([70, 30, 0, -5, -40]))
    with pytest.raises(InitialisationError):
        label_markers(Detections(0.0, uv, z), CAM, other)


def _subject(rng) -> HandLayout:
    """A hand unlike the default template: other size and proportions."""
    lengths = np.array([0.045, 0.085, 0.088, 0.083, 0.076]) * rng.uniform(0.9, 1.15)
    jitter = np.radians([4, 2.5, 0, 2.5, 2.5]) * rng.uniform(-1, 1, 5)
    angles = np.radians([50, 16, 0, -14, -28]) + jitter
    return HandLayout.from_paper(lengths * rng.uniform(0.96, 1.04, 5), angles)


def test_initialise_without_layout_measures_it_from_depth():
    rng = np.random.default_rng(5)
    errors = []
    for _ in range(12):
        subject = _subject(rng)
        det, truth, R, t = _random_scene(rng, subject, int(rng.integers(0, 3)))
        res = initialise(det, CAM, None)
        assert np.array_equal(res.labels, truth)
        lengths = np.linalg.norm(res.layout.points[1:], axis=1)
        errors.append(lengths - np.linalg.norm(subject.points[1:], axis=1))
        assert _angle(res.R_ch, R) < np.radians(2.0)
    rms_mm = 1e3 * np.sqrt(np.mean(np.square(errors)))
    assert rms_mm < 2.0 and 1e3 * np.abs(errors).max() < 5.0, f"length RMS error {rms_mm:.2f} mm"


def test_initialise_needs_layout_or_depth():
    uv = _project(R_C0, T_C0, LAYOUT.points)
    with pytest.raises(InitialisationError, match="hand.json"):
        initialise(Detections(0.0, uv), CAM, None)


def test_initialise_rgb_only_scale_from_layout():
    R, t = _pose((0.15, -0.2, 0.3))
    uv = _project(R, t, LAYOUT.points)
    order = np.random.default_rng(1).permutation(6)
    res = initialise(Detections(0.0, uv[order]), CAM, LAYOUT)
    assert np.array_equal(res.labels, order)
    assert np.linalg.norm(res.t_ch - t) < 1e-6 and _angle(res.R_ch, R) < 1e-6
    # With 0.7 px noise the known layout still fixes the distance to several mm at 0.65 m
    # (a 9 cm hand spans ~70 px, so ~1% scale noise), as the fit's covariance predicts.
    rng = np.random.default_rng(2)
    errs, stds = [], []
    for _ in range(30):
        res = initialise(Detections(0.0, uv + rng.normal(0, PIXEL_SIGMA, uv.shape)), CAM, LAYOUT)
        errs.append(res.t_ch - t)
        stds.append(np.sqrt(np.diag(res.cov)[3:]))
    rms_mm = 1e3 * np.sqrt(np.mean(np.square(errs), axis=0))
    predicted_mm = 1e3 * np.mean(stds, axis=0)
    msg = f"RGB-only translation RMS error {rms_mm} mm, predicted {predicted_mm} mm"
    assert np.linalg.norm(rms_mm) < 10.0 and np.all(rms_mm < 1.5 * predicted_mm), msg


def test_initialise_with_manual_labels():
    R, t = _pose((0.2, 0.1, -0.3))
    uv = _project(R, t, LAYOUT.points)
    z = _depth(R, t, LAYOUT.points)
    blobs = np.vstack([uv[[2, 0, 5, 1, 3]], [100.0, 100.0]])  # MCP4 hidden, one clutter blob
    labels = np.array([2, 0, 5, 1, 3, -1])
    res = initialise(
        Detections(0.0, blobs, np.append(z[[2, 0, 5, 1, 3]], 1.0)), CAM, LAYOUT, labels
    )
    assert _angle(res.R_ch, R) < 1e-9 and np.linalg.norm(res.t_ch - t) < 1e-9
    assert np.array_equal(res.labels, labels)
    with pytest.raises(InitialisationError, match="MCP2"):
        initialise(Detections(0.0, blobs), CAM, LAYOUT, np.array([2, 0, 5, 1, 2, -1]))
    with pytest.raises(InitialisationError, match="badly"):  # wrong labels are noticed
        initialise(Detections(0.0, blobs), CAM, LAYOUT, np.array([0, 2, 5, 1, 3, -1]))


def test_labelling_many_blobs_keeps_memory_bounded():
    """Twelve blobs, six of them clutter hugging the markers (split or doubled blobs), leave
    tens of thousands of candidate assignments after pruning (tiny triangles cannot be
    tested); scoring them in chunks keeps the peak allocation small (~56 MB unchunked)."""
    import tracemalloc

    rng = np.random.default_rng(1)
    R, t = _pose((0.1, -0.05, 0.3))
    uv = _project(R, t, LAYOUT.points)
    clutter = uv[rng.integers(0, 6, 6)] + rng.normal(0, 1.5, (6, 2))
    blobs = np.vstack([uv, clutter])
    tracemalloc.start()
    try:
        label_markers(Detections(0.0, blobs), CAM, LAYOUT)
    except InitialisationError:
        pass  # refusing is fine here; what is tested is the memory it took
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 30e6, f"peak {peak / 1e6:.0f} MB"
