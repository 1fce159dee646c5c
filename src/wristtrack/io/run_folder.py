"""Reading a finished run folder of ``wristtrack track`` back: poses.csv and summary.json.

Shared by everything that works on a run after the fact (report, exports, evaluate, compare),
so a missing or damaged run folder gives the same one-line errors everywhere.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.errors import InputError
from wristtrack.io.poses import read_poses

# Without hand.json, the layout `track` surveyed over the recording (tracking/layout_survey.py),
# in hand.json's format, for the subject's other recordings
SURVEYED_HAND = "hand_surveyed.json"
# track --smooth's refit pass, under way (pipeline/refit.py): the run is not complete yet
REFIT_DIR = "refit.partial"


def run_file(run_dir: str | Path, name: str) -> Path:
    """The file ``name`` of a run folder; InputError with one line where the folder or the file
    is missing."""
    run = Path(run_dir)
    if not run.is_dir():
        what = "is a file, not a folder" if run.exists() else "not found"
        raise InputError(f"run folder {run} {what}; give the --out folder of 'wristtrack track'")
    path = run / name
    if not path.is_file():
        raise InputError(
            f"run folder {run} has no {name}; run 'wristtrack track ... --out {run}' first")
    return path


def read_run(run_dir: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """poses.csv columns and summary.json of a run folder; InputError with one line if unusable."""
    poses = run_file(run_dir, "poses.csv")
    return read_poses(poses), read_summary(run_dir)


def read_summary(run_dir: str | Path) -> dict[str, Any]:
    """summary.json of a run folder; InputError with one line if unusable."""
    summary_path = run_file(run_dir, "summary.json")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{summary_path} is not valid JSON ({exc}); re-run the tracking") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("range_of_motion"), dict):
        raise InputError(
            f"{summary_path} is not a wristtrack summary (no range_of_motion); re-run the tracking"
        )
    return summary
