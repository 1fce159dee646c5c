"""Reading and writing the small JSON configuration files (camera.json, hand.json, labels)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from wristtrack.errors import ConfigError
from wristtrack.io.atomic import write_json_atomic


def read_config(path: str | Path, kind: str) -> Any:
    """Parsed JSON of a ``kind`` file ("camera", "hand"); every problem is one ConfigError line
    naming the file and saying how to fix it."""
    path = Path(path)
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "not found"
        raise ConfigError(f"{kind} file {path} {what}; give the path of a {kind}.json")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ConfigError(
            f"{kind} file {path} is not valid JSON ({e.msg} at line {e.lineno}, column "
            f"{e.colno}); fix the syntax"
        ) from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{kind} file {path} cannot be read: {e}") from None


def write_config(path: str | Path, data: Any) -> None:
    """Write indented JSON (atomically), creating the parent folder if needed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, data)
