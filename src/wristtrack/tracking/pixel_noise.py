"""The pixel noise the filter takes for this recording's blobs.

``MeasurementNoise.pixel_sigma``, 0.3 px, covers the worst of blur, compression and highlights
together; sharp blobs are good to 0.015 px (detect/blobs.py), and the filter that takes them
at 0.3 px leaves most of what their pixels say about the out-of-plane angles to depth. Where
depth is poor that costs most: structured-light depth at 0.56 deg against 0.28 clean
(docs/BENCHMARKS.md at 1869a59), 0.43 with the pixels taken at 0.15 px throughout.

Variance-component estimation (tracking/noise_scale.py) measures the blob centres' noise frame
by frame: 0.03-0.05 px on sharp rendered blobs (0.037 against the truth), 0.14 under H.264 (0.13),
with the plain weighted centroid the detector had then. The filter cannot take that figure as
it is: the blob errors are correlated in time (the pixel grid, the codec's blocks and the blur
change slowly while the hand moves slowly), and the filter, which weighs about half a second of
frames, meets them larger than one frame's noise.
Against the truth, on the rendered recordings, the variance of half-second means of a blob's
error is 4-6x what white noise of its per-frame spread would give. So the sigma is the
white-noise equivalent over WINDOW_S: the per-frame variance times the inflation that windows
of the posterior residuals show, (sum_w e)^2 / sum_w e^2 (1 for white noise, the number of
frames for a constant), measured as the track goes (``BlobCorrelation``; 5.3-6.7 on the
rendered recordings, against 4.2-6.3 from the truth). Until MIN_WINDOWS windows are measured
the inflation is taken at the most it can be, errors constant over a window
(:func:`worst_inflation`, the number of frames a window holds): the per-frame noise, learned
within a second, then already lowers the sigma of sharp blobs, where waiting for the
correlation kept the model's 0.3 px over the first ~2.3 s (structured light 0.483 -> 0.464 deg
on the rendered recordings, 3 seeds; the others within +-0.01).

It is kept within ``SIGMA_FLOOR`` and the model's sigma. Below the floor the errors the
residuals cannot show dominate: blob errors along the pose's own patterns (all blobs shifted
alike, as JPEG's blocks do) are taken up by the pose and never show. With the sigma fixed, the
rendered clean recordings came out at 0.30 deg at 0.1 px, 0.27 at 0.15, 0.28 at 0.3 (3 seeds).
Above the model's, what the residuals show is mostly the layout's error (without hand.json, a
constant per marker), which is no noise: raising the sigma for it made the every-effect
recordings worse.

All of this is learned from, and taken for, the blobs the detector does not doubt. A suspect
blob (clipped, split, elongated, on the border, a streak: ``Detections.suspect``) is taken at the
model's sigma whatever is learned (``MarkerObservation.suspect_variance``) and left out of the
learning (``noise_scale.undoubted``).
"""

from __future__ import annotations

import math

import numpy as np

WINDOW_S = 0.5  # the span of frames whose errors the filter weighs together
_SPAN_TOLERANCE = 1e-6  # s: 15 x 1/30 s sums to 0.5 - 6e-17, which closes a window
TIME_CONSTANT_S = 10.0  # memory of the inflation: ~20 windows
MIN_WINDOWS = 4  # windows measured before the inflation is (the worst case until then)
SIGMA_FLOOR = 0.15  # px


class BlobCorrelation:
    """The inflation of the blobs' error variance over WINDOW_S by its correlation in time,
    from the markers' posterior pixel residuals, one window of frames at a time (module doc)."""

    def __init__(self) -> None:
        self._num = self._den = 0.0  # forgetting sums of (sum_w e)^2 and sum_w e^2
        self.windows = 0
        self.frames = 0  # frames the last window held

    def add(self, residuals: np.ndarray, span: float) -> None:
        """One window's residuals (frames, markers, 2) in px, NaN for markers not measured,
        spanning ``span`` seconds."""
        keep = math.exp(-span / TIME_CONSTANT_S)
        self._num = keep * self._num + float(np.sum(np.nansum(residuals, axis=0) ** 2))
        self._den = keep * self._den + float(np.nansum(residuals**2))
        self.windows += 1
        self.frames = residuals.shape[0]

    @property
    def inflation(self) -> float | None:
        """(sum_w e)^2 / sum_w e^2 over the windows so far (at least 1), or None before
        MIN_WINDOWS windows."""
        if self.windows < MIN_WINDOWS or not self._den > 0:
            return None
        return max(self._num / self._den, 1.0)


def window_full(span: float) -> bool:
    """Whether a window of frames spanning ``span`` s (first frame to last) is complete."""
    return span >= WINDOW_S - _SPAN_TOLERANCE


def worst_inflation(frame_interval: float) -> float | None:
    """The inflation of blob errors constant over a window: the number of frames a window
    holds (:func:`window_full`) for frames ``frame_interval`` s apart, 16 at 30 fps (None where
    the spacing is unknown, not positive)."""
    if not frame_interval > 0:
        return None
    return float(math.ceil((WINDOW_S - _SPAN_TOLERANCE) / frame_interval) + 1)


def filter_sigma(model_sigma: float, frame_factor: float, inflation: float | None) -> float:
    """The pixel sigma the filter takes: the model's ``model_sigma`` scaled by the per-frame
    variance factor learned (``frame_factor``) and the correlation's ``inflation`` (measured, or
    :func:`worst_inflation`), within [SIGMA_FLOOR, model_sigma]; the model's where there is
    no inflation to take."""
    if inflation is None:
        return model_sigma
    sigma = model_sigma * math.sqrt(frame_factor * inflation)
    return min(max(sigma, min(SIGMA_FLOOR, model_sigma)), model_sigma)
