"""The detector's search near the predicted markers while tracking, and its fall-backs.

Oracles: the same detector searching the whole frame every time (the window path must find
the very same blobs), and the scene's own marker truth."""

from __future__ import annotations

import numpy as np

from wristtrack.detect.detector import DetectorConfig, MarkerDetector
from wristtrack.sim.marker_scene import synth_scene


def test_window_search_finds_the_same_blobs_as_the_whole_frame():
    """A hand moving across the image: while tracking, only a window around the markers' last
    positions moved on by their own motion is searched (no whole-frame downsampling or skin
    pass), and every centre equals the whole-frame search's to rounding."""
    windowed = MarkerDetector(synth_scene(40).camera)
    whole = MarkerDetector(synth_scene(40).camera, DetectorConfig(track_roi=False))
    used_window = 0
    for k in range(8):
        s = synth_scene(40 + k, centre=(220.0 + 12 * k, 280.0 - 6 * k), yaw_deg=-20.0 + 2 * k)
        a = windowed.detect(s.bgr, s.depth, float(k))
        b = whole.detect(s.bgr, s.depth, float(k))
        if k == 0:
            for det in (windowed, whole):
                det.learn_markers(s.bgr, s.uv)
        used_window += windowed.last_region.origin != (0, 0)
        dist = np.linalg.norm(s.uv[:, None] - a.uv[None], axis=2).min(1)
        assert np.all(dist < 0.3), dist
        d = np.linalg.norm(a.uv[:, None] - b.uv[None], axis=2)
        assert a.count == b.count and np.all(d.min(1) < 1e-6), d.min(1)
        np.testing.assert_allclose(a.depth, b.depth[d.argmin(1)], atol=1e-9)
    assert used_window >= 6  # every frame after the first few


def test_markers_lost_under_the_learned_skin_model_are_searched_for_again():
    """After learning, the light turns much warmer at once (faster than adaptation follows):
    the learned skin model no longer sees the hand; the detector searches the whole frame
    ungated again instead of reporting no markers."""
    first = synth_scene(50)
    det = MarkerDetector(first.camera)
    det.detect(first.bgr, first.depth, 0.0)
    det.learn_markers(first.bgr, first.uv)
    det.detect(first.bgr, first.depth, 0.1)
    warm = synth_scene(51, white_balance=(0.6, 0.85, 1.45), centre=(400.0, 200.0))
    d = det.detect(warm.bgr, warm.depth, 0.2)
    dist = np.linalg.norm(warm.uv[:, None] - d.uv[None], axis=2).min(1)
    assert np.all(dist < 0.3), dist
