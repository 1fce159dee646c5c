"""C3D marker files through ezc3d (optional dependency: ``pip install 'wristtrack[c3d]'``).

- POINT:LABELS are the marker names, POINT:RATE = 1 / median frame interval, POINT:UNITS "mm"
  or "m", coordinates in W0 (the hand frame at initialisation); float storage (SCALE -1).
- A frame without an estimate is a gap as C3D defines it: residual -1 (ezc3d reads it back as
  NaN coordinates); estimated points have residual 0.
- C3D has no per-frame time: the file's frame 1 is the run's first frame and frame i lies
  (i - 1) / rate after it; irregular timing cannot be represented (the caller warns).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wristtrack.errors import ConfigError, InputError

if TYPE_CHECKING:
    from wristtrack.analysis.export import MarkerTrajectories


def _ezc3d():
    try:
        import ezc3d
    except ImportError:
        raise ConfigError(
            "C3D export needs the ezc3d package: pip install 'wristtrack[c3d]'"
        ) from None
    return ezc3d


def write_c3d(path: str | Path, traj: MarkerTrajectories, units: str = "mm") -> None:
    """Write ``traj`` as a C3D file of the six marker trajectories."""
    ezc3d = _ezc3d()
    path = Path(path)
    xyz = traj.in_units(units)  # (N, K, 3)
    n, k = xyz.shape[:2]
    points = np.ones((4, k, n))
    points[:3] = xyz.transpose(2, 1, 0)
    residuals = np.where(np.isfinite(xyz).all(axis=2).T, 0.0, -1.0)[None]  # (1, K, N)
    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [float(traj.rate)]
    point["LABELS"]["value"] = tuple(traj.names)
    point["DESCRIPTIONS"]["value"] = tuple(f"{name} marker (wristtrack, W0 frame)" for name in
                                           traj.names)
    point["UNITS"]["value"] = [units]
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {"residuals": residuals}
    tmp = path.with_name(path.stem + ".tmp.c3d")  # ezc3d appends .c3d to other names
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        c3d.write(str(tmp))
        os.replace(tmp, path)
    except (OSError, RuntimeError) as exc:
        raise InputError(f"cannot write {path}: {exc}") from None
