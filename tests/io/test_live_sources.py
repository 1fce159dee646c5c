"""Live sources without hardware: the replay clock, SOURCE parsing, RealSense recordings written
by the SDK itself (a software device recorded by its recorder), OpenNI2 through its own dummy
driver, and the one-line errors when a library or a device is missing."""

import gc
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.errors import ConfigError, InputError
from wristtrack.geometry import rotation_distance
from wristtrack.io.folder import FolderRecording
from wristtrack.io.live.opencv import LiveRecording
from wristtrack.io.live.replay import ReplayRecording
from wristtrack.io.live.sources import open_live
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses, rows_to_poses


@pytest.fixture(scope="module")
def short(rendered):
    return rendered("reach", n_frames=12)


# ------------------------------------------------------------------------------------- replay


class FakeClock:
    def __init__(self, decode_s=0.0):
        self.now, self.sleeps, self.decode_s = 100.0, [], decode_s

    def __call__(self):
        self.now += self.decode_s  # each reading of the clock follows a decoded frame
        return self.now

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.now += seconds


def test_replay_hands_each_frame_over_at_its_timestamp(short):
    clock = FakeClock()
    delivered = []
    with ReplayRecording(short, clock=clock, sleep=clock.sleep, speed=2.0) as rec:
        for frame in rec.frames():
            delivered.append((frame.index, frame.timestamp, clock.now))
    timestamps = [f.timestamp for f in FolderRecording(short).frames()]
    assert [d[0] for d in delivered] == list(range(12))
    assert [d[1] for d in delivered] == timestamps  # the recording's own timestamps
    t0 = delivered[0][2]
    for _, t, at in delivered:  # at speed 2, frame t is due at t0 + t / 2
        assert at == pytest.approx(t0 + t / 2, abs=1e-9)
    assert rec.late_frames == 0


def test_replay_counts_frames_it_could_not_decode_in_time(short):
    clock = FakeClock(decode_s=0.05)  # 50 ms per frame: slower than 30 fps
    with ReplayRecording(short, clock=clock, sleep=clock.sleep) as rec:
        assert len(list(rec.frames())) == 12
    assert clock.sleeps == [] and rec.late_frames == 11
    assert rec.max_late_ms == pytest.approx((0.05 * 11 - 11 / 30) * 1e3, rel=1e-6)


def test_source_strings(short):
    assert isinstance(open_live(f"replay:{short}"), ReplayRecording)
    with pytest.raises(InputError, match="unknown source; give realsense"):
        open_live("kinect")
    with pytest.raises(InputError, match="replay: needs a recording folder"):
        open_live("replay:")
    with pytest.raises(ConfigError, match="needs its intrinsics: pass --camera"):
        open_live("0")  # an OpenCV camera index: parsed as one
    with pytest.raises(InputError, match="cannot be opened"):
        LiveRecording("/dev/no-such-video", Camera(500, 500, 320, 240, 640, 480))


# ---------------------------------------------------------------------------------- RealSense


def _rs():
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        pytest.skip(f"pyrealsense2 cannot be imported ({exc}): pip install "
                    "'wristtrack[realsense]' (and apt-get install libusb-1.0-0)")
    return rs


