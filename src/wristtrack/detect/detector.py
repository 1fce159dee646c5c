"""Blue-marker detector: one colour (+ depth) frame in, unordered sub-pixel blob centres out.

The paper's detection (Cordella et al., section III-A), done as finely as the sensor allows
(DESIGN.md sections 4-5):

1. Skin region of interest (:mod:`wristtrack.detect.skin`): YCrCb skin classification on a 1/4
   image, fixed chroma box at first, the subject's own chroma (Mahalanobis) once fitted; the
   bounding box of the largest skin components plus a margin is searched, and blobs whose
   centre is off the dilated skin are ignored. No skin: the whole image is searched. To keep
   the work small, the search first covers only the neighbourhood of the last frame's blobs
   within that region, and the whole region whenever that finds fewer blobs.
2. Marker pixels (:mod:`wristtrack.detect.colour`), at half resolution: back-projection of a
   hue-saturation reference histogram, thresholded; connected components; a component is a
   marker candidate when the Bhattacharyya coefficient between its own (H, S) histogram and the
   reference is high enough.
3. Sub-pixel centres, shape and depth at full resolution (:mod:`wristtrack.detect.blobs`):
   blueness-weighted centroid, moment ellipse and skewness, trimmed-mean depth; size and shape
   must fit a 12 mm disc at the blob's depth.
4. Blobs too long for one marker are split in two where they have a waist (two markers merged
   by blur or proximity), else flagged; lopsided blobs (a marker clipped by an occluder) and
   blobs on the image border are flagged ``Blob.suspect``: still reported, for the tracker to
   down-weight, but not to be taken at face value.

``learn_markers`` refines the reference histogram and the skin model from the labelled
markers of one frame. ``DetectorConfig.paper()`` (preset "paper") is the paper's detection as
published, without steps 3-4 and the adaptations (:mod:`wristtrack.detect.paper`).
Cost: 1.5-2 ms per 640x480 frame on one core of a small shared VM, mostly fixed per-call
overhead (see :func:`wristtrack.sim.marker_scene.time_detection`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.blob_size import BlobSize, expected_length
from wristtrack.detect.blobs import (
    DEPTH_CORE,
    Shapes,
    blueness,
    discount_highlights,
    gather,
    shapes,
    split_pair,
    trimmed_depth,
    unmix_two_backgrounds_stack,
    upsample2,
)
from wristtrack.detect.colour import back_project, gaussian_reference
from wristtrack.detect.config import PRESETS, DetectorConfig
from wristtrack.detect.detections import Blob, Detections
from wristtrack.detect.learning import MarkerLearning
from wristtrack.detect.marker_colour import MarkerColour
from wristtrack.detect.paper import paper_blobs
from wristtrack.detect.skin import SkinModel, SkinRegion
from wristtrack.detect.tracking_window import TrackingWindow
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import MARKER_NAMES


@dataclass
class _Stack:
    """The candidate blobs of one frame, measured together in equal-size windows."""

    origin: np.ndarray  # (n, 2) full-res (x, y) of each window's top-left pixel
    w: np.ndarray  # (n, sy, sx) blueness weights
    depth: np.ndarray | None  # (n, sy, sx) raw depth windows
    similarity: np.ndarray  # (n,)
    border: np.ndarray  # (n,) bool
    shape: Shapes | None = None
    z: np.ndarray | None = None  # (n,) metres


class MarkerDetector(MarkerLearning, TrackingWindow):
    """Blue-marker detector for one camera; keeps the adapted colour models between frames."""

    def __init__(self, camera: Camera, config: DetectorConfig | None = None) -> None:
        self.camera = camera
        self.config = config = config or DetectorConfig()
        if config.skin_downsample % 2 or config.skin_downsample < 2:
            raise ConfigError(
                f"detector skin_downsample={config.skin_downsample}: must be an even number >= 2"
            )
        if config.preset not in PRESETS:
            raise ConfigError(f"detector preset {config.preset!r}: choose from "
                              f"{', '.join(PRESETS)}")
        self.colour = MarkerColour(gaussian_reference(
            config.hist_bins,
            config.marker_hue,
            config.marker_hue_sigma,
            config.marker_sat,
            config.marker_sat_sigma,
            config.min_saturation,
        ), config.min_value)
        self.learned_count = 0  # markers the last learn_markers call could use
        self.adapted_count = 0  # adapt() calls that changed the colour models
        self.skin = SkinModel(config)
        self.last_blobs: list[Blob] = []
        self._prev_uv: np.ndarray | None = None  # the blobs of the frame before last_blobs
        # mean BGR of the labelled markers and of the skin around them (learn_markers, adapt):
        # the two colours a motion-blurred marker's pixels mix (detect/streaks.py)
        self.marker_bgr: np.ndarray | None = None
        self.skin_bgr: np.ndarray | None = None
        self.last_region: SkinRegion | None = None
        self._focal = math.sqrt(camera.fx * camera.fy)
        self._last_diameter = math.nan
        self.blob_size = BlobSize()  # the blobs' typical length on the expected one, learned
        self._start_window()

    @property
    def reference(self) -> np.ndarray:
        """The learned marker reference histogram (H x S, peak 255), the default before."""
        return self.colour.reference

    @property
    def reference_learned(self) -> bool:
        return self.colour.learned is not None

    def set_reference(self, reference: np.ndarray) -> None:
        """Use ``reference`` (H x S histogram, any scale) as the learned marker colour (the
        default stays in use beside it: see :mod:`wristtrack.detect.marker_colour`)."""
        self.colour.set_learned(reference)

    # ------------------------------------------------------------------------------- frames

    def _check(self, bgr: np.ndarray, depth: np.ndarray | None) -> None:
        if not (isinstance(bgr, np.ndarray) and bgr.ndim == 3 and bgr.shape[2] == 3
                and bgr.dtype == np.uint8 and min(bgr.shape[:2]) >= 16):
            got = getattr(bgr, "shape", type(bgr).__name__), getattr(bgr, "dtype", "")
            raise InputError(f"colour frame must be a BGR uint8 (H, W, 3) array, got {got}")
        if depth is not None and (not isinstance(depth, np.ndarray)
                                  or depth.shape != bgr.shape[:2]):
            raise InputError(
                f"depth frame shape {getattr(depth, 'shape', None)} does not match the colour "
                f"frame {bgr.shape[:2]}; depth must be registered to colour, (H, W) uint16"
            )

    def detect(self, bgr: np.ndarray, depth: np.ndarray | None, timestamp: float,
               depth_delay: float | None = None) -> Detections:
        """Blob centres (sub-pixel) and depths (metres, trimmed mean; NaN where no valid pixel;
        None without a depth frame) of one frame; details in :attr:`last_blobs`.
        ``depth_delay``: the frame's (``Frame.depth_delay``), passed on to the tracker."""
        self._check(bgr, depth)
        h, w = bgr.shape[:2]
        blobs = None
        near = self._near_last_blobs((h, w))
        if near is not None:
            # only the window is downsampled and gated: no whole-frame work at all
            X0, Y0, X1, Y1 = near
            half = cv2.resize(bgr[Y0:Y1, X0:X1], ((X1 - X0) // 2, (Y1 - Y0) // 2),
                              interpolation=cv2.INTER_AREA)
            region = self.skin.window_region(half, near)
            blobs = self._search(bgr, half, depth, region)
            self.last_region = region
            if len(blobs) < len(self.last_blobs):  # something may lie outside: search it all
                blobs = None
        if blobs is None:
            half = cv2.resize(bgr, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
            region = self.skin.region(half, (h, w))
            self.last_region = region
            X0, Y0, X1, Y1 = region.box
            roi = half[Y0 // 2 : Y1 // 2, X0 // 2 : X1 // 2]
            blobs = self._search(bgr, roi, depth, region)
            if self.reference_learned and self._short(blobs):
                # markers lost under the learned colour (shade, a drifting light): again with
                # the default colour beside it (detect/marker_colour.py)
                more = self._search(bgr, roi, depth, region, wide=True)
                if len(more) > len(blobs):
                    blobs = more
            if region.found and self.skin.adapted and self._short(blobs):
                # Markers lost under the learned skin model (the light's colour drifted faster
                # than adapt() followed): the whole frame again, ungated, as before any skin was
                # known. The tracker's association sorts out what clutter that admits.
                whole = SkinRegion((0, 0, w - w % 2, h - h % 2), None, region.scale)
                more = self._search(bgr, half, depth, whole, wide=True)
                if len(more) > len(blobs):
                    blobs, self.last_region = more, whole
        blobs = blobs + self._missed_markers(bgr, depth, near, blobs, timestamp)
        self._prev_uv = np.array([b.uv for b in self.last_blobs]).reshape(-1, 2)
        self.last_blobs = blobs
        self._count(blobs)
        # the blobs as long as any (a minority of merged pairs leaves the median), not those
        # whose shape is cut (clipped, split, on the border) or smeared (a streak)
        self.blob_size.learn([(b.major, b.expected_diameter) for b in blobs
                              if b.reason in ("", "elongated")], self.config.psf_sigma_px)
        uv = np.array([b.uv for b in blobs], dtype=float).reshape(-1, 2)
        d = None if depth is None else np.array([b.depth for b in blobs], dtype=float)
        suspect = np.array([b.suspect for b in blobs], dtype=bool)
        return Detections(timestamp, uv, d, depth_image=depth, suspect=suspect,
                          depth_delay=depth_delay)

    def _short(self, blobs: list[Blob]) -> bool:
        """Fewer blobs than the last frame had markers (at most six): some may be missed."""
        return len(blobs) < min(len(self.last_blobs), len(MARKER_NAMES))

    def _search(self, bgr, half_roi, depth, region: SkinRegion, wide: bool = False) -> list[Blob]:
        """The blobs of one region (``half_roi``: its box at half resolution)."""
        if self.config.preset == "paper":
            return self._paper_search(bgr, depth, region)
        stack = self._candidates(bgr, half_roi, depth, region, wide)
        return [] if stack is None else self._classify(stack)

    def _paper_search(self, bgr, depth, region: SkinRegion) -> list[Blob]:
        """The paper's blobs of one region (detect/paper.py), none of them suspect."""
        found = paper_blobs(bgr, depth, region.box, self.colour, self.config)
        if found is None:
            return []
        uv, sh = found.uv, found.shape
        if self.config.require_skin and region.found:
            keep = region.on_skin(uv)
            uv = uv[keep]
        else:
            keep = np.ones(len(uv), bool)
        z = (np.full(len(keep), np.nan) if found.depth is None
             else found.depth * self.camera.depth_scale)
        return [Blob(uv=(float(uv_[0]), float(uv_[1])), area=float(found.area[k]),
                     depth=float(z[k]), similarity=float(found.similarity[k]),
                     major=float(sh.major[k]), minor=float(sh.minor[k]),
                     angle=float(sh.angle[k]), skew=float(sh.skew[k]),
                     expected_diameter=math.nan)
                for uv_, k in zip(uv, np.flatnonzero(keep).tolist(), strict=True)]

    def marker_mask(self, hsv: np.ndarray, wide: bool = False) -> np.ndarray:
        """uint8 0/255 mask of the pixels of an HSV image whose colour matches the reference
        (``wide``: the learned or the default one)."""
        bp = back_project(hsv, self.colour.wide_table if wide else self.colour.table)
        return cv2.threshold(bp, self.config.backproject_threshold * 255, 255,
                             cv2.THRESH_BINARY)[1]

    def _candidates(self, bgr, half_roi, depth, region: SkinRegion,
                    wide: bool = False) -> _Stack | None:
        """Marker candidates, found at half resolution (cheap), weighted at full resolution;
        ``half_roi`` is the region's box of the frame at half resolution."""
        cfg = self.config
        X0, Y0, X1, Y1 = region.box
        hx0, hy0 = X0 // 2, Y0 // 2
        hsv = cv2.cvtColor(half_roi, cv2.COLOR_BGR2HSV)
        n, labels, stats, cents = cv2.connectedComponentsWithStats(
            self.marker_mask(hsv, wide), connectivity=8, ltype=cv2.CV_16U
        )
        if n <= 1:
            return None
        stats, cents = stats[1:], cents[1:]
        x, y, bw, bh, area = stats.T
        ok = (area * 4 >= cfg.min_area_px) & (np.maximum(bw, bh) * 2 <= cfg.max_blob_px)
        if cfg.require_skin and region.found:
            # half-res pixel x covers full-res 2x, 2x+1: centre 2x + 0.5
            ok &= region.on_skin((cents + (hx0, hy0)) * 2 + 0.5)
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            return None
        idx = idx[np.argsort(-area[idx], kind="stable")[: cfg.max_candidates]]
        x, y, bw, bh = x[idx], y[idx], bw[idx], bh[idx]

        # One window size for all (half-res): the largest box plus the blur margin and a
        # 2-pixel background ring on each side, shifted to lie inside the search region.
        hh, hw = labels.shape
        mg = cfg.blur_margin
        pad = mg + 2
        sy = min(int(bh.max()) + 2 * pad, hh)
        sx = min(int(bw.max()) + 2 * pad, hw)
        wy0 = np.minimum(np.maximum(y + bh // 2 - sy // 2, 0), hh - sy)
        wx0 = np.minimum(np.maximum(x + bw // 2 - sx // 2, 0), hw - sx)
        lab = gather(labels, wy0, wx0, (sy, sx))
        core = lab == (idx + 1).astype(labels.dtype)[:, None, None]
        # the paper's test: each blob's colour histogram against the reference
        sims = self.colour.similarities(gather(hsv, wy0, wx0, (sy, sx)), core, wide)
        good = sims >= cfg.min_similarity
        if not good.any():
            return None
        if not good.all():
            x, y, bw, bh, wy0, wx0, lab, core, sims = (
                v[good] for v in (x, y, bw, bh, wy0, wx0, lab, core, sims))
        # support: the blob's box grown by the blur margin; the background ring is the rest
        iy, ix = np.arange(sy), np.arange(sx)
        in_y = (iy >= (y - mg - wy0)[:, None]) & (iy < (y + bh + mg - wy0)[:, None])
        in_x = (ix >= (x - mg - wx0)[:, None]) & (ix < (x + bw + mg - wx0)[:, None])
        box = in_y[:, :, None] & in_x[:, None, :]
        free = lab == 0
        ring = free & ~box
        # colour sums over the blob and over the ring as one batched matrix product
        nb = len(x)
        hp = gather(half_roi, wy0, wx0, (sy, sx)).reshape(nb, sy * sx, 3).astype(np.float64)
        sel = np.stack([core, ring], 1).reshape(nb, 2, sy * sx).astype(np.float64)
        sums = sel @ hp
        sq = sel[:, 1:] @ (hp * hp)
        n_core, n_ring = sel.sum(2).T
        m = sums[:, 0] / n_core[:, None]
        b = sums[:, 1] / np.maximum(n_ring, 1)[:, None]
        spread = np.sqrt(np.maximum(sq[:, 0] / np.maximum(n_ring, 1)[:, None] - b * b, 0).sum(1))
        contrast = np.sqrt(((m - b) ** 2).sum(1))
        keep = (n_ring >= 4) & (contrast >= cfg.min_contrast)
        if not keep.any():
            return None

        # full resolution
        gy, gx = 2 * (hy0 + wy0), 2 * (hx0 + wx0)
        patch = gather(bgr, gy, gx, (2 * sy, 2 * sx))
        t, brightness = blueness(patch, m, b)
        t = discount_highlights(t, brightness, patch, m, b, cfg.highlight_excess)
        mixed = np.flatnonzero(keep & (spread > cfg.mixed_background * contrast))
        if mixed.size:
            # each mixed blob's support (its box) unmixed against two background colours
            pm = patch[mixed]
            u, ok, bg, first = unmix_two_backgrounds_stack(
                pm, hp[mixed], ring[mixed].reshape(len(mixed), -1), m[mixed], b[mixed])
            # highlights judged against the background each pixel was unmixed from: against
            # the ring's mean, a white table by the hand's edge would pass for one
            u = np.where(first, *(discount_highlights(u, brightness[mixed], pm, m[mixed],
                                                      bg[:, k], cfg.highlight_excess)
                                  for k in (0, 1)))
            # (only the support is used below: the rest of each window is zeroed)
            t[mixed[ok]] = u[ok]
        # weights only inside the support, off other blobs; scaled so the bluest pixel is 1
        t *= upsample2(box & (free | core))
        peak = t.reshape(len(t), -1).max(1)
        keep &= peak > 0.5
        t /= np.where(keep, peak, 1.0).astype(np.float32)[:, None, None]
        dwin = None if depth is None else gather(depth, gy, gx, (2 * sy, 2 * sx))
        H, W = bgr.shape[:2]
        border = ((X0 + 2 * x <= 0) | (Y0 + 2 * y <= 0)
                  | (X0 + 2 * (x + bw) >= W - 1) | (Y0 + 2 * (y + bh) >= H - 1))
        st = _Stack(np.stack([gx, gy], 1)[keep], t[keep],
                    None if dwin is None else dwin[keep], sims[keep], border[keep])
        self._measure(st)
        return st

    def _measure(self, st: _Stack) -> None:
        """Shapes and depths (metres) of a stack, in place."""
        st.shape = shapes(st.w)
        if st.depth is None:
            st.z = np.full(len(st.w), np.nan)
        else:
            st.z = trimmed_depth(st.depth, st.w > DEPTH_CORE, self.config.depth_trim)
            st.z *= self.camera.depth_scale

    def _classify(self, st: _Stack) -> list[Blob]:
        cfg = self.config
        sh = st.shape
        with np.errstate(divide="ignore", invalid="ignore"):
            own_d = self._focal * cfg.marker_diameter_m / st.z
        # Expected marker diameter: from the blob's own depth where that agrees with the frame's
        # median (all markers are on one hand; a blob on the hand's edge may average in the
        # table behind), else the frame's median from depth, else the median blob length (most
        # blobs are single markers), else the previous frame's.
        finite = np.sort(own_d[np.isfinite(own_d)])
        if finite.size:
            frame_d = float(finite[finite.size // 2])
        elif len(sh.major) >= 3:
            frame_d = float(np.sort(sh.major)[len(sh.major) // 2])
        else:
            frame_d = self._last_diameter
        if frame_d > 0:
            self._last_diameter = frame_d
        with np.errstate(invalid="ignore"):
            agree = np.abs(own_d - frame_d) <= cfg.depth_size_tolerance * frame_d
        exp_d = np.where(agree, own_d, frame_d)
        ratio = sh.major / (expected_length(exp_d, cfg.psf_sigma_px) * self.blob_size.scale)
        ok = (sh.mass >= cfg.min_area_px) & (sh.minor >= cfg.min_axis_ratio * sh.major)
        with np.errstate(invalid="ignore"):
            ok &= ~((ratio < cfg.min_size_ratio) | (ratio > cfg.max_size_ratio))
            long = ok & (ratio > cfg.merge_ratio)
        # A long blob may be two markers side by side. Two touching discs fill 0.89 of their
        # moment ellipse at any view, but the image noise over the pair's wider support
        # inflates its second moments more than a single marker's: the fill test judges the
        # two parts, not the pair.
        filled = self._filled(sh)
        blobs = []
        for k in np.flatnonzero(ok).tolist():
            reason = "border" if st.border[k] else ""
            if long[k]:
                parts = self._split(st, k, float(exp_d[k]))
                if parts:
                    blobs.extend(parts)
                    continue
                reason = reason or "elongated"
            if not filled[k]:
                continue
            if not reason and sh.skew[k] > cfg.max_skew:
                reason = "clipped"
            blobs.append(self._blob(st, k, float(exp_d[k]), reason))
        return blobs

    def _filled(self, sh: Shapes) -> np.ndarray:
        """Whether each blob's weight fills enough of its moment ellipse (a regular shape)."""
        return sh.mass >= self.config.min_fill * np.pi / 4 * sh.major * sh.minor

    @staticmethod
    def _blob(st: _Stack, k: int, expected: float, reason: str) -> Blob:
        sh = st.shape
        return Blob(
            uv=(float(st.origin[k, 0] + sh.cx[k]), float(st.origin[k, 1] + sh.cy[k])),
            area=float(sh.mass[k]),
            depth=float(st.z[k]),
            similarity=float(st.similarity[k]),
            major=float(sh.major[k]),
            minor=float(sh.minor[k]),
            angle=float(sh.angle[k]),
            skew=float(sh.skew[k]),
            expected_diameter=expected,
            suspect=bool(reason),
            reason=reason,
        )

    def _split(self, st: _Stack, k: int, expected: float) -> list[Blob]:
        """The two markers of an elongated blob, or [] if it has no waist to cut at."""
        cfg = self.config
        sh = st.shape
        halves = split_pair(st.w[k], sh.cx[k], sh.cy[k], sh.angle[k], cfg.waist_ratio,
                            cfg.split_min_mass_ratio)
        if halves is None:
            return []
        two = _Stack(st.origin[[k, k]], st.w[k] * np.stack(halves),
                     None if st.depth is None else st.depth[[k, k]],
                     st.similarity[[k, k]], st.border[[k, k]])
        self._measure(two)
        if not self._filled(two.shape).all():
            return []
        return [self._blob(two, j, expected, "split") for j in range(2)]
