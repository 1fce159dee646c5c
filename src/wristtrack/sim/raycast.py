"""Ray casting of a layer of primitives into colour, z and surface-id buffers.

Only the pixels inside each primitive's projected outline (drawn with cv2, a couple of pixels
wider) are tested, so a hand costs a few thousand rays, not the whole image.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.sim.primitives import (
    CIRCLE16,
    Cones,
    Solid,
    cone_constants,
    cone_hits,
    cone_normals,
)
from wristtrack.sim.shading import shade

Region = tuple[int, int, int, int]  # x0, y0, x1, y1 (pixels, x1/y1 exclusive)


@dataclass(frozen=True)
class Layer:
    """Geometry of one instant: convex solids, round cones, and the hand pose."""

    solids: list[Solid]
    cones: Cones
    R: np.ndarray
    t: np.ndarray


class RayCaster:
    """The camera's pixel rays, and the drawing of layers through them."""

    def __init__(self, cam: Camera):
        self.cam = cam
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
        self.margin = 1.5 + (6 if cam.has_distortion else 0)

    def draw(self, region: Region, layer: Layer, colour: np.ndarray, zbuf: np.ndarray,
             ids: np.ndarray) -> None:
        """Ray-cast a layer into the buffers of ``region`` (x0, y0, x1, y1), z-tested."""
        zf, idf, cf = zbuf.reshape(-1), ids.reshape(-1), colour.reshape(-1, 3)
        for solid in layer.solids:
            pix, full = self._solid_pixels(solid, region)
            if pix is None:
                continue
            t, face = solid.hit(self.rays[full])
            front = t < zf[pix]
            pix, face = pix[front], face[front]
            zf[pix] = t[front]
            shade(idf, cf, pix, solid.normals[face], solid.albedo[face], solid.part[face])
        c = layer.cones
        pix, full, which = self._cone_pixels(c, region)
        if pix is None:
            return
        k = cone_constants(c)
        t, surf = cone_hits(self.rx[full], self.ry[full], which, k)
        front = t < zf[pix]
        pix, full, t, surf, which = pix[front], full[front], t[front], surf[front], which[front]
        # Overlapping cones: the nearest hit per pixel wins (the minimum is one of the values).
        np.minimum.at(zf, pix, t)
        win = t == zf[pix]
        pix, full, t, surf, which = pix[win], full[win], t[win], surf[win], which[win]
        normal = cone_normals(t[:, None] * self.rays[full], which, surf, k)
        shade(idf, cf, pix, normal, c.albedo[which], c.part[which])

    def _solid_pixels(self, solid: Solid, region: Region) -> tuple[np.ndarray | None, ...]:
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
        cv2.polylines(mask, [hull], True, 1, int(np.ceil(2 * self.margin)), cv2.LINE_8, shift=4)
        return self._mask_pixels(mask, lo, region)

    def _cone_pixels(self, c: Cones, region: Region) -> tuple[np.ndarray | None, ...]:
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
            rho = f * r / (centre[:, 2] - r) * (1.0 + off2) + self.margin
            ends.append(uv[:, None, :] + rho[:, None, None] * CIRCLE16)
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
