"""wristtrack.camera against OpenCV (projectPoints, undistortPoints) and hand-derived values."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, WristtrackError

DISTORTIONS = {
    "none": None,
    "k4": (0.1, -0.2, 0.001, 0.002),
    "k5": (0.12, -0.25, 0.001, -0.0015, 0.09),
    "k5_strong": (0.2, -0.5, 0.002, -0.001, 0.3),
    "barrel": (-0.3, 0.1, 0.0, 0.0, 0.0),
    "rational8": (0.1, -0.2, 0.001, 0.002, 0.05, 0.02, -0.01, 0.03),
}


def make_camera(dist=None) -> Camera:
    return Camera(fx=525.0, fy=527.0, cx=320.3, cy=241.1, width=640, height=480, dist=dist)


def points_in_view(n: int = 2000, seed: int = 0) -> np.ndarray:
    """Camera-frame points spread over (slightly beyond) the 640x480 field of view."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.4, 2.0, n)
    return np.column_stack([rng.uniform(-0.62, 0.62, n) * z, rng.uniform(-0.47, 0.47, n) * z, z])


def cv2_project(cam: Camera, p: np.ndarray) -> np.ndarray:
    dist = np.zeros(5) if cam.dist is None else np.array(cam.dist)
    uv, _ = cv2.projectPoints(p.reshape(-1, 3), np.zeros(3), np.zeros(3), cam.K, dist)
    return uv.reshape(*p.shape[:-1], 2)


def write_json(tmp_path, content, name="camera.json"):
    path = tmp_path / name
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    return path


GOOD = {
    "fx": 525.0,
    "fy": 525.0,
    "cx": 319.5,
    "cy": 239.5,
    "width": 640,
    "height": 480,
    "depth_scale": 0.001,
}


# ------------------------------------------------------------------------------------- basics


def test_default_camera():
    cam = Camera.default()
    assert (cam.width, cam.height) == (640, 480)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (525.0, 525.0, 319.5, 239.5)
    assert cam.depth_scale == 0.001
    assert cam.dist is None
    assert cam.area == 640.0 * 480.0
    np.testing.assert_array_equal(cam.K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])


def test_camera_is_frozen_and_hashable():
    cam = Camera.default()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.fx = 1.0  # type: ignore[misc]
    assert hash(cam) == hash(Camera.default())
    assert isinstance(make_camera([0.1, 0, 0, 0]).dist, tuple)


def test_project_hand_computed():
    cam = Camera.default()
    # (0.1, -0.05, 0.5): x/z = 0.2, y/z = -0.1
    np.testing.assert_allclose(
        cam.project(np.array([0.1, -0.05, 0.5])), [525 * 0.2 + 319.5, 525 * -0.1 + 239.5]
    )
    np.testing.assert_allclose(cam.project(np.array([0.0, 0.0, 1.0])), [319.5, 239.5])


@pytest.mark.parametrize("name", list(DISTORTIONS))
def test_project_matches_cv2(name):
    cam = make_camera(DISTORTIONS[name])
    p = points_in_view().reshape(4, 500, 3)
    uv = cam.project(p)
    assert uv.shape == (4, 500, 2)
    np.testing.assert_allclose(uv, cv2_project(cam, p), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(DISTORTIONS))
def test_backproject_inverts_project(name):
    cam = make_camera(DISTORTIONS[name])
    p = points_in_view(seed=1)
    uv = cam.project(p)
    back = cam.backproject(uv, p[:, 2])
    assert back.shape == p.shape
    # 1e-12 m at <= 2 m is far below 1e-6 px.
    np.testing.assert_allclose(back, p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam.project(back), uv, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["k4", "k5", "k5_strong", "rational8"])
def test_normalize_matches_cv2_undistort_points(name):
    cam = make_camera(DISTORTIONS[name])
    rng = np.random.default_rng(2)
    uv = np.column_stack([rng.uniform(0, 639, 500), rng.uniform(0, 479, 500)])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-16)
    ref = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, np.array(cam.dist), criteria=criteria)
    np.testing.assert_allclose(cam.normalize(uv), ref[:, 0], rtol=0, atol=1e-10)


