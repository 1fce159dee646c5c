"""Where the markers should be while tracking: the window around the last frame's blobs, and
the markers the colour search missed there, found by chromaticity (detect/streaks.py): streaks
of motion blur, and markers in the lamp's shade.

Mixed into :class:`wristtrack.detect.detector.MarkerDetector`, whose ``config``, ``skin``,
``camera``, ``last_blobs``, ``_prev_uv``, ``_last_diameter``, ``marker_bgr``, ``skin_bgr`` and
``_short`` it uses; it keeps ``_window`` and ``_counts`` (``_start_window``).
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.detect.detections import Blob
from wristtrack.detect.streaks import (
    MAX_STREAK_RATIO,
    STREAK_RATIO,
    find_chroma_blobs,
    is_shaded_marker,
)
from wristtrack.hand import MARKER_NAMES

# Markers lost to the shade are searched for by chromaticity in the last tracking window for
# this long, wherever a frame has fewer blobs than the most of this many frames. (Streaks, where
# it has fewer than the frame before, in the current window: a marker hidden for long, by an
# occluder, would let its edges pass for one.)
RECENT_WINDOW_S = 0.5
RECENT_FRAMES = 15


class TrackingWindow:
    """The tracking window and the chromaticity searches in it (see the module doc)."""

    _window: tuple[tuple[int, int, int, int], float] | None  # the last window, its timestamp
    _counts: list[int]  # blobs found in each of the last RECENT_FRAMES frames

    def _start_window(self) -> None:
        """No window yet, and no frames counted."""
        self._window = None
        self._counts = []

    def _missed_markers(self, bgr, depth, near, blobs: list[Blob],
                        timestamp: float) -> list[Blob]:
        """The markers the colour search missed (``blobs`` it found) while tracking: streaks
        in the current window ``near`` (``_near_last_blobs``; None: not tracking) where the
        frame has fewer blobs than the last, markers in the shade in the last window where it
        has fewer than the recent frames' most."""
        if near is not None:
            self._window = (near, timestamp)
        window = self._recent_window(timestamp)
        out = []
        if near is not None and self._short(blobs):
            out = self._chroma_blobs(bgr, depth, near, blobs, shade=False)
        if window is not None and len(blobs) + len(out) < self._markers_seen():
            out += self._chroma_blobs(bgr, depth, window, blobs + out, shade=True)
        return out

    def _count(self, blobs: list[Blob]) -> None:
        """Keep the number of blobs a frame gave, for ``_markers_seen``."""
        self._counts = (self._counts + [len(blobs)])[-RECENT_FRAMES:]

    def _chroma_blobs(self, bgr, depth, box, blobs: list[Blob], shade: bool) -> list[Blob]:
        """Markers in the tracking window ``box`` that the colour search missed, found by
        chromaticity (detect/streaks.py): motion-blurred ones (reason "streak") or, with
        ``shade``, ones in the shade (reason "shade"), suspect blobs both; none before
        learning."""
        d = self._last_diameter
        if self.marker_bgr is None or self.skin_bgr is None or not d > 0:
            return []
        found = [b.uv for b in blobs]
        out = []
        # a streak reaches up to MAX_STREAK_RATIO / 2 diameters beyond where its marker is
        grow = int(MAX_STREAK_RATIO * d / 2) + 1
        H, W = bgr.shape[:2]
        box = (max(box[0] - grow, 0), max(box[1] - grow, 0), min(box[2] + grow, W),
               min(box[3] + grow, H))
        for c in find_chroma_blobs(bgr, depth, box, self.marker_bgr, self.skin_bgr, d,
                                   skin_around=shade, depth_trim=self.config.depth_trim):
            if any(math.hypot(c.u - a, c.v - b) < d for a, b in found):
                continue  # the colour search has this one
            if shade and not is_shaded_marker(c, d):
                continue
            if not shade and c.length < STREAK_RATIO * d:
                continue  # a sharp blob is the colour search's
            out.append(Blob(uv=(c.u, c.v), area=math.pi / 4 * d * d,
                            depth=c.depth * self.camera.depth_scale, similarity=0.0,
                            major=c.length, minor=c.width, angle=c.angle, skew=0.0,
                            expected_diameter=d, suspect=True,
                            reason="shade" if shade else "streak"))
        return out

    def _recent_window(self, timestamp: float) -> tuple[int, int, int, int] | None:
        """The last tracking window (``_near_last_blobs``) if it is at most RECENT_WINDOW_S
        old: markers lost in the shade leave the window without the blobs that made it, while
        the hand is still where it was."""
        if self._window is None or not 0.0 <= timestamp - self._window[1] <= RECENT_WINDOW_S:
            return None
        return self._window[0]

    def _markers_seen(self) -> int:
        """The most blobs (at most six) of the last RECENT_FRAMES frames: a frame with fewer may
        have missed some."""
        return min(max(self._counts, default=0), len(MARKER_NAMES))

    def _near_last_blobs(self, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
        """The window around where the markers should be (box (x0, y0, x1, y1), corners on
        multiples of the skin downsampling): the last frame's blobs, each moved on by its own
        motion since the frame before (matched by nearness), plus a margin. None to search the
        whole frame: fewer than 3 blobs last frame, the skin model still gathering its first
        frames, or tracking off. The caller searches the whole frame again whenever the window
        gives fewer blobs than the last frame had."""
        cfg = self.config
        if (not cfg.track_roi or len(self.last_blobs) < 3
                or not (self.skin.adapted or cfg.skin_adapt_frames <= 0)):
            return None
        uv = np.array([b.uv for b in self.last_blobs])
        if self._prev_uv is not None and len(self._prev_uv):
            d = np.linalg.norm(uv[:, None] - self._prev_uv[None], axis=2)
            step = uv - self._prev_uv[d.argmin(1)]
            moved = d.min(1) < cfg.track_margin_px  # the same blob one frame earlier
            uv = np.concatenate((uv, uv[moved] + step[moved]))
        lo, hi = uv.min(0), uv.max(0)
        m = max(cfg.track_margin_px, cfg.track_margin_ratio * float((hi - lo).max()))
        s = cfg.skin_downsample
        H, W = shape
        x0, y0 = max(int(lo[0] - m) // s * s, 0), max(int(lo[1] - m) // s * s, 0)
        x1 = min(-(-int(hi[0] + m + 1) // s) * s, W // s * s)
        y1 = min(-(-int(hi[1] + m + 1) // s) * s, H // s * s)
        if x1 - x0 < 16 or y1 - y0 < 16:
            return None
        return x0, y0, x1, y1
