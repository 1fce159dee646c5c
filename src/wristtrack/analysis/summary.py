"""summary.json of a run (DESIGN.md section 3): accumulated frame by frame in constant memory."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wristtrack import __version__
from wristtrack.geometry import ISB_WRIST_SEQUENCE, quat_from_matrix, wrist_angles

AXES = ("deviation", "flexion", "pronation")

CONVENTIONS = {
    "angles": (
        f"ISB wrist (Wu et al. 2005): intrinsic {'-'.join(ISB_WRIST_SEQUENCE)} decomposition of "
        "the hand rotation relative to W0 in hand axes: flexion(+)/extension(-) about Y, then "
        "ulnar(+)/radial(-) deviation about the floating Z, then pronation(+)/supination(-) "
        "about X; for a right hand (thumb on +Y) the Z and X angles of the decomposition are "
        "negated so that the signs mean the same on both hands"
    ),
    "side": "right",
    "neutral": "W0 = the hand frame at the first initialisation (hand still, neutral posture)",
    "hand_frame": "origin WRIST marker; +X towards MCP3; +Z out of the back of the hand; Y = Z x X",
    "units": "metres, seconds, radians; *_deg columns and summary angles in degrees",
    "velocities": "v and w in W0 (m/s, rad/s)",
}


class SummaryAccumulator:
    """Range of motion, speeds, path length and frame counts over the frames of a run."""

    def __init__(self) -> None:
        self.frames = 0
        self.status_counts: dict[str, int] = {}
        self.clutter = 0
        self.first_time = self.last_time = math.nan
        self.angle_min = np.full(3, np.inf)
        self.angle_max = np.full(3, -np.inf)
        self.angle_start = np.full(3, np.nan)
        self.angle_end = np.full(3, np.nan)
        self.peak_speed = 0.0
        self.speed_sum = 0.0
        self.speed_n = 0
        self.path = 0.0
        self._last_p: np.ndarray | None = None
        self.side: str | None = None

    def add(self, result) -> None:
        """Account for one tracker.FrameResult."""
        self.frames += 1
        key = str(result.status)
        self.status_counts[key] = self.status_counts.get(key, 0) + 1
        self.clutter += int(result.n_clutter)
        if math.isnan(self.first_time):
            self.first_time = float(result.timestamp)
        self.last_time = float(result.timestamp)
        if not result.has_estimate:
            self._last_p = None  # a gap: do not draw a line across it
            return
        self.side = getattr(result, "side", "right")
        angles = np.degrees(wrist_angles(result.R, self.side))
        self.angle_min = np.minimum(self.angle_min, angles)
        self.angle_max = np.maximum(self.angle_max, angles)
        if np.isnan(self.angle_start).all():
            self.angle_start = angles
        self.angle_end = angles
        speed = float(np.linalg.norm(result.v))
        if math.isfinite(speed):
            self.peak_speed = max(self.peak_speed, speed)
            self.speed_sum += speed
            self.speed_n += 1
        if self._last_p is not None:
            self.path += float(np.linalg.norm(result.p - self._last_p))
        self._last_p = result.p.copy()

    def to_dict(self, **extra: Any) -> dict[str, Any]:
        tracked = self.status_counts.get("tracking", 0) + self.status_counts.get("coasting", 0)
        rom = {}
        for k, axis in enumerate(AXES):
            seen = math.isfinite(self.angle_min[k])
            rom[axis] = {
                "min_deg": float(self.angle_min[k]) if seen else None,
                "max_deg": float(self.angle_max[k]) if seen else None,
                "range_deg": float(self.angle_max[k] - self.angle_min[k]) if seen else None,
                "start_deg": float(self.angle_start[k]) if seen else None,
                "end_deg": float(self.angle_end[k]) if seen else None,
            }
        return {
            "software": {"name": "wristtrack", "version": __version__},
            "conventions": {
                **CONVENTIONS,
                "side": self.side or "unknown (no frame was tracked)",
            },
            "range_of_motion": rom,
            "peak_speed_m_s": self.peak_speed if self.speed_n else None,
            "mean_speed_m_s": self.speed_sum / self.speed_n if self.speed_n else None,
            "path_length_m": self.path,
            "duration_s": (self.last_time - self.first_time) if self.frames else 0.0,
            "frames": {
                "total": self.frames,
                "tracked": tracked,
                "lost": self.status_counts.get("lost", 0),
                "by_status": dict(self.status_counts),
            },
            "clutter_blobs_seen": self.clutter,
            **extra,
        }


def camera_pose_dict(R_c0: np.ndarray | None, t_c0: np.ndarray | None) -> dict[str, Any] | None:
    """W0 in the camera frame (hand -> camera at initialisation)."""
    if R_c0 is None:
        return None
    return {"t_m": [float(x) for x in t_c0], "q_wxyz": [float(x) for x in quat_from_matrix(R_c0)]}

