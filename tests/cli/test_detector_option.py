"""`wristtrack track --detector paper`: a valid run on the paper's detector, recorded in the
settings, refused on --resume with another detector, and one line for an unknown name."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from wristtrack.cli import main
from wristtrack.io.open import open_recording
from wristtrack.pipeline.track import track_recording

ARGS = ("--no-progress", "--no-report")


@pytest.fixture(scope="module", autouse=True)
def _brief_priming(briefly_primed):
    """Interrupts part-way need a priming shorter than these recordings (conftest)."""
    with briefly_primed():
        yield


@pytest.fixture(scope="module")
def rec(rendered):
    return rendered("reach", seed=0, n_frames=40)  # shared with the report tests


@pytest.fixture(scope="module")
def paper_run(rec, tmp_path_factory):
    out = tmp_path_factory.mktemp("paper") / "run"
    assert main(["track", str(rec), "--out", str(out), "--detector", "paper", *ARGS]) == 0
    return out


def _one_error_line(capsys, *argv) -> tuple[int, str]:
    code = main(list(argv))
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return code, err


def test_track_with_the_paper_detector_is_a_valid_run(rec, paper_run, check_run):
    checked = subprocess.run([sys.executable, str(check_run), str(paper_run)],
                             capture_output=True, text=True, check=False)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    summary = json.loads((paper_run / "summary.json").read_text())
    assert summary["settings"]["detector"] == "paper"
    assert summary["settings"]["model"] == "default"  # the detector alone changes
    from wristtrack.analysis.evaluate import evaluate

    # the slow clean reach is tracked on the paper's blobs too (0.35 deg, 1.5 mm measured);
    # the second of two frames whose blobs it missed has no pose (its prediction, 21 mm off,
    # is too uncertain to report: TrackerConfig.coast_rot_sigma_deg)
    r = evaluate(paper_run / "poses.csv", rec / "truth.csv")
    assert r["coverage"] >= 0.97
    assert r["orientation_rmse_deg"] < 3.0 and r["position_rmse_mm"] < 10.0


def test_resume_with_another_detector_is_refused(rec, paper_run, tmp_path, capsys,
                                                 interrupt_at):
    out = tmp_path / "run"
    with open_recording(rec) as recording:
        interrupt_at(recording, 20)
        with pytest.raises(KeyboardInterrupt):
            track_recording(recording, out, progress=False, checkpoint_every=10,
                            detector="paper")
    code, err = _one_error_line(capsys, "track", str(rec), "--out", str(out), "--resume", *ARGS)
    assert code == 2 and "settings (detector)" in err
    # with the same detector it continues to the uninterrupted run's result
    assert main(["track", str(rec), "--out", str(out), "--resume", "--detector", "paper",
                 *ARGS]) == 0
    assert (out / "poses.csv").read_bytes() == (paper_run / "poses.csv").read_bytes()


def test_unknown_detector_and_live_paper_detector_are_one_line(rec, tmp_path, capsys):
    code, err = _one_error_line(capsys, "track", str(rec), "--out", str(tmp_path / "a"),
                                "--detector", "papr", *ARGS)
    assert code == 2 and "unknown detector 'papr': choose from default, paper" in err
    assert not (tmp_path / "a").exists()
    code, err = _one_error_line(capsys, "track", "--live", "replay:" + str(rec), "--out",
                                str(tmp_path / "b"), "--detector", "paper", *ARGS)
    assert code == 2 and "--detector paper cannot be used with --live" in err
