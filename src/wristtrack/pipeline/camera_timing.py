"""``wristtrack timing RECORDING``: a camera's timing measured from a recording of the hand.

Two numbers of camera.json change where a moving marker is seen, and a camera seldom says
them: ``readout_s``, how long a rolling-shutter colour sensor takes to read its rows (no SDK
reports it), and ``depth_delay_s``, how long after the colour its depth frame was captured
(a folder from another program keeps no stamps). The value that explains the markers best is
the right one: the recording's frames are detected once, then tracked again at values across
their range, and the one whose updates have the lowest normalised innovation (NIS per degree
of freedom) over the frames where the hand moves fastest wins, refined by a parabola through
the best three. A wrong value puts each marker where it was not seen, which the innovations
show; the frames where the hand is slow cannot tell, and averaged in they flattened the curve
(session 40's grid over the first 10 s of all frames missed delays by 5-9 ms).

Rendered recordings of the robustness movement (3 seeds): readouts 17.3, 22.7, 18.7 ms gave
16.4, 22.6, 18.0 ms, and with every other effect too (whose errors flatten the curve to a 2-4 %
dip) 14.3, 24.0, 17.5 ms; depth delays -2.9, -11.9, 12.8 ms gave -3.4, -11.3, 12.6 ms, and
with every effect -2.4, -9.8, 12.2 ms. A hand held still explains every value alike, and the
command says so instead of guessing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InputError
from wristtrack.io.base import Recording
from wristtrack.tracking.results import FrameResult
from wristtrack.tracking.tracker import Tracker, TrackerConfig

GRID_STEPS = 6  # values tried across the range, in this many steps
FAST_SHARE = 1 / 3  # the frames the NIS is taken over: the fastest third
# The best value must explain the fast frames this much better (NIS) than the worst one, or
# the recording moved too little to tell: a still hand 0.3 %, every effect at once 2-4 %.
MIN_CONTRAST = 0.01
# ... and the fast frames must move (their median image speed, px/s): a still hand's rates are
# noise, whose coupling with a stated depth delay alone moved the NIS 5 % (the fast third of a
# reach moves at 300-700 px/s, of a still start at ~5).
MIN_IMAGE_SPEED = 50.0
ARM_M = 0.05  # the markers' typical distance from the hand's origin, for their image speed


@dataclass(frozen=True)
class TimingEstimate:
    """The value (s) of camera.json's ``field`` that explains the markers best, and the curve
    it was found on."""

    field: str  # "readout_s" or "depth_delay_s"
    value: float
    tried: tuple[float, ...]  # values (s)
    nis: tuple[float, ...]  # mean NIS per dof over the fast frames, for each
    frames: int  # the fast frames it was taken over


def detect_all(recording: Recording) -> list[Detections]:
    """Every readable frame's detections, in order (unreadable frames left out)."""
    detector = MarkerDetector(recording.camera)
    found = [detector.detect(f.bgr, f.depth, f.timestamp, f.depth_delay)
             for f in recording.frames() if f.ok]
    if not found:
        raise InputError(f"{recording.source}: no frame could be read")
    return found


def estimate_readout(recording: Recording, detections: list[Detections],
                     camera: Camera | None = None,
                     config: TrackerConfig | None = None) -> TimingEstimate:
    """The rolling shutter's readout (s) of ``camera`` (default the recording's): from none to
    one frame interval, over the frames where the markers move fastest in the image."""
    interval = _frame_interval(recording, detections)
    return _search(recording, detections, camera or recording.camera, config or TrackerConfig(),
                   "readout_s",
                   np.linspace(0.0, interval, GRID_STEPS + 1),
                   lambda camera, value: replace(camera, readout=value or None))


def estimate_depth_delay(recording: Recording, detections: list[Detections],
                         camera: Camera | None = None,
                         config: TrackerConfig | None = None) -> TimingEstimate:
    """The depth frames' capture after their colour frames (s) for ``camera`` (default the
    recording's): within half a frame interval either way (the pairing's reach), over the
    frames where the markers move fastest. (Frames that carry their own delay, the camera's
    stamps, need none: they are read at it where camera.json states none.)"""
    if all(d.depth is None for d in detections):
        raise InputError(f"{recording.source} has no depth: there is no depth delay to measure")
    half = _frame_interval(recording, detections) / 2
    return _search(recording, detections, camera or recording.camera, config or TrackerConfig(),
                   "depth_delay_s",
                   np.linspace(-half, half, GRID_STEPS + 1),
                   lambda camera, value: replace(camera, depth_delay=value))


def _frame_interval(recording: Recording, detections: list[Detections]) -> float:
    times = np.array([d.timestamp for d in detections])
    interval = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    if not interval > 0:
        raise InputError(f"{recording.source}: too few frames to measure the camera's timing")
    return interval


def _search(recording: Recording, detections: list[Detections], camera: Camera,
            config: TrackerConfig, field: str, values: np.ndarray,
            with_value: Callable[[Camera, float], Camera]) -> TimingEstimate:
    runs = [_track(with_value(camera, float(v)), recording, detections, config) for v in values]
    middle = runs[len(runs) // 2]  # the frames are ranked by speed as one run tracked them
    speeds = np.array([_image_speed(r, camera.fx) if r.nis_dof else np.nan for r in middle])
    if np.count_nonzero(np.isfinite(speeds)) < 10:
        raise InputError(f"{recording.source}: the hand was tracked in too few frames to measure "
                         f"{field}; record the hand moving fast across the image")
    fast = speeds >= np.nanquantile(speeds, 1 - FAST_SHARE)
    nis = [_fast_nis(results, fast) for results in runs]
    best = int(np.argmin(nis))
    moved = float(np.median(speeds[fast]))
    if moved < MIN_IMAGE_SPEED or (max(nis) - nis[best]) < MIN_CONTRAST * nis[best]:
        raise InputError(
            f"{recording.source}: every {field} from {1e3 * values[0]:.0f} to "
            f"{1e3 * values[-1]:.0f} ms explains the markers alike (the hand moved too little: "
            f"{moved:.0f} px/s in its fastest frames); record the hand moving fast across the "
            "image")
    value = float(values[best])
    if 0 < best < len(values) - 1:  # the parabola's vertex through the best three
        a, b, c = nis[best - 1:best + 2]
        step = float(values[1] - values[0])
        if a - 2 * b + c > 0:
            value += float(np.clip(0.5 * step * (a - c) / (a - 2 * b + c), -step / 2, step / 2))
    return TimingEstimate(field, value, tuple(float(v) for v in values), tuple(nis),
                          int(fast.sum()))


def _image_speed(result: FrameResult, fx: float) -> float:
    """The markers' image speed (px/s), roughly: the hand's speed and its turning at ARM_M
    from its origin, seen at its depth."""
    moving = float(np.linalg.norm(result.v)) + ARM_M * float(np.linalg.norm(result.w))
    return fx * moving / float(result.t_ch[2])


def _track(camera: Camera, recording: Recording, detections: list[Detections],
           config: TrackerConfig) -> list[FrameResult]:
    tracker = Tracker(camera, recording.hand, config)
    return [tracker.step(d) for d in detections]


def _fast_nis(results: list[FrameResult], fast: np.ndarray) -> float:
    """Mean NIS per degree of freedom of ``results`` over the ``fast`` frames with an update."""
    values = [r.nis / r.nis_dof for r, f in zip(results, fast, strict=True)
              if f and r.nis_dof and np.isfinite(r.nis)]
    return float(np.mean(values)) if values else np.inf
