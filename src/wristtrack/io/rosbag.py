"""ROS 1 .bag files and ROS 2 bag folders of an RGB-D driver, through the pure-Python ``rosbags``.

Reads sensor_msgs/Image (or CompressedImage) colour, registered depth and sensor_msgs/CameraInfo.
Topics are found by message type and by the names OpenNI and RealSense drivers use
(``/camera/color/image_raw``, ``/camera/rgb/image_color``, ``/camera/aligned_depth_to_color/
image_raw``, ``/camera/depth_registered/image_raw``, ...); ``color_topic``, ``depth_topic`` and
``info_topic`` override the choice (``depth_topic="none"`` reads colour only). Only depth that
is registered to the colour image is picked automatically: unregistered depth would put every
blob's depth at the wrong pixel.

Depth comes out as uint16 in the camera's depth units (REP 118: 16UC1 is millimetres, 32FC1 is
metres); a camera made from camera_info has depth_scale 0.001. Each colour frame is paired with
the depth frame nearest in header time, if one is within half a colour frame interval
(``sync_tolerance`` overrides); each pair's stamps tell how long after its colour frame the
depth frame was captured (``Frame.depth_delay``; tracking/depth_timing.py).
Timestamps are header stamps (the bag's receive time where a stamp is zero) in seconds relative
to the first colour frame; ``time_origin`` is that frame's absolute time (s since the epoch).
Messages are streamed: a few frames are buffered for pairing, never the recording.
"""

from __future__ import annotations

import math
import re
import statistics
import warnings
from collections import deque
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path
from typing import Any

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, check_depth, reject_options
from wristtrack.io.ros_messages import (
    COMPRESSED,
    IMAGE_TYPES,
    INFO,
    RosMessage,
    camera_from_info,
    decode_colour,
    decode_depth,
    stamp_ns,
)

MAX_PENDING_COLOR = 16  # colour frames waiting for a later depth frame before going without
MAX_DEPTH_BUFFER = 32  # depth frames kept as pairing candidates
PERIOD_SAMPLE = 11  # colour stamps read at opening to estimate the frame interval
DEFAULT_PERIOD_NS = 33_333_333  # 30 Hz, if the bag has a single colour frame

_COLOR_WORDS = {"color", "colour", "rgb"}
_REGISTERED = ("aligned_depth_to_color", "aligned_depth_to_colour", "depth_registered")
# Last name of an image topic -> preference (higher wins) for colour and for depth.
_COLOR_LEAF = {"image_color": 4, "image_raw": 3, "image_rect_color": 2, "image_rect_raw": 2,
               "image": 1}
_DEPTH_LEAF = {"image_raw": 3, "image_rect_raw": 2, "image": 1, "image_rect": 1}
_TRANSPORTS = ("compressed", "compresseddepth")


def _rosbags() -> Any:
    """The rosbags modules, or an InputError saying how to install them."""
    try:
        from rosbags import highlevel, typesys
    except ImportError:
        raise InputError(
            "reading ROS bags needs the rosbags package: install wristtrack[ros] "
            "(pip install 'wristtrack[ros]')"
        ) from None
    return highlevel, typesys


def written_by_realsense_sdk(path: Path) -> bool:
    """Whether a ROS 1 .bag is a RealSense Viewer/SDK recording (its /device_N/... layout,
    which the SDK reads back far better than a topic reader: streams, options, extrinsics)."""
    try:
        from rosbags.rosbag1 import Reader
    except ImportError:
        return False  # BagRecording then says how to install rosbags
    try:
        with Reader(path) as reader:
            return any(t.startswith("/device_0/") for t in reader.topics)
    except Exception:  # a damaged or foreign file: BagRecording gives the error line
        return False


# ------------------------------------------------------------------------------ topic choice


def _tokens(topic: str) -> set[str]:
    return set(re.split(r"[/_]+", topic.lower())) - {""}


def _strip_transport(topic: str) -> str:
    head, _, leaf = topic.rpartition("/")
    return head if leaf.lower() in _TRANSPORTS else topic


def _namespace(topic: str) -> str:
    return _strip_transport(topic).rpartition("/")[0]


def _root(topic: str) -> str:
    return topic.strip("/").split("/")[0]


