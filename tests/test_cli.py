"""The command line: the demo prints real errors; bad arguments give one line and exit != 0."""

import subprocess
import sys

from wristtrack.cli import main


def test_demo_prints_errors_for_a_scenario(capsys):
    assert main(["demo", "--scenario", "deviation"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("deviation"))
    pos, rot = (float(v) for v in row.split()[2:4])
    assert 0 < pos < 3.0 and 0 < rot < 1.5


def test_unknown_scenario_is_one_line_without_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "wristtrack.cli", "demo", "--scenario", "nope"],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown scenario 'nope'" in lines[0]
