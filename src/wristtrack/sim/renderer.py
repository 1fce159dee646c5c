"""The frame renderer: the moving hand (with its forearm and the occluder) ray-cast over the
static background, the markers filled at 8x supersampling, the soft shadow, motion blur over the
exposure, then the colour and depth sensors.

Speed: only the region around the moving parts is re-rendered each frame (the table and clutter
are drawn once).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.sim import realism
from wristtrack.sim.background import draw_background
from wristtrack.sim.depth_sensor import DepthSensor
from wristtrack.sim.hand_model import MARKER_RADIUS, hand_model
from wristtrack.sim.motion import min_jerk
from wristtrack.sim.primitives import Cones, cone, place_solid, polygon_centroid
from wristtrack.sim.raycast import Layer, RayCaster, Region
from wristtrack.sim.scenes import Occlusion, Scene
from wristtrack.sim.sensor import NOISE_PAD, ColourSensor
from wristtrack.sim.shading import (
    AMBIENT,
    ARM,
    ARM_SKIN,
    CLUTTER,
    DIFFUSE,
    DORSUM,
    HAND,
    HIGHLIGHT_WHITE,
    LIGHT,
    MARKER_BLUE,
    OCCLUDER,
    PEN,
    SHADOW_DARKNESS,
    SKIN,
    highlight_offset,
)

_SUPERSAMPLE = 8  # marker coverage resolution per pixel side
# A marker is a sticker on the skin and moves with it: with the fingers flexed the MCP markers
# slide distally (soft tissue) past their knuckles' pads onto the base of the fingers, and they
# show there too, where the finger's surface is at the marker's plane; a finger lying in front
# of a marker (at least its radius in front of the plane) hides it. The back of the hand's
# convex solids are one skin surface, so a marker shows wherever they are what the pixel sees.
_ON_FINGER_M = 0.004


def _band(weights: np.ndarray) -> tuple[int, int]:
    """The rows [a, b) with a share of a sub-frame (``weights`` (rows,)): one band, as each
    row's exposure follows the one above it."""
    inside = np.flatnonzero(weights > 0)
    return (int(inside[0]), int(inside[-1]) + 1) if inside.size else (0, 0)


@dataclass(frozen=True)
class RenderedFrame:
    """One rendered frame and its marker truth at ``timestamp``.

    ``uv`` (6,2) is the centroid of each marker's projected rim polygon (what an ideal blob
    detector finds; not exactly the projection of the marker centre; under a rolling shutter,
    where the row it is on was read), ``visible`` (6,) the fraction of the marker's area that
    can be seen (0 when it faces away or is covered).
    """

    timestamp: float
    bgr: np.ndarray
    depth: np.ndarray | None
    uv: np.ndarray
    visible: np.ndarray


@dataclass(frozen=True)
class _Moment:
    """The moving geometry at one instant, and where the markers are (hand frame)."""

    layer: Layer
    markers: np.ndarray  # (6,3) marker centres, hand frame (soft tissue moves them)


