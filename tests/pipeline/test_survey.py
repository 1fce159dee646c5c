"""``wristtrack track`` without hand.json: a first pass surveys the layout, a second tracks with
it. Truth: the renderer's hand (the default layout) and poses; an uninterrupted run for
--resume."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from wristtrack.cli import main
from wristtrack.hand import HandLayout
from wristtrack.io.open import open_recording
from wristtrack.io.run_folder import SURVEYED_HAND
from wristtrack.pipeline.checkpoint import CHECKPOINT_FILE, CheckpointMismatch
from wristtrack.pipeline.track import track_recording


@pytest.fixture(scope="module", autouse=True)
def _brief_priming(briefly_primed):
    """Interrupts part-way need a priming shorter than these recordings (conftest)."""
    with briefly_primed():
        yield


@pytest.fixture(scope="module")
def rec(rendered):
    folder = rendered("no_hand", seed=11, duration=3.0)
    assert not (folder / "hand.json").exists()
    return folder


@pytest.fixture(scope="module")
def runs(rec, tmp_path_factory):
    """The recording tracked as it comes (surveyed) and with --no-survey."""
    root = tmp_path_factory.mktemp("survey")
    out = {}
    for name, extra in (("surveyed", []), ("single", ["--no-survey"])):
        argv = ["track", str(rec), "--out", str(root / name), "--no-progress", "--no-report"]
        assert main(argv + extra) == 0
        assert main(["evaluate", str(root / name), "--truth", str(rec / "truth.csv")]) == 0
        out[name] = root / name
    return out


def _json(path):
    return json.loads(path.read_text())


def test_the_surveyed_layout_is_written_used_and_closer_to_the_hand(runs, check_run):
    surveyed, single = runs["surveyed"], runs["single"]
    summary = _json(surveyed / "summary.json")
    assert summary["settings"]["hand_layout_from"].startswith("surveyed")
    layout = HandLayout.load(surveyed / SURVEYED_HAND)  # hand.json's format
    np.testing.assert_allclose(HandLayout.from_dict(summary["hand_layout"]).points, layout.points)
    assert not (single / SURVEYED_HAND).exists()
    still = HandLayout.from_dict(_json(single / "summary.json")["hand_layout"])
    assert _json(single / "summary.json")["settings"]["hand_layout_from"] == "still start"
    truth = HandLayout.default().points  # what the renderer put on the hand
    # the heights the still start took from depth, surveyed by the turning hand
    assert (np.abs(layout.points - truth)[:, 2].max()
            < 0.5 * np.abs(still.points - truth)[:, 2].max())
    better = _json(surveyed / "evaluation.json")["orientation_rmse_deg"]
    assert better < _json(single / "evaluation.json")["orientation_rmse_deg"]
    proc = subprocess.run([sys.executable, str(check_run), str(surveyed)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout
    assert main(["report", str(surveyed)]) == 0  # the report says where the layout came from
    page = (surveyed / "report.html").read_text()
    assert "Hand layout" in page and "surveyed over the recording" in page


def test_a_recording_with_hand_json_is_tracked_once(rec, tmp_path):
    given = tmp_path / "hand.json"
    given.write_text(json.dumps(HandLayout.default().to_dict()))
    out = tmp_path / "run"
    argv = ["track", str(rec), "--out", str(out), "--hand", str(given), "--no-progress",
            "--no-report"]
    assert main(argv) == 0
    assert _json(out / "summary.json")["settings"]["hand_layout_from"] == "hand.json"
    assert not (out / SURVEYED_HAND).exists()


@pytest.mark.parametrize("nth", [1, 2], ids=["first pass", "second pass"])
def test_an_interrupted_survey_resumes_to_the_uninterrupted_result(rec, runs, tmp_path, nth,
                                                                   interrupt_at):
    out = tmp_path / "run"
    with open_recording(rec) as recording:
        interrupt_at(recording, 40, nth)  # nth 2: in the second pass
        with pytest.raises(KeyboardInterrupt):
            track_recording(recording, out, progress=False, checkpoint_every=15)
    assert (out / CHECKPOINT_FILE).is_file()
    assert (out / SURVEYED_HAND).exists() == (nth == 2)
    with open_recording(rec) as recording:
        track_recording(recording, out, progress=False, resume=True)
    reference = runs["surveyed"]
    assert (out / "poses.csv").read_bytes() == (reference / "poses.csv").read_bytes()
    assert (out / SURVEYED_HAND).read_bytes() == (reference / SURVEYED_HAND).read_bytes()
    ours, theirs = _json(out / "summary.json"), _json(reference / "summary.json")
    assert ours["range_of_motion"] == theirs["range_of_motion"]
    assert ours["hand_layout"] == theirs["hand_layout"]


def test_a_run_stopped_between_the_passes_resumes_with_the_second(rec, runs, tmp_path):
    """The first pass complete and its layout written, the second not begun: --resume runs
    the second (not 'already complete' on the first pass's summary)."""
    out = tmp_path / "run"
    with open_recording(rec) as recording:
        track_recording(recording, out, progress=False, survey=False)
    (out / SURVEYED_HAND).write_bytes((runs["surveyed"] / SURVEYED_HAND).read_bytes())
    with open_recording(rec) as recording:
        summary = track_recording(recording, out, progress=False, resume=True)
    assert summary["settings"]["hand_layout_from"].startswith("surveyed")
    assert (out / "poses.csv").read_bytes() == (runs["surveyed"] / "poses.csv").read_bytes()


def test_resuming_the_second_pass_with_no_survey_is_refused_and_keeps_it(rec, runs, tmp_path,
                                                                        interrupt_at):
    out = tmp_path / "run"
    with open_recording(rec) as recording:
        interrupt_at(recording, 40, 2)
        with pytest.raises(KeyboardInterrupt):
            track_recording(recording, out, progress=False, checkpoint_every=15)
    with open_recording(rec) as recording, pytest.raises(CheckpointMismatch,
                                                         match="hand layout"):
        track_recording(recording, out, progress=False, resume=True, survey=False)
    with open_recording(rec) as recording:
        track_recording(recording, out, progress=False, resume=True)
    assert (out / "poses.csv").read_bytes() == (runs["surveyed"] / "poses.csv").read_bytes()


def test_a_live_session_without_hand_json_writes_the_surveyed_layout(rec, runs, tmp_path):
    """Live: tracked once with the still start's layout (the camera cannot be read twice), the
    survey written for the subject's next session."""
    out = tmp_path / "live"
    assert main(["track", "--live", f"replay:{rec}", "--out", str(out), "--no-report"]) == 0
    summary = _json(out / "summary.json")
    live = HandLayout.load(out / SURVEYED_HAND)
    assert summary["hand_layout_surveyed"] == live.to_dict()
    still = HandLayout.from_dict(summary["hand_layout"])
    assert summary["settings"]["hand_layout_from"] == "still start"
    truth = HandLayout.default().points
    assert (np.abs(live.points - truth)[:, 2].max()
            < 0.5 * np.abs(still.points - truth)[:, 2].max())
    assert main(["report", str(out)]) == 0
    assert "surveyed over the session for the next one" in (out / "report.html").read_text()
