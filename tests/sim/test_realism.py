"""The simulator's realism effects against independent truth: the statistics of real OpenNI depth
frames (../shared/realdata), cv2.projectPoints with the camera's distortion, a hand-written
bilinear demosaic, geometry worked out here rather than in the renderer."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.depth_noise import depth_sigma_nguyen, oblique_sigma
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import ConfigError
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.poses import read_poses
from wristtrack.sim import realism
from wristtrack.sim.depth_sensor import NOISE_PAD, DepthSensor
from wristtrack.sim.hand_model import MARKER_RADIUS
from wristtrack.sim.motion import still
from wristtrack.sim.renderer import Renderer
from wristtrack.sim.scenes import custom_scene, make_scene, with_effects
from wristtrack.sim.sensor import bayer_round_trip, jpeg_round_trip
from wristtrack.sim.shading import LIGHT

REAL_FRAMES = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "pcl_openni_frames"


def _first(scene, seed=0, k=0):
    r = Renderer(scene, seed)
    frame = None
    for t in scene.times[:k + 1]:
        frame = r.frame(float(t))
    return r, frame


@pytest.fixture(scope="module")
def real_depth():
    files = sorted(REAL_FRAMES.glob("*_depth.tiff"))
    if not files:
        pytest.skip(f"no real OpenNI frames in {REAL_FRAMES} (../shared/realdata beside the repo)")
    return [cv2.imread(str(f), cv2.IMREAD_UNCHANGED) for f in files]


@pytest.fixture(scope="module")
def structured():
    """Frame 0 of 'deviation' with structured-light depth, and the same frame plain."""
    sc = make_scene("deviation", 0, n_frames=2)
    sl = with_effects(sc, ["structured_light"])
    return _first(sl), _first(sc)


def _step_sizes(depth_mm: np.ndarray, z_m: float, half_band_m: float = 0.04) -> float:
    """Mean spacing (m) of the distinct depth values within +-half_band of z."""
    v = depth_mm[depth_mm > 0].astype(float) / 1000.0
    u = np.unique(v[np.abs(v - z_m) < half_band_m])
    assert len(u) > 5
    return float(np.mean(np.diff(u)))


# ----------------------------------------------------------------------- structured light


def test_disparity_quantisation_matches_the_real_camera(real_depth, structured):
    """Depth takes only values 1/8 px of disparity apart: steps of 2.85e-3 z^2 m, as the real
    frames show at 0.7, 0.9 and 1.2 m, and as the rendered table shows at its depth."""
    for z in (0.7, 0.9, 1.2):
        assert _step_sizes(real_depth[0], z) == pytest.approx(2.85e-3 * z * z, rel=0.12)
    (r, frame), _ = structured
    table = float(np.median(frame.depth[frame.depth > 0])) / 1000.0
    assert 0.72 < table < 0.85
    assert _step_sizes(frame.depth, table, 0.02) == pytest.approx(2.85e-3 * table**2, rel=0.12)
    # The plain Kinect model writes every millimetre.
    _, plain = structured[1]
    assert _step_sizes(plain.depth, table, 0.02) == pytest.approx(0.001, abs=1e-4)


def test_holes_and_invalid_border_like_the_real_frames(real_depth, structured):
    (r, frame), (_, plain) = structured
    real = np.mean([np.mean(d == 0) for d in real_depth])
    rendered = float(np.mean(frame.depth == 0))
    assert 0.10 < real < 0.13  # the README's 11.6 %
    assert abs(rendered - real) < 0.03, (rendered, real)
    assert np.mean(plain.depth == 0) < 0.05  # the plain model has few
    # Registration leaves columns on the right and rows at the top without depth, on both.
    for d in (*real_depth, frame.depth):
        assert np.all(d[:, -realism.BORDER_RIGHT + 2:] == 0)
        assert np.all(d[:realism.BORDER_TOP - 2] == 0)
        assert np.mean(d[:, :3] == 0) > 0.6 and np.mean(d[:, 40:60] == 0) < 0.4


def _jumps(depth: np.ndarray, rows: slice = slice(None)) -> np.ndarray:
    """(K, 4) each depth jump of more than 5 % between valid pixels along the rows of
    ``depth``: the columns of the valid pixel before and after it, whether the nearer surface
    is on the right (1) or left (0), and the number of holes between the two."""
    out = []
    for row in depth[rows].astype(float):
        idx = np.flatnonzero(row > 0)
        idx = idx[(idx > 40) & (idx < len(row) - 40)]  # clear of the invalid borders
        a, b = idx[:-1], idx[1:]
        jump = np.abs(row[a] - row[b]) > 0.05 * np.minimum(row[a], row[b])
        out += [(i, j, float(row[j] < row[i]), j - i - 1)
                for i, j in zip(a[jump], b[jump], strict=True)]
    return np.array(out, dtype=float).reshape(-1, 4)


def _fattening(bgr: np.ndarray, depth: np.ndarray) -> float:
    """How far (px) the nearer surface's depth reaches past its outline in the colour image:
    at each straight jump with flat depth on both sides, the strongest grey-level edge within
    8 px; the mean of the median offsets of the nearer surface's left and right edges (a
    misregistration moves those two alike and drops out)."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(float)
    offsets: dict[float, list[float]] = {0.0: [], 1.0: []}
    for y, row in enumerate(depth.astype(float)):
        for i, _, near_right, gap in _jumps(row[None]):
            i = int(i)
            side = row[i - 3:i + 5]
            if gap or i < 12 or i > len(row) - 12 or np.ptp(side[:4]) > 0.02 * side[0] \
                    or np.ptp(side[4:]) > 0.02 * side[4]:
                continue
            g = np.abs(np.diff(grey[y, i - 7:i + 9]))
            k = int(np.argmax(g))
            if g[k] < 12 or not 0 < k < len(g) - 1:
                continue
            sub = 0.5 * (g[k - 1] - g[k + 1]) / min(g[k - 1] - 2 * g[k] + g[k + 1], -1e-9)
            colour_edge = i - 7 + k + 0.5 + sub
            past = colour_edge - (i + 0.5)  # > 0: depth's edge left of the colour edge
            offsets[near_right].append(past if near_right else -past)
    return 0.5 * (float(np.median(offsets[1.0])) + float(np.median(offsets[0.0])))


