"""wristtrack.io: recording folders, videos, ROS bags and live cameras, with files written here.

Oracles: the arrays the test wrote (pixel-exact for lossless formats), OpenCV's own VideoWriter,
and rosbags' own bag writers.
"""

from __future__ import annotations

import inspect
import shutil
import sys
import tracemalloc
import warnings
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording
from wristtrack.io.folder import RecordingWriter
from wristtrack.io.live import opencv as live_module
from wristtrack.io.open import open_recording
from wristtrack.io.ros_messages import IMAGE, RosMessage, decode_colour, decode_depth

try:  # the test extra installs rosbags; without it only the ROS bag tests are skipped
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore
except ImportError:  # pragma: no cover
    Writer1 = None

needs_rosbags = pytest.mark.skipif(Writer1 is None, reason="rosbags not installed")

W, H = 64, 48
CAMERA = Camera(
    fx=80.0, fy=81.0, cx=31.7, cy=23.2, width=W, height=H, depth_scale=0.001,
    dist=(0.11, -0.21, 0.001, -0.002, 0.05),
)
# Awkward timestamps: repr-precision, tiny, large, repeated and decreasing (not this layer's error).
TIMESTAMPS = [0.1 + 1 / 3, 1e-9, 12345.678901234567, 12345.678901234567, 2.0 / 7.0]


def colour(i: int, w: int = W, h: int = H) -> np.ndarray:
    return np.random.default_rng(i).integers(0, 256, (h, w, 3), dtype=np.uint8)


def depth(i: int, w: int = W, h: int = H) -> np.ndarray:
    d = np.random.default_rng(100 + i).integers(0, 65536, (h, w), dtype=np.uint16)
    d[:5] = 0  # no reading
    return d


def write_folder(folder: Path, n: int = 3, hand: HandLayout | None = None) -> Path:
    with RecordingWriter(folder, CAMERA, hand) as writer:
        for i in range(n):
            writer.write(i / 30, colour(i), depth(i))
    return folder


def one_line(err: pytest.ExceptionInfo, *needles: str) -> None:
    """The error is one line and mentions every needle (file names, the fix)."""
    text = str(err.value)
    assert "\n" not in text
    for needle in needles:
        assert needle in text, (needle, text)


# ------------------------------------------------------------------------- native folders


def test_folder_round_trip_is_exact(tmp_path):
    hand = HandLayout.default()
    folder = tmp_path / "rec"
    with RecordingWriter(folder, CAMERA, hand) as writer:
        for i, t in enumerate(TIMESTAMPS):
            writer.write(t, colour(i), None if i == 2 else depth(i))
    assert (folder / "frames.csv").read_text().splitlines()[0] == "timestamp,rgb,depth"
    lines = (folder / "frames.csv").read_text().splitlines()
    assert lines[3] == f"{TIMESTAMPS[2]!r},rgb/000002.png,"

    with open_recording(folder) as rec:
        assert isinstance(rec, Recording)
        assert len(rec) == len(TIMESTAMPS)
        assert rec.camera == CAMERA and rec.hand == hand
        assert rec.source == str(folder)
        frames_iter = iter(rec)
        assert inspect.isgenerator(frames_iter)
        frames = list(frames_iter)
    assert [f.index for f in frames] == list(range(len(TIMESTAMPS)))
    assert [f.timestamp for f in frames] == TIMESTAMPS  # exact, not approximate
    for i, f in enumerate(frames):
        assert isinstance(f, Frame)
        assert f.bgr.dtype == np.uint8 and f.bgr.shape == (H, W, 3)
        np.testing.assert_array_equal(f.bgr, colour(i))
        if i == 2:
            assert f.depth is None
        else:
            assert f.depth.dtype == np.uint16
            np.testing.assert_array_equal(f.depth, depth(i))


def test_folder_arguments_override_files_and_frames_csv_path_works(tmp_path):
    folder = write_folder(tmp_path / "rec", hand=HandLayout.default())
    other_cam = Camera(fx=50.0, fy=50.0, cx=32.0, cy=24.0, width=W, height=H)
    other_hand = HandLayout.default().mirrored()
    rec = open_recording(folder / "frames.csv", camera=other_cam, hand=other_hand)
    assert rec.camera == other_cam and rec.hand == other_hand
    assert len(list(rec)) == 3
    assert open_recording(write_folder(tmp_path / "nohand")).hand is None


