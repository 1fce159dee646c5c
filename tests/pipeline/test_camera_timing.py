"""``wristtrack timing``: a rolling shutter's readout and the depth's delay measured from a
recording, against the values the simulator rendered it with."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.pipeline import camera_timing


def _render_without(folder, switch: str, field: str, scenario: str = "reach", seed: int = 8,
                    frames: int = 60) -> float:
    """``scenario`` (default a fast reach, seed 8, 60 frames) rendered with ``switch``, ``field``
    taken out of its camera.json (a camera that does not say it); returns the rendered
    value."""
    assert main(["simulate", str(folder), "--scenario", scenario, "--seed", str(seed), switch,
                 "--n-frames", str(frames)]) == 0
    camera = json.loads((folder / "camera.json").read_text())
    value = camera.pop(field)
    (folder / "camera.json").write_text(json.dumps(camera))
    return value


@pytest.fixture(scope="module")
def rolled(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rolled") / "rec"
    return folder, _render_without(folder, "--rolling-shutter", "readout_s")


def test_the_readout_is_measured_and_written(rolled, capsys):
    """Within 1 ms of the rendered 18.8 ms (18.5 when written), into --camera's file. The
    reach moves the hand bodily: a depth delay would move its markers' depths alike (0.27 mm
    apart at 17 ms, their noise 1.3), which reads as a hand a little nearer, so the depth's
    delay is not measured, and not written."""
    folder, truth = rolled
    assert main(["timing", str(folder), "--camera", str(folder / "camera.json"), "--write",
                 "--hand", str(folder / "hand.json")]) == 0
    out = capsys.readouterr().out
    measured = Camera.load(folder / "camera.json")
    assert abs(measured.readout - truth) < 0.001, (measured.readout, truth)
    assert measured.depth_delay is None
    assert f"readout_s: {measured.readout:.4f}" in out
    assert "not measured:" in out and "depth_delay_s cannot be told" in out
    assert "record the hand turning" in out
    assert "wrote readout_s into" in out
    assert out.count("NIS per dof") == 7


def test_the_depth_delay_is_measured_on_a_turning_hand(tmp_path, capsys):
    """A pronation (seed 1, 90 frames) whose depth frames were captured 11.9 ms before their
    colour: measured within 1 ms (12.0), into the recording's own camera.json. The hand turns
    in depth, hardly across the image: a rolling shutter would move its markers' images 0.04 px
    apart (their noise 0.3 px), so the readout is not measured (a parabola through that flat
    curve put a global shutter's at 7 ms)."""
    folder = tmp_path / "lagged"
    truth = _render_without(folder, "--depth-lag", "depth_delay_s", "pronation", 1, 90)
    assert main(["timing", str(folder), "--write"]) == 0
    measured = Camera.load(folder / "camera.json")
    assert abs(measured.depth_delay - truth) < 0.001, (measured.depth_delay, truth)
    assert measured.readout is None
    out = capsys.readouterr().out
    assert f"depth_delay_s: {measured.depth_delay:.4f}" in out
    assert "readout_s cannot be told" in out and "moving fast across the image" in out


def test_the_markers_are_moved_apart_as_derived_by_hand():
    """What a value moves the markers apart by, the frames' score and the refusal's measure:
    nothing for what moves them all alike, and for what does not, the hand-derived spread."""
    camera = Camera(fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480)
    points = np.array([[0.0, -0.03, 0.0], [0.06, -0.04, 0.0], [0.08, -0.02, 0.0],
                       [0.08, 0.0, 0.0], [0.08, 0.02, 0.0], [0.06, 0.04, 0.0]])
    facing = np.diag([1.0, -1.0, -1.0])  # the back of the hand (its +Z) towards the camera
    z = 0.5

    def frame(v, w):  # W0 = the camera's pose of the hand at rest
        return SimpleNamespace(R_ch=facing, t_ch=np.array([0.0, 0.0, z]), R=np.eye(3),
                               v=np.asarray(v, float) @ facing, w=np.asarray(w, float) @ facing)

    delay = 0.0167
    # moving straight towards the camera: every depth changes by delay * speed
    assert camera_timing._delay_effect(camera, points, frame([0, 0, -0.3], [0, 0, 0]),
                                       delay) == pytest.approx(0.0, abs=1e-12)
    # turning about the image's x axis at 2 rad/s: a marker at image height y moves
    # in depth at 2 y (camera frame), so they part by delay * 2 * sd(y)
    y = (points @ facing.T)[:, 1]
    assert camera_timing._delay_effect(camera, points, frame([0, 0, 0], [2.0, 0, 0]), delay) \
        == pytest.approx(delay * 2.0 * np.std(y, ddof=1), rel=1e-9)
    readout = 0.03
    # across the image at 0.5 m/s: each marker shifts du * row_time(v), row_time linear in v
    shifted = camera_timing._readout_effect(camera, points, frame([0.5, 0, 0], [0, 0, 0]),
                                            readout)
    rows = camera.project(points @ facing.T + [0.0, 0.0, z])[:, 1]
    assert shifted == pytest.approx(600.0 * 0.5 / z * readout / 480 * np.std(rows, ddof=1),
                                    rel=1e-9)
    # the same markers on one row, moving across it: all shift alike
    flat = points * [1.0, 0.0, 0.0]
    assert camera_timing._readout_effect(camera, flat, frame([0.5, 0, 0], [0, 0, 0]),
                                         readout) == pytest.approx(0.0, abs=1e-12)


def test_a_still_hand_cannot_tell_values_apart(rolled, cut_recording, tmp_path, capsys):
    """The reach's still start (its first 14 frames): no value would move the markers apart,
    and the command says so in one line instead of guessing."""
    folder, _ = rolled
    still = cut_recording(folder, range(14), tmp_path / "still")
    assert main(["timing", str(still)]) == 2
    err = capsys.readouterr().err.strip()
    assert "readout_s cannot be told from this recording" in err and "moving fast" in err
    assert "\n" not in err and "Traceback" not in err


def test_a_missing_recording_is_one_line(tmp_path, capsys):
    assert main(["timing", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(tmp_path / "none") in err and "\n" not in err