def _is_not_colour(topic: str) -> bool:
    tokens = _tokens(topic)
    return bool(
        tokens & {"depth", "ir", "disparity", "confidence", "mask"}
        or any(t.startswith("infra") for t in tokens)
    )


def _colour_score(topic: str, msgtype: str) -> float | None:
    if _is_not_colour(topic):
        return None
    score = 10.0 if _tokens(topic) & _COLOR_WORDS else 0.0
    base = _strip_transport(topic)
    score += _COLOR_LEAF.get(base.rpartition("/")[2].lower(), 0)
    return score - (0.5 if msgtype == COMPRESSED else 0.0)


def _is_registered(topic: str) -> bool:
    low = topic.lower()
    return any(word in low for word in _REGISTERED) or "registered" in _tokens(topic)


def _depth_score(topic: str, msgtype: str, colour: str) -> float | None:
    if "depth" not in topic.lower() or not _is_registered(topic):
        return None
    score = 5.0 if _root(topic) == _root(colour) else 0.0
    base = _strip_transport(topic)
    score += _DEPTH_LEAF.get(base.rpartition("/")[2].lower(), 0)
    return score - (0.5 if msgtype == COMPRESSED else 0.0)


def _info_score(topic: str, colour: str) -> float | None:
    # camera_info of the colour camera, or of depth registered to it (same intrinsics).
    if _namespace(topic) == _namespace(colour):
        return 20.0
    if _is_registered(topic) or (_tokens(topic) & _COLOR_WORDS and not _is_not_colour(topic)):
        return 10.0 + (5.0 if _root(topic) == _root(colour) else 0.0)
    return None


def _best(scores: dict[str, float], what: str, option: str, where: str) -> str:
    top = max(scores.values())
    winners = sorted(t for t, s in scores.items() if s == top)
    if len(winners) > 1:
        raise InputError(
            f"{where}: several {what} topics fit ({', '.join(winners)}); choose one with "
            f"{option}=TOPIC"
        )
    return winners[0]

# ------------------------------------------------------------------------------ the recording


