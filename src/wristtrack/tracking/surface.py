"""The back of the hand as a depth measurement: patches of skin between the markers.

Under a structured-light camera the out-of-plane angles are set by depth, and six markers give
six depth readings, each with the sensor's full noise: the noise is correlated over the ~9x9 px
matching window, as large as a marker's image, so a marker's pixels do not average it down. The
skin between the markers is read by the same sensor, ~25 matching windows of it at arm's
length. Each patch of skin (radius ``radius``, centres ``spacing`` apart, about one matching
window, so that their noises are nearly independent) is a depth measurement of the hand's pose:

- Learned over the still start (:func:`learn_surface`): the still frames' depth, averaged per
  pixel and put into the hand frame by W0 (the hand's pose over the still start), gives each
  patch a local plane (centre point and normal, hand frame; the normal fitted over the patch's
  neighbourhood). The hand's own shape is learned, not assumed: a real back of the hand arches
  over the knuckles.
- Read every tracked frame (:func:`read_patches`): the pixels within a patch's image disc, each
  carried along the patch's plane to its centre's ray (the plane's depth there plus the pixel's
  residual from the plane), are gated (a finger, the background, a marker) and averaged with
  their tails trimmed.
- Used as a second unscented update after the markers' (:func:`surface_update`): the measured
  depth of each centre ray against where the ray meets the patch's plane at each sigma point
  (:func:`plane_depths`). Noise: the sensor's axial noise, the skin's own shape error and the
  colour-depth misregistration, which the patches share as the markers do. The sensor's noise
  is shared too, through its matching window (:func:`reading_correlation`): facing the camera
  the patches' image discs lie ~10 px apart and share a tenth of it, but on a hand turned
  edge-on their images crowd together (4 px apart at ~65 deg: three quarters shared, discs
  overlapping), and taken as independent there, the readings of one stretch of skin counted
  many times, and each frame's noise moved the pose by up to 1.2 deg (0.8 with the correlation;
  every effect, right hand making the left hand's movement, seed 0: pronation at the extremes
  of the movement, with exact pixels and marker depths too). The axial noise is
  taken as facing the camera, without the growth beyond 60 deg the markers' depth takes
  (depth_noise.oblique_sigma): with it, the extremes of a turned hand's movement leaned on the
  pixels and the worst range-of-motion error grew (every effect, right hands making the left
  hand's movement, 10 rendered seeds: 1.55 -> 1.66 deg). Patches seen beyond ``grazing_cos``
  are not read at all.

Off the still start (the paper model) or without a depth image there is no surface update.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.signal import convolve2d
from scipy.spatial import Delaunay

from wristtrack.camera import Camera
from wristtrack.depth_noise import MATCH_WINDOW_PX, neighbour_jumps, window_correlation
from wristtrack.filter import ukf
from wristtrack.hand import HandLayout
from wristtrack.tracking.observation import (
    MeasurementNoise,
    depth_offset_change,
    hand_in_camera,
    point_rates,
    registration_depth_jacobian,
)

_TRIM = 0.1  # fraction of a patch's residuals cut off each tail before averaging


@dataclass(frozen=True)
class SurfaceSettings:
    """How the back of the hand is cut into depth patches and trusted."""

    spacing: float = 0.012  # m between patch centres: about a matching window at arm's length
    radius: float = 0.005  # m, patch radius
    clearance: float = 0.010  # m from any marker centre: a 12 mm marker and its rim
    shape_sigma: float = 0.0005  # m: the skin's own movement and the local plane's misfit
    gate: float = 0.008  # m: a pixel further off the patch's plane is something else
    min_valid: float = 0.5  # fraction of a patch's pixels that must read and pass the gate
    min_points: int = 12  # pixels (averaged over the still start) to learn a patch's plane
    edge_jump: float = 0.012  # m between neighbouring pixels: a depth edge
    edge_clearance: int = 3  # px kept clear of a depth edge (0: none)
    grazing_cos: float = 0.3  # a patch seen more obliquely than this is not read
    nis_quantile: float = 0.999  # an update beyond this chi-square quantile is not applied


@dataclass(frozen=True)
class DorsumSurface:
    """Local planes of the back of the hand: centres and unit normals (K, 3), hand frame; the
    normals point along the hand frame's +Z, towards a camera that sees the markers.

    ``offset_shift`` (K, 2): how far each plane was learned off the skin along its normal (m)
    per pixel of the depth map's offset from the colour image (du, dv): the still start read the
    skin that far beside where the colour image puts it (:func:`learned_offset_shift`). A state
    that carries the offset (tracking/offset_model.py) moves the planes back by it. None: not
    known (taken as zero)."""

    points: np.ndarray
    normals: np.ndarray
    offset_shift: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True)
class PatchReading:
    """One frame's readings: which patches (indices), their centre rays (K, 3) with z = 1, the
    measured depth (m) along each, the patches' centres and normals (K, 3) in the camera
    frame at the pose they were read at, and the image discs read: centre pixels (K, 2) (u, v)
    and radii (K,) px."""

    patches: np.ndarray
    rays: np.ndarray
    depth: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    pixels: np.ndarray
    radius_px: np.ndarray


def plane_depths(points: np.ndarray, normals: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Depth (z) at which each ray (..., 3), z = 1, meets the plane through ``points`` with
    ``normals`` (camera frame, broadcast against the rays): (n . p) / (n . r)."""
    return np.einsum("...j,...j->...", normals, points) / np.einsum("...j,...j->...", normals,
                                                                      rays)


