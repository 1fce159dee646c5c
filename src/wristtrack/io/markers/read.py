"""One entry point for a reference system's marker file: C3D, OpenSim TRC or Qualisys TSV."""

from __future__ import annotations

from pathlib import Path

from wristtrack.errors import InputError
from wristtrack.io.markers.data import MarkerData

MARKER_SUFFIXES = (".c3d", ".trc", ".tsv")


def read_markers(path: str | Path) -> MarkerData:
    """Marker trajectories (metres) of ``path``, by its suffix."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"marker file {path} not found")
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        from wristtrack.io.markers.c3d import read_c3d

        return read_c3d(path)
    if suffix == ".trc":
        from wristtrack.io.markers.trc import read_trc

        return read_trc(path)
    if suffix == ".tsv":
        from wristtrack.io.markers.tsv import read_tsv

        return read_tsv(path)
    raise InputError(
        f"{path}: unknown reference format {suffix or '(no suffix)'}; give a .c3d, .trc, .tsv "
        "or a truth.csv"
    )
