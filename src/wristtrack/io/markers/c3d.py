"""C3D marker files through ezc3d (optional dependency: ``pip install 'wristtrack[c3d]'``):
:func:`write_c3d` for our exports, :func:`read_c3d` for a reference system's recordings.

- POINT:LABELS are the marker names, POINT:RATE = 1 / median frame interval, POINT:UNITS "mm"
  or "m", coordinates in W0 (the hand frame at initialisation); float storage (SCALE -1).
- A frame without an estimate is a gap as C3D defines it: residual -1 (ezc3d reads it back as
  NaN coordinates); estimated points have residual 0.
- C3D has no per-frame time: the file's frame 1 is the run's first frame and frame i lies
  (i - 1) / rate after it; irregular timing cannot be represented (the caller warns).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wristtrack.errors import ConfigError, InputError
from wristtrack.io.atomic import atomic_path
from wristtrack.io.markers.data import MarkerData, unit_scale, zeros_as_gaps
from wristtrack.io.markers.trajectories import MarkerTrajectories


def _ezc3d():
    try:
        import ezc3d
    except ImportError:
        raise ConfigError(
            "C3D files need the ezc3d package: pip install 'wristtrack[c3d]'"
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
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path, suffix=".tmp.c3d") as tmp:  # ezc3d appends .c3d to other names
            c3d.write(str(tmp))
    except (OSError, RuntimeError) as exc:
        raise InputError(f"cannot write {path}: {exc}") from None


def _labels(point: dict) -> list[str]:
    """POINT:LABELS, continued in LABELS2, LABELS3, ... (C3D caps one parameter at 255)."""
    labels = list(point["LABELS"]["value"])
    k = 2
    while f"LABELS{k}" in point:
        labels += list(point[f"LABELS{k}"]["value"])
        k += 1
    return [str(label).strip() for label in labels]


def read_c3d(path: str | Path) -> MarkerData:
    """The marker trajectories of a C3D file, in metres (POINT:UNITS says what the file used).

    Gaps: ezc3d gives NaN where a point's residual is negative; points at exactly (0, 0, 0) are
    gaps too (some writers mark lost markers so). Times run from 0 at the file's first frame.
    """
    ezc3d = _ezc3d()
    path = Path(path)
    if not path.is_file():
        raise InputError(f"reference file {path} not found")
    try:
        c3d = ezc3d.c3d(str(path))
    except (RuntimeError, OSError, ValueError) as exc:
        raise InputError(f"{path} is not a readable C3D file ({exc})") from None
    point = c3d["parameters"]["POINT"]
    rate = float(c3d["header"]["points"]["frame_rate"])
    if "RATE" in point and len(point["RATE"]["value"]):
        rate = float(point["RATE"]["value"][0])
    if not rate > 0:
        raise InputError(f"{path}: POINT:RATE is {rate}; the file does not say its frame rate")
    units = str(point["UNITS"]["value"][0]).strip() if "UNITS" in point else "mm"
    notes = []
    if not units:
        units = "mm"  # the C3D default
        notes.append("POINT:UNITS empty: millimetres assumed (the C3D default)")
    scale = unit_scale(units, str(path))
    labels = _labels(point)
    xyz = np.asarray(c3d["data"]["points"][:3], dtype=float).transpose(2, 1, 0)  # (N, K, 3)
    if xyz.shape[1] != len(labels):
        raise InputError(f"{path}: {xyz.shape[1]} points but {len(labels)} labels")
    xyz, zeros = zeros_as_gaps(xyz)
    if zeros:
        notes.append(f"{zeros} points at exactly (0, 0, 0) read as gaps")
    n = xyz.shape[0]
    return MarkerData(
        labels=tuple(labels), times=np.arange(n) / rate, xyz=xyz * scale, rate=rate,
        units=units, source=str(path), notes=tuple(notes),
    )
