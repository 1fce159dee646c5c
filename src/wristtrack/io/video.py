"""Video files through OpenCV (RGB only; the intrinsics come from a camera.json)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import cv2

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.recording import Frame, Recording, as_bgr, reject_options


class VideoRecording(Recording):
    """Frames of a video file decoded one at a time by ``cv2.VideoCapture``.

    Timestamps are the decoder's presentation times (CAP_PROP_POS_MSEC) where it gives them,
    else frame index / frame rate (``fps`` overrides the file's rate for that fallback).
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
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise InputError(
                f"video {self.path} cannot be opened by OpenCV (unsupported container or codec); "
                "re-encode it, e.g. ffmpeg -i IN -c:v mjpeg OUT.avi"
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

    def _frames(self) -> Iterator[Frame]:
        cap = self._open()
        try:
            index = 0
            while True:
                ok, image = cap.read()
                if not ok or image is None:
                    return
                where = f"video {self.path} frame {index}"
                bgr = as_bgr(image, where)
                self.check_size(bgr, where)
                yield Frame(index, self._timestamp(cap, index), bgr, None)
                index += 1
        finally:
            cap.release()
