"""Ground-truth wrist motion: continuous motions relative to W0, sampled into trajectories.

A :class:`Motion` is a pair of continuous functions of time (seconds from the motion's start):
the wrist angles (deviation, flexion, pronation) and the wrist position in W0. Primitives start
and end at rest and hold their end value outside their span, so they can be delayed and summed
(:func:`combine`) into simultaneous movements. :func:`sample` turns a motion into a
:class:`Trajectory` at given timestamps with exact velocities.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wristtrack import geometry
from wristtrack.camera import Camera
from wristtrack.errors import ConfigError
from wristtrack.hand import HandLayout

_AXES = {"deviation": 0, "flexion": 1, "pronation": 2}
_H = 1e-6  # central-difference step (s): truncation ~h^2, rounding ~1e-16/h, both << 1e-8

SCENARIOS = ("deviation", "flexion", "pronation", "reach", "mix")

TimeFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Trajectory:
    """Sampled ground truth. Hand->camera pose (R_ch, t_ch), pose relative to W0, velocities in W0.

    ``w`` is the angular velocity in W0 (dR_rel/dt = skew(w) R_rel); ``angles`` are
    geometry.wrist_angles(R_rel): (deviation, flexion, pronation), radians.
    """

    t: np.ndarray
    R_ch: np.ndarray
    t_ch: np.ndarray
    R_rel: np.ndarray
    p_rel: np.ndarray
    v: np.ndarray
    w: np.ndarray
    angles: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class Motion:
    """Continuous wrist motion relative to W0; both functions map times (N,) to (N,3)."""

    angles: TimeFn  # (deviation, flexion, pronation), radians
    position: TimeFn  # wrist position in W0, metres
    duration: float

    def pose(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_rel (N,3,3), p_rel (N,3)) at times t (N,)."""
        t = np.asarray(t, dtype=float)
        a = self.angles(t)
        return geometry.matrix_from_wrist_angles(a[:, 0], a[:, 1], a[:, 2]), self.position(t)


def _zeros(t: np.ndarray) -> np.ndarray:
    return np.zeros((np.shape(t)[0], 3))


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 10s^3 - 15s^4 + 6s^5 of s clipped to [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 + s * (-15.0 + 6.0 * s))


def _ramped_phase(tau: np.ndarray, period: float, cycles: float) -> np.ndarray:
    """Phase (in cycles) whose rate rises from 0 to 1/period over a raised-cosine ramp of half
    a period and falls back to 0 at the end, reaching exactly ``cycles``.

    The ramps make angle velocity and acceleration continuous at the start and end; the first
    peak is reached exactly at the end of the ramp (phase 1/4), so amplitudes are exact.
    """
    ramp = 0.5 * period
    span = cycles * period + ramp

    def ramp_integral(x: np.ndarray) -> np.ndarray:  # integral of (1 - cos(pi u/ramp))/2
        x = np.clip(x, 0.0, ramp)
        return 0.5 * x - ramp / (2.0 * np.pi) * np.sin(np.pi * x / ramp)

    tau = np.clip(tau, 0.0, span)
    middle = np.clip(tau - ramp, 0.0, span - 2.0 * ramp)
    tail = 0.5 * ramp - ramp_integral(span - tau)
    tail = np.where(tau > span - ramp, tail, 0.0)
    return (ramp_integral(tau) + middle + tail) / period


