"""The planar flip at a colour-only initialisation (issue 11), against the simulated truth: the
initialisation never picks the mirrored pose silently; with depth nothing changes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.rgb_flip import tilted_view
from wristtrack.camera import Camera
from wristtrack.depth_noise import KINECT_DEPTH_COEFF
from wristtrack.detect.detections import Detections
from wristtrack.hand import HandLayout
from wristtrack.sim.motion import neutral_camera_pose
from wristtrack.tracking.initialise import FLIP_LOG_EVIDENCE, initialise
from wristtrack.tracking.pose_fit import initial_guess, mirrored, refine_pose

CAM = Camera.default()
LAYOUT = HandLayout.default()
SIGMA = 0.7
_view = tilted_view  # neutral view tilted about a random in-image axis, any roll
R_N, _ = neutral_camera_pose()  # the back of a right hand, fingers up in the image


def _flipped(R_est: np.ndarray, R: np.ndarray, t: np.ndarray) -> bool:
    """The estimate's palm normal is nearer the truth's mirror image about the line of sight
    than the truth's own (hand-derived: reflect n about the unit sight line u)."""
    c = R @ LAYOUT.points.mean(axis=0) + t
    u = c / np.linalg.norm(c)
    n = R[:, 2]
    mirror = 2 * (n @ u) * u - n
    return bool(np.linalg.norm(R_est[:, 2] - mirror) < np.linalg.norm(R_est[:, 2] - n))


def _trials(seed: int, n_markers: int, tilt_deg: float, trials: int) -> dict[str, int]:
    rng = np.random.default_rng(seed)
    count = dict.fromkeys(("flipped", "flagged", "silent", "twin_right"), 0)
    for _ in range(trials):
        R, t = _view(rng, tilt_deg)
        uv = CAM.project(LAYOUT.points @ R.T + t) + rng.normal(0.0, SIGMA, (6, 2))
        keep = np.sort(rng.choice(6, n_markers, replace=False))
        order = rng.permutation(n_markers)
        labels = None if n_markers == 6 else keep[order]  # four markers: named by hand
        init = initialise(Detections(0.0, uv[keep][order], None), CAM, LAYOUT, labels)
        flipped, alt = _flipped(init.R_ch, R, t), init.alternative
        count["flipped"] += flipped
        count["flagged"] += alt is not None
        count["silent"] += flipped and alt is None
        count["twin_right"] += flipped and alt is not None and not _flipped(alt.R_ch, R, t)
        if alt is not None:  # the twin is the other answer, never less likely than allowed
            assert 0.0 <= init.log_evidence <= FLIP_LOG_EVIDENCE
            assert np.isclose(init.log_evidence, 0.5 * (alt.cost - init.cost))
    return count


@pytest.mark.parametrize("n_markers", [4, 6])
def test_near_fronto_parallel_the_flip_is_never_silent(n_markers):
    """10 deg of tilt, 0.7 px: the pixels pick the mirrored pose in about a third of the views
    (the problem is real); every one of those keeps the twin, and the twin is the right side."""
    trials = 150
    c = _trials(n_markers, n_markers, 10.0, trials)
    assert c["flipped"] > 0.2 * trials, c
    assert c["silent"] == 0, c
    assert c["twin_right"] >= 0.9 * c["flipped"], c


def test_strong_perspective_decides_alone():
    """At 45 deg of tilt six markers tell the two poses apart: mostly no twin, never a flip."""
    trials = 100
    c = _trials(3, 6, 45.0, trials)
    assert c["silent"] == 0 and c["flipped"] <= 2, c
    assert c["flagged"] < 0.5 * trials, c


def test_mirrored_reflects_the_normal_and_keeps_the_centre():
    R, t = Rotation.from_rotvec([0.15, -0.1, 0.0]).as_matrix() @ R_N, np.array([0.03, 0.02, 0.6])
    Rm, tm, axis = mirrored(R, t, LAYOUT)
    centre = LAYOUT.points.mean(axis=0)
    c = R @ centre + t
    u = c / np.linalg.norm(c)
    assert np.allclose(Rm @ centre + tm, c)
    assert np.allclose(Rm[:, 2], 2 * (R[:, 2] @ u) * u - R[:, 2])
    assert np.isclose(np.linalg.det(Rm), 1.0) and np.isclose(np.linalg.norm(axis), 1.0)
    # to first order the same image: the markers move by a few pixels at most
    moved = CAM.project(LAYOUT.points @ Rm.T + tm) - CAM.project(LAYOUT.points @ R.T + t)
    assert np.abs(moved).max() < 5.0


def test_with_depth_the_initialisation_is_unchanged():
    """Depth decides the side of the plane: no twin, and the pose the old path gave
    (Kabsch start, one refinement), bit for bit."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        R, t = _view(rng, 10.0)
        X = LAYOUT.points @ R.T + t
        uv = CAM.project(X) + rng.normal(0.0, SIGMA, (6, 2))
        z = X[:, 2] + rng.normal(0.0, KINECT_DEPTH_COEFF * X[:, 2] ** 2)
        init = initialise(Detections(0.0, uv, z), CAM, LAYOUT, np.arange(6))
        old = refine_pose(uv, z, CAM, LAYOUT, *initial_guess(uv, z, CAM, LAYOUT), SIGMA)
        assert init.alternative is None
        assert np.array_equal(init.R_ch, old.R_ch) and np.array_equal(init.t_ch, old.t_ch)
