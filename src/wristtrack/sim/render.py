"""Realistic synthetic RGB-D recordings with ground truth (``wristtrack simulate``).

Each frame is ray-cast from 3-D geometry with the recording's Camera (so projection,
foreshortening and lens distortion are the tracker's own): a textured table, a skin-coloured
forearm (a tapered round cone), a palm (a convex slab around the marker layout, in the hand
frame) with fingers and thumb (chains of round cones), and the six 12 mm blue markers, flat on
the back of the palm, filled as their projected rim polygons at 8x supersampling (exact
sub-pixel coverage). Every surface is analytic, so the z-buffer gives the depth image too.

Realism added on top: Lambert shading with a little gloss, the hand's soft shadow on the table,
vignetting, a slight lens blur, motion blur (the frame is the mean of sub-frame renders over
the exposure, as many as the marker motion needs), slow brightness and white-balance drift,
shot and read noise; and a Kinect-like depth image: noise sigma = 1.425e-3 z^2 m, millimetre
quantisation, no reading at depth edges, in the projector's shadow and in random speckles.

Speed: only the region around the moving parts is re-rendered each frame (the table and clutter
are drawn once); noise comes from a bank drawn once, taken at random offsets per frame.
"""

from __future__ import annotations

import csv
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.folder import RecordingWriter
from wristtrack.io.poses import write_truth
from wristtrack.sim.motion import min_jerk
from wristtrack.sim.scenes import RENDER_SCENARIOS, Occlusion, Scene, make_scene

__all__ = ["RENDER_SCENARIOS", "RenderedFrame", "render_frames", "render_recording"]

MARKER_RADIUS = 0.006  # 12 mm discs
DEPTH_SIGMA_COEFF = 1.425e-3  # Kinect-like depth noise: sigma = coeff * z^2 (m)
DEPTH_NOISE_CORRELATION_PX = 3.0  # Gaussian correlation length of the depth noise (pixels)
TABLE_GAP = 0.13  # table this far below the back of the neutral hand (m): room for flexion

# Surface ids in the id buffer. Markers are visible only where the back of the palm is in front.
TABLE, CLUTTER, ARM, DORSUM, HAND, OCCLUDER = range(6)

# Albedos, BGR, 0..255 at full light.
SKIN = np.array([118.0, 148.0, 204.0])
PALM_SIDE = np.array([138.0, 166.0, 218.0])
ARM_SKIN = np.array([112.0, 142.0, 198.0])
MARKER_BLUE = np.array([196.0, 84.0, 22.0])
PEN = np.array([46.0, 44.0, 50.0])

# Light direction towards the light, camera frame: above, up-left of the camera.
_LIGHT = np.array([-0.25, -0.35, -1.0]) / np.linalg.norm([-0.25, -0.35, -1.0])
_HALF = (_LIGHT + np.array([0.0, 0.0, -1.0])) / np.linalg.norm(_LIGHT + [0.0, 0.0, -1.0])
_AMBIENT, _DIFFUSE = 0.38, 0.62
_SHADOW_DARKNESS = 0.35
_PROJECTOR_BASELINE = 0.075  # m, structured-light projector to IR camera
_SUPERSAMPLE = 8  # marker coverage resolution per pixel side
_NOISE_PAD = 64


@dataclass(frozen=True)
class RenderedFrame:
    """One rendered frame and its marker truth at ``timestamp``.

    ``uv`` (6,2) is the centroid of each marker's projected rim polygon (what an ideal blob
    detector finds; not exactly the projection of the marker centre), ``visible`` (6,) the
    fraction of the marker's area that can be seen (0 when it faces away or is covered).
    """

    timestamp: float
    bgr: np.ndarray
    depth: np.ndarray | None
    uv: np.ndarray
    visible: np.ndarray


# ------------------------------------------------------------------------------- primitives


@dataclass(frozen=True)
class _Cones:
    """Round cones, camera frame: spheres (a, ra) and (b, rb) joined by their tangent cone.

    A set of N, hit-tested together: fingers, forearm, pens are all round cones.
    """

    a: np.ndarray  # (N,3)
    b: np.ndarray  # (N,3)
    ra: np.ndarray  # (N,)
    rb: np.ndarray  # (N,)
    albedo: np.ndarray  # (N,3)
    part: np.ndarray  # (N,) uint8

    @staticmethod
    def concat(sets: list[_Cones]) -> _Cones:
        return _Cones(*(np.concatenate([getattr(c, f) for c in sets]) for f in _CONE_FIELDS))


_CONE_FIELDS = ("a", "b", "ra", "rb", "albedo", "part")
_CIRCLE16 = np.column_stack(
    [np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
     np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))]
) / np.cos(np.pi / 16)  # a 16-gon around the unit circle


def _cone(a, b, ra, rb, albedo, part) -> _Cones:
    return _Cones(np.atleast_2d(a), np.atleast_2d(b), np.array([ra]), np.array([rb]),
                  np.atleast_2d(albedo), np.array([part], dtype=np.uint8))


def _cone_constants(c: _Cones) -> dict[str, np.ndarray]:
    """Per-cone constants of the ray tests (each (N,)): spheres, axis w, frustum profile.

    Along the axis w (s measured from a) the tangent cone's radius is
    r(s) = (ra - s sin_a) / cos_a with sin_a = (ra - rb) / L, between the tangent circles
    s in [ra sin_a, L + rb sin_a].
    """
    axis = c.b - c.a
    length = np.linalg.norm(axis, axis=1)
    w = axis / np.maximum(length, 1e-12)[:, None]
    sin_a = np.clip((c.ra - c.rb) / np.maximum(length, 1e-12), -0.99, 0.99)
    cos_a = np.sqrt(1.0 - sin_a**2)
    s0 = -np.einsum("ij,ij->i", c.a, w)
    c0 = (c.ra - s0 * sin_a) / cos_a
    aa = np.einsum("ij,ij->i", c.a, c.a)
    return {
        "ax": c.a[:, 0], "ay": c.a[:, 1], "az": c.a[:, 2], "ka": aa - c.ra**2,
        "bx": c.b[:, 0], "by": c.b[:, 1], "bz": c.b[:, 2],
        "kb": np.einsum("ij,ij->i", c.b, c.b) - c.rb**2,
        "wx": w[:, 0], "wy": w[:, 1], "wz": w[:, 2], "s0": s0,
        "m": c0 * sin_a / cos_a - s0,  # qb / 2 = -(D.a) + sd * m
        "qc": aa - s0 * s0 - c0 * c0, "inv_cos2": 1.0 / cos_a**2, "c0": c0,
        "k": sin_a / cos_a, "s_lo": c.ra * sin_a, "s_hi": length + c.rb * sin_a,
        "cone": (length > 1e-9).astype(float), "ra": c.ra, "rb": c.rb,
        "sin": sin_a, "cos": cos_a,
    }


