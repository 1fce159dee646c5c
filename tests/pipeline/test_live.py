"""Live tracking without hardware: a rendered recording replayed as a camera (`--live replay:`).

Truth: the offline run of the same folder (the live loop must give the same poses on the frames
it processes), the recording's own frame list (every frame is accounted for: processed or
dropped, one poses.csv row each) and, for --record, the recording itself.
"""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from wristtrack.cli import main
from wristtrack.errors import InputError
from wristtrack.geometry import rotation_distance
from wristtrack.io.base import Recording
from wristtrack.io.folder import FolderRecording
from wristtrack.io.poses import read_poses, rows_to_poses
from wristtrack.pipeline.live.loop import Captured, NewestFrameSlot, track_live
from wristtrack.pipeline.track import track_recording
from wristtrack.tracking.config import TrackerConfig

ANGLES = ("deviation_deg", "flexion_deg", "pronation_deg")


@pytest.fixture(scope="module")
def reach(rendered):
    return rendered("reach")  # 127 frames at 30 fps, shared with the report and resume tests


@pytest.fixture(scope="module")
def offline(reach, tmp_path_factory):
    out = tmp_path_factory.mktemp("offline")
    with FolderRecording(reach) as rec:
        track_recording(rec, out, progress=False)
    return read_poses(out / "poses.csv")


def _agree(live, reach, cut_recording, tmp_path, deg, mm):
    """Poses of the frames the live run processed against an offline run over exactly those frames
    (the folder cut to them), in the camera frame: a dropped frame gives the frames after it a
    longer filter step, which the offline run over the same frames takes too, however many a busy
    machine dropped. Not digit for digit: the cut folder numbers its frames afresh, so its colours
    adapt on other frames than the live run's (every 10th, pipeline/colours.py), which moves the
    blobs' centres by a fraction of a pixel; on sharp blobs the out-of-plane angles rest on that
    fraction, which acts as a measurement noise of their own on each run. So a frame's two
    orientations agree within ``deg`` or, where larger, three times the spread of the difference of
    two estimates each with the reported 1-sigma uncertainty, 3 sqrt(2) sigma (the reach's frames
    61-67: up to 0.65 deg apart at 0.56 reported on a loaded machine that dropped frames, 0.43 at
    0.67 on an idle one, each run within 0.3 deg of the truth there), and their positions within
    ``mm`` or, where larger, 3 sqrt(2) times the reported position sigma. A run that kept 4 of 60
    frames, each after a gap that leaves it to its own blobs, had two of them 1.57 mm apart at 1.02
    mm reported: 1.1 sigma of the difference, as expected of two draws of the blobs' noise; a bound
    at one sigma of the difference fails such a run a third of the time."""
    taken = live["status"] != "dropped"
    cut = cut_recording(reach, np.asarray(live["frame"][taken], int), tmp_path / "taken")
    with FolderRecording(cut) as rec:  # learning its noise from the first frame on, as live
        track_recording(rec, tmp_path / "taken-run", TrackerConfig(prime_noise=False),
                        progress=False)
    offline = read_poses(tmp_path / "taken-run" / "poses.csv")
    status = live["status"][taken]
    done = np.isin(status, ("tracking", "coasting"))
    assert done.sum() > 0.9 * taken.sum()
    np.testing.assert_array_equal(status, offline["status"])
    R_live, t_live = rows_to_poses(live)
    R_off, t_off = rows_to_poses(offline)
    ang = np.degrees(rotation_distance(R_live[taken][done], R_off[done]))
    tolerance = np.maximum(deg, 3 * np.sqrt(2.0) * np.asarray(live["rot_sigma_deg"])[taken][done])
    beyond = ang > tolerance
    assert not beyond.any(), np.c_[live["frame"][taken][done], ang, tolerance][beyond]
    err = np.linalg.norm(t_live[taken][done] - t_off[done], axis=1) * 1e3
    limit = np.maximum(mm, 3 * np.sqrt(2.0) * np.asarray(live["pos_sigma_mm"])[taken][done])
    assert not (err > limit).any(), np.c_[live["frame"][taken][done], err, limit][err > limit]


