"""``track --smooth``: replace a finished run's filtered poses by smoothed ones.

The run streams filtered poses to poses.csv and filter states to filter_states.f64 as it goes
(so an interrupted run keeps them). Afterwards this module runs the unscented RTS smoother
(wristtrack.filter.smoother) over every track, keeps the filtered rows as ``poses_filtered.csv`` and
writes the smoothed rows as ``poses.csv`` (atomically), row for row: frames without an estimate
keep their row unchanged, and what the filter saw (markers, clutter, NIS) is kept too.
"""

from __future__ import annotations

import csv
import io
import math
import os
import shutil
from pathlib import Path

import numpy as np

from wristtrack.errors import InputError
from wristtrack.filter.ukf import UKFParams
from wristtrack.geometry import matrix_from_quat
from wristtrack.io.atomic import write_text_atomic
from wristtrack.io.poses import COLUMNS, pose_row, read_pose_table
from wristtrack.io.states import STATES_FILE, read_states
from wristtrack.tracking.smoothed_results import smooth_results
from wristtrack.tracking.tracker import FrameResult, Status

FILTERED_POSES = "poses_filtered.csv"
_STATUSES = {s.value: s for s in Status}

_DEFAULT_PARAMS = UKFParams()


def smooth_run(
    out: str | Path,
    model,
    params: UKFParams = _DEFAULT_PARAMS,
    side: str = "right",
    coast_limit: tuple[float, float] | None = None,
) -> list[FrameResult]:
    """Smooth the run in ``out``; returns one FrameResult per tracked frame (smoothed where it
    has an estimate, and where a prediction the filter did not report is, smoothed, within
    ``coast_limit``: smoothed_results.smooth_results) for the summary. Removes the state file
    once poses.csv is rewritten."""
    out = Path(out)
    poses_path, states_path = out / "poses.csv", out / STATES_FILE
    header, rows = read_pose_table(poses_path)
    body = list(rows)  # a last line cut short by an interruption is already dropped
    states = read_states(states_path)
    if len(states.frame) != len(body):
        raise InputError(
            f"{states_path} has {len(states.frame)} frames but poses.csv has {len(body)}; "
            "track the recording again with --smooth"
        )
    col = {name: j for j, name in enumerate(header)}
    results = [
        _filtered_result(row, col, states, k, model, side) for k, row in enumerate(body)
    ]
    tracked = [r for r in results if r is not None]
    smoothed = iter(smooth_results(model, tracked, params, coast_limit))
    out_rows = []
    summary_results = []
    for row, r in zip(body, results, strict=True):
        if r is None:  # skipped or unreadable frame: its row stays as it was
            out_rows.append(row)
            continue
        s = next(smoothed)
        summary_results.append(s)
        if s.has_estimate:
            row = pose_row(
                s.frame, s.timestamp, str(s.status), s.R_ch, s.t_ch, s.R, s.p, s.v, s.w,
                s.n_visible, s.n_clutter, s.pos_sigma_mm, s.rot_sigma_deg, s.nis, s.nis_dof,
                s.side,
            ) + row[len(COLUMNS):]
        out_rows.append(row)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(out_rows)
    # keep the filtered rows under their new name first (a second link to the same file), then
    # swap the smoothed ones in: at no moment is there no poses.csv
    filtered = out / FILTERED_POSES
    filtered.unlink(missing_ok=True)
    try:
        os.link(poses_path, filtered)
    except OSError:  # a file system without hard links
        shutil.copyfile(poses_path, filtered)
    write_text_atomic(poses_path, text.getvalue())
    states_path.unlink()
    return summary_results


def _filtered_result(row, col, states, k, model, side) -> FrameResult | None:
    """The tracker's result for poses.csv row ``row``, rebuilt from the row and the state log;
    None for a row the tracker never saw (a skipped frame)."""
    status = _STATUSES.get(row[col["status"]])
    if status is None:
        return None

    def number(name: str) -> float:
        cell = row[col[name]] if name in col else ""
        return float(cell) if cell else math.nan

    n_visible, n_clutter = int(number("n_visible")), int(number("n_clutter"))
    nis, dof = number("nis"), number("nis_dof")
    timestamp = float(row[col["timestamp"]])
    if states.track_id[k] < 0:
        return FrameResult.empty(
            int(row[col["frame"]]), timestamp, status, labels=np.empty(0, int),
            n_visible=n_visible, n_clutter=n_clutter, nis=nis,
            nis_dof=0 if math.isnan(dof) else int(dof), side=side,
        )
    x = states.x[k]
    v, w = model.velocities(x)
    # the poses as the filter wrote them: W0 changes at the end of the still start, and its
    # rows are reported against W0 as refined so far (Tracker._provisional_w0)
    R_ch, t_ch = _pose(number, "cam_q", "cam_t")
    R, p = _pose(number, "q", "t")
    return FrameResult(
        frame=int(row[col["frame"]]), timestamp=timestamp, status=status, R_ch=R_ch,
        t_ch=t_ch, R=R, p=p, v=np.asarray(v), w=np.asarray(w), cov=states.P[k],
        labels=np.empty(0, int), n_visible=n_visible, n_clutter=n_clutter, nis=nis,
        nis_dof=0 if math.isnan(dof) else int(dof), pos_sigma_mm=number("pos_sigma_mm"),
        rot_sigma_deg=number("rot_sigma_deg"), x=x, track_id=int(states.track_id[k]), side=side,
    )


def _pose(number, q: str, t: str) -> tuple[np.ndarray, np.ndarray]:
    """A rotation and translation from a row's quaternion (w, x, y, z) and translation columns
    named ``q``w.. and ``t``x.. (``number`` reads a column)."""
    quat = np.array([number(q + c) for c in "wxyz"])
    return matrix_from_quat(quat), np.array([number(t + c) for c in "xyz"])