def _cone_hits(x: np.ndarray, y: np.ndarray, which: np.ndarray, k: dict) -> tuple[np.ndarray, ...]:
    """First hit depth (inf if none) and surface (0: sphere a, 1: sphere b, 2: cone) of the
    rays (x, y, 1) with the round cones ``which`` (per ray), from :func:`_cone_constants`."""
    g = {name: v[which] for name, v in k.items()}
    dd = x * x + y * y + 1.0
    t = np.full(len(x), np.inf)
    surf = np.zeros(len(x), np.uint8)
    for code, (cx, cy, cz, kk) in enumerate((("ax", "ay", "az", "ka"), ("bx", "by", "bz", "kb"))):
        b = x * g[cx] + y * g[cy] + g[cz]
        disc = b * b - dd * g[kk]
        ts = (b - np.sqrt(np.maximum(disc, 0.0))) / dd
        closer = (disc >= 0) & (ts > 0) & (ts < t)
        t = np.where(closer, ts, t)
        surf[closer] = code
    sd = x * g["wx"] + y * g["wy"] + g["wz"]
    da = x * g["ax"] + y * g["ay"] + g["az"]
    qa = dd - sd * sd * g["inv_cos2"]
    half_b = sd * g["m"] - da
    disc = half_b * half_b - qa * g["qc"]
    ok = (disc >= 0) & (np.abs(qa) > 1e-12) & (g["cone"] > 0)
    root = np.sqrt(np.where(ok, disc, 0.0))
    qa = np.where(ok, qa, 1.0)
    for sign in (-1.0, 1.0):
        tr = (-half_b + sign * root) / qa
        s = g["s0"] + tr * sd
        valid = ok & (tr > 0) & (tr < t) & (s >= g["s_lo"]) & (s <= g["s_hi"])
        valid &= g["c0"] - g["k"] * sd * tr > 0  # not the mirrored nappe
        t = np.where(valid, tr, t)
        surf[valid] = 2
    return t, surf


def _cone_normals(P: np.ndarray, which: np.ndarray, surf: np.ndarray, k: dict) -> np.ndarray:
    """Unit outward normals at hit points P (n,3) on surface ``surf`` of cones ``which``."""
    n = np.empty_like(P)
    on_a, on_b = surf == 0, surf == 1
    for comp, (ca, cb) in enumerate((("ax", "bx"), ("ay", "by"), ("az", "bz"))):
        n[:, comp] = P[:, comp] - np.where(on_a, k[ca][which], k[cb][which])
    r = np.where(on_a, k["ra"][which], k["rb"][which])
    n /= r[:, None]
    on_cone = ~(on_a | on_b)
    if on_cone.any():
        wi = which[on_cone]
        w = np.column_stack([k["wx"][wi], k["wy"][wi], k["wz"][wi]])
        q = P[on_cone] - np.column_stack([k["ax"][wi], k["ay"][wi], k["az"][wi]])
        radial = q - np.einsum("ij,ij->i", q, w)[:, None] * w
        radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
        n[on_cone] = k["cos"][wi, None] * radial + k["sin"][wi, None] * w
    return n