def test_folder_reader_streams_one_frame_at_a_time(tmp_path):
    n, w, h = 24, 320, 240
    folder = tmp_path / "rec"
    flat = np.full((h, w, 3), 90, np.uint8)  # compresses well: fast to write
    cam = Camera(fx=300.0, fy=300.0, cx=160.0, cy=120.0, width=w, height=h)
    with RecordingWriter(folder, cam) as writer:
        for i in range(n):
            writer.write(i / 30, flat, np.full((h, w), i, np.uint16))
    frame_bytes = flat.nbytes + w * h * 2
    rec = open_recording(folder)
    tracemalloc.start()
    try:
        count = 0
        for f in rec:
            assert int(f.depth[0, 0]) == count
            count += 1
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert count == n
    assert peak < 4 * frame_bytes, peak  # a few frames, not the recording (n frames)


def test_frames_are_read_lazily(tmp_path):
    folder = write_folder(tmp_path / "rec", n=4)
    rec = open_recording(folder)
    (folder / "rgb" / "000002.png").write_bytes(b"not a png")  # damaged after opening
    frames = iter(rec)
    assert next(frames).index == 0 and next(frames).index == 1
    bad = next(frames)  # a damaged frame is yielded as bad, and reading goes on
    assert bad.index == 2 and not bad.ok and bad.bgr.size == 0
    assert "\n" not in bad.error
    assert "000002.png" in bad.error and "corrupt or truncated" in bad.error
    assert next(frames).ok


def test_writer_leaves_a_valid_folder_when_interrupted(tmp_path):
    folder = tmp_path / "rec"
    writer = RecordingWriter(folder, CAMERA)  # never closed: as if the process were killed
    for i in range(3):
        writer.write(i * 0.5, colour(i), depth(i))
    frames = list(open_recording(folder))
    assert [f.timestamp for f in frames] == [0.0, 0.5, 1.0]
    np.testing.assert_array_equal(frames[2].depth, depth(2))
    writer.close()


def test_writer_refuses_to_overwrite_unless_asked(tmp_path):
    folder = write_folder(tmp_path / "rec", n=3, hand=HandLayout.default())
    (folder / "notes.txt").write_text("keep me")
    with pytest.raises(InputError) as err:
        RecordingWriter(folder, CAMERA)
    one_line(err, str(folder), "overwrite=True")
    assert len(open_recording(folder)) == 3  # untouched

    with RecordingWriter(folder, CAMERA, overwrite=True) as writer:
        writer.write(7.0, colour(9))
    rec = open_recording(folder)
    assert len(rec) == 1 and rec.hand is None  # stale hand.json gone
    assert not any((folder / "depth").iterdir()) and len(list((folder / "rgb").iterdir())) == 1
    assert (folder / "notes.txt").read_text() == "keep me"  # not the writer's file
    (tmp_path / "empty").mkdir()
    RecordingWriter(tmp_path / "empty", CAMERA).close()  # an existing empty folder is fine


def test_writer_rejects_bad_frames(tmp_path):
    with RecordingWriter(tmp_path / "rec", CAMERA) as writer:
        for bad in (colour(0)[:, :, 0], colour(0).astype(np.uint16), colour(0, w=W + 2)):
            with pytest.raises(InputError):
                writer.write(0.0, bad)
        with pytest.raises(InputError):
            writer.write(float("nan"), colour(0))
        with pytest.raises(InputError):
            writer.write(0.0, colour(0), depth(0)[:-1])
        assert writer.count == 0


# ----------------------------------------------------------------------- bad folder input


def _edit_csv(folder: Path, text: str) -> None:
    (folder / "frames.csv").write_text(text)


BAD_OPEN = {
    "wrong header": (lambda f: _edit_csv(f, "time,rgb,depth\n0,rgb/000000.png,\n"),
                     InputError, ["frames.csv", "timestamp,rgb,depth"]),
    "empty file": (lambda f: _edit_csv(f, ""), InputError, ["frames.csv", "empty", "header"]),
    "no frames": (lambda f: _edit_csv(f, "timestamp,rgb,depth\n"), InputError,
                  ["frames.csv", "empty"]),
    "timestamp text": (lambda f: _edit_csv(f, "timestamp,rgb,depth\nabc,rgb/000000.png,\n"),
                       InputError, ["frames.csv line 2", "'abc'", "not a number"]),
    "timestamp nan": (lambda f: _edit_csv(f, "timestamp,rgb,depth\nnan,rgb/000000.png,\n"),
                      InputError, ["line 2", "not a number"]),
    "too many cells": (lambda f: _edit_csv(f, "timestamp,rgb,depth\n0,a.png,b.png,c\n"),
                       InputError, ["line 2", "3 cells"]),
    "rgb missing": (lambda f: (f / "rgb" / "000001.png").unlink(), InputError,
                    ["frames.csv line 3", "000001.png", "not found"]),
    "depth missing": (lambda f: (f / "depth" / "000002.png").unlink(), InputError,
                      ["line 4", "depth", "000002.png", "not found"]),
    "no camera.json": (lambda f: (f / "camera.json").unlink(), ConfigError,
                       ["camera.json", "--camera"]),
    "bad camera.json": (lambda f: (f / "camera.json").write_text('{"fx": 1}'), ConfigError,
                        ["camera.json", "missing field"]),
    "no frames.csv": (lambda f: (f / "frames.csv").unlink(), InputError, ["no frames.csv"]),
}


