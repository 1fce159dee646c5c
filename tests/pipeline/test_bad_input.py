"""Bad input through `wristtrack track`: one clear line, exit code 2, no traceback, nothing already
written damaged; one bad frame inside a recording is reported, marked and skipped.

Each case spoils a copy of a small rendered recording (or writes the bad file) and checks what
the user sees: the exit code, the single stderr line naming the file and the fix, and the
output folder.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.io.folder import PROBE_FRAMES, RecordingWriter
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses

N = 60
BAD = 20  # the frame spoilt inside the recording


@pytest.fixture(scope="module")
def deviation(rendered):
    return rendered("deviation", seed=5, n_frames=N)


@pytest.fixture
def rec(deviation, tmp_path):
    """A fresh copy of the rendered recording to spoil."""
    return Path(shutil.copytree(deviation, tmp_path / "rec"))


def track(capsys, *argv: str) -> tuple[int, list[str]]:
    """Exit code of `wristtrack track ARGV` and the stderr lines (no progress bar, no report:
    the report is not what these tests are about)."""
    code = main(["track", *argv, "--no-progress", "--no-report"])
    return code, capsys.readouterr().err.strip().splitlines()


def fails_with_one_line(capsys, argv, *needles: str) -> str:
    code, lines = track(capsys, *argv)
    assert code == 2
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("wristtrack track: error: ")
    for needle in needles:
        assert needle in line, (needle, line)
    return line


def cli(*argv: str) -> subprocess.CompletedProcess:
    """The installed command in its own process: what a user's terminal shows."""
    return subprocess.run([sys.executable, "-m", "wristtrack.cli", *argv], capture_output=True,
                          text=True, check=False)


# ------------------------------------------------------------------ whole-recording problems


def test_missing_recording(capsys, tmp_path):
    fails_with_one_line(capsys, [str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")],
                        "nowhere", "not found", "recording folder")
    assert not (tmp_path / "o").exists()


def test_empty_recording(capsys, tmp_path):
    RecordingWriter(tmp_path / "empty", Camera.default()).close()
    fails_with_one_line(capsys, [str(tmp_path / "empty"), "--out", str(tmp_path / "o")],
                        "frames.csv", "empty")


def test_missing_or_unreadable_image_file(rec, capsys, tmp_path):
    (rec / "depth" / "000007.png").unlink()
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o")],
                        "frames.csv line 9", "depth image", "000007.png", "not found",
                        "remove that row")
    path = rec / "depth" / "000007.png"
    path.mkdir()  # there, but not a readable file (file modes would not stop root)
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o")],
                        "000007.png", "is not a file")


@pytest.mark.parametrize("spoil, needles", [
    ("truncated png", ["rgb/000000.png", "corrupt or truncated"]),
    ("8-bit depth", ["depth/000000.png", "8-bit", "16-bit"]),
    ("small depth", ["depth/000000.png", "320x240", "640x480", "registered"]),
    ("large colour", ["rgb/000000.png", "1280x960", "640x480", "camera.json"]),
])
def test_a_recording_whose_first_frames_are_all_bad_fails_at_once(rec, capsys, tmp_path, spoil,
                                                                  needles):
    # a fault of the whole recording shows in its first frames; it is refused as one line
    # rather than reported frame by frame
    for i in range(PROBE_FRAMES):
        rgb, depth = rec / "rgb" / f"{i:06d}.png", rec / "depth" / f"{i:06d}.png"
        if spoil == "truncated png":
            rgb.write_bytes(rgb.read_bytes()[:500])
        elif spoil == "8-bit depth":
            cv2.imwrite(str(depth), (cv2.imread(str(depth), cv2.IMREAD_UNCHANGED) // 8).astype(
                np.uint8))
        elif spoil == "small depth":
            cv2.imwrite(str(depth), cv2.imread(str(depth), cv2.IMREAD_UNCHANGED)[::2, ::2])
        else:
            cv2.imwrite(str(rgb), cv2.resize(cv2.imread(str(rgb)), (1280, 960)))
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o")], *needles)


# ------------------------------------------------------------------------- config files


@pytest.mark.parametrize("content, needles", [
    ("{not json", ["camera.json", "not valid JSON", "line 1"]),
    ('{"fx": 500}', ["camera.json", "missing field"]),
    ('{"fx": -525, "fy": 525, "cx": 320, "cy": 240, "width": 640, "height": 480, '
     '"depth_scale": 0.001}', ["camera.json", "'fx'", "positive"]),
    ('{"fx": 525, "fy": 525, "cx": 320, "cy": 240, "width": 640.5, "height": 480, '
     '"depth_scale": 0.001}', ["camera.json", "'width'", "integer"]),
    ('{"fx": 525, "fy": 525, "cx": 240, "cy": 520, "width": 640, "height": 480, '
     '"depth_scale": 0.001}', ["camera.json", "principal point", "outside the 640x480 image"]),
    ('{"fx": 525, "fy": 525, "cx": 320, "cy": 240, "width": 640, "height": 480, '
     '"depth_scale": 1000}', ["camera.json", "'depth_scale'", "metres per unit"]),
])
def test_bad_camera_file(rec, capsys, tmp_path, content, needles):
    (rec / "camera.json").write_text(content)
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o")], *needles)


