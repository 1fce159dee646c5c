"""Markers found by chromaticity (detect/streaks.py) against drawn truth: a disc of marker colour
swept across skin during the exposure (the mean of many sharp renders), whose centre at
mid-exposure is known; markers in the shade, dark and desaturated on skin whose chromaticity
has drifted toward theirs; and a rendered fast reach under a 1/30 s shutter."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.detect.detector import DetectorConfig, MarkerDetector
from wristtrack.detect.streaks import STREAK_RATIO, find_chroma_blobs, is_shaded_marker

SKIN = np.array([121.0, 147.0, 199.0])
MARKER = np.array([173.0, 83.0, 38.0])


def swept_disc(start, end, diameter=10.0, shade=1.0, seed=0, size=(160, 200), offsets=((0, 0),),
               skin=SKIN, marker=MARKER):
    """BGR image of a disc swept from ``start`` to ``end`` over skin (mean of 64 sharp discs,
    each anti-aliased by 8x supersampling), with sensor noise; truth: the mid-point. With
    ``offsets``, one such disc at each offset (pixels) from the first; ``skin`` and ``marker``
    the two colours at full light."""
    h, w = size
    acc = np.zeros((h, w), np.float64)
    for s in np.linspace(0.0, 1.0, 64):
        big = np.zeros((h * 8, w * 8), np.uint8)
        for off in offsets:
            c = (1 - s) * np.asarray(start) + s * np.asarray(end) + off
            # supersampled pixel j is centred on (j + 0.5) / 8 - 0.5: centre in 1/16 of its px
            x, y = (int(round(((c[k] + 0.5) * 8 - 0.5) * 16)) for k in (0, 1))
            cv2.circle(big, (x, y), int(round(diameter / 2 * 8 * 16)), 255, -1, cv2.LINE_8,
                       shift=4)
        acc += cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA) / 255.0
    a = (acc / 64)[..., None]
    img = shade * ((1 - a) * skin + a * marker)
    img += np.random.default_rng(seed).normal(0, 2.0, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), (np.asarray(start) + end) / 2


@pytest.mark.parametrize(("length", "angle", "shade"), [(25, 0.0, 1.0), (40, 0.6, 0.7),
                                                          (45, -1.2, 1.2)])
def test_streak_centre_is_the_mid_exposure_centre(length, angle, shade):
    start = np.array([100.0, 80.0]) - 0.5 * length * np.array([np.cos(angle), np.sin(angle)])
    end = start + length * np.array([np.cos(angle), np.sin(angle)])
    img, truth = swept_disc(start, end, shade=shade, seed=int(length))
    found = find_chroma_blobs(img, None, (0, 0, img.shape[1], img.shape[0]), MARKER, SKIN, 10.0)
    assert len(found) == 1, found
    u, v, z, long, wide, direction = found[0][:6]
    # (a sharp blob is found to ~0.05 px; a faint 50 px streak to a few tenths)
    assert np.hypot(u - truth[0], v - truth[1]) < 0.5, (u, v, truth)
    assert abs(long - (length + 10)) < 0.35 * length  # about the swept length
    assert 6 < wide < 14 and np.isnan(z)
    turn = (direction - angle + np.pi / 2) % np.pi - np.pi / 2
    assert abs(turn) < 0.05


def test_a_sharp_marker_is_one_marker_long_and_plain_skin_gives_nothing():
    img, truth = swept_disc((100.0, 80.0), (100.5, 80.0))
    (u, v, _, long, *_), = find_chroma_blobs(img, None, (0, 0, 200, 160), MARKER, SKIN, 10.0)
    assert long < STREAK_RATIO * 10.0 and np.hypot(u - truth[0], v - truth[1]) < 0.1
    skin = np.clip(np.random.default_rng(1).normal(SKIN, 2.0, (160, 200, 3)), 0, 255)
    assert find_chroma_blobs(skin.astype(np.uint8), None, (0, 0, 200, 160), MARKER, SKIN,
                             10.0) == []


# In the lamp's shade (a third of full light) the markers lose most of their saturation to the
# codec and the demosaicing (rendered: S 0.3-0.5, V 40-60), and the skin's chromaticity drifts
# toward the marker's (t -0.1 to 0.2 on the lit skin-to-marker segment).
SHADE = 0.33
MARKER_SHADE = 0.45 * MARKER + 0.55 * MARKER.mean()  # saturation 0.78 -> 0.35
OFFSETS = ((0, 0), (0, 30), (25, 55))


def shaded_markers(seed=0, drift=0.15):
    """Three shaded markers on shaded skin ``drift`` of the way to the marker's colour."""
    skin = (1 - drift) * SKIN + drift * MARKER
    return swept_disc((30.0, 50.0), (30.4, 50.0), shade=SHADE, seed=seed, offsets=OFFSETS,
                      skin=skin, marker=MARKER_SHADE)


