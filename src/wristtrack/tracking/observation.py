"""Measurement model: where each marker appears in the image, and at what depth.

Marker j at T_j in the hand frame projects to y_j = pi(R_ch T_j + t_ch) (paper eq. 2-3), with
R_ch = R_c0 R and t_ch = R_c0 p + t_c0 for the pose (R, p) relative to W0. Where the sensor has
depth, the marker centre's depth z_j is a third component of y_j: the paper uses depth only to
initialise; using it in every update resolves the planar-target flip and sharpens the
out-of-plane angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wristtrack.camera import Camera
from wristtrack.tracking.models import QUAT_TO_MATRIX, mat3_mul, mat3_vec


@dataclass(frozen=True)
class MeasurementNoise:
    pixel_sigma: float = 0.7  # px, blob centre noise
    depth_coeff: float = 1.425e-3  # Kinect-like depth noise: sigma = coeff * z^2 (m)
    depth_floor: float = 0.5e-3  # m, lower bound on the depth sigma (blob depth resolution)


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
        self._column_map: np.ndarray | None = None
        self._R_c0_list = self.R_c0.reshape(9).tolist()
        self._t_c0_list = self.t_c0.tolist()
        self._layout_list = self.layout_T.T.tolist()

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
            var[:, 2] = np.maximum(self.noise.depth_coeff * z * z, self.noise.depth_floor) ** 2
        return var.reshape(-1)

    # ------------------------------------------------------------- hot path (sigma columns)
    # The tracker's fast path (default model, depth, no lens distortion) measures sigma points
    # held as columns of the constant-rate model's measurement features F = (1, p, v, w,
    # vec(q q^T)) (motion.SigmaPropagator), q the orientation quaternion. Rows of such a
    # measurement are axis-major: u of each marker, then v, then z.

    @property
    def has_column_path(self) -> bool:
        return self.k == 3 and not self.camera.has_distortion

    def measure_columns(self, features: np.ndarray, out: np.ndarray) -> None:
        """Measurements (3 n_markers, S) of the feature columns (26, S).

        The camera-frame point X of marker j is linear in the features (R(q) is quadratic in
        q), and so are f_x X + c_x Z, f_y Y + c_y Z and Z: one matrix product and one division
        by the depth give the pixels.
        """
        if self._column_map is None:
            self._column_map = self._build_column_map()
        self._column_map.dot(features, out=out)
        n = self.n_markers
        uv = out[: 2 * n].reshape(2, n, -1)
        np.divide(uv, out[2 * n : 3 * n], out=uv)

    def _build_column_map(self) -> np.ndarray:
        """(3n, 26): rows (f_x X + c_x Z, f_y Y + c_y Z, Z) of each marker, axis-major."""
        cam, n = self.camera, self.n_markers
        K = np.array([[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]])
        KR, kt = K @ self.R_c0, K @ self.t_c0
        rot = QUAT_TO_MATRIX.reshape(3, 3, 16)  # R(q)[r, c] = rot[r, c] . vec(q q^T)
        M = np.zeros((3, n, 26))
        M[:, :, 0] = kt[:, None]  # K t_c0
        M[:, :, 1:4] = KR[:, None, :]  # K R_c0 p
        M[:, :, 10:] = np.einsum("ar,rcm,cj->ajm", KR, rot, self.layout_T)  # K R_c0 R(q) T_j
        return M.reshape(3 * n, 26)

    def noise_variances(self, y: list[float]) -> list[float]:
        """``noise_variance`` for an axis-major predicted measurement given as floats."""
        noise, n = self.noise, self.n_markers
        coeff, floor = noise.depth_coeff, noise.depth_floor
        depth = [coeff * z * z for z in y[2 * n : 3 * n]]
        return [noise.pixel_sigma**2] * (2 * n) + [(s if s > floor else floor) ** 2 for s in depth]

    def all_visible(self, R_rel: list[float], p: list[float], facing_cos: float) -> bool:
        """Whether Tracker._expected_markers holds for every marker at one pose (R_rel
        row-major, p), in Python floats: in front of the camera, palm not turned away, centre
        on the sensor."""
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = mat3_mul(self._R_c0_list, R_rel)  # R_ch
        t0, t1, t2 = mat3_vec(self._R_c0_list, p)
        c0, c1, c2 = self._t_c0_list
        t0, t1, t2 = t0 + c0, t1 + c1, t2 + c2
        cam = self.camera
        fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
        u_max, v_max = cam.width - 0.5, cam.height - 0.5
        for a, b, c in self._layout_list:
            X = r0 * a + r1 * b + r2 * c + t0
            Y = r3 * a + r4 * b + r5 * c + t1
            Z = r6 * a + r7 * b + r8 * c + t2
            # facing the camera: the palm normal (the hand's z axis, R_ch's last column) points
            # back along the line of sight; Z > 0 first, so the norm is not zero
            if not (
                Z > 0
                and -(X * r2 + Y * r5 + Z * r8) / math.sqrt(X * X + Y * Y + Z * Z) > facing_cos
                and -0.5 <= X / Z * fx + cx < u_max
                and -0.5 <= Y / Z * fy + cy < v_max
            ):
                return False
        return True
