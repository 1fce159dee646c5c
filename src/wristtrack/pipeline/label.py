"""Manual marker labelling, the paper's calibration step and our fallback: ``wristtrack label``.

The paper detects the marker centres by hand in the first frame. Here the automatic labelling
(``initialise.label_markers``) normally does it; when it refuses (ambiguous layout, blue clutter,
too many blobs) the user names the blobs once: the detector runs up to the chosen frame exactly
as ``wristtrack track`` runs it, a preview PNG shows every blob numbered, and the terminal asks
which blob each marker is.

labels.json (the file ``wristtrack track --labels`` reads)::

    {"frame": 0,                     # frame index (0-based) the labels belong to
     "timestamp": 0.0,               # its timestamp, s (informative)
     "markers": {"WRIST": [u, v], "CMC1": [u, v], ...},   # all six, pixel centres
     "blobs": [[u, v], ...]}         # every blob of that frame (informative)

Pixel positions rather than blob numbers are stored so the labels survive a re-run of the
detector: each marker is matched to the nearest blob of that frame within ``MATCH_RADIUS_PX``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import ConfigError, InitialisationError, InputError, WristtrackError
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.base import Frame, Recording
from wristtrack.jsonfile import read_config, write_config
from wristtrack.tracking.initialise import InitResult, initialise

# A re-run of the same detector gives the same centres; a few pixels allow for a changed
# detector setting while staying well below the spacing of two markers (~15 px at 60 cm).
MATCH_RADIUS_PX = 4.0


class LabelAborted(WristtrackError):
    """The user quit the interactive labelling."""


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value)


def _pixel(value: Any) -> bool:
    return isinstance(value, list | tuple) and len(value) == 2 and all(map(_is_number, value))


@dataclass(frozen=True)
class ManualLabels:
    """The six marker centres (6, 2) px of one frame, in MARKER_NAMES order."""

    frame: int
    timestamp: float
    markers: np.ndarray
    blobs: np.ndarray  # (M, 2) every blob centre of that frame
    source: str = "labels.json"

    def to_dict(self) -> dict[str, Any]:
        return {
            "frame": int(self.frame),
            "timestamp": float(self.timestamp),
            "markers": {n: [float(c) for c in self.markers[k]] for k, n in enumerate(MARKER_NAMES)},
            "blobs": [[float(c) for c in uv] for uv in self.blobs],
        }

    @classmethod
    def from_dict(cls, d: Any, source: str = "labels.json") -> ManualLabels:
        """Validated labels; a ConfigError naming ``source`` and the problem otherwise."""
        where = f"labels file {source}"
        if not isinstance(d, dict) or not isinstance(d.get("markers"), dict):
            raise ConfigError(
                f'{where}: expected {{"frame": N, "markers": {{"WRIST": [u, v], ...}}}}; '
                "write it with `wristtrack label`"
            )
        frame = d.get("frame", 0)
        if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
            raise ConfigError(f"{where}: frame must be a frame index >= 0, got {frame!r}")
        timestamp = d.get("timestamp", float("nan"))
        if not (_is_number(timestamp) or timestamp is None):
            raise ConfigError(f"{where}: timestamp must be a number of seconds, got {timestamp!r}")
        markers = d["markers"]
        unknown = [k for k in markers if k not in MARKER_NAMES]
        missing = [k for k in MARKER_NAMES if k not in markers]
        if unknown or missing:
            parts = [f"unknown marker name(s) {', '.join(map(repr, unknown))}"] if unknown else []
            parts += [f"missing marker(s) {', '.join(missing)}"] if missing else []
            raise ConfigError(
                f"{where}: {'; '.join(parts)}; label all of {', '.join(MARKER_NAMES)} (upper case)"
            )
        for name in MARKER_NAMES:
            if not _pixel(markers[name]):
                raise ConfigError(
                    f"{where}: marker {name} must be a pixel position [u, v], got {markers[name]!r}"
                )
        blobs = d.get("blobs", [])
        if not isinstance(blobs, list) or not all(map(_pixel, blobs)):
            raise ConfigError(f"{where}: blobs must be a list of pixel positions [u, v]")
        uv = np.array([markers[n] for n in MARKER_NAMES], dtype=float)
        return cls(
            frame=frame,
            timestamp=float("nan") if timestamp is None else float(timestamp),
            markers=uv,
            blobs=np.array(blobs, dtype=float).reshape(-1, 2),
            source=str(source),
        )

    @classmethod
    def load(cls, path: str | Path) -> ManualLabels:
        return cls.from_dict(read_config(path, "labels"), source=str(path))

    def save(self, path: str | Path) -> None:
        write_config(path, self.to_dict())

    def match(self, det: Detections) -> np.ndarray:
        """Labels (M,) of ``det``'s blobs: marker index 0..5, -1 = clutter.

        Each marker takes the nearest blob within MATCH_RADIUS_PX; InputError (one line) when a
        marker has no blob there or two markers land on one blob.
        """
        where = f"labels file {self.source} (frame {self.frame})"
        if det.count == 0:
            raise InputError(f"{where}: the frame has no blobs; label the right recording")
        dist = np.linalg.norm(self.markers[:, None, :] - det.uv[None, :, :], axis=-1)  # (6, M)
        nearest = np.argmin(dist, axis=1)
        labels = np.full(det.count, -1, dtype=int)
        for k, name in enumerate(MARKER_NAMES):
            b, gap = int(nearest[k]), float(dist[k, nearest[k]])
            if gap > MATCH_RADIUS_PX:
                u, v = self.markers[k]
                raise InputError(
                    f"{where}: marker {name} at ({u:.1f}, {v:.1f}) px matches no blob (nearest "
                    f"{gap:.1f} px away, limit {MATCH_RADIUS_PX:g} px); label this recording "
                    "again with `wristtrack label`"
                )
            if labels[b] >= 0:
                raise InputError(
                    f"{where}: markers {MARKER_NAMES[labels[b]]} and {name} match the same blob "
                    f"{b}; label this recording again with `wristtrack label`"
                )
            labels[b] = k
        return labels

    def for_frame(self, index: int, det: Detections) -> np.ndarray | None:
        """Labels of ``det`` if it is the labelled frame, else None (the tracker's own)."""
        return self.match(det) if index == self.frame else None


# ----------------------------------------------------------------------------------- detection


def detect_frame(recording: Recording, index: int) -> tuple[Frame, Detections]:
    """Frame ``index`` and its detections, the detector having run over every earlier frame as
    ``wristtrack track`` runs it (it carries its search region from frame to frame)."""
    if index < 0:
        raise InputError(f"frame {index}: give a frame index >= 0")
    detector = MarkerDetector(recording.camera)
    for frame in recording:
        det = detector.detect(frame.bgr, frame.depth, frame.timestamp, frame.depth_delay)
        if frame.index == index:
            return frame, det
    raise InputError(
        f"{recording.source} has no frame {index}; give --frame below the number of frames"
    )


def draw_preview(bgr: np.ndarray, uv: np.ndarray, path: str | Path) -> Path:
    """Write a PNG of the frame with every blob circled and numbered; returns its path."""
    path = Path(path)
    img = bgr.copy()
    scale = max(0.5, img.shape[1] / 1280)
    for i, (u, v) in enumerate(np.asarray(uv, dtype=float)):
        centre = (int(round(u)), int(round(v)))
        cv2.circle(img, centre, int(10 * scale), (0, 255, 255), max(1, int(2 * scale)))
        org = (centre[0] + int(9 * scale), centre[1] - int(9 * scale))
        for colour, thick in (((0, 0, 0), 4), ((0, 255, 255), 1)):  # outlined: legible anywhere
            cv2.putText(img, str(i), org, cv2.FONT_HERSHEY_SIMPLEX, 0.6 * scale, colour,
                        max(1, int(thick * scale)), cv2.LINE_AA)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), img):
        raise InputError(f"cannot write the preview image {path}; give a writable --preview path")
    return path