def test_real_depth_edges_jump_straight_and_fatten_the_nearer_surface(real_depth):
    """The real OpenNI frames: the depth goes straight from one surface to the other (no band
    of holes at 93-96 % of its jumps) and the nearer surface reaches 1-2 px past its outline in
    the colour image, the simulator's realism.FATTEN_PX."""
    files = sorted(REAL_FRAMES.glob("*_rgb.tiff"))
    for depth, rgb in zip(real_depth, files, strict=True):
        jumps = _jumps(depth)
        assert np.mean(jumps[:, 3] == 0) > 0.9
        assert 0.8 < _fattening(cv2.imread(str(rgb)), depth) < 2.4
    assert realism.FATTEN_PX == 2  # 1 or 2 px, 1.5 on average


def _box_in_front(seed: int, box_z: float = 0.70, wall_z: float = 0.85):
    """Structured-light depth (m) of a box ``box_z`` away before a wall at ``wall_z``, the box's
    clean outline (columns 250..390, rows 180..300) and the sensor."""
    scene = make_scene("deviation", 0, n_frames=2)
    cam = scene.camera
    z = np.full((cam.height, cam.width), wall_z)
    z[180:300, 250:390] = box_z
    rng = np.random.default_rng(seed)
    bank = rng.standard_normal((2, cam.height + NOISE_PAD, cam.width + NOISE_PAD),
                               dtype=np.float32)
    sensor = DepthSensor(with_effects(scene, ["structured_light"]), z, bank, rng,
                         np.random.default_rng([seed, 4]))
    raw = sensor.capture(np.empty((0, 0)), (0, 0, 0, 0)).astype(float) * cam.depth_scale
    return raw, sensor


def test_rendered_depth_edges_fatten_the_nearer_surface_like_the_real_frames():
    """The box's depth reaches 1-2 px past its outline on both sides, its left edge jumps
    straight to the wall (its right one has the projector's shadow), and the wall keeps its
    depth away from the edge."""
    reach = {"left": [], "right": []}
    for seed in range(3):
        raw, sensor = _box_in_front(seed)
        dx, dy = sensor.sl_shift
        rows = slice(200 + dy, 280 + dy)  # clear of the box's top and bottom
        box = (raw[rows] > 0) & (raw[rows] < 0.76)
        cols = np.arange(raw.shape[1])
        first = np.array([cols[b].min() for b in box])
        last = np.array([cols[b].max() for b in box])
        reach["left"] += list(250 + dx - first)
        reach["right"] += list(last - (389 + dx))
        left = _jumps(raw, rows)
        left = left[(left[:, 2] == 1) & (np.abs(left[:, 1] - 250 - dx) < 6)]
        assert len(left) >= 75 and np.mean(left[:, 3] == 0) > 0.9
        assert np.all(np.abs(raw[rows, 200:235][raw[rows, 200:235] > 0] - 0.85) < 0.02)
    for side in ("left", "right"):
        r = np.array(reach[side])
        # 1 or 2 px, and the lateral jitter of depth edges (0.8 px) on top
        assert 1.0 <= np.median(r) <= 2.0, (side, np.median(r))
        assert np.mean((r >= 0) & (r <= 4)) > 0.9, side