@pytest.mark.parametrize("case", BAD_OPEN)
def test_bad_folder_fails_at_open_with_one_line(tmp_path, case):
    spoil, kind, needles = BAD_OPEN[case]
    folder = write_folder(tmp_path / "rec")
    spoil(folder)
    with pytest.raises(kind) as err:
        open_recording(folder)
    one_line(err, *needles)


def _png(path: Path, image: np.ndarray) -> None:
    assert cv2.imwrite(str(path), image)


BAD_READ = {
    "corrupt colour": (lambda f: (f / "rgb" / "000001.png").write_bytes(b"\x89PNG garbage"),
                       ["rgb", "000001.png", "corrupt"]),
    "truncated colour": (
        lambda f: (f / "rgb" / "000001.png").write_bytes(
            (f / "rgb" / "000001.png").read_bytes()[:-40]),
        ["000001.png", "truncated"]),
    "truncated depth": (
        lambda f: (f / "depth" / "000001.png").write_bytes(
            (f / "depth" / "000001.png").read_bytes()[:200]),
        ["depth", "000001.png", "truncated"]),
    "depth 8-bit": (lambda f: _png(f / "depth" / "000001.png", np.zeros((H, W), np.uint8)),
                    ["depth image", "000001.png", "8-bit", "16-bit"]),
    "depth colour": (lambda f: _png(f / "depth" / "000001.png", np.zeros((H, W, 3), np.uint16)),
                     ["000001.png", "single-channel"]),
    "depth size": (lambda f: _png(f / "depth" / "000001.png", depth(1, w=W // 2, h=H // 2)),
                   ["000001.png", "32x24", "64x48", "registered"]),
    "colour 16-bit": (lambda f: _png(f / "rgb" / "000001.png", np.zeros((H, W, 3), np.uint16)),
                      ["rgb", "000001.png", "16-bit", "8-bit"]),
    "colour size": (lambda f: _png(f / "rgb" / "000001.png", colour(1, w=W * 2, h=H * 2)),
                    ["000001.png", "128x96", "64x48", "camera.json"]),
}


@pytest.mark.parametrize("case", BAD_READ)
def test_bad_image_is_a_bad_frame_with_one_line(tmp_path, case):
    spoil, needles = BAD_READ[case]
    folder = write_folder(tmp_path / "rec")
    spoil(folder)
    frames = list(open_recording(folder))
    assert [f.ok for f in frames] == [True, False, True]
    error = frames[1].error
    assert "\n" not in error and all(n in error for n in needles), error


@pytest.mark.parametrize("case", BAD_READ)
def test_bad_first_frames_fail_at_open_with_one_line(tmp_path, case):
    # every probed frame bad: the recording, not a frame, is at fault
    spoil, needles = BAD_READ[case]
    folder = write_folder(tmp_path / "rec", n=3)
    spoil(folder)
    for sub in ("rgb", "depth"):  # frames 0 and 2 spoiled the same way
        for i in (0, 2):
            shutil.copy(folder / sub / "000001.png", folder / sub / f"{i:06d}.png")
    with pytest.raises(InputError) as err:
        open_recording(folder)
    one_line(err, *[n.replace("000001", "000000") for n in needles])


def test_grayscale_colour_is_converted(tmp_path):
    folder = write_folder(tmp_path / "rec", n=1)
    grey = colour(5)[:, :, 0]
    _png(folder / "rgb" / "000000.png", grey)
    (frame,) = list(open_recording(folder))
    assert frame.bgr.shape == (H, W, 3)
    for c in range(3):
        np.testing.assert_array_equal(frame.bgr[:, :, c], grey)


def test_open_recording_dispatch_errors(tmp_path):
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "nothing")
    one_line(err, "nothing", "not found")
    (tmp_path / "plain").mkdir()
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "plain")
    one_line(err, "frames.csv", "metadata.yaml")
    (tmp_path / "x.xyz").write_text("?")
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "x.xyz")
    one_line(err, "x.xyz", "unknown kind")
    folder = write_folder(tmp_path / "rec", n=1)
    with pytest.raises(InputError) as err:
        open_recording(folder, color_topic="/a")
    one_line(err, "color_topic", "do not apply")