def test_backproject_hand_computed_and_broadcast():
    cam = Camera.default()
    p = cam.backproject(np.array([319.5 + 52.5, 239.5 - 105.0]), 2.0)
    np.testing.assert_allclose(p, [0.2, -0.4, 2.0])
    uv = np.zeros((3, 4, 2))
    assert cam.backproject(uv, 1.5).shape == (3, 4, 3)
    assert cam.backproject(uv, np.ones((3, 4))).shape == (3, 4, 3)


def test_backproject_nan_stays_nan_without_breaking_the_batch():
    cam = make_camera(DISTORTIONS["k5"])
    uv = np.array([[100.0, 200.0], [np.nan, 10.0], [300.0, 300.0]])
    p = cam.backproject(uv, np.array([1.0, 1.0, np.nan]))
    assert np.all(np.isnan(p[1, :2])) and np.all(np.isnan(p[2]))
    np.testing.assert_allclose(cam.project(p[0]), uv[0], atol=1e-9)


def test_unreachable_distorted_point_is_nan():
    # r (1 - 0.5 r^2) never exceeds ~0.544: a distorted radius of 2 has no preimage.
    cam = make_camera((-0.5, 0.0, 0.0, 0.0, 0.0))
    x = cam.normalize(np.array([[cam.cx + 2.0 * cam.fx, cam.cy], [cam.cx + 10.0, cam.cy]]))
    assert np.all(np.isnan(x[0]))
    assert np.all(np.isfinite(x[1]))


def test_in_image():
    cam = Camera.default()
    uv = np.array(
        [[-0.5, -0.5], [639.49, 479.49], [639.5, 0.0], [0.0, 479.5], [-0.51, 3.0], [np.nan, 1.0]]
    )
    np.testing.assert_array_equal(cam.in_image(uv), [True, True, False, False, False, False])
    assert cam.in_image(np.zeros((2, 3, 2))).shape == (2, 3)


# --------------------------------------------------------------------------------------- files


@pytest.mark.parametrize("name", list(DISTORTIONS))
def test_json_round_trip(tmp_path, name):
    cam = Camera(
        fx=612.25,
        fy=611.5,
        cx=318.1,
        cy=244.9,
        width=1280,
        height=720,
        depth_scale=0.00025,
        dist=DISTORTIONS[name],
    )
    path = tmp_path / "sub" / "camera.json"
    cam.save(path)
    assert Camera.load(path) == cam
    d = json.loads(path.read_text())
    assert set(d) == {*GOOD, *(["dist"] if cam.dist is not None else [])}
    assert Camera.from_dict(cam.to_dict()) == cam


@pytest.mark.parametrize("delay", [-0.0125, 0.0])
def test_depth_delay_round_trips_and_unknown_is_left_out(tmp_path, delay):
    """camera.json's optional depth_delay_s: the depth frames' capture after the colour's; 0 is
    a stated delay (synchronised sensors), absent an unknown one."""
    cam = dataclasses.replace(Camera.default(), depth_delay=delay)
    path = tmp_path / "camera.json"
    cam.save(path)
    assert json.loads(path.read_text())["depth_delay_s"] == delay
    assert Camera.load(path) == cam and Camera.load(path).depth_delay == delay
    Camera.default().save(path)
    assert "depth_delay_s" not in json.loads(path.read_text())
    assert Camera.load(path).depth_delay is None


def test_readout_round_trips_and_gives_each_rows_time(tmp_path):
    """camera.json's optional readout_s (a rolling shutter's top row to bottom one): the middle
    row at the frame's time, the top and bottom rows half the readout before and after (by
    hand: rows 0 and 479 of 480 are 0.5 and 479.5 / 480 of the way down); absent, a global
    shutter's rows all at once."""
    cam = dataclasses.replace(Camera.default(), readout=0.024)
    path = tmp_path / "camera.json"
    cam.save(path)
    assert json.loads(path.read_text())["readout_s"] == 0.024 and Camera.load(path) == cam
    np.testing.assert_allclose(cam.row_time(np.array([0.0, 239.5, 479.0])),
                               [-0.012 + 0.024 / 960, 0.0, 0.012 - 0.024 / 960], atol=1e-15)
    assert Camera.default().row_time(479.0) == 0.0
    Camera.default().save(path)
    assert "readout_s" not in json.loads(path.read_text()) and Camera.load(path).readout is None