def test_axial_noise_is_nguyens_and_spatially_correlated(structured):
    (r, frame), _ = structured
    d = frame.depth.astype(float) / 1000.0
    patch = d[330:447, 60:195]  # table, away from the hand and the border
    ok = patch > 0
    yy, xx = np.nonzero(ok)
    A = np.column_stack([xx, yy, np.ones_like(xx)]).astype(float)
    res = np.full(patch.shape, np.nan)
    res[ok] = patch[ok] - A @ np.linalg.lstsq(A, patch[ok], rcond=None)[0]
    z0 = float(np.median(patch[ok]))
    sigma = float(np.nanstd(res))
    assert sigma == pytest.approx(depth_sigma_nguyen(z0), rel=0.25)
    assert sigma > 1.5 * 1.425e-3 * z0**2 * 0.7  # well above the plain Kinect model
    # Averaging 9x9 pixels would cut iid noise 9-fold; the matching window's correlation keeps
    # most of it.
    blocks = np.nanmean(res.reshape(13, 9, 15, 9), axis=(1, 3))
    assert np.nanstd(blocks) / sigma > 0.4


def _tilted_plane_noise(scene, degrees: float, seed: int = 0) -> float:
    """The spread (m) about the plane of structured-light depth of a plane 0.7 m away turned
    ``degrees`` about the vertical axis, read in a band around the image centre (where the line
    of sight is the optical axis)."""
    cam = scene.camera
    H, W = cam.height, cam.width
    a = np.radians(degrees)
    normal = np.array([np.sin(a), 0.0, -np.cos(a)])  # towards the camera
    v, u = np.mgrid[0:H, 0:W].astype(float)
    rays = np.dstack(((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones((H, W))))
    z = (normal @ np.array([0.0, 0.0, 0.7])) / (rays @ normal)  # depth where each ray meets it
    rng = np.random.default_rng(seed)
    bank = rng.standard_normal((2, H + NOISE_PAD, W + NOISE_PAD), dtype=np.float32)
    sensor = DepthSensor(scene, z, bank, rng, np.random.default_rng([seed, 4]))
    raw = sensor.capture(np.empty((0, 0)), (0, 0, 0, 0)).astype(float) * cam.depth_scale
    band = (slice(int(cam.cy) - 40, int(cam.cy) + 40), slice(int(cam.cx) - 25, int(cam.cx) + 25))
    ok = raw[band] > 0
    return float(np.std((raw[band] - z[band])[ok]))


def test_axial_noise_grows_where_the_surface_is_seen_obliquely(structured):
    """Nguyen et al.'s axial noise against the angle between the surface and the line of sight:
    the same up to 60 deg, then + 1e-4 theta^2 / (sqrt(z) (pi/2 - theta)^2) (worked out here)."""
    (r, _), _ = structured
    scene = r.scene
    facing = np.mean([_tilted_plane_noise(scene, 20.0, s) for s in range(3)])
    z = 0.7
    assert facing == pytest.approx(depth_sigma_nguyen(z), rel=0.2)
    for degrees in (70.0, 75.0):
        theta = np.radians(degrees)
        extra = 1e-4 * theta**2 / (np.sqrt(z) * (np.pi / 2 - theta) ** 2)
        assert oblique_sigma(z, np.cos(theta)) == pytest.approx(extra)
        # the sd across the band: the matching window's correlated noise, the lateral jitter
        # over the slope and the disparity steps around the axial sigma
        measured = np.mean([_tilted_plane_noise(scene, degrees, s) for s in range(3)])
        assert measured == pytest.approx(depth_sigma_nguyen(z) + extra, rel=0.3)
    assert measured > 2.5 * facing


def test_depth_is_misregistered_by_one_to_two_pixels(structured):
    (r, frame), (_, plain) = structured
    # The hand in each, clear of the registered map's border: the structured one is 1-2 px wider
    # all round (fattening), the plain one 1-2 px narrower (its holes at depth edges).
    # Every shift that keeps the one inside the other overlaps as much: blurred, the overlap
    # peaks in the middle of those shifts.
    inner = (slice(realism.BORDER_TOP, -2 * realism.BORDER_BOTTOM), slice(None))
    a, b = (cv2.GaussianBlur(((d[inner] > 0) & (d[inner] < 720)).astype(np.float32), (0, 0), 2.0)
            for d in (plain.depth, frame.depth))
    scores = {(dx, dy): float(np.sum(np.roll(a, (dy, dx), (0, 1)) * b))
              for dx in range(-4, 5) for dy in range(-4, 5)}
    dx, dy = max(scores, key=scores.get)
    # (the rows have edges on both sides, the columns mostly the fingertips: dy is rougher)
    assert dx == r.depth.sl_shift[0] and abs(dy - r.depth.sl_shift[1]) <= 1
    assert 1 <= abs(dx) <= 2 and abs(dy) <= 1


# ------------------------------------------------------------------------- the colour camera


def _rim_centroids(R, t, layout, cam, offsets=None):
    """Area centroids of the projected marker rims by cv2.projectPoints with the camera's own
    distortion (the oracle)."""
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    circle = MARKER_RADIUS * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    rvec = cv2.Rodrigues(R)[0]
    dist = np.array(cam.dist) if cam.dist is not None else None
    pts = layout.points if offsets is None else layout.points + offsets
    out = []
    for p in pts:
        uv = cv2.projectPoints(p + circle, rvec, t, cam.K, dist)[0][:, 0].astype(np.float32)
        m = cv2.moments(uv)
        out.append([m["m10"] / m["m00"], m["m01"] / m["m00"]])
    return np.array(out)


def _blue_centroid(bgr, uv, radius=8):
    u0, v0 = int(round(uv[0])), int(round(uv[1]))
    win = bgr[v0 - radius:v0 + radius + 1, u0 - radius:u0 + radius + 1].astype(np.float32)
    w = np.clip(win[..., 0] - win[..., 2] - 40.0, 0, None)
    m = cv2.moments(w)
    return np.array([m["m10"] / m["m00"] + u0 - radius, m["m01"] / m["m00"] + v0 - radius])


def test_lens_distortion_is_rendered_through_the_cameras_model():
    sc = make_scene("reach", 0, n_frames=3, effects=["distortion"])
    assert sc.camera.dist == realism.XTION_DIST
    r, frame = _first(sc, k=2)  # the end of the reach: the hand off-centre
    traj = sc.trajectory()
    oracle = _rim_centroids(traj.R_ch[2], traj.t_ch[2], sc.layout, sc.camera)
    undistorted = _rim_centroids(traj.R_ch[2], traj.t_ch[2], sc.layout, Camera.default())
    moved = np.linalg.norm(oracle - undistorted, axis=1)
    assert moved.max() > 0.35  # ~2 px at the corners; here, off-centre, a fraction of that
    np.testing.assert_allclose(frame.uv, oracle, atol=0.02)
    blobs = np.array([_blue_centroid(frame.bgr, uv) for uv in oracle])
    to_oracle = np.linalg.norm(blobs - oracle, axis=1)
    assert to_oracle.max() < 0.2
    j = int(np.argmax(moved))
    assert to_oracle[j] < 0.5 * np.linalg.norm(blobs[j] - undistorted[j])


def test_bayer_round_trip_keeps_each_sites_channel_and_interpolates_bilinearly():
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.integers(0, 256, (40, 60, 3)).astype(np.uint8), (0, 0), 1.5)
    out = bayer_round_trip(img).astype(float)
    f = img.astype(float)
    np.testing.assert_array_equal(out[2:-2:2, 2:-2:2, 0], f[2:-2:2, 2:-2:2, 0])  # blue sites
    np.testing.assert_array_equal(out[3:-2:2, 3:-2:2, 2], f[3:-2:2, 3:-2:2, 2])  # red sites
    # At a blue site, green is the mean of its 4 neighbours, red of its 4 diagonals.
    y, x = 10, 20
    green = np.mean([f[y - 1, x, 1], f[y + 1, x, 1], f[y, x - 1, 1], f[y, x + 1, 1]])
    red = np.mean([f[y - 1, x - 1, 2], f[y - 1, x + 1, 2], f[y + 1, x - 1, 2], f[y + 1, x + 1, 2]])
    assert out[y, x, 1] == pytest.approx(green, abs=1.0)
    assert out[y, x, 2] == pytest.approx(red, abs=1.0)


