"""``wristtrack track --live SOURCE``: tracking a camera in real time.

A capture thread reads the source as fast as it delivers and puts each frame, stamped with
its arrival time, into a single slot; the tracking loop takes the newest frame from that slot.
A frame that arrives while the previous one is still waiting in the slot replaces it: the
waiting one is dropped, counted and written to poses.csv as a ``dropped`` row, so nothing
queues up and the estimate never lags behind the camera by more than one frame. Every frame
that is processed gets its latency, from arrival to its pose row written, in ``live.json``.

Ctrl-C (or SIGTERM) ends the session at the end of the current frame: the outputs are then
complete, as when the source ends by itself. Live tracking is causal: smooth a ``--record``
copy of the session offline.

The detector's colours are learnt at the first fix and then follow the light every 10th
confidently tracked frame, as offline (pipeline/colours.py), between frames: 6-10 ms each on
a shared 2-core server (learning 7-8 ms), a third of a frame period at 30 fps.

Without hand.json the session is tracked with the still start's layout (a camera cannot be read
twice), and the layout surveyed over the session (tracking/layout_survey.py) is written as
hand_surveyed.json, a hand.json for the subject's next session.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.analysis.kinematics import analyse_file
from wristtrack.analysis.summary import SummaryAccumulator, camera_pose_dict
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InitialisationError, InputError, WristtrackError
from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.base import Frame, Recording
from wristtrack.io.live.record import LiveRecorder
from wristtrack.io.poses import PosesWriter
from wristtrack.io.run_folder import SURVEYED_HAND
from wristtrack.pipeline.colours import follow_colours
from wristtrack.pipeline.frame_step import came_without_depth, skipped_row
from wristtrack.pipeline.interrupt import DeferredInterrupt
from wristtrack.pipeline.track import no_initialisation_message, settings_dict
from wristtrack.tracking import compiled
from wristtrack.tracking.layout_survey import RunSurvey
from wristtrack.tracking.tracker import Tracker, TrackerConfig

LIVE_JSON = "live.json"
DROPPED = "dropped"  # poses.csv status of a frame the tracker had no time for
STOP_POLL_S = 0.1  # how often the loop looks for Ctrl-C while waiting for a frame


@dataclass
class Captured:
    frame: Frame
    arrived: float  # time.perf_counter() when the source delivered it


class NewestFrameSlot:
    """One slot between the capture thread and the tracking loop; the newest frame wins.

    :meth:`put` never blocks: a frame still waiting is replaced and noted as dropped.
    :meth:`take` waits for a frame and returns it with the frames dropped since the last take
    (index, timestamp), or None once the source has ended and the slot is empty.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._item: Captured | None = None
        self._dropped: list[tuple[int, float]] = []
        self.ended = False
        self.error: str | None = None

    def put(self, item: Captured) -> None:
        with self._cond:
            if self._item is not None:
                old = self._item.frame
                self._dropped.append((old.index, old.timestamp))
            self._item = item
            self._cond.notify()

    def end(self, error: str | None = None) -> None:
        with self._cond:
            self.ended, self.error = True, error
            self._cond.notify()

    def take(self, timeout: float) -> tuple[Captured | None, list[tuple[int, float]]]:
        """(frame, dropped) -- frame None on timeout, or at the end (``ended`` then True)."""
        with self._cond:
            if self._item is None and not self.ended:
                self._cond.wait(timeout)
            item, dropped = self._item, self._dropped
            self._item, self._dropped = None, []
            return item, dropped


class CaptureThread(threading.Thread):
    """Reads ``source`` into ``slot`` (and every frame into ``recorder``) until it ends or
    :meth:`stop` is called. A source error ends the slot with its one-line message."""

    def __init__(self, source: Recording, slot: NewestFrameSlot,
                 recorder: LiveRecorder | None = None) -> None:
        super().__init__(name="wristtrack-capture", daemon=True)  # a hung device cannot block exit
        self.source, self.slot, self.recorder = source, slot, recorder
        self.captured = 0
        self._stop_event = threading.Event()

    def stop(self) -> None:
        self._stop_event.set()

    def run(self) -> None:
        error = None
        frames = self.source.frames()
        try:
            for frame in frames:
                arrived = time.perf_counter()
                if self._stop_event.is_set():
                    break
                self.captured += 1
                if self.recorder is not None and frame.ok:
                    self.recorder.put(frame.timestamp, frame.bgr, frame.depth, frame.depth_delay)
                self.slot.put(Captured(frame, arrived))
        except WristtrackError as exc:
            error = str(exc)
        except Exception as exc:  # a device library's own error: still one line for the user
            error = f"{self.source.source}: {type(exc).__name__}: {exc}"
        finally:
            frames.close()  # the generator belongs to this thread: close it here
            self.slot.end(error)


