"""Synthetic RGB-D frames with known marker centres, and the detector's timing for the benchmark.

:func:`synth_scene` draws, with OpenCV only, a textured table, a skin-coloured hand (forearm,
palm, fingers, thumb) in perspective, the six 12 mm markers of the default hand layout as
anti-aliased sub-pixel polygons (the exact perspective image of each disc), blue clutter, noise,
and a Kinect-like depth image (noise sigma 1.425e-3 z^2 m, whole millimetres, holes). Truth is
the projection of each marker's centre and its depth, computed from the geometry, never from the
image. It is independent of the detector and shared by the tests and :func:`time_detection`.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.depth_noise import depth_sigma
from wristtrack.detect.detector import MarkerDetector
from wristtrack.hand import HandLayout

SHIFT = 8  # sub-pixel bits for OpenCV drawing
SKIN_BGR = (105.0, 135.0, 190.0)
MARKER_BGR = (175.0, 85.0, 25.0)
TABLE_BGR = (105.0, 118.0, 108.0)
MARKER_RADIUS = 0.006


@dataclass
class SynthScene:
    """One synthetic frame and its truth. ``uv`` (6,2) and ``z`` (6,) are the true marker
    centres (MARKER_NAMES order); ``clutter_uv`` the off-hand clutter, ``edge_clutter_uv`` the
    clutter on the hand's edge; ``hand`` the hand's pixel mask."""

    bgr: np.ndarray
    depth: np.ndarray | None
    uv: np.ndarray
    z: np.ndarray
    clutter_uv: np.ndarray
    edge_clutter_uv: np.ndarray
    hand: np.ndarray
    camera: Camera


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _fill(img: np.ndarray, uv: np.ndarray, colour) -> None:
    pts = np.round(np.asarray(uv) * (1 << SHIFT)).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(img, [pts], colour, cv2.LINE_AA, SHIFT)


def _blend(img: np.ndarray, uv: np.ndarray, colour, supersample: int = 8) -> None:
    """Paint polygon ``uv`` (N,2) into float image ``img`` with exact area coverage.

    The polygon is filled (no anti-aliasing) on a ``supersample`` x finer grid around it and
    area-averaged back, so each pixel's colour mixes in proportion to the area covered: the
    centroid of the result is the polygon's to ~0.01 px. (OpenCV's LINE_AA fill is off by up to
    0.2 px in y, too coarse for truth.)"""
    S = supersample
    uv = np.asarray(uv, dtype=np.float64)
    h, w = img.shape[:2]
    x0, y0 = (np.floor(uv.min(0)) - 2).astype(int)
    x1, y1 = (np.ceil(uv.max(0)) + 3).astype(int)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if x1 <= x0 or y1 <= y0:
        return
    big = np.zeros(((y1 - y0) * S, (x1 - x0) * S), np.uint8)
    # pixel centres are at integers: full-res x maps to fine (x - x0 + 0.5) * S - 0.5
    fine = ((uv - (x0, y0) + 0.5) * S - 0.5) * 16
    cv2.fillPoly(big, [np.round(fine).astype(np.int32).reshape(-1, 1, 2)], 255, cv2.LINE_8, 4)
    a = cv2.resize(big.astype(np.float32), (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    a = (a / 255)[..., None]
    patch = img[y0:y1, x0:x1]
    patch *= 1 - a
    patch += a * np.asarray(colour, np.float32)


def _ellipse_pts(cx: float, cy: float, a: float, b: float, n: int = 64) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([cx + a * np.cos(t), cy + b * np.sin(t), np.zeros(n)], -1)


def _plane_depth(camera: Camera, normal: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(H,W) z of the plane through ``point`` with ``normal`` along each pixel's ray."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    ray = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)], -1)
    return float(normal @ point) / (ray @ normal)


def synth_scene(
    rng: np.random.Generator | int = 0,
    *,
    camera: Camera | None = None,
    z: float = 0.5,
    centre: tuple[float, float] = (250.0, 260.0),
    yaw_deg: float = -20.0,
    tilt_deg: float = 25.0,
    noise: float = 3.0,
    gain: float = 1.0,
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0),
    blur: float = 0.5,
    with_depth: bool = True,
    depth_dropout: float = 0.1,
    hole_over_marker: int | None = None,
    merged: bool = False,
    clipped: int | None = None,
    clutter: bool = True,
    markers: bool = True,
    extra_discs: tuple[tuple[float, float, tuple[float, float, float]], ...] = (),
) -> SynthScene:
    """One synthetic RGB-D frame (see the module docstring).

    The hand's wrist is at pixel ``centre`` and depth ``z``; ``yaw_deg`` turns it in the image,
    ``tilt_deg`` tips the palm plane about the hand's long axis (foreshortening). ``merged``
    moves MCP4 to overlap MCP3 by 0.5 mm; ``clipped`` hides about 40 % of that marker under a
    small grey bar; ``hole_over_marker`` blanks the depth around that marker. ``gain`` scales
    brightness, ``white_balance`` the B, G, R channels. ``extra_discs``: (hand x, hand y, BGR)
    12 mm discs of other colours drawn on the hand.
    """
    rng = np.random.default_rng(rng)
    cam = camera or Camera.default()
    H, W = cam.height, cam.width
    # hand -> camera: hand X right, Y up in the image, Z towards the camera; then yaw and tilt
    R = _rot(2, np.radians(yaw_deg)) @ np.diag([1.0, -1.0, -1.0]) @ _rot(0, np.radians(tilt_deg))
    t = np.array([(centre[0] - cam.cx) / cam.fx * z, (centre[1] - cam.cy) / cam.fy * z, z])

    def proj(p: np.ndarray) -> np.ndarray:
        return cam.project(p @ R.T + t)

    pts = HandLayout.default().points.copy()
    if merged:
        d = pts[4] - pts[3]
        pts[4] = pts[3] + d / np.linalg.norm(d) * (2 * MARKER_RADIUS - 0.0005)

    # --- table: textured, lit unevenly
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    grain = 8 * np.sin(u * 0.05 + 3 * np.sin(v * 0.013)) + 4 * np.sin(v * 0.31 + u * 0.02)
    blotch = cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 9) * 60
    img = np.empty((H, W, 3), np.float32)
    for c in range(3):
        img[..., c] = TABLE_BGR[c] + grain + blotch
    img *= (0.85 + 0.3 * u / W)[..., None]

    # --- hand, drawn into its own layer so it can be shaded and masked
    layer = np.zeros((H, W), np.uint8)
    forearm = np.array(
        [[0.012, 0.033, 0], [-0.40, 0.045, 0], [-0.40, -0.045, 0], [0.012, -0.033, 0]]
    )
    _fill(layer, proj(forearm), 255)
    _fill(layer, proj(_ellipse_pts(0.045, 0.0, 0.06, 0.05)), 255)
    for fy, length in ((0.027, 0.15), (0.008, 0.165), (-0.012, 0.16), (-0.031, 0.145)):
        finger = _ellipse_pts((0.09 + length) / 2, fy, (length - 0.09) / 2 + 0.01, 0.0085)
        _fill(layer, proj(finger), 255)
    thumb = _ellipse_pts(0.0, 0.0, 0.04, 0.011)
    ang = np.radians(40)
    turn = np.array([[np.cos(ang), np.sin(ang)], [-np.sin(ang), np.cos(ang)]])
    thumb[:, :2] = thumb[:, :2] @ turn
    thumb[:, :2] += (0.055, 0.055)
    _fill(layer, proj(thumb), 255)
    alpha = layer.astype(np.float32)[..., None] / 255
    shade = 0.9 + 0.15 * np.cos((u - centre[0]) / 140)[..., None] + 8 * blotch[..., None] / 3000
    skin = np.array(SKIN_BGR, np.float32) * shade
    img = img * (1 - alpha) + skin * alpha
    hand = layer > 127

    # --- markers: the exact perspective image of each disc, as a fine anti-aliased polygon
    uv = proj(pts)
    zt = (pts @ R.T + t)[:, 2]

    def disc(x: float, y: float, colour) -> None:
        ring = _ellipse_pts(x, y, MARKER_RADIUS, MARKER_RADIUS, 96)
        _blend(img, proj(ring), colour)

    if markers:
        for k in range(6):
            s = float(shade[int(uv[k, 1]), int(uv[k, 0]), 0])
            disc(pts[k, 0], pts[k, 1], tuple(c * s for c in MARKER_BGR))
    for x, y, colour in extra_discs:
        disc(x, y, colour)

    # --- clutter: blue things on the table far from the hand, one on the hand's edge
    clutter_uv = np.zeros((0, 2))
    edge_uv = np.zeros((0, 2))
    if clutter:
        far = cv2.distanceTransform((~hand).astype(np.uint8), cv2.DIST_L2, 5)
        far[:30], far[-30:], far[:, :30], far[:, -30:] = 0, 0, 0, 0
        spots = np.argwhere(far > 60)
        chosen = spots[rng.choice(len(spots), 3, replace=False)][:, ::-1].astype(float)
        chosen += rng.uniform(0, 1, chosen.shape)
        colours = [MARKER_BGR, (160, 70, 40), (190, 110, 30)]
        for (cu, cv_), col in zip(chosen[:2], colours, strict=False):
            r = rng.uniform(5, 9)
            _blend(img, _ellipse_pts(cu, cv_, r, r)[:, :2], col)
        cu, cv_ = chosen[2]
        box = cv2.boxPoints(((cu, cv_), (40, 7), rng.uniform(0, 180)))  # a blue pen
        _blend(img, box, colours[2])
        clutter_uv = chosen
        # on the edge of the palm (the little-finger side), centred on the outline
        e = proj(np.array([[0.02, -0.05 * np.sqrt(1 - (0.025 / 0.06) ** 2), 0.0]]))[0]
        _blend(img, _ellipse_pts(e[0], e[1], 7.0, 6.0)[:, :2], MARKER_BGR)
        edge_uv = e[None]

    if clipped is not None:
        # a grey bar (a pen, a fingertip) whose edge passes 0.2 marker radii beyond the centre:
        # ~40 % of the disc hidden
        c = uv[clipped]
        r_px = cam.fx * MARKER_RADIUS / zt[clipped]
        box = cv2.boxPoints(((c[0] + 1.2 * r_px, c[1]), (2 * r_px, 4 * r_px), 0.0))
        _blend(img, box, (95, 95, 100))

    # --- camera: blur, brightness, white balance, sensor noise
    out = img
    if blur > 0:
        out = cv2.GaussianBlur(out, (0, 0), blur)
    out *= gain * np.array(white_balance, np.float32)
    out += rng.normal(0, noise, out.shape).astype(np.float32)
    bgr = np.clip(out + 0.5, 0, 255).astype(np.uint8)

    depth = None
    if with_depth:
        n_hand = R[:, 2]
        zmap = _plane_depth(cam, np.array([0.0, -0.45, -0.9]), np.array([0.0, 0.0, 0.85]))
        zmap = np.where(hand, _plane_depth(cam, n_hand, t), zmap)
        zmap = zmap + rng.normal(0, 1, zmap.shape) * depth_sigma(zmap)
        raw = np.round(zmap / cam.depth_scale)
        raw[rng.random(raw.shape) < depth_dropout] = 0
        # Kinect-like holes: a shadow band along the hand's left edge, a few blobs on the table
        shadow = np.zeros_like(hand)
        for shift in range(1, 5):
            shadow |= np.roll(hand, -shift, axis=1)
        raw[shadow & ~hand] = 0
        for _ in range(4):
            cu, cv_ = rng.uniform(0, W), rng.uniform(0, H)
            hole = np.zeros((H, W), np.uint8)
            cv2.circle(hole, (int(cu), int(cv_)), int(rng.uniform(5, 15)), 1, -1)
            raw[(hole > 0) & ~hand] = 0
        if hole_over_marker is not None:
            c = uv[hole_over_marker]
            cv2.circle(raw, (int(round(c[0])), int(round(c[1]))), 14, 0, -1)
        depth = raw.astype(np.uint16)

    return SynthScene(bgr, depth, uv, zt, clutter_uv, edge_uv, hand, cam)


def time_detection(n_frames: int = 200, seed: int = 0, config=None) -> float:
    """Median wall time (ms) of ``MarkerDetector.detect`` per 640x480 RGB-D frame on one core
    (OpenCV's own threads limited to 1 while timing), over ``n_frames`` synthetic frames with
    six markers, clutter and depth holes: 8 poses along a path (the hand moving 20 px and turning
    5 degrees between poses, a fast movement at 30 fps), played back and forth. ``config``: a
    DetectorConfig (default settings if None)."""
    rng = np.random.default_rng(seed)
    n_poses = max(1, min(8, n_frames))
    scenes = [
        synth_scene(rng, centre=(230.0 + 20 * k, 280.0 - 8 * k), yaw_deg=-30.0 + 5 * k,
                    tilt_deg=10.0 + 4 * k)
        for k in range(n_poses)
    ]
    order = list(range(n_poses)) + list(range(n_poses - 2, 0, -1))
    detector = MarkerDetector(scenes[0].camera, config)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        for k in order:  # warm-up, and the skin model adapts on these
            detector.detect(scenes[k].bgr, scenes[k].depth, 0.0)
        times = []
        for i in range(n_frames):
            s = scenes[order[i % len(order)]]
            start = time.perf_counter()
            detector.detect(s.bgr, s.depth, i / 30)
            times.append(time.perf_counter() - start)
    finally:
        cv2.setNumThreads(threads)
    return 1e3 * statistics.median(times)
