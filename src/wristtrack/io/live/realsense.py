"""``realsense[:SERIAL]`` and RealSense SDK recordings, through Intel's ``pyrealsense2``.

Depth is aligned to the colour image by the SDK (``rs.align``), so frames are registered as
the recording-folder contract asks; the colour intrinsics, distortion and the depth scale are
read from the device (or from the recording), not assumed. The SDK's own recordings are read
through the same pipeline, as the SDK plays them back: ``.bag`` (RealSense Viewer up to SDK
2.56, ROS 1 layout) and ``.db3`` (SDK 2.57 on, ROS 2 layout). ``pip install
'wristtrack[realsense]'``; a missing library, no device or an unknown serial is one line.
"""

from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, pairing_tolerance, reject_options

INSTALL = "pip install 'wristtrack[realsense]'"
RECORDING_SUFFIXES = (".bag", ".db3")
# RealSense models whose colour sensor is a rolling shutter (the OV2740 of the D415, D435 and
# L515); the D405's and D45x's colour is a global shutter (realsense-ros #3451).
ROLLING_COLOUR_MODELS = ("D415", "D435", "L515")
FRAME_TIMEOUT_S = 5.0  # no frameset for this long: the device stalled (or was unplugged)
POLL_S = 0.1  # waits in steps this long, so a recording's end is seen at once


def import_pyrealsense2():
    """The ``pyrealsense2`` module, or one ConfigError line saying what to install."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        missing = getattr(exc, "name", None)
        if missing in ("pyrealsense2", None) and "cannot open shared object" not in str(exc):
            raise ConfigError(
                f"RealSense cameras need Intel's pyrealsense2: {INSTALL}"
            ) from None
        # The wheel is there but a system library it links to is not (libusb on a slim image).
        raise ConfigError(
            f"pyrealsense2 is installed but cannot load ({exc}); install the system library it "
            "names (Debian/Ubuntu: apt-get install libusb-1.0-0)"
        ) from None
    return rs


def camera_from_intrinsics(intr: Any, depth_scale: float, rs: Any) -> Camera:
    """Camera from the SDK's colour-stream intrinsics (OpenCV-compatible distortion only)."""
    coeffs = [float(c) for c in intr.coeffs]
    dist = None
    if any(coeffs):
        if intr.model != rs.distortion.brown_conrady:
            raise ConfigError(
                f"the RealSense colour stream reports {intr.model} distortion "
                f"{coeffs}, which OpenCV's model does not express; calibrate the colour "
                "camera with OpenCV and pass --camera camera.json"
            )
        dist = tuple(coeffs)  # SDK order k1, k2, p1, p2, k3 = OpenCV's
    return Camera(fx=float(intr.fx), fy=float(intr.fy), cx=float(intr.ppx), cy=float(intr.ppy),
                  width=int(intr.width), height=int(intr.height),
                  depth_scale=float(depth_scale), dist=dist)


def _already_registered(depth: Any, color: Any) -> bool:
    """Whether depth pixels already are colour pixels: same intrinsics, identity extrinsics."""
    a, b = depth.get_intrinsics(), color.get_intrinsics()
    same = [a.width, a.height, a.fx, a.fy, a.ppx, a.ppy, a.model, *a.coeffs] == \
        [b.width, b.height, b.fx, b.fy, b.ppx, b.ppy, b.model, *b.coeffs]
    try:
        ext = depth.get_extrinsics_to(color)
    except RuntimeError:  # no extrinsics recorded between them: cannot tell, so align
        return False
    return same and np.allclose(ext.rotation, np.eye(3).ravel(), atol=1e-9) and \
        np.allclose(ext.translation, 0.0, atol=1e-9)


def exposure_lead(frame: Any, rs: Any) -> float:
    """How long before its stamp (``get_timestamp``, the start of its USB transfer) the frame's
    exposure had its middle (s; SENSOR_TIMESTAMP and FRAME_TIMESTAMP metadata, us, one clock),
    or 0 where the device does not say. It changes with the auto-exposure (a colour exposure
    from 10 to 30 ms moves it 10 ms: 5 mm of a 0.5 m/s reach)."""
    middle, sent = rs.frame_metadata_value.sensor_timestamp, rs.frame_metadata_value.frame_timestamp
    if not (frame.supports_frame_metadata(middle) and frame.supports_frame_metadata(sent)):
        return 0.0
    lead = (frame.get_frame_metadata(sent) - frame.get_frame_metadata(middle)) / 1e6
    return lead if 0.0 <= lead < 1.0 else 0.0  # (the counter wrapped between them)


def _unstated_rolling_shutter(device_name: str) -> list[str]:
    """The warning for a camera whose colour sensor is a rolling shutter of unknown readout."""
    if not any(model in device_name for model in ROLLING_COLOUR_MODELS):
        return []
    return [f"the {device_name}'s colour sensor is a rolling shutter and the camera states no "
            "readout_s: a fast-moving marker is seen where it was when its row was read, a few "
            "pixels from where the tracker looks; measure it (wristtrack timing RECORDING) and "
            "give --camera a camera.json with readout_s"]


