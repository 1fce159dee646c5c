"""Tracking errors against ground truth: pure NumPy, shared by `evaluate`, tests and benchmarks."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.geometry import rotation_distance

# A frame counts as a failure beyond these errors (DESIGN: "failure rate (> 10 deg or > 20 mm)").
FAIL_DEG = 10.0
FAIL_MM = 20.0


@dataclass(frozen=True)
class PoseErrors:
    """Camera-frame errors over the frames that have an estimate."""

    position_rmse_mm: float
    orientation_rmse_deg: float
    position_p95_mm: float
    orientation_p95_deg: float
    failure_rate: float  # share of estimated frames beyond FAIL_DEG or FAIL_MM
    coverage: float  # share of frames after the first estimate that have an estimate
    frames: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def pose_errors(
    R_est: np.ndarray, t_est: np.ndarray, R_true: np.ndarray, t_true: np.ndarray
) -> PoseErrors:
    """Errors of estimated poses (N,3,3), (N,3) against truth; NaN rows mean no estimate."""
    valid = np.isfinite(t_est).all(axis=1) & np.isfinite(R_est).all(axis=(1, 2))
    if not valid.any():
        nan = float("nan")
        return PoseErrors(nan, nan, nan, nan, nan, 0.0, 0)
    pos = np.linalg.norm(t_est[valid] - t_true[valid], axis=1) * 1e3
    ang = np.degrees(rotation_distance(R_est[valid], R_true[valid]))
    first = int(np.argmax(valid))
    return PoseErrors(
        position_rmse_mm=float(np.sqrt(np.mean(pos**2))),
        orientation_rmse_deg=float(np.sqrt(np.mean(ang**2))),
        position_p95_mm=float(np.percentile(pos, 95)),
        orientation_p95_deg=float(np.percentile(ang, 95)),
        failure_rate=float(np.mean((ang > FAIL_DEG) | (pos > FAIL_MM))),
        coverage=float(valid[first:].mean()),
        frames=int(valid.sum()),
    )


def rmse_net_of_constant_errors(
    R_est: np.ndarray, t_est: np.ndarray, R_true: np.ndarray, t_true: np.ndarray
) -> tuple[float, float]:
    """(position mm, orientation deg) RMS errors of estimated poses against truth (as
    :func:`pose_errors`) after taking out their constant parts, as a registration to another
    system (``wristtrack compare``) takes them up and cannot report them: the mean
    camera-frame rotation error (R_est = E R_true) and the mean position error; NaN without an
    estimate."""
    valid = np.isfinite(t_est).all(axis=1) & np.isfinite(R_est).all(axis=(1, 2))
    if not valid.any():
        return float("nan"), float("nan")
    err = Rotation.from_matrix(R_est[valid] @ np.swapaxes(R_true[valid], 1, 2))
    rot = (err.mean().inv() * err).magnitude()
    pos = t_est[valid] - t_true[valid]
    pos = pos - pos.mean(axis=0)
    return (float(np.sqrt(np.mean(np.sum(pos**2, axis=1))) * 1e3),
            float(np.degrees(np.sqrt(np.mean(rot**2)))))


def labelling_accuracy(estimated: list[np.ndarray], truth: list[np.ndarray]) -> dict[str, float]:
    """Share of true marker blobs given their right label, and of clutter blobs taken as markers."""
    est = np.concatenate(estimated) if estimated else np.zeros(0, int)
    true = np.concatenate(truth) if truth else np.zeros(0, int)
    markers, clutter = true >= 0, true < 0
    return {
        "markers_correct": float(np.mean(est[markers] == true[markers])) if markers.any() else 1.0,
        "clutter_as_marker": float(np.mean(est[clutter] >= 0)) if clutter.any() else 0.0,
    }