class Renderer:
    """Draws the frames of one Scene; the static background is drawn once at construction."""

    def __init__(self, scene: Scene, seed: int):
        self.scene = scene
        self.cam = cam = scene.camera
        self.rng = np.random.default_rng([seed, 2])
        self.model = hand_model(scene.layout)
        self.caster = RayCaster(cam)
        self.t0 = float(scene.times[0]) if len(scene.times) else 0.0
        H, W = cam.height, cam.width
        u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        r2 = ((u - cam.cx) / cam.fx) ** 2 + ((v - cam.cy) / cam.fy) ** 2
        vignette = (1.0 - 0.22 * r2 / r2.max()).astype(np.float32)
        self.vignette = cv2.merge((vignette, vignette, vignette))
        self.bg = draw_background(scene, self.caster, self.vignette)
        # The noise banks are drawn in this order (colour, depth, drift phases) so a seed
        # renders the same frames as ever; the effects draw from their own streams.
        pad = (H + NOISE_PAD, W + NOISE_PAD)
        noise_bank = self.rng.standard_normal((2, *pad, 3), dtype=np.float32)
        depth_bank = self.rng.standard_normal((2, *pad), dtype=np.float32)
        phases = self.rng.uniform(0, 2 * np.pi, 5)
        fx_rng = np.random.default_rng([seed, 3])
        self.colour = ColourSensor(scene, self.bg.blurred, noise_bank, phases, self.rng,
                                   fx_rng, self.t0)
        self.depth = DepthSensor(scene, self.bg.z, depth_bank, self.rng,
                                 np.random.default_rng([seed, 4]))

    # --------------------------------------------------------------------- geometry

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R_ch, t_ch) of the hand at time t. The forearm keeps W0's axes and moves with the
        wrist (t_ch): the wrist angles are the hand relative to the forearm."""
        R_rel, p_rel = self.scene.motion.pose(np.array([t]))
        R_c0, t_c0 = self.scene.R_c0, self.scene.t_c0
        return R_c0 @ R_rel[0], R_c0 @ p_rel[0] + t_c0

    def moment(self, t: float) -> _Moment:
        """The moving geometry at time t."""
        R, tr = self.pose(t)
        m = self.model
        markers = self.scene.layout.points
        cones = m.cones
        if "soft_tissue" in self.scene.effects:
            flex = float(realism.finger_flexion_deg(t, self.t0))
            cones = m.finger_cones(flex)
            markers = markers + realism.skin_slide(flex, self.scene.layout)
        palm = [place_solid(planes, R, tr, albedo, part)
                for planes, albedo, part in zip(m.palm, m.palm_albedo, m.palm_part, strict=True)]
        n = len(cones)
        sets = [Cones(cones[:, :3] @ R.T + tr, cones[:, 3:6] @ R.T + tr, cones[:, 6],
                      cones[:, 7], np.tile(SKIN, (n, 1)), np.full(n, HAND, np.uint8))]
        f, R0 = m.forearm, self.scene.R_c0
        sets.append(cone(R0 @ f[:3] + tr, R0 @ f[3:6] + tr, f[6], f[7], ARM_SKIN, ARM))
        if self.scene.occlusion is not None:
            pen = self._occluder(self.scene.occlusion, t, R, tr)
            if pen is not None:
                sets.append(pen)
        return _Moment(Layer(palm, Cones.concat(sets), R, tr), markers)

    def layer(self, t: float) -> Layer:
        return self.moment(t).layer

    def _occluder(self, occ: Occlusion, t: float, R: np.ndarray, tr: np.ndarray) -> Cones | None:
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
        return cone(ends[0], ends[1], occ.radius, occ.radius, PEN, OCCLUDER)

    # ------------------------------------------------------------------------ drawing

    def _rims(self, mo: _Moment) -> np.ndarray:
        """(6, M, 2) the markers' rim polygons in the image at moment ``mo``."""
        rim = self.model.rim
        if mo.markers is not self.scene.layout.points:
            rim = rim + (mo.markers - self.scene.layout.points)[:, None, :]
        return self.cam.project(rim @ mo.layer.R.T + mo.layer.t)

    def _rolled_centres(self, t: float, cents: np.ndarray) -> np.ndarray:
        """The markers' rim centroids (6, 2) where a rolling shutter sees them: each at the
        moment its own row is read (Camera.row_time), from ``cents``, the frame moment's."""
        for _ in range(3):  # the row moves with the marker: a fixed point, reached in a few
            cents = np.array([polygon_centroid(self._rims(self.moment(t + float(dt)))[k])
                              for k, dt in enumerate(self.cam.row_time(cents[:, 1]))])
        return cents

    def _markers(self, region: Region, mo: _Moment, colour, ids, zbuf) -> tuple[np.ndarray, ...]:
        """Blend the facing markers into ``colour`` where the pixel sees the back of the hand, or
        a finger's base at the marker's plane (``zbuf``: the region's depth).

        Returns rim-polygon centroids (6,2) and visible fractions (6,).
        """
        rx0, ry0, rx1, ry1 = region
        R, tr = mo.layer.R, mo.layer.t
        centre = mo.markers @ R.T + tr
        normal = R[:, 2]
        facing = (-centre @ normal > 0.0) & (centre[:, 2] > 0)
        shade = AMBIENT + DIFFUSE * max(float(normal @ LIGHT), 0.0)
        blue = (MARKER_BLUE * shade).astype(np.float32)
        uv_all = self._rims(mo)
        cents = np.array([polygon_centroid(q) for q in uv_all])
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
            # depth of the marker's plane along each pixel's ray (z = 1 rays: t is the depth)
            rays = self.caster.rays.reshape(self.cam.height, self.cam.width, 3)[y0:y1, x0:x1]
            with np.errstate(divide="ignore", invalid="ignore"):
                z_plane = float(normal @ centre[k]) / (rays @ normal)
            on_skin = (ids[sl] == DORSUM) | (
                (ids[sl] == HAND) & (zbuf[sl] >= z_plane - _ON_FINGER_M))
            alpha = cover * on_skin
            total = float(cover.sum())
            vis[k] = float(alpha.sum()) / total if total > 0 else 0.0
            a = alpha[..., None]
            colour[sl] = colour[sl] * (1.0 - a) + a * blue
            if "specular" in self.scene.effects:
                self._highlight(colour[sl], alpha, x0, y0, centre[k], normal)
        return cents, vis

    def _highlight(self, patch, alpha, x0: int, y0: int, centre, normal) -> None:
        """Add the lamp's mirror image on a domed glossy marker (in place, on the marker only)."""
        off = highlight_offset(normal, centre, realism.DOME_RADIUS, MARKER_RADIUS)
        if off is None:
            return
        p = centre + off
        u, v = self.cam.project(p)
        # A sphere doubles angles: the lamp's image on the dome has radius D * a / 2.
        sigma = max(self.cam.fx * realism.DOME_RADIUS * realism.LAMP_ANGULAR_RADIUS / 2 / p[2],
                    0.3)
        h, w = alpha.shape
        gx = np.exp(-0.5 * ((np.arange(w) + x0 - u) / sigma) ** 2)
        gy = np.exp(-0.5 * ((np.arange(h) + y0 - v) / sigma) ** 2)
        spot = (realism.HIGHLIGHT_PEAK * np.outer(gy, gx) * alpha).astype(np.float32)
        patch += spot[..., None] * HIGHLIGHT_WHITE

    def _shadow_offset(self, R, tr) -> np.ndarray:
        """Pixel offset (dx, dy) of the shadow on the table from the middle of the hand."""
        X = tr + R @ np.array([0.04, 0.0, -0.015])
        height = float(self.bg.table_n @ (X - self.bg.table_p))
        S = X - height / float(self.bg.table_n @ LIGHT) * LIGHT
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
        return np.where(ids <= CLUTTER, 1.0 - SHADOW_DARKNESS * soft, 1.0).astype(np.float32)

    # --------------------------------------------------------------------------- frames

    def region(self, layers: list[Layer]) -> Region:
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
        scene, cam, bg = self.scene, self.cam, self.bg
        times = self._subframe_times(t)
        moments = [self.moment(s) for s in times]
        # the depth frame paired with this colour frame, captured cam.depth_delay after it
        lagged = self.moment(t + cam.depth_delay) if scene.depth and cam.depth_delay else None
        extra = [] if lagged is None else [lagged.layer]
        region = x0, y0, x1, y1 = self.region([mo.layer for mo in moments] + extra)
        acc = np.zeros((y1 - y0, x1 - x0, 3), np.float32)
        rows = self._row_weights(times, t, y0, y1) if cam.readout else None
        mid = len(times) // 2
        z_mid, light = None, None
        for i in [mid] + [j for j in range(len(times)) if j != mid]:
            layer = moments[i].layer
            # a rolling shutter's sub-frame is drawn only on the rows it is part of (the
            # middle one everywhere: its shadow, depth and truth are the frame's)
            a, b = (0, y1 - y0) if rows is None or i == mid else _band(rows[i])
            if a == b:
                continue
            box = (x0, y0 + a, x1, y0 + b)
            colour = bg.colour[y0 + a:y0 + b, x0:x1].copy()
            zbuf = bg.z[y0 + a:y0 + b, x0:x1].copy()
            ids = bg.ids[y0 + a:y0 + b, x0:x1].copy()
            self.caster.draw(box, layer, colour, zbuf, ids)
            if i == mid:
                light = self._shadow(layer.R, layer.t, ids)
            elif light is not None:  # the shadow of the middle sub-frame, on the background
                light_i = np.where(ids <= CLUTTER, light[a:b], np.float32(1.0))
            if light is not None:
                li = light if i == mid else light_i
                cv2.multiply(colour, cv2.merge((li, li, li)), dst=colour)
            c, v = self._markers(box, moments[i], colour, ids, zbuf)
            if rows is None:
                acc += colour
            else:  # each row its share of the sub-frame (its own exposure)
                acc[a:b] += colour * rows[i][a:b, None, None]
            if i == mid:
                z_mid, cents, vis = zbuf, c, v
        acc = cv2.multiply(acc, self.vignette[y0:y1, x0:x1],
                           scale=1.0 / len(times) if rows is None else 1.0)
        img = bg.blurred.copy()
        blurred = cv2.GaussianBlur(acc, (0, 0), 0.6)
        m = 3  # the region's outer pixels keep the background's own blur
        ix0, iy0 = (m if x0 > 0 else 0), (m if y0 > 0 else 0)
        ix1 = (x1 - x0) - (m if x1 < cam.width else 0)
        iy1 = (y1 - y0) - (m if y1 < cam.height else 0)
        img[y0 + iy0:y0 + iy1, x0 + ix0:x0 + ix1] = blurred[iy0:iy1, ix0:ix1]
        bgr = self.colour.capture(img, t, region)
        if lagged is not None:
            z_mid = bg.z[y0:y1, x0:x1].copy()
            self.caster.draw(region, lagged.layer, bg.colour[y0:y1, x0:x1].copy(), z_mid,
                             bg.ids[y0:y1, x0:x1].copy())
        depth = self.depth.capture(z_mid, region) if scene.depth else None
        if cam.readout:
            cents = self._rolled_centres(t, cents)
        return RenderedFrame(float(t), bgr, depth, cents, vis)

    def _row_weights(self, times: np.ndarray, t: float, y0: int, y1: int) -> np.ndarray:
        """(sub-frames, rows y0..y1) float32: each row's share of each sub-frame under a rolling
        shutter. Row y is exposed over scene.exposure centred on t + Camera.row_time(y); each
        sub-frame stands for the time halfway to its neighbours (the two ends half that:
        trapezoids), and a row takes each one's overlap with its exposure (with none, the
        sub-frame nearest its moment). Each row's shares sum to 1."""
        centre = t + self.cam.row_time(np.arange(y0, y1))
        e = self.scene.exposure
        if len(times) == 1:
            return np.ones((1, y1 - y0), np.float32)
        step = times[1] - times[0]
        if e <= 0:
            nearest = np.clip(np.rint((centre - times[0]) / step), 0, len(times) - 1)
            return (np.arange(len(times))[:, None] == nearest[None]).astype(np.float32)
        lo = np.maximum(times[:, None] - step / 2, centre[None] - e / 2)
        hi = np.minimum(times[:, None] + step / 2, centre[None] + e / 2)
        share = np.clip(hi - lo, 0.0, None)
        return (share / share.sum(axis=0)).astype(np.float32)

    def _subframe_times(self, t: float) -> np.ndarray:
        """Sub-frame times over the exposure (of every row: a rolling shutter's span its
        readout more): enough that markers move < ~1 px between (the lens blur smooths the
        steps)."""
        e = self.scene.exposure + (self.cam.readout or 0.0)
        if e <= 0:
            return np.array([t])
        pts = []
        for s in (t - e / 2, t + e / 2):
            R, tr = self.pose(s)
            pts.append(self.cam.project(self.scene.layout.points @ R.T + tr))
        move = float(np.max(np.linalg.norm(pts[1] - pts[0], axis=1)))
        # A long shutter's streaks need more sub-frames than the plain scenarios ever did.
        k = int(np.clip(np.ceil(move), 1, 31 if "shutter" in self.scene.effects else 15))
        if self.cam.readout:
            # Each row's own exposure needs sub-frames of its own, three or more (without blur,
            # one within 0.1 px of its moment): with two in a span of three a row blends two
            # poses, and its blob centre strays 0.1 px from where the row saw the marker.
            exposure = self.scene.exposure
            k = max(k, int(np.ceil(3 * e / exposure if exposure > 0 else 10 * move)) + 1)
            k = min(k, 61)
        k += 1 - k % 2  # odd: the middle sub-frame is at t exactly (depth, truth)
        return t + e * (np.linspace(-0.5, 0.5, k) if k > 1 else np.zeros(1))
