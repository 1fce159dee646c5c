"""Qualisys Track Manager 3-D TSV exports (tab-separated text).

The file opens with ``KEY<TAB>value`` header lines (NO_OF_FRAMES, FREQUENCY, NO_OF_MARKERS,
MARKER_NAMES, ...). Newer QTM versions add TRAJECTORY_TYPES and a column header line
``Frame Time A X A Y A Z ...`` before the data; older ones go straight to rows of X Y Z
triples. Coordinates are in millimetres; a lost marker is written as 0 0 0 (or left empty).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wristtrack.errors import InputError
from wristtrack.io.markers.data import MarkerData, unit_scale, zeros_as_gaps


def _cell(text: str) -> float:
    text = text.strip()
    return float(text) if text else np.nan


def read_tsv(path: str | Path) -> MarkerData:
    """The marker trajectories of a QTM 3-D TSV export, in metres."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8-sig", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    header: dict[str, list[str]] = {}
    i = 0
    while i < len(lines):
        cells = lines[i].split("\t")
        key = cells[0].strip()
        if key and key.replace("_", "").isalpha() and key.isupper():
            header[key] = [c.strip() for c in cells[1:]]
            i += 1
            continue
        break
    if "MARKER_NAMES" not in header or "FREQUENCY" not in header:
        raise InputError(
            f"{path} is not a Qualisys 3-D TSV export (no MARKER_NAMES / FREQUENCY header); "
            "export it from QTM with the 3D data included"
        )
    labels = [c for c in header["MARKER_NAMES"] if c]
    try:
        rate = float(header["FREQUENCY"][0])
    except (IndexError, ValueError):
        rate = float("nan")
    if not rate > 0 or not labels:
        raise InputError(f"{path}: FREQUENCY or MARKER_NAMES is empty")
    units = "mm"  # QTM's 3-D export unit; it is not written in the file
    k = len(labels)
    columns = None
    if i < len(lines) and lines[i].split("\t")[0].strip().lower() == "frame":
        columns = [c.strip().lower() for c in lines[i].split("\t")]
        i += 1
    first = 2 if columns and len(columns) > 1 and columns[1] == "time" else (1 if columns else 0)
    rows, frames = [], []
    for number, line in enumerate(lines[i:], start=i + 1):
        if not line.strip():
            continue
        cells = line.split("\t")
        try:
            values = [_cell(c) for c in cells[first : first + 3 * k]]
            frames.append(_cell(cells[0]) if first else float(len(rows) + 1))
        except ValueError:
            raise InputError(f"{path} line {number}: a cell is not a number") from None
        values += [np.nan] * (3 * k - len(values))
        rows.append(values)
    if not rows:
        raise InputError(f"{path} holds no data rows")
    notes = []
    claimed = header.get("NO_OF_FRAMES", [""])[0]
    if claimed.isdigit() and int(claimed) != len(rows):
        notes.append(f"header claims {claimed} frames; the file holds {len(rows)} rows")
    xyz, zeros = zeros_as_gaps(np.array(rows, dtype=float).reshape(len(rows), k, 3))
    if zeros:
        notes.append(f"{zeros} points at exactly (0, 0, 0) read as gaps")
    frames_a = np.array(frames, dtype=float)
    return MarkerData(
        labels=tuple(labels), times=(frames_a - frames_a[0]) / rate,
        xyz=xyz * unit_scale(units, str(path)), rate=rate, units=units, source=str(path),
        notes=tuple(notes),
    )