@pytest.fixture(scope="module")
def compressed():
    sc = make_scene("deviation", 0, n_frames=3)
    plain = _first(sc, k=1)[1]
    return sc, plain


def _psnr(a, b):
    return 10 * np.log10(255.0**2 / np.mean((a.astype(float) - b.astype(float)) ** 2))


def test_jpeg_and_h264_compress_the_frame_and_nothing_else(compressed):
    sc, plain = compressed
    jpeg = _first(with_effects(sc, ["jpeg"]), k=1)[1]
    # The same frame, then OpenCV's JPEG at quality 80.
    np.testing.assert_array_equal(jpeg.bgr, jpeg_round_trip(plain.bgr, realism.JPEG_QUALITY))
    assert 30 < _psnr(jpeg.bgr, plain.bgr) < 45
    np.testing.assert_array_equal(jpeg.depth, plain.depth)
    pytest.importorskip("av", reason="the h264 effect needs PyAV: pip install 'wristtrack[video]'")
    h264 = _first(with_effects(sc, ["h264"]), k=1)[1]
    assert h264.bgr.shape == plain.bgr.shape and h264.bgr.dtype == np.uint8
    assert 30 < _psnr(h264.bgr, plain.bgr) < 45
    assert not np.array_equal(h264.bgr, jpeg.bgr)