# --------------------------------------------------------------------------------- interaction


def ask_labels(
    det: Detections,
    ask: Callable[[str], str] = input,
    say: Callable[[str], None] = print,
) -> np.ndarray:
    """Ask, for each marker, which blob it is; returns labels (M,) (marker index, -1 clutter).

    Re-asks on anything but an unused blob number in range; 'q' (or end of input) aborts.
    """
    M = det.count
    if M < len(MARKER_NAMES):
        raise InitialisationError(
            f"the frame has {M} blobs, fewer than the six markers; pick a frame where every "
            "marker is visible (--frame N)"
        )
    say(f"{M} blobs (see the preview image for their numbers):")
    for i, (u, v) in enumerate(det.uv):
        z = "" if det.depth is None or not np.isfinite(det.depth[i]) else f"  {det.depth[i]:.3f} m"
        say(f"  {i:2d}: u {u:7.1f}  v {v:7.1f}{z}")
    chosen: dict[int, str] = {}
    labels = np.full(M, -1, dtype=int)
    for k, name in enumerate(MARKER_NAMES):
        while True:
            try:
                answer = ask(f"{name}: blob number (0-{M - 1}, q to quit)? ").strip()
            except EOFError:
                raise LabelAborted(
                    "input ended before every marker was labelled; no labels written"
                ) from None
            if answer.lower() in ("q", "quit"):
                raise LabelAborted("labelling aborted; no labels written")
            try:
                b = int(answer)
            except ValueError:
                say(f"  {answer!r} is not a blob number; type one of 0-{M - 1}, or q to quit")
                continue
            if not 0 <= b < M:
                say(f"  there is no blob {b}; type one of 0-{M - 1}")
                continue
            if b in chosen:
                say(f"  blob {b} is already {chosen[b]}; each blob can be one marker only")
                continue
            chosen[b] = name
            labels[b] = k
            break
    return labels