# ---------------------------------------------------------------------------------- video


def video_frame(i: int) -> np.ndarray:
    """Smooth content (survives JPEG): a gradient plus a bright square that moves."""
    y, x = np.mgrid[0:H, 0:W]
    img = np.stack([x * 3, y * 4, np.full_like(x, 40 + 10 * i)], -1).astype(np.uint8)
    img[8:24, 4 + 4 * i:20 + 4 * i] = (30, 220, 240)
    return img


def write_video(path: Path, n: int, fps: float = 25.0) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (W, H))
    assert writer.isOpened(), "this OpenCV build cannot write MJPG .avi"
    for i in range(n):
        writer.write(video_frame(i))
    writer.release()


def test_video_round_trip(tmp_path):
    path = tmp_path / "clip.avi"
    write_video(path, 8, fps=25.0)
    with open_recording(path, camera=CAMERA) as rec:
        assert len(rec) == 8 and rec.camera == CAMERA and not rec.has_depth
        frames = list(rec)
    assert [f.index for f in frames] == list(range(8))
    np.testing.assert_allclose([f.timestamp for f in frames], np.arange(8) / 25.0, atol=1e-6)
    for i, f in enumerate(frames):
        assert f.depth is None and f.bgr.dtype == np.uint8 and f.bgr.shape == (H, W, 3)
        err = np.abs(f.bgr.astype(int) - video_frame(i).astype(int))
        assert err.mean() < 6, (i, err.mean())
        # The square is where it was drawn in this frame (order preserved).
        assert f.bgr[16, 12 + 4 * i, 1] > 180


def test_video_errors(tmp_path):
    path = tmp_path / "clip.avi"
    write_video(path, 2)
    with pytest.raises(ConfigError) as err:
        open_recording(path)
    one_line(err, "clip.avi", "a video has no intrinsics: pass --camera camera.json")
    with pytest.raises(InputError) as err:
        open_recording(path, camera=Camera.default())
    one_line(err, "clip.avi", "64x48", "640x480")
    (tmp_path / "bad.mp4").write_bytes(b"\x00" * 2048)
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "bad.mp4", camera=CAMERA)
    one_line(err, "bad.mp4", "cannot be opened")
    write_video(tmp_path / "empty.avi", 0)
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "empty.avi", camera=CAMERA)
    one_line(err, "empty.avi", "no readable frames")


# --------------------------------------------------------------------------------- ROS bags


T0_NS = 1_700_000_000_123_456_789
PERIOD_NS = 33_333_333
K = (80.0, 0.0, 31.7, 0.0, 81.0, 23.2, 0.0, 0.0, 1.0)
D = (0.11, -0.21, 0.001, -0.002, 0.05)