def capture_offset(color: Any, depth: Any, rs: Any) -> float | None:
    """How long after the colour frame's capture its depth frame's was (s), or None: not known.

    The moment a sensor captures is the middle of its exposure, which the device reports as
    SENSOR_TIMESTAMP metadata (us). ``get_timestamp`` is the start of the frame's USB transfer,
    which follows the readout: with the colour exposed 30 ms and the depth 8 ms indoors, the
    colour's middle is 11 ms further before its stamp, and those stamps say the depth came
    11 ms sooner after the colour than it did. Both come from the device's clock, where it
    sends them; without the metadata (a Linux kernel the SDK has not patched) the stamps are
    the host's arrival times (system time), a USB transfer's delay, not the sensors'.
    """
    middle = rs.frame_metadata_value.sensor_timestamp
    if color.supports_frame_metadata(middle) and depth.supports_frame_metadata(middle):
        offset = (depth.get_frame_metadata(middle) - color.get_frame_metadata(middle)) / 1e6
        if abs(offset) < 1.0:  # (the firmware's 32-bit microsecond counter wraps hourly)
            return offset
    host = rs.timestamp_domain.system_time
    if host in (color.get_frame_timestamp_domain(), depth.get_frame_timestamp_domain()):
        return None
    return (depth.get_timestamp() - color.get_timestamp()) / 1e3


