"""Cramér-Rao lower bound of the per-frame wrist pose from marker projections and depths.

The bound is what any unbiased estimator using one frame's measurements alone can reach: the
inverse of the Fisher information J^T Sigma^-1 J, with J the Jacobian of the stacked marker
measurements (u, v and, where measured, z of each visible marker) with respect to a 6-D pose
perturbation, and Sigma the measurement noise. The perturbation is the one the benchmarks score:
R = exp(dphi) R_ch (rotation about the wrist, in camera axes; its norm is the geodesic angle)
and t = t_ch + dt (wrist position in the camera frame). The Jacobian is taken by central
differences of ``Camera.project``, so it is independent of the analytic Jacobians in
``pose_fit.refine_pose`` and the filters, and covers lens distortion.

The depth sigma c z^2 depends on the pose; the extra Fisher information from that dependence,
(1/2) tr(Sigma^-1 dSigma Sigma^-1 dSigma) ~ 8/z^2 per marker, is below 1e-5 of the mean term at
hand distances and is left out. A filter with a motion prior pools frames and may beat this
per-frame bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristtrack.camera import Camera
from wristtrack.depth_noise import KINECT_DEPTH_COEFF, depth_sigma
from wristtrack.geometry import so3_exp

_STEP = 1e-6  # rad / m: central-difference truncation ~1e-12, rounding ~1e-10 relative


@dataclass(frozen=True)
class PoseBound:
    """Per-frame bounds: ``cov`` (N,6,6) over (dphi, dt), NaN where the pose is unobservable
    (fewer than 3 visible markers or degenerate geometry)."""

    cov: np.ndarray

    @property
    def orientation_std_deg(self) -> np.ndarray:
        """(N,) root of the expected squared geodesic angle error, degrees."""
        return np.degrees(np.sqrt(np.trace(self.cov[:, :3, :3], axis1=1, axis2=2)))

    @property
    def position_std_mm(self) -> np.ndarray:
        """(N,) root of the expected squared position error, millimetres."""
        return 1e3 * np.sqrt(np.trace(self.cov[:, 3:, 3:], axis1=1, axis2=2))

    def rms(self) -> tuple[float, float]:
        """(orientation deg, position mm): root mean square over the observable frames."""
        ok = np.isfinite(self.cov).all(axis=(1, 2))
        if not ok.any():
            return float("nan"), float("nan")
        o, p = self.orientation_std_deg[ok], self.position_std_mm[ok]
        return float(np.sqrt(np.mean(o**2))), float(np.sqrt(np.mean(p**2)))


def _measure(camera: Camera, points: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N,n,3) u, v, z of layout ``points`` (n,3) at poses R (N,3,3), t (N,3)."""
    X = np.einsum("nij,mj->nmi", R, points) + t[:, None, :]
    return np.concatenate([camera.project(X), X[..., 2:3]], axis=-1)


def measurement_jacobian(
    camera: Camera, points: np.ndarray, R_ch: np.ndarray, t_ch: np.ndarray
) -> np.ndarray:
    """(N,n,3,6) d(u, v, z)/d(dphi, dt) of every marker by central differences."""
    R_ch = np.asarray(R_ch, dtype=float).reshape(-1, 3, 3)
    t_ch = np.asarray(t_ch, dtype=float).reshape(-1, 3)
    points = np.asarray(points, dtype=float)
    J = np.empty((R_ch.shape[0], points.shape[0], 3, 6))
    for k in range(6):
        delta = np.zeros(6)
        delta[k] = _STEP
        out = []
        for sign in (1.0, -1.0):
            R = so3_exp(sign * delta[:3]) @ R_ch
            out.append(_measure(camera, points, R, t_ch + sign * delta[3:]))
        J[..., k] = (out[0] - out[1]) / (2 * _STEP)
    return J


def pose_crlb(
    camera: Camera,
    points: np.ndarray,
    R_ch: np.ndarray,
    t_ch: np.ndarray,
    visible: np.ndarray | None = None,
    has_depth: np.ndarray | bool = True,
    pixel_sigma: float = 0.7,
    depth_coeff: float = KINECT_DEPTH_COEFF,
    depth_floor: float = 0.0,
) -> PoseBound:
    """Cramér-Rao bound of the pose at true poses R_ch (N,3,3), t_ch (N,3).

    ``points`` (n,3) are the marker centres in the hand frame; ``visible`` (N,n) which markers
    are measured in each frame (all if None); ``has_depth`` (N,n) or a bool, which of those
    carry a depth. Pixel noise is isotropic ``pixel_sigma``; depth noise sigma is
    ``depth_noise.depth_sigma`` at the true depth z (the simulator's
    ``NoiseModel.depth_sigma_coeff``; it applies no floor).
    """
    R_ch = np.asarray(R_ch, dtype=float).reshape(-1, 3, 3)
    t_ch = np.asarray(t_ch, dtype=float).reshape(-1, 3)
    N, n = R_ch.shape[0], np.asarray(points).shape[0]
    if pixel_sigma <= 0 or depth_coeff < 0 or depth_floor < 0:
        raise ValueError("pixel_sigma must be positive, depth_coeff and depth_floor >= 0")
    vis = np.ones((N, n), bool) if visible is None else np.asarray(visible, bool).reshape(N, n)
    dep = np.broadcast_to(np.asarray(has_depth, bool), (N, n)) & vis
    J = measurement_jacobian(camera, points, R_ch, t_ch)
    z = _measure(camera, np.asarray(points, float), R_ch, t_ch)[..., 2]
    sz = depth_sigma(z, depth_coeff, depth_floor)
    if (dep & ~(sz > 0)).any():
        raise ValueError("depth measured with zero noise: give depth_coeff or depth_floor > 0")
    w = np.zeros((N, n, 3))  # inverse variances; zero where not measured
    w[..., :2] = np.where(vis, pixel_sigma**-2, 0.0)[..., None]
    with np.errstate(divide="ignore"):
        w[..., 2] = np.where(dep, 1.0 / np.where(dep, sz, 1.0) ** 2, 0.0)
    info = np.einsum("fmai,fma,fmaj->fij", J, w, J)
    cov = np.full((N, 6, 6), np.nan)
    ok = vis.sum(axis=1) >= 3
    if ok.any():
        # scale to unit diagonal before the condition test: radians and metres differ in size
        d = np.sqrt(np.einsum("fii->fi", info[ok]))
        good = (d > 0).all(axis=1)
        idx = np.flatnonzero(ok)[good]
        d = d[good]
        scaled = info[idx] / (d[:, :, None] * d[:, None, :])
        fine = np.linalg.cond(scaled) < 1e12
        idx, d, scaled = idx[fine], d[fine], scaled[fine]
        cov[idx] = np.linalg.inv(scaled) / (d[:, :, None] * d[:, None, :])
    return PoseBound(0.5 * (cov + cov.transpose(0, 2, 1)))