@dataclass(frozen=True)
class _Solid:
    """Convex polyhedron {p : normals @ p <= offsets}, camera frame; albedo and part per face."""

    normals: np.ndarray  # (P,3) outward
    offsets: np.ndarray  # (P,)
    vertices: np.ndarray  # (V,3) for the bounding box
    albedo: np.ndarray  # (P,3)
    part: np.ndarray  # (P,) uint8

    def hit(self, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hit z (inf if none) and face index of rays D (n,3) (Kay-Kajiya slabs)."""
        denom = D @ self.normals.T  # (n,P)
        with np.errstate(divide="ignore", invalid="ignore"):
            tp = self.offsets / denom
        t_in = np.where(denom < 0, tp, -np.inf)
        face = np.argmax(t_in, axis=1)
        t_enter = np.take_along_axis(t_in, face[:, None], 1)[:, 0]
        t_exit = np.where(denom > 0, tp, np.inf).min(axis=1)
        parallel_out = ((denom == 0) & (self.offsets < 0)).any(axis=1)
        hit = (t_enter <= t_exit) & (t_enter > 0) & ~parallel_out
        return np.where(hit, t_enter, np.inf), face


def _prism(
    polygon: np.ndarray, z_top: float, z_bottom: float, bevel: float = 0.0
) -> tuple[np.ndarray, ...]:
    """Planes (normals, offsets) and vertices of a vertical prism over a convex polygon (K,2)
    (counter-clockwise), local frame. Face 0 is the top (+z), face 1 the bottom, then the K
    sides; ``bevel`` > 0 adds K 45-degree faces cutting the top edges ``bevel`` metres in."""
    poly = np.asarray(polygon, dtype=float)
    edges = np.roll(poly, -1, axis=0) - poly
    out = np.column_stack([edges[:, 1], -edges[:, 0], np.zeros(len(poly))])  # CCW: outward
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    normals = [[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], out]
    offsets = [[z_top, -z_bottom], np.einsum("ij,ij->i", out[:, :2], poly)]
    if bevel > 0:
        nb = (out + [0.0, 0.0, 1.0]) / np.sqrt(2.0)
        inset = np.column_stack([poly - bevel * out[:, :2], np.full(len(poly), z_top)])
        normals.append(nb)
        offsets.append(np.einsum("ij,ij->i", nb, inset))
    verts = np.vstack(
        [np.column_stack([poly, np.full(len(poly), z)]) for z in (z_top, z_bottom)]
    )
    return np.vstack(normals), np.concatenate(offsets), verts


def _box(size: tuple[float, float, float]) -> tuple[np.ndarray, ...]:
    hx, hy, hz = (0.5 * s for s in size)
    square = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return _prism(square, hz, -hz)


def _place_solid(planes, R, t, albedo, part) -> _Solid:
    """A local prism (normals, offsets, vertices) moved by p -> R p + t."""
    normals, offsets, verts = planes
    n = normals @ R.T
    P = len(normals)
    albedo = np.broadcast_to(np.asarray(albedo, dtype=float), (P, 3)).copy()
    part = np.broadcast_to(np.asarray(part, dtype=np.uint8), (P,)).copy()
    return _Solid(n, offsets + n @ t, verts @ R.T + t, albedo, part)


# ------------------------------------------------------------------------------- hand model


@dataclass(frozen=True)
class _HandModel:
    """Hand geometry in the hand frame, forearm in W0 axes (it moves with the wrist only)."""

    palm: tuple[np.ndarray, np.ndarray, np.ndarray]  # prism planes and vertices
    palm_albedo: np.ndarray  # (P,3)
    palm_part: np.ndarray  # (P,)
    cones: np.ndarray  # (N,8): ax ay az bx by bz ra rb, hand frame
    forearm: np.ndarray  # (8,) the same, W0 axes, relative to the wrist
    rim: np.ndarray  # (6,M,3) marker rim points, hand frame


def _hand_model(layout: HandLayout) -> _HandModel:
    p = layout.points
    # Palm: convex hull of 13 mm discs around the markers (every marker lies on its flat top,
    # clear of the 4 mm bevel) plus the width of the wrist; 3 cm thick under the back (z = 0).
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = 0.013 * np.column_stack([np.cos(ang), np.sin(ang)])
    pts = np.vstack([(p[:, None, :2] + ring).reshape(-1, 2), [[-0.024, 0.027], [-0.024, -0.027]]])
    hull = cv2.convexHull(pts.astype(np.float32))[:, 0].astype(float)
    hull = cv2.approxPolyDP(hull.astype(np.float32), 0.001, True)[:, 0].astype(float)
    if _signed_area(hull) < 0:
        hull = hull[::-1]
    palm = _prism(hull, 0.0, -0.03, bevel=0.004)
    n_faces = len(palm[0])
    albedo = np.tile(SKIN, (n_faces, 1))
    albedo[1] = PALM_SIDE
    part = np.full(n_faces, HAND, dtype=np.uint8)
    part[0] = DORSUM

    cones: list[np.ndarray] = []
    # Fingers from the MCP knuckles: three phalanges, slightly curled towards the palm.
    for k, s in zip(range(2, 6), (0.95, 1.0, 0.97, 0.8), strict=True):
        d = 0.55 * p[k, :2] / np.linalg.norm(p[k, :2]) + [0.45, 0.0]
        start = np.array([p[k, 0], p[k, 1], -0.0105])
        cones += _chain(start, d / np.linalg.norm(d), [0.044 * s, 0.027 * s, 0.021 * s],
                        [12, 20, 12], [0.0095, 0.0088, 0.0078, 0.0066])
    # Thumb from CMC1 (metacarpal, proximal, distal), turned towards the fingers, lower.
    c = p[1, :2]
    turn = np.deg2rad(-25.0) * (np.sign(c[1]) or 1.0)  # towards +X for either hand
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    cones += _chain(np.array([c[0], c[1], -0.016]), rot @ c / np.linalg.norm(c),
                    [0.036, 0.030, 0.024], [18, 10, 15], [0.0125, 0.0105, 0.0095, 0.0082])
    # Forearm: tapered, sloping down towards the elbow; its top stays below the WRIST marker.
    a = np.array([-0.012, 0.0, -0.032])
    elbow = a + 0.45 * np.array([-np.cos(np.deg2rad(12)), 0.0, -np.sin(np.deg2rad(12))])
    forearm = np.concatenate([a, elbow, [0.026, 0.040]])

    phi = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    circle = MARKER_RADIUS * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    return _HandModel(palm, albedo, part, np.array(cones), forearm, p[:, None, :] + circle)


def _chain(start, direction2d, lengths, curl_deg, radii) -> list[np.ndarray]:
    """Round cones of a finger: segments of ``lengths`` bending down by ``curl_deg`` each."""
    out, pos, pitch = [], np.asarray(start, dtype=float), 0.0
    for i, (length, curl) in enumerate(zip(lengths, curl_deg, strict=True)):
        pitch += np.deg2rad(curl)
        step = length * np.array(
            [np.cos(pitch) * direction2d[0], np.cos(pitch) * direction2d[1], -np.sin(pitch)]
        )
        out.append(np.concatenate([pos, pos + step, [radii[i], radii[i + 1]]]))
        pos = pos + step
    return out


def _signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid of a simple polygon (K,2) (shoelace)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return poly.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


# --------------------------------------------------------------------------------- renderer


@dataclass(frozen=True)
class _Layer:
    """Geometry of one instant: convex solids, round cones, and the hand pose."""

    solids: list[_Solid]
    cones: _Cones
    R: np.ndarray
    t: np.ndarray


class _Renderer:
    """Draws the frames of one Scene; the static background is drawn once at construction."""

    def __init__(self, scene: Scene, seed: int):
        self.scene = scene
        self.cam = cam = scene.camera
        self.rng = np.random.default_rng([seed, 2])
        self.model = _hand_model(scene.layout)
        H, W = cam.height, cam.width
        u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        xy = cam.normalize(np.stack([u, v], -1))
        rays = np.concatenate([xy, np.ones((H, W, 1))], -1)  # z = 1: the ray parameter is depth
        # Pixels outside a distortion model's valid field get rays far off to the side (they
        # hit nothing) and stay black with no depth.
        self.ray_ok = np.isfinite(xy).all(axis=-1).reshape(-1)
        self.rays = np.nan_to_num(rays, nan=1e3).reshape(-1, 3)
        self.rx, self.ry = self.rays[:, 0].copy(), self.rays[:, 1].copy()
        # Outline margin (px) around projected primitives; lens distortion bends straight edges.
        self._margin = 1.5 + (6 if cam.has_distortion else 0)
        self.t0 = float(scene.times[0]) if len(scene.times) else 0.0
        # Table plane: normal towards the camera (W0 +Z), TABLE_GAP below the back of the hand.
        self.table_n = scene.R_c0[:, 2]
        self.table_p = scene.t_c0 - TABLE_GAP * self.table_n
        r2 = ((u - cam.cx) / cam.fx) ** 2 + ((v - cam.cy) / cam.fy) ** 2
        vignette = (1.0 - 0.22 * r2 / r2.max()).astype(np.float32)
        self.vignette = cv2.merge((vignette, vignette, vignette))
        self._draw_background()
        pad = (H + _NOISE_PAD, W + _NOISE_PAD)
        self.noise_bank = self.rng.standard_normal((2, *pad, 3), dtype=np.float32)
        self.depth_bank = self.rng.standard_normal((2, *pad), dtype=np.float32)
        # A structured-light sensor matches windows of several pixels, so its depth noise is
        # correlated over a few pixels: averaging a blob's pixels cannot beat it down as iid
        # noise would (Khoshelham & Elberink 2012). Blur the bank, then restore unit variance.
        for b in range(2):
            smooth = cv2.GaussianBlur(self.depth_bank[b], (0, 0), DEPTH_NOISE_CORRELATION_PX)
            self.depth_bank[b] = smooth / smooth.std()
        self.phases = self.rng.uniform(0, 2 * np.pi, 5)
        self._static_sensor()

    # ---------------------------------------------------------------------- background

    def _draw_background(self) -> None:
        cam, scene = self.cam, self.scene
        H, W = cam.height, cam.width
        with np.errstate(divide="ignore"):
            z = (self.table_n @ self.table_p) / (self.rays @ self.table_n)
        z = np.where(z > 0, z, np.inf)
        hit_w0 = (z[:, None] * self.rays - scene.t_c0) @ scene.R_c0  # table points in W0
        albedo = self._table_texture(hit_w0[:, 0].reshape(H, W), hit_w0[:, 1].reshape(H, W))
        shade = _AMBIENT + _DIFFUSE * max(float(self.table_n @ _LIGHT), 0.0)
        albedo[~self.ray_ok.reshape(H, W)] = 0.0
        z[~self.ray_ok] = np.inf
        self.bg_colour = (albedo * shade).astype(np.float32)  # before vignetting
        self.bg_z = z.reshape(H, W)
        self.bg_id = np.full((H, W), TABLE, dtype=np.uint8)
        if scene.clutter:
            solids, cones = self._clutter()
            self._draw((0, 0, W, H), _Layer(solids, cones, np.eye(3), np.zeros(3)),
                       self.bg_colour, self.bg_z, self.bg_id)
        self.bg_blurred = cv2.GaussianBlur(self.bg_colour * self.vignette, (0, 0), 0.6)

    @staticmethod
    def _table_texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Albedo (H,W,3) of a light wood-grain laminate at W0 table coordinates (H,W) (m)."""
        rng = np.random.default_rng(11)
        res, half = 0.002, 0.8
        n = int(2 * half / res)
        low = cv2.resize(rng.standard_normal((12, 12)).astype(np.float32), (n, n),
                         interpolation=cv2.INTER_CUBIC)
        fine = cv2.GaussianBlur(rng.standard_normal((n, n)).astype(np.float32), (0, 0), 1.2)
        gy = np.linspace(-half, half, n, dtype=np.float32)[:, None]
        grain = np.sin(2 * np.pi * (gy / 0.011 + 0.9 * low)) + 0.5 * np.sin(
            2 * np.pi * (gy / 0.0043 + 1.7 * low)
        )
        lum = 1.0 + 0.035 * grain + 0.05 * low + 0.035 * fine
        tex = lum[..., None] * np.array([150.0, 170.0, 188.0], dtype=np.float32)
        mx = ((x + half) / res).astype(np.float32)
        my = ((y + half) / res).astype(np.float32)
        return cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)

    def _clutter(self) -> tuple[list[_Solid], _Cones]:
        """Blue things on the table: a box, a bottle cap and a pen cap (placed in W0)."""
        R0, t0 = self.scene.R_c0, self.scene.t_c0
        floor = -TABLE_GAP

        def place(planes, xyz, yaw_deg, albedo):
            c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
            Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            return _place_solid(planes, R0 @ Rz, R0 @ np.asarray(xyz) + t0, albedo, CLUTTER)

        box = place(_box((0.07, 0.045, 0.03)), (0.03, -0.17, floor + 0.015), 20,
                    [165.0, 92.0, 34.0])
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        disc = 0.016 * np.column_stack([np.cos(ang), np.sin(ang)])
        cap = place(_prism(disc, 0.006, -0.006), (-0.08, 0.12, floor + 0.006), 0,
                    [190.0, 98.0, 40.0])
        a = np.array([0.17, -0.09, floor + 0.0065])
        b = a + 0.05 * np.array([np.cos(1.0), np.sin(1.0), 0.0])
        pen_cap = _cone(R0 @ a + t0, R0 @ b + t0, 0.0065, 0.0055, [178.0, 72.0, 26.0], CLUTTER)
        return [box, cap], pen_cap

    # --------------------------------------------------------------------- geometry

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R_ch, t_ch) of the hand at time t. The forearm keeps W0's axes and moves with the
        wrist (t_ch): the wrist angles are the hand relative to the forearm."""
        R_rel, p_rel = self.scene.motion.pose(np.array([t]))
        R_c0, t_c0 = self.scene.R_c0, self.scene.t_c0
        return R_c0 @ R_rel[0], R_c0 @ p_rel[0] + t_c0

    def layer(self, t: float) -> _Layer:
        """The moving geometry at time t."""
        R, tr = self.pose(t)
        m = self.model
        palm = _place_solid(m.palm, R, tr, m.palm_albedo, m.palm_part)
        n = len(m.cones)
        sets = [_Cones(m.cones[:, :3] @ R.T + tr, m.cones[:, 3:6] @ R.T + tr, m.cones[:, 6],
                       m.cones[:, 7], np.tile(SKIN, (n, 1)), np.full(n, HAND, np.uint8))]
        f, R0 = m.forearm, self.scene.R_c0
        sets.append(_cone(R0 @ f[:3] + tr, R0 @ f[3:6] + tr, f[6], f[7], ARM_SKIN, ARM))
        if self.scene.occlusion is not None:
            pen = self._occluder(self.scene.occlusion, t, R, tr)
            if pen is not None:
                sets.append(pen)
        return _Layer([palm], _Cones.concat(sets), R, tr)

    def _occluder(self, occ: Occlusion, t: float, R: np.ndarray, tr: np.ndarray) -> _Cones | None:
        """The pen: along the MCP4 -> MCP5 line, slid out by s metres, lifted towards the camera.

        It follows the hand while it covers the markers, so exactly MCP4 and MCP5 are hidden.
        """
        u = (t - self.t0) / max(self.scene.duration, 1e-9)
        if not occ.enter <= u <= occ.gone:
            return None
        if u < occ.cover:
            s = 1.0 - float(min_jerk(np.array([(u - occ.enter) / (occ.cover - occ.enter)]))[0])
        else:
            s = float(min_jerk(np.array([(u - occ.leave) / (occ.gone - occ.leave)]))[0])
        s *= 0.14  # metres out along the MCP4 -> MCP5 line (0 while covering)
        p = self.scene.layout.points
        e = (p[5] - p[4]) / np.linalg.norm(p[5] - p[4])
        ends = (np.array([p[4] - 0.002 * e, p[5] + 0.13 * e]) + s * e) @ R.T + tr
        ends *= ((ends[:, 2] - occ.lift) / ends[:, 2])[:, None]  # along the lines of sight
        return _cone(ends[0], ends[1], occ.radius, occ.radius, PEN, OCCLUDER)

    # ------------------------------------------------------------------------ drawing

    def _draw(self, region, layer: _Layer, colour, zbuf, ids) -> None:
        """Ray-cast a layer into the buffers of ``region`` (x0, y0, x1, y1), z-tested.

        Only the pixels inside each primitive's projected outline (drawn with cv2, a couple of
        pixels wider) are tested.
        """
        zf, idf, cf = zbuf.reshape(-1), ids.reshape(-1), colour.reshape(-1, 3)
        for solid in layer.solids:
            pix, full = self._solid_pixels(solid, region)
            if pix is None:
                continue
            t, face = solid.hit(self.rays[full])
            front = t < zf[pix]
            pix, face = pix[front], face[front]
            zf[pix] = t[front]
            self._shade(idf, cf, pix, solid.normals[face], solid.albedo[face], solid.part[face])
        c = layer.cones
        pix, full, which = self._cone_pixels(c, region)
        if pix is None:
            return
        k = _cone_constants(c)
        t, surf = _cone_hits(self.rx[full], self.ry[full], which, k)
        front = t < zf[pix]
        pix, full, t, surf, which = pix[front], full[front], t[front], surf[front], which[front]
        # Overlapping cones: the nearest hit per pixel wins (the minimum is one of the values).
        np.minimum.at(zf, pix, t)
        win = t == zf[pix]
        pix, full, t, surf, which = pix[win], full[win], t[win], surf[win], which[win]
        normal = _cone_normals(t[:, None] * self.rays[full], which, surf, k)
        self._shade(idf, cf, pix, normal, c.albedo[which], c.part[which])

    def _solid_pixels(self, solid: _Solid, region) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Region and image flat indices of the pixels a convex solid may cover."""
        if np.any(solid.vertices[:, 2] < 0.05):
            return None, None
        uv = self.cam.project(solid.vertices)
        x0, y0, x1, y1 = region
        lo = np.maximum(np.floor(uv.min(axis=0)).astype(int) - 3, [x0, y0])
        hi = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + 4, [x1, y1])
        if np.any(hi <= lo):
            return None, None
        mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.uint8)
        hull = cv2.convexHull(np.round((uv - lo) * 16).astype(np.int32))
        cv2.fillConvexPoly(mask, hull, 1, cv2.LINE_8, shift=4)
        cv2.polylines(mask, [hull], True, 1, int(np.ceil(2 * self._margin)), cv2.LINE_8, shift=4)
        return self._mask_pixels(mask, lo, region)

    def _cone_pixels(self, c: _Cones, region) -> tuple[np.ndarray | None, ...]:
        """(region index, image index, cone index) of the pixels each cone may cover: the
        convex hull of its two end spheres' outlines (each a disc a little larger than the
        sphere's projection, which is an ellipse stretched away from the principal point)."""
        cam = self.cam
        front = (c.a[:, 2] - c.ra > 0.05) & (c.b[:, 2] - c.rb > 0.05)
        if not front.any():
            return None, None, None
        f = max(cam.fx, cam.fy)
        ends = []
        for centre, r in ((c.a[front], c.ra[front]), (c.b[front], c.rb[front])):
            uv = cam.project(centre)
            off2 = ((uv - [cam.cx, cam.cy]) ** 2).sum(axis=1) / f**2
            rho = f * r / (centre[:, 2] - r) * (1.0 + off2) + self._margin
            ends.append(uv[:, None, :] + rho[:, None, None] * _CIRCLE16)
        outline = np.concatenate(ends, axis=1)  # (n, 32, 2)
        x0, y0, x1, y1 = region
        lo_all = np.maximum(np.floor(outline.min(axis=1)).astype(int), [x0, y0])
        hi_all = np.minimum(np.ceil(outline.max(axis=1)).astype(int) + 1, [x1, y1])
        out_pix, out_full, out_which = [], [], []
        for n, i in enumerate(np.flatnonzero(front)):
            lo, hi = lo_all[n], hi_all[n]
            if np.any(hi <= lo):
                continue
            mask = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.uint8)
            hull = cv2.convexHull(np.round((outline[n] - lo) * 16).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 1, cv2.LINE_8, shift=4)
            pix, full = self._mask_pixels(mask, lo, region)
            if pix is not None:
                out_pix.append(pix)
                out_full.append(full)
                out_which.append(np.full(len(pix), i))
        if not out_pix:
            return None, None, None
        return np.concatenate(out_pix), np.concatenate(out_full), np.concatenate(out_which)

    def _mask_pixels(self, mask, lo, region) -> tuple[np.ndarray | None, np.ndarray | None]:
        r, col = np.nonzero(mask)
        if len(r) == 0:
            return None, None
        r = r + lo[1]
        col = col + lo[0]
        x0, y0, x1, _ = region
        return (r - y0) * (x1 - x0) + (col - x0), r * self.cam.width + col

    @staticmethod
    def _shade(idf, cf, pix, normal, albedo, part) -> None:
        """Lambert shading with a little gloss (not on the matte clutter) into flat buffers."""
        if len(pix) == 0:
            return
        lam = np.maximum(normal @ _LIGHT, 0.0)
        h = np.maximum(normal @ _HALF, 0.0)
        h *= h
        h *= h
        h *= h
        h *= h  # ^16
        gloss = np.where(part != CLUTTER, 22.0 * h, 0.0)
        cf[pix] = albedo * (_AMBIENT + _DIFFUSE * lam)[:, None] + gloss[:, None]
        idf[pix] = part

    def _markers(self, region, R, tr, colour, ids) -> tuple[np.ndarray, np.ndarray]:
        """Blend the facing markers into ``colour`` where the back of the palm is in front.

        Returns rim-polygon centroids (6,2) and visible fractions (6,).
        """
        rx0, ry0, rx1, ry1 = region
        rim_cam = self.model.rim @ R.T + tr  # (6,M,3)
        centre = self.scene.layout.points @ R.T + tr
        normal = R[:, 2]
        facing = (-centre @ normal > 0.0) & (centre[:, 2] > 0)
        shade = _AMBIENT + _DIFFUSE * max(float(normal @ _LIGHT), 0.0)
        blue = (MARKER_BLUE * shade).astype(np.float32)
        uv_all = self.cam.project(rim_cam)
        cents = np.array([_polygon_centroid(q) for q in uv_all])
        vis = np.zeros(6)
        S = _SUPERSAMPLE
        for k in np.flatnonzero(facing):
            uv = uv_all[k]
            x0 = max(int(np.floor(uv[:, 0].min())) - 1, rx0)
            y0 = max(int(np.floor(uv[:, 1].min())) - 1, ry0)
            x1 = min(int(np.ceil(uv[:, 0].max())) + 2, rx1)
            y1 = min(int(np.ceil(uv[:, 1].max())) + 2, ry1)
            if x0 >= x1 or y0 >= y1:
                continue
            # Supersampled pixel j spans [x0 - 0.5 + j/S, x0 - 0.5 + (j+1)/S]: map to its centre.
            q = (uv - [x0 - 0.5, y0 - 0.5]) * S - 0.5
            mask = np.zeros(((y1 - y0) * S, (x1 - x0) * S), np.uint8)
            cv2.fillPoly(mask, [np.round(q * 16).astype(np.int32)], 255, cv2.LINE_8, shift=4)
            cover = cv2.resize(mask, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
            cover = cover.astype(np.float32) / 255.0
            sl = (slice(y0 - ry0, y1 - ry0), slice(x0 - rx0, x1 - rx0))
            alpha = cover * (ids[sl] == DORSUM)
            total = float(cover.sum())
            vis[k] = float(alpha.sum()) / total if total > 0 else 0.0
            a = alpha[..., None]
            colour[sl] = colour[sl] * (1.0 - a) + a * blue
        return cents, vis

    def _shadow_offset(self, R, tr) -> np.ndarray:
        """Pixel offset (dx, dy) of the shadow on the table from the middle of the hand."""
        X = tr + R @ np.array([0.04, 0.0, -0.015])
        height = float(self.table_n @ (X - self.table_p))
        S = X - height / float(self.table_n @ _LIGHT) * _LIGHT
        return np.diff(self.cam.project(np.array([X, S])), axis=0)[0]

    def _shadow(self, R, tr, ids) -> np.ndarray | None:
        """Light factor (h,w) of the arm and hand's soft shadow (applied to table and clutter)."""
        mask = (ids >= ARM).astype(np.float32)
        h, w = mask.shape
        if h < 8 or w < 8:
            return None
        dx, dy = self._shadow_offset(R, tr)
        # Blur at quarter resolution: it is soft anyway, and 16x cheaper.
        small = cv2.resize(mask, (w // 4, h // 4), interpolation=cv2.INTER_AREA)
        M = np.float32([[1, 0, dx / 4], [0, 1, dy / 4]])
        small = cv2.warpAffine(small, M, (w // 4, h // 4))
        small = cv2.GaussianBlur(small, (0, 0), 0.5 + 0.01 * np.hypot(dx, dy))
        soft = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
        return np.where(ids <= CLUTTER, 1.0 - _SHADOW_DARKNESS * soft, 1.0).astype(np.float32)

    # --------------------------------------------------------------------------- frames

    def _region(self, layers: list[_Layer]) -> tuple[int, int, int, int]:
        """Pixel box of everything that moves, with room for its shadow and the lens blur."""
        pts, rad = [], []
        for layer in layers:
            pts += [s.vertices for s in layer.solids] + [layer.cones.a, layer.cones.b]
            rad += [np.zeros(len(s.vertices)) for s in layer.solids]
            rad += [layer.cones.ra, layer.cones.rb]
        p, r = np.vstack(pts), np.concatenate(rad)
        ok = p[:, 2] - r > 0.05
        W, H = self.cam.width, self.cam.height
        if not ok.any():
            return 0, 0, 8, 8
        uv = self.cam.project(p[ok])
        rho = r[ok] * max(self.cam.fx, self.cam.fy) / (p[ok, 2] - r[ok])
        mid = layers[len(layers) // 2]
        shift = float(np.hypot(*self._shadow_offset(mid.R, mid.t)))
        m = int(np.ceil(1.3 * shift)) + 24  # the shadow's offset and softness, the lens blur
        lo = np.floor((uv - rho[:, None]).min(axis=0)).astype(int) - m
        hi = np.ceil((uv + rho[:, None]).max(axis=0)).astype(int) + m
        x0, y0 = max(lo[0], 0), max(lo[1], 0)
        x1, y1 = min(hi[0], W), min(hi[1], H)
        return int(x0), int(y0), max(int(x1), int(x0) + 8), max(int(y1), int(y0) + 8)

    def frame(self, t: float) -> RenderedFrame:
        scene, cam = self.scene, self.cam
        times = self._subframe_times(t)
        layers = [self.layer(s) for s in times]
        region = x0, y0, x1, y1 = self._region(layers)
        acc = np.zeros((y1 - y0, x1 - x0, 3), np.float32)
        mid = len(times) // 2
        z_mid, light = None, None
        for i in [mid] + [j for j in range(len(times)) if j != mid]:
            layer = layers[i]
            colour = self.bg_colour[y0:y1, x0:x1].copy()
            zbuf = self.bg_z[y0:y1, x0:x1].copy()
            ids = self.bg_id[y0:y1, x0:x1].copy()
            self._draw(region, layer, colour, zbuf, ids)
            if i == mid:
                light = self._shadow(layer.R, layer.t, ids)
            elif light is not None:  # the shadow of the middle sub-frame, on the background
                light_i = np.where(ids <= CLUTTER, light, np.float32(1.0))
            if light is not None:
                li = light if i == mid else light_i
                cv2.multiply(colour, cv2.merge((li, li, li)), dst=colour)
            c, v = self._markers(region, layer.R, layer.t, colour, ids)
            acc += colour
            if i == mid:
                z_mid, cents, vis = zbuf, c, v
        acc = cv2.multiply(acc, self.vignette[y0:y1, x0:x1], scale=1.0 / len(times))
        img = self.bg_blurred.copy()
        blurred = cv2.GaussianBlur(acc, (0, 0), 0.6)
        m = 3  # the region's outer pixels keep the background's own blur
        ix0, iy0 = (m if x0 > 0 else 0), (m if y0 > 0 else 0)
        ix1 = (x1 - x0) - (m if x1 < cam.width else 0)
        iy1 = (y1 - y0) - (m if y1 < cam.height else 0)
        img[y0 + iy0:y0 + iy1, x0 + ix0:x0 + ix1] = blurred[iy0:iy1, ix0:ix1]
        bgr = self._sensor(img, t, region)
        depth = self._depth(z_mid, region) if scene.depth else None
        return RenderedFrame(float(t), bgr, depth, cents, vis)

    def _subframe_times(self, t: float) -> np.ndarray:
        """Sub-frame times over the exposure: enough that markers move < ~1 px between (the
        lens blur smooths the steps)."""
        e = self.scene.exposure
        if e <= 0:
            return np.array([t])
        pts = []
        for s in (t - e / 2, t + e / 2):
            R, tr = self.pose(s)
            pts.append(self.cam.project(self.scene.layout.points @ R.T + tr))
        move = float(np.max(np.linalg.norm(pts[1] - pts[0], axis=1)))
        k = int(np.clip(np.ceil(move), 1, 15))
        k += 1 - k % 2  # odd: the middle sub-frame is at t exactly (depth, truth)
        return t + e * (np.linspace(-0.5, 0.5, k) if k > 1 else np.zeros(1))

    def _sensor(self, img: np.ndarray, t: float, region) -> np.ndarray:
        """Gain and white-balance drift, shot and read noise, 8-bit quantisation (in place).

        The noise level of the static background is precomputed (from the undrifted image);
        inside ``region`` it follows the frame.
        """
        sc, ph = self.scene, self.phases
        tt = t - self.t0
        g = 1.0 + sc.gain_drift * (
            0.7 * np.sin(2 * np.pi * tt / 6.3 + ph[0]) + 0.3 * np.sin(2 * np.pi * tt / 2.1 + ph[1])
        )
        wb = 1.0 + 0.12 * sc.gain_drift * np.sin(2 * np.pi * tt / 9.0 + ph[2:5])
        H, W = self.cam.height, self.cam.width
        rows = img.reshape(H, W * 3)  # a long inner axis: numpy broadcasts fast along it
        rows *= np.tile((g * wb).astype(np.float32), W)
        k = int(self.rng.integers(2))
        oy, ox = (int(x) for x in self.rng.integers(_NOISE_PAD, size=2))
        noise = self.noise_bank[k, oy:oy + H, ox:ox + W]
        term = np.multiply(self.bg_sigma, noise, out=self._noise_buf)
        x0, y0, x1, y1 = region
        roi = img[y0:y1, x0:x1]
        term[y0:y1, x0:x1] = np.sqrt(self._read_var + self._shot * roi) * noise[y0:y1, x0:x1]
        img += term
        return cv2.convertScaleAbs(img)  # rounds and saturates at 255 (no value is negative)

    def _static_sensor(self) -> None:
        sc = self.scene
        self._read_var = np.float32((1.2 * sc.noise) ** 2)
        self._shot = np.float32((0.2 * sc.noise) ** 2)
        self.bg_sigma = np.sqrt(self._read_var + self._shot * self.bg_blurred)
        self._noise_buf = np.empty_like(self.bg_blurred)
        # Depth: the background's clean raw depth, noise level and valid pixels, computed once.
        z = self.bg_z.astype(np.float32)
        finite = np.isfinite(z)
        scale = np.float32(self.cam.depth_scale)
        self.bg_raw = np.where(finite, z / scale, 0.0).astype(np.float32)
        self.bg_dsigma = np.where(finite, DEPTH_SIGMA_COEFF * z * z / scale, 0.0).astype(np.float32)
        H, W = z.shape
        self.bg_keep, self.bg_proj_max = self._valid(z, 0, 0, np.full(H, -np.inf, np.float32))
        self._depth_buf = np.empty_like(z)

    def _valid(
        self, z: np.ndarray, x0: int, y0: int, seen_left: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (uint16 1/0) of a clean depth patch (its corner at image pixel x0, y0) that
        get a reading, and the running maximum of projector columns along each row.

        No reading where the surface jumps (mixed pixels, with ragged random edges), where the
        projector (baseline to the left) cannot light the point, and outside 0.4..4.5 m.
        ``seen_left`` is the running maximum just left of the patch (-inf at the image edge).
        """
        with np.errstate(invalid="ignore"):
            zc = np.where(np.isfinite(z), z, 1e3).astype(np.float32)
            kernel = np.ones((3, 3), np.uint8)
            edge = (cv2.dilate(zc, kernel) - cv2.erode(zc, kernel)) > 0.012
            ragged = cv2.dilate(edge.astype(np.uint8), kernel) > 0
            h, w = z.shape
            oy, ox = (int(v) for v in self.rng.integers(_NOISE_PAD, size=2))
            coin = self.depth_bank[1, y0 + oy:y0 + oy + h, x0 + ox:x0 + ox + w] > 0.25
            holes = edge | (ragged & coin)
            cols = np.arange(x0, x0 + w, dtype=np.float32)
            proj = cols + np.float32(self.cam.fx * _PROJECTOR_BASELINE) / zc
            seen = np.maximum.accumulate(np.column_stack([seen_left, proj]), axis=1)
            holes |= seen[:, :-1] > proj + 0.5
            holes |= (zc < 0.4) | (zc > 4.5)
        return (~holes).astype(np.uint16), seen[:, 1:]

    def _depth(self, z_roi: np.ndarray, region) -> np.ndarray:
        """Kinect-like raw depth (uint16, camera.depth_scale units): the static background's
        plus the re-rendered region's clean depth, with noise, holes and speckles."""
        cam = self.cam
        H, W = cam.height, cam.width
        x0, y0, x1, y1 = region
        k = int(self.rng.integers(2))
        oy, ox = (int(x) for x in self.rng.integers(_NOISE_PAD, size=2))
        noise = self.depth_bank[k, oy:oy + H, ox:ox + W]
        raw = np.multiply(self.bg_dsigma, noise, out=self._depth_buf)
        raw += self.bg_raw
        z = z_roi.astype(np.float32)
        finite = np.isfinite(z)
        z = np.where(finite, z, 0.0).astype(np.float32)
        scale = np.float32(cam.depth_scale)
        raw[y0:y1, x0:x1] = z / scale + DEPTH_SIGMA_COEFF * z * z / scale * noise[y0:y1, x0:x1]
        raw += 0.5  # round on truncation (all values >= 0)
        np.maximum(raw, 0.0, out=raw)
        np.minimum(raw, 65535.0, out=raw)
        out = raw.astype(np.uint16)
        keep = self.bg_keep.copy()
        seen_left = self.bg_proj_max[y0:y1, x0 - 1] if x0 > 0 else np.full(y1 - y0, -np.inf)
        keep_roi, _ = self._valid(np.where(finite, z_roi, np.inf), x0, y0, seen_left)
        keep[y0:y1, x0:x1] = keep_roi
        # Random dropouts: 2x2 speckles on 0.2 % of the image.
        n = int(self.rng.poisson(0.002 * H * W / 4))
        ys = self.rng.integers(0, H - 1, n)
        xs = self.rng.integers(0, W - 1, n)
        for dy in (0, 1):
            for dx in (0, 1):
                keep[ys + dy, xs + dx] = 0
        out *= keep
        return out


# ------------------------------------------------------------------------------------ API


def render_frames(scene: Scene, seed: int = 0) -> Iterator[RenderedFrame]:
    """Render the frames of ``scene`` one at a time (deterministic for a given seed)."""
    renderer = _Renderer(scene, seed)
    for t in scene.times:
        yield renderer.frame(float(t))


def render_recording(
    out: str | Path, scenario: str | Scene, seed: int = 0, overwrite: bool = False, **options: Any
) -> Path:
    """Render a synthetic RGB-D recording folder with ground truth; returns its path.

    ``scenario`` is one of RENDER_SCENARIOS (see :func:`wristtrack.sim.scenes.make_scene` for
    ``options``: fps, duration, n_frames, camera, layout, exposure, gain_drift, noise) or a
    ready Scene. Writes camera.json, frames.csv, rgb/ and depth/ PNGs, hand.json (unless the
    scenario has none), truth.csv (the poses.csv columns) and truth_markers.csv (per frame and
    marker: rim-centroid pixel and visible fraction, for detector tests). PNG encoding runs in
    a second thread while the next frame renders.
    """
    out = Path(out)
    scene = scenario if isinstance(scenario, Scene) else make_scene(scenario, seed, **options)
    hand = scene.layout if scene.write_hand else None
    header = ["frame", "timestamp"] + [
        f"{name}_{c}" for name in MARKER_NAMES for c in ("u", "v", "visible")
    ]
    with RecordingWriter(out, scene.camera, hand, overwrite=overwrite) as writer, open(
        out / "truth_markers.csv", "w", newline="", encoding="utf-8"
    ) as fh, ThreadPoolExecutor(max_workers=1) as pool:
        rows = csv.writer(fh, lineterminator="\n")
        rows.writerow(header)

        def write(i: int, fr: RenderedFrame) -> None:
            writer.write(fr.timestamp, fr.bgr, fr.depth)
            cells = [str(i), repr(fr.timestamp)]
            for k in range(6):
                cells += [f"{fr.uv[k, 0]:.4f}", f"{fr.uv[k, 1]:.4f}", f"{fr.visible[k]:.3f}"]
            rows.writerow(cells)

        pending: deque[Future] = deque()
        for i, fr in enumerate(render_frames(scene, seed)):
            pending.append(pool.submit(write, i, fr))
            while len(pending) > 2:  # bounded: a few frames in memory at most
                pending.popleft().result()
        while pending:
            pending.popleft().result()
    write_truth(out / "truth.csv", scene.trajectory(), scene.layout.side)
    return out
