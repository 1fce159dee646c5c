"""The noise's priming (TrackerConfig.prime_noise): the run starts from the markers' noise its
recording's first PRIMING_S show, instead of learning it as it goes.

A fresh detector and tracker go through the first PRIMING_S; their rows are discarded and what
the tracker learned (tracking/noise_scale.py) primes the run's. The run then tracks the same
detections, held in memory, and goes on from the next frame with the priming pass's detector,
whose colours have learned from them: every frame is read and detected once.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from wristtrack.analysis.summary import SummaryAccumulator
from wristtrack.detect.config import DetectorConfig
from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.io.base import Frame, Recording
from wristtrack.pipeline.frame_step import (
    Rows,
    RunState,
    came_without_depth,
    note_bad,
    track_detections,
    track_frame,
)
from wristtrack.pipeline.sinks import Discarded, Muted, NoStates, progress_bar
from wristtrack.tracking.noise_scale import primes
from wristtrack.tracking.tracker import Tracker, TrackerConfig

# The detections held for the run weigh what their depth frames weigh (and the colour frames,
# for an overlay): 10 s of 640x480 depth at 30 frames/s is 184 MB. Past this the priming
# ends early, with the frames it has (1280x720 depth at 30 frames/s: 9.3 s).
HELD_BYTES = 512 * 2**20


@dataclass
class _Detected:
    """A frame of the priming pass as the run needs it again: its detections (None for an
    unreadable frame, with its ``error``), and its colour image only for an overlay."""

    index: int
    timestamp: float
    det: Detections | None
    error: str | None
    without_depth: bool  # a recording with depth, a frame without
    bgr: np.ndarray | None

    @property
    def nbytes(self) -> int:
        depth = self.det.depth_image if self.det is not None else None
        return sum(a.nbytes for a in (depth, self.bgr) if a is not None)

    def track(self, run: RunState, labels: Any, rows: Rows) -> None:
        """Track it in the run, as the run's frame loop would have (detected already)."""
        if self.without_depth:
            run.without_depth.append(self.index)
        if self.det is None:
            note_bad(rows.bar, run.bad_frames, self.index, self.error or "unreadable")
            rows.skipped(self.index, self.timestamp, 0, "bad_frame")
            return
        track_detections(self.index, self.timestamp, self.det, run, labels, rows, self.bgr,
                         follow=False)


@dataclass
class Priming:
    """The priming of one run's tracker (see the module's doc)."""

    recording: Recording
    config: TrackerConfig
    detector: DetectorConfig
    labels: Any
    progress: bool

    def __call__(self, frames: Iterator[Frame], run: RunState, rows: Rows) -> Iterator[Frame]:
        """Prime ``run`` (fresh) over the first frames of ``frames``, track them in it into
        ``rows``, and return the frames after them. The caller's Ctrl-C is honoured after
        that, at the next frame; a second one stops at once."""
        first = RunState(MarkerDetector(self.recording.camera, self.detector),
                         Tracker(self.recording.camera, self.recording.hand, self.config),
                         SummaryAccumulator())
        quiet = Rows(Discarded(), NoStates(), None, Muted())  # the run says what it has to
        keep_bgr = rows.overlay is not None
        has_depth = self.recording.has_depth
        held: list[_Detected] = []
        size, begin, rest = 0, None, None
        bar = progress_bar(self.recording, self.progress, "learning the noise", counted=False)
        try:
            for frame in frames:
                begin = frame.timestamp if begin is None else begin
                if not primes(frame.timestamp, begin) or size > HELD_BYTES:
                    rest = frame
                    break
                det = track_frame(frame, first, self.labels, quiet)
                held.append(_Detected(frame.index, frame.timestamp, det, frame.error,
                                      came_without_depth(frame, has_depth),
                                      frame.bgr if keep_bgr and frame.ok else None))
                size += held[-1].nbytes
                bar.update(1)
        finally:
            bar.close()
        run.tracker.start_from(first.tracker.learned_noise)
        for frame in held:
            frame.track(run, self.labels, rows)
            rows.bar.update(1)
        run.detector, run.learned = first.detector, first.learned
        return frames if rest is None else itertools.chain([rest], frames)
