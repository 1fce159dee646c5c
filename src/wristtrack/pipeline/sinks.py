"""Where a pass's rows go besides poses.csv: the progress bar, and the sinks of what a pass
does not keep (no --smooth states, the priming pass's rows)."""

from __future__ import annotations

import sys

from wristtrack.io.base import Recording


class Discarded:
    """poses.csv of the priming pass (pipeline/priming.py): kept nowhere."""

    def write(self, row) -> None:
        pass

    def write_result(self, result) -> None:
        pass


class Muted:
    """The priming pass's lines about its frames (a frame skipped): said by the run itself,
    which tracks the same frames again."""

    def write(self, line: str, file=None) -> None:
        pass


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


def progress_bar(recording: Recording, enabled: bool, desc: str = "tracking",
                 counted: bool = True):
    """A progress bar over ``recording``'s frames (``counted``: out of its length)."""
    if not enabled:
        return NoBar()
    from tqdm import tqdm

    try:
        total = (len(recording) or None) if counted else None
    except TypeError:
        total = None
    return tqdm(total=total, unit="frame", desc=desc, leave=False)
