"""``wristtrack demo``: the main job on a bundled default, with nothing to set up.

Renders a deterministic simulated recording (once), tracks it with ``wristtrack track``'s
pipeline, smooths it (unscented RTS), writes the clinician's report and scores the filtered and
the smoothed poses against the simulator's ground truth.
"""

from __future__ import annotations

import time
from pathlib import Path

from wristtrack.analysis.evaluate import evaluate, format_report
from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.open import open_recording
from wristtrack.pipeline.smoothing import FILTERED_POSES
from wristtrack.pipeline.track import track_recording
from wristtrack.report.html import write_report
from wristtrack.sim.render import render_recording
from wristtrack.tracking.tracker import TrackerConfig

DEFAULT_SCENARIO = "reach"


def run_demo(out: str | Path, scenario: str = DEFAULT_SCENARIO, seed: int = 0,
             config: TrackerConfig | None = None, progress: bool = True,
             smooth: bool = True) -> dict:
    """Render (if not there yet), track, smooth, report and evaluate; returns the evaluation
    of the run's poses.csv (smoothed unless ``smooth`` is False)."""
    out = Path(out)
    recording_dir = out / f"recording-{scenario}-{seed}"
    if not (recording_dir / "frames.csv").exists():
        print(f"rendering the simulated '{scenario}' recording into {recording_dir} ...")
        render_recording(recording_dir, scenario, seed=seed, overwrite=True)
    run_dir = out / f"run-{scenario}-{seed}"
    start = time.perf_counter()
    with open_recording(recording_dir) as recording:
        n_frames = len(recording)
        summary = track_recording(recording, run_dir, config, progress=progress, smooth=smooth)
    seconds = time.perf_counter() - start
    report = write_report(run_dir)
    truth = recording_dir / "truth.csv"
    result = evaluate(run_dir / "poses.csv", truth)
    write_json_atomic(run_dir / "evaluation.json", result)
    frames = summary["frames"]
    print(f"tracked {frames['tracked']} of {frames['total']} frames in {seconds:.1f} s "
          f"({n_frames / seconds:.0f} frames/s, recording at {n_frames / summary['duration_s']:.0f}"
          " frames/s)")
    if smooth and (run_dir / FILTERED_POSES).exists():
        filtered = evaluate(run_dir / FILTERED_POSES, truth)
        print(f"smoothing: orientation RMSE {filtered['orientation_rmse_deg']:.2f} -> "
              f"{result['orientation_rmse_deg']:.2f} deg, position RMSE "
              f"{filtered['position_rmse_mm']:.2f} -> {result['position_rmse_mm']:.2f} mm")
    print(format_report(result))
    for reach in summary.get("kinematics", {}).get("reaches", []):
        print(f"reach {reach['index']}: movement time {reach['movement_time_s']:.2f} s, peak speed "
              f"{reach['peak_speed_m_s']:.3f} m/s at {reach['time_to_peak_pct']:.0f}% of it, "
              f"SPARC {reach['sparc']:.2f}")
    print(f"outputs: {run_dir}/poses.csv, summary.json, evaluation.json")
    print(f"report: {report}")
    return result
