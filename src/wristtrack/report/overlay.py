"""Overlay video (``wristtrack track --overlay video.mp4``): what the tracker saw and concluded.

Each input frame is written with the detected blobs circled and named by the marker they were
associated with, clutter blobs crossed out, the layout's markers where the estimate puts them
(small squares, when the layout is known), the wrist axes projected with the camera (X red,
Y green, Z blue) and a status line.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InputError
from wristtrack.hand import MARKER_NAMES

AXIS_LENGTH_M = 0.05
# BGR colours.
AXIS_BGR = ((0, 0, 255), (0, 200, 0), (255, 0, 0))  # X red, Y green, Z blue
BLOB_BGR = (0, 255, 255)  # associated blob: yellow circle and its marker's name
CLUTTER_BGR = (0, 0, 255)  # clutter blob: red cross
MODEL_BGR = (255, 255, 255)  # layout marker where the estimate puts it
STATUS_BGR = {
    "tracking": (0, 200, 0),
    "coasting": (0, 176, 255),
    "initialising": (200, 200, 200),
    "lost": (0, 0, 255),
    "skipped": (200, 60, 160),
}
BLOB_RADIUS = 9


def nominal_fps(recording, default: float = 30.0) -> float:
    """The recording's frame rate for the video: its own when it has one, else 1 / the median
    frame interval of its timestamps (a recording folder), else ``default``."""
    fps = getattr(recording, "fps", None)
    if isinstance(fps, int | float) and math.isfinite(fps) and fps > 0:
        return float(fps)
    timestamps = getattr(recording, "timestamps", None)  # a recording folder's, from frames.csv
    if callable(timestamps):
        try:
            dt = np.diff(timestamps())
        except (InputError, OSError):
            return default  # frames.csv problems are the reader's to report
        dt = dt[dt > 0]
        if dt.size:
            return float(1.0 / np.median(dt))
    return default


class OverlayWriter:
    """Writes annotated frames to an MP4 (mp4v) video; use as a context manager or call close().

    ``layout_points`` (6,3) hand-frame marker positions, or None to skip the model markers.
    """

    def __init__(self, path: str | Path, camera: Camera, layout_points: np.ndarray | None = None,
                 fps: float = 30.0) -> None:
        self.path = Path(path)
        self.camera = camera
        self.layout_points = None if layout_points is None else np.asarray(layout_points, float)
        self.size = (int(camera.width), int(camera.height))
        self.frames = 0
        if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
            raise InputError(f"overlay video {self.path}: frame rate {fps!r} must be positive")
        if self.path.suffix.lower() not in (".mp4", ".m4v", ".mov"):
            raise InputError(
                f"overlay video {self.path}: name it .mp4 (the video is written as MPEG-4)"
            )
        if not self.path.parent.is_dir():
            raise InputError(
                f"overlay video {self.path}: folder {self.path.parent} does not exist; create it"
            )
        fourcc = cv2.VideoWriter_fourcc(*"mp4v")
        self._writer = cv2.VideoWriter(str(self.path), fourcc, float(fps), self.size)
        if not self._writer.isOpened():
            raise InputError(
                f"cannot open overlay video {self.path} for writing with OpenCV (mp4v); check the "
                "path is writable"
            )

    def add(self, bgr: np.ndarray, detections: Detections, result) -> None:
        """Annotate one frame and append it. ``result`` is a tracker.FrameResult, or None for a
        frame the tracker skipped."""
        h, w = bgr.shape[:2]
        if (w, h) != self.size:
            raise InputError(
                f"overlay video {self.path}: frame is {w}x{h} but the camera is "
                f"{self.size[0]}x{self.size[1]}; give the camera.json of this recording"
            )
        img = np.ascontiguousarray(bgr[..., :3], dtype=np.uint8).copy()
        labels = None if result is None else np.asarray(result.labels, dtype=int)
        self._draw_blobs(img, detections.uv, labels)
        if result is not None and result.has_estimate:
            R, t = np.asarray(result.R_ch, float), np.asarray(result.t_ch, float)
            if self.layout_points is not None:
                self._draw_model(img, R, t)
            self._draw_axes(img, R, t)
        self._draw_status(img, result, detections)
        self._writer.write(img)
        self.frames += 1

    def close(self) -> None:
        self._writer.release()

    def __enter__(self) -> OverlayWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------------ drawing

    def _draw_blobs(self, img: np.ndarray, uv: np.ndarray, labels: np.ndarray | None) -> None:
        for i, (u, v) in enumerate(np.asarray(uv, float).reshape(-1, 2)):
            if not (math.isfinite(u) and math.isfinite(v)):
                continue
            c = (int(round(u)), int(round(v)))
            label = -2 if labels is None or i >= labels.size else int(labels[i])
            if label == -1:
                cv2.drawMarker(img, c, CLUTTER_BGR, cv2.MARKER_TILTED_CROSS, 14, 2, cv2.LINE_AA)
                continue
            cv2.circle(img, c, BLOB_RADIUS, BLOB_BGR, 2, cv2.LINE_AA)
            if 0 <= label < len(MARKER_NAMES):
                cv2.putText(img, MARKER_NAMES[label], (c[0] + BLOB_RADIUS + 2, c[1] - 4),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.4, BLOB_BGR, 1, cv2.LINE_AA)

    def _draw_model(self, img: np.ndarray, R: np.ndarray, t: np.ndarray) -> None:
        pts = self.layout_points @ R.T + t
        for p, uv in zip(pts, self.camera.project(pts), strict=True):
            if p[2] > 0 and np.isfinite(uv).all():
                c = (int(round(uv[0])), int(round(uv[1])))
                cv2.drawMarker(img, c, MODEL_BGR, cv2.MARKER_SQUARE, 7, 1, cv2.LINE_AA)

    def _draw_axes(self, img: np.ndarray, R: np.ndarray, t: np.ndarray) -> None:
        pts = np.vstack([t, t + AXIS_LENGTH_M * R.T])  # origin, then the tips of X, Y, Z
        if not (pts[:, 2] > 0).all():
            return  # behind the camera: nothing meaningful to draw
        uv = self.camera.project(pts)
        if not np.isfinite(uv).all() or np.abs(uv).max() > 1e5:
            return
        o = (int(round(uv[0, 0])), int(round(uv[0, 1])))
        # Draw the axis pointing most towards the camera last so it stays visible on top.
        order = np.argsort(-(R[2, :]))
        for k in order:
            tip = (int(round(uv[k + 1, 0])), int(round(uv[k + 1, 1])))
            cv2.line(img, o, tip, AXIS_BGR[k], 3, cv2.LINE_AA)
        cv2.circle(img, o, 3, (255, 255, 255), -1, cv2.LINE_AA)

    def _draw_status(self, img: np.ndarray, result, detections: Detections) -> None:
        if result is None:
            status, text = "skipped", f"t={detections.timestamp:.2f}s  skipped"
        else:
            status = str(result.status)
            text = (f"frame {result.frame}  t={result.timestamp:.2f}s  {status}  markers "
                    f"{result.n_visible}/6  clutter {result.n_clutter}")
        (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        cv2.rectangle(img, (4, 4), (12 + tw, 12 + th + base), (0, 0, 0), -1)
        cv2.putText(img, text, (8, 8 + th), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    STATUS_BGR.get(status, (255, 255, 255)), 1, cv2.LINE_AA)
