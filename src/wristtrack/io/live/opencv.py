"""A live camera through OpenCV (colour only), read frame by frame as it streams."""

from __future__ import annotations

import time
from collections.abc import Iterator

import cv2

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, as_bgr, reject_options


def parse_device(device: int | str) -> int | str:
    """Camera index as an int ("0" -> 0); anything else (a device path, a URL) as given."""
    if isinstance(device, str) and device.strip().lstrip("-").isdigit():
        return int(device)
    return device


class LiveRecording(Recording):
    """Frames from ``cv2.VideoCapture(device)``; timestamps from ``time.monotonic`` at each grab,
    relative to the first frame. Streams until the camera stops, ``max_frames`` or the caller
    stops iterating (e.g. Ctrl-C)."""

    kind = "live camera"

    def __init__(
        self,
        device: int | str,
        camera: Camera | None,
        hand: HandLayout | None = None,
        *,
        max_frames: int | None = None,
        **unknown: object,
    ) -> None:
        device = parse_device(device)
        name = f"live:{device}"
        reject_options("the live camera", name, unknown)
        if camera is None:
            raise ConfigError(
                f"{name}: a live camera needs its intrinsics: pass --camera camera.json"
            )
        super().__init__(name, camera, hand)
        self.device = device
        self.max_frames = max_frames
        self.has_depth = False
        self._cap = cv2.VideoCapture(device)
        if not self._cap.isOpened():
            self._cap.release()
            raise InputError(
                f"camera {name} cannot be opened; check it is connected and not in use, or try "
                "another index"
            )
        # Ask for the calibrated resolution; check_size reports it if the camera ignores that.
        self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, camera.width)
        self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, camera.height)

    def __len__(self) -> int:
        raise TypeError(f"{self.source}: a live camera has no length")

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        if start:
            raise InputError(f"camera {self.source}: a live camera cannot start at frame {start}")
        t0 = None
        index = 0
        while self.max_frames is None or index < self.max_frames:
            # Time the grab, not the decode, so the timestamp is as close to capture as we get.
            grabbed = self._cap.grab()
            now = time.monotonic()
            ok, image = self._cap.retrieve() if grabbed else (False, None)
            if not ok or image is None:
                if index == 0:
                    raise InputError(
                        f"camera {self.source} opened but delivers no frames; check the device"
                    )
                return  # the stream ended (camera unplugged or closed)
            if t0 is None:
                t0 = now
            where = f"camera {self.source} frame {index}"
            bgr = as_bgr(image, where)
            self.check_size(bgr, where)
            yield Frame(index, now - t0, bgr, None)
            index += 1

    def close(self) -> None:
        super().close()
        self._cap.release()
