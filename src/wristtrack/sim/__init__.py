"""Measurement-level simulator: ground-truth wrist motion and what a blob detector would see."""

from wristtrack.sim.detections import (
    NoiseModel,
    SimFrame,
    acceptance_noise,
    simulate_detections,
    visible_markers,
)
from wristtrack.sim.motion import (
    SCENARIOS,
    Motion,
    Trajectory,
    combine,
    delay,
    min_jerk,
    min_jerk_reach,
    neutral_camera_pose,
    rom_cycle,
    sample,
    scenario,
    scenario_motion,
    still,
    timestamps,
)

__all__ = [
    "SCENARIOS",
    "Motion",
    "NoiseModel",
    "SimFrame",
    "Trajectory",
    "acceptance_noise",
    "combine",
    "delay",
    "min_jerk",
    "min_jerk_reach",
    "neutral_camera_pose",
    "rom_cycle",
    "sample",
    "scenario",
    "scenario_motion",
    "simulate_detections",
    "still",
    "timestamps",
    "visible_markers",
]
