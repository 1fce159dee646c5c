"""tracking.layout_survey: the layout measured over a recording, against a known hand.

Truth: a non-planar hand (the renderer's arch) turned through known poses in front of a
pinhole camera; the blobs are the markers' projections, the depths their z, with noise where
a test says so. The still start's layout is the truth with the errors a structured-light camera
leaves in it (heights off by up to a millimetre). SciPy's least_squares is the oracle for the
Gauss-Newton step.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.hand import HandLayout, fit_pose
from wristtrack.sim.realism import arched
from wristtrack.tracking.layout_survey import DEPTH_FRAMES, MIN_FRAMES, LayoutSurvey, RunSurvey
from wristtrack.tracking.observation import SLIDING_MARKERS, MeasurementNoise
from wristtrack.tracking.results import FrameResult, Status

CAMERA = Camera(fx=570.0, fy=570.0, cx=320.0, cy=240.0, width=640, height=480)
TRUTH = arched(HandLayout.default())
# the still start's errors: heights (z) up to 1.1 mm, a little across the hand
STILL_ERROR = np.array([[0, 0, 0], [-0.2e-3, -0.1e-3, 0.4e-3], [0.1e-3, 0.05e-3, -1.1e-3],
                        [0.2e-3, 0, 0], [-0.1e-3, 0.1e-3, -0.65e-3], [0.1e-3, -0.05e-3, -0.24e-3]])


def still_layout() -> HandLayout:
    return HandLayout(TRUTH.points + STILL_ERROR)


def poses(n: int, turn_deg: float = 35.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R_ch, t_ch) of a hand facing the camera 0.6 m away that turns about its three axes."""
    face = Rotation.from_euler("X", np.pi)  # the back of the hand towards the camera
    out = []
    for k in range(n):
        s = 2 * np.pi * k / n
        turn = np.radians(turn_deg) * np.array([np.sin(s), np.sin(2 * s), np.cos(3 * s) - 1])
        R = (face * Rotation.from_euler("XYZ", turn)).as_matrix()
        out.append((R, np.array([-0.04, 0.0, 0.6])))
    return out


def frame(R, t, points, rng=None, px=0.0, mm=0.0, extra=None) -> Detections:
    """The markers ``points`` (hand frame) at pose (R, t) as blobs (and depths), with noise."""
    cam = points @ R.T + t
    uv = CAMERA.project(cam)
    z = cam[:, 2].copy()
    if rng is not None:
        uv = uv + rng.normal(scale=px, size=uv.shape)
        z = z + rng.normal(scale=mm * 1e-3, size=z.shape)
    if extra is not None:  # one more blob, labelled as a marker by the caller
        uv, z = np.vstack([uv, extra[0]]), np.append(z, extra[1])
    return Detections(0.0, uv, z)


def survey_of(layout, frames_poses, dets, labels=None) -> LayoutSurvey:
    s = LayoutSurvey(CAMERA, layout, *frames_poses[0])
    for (R, t), d in zip(frames_poses, dets, strict=True):
        s.add(d, np.arange(6) if labels is None else labels, R, t)
    return s


def test_the_survey_recovers_the_heights_the_still_start_got_wrong():
    rng = np.random.default_rng(1)
    ps = poses(120)
    dets = [frame(R, t, TRUTH.points, rng, px=0.1, mm=1.4) for R, t in ps]
    s = survey_of(still_layout(), ps, dets)
    assert (s.frames == 120).all()
    err = s.surveyed_points() - TRUTH.points
    # from up to 1.1 mm to a tenth of that; across the hand as good as the still start's
    assert np.abs(err[:, 2]).max() < 0.1e-3
    assert np.abs(err[:, :2]).max() < 0.25e-3


def test_the_step_is_the_least_squares_solution():
    """One Gauss-Newton step from the still start's layout against SciPy's solver."""
    rng = np.random.default_rng(2)
    ps = poses(60)
    dets = [frame(R, t, TRUTH.points, rng, px=0.3, mm=1.0) for R, t in ps]  # within the gates
    noise = MeasurementNoise()
    start = still_layout()
    s = survey_of(start, ps, dets)
    raw = start.points + np.array([s.step(j) for j in range(6)])
    for j in range(6):
        def residuals(X, j=j):
            out = []
            for (R, t), d in zip(ps, dets, strict=True):
                pc = R @ X + t
                out += list((CAMERA.project(pc) - d.uv[j]) / noise.pixel_sigma)
                # depth weighed as over the still start's frames (DEPTH_FRAMES of them)
                w = np.sqrt(DEPTH_FRAMES / len(ps))
                out.append(w * (pc[2] - d.depth[j]) / noise.depth_sigma(d.depth[j]))
            return out
        oracle = least_squares(residuals, start.points[j], xtol=1e-12, ftol=1e-12).x
        np.testing.assert_allclose(raw[j], oracle, atol=2e-6)


