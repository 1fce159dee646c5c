"""Checkpoints of a run, so ``wristtrack track --resume`` can continue an interrupted one.

Every few hundred frames (and when the run is interrupted) the pipeline's state between two
frames -- tracker, detector, summary accumulator, ... -- is pickled to ``OUT/.checkpoint.pkl``
together with the index of the next frame, the byte size each output file had at that moment
and a fingerprint of the input and the settings. The file is replaced atomically, so a kill
at any moment leaves either the previous checkpoint or the new one. On ``--resume`` the output
files are cut back to those sizes (dropping rows written after the checkpoint, and any line a
kill cut short), the state is restored and tracking continues from that frame: the result is
the same, byte for byte, as a run that was never interrupted. A completed run removes its
checkpoint.

A checkpoint is a pickle: load only those of runs you made (as ``--resume`` does, from the
output folder you name).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wristtrack import __version__
from wristtrack.errors import InputError, WristtrackError
from wristtrack.io.atomic import write_bytes_atomic
from wristtrack.io.run_folder import REFIT_DIR

CHECKPOINT_FILE = ".checkpoint.pkl"
CHECKPOINT_FRAMES = 300  # default: a checkpoint at least every this many frames ...
CHECKPOINT_SECONDS = 30.0  # ... and at least this often (s of wall time)
_FORMAT = "wristtrack-checkpoint"
_VERSION = 13  # 2: the skin's shape learned over the still start; 3: its noise; 4: the frame
# rate; 5: the frame rate taken from the correlation's windows; 6: suspect blobs (the
# observation keeps the model's pixel sigma); 7: the blob noise from each frame's own fit;
# 8: the observation keeps the layout's mean squared radius, the still start its last frame's
# time; 9: the run keeps the frames that came without depth; 10: a first pass keeps its survey
# of the hand layout; 11: the detector keeps the blobs' size it learned; 12: the blobs' spread
# keeps the fastest frames it was learned from; 13: the tracker keeps each frame's depth delay
_SAMPLE = 1 << 20  # bytes hashed at each end of a video or bag file for its fingerprint
_FINGERPRINT_NAMES = {
    "software": "software version",
    "input": "input recording",
    "camera": "camera calibration",
    "hand": "hand layout",
    "settings": "settings",
}


class RunComplete(WristtrackError):
    """``--resume`` of a run that already finished; ``summary`` is its summary.json."""

    def __init__(self, message: str, summary: dict[str, Any]) -> None:
        super().__init__(message)
        self.summary = summary


class CheckpointMismatch(InputError):
    """The checkpoint was written for another input or other settings."""


@dataclass
class Checkpoint:
    fingerprint: dict[str, Any]
    next_index: int  # index of the recording frame to continue from
    sizes: dict[str, int]  # output file name -> its size in bytes at the checkpoint
    state: dict[str, Any] = field(default_factory=dict)  # the pipeline's objects


# ------------------------------------------------------------------------------ fingerprint


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _file_sample(path: Path) -> dict[str, Any]:
    """Size and a hash of both ends of a (possibly huge) file: cheap, and any re-encoding,
    truncation or different file changes it."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(_SAMPLE)
        fh.seek(max(size - _SAMPLE, 0))
        tail = fh.read(_SAMPLE)
    return {"size": size, "sample_sha256": _sha256(head + tail)}


def input_identity(recording) -> dict[str, Any] | None:
    """What identifies the frames of ``recording`` (None for a live camera: nothing to resume).

    A recording folder by the content of its frames.csv (the images it lists are taken as
    unchanged), a video or ROS 1 bag by its size and both ends, a ROS 2 bag folder by its
    metadata.yaml and file sizes. Paths are not part of it: a moved or copied recording resumes.
    """
    identity: dict[str, Any] = {"kind": recording.kind}
    frames_csv = getattr(recording, "frames_csv", None)
    source = Path(str(getattr(recording, "file", None) or recording.source))
    if frames_csv is not None:
        identity["frames_csv_sha256"] = _sha256(Path(frames_csv).read_bytes())
    elif recording.kind == "live camera":
        return None
    elif source.is_file():
        identity.update(_file_sample(source))
    elif source.is_dir():
        files = sorted(p for p in source.iterdir() if p.is_file())
        identity["files"] = {p.name: p.stat().st_size for p in files}
        if (source / "metadata.yaml").is_file():
            identity["metadata_sha256"] = _sha256((source / "metadata.yaml").read_bytes())
    else:
        return None
    try:
        identity["frames"] = len(recording)
    except TypeError:
        pass
    return identity


