"""Recorded hand motion driving the simulator, and the reference a motion-capture system would
give of the same take (``wristtrack simulate OUT --motion FILE.c3d --cluster A,B,C``).

The motion: the pose of a rigid marker cluster on the back of a hand in a real recording
(C3D/TRC/TSV), taken as the hand's pose (hand frame = the cluster's canonical frame: origin at
its centroid, +Z its plane's normal, +X towards its first marker), relative to its pose at the
start of the chosen segment (W0). Rotation and position splines through the recorded samples
give a continuous motion the renderer samples at the camera's own timestamps (so it is
resampled to the camera's rate). The motion starts and ends at rest (held 0.4 s, eased in and
out over 0.3 s of a minimum-jerk time warp) so the tracker can initialise on a still hand.
Optional, stated in the metadata: ``speed`` plays it slower (< 1) or faster, ``position_scale``
and ``rotation_scale`` shrink the excursions (the displacement from the start, and the angular
velocity) so a fast, wide recording stays in the camera's view.

The reference: what the motion-capture system records of the rendered take: the cluster's
markers (and the six hand markers, as WRIST..MCP5) in its own lab frame (a rigid transform from
the camera, planted), at its own rate, on its own clock (reference time = offset + ratio x
camera time, planted), with Gaussian marker noise, written as reference.c3d (millimetres) with
the planted values in reference.json.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from wristtrack import geometry
from wristtrack.analysis.compare.reference import rigid_fit
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import MARKER_NAMES
from wristtrack.io.markers.read import read_markers
from wristtrack.sim.motion import Motion, neutral_camera_pose, timestamps
from wristtrack.sim.scenes import Scene

REST_S = 0.4  # still hand before and after the motion (initialisation needs it)
EASE_S = 0.3  # minimum-jerk ease in/out of the recorded motion's time
MAX_GAP_S = 0.1  # shorter reference gaps in the segment are bridged by the splines


@dataclass(frozen=True)
class RecordedMotion:
    motion: Motion
    shape_hand: np.ndarray  # (K,3) the cluster's markers in the hand frame (metres)
    labels: tuple[str, ...]
    meta: dict[str, Any]


def canonical_shape(shape: np.ndarray) -> np.ndarray:
    """A rigid cluster's marker positions (K,3) in its canonical frame: origin at the
    centroid, +Z the normal of the markers' plane, +X towards the first marker."""
    c = shape - shape.mean(axis=0)
    _, _, Vt = np.linalg.svd(c)
    z = Vt[2]
    x = c[0] - (c[0] @ z) * z
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])  # columns: the frame's axes
    return c @ R


def _ease(u: np.ndarray, span: float) -> np.ndarray:
    """Recorded time elapsed (s) after ``u`` s of playback of a ``span``-second segment, easing
    in and out over EASE_S (the derivative rises 0 -> 1 and falls 1 -> 0 as min-jerk)."""
    r = min(EASE_S, span / 4)

    def up(x):  # integral over [0, x] of the min-jerk rise over r
        s = np.clip(x / r, 0.0, 1.0)
        return r * (2.5 * s**4 - 3.0 * s**5 + s**6) + np.clip(x - r, 0.0, None)

    total = span + r  # playback length: the two ramps each lose r/2
    u = np.clip(u, 0.0, total)
    return np.where(u <= total / 2, up(u), span - up(total - u))


