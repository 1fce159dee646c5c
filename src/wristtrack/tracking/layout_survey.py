"""The subject's layout measured over a whole recording, for a second pass without hand.json.

Without hand.json the layout comes from the still start (tracking/neutral.py). The back of the
hand faces the camera there, so the pixels place each marker across the hand sharply, but its
height above the palm only depth measures. A structured-light camera's depth errors are
correlated over the half second and over a marker, so averaging the still start's frames leaves
~1 mm in the MCP markers' heights, and the hand frame (the palm plane's normal) 0.2-0.5 deg
off. That error sits in every pose of the run. Once the hand turns, the pixels see the heights
too, by parallax.

:class:`LayoutSurvey` takes each tracked frame's labelled markers (the blobs the detector does
not doubt) with the filter's pose of that frame, and accumulates, per marker, the normal
equations of one Gauss-Newton step on its hand-frame position: pixels and depth weighed as the
filter weighs them (depth no more than over the still start: its errors are correlated in
time), linearised at the layout in use. A marker moves only where the pixels alone place it
to half a millimetre. Memory stays flat however long the run.
:meth:`LayoutSurvey.surveyed_layout` solves them (the poses are taken as they are: a second
round of pose and layout changed the rendered recordings' errors by less than 0.01 deg).
:class:`RunSurvey` follows a tracker through a run and keeps the survey of its longest-held
layout; ``wristtrack track`` then tracks the recording again with it (pipeline/track.py).

Skin slide: the skin over the knuckles slides distally as the fingers flex (DESIGN section 2), so
over a recording the MCP markers sit on average up to ~1 mm distal of where they sat at the
neutral start, where the hand frame and W0 are defined. The MCP markers' common shift across
the hand (x, y) against the still start is that slide, not a better measurement, so it is taken
out; the heights and the markers' places relative to one another are kept. (Kept in, the hand
frame built on the surveyed markers was 0.3 deg off the neutral one, and the orientation error
of the rendered every-effect recordings rose from 0.69 to 0.90 deg.)
"""

from __future__ import annotations

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import ConfigError
from wristtrack.hand import HandLayout, estimate_layout
from wristtrack.tracking.neutral import STILL_FRAMES
from wristtrack.tracking.observation import SLIDING_MARKERS, MeasurementNoise
from wristtrack.tracking.pose_fit import pinhole_jacobian
from wristtrack.tracking.results import FrameResult, Status

MIN_FRAMES = 30  # a marker seen in fewer frames keeps its place (1 s at 30 fps)
# A marker the pixels alone place less sharply than this along its worst direction (metres,
# 1 sigma) keeps its place: the hand did not turn enough to see it from the side, and depth
# says no more than it said over the still start.
MAX_SIGMA = 0.0005
# Depth errors of a structured-light camera are correlated in time (a still hand keeps its
# speckle), so depth's weight is capped at that of the still start's frames, however many.
DEPTH_FRAMES = STILL_FRAMES
MAX_PIXEL_RESIDUAL = 3.0  # px: a blob this far from its marker's projection is not taken
MAX_DEPTH_RESIDUAL = 4.0  # depth sigmas: a depth this far off (an edge, a hole) is not taken