def fingerprint(recording, settings: dict[str, Any]) -> dict[str, Any] | None:
    """Input, calibration, layout, settings and software version of a run, as JSON-like data;
    None where the input cannot be resumed (a live camera)."""
    identity = input_identity(recording)
    if identity is None:
        return None
    hand = recording.hand.to_dict() if recording.hand is not None else None
    # A JSON round trip makes tuples lists and checks it is plain data, so that comparing
    # a loaded fingerprint with a fresh one compares values, not types.
    return json.loads(json.dumps({
        "software": __version__,
        "input": identity,
        "camera": recording.camera.to_dict(),
        "hand": hand,
        "settings": settings,
    }))


def differences(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """Human names of what differs between two fingerprints (settings by field)."""
    out = []
    for key, name in _FINGERPRINT_NAMES.items():
        a, b = saved.get(key), current.get(key)
        if a == b:
            continue
        if key == "settings" and isinstance(a, dict) and isinstance(b, dict):
            fields = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
            name = f"settings ({', '.join(fields)})"
        out.append(name)
    return out


# --------------------------------------------------------------------------------- pickling


def _mat(array: np.ndarray, wrap_channels: bool) -> cv2.Mat:
    return cv2.Mat(array, wrap_channels=wrap_channels)


class _Pickler(pickle.Pickler):
    """Pickles the pipeline's objects so they come back working exactly as they were."""

    def __init__(self, fh: io.BytesIO) -> None:
        super().__init__(fh, protocol=pickle.HIGHEST_PROTOCOL)

    def reducer_override(self, obj: Any) -> Any:
        # cv2.Mat pickles as a plain array and forgets wrap_channels (a 3-D lookup table would
        # come back as a 2-D image with 32 channels).
        if type(obj) is cv2.Mat:
            return _mat, (np.asarray(obj).copy(), obj.wrap_channels)
        # (The tracker leaves its compiled step out of a pickle itself: Tracker.__getstate__.)
        return NotImplemented


def dumps(checkpoint: Checkpoint) -> bytes:
    fh = io.BytesIO()
    _Pickler(fh).dump({"format": _FORMAT, "version": _VERSION, "checkpoint": checkpoint})
    return fh.getvalue()


# ---------------------------------------------------------------------------------- saving


class Checkpointer:
    """Writes a run's checkpoints: call :meth:`due` between frames and :meth:`save` when it
    says so. Disabled (never due, save does nothing) without a fingerprint."""

    def __init__(
        self,
        out: str | Path,
        fingerprint: dict[str, Any] | None,
        every: int = CHECKPOINT_FRAMES,
        seconds: float = CHECKPOINT_SECONDS,
    ) -> None:
        if every < 1:
            raise InputError(f"checkpoint interval {every} frames: give a whole number >= 1")
        self.path = Path(out) / CHECKPOINT_FILE
        self.fingerprint = fingerprint
        self.every, self.seconds = every, seconds
        self._last_index: int | None = None
        self._last_time = time.monotonic()

    @property
    def enabled(self) -> bool:
        return self.fingerprint is not None

    def due(self, index: int) -> bool:
        """Whether to save before processing frame ``index``."""
        if not self.enabled:
            return False
        if self._last_index is None:
            return True
        return (
            index - self._last_index >= self.every
            or time.monotonic() - self._last_time >= self.seconds
        )

    def save(self, next_index: int, files: list[Path], state: dict[str, Any]) -> None:
        """Checkpoint before frame ``next_index``; ``files`` must be flushed up to that frame."""
        if not self.enabled:
            return
        sizes = {f.name: f.stat().st_size for f in files if f.exists()}
        data = dumps(Checkpoint(self.fingerprint, next_index, sizes, state))
        write_bytes_atomic(self.path, data)
        self._last_index, self._last_time = next_index, time.monotonic()

    def discard(self) -> None:
        """Remove the checkpoint (the run is complete)."""
        self.path.unlink(missing_ok=True)


# --------------------------------------------------------------------------------- resuming


def resumable(out: str | Path) -> bool:
    """Whether ``out`` holds an interrupted run: a checkpoint, or --smooth's refit under way
    (pipeline/refit.py)."""
    out = Path(out)
    return (out / CHECKPOINT_FILE).is_file() or (out / REFIT_DIR).is_dir()


def completed_summary(out: str | Path) -> dict[str, Any] | None:
    """summary.json of a finished run in ``out`` (not interrupted, no checkpoint, no refit
    under way), else None."""
    out = Path(out)
    if (out / CHECKPOINT_FILE).exists() or (out / REFIT_DIR).is_dir():
        return None
    try:
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict) or summary.get("interrupted", False):
        return None
    return summary


