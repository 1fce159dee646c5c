"""Frames without markers: the prediction is reported only while it is worth a pose, filtered
and smoothed.

Oracles: the simulated ground truth, and the tracker's own last measured uncertainty (the
bounds of TrackerConfig.coast_rot_sigma_deg / coast_pos_sigma_mm are on what a prediction adds
to it).
"""

import argparse
import math

import numpy as np
import pytest

from wristtrack.cli.options import add_tracker_options, tracker_config
from wristtrack.geometry import rotation_distance
from wristtrack.tracking.smoothed_results import smooth_results, track_segments
from wristtrack.tracking.tracker import Status, TrackerConfig


def _angle_error(r, truth, k: int) -> float:
    return float(np.degrees(rotation_distance(r.R, truth.R_rel[k])))


def test_a_prediction_is_reported_while_it_adds_little_then_no_pose_then_the_same_track(
        hidden_markers):
    """Hidden for a third of a second: the first frames report the prediction, within the
    bounds and near the truth; the rest report no pose (they had been up to tens of degrees
    off: the control below); when the markers return the same track takes them back, without a
    fresh start, its first update iterated as after a gap (a single update from the widened prior
    had been 6.3 deg off)."""
    cfg, (start, end) = TrackerConfig(), hidden_markers.hidden
    truth, results, _ = hidden_markers.run(cfg)
    last = results[start - 1]
    assert last.status == Status.TRACKING
    hidden = results[start:end]
    coasted = [r for r in hidden if r.status == Status.COASTING]
    assert 1 <= len(coasted) <= 4 and hidden[: len(coasted)] == coasted
    for k, r in enumerate(coasted, start=start):
        assert r.rot_sigma_deg**2 - last.rot_sigma_deg**2 <= cfg.coast_rot_sigma_deg**2
        assert r.pos_sigma_mm**2 - last.pos_sigma_mm**2 <= cfg.coast_pos_sigma_mm**2
        assert _angle_error(r, truth, k) < 3 * r.rot_sigma_deg
    rest = hidden[len(coasted):]
    assert all(r.status == Status.LOST and np.isnan(r.R).all() for r in rest)
    back = results[end]
    assert back.status == Status.TRACKING and back.track_id == last.track_id
    assert _angle_error(back, truth, end) < 2.0


def test_without_the_bounds_the_hidden_frames_drift_far_off(hidden_markers):
    """The control: every prediction reported (``--coast-limit inf inf``, the paper's way), the
    hidden frames end more than 5 degrees from the truth, so the test above measures the
    bounds."""
    start, end = hidden_markers.hidden
    truth, results, _ = hidden_markers.run(TrackerConfig(coast_rot_sigma_deg=math.inf,
                                                         coast_pos_sigma_mm=math.inf))
    hidden = results[start:end]
    assert all(r.status == Status.COASTING for r in hidden)
    assert _angle_error(hidden[-1], truth, end - 1) > 5.0


def test_smoothed_the_track_runs_across_and_its_ends_are_reported(hidden_markers):
    """Offline (``--smooth``): the frames the filter predicted and did not report keep the track
    one across the gap, and those whose smoothed uncertainty is within the same bounds, against
    the last tracked frame's, are reported (coasting), near the truth: the frames after the gap
    pin down its end too. Where the smoothed prediction is still too uncertain there is still
    no pose, and without the bounds (None) none is reported."""
    cfg, (start, end) = TrackerConfig(), hidden_markers.hidden
    truth, results, tracker = hidden_markers.run(cfg)
    assert any(s[0] < start and s[-1] >= end for s in track_segments(results))
    smoothed = smooth_results(tracker.model, results, cfg.ukf, cfg.coast_limit)
    hidden = range(start, end)
    shown = [k for k in hidden if smoothed[k].status == Status.COASTING]
    filtered = [k for k in hidden if results[k].status == Status.COASTING]
    assert set(filtered) < set(shown) and shown[-1] == end - 1  # the end, too
    assert any(smoothed[k].status == Status.LOST for k in hidden)  # the middle: no pose
    tracked = smoothed[start - 1]
    for k in shown:
        s = smoothed[k]
        assert s.rot_sigma_deg**2 - tracked.rot_sigma_deg**2 <= cfg.coast_rot_sigma_deg**2
        assert _angle_error(s, truth, k) < 3 * s.rot_sigma_deg
    plain = smooth_results(tracker.model, results, cfg.ukf)
    assert [plain[k].status for k in hidden] == [results[k].status for k in hidden]


@pytest.mark.parametrize(("argv", "bounds"), [
    ([], (2.0, 10.0)),
    (["--coast-limit", "1.5", "4"], (1.5, 4.0)),
    (["--coast-limit", "inf", "inf"], (math.inf, math.inf)),
    (["--model", "paper"], (math.inf, math.inf)),
])
def test_the_option_sets_the_bounds(argv, bounds):
    parser = argparse.ArgumentParser()
    add_tracker_options(parser)
    cfg = tracker_config(parser.parse_args(argv))
    assert (cfg.coast_rot_sigma_deg, cfg.coast_pos_sigma_mm) == bounds


@pytest.mark.parametrize("bad", [["-1", "3"], ["nan", "3"], ["a", "3"]])
def test_a_bound_that_is_no_number_at_or_above_zero_is_refused(bad, capsys):
    parser = argparse.ArgumentParser()
    add_tracker_options(parser)
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["--coast-limit", *bad])
    assert exc.value.code == 2
    assert "--coast-limit" in capsys.readouterr().err
