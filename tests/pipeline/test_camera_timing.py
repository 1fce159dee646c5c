"""``wristtrack timing``: a rolling shutter's readout and the depth's delay measured from a
recording, against the values the simulator rendered it with."""

from __future__ import annotations

import json

import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main


def _render_without(folder, switch: str, field: str) -> float:
    """A fast reach (seed 8, 60 frames) rendered with ``switch``, ``field`` taken out of its
    camera.json (a camera that does not say it); returns the rendered value."""
    assert main(["simulate", str(folder), "--scenario", "reach", "--seed", "8", switch,
                 "--n-frames", "60"]) == 0
    camera = json.loads((folder / "camera.json").read_text())
    value = camera.pop(field)
    (folder / "camera.json").write_text(json.dumps(camera))
    return value


@pytest.fixture(scope="module")
def rolled(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rolled") / "rec"
    return folder, _render_without(folder, "--rolling-shutter", "readout_s")


def test_the_readout_is_measured_and_written(rolled, capsys):
    """Within 1 ms of the rendered 18.8 ms (18.6 when written); the depth, captured with the
    colour here, within 3 ms of none; --write puts both into --camera's file."""
    folder, truth = rolled
    assert main(["timing", str(folder), "--camera", str(folder / "camera.json"), "--write",
                 "--hand", str(folder / "hand.json")]) == 0
    out = capsys.readouterr().out
    measured = Camera.load(folder / "camera.json")
    assert abs(measured.readout - truth) < 0.001, (measured.readout, truth)
    assert abs(measured.depth_delay) < 0.003, measured.depth_delay
    assert f"readout_s: {measured.readout:.4f}" in out
    assert "wrote readout_s and depth_delay_s into" in out
    assert out.count("NIS per dof") == 14


def test_the_depth_delay_is_measured(tmp_path, capsys):
    """A depth frame captured 16.6 ms after its colour (the longest the pairing allows at
    30 fps): measured within 3 ms, into the recording's own camera.json."""
    folder = tmp_path / "lagged"
    truth = _render_without(folder, "--depth-lag", "depth_delay_s")
    assert main(["timing", str(folder), "--write"]) == 0
    measured = Camera.load(folder / "camera.json").depth_delay
    assert abs(measured - truth) < 0.003, (measured, truth)
    assert f"depth_delay_s: {measured:.4f}" in capsys.readouterr().out


def test_a_still_hand_cannot_tell_values_apart(rolled, cut_recording, tmp_path, capsys):
    """The reach's still start (its first 14 frames): every value explains the markers alike,
    and the command says so in one line instead of guessing."""
    folder, _ = rolled
    still = cut_recording(folder, range(14), tmp_path / "still")
    assert main(["timing", str(still)]) == 2
    err = capsys.readouterr().err.strip()
    assert "explains the markers alike" in err and "moving fast" in err
    assert "\n" not in err and "Traceback" not in err


def test_a_missing_recording_is_one_line(tmp_path, capsys):
    assert main(["timing", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(tmp_path / "none") in err and "\n" not in err
