"""Marker trajectories of a finished run, for C3D and OpenSim TRC (``wristtrack export``).

A run folder holds poses.csv (the wrist pose relative to W0 per frame) and summary.json (the
hand layout used). The six markers are rebuilt from them: marker k at ``R @ m_k + p`` in W0,
NaN in frames without an estimate, so the exports leave those frames as gaps.

Both formats assume one uniform sampling rate: it is 1 / the median frame interval. A
recording whose timing is irregular is not resampled (that would invent samples); the actual
timestamps go into the TRC Time column and ``MarkerTrajectories.irregular`` tells the caller
to warn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wristtrack.errors import ConfigError, InputError
from wristtrack.geometry import matrix_from_quat
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.markers.formats import FILE_NAMES, check_format, write_markers
from wristtrack.io.markers.trajectories import IRREGULAR_FRACTION, MarkerTrajectories, frame_rate
from wristtrack.io.run_folder import read_run


def marker_positions(R: np.ndarray, p: np.ndarray, layout_points: np.ndarray) -> np.ndarray:
    """(N, K, 3) marker positions ``R_i @ m_k + p_i`` from poses (N,3,3), (N,3) and layout (K,3).

    NaN poses give NaN markers.
    """
    return np.einsum("nij,kj->nki", R, layout_points) + p[:, None, :]


def markers_from_run(run_dir: str | Path) -> MarkerTrajectories:
    """Marker trajectories of a run folder (poses.csv + summary.json); one-line InputErrors."""
    run = Path(run_dir)
    cols, summary = read_run(run)
    poses_path, summary_path = run / "poses.csv", run / "summary.json"
    hand = summary.get("hand_layout")
    if hand is None:
        raise InputError(
            f"{summary_path} holds no hand layout (the run never initialised?); nothing to export"
        )
    try:
        layout = HandLayout.from_dict(hand, source=f"{summary_path} hand_layout")
    except ConfigError as exc:
        raise InputError(str(exc)) from None
    times = cols["timestamp"]
    rate, irregular = frame_rate(times, str(poses_path))
    q = np.column_stack([cols[c] for c in ("qw", "qx", "qy", "qz")])
    p = np.column_stack([cols[c] for c in ("tx", "ty", "tz")])
    ok = np.isfinite(q).all(axis=1) & np.isfinite(p).all(axis=1)
    if not ok.any():
        raise InputError(
            f"{poses_path}: no frame has a pose estimate (the wrist was never tracked); "
            "nothing to export"
        )
    R = np.full((len(times), 3, 3), np.nan)
    R[ok] = matrix_from_quat(q[ok])
    p = np.where(ok[:, None], p, np.nan)
    return MarkerTrajectories(
        names=MARKER_NAMES,
        frames=cols["frame"].astype(int),
        times=times,
        xyz=marker_positions(R, p, layout.points),
        rate=rate,
        irregular=irregular,
        source=str(run),
    )


def export_run(
    run_dir: str | Path, fmt: str, out: str | Path | None = None, units: str = "mm"
) -> tuple[Path, MarkerTrajectories]:
    """Export a run folder's markers as ``fmt``; ``out`` defaults to RUN_DIR/markers.<fmt>."""
    check_format(fmt)
    traj = markers_from_run(run_dir)
    if out is None:
        out = Path(run_dir) / FILE_NAMES[fmt]
    return write_markers(traj, fmt, out, units), traj


def timing_warning(traj: MarkerTrajectories) -> str:
    """The one-line warning for irregular timing ('' when the timing is regular)."""
    if not traj.irregular:
        return ""
    return (
        f"warning: {traj.source}: frame timing is irregular (intervals differ from the median "
        f"by more than {IRREGULAR_FRACTION:.0%}); exports use {traj.rate:.6g} Hz = 1/median "
        "interval, the TRC Time column keeps the actual timestamps"
    )
