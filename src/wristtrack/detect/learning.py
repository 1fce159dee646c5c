"""The detector's colour learning: from markers the tracker labelled, the marker and skin models.

``learn_markers`` learns them once at the first fix; ``adapt`` follows slow changes of the light
from later confidently labelled frames, with a bounded drift (detect/marker_colour.py, the skin
model's adapt). Mixed into :class:`wristtrack.detect.detector.MarkerDetector`, whose ``colour``,
``skin``, ``config`` and ``_check`` it uses.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from wristtrack.detect.colour import hs_histogram, smooth
from wristtrack.errors import InputError


class MarkerLearning:
    """learn_markers / adapt for the marker detector (see the module doc)."""

    def learn_markers(self, bgr: np.ndarray, uv: np.ndarray) -> None:
        """Refine the marker reference histogram and the skin model from labelled markers.

        ``uv`` (N,2): the centres of known markers in ``bgr`` (the tracker passes the six it
        initialised on). Around each, the marker is segmented by colour alone (pixels closer to
        the colour at its centre than to the surrounding skin, connected to the centre), so this
        works even when the current reference no longer matches (a white-balance change); the
        markers' pixels give the new reference, the hand between and around them (markers
        excluded) gives the subject's skin chroma. Markers that do not stand out are skipped;
        if none does, the models stay as they were (:attr:`learned_count` says how many were
        used): a refinement that cannot be made must not stop a recording.
        Nothing is learned when the config's ``learn_colours`` is off (the paper preset).
        """
        if not self.config.learn_colours:  # the paper preset: its reference stays fixed
            self._check(bgr, None)
            self.learned_count = 0
            return
        masks = self._labelled_masks(bgr, uv, "learn_markers")
        self.learned_count = 0 if masks is None else masks[2]
        if masks is None:
            return
        marker, skin, _ = masks
        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
        self.colour.set_learned(smooth(hs_histogram(hsv, marker, self.config.hist_bins)))
        self.skin.learn(bgr, skin)
        self._mean_colours(bgr, marker, skin, 1.0)

    def adapt(self, bgr: np.ndarray, uv: np.ndarray) -> bool:
        """Follow a slow change of the marker and skin colours from confidently labelled markers.

        ``uv`` (N,2): centres of markers the tracker labelled with confidence in ``bgr`` (NaN
        rows are skipped). Their histogram is blended into the learned marker reference and the
        hand around them into the skin model, each with a bounded drift from what
        :meth:`learn_markers` learned (see :mod:`wristtrack.detect.marker_colour` and
        :meth:`wristtrack.detect.skin.SkinModel.adapt`); the default marker colour stays in use
        beside the learned one. Needs at least 3 markers that stand out; True if a model changed.
        """
        if not self.config.learn_colours:
            return False
        masks = self._labelled_masks(bgr, uv, "adapt")
        if masks is None or masks[2] < 3:
            return False
        marker, skin, _ = masks
        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
        changed = self.colour.adapt(smooth(hs_histogram(hsv, marker, self.config.hist_bins)))
        changed = self.skin.adapt(bgr, skin) or changed
        if changed:
            self._mean_colours(bgr, marker, skin, 0.1)
        self.adapted_count += changed
        return changed

    def _mean_colours(self, bgr, marker, skin, rate: float) -> None:
        """Blend the mean BGR of the marker and skin masks into marker_bgr / skin_bgr."""
        for name, mask in (("marker_bgr", marker), ("skin_bgr", skin)):
            px = bgr[mask > 0]
            if len(px):
                new = px.mean(axis=0)
                old = getattr(self, name)
                setattr(self, name, new if old is None else (1 - rate) * old + rate * new)

    def _labelled_masks(self, bgr: np.ndarray, uv: np.ndarray, caller: str):
        """(marker mask, skin mask, markers used) around the labelled marker centres ``uv``, or
        None when no marker stands out. The skin is the hand around the markers used (their
        convex hull grown by two marker diameters), the markers themselves (grown) cut out."""
        self._check(bgr, None)
        try:
            uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        except (TypeError, ValueError):
            raise InputError(
                f"{caller}: marker positions must be an (N, 2) array of pixels, got {uv!r}"
            ) from None
        h, w = bgr.shape[:2]
        r = self.config.learn_radius_px
        marker = np.zeros((h, w), np.uint8)
        radii, used = [], []
        for u, v in uv:
            if not (np.isfinite(u) and np.isfinite(v)):
                continue
            cu, cv_ = int(round(u)), int(round(v))
            x0, y0 = max(cu - r, 0), max(cv_ - r, 0)
            x1, y1 = min(cu + r + 1, w), min(cv_ + r + 1, h)
            if not (x0 <= cu < x1 and y0 <= cv_ < y1):
                continue
            seg = _segment_marker(bgr[y0:y1, x0:x1].astype(np.float32), cu - x0, cv_ - y0)
            if seg is not None:
                marker[y0:y1, x0:x1] |= seg
                radii.append(math.sqrt(np.count_nonzero(seg) / math.pi))
                used.append((cu, cv_))
        if not radii:
            return None
        rad = float(np.median(radii))
        skin = np.zeros((h, w), np.uint8)
        if len(used) >= 3:
            cv2.fillConvexPoly(skin, cv2.convexHull(np.array(used, np.int32)), 1)
        else:
            for c in used:
                skin[c[1], c[0]] = 1
        skin = cv2.dilate(skin, cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (int(4 * rad) | 1, int(4 * rad) | 1)))
        grown = cv2.dilate(marker, cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (int(2 * rad) | 1, int(2 * rad) | 1)))
        skin[grown > 0] = 0
        return marker, skin, len(radii)


def _segment_marker(patch: np.ndarray, cu: int, cv_: int) -> np.ndarray | None:
    """0/1 mask of the marker at (cu, cv_) in a float BGR patch, or None if it does not stand
    out: pixels nearer the centre colour than the border colour, connected to the centre."""
    m = np.median(patch[max(cv_ - 1, 0) : cv_ + 2, max(cu - 1, 0) : cu + 2].reshape(-1, 3), 0)
    border = np.concatenate((patch[0], patch[-1], patch[:, 0], patch[:, -1]))
    b = np.median(border, 0)
    d = m - b
    dd = float(d @ d)
    if dd < 30.0**2:  # no colour contrast with the surroundings worth learning from
        return None
    t = (patch - b) @ (d / dd)
    n, labels = cv2.connectedComponents((t > 0.5).view(np.uint8), connectivity=8)
    lab = labels[cv_, cu]
    if lab == 0:
        return None
    seg = (labels == lab).astype(np.uint8)
    # touching the patch border: not an isolated marker (a blue sleeve, a wrong label)
    if seg[0].any() or seg[-1].any() or seg[:, 0].any() or seg[:, -1].any():
        return None
    return seg