def write_realsense_recording(path, folder, n=12, dist=None, depth_scale=None, lost_depth=(),
                              baseline=0.0, depth_lag=lambda i: 0.0, domain="hardware_clock",
                              exposure=None, name="wristtrack test software device"):
    """Record the first ``n`` frames of a recording folder through the SDK: a software device
    with a colour and a depth sensor (the folder's intrinsics, identity extrinsics, as
    registered depth is, or the depth sensor ``baseline`` metres beside the colour one, so
    the reader aligns them), recorded by the SDK's own recorder; the depth frames
    ``lost_depth`` never reach it (as a USB transfer a device drops). Depth frame i is stamped
    ``depth_lag(i)`` s after its colour frame, both in the timestamp ``domain``; with
    ``exposure(i)`` (colour, depth; s) the frames also carry the middle of their exposure
    (SENSOR_TIMESTAMP metadata, us), which ends as their transfer starts (FRAME_TIMESTAMP, the
    stamp). ``name``: the device's, as the recording reports it. Returns the folder's camera."""
    rs = _rs()
    rec = FolderRecording(folder)
    cam = rec.camera
    scale = depth_scale or cam.depth_scale
    dev = rs.software_device()
    depth_sensor, color_sensor = dev.add_sensor("Depth"), dev.add_sensor("Color")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy = cam.width, cam.height, cam.fx, cam.fy
    intr.ppx, intr.ppy = cam.cx, cam.cy
    intr.model = rs.distortion.brown_conrady
    intr.coeffs = list(dist or (0.0,) * 5)
    profiles = []
    for sensor, kind, fmt, bpp, uid in ((depth_sensor, rs.stream.depth, rs.format.z16, 2, 0),
                                        (color_sensor, rs.stream.color, rs.format.bgr8, 3, 1)):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = kind, 0, uid, cam.width, cam.height
        vs.fps, vs.bpp, vs.fmt, vs.intrinsics = 30, bpp, fmt, intr
        profiles.append(sensor.add_video_stream(vs).as_video_stream_profile())
    depth_profile, color_profile = profiles
    extrinsics = rs.extrinsics()
    extrinsics.rotation, extrinsics.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [baseline, 0, 0]
    depth_profile.register_extrinsics_to(color_profile, extrinsics)
    depth_sensor.add_read_only_option(rs.option.depth_units, scale)
    dev.create_matcher(rs.matchers.dlr_c)
    dev.register_info(rs.camera_info.name, name)
    recorder = rs.recorder(str(path), dev)
    depth_sensor.open(depth_profile)
    color_sensor.open(color_profile)
    depth_sensor.start(lambda f: None)
    color_sensor.start(lambda f: None)
    start = time.perf_counter()
    for i, frame in zip(range(n), rec.frames(), strict=False):
        # The recorder keeps the time each frame reached it and playback honours it: inject
        # at the camera's pace, as a real device would deliver them.
        time.sleep(max(start + frame.timestamp - time.perf_counter(), 0.0))
        for sensor, profile, image, bpp in ((depth_sensor, depth_profile, frame.depth, 2),
                                            (color_sensor, color_profile, frame.bgr, 3)):
            if bpp == 2 and i in lost_depth:
                continue
            sw = rs.software_video_frame()
            sw.pixels, sw.bpp, sw.stride = np.ascontiguousarray(image), bpp, cam.width * bpp
            lag = depth_lag(i) if bpp == 2 else 0.0
            sw.timestamp, sw.frame_number, sw.profile = (frame.timestamp + lag) * 1e3, i, profile
            sw.domain = getattr(rs.timestamp_domain, domain)
            if bpp == 2:
                sw.depth_units = scale
            if exposure is not None:
                sent = frame.timestamp + lag
                middle = sent - exposure(i)[bpp == 2] / 2
                sensor.set_metadata(rs.frame_metadata_value.sensor_timestamp, round(middle * 1e6))
                sensor.set_metadata(rs.frame_metadata_value.frame_timestamp, round(sent * 1e6))
            sensor.on_video_frame(sw)
    for sensor in (depth_sensor, color_sensor):
        sensor.stop()
        sensor.close()
    # The file is complete only once the recorder and the device are gone (pybind objects
    # held in cycles by the callbacks: collect them now, before anyone reads the file).
    del recorder, dev, depth_sensor, color_sensor, sensor, profiles, depth_profile, color_profile
    gc.collect()
    return cam


@pytest.fixture(scope="module")
def reach(rendered):
    return rendered("reach")  # shared with the pipeline tests


@pytest.fixture(scope="module")
def realsense_file(reach, tmp_path_factory):
    rs = _rs()
    suffix = ".db3"  # what this SDK writes; older ones (<= 2.56, RealSense Viewer) write .bag
    try:
        rs.recorder(str(tmp_path_factory.mktemp("probe") / "x.bag"), rs.software_device())
        suffix = ".bag"
    except RuntimeError:
        pass
    path = tmp_path_factory.mktemp("realsense") / f"session{suffix}"
    write_realsense_recording(path, reach)
    return path


