"""OpenSim TRC marker files (tab-separated text), written directly: the format is five header
lines and one row per frame.

- ``DataRate`` = ``CameraRate`` = ``OrigDataRate`` = 1 / median frame interval (the format has one
  rate); the Time column holds the recording's actual timestamps (s).
- ``Frame#`` is 1-based: poses.csv frame + 1 (as C3D frames are).
- ``Units`` is "mm" or "m"; coordinates are in W0, the hand frame at initialisation.
- A frame without an estimate has empty coordinate cells: a gap, never an invented value.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wristtrack.errors import InputError

if TYPE_CHECKING:
    from wristtrack.analysis.export import MarkerTrajectories

HEADER_KEYS = (
    "DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate",
    "OrigDataStartFrame", "OrigNumFrames",
)  # fmt: skip


def trc_text(traj: MarkerTrajectories, units: str = "mm", file_name: str = "markers.trc") -> str:
    """The whole TRC file as text (lines end with '\\n')."""
    xyz = traj.in_units(units)
    n, k = xyz.shape[:2]
    rate = f"{traj.rate:.10g}"
    first = int(traj.frames[0]) + 1 if n else 1
    values = (rate, rate, str(n), str(k), units, rate, str(first), str(n))
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{file_name}",
        "\t".join(HEADER_KEYS),
        "\t".join(values),
        "\t".join(["Frame#", "Time"] + [f"{name}\t\t" for name in traj.names]).rstrip("\t"),
        "\t\t" + "\t".join(f"{c}{i + 1}" for i in range(k) for c in "XYZ"),
        "",  # OpenSim's own writer leaves a blank line before the data
    ]
    for i in range(n):
        row = xyz[i].reshape(-1)
        cells = [str(int(traj.frames[i]) + 1), repr(float(traj.times[i]))]
        cells += ["" if not np.isfinite(c) else f"{c:.9g}" for c in row]
        lines.append("\t".join(cells))
    return "\n".join(lines) + "\n"


def write_trc(path: str | Path, traj: MarkerTrajectories, units: str = "mm") -> None:
    """Write ``traj`` as an OpenSim TRC file (via a temporary file: never a half-written one)."""
    path = Path(path)
    text = trc_text(traj, units, path.name)
    tmp = path.with_name(path.name + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text, encoding="utf-8", newline="\n")
        os.replace(tmp, path)
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror or exc}") from None
