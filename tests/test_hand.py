"""wristtrack.hand: layouts, validation, hand.json, and layout/pose estimation from 3-D markers.

Oracles: hand-computed layouts, scipy Rotation (align_vectors), numpy eigh plane fits and
cv2.solvePnP on the projected markers.
"""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InitialisationError, InputError
from wristtrack.hand import (
    MARKER_NAMES,
    HandLayout,
    LayoutEstimateError,
    average_layout,
    estimate_layout,
    fit_pose,
    hand_frame_from_points,
)

DEFAULT_LENGTHS = np.array([0.045, 0.085, 0.088, 0.083, 0.076])
DEFAULT_ANGLES = np.radians([50.0, 16.0, 0.0, -14.0, -28.0])


def posed_towards_camera(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random hand pose 0.5-1 m in front of the camera with the back of the hand facing it."""
    while True:
        r = Rotation.from_euler("X", np.pi) * Rotation.from_rotvec(0.5 * rng.normal(size=3))
        R = r.as_matrix()
        t = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(0.5, 1.0)])
        if R[:, 2] @ (-t) > 0.1 * np.linalg.norm(t):
            return R, t


def to_camera(R: np.ndarray, t: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return pts @ R.T + t  # written out here rather than using wristtrack.geometry


def valid_points() -> np.ndarray:
    return HandLayout.default().points.copy()


# ------------------------------------------------------------------------------------ layouts


def test_marker_names():
    assert MARKER_NAMES == ("WRIST", "CMC1", "MCP2", "MCP3", "MCP4", "MCP5")


def test_default_layout_recovers_lengths_and_angles():
    h = HandLayout.default()
    assert h.points.shape == (6, 3)
    np.testing.assert_allclose(h.lengths, DEFAULT_LENGTHS, atol=1e-15)
    np.testing.assert_allclose(h.angles, DEFAULT_ANGLES, atol=1e-15)
    np.testing.assert_array_equal(h.points[:, 2], 0.0)
    np.testing.assert_array_equal(h.marker("WRIST"), [0, 0, 0])
    np.testing.assert_array_equal(h.marker("MCP3"), [0.088, 0, 0])
    # +Y is the thumb side of a right hand: CMC1 (thumb) above, MCP5 (little finger) below.
    assert h.marker("CMC1")[1] > 0 > h.marker("MCP5")[1]
    np.testing.assert_allclose(
        h.marker("CMC1"), [0.045 * np.cos(np.radians(50)), 0.045 * np.sin(np.radians(50)), 0]
    )
    assert h.validate() is h


def test_from_paper_hand_computed():
    L = np.array([0.05, 0.09, 0.1, 0.095, 0.08])
    a = np.array([0.9, 0.3, 0.0, -0.2, -0.45])
    h = HandLayout.from_paper(L, a)
    expected = np.vstack([[0, 0, 0], np.column_stack([L * np.cos(a), L * np.sin(a), np.zeros(5)])])
    np.testing.assert_allclose(h.points, expected, atol=1e-16)
    np.testing.assert_allclose(h.lengths, L)
    np.testing.assert_allclose(h.angles, a, atol=1e-15)


@pytest.mark.parametrize(
    ("lengths", "angles", "match"),
    [
        (DEFAULT_LENGTHS, DEFAULT_ANGLES + 0.1, "MCP3 angle must be 0"),
        (DEFAULT_LENGTHS[:4], DEFAULT_ANGLES, "5 lengths"),
        (-DEFAULT_LENGTHS, DEFAULT_ANGLES, "positive"),
        (DEFAULT_LENGTHS, np.full(5, np.nan), "finite"),
        # MCP4 placed on top of MCP3.
        ([0.045, 0.085, 0.088, 0.088, 0.076], [0.87, 0.28, 0.0, 0.05, -0.49], "MCP3 and MCP4"),
    ],
)
def test_from_paper_rejects(lengths, angles, match):
    with pytest.raises(ConfigError, match=match):
        HandLayout.from_paper(np.asarray(lengths), np.asarray(angles))


def test_layout_is_frozen_and_comparable():
    h = HandLayout.default()
    with pytest.raises(dataclasses.FrozenInstanceError):
        h.points = np.zeros((6, 3))  # type: ignore[misc]
    with pytest.raises(ValueError):
        h.points[0, 0] = 1.0
    assert h == HandLayout(valid_points()) and hash(h) == hash(HandLayout(valid_points()))
    assert h != h.mirrored() and h.mirrored().mirrored() == h
    assert HandLayout(np.zeros((5, 3))) != h


# ------------------------------------------------------------------------------------ validation


def _moved(name: str, xyz) -> np.ndarray:
    p = valid_points()
    p[MARKER_NAMES.index(name)] = xyz
    return p


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.zeros((5, 3)), "expected 6 markers"),
        (np.zeros((6, 2)), "expected 6 markers"),
        (_moved("MCP2", [np.nan, 0.02, 0.0]), "MCP2 has non-finite"),
        (valid_points() * 1000, "coordinates must be in metres"),
        (_moved("MCP5", [0.2, -0.2, 0.0]), "MCP5 is 0.283 m"),
        (valid_points() + [0.01, 0, 0], "WRIST must be at the origin"),
        (_moved("MCP3", [0.088, 0.002, 0.0]), "MCP3 must lie on the \\+X axis"),
        (_moved("MCP3", [0.088, 0.0, -0.0015]), "MCP3 must lie on the \\+X axis"),
        (_moved("MCP3", [-0.088, 0.0, 0.0]), "MCP3 must lie on the \\+X axis"),
        (_moved("MCP4", [0.086, -0.004, 0.0]), "MCP3 and MCP4 are 4.5 mm apart"),
        (_moved("CMC1", [0.005, 0.0, 0.0]), "WRIST and CMC1 are 5.0 mm apart"),
        (
            np.array(
                [
                    [0, 0, 0],
                    [0.02, 0.003, 0],
                    [0.04, -0.002, 0],
                    [0.1, 0, 0],
                    [0.06, 0.004, 0.001],
                    [0.08, -0.003, 0],
                ]
            ),
            "collinear",
        ),
    ],
)
def test_validate_rejects(points, match):
    with pytest.raises(ConfigError, match=match) as e:
        HandLayout(points).validate("my_hand.json")
    assert "my_hand.json" in str(e.value)
    assert "\n" not in str(e.value)


def test_validate_accepts_within_tolerances():
    HandLayout(_moved("MCP3", [0.088, 0.0007, -0.0005])).validate()
    HandLayout(_moved("MCP4", [0.083, -0.02, 0.015])).validate()  # non-planar is allowed


# ------------------------------------------------------------------------------------ hand.json


def test_json_round_trip(tmp_path):
    for layout in (HandLayout.default(), HandLayout(_moved("MCP4", [0.081, -0.02, 0.007]))):
        path = tmp_path / "a" / "hand.json"
        layout.save(path)
        assert HandLayout.load(path) == layout
        d = json.loads(path.read_text())
        assert list(d) == ["markers"] and list(d["markers"]) == list(MARKER_NAMES)
        assert HandLayout.from_dict(layout.to_dict()) == layout


def _write(tmp_path, content) -> str:
    path = tmp_path / "hand.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    return path


def test_wrong_marker_names_are_named(tmp_path):
    markers = HandLayout.default().to_dict()["markers"]
    markers["Wrist"] = markers.pop("WRIST")
    markers["MCP6"] = [0.05, -0.05, 0.0]
    path = _write(tmp_path, {"markers": markers})
    with pytest.raises(ConfigError) as e:
        HandLayout.load(path)
    msg = str(e.value)
    assert str(path) in msg and "'Wrist'" in msg and "'MCP6'" in msg
    assert "missing marker(s) WRIST" in msg


def test_missing_marker_is_named(tmp_path):
    markers = HandLayout.default().to_dict()["markers"]
    del markers["CMC1"]
    with pytest.raises(ConfigError, match="missing marker\\(s\\) CMC1"):
        HandLayout.load(_write(tmp_path, {"markers": markers}))


@pytest.mark.parametrize("value", [[0.0, 0.0], "0 0 0", [0.0, "a", 0.0], None, [True, 0, 0]])
def test_bad_marker_value(tmp_path, value):
    markers = HandLayout.default().to_dict()["markers"]
    markers["MCP2"] = value
    path = _write(tmp_path, {"markers": markers})
    with pytest.raises(ConfigError, match="marker MCP2 must be \\[x, y, z\\]") as e:
        HandLayout.load(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ('{"markers": {"WRIST": [0, 0, 0],', "not valid JSON"),
        ("[1, 2, 3]", "expected"),
        ({"WRIST": [0, 0, 0]}, "expected"),
    ],
)
def test_bad_hand_file(tmp_path, content, match):
    path = _write(tmp_path, content)
    with pytest.raises(ConfigError, match=match) as e:
        HandLayout.load(path)
    assert str(path) in str(e.value)


def test_impossible_layout_in_file_names_file(tmp_path):
    d = HandLayout.default().to_dict()
    d["markers"]["MCP4"] = d["markers"]["MCP3"]
    path = _write(tmp_path, d)
    with pytest.raises(ConfigError, match="MCP3 and MCP4 are 0.0 mm apart") as e:
        HandLayout.load(path)
    assert str(path) in str(e.value)


def test_missing_hand_file(tmp_path):
    path = tmp_path / "hand.json"
    with pytest.raises(ConfigError, match="^hand file .* not found") as e:
        HandLayout.load(path)
    assert str(path) in str(e.value)


# ------------------------------------------------------------------------------------ estimation


@pytest.mark.parametrize("seed", range(5))
def test_estimate_layout_exact(seed):
    rng = np.random.default_rng(seed)
    truth = HandLayout.from_paper(
        DEFAULT_LENGTHS * rng.uniform(0.85, 1.15, 5),
        DEFAULT_ANGLES * np.array([rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), 0, 1, 1]),
    )
    R, t = posed_towards_camera(rng)
    layout, R_ch, t_ch = estimate_layout(to_camera(R, t, truth.points))
    np.testing.assert_allclose(layout.points, truth.points, atol=1e-14)
    np.testing.assert_allclose(layout.lengths, truth.lengths, atol=1e-14)
    np.testing.assert_allclose(layout.angles, truth.angles, atol=1e-12)
    np.testing.assert_allclose(R_ch, R, atol=1e-13)
    np.testing.assert_allclose(t_ch, t, atol=1e-15)
    np.testing.assert_allclose(R_ch.T @ R_ch, np.eye(3), atol=1e-15)
    assert np.linalg.det(R_ch) > 0


def test_estimate_pose_agrees_with_solvepnp():
    rng = np.random.default_rng(42)
    cam = Camera.default()
    truth = HandLayout.default()
    R, t = posed_towards_camera(rng)
    pts = to_camera(R, t, truth.points)
    layout, R_ch, t_ch = estimate_layout(pts)
    ok, rvec, tvec = cv2.solvePnP(
        layout.points, cam.project(pts), cam.K, None, flags=cv2.SOLVEPNP_ITERATIVE
    )
    assert ok
    R_pnp = Rotation.from_rotvec(rvec.ravel()).as_matrix()
    np.testing.assert_allclose(R_ch, R_pnp, atol=1e-6)
    np.testing.assert_allclose(t_ch, tvec.ravel(), atol=1e-6)


def test_z_axis_points_towards_the_camera():
    truth = HandLayout.default()
    # Hand frame aligned with the camera: its Z (the back of the hand) faces AWAY from the camera.
    R_away = Rotation.from_rotvec([0.2, -0.1, 0.3]).as_matrix()
    t = np.array([0.02, -0.03, 0.6])
    assert R_away[:, 2] @ (-t) < 0
    layout, R_ch, t_ch = estimate_layout(to_camera(R_away, t, truth.points))
    assert R_ch[:, 2] @ (np.zeros(3) - t_ch) > 0
    # Flipping Z keeps X (towards MCP3) so Y = Z x X flips too: a 180 deg turn about X ...
    np.testing.assert_allclose(R_ch, R_away @ np.diag([1.0, -1.0, -1.0]), atol=1e-13)
    # ... and the layout measured that way is the mirror image (a left hand seen from the back).
    np.testing.assert_allclose(layout.points, truth.mirrored().points, atol=1e-14)


def arched_points() -> np.ndarray:
    """A non-planar right hand in a hand-like frame (+Z up): knuckles arched up to 7 mm, the
    thumb base 4 mm lower (DESIGN.md section 2); not yet in the DESIGN hand frame."""
    p = HandLayout.default().points.copy()
    p[:, 2] = [0.0, -0.004, 0.006, 0.007, 0.006, 0.004]
    return p


def test_estimate_layout_non_planar_markers_keeps_heights_in_the_design_frame():
    rng = np.random.default_rng(3)
    pts_hand = arched_points()
    R, t = posed_towards_camera(rng)
    pts = to_camera(R, t, pts_hand)
    layout, R_ch, t_ch = estimate_layout(pts)
    # Oracle for the frame (DESIGN.md section 2): X exactly WRIST -> MCP3; Z the smallest
    # eigenvector of the scatter matrix made perpendicular to X, towards the camera.
    x = (pts[3] - pts[0]) / np.linalg.norm(pts[3] - pts[0])
    c = pts - pts.mean(axis=0)
    normal = np.linalg.eigh(c.T @ c)[1][:, 0]
    z = normal - (normal @ x) * x
    z *= np.sign(z @ -pts[0]) / np.linalg.norm(z)
    np.testing.assert_allclose(R_ch, np.column_stack([x, np.cross(z, x), z]), atol=1e-12)
    np.testing.assert_allclose(t_ch, pts[0], atol=0)
    # the layout is the measured markers in that frame: heights kept, distances unchanged
    np.testing.assert_allclose(layout.points, (pts - t_ch) @ R_ch, atol=1e-15)
    assert np.ptp(layout.points[:, 2]) > 0.004  # not flattened
    np.testing.assert_allclose(layout.points[3], [np.linalg.norm(pts[3] - pts[0]), 0, 0],
                               atol=1e-15)
    d_true = np.linalg.norm(pts_hand[:, None] - pts_hand[None], axis=-1)
    d_est = np.linalg.norm(layout.points[:, None] - layout.points[None], axis=-1)
    np.testing.assert_allclose(d_est, d_true, atol=1e-14)
    assert layout.side == "right"
    # a layout already in the DESIGN frame comes back exactly, from any pose
    R2, t2 = posed_towards_camera(rng)
    again, R_ch2, _ = estimate_layout(to_camera(R2, t2, layout.points))
    np.testing.assert_allclose(again.points, layout.points, atol=1e-13)
    np.testing.assert_allclose(R_ch2, R2, atol=1e-12)
    # the paper's planar model on request: the same frame, heights zeroed
    flat, R_flat, _ = estimate_layout(pts, planar=True)
    np.testing.assert_array_equal(flat.points[:, 2], 0.0)
    np.testing.assert_allclose(flat.points[:, :2], layout.points[:, :2], atol=1e-15)
    np.testing.assert_allclose(R_flat, R_ch, atol=0)


def test_estimate_layout_of_a_left_hand_is_a_left_layout():
    rng = np.random.default_rng(5)
    left = arched_points() * [1.0, -1.0, 1.0]  # mirrored: the thumb on -Y
    R, t = posed_towards_camera(rng)
    layout, _, _ = estimate_layout(to_camera(R, t, left))
    assert layout.side == "left"
    mirrored, _, _ = estimate_layout(to_camera(R, t, arched_points()))
    np.testing.assert_allclose(layout.points, mirrored.mirrored().points, atol=1e-13)


def test_average_layout_of_still_frames_beats_one_frame():
    """Heights from one frame carry the depth noise; averaged over 16 still frames (each with
    its own small drift and 1.4 mm depth noise, correlated within a frame as a structured-light
    camera's is) the error falls by about sqrt(16)."""
    rng = np.random.default_rng(9)
    truth, _, _ = estimate_layout(to_camera(*posed_towards_camera(rng), arched_points()))
    one, many = [], []
    for _ in range(40):
        R, t = posed_towards_camera(rng)
        frames = []
        for _ in range(16):
            dR = Rotation.from_rotvec(rng.normal(scale=0.002, size=3)).as_matrix()
            noise = rng.normal(scale=0.0014, size=(6, 1)) * np.array([[0, 0, 1.0]])
            frames.append(to_camera(R @ dR, t + rng.normal(scale=2e-4, size=3), truth.points)
                          + noise)
        frames = np.array(frames)
        one.append(estimate_layout(frames[0])[0].points - truth.points)
        layout, R_ch, t_ch, rms = average_layout(frames)
        many.append(layout.points - truth.points)
        assert 0.0005 < rms < 0.0025
        # the pose is the last frame's, from its noisy depths (a start for the pixel fit)
        assert np.degrees((Rotation.from_matrix(R_ch).inv()
                           * Rotation.from_matrix(R @ dR)).magnitude()) < 4.0
    err_one = np.sqrt(np.mean(np.square(one)))
    err_many = np.sqrt(np.mean(np.square(many)))
    assert err_many < err_one / 3.0, (err_one, err_many)
    assert err_many < 0.0003


def test_average_layout_skips_frames_without_depth_and_refuses_none():
    pts = to_camera(np.diag([1.0, -1.0, -1.0]), np.array([0, 0, 0.6]), arched_points())
    frames = np.stack([pts, np.full((6, 3), np.nan), pts])
    layout, _, _, rms = average_layout(frames)
    assert rms < 1e-12 and layout.side == "right"
    with pytest.raises(InputError, match="no frame"):
        average_layout(np.full((2, 6, 3), np.nan))
    with pytest.raises(InputError, match="frames, 6, 3"):
        average_layout(np.zeros((6, 3)))


def test_estimate_layout_with_half_millimetre_noise():
    rng = np.random.default_rng(7)
    truth = HandLayout.default()
    length_err, angle_err, rot_err = [], [], []
    for _ in range(200):
        R, t = posed_towards_camera(rng)
        noisy = to_camera(R, t, truth.points) + rng.normal(scale=0.0005, size=(6, 3))
        layout, R_ch, t_ch = estimate_layout(noisy)
        length_err.append(layout.lengths - truth.lengths)
        angle_err.append(layout.angles - truth.angles)
        rot_err.append((Rotation.from_matrix(R_ch).inv() * Rotation.from_matrix(R)).magnitude())
    length_err = np.array(length_err)
    assert np.sqrt(np.mean(length_err**2)) < 0.001  # ~0.7 mm expected
    assert np.max(np.abs(length_err)) < 0.0035
    assert np.degrees(np.sqrt(np.mean(np.square(angle_err)))) < 1.0
    assert np.degrees(np.max(rot_err)) < 3.0


def test_estimate_layout_rejects_impossible_measurements():
    pts = np.column_stack([np.linspace(0, 0.1, 6), np.zeros(6), np.full(6, 0.7)])
    pts[:, 1] += [0, 0.001, -0.001, 0, 0.002, -0.002]
    with pytest.raises(LayoutEstimateError, match="collinear") as e:
        estimate_layout(pts)
    assert isinstance(e.value, ConfigError) and isinstance(e.value, InitialisationError)


@pytest.mark.parametrize("bad", [np.zeros((5, 3)), np.full((6, 3), np.nan)])
def test_estimate_layout_bad_input(bad):
    with pytest.raises(InputError):
        estimate_layout(bad)
    with pytest.raises(InputError):
        hand_frame_from_points(bad)


def test_fit_pose_against_scipy_align_vectors():
    rng = np.random.default_rng(11)
    truth = HandLayout.default()
    R, t = posed_towards_camera(rng)
    noisy = to_camera(R, t, truth.points) + rng.normal(scale=0.001, size=(6, 3))
    R_fit, t_fit = fit_pose(truth, noisy)
    q = truth.points - truth.points.mean(axis=0)
    p = noisy - noisy.mean(axis=0)
    r_ref, _ = Rotation.align_vectors(p, q)
    np.testing.assert_allclose(R_fit, r_ref.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(t_fit, noisy.mean(axis=0) - R_fit @ truth.points.mean(axis=0))
    # Exact data: exact pose.
    R_fit, t_fit = fit_pose(truth, to_camera(R, t, truth.points))
    np.testing.assert_allclose(R_fit, R, atol=1e-13)
    np.testing.assert_allclose(t_fit, t, atol=1e-14)