def load_recorded_motion(
    path: str | Path,
    cluster: list[str],
    start_s: float | None = None,
    duration_s: float | None = None,
    speed: float = 1.0,
    position_scale: float = 1.0,
    rotation_scale: float = 1.0,
) -> RecordedMotion:
    """The hand motion of cluster ``cluster`` in a marker file, over [start, start + duration]
    of the recording (default: the longest stretch without gaps over MAX_GAP_S)."""
    if not speed > 0 or not position_scale > 0 or not rotation_scale > 0:
        raise ConfigError("--speed, --position-scale and --rotation-scale must be positive")
    if len(cluster) < 3:
        raise ConfigError(f"--cluster needs three or more marker labels, got {len(cluster)}")
    data = read_markers(path)
    xyz = data.select(cluster)
    full = np.isfinite(xyz).all(axis=(1, 2))
    if full.sum() < 4:
        raise InputError(f"{path}: the cluster {','.join(cluster)} is complete in fewer than 4 "
                         "frames")
    shape = canonical_shape(xyz[np.flatnonzero(full)[0]])
    for _ in range(2):  # mean shape over the take (Procrustes)
        R, t, _ = rigid_fit(shape, xyz[full])
        shape = canonical_shape(np.einsum("nji,nkj->nki", R, xyz[full] - t[:, None]).mean(0))
    R, p, _ = rigid_fit(shape, xyz)
    ok = np.isfinite(p).all(axis=1)
    times = data.times
    if start_s is None:
        start_s, end_s = _longest_stretch(times, ok)
        if duration_s is not None:
            end_s = min(end_s, start_s + duration_s)
    else:
        end_s = times[ok][-1] if duration_s is None else start_s + duration_s
    keep = ok & (times >= start_s - 1e-9) & (times <= end_s + 1e-9)
    tk = times[keep]
    if len(tk) < 4 or tk[-1] - tk[0] < 0.2:
        raise InputError(f"{path}: fewer than 0.2 s of cluster poses in the chosen segment")
    gaps = np.diff(tk)
    if gaps.max() > MAX_GAP_S:
        at = tk[int(np.argmax(gaps))]
        raise InputError(
            f"{path}: the cluster has a {gaps.max():.2f} s gap at {at:.2f} s in the chosen "
            "segment; choose another with --motion-start/--motion-duration"
        )
    Rk, pk = R[keep], p[keep]
    R0, p0 = Rk[0], pk[0]
    R_rel = np.swapaxes(R0, -1, -2)[None] @ Rk
    p_rel = (pk - p0) @ R0  # R0^T (p - p0)
    if rotation_scale != 1.0:
        R_rel = _scaled_rotation(R_rel, rotation_scale)
    p_rel = p_rel * position_scale
    span = float(tk[-1] - tk[0])
    rot = RotationSpline(tk - tk[0], Rotation.from_matrix(R_rel))
    pos = CubicSpline(tk - tk[0], p_rel)
    play = (span + min(EASE_S, span / 4)) / speed

    def recorded(t: np.ndarray) -> np.ndarray:
        return _ease((np.asarray(t, dtype=float) - REST_S) * speed, span)

    def angles(t: np.ndarray) -> np.ndarray:
        return geometry.wrist_angles(rot(recorded(t)).as_matrix())

    def position(t: np.ndarray) -> np.ndarray:
        return pos(recorded(t))

    motion = Motion(angles, position, play + 2 * REST_S)
    angle = np.degrees(geometry.rotation_angle(R_rel))
    meta = {
        "source": str(path), "cluster": list(cluster), "segment_s": [float(tk[0]),
                                                                      float(tk[-1])],
        "recorded_rate_hz": data.rate, "speed": speed, "time_scaled": speed != 1.0,
        "position_scale": position_scale, "rotation_scale": rotation_scale,
        "rest_s": REST_S, "ease_s": min(EASE_S, span / 4), "duration_s": motion.duration,
        "max_rotation_from_start_deg": float(angle.max()),
        "max_displacement_m": float(np.linalg.norm(p_rel, axis=1).max()),
        "hand_frame": "the cluster's canonical frame: origin centroid, +Z plane normal, +X "
        "towards the first marker",
        "notes": list(data.notes),
    }
    return RecordedMotion(motion, shape, tuple(cluster), meta)


def _scaled_rotation(R_rel: np.ndarray, scale: float) -> np.ndarray:
    """The rotation path whose angular velocity (hand frame) is ``scale`` times the recorded:
    the sample-to-sample increments scaled and chained from the identity. (Scaling each pose's
    rotation from the start instead breaks down past 180 degrees, where the axis flips.)"""
    steps = geometry.so3_log(np.swapaxes(R_rel[:-1], -1, -2) @ R_rel[1:])
    out = np.empty_like(R_rel)
    out[0] = np.eye(3)
    for i, step in enumerate(geometry.so3_exp(scale * steps)):
        out[i + 1] = geometry.project_to_so3(out[i] @ step)
    return out


def _longest_stretch(times: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    """[start, end] (s) of the longest run of valid samples with no gap over MAX_GAP_S."""
    tv = times[ok]
    breaks = np.flatnonzero(np.diff(tv) > MAX_GAP_S)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(tv) - 1]])
    k = int(np.argmax(tv[ends] - tv[starts]))
    return float(tv[starts[k]]), float(tv[ends[k]])


def recorded_scene(rec: RecordedMotion, fps: float = 30.0, name: str = "recorded",
                   **fields: Any) -> Scene:
    """A Scene of the recorded motion at ``fps``, with the camera placed so the middle of the
    wrist's path is where the scripted scenarios hold the wrist."""
    R_c0, t_c0 = neutral_camera_pose()
    t = np.linspace(0.0, rec.motion.duration, 200)
    mid = R_c0 @ rec.motion.position(t).mean(axis=0)
    t_c0 = t_c0 - np.array([mid[0], mid[1], 0.0])
    n = int(np.floor(rec.motion.duration * fps + 1e-9)) + 1
    return Scene(name=name, motion=rec.motion, R_c0=R_c0, t_c0=t_c0,
                 times=timestamps(n, fps), **fields)