def test_markers_in_the_shade_are_found_above_the_skin_around_them():
    img, mid = shaded_markers()
    truth = mid + np.array(OFFSETS)
    found = find_chroma_blobs(img, None, (0, 0, 200, 160), MARKER, SKIN, 10.0, skin_around=True)
    assert len(found) == 3, found
    err = np.linalg.norm(truth[:, None] - np.array([f[:2] for f in found])[None], axis=2).min(1)
    assert np.all(err < 0.3), err
    assert all(is_shaded_marker(f, 10.0) for f in found)
    # against the skin learned under the lamp, the drifted skin is one blob with the markers
    assert not any(is_shaded_marker(f, 10.0) and min(np.hypot(*(t - f[:2])) for t in truth) < 1
                   for f in find_chroma_blobs(img, None, (0, 0, 200, 160), MARKER, SKIN, 10.0))


def test_a_grey_spot_over_the_skin_is_not_a_marker_in_the_shade():
    """A bluish-grey spot of a marker's size (the edge of a dark pen lying over the skin, mixed
    with it, measured 0.25-0.33 on the rendered occlusions) lies a third of the way toward the
    marker's chromaticity: found by chromaticity, but no marker in the shade."""
    grey = np.array([56.0, 48.0, 52.0])
    img, _ = swept_disc((100.0, 80.0), (100.4, 80.0), seed=4, marker=grey)
    found = find_chroma_blobs(img, None, (0, 0, 200, 160), MARKER, SKIN, 10.0, skin_around=True)
    assert len(found) == 1 and 0.2 < found[0].contrast < 0.4, found
    assert not is_shaded_marker(found[0], 10.0)


def _tracked_sharp(step_px: float, interval_s: float):
    """(detector, frame): the detector after tracking three sharp markers (OFFSETS) over three
    frames ``interval_s`` apart, moving ``step_px`` a frame, given the colours learn_markers
    would measure; the frame its last, markers on a patch of skin."""
    # (no skin fit from this small synthetic patch of skin: the fixed skin box gates)
    det = MarkerDetector(Camera.default(), DetectorConfig(skin_adapt_frames=0))
    frame = np.zeros((480, 640, 3), np.uint8)
    frame[:] = (60, 70, 80)
    for k in range(3):
        start = (30.0 + step_px * k, 50.0)
        img, _ = swept_disc(start, (start[0] + 0.4, 50.0), seed=k, offsets=OFFSETS)
        frame[200:360, 200:400] = img
        d = det.detect(frame, None, k * interval_s)
        det.marker_bgr, det.skin_bgr = MARKER, SKIN
    assert d.count == 3 and not any(b.suspect for b in det.last_blobs)
    return det, frame


def test_detector_recovers_blurred_markers_while_tracking():
    """Three markers tracked sharp over three frames, then they smear (a 40 px sweep): the
    colour search misses the streaks, the streak search in the tracking window finds them, as
    suspect 'streak' blobs at the mid-exposure centres."""
    det, frame = _tracked_sharp(step_px=5.0, interval_s=1.0)
    blurred, mid = swept_disc((57.0, 50.0), (97.0, 50.0), seed=9, offsets=OFFSETS)
    frame[200:360, 200:400] = blurred
    d = det.detect(frame, None, 3.0)
    assert d.count == 3 and all(b.reason == "streak" for b in det.last_blobs)
    truth = mid + np.array(OFFSETS) + (200, 200)
    err = np.linalg.norm(truth[:, None] - d.uv[None], axis=2).min(1)
    assert np.all(err < 0.5), err


def test_detector_finds_markers_in_the_shade_while_tracking():
    """Three markers tracked under the lamp, then the hand turns into the shade: dark and
    desaturated, they fail the colour reference (no blob at all), and the search by
    chromaticity in the tracking window finds them as suspect 'shade' blobs at their centres.
    The window outlives the frames without blobs by RECENT_WINDOW_S."""
    det, frame = _tracked_sharp(step_px=0.0, interval_s=1 / 30)
    shaded, mid = shaded_markers(seed=5, drift=0.05)
    frame[:] = np.round(SHADE * SKIN).astype(np.uint8)  # the lamp's shade over everything
    frame[200:360, 200:400] = shaded
    truth = mid + np.array(OFFSETS) + (200, 200)
    colour_only = MarkerDetector(Camera.default(), DetectorConfig(skin_adapt_frames=0))
    assert colour_only.detect(frame, None, 0.0).count == 0
    for k in range(3, 6):  # the window stays although the frame before had no colour blob
        d = det.detect(frame, None, k / 30)
        assert d.count == 3 and all(b.reason == "shade" for b in det.last_blobs)
        err = np.linalg.norm(truth[:, None] - d.uv[None], axis=2).min(1)
        assert np.all(err < 0.3), err
    blank = np.clip(np.random.default_rng(2).normal(SHADE * SKIN, 2.0, (160, 200, 3)), 0,
                    255).astype(np.uint8)
    frame[200:360, 200:400] = blank  # the markers gone from view: no window is made
    assert det.detect(frame, None, 6 / 30).count == 0
    frame[200:360, 200:400] = shaded
    assert det.detect(frame, None, 5 / 30 + 0.6).count == 0  # the last window has expired
