"""The per-frame pose bound against hand-derived values and the scatter of real estimators."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.crlb import pose_crlb
from wristtrack.camera import Camera
from wristtrack.depth_noise import depth_sigma
from wristtrack.hand import HandLayout
from wristtrack.tracking.pose_fit import refine_pose

CAM = Camera(fx=525.0, fy=500.0, cx=319.5, cy=239.5, width=640, height=480, depth_scale=0.001)
FACING = np.diag([1.0, -1.0, -1.0])  # hand +Z towards the camera, hand X along camera x
SIGMA = 0.7


def test_fronto_parallel_bound_matches_hand_derivation():
    # Four points symmetric about the hand origin, the palm plane facing the camera at z, and
    # depth so precise that tilt and distance are pinned: the pixel rows then measure x, y and
    # the in-plane turn independently, each column of the Jacobian constant per point:
    # du/dt_x = fx/z  ->  var(t_x) = sigma^2 z^2 / (fx^2 n), likewise t_y with fy;
    # (du, dv)/dphi_z = (fx b, fy a)/z  ->  var(phi_z) = sigma^2 z^2 / sum(fx^2 b^2 + fy^2 a^2).
    pts = np.array([[0.05, 0, 0], [-0.05, 0, 0], [0, 0.04, 0], [0, -0.04, 0]])
    z = 0.5
    bound = pose_crlb(CAM, pts, FACING, [0.0, 0.0, z], pixel_sigma=SIGMA, depth_coeff=0.0,
                      depth_floor=1e-9)
    cov = bound.cov[0]
    n = len(pts)
    assert cov[3, 3] == pytest.approx(SIGMA**2 * z**2 / (CAM.fx**2 * n), rel=1e-6)
    assert cov[4, 4] == pytest.approx(SIGMA**2 * z**2 / (CAM.fy**2 * n), rel=1e-6)
    a, b = pts[:, 0], pts[:, 1]
    expected = SIGMA**2 * z**2 / np.sum(CAM.fx**2 * b**2 + CAM.fy**2 * a**2)
    assert cov[2, 2] == pytest.approx(expected, rel=1e-6)
    # the pinned parameters: far below the pixel-limited ones
    assert cov[0, 0] < 1e-6 * cov[2, 2] and cov[5, 5] < 1e-6 * cov[3, 3]


def test_unobservable_frames_are_nan():
    pts = HandLayout.default().points
    vis = np.array([[True, True, False, False, False, False], [True] * 6])
    R = np.stack([FACING, FACING])
    t = np.array([[0.0, 0.0, 0.6], [0.0, 0.0, 0.6]])
    bound = pose_crlb(CAM, pts, R, t, visible=vis)
    assert np.isnan(bound.cov[0]).all() and np.isfinite(bound.cov[1]).all()
    o, p = bound.rms()  # over the observable frame only
    assert o == pytest.approx(bound.orientation_std_deg[1]) and np.isfinite(p)


def _oblique_pose():
    R = Rotation.from_rotvec([0.35, -0.25, 0.6]).as_matrix() @ FACING
    return R, np.array([0.03, -0.02, 0.65])


def _errors(R_est, t_est, R, t):
    return np.concatenate([Rotation.from_matrix(R_est @ R.T).as_rotvec(), t_est - t])


@pytest.mark.parametrize("with_depth", [True, False])
def test_bound_matches_scatter_of_refine_pose(with_depth):
    """Maximum-likelihood fits on many noisy samples of one pose scatter as the bound says
    (the estimator is efficient at this noise level): within 15 % in each std."""
    layout = HandLayout.default()
    R, t = _oblique_pose()
    rng = np.random.default_rng(1)
    X = layout.points @ R.T + t
    uv0, z0 = CAM.project(X), X[:, 2]
    sz = depth_sigma(z0)
    errs = []
    for _ in range(800):
        uv = uv0 + rng.normal(0, SIGMA, uv0.shape)
        depth = z0 + rng.normal(0, 1, 6) * sz if with_depth else None
        fit = refine_pose(uv, depth, CAM, layout, R, t, SIGMA, sz)
        errs.append(_errors(fit.R_ch, fit.t_ch, R, t))
    emp = np.cov(np.array(errs).T)
    bound = pose_crlb(CAM, layout.points, R, t, has_depth=with_depth, pixel_sigma=SIGMA)
    cov = bound.cov[0]
    assert np.sqrt(np.trace(emp[:3, :3])) == pytest.approx(np.sqrt(np.trace(cov[:3, :3])), rel=0.15)
    assert np.sqrt(np.trace(emp[3:, 3:])) == pytest.approx(np.sqrt(np.trace(cov[3:, 3:])), rel=0.15)
    assert np.sqrt(np.diag(emp)) == pytest.approx(np.sqrt(np.diag(cov)), rel=0.15)


def test_bound_matches_scatter_of_opencv_pnp():
    """An independent estimator, OpenCV's iterative PnP (pixels only), scatters as the bound."""
    layout = HandLayout.default()
    R, t = _oblique_pose()
    rng = np.random.default_rng(2)
    uv0 = CAM.project(layout.points @ R.T + t)
    rvec0 = cv2.Rodrigues(R)[0]
    errs = []
    for _ in range(1500):
        uv = uv0 + rng.normal(0, SIGMA, uv0.shape)
        ok, rvec, tvec = cv2.solvePnP(layout.points, uv, CAM.K, None, rvec0.copy(), t.copy(),
                                      useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        assert ok
        errs.append(_errors(cv2.Rodrigues(rvec)[0], tvec.ravel(), R, t))
    emp = np.cov(np.array(errs).T)
    cov = pose_crlb(CAM, layout.points, R, t, has_depth=False, pixel_sigma=SIGMA).cov[0]
    assert np.sqrt(np.diag(emp)) == pytest.approx(np.sqrt(np.diag(cov)), rel=0.15)