@dataclass(frozen=True)
class ReferenceSettings:
    """The motion-capture system's take: its rate, clock, lab frame and noise (planted)."""

    rate_hz: float = 100.0
    offset_s: float = 0.4173  # reference time = offset + ratio x camera time
    ratio: float = 1.0002
    rotation_deg: tuple[float, float, float] = (12.0, -160.0, 35.0)  # lab <- camera, XYZ Euler
    translation_m: tuple[float, float, float] = (0.62, 1.35, 0.91)
    noise_mm: float = 0.05  # per coordinate: a well-calibrated system in a small volume
    seed: int = 0

    @property
    def R_lc(self) -> np.ndarray:
        return Rotation.from_euler("xyz", self.rotation_deg, degrees=True).as_matrix()


def reference_markers(
    scene: Scene, rec: RecordedMotion, layout: np.ndarray, settings: ReferenceSettings
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """(times (N,), positions (N,K,3) m in the lab, labels): the cluster's markers and our six,
    sampled at the reference's rate over the camera's take, on the reference's clock."""
    tc = np.asarray(scene.times, dtype=float)
    tau0 = settings.offset_s + settings.ratio * tc[0]
    tau1 = settings.offset_s + settings.ratio * tc[-1]
    # The motion-capture take starts a little before the camera and ends a little after.
    tau = np.arange(max(tau0 - 0.5, 0.0), tau1 + 0.5, 1.0 / settings.rate_hz)
    t_cam = (tau - settings.offset_s) / settings.ratio
    R_rel, p_rel = scene.motion.pose(np.clip(t_cam, 0.0, scene.motion.duration))
    R_ch = scene.R_c0 @ R_rel
    t_ch = p_rel @ scene.R_c0.T + scene.t_c0
    points = np.concatenate([rec.shape_hand, layout])  # hand frame
    cam = np.einsum("nij,kj->nki", R_ch, points) + t_ch[:, None]
    lab = cam @ settings.R_lc.T + np.asarray(settings.translation_m)
    rng = np.random.default_rng([settings.seed, 7])
    lab = lab + rng.normal(0.0, settings.noise_mm * 1e-3, lab.shape)
    labels = (*rec.labels, *MARKER_NAMES)
    return tau, lab, labels


def write_reference(out: str | Path, scene: Scene, rec: RecordedMotion, layout: np.ndarray,
                    settings: ReferenceSettings) -> Path:
    """reference.c3d (mm) and reference.json (the planted truth) in the recording folder."""
    from wristtrack.io.markers.c3d import write_c3d
    from wristtrack.io.markers.trajectories import MarkerTrajectories

    out = Path(out)
    tau, lab, labels = reference_markers(scene, rec, layout, settings)
    traj = MarkerTrajectories(
        names=labels, frames=np.arange(len(tau)), times=tau - tau[0], xyz=lab,
        rate=settings.rate_hz, irregular=False, source="wristtrack simulate --motion",
    )
    path = out / "reference.c3d"
    write_c3d(path, traj, "mm")
    # The file's frame 1 is at reference time tau[0]: the offset as seen from the file's clock.
    offset_file = settings.offset_s - tau[0]
    meta = {
        "reference_file": path.name,
        "time_offset_s": offset_file,
        "clock_ratio": settings.ratio,
        "clock": "reference time (0 at the file's first frame) = time_offset_s + clock_ratio x "
        "camera time (frames.csv)",
        "registration": {"rotation": settings.R_lc.tolist(),
                         "translation": list(settings.translation_m),
                         "frame": "reference lab <- camera (metres)"},
        "rate_hz": settings.rate_hz,
        "marker_noise_mm": settings.noise_mm,
        "cluster_labels": list(rec.labels),
        "hand_marker_labels": list(MARKER_NAMES),
        "cluster_in_hand_frame_m": rec.shape_hand.tolist(),
        "motion": rec.meta,
    }
    (out / "reference.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    return path


def render_recorded(
    out: str | Path,
    motion_file: str | Path,
    cluster: list[str],
    *,
    seed: int = 0,
    overwrite: bool = False,
    fps: float = 30.0,
    start_s: float | None = None,
    duration_s: float | None = None,
    speed: float = 1.0,
    position_scale: float = 1.0,
    rotation_scale: float = 1.0,
    reference: ReferenceSettings | None = None,
    effects: tuple[str, ...] = (),
    hand_side: str = "right",
) -> Path:
    """Render the recorded motion as a recording folder (with truth.csv) and write the
    motion-capture reference beside it; returns the folder. ``effects`` and ``hand_side`` as
    for the scripted scenarios (wristtrack.sim.scenes.with_effects)."""
    from wristtrack.sim.render import render_recording
    from wristtrack.sim.scenes import with_effects

    rec = load_recorded_motion(motion_file, cluster, start_s, duration_s, speed,
                               position_scale, rotation_scale)
    scene = with_effects(recorded_scene(rec, fps), effects, hand_side, seed=seed)
    out = render_recording(out, scene, seed=seed, overwrite=overwrite)
    write_reference(out, scene, rec, scene.layout.points, reference or ReferenceSettings())
    return Path(out)