class LayoutSurvey:
    """Accumulates one frame at a time what the markers say about their hand-frame positions
    (see module doc), for one layout and one W0 (a new one starts afresh)."""

    def __init__(self, camera: Camera, layout: HandLayout, R_c0: np.ndarray, t_c0: np.ndarray,
                 noise: MeasurementNoise | None = None) -> None:
        self.camera = camera
        self.layout = layout
        self.R_c0, self.t_c0 = np.array(R_c0, dtype=float), np.array(t_c0, dtype=float)
        self.noise = noise or MeasurementNoise()
        # J^T J and J^T r per marker, of the pixels [0] and of depth [1]
        self.normal = np.zeros((2, 6, 3, 3))
        self.gradient = np.zeros((2, 6, 3))
        self.frames = np.zeros(6, dtype=int)  # frames that saw each marker

    def add(self, det: Detections, labels: np.ndarray, R_ch: np.ndarray,
            t_ch: np.ndarray) -> None:
        """One frame: blob ``labels`` (marker index, -1 clutter) and the filter's pose."""
        blobs = np.flatnonzero(np.asarray(labels) >= 0)
        if det.suspect is not None:
            blobs = blobs[~det.suspect[blobs]]
        if blobs.size == 0:
            return
        marker = np.asarray(labels)[blobs]
        pc = self.layout.points[marker] @ R_ch.T + t_ch  # (n,3) camera frame
        z = pc[:, 2]
        cam, s = self.camera, self.noise.pixel_sigma
        xy = cam.normalize(det.uv[blobs])
        r_px = np.stack([cam.fx * (pc[:, 0] / z - xy[:, 0]),
                         cam.fy * (pc[:, 1] / z - xy[:, 1])], 1) / s
        # d(u, v)/d(point) of the pinhole projection, then through the pose to the hand frame
        J = np.zeros((len(blobs), 3, 3))
        J[:, :2] = pinhole_jacobian(cam, pc) / s
        r = np.zeros((len(blobs), 3))  # rows: u, v, depth
        r[:, :2] = r_px
        if det.depth is not None:
            depth = det.depth[blobs]
            with np.errstate(invalid="ignore"):
                sz = self.noise.depth_sigma(np.nan_to_num(depth, nan=1.0))
                r_z = (z - depth) / sz
                use = np.isfinite(r_z) & (np.abs(r_z) <= MAX_DEPTH_RESIDUAL)
            J[use, 2, 2] = 1.0 / sz[use]
            r[use, 2] = r_z[use]
        ok = np.isfinite(r_px).all(1) & (np.hypot(*(r_px * s).T) <= MAX_PIXEL_RESIDUAL)
        J = J @ R_ch  # d(residual)/d(hand-frame point)
        Jt = np.swapaxes(J, 1, 2)
        for k in np.flatnonzero(ok):
            j = marker[k]
            for part, rows in ((0, slice(0, 2)), (1, slice(2, 3))):
                self.normal[part, j] += Jt[k, :, rows] @ J[k, rows]
                self.gradient[part, j] += Jt[k, :, rows] @ r[k, rows]
            self.frames[j] += 1

    def step(self, j: int) -> np.ndarray | None:
        """Marker ``j``'s Gauss-Newton step (3,), or None where the survey cannot place it."""
        if self.frames[j] < MIN_FRAMES:
            return None
        eig = np.linalg.eigvalsh(self.normal[0, j])
        if not eig[0] > 0 or 1.0 / np.sqrt(eig[0]) > MAX_SIGMA:
            return None
        depth = min(1.0, DEPTH_FRAMES / self.frames[j])
        A = self.normal[0, j] + depth * self.normal[1, j]
        return -np.linalg.solve(A, self.gradient[0, j] + depth * self.gradient[1, j])

    def surveyed_points(self) -> np.ndarray:
        """(6,3) hand-frame marker positions: surveyed where the survey places them (:meth:`step`),
        the layout's elsewhere; the MCP markers' common lateral shift (skin slide) taken out."""
        X = self.layout.points.copy()
        for j in range(6):
            step = self.step(j)
            if step is not None:
                X[j] += step
        moved = [j for j in SLIDING_MARKERS if not np.array_equal(X[j], self.layout.points[j])]
        if moved:
            X[moved, :2] -= (X[moved, :2] - self.layout.points[moved, :2]).mean(axis=0)
        return X

    def surveyed_layout(self) -> HandLayout | None:
        """The surveyed layout in its own hand frame (DESIGN section 2), or None when the
        survey moved no marker or the result is not a valid layout."""
        X = self.surveyed_points()
        if np.array_equal(X, self.layout.points):
            return None
        # the frame's convention (palm normal towards the camera) is read in W0's camera frame
        try:
            return estimate_layout(X @ self.R_c0.T + self.t_c0)[0]
        except ConfigError:
            return None


class RunSurvey:
    """Surveys the layout a tracker uses through a run: a fresh :class:`LayoutSurvey` whenever
    the tracker takes another layout or W0 (the still start's end, a re-initialisation without
    hand.json), and the survey of the one held longest at the end."""

    def __init__(self) -> None:
        self.current: LayoutSurvey | None = None
        self.best: LayoutSurvey | None = None

    def add(self, tracker, det: Detections, result: FrameResult) -> None:
        """One frame of ``tracker`` (a tracking.tracker.Tracker): its detections and result."""
        if result.status != Status.TRACKING or tracker.layout is None or tracker.R_c0 is None:
            return
        cur = self.current
        if cur is None or cur.layout is not tracker.layout or not (
                np.array_equal(cur.R_c0, tracker.R_c0) and np.array_equal(cur.t_c0, tracker.t_c0)):
            self._keep_best()
            cur = self.current = LayoutSurvey(tracker.camera, tracker.layout, tracker.R_c0,
                                              tracker.t_c0, tracker.config.measurement)
        cur.add(det, result.labels, result.R_ch, result.t_ch)

    def _keep_best(self) -> None:
        if self.current is not None and (
                self.best is None or self.current.frames.sum() > self.best.frames.sum()):
            self.best = self.current

    def survey(self) -> LayoutSurvey | None:
        """The survey of the layout held longest, or None when the tracker never tracked."""
        self._keep_best()
        return self.best

    def surveyed_layout(self) -> HandLayout | None:
        """The layout held longest, as surveyed (:meth:`LayoutSurvey.surveyed_layout`), or
        None: nothing tracked, or nothing the survey could move."""
        best = self.survey()
        return best.surveyed_layout() if best is not None else None
