"""Marker trajectories as a reference system (Vicon, Qualisys, Optotrak, ...) records them.

What the readers of :mod:`wristtrack.io.markers.read` return: any labels, the system's own lab
frame, positions converted to metres, NaN where the system lost a marker (a gap). ``notes``
list the quirks met while reading (a header that claims more frames than the file holds, gaps
coded as zeros), so a comparison can state them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wristtrack.errors import InputError

UNIT_SCALE = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def unit_scale(units: str, where: str) -> float:
    """Metres per unit of a file's declared ``units`` ("mm", "cm" or "m", any case)."""
    key = units.strip().lower()
    if key not in UNIT_SCALE:
        raise InputError(
            f"{where}: unknown coordinate units {units!r}; expected one of mm, cm, m"
        )
    return UNIT_SCALE[key]


@dataclass(frozen=True)
class MarkerData:
    """Labelled 3-D marker positions over time, in the recording system's lab frame."""

    labels: tuple[str, ...]
    times: np.ndarray  # (N,) s on the recording system's clock (C3D: 0 at its first frame)
    xyz: np.ndarray  # (N, K, 3) metres; NaN = gap
    rate: float  # Hz, as the file declares it
    units: str  # the units the file stored (the data are converted to metres)
    source: str
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        n, k = self.xyz.shape[:2]
        if self.xyz.shape != (n, k, 3) or len(self.labels) != k or len(self.times) != n:
            raise InputError(
                f"{self.source}: {len(self.labels)} labels, {len(self.times)} times and "
                f"positions of shape {self.xyz.shape} do not fit together"
            )

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def index(self, label: str) -> int:
        """Column of ``label``: exact, else case-insensitive, else without a "Subject:" prefix
        (Vicon Nexus writes 'Derrick:RWRA'). One clear line if it is missing or ambiguous."""
        if label in self.labels:
            return self.labels.index(label)
        want = label.strip().lower()
        for key in (lambda s: s.strip().lower(), lambda s: s.split(":")[-1].strip().lower()):
            hits = [i for i, s in enumerate(self.labels) if key(s) == want]
            if len(hits) == 1:
                return hits[0]
            if len(hits) > 1:
                names = ", ".join(self.labels[i] for i in hits)
                raise InputError(f"{self.source}: marker label {label!r} is ambiguous ({names})")
        shown = ", ".join(self.labels[:40]) + (" ..." if len(self.labels) > 40 else "")
        raise InputError(f"{self.source} has no marker {label!r}; its labels are: {shown}")

    def marker(self, label: str) -> np.ndarray:
        """(N, 3) positions of one marker, metres, NaN in its gaps."""
        return self.xyz[:, self.index(label)]

    def select(self, labels: list[str] | tuple[str, ...]) -> np.ndarray:
        """(N, len(labels), 3) positions of the named markers."""
        return np.stack([self.marker(label) for label in labels], axis=1)


def zeros_as_gaps(xyz: np.ndarray) -> tuple[np.ndarray, int]:
    """Positions with exact (0, 0, 0) points turned into NaN (how QTM and some C3D writers mark
    a lost marker: a real marker is never at the lab origin to the last bit); their count."""
    zero = np.all(xyz == 0.0, axis=-1)
    out = xyz.copy()
    out[zero] = np.nan
    return out, int(zero.sum())