@dataclass
class LiveLog:
    """Per-frame latency and the drops of one session; ``to_dict`` is live.json."""

    frame: list[int] = field(default_factory=list)
    timestamp: list[float] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)  # arrival -> pose row written
    processing_ms: list[float] = field(default_factory=list)  # taken from the slot -> written
    dropped: list[int] = field(default_factory=list)
    bad: list[int] = field(default_factory=list)
    # processed frames of a depth camera that came without depth: their depth frame was lost
    # or was not of their moment (io.base.pairing_tolerance); tracked on colour alone
    without_depth: list[int] = field(default_factory=list)

    def add(self, frame: Frame, arrived: float, started: float, done: float) -> None:
        self.frame.append(frame.index)
        self.timestamp.append(frame.timestamp)
        self.latency_ms.append((done - arrived) * 1e3)
        self.processing_ms.append((done - started) * 1e3)

    def frame_period_ms(self) -> float | None:
        dt = np.diff(np.asarray(self.timestamp, float))
        dt = dt[dt > 0]
        return float(np.median(dt) * 1e3) if dt.size else None

    def stats(self) -> dict[str, Any]:
        """Running numbers for the live view and the closing line."""
        lat = np.asarray(self.latency_ms[-90:], float)
        t = np.asarray(self.timestamp[-30:], float)
        fps = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else None
        return {
            "frames": len(self.frame) + len(self.dropped) + len(self.bad),
            "processed": len(self.frame),
            "dropped": len(self.dropped),
            "fps": fps,
            "latency_ms": float(lat[-1]) if lat.size else None,
            "latency_p95_ms": float(np.percentile(lat, 95)) if lat.size else None,
        }

    def to_dict(self, **extra: Any) -> dict[str, Any]:
        lat = np.asarray(self.latency_ms, float)
        period = self.frame_period_ms()

        def pct(q: float) -> float | None:
            return float(np.percentile(lat, q)) if lat.size else None

        return {
            "frames": {
                "total": len(self.frame) + len(self.dropped) + len(self.bad),
                "processed": len(self.frame),
                "dropped": len(self.dropped),
                "bad": len(self.bad),
                "without_depth": len(self.without_depth),
            },
            "frame_period_ms": period,
            "latency_ms": {
                "definition": "frame arrival from the source to its poses.csv row written",
                "mean": float(lat.mean()) if lat.size else None,
                "p50": pct(50), "p95": pct(95), "p99": pct(99),
                "max": float(lat.max()) if lat.size else None,
                "over_frame_period": int((lat > period).sum()) if period and lat.size else 0,
            },
            "dropped_frames": self.dropped,
            "bad_frames": self.bad,
            "frames_without_depth": self.without_depth,
            "per_frame": {
                "frame": self.frame,
                "timestamp": self.timestamp,
                "latency_ms": [round(x, 3) for x in self.latency_ms],
                "processing_ms": [round(x, 3) for x in self.processing_ms],
            },
            **extra,
        }


