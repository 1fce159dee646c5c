"""What ``track`` does with the detector's colours as the tracker labels the markers: learn
them at the first fix, then follow slow changes of the light (``MarkerDetector.adapt``)."""

from __future__ import annotations

import numpy as np

from wristtrack.detect.detector import MarkerDetector
from wristtrack.filter.ukf import chi2_quantile
from wristtrack.tracking.tracker import FrameResult, Status

# The detector's colours follow slow changes of the light (detector.adapt) from every
# ADAPT_EVERY-th frame whose markers the tracker labelled confidently: at least 4 blobs labelled
# (a merged blob is one colour sample) and an update whose NIS is within its 95 % quantile.
ADAPT_EVERY = 10
ADAPT_NIS_QUANTILE = 0.95


def _confident(result: FrameResult) -> bool:
    labelled = np.unique(result.labels[result.labels >= 0]).size
    return (result.status == Status.TRACKING and labelled >= 4 and result.nis_dof > 0
            and result.nis <= chi2_quantile(ADAPT_NIS_QUANTILE, result.nis_dof))


def follow_colours(detector: MarkerDetector, bgr: np.ndarray, det, result: FrameResult,
                   index: int, learned: bool) -> bool:
    """What ``track`` does with the detector's colours after each frame: learn them at the
    first fix, then adapt them every ADAPT_EVERY-th confident frame. Returns ``learned``."""
    if not learned and result.status == Status.TRACKING:
        learn_colours(detector, bgr, det, result)
        return True
    if learned and index % ADAPT_EVERY == 0 and _confident(result):
        learn_colours(detector, bgr, det, result, adapt=True)
    return learned


def learn_colours(detector: MarkerDetector, bgr: np.ndarray, det, result: FrameResult,
           adapt: bool = False) -> None:
    """Refine the detector's colour models from the six labelled markers of the first fix, or
    (``adapt``) blend in the markers labelled in this frame."""
    uv = np.full((6, 2), np.nan)
    for blob, label in enumerate(result.labels):
        if label >= 0:
            uv[label] = det.uv[blob]
    if adapt:
        detector.adapt(bgr, uv)
    elif np.isfinite(uv).all():
        detector.learn_markers(bgr, uv)
