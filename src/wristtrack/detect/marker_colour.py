"""The marker colour the detector looks for: the default model, the learned one, its adaptation.

A marker colour learned once from the first labelled frame is narrow (a few hundred pixels under
one light). Once the hand turns away from the light (pronation, extension) the markers' pixels
darken and their hue and saturation spread with the sensor noise: a narrow learned histogram
rejects them, while the wide default (a Gaussian around the nominal blue) still finds them. So:

- the default reference is never dropped: where the learned one finds fewer markers than the
  frame before, the detector searches again with both (:attr:`MarkerColour.wide_table`, the
  maximum of the two tables, each scaled to a peak of 255; a blob's Bhattacharyya coefficient
  the larger of its two). Not always both: the wider table lets a marker's darker fringe into
  its core, which moves its centre a little (rendered RGB-only: 0.91 -> 1.03 deg);
- the learned reference keeps adapting, but only from markers the tracker labelled confidently
  (:meth:`MarkerColour.adapt`), as a running blend whose distance from the first learned
  histogram is bounded (Bhattacharyya coefficient >= ``min_anchor_similarity``): a slow drift
  of the light's colour is followed, a wrong label (clutter, skin) cannot pull it away.
"""

from __future__ import annotations

import numpy as np

from wristtrack.detect.colour import (
    backprojection_table,
    blob_similarities,
    lut_scaled,
)

ADAPT_RATE = 0.1  # weight of a new frame's histogram in the running blend
MIN_ANCHOR_SIMILARITY = 0.8  # the blend may not drift further than this from the first learned


def _normalised(hist: np.ndarray) -> np.ndarray:
    h = np.asarray(hist, np.float64)
    total = h.sum()
    return h / total if total > 0 else h


def similarity(a: np.ndarray, b: np.ndarray) -> float:
    """Bhattacharyya coefficient of two non-negative histograms of the same shape, in [0, 1]."""
    pa, pb = _normalised(a), _normalised(b)
    return float(np.sqrt(pa * pb).sum())


class MarkerColour:
    """Default and learned (H, S) marker references and the detector's lookup table."""

    def __init__(self, default: np.ndarray, min_value: int) -> None:
        self.default = lut_scaled(default)
        self.min_value = min_value
        self.learned: np.ndarray | None = None
        self.anchor: np.ndarray | None = None  # the first learned histogram, normalised
        self._blend: np.ndarray | None = None  # the running blend, normalised
        self.table = backprojection_table(self.default, min_value)
        self.wide_table = self.table  # learned or default: see the module doc

    @property
    def reference(self) -> np.ndarray:
        """The learned reference, or the default before any learning (peak 255)."""
        return self.default if self.learned is None else self.learned

    def set_learned(self, hist: np.ndarray) -> None:
        """Use ``hist`` (any scale) as the learned reference and the anchor of adaptation."""
        self.anchor = self._blend = _normalised(hist)
        self._use(self._blend)

    def _use(self, hist: np.ndarray) -> None:
        self.learned = lut_scaled(hist)
        self.table = backprojection_table(self.learned, self.min_value)
        self.wide_table = backprojection_table(np.maximum(self.learned, self.default),
                                               self.min_value)

    def adapt(self, hist: np.ndarray, rate: float = ADAPT_RATE,
              min_anchor_similarity: float = MIN_ANCHOR_SIMILARITY) -> bool:
        """Blend the histogram of confidently labelled markers into the learned reference.

        Refused (False, unchanged) when the blend would fall below ``min_anchor_similarity``
        with the first learned histogram; the first call, before any learning, learns.
        """
        if not np.asarray(hist).sum() > 0:
            return False
        if self._blend is None:
            self.set_learned(hist)
            return True
        blend = (1.0 - rate) * self._blend + rate * _normalised(hist)
        if similarity(blend, self.anchor) < min_anchor_similarity:
            return False
        self._blend = blend
        self._use(blend)
        return True

    def similarities(self, hsv: np.ndarray, masks: np.ndarray, wide: bool = False) -> np.ndarray:
        """(n,) Bhattacharyya coefficient of each blob (see colour.blob_similarities) with the
        reference in use; ``wide``: with the one that suits it best, learned or default."""
        if self.learned is None:
            return blob_similarities(hsv, masks, self.default)
        if not wide:
            return blob_similarities(hsv, masks, self.learned)
        return blob_similarities(hsv, masks, self.default, self.learned)
