"""Geometry primitives of the image simulator, all in the camera frame and ray-cast analytically:
round cones (two spheres joined by their tangent cone: fingers, forearm, pens) and convex
polyhedra (palm, boxes), plus the polygon helpers of the marker rims.

Rays are (x, y, 1) through each pixel, so a hit's ray parameter is its depth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Cones:
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
    def concat(sets: list[Cones]) -> Cones:
        return Cones(*(np.concatenate([getattr(c, f) for c in sets]) for f in CONE_FIELDS))


CONE_FIELDS = ("a", "b", "ra", "rb", "albedo", "part")
CIRCLE16 = np.column_stack(
    [np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
     np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))]
) / np.cos(np.pi / 16)  # a 16-gon around the unit circle


def cone(a: np.ndarray, b: np.ndarray, ra: float, rb: float, albedo: np.ndarray | list,
         part: int) -> Cones:
    return Cones(np.atleast_2d(a), np.atleast_2d(b), np.array([ra]), np.array([rb]),
                  np.atleast_2d(albedo), np.array([part], dtype=np.uint8))


def cone_constants(c: Cones) -> dict[str, np.ndarray]:
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


def cone_hits(x: np.ndarray, y: np.ndarray, which: np.ndarray, k: dict) -> tuple[np.ndarray, ...]:
    """First hit depth (inf if none) and surface (0: sphere a, 1: sphere b, 2: cone) of the
    rays (x, y, 1) with the round cones ``which`` (per ray), from :func:`cone_constants`."""
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


def cone_normals(P: np.ndarray, which: np.ndarray, surf: np.ndarray, k: dict) -> np.ndarray:
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
class Solid:
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


def prism(
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


def box(size: tuple[float, float, float]) -> tuple[np.ndarray, ...]:
    hx, hy, hz = (0.5 * s for s in size)
    square = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return prism(square, hz, -hz)


def place_solid(planes: tuple[np.ndarray, ...], R: np.ndarray, t: np.ndarray,
                albedo: np.ndarray | list, part: int | np.ndarray) -> Solid:
    """A local prism (normals, offsets, vertices) moved by p -> R p + t."""
    normals, offsets, verts = planes
    n = normals @ R.T
    P = len(normals)
    albedo = np.broadcast_to(np.asarray(albedo, dtype=float), (P, 3)).copy()
    part = np.broadcast_to(np.asarray(part, dtype=np.uint8), (P,)).copy()
    return Solid(n, offsets + n @ t, verts @ R.T + t, albedo, part)


def signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid of a simple polygon (K,2) (shoelace)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return poly.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)