class BagWriter:
    """Writes sensor_msgs with rosbags' own writers, ROS 1 or ROS 2 naming and serialisation."""

    def __init__(self, path: Path, ros: int) -> None:
        self.ros = ros
        self.store = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
        if ros == 1:
            self.writer = Writer1(path)
        elif "version" in inspect.signature(Writer2).parameters:
            self.writer = Writer2(path, version=9)
        else:  # pragma: no cover - older rosbags
            self.writer = Writer2(path)
        self.writer.open()
        self.connections: dict[str, object] = {}
        self.types = self.store.types

    def header(self, stamp_ns: int):
        t = self.types["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
        )
        extra = {"seq": 0} if self.ros == 1 else {}
        return self.types["std_msgs/msg/Header"](stamp=t, frame_id="camera", **extra)

    def write(self, topic: str, msgtype: str, msg, log_ns: int) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(
                topic, msgtype, typestore=self.store
            )
        ser = self.store.serialize_ros1 if self.ros == 1 else self.store.serialize_cdr
        self.writer.write(self.connections[topic], log_ns, ser(msg, msgtype))

    def image(self, topic, stamp_ns, array, encoding, log_ns=None, pad=0):
        h, w = array.shape[:2]
        rows = array.reshape(h, -1).view(np.uint8)
        if pad:
            rows = np.hstack([rows, np.full((h, pad), 7, np.uint8)])
        msg = self.types["sensor_msgs/msg/Image"](
            header=self.header(stamp_ns), height=h, width=w, encoding=encoding, is_bigendian=0,
            step=rows.shape[1], data=np.ascontiguousarray(rows).reshape(-1),
        )
        self.write(topic, "sensor_msgs/msg/Image", msg, log_ns or stamp_ns)

    def compressed(self, topic, stamp_ns, data: bytes, fmt: str):
        msg = self.types["sensor_msgs/msg/CompressedImage"](
            header=self.header(stamp_ns), format=fmt, data=np.frombuffer(data, np.uint8),
        )
        self.write(topic, "sensor_msgs/msg/CompressedImage", msg, stamp_ns)

    def info(self, topic, stamp_ns, k=K, d=D, model="plumb_bob"):
        T = self.types
        roi = T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        mats = {"d": np.array(d, float), "k": np.array(k, float),
                "r": np.eye(3).reshape(-1), "p": np.zeros(12)}
        if self.ros == 1:
            mats = {key.upper(): value for key, value in mats.items()}
        msg = T["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp_ns), height=H, width=W, distortion_model=model,
            binning_x=0, binning_y=0, roi=roi, **mats,
        )
        self.write(topic, "sensor_msgs/msg/CameraInfo", msg, stamp_ns)

    def string(self, topic, stamp_ns, text="x"):
        self.write(topic, "std_msgs/msg/String", self.types["std_msgs/msg/String"](data=text),
                   stamp_ns)

    def close(self):
        self.writer.close()


def bag_path(tmp_path: Path, ros: int, name: str = "rec") -> Path:
    return tmp_path / (f"{name}.bag" if ros == 1 else name)


N_BAG = 6
MISSING_DEPTH = 3  # frame whose depth message was dropped


def write_rgbd_bag(path: Path, ros: int, *, color="/camera/color/image_raw",
                   depth_topic: str | None = "/camera/aligned_depth_to_color/image_raw",
                   info="/camera/color/camera_info", distractors=True) -> None:
    bag = BagWriter(path, ros)
    for i in range(N_BAG):
        stamp = T0_NS + i * PERIOD_NS
        if i == 0 and info:
            bag.info(info, stamp - 1000)
        if distractors and i == 0:
            bag.info("/camera/depth/camera_info", stamp - 1000, k=(60, 0, 30, 0, 60, 20, 0, 0, 1))
            bag.string("/diagnostics", stamp)
        rgb = cv2.cvtColor(colour(i), cv2.COLOR_BGR2RGB)
        # Depth stamped 2 ms after colour, and 0.1 ms more each frame (the depth sensor's clock
        # running slow); logged before colour on even frames.
        d_stamp = stamp + round(1e9 * depth_delay(i))
        d_log = stamp + (1_000_000 if i % 2 else -1_000_000)
        if depth_topic and i != MISSING_DEPTH and i % 2 == 0:
            bag.image(depth_topic, d_stamp, depth(i), "16UC1", log_ns=d_log)
        bag.image(color, stamp, rgb, "rgb8", log_ns=stamp + 500_000, pad=4 * (i == 1))
        if depth_topic and i != MISSING_DEPTH and i % 2 == 1:
            bag.image(depth_topic, d_stamp, depth(i), "16UC1", log_ns=d_log)
        if distractors:
            bag.image("/camera/depth/image_rect_raw", stamp, depth(50 + i), "16UC1")
            bag.image("/camera/infra1/image_rect_raw", stamp, colour(i)[:, :, 0], "mono8")
    bag.close()


def depth_delay(i: int) -> float:
    """When write_rgbd_bag's depth frame ``i`` is stamped after its colour frame (s)."""
    return 0.002 + 1e-4 * i


def check_rgbd_frames(frames: list[Frame], with_depth: bool = True) -> None:
    assert [f.index for f in frames] == list(range(N_BAG))
    np.testing.assert_allclose(
        [f.timestamp for f in frames], np.arange(N_BAG) * PERIOD_NS / 1e9, atol=1e-9
    )
    for i, f in enumerate(frames):
        np.testing.assert_array_equal(f.bgr, colour(i))  # rgb8 -> BGR, row padding removed
        if with_depth and i != MISSING_DEPTH:
            np.testing.assert_array_equal(f.depth, depth(i))
            assert f.depth_delay == pytest.approx(depth_delay(i), abs=1e-9)  # each its own
        else:
            assert f.depth is None and f.depth_delay is None


