"""``openni[:URI]``: Asus Xtion, Kinect v1, Orbbec and other OpenNI2 cameras, and ``.oni`` files.

Through the ``openni`` Python bindings (``pip install 'wristtrack[openni]'``) and the system's
OpenNI2 runtime (Debian/Ubuntu: ``apt-get install libopenni2-0``; or an OpenNI2/Orbbec SDK
folder named by ``OPENNI2_REDIST64``). Depth is registered to colour by the device
(``IMAGE_REGISTRATION_DEPTH_TO_COLOR``) with depth/colour frame sync on. OpenNI2 reports no
calibration, only the fields of view: without ``--camera`` the pinhole is derived from them
(no distortion; an Xtion's is ~2 px at the corners, so calibrate for best accuracy).
The device stamps both streams on its own clock: a pair's two stamps tell how long after its
colour frame the depth frame was captured (``Frame.depth_delay``).
"""

from __future__ import annotations

import ctypes.util
import math
import os
import platform
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, pairing_tolerance, reject_options

INSTALL = "pip install 'wristtrack[openni]'"
RUNTIME = "apt-get install libopenni2-0 (Debian/Ubuntu) or set OPENNI2_REDIST64 to the SDK's Redist"
FRAME_TIMEOUT_S = 5.0
DEPTH_SCALES = {"ONI_PIXEL_FORMAT_DEPTH_1_MM": 0.001, "ONI_PIXEL_FORMAT_DEPTH_100_UM": 0.0001}


def _library_candidates() -> list[Path]:
    """Where libOpenNI2 may be: the SDK folder named by the environment, then the system's
    (Debian ships only the versioned ``libOpenNI2.so.0``, which the bindings do not look for)."""
    dirs = [os.environ[k] for k in ("OPENNI2_REDIST64", "OPENNI2_REDIST") if os.environ.get(k)]
    multiarch = f"/usr/lib/{platform.machine()}-linux-gnu"
    dirs += [multiarch, "/usr/lib", "/usr/local/lib", "/lib"]
    names = ("libOpenNI2.so", "libOpenNI2.so.0", "libOpenNI2.dylib", "OpenNI2.dll")
    found = [Path(d) / n for d in dirs for n in names if (Path(d) / n).is_file()]
    system = ctypes.util.find_library("OpenNI2")
    if system:
        found += [Path(d) / system for d in dirs if (Path(d) / system).is_file()]
    return found


def load_openni2():
    """The initialised ``openni.openni2`` module, or one ConfigError line on what is missing."""
    try:
        from openni import _openni2 as c_api
        from openni import openni2
    except ImportError:
        raise ConfigError(f"OpenNI2 cameras need the openni bindings: {INSTALL}") from None
    if openni2.is_initialized():
        return openni2
    for path in _library_candidates():
        try:
            c_api.load_dll(str(path))
            # The bindings only look for the unversioned name; having loaded the library from
            # its real path, tell them where it came from so initialize() just starts it.
            openni2.loaded_dll_directory = str(path.parent)
            openni2.initialize()
            return openni2
        except Exception:  # a broken or foreign-architecture file: try the next one
            continue
    raise ConfigError(f"the OpenNI2 runtime (libOpenNI2) is not installed: {RUNTIME}")


def _pinhole_from_fov(stream: Any, width: int, height: int, depth_scale: float) -> Camera:
    try:
        hfov, vfov = stream.get_horizontal_fov(), stream.get_vertical_fov()
    except Exception:  # drivers without the property (e.g. OpenNI2's dummy device)
        hfov = vfov = math.nan
    if not (0 < hfov < math.pi and 0 < vfov < math.pi):
        raise ConfigError("the OpenNI2 device reports no field of view to derive intrinsics "
                          "from; pass --camera camera.json")
    return Camera(fx=width / 2 / math.tan(hfov / 2), fy=height / 2 / math.tan(vfov / 2),
                  cx=(width - 1) / 2, cy=(height - 1) / 2, width=width, height=height,
                  depth_scale=depth_scale)