def test_realsense_recording_reads_back_frames_intrinsics_and_depth_scale(reach, realsense_file):
    original = FolderRecording(reach)
    with open_live(f"realsense:{realsense_file}") as rec:
        assert rec.camera.depth_scale == pytest.approx(original.camera.depth_scale, rel=1e-6)
        for field in ("fx", "fy", "cx", "cy"):  # the SDK stores them as float32
            assert getattr(rec.camera, field) == pytest.approx(getattr(original.camera, field),
                                                               abs=1e-4)
        assert (rec.camera.width, rec.camera.height) == (original.camera.width,
                                                         original.camera.height)
        assert rec.camera.dist is None and rec.has_depth
        frames = list(rec.frames())
    truth = [f for _, f in zip(range(12), original.frames(), strict=False)]
    assert len(frames) == len(truth)
    for got, want in zip(frames, truth, strict=True):
        assert got.timestamp == pytest.approx(want.timestamp, abs=1e-6)
        np.testing.assert_array_equal(got.bgr, want.bgr)
        # aligned to colour by the SDK; with identical intrinsics and no offset it is the same
        np.testing.assert_array_equal(got.depth, want.depth)


BAG = Path(__file__).parent / "data" / "realsense_sdk256.bag"  # see data/make_realsense_bag.py


def test_realsense_viewer_bag_written_by_an_older_sdk():
    """A ROS 1 .bag, as RealSense Viewer and SDK <= 2.56 write them, written by SDK 2.56's own
    recorder from a software device whose every pixel is known (make_realsense_bag.py)."""
    _rs()
    # As fast as it is read: at the recording's own pace a loaded machine can make the SDK's
    # syncer pair a colour frame with a later depth frame (seen: depth two frames ahead).
    with open_live(f"realsense:{BAG}", real_time=False) as rec:
        cam = rec.camera
        frames = list(rec.frames())
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (50.5, 51.25, 31.5, 23.75,
                                                                     64, 48)
    np.testing.assert_allclose(cam.dist, (0.1, -0.2, 0.001, 0.002, 0.01), atol=1e-7)
    assert cam.depth_scale == pytest.approx(1e-4, rel=1e-6)
    assert len(frames) >= 6  # of 8 (the recorder misses the first)
    with open_live(str(BAG)) as again:  # a bare recording path: the same source
        assert type(again) is type(rec) and again.camera == cam
    r, c = np.mgrid[0:48, 0:64]
    first = int(frames[0].bgr[0, 0, 0])
    for k, frame in enumerate(frames):
        i = first + k  # consecutive: none lost in playback
        np.testing.assert_array_equal(frame.bgr[..., 0], i)
        np.testing.assert_array_equal(frame.bgr[..., 1], r + 10)
        np.testing.assert_array_equal(frame.bgr[..., 2], c)
        np.testing.assert_array_equal(frame.depth, 1000 + 10 * i + r + c)
        assert frame.timestamp == pytest.approx(k / 30, abs=1e-6)


def test_realsense_distortion_is_read_from_the_recording(short, tmp_path):
    dist = (0.05, -0.1, 0.001, -0.002, 0.01)
    write_realsense_recording(tmp_path / "d.db3", short, n=2, dist=dist, depth_scale=0.0001)
    with open_live(f"realsense:{tmp_path / 'd.db3'}") as rec:
        np.testing.assert_allclose(rec.camera.dist, dist, atol=1e-7)
        assert rec.camera.depth_scale == pytest.approx(0.0001, rel=1e-6)


@pytest.mark.parametrize("baseline", [0.0, 0.025])
def test_a_colour_frame_whose_depth_was_lost_comes_without_depth(reach, tmp_path, baseline):
    """The SDK's syncer hands a colour frame whose depth frame was lost the last depth frame it
    had (frames 4 and 5 both got frame 3's): a depth of another moment, which would put the
    markers where the hand was then. Such a frame comes without depth; the others with their
    own (io.base.pairing_tolerance). Registered depth as it is, or a sensor 25 mm beside the
    colour one, whose depth the SDK aligns (rs.align) before it is read."""
    path = tmp_path / "lost.db3"
    lost = (4, 5, 8)
    write_realsense_recording(path, reach, lost_depth=lost, baseline=baseline)
    want = [f for _, f in zip(range(12), FolderRecording(reach).frames(), strict=False)]
    with open_recording(path) as rec:
        got = list(rec.frames())
    assert [f.index for f in got] == list(range(12))
    for frame, truth in zip(got, want, strict=True):
        np.testing.assert_array_equal(frame.bgr, truth.bgr)
        if frame.index in lost:
            assert frame.depth is None, f"frame {frame.index} took another frame's depth"
        elif not baseline:
            np.testing.assert_array_equal(frame.depth, truth.depth)
        else:  # re-projected into the colour camera: the hand's depth moved by the parallax
            assert not np.array_equal(frame.depth, truth.depth)  # rs.align ran
            both = (frame.depth > 0) & (truth.depth > 0)
            assert both.mean() > 0.8
            diff = np.abs(frame.depth[both].astype(float) - truth.depth[both])
            assert np.median(diff) * rec.camera.depth_scale < 0.002, np.median(diff)


