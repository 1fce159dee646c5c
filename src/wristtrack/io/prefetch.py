"""Reading frames ahead in a background thread, while the caller processes the previous ones.

Decoding a frame (PNG colour and depth, a video frame) takes about as long as detecting and
tracking it, and OpenCV's decoders release the GIL: on two cores the two overlap, and a run
goes nearly at the pace of whichever is slower instead of their sum.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, closing
from typing import TYPE_CHECKING, Generic, TypeVar

if TYPE_CHECKING:
    from wristtrack.io.base import Frame, Recording

T = TypeVar("T")

AHEAD = 4  # frames decoded ahead: enough to absorb one slow frame, little memory (VGA: 6 MB)
_POLL_S = 0.05  # how often a blocked reader looks whether it has been stopped


class _End:
    """The source is exhausted."""


class _Raised:
    """The source raised ``error``: the consumer raises it in its own thread."""

    def __init__(self, error: BaseException) -> None:
        self.error = error


class Prefetch(Generic[T]):
    """Iterates ``source`` (a generator, e.g. ``Recording.frames()``) in a background thread,
    up to ``ahead`` items in advance; yields its items in order and raises its exceptions where
    they would have been met. The source is only ever advanced and closed by that thread.

    Use it as a context manager (or call :meth:`close`): leaving stops the thread, which closes
    the source (its files, its video capture) before the caller goes on.
    """

    def __init__(self, source: Iterator[T], ahead: int = AHEAD) -> None:
        if ahead < 1:
            raise ValueError(f"ahead must be at least 1, not {ahead}")
        self._source = source
        self._queue: queue.Queue = queue.Queue(maxsize=ahead)
        self._stop = threading.Event()
        self._done = False
        self._thread = threading.Thread(target=self._read, name="wristtrack-prefetch",
                                        daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            for item in self._source:
                if not self._put(item):
                    return
            self._put(_End())
        except BaseException as error:  # noqa: BLE001 - handed to the consumer to raise
            self._put(_Raised(error))
        finally:
            close = getattr(self._source, "close", None)
            if close is not None:
                close()

    def _put(self, item: object) -> bool:
        """Queue ``item`` once there is room; False if stopped meanwhile."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def __iter__(self) -> Prefetch[T]:
        return self

    def __next__(self) -> T:
        if self._done:
            raise StopIteration
        item = self._queue.get()
        if isinstance(item, _End):
            self._done = True
            raise StopIteration
        if isinstance(item, _Raised):
            self._done = True
            raise item.error
        return item

    def close(self) -> None:
        """Stop reading ahead and wait for the thread to close the source."""
        self._done = True
        self._stop.set()  # a reader waiting for room sees it within _POLL_S
        self._thread.join()

    def __enter__(self) -> Prefetch[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def frames_ahead(recording: Recording, start: int = 0) -> AbstractContextManager[Iterator[Frame]]:
    """``recording.frames(start)`` read ahead (:class:`Prefetch`), as a context manager that
    closes it. A live camera is read as it streams, in the caller's thread: its frames come at
    the camera's pace, and its SDK stays in the thread that opened it."""
    frames = recording.frames(start)
    if recording.kind == "live camera":
        return closing(frames)
    return Prefetch(frames)
