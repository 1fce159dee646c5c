"""The depth camera: the z-buffer of a rendered frame turned into a registered 16-bit depth image.

Two models. The plain scenarios' Kinect-like depth (noise sigma = 1.425e-3 z^2 m correlated over
a few pixels, whole millimetres, no reading at depth edges, in the projector's shadow and in
random speckles) is kept exactly as it was, so older figures stay comparable. The
``structured_light`` effect is a Kinect v1 / Xtion as measured (see
:mod:`wristtrack.sim.realism`): Nguyen et al.'s axial noise correlated over the 9x9 matching
window and their lateral jitter at depth edges, both growing where the surface is seen
obliquely; the nearer surface's depth spread 1-2 px over the farther one at a depth edge
(foreground fattening: the real frames jump straight from one surface to the other, without the
plain model's band of holes); disparity quantised to 1/8 px, the registered map's invalid
border, and a 1-2 px misregistration with the colour image.
"""

from __future__ import annotations

import cv2
import numpy as np

from wristtrack.depth_noise import (
    MATCH_WINDOW_PX,
    depth_sigma,
    depth_sigma_nguyen,
    lateral_sigma_nguyen,
    neighbour_jumps,
    oblique_sigma,
)
from wristtrack.sim import realism
from wristtrack.sim.scenes import Scene

NOISE_PAD = 64
_PROJECTOR_BASELINE = 0.075  # m, structured-light projector to IR camera
_PLAIN_CORRELATION_PX = 3.0  # Gaussian correlation length of the plain model's depth noise