def test_track_live_plays_a_realsense_recording_as_a_camera(reach, realsense_file,
                                                           cut_recording, tmp_path):
    """Played at its own pace, as a camera: on a loaded machine frames may be dropped (by the
    SDK's real-time playback or the newest-frame rule), and the frames after a drop are filtered
    with a longer step. So the live rows are compared with an offline run over exactly the
    frames the live run took (the folder cut to them, without hand.json, as in the SDK file),
    however many were dropped. They agree within the filter's noise, not digit for digit: the
    cut folder numbers its frames afresh, so its colours adapt on other frames (every 10th,
    pipeline/colours.py)."""
    assert main(["track", "--live", f"realsense:{realsense_file}", "--out",
                 str(tmp_path / "live"), "--no-report"]) == 0
    live = read_poses(tmp_path / "live" / "poses.csv")
    log = json.loads((tmp_path / "live" / "live.json").read_text())
    assert log["frames"]["total"] == len(live["frame"])
    # each live row is a frame of the recording, in order; a dropped one was never tracked
    # (the SDK's real-time playback may drop the frames behind the slow first one)
    taken = live["status"] != "dropped"
    assert taken.sum() >= 6 and (live["status"] == "tracking").sum() >= taken.sum() - 3
    recorded = live["timestamp"][taken]
    lines = (reach / "frames.csv").read_text().splitlines()
    stamps = np.array([float(line.split(",")[0]) for line in lines[1:]])
    k = np.searchsorted(stamps, recorded - 1e-6)
    np.testing.assert_allclose(stamps[k], recorded, atol=1e-6)
    assert (np.diff(k) > 0).all()
    # Under load the SDK's real-time syncer can pair a colour frame with a depth frame of
    # another moment; the source then gives it no depth, and so does the offline run.
    no_depth = k[np.isin(live["frame"][taken], log["frames_without_depth"])]
    took = cut_recording(reach, k, tmp_path / "took", hand=False, without_depth=no_depth)
    assert main(["track", str(took), "--out", str(tmp_path / "off"), "--no-report",
                 "--no-progress"]) == 0
    off = read_poses(tmp_path / "off" / "poses.csv")
    live = {name: column[taken] for name, column in live.items()}
    np.testing.assert_array_equal(live["status"], off["status"])
    tracked = live["status"] == "tracking"
    R_live, t_live = rows_to_poses(live)
    R_off, t_off = rows_to_poses(off)
    np.testing.assert_allclose(t_live[tracked], t_off[tracked], atol=1e-3)
    assert np.degrees(rotation_distance(R_live[tracked], R_off[tracked])).max() <= 0.5


def test_track_reads_a_realsense_recording_offline_frame_by_frame(reach, realsense_file,
                                                                   cut_recording, tmp_path):
    """Given as a file (not --live), an SDK recording is read in full, as fast as the tracker
    takes it: the same poses as the recording folder it was made from, frame by frame."""
    with open_recording(realsense_file) as rec:
        assert rec.file == realsense_file
        tail = list(rec.frames(5))  # a resumed run starts part-way through
    assert [f.index for f in tail] == list(range(5, 12))
    want = [f for _, f in zip(range(12), FolderRecording(reach).frames(), strict=False)][5:]
    for got, frame in zip(tail, want, strict=True):
        np.testing.assert_array_equal(got.bgr, frame.bgr)
    assert main(["track", str(realsense_file), "--out", str(tmp_path / "bag"), "--no-report",
                 "--no-progress"]) == 0
    # the folder cut to the frames that were recorded (and, as in the SDK file, without hand.json)
    first = cut_recording(reach, range(12), tmp_path / "first12", hand=False)
    assert main(["track", str(first), "--out", str(tmp_path / "off"), "--no-report",
                 "--no-progress"]) == 0
    bag = read_poses(tmp_path / "bag" / "poses.csv")
    off = read_poses(tmp_path / "off" / "poses.csv")
    assert len(bag["frame"]) == len(off["frame"]) == 12
    np.testing.assert_array_equal(bag["status"], off["status"])
    # Timestamps pass through the SDK as float milliseconds (~1e-7 s), the intrinsics and
    # depth scale as float32 (relative 6e-8); nothing else differs.
    np.testing.assert_allclose(bag["timestamp"], off["timestamp"], atol=1e-6)
    for col in ("tx", "ty", "tz"):
        np.testing.assert_allclose(bag[col], off[col], atol=1e-6)
    for col in ("deviation_deg", "flexion_deg", "pronation_deg"):
        np.testing.assert_allclose(bag[col], off[col], atol=1e-4)