class BagRecording(Recording):
    """Colour (+ registered depth) frames of a ROS 1 .bag or a ROS 2 bag folder."""

    kind = "ROS bag"

    def __init__(
        self,
        path: str | Path,
        camera: Camera | None = None,
        hand: HandLayout | None = None,
        *,
        color_topic: str | None = None,
        depth_topic: str | None = None,
        info_topic: str | None = None,
        sync_tolerance: float | None = None,
        **unknown: object,
    ) -> None:
        path = Path(path)
        reject_options("the ROS bag", path, unknown)
        self.path = path
        self.where = f"ROS bag {path}"
        if not path.exists():
            raise InputError(f"{self.where} not found; give a .bag file or a ROS 2 bag folder")
        with self._reader() as reader:
            topics = {name: info.msgtype for name, info in reader.topics.items()}
            counts = {name: info.msgcount for name, info in reader.topics.items()}
            self.color_topic = self._choose_colour(topics, color_topic)
            self.depth_topic = self._choose_depth(topics, depth_topic)
            if camera is None:
                info = self._choose_info(topics, info_topic)
                camera = camera_from_info(
                    self._first(reader, info).msg, f"{self.where} topic {info}"
                )
                self.info_topic: str | None = info
            else:
                self.info_topic = None
            super().__init__(str(path), camera, hand)
            self._length = counts[self.color_topic]
            if self._length == 0:
                raise InputError(
                    f"{self.where}: topic {self.color_topic} has no messages; the recording is "
                    "empty"
                )
            stamps = self._colour_stamps(reader)
            diffs = [b - a for a, b in zip(stamps, stamps[1:], strict=False) if b > a]
            period = statistics.median(diffs) if diffs else DEFAULT_PERIOD_NS
            self.sync_tolerance = sync_tolerance if sync_tolerance is not None else period / 2e9
            self.has_depth = self.depth_topic is not None
        self.time_origin = stamps[0] / 1e9
        self._t0 = stamps[0]

    # ------------------------------------------------------------------------------ opening

    def _reader(self) -> Any:
        highlevel, typesys = _rosbags()
        try:
            try:
                # Bags written by ROS 2 before Iron carry no message definitions: assume the
                # standard ones (older rosbags releases have no default_typestore).
                typestore = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
                reader = highlevel.AnyReader([self.path], default_typestore=typestore)
            except (AttributeError, TypeError):
                reader = highlevel.AnyReader([self.path])
            reader.open()
        except Exception as e:  # rosbags raises several types for damaged or foreign files
            raise InputError(
                f"{self.where} cannot be read ({e}); give a complete ROS 1 .bag (rosbag reindex "
                "an interrupted one) or a ROS 2 bag folder"
            ) from None
        return closing(reader)

    def _list(self, topics: dict[str, str]) -> str:
        listing = ", ".join(f"{name} ({kind})" for name, kind in sorted(topics.items()))
        return listing or "none"

    def _given(self, topics: dict[str, str], topic: str, types: tuple[str, ...], option: str):
        if topic not in topics:
            raise InputError(
                f"{self.where} has no topic {topic!r} ({option}); its topics: "
                f"{self._list(topics)}"
            )
        if topics[topic] not in types:
            raise InputError(
                f"{self.where}: topic {topic} is {topics[topic]}, not {' or '.join(types)}; "
                f"fix {option}"
            )
        return topic

    def _choose_colour(self, topics: dict[str, str], given: str | None) -> str:
        if given:
            return self._given(topics, given, IMAGE_TYPES, "color_topic")
        scores = {t: _colour_score(t, k) for t, k in topics.items() if k in IMAGE_TYPES}
        scores = {t: s for t, s in scores.items() if s is not None}
        if not scores:
            raise InputError(
                f"{self.where} has no colour image topic (sensor_msgs/Image or CompressedImage); "
                f"its topics: {self._list(topics)}; set color_topic= if one is the colour camera"
            )
        return _best(scores, "colour image", "color_topic", self.where)

    def _choose_depth(self, topics: dict[str, str], given: str | None) -> str | None:
        if given and given.lower() == "none":
            return None
        if given:
            return self._given(topics, given, IMAGE_TYPES, "depth_topic")
        images = [t for t, k in topics.items() if k in IMAGE_TYPES and t != self.color_topic]
        scores = {t: _depth_score(t, topics[t], self.color_topic) for t in images}
        scores = {t: s for t, s in scores.items() if s is not None}
        if not scores:
            unregistered = [t for t in images if "depth" in t.lower()]
            if unregistered:
                warnings.warn(
                    f"{self.where}: no registered depth topic; ignoring {', '.join(unregistered)} "
                    "(not aligned to colour). Set depth_topic= if it is registered.",
                    stacklevel=3,
                )
            return None
        return _best(scores, "registered depth", "depth_topic", self.where)

    def _choose_info(self, topics: dict[str, str], given: str | None) -> str:
        if given:
            return self._given(topics, given, (INFO,), "info_topic")
        scores = {t: _info_score(t, self.color_topic) for t, k in topics.items() if k == INFO}
        scores = {t: s for t, s in scores.items() if s is not None}
        if not scores:
            raise ConfigError(
                f"{self.where} has no sensor_msgs/CameraInfo topic for {self.color_topic}; its "
                f"topics: {self._list(topics)}; pass --camera camera.json (or info_topic=)"
            )
        return _best(scores, "camera_info", "info_topic", self.where)

    def _connections(self, reader: Any, topic: str) -> list[Any]:
        return [c for c in reader.connections if c.topic == topic]

    def _messages(self, reader: Any, topics: list[str]) -> Iterator[tuple[str, RosMessage]]:
        conns = [c for topic in topics for c in self._connections(reader, topic)]
        with closing(reader.messages(connections=conns)) as messages:
            for conn, log_time, raw in messages:
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as e:  # one damaged message: its frame is reported as bad
                    error = (
                        f"{self.where}: a message on {conn.topic} at {int(log_time)} ns cannot "
                        f"be decoded ({type(e).__name__}: {e}); the bag is damaged there"
                    )
                    error = " ".join(error.split())  # one line, whatever the library said
                    yield conn.topic, RosMessage(int(log_time), conn.msgtype, None, error)
                    continue
                stamp = stamp_ns(msg, log_time) if hasattr(msg, "header") else int(log_time)
                yield conn.topic, RosMessage(stamp, conn.msgtype, msg)

    def _first(self, reader: Any, topic: str) -> RosMessage:
        with closing(self._messages(reader, [topic])) as messages:
            for _, m in messages:
                if m.error:
                    raise InputError(m.error)
                return m
        raise ConfigError(
            f"{self.where}: topic {topic} has no messages; pass --camera camera.json"
        )

    def _colour_stamps(self, reader: Any) -> list[int]:
        """Stamps of the first few colour frames; the first one is decoded to check its size."""
        where = f"{self.where} topic {self.color_topic}"
        stamps: list[int] = []
        with closing(self._messages(reader, [self.color_topic])) as messages:
            for _, m in messages:
                if not stamps:
                    self.check_size(decode_colour(m, where), where)
                stamps.append(m.stamp)
                if len(stamps) >= PERIOD_SAMPLE:
                    break
        return stamps

    def __len__(self) -> int:
        return self._length

    # ------------------------------------------------------------------------------ frames

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        tol = round(self.sync_tolerance * 1e9)
        topics = [self.color_topic] + ([self.depth_topic] if self.depth_topic else [])
        pending: deque[RosMessage] = deque()  # colour frames waiting for their depth
        depths: deque[RosMessage] = deque()  # depth candidates
        newest_depth: int | None = None
        last_colour: int | None = None
        index = 0
        failure: list[str] = []
        with self._reader() as reader, closing(self._messages(reader, topics)) as messages:
            for topic, m in _until_damaged(messages, failure):
                if topic == self.color_topic:
                    pending.append(m)
                else:
                    depths.append(m)
                    newest_depth = m.stamp if newest_depth is None else max(newest_depth, m.stamp)
                # A colour frame is complete once depth has moved past its window (depth stamps
                # increase), or when depth stalls (dropped, or the stream has ended).
                while pending and (
                    self.depth_topic is None
                    or (newest_depth is not None and newest_depth > pending[0].stamp + tol)
                    or len(pending) > MAX_PENDING_COLOR
                ):
                    c = pending.popleft()
                    last_colour = c.stamp
                    if index >= start:  # resuming: frames before start are paired, not decoded
                        yield self._frame(index, c, depths, tol)
                    index += 1
                reference = pending[0].stamp if pending else last_colour
                while depths and (
                    len(depths) > MAX_DEPTH_BUFFER
                    or (reference is not None and depths[0].stamp < reference - tol)
                ):
                    depths.popleft()
            while pending:
                c = pending.popleft()
                if index >= start:
                    yield self._frame(index, c, depths, tol)
                index += 1
            if failure:
                after = (last_colour - self._t0) / 1e9 if last_colour is not None else math.nan
                yield Frame.bad(
                    index, after,
                    f"{self.where} cannot be read past {after:.3f} s ({failure[0]}); the rest of "
                    "the recording is missing (for a ROS 1 bag try rosbag reindex)",
                )

    def _frame(self, index: int, c: RosMessage, depths: deque[RosMessage], tol: int) -> Frame:
        where = f"{self.where} topic {self.color_topic} frame {index}"
        timestamp = (c.stamp - self._t0) / 1e9
        try:
            bgr = decode_colour(c, where)
            self.check_size(bgr, where)
            depth = delay = None
            if depths:
                best = min(depths, key=lambda d: abs(d.stamp - c.stamp))
                if abs(best.stamp - c.stamp) <= tol:
                    where = f"{self.where} topic {self.depth_topic} (for frame {index})"
                    raw = decode_depth(best, self.camera.depth_scale, where)
                    depth, delay = check_depth(raw, bgr, where), (best.stamp - c.stamp) / 1e9
        except InputError as e:  # this frame only: the caller notes it and goes on
            return Frame.bad(index, timestamp, str(e))
        return Frame(index, timestamp, bgr, depth, depth_delay=delay)


def _until_damaged(messages: Iterator, failure: list[str]) -> Iterator:
    """The messages until the bag reader itself fails (a damaged chunk, a truncated file);
    the failure, one line, goes into ``failure`` instead of ending the run with a traceback."""
    while True:
        try:
            item = next(messages)
        except StopIteration:
            return
        except InputError:
            raise
        except Exception as e:  # rosbags raises several types for damaged files
            failure.append(" ".join(f"{type(e).__name__}: {e}".split()))
            return
        yield item