def test_auto_exposure_steps_and_white_balance_drift():
    sc = make_scene("deviation", 0, n_frames=50, fps=5)  # ~10 s
    fx = with_effects(sc, ["auto_exposure", "white_balance"])
    ra, rb = Renderer(sc, 0), Renderer(fx, 0)
    gain, blue_red = [], []
    for t in sc.times[::2]:
        a, b = ra.frame(float(t)).bgr, rb.frame(float(t)).bgr
        pa = a[20:120, 20:160].reshape(-1, 3).mean(axis=0)  # static table, no hand
        pb = b[20:120, 20:160].reshape(-1, 3).mean(axis=0)
        gain.append(pb[1] / pa[1])
        blue_red.append((pb[0] / pa[0]) / (pb[2] / pa[2]))
    gain, blue_red = np.array(gain), np.array(blue_red)
    assert gain.min() > 0.68 and gain.max() < 1.32
    assert gain.max() / gain.min() > 1.1  # at least one real step over 10 s
    assert np.max(np.abs(np.diff(gain))) > 0.05  # steps, not a crawl
    assert np.ptp(blue_red) > 0.02 and np.all(np.abs(blue_red - 1) < 0.25)


def test_long_shutter_streaks_markers_by_their_motion():
    sc = make_scene("reach", 0)  # natural speed
    long = with_effects(sc, ["shutter"])
    assert long.exposure == pytest.approx(1 / 30)
    j, e = 3, long.exposure  # MCP3

    def image_path(t):
        ends = []
        for dt in (-e / 2, e / 2):
            R, p = sc.motion.pose(np.array([t + dt]))
            R_ch, t_ch = sc.R_c0 @ R[0], sc.R_c0 @ p[0] + sc.t_c0
            ends.append(sc.camera.project(sc.layout.points[j] @ R_ch.T + t_ch))
        return ends

    # A frame where the marker's image moves 8-16 px during the long exposure.
    k = next(i for i, t in enumerate(sc.times)
             if 8 < np.linalg.norm(np.subtract(*image_path(t))) < 16)
    t = float(sc.times[k])
    ends = image_path(t)
    streak = float(np.linalg.norm(ends[1] - ends[0]))
    a = Renderer(sc, 0).frame(t)
    b = Renderer(long, 0).frame(t)

    def spread_along(bgr):
        u0, v0 = np.round(a.uv[j]).astype(int)
        r = 14
        win = bgr[v0 - r:v0 + r + 1, u0 - r:u0 + r + 1].astype(np.float32)
        base = np.percentile(win[..., 0] - win[..., 2], 30)  # the skin around
        w = np.clip(win[..., 0] - win[..., 2] - base - 6.0, 0, None)
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        w[xx**2 + yy**2 > r * r] = 0
        m = cv2.moments(w)
        d = (ends[1] - ends[0]) / streak
        return (m["mu20"] * d[0] ** 2 + 2 * m["mu11"] * d[0] * d[1] + m["mu02"] * d[1] ** 2) / m[
            "m00"]

    # A uniform streak of length L adds L^2/12 to the variance along the motion; the plain
    # scenario's 8 ms shutter already streaks it by L * 0.008 / e.
    added = spread_along(b.bgr) - spread_along(a.bgr)
    expected = streak * np.sqrt(1.0 - (sc.exposure / e) ** 2)
    assert np.sqrt(12 * added) == pytest.approx(expected, rel=0.3)