@pytest.mark.parametrize("baseline", [0.0, 0.025])
def test_realsense_depth_stamps_tell_each_frames_depth_delay(short, tmp_path, baseline):
    """The depth sensor's stamps 6 ms after the colour's, slipping 0.5 ms a frame (two clocks):
    each frame carries its own delay. Where the frames report the middle of their exposure
    (the colour exposed 30 ms, the depth 8 ms, each stamped as its transfer starts) that is
    the moment captured: the colour's middle 15 ms before its stamp, the depth's 4 ms, so the
    depth came 11 ms later after it than the stamps say; and under the colour's auto-exposure
    (10 ms, growing 4 ms a frame) each frame's time is its own middle. Stamps of the host's
    arrival (system time, as without the SDK's kernel patches) say nothing of the capture: no
    delay. Registered depth, or depth the reader aligns (rs.align keeps its metadata)."""
    lag = lambda i: 0.006 + 0.0005 * i  # noqa: E731
    stamps = [f.timestamp for _, f in zip(range(6), FolderRecording(short).frames(),
                                         strict=False)]
    auto = lambda i: (0.010 + 0.004 * i, 0.008)  # noqa: E731  (the colour's auto-exposure)
    for name, exposure, later, lead in (
        ("stamps", None, lambda i: 0.0, lambda i: 0.0),
        ("fixed", lambda i: (0.030, 0.008), lambda i: 0.011, lambda i: 0.0),
        ("auto", auto, lambda i: auto(i)[0] / 2 - 0.004, lambda i: 0.002 * i),
    ):
        path = tmp_path / f"{name}.db3"
        write_realsense_recording(path, short, n=6, depth_lag=lag, exposure=exposure,
                                  baseline=baseline)
        with open_recording(path) as rec:
            frames = list(rec.frames())
        assert [f.index for f in frames] == list(range(6))
        assert all(f.depth is not None for f in frames)
        np.testing.assert_allclose([f.depth_delay for f in frames],  # stamps pass through
                                   [lag(i) + later(i) for i in range(6)], atol=1e-6)  # as ms
        # a frame's time is its colour's middle of exposure (from the first frame's)
        np.testing.assert_allclose([f.timestamp for f in frames],
                                   [stamps[i] - lead(i) for i in range(6)], atol=1e-6)
    write_realsense_recording(tmp_path / "host.db3", short, n=4, depth_lag=lag,
                              domain="system_time")
    with open_recording(tmp_path / "host.db3") as rec:
        frames = list(rec.frames())
    assert len(frames) == 4 and all(f.depth is not None and f.depth_delay is None
                                    for f in frames)


