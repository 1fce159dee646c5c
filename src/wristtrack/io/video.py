"""Video files through OpenCV (RGB only; the intrinsics come from a camera.json)."""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, as_bgr, reject_options

# FFmpeg logs every damaged packet to stderr; the reader reports problems as one line itself.
# (setdefault: a user who sets the variable keeps their choice.)
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
VIDEO_SUFFIXES = frozenset(  # the file names open_recording and batch take for a video
    ".mp4 .m4v .avi .mov .mkv .webm .mpg .mpeg .wmv .flv .ogv .mjpeg .mjpg .h264 .ts".split()
)
# A container whose stated frame count is estimated (from duration x rate) may be off by one.
COUNT_SLACK = 1


@contextmanager
def _native_stderr_silenced() -> Iterator[None]:
    """Silence file descriptor 2 while OpenCV probes a file: some of its container parsers
    print straight to stderr when a file is damaged, which would add lines to our one-line
    error. Python's own sys.stderr is flushed first and works again afterwards."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable fd 2 (e.g. a closed or replaced stream)
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


class VideoRecording(Recording):
    """Frames of a video file decoded one at a time by ``cv2.VideoCapture``.

    Timestamps are the decoder's presentation times (CAP_PROP_POS_MSEC) where it gives them,
    else frame index / frame rate (``fps`` overrides the file's rate for that fallback). A video
    that stops decoding before the frame count its container states (truncated, damaged) ends
    with one bad frame saying so; a frame of another size is a bad frame.
    """

    kind = "video"

    def __init__(
        self,
        path: str | Path,
        camera: Camera | None,
        hand: HandLayout | None = None,
        *,
        fps: float | None = None,
        **unknown: object,
    ) -> None:
        path = Path(path)
        reject_options("the video", path, unknown)
        if not path.is_file():
            raise InputError(f"video {path} not found; give the path of a video file")
        if camera is None:
            raise ConfigError(
                f"video {path}: a video has no intrinsics: pass --camera camera.json"
            )
        super().__init__(str(path), camera, hand)
        self.path = path
        self.has_depth = False
        cap = self._open()
        try:
            self._count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            file_fps = cap.get(cv2.CAP_PROP_FPS)
            ok, first = cap.read()
        finally:
            cap.release()
        if not ok or first is None:
            raise InputError(
                f"video {path} has no readable frames (empty, or a codec this OpenCV build "
                "cannot decode); re-encode it, e.g. ffmpeg -i IN -c:v mjpeg OUT.avi"
            )
        self.check_size(first, f"video {path}")
        rate = fps if fps is not None else file_fps
        self.fps = float(rate) if rate and math.isfinite(rate) and rate > 0 else None

    def _open(self) -> cv2.VideoCapture:
        with _native_stderr_silenced():
            cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise InputError(
                f"video {self.path} cannot be opened by OpenCV (damaged or truncated file, or an "
                "unsupported container or codec); re-encode it, e.g. ffmpeg -i IN -c:v mjpeg "
                "OUT.avi"
            )
        return cap

    def __len__(self) -> int:
        """Frame count from the container (exact for common formats, an estimate for some)."""
        if self._count <= 0:
            raise TypeError(f"video {self.path} does not state its frame count")
        return self._count

    def _timestamp(self, cap: cv2.VideoCapture, index: int) -> float:
        msec = cap.get(cv2.CAP_PROP_POS_MSEC)
        # Position of the frame just read; some decoders report 0 (or nothing) past the start.
        if math.isfinite(msec) and msec >= 0 and (index == 0 or msec > 0):
            return msec / 1000.0
        if self.fps is None:
            raise InputError(
                f"video {self.path} gives neither frame times nor a frame rate; pass fps= "
                "(--fps) with the recording rate"
            )
        return index / self.fps

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        cap = self._open()
        try:
            index = 0
            last = -math.inf
            while index < start and cap.grab():  # resuming: decode forward, convert nothing
                last = self._timestamp(cap, index)
                index += 1
            while True:
                ok, image = cap.read()
                if not ok or image is None:
                    if index < self._count - COUNT_SLACK:
                        yield self._truncated(index, last)
                    return
                where = f"video {self.path} frame {index}"
                timestamp = self._timestamp(cap, index)
                try:
                    bgr = as_bgr(image, where)
                    self.check_size(bgr, where)
                except InputError as e:  # this frame only: the caller notes it and goes on
                    yield Frame.bad(index, timestamp, str(e))
                else:
                    yield Frame(index, timestamp, bgr, None)
                last = timestamp
                index += 1
        finally:
            cap.release()

    def _truncated(self, index: int, last: float) -> Frame:
        step = 1.0 / self.fps if self.fps else math.nan
        timestamp = last + step if math.isfinite(last) else math.nan
        return Frame.bad(
            index, timestamp,
            f"video {self.path} stops decoding at frame {index} of the {self._count} its "
            "container states (truncated or damaged); the rest of the video is missing, "
            "re-copy or re-export the file to track it",
        )