def test_specular_highlight_sits_where_the_dome_mirrors_the_lamp():
    sc = custom_scene("still", still(1.0), np.array([0.0, 0.1]))
    spec = with_effects(sc, ["specular"])
    _, plain = _first(sc)
    _, frame = _first(spec)
    traj = sc.trajectory()
    R, t = traj.R_ch[0], traj.t_ch[0]
    n = R[:, 2]
    found = 0
    for j in range(6):
        c = sc.layout.points[j] @ R.T + t
        # Brute force over the dome: the point whose surface normal mirrors the lamp into the
        # camera best (reflection of -LIGHT about the normal closest to the view ray).
        best, where = -2.0, None
        for a in np.linspace(-0.4, 0.4, 81):
            for b in np.linspace(-0.4, 0.4, 81):
                e1 = R[:, 0] * a + R[:, 1] * b
                normal = n + e1
                normal /= np.linalg.norm(normal)
                p = c + realism.DOME_RADIUS * (normal - n)  # on the cap (tangent offset)
                view = -p / np.linalg.norm(p)
                refl = 2 * (normal @ LIGHT) * normal - LIGHT
                if refl @ view > best:
                    best, where = refl @ view, p
        if np.linalg.norm(where - c) > MARKER_RADIUS:
            continue  # the highlight falls off this marker
        found += 1
        uv = sc.camera.project(where)
        diff = frame.bgr.astype(float).sum(axis=2) - plain.bgr.astype(float).sum(axis=2)
        u0, v0 = int(round(uv[0])), int(round(uv[1]))
        win = diff[v0 - 6:v0 + 7, u0 - 6:u0 + 7]
        peak = np.array(np.unravel_index(np.argmax(win), win.shape))[::-1] + [u0 - 6, v0 - 6]
        assert win.max() > 300  # near-white on a blue marker
        assert np.linalg.norm(peak - uv) <= 1.5
        np.testing.assert_allclose(frame.uv[j], plain.uv[j])  # the truth is the rim's
    assert found >= 3


# ------------------------------------------------------------------------------- the hand


def test_arched_layout_is_three_dimensional_and_rendered_on_the_skin(tmp_path):
    sc = make_scene("deviation", 0, n_frames=2, effects=["nonplanar"])
    lay = sc.layout
    lay.validate()
    assert lay.points[3, 1] == 0 and lay.points[3, 2] == 0  # MCP3 on +X: the contract's frame
    assert np.ptp(lay.points[:, 2]) > 0.004  # the thumb base well below the knuckles
    assert lay.points[1, 2] < -0.003
    r, frame = _first(sc)
    traj = sc.trajectory()
    oracle = _rim_centroids(traj.R_ch[0], traj.t_ch[0], lay, sc.camera)
    np.testing.assert_allclose(frame.uv, oracle, atol=0.02)
    blobs = np.array([_blue_centroid(frame.bgr, uv) for uv in oracle])
    assert np.max(np.linalg.norm(blobs - oracle, axis=1)) < 0.3
    # Depth at the markers is their own: each lies on the skin, none buried under the arch.
    z_true = (lay.points @ traj.R_ch[0].T + traj.t_ch[0])[:, 2]
    for j, uv in enumerate(oracle):
        u, v = np.round(uv).astype(int)
        d = frame.depth[v - 2:v + 3, u - 2:u + 3].astype(float) / 1000
        assert np.median(d[d > 0]) == pytest.approx(z_true[j], abs=0.0015)  # noise: 0.6 mm
    # The same in the exact z-buffer, off-centre and tilted.
    for t in (2.0, 5.5):
        mo = r.moment(t)
        region = x0, y0, x1, y1 = r.region([mo.layer])
        z, ids = r.bg.z[y0:y1, x0:x1].copy(), r.bg.ids[y0:y1, x0:x1].copy()
        r.caster.draw(region, mo.layer, r.bg.colour[y0:y1, x0:x1].copy(), z, ids)
        centres = lay.points @ mo.layer.R.T + mo.layer.t
        for (u, v), zc in zip(sc.camera.project(centres), centres[:, 2], strict=True):
            u, v = int(round(u)), int(round(v))
            assert z[v - y0, u - x0] == pytest.approx(zc, abs=2e-4)


