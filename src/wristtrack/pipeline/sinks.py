"""Where a pass's rows go besides poses.csv: the progress bar, and the sink of what a pass
does not keep (the filter states of a run without --smooth)."""

from __future__ import annotations

import sys

from wristtrack.io.base import Recording


class NoStates:
    """The filter states of a run without --smooth: kept nowhere."""

    def write(self, frame: int, timestamp: float, result) -> None:
        pass

    def flush(self) -> None:
        pass

    def __enter__(self) -> NoStates:
        return self

    def __exit__(self, *exc) -> None:
        pass


class NoBar:
    """No progress bar (--no-progress); what it is told to write still goes to stderr."""

    def update(self, n: int) -> None:
        pass

    def write(self, line: str, file=None) -> None:
        print(line, file=file or sys.stderr)

    def close(self) -> None:
        pass


def progress_bar(recording: Recording, enabled: bool, desc: str = "tracking"):
    """A progress bar over ``recording``'s frames."""
    if not enabled:
        return NoBar()
    from tqdm import tqdm

    try:
        total = len(recording) or None
    except TypeError:
        total = None
    return tqdm(total=total, unit="frame", desc=desc, leave=False)
