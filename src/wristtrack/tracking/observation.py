"""Measurement model: where each marker appears in the image, and at what depth.

Marker j at T_j in the hand frame projects to y_j = pi(R_ch T_j + t_ch) (paper eq. 2-3), with
R_ch = R_c0 R and t_ch = R_c0 p + t_c0 for the pose (R, p) relative to W0. Where the sensor has
depth, the marker centre's depth z_j is a third component of y_j: the paper uses depth only to
initialise; using it in every update resolves the planar-target flip and sharpens the
out-of-plane angles.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wristtrack.camera import Camera
from wristtrack.depth_noise import KINECT_DEPTH_COEFF, depth_sigma


@dataclass(frozen=True)
class MeasurementNoise:
    pixel_sigma: float = 0.7  # px, blob centre noise
    depth_coeff: float = KINECT_DEPTH_COEFF  # depth noise sigma = coeff * z^2 (depth_noise)
    # m, lower bound on a blob's depth sigma. Nguyen et al.'s 1.2 mm offset (structured-light
    # noise is correlated over the matching window, so a blob's pixels do not average it away)
    # helped every rendered scenario at 30 fps (deviation 0.48 -> 0.43 deg) but lost the
    # 10 fps flexion of tests/pipeline/test_batch.py (25 deg per frame: the weaker depth let
    # the filter slide into the planar flip). Kept at 0.5 mm until the noise is per blob.
    depth_floor: float = 0.5e-3


class MarkerObservation:
    """Maps states (S, D) to stacked marker measurements (S, 6*k), marker-major, k = 2 or 3."""

    def __init__(
        self,
        camera: Camera,
        layout_points: np.ndarray,
        R_c0: np.ndarray,
        t_c0: np.ndarray,
        pose: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        use_depth: bool,
        noise: MeasurementNoise = MeasurementNoise(),
    ):
        self.camera = camera
        self.layout_T = np.asarray(layout_points, dtype=float).T.copy()  # (3, 6)
        self.n_markers = self.layout_T.shape[1]
        self.R_c0 = np.asarray(R_c0, dtype=float)
        self.t_c0 = np.asarray(t_c0, dtype=float)
        self.pose = pose
        self.k = 3 if use_depth else 2
        self.noise = noise

    def marker_points(self, X: np.ndarray) -> np.ndarray:
        """Marker centres (S, 6, 3) in the camera frame for states X (S, D)."""
        R_rel, p = self.pose(X)
        R_ch = self.R_c0 @ R_rel
        t_ch = p @ self.R_c0.T + self.t_c0
        return (R_ch @ self.layout_T).swapaxes(1, 2) + t_ch[:, None, :]

    def __call__(self, X: np.ndarray) -> np.ndarray:
        pts = self.marker_points(X)
        out = np.empty((X.shape[0], self.n_markers, self.k))
        out[..., :2] = self.camera.project(pts)
        if self.k == 3:
            out[..., 2] = pts[..., 2]
        return out.reshape(X.shape[0], -1)

    def noise_variance(self, y_pred: np.ndarray) -> np.ndarray:
        """Diagonal measurement noise (6*k,) at the predicted measurement y_pred (6*k,)."""
        var = np.full((self.n_markers, self.k), self.noise.pixel_sigma**2)
        if self.k == 3:
            z = y_pred.reshape(self.n_markers, 3)[:, 2]
            var[:, 2] = depth_sigma(z, self.noise.depth_coeff, self.noise.depth_floor) ** 2
        return var.reshape(-1)
