"""Property-based tests (hypothesis): whatever the detector and the tracker are fed, they do not
raise (except the documented InputError), never report ``tracking`` with a NaN pose, and keep
the covariance symmetric positive definite.

Inputs: random images (noise, all marker-blue, all skin, blue discs on skin, flat; sizes from
the detector's 16 px minimum up, odd ones included), random depth frames; random blob sets
(0..20 blobs, inside and outside the image, NaN, zero, negative and absurd depths, duplicates)
mixed into a simulated recording so the tracker is exercised in every state; random timestamp
sequences (irregular, big gaps, repeats, going backwards).

The examples are derandomised and no example database is kept, so every run (and CI) tests the
same inputs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InputError
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.tracking.tracker import Status, Tracker, TrackerConfig

PROPERTY = settings(
    max_examples=30,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

# ------------------------------------------------------------------------------- detector

BLUE = (200, 70, 20)  # BGR of the markers' blue
SKIN = (120, 150, 215)


def _image(kind: str, w: int, h: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "noise":
        return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    if kind == "blue":
        return np.full((h, w, 3), BLUE, np.uint8)
    if kind == "skin":
        return np.full((h, w, 3), SKIN, np.uint8)
    if kind == "flat":
        return np.full((h, w, 3), rng.integers(0, 256, 3), np.uint8)
    # blue discs of random sizes (down to a pixel, up to larger than the image) on skin
    img = np.full((h, w, 3), SKIN, np.uint8)
    img = np.clip(img + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(int(rng.integers(0, 25))):
        cx, cy = rng.uniform(-5, w + 5), rng.uniform(-5, h + 5)
        r = rng.uniform(0.3, max(w, h) / 2)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 <= r * r] = BLUE
    return img


def _depth(kind: str, w: int, h: int, seed: int) -> np.ndarray | None:
    rng = np.random.default_rng(seed + 1)
    if kind == "none":
        return None
    if kind == "zeros":
        return np.zeros((h, w), np.uint16)
    if kind == "max":
        return np.full((h, w), 65535, np.uint16)
    d = rng.integers(0, 65536, (h, w), dtype=np.uint16)
    d[rng.random((h, w)) < 0.3] = 0  # holes
    return d


images = st.tuples(
    st.sampled_from(["noise", "blue", "skin", "flat", "discs"]),
    st.sampled_from(["none", "zeros", "max", "random"]),
    st.integers(0, 2**31 - 1),
)


@PROPERTY
@given(
    w=st.integers(16, 97),
    h=st.integers(16, 81),
    frames=st.lists(images, min_size=1, max_size=4),
    learn=st.booleans(),
)
def test_detector_never_raises_and_reports_sane_blobs(w, h, frames, learn):
    camera = Camera(fx=0.8 * w + 1, fy=0.8 * w + 1, cx=(w - 1) / 2, cy=(h - 1) / 2, width=w,
                    height=h)
    detector = MarkerDetector(camera)
    for k, (kind, depth_kind, seed) in enumerate(frames):
        bgr = _image(kind, w, h, seed)
        depth = _depth(depth_kind, w, h, seed)
        det = detector.detect(bgr, depth, k / 30)
        assert det.uv.shape == (det.count, 2)
        assert np.isfinite(det.uv).all()
        assert (det.uv >= -0.5).all() and (det.uv[:, 0] <= w - 0.5).all()
        assert (det.uv[:, 1] <= h - 0.5).all()
        if depth is None:
            assert det.depth is None
        else:
            assert det.depth.shape == (det.count,)
            known = det.depth[~np.isnan(det.depth)]
            assert np.isfinite(known).all() and (known > 0).all()
        if learn:  # the pipeline teaches the detector six marker positions after the first fix
            uv = np.random.default_rng(seed).uniform([0, 0], [w - 1, h - 1], (6, 2))
            detector.learn_markers(bgr, uv)


def test_detector_refuses_images_below_its_minimum_with_input_error():
    camera = Camera(fx=10.0, fy=10.0, cx=4.0, cy=4.0, width=8, height=8)
    with pytest.raises(InputError, match="colour frame"):
        MarkerDetector(camera).detect(np.zeros((8, 8, 3), np.uint8), None, 0.0)


# -------------------------------------------------------------------------------- tracker

_RNG = np.random.default_rng(21)
_TRUTH, CAMERA, LAYOUT = scenario("deviation", rng=_RNG)
SIM = simulate_detections(_TRUTH, CAMERA, LAYOUT, NoiseModel(p_miss=0.05), _RNG)

CONFIGS = {
    "default": TrackerConfig(),
    "no-depth": TrackerConfig(use_depth=False),
    "jpda": TrackerConfig(association="jpda"),
    "paper": TrackerConfig.paper(),
}

odd_depths = st.sampled_from([math.nan, 0.0, -0.5, 1e-9, 0.3, 0.65, 2.0, 1e4, math.inf])
positions = st.tuples(st.floats(-400.0, 1040.0), st.floats(-400.0, 880.0))

# a time step: ordinary, tiny, a big gap, or not forwards at all (repeat / backwards)
steps = st.one_of(
    st.floats(1 / 120, 1 / 10),
    st.floats(1 / 120, 1 / 10),
    st.floats(1e-6, 1e-3),
    st.floats(0.3, 10.0),
    st.sampled_from([0.0, -1 / 30, -5.0]),
)


@st.composite
def frame_ops(draw):
    kind = draw(st.sampled_from(
        ["true"] * 4 + ["random", "duplicates", "nan_depth", "no_depth", "empty"]
    ))
    dt = draw(steps)
    if kind == "random":
        blobs = draw(st.lists(st.tuples(positions, odd_depths), max_size=20))
        with_depth = draw(st.booleans())
        return kind, dt, blobs, with_depth
    if kind in ("duplicates", "nan_depth"):
        return kind, dt, draw(st.lists(st.integers(0, 30), min_size=1, max_size=8)), None
    return kind, dt, None, None


def _detections(op, k: int, t: float) -> Detections:
    kind, _, data, with_depth = op
    true = SIM[min(k, len(SIM) - 1)].detections
    if kind == "random":
        uv = np.array([p for p, _ in data], float).reshape(-1, 2)
        depth = np.array([d for _, d in data], float) if with_depth else None
        return Detections(t, uv, depth)
    if kind == "empty":
        return Detections(t, np.zeros((0, 2)), np.zeros(0))
    if kind == "no_depth":
        return Detections(t, true.uv, None)
    if kind == "true":
        return Detections(t, true.uv, true.depth)
    picks = [i % max(true.count, 1) for i in data]
    if kind == "nan_depth" and true.count:
        depth = true.depth.copy()
        depth[picks] = np.nan
        return Detections(t, true.uv, depth)
    if kind == "duplicates" and true.count:  # the same blob twice, exactly or nearly
        jitter = np.where(np.arange(len(picks))[:, None] % 2, 0.3, 0.0)
        uv = np.vstack([true.uv, true.uv[picks] + jitter])
        depth = np.concatenate([true.depth, true.depth[picks]])
        return Detections(t, uv, depth)
    return Detections(t, true.uv, true.depth)


def _check_result(r) -> None:
    assert isinstance(r.status, Status)
    pose = (r.R_ch, r.t_ch, r.R, r.p, r.v, r.w)
    if r.has_estimate:
        assert all(np.isfinite(a).all() for a in pose), r.status
        np.testing.assert_allclose(r.R_ch @ r.R_ch.T, np.eye(3), atol=1e-9)
        P = r.cov
        assert np.isfinite(P).all()
        np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * np.abs(P).max())
        assert np.linalg.eigvalsh(P).min() > 0
        np.linalg.cholesky(P)
    else:
        assert r.status != Status.TRACKING
        assert all(np.isnan(a).all() for a in pose[:4])


# Re-initialising among 8-12 random blobs costs a few hundred ms, so the lists stay short.
@settings(PROPERTY, max_examples=20)
@given(config=st.sampled_from(sorted(CONFIGS)), ops=st.lists(frame_ops(), min_size=1,
                                                               max_size=20))
def test_tracker_survives_any_blobs_and_timestamps(config, ops):
    tracker = Tracker(CAMERA, LAYOUT, CONFIGS[config])
    first = tracker.step(SIM[0].detections)  # a fix to start from, so every state is reached
    _check_result(first)
    t = last = SIM[0].detections.timestamp
    for k, op in enumerate(ops, start=1):
        t = t + op[1]
        det = _detections(op, k, t)
        if t <= last:  # the documented refusal; the track is left as it was
            with pytest.raises(InputError, match="increasing"):
                tracker.step(det)
            continue
        _check_result(tracker.step(det))
        last = t


@settings(PROPERTY, max_examples=15)
@given(st.lists(st.floats(-1.0, 1.0) | st.sampled_from([0.0, 1e-9, 5.0]), max_size=20))
def test_timestamps_are_refused_exactly_when_they_do_not_increase(increments):
    tracker = Tracker(CAMERA, LAYOUT)
    last, t = -math.inf, 0.0
    for k, dt in enumerate([0.0, *increments]):
        t += dt
        det = SIM[min(k, len(SIM) - 1)].detections
        det = Detections(t, det.uv, det.depth)
        if t <= last:
            with pytest.raises(InputError):
                tracker.step(det)
        else:
            _check_result(tracker.step(det))
            last = t


@PROPERTY
@given(
    uv=st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True),
                          st.floats(allow_nan=True, allow_infinity=True)), max_size=8),
    depth=st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=8),
)
def test_detections_take_impossible_depths_as_missing_and_refuse_non_finite_centres(uv, depth):
    depth = (depth + [0.5] * len(uv))[: len(uv)]
    uv_array = np.array(uv, float).reshape(-1, 2)
    if not np.isfinite(uv_array).all():
        with pytest.raises(InputError, match="finite"):
            Detections(0.0, uv_array, depth)
        return
    det = Detections(0.0, uv_array, depth)
    given_depth = np.array(depth, float)
    valid = np.isfinite(given_depth) & (given_depth > 0)
    np.testing.assert_array_equal(det.depth[valid], given_depth[valid])
    assert np.isnan(det.depth[~valid]).all()
