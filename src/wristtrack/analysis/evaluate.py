"""``wristtrack evaluate``: score a run's poses.csv against a simulated recording's truth.csv."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.analysis.pose_errors import pose_errors, rmse_net_of_constant_errors
from wristtrack.analysis.summary import AXES
from wristtrack.errors import InputError
from wristtrack.io.poses import read_poses, rows_to_poses

_MATCH_TOL_S = 1e-3  # rows are matched by timestamp within this


def match_rows(est: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> np.ndarray:
    """For each estimated row, the index of the truth row with the same timestamp (or -1)."""
    t_est, t_true = est["timestamp"], truth["timestamp"]
    if len(t_true) == 0:
        raise InputError("truth.csv has no rows")
    j = np.clip(np.searchsorted(t_true, t_est), 1, len(t_true) - 1) if len(t_true) > 1 else None
    if j is None:
        idx = np.zeros(len(t_est), int)
    else:
        left_closer = np.abs(t_true[j - 1] - t_est) <= np.abs(t_true[j] - t_est)
        idx = np.where(left_closer, j - 1, j)
    return np.where(np.abs(t_true[idx] - t_est) <= _MATCH_TOL_S, idx, -1)


def evaluate(poses_csv: str | Path, truth_csv: str | Path) -> dict[str, Any]:
    """Errors of a run against truth: pose RMSE and 95th percentiles, failure rate, coverage,
    range-of-motion error per anatomical axis and peak-speed error."""
    est, truth = read_poses(poses_csv), read_poses(truth_csv)
    if len(est["timestamp"]) == 0:
        raise InputError(f"{poses_csv} has no rows: did the run stop before its first frame?")
    idx = match_rows(est, truth)
    if (idx < 0).all():
        raise InputError(
            f"no timestamp of {poses_csv} matches {truth_csv}: is it the truth of that recording?"
        )
    keep = idx >= 0
    R_est, t_est = rows_to_poses(est)
    R_true, t_true = rows_to_poses(truth)
    R_est, t_est, R_true, t_true = R_est[keep], t_est[keep], R_true[idx[keep]], t_true[idx[keep]]
    errors = pose_errors(R_est, t_est, R_true, t_true)
    net_pos, net_rot = rmse_net_of_constant_errors(R_est, t_est, R_true, t_true)

    def angles(cols, rows):
        return np.column_stack([cols[f"{a}_deg"][rows] for a in AXES])

    a_est = angles(est, np.flatnonzero(keep))
    a_true = angles(truth, idx[keep])
    valid = np.isfinite(a_est).all(axis=1)
    rom = {}
    for k, axis in enumerate(AXES):
        if valid.any():
            r_est = np.ptp(a_est[valid, k])
            r_true = np.ptp(a_true[:, k])
            rom[axis] = {
                "range_est_deg": float(r_est),
                "range_true_deg": float(r_true),
                "range_error_deg": float(r_est - r_true),
            }
    speed_est = np.linalg.norm(np.column_stack([est[c] for c in ("vx", "vy", "vz")]), axis=1)
    speed_true = np.linalg.norm(np.column_stack([truth[c] for c in ("vx", "vy", "vz")]), axis=1)
    peak_true = float(np.nanmax(speed_true)) if np.isfinite(speed_true).any() else float("nan")
    peak_est = float(np.nanmax(speed_est)) if np.isfinite(speed_est).any() else float("nan")
    peak_error = 100.0 * (peak_est - peak_true) / peak_true if peak_true > 0 else None
    return {
        "frames_compared": int(keep.sum()),
        **{k: _num(v) for k, v in errors.as_dict().items()},
        # what a registration to a reference system (compare) leaves of them
        "position_rmse_net_of_constant_mm": _num(net_pos),
        "orientation_rmse_net_of_constant_deg": _num(net_rot),
        "rom": rom,
        "peak_speed_true_m_s": _num(peak_true),
        "peak_speed_est_m_s": _num(peak_est),
        "peak_speed_error_pct": _num(peak_error),
    }


def _num(x):
    return None if x is None or not np.isfinite(x) else float(x)


def format_report(result: dict[str, Any]) -> str:
    lines = [
        f"frames compared     {result['frames_compared']}",
        f"coverage            {100 * (result['coverage'] or 0):.1f} %",
        f"position RMSE       {_f(result['position_rmse_mm'])} mm "
        f"(95th pct {_f(result['position_p95_mm'])} mm)",
        f"orientation RMSE    {_f(result['orientation_rmse_deg'])} deg "
        f"(95th pct {_f(result['orientation_p95_deg'])} deg)",
        f"net of constant     {_f(result['position_rmse_net_of_constant_mm'])} mm, "
        f"{_f(result['orientation_rmse_net_of_constant_deg'])} deg (the mean error taken out, "
        "as a registration to a reference takes it up)",
        f"failure rate        {100 * (result['failure_rate'] or 0):.2f} % (> 10 deg or > 20 mm)",
    ]
    for axis, r in result["rom"].items():
        lines.append(
            f"RoM {axis:<15} {r['range_est_deg']:.1f} deg vs {r['range_true_deg']:.1f} "
            f"(error {r['range_error_deg']:+.2f} deg)"
        )
    lines.append(f"peak speed error    {_f(result['peak_speed_error_pct'])} %")
    return "\n".join(lines)


def _f(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"



