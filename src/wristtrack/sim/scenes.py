"""Scenario definitions of the image simulator: motion, timing and what else is in the picture.

A :class:`Scene` is everything :mod:`wristtrack.sim.render` needs to draw a recording: the
continuous ground-truth motion (from :mod:`wristtrack.sim.motion`), the frame timestamps, the
camera and hand, and the nuisances switched on (clutter, an occluder, motion blur, brightness
drift, no depth, no hand.json). :func:`make_scene` builds the named scenarios of
RENDER_SCENARIOS.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError
from wristtrack.hand import HandLayout
from wristtrack.sim import realism
from wristtrack.sim.codec import require_pyav
from wristtrack.sim.motion import (
    Motion,
    Trajectory,
    neutral_camera_pose,
    sample,
    scenario_motion,
    still,
    timestamps,
)

RENDER_SCENARIOS = (
    "deviation",
    "flexion",
    "pronation",
    "reach",
    "clutter",
    "occlusion",
    "rgb_only",
    "no_hand",
    "irregular",
    "hard",
)


@dataclass(frozen=True)
class Occlusion:
    """A dark pen slid in from the ulnar side over MCP4 and MCP5, held, then withdrawn.

    Times are fractions of the recording: it starts entering at ``enter``, covers both markers
    from ``cover`` to ``leave`` and is gone at ``gone``. ``lift`` (m) is its height above the
    back of the hand, along the line of sight.
    """

    enter: float = 0.38
    cover: float = 0.45
    leave: float = 0.58
    gone: float = 0.65
    lift: float = 0.06
    radius: float = 0.009


@dataclass(frozen=True)
class Scene:
    """A renderable recording. ``motion`` is relative to W0, which sits at (R_c0, t_c0).

    ``times`` are the frame timestamps (s). ``exposure`` (s) sets the motion blur (the frame is
    the mean of sub-frame renders over the exposure, centred on the timestamp); ``gain_drift``
    the relative amplitude of the slow brightness drift; ``noise`` scales the sensor noise.
    """

    name: str
    motion: Motion
    R_c0: np.ndarray
    t_c0: np.ndarray
    times: np.ndarray
    camera: Camera = field(default_factory=Camera.default)
    layout: HandLayout = field(default_factory=HandLayout.default)
    depth: bool = True
    write_hand: bool = True
    clutter: bool = False
    occlusion: Occlusion | None = None
    exposure: float = 0.008
    gain_drift: float = 0.04
    noise: float = 1.0
    effects: frozenset[str] = frozenset()  # realism effects switched on (sim.realism.EFFECTS)

    def trajectory(self) -> Trajectory:
        """Ground truth at the frame timestamps."""
        return sample(self.motion, self.times, self.R_c0, self.t_c0)

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0]) if len(self.times) > 1 else 0.0

    @property
    def fps(self) -> float:
        """Nominal frame rate (the median frame interval's)."""
        return 1.0 / float(np.median(np.diff(self.times))) if len(self.times) > 1 else 30.0


def mirrored(motion: Motion) -> Motion:
    """The same movement made the other way across the hand: deviation and pronation of the
    opposite sign (ulnar for radial, supination for pronation), flexion as it is, and the wrist's
    path mirrored sideways (W0's Y). What the other hand does when it makes the same anatomical
    movement, in a scene whose hand is not mirrored: with a left hand, the right hand's
    anatomical movement, and the reverse."""
    sign, side = np.array([-1.0, 1.0, -1.0]), np.array([1.0, -1.0, 1.0])
    return Motion(
        lambda t: motion.angles(t) * sign,
        lambda t: motion.position(t) * side,
        motion.duration,
    )


def time_scaled(motion: Motion, factor: float) -> Motion:
    """The same movement played ``factor`` times faster (factor < 1: slower)."""
    if not factor > 0:
        raise ValueError("factor must be positive")
    return Motion(
        lambda t: motion.angles(np.asarray(t, dtype=float) * factor),
        lambda t: motion.position(np.asarray(t, dtype=float) * factor),
        motion.duration / factor,
    )


def back_turned(duration_s: float = 1.0, pronation_deg: float = 150.0) -> Motion:
    """A hand held still and turned over (palm to the camera): its markers cannot be seen."""
    return still(duration_s, angles_deg=(0.0, 0.0, pronation_deg))


# Per scenario: (motion of sim.motion, irregular timing, clutter, occlusion, depth, hand.json,
# exposure s, gain drift, noise scale).
_SPECS: dict[str, dict[str, Any]] = {
    "deviation": {"motion": "deviation"},
    "flexion": {"motion": "flexion"},
    "pronation": {"motion": "pronation"},
    "reach": {"motion": "reach", "exposure": 0.012},
    "clutter": {"motion": "mix", "clutter": True},
    "occlusion": {"motion": "deviation", "occlusion": True},
    "rgb_only": {"motion": "mix", "depth": False},
    "no_hand": {"motion": "mix", "write_hand": False},
    "irregular": {"motion": "mix", "irregular": True},
    "hard": {
        "motion": "mix",
        "irregular": True,
        "clutter": True,
        "occlusion": True,
        "exposure": 0.025,
        "gain_drift": 0.25,
        "noise": 1.6,
    },
}

_OPTIONS = ("fps", "duration", "n_frames", "camera", "layout", "exposure", "gain_drift", "noise",
            "effects", "hand_side")


def make_scene(name: str, seed: int = 0, **options: Any) -> Scene:
    """The named scenario (one of RENDER_SCENARIOS), with ``options``:

    - ``fps`` (30): nominal frame rate;
    - ``duration`` (s): play the scenario's movement faster or slower to last this long;
    - ``n_frames``: number of nominal frames; without ``duration`` the whole movement is
      squeezed into them, so a short test recording still contains all of it;
    - ``camera`` (Camera or camera.json path), ``layout`` (HandLayout or hand.json path);
    - ``exposure`` (s), ``gain_drift``, ``noise``: override the scenario's settings;
    - ``effects``: names of :data:`wristtrack.sim.realism.EFFECTS` to switch on (e.g.
      ``realism.PRESET_REAL``); ``hand_side`` ("right" or "left"): "left" is the
      ``left_hand`` effect.

    Irregular timing (jitter 3 ms, 5 % dropped frames) is drawn from ``seed``.
    """
    if name not in _SPECS:
        raise ConfigError(
            f"unknown render scenario {name!r}; choose one of {', '.join(RENDER_SCENARIOS)}"
        )
    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise ConfigError(
            f"unknown render option(s) {', '.join(unknown)}; use {', '.join(_OPTIONS)}"
        )
    spec = _SPECS[name]
    fps = float(options.get("fps", 30.0))
    if not fps > 0:
        raise ConfigError(f"render option fps must be positive, got {fps!r}")
    motion, (R_c0, t_c0) = scenario_motion(spec["motion"])
    natural = motion.duration
    duration = options.get("duration")
    n_frames = options.get("n_frames")
    if n_frames is not None and int(n_frames) < 1:
        raise ConfigError(f"render option n_frames must be at least 1, got {n_frames!r}")
    if duration is None and n_frames is not None and int(n_frames) > 1:
        duration = (int(n_frames) - 1) / fps
    if duration is not None:
        if not float(duration) > 0:
            raise ConfigError("render option duration (or n_frames - 1) must be positive")
        motion = time_scaled(motion, natural / float(duration))
    n = int(n_frames) if n_frames is not None else int(np.floor(motion.duration * fps + 1e-9)) + 1
    irregular = spec.get("irregular", False)
    times = timestamps(
        n,
        fps,
        jitter=0.003 if irregular else 0.0,
        drop_prob=0.05 if irregular else 0.0,
        rng=np.random.default_rng([seed, 1]),
    )
    scene = Scene(
        name=name,
        motion=motion,
        R_c0=R_c0,
        t_c0=t_c0,
        times=times,
        depth=spec.get("depth", True),
        write_hand=spec.get("write_hand", True),
        clutter=spec.get("clutter", False),
        occlusion=Occlusion() if spec.get("occlusion") else None,
        exposure=spec.get("exposure", 0.008),
        gain_drift=spec.get("gain_drift", 0.04),
        noise=spec.get("noise", 1.0),
    )
    changes: dict[str, Any] = {}
    for key in ("exposure", "gain_drift", "noise"):
        if key in options:
            value = float(options[key])
            if value < 0:
                raise ConfigError(f"render option {key} must be >= 0, got {value!r}")
            changes[key] = value
    camera = options.get("camera")
    if camera is not None:
        changes["camera"] = camera if isinstance(camera, Camera) else Camera.load(camera)
    layout = options.get("layout")
    if layout is not None:
        changes["layout"] = layout if isinstance(layout, HandLayout) else HandLayout.load(layout)
    scene = replace(scene, **changes)
    return with_effects(scene, options.get("effects", ()), options.get("hand_side", "right"),
                        keep_exposure="exposure" in options, seed=seed)


def with_effects(scene: Scene, effects: Any, hand_side: str = "right",
                 keep_exposure: bool = False, seed: int = 0) -> Scene:
    """``scene`` with realism ``effects`` switched on: those that change the hand or the camera
    (left hand, arched layout, lens distortion, long shutter) are applied to them here, the
    others when rendering. ``keep_exposure``: an exposure chosen explicitly wins over the
    ``shutter`` effect's. ``seed`` draws the depth stream's delay (``depth_lag``) and the
    rolling shutter's readout (``rolling_shutter``)."""
    names = set(realism.check_effects(effects))
    if hand_side not in ("right", "left"):
        raise ConfigError(f"hand side must be 'right' or 'left', got {hand_side!r}")
    if hand_side == "left":
        names.add("left_hand")
    if not names:
        return scene
    if "h264" in names:
        require_pyav()  # fail before a recording folder is created
    layout, camera, exposure = scene.layout, scene.camera, scene.exposure
    if "left_hand" in names:
        layout = realism.left(layout)
    if "nonplanar" in names:
        layout = realism.arched(layout)
    if "distortion" in names:
        camera = realism.distorted(camera)
    if "depth_lag" in names and scene.depth:
        camera = replace(camera, depth_delay=realism.depth_delay(seed, scene.fps))
    if "rolling_shutter" in names:
        camera = replace(camera, readout=realism.readout(seed, scene.fps))
    if "shutter" in names and not keep_exposure:
        exposure = realism.LONG_SHUTTER_S
    return replace(scene, layout=layout, camera=camera, exposure=exposure,
                   effects=frozenset(names))


def custom_scene(name: str, motion: Motion, times: np.ndarray, **fields: Any) -> Scene:
    """A scene of any motion (e.g. :func:`back_turned`) at the default camera pose."""
    R_c0, t_c0 = neutral_camera_pose()
    return Scene(name=name, motion=motion, R_c0=R_c0, t_c0=t_c0, times=np.asarray(times), **fields)