def track_live(
    source: Recording,
    out: str | Path,
    config: TrackerConfig | None = None,
    *,
    record: str | Path | None = None,
    view: Any = None,
    overlay: Any = None,
    max_seconds: float | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Track ``source`` in real time into ``out`` (poses.csv, summary.json, live.json).

    ``record``: also write every captured frame as a recording folder there. ``view`` (a
    view.LiveView) and ``overlay`` (a report.overlay.OverlayWriter) receive each processed
    frame with its detections and estimate, after its latency is taken. ``max_seconds`` ends
    the session after that much wall time. Returns (summary, live log) as written.
    """
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"cannot create the output folder {out} ({e.strerror}); give --out a "
                         "folder you can write to") from None
    for stale in ("summary.json", LIVE_JSON, SURVEYED_HAND):
        (out / stale).unlink(missing_ok=True)
    # a live camera cannot be read twice: its noise is learned from the first frame on
    config = replace(config or TrackerConfig(), prime_noise=False)
    camera = source.camera
    detector = MarkerDetector(camera)
    tracker = Tracker(camera, source.hand, config)
    # without hand.json the layout is surveyed as the session goes, for the subject's next one
    # (a live camera cannot be read twice: this session keeps the still start's)
    survey = RunSurvey() if source.hand is None else None
    summary = SummaryAccumulator()
    log = LiveLog()
    learned = False  # the detector's colours, from the first fix on
    skipped: list[dict[str, Any]] = []  # unusable frames, for summary.json (drops: live.json)
    recorder = LiveRecorder(record, camera, source.hand) if record is not None else None
    slot = NewestFrameSlot()
    capture = CaptureThread(source, slot, recorder)
    # Load (or compile) the tracker's compiled step now: in the first tracked frame it would
    # take ~0.3-1.5 s and drop the frames of that time.
    compiled.load()
    deadline = None if max_seconds is None else time.perf_counter() + max_seconds
    stopped_by = None
    try:
        with PosesWriter(out / "poses.csv") as writer, DeferredInterrupt() as stop:
            capture.start()
            while True:
                if stop.requested or (deadline is not None and time.perf_counter() > deadline):
                    stopped_by = stop.requested or "time limit"
                    break
                item, dropped = slot.take(STOP_POLL_S)
                for index, timestamp in dropped:
                    writer.write(skipped_row(index, timestamp, 0, DROPPED))
                    log.dropped.append(index)
                if item is None:
                    if slot.ended:
                        break
                    continue
                started = time.perf_counter()
                frame = item.frame
                if not frame.ok:
                    writer.write(skipped_row(frame.index, frame.timestamp, 0, "bad_frame"))
                    log.bad.append(frame.index)
                    skipped.append({"frame": frame.index, "error": frame.error})
                    continue
                if came_without_depth(frame, source.has_depth):
                    log.without_depth.append(frame.index)
                det = detector.detect(frame.bgr, frame.depth, frame.timestamp, frame.depth_delay)
                try:
                    result = tracker.step(det)
                except InputError as exc:  # e.g. a timestamp going backwards: skip the frame
                    writer.write(skipped_row(frame.index, frame.timestamp, det.count, "skipped"))
                    log.bad.append(frame.index)
                    skipped.append({"frame": frame.index, "error": str(exc)})
                    continue
                if result.frame != frame.index:  # after dropped frames: the source's numbers
                    result = replace(result, frame=frame.index)
                writer.write_result(result)
                log.add(frame, item.arrived, started, time.perf_counter())
                summary.add(result)
                if survey is not None:
                    survey.add(tracker, det, result)
                learned = follow_colours(detector, frame.bgr, det, result, frame.index, learned)
                if view is not None:
                    view.publish(frame.bgr, det, result, log.stats())
                if overlay is not None:
                    overlay.add(frame.bgr, det, result)
    finally:
        capture.stop()
        capture.join(timeout=5.0)
        source.close()
        if recorder is not None:
            recorder.close()
    if slot.error is not None and log.frame == [] and not log.bad:
        raise InputError(slot.error)  # the source failed before delivering a frame
    live = log.to_dict(
        source=str(source.source),
        ended_by=stopped_by or ("source error" if slot.error else "end of stream"),
        source_error=slot.error,
        **_source_notes(source),
        record=_record_notes(recorder),
    )
    write_json_atomic(out / LIVE_JSON, live)
    surveyed = survey.surveyed_layout() if survey is not None else None
    if surveyed is not None:
        write_json_atomic(out / SURVEYED_HAND, surveyed.to_dict())
    data = summary.to_dict(
        hand_layout=tracker.layout.to_dict() if tracker.layout is not None else None,
        camera_pose_w0=camera_pose_dict(tracker.R_c0, tracker.t_c0),
        camera=camera.to_dict(),
        source=str(source.source),
        settings={**settings_dict(config), "smoothed": False, "live": True,
                  "hand_layout_from": "hand.json" if source.hand is not None else "still start"},
        skipped_frames=skipped,
        frames_without_depth=log.without_depth,
        # e.g. an unresolved planar flip, a rolling shutter of unknown readout
        warnings=[*getattr(source, "warnings", []), *getattr(tracker, "warnings", [])],
        depth_timing=tracker.depth_timing.to_dict(),  # from the camera's stamps, where it has them
        interrupted=False,
        live={k: live[k] for k in ("frames", "latency_ms", "ended_by")},
        hand_layout_surveyed=surveyed.to_dict() if surveyed is not None else None,
        kinematics=analyse_file(out / "poses.csv"),
    )
    write_json_atomic(out / "summary.json", data)
    if view is not None:
        view.finish(log.stats(), live["ended_by"])
    if tracker.R_c0 is None:
        raise InitialisationError(no_initialisation_message(source, summary.frames, tracker))
    return data, live


def _source_notes(source: Recording) -> dict[str, Any]:
    """What the source knows about its own timing (a replay: how often decoding ran late)."""
    notes = {}
    if hasattr(source, "late_frames"):
        notes["replay"] = {"late_frames": source.late_frames,
                           "max_late_ms": round(source.max_late_ms, 3),
                           "speed": getattr(source, "speed", 1.0)}
    return notes


def _record_notes(recorder: LiveRecorder | None) -> dict[str, Any] | None:
    if recorder is None:
        return None
    return {"folder": str(recorder.folder), "frames": recorder.written, "lost": recorder.lost,
            "error": recorder.error, "depth_delay_s": recorder.depth_delay}
