"""wristtrack: 6-DoF wrist pose from one RGB-D camera and six blue markers on the hand.

The public API, loaded on first use so that ``import wristtrack`` stays light (no OpenCV,
Matplotlib or numba until something needs them)::

    import wristtrack as wt
    rec = wt.open_recording("rec/")                       # folder, video or ROS bag
    summary = wt.track_recording(rec, "run/")             # poses.csv, summary.json, report
    poses = wt.read_poses("run/poses.csv")                # columns as NumPy arrays
    print(wt.evaluate("run/poses.csv", "rec/truth.csv"))  # errors against ground truth

Frame by frame: ``wt.MarkerDetector(camera).detect(rgb, depth)`` then
``wt.Tracker(camera, layout).step(detections)``.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# public name -> module that defines it
_API = {
    "WristtrackError": "wristtrack.errors",
    "ConfigError": "wristtrack.errors",
    "InputError": "wristtrack.errors",
    "InitialisationError": "wristtrack.errors",
    "Camera": "wristtrack.camera",
    "HandLayout": "wristtrack.hand",
    "MARKER_NAMES": "wristtrack.hand",
    "wrist_angles": "wristtrack.geometry",
    "MarkerDetector": "wristtrack.detect.detector",
    "Detections": "wristtrack.detect.detections",
    "Tracker": "wristtrack.tracking.tracker",
    "TrackerConfig": "wristtrack.tracking.tracker",
    "FrameResult": "wristtrack.tracking.tracker",
    "Status": "wristtrack.tracking.tracker",
    "open_recording": "wristtrack.io.open",
    "read_poses": "wristtrack.io.poses",
    "track_recording": "wristtrack.pipeline.track",
    "analyse_file": "wristtrack.analysis.kinematics",
    "evaluate": "wristtrack.analysis.evaluate",
    "render_recording": "wristtrack.sim.render",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'wristtrack' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
