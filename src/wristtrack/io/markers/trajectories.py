"""Marker trajectories: what every marker format holds, whichever way it is read or written.

:class:`MarkerTrajectories` is the one in-memory form the C3D and TRC writers (and readers of
reference systems) share; :func:`frame_rate` is the single rate such files carry. Formats rely
on this module, never on the analysis that fills it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristtrack.errors import ConfigError, InputError

UNITS = {"mm": 1000.0, "m": 1.0}  # name -> factor from metres
# Timing counts as irregular when some frame interval differs from the median by more than this
# fraction of it (dropped frames, jitter of a USB camera, a skipped backwards timestamp).
IRREGULAR_FRACTION = 0.10


@dataclass(frozen=True)
class MarkerTrajectories:
    """Marker positions over a recording, metres; NaN rows where there is no estimate.

    ``irregular`` says the timestamps are not evenly spaced: formats with a single rate (C3D)
    cannot represent that, so the caller warns.
    """

    names: tuple[str, ...]
    frames: np.ndarray  # (N,) frame numbers (0-based)
    times: np.ndarray  # (N,) s, as recorded
    xyz: np.ndarray  # (N, K, 3) metres
    rate: float  # Hz, 1 / median frame interval
    irregular: bool  # frame intervals spread more than IRREGULAR_FRACTION of the median
    source: str  # where the trajectories came from (a run folder, a file)

    @property
    def valid(self) -> np.ndarray:
        """(N,) frames that have an estimate."""
        return np.isfinite(self.xyz).all(axis=(1, 2))

    def in_units(self, units: str) -> np.ndarray:
        """(N, K, 3) positions in ``units`` ("mm" or "m")."""
        if units not in UNITS:
            raise ConfigError(f"unknown units {units!r}; choose one of {', '.join(UNITS)}")
        return self.xyz * UNITS[units]


def frame_rate(times: np.ndarray, where: str = "poses.csv") -> tuple[float, bool]:
    """(rate in Hz = 1 / median interval, whether the timing is irregular) of timestamps (N,)."""
    times = np.asarray(times, dtype=float)
    if times.size < 2 or not np.isfinite(times).all():
        raise InputError(
            f"{where}: need at least two frames with finite timestamps to know the frame rate, "
            f"got {times.size}; export a longer run"
        )
    dt = np.diff(times)
    median = float(np.median(dt))
    if not median > 0:
        raise InputError(
            f"{where}: timestamps do not increase (median frame interval {median} s); "
            "check the recording's timestamps"
        )
    irregular = bool(np.max(np.abs(dt - median)) > IRREGULAR_FRACTION * median)
    return 1.0 / median, irregular
