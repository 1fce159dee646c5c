"""OpenSim TRC marker files (tab-separated text), written and read directly: the format is five
header lines and one row per frame.

- ``DataRate`` = ``CameraRate`` = ``OrigDataRate`` = 1 / median frame interval (the format has one
  rate); the Time column holds the recording's actual timestamps (s).
- ``Frame#`` is 1-based: poses.csv frame + 1 (as C3D frames are).
- ``Units`` is "mm" or "m"; coordinates are in W0, the hand frame at initialisation.
- A frame without an estimate has empty coordinate cells: a gap, never an invented value.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wristtrack.errors import InputError
from wristtrack.io.atomic import write_text_atomic
from wristtrack.io.markers.data import MarkerData, unit_scale, zeros_as_gaps
from wristtrack.io.markers.trajectories import MarkerTrajectories

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
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, text)
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror or exc}") from None


def _number(cell: str) -> float:
    cell = cell.strip()
    return float(cell) if cell else np.nan


def read_trc(path: str | Path) -> MarkerData:
    """The marker trajectories of a TRC file, in metres.

    Real files are read as they are, not as their header says: the frames are the data rows
    actually present (a header may claim more, e.g. 1300 for 138 rows; noted), empty cells and
    short rows are gaps, a blank line before the data is skipped, and the Time column is used
    as written (a missing or non-numeric one is rebuilt from Frame# and DataRate).
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise InputError(f"{path} is not a TRC file (its first line is not 'PathFileType ...')")
    keys = [c.strip() for c in lines[1].split("\t")]
    values = [c.strip() for c in lines[2].split("\t")]
    header = dict(zip(keys, values, strict=False))
    try:
        rate = float(header.get("DataRate") or header.get("CameraRate") or "nan")
    except ValueError:
        rate = float("nan")
    if not rate > 0:
        raise InputError(f"{path}: the header gives no DataRate; cannot time the frames")
    units = header.get("Units", "")
    notes = []
    if not units:
        units = "mm"
        notes.append("Units missing from the header: millimetres assumed")
    scale = unit_scale(units, str(path))
    labels = [c.strip() for c in lines[3].split("\t")[2:] if c.strip()]
    if not labels:
        raise InputError(f"{path}: line 4 names no markers")
    k = len(labels)
    rows = []
    for number, line in enumerate(lines[5:], start=6):
        cells = line.split("\t")
        if not line.strip():
            continue
        try:
            frame, time = _number(cells[0]), _number(cells[1]) if len(cells) > 1 else np.nan
            coords = [_number(c) for c in cells[2 : 2 + 3 * k]]
        except ValueError:
            raise InputError(f"{path} line {number}: a cell is not a number") from None
        coords += [np.nan] * (3 * k - len(coords))  # trailing gaps left out by some writers
        rows.append([frame, time, *coords])
    if not rows:
        raise InputError(f"{path} holds no data rows")
    data = np.array(rows, dtype=float)
    claimed = header.get("NumFrames", "")
    if claimed.isdigit() and int(claimed) != len(data):
        notes.append(f"header claims {claimed} frames; the file holds {len(data)} rows")
    times = data[:, 1]
    if not np.isfinite(times).all():
        times = (data[:, 0] - data[0, 0]) / rate
        notes.append("Time column incomplete: times rebuilt from Frame# and DataRate")
    xyz, zeros = zeros_as_gaps(data[:, 2:].reshape(len(data), k, 3))
    if zeros:
        notes.append(f"{zeros} points at exactly (0, 0, 0) read as gaps")
    return MarkerData(
        labels=tuple(labels), times=times, xyz=xyz * scale, rate=rate, units=units,
        source=str(path), notes=tuple(notes),
    )