@needs_rosbags
@pytest.mark.parametrize("ros", [1, 2])
def test_bag_auto_detects_topics_and_camera(tmp_path, ros):
    path = bag_path(tmp_path, ros)
    write_rgbd_bag(path, ros)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # registered depth exists: nothing to warn about
        rec = open_recording(path)
    assert rec.color_topic == "/camera/color/image_raw"
    assert rec.depth_topic == "/camera/aligned_depth_to_color/image_raw"
    assert rec.info_topic == "/camera/color/camera_info"
    assert len(rec) == N_BAG and rec.has_depth
    assert rec.time_origin == pytest.approx(T0_NS / 1e9, abs=1e-6)
    # the depth's delays are the frames' own (check_rgbd_frames), not the camera's
    expected = Camera(fx=80.0, fy=81.0, cx=31.7, cy=23.2, width=W, height=H, depth_scale=0.001,
                      dist=D)
    assert rec.camera == expected
    with rec:
        check_rgbd_frames(list(rec))
    assert rec.sync_tolerance == pytest.approx(PERIOD_NS / 2e9)
    frames = iter(rec)
    next(frames)
    rec.close()  # ends the iteration in progress and closes the bag
    with pytest.raises(StopIteration):
        next(frames)


@needs_rosbags
@pytest.mark.parametrize("ros", [1, 2])
def test_bag_with_overridden_topics(tmp_path, ros):
    path = bag_path(tmp_path, ros)
    write_rgbd_bag(path, ros, color="/sensor/a", depth_topic="/sensor/b", info="/sensor/calib",
                   distractors=False)
    # Names that say nothing: auto-detection cannot tell colour from depth, and says so.
    with pytest.raises(InputError) as err:
        open_recording(path)
    one_line(err, "/sensor/a", "/sensor/b", "color_topic=")
    rec = open_recording(path, color_topic="/sensor/a", depth_topic="/sensor/b",
                         info_topic="/sensor/calib")
    assert rec.camera.fx == 80.0 and rec.camera.dist == D
    check_rgbd_frames(list(rec))
    rgb_only = open_recording(path, color_topic="/sensor/a", depth_topic="none",
                              info_topic="/sensor/calib")
    check_rgbd_frames(list(rgb_only), with_depth=False)
    with pytest.raises(InputError) as err:
        open_recording(path, color_topic="/sensor/nope", info_topic="/sensor/calib")
    one_line(err, "/sensor/nope", "/sensor/a (sensor_msgs/msg/Image)", "/sensor/calib")
    with pytest.raises(InputError) as err:
        open_recording(path, color_topic="/sensor/calib")
    one_line(err, "/sensor/calib", "CameraInfo", "color_topic")


@needs_rosbags
@pytest.mark.parametrize("ros", [1, 2])
def test_bag_rgb_only(tmp_path, ros):
    path = bag_path(tmp_path, ros)
    write_rgbd_bag(path, ros, depth_topic=None, distractors=False)
    rec = open_recording(path)
    assert rec.depth_topic is None and not rec.has_depth
    check_rgbd_frames(list(rec), with_depth=False)


@needs_rosbags
def test_bag_ignores_unregistered_depth_with_a_warning(tmp_path):
    path = bag_path(tmp_path, 1)
    write_rgbd_bag(path, 1, depth_topic=None)  # distractors include /camera/depth/image_rect_raw
    with pytest.warns(UserWarning, match="/camera/depth/image_rect_raw"):
        rec = open_recording(path)
    assert rec.depth_topic is None
    check_rgbd_frames(list(rec), with_depth=False)


@needs_rosbags
def test_bag_missing_topics_list_what_is_there(tmp_path):
    path = bag_path(tmp_path, 2)
    bag = BagWriter(path, 2)
    bag.string("/chatter", T0_NS)
    bag.image("/camera/depth/image_raw", T0_NS, depth(0), "16UC1")
    bag.close()
    with pytest.raises(InputError) as err:
        open_recording(path)
    one_line(err, str(path), "no colour image topic", "/chatter (std_msgs/msg/String)",
             "/camera/depth/image_raw (sensor_msgs/msg/Image)")

    path = bag_path(tmp_path, 1, "noinfo")
    write_rgbd_bag(path, 1, info=None, distractors=False)
    with pytest.raises(ConfigError) as err:
        open_recording(path)
    one_line(err, "noinfo.bag", "CameraInfo", "/camera/color/image_raw", "--camera")
    rec = open_recording(path, camera=CAMERA)  # a camera file replaces camera_info
    assert rec.camera == CAMERA and rec.info_topic is None
    check_rgbd_frames(list(rec))
    stated = replace(CAMERA, depth_delay=-0.004)  # the tracker takes it over the frames' own
    assert open_recording(path, camera=stated).camera == stated


