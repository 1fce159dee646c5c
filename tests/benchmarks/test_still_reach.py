"""The still-start-and-reach benchmark's own arithmetic, against hand-built angles."""

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.still_reach import (
    BUDGET,
    COMBINED,
    TRACKERS,
    _runs,
    axis_errors,
    budget_lines,
    summary_lines,
)
from wristtrack.geometry import matrix_from_wrist_angles


def _results(angles_deg: np.ndarray, missing: tuple[int, ...] = ()) -> list:
    R = matrix_from_wrist_angles(*np.radians(angles_deg).T)
    R[list(missing)] = np.nan  # frames without an estimate
    return [SimpleNamespace(R=r) for r in R]


def test_range_errors_split_the_turning_axis_from_the_still_ones():
    """Truth: flexion 0 -> -20 deg, the others still. The estimate overshoots flexion by 0.5 deg
    and wanders 0.3 deg in deviation and 0.8 deg in pronation (peak to peak): errors 0.5 and the
    worse still axis, 0.8. A frame without an estimate (a 5 deg outlier's place) is left out."""
    true = np.zeros((5, 3))
    true[:, 1] = [0.0, -5.0, -10.0, -15.0, -20.0]
    est = true.copy()
    est[4, 1] = -20.5
    est[:, 0] = [0.0, 0.1, -0.2, 0.1, 0.0]
    est[:, 2] = [0.3, -0.5, 0.0, 5.0, 0.2]
    truth = SimpleNamespace(angles=np.radians(true))
    turning, still = axis_errors(_results(est, missing=(3,)), truth)
    assert turning == pytest.approx(0.5, abs=1e-9)
    assert still == pytest.approx(0.8, abs=1e-9)
    assert np.isnan(axis_errors(_results(est, missing=(0, 1, 2, 3)), truth)[1])


def test_summary_says_whether_the_still_axes_meet_the_targets():
    def acc(filtered: float, smoothed: float) -> dict:
        return {COMBINED: {"default": {"still": filtered},
                           "default, smoothed (offline)": {"still": smoothed}}}

    assert summary_lines(acc(0.9, 0.6))[0].endswith("met.")
    assert "**not met**" in summary_lines(acc(0.9, 0.8))[0]  # smoothed above 0.7
    assert "**not met**" in summary_lines(acc(2.05, 0.6))[0]
    assert summary_lines({}) == []


def test_the_error_budget_rows_run_under_every_effect_only():
    """The corrected blobs' rows join the combined condition's; the others keep the trackers."""
    assert set(_runs("clean")) == set(TRACKERS)
    assert set(_runs(COMBINED)) == set(TRACKERS) | set(BUDGET)
    assert {data for data, _ in BUDGET.values()} == {
        "pixels exact", "depth exact", "pixels and depth exact"}
    assert all(_runs(COMBINED)[label][0] is None for label in TRACKERS)


def test_budget_lines_set_each_correction_beside_the_blobs_as_detected():
    rows = {"default": {"still": 2.1}, "default, pixels exact": {"still": 1.0},
            "default, depth exact": {"still": 1.6},
            "default, pixels and depth exact": {"still": 0.9}}
    (line,) = budget_lines({COMBINED: rows})
    assert line == ("- Every effect, default: still axes 2.10 deg as detected; 1.00 with exact "
                    "pixels, 1.60 with exact depth, 0.90 with both.")
    assert budget_lines({COMBINED: {"default": {"still": 2.1}}}) == []
