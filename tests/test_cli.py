"""The command line: the demo runs the main job end to end; bad arguments give one line."""

import json
import subprocess
import sys

from wristtrack.cli import main


def test_demo_renders_tracks_and_scores_the_default_recording(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "orientation RMSE" in out and "outputs:" in out
    runs = list(tmp_path.glob("run-*"))
    assert len(runs) == 1
    result = json.loads((runs[0] / "evaluation.json").read_text())
    assert result["orientation_rmse_deg"] < 2.0 and result["position_rmse_mm"] < 5.0
    assert abs(result["peak_speed_error_pct"]) < 5.0  # the reach's peak speed
    # a second run reuses the rendered recording
    assert main(["demo", "--out", str(tmp_path), "--no-progress"]) == 0
    assert "rendering" not in capsys.readouterr().out


def test_unknown_scenario_is_one_line_without_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "wristtrack.cli", "simulate", str(tmp_path / "x"), "--scenario",
         "nope"],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "nope" in lines[0]


def test_argument_errors_are_one_line_naming_the_help(tmp_path, capsys):
    """argparse's own errors (a required option missing, a value out of range, an unknown
    command) come as one line, as the commands' own do, pointing at the command's --help
    instead of printing the whole usage first."""
    cases = ((["track", str(tmp_path)], "wristtrack track: error: the following arguments are "
              "required: --out (options: wristtrack track --help)"),
             (["track", str(tmp_path), "--out", str(tmp_path / "o"), "--coast-limit", "-3", "1"],
              "argument --coast-limit: -3 is not a number >= 0"),
             (["simulate", str(tmp_path / "x"), "--seed", "-1"],
              "argument --seed: -1 is not a whole number >= 0"),
             (["nosuch"], "wristtrack: error: argument command: invalid choice: 'nosuch'"))
    for argv, expect in cases:
        try:
            main(argv)
        except SystemExit as exc:
            assert exc.code == 2
        else:
            raise AssertionError(f"{argv} was accepted")
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expect in err and "usage:" not in err, err
