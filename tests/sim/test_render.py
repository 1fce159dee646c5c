"""Tests of the image simulator against independent truth: cv2.projectPoints of the true pose from
truth.csv, blob centroids by cv2.moments on the rendered pixels, the recording reader."""

import csv
import json

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses, rows_to_poses
from wristtrack.sim.motion import still
from wristtrack.sim.render import MARKER_RADIUS, RENDER_SCENARIOS, render_frames, render_recording
from wristtrack.sim.scenes import back_turned, custom_scene, make_scene

N_FRAMES = 15
FPS = 5.0  # 15 frames over 2.8 s: each movement played about 2-3x faster than natural


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("render")
    return {
        name: render_recording(root / name, name, seed=3, n_frames=N_FRAMES, fps=FPS)
        for name in RENDER_SCENARIOS
    }


def _frames_csv(folder):
    with open(folder / "frames.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _rim_centroids(R, t, layout, cam):
    """Area centroids of the projected marker rims, by cv2.projectPoints (the oracle)."""
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    circle = MARKER_RADIUS * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    rvec = cv2.Rodrigues(R)[0]
    out = []
    for p in layout.points:
        uv = cv2.projectPoints(p + circle, rvec, t, cam.K, None)[0][:, 0].astype(np.float32)
        m = cv2.moments(uv)  # contour moments: the polygon's area centroid
        out.append([m["m10"] / m["m00"], m["m01"] / m["m00"]])
    return np.array(out)


def _blob(bgr, uv, radius=9):
    """Centroid, area (px) and weight image of the blue blob near uv.

    Weight = blueness B - R above the bluest of the surroundings (90th percentile of a ring
    around it: a marker can sit near the edge of the hand, so its surroundings are not one
    colour), so partly covered edge pixels count in proportion. Only a disc of radius - 1.5 px
    counts (neighbouring markers are ~16 px away).
    """
    u0, v0 = int(round(uv[0])), int(round(uv[1]))
    win = bgr[v0 - radius:v0 + radius + 1, u0 - radius:u0 + radius + 1].astype(np.float32)
    blue = win[..., 0] - win[..., 2]
    yy, xx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    r2 = xx**2 + yy**2
    ring = blue[(r2 >= (radius - 1.5) ** 2) & (r2 <= radius**2)]
    level = np.percentile(ring, 90) + 8.0  # + a few noise sigmas
    weight = np.where(r2 < (radius - 1.5) ** 2, np.clip(blue - level, 0, None), 0.0)
    m = cv2.moments(weight)
    if m["m00"] <= 0:
        return None, 0.0, weight
    c = np.array([m["m10"] / m["m00"] + u0 - radius, m["m01"] / m["m00"] + v0 - radius])
    # Area: coverage between the surroundings' typical level and a fully covered pixel.
    low, full = np.median(ring), np.percentile(blue, 99)
    cover = np.clip((blue - low) / max(full - low, 1e-9), 0, 1)
    area = float(np.sum(np.where(r2 < (radius - 1.5) ** 2, cover, 0.0)))
    return c, area, weight


@pytest.mark.parametrize("name", RENDER_SCENARIOS)
def test_scenario_writes_a_contract_folder(recordings, name):
    folder = recordings[name]
    header, rows = _frames_csv(folder)
    assert header == ["timestamp", "rgb", "depth"]
    cam = Camera.load(folder / "camera.json")
    assert cam == Camera.default()
    truth = read_poses(folder / "truth.csv")
    assert len(rows) == len(truth["timestamp"]) >= N_FRAMES - 3  # irregular timing drops some
    np.testing.assert_array_equal([float(r[0]) for r in rows], truth["timestamp"])
    bgr = cv2.imread(str(folder / rows[0][1]), cv2.IMREAD_UNCHANGED)
    assert bgr.dtype == np.uint8 and bgr.shape == (480, 640, 3)
    if name == "rgb_only":
        assert all(r[2] == "" for r in rows)
    else:
        depth = cv2.imread(str(folder / rows[0][2]), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16 and depth.shape == (480, 640)
        table = np.median(depth[depth > 0]) * cam.depth_scale
        assert 0.7 < table < 0.85  # the table, below the hand at 0.65 m
    if name == "no_hand":
        assert not (folder / "hand.json").exists()
    else:
        assert HandLayout.load(folder / "hand.json") == HandLayout.default()
    # The project's own reader takes it back.
    with open_recording(folder) as rec:
        frames = list(rec)
    assert len(frames) == len(rows)
    assert (frames[0].depth is None) == (name == "rgb_only")


def test_truth_is_the_scene_trajectory(recordings):
    scene = make_scene("reach", seed=3, n_frames=N_FRAMES, fps=FPS)
    traj = scene.trajectory()
    truth = read_poses(recordings["reach"] / "truth.csv")
    R, t = rows_to_poses(truth)
    np.testing.assert_allclose(t, traj.t_ch, atol=1e-8)
    np.testing.assert_allclose(R, traj.R_ch, atol=1e-7)
    np.testing.assert_allclose(np.radians(truth["flexion_deg"]), traj.angles[:, 1], atol=1e-8)
    assert np.linalg.norm(traj.p_rel[-1]) == pytest.approx(0.3)  # the whole reach is in it


@pytest.mark.parametrize("name", ["deviation", "flexion", "pronation", "reach"])
def test_marker_centroids_and_depth_match_the_true_pose(recordings, name):
    folder = recordings[name]
    cam, layout = Camera.load(folder / "camera.json"), HandLayout.load(folder / "hand.json")
    R, t = rows_to_poses(read_poses(folder / "truth.csv"))
    _, rows = _frames_csv(folder)
    errors, depth_errors = [], []
    for k, row in enumerate(rows):
        bgr = cv2.imread(str(folder / row[1]))
        depth = cv2.imread(str(folder / row[2]), cv2.IMREAD_UNCHANGED) * cam.depth_scale
        truth_uv = _rim_centroids(R[k], t[k], layout, cam)
        z_true = (layout.points @ R[k].T + t[k])[:, 2]
        for j in range(6):
            c, area, weight = _blob(bgr, truth_uv[j])
            assert c is not None, f"{name} frame {k}: marker {MARKER_NAMES[j]} not drawn"
            errors.append(np.linalg.norm(c - truth_uv[j]))
            u0, v0 = np.round(truth_uv[j]).astype(int)
            d = depth[v0 - 9:v0 + 10, u0 - 9:u0 + 10][weight > 0.5 * weight.max()]
            d = d[d > 0]
            if len(d) >= 5:
                depth_errors.append(np.median(d) - z_true[j])
    errors = np.array(errors)
    # The renderer fills the rim polygons exactly; what is left is noise and motion blur.
    assert np.percentile(errors, 95) < 0.15 and errors.max() < 0.3, errors.max()
    # Depth noise at 0.65 m is 0.6 mm per pixel, then whole millimetres: medians within ~1 mm.
    depth_errors = np.abs(depth_errors)
    assert len(depth_errors) > 0.8 * errors.size
    assert np.median(depth_errors) < 0.0008 and depth_errors.max() < 0.002


def test_back_turned_hand_hides_markers_and_tilted_ones_foreshorten():
    times = np.array([0.0, 0.1])
    layout = HandLayout.default()
    scenes = {
        "flat": custom_scene("flat", still(1.0), times),
        "tilted": custom_scene("tilted", still(1.0, (0.0, 0.0, -55.0)), times),  # 55 deg supinated
        "turned": custom_scene("turned", back_turned(), times),
    }
    frames = {k: next(render_frames(s, seed=1)) for k, s in scenes.items()}
    np.testing.assert_array_equal(frames["flat"].visible, 1.0)
    np.testing.assert_array_equal(frames["tilted"].visible, 1.0)
    np.testing.assert_array_equal(frames["turned"].visible, 0.0)

    def blue_pixels(bgr):
        b, g, r = (bgr[..., i].astype(int) for i in range(3))
        return (b - r > 60) & (b - g > 40)

    assert blue_pixels(frames["flat"].bgr).sum() > 6 * 60  # six discs ~10 px across
    assert blue_pixels(frames["turned"].bgr).sum() == 0
    # Foreshortening: a small flat disc of area A covers f^2 A |n.p| / z^3 pixels.
    def expected_area(scene, j):
        traj = scene.trajectory()
        R, t = traj.R_ch[0], traj.t_ch[0]
        p = R @ layout.points[j] + t
        return abs(R[:, 2] @ p) / p[2] ** 3

    for j in range(6):
        areas = [_blob(frames[k].bgr, frames[k].uv[j])[1] for k in ("flat", "tilted")]
        ratio = expected_area(scenes["tilted"], j) / expected_area(scenes["flat"], j)
        assert 0.4 < ratio < 0.7
        assert areas[1] / areas[0] == pytest.approx(ratio, rel=0.12)


def test_occluder_hides_two_markers_then_leaves(recordings):
    folder = recordings["occlusion"]
    with open(folder / "truth_markers.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    vis = np.array([[float(r[f"{n}_visible"]) for n in MARKER_NAMES] for r in rows])
    hidden = (vis[:, 4] == 0) & (vis[:, 5] == 0)
    assert hidden.any() and vis[0].min() == 1.0 and vis[-1].min() == 1.0
    assert np.all(vis[hidden][:, :4] == 1.0)  # only MCP4 and MCP5
    _, frame_rows = _frames_csv(folder)
    k = int(np.flatnonzero(hidden)[0])
    bgr = cv2.imread(str(folder / frame_rows[k][1]))
    for j in (4, 5):
        uv = (float(rows[k][f"{MARKER_NAMES[j]}_u"]), float(rows[k][f"{MARKER_NAMES[j]}_v"]))
        c, _, weight = _blob(bgr, uv)
        assert c is None or weight.sum() < 0.02 * 255 * 80  # no blue left at the marker


def test_clutter_adds_blue_objects(recordings):
    def blue_components(folder):
        _, rows = _frames_csv(folder)
        bgr = cv2.imread(str(folder / rows[0][1])).astype(int)
        mask = ((bgr[..., 0] - bgr[..., 2] > 60) & (bgr[..., 0] - bgr[..., 1] > 40))
        n, _, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8))
        return int(np.sum(stats[1:, cv2.CC_STAT_AREA] >= 20))

    assert blue_components(recordings["deviation"]) == 6
    assert blue_components(recordings["clutter"]) >= 9


def test_irregular_timestamps(recordings):
    for name in ("irregular", "hard"):
        _, rows = _frames_csv(recordings[name])
        t = np.array([float(r[0]) for r in rows])
        dt = np.diff(t)
        assert np.all(dt > 0)
        assert dt.std() > 1e-3  # jittered (3 ms) and/or dropped frames
        assert np.abs(dt - 1 / FPS).max() > 5e-4
    _, rows = _frames_csv(recordings["deviation"])
    np.testing.assert_allclose(np.diff([float(r[0]) for r in rows]), 1 / FPS, atol=1e-12)


def test_deterministic_for_a_seed():
    scene = make_scene("hard", seed=5, n_frames=3, fps=10)
    a = list(render_frames(scene, seed=5))
    b = list(render_frames(scene, seed=5))
    c = list(render_frames(scene, seed=6))
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.bgr, y.bgr)
        np.testing.assert_array_equal(x.depth, y.depth)
    assert any(np.any(x.bgr != z.bgr) for x, z in zip(a, c, strict=True))


