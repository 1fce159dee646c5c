"""Marker colour model: hue-saturation histograms, back-projection, Bhattacharyya similarity.

Colours are compared in OpenCV's 8-bit HSV (hue 0..179 in 2-degree steps, saturation 0..255):
hue and saturation do not change when the light gets brighter or dimmer, value (brightness)
does, so value is only used to gate out pixels too dark for their hue to mean anything. Blue
sits near hue 110, far from the 0/180 wrap, which is therefore ignored.

The reference histogram (H x S bins) is both the lookup table of ``cv2.calcBackProject``
(scaled so its peak is 255) and the template every blob's own histogram is compared with.
``cv2.compareHist(..., HISTCMP_BHATTACHARYYA)`` returns the Hellinger *distance*
d = sqrt(1 - BC) between the normalised histograms; we report the Bhattacharyya *coefficient*
BC = 1 - d**2 in [0, 1] (1 = same distribution), as the paper does.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

HS_RANGES = [0, 180, 0, 256]
HS_CHANNELS = [0, 1]
# Histograms are smoothed by this many bins (Gaussian sigma) before use: a blob is a few dozen
# pixels, so its raw histogram is spiky, and a marker seen under slightly different light should
# still land on the reference.
SMOOTH_BINS = 1.0


def smooth(hist: np.ndarray) -> np.ndarray:
    """Histogram blurred by SMOOTH_BINS (edges not wrapped), float32."""
    return cv2.GaussianBlur(
        np.asarray(hist, np.float32), (0, 0), SMOOTH_BINS, borderType=cv2.BORDER_CONSTANT
    )


def gaussian_reference(
    bins: tuple[int, int],
    hue: float,
    hue_sigma: float,
    sat: float,
    sat_sigma: float,
    min_sat: float,
) -> np.ndarray:
    """Default marker histogram before any marker was labelled: a Gaussian in (H, S) around the
    nominal marker colour, zero below ``min_sat`` (greys have an arbitrary hue)."""
    h = (np.arange(bins[0]) + 0.5) * 180 / bins[0]
    s = (np.arange(bins[1]) + 0.5) * 256 / bins[1]
    g = np.exp(-0.5 * ((h[:, None] - hue) / hue_sigma) ** 2
               - 0.5 * ((s[None] - sat) / sat_sigma) ** 2)
    g[:, s < min_sat] = 0.0
    return lut_scaled(g)


def lut_scaled(hist: np.ndarray) -> np.ndarray:
    """Histogram scaled to a peak of 255: back-projection then gives 0..255 per pixel."""
    hist = np.asarray(hist, np.float32)
    peak = float(hist.max())
    if peak <= 0:
        raise ValueError("empty colour histogram")
    return hist * np.float32(255.0 / peak)


def hs_histogram(hsv: np.ndarray, mask: np.ndarray | None, bins: tuple[int, int]) -> np.ndarray:
    """Raw (H, S) histogram of the pixels of ``hsv`` where ``mask`` is nonzero."""
    return cv2.calcHist([hsv], HS_CHANNELS, mask, list(bins), HS_RANGES)


V_BINS = 8  # value gate resolution in the back-projection table (32 levels a bin)


def backprojection_table(reference: np.ndarray, min_value: int):
    """(H, S, V) lookup table for :func:`back_project`: the (H, S) reference, zero in the value
    bins darker than ``min_value`` (so the gate costs nothing extra per pixel)."""
    centres = (np.arange(V_BINS) + 0.5) * 256 / V_BINS
    table = np.asarray(reference, np.float32)[..., None] * (centres >= min_value)
    # a 3-D numpy array would reach OpenCV as a 2-D image with V_BINS channels
    return cv2.Mat(np.ascontiguousarray(table, np.float32), wrap_channels=False)


def back_project(hsv: np.ndarray, table) -> np.ndarray:
    """uint8 image: the table's value (0..255) at each pixel's (H, S, V)."""
    return cv2.calcBackProject([hsv], [0, 1, 2], table, HS_RANGES + [0, 256], 1)


@functools.cache
def _smoothing_matrix(n: int) -> np.ndarray:
    """(n, n) matrix applying smooth()'s 1-D kernel with a zero border: K @ h == blur of h."""
    k = cv2.getGaussianKernel(int(round(SMOOTH_BINS * 4 * 2 + 1)) | 1, SMOOTH_BINS, cv2.CV_64F)
    r = k.size // 2
    offset = np.arange(n)[None, :] - np.arange(n)[:, None]
    return np.where(np.abs(offset) <= r, k.ravel()[np.clip(offset + r, 0, 2 * r)], 0.0)


def blob_similarities(hsv: np.ndarray, masks: np.ndarray, reference: np.ndarray,
                      *others: np.ndarray) -> np.ndarray:
    """Bhattacharyya coefficients (n,) between the smoothed (H, S) histogram of the pixels of
    each HSV window ``hsv`` (n, sy, sx, 3) where ``masks`` (n, sy, sx) is set and
    ``reference``, all blobs at once; with ``others`` (more references of the same shape), each
    blob's largest coefficient over all of them (its histogram is built once).

    Equal to ``bhattacharyya(smooth(hs_histogram(hsv[i], masks[i], bins)), reference)`` for each
    i (same binning as cv2.calcHist, same kernel as smooth()), without a per-blob loop.
    """
    hb, sb = reference.shape
    n = masks.shape[0]
    row, yy, xx = np.nonzero(masks)
    px = hsv[row, yy, xx].astype(np.int64)
    bin_ = (px[:, 0] * hb // 180) * sb + px[:, 1] * sb // 256
    counts = np.bincount(row * (hb * sb) + bin_, minlength=n * hb * sb)
    h = _smoothing_matrix(hb) @ counts.reshape(n, hb, sb).astype(np.float64) \
        @ _smoothing_matrix(sb).T
    root = np.sqrt(h)
    total = h.sum(axis=(1, 2))
    best = np.zeros(n)
    for ref in (reference, *others):
        ref = np.asarray(ref, np.float64)
        num = (root * np.sqrt(ref)).sum(axis=(1, 2))
        den = np.sqrt(total * ref.sum())
        best = np.maximum(best, np.divide(num, den, out=np.zeros(n), where=den > 0))
    return best


def bhattacharyya(hist: np.ndarray, reference: np.ndarray) -> float:
    """Bhattacharyya coefficient in [0, 1] of two non-empty histograms (OpenCV normalises)."""
    d = cv2.compareHist(hist, reference, cv2.HISTCMP_BHATTACHARYYA)
    return float(max(0.0, 1.0 - d * d))