class DepthSensor:
    """Depth images of one recording; the static background's part is prepared once."""

    def __init__(self, scene: Scene, bg_z: np.ndarray, bank: np.ndarray,
                 rng: np.random.Generator, fx_rng: np.random.Generator):
        self.cam = scene.camera
        self.rng, self.fx_rng = rng, fx_rng
        self.structured = "structured_light" in scene.effects
        # A structured-light sensor matches windows of several pixels, so its depth noise is
        # correlated over a few pixels: averaging a blob's pixels cannot beat it down as iid
        # noise would (Khoshelham & Elberink 2012). Blur the bank, then restore unit variance.
        for b in range(2):
            smooth = cv2.GaussianBlur(bank[b], (0, 0), _PLAIN_CORRELATION_PX)
            bank[b] = smooth / smooth.std()
        self.bank = bank
        # Depth: the background's clean raw depth, noise level and valid pixels, computed once.
        self.bg_z = bg_z
        z = bg_z.astype(np.float32)
        finite = np.isfinite(z)
        scale = np.float32(self.cam.depth_scale)
        self.bg_raw = np.where(finite, z / scale, 0.0).astype(np.float32)
        self.bg_dsigma = np.where(finite, depth_sigma(z) / scale, 0.0).astype(np.float32)
        H, W = z.shape
        self.bg_keep, self.bg_proj_max = self._valid(z, 0, 0, np.full(H, -np.inf, np.float32))
        self._buf = np.empty_like(z)
        if self.structured:
            self._prepare_structured(H, W)

    def capture(self, z_roi: np.ndarray, region) -> np.ndarray:
        """Raw depth (uint16, camera.depth_scale units) of a frame whose clean depth is the
        background's with ``z_roi`` (the re-rendered region's z-buffer) put in."""
        if self.structured:
            return self._structured(z_roi, region)
        return self._plain(z_roi, region)

    # ------------------------------------------------------------------ plain (Kinect-like)

    def _valid(
        self, z: np.ndarray, x0: int, y0: int, seen_left: np.ndarray, edge_holes: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (uint16 1/0) of a clean depth patch (its corner at image pixel x0, y0) that
        get a reading, and the running maximum of projector columns along each row.

        No reading where the projector (baseline to the left) cannot light the point, outside
        0.4..4.5 m, and, with ``edge_holes``, where the surface jumps (mixed pixels, with ragged
        random edges). ``seen_left`` is the running maximum just left of the patch (-inf at the
        image edge).
        """
        with np.errstate(invalid="ignore"):
            zc = np.where(np.isfinite(z), z, 1e3).astype(np.float32)
            h, w = z.shape
            holes = np.zeros((h, w), bool)
            # drawn either way: the recording's other noise stays as it was
            oy, ox = (int(v) for v in self.rng.integers(NOISE_PAD, size=2))
            if edge_holes:
                edge = _depth_edges(zc)
                ragged = cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
                coin = self.bank[1, y0 + oy:y0 + oy + h, x0 + ox:x0 + ox + w] > 0.25
                holes = edge | (ragged & coin)
            cols = np.arange(x0, x0 + w, dtype=np.float32)
            proj = cols + np.float32(self.cam.fx * _PROJECTOR_BASELINE) / zc
            seen = np.maximum.accumulate(np.column_stack([seen_left, proj]), axis=1)
            holes |= seen[:, :-1] > proj + 0.5
            holes |= (zc < 0.4) | (zc > 4.5)
        return (~holes).astype(np.uint16), seen[:, 1:]

    def _speckles(self, keep: np.ndarray) -> None:
        """Random dropouts: 2x2 speckles on 0.2 % of the image (in place)."""
        H, W = keep.shape
        n = int(self.rng.poisson(0.002 * H * W / 4))
        ys = self.rng.integers(0, H - 1, n)
        xs = self.rng.integers(0, W - 1, n)
        for dy in (0, 1):
            for dx in (0, 1):
                keep[ys + dy, xs + dx] = 0

    def _plain(self, z_roi: np.ndarray, region) -> np.ndarray:
        cam = self.cam
        H, W = cam.height, cam.width
        x0, y0, x1, y1 = region
        k = int(self.rng.integers(2))
        oy, ox = (int(x) for x in self.rng.integers(NOISE_PAD, size=2))
        noise = self.bank[k, oy:oy + H, ox:ox + W]
        raw = np.multiply(self.bg_dsigma, noise, out=self._buf)
        raw += self.bg_raw
        z = z_roi.astype(np.float32)
        finite = np.isfinite(z)
        z = np.where(finite, z, 0.0).astype(np.float32)
        scale = np.float32(cam.depth_scale)
        raw[y0:y1, x0:x1] = z / scale + depth_sigma(z) / scale * noise[y0:y1, x0:x1]
        raw += 0.5  # round on truncation (all values >= 0)
        np.maximum(raw, 0.0, out=raw)
        np.minimum(raw, 65535.0, out=raw)
        out = raw.astype(np.uint16)
        keep = self.bg_keep.copy()
        seen_left = self.bg_proj_max[y0:y1, x0 - 1] if x0 > 0 else np.full(y1 - y0, -np.inf)
        keep_roi, _ = self._valid(np.where(finite, z_roi, np.inf), x0, y0, seen_left)
        keep[y0:y1, x0:x1] = keep_roi
        self._speckles(keep)
        out *= keep
        return out

    # ------------------------------------------------------------------- structured light

    def _prepare_structured(self, H: int, W: int) -> None:
        r = self.fx_rng
        self.fatten_rng = np.random.default_rng(r.bit_generator.seed_seq.spawn(1)[0])
        pad = (H + NOISE_PAD, W + NOISE_PAD)
        win = MATCH_WINDOW_PX
        # Correlated over the matching window: white noise averaged over 9x9, unit variance.
        white = r.standard_normal((3, *pad), dtype=np.float32)
        self.sl_bank = np.stack([cv2.blur(b, (win, win)) for b in white])
        self.sl_bank /= self.sl_bank.std(axis=(1, 2), keepdims=True)
        self.grid_x, self.grid_y = np.meshgrid(np.arange(W, dtype=np.float32),
                                               np.arange(H, dtype=np.float32))
        # each pixel's line of sight (z = 1), for the angle the surface is seen at
        xy = self.cam.normalize(np.stack((self.grid_x, self.grid_y), axis=-1))
        self.sl_rays = np.concatenate((xy, np.ones((H, W, 1))), axis=-1).astype(np.float32)
        self.sl_bg_cos = _incidence_cos(np.where(np.isfinite(self.bg_z), self.bg_z, 0.0),
                                        self.sl_rays)
        # The registered map's border, as measured on real OpenNI frames (see realism).
        border = np.zeros((H, W), bool)
        border[:realism.BORDER_TOP] = True
        border[H - realism.BORDER_BOTTOM:] = True
        border[:, W - realism.BORDER_RIGHT:] = True
        ramp = 0.9 * np.clip(1.0 - np.arange(W) / realism.BORDER_LEFT_RAMP, 0.0, 1.0)
        self.sl_border = border
        self.sl_left_ramp = ramp.astype(np.float32)
        # Misregistration: 1-2 px horizontally, 0-1 px vertically, a fixed calibration error.
        self.sl_shift = (int(r.choice([-2, -1, 1, 2])), int(r.choice([-1, 0, 1])))

    def _structured(self, z_roi: np.ndarray, region) -> np.ndarray:
        cam, r = self.cam, self.fx_rng
        H, W = cam.height, cam.width
        x0, y0, x1, y1 = region
        z = self.bg_z.astype(np.float32)
        z[y0:y1, x0:x1] = z_roi
        z = np.where(np.isfinite(z), z, 0.0).astype(np.float32)

        def bank(i: int) -> np.ndarray:
            oy, ox = (int(v) for v in r.integers(NOISE_PAD, size=2))
            return self.sl_bank[i, oy:oy + H, ox:ox + W]

        # its own generator, so the depth noise drawn after it stays as it was
        oy, ox = (int(v) for v in self.fatten_rng.integers(NOISE_PAD, size=2))
        z = _fatten(z, self.sl_bank[0, oy:oy + H, ox:ox + W] > 0.0)

        # The angle each pixel's surface is seen at (the clean depth's), in the re-rendered
        # region and a pixel around it; the static background's is computed once.
        cos = self.sl_bg_cos.copy()
        a0, b0, a1, b1 = max(x0 - 1, 0), max(y0 - 1, 0), min(x1 + 1, W), min(y1 + 1, H)
        if a1 - a0 > 1 and b1 - b0 > 1:
            cos[b0:b1, a0:a1] = _incidence_cos(z[b0:b1, a0:a1], self.sl_rays[b0:b1, a0:a1])
        # Depth edges wander: lateral jitter of where the windows near an edge take their depth
        # from. (Not elsewhere: on a slope it would read as axial noise, which Nguyen et al.'s
        # axial sigma, measured on sloped planes, already is.)
        s = lateral_sigma_nguyen(cos).astype(np.float32)
        jittered = cv2.remap(z, self.grid_x + s * bank(0), self.grid_y + s * bank(1),
                             cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        z = np.where(_near_edges(z), jittered, z)
        valid = z > 0
        zn = z + (depth_sigma_nguyen(z) + oblique_sigma(z, cos)).astype(np.float32) * bank(2)
        # Disparity quantised to 1/8 px: depth takes only the values fb / (n / 8).
        with np.errstate(divide="ignore"):
            d = realism.FOCAL_BASELINE / zn
            dq = np.round(d / realism.DISPARITY_STEP_PX) * realism.DISPARITY_STEP_PX
            zq = realism.FOCAL_BASELINE / dq
        valid &= np.isfinite(zq) & (dq > 0)
        zin = np.where(valid, z, np.inf)
        keep, _ = self._valid(zin, 0, 0, np.full(H, -np.inf, np.float32), edge_holes=False)
        keep[self.sl_border] = 0
        keep[r.random((H, W), dtype=np.float32) < self.sl_left_ramp] = 0
        self._speckles(keep)
        raw = np.where(valid, zq / cam.depth_scale + 0.5, 0.0)
        out = np.clip(raw, 0, 65535).astype(np.uint16) * keep
        dx, dy = self.sl_shift
        return np.roll(out, (dy, dx), axis=(0, 1)) * _inside(H, W, dx, dy)


def _fatten(z: np.ndarray, wide: np.ndarray) -> np.ndarray:
    """The clean depth ``z`` (m, float32, 0: no surface) with each depth edge's nearer surface
    spread over the farther one by FATTEN_PX px (``wide``, (H, W) bool) or one px less.

    A structured-light camera matches a window of the projected pattern: where the window
    straddles an edge, the nearer surface's pattern wins and the whole window takes its depth.
    On the real OpenNI frames the depth jumps straight from one surface to the other at
    90-95 % of the edges, and the nearer surface reaches 1.0-1.9 px (mean 1.5) past its
    outline in the colour image (realism.FATTEN_PX; tests/sim/test_realism.py measures both)."""
    none = np.float32(1e4)  # no surface: farther than any (OpenCV's erosion saturates inf)
    far = np.where(z > 0, z, none).astype(np.float32)
    narrow_k = np.ones((2 * realism.FATTEN_PX - 1,) * 2, np.uint8)
    wide_k = np.ones((2 * realism.FATTEN_PX + 1,) * 2, np.uint8)
    nearest = np.where(wide, cv2.erode(far, wide_k), cv2.erode(far, narrow_k))
    # Only beside a jump between neighbouring pixels: a steep but continuous surface (a plane
    # turned 78 deg drops 12 mm over two pixels at 0.7 m, 6 mm from one to the next) keeps its
    # depth.
    jumps = neighbour_jumps(z, realism.EDGE_JUMP_M, jump_to_zero=True)
    beside = cv2.dilate(jumps.astype(np.uint8), wide_k) > 0
    spread = beside & (nearest < far - realism.EDGE_JUMP_M)
    return np.where(spread, nearest, z).astype(np.float32)


def _near_edges(z: np.ndarray, reach_px: int = 3) -> np.ndarray:
    """(H, W) bool: within ``reach_px`` of a depth edge (``depth_noise.neighbour_jumps``) of
    the clean depth ``z`` (0: no surface)."""
    edge = neighbour_jumps(z, realism.EDGE_JUMP_M, jump_to_zero=True)
    return cv2.dilate(edge.astype(np.uint8), np.ones((2 * reach_px + 1,) * 2, np.uint8)) > 0


def _depth_edges(z: np.ndarray) -> np.ndarray:
    """(H, W) bool: where the depth ``z`` (m, float32) jumps by more than EDGE_JUMP_M within a
    pixel's 3x3 neighbourhood."""
    kernel = np.ones((3, 3), np.uint8)
    return (cv2.dilate(z, kernel) - cv2.erode(z, kernel)) > realism.EDGE_JUMP_M


def _incidence_cos(z: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(H, W) cosine between the surface's normal and the line of sight at each pixel of the
    depth map ``z`` (H, W), m (0: no surface), ``rays`` (H, W, 3) the lines of sight (z = 1):
    the normal from the back-projected points' differences to the neighbouring pixels. Across a
    depth edge it is near 0, the steepest angle (such pixels mostly read nothing anyway)."""
    X = z[..., None] * rays
    n = np.cross(np.gradient(X, axis=1), np.gradient(X, axis=0))
    dot = np.abs(np.einsum("ijk,ijk->ij", n, X))
    norm = np.linalg.norm(n, axis=-1) * np.linalg.norm(X, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.where(norm > 0, dot / norm, 1.0)
    return cos.astype(np.float32)


def _inside(H: int, W: int, dx: int, dy: int) -> np.ndarray:
    """uint16 mask of the pixels a (dx, dy) shift brings in from inside the image."""
    m = np.zeros((H, W), np.uint16)
    m[max(dy, 0):H + min(dy, 0), max(dx, 0):W + min(dx, 0)] = 1
    return m
