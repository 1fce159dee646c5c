"""One frame of marker-detector output: what the tracker consumes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wristtrack.errors import InputError


@dataclass(frozen=True)
class Detections:
    """Unordered blob centres of one frame.

    ``uv`` is (M, 2) pixels; ``depth`` is (M,) metres along the camera z axis with NaN where the
    sensor gave no reading, or None when the recording has no depth at all. A depth that cannot
    be a reading (zero, negative, infinite) is taken as NaN; a non-finite centre is an
    InputError. ``depth_image`` is the raw depth frame (H, W) the blobs' depths were read from
    (registered to colour, camera.depth_scale units), where the detector had one: the tracker
    reads the skin between the markers in it (tracking/surface.py). ``suspect`` (M,) marks the
    blobs whose centre the detector doubts (``Blob.suspect``: clipped, split, elongated, on the
    border, a streak, in the shade), or is None: none doubted. The tracker takes a suspect
    centre at the model's pixel noise, never at the lower noise it learns from the other blobs.
    ``depth_delay`` (s) is how long after the colour frame its depth frame was captured, as the
    source's two stamps tell it (``Frame.depth_delay``), or None: not known for this frame
    (tracking/depth_timing.py).
    """

    timestamp: float
    uv: np.ndarray
    depth: np.ndarray | None = None
    depth_image: np.ndarray | None = field(default=None, repr=False, compare=False)
    suspect: np.ndarray | None = None
    depth_delay: float | None = None

    def __post_init__(self) -> None:
        uv = np.asarray(self.uv, dtype=float).reshape(-1, 2)
        object.__setattr__(self, "uv", uv)
        if self.depth is not None:
            depth = np.asarray(self.depth, dtype=float).reshape(-1)
            if depth.shape[0] != uv.shape[0]:
                raise InputError(
                    f"detections at t={self.timestamp}: {uv.shape[0]} blobs but {depth.shape[0]} "
                    "depths; give one depth per blob (NaN where unknown)"
                )
            with np.errstate(invalid="ignore"):
                valid = np.isfinite(depth) & (depth > 0)
            if not valid.all():
                depth = np.where(valid, depth, np.nan)
            object.__setattr__(self, "depth", depth)
        if self.suspect is not None:
            suspect = np.asarray(self.suspect, dtype=bool).reshape(-1)
            if suspect.shape[0] != uv.shape[0]:
                raise InputError(
                    f"detections at t={self.timestamp}: {uv.shape[0]} blobs but "
                    f"{suspect.shape[0]} suspect flags; give one flag per blob"
                )
            object.__setattr__(self, "suspect", suspect)
        if not np.isfinite(uv).all():
            raise InputError(
                f"detections at t={self.timestamp}: blob centres must be finite pixel positions, "
                f"got {uv[~np.isfinite(uv).all(axis=1)][:3].tolist()}"
            )
        if not np.isfinite(self.timestamp):
            raise InputError(f"detections timestamp {self.timestamp} is not a finite number")
        if self.depth_delay is not None:
            delay = float(self.depth_delay)
            object.__setattr__(self, "depth_delay", delay if np.isfinite(delay) else None)

    @property
    def count(self) -> int:
        return int(self.uv.shape[0])


@dataclass(frozen=True)
class Blob:
    """One detected blob (full details; ``Detections`` carries its uv, depth and suspect flag).

    ``suspect`` marks a measurement not to take at face value; ``reason`` says why: "split"
    (one of two markers cut from a merged blob), "elongated" (too long for one marker, no waist
    to cut: blur or a merged pair), "clipped" (lopsided: partly hidden), "border" (touches the
    image border), "streak" (smeared by motion) or "shade" (too dark for the colour reference;
    both found by chromaticity, detect/streaks.py). ``expected_diameter`` is the
    unforeshortened marker diameter at the blob's depth (px), NaN when unknown.
    """

    uv: tuple[float, float]
    area: float  # px, coverage-weighted
    depth: float  # metres, NaN if no valid depth or no depth image
    similarity: float  # Bhattacharyya coefficient with the reference histogram, 0..1
    major: float  # px, full axes of the moment-equivalent ellipse
    minor: float
    angle: float  # rad, major-axis direction
    skew: float
    expected_diameter: float
    suspect: bool = False
    reason: str = ""
