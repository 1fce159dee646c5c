"""Atomic file writes: a temporary file beside the target, then a rename. The one way the
package replaces a file.

A reader (or a run killed half-way) sees either the old file or the new one, never a mix. The
temporary name is unique, so two processes writing the same target do not write into each
other's temporary file.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

# mkstemp makes files only their owner may read; a replaced file gets the mode a plain open()
# would give it. (The umask can only be read by setting it: done once, at import.)
_UMASK = os.umask(0o022)
os.umask(_UMASK)
_FILE_MODE = 0o666 & ~_UMASK


@contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp", durable: bool = False) -> Iterator[Path]:
    """A fresh temporary path beside ``path`` for a writer that wants a file name (a library
    that writes the file itself); when the block ends without error it replaces ``path``, else
    it is removed. ``suffix`` ends the temporary name (some writers insist on an extension);
    ``durable`` fsyncs it before the rename (survives a power cut, not only a killed process)."""
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    tmp = Path(name)
    try:
        os.fchmod(fd, _FILE_MODE)
        os.close(fd)
        yield tmp
        if durable:
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | Path, data: bytes, durable: bool = False) -> None:
    """Replace ``path`` with ``data`` in one step (see :func:`atomic_path` for ``durable``)."""
    with atomic_path(path, durable=durable) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | Path, text: str, durable: bool = False) -> None:
    """:func:`write_bytes_atomic` of UTF-8 text (newlines written as given)."""
    write_bytes_atomic(path, text.encode("utf-8"), durable)


def write_json_atomic(path: str | Path, data: Any) -> None:
    """:func:`write_text_atomic` of indented, strict JSON (NaN is refused: it is not JSON)."""
    write_text_atomic(path, json.dumps(data, indent=2, allow_nan=False) + "\n")
