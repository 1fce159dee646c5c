"""``wristtrack timing RECORDING``: a camera's timing measured from a recording of the hand.

Two numbers of camera.json change where a moving marker is seen, and a camera seldom says
them: ``readout_s``, how long a rolling-shutter colour sensor takes to read its rows (no SDK
reports it), and ``depth_delay_s``, how long after the colour its depth frame was captured
(a folder from another program keeps no stamps). The value that explains the markers best is
the right one: the recording's frames are detected once, then tracked again at values across
their range, and the one whose updates have the lowest normalised innovation (NIS per degree
of freedom) over the frames where the hand moves fastest wins, refined by a parabola through
the best three. The frames where the hand is slow cannot tell, and averaged in they flattened
the curve (session 40's grid over the first 10 s of all frames missed delays by 5-9 ms).

Whether those frames tell at all: a value is seen only in how it moves the markers'
measurements *against each other*. What it moves them all alike, the filter takes as the hand
being elsewhere: a depth delay on a hand moving bodily towards the camera reads as a hand a
little nearer, and the innovations do not show it. So each fast frame is scored by how far the
range's largest value moves its markers apart (their shifts less their mean, rms; the state's
rates through the tracker's own models: ``observation.rolling_shift``,
``observation.lag_depth_change``). Where the median moves them apart by less than
``MIN_EFFECT`` of their noise sigma (the model's), the recording cannot tell the values apart
and the command says so:

- readout, at a whole frame interval: 0.36-0.77 px on rendered reaches (1.2-2.6 of the
  model's 0.3 px), 0.18 px (0.6) on the robustness movement, with or without every other
  effect, and 0.02-0.04 px (0.06-0.12) on a fast pronation, whose markers turn in depth,
  hardly across the image: a parabola through its flat curve put a global shutter's readout
  at 5.6-6.9 ms;
- depth delay, at half a frame interval: 0.6 of the depth sigma on the robustness movement,
  0.8-1.5 on a pronation (measured within 0.3 ms), and 0.11-0.19 on reaches, whose hand
  moves bodily: their minimum fell at the range's edge (-16.7 ms) for rendered delays of 0,
  -2.9 and -11.9 ms.

The frames are ranked by the markers' image speed as the filter's pixel noise takes it
(``pixel_noise.image_speed2``). Rendered recordings of the robustness movement (3 seeds):
readouts 17.3, 22.7, 18.7 ms gave 16.6, 22.7, 18.1 ms, and with every other effect too (whose
errors flatten the curve to a 2-4 % dip) 16.8, 22.5, 19.7 ms; depth delays -2.9, -11.9,
12.8 ms gave -3.4, -11.2, 12.5 ms, and with every effect -3.4, -11.8, 12.6 ms. With neither
stated (every effect; the readout first, the delay through it, as the command runs) 16.9,
22.3, 18.0 ms and -3.4, -11.8, 12.5 ms: the delay left unknown costs the readout nothing
here, and a second round of both did not improve them. A hand held still explains every
value alike, and the command says so instead of guessing.
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
from wristtrack.tracking.observation import (
    MeasurementNoise,
    lag_depth_change,
    point_rates,
    rolling_shift,
)
from wristtrack.tracking.pixel_noise import image_speed2, mean_square_radius
from wristtrack.tracking.results import FrameResult
from wristtrack.tracking.tracker import Tracker, TrackerConfig

GRID_STEPS = 6  # values tried across the range, in this many steps
FAST_SHARE = 1 / 3  # the frames the NIS is taken over: the fastest third
# The best value must explain those frames this much better (NIS) than the worst one, or the
# recording cannot tell: a still hand 0.3 %, every effect at once 2-4 %.
MIN_CONTRAST = 0.01
# ... and the range's largest value must move their markers apart by this share of their
# noise sigma: the geometric middle of the most that did not tell (0.21) and the least that did
# (0.58; the module's doc). Ranked by this instead of by speed, the frames told less under
# every effect at once (readouts 4.3, 4.8, 2.1 ms off against 3.0, 1.3, 1.2).
MIN_EFFECT = 0.35


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
                   _READOUT, np.linspace(0.0, interval, GRID_STEPS + 1))


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
                   _DEPTH_DELAY, np.linspace(-half, half, GRID_STEPS + 1))


def _frame_interval(recording: Recording, detections: list[Detections]) -> float:
    times = np.array([d.timestamp for d in detections])
    interval = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    if not interval > 0:
        raise InputError(f"{recording.source}: too few frames to measure the camera's timing")
    return interval


def _search(recording: Recording, detections: list[Detections], camera: Camera,
            config: TrackerConfig, field: _Field, values: np.ndarray) -> TimingEstimate:
    def track(value: float) -> tuple[np.ndarray, list[FrameResult]]:
        return _track(field.with_value(camera, float(value)), recording, detections, config)

    mid = len(values) // 2
    points, middle = track(values[mid])  # the frames are ranked, and judged, as it tracked them
    r2 = mean_square_radius(points)
    speeds = np.array([image_speed2(r.v, r.w, float(r.t_ch[2]), camera.fx, r2)
                       if r.nis_dof else np.nan for r in middle])
    if np.count_nonzero(np.isfinite(speeds)) < 10:
        raise InputError(f"{recording.source}: the hand was tracked in too few frames to measure "
                         f"{field.name}; {field.advice}")
    fast = speeds >= np.nanquantile(speeds, 1 - FAST_SHARE)
    largest = float(np.abs(values).max())
    moved = float(np.median([field.effect(camera, points, r, largest)
                             for r, f in zip(middle, fast, strict=True) if f]))
    noise = float(np.median([field.noise(config.measurement, r)
                             for r, f in zip(middle, fast, strict=True) if f]))
    if moved < MIN_EFFECT * noise:  # before the other values' runs: nothing to find
        raise InputError(
            f"{recording.source}: {field.name} cannot be told from this recording: at "
            f"{1e3 * largest:.0f} ms it would move the markers {field.apart} by "
            f"{moved * field.scale:.2f} {field.unit} (their noise {noise * field.scale:.2f} "
            f"{field.unit}) where the hand moves fastest; {field.advice}")
    nis = [_fast_nis(middle if k == mid else track(v)[1], fast) for k, v in enumerate(values)]
    best = int(np.argmin(nis))
    span = f"{1e3 * values[0]:.0f} to {1e3 * values[-1]:.0f} ms"
    if (max(nis) - nis[best]) < MIN_CONTRAST * nis[best]:
        raise InputError(f"{recording.source}: every {field.name} from {span} explains the "
                         f"markers alike; {field.advice}")
    value = float(values[best])
    if 0 < best < len(values) - 1:  # the parabola's vertex through the best three
        a, b, c = nis[best - 1:best + 2]
        step = float(values[1] - values[0])
        if a - 2 * b + c > 0:
            value += float(np.clip(0.5 * step * (a - c) / (a - 2 * b + c), -step / 2, step / 2))
    return TimingEstimate(field.name, value, tuple(float(v) for v in values), tuple(nis),
                          int(fast.sum()))


def _markers(points: np.ndarray, result: FrameResult) -> tuple[np.ndarray, np.ndarray]:
    """The markers' camera-frame positions and velocities (K, 3) each in frame ``result``."""
    at = points @ result.R_ch.T + result.t_ch
    R_c0 = result.R_ch @ result.R.T  # the W0 its rates are given in (a provisional one too)
    return at, point_rates(result.v[None], result.w[None], R_c0, (at - result.t_ch)[None])[0]


