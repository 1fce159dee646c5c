"""``wristtrack track``: a recording in, poses.csv and summary.json out, one frame at a time.

Frames stream from the reader through the detector and the tracker to the writer, so memory
stays flat however long the recording, and every processed frame is on disk as soon as it is
done: an interrupted run keeps what it computed.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.detect import MarkerDetector
from wristtrack.errors import InputError
from wristtrack.io.poses import PosesWriter, pose_row
from wristtrack.io.recording import Recording
from wristtrack.summary import SummaryAccumulator, camera_pose_dict, write_json_atomic
from wristtrack.tracker import FrameResult, Status, Tracker, TrackerConfig

_NAN3 = np.full(3, np.nan)
_NAN33 = np.full((3, 3), np.nan)


def track_recording(
    recording: Recording,
    out: str | Path,
    config: TrackerConfig | None = None,
    labels: np.ndarray | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Track every frame of ``recording``; write ``out``/poses.csv and ``out``/summary.json.

    ``labels`` (M,) optionally names the blobs of the first frame (manual labelling) when the
    automatic labelling cannot. Returns the summary.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config = config or TrackerConfig()
    camera = recording.camera
    detector = MarkerDetector(camera)
    tracker = Tracker(camera, recording.hand, config)
    summary = SummaryAccumulator()
    learned = False
    interrupted = False
    bad_frames: list[dict[str, Any]] = []
    bar = _progress(recording, progress)
    with PosesWriter(out / "poses.csv") as writer:
        try:
            for frame in recording:
                det = detector.detect(frame.bgr, frame.depth, frame.timestamp)
                manual = labels if not learned else None
                try:
                    result = tracker.step(det, manual)
                except InputError as exc:  # e.g. a timestamp that goes backwards: skip the frame
                    bad_frames.append({"frame": frame.index, "error": str(exc)})
                    writer.write(_skipped_row(frame.index, frame.timestamp, det.count))
                    bar.update(1)
                    continue
                if not learned and result.status == Status.TRACKING:
                    _learn(detector, frame.bgr, det, result)
                    learned = True
                writer.write_result(result)
                summary.add(result)
                bar.update(1)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
    data = summary.to_dict(
        hand_layout=tracker.layout.to_dict() if tracker.layout is not None else None,
        camera_pose_w0=camera_pose_dict(tracker.R_c0, tracker.t_c0),
        camera=camera.to_dict(),
        source=str(recording.source),
        settings=_settings(config),
        skipped_frames=bad_frames,
        interrupted=interrupted,
    )
    write_json_atomic(out / "summary.json", data)
    if interrupted:
        raise KeyboardInterrupt
    return data


def _learn(detector: MarkerDetector, bgr: np.ndarray, det, result: FrameResult) -> None:
    """Refine the detector's colour models from the six labelled markers of the first fix."""
    uv = np.full((6, 2), np.nan)
    for blob, label in enumerate(result.labels):
        if label >= 0:
            uv[label] = det.uv[blob]
    if np.isfinite(uv).all():
        detector.learn_markers(bgr, uv)


def _skipped_row(index: int, timestamp: float, n_blobs: int) -> list[str]:
    return pose_row(
        index, timestamp, "skipped", _NAN33, _NAN3, _NAN33, _NAN3, _NAN3, _NAN3, 0, n_blobs
    )


def _settings(config: TrackerConfig) -> dict[str, Any]:
    def clean(value):
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, tuple | list):
            return [clean(v) for v in value]
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    return clean(asdict(config))


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(recording: Recording, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    try:
        total = len(recording) or None
    except TypeError:
        total = None
    return tqdm(total=total, unit="frame", desc="tracking", leave=False)
