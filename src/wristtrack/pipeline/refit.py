"""``track --smooth``'s last pass: the recording tracked again, and smoothed, at the angular
process noise the first smoothed run's rates show (tracking/smoother_noise.py).

The pass runs in the subfolder REFIT_DIR of the run folder, so the first run stays whole
beside it until the refit is complete: an interrupted refit leaves a finished smoothed run
(and its own checkpoint: ``--resume`` completes the refit). A complete refit replaces the
first run's poses.csv and summary.json if it has an estimate in as many frames
(smoother_noise.keeps_refit); either way summary.json says what was learned and used
(``smoothing_process_noise``). poses_filtered.csv and the overlay video stay the first run's:
the filter at the model's noise, as ``track`` without --smooth and a live camera give it (at
the learned noise the filter alone lags a fast turn; only smoothed is it better).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.poses import read_poses
from wristtrack.io.run_folder import REFIT_DIR, read_summary
from wristtrack.pipeline import checkpoint as ckpt
from wristtrack.tracking.smoother_noise import keeps_refit, smoothing_angular_accel
from wristtrack.tracking.tracker import TrackerConfig

_REPLACED = ("poses.csv", "summary.json")  # summary.json last: it says the run is done
_ESTIMATE = ("tracking", "coasting")

# One pass of the run: (its config, the folder it writes, resume) -> its summary.
RunPass = Callable[[TrackerConfig, Path, bool], dict[str, Any]]


def refit_begun(out: Path) -> bool:
    return (out / REFIT_DIR).is_dir()


def clear_refit(out: Path) -> None:
    """Before a fresh run: a previous run's unfinished refit goes."""
    shutil.rmtree(out / REFIT_DIR, ignore_errors=True)


def learned_angular_accel(poses: Path, default: float) -> float | None:
    """The density to track ``poses`` (a smoothed poses.csv) again at, from its rates; None:
    no second pass (smoother_noise.smoothing_angular_accel)."""
    cols = read_poses(poses, ("timestamp", "status", "wx", "wy", "wz"))
    w = np.column_stack([cols["wx"], cols["wy"], cols["wz"]])
    ok = np.isin(cols["status"], _ESTIMATE)
    return smoothing_angular_accel(w, cols["timestamp"], ok, default)


def refit_run(out: Path, config: TrackerConfig, first: dict[str, Any] | None,
              run_pass: RunPass, resume: bool) -> dict[str, Any]:
    """The refit of the finished smoothed run in ``out`` (its summary ``first``; None: read it
    from ``out``); the run's final summary. ``resume`` continues an interrupted refit."""
    first = first if first is not None else read_summary(out)
    default = config.process.angular_accel
    folder = out / REFIT_DIR
    q = learned_angular_accel(out / "poses.csv", default)
    if q is None:
        clear_refit(out)
        return _noted(out, first, default, None, kept=False)
    folder.mkdir(exist_ok=True)
    again = resume and (folder / ckpt.CHECKPOINT_FILE).is_file()
    refit_config = replace(config, process=replace(config.process, angular_accel=q))
    data = run_pass(refit_config, folder, again)
    kept = keeps_refit(first["frames"]["tracked"], data["frames"]["tracked"])
    if kept:
        for name in _REPLACED:
            if (folder / name).exists():
                os.replace(folder / name, out / name)
    clear_refit(out)
    return _noted(out, data if kept else first, default, q, kept)


def _noted(out: Path, summary: dict[str, Any], default: float, learned: float | None,
           kept: bool) -> dict[str, Any]:
    """``summary`` with what the smoothing's process noise was, written to ``out``."""
    summary = {**summary, "smoothing_process_noise": {
        "model_angular_accel": default,
        "learned_angular_accel": learned,  # None: the rates said too little, or near the model
        "angular_accel_used": learned if kept else default,
        "refit_kept": kept,  # False: the refit had an estimate in fewer frames, or none ran
    }}
    write_json_atomic(out / "summary.json", summary)
    return summary