def _apart(shifts: np.ndarray) -> float:
    """rms over the markers of their ``shifts`` (K,) or (K, d) less their mean (the part the
    filter cannot take for the hand being elsewhere)."""
    d = shifts - shifts.mean(axis=0)
    return float(np.sqrt(np.sum(d * d) / max(len(d) - 1, 1)))


def _readout_effect(camera: Camera, points: np.ndarray, result: FrameResult,
                    readout: float) -> float:
    """px: how far a ``readout`` s rolling shutter moves the markers' images apart."""
    at, rates = _markers(points, result)
    shutter = replace(camera, readout=readout)
    return _apart(rolling_shift(shutter, at, rates, shutter.project(at)[:, 1]))


def _delay_effect(camera: Camera, points: np.ndarray, result: FrameResult,
                  delay: float) -> float:
    """m: how far a depth frame ``delay`` s after the colour moves the markers' depths apart."""
    at, rates = _markers(points, result)
    return _apart(lag_depth_change(at[None], result.R_ch[None, None, :, 2], rates[None],
                                   delay)[0])


@dataclass(frozen=True)
class _Field:
    """One of camera.json's timing fields as the search measures it."""

    name: str
    with_value: Callable[[Camera, float], Camera]
    effect: Callable[[Camera, np.ndarray, FrameResult, float], float]
    noise: Callable[[MeasurementNoise, FrameResult], float]  # the model's sigma, same unit
    apart: str  # what the effect moves apart, in words
    scale: float  # the effect in ``unit``
    unit: str
    advice: str


_READOUT = _Field("readout_s", lambda camera, value: replace(camera, readout=value or None),
                  _readout_effect, lambda noise, _: noise.pixel_sigma, "apart in the image",
                  1.0, "px",
                  "record the hand moving fast across the image")
_DEPTH_DELAY = _Field("depth_delay_s", lambda camera, value: replace(camera, depth_delay=value),
                      _delay_effect,
                      lambda noise, result: float(noise.depth_sigma(float(result.t_ch[2]))),
                      "apart in depth", 1e3, "mm",
                      "record the hand turning (flexing, pronating) fast in front of the camera")


def _track(camera: Camera, recording: Recording, detections: list[Detections],
           config: TrackerConfig) -> tuple[np.ndarray, list[FrameResult]]:
    """The layout the tracker used (K, 3) and its results on ``detections``."""
    tracker = Tracker(camera, recording.hand, config)
    results = [tracker.step(d) for d in detections]
    return tracker.layout.points if tracker.layout is not None else np.zeros((0, 3)), results


def _fast_nis(results: list[FrameResult], fast: np.ndarray) -> float:
    """Mean NIS per degree of freedom of ``results`` over the ``fast`` frames with an update."""
    values = [r.nis / r.nis_dof for r, f in zip(results, fast, strict=True)
              if f and r.nis_dof and np.isfinite(r.nis)]
    return float(np.mean(values)) if values else np.inf
