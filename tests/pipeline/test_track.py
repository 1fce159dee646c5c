"""End to end: rendered RGB-D recordings -> `wristtrack track` -> `wristtrack evaluate`."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from wristtrack.analysis.pose_errors import pose_errors
from wristtrack.cli import main
from wristtrack.hand import HandLayout
from wristtrack.io.poses import read_poses, rows_to_poses
from wristtrack.sim.render import render_recording
from wristtrack.tracking.pixel_noise import SIGMA_FLOOR


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("recordings")
    return {
        name: render_recording(root / name, name, seed=11, duration=duration)
        for name, duration in (("flexion", 4.0), ("rgb_only", 3.0), ("no_hand", 3.0))
    }


def _track(recording, out, *extra):
    assert main(["track", str(recording), "--out", str(out), "--no-progress", *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def _evaluate(out, recording, capsys):
    assert main(["evaluate", str(out), "--truth", str(recording / "truth.csv")]) == 0
    capsys.readouterr()
    return json.loads((out / "evaluation.json").read_text())


def test_track_and_evaluate_a_rendered_recording(recordings, tmp_path, capsys, check_run):
    rec = recordings["flexion"]
    summary = _track(rec, tmp_path / "run")
    proc = subprocess.run(
        [sys.executable, str(check_run), str(tmp_path / "run")],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 0, proc.stdout
    result = _evaluate(tmp_path / "run", rec, capsys)
    assert result["orientation_rmse_deg"] <= 2.0
    assert result["position_rmse_mm"] <= 5.0
    assert result["coverage"] >= 0.98
    assert abs(result["rom"]["flexion"]["range_error_deg"]) <= 2.0
    assert summary["frames"]["total"] == len(read_poses(tmp_path / "run" / "poses.csv")["frame"])
    assert summary["range_of_motion"]["flexion"]["range_deg"] > 90  # +-50 degrees of flexion
    # the rendered blobs are sharp (0.015 px against the truth): their scatter about the pose
    # says so, the pixel noise learned falls below the model's, their errors' correlation in
    # time measured on the way
    noise = summary["measurement_noise"]
    assert 0.005 < noise["blob_error_px"] < 0.03
    assert SIGMA_FLOOR <= noise["pixel_sigma_px"] < noise["pixel_sigma_model_px"] == 0.3
    assert noise["blob_error_inflation"] > 1.0


def test_fixed_noise_keeps_the_models_values(recordings, tmp_path):
    """--fixed-noise: the model's pixel sigma and skin slide, whatever the blobs show."""
    summary = _track(recordings["flexion"], tmp_path / "run", "--fixed-noise", "--no-report")
    assert summary["measurement_noise"]["pixel_sigma_px"] == 0.3
    assert summary["measurement_noise"]["skin_slide_sd_factor"] == 1.0
    assert summary["settings"]["adapt_pixel"] is False


def test_the_noise_is_primed_over_the_first_seconds(recordings, tmp_path):
    """By default a run starts from the noise a first pass over the recording's first 10 s
    learned (here all 4 s of it): its first second is nearer the truth than a run that learns
    from its first frame on, as a live camera must (--no-prime-noise; measured 0.25 against
    0.28 deg)."""
    rec = recordings["flexion"]
    truth = rows_to_poses(read_poses(rec / "truth.csv"))
    errors = {}
    for name, extra in (("primed", ()), ("fresh", ("--no-prime-noise",))):
        summary = _track(rec, tmp_path / name, "--no-report", *extra)
        assert summary["settings"]["prime_noise"] is (name == "primed")
        R, t = rows_to_poses(read_poses(tmp_path / name / "poses.csv"))
        first = 30  # frames: the first second
        errors[name] = pose_errors(R[:first], t[:first], truth[0][:first],
                                   truth[1][:first]).orientation_rmse_deg
    assert errors["primed"] < errors["fresh"], errors


def test_rgb_only_recording_is_tracked_with_the_layout_fixing_the_scale(recordings, tmp_path,
                                                                          capsys):
    rec = recordings["rgb_only"]
    _track(rec, tmp_path / "run")
    cols = read_poses(tmp_path / "run" / "poses.csv")
    assert (cols["status"] == "tracking").mean() > 0.95
    result = _evaluate(tmp_path / "run", rec, capsys)
    # without depth the out-of-plane angles and the distance are much weaker (see BENCHMARKS)
    assert result["coverage"] >= 0.98
    assert result["position_rmse_mm"] < 30.0
    assert result["orientation_rmse_deg"] < 15.0


