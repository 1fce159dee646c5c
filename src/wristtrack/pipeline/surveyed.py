"""The layout a first pass of ``wristtrack track`` surveyed (tracking/layout_survey.py): where a
pass's layout came from, which pass a run folder is at, and the layout's file
(``io.run_folder.SURVEYED_HAND``) read back (pipeline/track.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Recording
from wristtrack.io.run_folder import SURVEYED_HAND
from wristtrack.pipeline import checkpoint as ckpt
from wristtrack.tracking.layout_survey import RunSurvey

SURVEYED_FROM = "surveyed over the recording"  # settings.hand_layout_from of a surveyed pass


def layout_origin(recording: Recording, survey: RunSurvey | None, surveyed: bool) -> str:
    """Where a pass's hand layout comes from, as summary.json's settings say it."""
    if surveyed:
        return f"{SURVEYED_FROM} ({SURVEYED_HAND})"
    if recording.hand is not None:
        return "hand.json"
    return "still start" + (" (surveying)" if survey is not None else "")


def is_surveyed(settings: dict[str, Any]) -> bool:
    """Whether a run's settings (summary.json) say it tracked with the surveyed layout."""
    return str(settings.get("hand_layout_from", "")).startswith(SURVEYED_FROM)


def second_pass_begun(out: Path) -> bool:
    """Whether the second pass in ``out`` has a checkpoint or is complete (else the run
    stopped between the passes and the second starts afresh)."""
    if (out / ckpt.CHECKPOINT_FILE).is_file():
        return True
    summary = ckpt.completed_summary(out)
    return is_surveyed((summary or {}).get("settings", {}))


@contextmanager
def hand_of(recording: Recording, layout: HandLayout) -> Iterator[None]:
    """``recording`` with ``layout`` as its hand.json while the block runs."""
    own = recording.hand
    recording.hand = layout
    try:
        yield
    finally:
        recording.hand = own


def load_surveyed(path: Path) -> HandLayout:
    try:
        return HandLayout.load(path)
    except (ConfigError, InputError) as e:
        raise InputError(f"{e}; track the recording again without --resume") from None
