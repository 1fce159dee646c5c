"""Decoding ROS sensor messages: Image / CompressedImage into BGR colour or raw depth, CameraInfo
into a Camera. No bag reading here (that is io.rosbag); these work on deserialised messages.

Depth comes out as uint16 in the camera's depth units (REP 118: 16UC1 is millimetres, 32FC1 is
metres); a camera made from camera_info has depth_scale 0.001.
"""

from __future__ import annotations

import struct
from typing import Any, NamedTuple

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
INFO = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPES = (IMAGE, COMPRESSED)
MM = 0.001  # depth_scale of REP 118 16UC1 depth

_BAYER = {  # ROS encoding -> OpenCV conversion (OpenCV's older names are shifted by one pixel)
    "bayer_rggb8": ("COLOR_BayerRGGB2BGR", "COLOR_BayerBG2BGR"),
    "bayer_bggr8": ("COLOR_BayerBGGR2BGR", "COLOR_BayerRG2BGR"),
    "bayer_gbrg8": ("COLOR_BayerGBRG2BGR", "COLOR_BayerGR2BGR"),
    "bayer_grbg8": ("COLOR_BayerGRBG2BGR", "COLOR_BayerGB2BGR"),
}
_ENCODINGS = {  # ROS image encoding -> (dtype, channels)
    "rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "8uc3": (np.uint8, 3),
    "rgba8": (np.uint8, 4), "bgra8": (np.uint8, 4), "8uc4": (np.uint8, 4),
    "mono8": (np.uint8, 1), "8uc1": (np.uint8, 1),
    "mono16": (np.uint16, 1), "16uc1": (np.uint16, 1), "32fc1": (np.float32, 1),
    **{name: (np.uint8, 1) for name in _BAYER},
}


class RosMessage(NamedTuple):
    """One message read from a bag: its stamp, type and deserialised body (or why it is not)."""

    stamp: int  # ns
    msgtype: str
    msg: Any
    error: str | None = None  # the message could not be deserialised (msg is None)


def stamp_ns(msg: Any, log_time: int) -> int:
    """Header stamp in ns; the bag's receive time where the driver left the stamp at zero."""
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns if ns > 0 else int(log_time)


def _raw_array(msg: Any, where: str) -> tuple[str, np.ndarray]:
    """(encoding, array (H,W) or (H,W,C)) of a sensor_msgs/Image, honouring step and endianness."""
    enc = str(msg.encoding).lower()
    if enc not in _ENCODINGS:
        raise InputError(
            f"{where}: image encoding {msg.encoding!r} is not supported; supported: "
            f"{', '.join(sorted(_ENCODINGS))}"
        )
    dtype, channels = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * np.dtype(dtype).itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if h == 0 or w == 0 or step < row or data.size < h * step:
        raise InputError(
            f"{where}: image message is inconsistent ({w}x{h}, step {step}, {data.size} bytes); "
            "the bag is damaged"
        )
    rows = np.ascontiguousarray(data[: h * step].reshape(h, step)[:, :row])
    order = ">" if msg.is_bigendian else "<"
    array = rows.view(np.dtype(dtype).newbyteorder(order)).astype(dtype, copy=False)
    return enc, array.reshape((h, w) if channels == 1 else (h, w, channels))


