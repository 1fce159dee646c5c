"""The paper's marker detection as published (Cordella et al., section III-A): the ``paper``
preset of the detector (``DetectorConfig.paper()``, ``wristtrack track --detector paper``).

The paper: locate the hand by skin colour to get a region of interest; in it, extract the blobs
whose colour histogram is closest (Bhattacharyya coefficient) to the reference histogram of the
blue marker colour; label connected components; each blob's centre is a measurement. Here, in
the region of interest the detector's skin model gives (the fixed YCrCb box, never adapted):

1. marker pixels: back-projection of the fixed reference histogram, thresholded, at full
   resolution;
2. 8-connected components of at least ``min_area_px`` pixels (the ``max_candidates`` largest);
3. each kept when the Bhattacharyya coefficient of its (H, S) histogram with the reference is at
   least ``min_similarity``;
4. its centre: the centroid of its pixels; its depth: the median of its valid depth pixels.

Left out, being ours and not the paper's: the blueness-weighted sub-pixel centroid and the
unmixing of two backgrounds (detect/blobs.py), size and shape tests against the expected
marker, the splitting of merged blobs and the suspect flags, the contrast test, the per-blob
skin gate, the subject's skin model and the learned and adapted marker colour
(detect/learning.py), the search in a tracked window and the fallback searches, and the
streak model of motion blur (detect/streaks.py). Kept, as any implementation needs one: the
value gate of the colour table (too dark for a hue), the smoothing of the histograms compared
(a blob is a few dozen pixels), and a minimum blob area against single-pixel noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.detect.blobs import Shapes, gather, shapes
from wristtrack.detect.colour import back_project
from wristtrack.detect.marker_colour import MarkerColour


@dataclass
class PaperBlobs:
    """The blobs of one frame, full-resolution pixels; ``depth`` in the depth image's units
    (NaN where no valid pixel; None without a depth image); ``shape`` of the binary masks (for
    the blob details only: nothing is decided on it)."""

    uv: np.ndarray  # (n, 2)
    area: np.ndarray  # (n,) pixels
    similarity: np.ndarray  # (n,)
    depth: np.ndarray | None
    shape: Shapes


def paper_blobs(bgr: np.ndarray, depth: np.ndarray | None, box: tuple[int, int, int, int],
                colour: MarkerColour, cfg) -> PaperBlobs | None:
    """The paper's blobs in the region ``box`` (x0, y0, x1, y1, full resolution) of ``bgr``;
    ``cfg`` a DetectorConfig. None when there is none."""
    X0, Y0, X1, Y1 = box
    hsv = cv2.cvtColor(bgr[Y0:Y1, X0:X1], cv2.COLOR_BGR2HSV)
    mask = cv2.threshold(back_project(hsv, colour.table), cfg.backproject_threshold * 255, 255,
                         cv2.THRESH_BINARY)[1]
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8,
                                                               ltype=cv2.CV_32S)
    if n <= 1:
        return None
    stats, cents = stats[1:], cents[1:]
    x, y, bw, bh, area = stats.T
    idx = np.flatnonzero(area >= cfg.min_area_px)
    if idx.size == 0:
        return None
    idx = idx[np.argsort(-area[idx], kind="stable")[: cfg.max_candidates]]
    # every blob's box in one window size, shifted to lie inside the region
    hh, hw = labels.shape
    sy, sx = int(bh[idx].max()), int(bw[idx].max())
    wy0 = np.minimum(y[idx], hh - sy)
    wx0 = np.minimum(x[idx], hw - sx)
    own = gather(labels, wy0, wx0, (sy, sx)) == (idx + 1)[:, None, None]
    sims = colour.similarities(gather(hsv, wy0, wx0, (sy, sx)), own)
    good = sims >= cfg.min_similarity
    if not good.any():
        return None
    idx, wy0, wx0, own, sims = idx[good], wy0[good], wx0[good], own[good], sims[good]
    z = None
    if depth is not None:
        win = gather(depth, wy0 + Y0, wx0 + X0, (sy, sx))
        z = np.array([np.median(d[m & (d > 0)]) if (m & (d > 0)).any() else np.nan
                      for d, m in zip(win, own, strict=True)])
    return PaperBlobs(uv=cents[idx] + (X0, Y0), area=area[idx].astype(float), similarity=sims,
                      depth=z, shape=shapes(own.astype(np.float64)))
