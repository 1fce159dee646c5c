"""``wristtrack demo``: the main job on a bundled default, with nothing to set up.

Renders a deterministic simulated recording (once), tracks it with ``wristtrack track``'s
pipeline and scores the run against the simulator's ground truth.
"""

from __future__ import annotations

import time
from pathlib import Path

from wristtrack.evaluate import evaluate, format_report
from wristtrack.io.recording import open_recording
from wristtrack.pipeline import track_recording
from wristtrack.sim.render import render_recording
from wristtrack.summary import write_json_atomic
from wristtrack.tracker import TrackerConfig

DEFAULT_SCENARIO = "reach"


def run_demo(out: str | Path, scenario: str = DEFAULT_SCENARIO, seed: int = 0,
             config: TrackerConfig | None = None, progress: bool = True) -> dict:
    """Render (if not there yet), track and evaluate; returns the evaluation."""
    out = Path(out)
    recording_dir = out / f"recording-{scenario}-{seed}"
    if not (recording_dir / "frames.csv").exists():
        print(f"rendering the simulated '{scenario}' recording into {recording_dir} ...")
        render_recording(recording_dir, scenario, seed=seed, overwrite=True)
    run_dir = out / f"run-{scenario}-{seed}"
    start = time.perf_counter()
    with open_recording(recording_dir) as recording:
        n_frames = len(recording)
        summary = track_recording(recording, run_dir, config, progress=progress)
    seconds = time.perf_counter() - start
    result = evaluate(run_dir / "poses.csv", recording_dir / "truth.csv")
    write_json_atomic(run_dir / "evaluation.json", result)
    frames = summary["frames"]
    print(f"tracked {frames['tracked']} of {frames['total']} frames in {seconds:.1f} s "
          f"({n_frames / seconds:.0f} frames/s, recording at {n_frames / summary['duration_s']:.0f}"
          " frames/s)")
    print(format_report(result))
    print(f"outputs: {run_dir}/poses.csv, summary.json, evaluation.json")
    return result
