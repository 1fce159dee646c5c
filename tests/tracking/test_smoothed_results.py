"""The tracker's results smoothed track by track, against the simulator's ground truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wristtrack.sim.motion import SCENARIOS
from wristtrack.sim.scenario_run import score_run, track_scenario
from wristtrack.tracking.smoothed_results import smooth_results, track_segments
from wristtrack.tracking.tracker import Status, TrackerConfig


@pytest.mark.parametrize("name", SCENARIOS)
def test_smoothing_reduces_error_on_every_scenario(name):
    config = TrackerConfig()
    run = track_scenario(name, config, seed=2)
    smoothed = smooth_results(run.model, run.results, config.ukf)
    after = score_run(name, run.truth, run.frames, smoothed).errors
    assert after.orientation_rmse_deg < 0.85 * run.errors.orientation_rmse_deg
    assert after.position_rmse_mm < 0.85 * run.errors.position_rmse_mm
    # the last frame has no future: smoothed = filtered there
    last = run.results[-1]
    np.testing.assert_allclose(smoothed[-1].R, last.R, atol=1e-12)
    # the smoothed covariance is never larger than the filtered one
    for r, s in zip(run.results[::20], smoothed[::20], strict=True):
        if r.has_estimate:
            assert np.trace(s.cov) <= np.trace(r.cov) + 1e-12
            assert np.all(np.linalg.eigvalsh(s.cov) > 0)


def test_each_track_is_smoothed_on_its_own():
    config = TrackerConfig()
    run = track_scenario("reach", config, seed=0)
    results = list(run.results)
    # break the run in two: a gap of frames without estimate, then a track of its own
    gap = range(60, 64)
    for i in gap:
        results[i] = replace(results[i], status=Status.LOST, x=None, cov=None)
    # (the run has its own splits too: where the still start moves W0, tracking/neutral.py)
    last_id = max(r.track_id for r in results[:60])
    for i in range(64, len(results)):
        results[i] = replace(results[i], track_id=last_id + 1)
    segments = track_segments(results)
    assert segments[-2][-1] == 59 and (segments[-1][0], segments[-1][-1]) == (64, len(results) - 1)
    smoothed = smooth_results(run.model, results, config.ukf)
    for i in gap:
        assert smoothed[i] is results[i]
    # the end of the first track has no future inside its track: unchanged by the smoother
    np.testing.assert_allclose(smoothed[59].p, results[59].p, atol=1e-12)
    assert not np.allclose(smoothed[30].p, results[30].p, atol=1e-9)
