"""The marker file formats by name: ``write_markers(traj, "c3d" | "trc", path)``.

A new format is one module in this package plus one entry in :data:`WRITERS` (and its default
file name in :data:`FILE_NAMES`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from wristtrack.errors import ConfigError
from wristtrack.io.markers.c3d import write_c3d
from wristtrack.io.markers.trajectories import MarkerTrajectories
from wristtrack.io.markers.trc import write_trc

WRITERS: dict[str, Callable[[Path, MarkerTrajectories, str], None]] = {
    "c3d": write_c3d,
    "trc": write_trc,
}
FILE_NAMES = {"c3d": "markers.c3d", "trc": "markers.trc"}  # default name in a run folder


def check_format(fmt: str) -> None:
    """ConfigError naming the formats if ``fmt`` is not one of them."""
    if fmt not in WRITERS:
        raise ConfigError(f"unknown export format {fmt!r}; choose one of {', '.join(WRITERS)}")


def write_markers(traj: MarkerTrajectories, fmt: str, out: str | Path, units: str = "mm") -> Path:
    """Write ``traj`` as ``fmt`` ("c3d" or "trc") to the file ``out``; returns its path."""
    check_format(fmt)
    out = Path(out)
    WRITERS[fmt](out, traj, units)
    return out