def load_checkpoint(out: str | Path, current: dict[str, Any] | None) -> Checkpoint:
    """The checkpoint to resume the run in ``out`` from, checked against the fingerprint of
    the input and settings given now. One-line errors when there is nothing to resume, the run
    is already complete (:class:`RunComplete`), the input or settings differ
    (:class:`CheckpointMismatch`) or the output files were changed since."""
    out = Path(out)
    path = out / CHECKPOINT_FILE
    if current is None:
        raise InputError("a live camera cannot be resumed; track it again without --resume")
    if not path.is_file():
        summary = completed_summary(out)
        if summary is not None:
            raise RunComplete(
                f"the run in {out} is already complete; nothing to resume (track again without "
                "--resume to redo it)",
                summary,
            )
        if (out / "poses.csv").exists():
            raise InputError(
                f"{out} holds a run but no {CHECKPOINT_FILE} to resume it from (stopped while "
                "finishing, or written by a version without checkpoints); track again without "
                "--resume"
            )
        raise InputError(
            f"nothing to resume in {out}: no interrupted run there; track without --resume"
        )
    try:
        payload = pickle.loads(path.read_bytes())
        ok = isinstance(payload, dict) and payload.get("format") == _FORMAT
    except Exception as exc:  # any unpickling failure means the same to the user
        raise InputError(
            f"checkpoint {path} cannot be read ({type(exc).__name__}); track again without "
            "--resume"
        ) from None
    if not ok or payload.get("version") != _VERSION:
        raise InputError(
            f"{path} is not a checkpoint this version of wristtrack can resume; track again "
            "without --resume"
        )
    checkpoint: Checkpoint = payload["checkpoint"]
    changed = differences(checkpoint.fingerprint, current)
    if changed:
        raise CheckpointMismatch(
            f"cannot resume the run in {out}: the {', '.join(changed)} differ from the "
            "interrupted run's; give the same input and options, or track again without --resume"
        )
    for name, size in checkpoint.sizes.items():
        target = out / name
        actual = target.stat().st_size if target.is_file() else -1
        if actual < size:
            raise InputError(
                f"{target} is {'missing' if actual < 0 else 'shorter than at the checkpoint'}; "
                "it was changed after the run stopped; track again without --resume"
            )
    return checkpoint


def truncate_outputs(out: str | Path, checkpoint: Checkpoint) -> None:
    """Cut every output file back to its size at the checkpoint."""
    for name, size in checkpoint.sizes.items():
        os.truncate(Path(out) / name, size)


def clear_stale(out: str | Path) -> None:
    """Before a fresh run: remove a previous run's checkpoint and summary, so neither can be
    taken for this run's if it is interrupted."""
    out = Path(out)
    (out / CHECKPOINT_FILE).unlink(missing_ok=True)
    (out / "summary.json").unlink(missing_ok=True)
