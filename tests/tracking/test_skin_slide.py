"""The noise the markers share in the measurement model (MarkerObservation.noise_covariance): the
MCP markers' common skin slide against a Monte Carlo of the slide itself and on detections whose
skin slides as the renderer's soft-tissue effect moves it; the colour-depth misregistration
against depths read off a tilted plane at shifted pixels."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.sim import realism
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import Trajectory, neutral_camera_pose, scenario
from wristtrack.sim.scenario_run import score_run
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import SLIDING_MARKERS, MarkerObservation, MeasurementNoise
from wristtrack.tracking.tracker import Tracker, TrackerConfig


@pytest.mark.parametrize("dist", [None, (0.033, -0.108, 0.0, 0.0, 0.0)], ids=["pinhole", "xtion"])
@pytest.mark.parametrize("use_depth", [True, False], ids=["depth", "colour-only"])
def test_slide_covariance_is_the_spread_of_the_slid_markers_measurements(dist, use_depth):
    """G G^T equals the sample covariance of the measurements of markers slid by draws of the
    slide (hand frame, one draw shared by the four MCPs), on a tilted hand; WRIST and CMC1 rows
    and columns are zero."""
    base = Camera.default()
    camera = Camera(base.fx, base.fy, base.cx, base.cy, base.width, base.height,
                    base.depth_scale, dist)
    layout = HandLayout.default()
    R_c0, t_c0 = neutral_camera_pose()
    obs = MarkerObservation(camera, layout.points, R_c0, t_c0, ConstantRateModel.pose, use_depth)
    R = Rotation.from_euler("xyz", [25, -15, 30], degrees=True).as_matrix()
    x = ConstantRateModel.initial_state(R, np.array([0.03, -0.02, 0.05]))
    G = obs.slide_jacobian(x)
    noise = G @ G.T

    rng = np.random.default_rng(3)
    slides = rng.normal(size=(40000, 3)) * np.array(MeasurementNoise().skin_slide)
    R_ch, t_ch = R_c0 @ R, R_c0 @ np.array([0.03, -0.02, 0.05]) + t_c0
    pts = np.repeat(layout.points[None], len(slides), axis=0)
    pts[:, list(SLIDING_MARKERS)] += slides[:, None, :]
    cam = pts @ R_ch.T + t_ch
    y = camera.project(cam)
    if use_depth:
        y = np.concatenate([y, cam[..., 2:]], axis=-1)
    sample = np.cov(y.reshape(len(slides), -1), rowvar=False)

    assert np.linalg.norm(noise - sample) < 0.03 * np.linalg.norm(sample)
    k = 3 if use_depth else 2
    rigid = [j * k + a for j, name in enumerate(MARKER_NAMES) if not name.startswith("MCP")
             for a in range(k)]
    assert np.all(noise[rigid] == 0.0) and np.all(noise[:, rigid] == 0.0)


def _sliding_skin_frames(name: str, seed: int):
    """The scenario's detections with the MCP markers slid by the renderer's soft-tissue effect
    (fingers flexing 0-70 deg every 3.3 s: up to 2.3 mm distally, 0.8 mm towards the palm)."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario(name, rng=rng)
    noise = NoiseModel(clutter_mean=1.0, p_miss=0.05)
    frames = []
    for k, t in enumerate(truth.t):
        flex = float(realism.finger_flexion_deg(t, truth.t[0]))
        slid = HandLayout(layout.points + realism.skin_slide(flex, layout))
        one = Trajectory(*(getattr(truth, f)[k:k + 1] for f in Trajectory.__dataclass_fields__))
        frames += simulate_detections(one, camera, slid, noise, rng)
    return truth, camera, layout, frames


@pytest.mark.parametrize("name", ["flexion", "mix"])
def test_sliding_skin_costs_little_with_the_slide_in_the_model(name):
    """The same tracker told its markers are rigid (0.3 px, the blob noise alone) takes the
    slide for motion: 1.2-1.6 deg here against 0.65-0.93 deg with the slide modelled as noise
    the markers share. Covering the slide by 0.7 px on every marker instead does nearly as well
    on this simulator's sharp frames and steady depth (0.67-0.98 deg); on rendered recordings it
    does not (the robustness benchmark), but it must never do better.

    The slide carried in the state (the default) does better still where the hand turns as the
    fingers flex (mix: 0.89 against 0.93 deg; 0.86 against 0.89 over seeds 1-6); in flexion
    alone the slide runs along the flexion tilt, and it does as well as the shared noise within
    7 % (0.69 against 0.65 here; 0.71 against 0.70 over seeds 1-6)."""
    truth, camera, layout, frames = _sliding_skin_frames(name, 1)

    def rmse(noise: MeasurementNoise, follow_slide: bool = False) -> float:
        tracker = Tracker(camera, layout, TrackerConfig(measurement=noise,
                                                        follow_slide=follow_slide))
        results = [tracker.step(f.detections) for f in frames]
        run = score_run(name, truth, frames, results)
        assert run.errors.coverage == 1.0
        return run.errors.orientation_rmse_deg

    modelled = rmse(MeasurementNoise())
    rigid = rmse(MeasurementNoise(skin_slide=(0.0, 0.0, 0.0)))
    inflated = rmse(MeasurementNoise(pixel_sigma=0.7, skin_slide=(0.0, 0.0, 0.0)))
    assert modelled < 0.8 * rigid and modelled < inflated, (modelled, rigid, inflated)
    state = rmse(MeasurementNoise(), follow_slide=True)
    assert state < (modelled if name == "mix" else 1.07 * modelled), (state, modelled)


def test_misregistration_covariance_is_the_spread_of_depths_read_off_the_blob():
    """Each marker's depth read at a pixel shifted by draws of the misregistration (one shift for
    the whole frame), where that pixel's ray meets the back of the hand (the plane through the
    marker normal to the hand's Z): its sample covariance is G G^T, pixels untouched."""
    camera, layout = Camera.default(), HandLayout.default()
    R_c0, t_c0 = neutral_camera_pose()
    obs = MarkerObservation(camera, layout.points, R_c0, t_c0, ConstantRateModel.pose, True)
    R = Rotation.from_euler("xyz", [35, -20, 10], degrees=True).as_matrix()
    x = ConstantRateModel.initial_state(R, np.array([0.02, 0.01, 0.0]))
    G = obs.registration_jacobian(x)

    pts = obs.marker_points(x[None])[0]
    n = (R_c0 @ R)[:, 2]
    uv = camera.project(pts)
    rng = np.random.default_rng(5)
    shift = rng.normal(size=(40000, 1, 2)) * MeasurementNoise().registration_px
    rays = np.concatenate([camera.normalize(uv[None] + shift), np.ones((40000, 6, 1))], -1)
    z = (pts @ n)[None] / (rays @ n)  # ray-plane intersection: z of the point on the plane
    sample = np.cov(z - pts[:, 2], rowvar=False)
    depth = np.arange(6) * 3 + 2
    assert np.linalg.norm(G[depth] @ G[depth].T - sample) < 0.03 * np.linalg.norm(sample)
    assert np.all(np.delete(G, depth, axis=0) == 0.0)
    colour_only = MarkerObservation(camera, layout.points, R_c0, t_c0, ConstantRateModel.pose,
                                    False)
    assert not np.any(colour_only.registration_jacobian(x))
