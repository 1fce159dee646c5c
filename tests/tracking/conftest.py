"""Fixtures of the tracking tests."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from wristtrack.analysis.evaluate import evaluate
from wristtrack.cli import main


@pytest.fixture
def stated_against_unsaid(tmp_path: Path) -> Callable[[str, str], tuple[Path, dict]]:
    """``(switch, field) -> (recording, errors)``: a fast reach (seed 8, 60 frames) rendered
    with the simulator's ``switch`` (e.g. "--depth-lag"), tracked with its camera.json as
    written and again with ``field`` left out of it; ``errors["stated"]``,
    ``errors["unsaid"]``: evaluate()'s against the truth. The runs: tmp_path / "run_stated",
    "run_unsaid"."""

    def run(switch: str, field: str) -> tuple[Path, dict]:
        errors = {}
        for name in ("stated", "unsaid"):
            folder = tmp_path / name
            assert main(["simulate", str(folder), "--scenario", "reach", "--seed", "8", switch,
                         "--n-frames", "60"]) == 0
            if name == "unsaid":
                cam = json.loads((folder / "camera.json").read_text())
                del cam[field]
                (folder / "camera.json").write_text(json.dumps(cam))
            out = tmp_path / f"run_{name}"
            assert main(["track", str(folder), "--out", str(out), "--no-report",
                         "--no-progress"]) == 0
            errors[name] = evaluate(out / "poses.csv", tmp_path / "stated" / "truth.csv")
        return tmp_path / "stated", errors

    return run
