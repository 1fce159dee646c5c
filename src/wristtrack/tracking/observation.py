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
from wristtrack.depth_noise import NGUYEN_OFFSET, NGUYEN_QUADRATIC, NGUYEN_Z0, depth_sigma


@dataclass(frozen=True)
class MeasurementNoise:
    """The sensor's noise as the filter models it.

    Depth: sigma_z = max(offset + coeff (z - z0)^2, floor) (``depth_noise.depth_sigma``), by
    default Nguyen, Izadi and Lovell's measurement of a Kinect v1 / Xtion (1.3 mm at 0.65 m).
    A blob's depth is a trimmed mean of its pixels, but structured-light noise is correlated over
    the ~9x9 px matching window, as large as a marker's image: the mean removes little of it,
    so the blob's sigma is the pixel's. (Khoshelham and Elberink's 1.425e-3 z^2, half of it at
    arm's length, had the filter trust depth twice too much: the out-of-plane angles took the
    depth noise, 2.2x the error of the same recording without structured-light noise.)
    """

    pixel_sigma: float = 0.7  # px, blob centre noise
    depth_coeff: float = NGUYEN_QUADRATIC  # 1/m
    depth_floor: float = 0.0  # m
    depth_offset: float = NGUYEN_OFFSET  # m
    depth_z0: float = NGUYEN_Z0  # m

    def depth_sigma(self, z: float | np.ndarray) -> float | np.ndarray:
        """The depth sigma (m) of a marker at depth ``z`` (m)."""
        return depth_sigma(z, self.depth_coeff, self.depth_floor, self.depth_offset,
                           self.depth_z0)


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
            var[:, 2] = self.noise.depth_sigma(z) ** 2
        return var.reshape(-1)


def markers_on_blobs(obs: MarkerObservation, x: np.ndarray, labels: np.ndarray, uv: np.ndarray,
                     pixel_sigma: float, limit: float) -> bool:
    """Whether the markers at state ``x`` lie on the blobs labelled as them: the sum of squared
    pixel residuals (in units of ``pixel_sigma``) within ``limit`` (a chi-square quantile for
    2 per labelled blob). An update can pass its NIS test with a wide prior (a manoeuvre
    retry, a fresh start) and still stop short of the blobs it was given."""
    blobs = np.flatnonzero(labels >= 0)
    if blobs.size == 0:
        return False
    at = obs(x[None])[0].reshape(-1, 2)
    r = (uv[blobs] - at[labels[blobs]]) / pixel_sigma
    return float(np.sum(r * r)) <= limit