def test_load_accepts_integral_floats_and_extra_fields(tmp_path):
    path = write_json(tmp_path, {**GOOD, "width": 640.0, "model": "xtion", "dist": None})
    cam = Camera.load(path)
    assert cam == Camera.default()
    assert isinstance(cam.width, int)


@pytest.mark.parametrize("field", list(GOOD))
def test_missing_field(tmp_path, field):
    path = write_json(tmp_path, {k: v for k, v in GOOD.items() if k != field})
    with pytest.raises(ConfigError, match=str(path).replace("\\", "\\\\")) as e:
        Camera.load(path)
    assert f"'{field}'" in str(e.value) and "missing" in str(e.value)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("fx", -525.0),
        ("fy", 0.0),
        ("fx", "525"),
        ("fx", True),
        ("cx", None),
        ("width", 0),
        ("height", -480),
        ("width", 640.5),
        ("depth_scale", -0.001),
        ("depth_scale", 0),
        ("dist", [0.1, 0.2, 0.3]),
        ("dist", [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]),
        ("dist", [0.1, "a", 0.0, 0.0]),
        ("dist", "0.1 0.2 0 0"),
        ("dist", 0.1),
        ("depth_delay_s", 8),  # milliseconds given for seconds
        ("depth_delay_s", "0.008"),
        ("depth_delay_s", float("inf")),
        ("readout_s", 25),  # milliseconds given for seconds
        ("readout_s", -0.01),
        ("readout_s", "0.025"),
    ],
)
def test_bad_field_value(tmp_path, field, value):
    path = write_json(tmp_path, {**GOOD, field: value})
    with pytest.raises(ConfigError) as e:
        Camera.load(path)
    msg = str(e.value)
    assert str(path) in msg and f"'{field}'" in msg
    assert "\n" not in msg


def test_nan_in_file(tmp_path):
    path = write_json(tmp_path, json.dumps(GOOD).replace("319.5", "NaN"))
    with pytest.raises(ConfigError, match="'cx'"):
        Camera.load(path)


def test_not_json(tmp_path):
    path = write_json(tmp_path, '{"fx": 525, "fy": ')
    with pytest.raises(ConfigError, match="not valid JSON") as e:
        Camera.load(path)
    assert str(path) in str(e.value)


def test_not_an_object(tmp_path):
    path = write_json(tmp_path, "[525, 525, 319.5]")
    with pytest.raises(ConfigError, match="JSON object") as e:
        Camera.load(path)
    assert str(path) in str(e.value)


def test_missing_file(tmp_path):
    path = tmp_path / "nope" / "camera.json"
    with pytest.raises(ConfigError, match=r"^camera file .* not found") as e:
        Camera.load(path)
    assert str(path) in str(e.value)
    assert isinstance(e.value, WristtrackError)


def test_directory_instead_of_file(tmp_path):
    with pytest.raises(ConfigError, match="directory"):
        Camera.load(tmp_path)


def test_from_dict_default_source_name():
    with pytest.raises(ConfigError, match=r"camera file camera\.json: field 'fx'"):
        Camera.from_dict({**GOOD, "fx": -1})
    with pytest.raises(ConfigError, match=r"my_cam\.json"):
        Camera.from_dict({**GOOD, "fy": -1}, source="my_cam.json")


def test_direct_construction_is_validated():
    with pytest.raises(ConfigError, match="'fx'"):
        Camera(fx=-1.0, fy=525.0, cx=0.0, cy=0.0, width=640, height=480)
    with pytest.raises(ConfigError, match="'dist'"):
        make_camera((0.1, 0.2))
