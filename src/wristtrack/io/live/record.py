"""``--record DIR``: the raw frames of a live session written as a recording folder.

PNG encoding of a colour and a depth image costs several milliseconds, which the tracking
loop cannot spare at 30 fps, so frames are handed to a writer thread through a bounded queue
(OpenCV releases the GIL while it encodes). Every captured frame is recorded, including the
ones the tracker dropped; only if the disk cannot keep up for ``max_pending`` frames is a frame
left out of the recording, and that is counted (``lost``), never silent.

A folder has one time stamp per frame, so the depth frames' capture after their colour frames,
which the camera stamps per frame (``Frame.depth_delay``), is kept as its median in the
folder's camera.json (``depth_delay_s``), where the camera states none.
"""

from __future__ import annotations

import queue
import statistics
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np

from wristtrack.camera import MAX_DEPTH_DELAY_S, Camera
from wristtrack.errors import WristtrackError
from wristtrack.hand import HandLayout
from wristtrack.io.folder import RecordingWriter

MAX_PENDING = 90  # frames (3 s at 30 fps, ~140 MB at 640x480 RGB-D) waiting for the disk

_END = object()


class LiveRecorder:
    """Writes frames to a recording folder from a background thread; use as a context manager.

    The folder must be new or empty (RecordingWriter refuses to overwrite a recording).
    ``error`` holds the one-line reason if writing failed (the session goes on untracked by the
    recorder, and the caller reports it).
    """

    def __init__(
        self,
        folder: str | Path,
        camera: Camera,
        hand: HandLayout | None = None,
        max_pending: int = MAX_PENDING,
    ) -> None:
        self.writer = RecordingWriter(folder, camera, hand)  # refuses a non-empty folder now
        self.folder = self.writer.folder
        self.lost = 0
        self.error: str | None = None
        self._delays: list[float] = []  # the frames' depth delays (s), from the camera's stamps
        self._lock = threading.Lock()
        self._queue: queue.Queue = queue.Queue(maxsize=max_pending)
        self._thread = threading.Thread(target=self._run, name="wristtrack-record", daemon=True)
        self._thread.start()

    @property
    def written(self) -> int:
        return self.writer.count

    def put(self, timestamp: float, bgr: np.ndarray, depth: np.ndarray | None,
            depth_delay: float | None = None) -> None:
        """Queue one frame; never blocks (a full queue loses the frame and counts it).
        ``depth_delay``: the frame's (``Frame.depth_delay``)."""
        if depth is not None and depth_delay is not None:
            self._delays.append(depth_delay)
        if self.error is not None:
            self._lose()
            return
        try:
            self._queue.put_nowait((timestamp, bgr, depth))
        except queue.Full:
            self._lose()

    def _lose(self) -> None:
        with self._lock:  # counted from the capture thread and the writer thread
            self.lost += 1

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _END:
                return
            if self.error is not None:
                self._lose()  # drain: the caller learns of the failure from ``error``
                continue
            try:
                self.writer.write(*item)
            except (WristtrackError, OSError) as exc:
                self.error = str(exc)
                self._lose()

    @property
    def depth_delay(self) -> float | None:
        """The delay camera.json states (s): the camera's own, else the frames' median."""
        stated = self.writer.camera.depth_delay
        if stated is not None or not self._delays:
            return stated
        median = statistics.median(self._delays)
        return median if abs(median) <= MAX_DEPTH_DELAY_S else None  # (a camera.json limit)

    def close(self) -> None:
        """Write what is queued, then close the folder with the depth delay in camera.json."""
        if self._thread.is_alive():
            self._queue.put(_END)
            self._thread.join()
        self.writer.close()
        camera = self.writer.camera
        if camera.depth_delay is None and self.depth_delay is not None:
            try:
                replace(camera, depth_delay=self.depth_delay).save(self.folder / "camera.json")
            except OSError as exc:
                self.error = self.error or f"cannot update {self.folder / 'camera.json'}: {exc}"

    def __enter__(self) -> LiveRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
