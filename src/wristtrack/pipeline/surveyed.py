"""The layout a first pass of ``wristtrack track`` surveyed (tracking/layout_survey.py): its
file in the run folder, and which pass a run folder is at (pipeline/track.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Recording
from wristtrack.pipeline import checkpoint as ckpt
from wristtrack.tracking.layout_survey import RunSurvey

SURVEYED_HAND = "hand_surveyed.json"  # hand.json's format, for the subject's other recordings


def layout_origin(recording: Recording, survey: RunSurvey | None, surveyed: bool) -> str:
    """Where a pass's hand layout comes from, as summary.json's settings say it."""
    if surveyed:
        return f"surveyed over the recording ({SURVEYED_HAND})"
    if recording.hand is not None:
        return "hand.json"
    return "still start" + (" (surveying)" if survey is not None else "")


def second_pass_begun(out: Path) -> bool:
    """Whether the second pass in ``out`` has a checkpoint or is complete (else the run
    stopped between the passes and the second starts afresh)."""
    if (out / ckpt.CHECKPOINT_FILE).is_file():
        return True
    summary = ckpt.completed_summary(out)
    origin = (summary or {}).get("settings", {}).get("hand_layout_from", "")
    return origin.startswith("surveyed")


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
