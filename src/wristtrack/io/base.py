"""The recording interface every source implements, and the checks the sources share.

:class:`Recording` is a source of :class:`Frame` s: the native folder (io.folder), a video
(io.video), a ROS bag (io.rosbag) and live cameras (io.live) subclass it; ``open_recording``
(io.open) picks one. The sources import only this module, never each other.

Every reader is a generator of :class:`Frame` holding one frame at a time, so memory does not grow
with the length of the recording. Problems with the input are one-line InputError/ConfigError
messages naming the file and saying how to fix it. A problem with the recording as a whole
(missing files, wrong camera.json, a first frame that cannot be used) is raised when it is
opened; a problem confined to one frame (a corrupt PNG in the middle) is not raised but yielded
as a bad frame (``Frame.error`` set, no image) so a long run can note it and go on. Timestamps
are passed through as given: a non-increasing timestamp is the tracker's to report.
"""

from __future__ import annotations

from collections.abc import Generator, Iterator
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import InputError
from wristtrack.hand import HandLayout

_NO_IMAGE = np.zeros((0, 0, 3), np.uint8)
_NO_IMAGE.setflags(write=False)


@dataclass(frozen=True)
class Frame:
    """One frame: colour as OpenCV BGR uint8 (H,W,3); depth raw uint16 (H,W) or None.

    ``timestamp`` is in seconds; metres of depth = raw * camera.depth_scale (0 = no reading).
    A bad frame (unreadable, wrong size, ...) has ``error`` set to a one-line message and an
    empty (0,0,3) image: skip it. ``timestamp`` is then the listed one, or NaN if unknown.
    ``depth_delay`` (s): how long after the colour image the depth image was captured, where
    the source stamps both (a RealSense or OpenNI2 camera, a ROS bag), else None
    (tracking/depth_timing.py).
    """

    index: int
    timestamp: float
    bgr: np.ndarray
    depth: np.ndarray | None = None
    error: str | None = None
    depth_delay: float | None = None

    @classmethod
    def bad(cls, index: int, timestamp: float, error: str) -> Frame:
        """A frame that could not be read: its place in the recording and why."""
        return cls(index, timestamp, _NO_IMAGE, None, error)

    @property
    def ok(self) -> bool:
        return self.error is None


class Recording:
    """A source of frames: iterate it for :class:`Frame` s, one at a time.

    Subclasses implement :meth:`_frames` (a generator) and :meth:`__len__`. Iterating twice reads
    the recording twice (a live camera simply goes on streaming).
    """

    kind = "recording"
    has_depth = False  # whether frames can carry depth (subclasses set it)

    def __init__(self, source: str, camera: Camera, hand: HandLayout | None = None) -> None:
        self.source = source
        self.camera = camera
        self.hand = hand
        self._active: list[Generator[Frame, None, None]] = []

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def frames(self, start: int = 0) -> Iterator[Frame]:
        """Frames from index ``start`` on (``--resume``). Readers skip the frames before it
        without decoding them where the format allows (a recording folder, a bag); a video
        decodes its way forward; a live camera cannot start part-way."""
        frames = self._frames(start) if start else self._frames()
        # Keep unfinished iterations so close() can release what they hold.
        self._active = [g for g in self._active if g.gi_frame is not None]
        self._active.append(frames)
        return frames

    def _frames(self, start: int = 0) -> Generator[Frame, None, None]:  # pragma: no cover
        raise NotImplementedError  # abstract

    def __len__(self) -> int:  # pragma: no cover - abstract
        raise TypeError(f"{type(self).__name__} has no known length")

    def close(self) -> None:
        """Release files and devices held by iterations still in progress."""
        for frames in self._active:
            frames.close()  # runs the generator's finally blocks
        self._active.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.source}>"

    # ------------------------------------------------------------------------ shared checks

    def check_size(self, bgr: np.ndarray, where: str) -> None:
        """InputError if a colour image's size differs from the camera's (wrong camera.json)."""
        h, w = bgr.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            raise InputError(
                f"{where} is {w}x{h} but the camera is {self.camera.width}x{self.camera.height}; "
                "give the camera.json calibrated at this resolution"
            )



# ------------------------------------------------------------------------ shared helpers


def as_bgr(image: np.ndarray, where: str) -> np.ndarray:
    """8-bit colour as BGR (H,W,3); grayscale and BGRA are converted; anything else InputError."""
    if image.dtype != np.uint8:
        bits = image.dtype.itemsize * 8
        raise InputError(
            f"{where} is {bits}-bit ({image.dtype}); colour frames must be 8-bit (convert it, "
            "e.g. to an 8-bit PNG)"
        )
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    raise InputError(
        f"{where} has shape {image.shape}; expected 8-bit colour (H, W, 3)"
    )


def check_depth(depth: np.ndarray, bgr: np.ndarray, where: str) -> np.ndarray:
    """Raw 16-bit depth (H,W) the size of the colour image, else InputError."""
    if depth.dtype != np.uint16 or depth.ndim != 2:
        kind = f"{depth.dtype.itemsize * 8}-bit" if depth.dtype != np.uint16 else "16-bit"
        channels = depth.shape[2] if depth.ndim == 3 else 1
        raise InputError(
            f"{where} is {kind} with {channels} channel(s); depth must be 16-bit single-channel "
            "raw units (0 = no reading), registered to the colour image"
        )
    if depth.shape != bgr.shape[:2]:
        raise InputError(
            f"{where} is {depth.shape[1]}x{depth.shape[0]} but the colour image is "
            f"{bgr.shape[1]}x{bgr.shape[0]}; depth must be registered (aligned) to colour"
        )
    return depth


def pairing_tolerance(fps: float) -> float:
    """Seconds a depth frame's timestamp may be off its colour frame's and still show the same
    moment: half a frame period at ``fps`` (30 if unknown). A camera's colour and depth
    sensors are read apart, and a depth frame of the moment before or after places every
    marker where the hand was then (at 1 m/s, 33 mm at 30 fps): such a colour frame goes
    without depth."""
    return 0.5 / (fps if fps and fps > 0 else 30.0)


def reject_options(kind: str, source: Any, options: dict[str, Any]) -> None:
    """InputError for options the kind of recording does not take (e.g. a topic for a video)."""
    if options:
        raise InputError(
            f"option(s) {', '.join(sorted(options))} do not apply to {kind} {source}; "
            "remove them"
        )

