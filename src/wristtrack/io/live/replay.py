"""``replay:RECORDING``: a recording folder played at its own timestamps, as if it were a camera.

The way to run and test live mode without hardware: each frame is decoded ahead of time and
handed over when its timestamp comes due on the wall clock (relative to the first frame), so
the consumer sees the recording's frame rate and timing, and falls behind exactly as it would
behind a real camera. Frames keep the recording's indices and timestamps, so a live run of a
replay can be compared row by row with an offline run of the same folder.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, reject_options
from wristtrack.io.folder import FolderRecording

# A frame handed over later than this after its due time counts as late (decoding could not
# keep up): the replay then under-states the latency a real camera would have shown.
LATE_S = 0.005


class ReplayRecording(Recording):
    """Frames of a recording folder, each delivered at ``t0 + (timestamp - first) / speed``.

    ``late_frames`` and ``max_late_ms`` say how often and by how much decoding made a frame
    later than its due time.
    """

    kind = "replayed recording"

    def __init__(
        self,
        folder: str | Path,
        camera: Camera | None = None,
        hand: HandLayout | None = None,
        *,
        speed: float = 1.0,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
        **unknown: object,
    ) -> None:
        reject_options("the replayed recording", folder, unknown)
        if not speed > 0:
            raise ConfigError(f"replay speed {speed!r} must be positive (1 = real time)")
        self.recording = FolderRecording(folder, camera, hand)
        super().__init__(f"replay:{folder}", self.recording.camera, self.recording.hand)
        self.folder = self.recording.folder
        self.has_depth = self.recording.has_depth
        self.speed = float(speed)
        self._clock, self._sleep = clock, sleep
        self.late_frames = 0
        self.max_late_ms = 0.0

    def __len__(self) -> int:
        return len(self.recording)

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        t0 = first = None
        frames = self.recording.frames(start)
        try:
            for frame in frames:  # decoded here, before its due time
                if t0 is None:
                    t0, first = self._clock(), frame.timestamp
                elif frame.timestamp == frame.timestamp:  # NaN (a bad row): hand it over now
                    due = t0 + (frame.timestamp - first) / self.speed
                    wait = due - self._clock()
                    if wait > 0:
                        self._sleep(wait)
                    elif -wait > LATE_S:
                        self.late_frames += 1
                        self.max_late_ms = max(self.max_late_ms, -wait * 1e3)
                yield frame
        finally:
            frames.close()

    def close(self) -> None:
        super().close()
        self.recording.close()