def labels_from_array(labels: np.ndarray, det: Detections, frame: Frame) -> ManualLabels:
    """ManualLabels of ``det`` from labels (M,) naming all six markers."""
    idx = [int(np.flatnonzero(labels == k)[0]) for k in range(len(MARKER_NAMES))]
    return ManualLabels(frame.index, frame.timestamp, det.uv[idx], det.uv.copy())


def check_fit(
    labels: np.ndarray, det: Detections, camera: Camera, layout: HandLayout | None
) -> InitResult:
    """Initialise from ``labels`` as the tracker will; InitialisationError when they do not fit
    the hand layout (markers in the wrong order, or a wrong hand.json)."""
    return initialise(det, camera, layout, labels=labels)


def label_interactively(
    recording: Recording,
    out: str | Path,
    frame_index: int = 0,
    preview: str | Path | None = None,
    ask: Callable[[str], str] = input,
    say: Callable[[str], None] = print,
) -> ManualLabels:
    """Detect frame ``frame_index``, write the numbered preview, ask the user, check that the
    answers fit the hand layout (asking again if not) and save ``out`` (labels.json)."""
    out = Path(out)
    frame, det = detect_frame(recording, frame_index)
    image = draw_preview(frame.bgr, det.uv, preview or out.with_name(out.stem + "_preview.png"))
    say(f"frame {frame.index} (t = {frame.timestamp:.3f} s): numbered blobs in {image}")
    while True:
        labels = ask_labels(det, ask, say)
        try:
            fit = check_fit(labels, det, recording.camera, recording.hand)
        except InitialisationError as exc:
            say(f"these labels do not fit the hand: {exc}. Try again.")
            continue
        break
    result = labels_from_array(labels, det, frame)
    result.save(out)
    say(f"labels fit with {fit.rms_px:.2f} px RMS; wrote {out}")
    return result


def check_labels(recording: Recording, path: str | Path) -> tuple[ManualLabels, np.ndarray,
                                                                   InitResult]:
    """Load labels.json, match it to its frame's blobs and initialise from it, as ``track``
    will; every problem is a one-line error."""
    manual = ManualLabels.load(path)
    _, det = detect_frame(recording, manual.frame)
    labels = manual.match(det)
    try:
        fit = check_fit(labels, det, recording.camera, recording.hand)
    except InitialisationError as exc:
        raise InitialisationError(f"labels file {path} (frame {manual.frame}): {exc}") from None
    return manual, labels, fit
