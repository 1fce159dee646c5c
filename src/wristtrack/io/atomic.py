"""Atomic file writes: a temporary file beside the target, then a rename.

A reader (or a run killed half-way) sees either the old file or the new one, never a mix. The
temporary name is unique, so two processes writing the same target do not write into each
other's temporary file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def write_bytes_atomic(path: str | Path, data: bytes, durable: bool = False) -> None:
    """Replace ``path`` with ``data`` in one step; ``durable`` also fsyncs before the rename
    (survives a power cut, not only a killed process)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | Path, text: str, durable: bool = False) -> None:
    """:func:`write_bytes_atomic` of UTF-8 text."""
    write_bytes_atomic(path, text.encode("utf-8"), durable)
