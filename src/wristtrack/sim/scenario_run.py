"""Run the tracker on a simulated scenario and score it: the loop behind demo, tests and bench."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wristtrack.analysis.pose_errors import PoseErrors, labelling_accuracy, pose_errors
from wristtrack.sim.detections import NoiseModel, SimFrame, acceptance_noise, simulate_detections
from wristtrack.sim.motion import Trajectory, scenario
from wristtrack.tracking.tracker import FrameResult, Status, Tracker, TrackerConfig


@dataclass(frozen=True)
class ScenarioRun:
    name: str
    truth: Trajectory
    frames: list[SimFrame]
    results: list[FrameResult]
    errors: PoseErrors
    labelling: dict[str, float]
    lost_frames: int  # frames after the first estimate without an estimate
    model: object = None  # the tracker's state model as the run left it (for the smoother)


def track_scenario(
    name: str,
    config: TrackerConfig | None = None,
    noise: NoiseModel | None = None,
    seed: int = 0,
    give_layout: bool = True,
) -> ScenarioRun:
    """Simulate scenario ``name`` (acceptance noise by default), track it, score it."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario(name, rng=rng)
    noise = acceptance_noise(len(truth.t)) if noise is None else noise
    frames = simulate_detections(truth, camera, layout, noise, rng)
    tracker = Tracker(camera, layout if give_layout else None, config or TrackerConfig())
    results = [tracker.step(f.detections) for f in frames]
    return replace(score_run(name, truth, frames, results), model=tracker.model)


def score_run(
    name: str, truth: Trajectory, frames: list[SimFrame], results: list[FrameResult]
) -> ScenarioRun:
    R = np.stack([r.R_ch for r in results])
    t = np.stack([r.t_ch for r in results])
    errors = pose_errors(R, t, truth.R_ch, truth.t_ch)
    tracked = [i for i, r in enumerate(results) if r.status == Status.TRACKING]
    labelling = labelling_accuracy(
        [results[i].labels for i in tracked], [frames[i].labels for i in tracked]
    )
    has = np.array([r.has_estimate for r in results])
    lost = int((~has[int(np.argmax(has)):]).sum()) if has.any() else len(results)
    return ScenarioRun(name, truth, frames, results, errors, labelling, lost)
