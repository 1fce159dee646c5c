"""``wristtrack readout``: a rolling shutter's readout measured from a recording, against the
readout the simulator rendered it with."""

from __future__ import annotations

import json

import pytest

from wristtrack.camera import Camera
from wristtrack.cli import main


@pytest.fixture(scope="module")
def rolled(tmp_path_factory):
    """A fast reach (seed 8, 60 frames) through a rolling shutter, its readout (18.8 ms) taken
    out of camera.json, as a camera whose SDK does not report it; and that readout."""
    folder = tmp_path_factory.mktemp("rolled") / "rec"
    assert main(["simulate", str(folder), "--scenario", "reach", "--seed", "8",
                 "--rolling-shutter", "--n-frames", "60"]) == 0
    camera = json.loads((folder / "camera.json").read_text())
    truth = camera.pop("readout_s")
    (folder / "camera.json").write_text(json.dumps(camera))
    return folder, truth


def test_the_readout_is_measured_and_written(rolled, tmp_path, capsys):
    """Within 1 ms of the rendered 18.8 ms (18.6 when written); --write puts it into the
    recording's camera.json, or into --camera's file."""
    folder, truth = rolled
    assert main(["readout", str(folder), "--camera", str(folder / "camera.json"), "--write",
                 "--hand", str(folder / "hand.json")]) == 0
    out = capsys.readouterr().out
    measured = Camera.load(folder / "camera.json").readout
    assert abs(measured - truth) < 0.001, (measured, truth)
    assert f"readout_s: {measured:.4f}" in out and "wrote readout_s into" in out
    assert out.count("NIS per dof") == 7


def test_a_still_hand_cannot_tell_readouts_apart(rolled, cut_recording, tmp_path, capsys):
    """The reach's still start (its first 14 frames): every readout explains the markers alike,
    and the command says so in one line instead of guessing."""
    folder, _ = rolled
    still = cut_recording(folder, range(14), tmp_path / "still")
    assert main(["readout", str(still)]) == 2
    err = capsys.readouterr().err.strip()
    assert "explains the markers alike" in err and "turning fast" in err
    assert "\n" not in err and "Traceback" not in err


def test_a_missing_recording_is_one_line(tmp_path, capsys):
    assert main(["readout", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(tmp_path / "none") in err and "\n" not in err
