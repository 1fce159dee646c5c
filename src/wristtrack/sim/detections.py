"""Simulated blob-detector output: noisy, unordered marker centres with clutter and misses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristtrack import geometry
from wristtrack.camera import Camera
from wristtrack.depth_noise import KINECT_DEPTH_COEFF, depth_sigma
from wristtrack.detect.detections import Detections
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.sim.motion import Trajectory

CLUTTER = -1


@dataclass(frozen=True)
class SimFrame:
    """Detections of one frame with their truth: ``labels`` (M,) is -1 for clutter, else the
    marker index (MARKER_NAMES order) of each blob."""

    detections: Detections
    labels: np.ndarray


@dataclass(frozen=True)
class NoiseModel:
    """What goes wrong between the true marker centres and the detector output.

    Depth noise is Kinect-like (``depth_noise.depth_sigma``): sigma = depth_sigma_coeff * z^2
    metres. A marker is hidden when the back of the hand turns away: cosine between hand +Z and
    the marker-to-camera direction below ``min_facing_cos``. ``occlusions``: (first frame, stop
    frame exclusive, marker indices).

    The centre noise is the filter's own pixel model (``MeasurementNoise.pixel_sigma``, the
    blob-centre noise measured on rendered recordings), white and independent between markers:
    this is the simulator to check the filter's consistency on. What breaks that model (skin
    slide, blur, shading, structured-light depth) is the renderer's (``sim.realism``).
    """

    pixel_sigma: float = 0.3
    clutter_mean: float = 3.0
    depth_range: tuple[float, float] = (0.3, 2.0)
    p_miss: float = 0.1
    depth: bool = True
    depth_sigma_coeff: float = KINECT_DEPTH_COEFF
    p_depth_hole: float = 0.0
    min_facing_cos: float = 0.15
    occlusions: tuple[tuple[int, int, tuple[int, ...]], ...] = ()
    # Clutter right next to the markers (a blue sleeve, a ring, a second marker sheet): the
    # hard case for association. Poisson count per frame around random visible markers.
    near_clutter_mean: float = 0.0
    near_clutter_px: float = 10.0  # spread of those blobs around the marker, px
    near_clutter_depth: float = 0.01  # and of their depth around the marker's, m

    def __post_init__(self) -> None:
        if not (0.0 <= self.p_miss <= 1.0 and 0.0 <= self.p_depth_hole <= 1.0):
            raise ValueError("p_miss and p_depth_hole are probabilities in [0, 1]")
        if min(self.pixel_sigma, self.clutter_mean, self.depth_sigma_coeff) < 0:
            raise ValueError("pixel_sigma, clutter_mean and depth_sigma_coeff must be >= 0")


def acceptance_noise(n_frames: int) -> NoiseModel:
    """The project's acceptance setting: the default pixel and depth noise, 3 clutter blobs/frame,
    10 % misses, and MCP4 and MCP5 occluded for 10 frames in the middle of an ``n_frames``
    recording."""
    start = max(n_frames // 2 - 5, 0)
    hidden = (MARKER_NAMES.index("MCP4"), MARKER_NAMES.index("MCP5"))
    return NoiseModel(occlusions=((start, start + 10, hidden),))


def visible_markers(
    traj: Trajectory, camera: Camera, layout: HandLayout, min_facing_cos: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True marker centres (N,6,3) in the camera frame, their projections (N,6,2) and which
    could be seen (N,6): in front of the camera, facing it and inside the image."""
    p_cam = geometry.transform_points(traj.R_ch, traj.t_ch, layout.points)
    uv = camera.project(p_cam)
    normal = traj.R_ch[:, None, :, 2]  # hand +Z in camera coordinates, (N,1,3)
    facing = np.sum(normal * -p_cam, -1) / np.linalg.norm(p_cam, axis=-1)
    seen = (p_cam[..., 2] > 0) & (facing >= min_facing_cos) & camera.in_image(uv)
    return p_cam, uv, seen


def simulate_detections(
    traj: Trajectory,
    camera: Camera,
    layout: HandLayout,
    noise: NoiseModel,
    rng: np.random.Generator | int | None = None,
) -> list[SimFrame]:
    """Per-frame detector output for a trajectory, blobs shuffled in every frame.

    Measured depth = true z of the marker centre + noise (NaN in holes); None when
    ``noise.depth`` is False. Blobs whose noisy centre leaves the image are not reported.
    """
    rng = np.random.default_rng(rng)
    n, m = len(traj), layout.points.shape[0]
    p_cam, uv_true, seen = visible_markers(traj, camera, layout, noise.min_facing_cos)
    uv = uv_true + rng.normal(0.0, noise.pixel_sigma, uv_true.shape)
    z_true = p_cam[..., 2]
    z = z_true + rng.normal(0.0, 1.0, seen.shape) * depth_sigma(z_true, noise.depth_sigma_coeff)
    detected = seen & (rng.random(seen.shape) >= noise.p_miss) & camera.in_image(uv)
    for start, stop, markers in noise.occlusions:
        detected[max(start, 0) : stop, list(markers)] = False

    n_clutter = rng.poisson(noise.clutter_mean, n)
    total = int(n_clutter.sum())
    # Inside [0, size - 1] so clutter is in the image under any pixel-centre convention.
    c_uv = rng.random((total, 2)) * [camera.width - 1, camera.height - 1]
    c_z = rng.uniform(*noise.depth_range, total)
    c_split = np.cumsum(n_clutter)[:-1]

    frames = []
    labels_all = np.broadcast_to(np.arange(m), (n, m))
    for k, (cu, cz) in enumerate(zip(np.split(c_uv, c_split), np.split(c_z, c_split), strict=True)):
        sel = detected[k]
        if noise.near_clutter_mean > 0 and seen[k].any():
            cu, cz = _near_clutter(rng, noise, uv_true[k, seen[k]], z_true[k, seen[k]], cu, cz)
        f_uv = np.concatenate([uv[k, sel], cu])
        f_z = np.concatenate([z[k, sel], cz])
        labels = np.concatenate([labels_all[k, sel], np.full(cz.shape[0], CLUTTER)])
        order = rng.permutation(labels.shape[0])  # the tracker must not rely on blob order
        depth = None
        if noise.depth:
            depth = np.where(rng.random(f_z.shape[0]) < noise.p_depth_hole, np.nan, f_z[order])
        frames.append(SimFrame(Detections(float(traj.t[k]), f_uv[order], depth), labels[order]))
    return frames


def _near_clutter(rng, noise: NoiseModel, uv_markers, z_markers, cu, cz):
    """Append Poisson-many clutter blobs scattered around randomly chosen visible markers."""
    count = rng.poisson(noise.near_clutter_mean)
    near = rng.integers(0, uv_markers.shape[0], count)
    n_uv = uv_markers[near] + rng.normal(0.0, noise.near_clutter_px, (count, 2))
    n_z = z_markers[near] + rng.normal(0.0, noise.near_clutter_depth, count)
    return np.concatenate([cu, n_uv]), np.concatenate([cz, n_z])
