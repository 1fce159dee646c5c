"""The filter's per-frame states, streamed to a run folder for the offline smoother.

``track --smooth`` needs every frame's filter state and covariance after the run; keeping them
in memory would make memory grow with the recording, so they go to ``filter_states.f64`` as the
run goes: a header of four float64 (format version, state size D, tangent size n, record size)
and then one fixed-size float64 record per frame: frame, timestamp, track id (-1 = no state: no
track, or nothing predicted), the state (D) and the covariance (n*n). One record per poses.csv
row, so a resumed run truncates both to the same frame count. A record cut short by an
interrupted run is ignored by the reader.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wristtrack.errors import InputError

STATES_FILE = "filter_states.f64"
_VERSION = 1.0
_HEADER = 4


@dataclass(frozen=True)
class StateLog:
    """Every frame's filter state as read back: NaN rows where ``track_id`` is -1."""

    frame: np.ndarray  # (N,) int
    timestamp: np.ndarray  # (N,)
    track_id: np.ndarray  # (N,) int, -1 where the frame has no state
    x: np.ndarray  # (N, D)
    P: np.ndarray  # (N, n, n)


class StateWriter:
    """Appends one record per frame; ``flush`` when poses.csv is flushed."""

    def __init__(self, path: str | Path, state_dim: int, tangent_dim: int, append: bool = False):
        self.path = Path(path)
        self.D, self.n = state_dim, tangent_dim
        self.record = 3 + self.D + self.n * self.n
        header = np.array([_VERSION, self.D, self.n, self.record])
        if append and self.path.exists() and self.path.stat().st_size >= 8 * _HEADER:
            existing = np.fromfile(self.path, dtype=np.float64, count=_HEADER)
            if not np.array_equal(existing, header):
                raise InputError(
                    f"{self.path} holds states of another filter model; remove it or track "
                    "the run again without --resume"
                )
            self._fh = open(self.path, "ab")  # noqa: SIM115
        else:
            self._fh = open(self.path, "wb")  # noqa: SIM115
            self._fh.write(header.tobytes())
        self._buffer = np.empty(self.record)

    def write(self, frame: int, timestamp: float, result) -> None:
        """Record a tracker.FrameResult: its state where it has one (an estimate, or a track's
        prediction too uncertain to report, which the smoother may still use), else NaN."""
        buf = self._buffer
        buf[0], buf[1] = frame, timestamp
        if (result is not None and result.x is not None and result.cov is not None
                and result.track_id >= 0):
            buf[2] = result.track_id
            buf[3 : 3 + self.D] = result.x
            buf[3 + self.D :] = result.cov.ravel()
        else:
            buf[2] = -1
            buf[3:] = np.nan
        self._fh.write(buf.tobytes())

    def flush(self) -> None:
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> StateWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_states(path: str | Path) -> StateLog:
    """Read a filter_states.f64; a trailing partial record is dropped."""
    path = Path(path)
    try:
        data = np.fromfile(path, dtype=np.float64)
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    if data.size < _HEADER or data[0] != _VERSION:
        raise InputError(f"{path} is not a wristtrack filter-state file; track the run again")
    D, n, record = (int(v) for v in data[1:_HEADER])
    if record != 3 + D + n * n:
        raise InputError(f"{path} has an inconsistent header; track the run again")
    body = data[_HEADER:]
    rows = body[: body.size // record * record].reshape(-1, record)
    return StateLog(
        frame=rows[:, 0].astype(int),
        timestamp=rows[:, 1].copy(),
        track_id=rows[:, 2].astype(int),
        x=rows[:, 3 : 3 + D].copy(),
        P=rows[:, 3 + D :].reshape(-1, n, n).copy(),
    )


def truncate_states(path: str | Path, n_frames: int) -> None:
    """Keep the first ``n_frames`` records (for a resumed run)."""
    path = Path(path)
    header = np.fromfile(path, dtype=np.float64, count=_HEADER)
    record = int(header[3])
    with open(path, "r+b") as fh:
        fh.truncate(8 * (_HEADER + n_frames * record))
