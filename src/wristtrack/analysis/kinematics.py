"""Kinematic measures of a run: range of motion, speeds, path length and reaching metrics.

Input is the column dict of a poses.csv (:func:`wristtrack.io.poses.read_poses`); output is a
JSON-ready dict (:func:`analyse`) that goes into summary.json under ``"kinematics"``. The numeric
core is pure NumPy functions on arrays, also used by the report figures.

The measures themselves live by job: :mod:`.motion_profiles` (velocities, speeds, the low-pass,
path length), :mod:`.range_of_motion`, :mod:`.reaches` (segmentation and per-reach metrics),
:mod:`.smoothness` (SPARC, log dimensionless jerk, movement units); their settings in
:mod:`.kinematics_settings`. This module runs them over a whole run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.analysis.kinematics_settings import KinematicsSettings
from wristtrack.analysis.motion_profiles import (
    angular_velocity_profile,
    lowpass,
    median_frame_rate,
    path_length,
    position_valid,
    velocity_profile,
)
from wristtrack.analysis.range_of_motion import ANGLE_COLUMNS, range_of_motion
from wristtrack.analysis.reaches import reach_metrics, segment_reaches
from wristtrack.errors import InputError
from wristtrack.io.poses import read_poses


def _column(columns: dict[str, np.ndarray], names: tuple[str, ...]) -> np.ndarray | None:
    if not all(n in columns for n in names):
        return None
    return np.column_stack([np.asarray(columns[n], dtype=float) for n in names])


def _series(columns: dict[str, np.ndarray], settings: KinematicsSettings) -> dict[str, np.ndarray]:
    """Time, positions, raw and analysed speed (m/s), analysed angular speed (deg/s)."""
    missing = [c for c in ("timestamp", "tx", "ty", "tz") if c not in columns]
    if missing:
        raise InputError(f"pose columns lack {', '.join(missing)}; give a poses.csv / truth.csv")
    t = np.asarray(columns["timestamp"], dtype=float).reshape(-1)
    p = _column(columns, ("tx", "ty", "tz"))
    if len(p) != len(t):
        raise InputError(f"pose columns differ in length ({len(t)} timestamps, {len(p)} rows)")
    valid = position_valid(t, p)
    velocity = velocity_profile(t, p, _column(columns, ("vx", "vy", "vz")))
    raw_speed = np.linalg.norm(velocity, axis=1)
    q = _column(columns, ("qw", "qx", "qy", "qz"))
    omega = (
        angular_velocity_profile(t, q, _column(columns, ("wx", "wy", "wz")))
        if q is not None
        else np.full((len(t), 3), np.nan)
    )
    if settings.lowpass_hz > 0:
        # Tracking noise rectified by |.| would otherwise hold the speed above the 2 % threshold
        # at rest, split reaches into spurious units and add jitter to the path length.
        velocity = lowpass(t, velocity, settings.lowpass_hz)
        omega = lowpass(t, omega, settings.lowpass_hz)
        p = lowpass(t, p, settings.lowpass_hz)
    return {
        "t": t,
        "valid": valid,
        "p": p,
        "raw_speed": raw_speed,
        "speed": np.linalg.norm(velocity, axis=1),
        "angular_speed": np.degrees(np.linalg.norm(omega, axis=1)),
    }


def speed_series(
    columns: dict[str, np.ndarray], settings: KinematicsSettings | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(as tracked, as analysed) wrist speed (N,), m/s, of poses.csv columns: |v| (differences
    of the positions where v is unknown), and that after the low-pass, the speed
    :func:`analyse` segments and measures the reaches on."""
    series = _series(columns, settings or KinematicsSettings())
    return series["raw_speed"], series["speed"]


def analyse(
    columns: dict[str, np.ndarray], settings: KinematicsSettings | None = None
) -> dict[str, Any]:
    """Kinematics of a run from poses.csv columns (read_poses); a JSON-ready dict (no NaN)."""
    settings = settings or KinematicsSettings()
    series = _series(columns, settings)
    t, p, valid, speed, rate = (
        series[k] for k in ("t", "p", "valid", "speed", "angular_speed")
    )
    angles = _column(columns, ANGLE_COLUMNS)
    fs = median_frame_rate(t, valid)
    reaches = []
    if fs is not None:
        for index, (s, e) in enumerate(segment_reaches(t, speed, settings)):
            reaches.append({"index": index, **reach_metrics(t, p, speed, s, e, fs, settings)})
    known_t = t[np.isfinite(t)]

    def peak_mean(x: np.ndarray) -> tuple[float | None, float | None]:
        x = x[np.isfinite(x)]
        return (float(x.max()), float(x.mean())) if x.size else (None, None)

    v_peak, v_mean = peak_mean(speed)
    w_peak, w_mean = peak_mean(rate)
    return {
        "settings": settings.to_dict(),
        "range_of_motion": range_of_motion(
            angles if angles is not None else np.full((len(t), 3), np.nan)
        ),
        "speed": {"peak_m_s": v_peak, "mean_m_s": v_mean},
        "angular_speed": {"peak_deg_s": w_peak, "mean_deg_s": w_mean},
        "path_length_m": path_length(p),
        "duration_s": float(known_t[-1] - known_t[0]) if known_t.size else 0.0,
        "frame_rate_hz": fs,
        "reaches": reaches,
        "reach_summary": {
            "count": len(reaches),
            "mean_peak_speed_m_s": (
                float(np.mean([r["peak_speed_m_s"] for r in reaches])) if reaches else None
            ),
            "mean_movement_time_s": (
                float(np.mean([r["movement_time_s"] for r in reaches])) if reaches else None
            ),
        },
    }


_NEEDED = (
    "timestamp", "tx", "ty", "tz", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz",
    *ANGLE_COLUMNS,
)


def analyse_file(
    poses_csv: str | Path, settings: KinematicsSettings | None = None
) -> dict[str, Any]:
    """:func:`analyse` of a poses.csv (or truth.csv) read back from disk."""
    # Only the columns analyse() needs: a long run's poses.csv read whole would break the
    # pipeline's flat memory.
    columns = read_poses(poses_csv, columns=_NEEDED)
    try:
        return analyse(columns, settings)
    except InputError as exc:
        raise InputError(f"{poses_csv}: {exc}") from None


def format_reaches(kinematics: dict[str, Any]) -> str:
    """One line for the console: number of reaches, mean peak speed and movement time."""
    s = kinematics["reach_summary"]
    if not s["count"]:
        return "  reaches    none detected"
    return (
        f"  reaches    {s['count']} detected: mean peak speed {s['mean_peak_speed_m_s']:.3f} m/s, "
        f"mean movement time {s['mean_movement_time_s']:.2f} s"
    )
