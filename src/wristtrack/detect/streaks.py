"""Markers the colour reference misses, found by chromaticity where the markers should be:
streaks of motion blur, and markers in the shade.

A marker moving at 1-1.5 m/s, 0.6 m away, under a 1/60-1/30 s shutter smears into a streak
40-50 px long and one marker wide. Each pixel of the streak saw the marker for only a fraction
of the exposure, so its colour is a mix of a little marker blue and much skin: its hue and
saturation no longer match the marker's reference, and the colour detector finds nothing.

Here every pixel of a window is placed on the segment from the skin's chromaticity to the
marker's (chromaticity: colour divided by its brightness, so shading and exposure do not move
it): t = (c - c_skin).(c_marker - c_skin) / |c_marker - c_skin|^2, the fraction of the exposure
the marker covered it, mixing being linear. Components of t above a small threshold are
streaks when their width fits one marker diameter (the blur does not widen a streak across its
motion) and their length at most MAX_STREAK_RATIO diameters. The t-weighted centroid of a
streak is the marker's centre at mid-exposure, the frame's timestamp: the same quantity a
sharp blob gives, with the streak's length along its direction as extra uncertainty.

A marker in the lamp's shade (a hand turned away from it: ulnar deviation with supination at
extension) is lit by the ambient light alone, a third of full light. Its pixels are dark enough
that the codec's and the demosaicing's chroma errors, absolute in size, take most of its
saturation (0.3-0.5 where lit markers show 0.8; value 40-60 of 255) and drift its hue toward
the skin's: the hue-saturation reference rejects it. Its chromaticity still lies well along the
skin-to-marker segment (t 0.3-0.6), but the shaded skin's has drifted a little too (t -0.1 to
0.2 from the skin learned under the lamp). So there t is taken above the skin around each
pixel (``skin_around``), and a blob one marker long standing SHADE_CONTRAST above the skin
around it is a marker in the shade (:func:`is_shaded_marker`); a grey edge, an occluder's mixed
with the skin, stands a third as far.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from wristtrack.detect.blobs import shapes, trimmed_depth
from wristtrack.detect.config import DetectorConfig

MIN_FRACTION = 0.12  # a pixel is part of a streak when the marker covered it this long
MAX_STREAK_RATIO = 8.0  # streak length / marker diameter above: not one marker
STREAK_RATIO = 1.3  # length / marker diameter above: a streak (below: one sharp marker)
# A marker in the shade (is_shaded_marker): at most this long (diameters; the grown weights
# make a round marker 1.0-1.45 diameters) and this far along the marker's chromaticity above
# the skin around it.
SHADE_MAX_LENGTH = 1.6
SHADE_CONTRAST = 0.4
# A shaded marker's weights gather at its core (its fringe is the skin's colour): its width
# measures 0.55-0.8 diameters, and less seen obliquely.
SHADE_MIN_WIDTH = 0.35
WIDTH_RATIO = (0.5, 1.8)  # streak width / marker diameter (the PSF and edge mixing widen it)
MIN_MASS = 0.5  # streak mass (sum of t) / marker disc area below: too faint to trust
GROW_PX = 3  # the thresholded streak is grown by this to take in its faint ends


class ChromaBlob(NamedTuple):
    """A blob of marker chromaticity: centre (u, v) px, depth in the depth image's units (NaN
    if none), length and width px, direction rad; ``contrast`` its peak t above the skin around
    it."""

    u: float
    v: float
    depth: float
    length: float
    width: float
    angle: float
    contrast: float


def chromaticity(bgr: np.ndarray) -> np.ndarray:
    """(..., 3) colour divided by its channel sum (1 for black, to avoid a division by 0)."""
    c = np.asarray(bgr, np.float32)
    return c / np.maximum(c.sum(axis=-1, keepdims=True), 1.0)


def find_chroma_blobs(
    bgr: np.ndarray,
    depth: np.ndarray | None,
    box: tuple[int, int, int, int],
    marker_bgr: np.ndarray,
    skin_bgr: np.ndarray,
    diameter_px: float,
    skin_around: bool = False,
    depth_trim: tuple[float, float] = DetectorConfig().depth_trim,
) -> list[ChromaBlob]:
    """Blobs of marker chromaticity one marker diameter ``diameter_px`` wide in the window
    ``box`` (x0, y0, x1, y1) of ``bgr``, streaks (longer than STREAK_RATIO diameters) or not
    (:func:`is_shaded_marker` tells a marker in the shade). ``marker_bgr`` and ``skin_bgr`` are
    the two colours mixed. ``skin_around``: each pixel's t taken above the skin around it, not
    above ``skin_bgr`` (for the shade: see below). A blob's depth is the trimmed mean of its
    core's readings, between the ``depth_trim`` quantiles, as the colour search's."""
    x0, y0, x1, y1 = box
    win = bgr[y0:y1, x0:x1]
    cs, cm = chromaticity(skin_bgr), chromaticity(marker_bgr)
    axis = cm - cs
    norm2 = float(axis @ axis)
    if norm2 < 1e-6 or not diameter_px > 0:
        return []
    t = (chromaticity(win) - cs) @ (axis / norm2)
    if skin_around:
        # The median over four marker diameters is the skin under a marker (markers cover a
        # minority of it), so the hand's shaded side, whose chromaticity has drifted toward
        # the marker's (t 0.1-0.2), does not pass for one large blob. (In uint8 steps of 1/64:
        # OpenCV's median of a wide window takes 8-bit images only.)
        wide = 4 * int(diameter_px) + 1
        skin = cv2.medianBlur(np.clip(np.round((t + 1.0) * 64.0), 0, 255).astype(np.uint8),
                              wide)
        t = t - (skin.astype(np.float32) / 64.0 - 1.0)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(
        (t > MIN_FRACTION).astype(np.uint8), connectivity=8)
    narrowest = SHADE_MIN_WIDTH if skin_around else WIDTH_RATIO[0]
    out = []
    disc = np.pi / 4 * diameter_px**2
    g = GROW_PX
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))
    for k in range(1, n):
        bx, by, bw, bh, area = stats[k]
        if area < 0.3 * disc or max(bw, bh) > (MAX_STREAK_RATIO + 1) * diameter_px:
            continue
        if bx == 0 or by == 0 or bx + bw == t.shape[1] or by + bh == t.shape[0]:
            continue  # cut by the window: its centre cannot be trusted
        # the component grown by a few pixels: a streak's faint ends (each end pixel saw the
        # marker briefly) lie below the threshold; weights unclipped, so the skin's noise
        # around it averages out instead of pulling the centre. The ring beyond (as wide again,
        # off other components) is the skin the blob's contrast is taken against, and with
        # ``skin_around`` its weights: the skin right around a marker in the shade is not
        # the median over four diameters (a few hundredths either way, which over the grown
        # support weigh as much as the marker's core).
        gx0, gy0 = max(bx - 2 * g, 0), max(by - 2 * g, 0)
        sl = (slice(gy0, by + bh + 2 * g), slice(gx0, bx + bw + 2 * g))
        mask = cv2.dilate((labels[sl] == k).astype(np.uint8), grow) > 0
        ring = (cv2.dilate(mask.astype(np.uint8), grow) > 0) & ~mask & (labels[sl] == 0)
        base = float(np.median(t[sl][ring])) if ring.any() else 0.0
        w = np.where(mask, t[sl] - (base if skin_around else 0.0), 0.0)
        if w.sum() < MIN_MASS * disc * 0.5:
            continue
        bx, by = gx0, gy0
        sh = shapes(w[None].astype(np.float64))
        width, length = float(sh.minor[0]), float(sh.major[0])
        if not (narrowest * diameter_px <= width <= WIDTH_RATIO[1] * diameter_px):
            continue
        if length > MAX_STREAK_RATIO * diameter_px:
            continue  # not one marker
        z = np.nan
        if depth is not None:
            z = float(trimmed_depth(depth[y0:y1, x0:x1][sl][None], (w > 0.3)[None],
                                    depth_trim)[0])
        out.append(ChromaBlob(x0 + bx + float(sh.cx[0]), y0 + by + float(sh.cy[0]), z, length,
                              width, float(sh.angle[0]), float(t[sl][mask].max()) - base))
    return out


def is_shaded_marker(blob: ChromaBlob, diameter_px: float) -> bool:
    """Whether ``blob`` is one marker in the shade, not a fringe of skin or an edge: one marker
    long and well along the marker's chromaticity above the skin around it (rendered: shaded
    markers 0.5-1.0; the edge of a dark pen over the skin, mixed with it, 0.25-0.33; the
    background 0.16-0.21)."""
    return blob.length < SHADE_MAX_LENGTH * diameter_px and blob.contrast >= SHADE_CONTRAST