def rom_cycle(
    axis: str,
    amplitude_deg: float,
    period_s: float,
    cycles: int = 2,
    rest_s: float = 0.5,
    drift: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Motion:
    """Range-of-motion cycles about one anatomical axis: neutral -> +A -> -A -> ... -> neutral.

    ``axis`` is "deviation", "flexion" or "pronation". The angle is A sin(2 pi phase) with a
    phase rate ramped smoothly up and down (see _ramped_phase), so the motion starts and ends at
    rest. ``drift`` (metres, W0) is a small minimum-jerk forearm translation over the movement,
    as a real forearm never stays perfectly still.
    """
    if axis not in _AXES:
        raise ValueError(f"unknown axis {axis!r}; use one of {tuple(_AXES)}")
    if period_s <= 0 or cycles <= 0:
        raise ValueError("period_s and cycles must be positive")
    amp = np.deg2rad(amplitude_deg)
    span = (cycles + 0.5) * period_s
    k = _AXES[axis]
    drift_v = np.asarray(drift, dtype=float)

    def angles(t: np.ndarray) -> np.ndarray:
        out = _zeros(t)
        out[:, k] = amp * np.sin(2.0 * np.pi * _ramped_phase(t - rest_s, period_s, cycles))
        return out

    def position(t: np.ndarray) -> np.ndarray:
        return min_jerk((t - rest_s) / span)[:, None] * drift_v

    return Motion(angles, position, span + 2.0 * rest_s)


def min_jerk_reach(
    distance: float = 0.3,
    duration_s: float = 1.2,
    direction_w0: tuple[float, float, float] = (1.0, 0.0, 0.0),
    rest_s: float = 0.5,
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Motion:
    """Straight minimum-jerk reach of ``distance`` m along ``direction_w0`` (normalised).

    Position D (10s^3 - 15s^4 + 6s^5) with s = (t - rest_s)/duration_s: peak speed
    1.875 D/T at mid-reach. ``rotation_deg`` (deviation, flexion, pronation) is reached with
    the same profile, e.g. (0, -20, 0) for a wrist extending while reaching.
    """
    d = np.asarray(direction_w0, dtype=float)
    if not np.linalg.norm(d) > 0 or duration_s <= 0:
        raise ValueError("direction_w0 must be non-zero and duration_s positive")
    d = d / np.linalg.norm(d)
    rot = np.deg2rad(np.asarray(rotation_deg, dtype=float))

    def profile(t: np.ndarray) -> np.ndarray:
        return min_jerk((np.asarray(t, dtype=float) - rest_s) / duration_s)[:, None]

    return Motion(
        lambda t: profile(t) * rot, lambda t: profile(t) * distance * d, duration_s + 2 * rest_s
    )


def still(
    duration_s: float,
    angles_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
    position: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Motion:
    """A hand held still at fixed wrist angles (degrees) and position (W0, metres)."""
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    p = np.asarray(position, dtype=float)
    return Motion(lambda t: _zeros(t) + a, lambda t: _zeros(t) + p, duration_s)


def delay(motion: Motion, seconds: float) -> Motion:
    """The same motion started ``seconds`` later (held at its start value before)."""
    return Motion(
        lambda t: motion.angles(np.asarray(t, dtype=float) - seconds),
        lambda t: motion.position(np.asarray(t, dtype=float) - seconds),
        motion.duration + seconds,
    )


def combine(*motions: Motion) -> Motion:
    """Simultaneous motions: wrist angles and positions add; lasts as long as the longest."""
    return Motion(
        lambda t: sum(m.angles(t) for m in motions),
        lambda t: sum(m.position(t) for m in motions),
        max(m.duration for m in motions),
    )


def neutral_camera_pose(
    distance: float = 0.65, wrist_offset: tuple[float, float] = (0.0, 0.06)
) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose of W0 (R_c0, t_c0): camera above a table, looking at the back of the hand.

    Hand +Z points at the camera (camera -z), fingers (+X) point up in the image (camera -y), so
    the thumb of a right hand (+Y) is on the image left. The wrist sits ``wrist_offset`` metres
    (camera x, y) from the optical axis: by default slightly below centre so the palm is central.
    """
    R_c0 = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # columns X, Y, Z
    return R_c0, np.array([wrist_offset[0], wrist_offset[1], distance])


def timestamps(
    n: int,
    fps: float = 30.0,
    jitter: float = 0.0,
    drop_prob: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Timestamps (s) of ``n`` nominal camera frames at ``fps``, first at exactly 0.

    ``jitter`` is the standard deviation (s) of Gaussian timing noise, clipped to 0.45 of a
    frame interval so the order is kept; each frame but the first is dropped with probability
    ``drop_prob`` (so fewer than n may be returned). Strictly increasing.
    """
    if not 0.0 <= drop_prob < 1.0 or jitter < 0 or fps <= 0:
        raise ValueError("need fps > 0, jitter >= 0 and 0 <= drop_prob < 1")
    rng = np.random.default_rng(rng)
    dt = 1.0 / fps
    t = np.arange(n) * dt
    if jitter > 0:
        t[1:] += np.clip(rng.normal(0.0, jitter, n - 1), -0.45 * dt, 0.45 * dt)
    keep = rng.random(n) >= drop_prob
    keep[0] = True
    return t[keep]


def sample(motion: Motion, times: np.ndarray, R_c0: np.ndarray, t_c0: np.ndarray) -> Trajectory:
    """Sample ``motion`` at ``times`` with W0 at camera pose (R_c0, t_c0).

    Velocities are central differences of the continuous motion with a 1 us step (exact to
    ~1e-9), not differences of the samples.
    """
    t = np.asarray(times, dtype=float).reshape(-1)
    R_rel, p_rel = motion.pose(t)
    R_p, p_p = motion.pose(t + _H)
    R_m, p_m = motion.pose(t - _H)
    step = ((t + _H) - (t - _H))[:, None]  # the step actually represented in floating point
    v = (p_p - p_m) / step
    # dR/dt R^T = skew(w); antisymmetrise to drop the O(h^2) symmetric part.
    W = (R_p - R_m) / step[:, :, None] @ np.swapaxes(R_rel, -1, -2)
    w = geometry.vee(0.5 * (W - np.swapaxes(W, -1, -2)))
    R_c0 = np.asarray(R_c0, dtype=float)
    t_c0 = np.asarray(t_c0, dtype=float)
    return Trajectory(
        t=t,
        R_ch=R_c0 @ R_rel,
        t_ch=p_rel @ R_c0.T + t_c0,
        R_rel=R_rel,
        p_rel=p_rel,
        v=v,
        w=w,
        angles=geometry.wrist_angles(R_rel),
    )


def scenario_motion(name: str) -> tuple[Motion, tuple[np.ndarray, np.ndarray]]:
    """The continuous motion of a named scenario and its camera pose of W0 (R_c0, t_c0)."""
    motion, wrist_offset = _scenario_motion(name)
    return motion, neutral_camera_pose(wrist_offset=wrist_offset)


def _scenario_motion(name: str) -> tuple[Motion, tuple[float, float]]:
    """The motion of a named scenario and where the wrist starts (wrist_offset, metres)."""
    if name == "deviation":  # +-25 deg as in the paper
        return rom_cycle("deviation", 25.0, 2.0, 2, drift=(0.01, 0.005, 0.0)), (0.0, 0.06)
    if name == "flexion":
        return rom_cycle("flexion", 50.0, 2.5, 2, drift=(-0.01, 0.0, 0.005)), (0.0, 0.06)
    if name == "pronation":
        return rom_cycle("pronation", 45.0, 2.0, 2, drift=(0.0, -0.01, 0.005)), (0.0, 0.06)
    if name == "reach":  # up and to the thumb side in the image, lifting slightly
        reach = min_jerk_reach(0.3, 1.2, (0.7, 0.7, 0.15), 1.5, rotation_deg=(0.0, -20.0, 0.0))
        return reach, (0.1, 0.14)
    if name == "mix":
        return combine(
            rom_cycle("deviation", 20.0, 2.0, 3, rest_s=0.6),
            delay(rom_cycle("flexion", 35.0, 3.0, 1, rest_s=0.2), 1.5),
            delay(rom_cycle("pronation", 30.0, 2.4, 2, rest_s=0.3), 0.8),
            delay(min_jerk_reach(0.2, 1.2, (0.6, 0.8, 0.0), 0.0, (0.0, -10.0, 0.0)), 3.0),
        ), (0.06, 0.12)
    raise ConfigError(f"unknown scenario {name!r}; choose one of {', '.join(SCENARIOS)}")


def scenario(
    name: str, fps: float = 30.0, rng: np.random.Generator | int | None = None
) -> tuple[Trajectory, Camera, HandLayout]:
    """A named ground-truth recording (see SCENARIOS) with the default camera and hand.

    "mix" combines the three range-of-motion cycles with a reach under irregular timing
    (jittered, dropped frames); the others are regularly sampled.
    """
    motion, (R_c0, t_c0) = scenario_motion(name)
    n = int(np.floor(motion.duration * fps)) + 1
    irregular = name == "mix"
    times = timestamps(
        n, fps, jitter=0.003 if irregular else 0.0, drop_prob=0.05 if irregular else 0.0, rng=rng
    )
    return sample(motion, times, R_c0, t_c0), Camera.default(), HandLayout.default()
