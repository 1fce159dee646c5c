"""How long a marker's blob should be: the expected diameter through the camera's blur.

The detector's size tests (detector.MarkerDetector._classify) judge each blob's major axis
against the length a marker at its depth should have: its image diameter widened by the optics'
blur, sqrt(D^2 + 16 s^2) for a disc of diameter D and a Gaussian blur of sigma s
(:func:`expected_length`). A real camera widens every blob further: JPEG and H.264 chroma,
demosaicing and the shutter. Under every realism effect at once the undoubted blobs measured
1.15x the expected length at the median (clean recordings: 1.05), and the merged-pair test
('elongated' above 1.2x) doubted 7 % of the single markers, whose centres were as good as the
undoubted blobs' (median error 0.12 px against 0.10). :class:`BlobSize` follows the blobs'
median length on the expected one, so the tests judge a blob against the camera's own blur. It
learns from the whole blobs, the 'elongated' ones included: a camera soft enough to make every
single marker 'elongated' would otherwise never teach it, and the median leaves the minority of
merged pairs.

On the rendered every-effect recordings (10 seeds) the doubted blobs went from 19 % to 13 %
(left hands) and the worst range-of-motion error 1.18 -> 1.11 deg (right 0.82 -> 0.81); each
effect alone kept its orientation error within 0.002 deg (H.264's range-of-motion error,
decided by one frame, 0.40 -> 0.44 on 3 seeds).

The scale is kept within SCALE_BOUNDS. The paper's detector (detect/paper.py) has no size
tests and does not use it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

MIN_BLOBS = 3  # a frame teaches the scale with at least this many whole blobs
RATE = 0.05  # of the way to a frame's median, per frame (~20 frames' memory)
SCALE_BOUNDS = (0.9, 1.5)


def expected_length(diameter: np.ndarray | float, psf_sigma_px: float) -> np.ndarray | float:
    """The major axis (px) of a disc of ``diameter`` px seen through a Gaussian blur of sigma
    ``psf_sigma_px``: sqrt(D^2 + 16 s^2) (a disc's second moment D^2/16, plus the blur's)."""
    return np.sqrt(np.square(diameter) + 16 * psf_sigma_px**2)


class BlobSize:
    """The blobs' typical length on the expected one (module doc); ``scale`` 1 until learned."""

    def __init__(self) -> None:
        self.scale = 1.0

    def learn(self, blobs: Iterable[tuple[float, float]], psf_sigma_px: float) -> None:
        """One frame's whole blobs as (major axis, expected diameter) in px."""
        ratios = [major / expected_length(d, psf_sigma_px) for major, d in blobs if d > 0]
        if len(ratios) < MIN_BLOBS:
            return
        log_scale = math.log(self.scale)
        log_scale += RATE * (math.log(float(np.median(ratios))) - log_scale)
        self.scale = float(np.clip(math.exp(log_scale), *SCALE_BOUNDS))