def test_options_and_errors(tmp_path):
    from wristtrack.errors import ConfigError

    cam = Camera(fx=500.0, fy=500.0, cx=330.0, cy=250.0, width=640, height=480,
                 dist=(0.05, -0.1, 0.0, 0.0, 0.0))
    folder = render_recording(tmp_path / "cam", "deviation", n_frames=2, fps=10, camera=cam)
    assert Camera.load(folder / "camera.json") == cam
    assert json.loads((folder / "hand.json").read_text())["markers"].keys() == set(MARKER_NAMES)
    with pytest.raises(ConfigError, match="unknown render scenario"):
        make_scene("juggling")
    with pytest.raises(ConfigError, match="unknown render option"):
        make_scene("deviation", speed=2)


def test_outline_culling_never_clips_geometry():
    """Only pixels inside each primitive's projected outline are ray-cast: with a much wider
    outline the z-buffer must not change (off-axis, tilted, moving poses)."""
    from wristtrack.sim.renderer import Renderer

    scene = make_scene("hard", seed=0)
    r = Renderer(scene, 0)
    for t in (1.0, 3.6, 5.0, 7.0):
        layer = r.layer(t)
        region = x0, y0, x1, y1 = r.region([layer])
        out = []
        for margin in (1.5, 12.0):
            r.caster.margin = margin
            z, ids = r.bg.z[y0:y1, x0:x1].copy(), r.bg.ids[y0:y1, x0:x1].copy()
            r.caster.draw(region, layer, r.bg.colour[y0:y1, x0:x1].copy(), z, ids)
            out.append((z, ids))
        np.testing.assert_array_equal(out[0][0], out[1][0])
        np.testing.assert_array_equal(out[0][1], out[1][1])