def _hand(markers) -> str:
    return json.dumps({"markers": markers})


GOOD_HAND = {"WRIST": [0, 0, 0], "CMC1": [0.03, 0.035, 0], "MCP2": [0.08, 0.025, 0],
             "MCP3": [0.088, 0, 0], "MCP4": [0.08, -0.02, 0], "MCP5": [0.067, -0.036, 0]}


@pytest.mark.parametrize("content, needles", [
    ('{"markers": [1, 2]', ["hand.json", "not valid JSON"]),
    (_hand({**{k: v for k, v in GOOD_HAND.items() if k != "MCP5"}, "mcp5": [0.067, -0.036, 0]}),
     ["hand.json", "unknown marker name(s) 'mcp5'", "missing marker(s) MCP5"]),
    (_hand({**GOOD_HAND, "MCP3": [88, 0, 0]}), ["hand.json", "MCP3", "metres"]),
    (_hand({**GOOD_HAND, "MCP4": [0.0885, 0.001, 0]}), ["hand.json", "MCP3", "MCP4", "apart"]),
    (_hand({k: [0.02 * i, 0, 0] for i, k in enumerate(GOOD_HAND)}), ["hand.json", "collinear"]),
])
def test_bad_hand_file(rec, capsys, tmp_path, content, needles):
    (rec / "hand.json").write_text(content)
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o")], *needles)
    hand = tmp_path / "other_hand.json"  # the same through --hand
    hand.write_text(content)
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "o"), "--hand", str(hand)],
                        "other_hand.json")