def test_newest_frame_wins_and_the_rest_are_counted():
    from wristtrack.io.base import Frame

    slot = NewestFrameSlot()
    frames = [Frame(i, i / 30, np.zeros((2, 2, 3), np.uint8)) for i in range(4)]
    for f in frames[:3]:
        slot.put(Captured(f, 0.0))
    item, dropped = slot.take(0.01)
    assert item.frame.index == 2 and dropped == [(0, 0.0), (1, 1 / 30)]
    assert slot.take(0.01) == (None, [])  # nothing new: a timeout, not the end
    slot.put(Captured(frames[3], 0.0))
    slot.end()
    item, dropped = slot.take(0.01)
    assert item.frame.index == 3 and dropped == [] and slot.ended
    assert slot.take(0.01) == (None, [])


def test_replay_tracks_in_real_time_and_records_what_retracks_the_same(
    reach, offline, cut_recording, tmp_path, capsys, check_run
):
    run, copy = tmp_path / "run", tmp_path / "copy"
    code = main(["track", "--live", f"replay:{reach}", "--out", str(run), "--record", str(copy),
                 "--no-report"])
    assert code == 0
    out = capsys.readouterr().out
    assert "latency p50" in out and f"recorded 127 frames to {copy}" in out
    assert subprocess.run([sys.executable, str(check_run), str(run)]).returncode == 0

    live = json.loads((run / "live.json").read_text())
    poses = read_poses(run / "poses.csv")
    n = len(FolderRecording(reach))
    # every frame accounted for, in order: processed or dropped, one row each
    assert live["frames"]["total"] == n == len(poses["frame"])
    np.testing.assert_array_equal(poses["frame"], np.arange(n))
    assert live["frames"]["processed"] + live["frames"]["dropped"] == n
    assert sorted(poses["frame"][poses["status"] == "dropped"].astype(int)) == \
        live["dropped_frames"]
    assert len(live["per_frame"]["latency_ms"]) == live["frames"]["processed"]
    assert 0 < live["latency_ms"]["p50"] <= live["latency_ms"]["p95"] <= live["latency_ms"]["max"]
    assert live["frame_period_ms"] == pytest.approx(1000 / 30, rel=1e-6)
    assert live["ended_by"] == "end of stream"
    _agree(poses, reach, cut_recording, tmp_path, deg=0.5, mm=1.0)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["settings"]["live"] and summary["live"]["frames"] == live["frames"]
    assert summary["settings"]["prime_noise"] is False  # a live camera is read once

    # --record: the same frames, timestamps and camera, so offline re-tracking gives the poses
    # of the recording itself (the live run's within filter noise)
    original, recorded = FolderRecording(reach), FolderRecording(copy)
    assert recorded.camera == original.camera and len(recorded) == n
    for a, b in zip(original.frames(), recorded.frames(), strict=True):
        assert a.timestamp == b.timestamp
        np.testing.assert_array_equal(a.bgr, b.bgr)
        np.testing.assert_array_equal(a.depth, b.depth)
    assert main(["track", str(copy), "--out", str(tmp_path / "again"), "--no-progress",
                 "--no-report"]) == 0
    again = read_poses(tmp_path / "again" / "poses.csv")
    for col in ANGLES + ("tx", "ty", "tz"):
        np.testing.assert_allclose(again[col], offline[col], atol=1e-9, equal_nan=True)


