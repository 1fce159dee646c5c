"""Skin region of interest for the marker detector (paper section III-A, first step).

Skin is classified in YCrCb on a downsampled frame: chroma (Cr, Cb) separates skin from most
backgrounds and changes little with brightness, and luma Y only gates out pixels too dark for
their chroma to mean anything. The classifier is a lookup table over (Y, Cr, Cb) bins applied by
``cv2.calcBackProject``, so a fixed box and a fitted ellipse cost the same per pixel:

- at start, the fixed box of Chai & Ngan (1999): Cr in [133, 173], Cb in [77, 127];
- once fitted (from the skin found in the first frames, or from the hand around the labelled
  markers in :meth:`SkinModel.learn`), the subject's own chroma: a Gaussian (mean, covariance in
  CrCb) and a Mahalanobis-distance threshold. The Gaussian is illumination-invariant: in 8-bit
  YCrCb a surface lit k times brighter has k times the luma and k times the chroma offset from
  grey (128), so the samples are normalised to the model's luma before fitting and the model is
  scaled to each luma bin of the table. A hand turned away from the light (pronation,
  extension) keeps its skin; a fixed chroma Gaussian loses it and, with it, the markers on it.
- :meth:`SkinModel.adapt` follows a slow change of the light's colour from skin known around
  confidently labelled markers, with the mean held within a bounded distance of the first fit.

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

# LUT resolution: luma in bins of 8 levels (the fitted model is scaled with luma, so finer than
# the gate alone would need); chroma in bins of 4 levels (skin clusters are tens of levels wide).
Y_BINS = 32
_Y_SUBSAMPLES = 4  # luma values per bin at which the scaled model is evaluated (then OR-ed)
# Adaptation (SkinModel.adapt): weight of a new frame's fit, and how far (Mahalanobis, in the
# first fit's covariance) the adapted mean may wander from the first fit before updates stop.
ADAPT_RATE = 0.1
ADAPT_MAX_DRIFT = 3.0
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
    mean: np.ndarray,
    cov: np.ndarray,
    threshold: float,
    y_min: int,
    luma: float | None = None,
    floor: float = 0.0,
) -> np.ndarray:
    """(Y, Cr, Cb) lookup table, 255 where the (Cr, Cb) Mahalanobis distance <= threshold.

    Without ``luma`` the same Gaussian serves every luma. With ``luma`` (the mean luma Y0 of the
    samples the Gaussian was fitted to) it is scaled to each luma Y: mean 128 + (mean - 128) Y/Y0
    and covariance (cov - floor^2 I)(Y/Y0)^2 + floor^2 I (``floor``: the noise part, in levels,
    that does not scale), evaluated at a few lumas across each bin.
    """
    mean, cov = np.asarray(mean, float), np.asarray(cov, float)
    gate = _y_gate(y_min)
    if luma is None:
        d2 = _chroma_distance2(mean, cov, 0.0, np.ones(1))[0]
        lut = gate[:, None, None] & (d2 <= threshold * threshold)[None]
        return lut.astype(np.float32) * 255.0
    # Every gated bin's lumas at once: the table is made again each time the skin model adapts
    # (every tenth frame or so), and bin by bin that cost 16-18 ms, 8x a frame's detection.
    width = 256 / Y_BINS
    bins = np.flatnonzero(gate)
    y = bins[:, None] * width + (np.arange(_Y_SUBSAMPLES) + 0.5) * width / _Y_SUBSAMPLES
    d2 = _chroma_distance2(mean, cov, floor, (y / luma).reshape(-1))
    lut = np.zeros((Y_BINS, C_BINS, C_BINS), bool)
    lut[bins] = (d2 <= threshold * threshold).reshape(len(bins), _Y_SUBSAMPLES, C_BINS,
                                                      C_BINS).any(axis=1)
    return lut.astype(np.float32) * 255.0


def _chroma_distance2(mean: np.ndarray, cov: np.ndarray, floor: float,
                      scales: np.ndarray) -> np.ndarray:
    """(K, C_BINS, C_BINS) squared Mahalanobis distance of each (Cr, Cb) bin centre from the
    chroma Gaussian (``mean``, ``cov``) scaled to each luma ratio of ``scales`` (K,): mean
    128 + (mean - 128) s, covariance (cov - floor^2 I) s^2 + floor^2 I (mahalanobis_skin_lut)."""
    c = _bin_centres(C_BINS)
    s = scales.reshape(-1, 1, 1)
    inv = np.linalg.inv((cov - np.eye(2) * floor**2) * (s * s) + np.eye(2) * floor**2)
    d0 = c[None, :, None] - (128.0 + (mean[0] - 128.0) * s)  # Cr along the table's axis 1
    d1 = c[None, None, :] - (128.0 + (mean[1] - 128.0) * s)  # Cb along axis 2
    return inv[:, :1, :1] * d0 * d0 + 2 * inv[:, :1, 1:] * d0 * d1 + inv[:, 1:, 1:] * d1 * d1


def normalised_chroma(ycc: np.ndarray, luma: float) -> np.ndarray:
    """(N, 2) chroma of (N, 3) YCrCb samples as it would be at luma ``luma``: the offset from
    grey scaled by luma / Y (the illumination-invariant chroma of :func:`mahalanobis_skin_lut`)."""
    ycc = np.asarray(ycc, np.float64).reshape(-1, 3)
    y = np.maximum(ycc[:, :1], 1.0)
    return 128.0 + (ycc[:, 1:3] - 128.0) * (luma / y)


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
    and the whole image is searched; its pixel (0, 0) covers full-resolution pixel ``origin``
    (the image's corner, or the corner of the window it was computed for).
    """

    box: tuple[int, int, int, int]
    gate: np.ndarray | None
    scale: int
    origin: tuple[int, int] = (0, 0)

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
        u = uv[:, 0] - self.origin[0] + 0.5
        v = uv[:, 1] - self.origin[1] + 0.5
        c = np.minimum(np.maximum((u // self.scale).astype(int), 0), w - 1)
        r = np.minimum(np.maximum((v // self.scale).astype(int), 0), h - 1)
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
        self.luma: float | None = None  # the luma the Gaussian stands for (see module doc)
        self.anchor: tuple[np.ndarray, np.ndarray] | None = None  # first fit: bounds adapt()
        self._frames_seen = 0
        # n, sum Y, then sums of rho = (Cr, Cb - 128) / Y: r, b, r^2, r*b, b^2
        self._acc = np.zeros(7)
        s = max(int(config.skin_dilate_px / config.skin_downsample + 0.5), 1)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * s + 1, 2 * s + 1))

    @property
    def adapted(self) -> bool:
        return self.mean is not None

    def set_gaussian(self, mean: np.ndarray, cov: np.ndarray, luma: float | None = None) -> None:
        """Switch to the subject's chroma model (Mahalanobis threshold from the config); with
        ``luma`` (the samples' mean luma) the model is scaled with brightness (module doc)."""
        self.mean, self.cov = np.asarray(mean, float), np.asarray(cov, float)
        self.luma = None if luma is None else float(luma)
        if self.anchor is None:
            self.anchor = (self.mean.copy(), self.cov.copy())
        self.lut = mahalanobis_skin_lut(
            self.mean, self.cov, self.config.skin_mahalanobis, self.config.skin_y_min,
            self.luma, self.config.skin_min_sigma,
        )  # fmt: skip

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

    def window_region(self, half_window: np.ndarray, box: tuple[int, int, int, int]) -> SkinRegion:
        """The skin gate of one window only (``box`` full-resolution, corners on multiples of
        the downsampling; ``half_window`` that window at half resolution): the skin pixels
        there, dilated, without the whole frame's component analysis. For the search near the
        predicted markers while tracking; it neither fits nor adapts the model."""
        s = self.config.skin_downsample
        hh, hw = half_window.shape[:2]
        small = cv2.resize(half_window, (hw * 2 // s, hh * 2 // s), interpolation=cv2.INTER_AREA)
        gate = cv2.dilate(self.mask(cv2.cvtColor(small, cv2.COLOR_BGR2YCrCb)), self._kernel)
        return SkinRegion(box, gate, s, (box[0], box[1]))

    def _accumulate(self, ycc: np.ndarray, skin: np.ndarray, component: np.ndarray) -> None:
        """Gather the chroma of the main skin component; fit once enough frames were seen."""
        # Erode so the samples are skin, not its blend with the background at the boundary.
        inner = cv2.erode(skin, None) > 0
        px = ycc[inner & component].astype(np.float64)
        y = np.maximum(px[:, 0], 1.0)
        r, b = (px[:, 1] - 128.0) / y, (px[:, 2] - 128.0) / y
        self._acc += (len(y), y.sum(), r.sum(), b.sum(), r @ r, r @ b, b @ b)
        self._frames_seen += 1
        if self._frames_seen < self.config.skin_adapt_frames:
            return
        n, sy, sr, sb, srr, srb, sbb = self._acc
        if n < self.config.skin_min_samples:
            return  # keep gathering
        luma = sy / n
        rho = np.array([sr, sb]) / n
        cov = (np.array([[srr, srb], [srb, sbb]]) / n - np.outer(rho, rho)) * luma**2
        self.set_gaussian(128.0 + rho * luma, cov + np.eye(2) * self.config.skin_min_sigma**2,
                          luma)

    def _fit(self, bgr: np.ndarray, mask: np.ndarray, luma: float | None):
        """(mean, cov, luma) of the skin where ``mask`` is set, normalised to ``luma`` (their
        own mean luma if None); None when too few pixels are usable."""
        ycc = cv2.cvtColor(bgr, cv2.COLOR_BGR2YCrCb)
        sel = (mask > 0) & (ycc[..., 0] >= self.config.skin_y_min)
        px = ycc[sel]
        if len(px) < self.config.skin_min_samples:
            return None
        luma = float(px[:, 0].mean()) if luma is None else luma
        try:
            mean, cov = fit_chroma(normalised_chroma(px, luma), self.config.skin_min_sigma,
                                   self.config.skin_min_samples)
        except ValueError:
            return None
        return mean, cov, luma

    def learn(self, bgr: np.ndarray, mask: np.ndarray) -> bool:
        """Fit the subject's chroma from the pixels of ``bgr`` where ``mask`` is nonzero
        (skin known from the labelled markers). False (model unchanged) if too few are usable.
        This fit becomes the anchor that bounds :meth:`adapt`."""
        fit = self._fit(bgr, mask, None)
        if fit is None:
            return False
        self.anchor = None
        self.set_gaussian(*fit)
        return True

    def adapt(self, bgr: np.ndarray, mask: np.ndarray, rate: float = ADAPT_RATE) -> bool:
        """Blend the chroma of the skin where ``mask`` is set into the model (weight ``rate``).

        For a slow change of the light's colour (white balance). Refused (False, model
        unchanged) when too few pixels are usable or when the blended mean would move more than
        ADAPT_MAX_DRIFT (Mahalanobis, first fit's covariance) from the first fit: a hand does
        not change colour that much, a wrong mask (a sleeve, the table) would. Without a fit yet
        this is :meth:`learn`.
        """
        if self.mean is None or self.anchor is None:
            return self.learn(bgr, mask)
        luma = self.luma if self.luma is not None else 128.0
        fit = self._fit(bgr, mask, luma)
        if fit is None:
            return False
        mean = (1.0 - rate) * self.mean + rate * fit[0]
        cov = (1.0 - rate) * self.cov + rate * fit[1]
        m0, c0 = self.anchor
        d = mean - m0
        if float(d @ np.linalg.solve(c0, d)) > ADAPT_MAX_DRIFT**2:
            return False
        self.set_gaussian(mean, cov, luma)
        return True
