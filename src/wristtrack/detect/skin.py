"""Skin region of interest for the marker detector (paper section III-A, first step).

Skin is classified in YCrCb on a downsampled frame: chroma (Cr, Cb) separates skin from most
backgrounds and changes little with brightness, and luma Y only gates out pixels too dark for
their chroma to mean anything. The classifier is a lookup table over (Y, Cr, Cb) bins applied by
``cv2.calcBackProject``, so a fixed box and a fitted ellipse cost the same per pixel:

- at start, the fixed box of Chai & Ngan (1999): Cr in [133, 173], Cb in [77, 127];
- once fitted (from the skin found in the first frames, or from the hand around the labelled
  markers in :meth:`SkinModel.learn`), the subject's own chroma: a Gaussian (mean, covariance in
  CrCb) and a Mahalanobis-distance threshold.

The mask is dilated (closing the holes the markers punch in it and reaching markers on the hand's
edge); its largest components give a bounding box with a margin (the region searched for markers)
and a gate (blobs whose centre is off the dilated skin are ignored: clutter on the table). A
component covering most of the picture is a skin-coloured background (a beige table), not a
hand; with no other, the whole image is searched without a gate, and the model does not adapt
to it (learn_markers, which knows where the hand is, fixes such a scene).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

# LUT resolution: Y only gates, so 8 bins of 32 levels; chroma in bins of 4 levels (skin
# clusters are tens of levels wide, so 4 loses nothing).
Y_BINS = 8
C_BINS = 64
_RANGES = [0, 256, 0, 256, 0, 256]
_CHANNELS = [0, 1, 2]


def _bin_centres(n: int) -> np.ndarray:
    width = 256 / n
    return (np.arange(n) + 0.5) * width


def _y_gate(y_min: int) -> np.ndarray:
    """(Y_BINS,) bool: luma bins bright enough for chroma to be trusted."""
    return _bin_centres(Y_BINS) >= y_min


def box_skin_lut(cr: tuple[float, float], cb: tuple[float, float], y_min: int) -> np.ndarray:
    """(Y, Cr, Cb) lookup table, 255 inside the chroma box (bin centres), 0 outside."""
    c = _bin_centres(C_BINS)
    in_cr = (c >= cr[0]) & (c <= cr[1])
    in_cb = (c >= cb[0]) & (c <= cb[1])
    lut = _y_gate(y_min)[:, None, None] & in_cr[None, :, None] & in_cb[None, None, :]
    return lut.astype(np.float32) * 255.0


def mahalanobis_skin_lut(
    mean: np.ndarray, cov: np.ndarray, threshold: float, y_min: int
) -> np.ndarray:
    """(Y, Cr, Cb) lookup table, 255 where the (Cr, Cb) Mahalanobis distance <= threshold."""
    c = _bin_centres(C_BINS)
    d = np.stack(np.meshgrid(c, c, indexing="ij"), -1) - np.asarray(mean)  # (C, C, 2)
    d2 = np.einsum("...i,ij,...j->...", d, np.linalg.inv(cov), d)
    lut = _y_gate(y_min)[:, None, None] & (d2 <= threshold * threshold)[None]
    return lut.astype(np.float32) * 255.0


def fit_chroma(crcb: np.ndarray, min_sigma: float, n_min: int) -> tuple[np.ndarray, np.ndarray]:
    """Robust Gaussian of (N,2) chroma samples: fit, drop samples beyond 3 sigma, refit.

    The covariance gets ``min_sigma**2`` added on its diagonal so a very uniform patch of skin
    does not give a model too tight for the next frame's noise and shading. Raises ValueError
    when there are fewer than ``n_min`` samples.
    """
    x = np.asarray(crcb, dtype=np.float64).reshape(-1, 2)
    for _ in range(2):
        if x.shape[0] < n_min:
            raise ValueError(f"{x.shape[0]} skin samples, need {n_min}")
        mean = x.mean(0)
        cov = np.cov(x, rowvar=False) + np.eye(2) * min_sigma**2
        d = x - mean
        keep = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d) <= 9.0
        x = x[keep]
    return mean, cov


@dataclass(frozen=True)
class SkinRegion:
    """Where to look for markers in one frame.

    ``box`` (x0, y0, x1, y1) is full-resolution, end-exclusive. ``gate`` is the dilated skin
    mask at 1/``scale`` resolution (nonzero = on or next to skin), None when no skin was found
    and the whole image is searched.
    """

    box: tuple[int, int, int, int]
    gate: np.ndarray | None
    scale: int

    @property
    def found(self) -> bool:
        return self.gate is not None

    def on_skin(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool: full-resolution points (N,2) inside the gate (all True without a gate)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if self.gate is None:
            return np.ones(uv.shape[0], bool)
        h, w = self.gate.shape
        # pixel centres at integers: full-res u covers low-res column floor((u + 0.5) / scale)
        # (np.clip is slow on tiny arrays)
        c = np.minimum(np.maximum(((uv[:, 0] + 0.5) // self.scale).astype(int), 0), w - 1)
        r = np.minimum(np.maximum(((uv[:, 1] + 0.5) // self.scale).astype(int), 0), h - 1)
        return self.gate[r, c] > 0


class SkinModel:
    """Skin classifier that adapts to the subject; gives each frame's :class:`SkinRegion`.

    ``config`` is a :class:`wristtrack.detect.detector.DetectorConfig` (only its ``skin_*`` and
    ``roi_margin_px`` fields are read).
    """

    def __init__(self, config) -> None:
        self.config = config
        self.lut = box_skin_lut(config.skin_cr, config.skin_cb, config.skin_y_min)
        self.mean: np.ndarray | None = None  # fitted CrCb Gaussian, None while on the fixed box
        self.cov: np.ndarray | None = None
        self._frames_seen = 0
        self._acc = np.zeros(6)  # n, sum cr, sum cb, sum cr^2, sum cr*cb, sum cb^2
        s = max(int(config.skin_dilate_px / config.skin_downsample + 0.5), 1)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * s + 1, 2 * s + 1))

    @property
    def adapted(self) -> bool:
        return self.mean is not None

    def set_gaussian(self, mean: np.ndarray, cov: np.ndarray) -> None:
        """Switch to the subject's chroma model (Mahalanobis threshold from the config)."""
        self.mean, self.cov = np.asarray(mean, float), np.asarray(cov, float)
        self.lut = mahalanobis_skin_lut(
            self.mean, self.cov, self.config.skin_mahalanobis, self.config.skin_y_min
        )

    @property
    def lut(self) -> np.ndarray:
        """(Y, Cr, Cb) lookup table in use, 0 or 255."""
        return np.asarray(self._lut)

    @lut.setter
    def lut(self, table: np.ndarray) -> None:
        # A 3-D numpy array would reach OpenCV as a 2-D image with 64 channels; wrap it as a
        # true 3-D Mat for calcBackProject.
        self._lut = cv2.Mat(np.ascontiguousarray(table, np.float32), wrap_channels=False)

    def mask(self, ycrcb: np.ndarray) -> np.ndarray:
        """uint8 0/255 skin mask of a YCrCb image."""
        return cv2.calcBackProject([ycrcb], _CHANNELS, self._lut, _RANGES, 1)

    def region(self, half: np.ndarray, full_shape: tuple[int, int]) -> SkinRegion:
        """Skin region of interest, from the frame at half resolution (the detector's search
        image); ``full_shape`` (H, W) of the full frame. The box is in full-resolution pixels,
        on even coordinates (so it maps exactly onto the half-resolution image)."""
        cfg = self.config
        s = cfg.skin_downsample
        h, w = full_shape
        small = cv2.resize(half, (w // s, h // s), interpolation=cv2.INTER_AREA)
        ycc = cv2.cvtColor(small, cv2.COLOR_BGR2YCrCb)
        skin = self.mask(ycc)
        grown = cv2.dilate(skin, self._kernel)
        # (BBDT with 32-bit labels: the same labelling as the default, measurably faster)
        n, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
            grown, 8, cv2.CV_32S, cv2.CCL_BBDT)
        areas = stats[1:, cv2.CC_STAT_AREA].copy()
        whole = SkinRegion((0, 0, w - w % 2, h - h % 2), None, s)
        # A "skin" component covering most of the picture is a skin-coloured background (a
        # beige table, a wall), not a hand: it cannot locate anything.
        pixels = small.shape[0] * small.shape[1]
        areas[areas > cfg.skin_max_fraction * pixels] = 0
        if n <= 1 or areas.max() < cfg.skin_min_fraction * pixels:
            return whole
        order = np.argsort(areas)[::-1][: cfg.skin_max_components]
        keep = [int(i) + 1 for i in order if areas[i] >= cfg.skin_component_ratio * areas[order[0]]]
        if len(keep) == 1:
            gate = (labels == keep[0]).view(np.uint8)
        else:
            gate = np.isin(labels, keep).view(np.uint8)
        st = stats[keep]
        x0, y0 = st[:, 0].min(), st[:, 1].min()
        x1, y1 = (st[:, 0] + st[:, 2]).max(), (st[:, 1] + st[:, 3]).max()
        m = cfg.roi_margin_px // 2 * 2
        box = (max(int(x0) * s - m, 0), max(int(y0) * s - m, 0),
               min(int(x1) * s + m, w - w % 2), min(int(y1) * s + m, h - h % 2))
        if not self.adapted and cfg.skin_adapt_frames > 0:
            self._accumulate(ycc, skin, labels == keep[0])
        return SkinRegion(box, gate, s)

    def _accumulate(self, ycc: np.ndarray, skin: np.ndarray, component: np.ndarray) -> None:
        """Gather the chroma of the main skin component; fit once enough frames were seen."""
        # Erode so the samples are skin, not its blend with the background at the boundary.
        inner = cv2.erode(skin, None) > 0
        crcb = ycc[inner & component][:, 1:3].astype(np.float64)
        cr, cb = crcb[:, 0], crcb[:, 1]
        self._acc += (len(cr), cr.sum(), cb.sum(), cr @ cr, cr @ cb, cb @ cb)
        self._frames_seen += 1
        if self._frames_seen < self.config.skin_adapt_frames:
            return
        n, scr, scb, scc, scrb, sbb = self._acc
        if n < self.config.skin_min_samples:
            return  # keep gathering
        mean = np.array([scr, scb]) / n
        cov = np.array([[scc, scrb], [scrb, sbb]]) / n - np.outer(mean, mean)
        self.set_gaussian(mean, cov + np.eye(2) * self.config.skin_min_sigma**2)

    def learn(self, bgr: np.ndarray, mask: np.ndarray) -> bool:
        """Fit the subject's chroma from the pixels of ``bgr`` where ``mask`` is nonzero
        (skin known from the labelled markers). False (model unchanged) if too few are usable."""
        ycc = cv2.cvtColor(bgr, cv2.COLOR_BGR2YCrCb)
        sel = (mask > 0) & (ycc[..., 0] >= self.config.skin_y_min)
        try:
            mean, cov = fit_chroma(
                ycc[sel][:, 1:3], self.config.skin_min_sigma, self.config.skin_min_samples
            )
        except ValueError:
            return False
        self.set_gaussian(mean, cov)
        return True