def test_the_skin_slide_is_taken_out_and_the_heights_kept():
    """The MCP markers slide distally with the fingers (0 at the still start, up to 2 mm): the
    mean slide is not a better measurement of the neutral layout."""
    ps = poses(150)
    slide = np.zeros((150, 6, 3))
    distal = 1e-3 * (1 - np.cos(np.linspace(0, 4 * np.pi, 150)))
    slide[:, list(SLIDING_MARKERS), 0] = distal[:, None]
    dets = [frame(R, t, TRUTH.points + slide[k]) for k, (R, t) in enumerate(ps)]
    start = still_layout()
    s = survey_of(start, ps, dets)
    raw = start.points + np.array([s.step(j) for j in range(6)])
    mcp = list(SLIDING_MARKERS)
    assert np.all(raw[mcp, 0] - TRUTH.points[mcp, 0] > 0.8e-3)  # the data do carry the slide
    err = s.surveyed_points() - TRUTH.points
    # distally the MCPs keep the still start's common place, their places relative to one
    # another surveyed; the heights surveyed
    np.testing.assert_allclose(err[mcp, 0], STILL_ERROR[mcp, 0].mean(), atol=0.03e-3)
    assert np.abs(err[:, 2]).max() < 0.15e-3


def test_the_surveyed_layout_is_in_the_contract_frame_and_keeps_the_side():
    ps = poses(90)
    for truth in (TRUTH, TRUTH.mirrored()):
        start = HandLayout(truth.points + STILL_ERROR * [1, truth.side == "right" or -1, 1])
        dets = [frame(R, t, truth.points) for R, t in ps]
        s = LayoutSurvey(CAMERA, start, *ps[0])
        for (R, t), d in zip(ps, dets, strict=True):
            s.add(d, np.arange(6), R, t)
        layout = s.surveyed_layout()
        assert layout is not None and layout.side == truth.side
        # in the truth's own frame, within 0.05 deg
        R, _ = fit_pose(truth, layout.points)
        assert np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))) < 0.05
        np.testing.assert_allclose(layout.points, truth.points, atol=0.25e-3)


def test_a_hand_that_never_turns_keeps_the_still_starts_layout():
    """Facing the camera, only depth sees the heights, and however many frames of it there
    are, a structured-light camera's are not independent: the survey says no more than the
    still start did."""
    rng = np.random.default_rng(3)
    ps = poses(200, turn_deg=0.5)
    dets = [frame(R, t, TRUTH.points, rng, px=0.1, mm=1.4) for R, t in ps]
    s = survey_of(still_layout(), ps, dets)
    assert s.surveyed_layout() is None
    few = survey_of(still_layout(), poses(MIN_FRAMES - 1), [
        frame(R, t, TRUTH.points) for R, t in poses(MIN_FRAMES - 1)])
    assert few.surveyed_layout() is None


def test_doubted_blobs_and_far_ones_are_not_taken():
    ps = poses(90)
    clean = survey_of(still_layout(), ps, [frame(R, t, TRUTH.points) for R, t in ps])
    dets = []
    for R, t in ps:
        d = frame(R, t, TRUTH.points, extra=(CAMERA.project(TRUTH.points[2] @ R.T + t) + 8.0,
                                             0.6))
        # the doubted copy of MCP2 sits 1 px off
        uv = d.uv.copy()
        uv = np.vstack([uv, uv[2] + 1.0])
        dets.append(Detections(0.0, uv, np.append(d.depth, d.depth[2]),
                               suspect=np.array([False] * 7 + [True])))
    labels = np.array([0, 1, 2, 3, 4, 5, 2, 2])  # the far blob and the doubted one as MCP2
    s = survey_of(still_layout(), ps, dets, labels)
    np.testing.assert_array_equal(s.frames, clean.frames)
    np.testing.assert_allclose(s.surveyed_points(), clean.surveyed_points(), atol=1e-12)


class _Tracker:
    """What RunSurvey reads of a tracker."""

    def __init__(self, layout, R_c0, t_c0):
        self.camera, self.layout, self.R_c0, self.t_c0 = CAMERA, layout, R_c0, t_c0
        self.config = type("C", (), {"measurement": MeasurementNoise()})()


def _result(R, t, status=Status.TRACKING):
    return FrameResult(0, 0.0, status, R, t, np.eye(3), np.zeros(3), np.zeros(3), np.zeros(3),
                       None, np.arange(6), 6, 0)


@pytest.mark.parametrize("first", [40, 100])
def test_a_run_keeps_the_survey_of_the_layout_it_held_longest(first):
    """A tracker that re-initialised without hand.json took another layout and W0: a survey
    each, the longer one kept; coasting frames are not taken."""
    ps = poses(140)
    other = HandLayout(TRUTH.points + 0.5 * STILL_ERROR)  # another still start's
    a, b = _Tracker(still_layout(), *ps[0]), _Tracker(other, *ps[first])
    run = RunSurvey()
    for k, (R, t) in enumerate(ps):
        tracker = a if k < first else b
        run.add(tracker, frame(R, t, TRUTH.points), _result(R, t))
        run.add(tracker, frame(R, t, TRUTH.points), _result(R, t, Status.COASTING))
    kept = run.survey()
    assert kept.layout is (a.layout if first > 70 else b.layout)
    assert (kept.frames == max(first, 140 - first)).all()
    np.testing.assert_array_equal(run.surveyed_layout().points, kept.surveyed_layout().points)
    assert RunSurvey().surveyed_layout() is None  # nothing tracked
