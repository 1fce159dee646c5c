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

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wristtrack.errors import ConfigError, InputError
from wristtrack.geometry import matrix_from_quat
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.run_folder import read_run

FORMATS = {"c3d": "markers.c3d", "trc": "markers.trc"}
UNITS = {"mm": 1000.0, "m": 1.0}
# Timing counts as irregular when some frame interval differs from the median by more than this
# fraction of it (dropped frames, jitter of a USB camera, a skipped backwards timestamp).
IRREGULAR_FRACTION = 0.10


@dataclass(frozen=True)
class MarkerTrajectories:
    """Marker positions over a run, in W0, metres; NaN rows where there is no estimate."""

    names: tuple[str, ...]
    frames: np.ndarray  # (N,) frame numbers of poses.csv (0-based)
    times: np.ndarray  # (N,) s, as recorded
    xyz: np.ndarray  # (N, K, 3) metres in W0
    rate: float  # Hz, 1 / median frame interval
    irregular: bool  # frame intervals spread more than IRREGULAR_FRACTION of the median
    source: str  # the run folder

    @property
    def valid(self) -> np.ndarray:
        """(N,) frames that have an estimate."""
        return np.isfinite(self.xyz).all(axis=(1, 2))

    def in_units(self, units: str) -> np.ndarray:
        """(N, K, 3) positions in ``units`` ("mm" or "m")."""
        if units not in UNITS:
            raise ConfigError(f"unknown units {units!r}; choose one of {', '.join(UNITS)}")
        return self.xyz * UNITS[units]


def marker_positions(R: np.ndarray, p: np.ndarray, layout_points: np.ndarray) -> np.ndarray:
    """(N, K, 3) marker positions ``R_i @ m_k + p_i`` from poses (N,3,3), (N,3) and layout (K,3).

    NaN poses give NaN markers.
    """
    return np.einsum("nij,kj->nki", R, layout_points) + p[:, None, :]


def frame_rate(times: np.ndarray, where: str = "poses.csv") -> tuple[float, bool]:
    """(rate in Hz = 1 / median interval, whether the timing is irregular) of timestamps (N,)."""
    times = np.asarray(times, dtype=float)
    if times.size < 2 or not np.isfinite(times).all():
        raise InputError(
            f"{where}: need at least two frames with finite timestamps to know the frame rate, "
            f"got {times.size}; export a longer run"
        )
    dt = np.diff(times)
    median = float(np.median(dt))
    if not median > 0:
        raise InputError(
            f"{where}: timestamps do not increase (median frame interval {median} s); "
            "check the recording's timestamps"
        )
    irregular = bool(np.max(np.abs(dt - median)) > IRREGULAR_FRACTION * median)
    return 1.0 / median, irregular


def load_run(run_dir: str | Path) -> MarkerTrajectories:
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


def export_markers(
    traj: MarkerTrajectories, fmt: str, out: str | Path, units: str = "mm"
) -> Path:
    """Write ``traj`` as ``fmt`` ("c3d" or "trc") to the file ``out``; returns its path."""
    out = Path(out)
    if fmt == "c3d":
        from wristtrack.io.markers.c3d import write_c3d

        write_c3d(out, traj, units)
    elif fmt == "trc":
        from wristtrack.io.markers.trc import write_trc

        write_trc(out, traj, units)
    else:
        raise ConfigError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")
    return out


def export_run(
    run_dir: str | Path, fmt: str, out: str | Path | None = None, units: str = "mm"
) -> tuple[Path, MarkerTrajectories]:
    """Export a run folder's markers as ``fmt``; ``out`` defaults to RUN_DIR/markers.<fmt>."""
    if fmt not in FORMATS:
        raise ConfigError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")
    traj = load_run(run_dir)
    if out is None:
        out = Path(run_dir) / FORMATS[fmt]
    return export_markers(traj, fmt, out, units), traj


def timing_warning(traj: MarkerTrajectories) -> str:
    """The one-line warning for irregular timing ('' when the timing is regular)."""
    if not traj.irregular:
        return ""
    return (
        f"warning: {traj.source}: frame timing is irregular (intervals differ from the median "
        f"by more than {IRREGULAR_FRACTION:.0%}); exports use {traj.rate:.6g} Hz = 1/median "
        "interval, the TRC Time column keeps the actual timestamps"
    )
