"""When each frame's depth was captured against its colour frame, and what a run took it as.

A camera whose depth and colour sensors run on their own clocks (a RealSense D4xx, an Xtion
or Kinect v1 paired in software, any ROS driver's approximate-time pairs) delivers each colour
frame with the depth frame nearest in time: up to half a frame interval before or after it.
The tracker reads each marker's depth where the hand's rates have moved it over that delay
(observation.lag_depth_change). Which delay a frame is read at, in this order:

1. camera.json's ``depth_delay_s`` (``Camera.depth_delay``): what the user states wins, e.g.
   a rig whose stamps are arrival times, not capture times;
2. the frame's own stamps (``Detections.depth_delay``, from ``Frame.depth_delay``): a RealSense
   device or recording, an OpenNI2 device or .oni file, a ROS bag. The two streams' phase
   walks as their clocks drift apart, so each frame keeps its own;
3. none known: read as simultaneous.

:class:`DepthTiming` decides it frame by frame and keeps a tally for summary.json
(``depth_timing``) and the report.
"""

from __future__ import annotations

import math
from typing import Any

from wristtrack.detect.detections import Detections

__all__ = ["DepthTiming"]


class DepthTiming:
    """The delay (s) each frame's depth is read at (``delay``), given the camera's stated one
    (None: not stated), and a tally of the delays the frames with depth were read at."""

    def __init__(self, stated: float | None) -> None:
        self.stated = stated
        self.current = stated or 0.0  # the delay of the frame being tracked
        self.frames = 0  # frames with depth
        self.stamped = 0  # of them, those read at their own stamps' delay
        self._low, self._high, self._sum = math.inf, -math.inf, 0.0

    def delay(self, det: Detections) -> float:
        """The delay frame ``det`` is read at; it becomes ``current``."""
        if det.depth is None:
            return self.current  # nothing read in depth: the tally and the delay stand
        delay = self.stated
        if delay is None and det.depth_delay is not None:
            delay = det.depth_delay
            self.stamped += 1
            self._low, self._high = min(self._low, delay), max(self._high, delay)
            self._sum += delay
        self.frames += 1
        self.current = delay or 0.0
        return self.current

    def to_dict(self) -> dict[str, Any] | None:
        """summary.json's ``depth_timing``: where the delays came from and, for frame stamps,
        their mean and range (ms); None for a run without depth."""
        if not self.frames:
            return None
        if self.stated is not None:
            return {"from": "camera.json", "delay_ms": round(1e3 * self.stated, 3)}
        if not self.stamped:
            return {"from": "not stated"}
        return {"from": "frame stamps", "frames": self.stamped,
                "delay_ms": round(1e3 * self._sum / self.stamped, 3),
                "min_ms": round(1e3 * self._low, 3), "max_ms": round(1e3 * self._high, 3)}