def test_soft_tissue_moves_only_the_mcp_markers_with_finger_flexion():
    sc = make_scene("deviation", 0, n_frames=12, fps=5, effects=["soft_tissue"])
    traj = sc.trajectory()
    r = Renderer(sc, 0)
    shifts = []
    for k in (0, 4, 8):
        t = float(sc.times[k])
        frame = r.frame(t)
        rigid = _rim_centroids(traj.R_ch[k], traj.t_ch[k], sc.layout, sc.camera)
        flex = 0.5 * realism.FINGER_FLEXION_MAX_DEG * (
            1 - np.cos(2 * np.pi * (t - sc.times[0]) / realism.FINGER_FLEXION_PERIOD_S))
        slide = np.zeros((6, 3))
        slide[2:] = [0.003 * flex / 90, 0.0, -0.001 * flex / 90]  # the stated 3 mm / 1 mm at 90
        moved = _rim_centroids(traj.R_ch[k], traj.t_ch[k], sc.layout, sc.camera, slide)
        np.testing.assert_allclose(frame.uv, moved, atol=0.02)
        shifts.append(np.linalg.norm(frame.uv - rigid, axis=1))
    shifts = np.array(shifts)
    assert np.all(shifts[:, :2] < 0.02)  # WRIST and CMC1 do not slide
    assert shifts[:, 2:].max() > 1.0  # the knuckles' skin does: ~2 mm, px at 0.65 m


def test_left_hand_is_mirrored_and_says_so(tmp_path):
    out = tmp_path / "left"
    assert main(["simulate", str(out), "--hand-side", "left", "--nonplanar", "--n-frames", "2",
                 "--scenario", "pronation"]) == 0
    lay = HandLayout.load(out / "hand.json")
    assert lay.side == "left" and lay.points[1, 1] < 0
    np.testing.assert_allclose(lay.points, realism.arched(HandLayout.default().mirrored()).points)
    truth = read_poses(out / "truth.csv")
    assert len(truth["timestamp"]) == 2
    rows = np.genfromtxt(out / "truth_markers.csv", delimiter=",", names=True)
    cam = Camera.load(out / "camera.json")
    # CMC1 is seen on the other side of the WRIST -> MCP3 line than on a right hand.
    uv = {n: np.array([rows[f"{n}_u"][0], rows[f"{n}_v"][0]]) for n in MARKER_NAMES}
    ax = uv["MCP3"] - uv["WRIST"]
    side = ax[0] * (uv["CMC1"] - uv["WRIST"])[1] - ax[1] * (uv["CMC1"] - uv["WRIST"])[0]
    right = make_scene("pronation", 0, n_frames=2)
    ruv = _first(right)[1].uv
    rax, rc = ruv[3] - ruv[0], ruv[1] - ruv[0]
    assert np.sign(side) == -np.sign(rax[0] * rc[1] - rax[1] * rc[0])
    assert cam == Camera.default()


def test_preset_real_through_the_cli_and_bad_effects(tmp_path, capsys):
    out = tmp_path / "real"
    assert main(["simulate", str(out), "--preset", "real", "--n-frames", "2"]) == 0
    assert "structured_light" in capsys.readouterr().out
    assert Camera.load(out / "camera.json").dist == realism.XTION_DIST
    assert np.ptp(HandLayout.load(out / "hand.json").points[:, 2]) > 0.004
    assert set(realism.PRESET_REAL) == set(realism.EFFECTS) - {"h264", "left_hand"}
    with pytest.raises(ConfigError, match="unknown simulator effect.*sparkle"):
        make_scene("deviation", effects=["sparkle"])
    with pytest.raises(ConfigError, match="hand side"):
        make_scene("deviation", hand_side="both")
    with pytest.raises(SystemExit):  # argparse: one line naming the choices, exit 2
        main(["simulate", str(tmp_path / "x"), "--hand-side", "middle"])