def test_frames_without_depth_are_tracked_on_colour_and_counted(reach, cut_recording, tmp_path,
                                                                 capsys):
    """A depth camera's frame that comes without depth (lost, or not of its colour frame's
    moment: io.base.pairing_tolerance) is tracked on colour alone, as offline, and live.json
    and the closing line say which."""
    lost = [40, 41, 90]
    gappy = cut_recording(reach, np.arange(len(FolderRecording(reach))), tmp_path / "gappy",
                          without_depth=lost)
    run = tmp_path / "run"
    assert main(["track", "--live", f"replay:{gappy}", "--out", str(run), "--no-report"]) == 0
    live = json.loads((run / "live.json").read_text())
    poses = read_poses(run / "poses.csv")
    processed = set(poses["frame"][poses["status"] != "dropped"].astype(int).tolist())
    expected = [i for i in lost if i in processed]
    assert expected, "a busy machine dropped every frame without depth: nothing was tested"
    assert live["frames_without_depth"] == expected
    assert live["frames"]["without_depth"] == len(expected)
    assert f"{len(expected)} without depth, on colour alone)" in capsys.readouterr().out
    assert set(poses["status"][np.isin(poses["frame"], expected)]) <= {"tracking", "coasting"}
    _agree(poses, gappy, cut_recording, tmp_path, deg=0.5, mm=1.0)


class Burst(Recording):
    """The first frames of a recording, decoded up front and delivered back to back (their own
    timestamps kept): a camera far faster than the tracker. 1 ms apart was not: the tracker,
    with detection in predicted windows, keeps up with every other such frame."""

    kind = "test burst"

    def __init__(self, folder, n):
        rec = FolderRecording(folder)
        super().__init__(f"burst:{folder}", rec.camera, rec.hand)
        self._frames_list = [f for _, f in zip(range(n), rec.frames(), strict=False)]

    def _frames(self, start=0):
        for frame in self._frames_list:
            time.sleep(0)  # only hand the interpreter to the tracker's thread
            yield frame


def test_a_slow_tracker_drops_frames_and_never_queues_them(reach, cut_recording, tmp_path):
    n = 60
    summary, live = track_live(Burst(reach, n), tmp_path / "run")
    poses = read_poses(tmp_path / "run" / "poses.csv")
    np.testing.assert_array_equal(poses["frame"], np.arange(n))  # a row for every frame
    dropped = poses["status"] == "dropped"
    assert live["frames"]["dropped"] == int(dropped.sum()) > n / 2
    assert live["frames"]["processed"] == n - dropped.sum()
    assert live["dropped_frames"] == poses["frame"][dropped].astype(int).tolist()
    assert np.isnan(poses["qw"][dropped]).all() and np.isnan(poses["flexion_deg"][dropped]).all()
    # One slot, no queue: a frame waits at most for the frame being processed, so its latency
    # is bounded by two processing times, and the threads' wake-ups on a busy machine (up to
    # ~35 ms seen with a benchmark beside the suite). A queue would make it grow frame after
    # frame, to the burst's n processing times (~900 ms here).
    proc = np.asarray(live["per_frame"]["processing_ms"])
    lat = np.asarray(live["per_frame"]["latency_ms"])
    assert (lat[1:] <= 2 * proc.max() + 50).all()
    assert lat.max() < 0.25 * n * proc.min()
    assert summary["frames"]["tracked"] == live["frames"]["processed"]
    _agree(poses, reach, cut_recording, tmp_path, deg=0.5, mm=1.0)


