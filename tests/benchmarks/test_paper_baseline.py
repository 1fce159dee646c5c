"""The paper-baseline sweep (benchmarks/paper_baseline.py): tuning recordings apart from the
test recordings, the best setting is the sweep's minimum."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import paper_baseline as pb

pytestmark = pytest.mark.skipif(not pb.KTK.is_dir(), reason="../shared/realdata not found")


def test_tuning_recordings_are_recorded_motion_not_the_test_scenarios():
    runs = pb.tuning_runs()
    assert [r[0] for r in runs] == [name for name, *_ in pb.TUNING]
    for _, truth, _, _, frames in runs:
        assert len(frames) == len(truth.t) > 60
        # real recorded motion: every axis moves, unlike the one-axis test scenarios
        assert (np.ptp(np.degrees(truth.angles), axis=0) > 3.0).all()


def test_sweep_scores_each_setting_and_best_is_its_minimum():
    runs = pb.tuning_runs()[:1]
    table = pb.sweep("paper_rpy", runs, rates=(0.03, 3.0), accels=(0.1,))
    assert set(table) == {(0.03, 0.1), (3.0, 0.1)}
    assert all(np.isfinite(v[0]) and np.isfinite(v[1]) for v in table.values())
    best = pb._best(table)
    assert table[best][0] == min(v[0] for v in table.values())