def test_track_reads_each_depth_at_its_stamped_delay(reach, cut_recording, tmp_path):
    """A recording whose depth is stamped 8 ms after the colour is tracked as the same frames
    with camera.json stating that delay (the tracker's lag model applied to each frame), not
    as they are without it; summary.json and the report say where the delay came from."""
    write_realsense_recording(tmp_path / "lag.db3", reach, depth_lag=lambda i: 0.008)
    assert main(["track", str(tmp_path / "lag.db3"), "--out", str(tmp_path / "bag"),
                 "--no-progress"]) == 0
    folders = {}
    for name, delay in (("stated", 0.008), ("none", None)):
        folders[name] = cut_recording(reach, range(12), tmp_path / name, hand=False)
        camera = json.loads((folders[name] / "camera.json").read_text())
        camera.pop("depth_delay_s", None)
        if delay is not None:
            camera["depth_delay_s"] = delay
        (folders[name] / "camera.json").write_text(json.dumps(camera))
        assert main(["track", str(folders[name]), "--out", str(tmp_path / f"off-{name}"),
                     "--no-report", "--no-progress"]) == 0
    bag = read_poses(tmp_path / "bag" / "poses.csv")
    stated = read_poses(tmp_path / "off-stated" / "poses.csv")
    none = read_poses(tmp_path / "off-none" / "poses.csv")
    np.testing.assert_array_equal(bag["status"], stated["status"])
    tracked = bag["status"] == "tracking"
    assert tracked.sum() >= 9
    for col in ("tx", "ty", "tz"):  # as the recording-folder test, to the SDK's float stamps
        np.testing.assert_allclose(bag[col], stated[col], atol=1e-6)
    moved = max(np.nanmax(np.abs(bag[c] - none[c])) for c in ("tx", "ty", "tz"))
    assert moved > 1e-5, moved  # the delay changed the poses
    summary = json.loads((tmp_path / "bag" / "summary.json").read_text())
    timing = summary["depth_timing"]
    assert timing["from"] == "frame stamps" and timing["frames"] == 12
    assert timing["delay_ms"] == pytest.approx(8.0, abs=1e-3)
    assert timing["min_ms"] == pytest.approx(8.0, abs=1e-3)
    off = json.loads((tmp_path / "off-stated" / "summary.json").read_text())["depth_timing"]
    assert off == {"from": "camera.json", "delay_ms": 8.0}
    report = (tmp_path / "bag" / "report.html").read_text(encoding="utf-8")
    assert ("captured 8.0 ms after its colour frame on average (8.0 to 8.0 ms, from the "
            "camera&#x27;s stamps of 12 frames)") in report


def test_a_d435_whose_readout_is_not_stated_is_warned_of(short, tmp_path):
    """A D435's colour sensor is a rolling shutter: without readout_s the run says so
    (summary.json's warnings, which the report and stderr repeat); a camera.json stating it
    silences that, and a D455 (a global shutter) has nothing to say."""
    write_realsense_recording(tmp_path / "d435.db3", short, n=3, name="Intel RealSense D435")
    assert main(["track", str(tmp_path / "d435.db3"), "--out", str(tmp_path / "unsaid"),
                 "--no-report", "--no-progress"]) in (0, 3)  # 3 frames may not initialise
    warned = json.loads((tmp_path / "unsaid" / "summary.json").read_text())["warnings"]
    assert any("Intel RealSense D435's colour sensor is a rolling shutter" in w
               and "readout_s" in w for w in warned), warned
    camera = {**json.loads((short / "camera.json").read_text()), "readout_s": 0.025}
    (tmp_path / "camera.json").write_text(json.dumps(camera))
    assert main(["track", str(tmp_path / "d435.db3"), "--camera", str(tmp_path / "camera.json"),
                 "--out", str(tmp_path / "stated"), "--no-report", "--no-progress"]) in (0, 3)
    stated = json.loads((tmp_path / "stated" / "summary.json").read_text())["warnings"]
    assert not any("rolling shutter" in w for w in stated)
    write_realsense_recording(tmp_path / "d455.db3", short, n=1, name="Intel RealSense D455")
    with open_recording(tmp_path / "d455.db3") as rec:
        assert rec.warnings == []  # a global shutter


def test_a_live_session_records_its_cameras_depth_delay(reach, tmp_path):
    """--record writes a folder, which has one stamp per frame: the median of the frames'
    stamped depth delays goes into its camera.json, so the folder is tracked offline as the
    camera was live. A camera that states its delay keeps it."""
    from wristtrack.io.live.record import LiveRecorder

    lag = lambda i: 0.007 + 0.0002 * (i % 3)  # noqa: E731
    write_realsense_recording(tmp_path / "lag.db3", reach, depth_lag=lag)
    assert main(["track", "--live", f"realsense:{tmp_path / 'lag.db3'}", "--out",
                 str(tmp_path / "live"), "--record", str(tmp_path / "rec"), "--no-report"]) == 0
    assert Camera.load(tmp_path / "rec" / "camera.json").depth_delay == pytest.approx(0.0072)
    live = json.loads((tmp_path / "live" / "live.json").read_text())
    assert live["record"]["depth_delay_s"] == pytest.approx(0.0072)
    timing = json.loads((tmp_path / "live" / "summary.json").read_text())["depth_timing"]
    assert timing["from"] == "frame stamps"
    assert (timing["min_ms"], timing["max_ms"]) == pytest.approx((7.0, 7.4))
    frame = next(iter(FolderRecording(reach).frames()))
    stated = replace(Camera.load(reach / "camera.json"), depth_delay=-0.003)
    with LiveRecorder(tmp_path / "stated", stated) as recorder:
        recorder.put(frame.timestamp, frame.bgr, frame.depth, 0.009)
    assert Camera.load(tmp_path / "stated" / "camera.json").depth_delay == -0.003