def decode_colour(m: RosMessage, where: str) -> np.ndarray:
    """BGR uint8 (H,W,3) of an Image (rgb8, bgr8, mono8, rgba8, bgra8, bayer) or CompressedImage."""
    if m.error:
        raise InputError(m.error)
    if m.msgtype == COMPRESSED:
        image = cv2.imdecode(np.asarray(m.msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f"{where}: compressed image ({m.msg.format}) cannot be decoded")
        return image
    enc, image = _raw_array(m.msg, where)
    if image.dtype != np.uint8:
        raise InputError(
            f"{where} has {m.msg.encoding} images; colour must be rgb8, bgr8 or mono8 (is this "
            "the depth topic? set color_topic=)"
        )
    if enc in ("rgb8",):
        return cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    if enc in ("rgba8",):
        return cv2.cvtColor(image, cv2.COLOR_RGBA2BGR)
    if enc in ("bgra8", "8uc4"):
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if enc in _BAYER:
        new, old = _BAYER[enc]
        return cv2.cvtColor(image, getattr(cv2, new, None) or getattr(cv2, old))
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image.copy()  # bgr8 / 8UC3; copy: the message buffer is read-only


def _depth_units(metres: np.ndarray, depth_scale: float) -> np.ndarray:
    """Float metres -> uint16 raw units; NaN, inf, <= 0 and out-of-range become 0 (no reading)."""
    with np.errstate(invalid="ignore"):
        units = np.rint(metres / depth_scale)
        valid = np.isfinite(units) & (units > 0) & (units <= np.iinfo(np.uint16).max)
    return np.where(valid, units, 0).astype(np.uint16)


def decode_depth(m: RosMessage, depth_scale: float, where: str) -> np.ndarray:
    """Raw uint16 depth (H,W) in units of ``depth_scale`` metres from 16UC1 (mm) or 32FC1 (m)."""
    if m.error:
        raise InputError(m.error)
    if m.msgtype == COMPRESSED:
        return _decode_compressed_depth(m.msg, depth_scale, where)
    enc, image = _raw_array(m.msg, where)
    if enc in ("16uc1", "mono16"):
        if depth_scale == MM:
            return image.copy()
        return _depth_units(image * MM, depth_scale)
    if enc == "32fc1":
        return _depth_units(image.astype(np.float64), depth_scale)
    raise InputError(
        f"{where} has {m.msg.encoding} images; depth must be 16UC1 (mm) or 32FC1 (m) (is this "
        "the colour topic? set depth_topic=)"
    )


def _decode_compressed_depth(msg: Any, depth_scale: float, where: str) -> np.ndarray:
    """image_transport compressedDepth: a 12-byte header (format, quantisation) then a PNG."""
    data = bytes(msg.data)
    fmt = str(msg.format).lower()
    start = data.find(b"\x89PNG")
    image = None
    if start >= 0 and "compresseddepth" in fmt:
        image = cv2.imdecode(np.frombuffer(data[start:], np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint16 or image.ndim != 2:
        raise InputError(
            f"{where}: compressed depth ({msg.format}) cannot be decoded; only "
            "compressedDepth PNG is supported, or use the raw depth topic"
        )
    if fmt.startswith("32fc1"):
        # Stored as quantised inverse depth: z = a / (v - b), v = 0 meaning no reading.
        _, a, b = struct.unpack("<iff", data[:12])
        with np.errstate(divide="ignore", invalid="ignore"):
            metres = np.where(image > 0, a / (image.astype(np.float64) - b), np.nan)
        return _depth_units(metres, depth_scale)
    return image if depth_scale == MM else _depth_units(image * MM, depth_scale)


def camera_from_info(msg: Any, where: str) -> Camera:
    """Camera (K, plumb_bob/rational_polynomial D, size; depth_scale 0.001) of a CameraInfo."""
    k = np.asarray(msg.k if hasattr(msg, "k") else msg.K, dtype=np.float64)
    d = np.asarray(msg.d if hasattr(msg, "d") else msg.D, dtype=np.float64)
    model = str(msg.distortion_model).lower()
    if d.size and np.any(d != 0) and model not in ("plumb_bob", "rational_polynomial"):
        raise ConfigError(
            f"{where}: distortion model {msg.distortion_model!r} is not supported (plumb_bob or "
            "rational_polynomial); use rectified images or pass --camera camera.json"
        )
    try:
        return Camera(
            fx=float(k[0]), fy=float(k[4]), cx=float(k[2]), cy=float(k[5]),
            width=int(msg.width), height=int(msg.height), depth_scale=MM,
            dist=tuple(float(c) for c in d) if d.size else None,
        )
    except (ConfigError, IndexError) as e:
        raise ConfigError(
            f"{where}: not a usable calibration ({e}); calibrate the camera or pass --camera "
            "camera.json"
        ) from None