@needs_rosbags
def test_bag_32fc1_depth_and_compressed_images(tmp_path):
    path = bag_path(tmp_path, 1)
    bag = BagWriter(path, 1)
    metres = depth(0).astype(np.float32) * np.float32(0.001)
    metres[0, :4] = (np.nan, np.inf, -1.0, 70.0)  # no reading, no reading, invalid, too far
    bag.info("/camera/rgb/camera_info", T0_NS)
    bag.image("/camera/depth_registered/image", T0_NS, metres, "32FC1")
    bag.image("/camera/rgb/image_color", T0_NS, cv2.cvtColor(colour(0), cv2.COLOR_BGR2RGB), "rgb8")
    jpeg = cv2.imencode(".jpg", video_frame(1), [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
    png = cv2.imencode(".png", depth(1))[1].tobytes()
    t1 = T0_NS + PERIOD_NS
    bag.compressed("/cam2/color/image_raw/compressed", t1, jpeg, "rgb8; jpeg compressed bgr8")
    bag.compressed("/cam2/aligned_depth_to_color/image_raw/compressedDepth", t1,
                   b"\x00" * 12 + png, "16UC1; compressedDepth png")
    bag.info("/cam2/color/camera_info", t1)
    bag.close()

    (frame,) = list(open_recording(path))  # OpenNI-style names
    expected = np.rint(depth(0) * np.float32(0.001) / 0.001).astype(np.uint16)
    expected[0, :4] = 0
    np.testing.assert_array_equal(frame.bgr, colour(0))
    np.testing.assert_array_equal(frame.depth, expected)

    rec = open_recording(path, color_topic="/cam2/color/image_raw/compressed")
    assert rec.depth_topic == "/cam2/aligned_depth_to_color/image_raw/compressedDepth"
    assert rec.info_topic == "/cam2/color/camera_info"
    (frame,) = list(rec)
    assert np.abs(frame.bgr.astype(int) - video_frame(1)).mean() < 3
    np.testing.assert_array_equal(frame.depth, depth(1))


def test_image_message_decoding():
    rgb = colour(3)[:, :, ::-1].copy()

    def msg(array, encoding, bigendian=0, pad=0):
        h, w = array.shape[:2]
        rows = array.reshape(h, -1).view(np.uint8)
        rows = np.hstack([rows, np.zeros((h, pad), np.uint8)])
        return RosMessage(0, IMAGE, SimpleNamespace(
            encoding=encoding, height=h, width=w, step=rows.shape[1], is_bigendian=bigendian,
            data=rows.reshape(-1)))

    dc, dd = decode_colour, decode_depth
    np.testing.assert_array_equal(dc(msg(rgb, "rgb8", pad=3), "t"), colour(3))
    np.testing.assert_array_equal(dc(msg(colour(3), "bgr8"), "t"), colour(3))
    bgra = cv2.cvtColor(colour(3), cv2.COLOR_BGR2BGRA)
    np.testing.assert_array_equal(dc(msg(bgra, "bgra8"), "t"), colour(3))
    grey = dc(msg(colour(3)[:, :, 1], "mono8"), "t")
    np.testing.assert_array_equal(grey[:, :, 2], colour(3)[:, :, 1])
    bayer = np.zeros((8, 8), np.uint8)  # a flat (R, G, B) = (200, 100, 50) scene seen as RGGB
    bayer[0::2, 0::2], bayer[0::2, 1::2], bayer[1::2, 0::2], bayer[1::2, 1::2] = 200, 100, 100, 50
    np.testing.assert_array_equal(dc(msg(bayer, "bayer_rggb8"), "t")[4, 4], (50, 100, 200))
    big = depth(4).astype(">u2")
    np.testing.assert_array_equal(dd(msg(big, "16UC1", bigendian=1), 0.001, "t"), depth(4))
    # 16UC1 is millimetres: a camera with 0.1 mm units gets ten times the numbers.
    np.testing.assert_array_equal(dd(msg(np.array([[5, 0]], np.uint16), "16UC1"), 1e-4, "t"),
                                  [[50, 0]])
    with pytest.raises(InputError) as err:
        dc(msg(depth(4), "16UC1"), "bag topic /x")
    one_line(err, "bag topic /x", "16UC1", "color_topic")
    with pytest.raises(InputError) as err:
        dd(msg(colour(4), "rgb8"), 0.001, "t")
    one_line(err, "rgb8", "16UC1", "depth_topic")
    with pytest.raises(InputError) as err:
        dc(msg(colour(4), "yuv422"), "t")
    one_line(err, "yuv422", "not supported")


@needs_rosbags
def test_bag_damaged_or_missing_rosbags(tmp_path, monkeypatch):
    (tmp_path / "junk.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\x01" * 100)
    with pytest.raises(InputError) as err:
        open_recording(tmp_path / "junk.bag")
    one_line(err, "junk.bag", "cannot be read")
    path = bag_path(tmp_path, 1)
    write_rgbd_bag(path, 1, distractors=False)
    monkeypatch.setitem(sys.modules, "rosbags", None)
    with pytest.raises(InputError) as err:
        open_recording(path)
    one_line(err, "wristtrack[ros]")


@needs_rosbags
def test_ros2_bag_by_metadata_or_storage_file(tmp_path):
    path = bag_path(tmp_path, 2)
    write_rgbd_bag(path, 2, distractors=False)
    storage = next(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
    for source in (path / "metadata.yaml", storage):
        assert len(list(open_recording(source))) == N_BAG
    shutil.rmtree(path)


# ------------------------------------------------------------------------------ live camera


class FakeCapture:
    """Stands in for cv2.VideoCapture(index): a few frames, then the stream ends."""

    instances: list[FakeCapture] = []
    frames = 5
    size = (W, H)
    opened = True

    def __init__(self, device):
        self.device, self.calls, self.released, self.settings = device, 0, False, {}
        FakeCapture.instances.append(self)

    def isOpened(self):  # noqa: N802 - OpenCV's name
        return self.opened

    def set(self, prop, value):
        self.settings[prop] = value
        return True

    def grab(self):
        self.calls += 1
        return self.calls <= self.frames

    def retrieve(self):
        w, h = self.size
        return True, np.full((h, w, 3), self.calls, np.uint8)

    def release(self):
        self.released = True


@pytest.fixture
def fake_camera(monkeypatch):
    FakeCapture.instances = []
    monkeypatch.setattr(cv2, "VideoCapture", FakeCapture)
    clock = iter([100.0, 100.04, 100.07, 100.11, 100.2, 100.3, 100.4, 100.5])
    monkeypatch.setattr(live_module, "time", SimpleNamespace(monotonic=lambda: next(clock)))
    monkeypatch.setattr(FakeCapture, "frames", 5)
    monkeypatch.setattr(FakeCapture, "size", (W, H))
    monkeypatch.setattr(FakeCapture, "opened", True)
    return FakeCapture


def test_live_capture_frame_by_frame(fake_camera):
    with open_recording("live:0", camera=CAMERA) as rec:
        cap = fake_camera.instances[0]
        assert cap.device == 0
        assert cap.settings == {cv2.CAP_PROP_FRAME_WIDTH: W, cv2.CAP_PROP_FRAME_HEIGHT: H}
        with pytest.raises(TypeError):
            len(rec)
        frames = iter(rec)
        first = next(frames)
        assert cap.calls == 1  # one grab per frame asked for, not read ahead
        rest = list(frames)
    assert cap.released
    got = [first, *rest]
    assert [f.index for f in got] == [0, 1, 2, 3, 4]
    np.testing.assert_allclose([f.timestamp for f in got], [0, 0.04, 0.07, 0.11, 0.2], atol=1e-9)
    assert all(f.depth is None and int(f.bgr[0, 0, 0]) == f.index + 1 for f in got)


def test_live_options_and_errors(fake_camera):
    rec = open_recording(None, camera=CAMERA, live=2, max_frames=2)
    assert fake_camera.instances[-1].device == 2
    assert len(list(rec)) == 2
    with pytest.raises(ConfigError) as err:
        open_recording("live:0")
    one_line(err, "live:0", "--camera")
    fake_camera.size = (W * 2, H * 2)
    with pytest.raises(InputError) as err:
        list(open_recording("live:1", camera=CAMERA))
    one_line(err, "live:1", "128x96", "64x48")
    fake_camera.size = (W, H)
    fake_camera.frames = 0
    with pytest.raises(InputError) as err:
        list(open_recording("live:1", camera=CAMERA))
    one_line(err, "live:1", "no frames")
    fake_camera.opened = False
    with pytest.raises(InputError) as err:
        open_recording("live:3", camera=CAMERA)
    one_line(err, "live:3", "cannot be opened")
    assert fake_camera.instances[-1].released