def test_a_failed_run_leaves_earlier_outputs_alone(rec, capsys, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    before = {"poses.csv": "frame,timestamp,status\n0,0.0,tracking\n", "summary.json": "{}\n"}
    for name, text in before.items():
        (out / name).write_text(text)
    (rec / "hand.json").write_text('{"markers": {}}')
    fails_with_one_line(capsys, [str(rec), "--out", str(out)], "hand.json")
    assert {p.name: p.read_text() for p in out.iterdir()} == before


def test_output_folder_that_is_a_file(rec, capsys, tmp_path):
    (tmp_path / "taken").write_text("not a folder")
    fails_with_one_line(capsys, [str(rec), "--out", str(tmp_path / "taken")],
                        "output folder", "taken", "--out")
    assert (tmp_path / "taken").read_text() == "not a folder"


# ------------------------------------------------------------------- problems in one frame


def test_a_corrupt_frame_inside_the_recording_is_reported_marked_and_skipped(rec, tmp_path,
                                                                           check_run):
    png = rec / "rgb" / f"{BAD:06d}.png"
    png.write_bytes(png.read_bytes()[: png.stat().st_size // 3])  # truncated
    out = tmp_path / "out"
    proc = cli("track", str(rec), "--out", str(out), "--no-progress", "--no-report")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, lines  # OpenCV's own warning about the PNG is not passed on
    assert f"frame {BAD} skipped" in lines[0] and png.name in lines[0]

    cols = read_poses(out / "poses.csv")
    np.testing.assert_array_equal(cols["frame"], np.arange(N))  # one row per frame, in order
    assert cols["status"][BAD] == "bad_frame"
    assert np.isnan([cols[c][BAD] for c in ("tx", "ty", "tz", "qw", "cam_tz")]).all()
    assert (cols["status"][:BAD] == "tracking").all()
    assert (cols["status"][BAD + 1 :] == "tracking").all()  # the run went on
    summary = json.loads((out / "summary.json").read_text())
    (skipped,) = summary["skipped_frames"]
    assert skipped["frame"] == BAD and "corrupt or truncated" in skipped["error"]
    check = subprocess.run([sys.executable, str(check_run), str(out)], capture_output=True,
                           text=True, check=False)
    assert check.returncode == 0, check.stdout


def test_wrong_depth_in_one_frame_and_time_going_backwards_are_skipped(rec, capsys, tmp_path):
    depth = rec / "depth" / f"{BAD:06d}.png"
    cv2.imwrite(str(depth), np.zeros((240, 320), np.uint16))  # not registered to colour
    lines = (rec / "frames.csv").read_text().splitlines()
    t = [float(row.split(",")[0]) for row in lines[1:]]
    back = 40  # goes back in time to before frame 38; frame 41 goes forward again
    lines[1 + back] = ",".join([repr(t[back - 2] - 0.001), *lines[1 + back].split(",")[1:]])
    (rec / "frames.csv").write_text("\n".join(lines) + "\n")
    code, err = track(capsys, str(rec), "--out", str(tmp_path / "out"))
    assert code == 0
    assert len(err) == 2 and "frame 20 skipped" in err[0] and "frame 40 skipped" in err[1]
    assert "320x240" in err[0] and "increasing" in err[1]
    cols = read_poses(tmp_path / "out" / "poses.csv")
    assert cols["status"][BAD] == "bad_frame" and cols["status"][back] == "skipped"
    others = np.delete(cols["status"], [BAD, back])
    assert (others == "tracking").all()


# --------------------------------------------------------------------------- no markers


def test_no_frame_shows_all_six_markers(rec, capsys, tmp_path):
    # cover two markers with the skin around them in every frame
    truth = np.genfromtxt(rec / "truth_markers.csv", delimiter=",", names=True)
    for k in range(N):
        path = rec / "rgb" / f"{k:06d}.png"
        img = cv2.imread(str(path))
        for name in ("MCP4", "MCP5"):
            u, v = int(round(truth[f"{name}_u"][k])), int(round(truth[f"{name}_v"][k]))
            # paint the marker over with the skin of a ring around it
            yy, xx = np.ogrid[: img.shape[0], : img.shape[1]]
            r2 = (xx - u) ** 2 + (yy - v) ** 2
            skin = np.median(img[(r2 >= 16**2) & (r2 <= 20**2)], axis=0)
            img[r2 < 15**2] = skin
        cv2.imwrite(str(path), img)
    out = tmp_path / "out"
    line = fails_with_one_line(capsys, [str(rec), "--out", str(out)],
                               "could be initialised", "no frame showed all six markers")
    assert str(rec) in line
    assert int(re.search(r"at most (\d+) blobs in one frame", line).group(1)) < 6
    # the outputs still say what happened, frame by frame
    cols = read_poses(out / "poses.csv")
    assert len(cols["frame"]) == N and (cols["status"] == "initialising").all()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"]["tracked"] == 0


# -------------------------------------------------------------------------- video and bags


def _video(path: Path, frames: list[np.ndarray]) -> None:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (w, h))
    for f in frames:
        writer.write(f)
    writer.release()


def test_truncated_and_corrupt_video(rec, tmp_path):
    frames = [cv2.imread(str(rec / "rgb" / f"{k:06d}.png")) for k in range(30)]
    video = tmp_path / "clip.avi"
    _video(video, frames)
    data = video.read_bytes()
    args = ["--camera", str(rec / "camera.json"), "--hand", str(rec / "hand.json"),
            "--no-progress", "--no-report"]

    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: int(len(data) * 0.6)])  # the end of the file is lost
    proc = cli("track", str(cut), "--out", str(tmp_path / "o1"), *args)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "cut.avi stops decoding at frame" in lines[0], lines
    cols = read_poses(tmp_path / "o1" / "poses.csv")
    assert cols["status"][-1] == "bad_frame" and (cols["status"][:-1] == "tracking").all()
    assert 5 < len(cols["frame"]) < 30

    broken = tmp_path / "broken.avi"
    broken.write_bytes(data[:2000])
    proc = cli("track", str(broken), "--out", str(tmp_path / "o2"), *args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "broken.avi" in lines[0] and "damaged or truncated" in lines[0]


def test_bag_without_image_topics(capsys, tmp_path):
    rosbag1 = pytest.importorskip("rosbags.rosbag1")
    typesys = pytest.importorskip("rosbags.typesys")
    store = typesys.get_typestore(typesys.Stores.ROS1_NOETIC)
    path = tmp_path / "chatter.bag"
    with rosbag1.Writer(path) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hello")
        writer.write(conn, 1_000_000_000, store.serialize_ros1(msg, "std_msgs/msg/String"))
    fails_with_one_line(capsys, [str(path), "--out", str(tmp_path / "o")],
                        "chatter.bag", "no colour image topic", "/chatter (std_msgs/msg/String)",
                        "color_topic")


def test_damaged_image_message_in_a_bag_is_a_bad_frame(tmp_path):
    rosbag1 = pytest.importorskip("rosbags.rosbag1")
    typesys = pytest.importorskip("rosbags.typesys")
    store = typesys.get_typestore(typesys.Stores.ROS1_NOETIC)
    T = store.types
    w, h = 32, 24
    camera = Camera(fx=40.0, fy=40.0, cx=15.5, cy=11.5, width=w, height=h)
    path = tmp_path / "rec.bag"
    with rosbag1.Writer(path) as writer:
        conn = writer.add_connection("/camera/color/image_raw", "sensor_msgs/msg/Image",
                                     typestore=store)
        for k in range(5):
            ns = 1_000_000_000 + k * 33_333_333
            stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            header = T["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="camera")
            data = np.full(h * w * 3, 40 * k, np.uint8)
            if k == 2:
                data = data[: w * 3 * 5]  # the message lost most of its rows
            msg = T["sensor_msgs/msg/Image"](header=header, height=h, width=w, encoding="bgr8",
                                             is_bigendian=0, step=w * 3, data=data)
            writer.write(conn, ns, store.serialize_ros1(msg, "sensor_msgs/msg/Image"))
    frames = list(open_recording(path, camera=camera))
    assert [f.ok for f in frames] == [True, True, False, True, True]
    assert "frame 2" in frames[2].error and "damaged" in frames[2].error
    assert frames[3].bgr[0, 0, 0] == 120  # the frames after it are read as they were written
