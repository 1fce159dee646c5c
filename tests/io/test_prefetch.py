"""Reading frames ahead: the same items in the same order, the source's errors where they
occur, the source advanced in one thread only and closed when the reader stops early."""

from __future__ import annotations

import threading
import time

import pytest

from wristtrack.errors import InputError
from wristtrack.io.folder import FolderRecording
from wristtrack.io.prefetch import Prefetch, frames_ahead


class _Source:
    """A generator of ``n`` numbers that records which threads advanced it and whether it
    was closed, and raises ``error`` after ``fail_after`` items."""

    def __init__(self, n: int, fail_after: int | None = None, error: Exception | None = None):
        self.n, self.fail_after, self.error = n, fail_after, error
        self.threads: set[int] = set()
        self.produced = 0
        self.closed = False

    def __call__(self):
        try:
            for i in range(self.n):
                self.threads.add(threading.get_ident())
                if i == self.fail_after:
                    raise self.error
                self.produced += 1
                yield i
        finally:
            self.closed = True


def test_yields_every_item_in_order_from_one_other_thread():
    source = _Source(50)
    with Prefetch(source(), ahead=3) as items:
        assert list(items) == list(range(50))
    assert source.closed
    assert len(source.threads) == 1 and threading.get_ident() not in source.threads


def test_the_sources_error_is_raised_after_the_items_before_it():
    source = _Source(10, fail_after=4, error=InputError("frames.csv line 6: bad timestamp"))
    got = []
    with pytest.raises(InputError, match="line 6"), Prefetch(source()) as items:
        for item in items:
            got.append(item)
    assert got == [0, 1, 2, 3]
    assert source.closed


def test_stopping_early_closes_the_source_without_reading_it_all():
    source = _Source(10_000)
    with Prefetch(source(), ahead=2) as items:
        assert next(items) == 0
        time.sleep(0.05)  # the reader fills the queue and waits
    assert source.closed
    assert source.produced <= 1 + 2 + 1  # the one taken, a full queue, one in hand
    with pytest.raises(StopIteration):  # closed: nothing more comes
        next(items)


def test_reads_ahead_while_the_caller_works():
    """The next items are read while the caller still holds the first: decoding overlaps
    the caller's work instead of waiting for its next request."""
    read = [threading.Event() for _ in range(3)]

    def source():
        for i in range(3):
            yield i
            read[i].set()  # runs when the next item is asked for

    with Prefetch(source(), ahead=3) as items:
        assert next(items) == 0
        # nothing more is asked for; the reader goes on by itself
        assert read[1].wait(timeout=10)


def test_frames_ahead_reads_a_recording_as_it_is(rendered):
    with FolderRecording(rendered("flexion", n_frames=8)) as recording:
        direct = [(f.index, f.timestamp, f.bgr.sum(), f.depth.sum()) for f in recording.frames(2)]
        with frames_ahead(recording, 2) as frames:
            ahead = [(f.index, f.timestamp, f.bgr.sum(), f.depth.sum()) for f in frames]
    assert ahead == direct and ahead[0][0] == 2


def test_ahead_must_be_positive():
    with pytest.raises(ValueError, match="at least 1"):
        Prefetch(iter(()), ahead=0)
