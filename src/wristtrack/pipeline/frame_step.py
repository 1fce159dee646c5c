"""One frame of ``track``: its detections, the tracker's step on them, its row in poses.csv.

Shared by the run's frame loop (pipeline/track.py) and the noise's priming pass
(pipeline/priming.py), which tracks the same way into rows it discards.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wristtrack.analysis.summary import SummaryAccumulator
from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InitialisationError, InputError
from wristtrack.io.base import Frame
from wristtrack.io.poses import PosesWriter, pose_row
from wristtrack.io.states import StateWriter
from wristtrack.pipeline.colours import follow_colours
from wristtrack.pipeline.sinks import Discarded, NoStates
from wristtrack.tracking.layout_survey import RunSurvey
from wristtrack.tracking.tracker import FrameResult, Status, Tracker

_NAN3 = np.full(3, np.nan)
_NAN33 = np.full((3, 3), np.nan)


@dataclass
class RunState:
    """What a run carries from one frame to the next: exactly what a checkpoint saves."""

    detector: MarkerDetector
    tracker: Tracker
    summary: SummaryAccumulator
    learned: bool = False  # the detector's colours were refined at the first fix
    bad_frames: list[dict[str, Any]] = field(default_factory=list)  # for summary.json
    # frames of a recording with depth that came without (a lost depth frame, or one not of
    # their moment: io.base.pairing_tolerance), tracked on colour alone; for summary.json
    without_depth: list[int] = field(default_factory=list)
    survey: RunSurvey | None = None  # a first pass's survey of the layout

    def saved(self) -> dict[str, Any]:
        return {"detector": self.detector, "tracker": self.tracker, "summary": self.summary,
                "learned": self.learned, "bad_frames": self.bad_frames,
                "without_depth": self.without_depth, "survey": self.survey}


@dataclass
class Rows:
    """Where each frame's outcome goes: its poses.csv row, its filter state (for --smooth),
    the overlay video, the progress bar."""

    writer: PosesWriter | Discarded
    states: StateWriter | NoStates
    overlay: Any
    bar: Any

    def skipped(self, index: int, timestamp: float, n_blobs: int, status: str) -> None:
        self.writer.write(skipped_row(index, timestamp, n_blobs, status))
        self.states.write(index, timestamp, None)

    def tracked(self, index: int, timestamp: float, result: FrameResult) -> None:
        self.writer.write_result(result)
        self.states.write(index, timestamp, result)


def track_frame(frame: Frame, run: RunState, labels: Any, rows: Rows) -> Detections | None:
    """One frame: detect, track, write its row; its detections (None for an unreadable
    frame, noted and written as a skipped row)."""
    if frame.error is not None:
        note_bad(rows.bar, run.bad_frames, frame.index, frame.error)
        rows.skipped(frame.index, frame.timestamp, 0, "bad_frame")
        return None
    det = run.detector.detect(frame.bgr, frame.depth, frame.timestamp, frame.depth_delay)
    track_detections(frame.index, frame.timestamp, det, run, labels, rows, frame.bgr)
    return det


def track_detections(index: int, timestamp: float, det: Detections, run: RunState,
                     labels: Any, rows: Rows, bgr: np.ndarray | None,
                     follow: bool = True) -> None:
    """The tracker's step on frame ``index``'s detections and its row; the overlay gets the
    frame's colour image ``bgr`` where there is one. With ``follow`` the detector's colours
    follow the labelled markers in ``bgr``; without (frames detected already, by the priming
    pass, whose detector has learned from them) they do not. A frame the tracker refuses (a
    timestamp going backwards) is noted and written as a skipped row."""
    manual = frame_labels(labels, index, det) if not run.learned else None
    try:
        result = run.tracker.step(det, manual)
    except InputError as exc:
        note_bad(rows.bar, run.bad_frames, index, str(exc))
        rows.skipped(index, timestamp, det.count, "skipped")
        if rows.overlay is not None and bgr is not None:
            rows.overlay.add(bgr, det, None)
        return
    if manual is not None and result.status != Status.TRACKING:
        raise InitialisationError(
            f"the manual labels of frame {index} do not initialise the tracker; "
            "check them with `wristtrack label INPUT --labels FILE --check`"
        )
    if result.frame != index:  # after skipped frames: the recording's numbers
        result = replace(result, frame=index)
    if follow and bgr is not None:
        run.learned = follow_colours(run.detector, bgr, det, result, index, run.learned)
    elif result.status == Status.TRACKING:
        run.learned = True  # its first fix: the colours were learned where it was detected
    if run.survey is not None:
        run.survey.add(run.tracker, det, result)
    rows.tracked(index, timestamp, result)
    if rows.overlay is not None and bgr is not None:
        rows.overlay.add(bgr, det, result)
    run.summary.add(result)


def came_without_depth(frame: Frame, has_depth: bool) -> bool:
    """A readable frame of a recording with depth (``has_depth``) that came without its depth:
    tracked on colour alone, and listed in summary.json."""
    return has_depth and frame.ok and frame.depth is None


def frame_labels(labels: Any, index: int, det) -> np.ndarray | None:
    """Manual labels for this frame's blobs, or None: the tracker labels them itself."""
    if labels is not None and hasattr(labels, "for_frame"):  # label.ManualLabels
        return labels.for_frame(index, det)
    return labels if index == 0 else None  # an array names the first frame's blobs


MAX_BAD_FRAME_LINES = 10  # bad frames reported on stderr; all of them are in summary.json


def note_bad(bar, bad_frames: list[dict[str, Any]], index: int, error: str) -> None:
    """Record a skipped frame for summary.json and say so on stderr (the first few)."""
    bad_frames.append({"frame": index, "error": error})
    if len(bad_frames) <= MAX_BAD_FRAME_LINES:
        bar.write(f"wristtrack: frame {index} skipped: {error}", file=sys.stderr)
    if len(bad_frames) == MAX_BAD_FRAME_LINES + 1:
        bar.write("wristtrack: more frames skipped; summary.json lists every one "
                  "(skipped_frames)", file=sys.stderr)


def skipped_row(index: int, timestamp: float, n_blobs: int, status: str) -> list[str]:
    return pose_row(
        index, timestamp, status, R_ch=_NAN33, t_ch=_NAN3, R=_NAN33, p=_NAN3, v=_NAN3, w=_NAN3,
        n_visible=0, n_clutter=n_blobs,
    )