def test_realsense_without_a_device_or_library_is_one_line(monkeypatch, tmp_path):
    _rs()
    with pytest.raises(InputError, match="no RealSense camera found"):
        open_live("realsense")
    with pytest.raises(InputError, match="RealSense recording .* not found"):
        open_live(f"realsense:{tmp_path / 'none.bag'}")
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)  # as if it were not installed
    with pytest.raises(ConfigError) as err:
        open_live("realsense")
    assert "pip install 'wristtrack[realsense]'" in str(err.value)


def test_cli_realsense_missing_device_exit_2(capsys, tmp_path):
    _rs()
    assert main(["track", "--live", "realsense:1234", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("wristtrack track: error: no RealSense camera found")
    assert "\n" not in err


# ------------------------------------------------------------------------------------ OpenNI2


def _openni():
    from wristtrack.io.live.openni import load_openni2

    try:
        return load_openni2()
    except ConfigError as exc:
        pytest.skip(f"OpenNI2 is not available here: {exc}")


# OpenNI2 2.2's dummy driver (Debian's libopenni2-0) corrupts the heap when its streams are
# destroyed and crashes in oniShutdown at exit; checked with the bare bindings (read frames,
# stream.close(), then any import segfaults; stop() alone is fine). So it runs in a child
# process that only stops the streams and leaves without the library's shutdown.
DUMMY_CHILD = """
import json, os, sys
from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InitialisationError
from wristtrack.io.live import openni
from wristtrack.io.live.sources import open_live
from wristtrack.pipeline.live.loop import track_live

openni.OpenNIRecording._release = lambda self: [s.stop() for s in self._streams]
out, rec = sys.argv[1], sys.argv[2]
result = {}
try:
    open_live("openni:Dummy")
except ConfigError as exc:
    result["no_camera"] = str(exc)
cam = Camera(fx=290, fy=290, cx=159.5, cy=119.5, width=320, height=240)
with open_live("openni:Dummy", camera=cam) as source:
    result["has_depth"] = source.has_depth
    try:
        track_live(source, out, record=rec, max_seconds=1.0)
    except InitialisationError as exc:
        result["error"] = str(exc)
print(json.dumps(result), flush=True)
os._exit(0)
"""


def test_openni_dummy_driver_streams_registered_depth_and_colour(tmp_path):
    """OpenNI2's own dummy driver: frames through the real library, tracked live (no markers
    on its test picture, so no pose) and recorded with --record."""
    _openni()
    import subprocess

    proc = subprocess.run([sys.executable, "-c", DUMMY_CHILD, str(tmp_path / "run"),
                           str(tmp_path / "rec")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    # this driver reports no field of view: without --camera there are no intrinsics
    assert "no field of view to derive intrinsics" in result["no_camera"]
    assert "--camera" in result["no_camera"]
    assert result["has_depth"] and "could be initialised" in result["error"]
    live = json.loads((tmp_path / "run" / "live.json").read_text())
    assert live["ended_by"] == "time limit" and live["frames"]["total"] >= 10
    frames = list(FolderRecording(tmp_path / "rec").frames())
    assert len(frames) >= live["frames"]["total"]
    # colour frames paired with their depth: the very first may precede the depth stream, and
    # on a loaded machine a colour frame whose depth lags too long goes without (openni._pair)
    paired = [f.depth is not None for f in frames[1:]]
    assert np.mean(paired) >= 0.8, paired
    assert all(f.depth.dtype == np.uint16 for f in frames if f.depth is not None)
    assert frames[0].bgr.shape == (240, 320, 3)
    dt = np.diff([f.timestamp for f in frames])
    np.testing.assert_allclose(dt, 0.033, atol=1e-9)  # the driver's 33 ms frame clock


def test_openni_errors_are_one_line(monkeypatch, tmp_path):
    ni = _openni()
    with pytest.raises(InputError, match="cannot open an OpenNI2 camera: .*no devices found"):
        open_live("openni")
    with pytest.raises(InputError, match="OpenNI recording .*none.oni not found"):
        open_live(f"openni:{tmp_path / 'none.oni'}")
    from wristtrack.io.live import openni as module

    monkeypatch.setattr(ni, "is_initialized", lambda: False)
    monkeypatch.setattr(module, "_library_candidates", lambda: [])
    with pytest.raises(ConfigError, match="libOpenNI2.*apt-get install libopenni2-0"):
        open_live("openni")
    monkeypatch.setitem(sys.modules, "openni", None)
    with pytest.raises(ConfigError, match=r"pip install 'wristtrack\[openni\]'"):
        open_live("openni")



# ------------------------------------------------------------------------------ --record writer


def test_recorder_never_blocks_and_counts_what_the_disk_could_not_take(short, tmp_path):
    import threading

    from wristtrack.io.live.record import LiveRecorder

    frames = [f for _, f in zip(range(5), FolderRecording(short).frames(), strict=False)]
    cam = FolderRecording(short).camera
    recorder = LiveRecorder(tmp_path / "rec", cam, max_pending=2)
    entered, release = threading.Event(), threading.Event()
    write = recorder.writer.write

    def slow_write(*args):  # a disk that stalls on the first frame
        entered.set()
        release.wait(10)
        write(*args)

    recorder.writer.write = slow_write
    recorder.put(frames[0].timestamp, frames[0].bgr, frames[0].depth)
    assert entered.wait(10)
    for f in frames[1:]:  # two wait in the queue, two find it full: put() returns at once
        recorder.put(f.timestamp, f.bgr, f.depth)
    assert recorder.lost == 2
    release.set()
    recorder.close()
    written = list(FolderRecording(tmp_path / "rec").frames())
    assert [f.timestamp for f in written] == [f.timestamp for f in frames[:3]]
    np.testing.assert_array_equal(written[2].depth, frames[2].depth)


def test_recorder_reports_a_write_failure_and_goes_on(short, tmp_path):
    from wristtrack.io.live.record import LiveRecorder

    frames = [f for _, f in zip(range(3), FolderRecording(short).frames(), strict=False)]
    recorder = LiveRecorder(tmp_path / "rec", FolderRecording(short).camera)

    def full_disk(*args):
        raise InputError("could not write rgb/000000.png (No space left on device)")

    recorder.writer.write = full_disk
    for f in frames:
        recorder.put(f.timestamp, f.bgr, f.depth)
    recorder.close()
    assert recorder.error.endswith("(No space left on device)") and recorder.lost == 3


def test_openni_colour_and_depth_frames_are_paired_by_time():
    """The order the dummy driver delivers in (D1 C1 D2 D3 C2 D4 C3 C4 ...), and a lost depth:
    each colour frame gets the depth of its own moment, or none; and how long after the colour
    that depth was stamped (the depth sensor 5 ms behind, slipping 1 ms a frame)."""
    from collections import deque

    from wristtrack.io.live.openni import _pair

    colors, depths, paired = deque(), deque(maxlen=4), []
    arrivals = "D1 C1 D2 D3 C2 D4 C3 C4 C5 D6 C6 D7 C7".split()  # D5 lost
    for item in arrivals:
        kind, k = item[0], int(item[1:])
        t = k / 30 + (0.005 + 0.001 * k if kind == "D" else 0.0)
        (depths if kind == "D" else colors).append((np.full((1, 1), k), t))
        paired += [(int(c[0, 0]), None if d is None else int(d[0, 0]), delay)
                   for c, _, d, delay in _pair(colors, depths, 0.5 / 30, True)]
    assert [p[:2] for p in paired] == [(1, 1), (2, 2), (3, 3), (4, 4), (5, None), (6, 6), (7, 7)]
    delays = [p[2] for p in paired]
    assert delays[4] is None
    np.testing.assert_allclose([d for d in delays if d is not None],
                               [0.005 + 0.001 * k for k in (1, 2, 3, 4, 6, 7)], atol=1e-12)