def test_ctrl_c_ends_the_session_with_complete_outputs(reach, tmp_path):
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "wristtrack.cli", "track", "--live", f"replay:{reach}", "--out",
         str(run), "--no-report"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:  # wait until frames are being tracked
        if (run / "poses.csv").exists() and (run / "poses.csv").read_text().count("\n") > 10:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "tracked" in out
    live = json.loads((run / "live.json").read_text())
    summary = json.loads((run / "summary.json").read_text())
    assert live["ended_by"] == "SIGINT" and not summary["interrupted"]
    assert 10 <= live["frames"]["total"] < 127


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--live", "replay:/no/such/rec"], "recording folder /no/such/rec not found"),
        (["--live", "tv"], "--live tv: unknown source; give realsense"),
        (["--live", "replay:REC", "--smooth"], "--smooth cannot be used with --live"),
        (["--live", "replay:REC", "--port", "9"], "--port is the --view page's port; add --view"),
        (["REC", "--record", "x"], "--view, --port and --record are for --live SOURCE"),
    ],
)
def test_bad_live_options_are_one_line(reach, tmp_path, capsys, argv, message):
    argv = [a.replace("REC", str(reach)) for a in argv]
    assert main(["track", *argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_record_refuses_an_existing_recording(reach, tmp_path, capsys):
    assert main(["track", "--live", f"replay:{reach}", "--out", str(tmp_path / "run"),
                 "--record", str(reach)]) == 2
    err = capsys.readouterr().err.strip()
    assert "already exists and is not empty" in err and "\n" not in err


def test_benchmark_section_judges_the_plain_runs_against_the_target():
    from benchmarks.live import live_section

    def run(p95, dropped=0, fraction=1.0):
        return {"frames": 100, "dropped": dropped, "tracked": 100, "tracked_fraction": fraction,
                "latency_p50_ms": 5.0, "latency_p95_ms": p95, "latency_max_ms": 40.0,
                "over_frame_period": 1, "replay_late_frames": 0, "recorded": None,
                "record_lost": None}

    result = {"cores_usable": 2, "load_average_before": 1.0, "load_average_after": 1.0,
              "runs": {"reach": run(20.0), "reach --record": run(40.0, dropped=3)}}
    text = "\n".join(live_section(result))
    assert "| reach | 100 | 100.0 % | 0 | 5.0 | 20.0 | 40.0 | 1 |" in text
    assert "(meets the target); with --record: worst p95 40.0 ms, 3 dropped" in text
    result["runs"]["flexion"] = run(20.0, fraction=0.98)
    assert "**misses**" in "\n".join(live_section(result))


class Unplugged(Burst):
    """A camera that stops with an error after ``after`` frames (a cable pulled)."""

    def __init__(self, folder, after):
        super().__init__(folder, after)

    def _frames(self, start=0):
        for frame in self._frames_list:
            time.sleep(1 / 30)
            yield frame
        raise InputError("camera test: device disconnected")


def test_a_camera_that_stops_ends_the_session_with_its_reason(reach, tmp_path):
    summary, live = track_live(Unplugged(reach, 8), tmp_path / "run")
    assert live["ended_by"] == "source error"
    assert live["source_error"] == "camera test: device disconnected"
    assert live["frames"]["total"] == 8 == len(read_poses(tmp_path / "run" / "poses.csv")["frame"])
    with pytest.raises(InputError, match="device disconnected"):  # before any frame: an error
        track_live(Unplugged(reach, 0), tmp_path / "run0")


def test_live_learns_and_follows_the_colours_as_offline(reach, cut_recording, tmp_path):
    """Replayed at half speed, so that no frame is dropped on an idle machine: the live loop
    learns the colours at the first fix and adapts them every 10th confident frame in place,
    as the offline run does (pipeline/colours.py), so its poses are the offline run's (its
    noise learned from the first frame on, as live) to the digit. Where a loaded machine
    dropped frames, the frames after a drop take a longer filter step, and the offline run over
    exactly the taken frames renumbers them (its adaptation falls on other frames): the runs
    then agree within the filter's noise (:func:`_agree`). Live without the adaptation, the
    poses differ by 1e-5 and more."""
    from wristtrack.io.live.replay import ReplayRecording

    track_live(ReplayRecording(reach, speed=0.5), tmp_path / "live")
    with FolderRecording(reach) as rec:
        track_recording(rec, tmp_path / "offline", TrackerConfig(prime_noise=False),
                        progress=False)
    live = read_poses(tmp_path / "live" / "poses.csv")
    offline = read_poses(tmp_path / "offline" / "poses.csv")
    if (live["status"] == "dropped").any():  # a loaded machine
        _agree(live, reach, cut_recording, tmp_path, deg=0.5, mm=1.0)
        return
    np.testing.assert_array_equal(live["status"], offline["status"])
    for column in ("tx", "ty", "tz", "qw", "qx", "qy", "qz", *ANGLES):
        np.testing.assert_array_equal(live[column], offline[column], err_msg=column)