class OpenNIRecording(Recording):
    """An OpenNI2 device (``uri``, or the first one) or an ``.oni`` recording (``file``)."""

    kind = "OpenNI2 camera"

    def __init__(
        self,
        uri: str | None = None,
        camera: Camera | None = None,
        hand: HandLayout | None = None,
        *,
        file: str | Path | None = None,
        max_frames: int | None = None,
        **unknown: object,
    ) -> None:
        name = f"openni:{file or uri or ''}".rstrip(":")
        reject_options("the OpenNI2 source", name, unknown)
        if file is not None and not Path(file).is_file():
            raise InputError(f"OpenNI recording {file} not found; give an .oni file")
        ni = load_openni2()
        self._ni = ni
        try:
            if file is not None:
                device = ni.Device.open_file(str(file).encode())
            elif uri:
                device = ni.Device(uri.encode())
            else:
                device = ni.Device.open_any()
        except Exception as exc:
            what = f"OpenNI recording {file}" if file else (
                f"OpenNI2 device {uri}" if uri else "an OpenNI2 camera")
            raise InputError(f"cannot open {what}: {_reason(exc)}; check it is connected (USB 2 "
                             "port, not in use by another program)" if not file else
                             f"cannot open {what}: {_reason(exc)}") from None
        self._device = device
        self._streams: list[Any] = []
        try:
            if not device.has_sensor(ni.SENSOR_COLOR):
                raise InputError(f"{name} has no colour sensor; the tracker needs colour")
            color = device.create_color_stream()
            self._streams.append(color)
            depth = device.create_depth_stream() if device.has_sensor(ni.SENSOR_DEPTH) else None
            if depth is not None:
                self._streams.append(depth)
                if device.is_image_registration_mode_supported(
                        ni.IMAGE_REGISTRATION_DEPTH_TO_COLOR):
                    device.set_image_registration_mode(ni.IMAGE_REGISTRATION_DEPTH_TO_COLOR)
                try:
                    device.set_depth_color_sync_enabled(True)
                except Exception:
                    pass  # files and some drivers do not support it: frames are paired below
            mode = color.get_video_mode()
            width, height = int(mode.resolutionX), int(mode.resolutionY)
            scale = 0.001
            if depth is not None:
                fmt = depth.get_video_mode().pixelFormat
                scale = DEPTH_SCALES.get(getattr(fmt, "name", str(fmt)), 0.001)
            if camera is None:
                camera = _pinhole_from_fov(color, width, height, scale)
            for stream in self._streams:
                stream.start()
        except Exception:
            self._release()
            raise
        super().__init__(name, camera, hand)
        self.has_depth = depth is not None
        self.max_frames = max_frames
        self.file = file
        self._color, self._depth = color, depth

    def __len__(self) -> int:
        raise TypeError(f"{self.source}: an OpenNI2 stream has no length")

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        if start:
            raise InputError(f"{self.source}: an OpenNI2 stream cannot start at frame {start}")
        index, t0 = 0, None
        # Colour and depth arrive as separate frames, in either order and sometimes two of one
        # kind in a row: pair each colour frame with the depth frame of the same moment
        # (pairing_tolerance). A colour frame whose depth is lost goes without depth.
        colors: deque[tuple[np.ndarray, float]] = deque()
        depths: deque[tuple[np.ndarray, float]] = deque(maxlen=4)
        tolerance = pairing_tolerance(float(self._color.get_video_mode().fps))
        while self.max_frames is None or index < self.max_frames:
            ready = self._ni.wait_for_any_stream(self._streams, FRAME_TIMEOUT_S)
            if ready is None:
                if self.file is not None and index > 0:
                    return
                raise InputError(f"{self.source} delivered no frame for {FRAME_TIMEOUT_S:g} s; "
                                 "check the device")
            while ready is not None:  # read all that is waiting (the wait favours colour)
                if ready is self._depth:
                    depths.append(self._read_depth())
                else:
                    colors.append(self._read_color(index + len(colors)))
                ready = self._ni.wait_for_any_stream(self._streams[::-1], 0)
            for bgr, t, raw, delay in _pair(colors, depths, tolerance, self._depth is not None):
                t0 = t if t0 is None else t0
                if raw is not None and raw.shape != bgr.shape[:2]:
                    raise InputError(f"{self.source}: depth is {raw.shape[1]}x{raw.shape[0]} "
                                     f"but colour is {bgr.shape[1]}x{bgr.shape[0]}; set both "
                                     "streams to one resolution")
                yield Frame(index, t - t0, bgr, raw, depth_delay=delay)
                index += 1

    def _read_color(self, index: int) -> tuple[np.ndarray, float]:
        frame = self._color.read_frame()
        rgb = np.frombuffer(frame.get_buffer_as_uint8(), np.uint8).reshape(
            frame.height, frame.width, 3)
        bgr = np.ascontiguousarray(rgb[..., ::-1])  # a copy: the library reuses its buffer
        self.check_size(bgr, f"{self.source} frame {index}")
        return bgr, frame.timestamp * 1e-6  # microseconds

    def _read_depth(self) -> tuple[np.ndarray, float]:
        frame = self._depth.read_frame()
        raw = np.frombuffer(frame.get_buffer_as_uint16(), np.uint16).reshape(
            frame.height, frame.width).copy()
        return raw, frame.timestamp * 1e-6

    def _release(self) -> None:
        for stream in self._streams:
            try:
                stream.close()  # stops it first (stopping twice corrupts OpenNI2's heap)
            except Exception:
                pass
        self._streams = []
        device, self._device = self._device, None  # closing twice crashes the library
        if device is not None:
            try:
                device.close()
            except Exception:
                pass

    def close(self) -> None:
        super().close()
        self._release()


def _pair(colors: deque, depths: deque, tolerance: float, has_depth: bool) -> list[tuple]:
    """(bgr, t, depth, its stamp after the colour's; or None, None) for the waiting colour
    frames that can be settled now."""
    out = []
    while colors:
        bgr, t = colors[0]
        while depths and depths[0][1] < t - tolerance:
            depths.popleft()  # older than any colour frame still to come
        if depths and abs(depths[0][1] - t) <= tolerance:
            raw, t_depth = depths.popleft()
            out.append((bgr, t, raw, t_depth - t))
        elif not has_depth or depths or len(colors) > 4:
            out.append((bgr, t, None, None))  # its depth is past, or too long in coming
        else:
            break  # its depth may still arrive
        colors.popleft()
    return out


def _reason(exc: Exception) -> str:
    """The OpenNI error's own message (its args hold a status, bytes and a log path)."""
    for arg in getattr(exc, "args", ()):
        if isinstance(arg, bytes) and arg:
            return arg.decode("utf-8", "replace")
    return str(exc) or type(exc).__name__