class RealSenseRecording(Recording):
    """A RealSense device (``serial`` or the first one found) or an SDK recording (``file``).

    A device streams ``width`` x ``height`` colour (BGR8) and depth (Z16) at ``fps``;
    timestamps are the middle of the colour frames' exposures (the SDK's frame timestamps
    where the device reports no exposure: :func:`exposure_lead`) in seconds from the first
    frame's; how long after the colour the depth was captured is the frame's ``depth_delay``
    (:func:`capture_offset`). A colour frame whose depth frame is not of the same moment
    (``pairing_tolerance``) comes without depth. A recording plays at its own pace
    (``real_time=True``, as a camera) or as fast as it is read. ``camera`` overrides the
    intrinsics read from the device. ``warnings``: what a run must say about its poses (a
    rolling shutter of unknown readout).
    """

    kind = "RealSense camera"

    def __init__(
        self,
        serial: str | None = None,
        camera: Camera | None = None,
        hand: HandLayout | None = None,
        *,
        file: str | Path | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        real_time: bool = True,
        max_frames: int | None = None,
        **unknown: object,
    ) -> None:
        name = f"realsense:{file or serial or ''}".rstrip(":")
        reject_options("the RealSense source", name, unknown)
        rs = import_pyrealsense2()
        self._rs = rs
        config = rs.config()
        if file is not None:
            file = Path(file)
            if not file.is_file():
                raise InputError(f"RealSense recording {file} not found; give a .bag or .db3 "
                                 "file written by the RealSense SDK or Viewer")
            if file.suffix.lower() not in RECORDING_SUFFIXES:
                raise InputError(f"{file}: a RealSense recording is a .bag or .db3 file")
            config.enable_device_from_file(str(file), repeat_playback=False)
        else:
            serials = [d.get_info(rs.camera_info.serial_number)
                       for d in rs.context().query_devices()]
            if not serials:
                raise InputError("no RealSense camera found; plug it into a USB 3 port (and check "
                                 "the udev rules), or give a recording: realsense:FILE.bag")
            if serial and serial not in serials:
                raise InputError(f"no RealSense camera with serial {serial}; connected: "
                                 f"{', '.join(serials)}")
            if serial:
                config.enable_device(serial)
            config.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
            config.enable_stream(rs.stream.color, width, height, rs.format.bgr8, fps)
        self._pipe, self._config = rs.pipeline(), config
        try:
            # Resolved, not started: streaming (or a recording's playback) starts when the
            # frames are first iterated, so a recording plays from its first frame.
            profile = config.resolve(rs.pipeline_wrapper(self._pipe))
        except RuntimeError as exc:  # busy device, unsupported mode, unreadable file
            raise InputError(f"{name} cannot be started: {exc}") from None
        device = profile.get_device()
        streams = {s.stream_type(): s for s in profile.get_streams()}
        if rs.stream.color not in streams:
            raise InputError(f"{name} has no colour stream; the tracker needs colour")
        self.has_depth = rs.stream.depth in streams
        intr = streams[rs.stream.color].as_video_stream_profile().get_intrinsics()
        self._tolerance = pairing_tolerance(float(streams[rs.stream.color].fps()))
        scale = device.first_depth_sensor().get_depth_scale() if self.has_depth else 0.001
        self.device_name = device.get_info(rs.camera_info.name)
        if camera is None:
            camera = camera_from_intrinsics(intr, scale, rs)
        self.warnings = [] if camera.readout else _unstated_rolling_shutter(self.device_name)
        registered = self.has_depth and _already_registered(
            streams[rs.stream.depth].as_video_stream_profile(),
            streams[rs.stream.color].as_video_stream_profile())
        self._real_time = bool(real_time)
        self._playback = None
        self._running = False
        super().__init__(name, camera, hand)
        self.file = file
        self.max_frames = max_frames
        # A D405 (colour from the depth imager) or a recording of aligned frames needs no
        # alignment; rs.align would only punch rounding holes into it.
        self._align = rs.align(rs.stream.color) if self.has_depth and not registered else None

    def __len__(self) -> int:
        raise TypeError(f"{self.source}: a RealSense stream has no length")

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        if start and self.file is None:
            raise InputError(f"{self.source}: a RealSense stream cannot start at frame {start}")
        index, t0 = 0, None
        last_number = None
        try:
            profile = self._pipe.start(self._config)
        except RuntimeError as exc:
            raise InputError(f"{self.source} cannot be started: {exc}") from None
        self._running = True
        if self.file is not None:
            # Playback starts with the pipeline, and a frameset delivered before the pace is
            # set can be lost (one run in three lost frame 0): pause, set the pace, rewind.
            self._playback = profile.get_device().as_playback()
            self._playback.pause()
            self._playback.set_real_time(self._real_time)
            self._playback.seek(timedelta(0))
            self._playback.resume()
        quiet = 0.0
        while self._running and (self.max_frames is None or index < self.max_frames):
            ok, frames = self._pipe.try_wait_for_frames(int(POLL_S * 1000))
            if not ok:
                if self._playback is not None and \
                        self._playback.current_status() == self._rs.playback_status.stopped:
                    return  # the recording has ended
                quiet += POLL_S
                if quiet >= FRAME_TIMEOUT_S:
                    raise InputError(f"{self.source} delivered no frame for "
                                     f"{FRAME_TIMEOUT_S:g} s; check the cable (USB 3) and that "
                                     "no other program uses it")
                continue
            quiet = 0.0
            if self._align is not None:
                frames = self._align.process(frames)
            color = frames.get_color_frame()
            depth = frames.get_depth_frame() if self.has_depth else None
            if not color:
                continue  # a depth-only frameset (streams start at different moments)
            number = color.get_frame_number()
            if number == last_number or (self._playback is not None and last_number is not None
                                         and number < last_number):
                # A playback may hand a colour frame to two framesets, or again after the
                # rewind; a device's counter may restart (a USB reset), so only files go by order.
                continue
            last_number = number
            t = color.get_timestamp() / 1000.0  # ms -> s
            if depth and abs(depth.get_timestamp() / 1000.0 - t) > self._tolerance:
                # The SDK's syncer fills a lost depth frame with the last one it had (a dropped
                # USB transfer, a late frame under load): that depth shows another moment.
                # (An aligned depth frame keeps the depth sensor's timestamp and metadata:
                # test_live_sources.)
                depth = None
            delay = capture_offset(color, depth, self._rs) if depth else None
            t -= exposure_lead(color, self._rs)  # the pose is the moment the colour captured
            t0 = t if t0 is None else t0
            if index < start:  # a resumed recording is read from its start, as it was played
                index += 1
                continue
            # The SDK recycles its buffers: copy (or convert) before the next wait.
            bgr = self._to_bgr(color)
            raw = np.array(np.asanyarray(depth.get_data()), np.uint16, copy=True) if depth else None
            where = f"{self.source} frame {index}"
            self.check_size(bgr, where)
            yield Frame(index, t - t0, bgr, raw, depth_delay=delay)
            index += 1

    def _to_bgr(self, color: Any) -> np.ndarray:
        """BGR8 copy of a colour frame (the Viewer records RGB8; devices may stream YUYV)."""
        rs, fmt = self._rs, color.get_profile().format()
        data = np.asanyarray(color.get_data())
        if fmt == rs.format.bgr8:
            return np.array(data, np.uint8, copy=True)
        if fmt == rs.format.rgb8:
            return cv2.cvtColor(data, cv2.COLOR_RGB2BGR)
        if fmt == rs.format.yuyv:
            return cv2.cvtColor(data.reshape(color.get_height(), -1, 2), cv2.COLOR_YUV2BGR_YUYV)
        raise InputError(f"{self.source}: colour format {fmt} is not supported; record or "
                         "stream colour as RGB8, BGR8 or YUYV")

    def close(self) -> None:
        super().close()
        if self._running:
            self._running = False
            try:
                self._pipe.stop()
            except RuntimeError:
                pass  # already stopped (a recording that ended)