def test_without_hand_json_the_layout_is_measured_from_depth(recordings, tmp_path, capsys):
    rec = recordings["no_hand"]
    assert not (rec / "hand.json").exists()
    summary = _track(rec, tmp_path / "run")
    measured = HandLayout.from_dict(summary["hand_layout"]).points
    truth = HandLayout.default().points  # what the renderer put on the hand
    assert np.abs(measured - truth).max() < 0.004
    result = _evaluate(tmp_path / "run", rec, capsys)
    assert result["orientation_rmse_deg"] <= 2.0
    assert result["position_rmse_mm"] <= 5.0


def test_video_input_with_camera_and_hand_files(recordings, tmp_path, capsys):
    rec = recordings["flexion"]
    video = tmp_path / "clip.avi"
    frames = sorted((rec / "rgb").glob("*.png"))
    first = cv2.imread(str(frames[0]))
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0,
                             (first.shape[1], first.shape[0]))
    for f in frames:
        writer.write(cv2.imread(str(f)))
    writer.release()
    _track(video, tmp_path / "run", "--camera", str(rec / "camera.json"),
           "--hand", str(rec / "hand.json"))
    cols = read_poses(tmp_path / "run" / "poses.csv")
    assert len(cols["frame"]) == len(frames)
    assert (cols["status"] == "tracking").mean() > 0.9


def test_a_video_without_camera_is_one_clear_line(tmp_path):
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (64, 48))
    writer.write(np.zeros((48, 64, 3), np.uint8))
    writer.release()
    proc = subprocess.run(
        [sys.executable, "-m", "wristtrack.cli", "track", str(video), "--out", str(tmp_path / "o")],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "--camera" in proc.stderr


def test_a_frame_with_a_repeated_timestamp_is_marked_and_skipped(recordings, tmp_path):
    rec = recordings["flexion"]
    copy = tmp_path / "rec"
    copy.mkdir()
    for name in ("camera.json", "hand.json"):
        (copy / name).write_text((rec / name).read_text())
    lines = (rec / "frames.csv").read_text().splitlines()
    header, rows = lines[0], lines[1:40]
    fixed = [",".join([r.split(",")[0], str(rec / r.split(",")[1]), str(rec / r.split(",")[2])])
             for r in rows]
    fixed[20] = ",".join([rows[19].split(",")[0], *fixed[20].split(",")[1:]])  # repeats frame 19
    (copy / "frames.csv").write_text("\n".join([header, *fixed]) + "\n")
    summary = _track(copy, tmp_path / "run")
    cols = read_poses(tmp_path / "run" / "poses.csv")
    assert cols["status"][20] == "skipped"
    assert (cols["status"][21:] == "tracking").all()
    assert summary["skipped_frames"][0]["frame"] == 20


def test_frames_without_depth_are_tracked_on_colour_and_listed(recordings, tmp_path, capsys,
                                                                 cut_recording, check_run):
    """A depth recording whose frames 30-32 lost their depth (an empty depth cell, as a camera
    that dropped them records it, or an SDK file whose depth was not of their moment): they are
    tracked on colour alone, near the truth, and summary.json and the closing line say which."""
    rec = recordings["flexion"]
    n = len((rec / "frames.csv").read_text().splitlines()) - 1
    gappy = cut_recording(rec, np.arange(n), tmp_path / "gappy", without_depth=[30, 31, 32])
    capsys.readouterr()
    summary = _track(gappy, tmp_path / "run")
    assert summary["frames_without_depth"] == [30, 31, 32]
    assert "(3 without depth, on colour alone)" in capsys.readouterr().out
    assert subprocess.run([sys.executable, str(check_run), str(tmp_path / "run")]).returncode == 0
    poses, truth = read_poses(tmp_path / "run" / "poses.csv"), read_poses(rec / "truth.csv")
    assert set(poses["status"][30:33]) == {"tracking"}
    for angle in ("deviation_deg", "flexion_deg", "pronation_deg"):
        assert np.abs(poses[angle][30:33] - truth[angle][30:33]).max() < 1.0
    assert _track(rec, tmp_path / "whole")["frames_without_depth"] == []


def test_evaluate_says_what_is_missing_in_one_line(tmp_path, capsys):
    """A folder that is no run (none there, no poses.csv in it) gets the run folder's one-line
    errors, as report and export give them, and exit code 2."""
    (tmp_path / "empty").mkdir()
    truth = tmp_path / "truth.csv"
    truth.write_text("timestamp\n")
    for folder, expect in ((tmp_path / "nowhere", "not found; give the --out folder"),
                           (tmp_path / "empty", "has no poses.csv; run 'wristtrack track")):
        assert main(["evaluate", str(folder), "--truth", str(truth)]) == 2
        err = capsys.readouterr().err
        assert expect in err and err.count("\n") == 1 and "Traceback" not in err