def test_h264_without_pyav_is_one_clear_line_and_writes_nothing(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "av", None)  # import av now fails as if not installed
    out = tmp_path / "h264"
    assert main(["simulate", str(out), "--h264", "--n-frames", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pip install 'wristtrack[video]'" in err
    assert not out.exists()


def test_a_marker_slid_onto_the_finger_base_shows_whole():
    # Wrist extended, fingers flexed: the MCP markers' skin has slid ~2.5 mm distally, past their
    # knuckles' pads onto the base of the fingers. A sticker shows wherever its skin is seen;
    # drawn on the back of the hand alone, a tenth of each disc went missing and the blobs'
    # centres moved ~0.5 px away from the fingers, all four alike.
    from wristtrack.detect.detector import MarkerDetector

    sc = make_scene("no_hand", 0, effects=["nonplanar", "soft_tissue"])
    t = 4.6
    assert realism.finger_flexion_deg(t, float(sc.times[0])) > 50
    frame = Renderer(sc, 0).frame(t)
    np.testing.assert_allclose(frame.visible, 1.0)
    det = MarkerDetector(sc.camera).detect(frame.bgr, frame.depth, t)
    for j in range(2, 6):
        assert np.linalg.norm(det.uv - frame.uv[j], axis=1).min() < 0.15, MARKER_NAMES[j]


def test_depth_lag_captures_the_depth_a_fixed_delay_after_the_colour():
    """The depth frame paired with a colour frame is the one a camera without the lag captures
    ``depth_delay`` later, to the pixel; the colour frame is unchanged (to a grey level: the box
    redrawn around the moving hand is a little larger). The delay is drawn per
    recording within half a frame interval and written into camera.json."""
    lagged, plain = make_scene("reach", 8, effects=["depth_lag"]), make_scene("reach", 8)
    delay = lagged.camera.depth_delay
    assert delay == realism.depth_delay(8, plain.fps) and 0.01 < abs(delay) <= 0.5 / plain.fps
    t = 2.1  # the reach's peak speed: the hand moves ~8 mm over the delay
    ours = Renderer(lagged, 8).frame(t)
    later, now = Renderer(plain, 8).frame(t + delay), Renderer(plain, 8).frame(t)
    moved = (ours.depth > 0) & (now.depth > 0) & (np.abs(now.depth.astype(int) - later.depth) > 3)
    assert moved.sum() > 1000
    np.testing.assert_array_equal(ours.depth, later.depth)
    assert np.median(np.abs(ours.depth[moved].astype(int) - now.depth[moved])) > 3  # mm
    assert np.abs(ours.bgr.astype(int) - now.bgr).max() <= 1
    delays = [realism.depth_delay(seed, 30.0) for seed in range(200)]
    assert max(np.abs(delays)) <= 1 / 60 and np.std(delays) == pytest.approx(1 / 60 / 3**0.5,
                                                                              rel=0.15)


def test_rolling_shutter_exposes_each_row_at_its_own_time():
    """Each row is exposed over the scene's exposure centred on its own time, the bottom row a
    readout after the top one: the detector finds each marker where it is when the row it is
    on is read (the time its own row gives, found by iterating the motion), to 0.1 px, where
    the frame's moment is up to several pixels off in the fast reach; the rendered truth
    (truth_markers.csv, for the detector's benchmarks) is there too. The readout is drawn per
    recording in half to one frame interval and written into camera.json; the depth (a global
    shutter) and every row of a still hand are as without it."""
    rolled = make_scene("reach", 8, n_frames=60, effects=["rolling_shutter"])
    plain = make_scene("reach", 8, n_frames=60)
    cam = rolled.camera
    assert cam.readout == realism.readout(8, rolled.fps) and 1 / 60 <= cam.readout <= 1 / 30
    renderer, detector = Renderer(rolled, 8), MarkerDetector(cam)
    points = rolled.layout.points

    def markers(t):
        R, p = renderer.pose(t)
        return cam.project(points @ R.T + p)

    off_frame, off_rows, off_truth = [], [], []
    for t in rolled.times[32:44]:  # the reach's fastest third
        frame = renderer.frame(float(t))
        found = detector.detect(frame.bgr, frame.depth, float(t)).uv
        when = np.full(6, float(t))
        for _ in range(5):  # each marker's row is read when it is on it
            read = np.array([markers(s)[j] for j, s in enumerate(when)])
            when = float(t) + cam.row_time(read[:, 1])
        nearest = np.linalg.norm(found[:, None] - read[None], axis=2).argmin(axis=0)
        off_rows.append(np.linalg.norm(found[nearest] - read, axis=1))
        off_frame.append(np.linalg.norm(found[nearest] - markers(float(t)), axis=1))
        off_truth.append(np.linalg.norm(found[nearest] - frame.uv, axis=1))
    assert np.max(off_frame) > 2.0 and np.max(off_rows) < 0.1 * np.max(off_frame)
    assert np.mean(off_rows) < 0.1
    assert np.mean(off_truth) < 0.05  # the rendered truth (truth_markers.csv) as the rows saw it
    # the depth is the global shutter's; a still hand (the start) renders as without it
    ours, theirs = Renderer(rolled, 8).frame(2.0), Renderer(plain, 8).frame(2.0)
    np.testing.assert_array_equal(ours.depth, theirs.depth)
    still_r, still_p = Renderer(rolled, 8).frame(0.0), Renderer(plain, 8).frame(0.0)
    assert np.abs(still_r.bgr.astype(int) - still_p.bgr).max() <= 1
    readouts = [realism.readout(seed, 30.0) for seed in range(200)]
    assert 1 / 60 <= min(readouts) and max(readouts) <= 1 / 30
    assert np.std(readouts) == pytest.approx(1 / 60 / 12**0.5, rel=0.15)