def patch_centres(layout: HandLayout, settings: SurfaceSettings) -> np.ndarray:
    """(K, 2) hand-frame X, Y of the patch centres: a grid over the markers' hull, clear of the
    markers."""
    xy = layout.points[:, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    gx = np.arange(lo[0], hi[0] + 1e-9, settings.spacing)
    gy = np.arange(lo[1], hi[1] + 1e-9, settings.spacing)
    grid = np.column_stack([a.ravel() for a in np.meshgrid(gx, gy)])
    grid = grid[Delaunay(xy).find_simplex(grid) >= 0]
    clear = np.linalg.norm(grid[:, None] - xy[None], axis=2).min(axis=1) > settings.clearance
    return grid[clear]


@lru_cache(maxsize=4)
def pixel_rays(camera: Camera) -> np.ndarray:
    """(H, W, 2) undistorted normalised coordinates of every pixel (read-only, one table per
    camera): looked up, not undistorted anew (iteratively, with lens distortion) for each
    patch's pixels in every frame. Building it takes 30-200 ms: the tracker does so when it is
    made, not in the middle of a live recording."""
    v, u = np.mgrid[0:camera.height, 0:camera.width]
    table = camera.normalize(np.stack((u, v), axis=-1).astype(np.float64))
    table.setflags(write=False)
    return table


def learn_surface(camera: Camera, layout: HandLayout, R_ch: np.ndarray, t_ch: np.ndarray,
                  depths: list[np.ndarray], settings: SurfaceSettings) -> DorsumSurface | None:
    """The back of the hand's local planes from depth frames (raw, registered to colour) of a
    hand held still at pose (R_ch, t_ch); None where no patch has enough pixels."""
    if not depths:
        return None
    H, W = depths[0].shape
    corners = camera.project(layout.points @ R_ch.T + t_ch)
    if not np.isfinite(corners).all():
        return None
    margin = camera.fx * (settings.radius + settings.spacing) / max(float(t_ch[2]), 1e-3)
    u0, v0 = np.maximum(np.floor(corners.min(axis=0) - margin).astype(int), 0)
    u1, v1 = np.minimum(np.ceil(corners.max(axis=0) + margin).astype(int) + 1, (W, H))
    if u1 <= u0 or v1 <= v0:
        return None
    # The hand is still over these frames (W0 is one pose for all of them): average each
    # pixel's readings, then fit the planes to one frame's worth of points.
    stack = np.stack([frame[v0:v1, u0:u1] for frame in depths]).astype(np.float64)
    n = (stack > 0).sum(axis=0)
    z = stack.sum(axis=0) / np.maximum(n, 1) * camera.depth_scale
    ok = n >= 0.5 * len(depths)
    if not ok.any():
        return None
    rays = np.concatenate((pixel_rays(camera)[v0:v1, u0:u1][ok], np.ones((int(ok.sum()), 1))),
                          axis=1)
    hand = (rays * z[ok, None] - t_ch) @ R_ch  # into the hand frame
    # the skin lies within a few mm of the markers' plane; the rest is fingers and background
    hand = hand[np.abs(hand[:, 2] - np.median(layout.points[:, 2])) < 2 * settings.gate]
    centres, normals = [], []
    for c in patch_centres(layout, settings):
        q = hand - np.append(c, 0.0)
        gap = np.linalg.norm(q[:, :2], axis=1)
        # the height from the patch itself, the normal from its neighbourhood: a 5 mm disc's
        # slope would carry a few degrees of the sensor's noise
        here = _plane_fit(q[gap < settings.radius], settings.min_points)
        around = _plane_fit(q[gap < settings.spacing], settings.min_points)
        if here is not None and around is not None:
            centres.append((c[0], c[1], here[0]))
            normals.append(around[1])
    if not centres:
        return None
    centres, normals = np.array(centres), np.array(normals)
    return DorsumSurface(centres, normals,
                         learned_offset_shift(camera, centres @ R_ch.T + t_ch, normals @ R_ch.T))


def learned_offset_shift(camera: Camera, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(K, 2) the shift along their normals (m per px of offset along u and v) of planes
    learned at camera-frame ``points`` with ``normals`` (K, 3) from a depth map offset from the
    colour image: each pixel read the depth the slope g (registration_depth_jacobian) times the
    offset further along its ray r, which moves the plane by (n . r) g along n."""
    rays = points / points[:, 2:]
    slope = registration_depth_jacobian(points, normals, 1.0, camera.fx, camera.fy)
    return np.einsum("kj,kj->k", normals, rays)[:, None] * slope


def _plane_fit(q: np.ndarray, min_points: int) -> tuple[float, np.ndarray] | None:
    """Height at the origin and unit normal (+Z) of the plane z = a + b x + c y through points
    ``q`` (n, 3), refitted twice without the points beyond 3 robust sigmas."""
    for _ in range(3):
        if len(q) < min_points:
            return None
        A = np.column_stack((np.ones(len(q)), q[:, 0], q[:, 1]))
        coef = np.linalg.lstsq(A, q[:, 2], rcond=None)[0]
        r = q[:, 2] - A @ coef
        spread = 1.4826 * np.median(np.abs(r))
        q = q[np.abs(r) <= max(3.0 * spread, 1e-4)]
    normal = np.array([-coef[1], -coef[2], 1.0])
    return float(coef[0]), normal / np.linalg.norm(normal)


def read_patches(camera: Camera, surface: DorsumSurface, R_ch: np.ndarray, t_ch: np.ndarray,
                 depth: np.ndarray, settings: SurfaceSettings,
                 rays_xy: np.ndarray | None = None) -> PatchReading | None:
    """The depth of each visible patch's centre ray in the raw depth frame ``depth`` (registered
    to colour), with the hand at (R_ch, t_ch); None where no patch can be read. ``rays_xy`` is
    :func:`pixel_rays` of the camera (computed here when not given)."""
    if rays_xy is None:
        rays_xy = pixel_rays(camera)
    P = surface.points @ R_ch.T + t_ch
    N = surface.normals @ R_ch.T
    dist = np.linalg.norm(P, axis=1)
    # the back of the hand faces the camera (as generic_step.expected_markers asks of the markers)
    facing = -np.einsum("kj,kj->k", N, P) / dist > settings.grazing_cos
    uv = camera.project(P)
    ok = facing & (P[:, 2] > 0) & np.isfinite(uv).all(axis=1)
    if not ok.any():
        return None
    index = np.flatnonzero(ok)
    P, N, uv = P[ok], N[ok], uv[ok]
    r_px = camera.fx * settings.radius / P[:, 2]
    half = int(np.ceil(r_px.max()))
    off = np.arange(-half, half + 1)
    du, dv = np.meshgrid(off, off)
    centre_px = np.rint(uv).astype(int)  # each disc's centre pixel (its correlation's too)
    pu = centre_px[:, :1] + du.ravel()  # (K, w*w) pixel columns and rows
    pv = centre_px[:, 1:] + dv.ravel()
    H, W = depth.shape
    inside = ((pu - uv[:, :1]) ** 2 + (pv - uv[:, 1:]) ** 2 <= r_px[:, None] ** 2) \
        & (pu >= 0) & (pu < W) & (pv >= 0) & (pv < H)
    iv, iu = np.clip(pv, 0, H - 1).astype(int), np.clip(pu, 0, W - 1).astype(int)
    z = depth[iv, iu] * camera.depth_scale
    rays = np.concatenate((rays_xy[iv, iu], np.ones((*pu.shape, 1))), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = z - plane_depths(P[:, None], N[:, None], rays)
    good = inside & (z > 0) & (np.abs(e) < settings.gate)
    if settings.edge_clearance > 0:
        good &= ~near_depth_edges(depth, camera.depth_scale, iv, iu, settings)
    n = good.sum(axis=1)
    read = (n >= settings.min_valid * inside.sum(axis=1)) & (n > 0)
    if not read.any():
        return None
    # trimmed mean of each patch's residuals: sort with the rejected ones last
    e = np.sort(np.where(good, e, np.inf), axis=1)[read]
    n = n[read]
    lo = np.floor(_TRIM * n).astype(int)
    hi = np.maximum(np.ceil((1 - _TRIM) * n).astype(int), lo + 1)
    csum = np.concatenate((np.zeros((len(n), 1)), np.cumsum(np.where(np.isfinite(e), e, 0.0),
                                                             axis=1)), axis=1)
    rows = np.arange(len(n))
    mean = (csum[rows, hi] - csum[rows, lo]) / (hi - lo)
    centre = P[read] / P[read, 2:]  # the ray through each disc's centre (no undistorting back)
    measured = plane_depths(P[read], N[read], centre) + mean
    return PatchReading(index[read], centre, measured, P[read], N[read],
                        centre_px[read], r_px[read])


def reading_correlation(reading: PatchReading, window: int = MATCH_WINDOW_PX) -> np.ndarray:
    """(K, K) correlation of the sensor noise of a frame's patch readings: each is the mean of
    an image disc of a depth noise correlated over the matching window
    (depth_noise.window_correlation), so two discs fewer than a window plus a disc apart share
    part of it (module doc), and discs that overlap share pixels too."""
    r2 = round(4.0 * float(np.mean(reading.radius_px)) ** 2)
    table = _disc_mean_correlation(r2, window)
    c = table.shape[0] // 2
    d = reading.pixels[:, None] - reading.pixels[None]  # (K, K, 2) offsets (du, dv)
    far = (np.abs(d) > c).any(axis=2)
    d = np.clip(d, -c, c)
    out = table[d[..., 1] + c, d[..., 0] + c]
    out[far] = 0.0
    return out


@lru_cache(maxsize=256)  # every radius a recording's depths give (0.5 ms each to build)
def _disc_mean_correlation(r2_quarters: int, window: int) -> np.ndarray:
    """Correlation of the means of two discs of pixels (read_patches': radius^2 =
    ``r2_quarters`` / 4 px^2) at every offset (dv, du) of their centres, a table centred on
    offset 0: the pairs of pixels at each offset (the discs' cross-correlation) weighed by
    window_correlation, over its value at offset 0."""
    r2 = r2_quarters / 4.0
    h = int(np.floor(np.sqrt(r2)))
    off = np.arange(-h, h + 1)
    du, dv = np.meshgrid(off, off)
    disc = (du * du + dv * dv <= r2).astype(np.float64)
    pairs = convolve2d(disc, disc[::-1, ::-1])
    k = np.arange(1 - window, window)
    g = convolve2d(pairs, window_correlation(k[None, :], k[:, None], window))
    return g / g[g.shape[0] // 2, g.shape[1] // 2]


def near_depth_edges(depth: np.ndarray, depth_scale: float, iv: np.ndarray, iu: np.ndarray,
                     settings: SurfaceSettings) -> np.ndarray:
    """Whether each pixel (rows ``iv``, columns ``iu``, any shape, inside the frame) of the raw
    depth frame ``depth`` is on the near side of a depth edge: within
    ``settings.edge_clearance`` px of two neighbouring readings more than ``settings.edge_jump``
    apart, and nearer than the farthest reading there by as much.

    A structured-light camera gives the nearer surface's depth to pixels of the farther one
    beside an edge (its matching window straddles the edge: 1-2 px on the real OpenNI frames),
    and the colour-depth misregistration (1-2 px) moves the edge further. A patch on the back
    of a hand turned edge-on that reaches past the hand's outline read the hand's edge there as
    skin, off by the slope times the displacement but within the gate. The farther surface's
    own pixels (skin beside a finger held over it) are kept."""
    c = settings.edge_clearance
    H, W = depth.shape
    v0, v1 = max(int(iv.min()) - c - 1, 0), min(int(iv.max()) + c + 2, H)
    u0, u1 = max(int(iu.min()) - c - 1, 0), min(int(iu.max()) + c + 2, W)
    z = depth[v0:v1, u0:u1].astype(np.float32) * np.float32(depth_scale)
    # between neighbours: within a 3x3 neighbourhood, two pixels apart, a turned hand's skin
    # counted as edges
    edge = neighbour_jumps(z, settings.edge_jump, jump_to_zero=False).astype(np.uint8)
    window = np.ones((2 * c + 1, 2 * c + 1), np.uint8)
    near_side = (cv2.dilate(z, window) - z > settings.edge_jump) & (cv2.dilate(edge, window) > 0)
    return near_side[iv - v0, iu - u0]


def skin_update(model, x: np.ndarray, P: np.ndarray, R_c0: np.ndarray, t_c0: np.ndarray,
                surface: DorsumSurface, depth_image: np.ndarray, noise: MeasurementNoise,
                settings: SurfaceSettings, camera: Camera, params: ukf.UKFParams,
                depth_delay: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(x, P) updated with the depth of the skin between the markers, read in the raw depth frame
    ``depth_image`` (captured ``depth_delay`` s after the colour) at the pose of x (the markers'
    update's); unchanged where no patch can be read or the update is beyond
    ``settings.nis_quantile`` (:func:`surface_update`)."""
    R_ch, t_ch = hand_in_camera(*model.pose(x[None]), R_c0, t_c0)
    reading = read_patches(camera, surface, R_ch[0], t_ch[0], depth_image, settings,
                           pixel_rays(camera))
    if reading is None:
        return x, P
    limit = ukf.chi2_quantile(settings.nis_quantile, len(reading.depth))
    x, P, _, _ = surface_update(model, x, P, R_c0, t_c0, surface, reading, noise, settings, camera,
                                params, limit, depth_delay)
    return x, P


def surface_update(model, x: np.ndarray, P: np.ndarray, R_c0: np.ndarray, t_c0: np.ndarray,
                   surface: DorsumSurface, reading: PatchReading, noise: MeasurementNoise,
                   settings: SurfaceSettings, camera: Camera, params: ukf.UKFParams,
                   nis_limit: float, depth_delay: float = 0.0,
                   ) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The unscented update of (x, P) with one frame's patch readings, read at the pose of x:
    (x, P, NIS, dof). ``noise`` is the markers' MeasurementNoise (the sensor's depth sigma and
    the misregistration); an update whose NIS is beyond ``nis_limit`` is not applied. The depth
    frame was captured ``depth_delay`` s after the colour (MarkerObservation.depth_delay)."""
    pts, nrm = surface.points[reading.patches], surface.normals[reading.patches]
    offset_of = getattr(model, "depth_offset", None)  # the misregistration in the state
    shift = None if surface.offset_shift is None else surface.offset_shift[reading.patches]

    rates_of = getattr(model, "rates", None) if depth_delay else None

    def h(X: np.ndarray) -> np.ndarray:
        R_ch, t_ch = hand_in_camera(*model.pose(X), R_c0, t_c0)
        Nw = np.einsum("sij,kj->ski", R_ch, nrm)
        o = None if offset_of is None else offset_of(X)
        # with the offset, the planes moved back onto the skin (learned off it by the offset)
        skin = pts if o is None or shift is None else (
            pts[None] - nrm[None] * (o @ shift.T)[..., None])
        Pw = np.einsum("sij,s...j->s...i", R_ch, np.broadcast_to(skin, (len(X), *pts.shape)))
        if rates_of is not None:  # read where the hand's rates move it over the depth's delay
            Pw = Pw + depth_delay * point_rates(*rates_of(X), R_c0, Pw)
        z = plane_depths(Pw + t_ch[:, None], Nw, reading.rays[None])
        if o is None:
            return z
        # each centre ray's depth read off it by the offset: the plane's depth along its slope
        return z + depth_offset_change(z[..., None] * reading.rays[None], Nw, o, camera.fx,
                                       camera.fy)

    pred = ukf.predict_measurement(model, x, P, h, params)
    sd = noise.depth_sigma(reading.depth)
    R = np.outer(sd, sd) * reading_correlation(reading) + np.diag(
        np.full(len(sd), settings.shape_sigma**2))
    if offset_of is None:  # the misregistration as noise the patches share
        G = registration_depth_jacobian(reading.points, reading.normals, noise.registration_px,
                                        camera.fx, camera.fy)
        R += G @ G.T
    res = ukf.update(model, x, P, pred, reading.depth, R)
    if not res.nis <= nis_limit:
        return x, P, res.nis, res.dof
    return res.x, res.P, res.nis, res.dof
