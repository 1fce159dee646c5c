"""``wristtrack readout RECORDING``: a rolling shutter's readout measured from a recording.

No camera SDK reports how long its colour sensor takes to read its rows (camera.json
``readout_s``), and a marker moving fast is seen where it was when its row was read. The
readout that explains the markers best is the right one: the recording's frames are detected
once, then tracked again at readouts from none to one frame interval, and the one whose
updates have the lowest normalised innovation (NIS per degree of freedom) over the frames
where the hand turns fastest wins, refined by a parabola through the best three. A wrong
readout puts each marker where its row was not read, which the innovations show.

Rendered recordings of the robustness movement (readouts 17.3, 22.7 and 18.7 ms) gave 16.4,
22.8 and 18.1 ms; with every other effect too (`--preset real`), whose errors flatten the
curve to a 2-4 % dip, 14.9, 25.4 and 17.6 ms. A fast reach: 18.6 ms for 18.8
(tests/pipeline/test_readout.py). A hand held still explains every readout alike (0.3 %
apart), and the command says so instead of guessing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InputError
from wristtrack.io.base import Recording
from wristtrack.tracking.tracker import Tracker, TrackerConfig

GRID_STEPS = 6  # readouts tried: 0 to one frame interval in this many steps
FAST_SHARE = 1 / 3  # the frames the NIS is taken over: the fastest turning third
# The best readout must explain the fast frames this much better (NIS) than the worst one, or
# the recording moved too little to tell: a still hand 0.3 %, every effect at once 2-4 %.
MIN_CONTRAST = 0.01


@dataclass(frozen=True)
class ReadoutEstimate:
    """The readout (s) that explains the markers best, and the curve it was found on."""

    readout: float
    tried: tuple[float, ...]  # readouts (s)
    nis: tuple[float, ...]  # mean NIS per dof over the fast frames, for each
    frames: int  # the fast frames it was taken over


def detect_all(recording: Recording, progress: Callable[[int], None] | None = None
               ) -> list[Detections]:
    """Every readable frame's detections, in order (unreadable frames left out)."""
    detector = MarkerDetector(recording.camera)
    found = []
    for frame in recording.frames():
        if frame.ok:
            found.append(detector.detect(frame.bgr, frame.depth, frame.timestamp,
                                         frame.depth_delay))
        if progress is not None:
            progress(frame.index)
    if not found:
        raise InputError(f"{recording.source}: no frame could be read")
    return found


def estimate_readout(recording: Recording, detections: list[Detections],
                     config: TrackerConfig | None = None) -> ReadoutEstimate:
    """The readout (s) under which ``detections`` (of ``recording``) are explained best."""
    config = config or TrackerConfig()
    times = np.array([d.timestamp for d in detections])
    interval = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    if not interval > 0:
        raise InputError(f"{recording.source}: too few frames to measure a readout from")
    global_shutter = _track(recording, detections, config, None)
    turning = np.array([np.linalg.norm(r.w) if r.nis_dof else np.nan for r in global_shutter])
    if np.count_nonzero(np.isfinite(turning)) < 10:
        raise InputError(f"{recording.source}: the hand was tracked in too few frames to measure "
                         "a readout; record the hand turning fast across the image")
    fast = turning >= np.nanquantile(turning, 1 - FAST_SHARE)
    tried = list(np.linspace(0.0, interval, GRID_STEPS + 1))
    nis = [_fast_nis(global_shutter, fast)]
    nis += [_fast_nis(_track(recording, detections, config, r), fast) for r in tried[1:]]
    best = int(np.argmin(nis))
    if (max(nis) - nis[best]) < MIN_CONTRAST * nis[best]:
        raise InputError(
            f"{recording.source}: every readout from 0 to {1e3 * interval:.0f} ms explains the "
            "markers alike (the hand moved too little); record the hand turning fast across the "
            "image, or take the frame interval as the readout's upper bound")
    readout = tried[best]
    if 0 < best < len(tried) - 1:  # the parabola's vertex through the best three
        a, b, c = nis[best - 1:best + 2]
        step = tried[1] - tried[0]
        curvature = a - 2 * b + c
        if curvature > 0:
            readout += float(np.clip(0.5 * step * (a - c) / curvature, -step / 2, step / 2))
    return ReadoutEstimate(readout, tuple(tried), tuple(nis), int(fast.sum()))


def _track(recording: Recording, detections: list[Detections], config: TrackerConfig,
           readout: float | None) -> list:
    tracker = Tracker(replace(recording.camera, readout=readout), recording.hand, config)
    return [tracker.step(d) for d in detections]


def _fast_nis(results: list, fast: np.ndarray) -> float:
    """Mean NIS per degree of freedom of ``results`` over the ``fast`` frames with an update."""
    values = [r.nis / r.nis_dof for r, f in zip(results, fast, strict=True)
              if f and r.nis_dof and np.isfinite(r.nis)]
    return float(np.mean(values)) if values else np.inf
