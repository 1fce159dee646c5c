"""Ctrl-C (SIGINT) and SIGTERM deferred to a safe point of a long loop.

A KeyboardInterrupt raised in the middle of a tracker step would leave the tracker half
updated, so its state could not be saved for ``--resume``. Inside :class:`DeferredInterrupt`
the signal only sets :attr:`requested`; the loop checks it between frames, saves a checkpoint
and stops. A second Ctrl-C raises KeyboardInterrupt at once (the last periodic checkpoint then
stands). Signal handlers can only be set in the main thread: elsewhere (a Dask worker thread)
this does nothing, and no signal arrives there anyway.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType
from typing import Any

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class DeferredInterrupt:
    """Context manager; ``requested`` is the name of the first signal received, else None."""

    def __init__(self) -> None:
        self.requested: str | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.requested is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt  # asked twice: stop now
        self.requested = signal.Signals(signum).name

    def __enter__(self) -> DeferredInterrupt:
        if threading.current_thread() is threading.main_thread():
            for sig in _SIGNALS:
                previous = signal.getsignal(sig)
                if previous is signal.SIG_IGN:  # e.g. a background job: leave it ignored
                    continue
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous.clear()
