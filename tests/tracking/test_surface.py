"""tracking.surface: the skin between the markers as depth patches.

Truth: depth images ray-cast here from a known hand surface (a plane, or a back of the hand
arched along its width) at a known pose, so the learned planes, the read depths and the
corrected pose are checked against geometry derived by hand, not against the module's own
formulas.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.camera import Camera
from wristtrack.depth_noise import window_correlation
from wristtrack.filter.ukf import UKFParams
from wristtrack.hand import HandLayout
from wristtrack.tracking import surface
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.offset_model import DepthOffsetModel, carry_offset
from wristtrack.tracking.surface import SurfaceSettings

CAMERA = Camera.default()
SETTINGS = SurfaceSettings()
ARCH = 4.0  # 1/m: the skin's height (hand frame z) falls by ARCH * (y - 0.0)^2 across the hand


def arched(q: np.ndarray) -> np.ndarray:
    """Height of the arched test skin at hand-frame x, y (..., 2): highest along the middle,
    ~4 mm lower at the sides (a real back of the hand arches over the metacarpals)."""
    return -ARCH * q[..., 1] ** 2


def flat(q: np.ndarray) -> np.ndarray:
    return np.zeros(q.shape[:-1])


def pose(tilt_deg: float = 0.0, z: float = 0.65) -> tuple[np.ndarray, np.ndarray]:
    """A hand facing the camera (its +Z towards it), tilted about its own x axis."""
    R = (Rotation.from_euler("X", np.pi) * Rotation.from_euler("x", tilt_deg, degrees=True))
    t = np.array([-0.04, 0.0, z])
    return R.as_matrix(), t


def render_depth(R: np.ndarray, t: np.ndarray, height=flat, noise: float = 0.0,
                 rng: np.random.Generator | None = None) -> np.ndarray:
    """Raw depth (mm, uint16) of the skin z_h = height(x_h, y_h) seen at pose (R, t), within
    70 mm of the hand's origin along x and y; zero (no reading) elsewhere."""
    v, u = np.mgrid[0:CAMERA.height, 0:CAMERA.width]
    rays = np.concatenate((CAMERA.normalize(np.stack((u, v), -1).astype(float)),
                           np.ones((*u.shape, 1))), -1)

    def gap(s: np.ndarray) -> np.ndarray:  # hand-frame height above the skin at depth s
        q = (rays * s[..., None] - t) @ R
        return q[..., 2] - height(q[..., :2])

    s = np.full(u.shape, t[2])
    for _ in range(6):  # Newton on the depth along each ray (the skin is gently curved)
        ds = 1e-4
        s = s - gap(s) * ds / (gap(s + ds) - gap(s))
    q = (rays * s[..., None] - t) @ R
    on = (np.abs(q[..., 0] - 0.045) < 0.07) & (np.abs(q[..., 1]) < 0.07)
    if noise:
        s = s + rng.normal(scale=noise, size=s.shape)
    return np.where(on, np.rint(s * 1000.0), 0).astype(np.uint16)


def test_plane_depths_meets_the_plane_on_the_ray():
    """(n.p)/(n.r): a plane z = 0.7 facing the camera, and one tilted 45 deg about y."""
    ray = np.array([0.1, -0.2, 1.0])
    assert surface.plane_depths(np.array([0, 0, 0.7]), np.array([0, 0, 1.0]), ray) \
        == pytest.approx(0.7)
    n = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)  # x + z = 0.7: along the ray 0.1 s + s = 0.7
    assert surface.plane_depths(np.array([0, 0, 0.7]), n, ray) == pytest.approx(0.7 / 1.1)


def test_patches_cover_the_back_of_the_hand_clear_of_the_markers():
    layout = HandLayout.default()
    c = surface.patch_centres(layout, SETTINGS)
    assert len(c) >= 15  # about one matching window per patch over ~35 cm^2 of skin
    gaps = np.linalg.norm(c[:, None] - layout.points[None, :, :2], axis=2)
    assert gaps.min() > SETTINGS.clearance


def test_learned_planes_follow_the_arch_of_the_skin():
    """Heights within 0.3 mm and normals within 2 deg of the arched skin's, from 10 noisy
    frames (1.3 mm per pixel, as a structured-light camera at arm's length)."""
    rng = np.random.default_rng(0)
    R, t = pose(10.0)
    frames = [render_depth(R, t, arched, 1.3e-3, rng) for _ in range(10)]
    learned = surface.learn_surface(CAMERA, HandLayout.default(), R, t, frames, SETTINGS)
    assert learned is not None and len(learned) >= 15
    xy = learned.points[:, :2]
    np.testing.assert_allclose(learned.points[:, 2], arched(xy), atol=3e-4)
    true_n = np.column_stack((-0.0 * xy[:, 0], 2 * ARCH * xy[:, 1], np.ones(len(xy))))
    true_n /= np.linalg.norm(true_n, axis=1, keepdims=True)
    off = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", learned.normals, true_n), -1, 1)))
    assert off.max() < 2.0, off


def test_no_skin_in_view_learns_nothing():
    R, t = pose()
    empty = np.zeros((CAMERA.height, CAMERA.width), np.uint16)
    assert surface.learn_surface(CAMERA, HandLayout.default(), R, t, [empty], SETTINGS) is None
    assert surface.learn_surface(CAMERA, HandLayout.default(), R, t, [], SETTINGS) is None


def test_read_depth_is_the_skins_on_each_centre_ray_despite_a_finger_over_it():
    """Noise-free arched skin seen at 30 deg: each patch's depth equals where its centre ray
    meets the true skin (within quantisation); a finger 3 cm above part of the skin is gated
    out of the patches it covers."""
    R, t = pose(30.0)
    learned = surface.learn_surface(CAMERA, HandLayout.default(), R, t,
                                    [render_depth(R, t, arched)], SETTINGS)
    image = render_depth(R, t, arched)
    P = learned.points @ R.T + t
    uv = CAMERA.project(P[0])
    u, v = int(uv[0]), int(uv[1])
    image[v - 1:v + 2, u - 2:u + 3] -= 30  # a fingertip over a third of one patch
    reading = surface.read_patches(CAMERA, learned, R, t, image, SETTINGS)
    assert reading is not None and 0 in reading.patches
    true_z = P[reading.patches, 2]  # each centre ray runs through its patch's centre
    np.testing.assert_allclose(reading.depth, true_z, atol=4e-4)



@pytest.mark.parametrize(("tilt_deg", "y_h"), [(50.0, 0.068), (60.0, 0.066)])
def test_a_patch_past_the_hands_outline_skips_the_depth_fattened_over_the_wall(tilt_deg, y_h):
    """A wall 0.9 m away behind a hand tilted 50-60 deg, and, as a structured-light camera
    (and the real OpenNI frames) show, the hand's depth spread 2 px over the wall beside its
    outline. Two patches 2-4 mm inside opposite edges reach past them: read with those pixels
    (no edge clearance) they are 0.4-0.9 mm off the skin along their centre rays, read without
    them 0.1 mm."""
    import cv2

    R, t = pose(tilt_deg)
    image = render_depth(R, t).astype(np.float32)
    wall = image == 0
    hand = np.where(wall, 1e4, image).astype(np.float32)
    nearest = cv2.erode(hand, np.ones((5, 5), np.uint8))  # the hand within 2 px
    image = np.where(wall, np.where(nearest < 1e4, nearest, 900.0), image)
    image = np.rint(image).astype(np.uint16)
    edges = surface.DorsumSurface(np.array([[0.045, y_h, 0.0], [0.045, -y_h, 0.0]]),
                                  np.array([[0.0, 0.0, 1.0]] * 2))
    true_z = (edges.points @ R.T + t)[:, 2]
    errors = {}
    for clearance in (SETTINGS.edge_clearance, 0):
        settings = SurfaceSettings(edge_clearance=clearance)
        reading = surface.read_patches(CAMERA, edges, R, t, image, settings)
        assert reading is not None and list(reading.patches) == [0, 1]
        errors[clearance] = np.abs(reading.depth - true_z)
    assert np.all(errors[SETTINGS.edge_clearance] < 0.15e-3), errors
    assert np.all(errors[0] > 0.4e-3), errors

def test_a_hand_turned_away_has_no_patches_to_read():
    R, t = pose(100.0)  # its back past edge-on
    learned = surface.DorsumSurface(np.array([[0.04, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert surface.read_patches(CAMERA, learned, R, t, render_depth(R, t), SETTINGS) is None


def _disc_means(fields: np.ndarray, centres: list[tuple[int, int]], r: float) -> np.ndarray:
    """(draws, K) means of each field (draws, H, W) over the pixels within ``r`` of each
    centre pixel (u, v): read_patches' discs."""
    v, u = np.mgrid[0:fields.shape[1], 0:fields.shape[2]]
    return np.stack([fields[:, (u - cu) ** 2 + (v - cv) ** 2 <= r * r].mean(axis=1)
                     for cu, cv in centres], axis=1)


def test_patch_readings_share_the_noise_of_the_sensors_matching_window():
    """Depth noise drawn as the structured-light simulator draws it (white noise averaged over
    the 9x9 px matching window): the correlation of single pixels and of patch means (discs of
    4 px, a 5 mm patch at 0.65 m) at offsets from 0 to 20 px, measured over 3000 draws, is what
    window_correlation and reading_correlation say, within 0.05. Patches 10 px apart (facing
    the camera) share a tenth of their noise; 4 px apart (a hand turned ~65 deg, its patches'
    images crowded) three quarters."""
    import cv2

    rng = np.random.default_rng(3)
    white = rng.standard_normal((3000, 64, 64)).astype(np.float32)
    fields = np.stack([cv2.blur(w, (9, 9)) for w in white])
    centres = [(20, 20), (20, 20), (24, 20), (30, 20), (23, 24), (27, 27), (40, 20)]
    pixels = np.array([fields[:, v, u] for u, v in centres]).T
    measured = np.corrcoef(pixels, rowvar=False)
    d = np.array(centres)[:, None] - np.array(centres)[None]
    np.testing.assert_allclose(measured, window_correlation(d[..., 0], d[..., 1]), atol=0.05)

    means = _disc_means(fields, centres, 4.0)
    measured = np.corrcoef(means, rowvar=False)
    k = len(centres)
    reading = surface.PatchReading(np.arange(k), np.zeros((k, 3)), np.zeros(k),
                                   np.zeros((k, 3)), np.zeros((k, 3)), np.array(centres),
                                   np.full(k, 4.0))
    modelled = surface.reading_correlation(reading)
    np.testing.assert_allclose(modelled, measured, atol=0.05)
    assert modelled[0, 3] == pytest.approx(0.1, abs=0.03)  # 10 px apart
    assert modelled[0, 2] == pytest.approx(0.72, abs=0.03)  # 4 px apart
    assert modelled[0, 6] == 0.0  # 20 px apart: no window reaches both


def test_patches_read_at_one_place_count_once():
    """Five readings of one patch (its image disc read five times, as a hand turned edge-on
    crowds its patches' images together) tell the pose hardly more than one: the information
    they add to the state is within 15 % of one reading's (taken as independent, five times)."""
    R, t = pose(15.0)
    flat_skin = surface.learn_surface(CAMERA, HandLayout.default(), R, t, [render_depth(R, t)],
                                      SETTINGS)
    model, x, P = _filter_state(R, t, 0.0)
    one = surface.read_patches(CAMERA, flat_skin, R, t, render_depth(R, t), SETTINGS)

    def information(copies: int) -> float:
        pick = np.zeros(copies, int)
        reading = surface.PatchReading(*(np.asarray(f)[pick] for f in (
            one.patches, one.rays, one.depth, one.points, one.normals, one.pixels,
            one.radius_px)))
        _, P1, _, _ = surface.surface_update(model, x, P, R, t, flat_skin, reading,
                                             MeasurementNoise(), SETTINGS, CAMERA, UKFParams(),
                                             nis_limit=np.inf)
        return float(np.trace(np.linalg.inv(P1) - np.linalg.inv(P)))

    assert information(5) == pytest.approx(information(1), rel=0.15)


def _filter_state(R_true, t_true, error_deg):
    """A default-model state whose pose is the truth turned by ``error_deg`` about the hand's
    y axis (an out-of-plane error: the one depth sees), with W0 at the truth."""
    model = ConstantRateModel()
    turn = Rotation.from_rotvec(np.radians(error_deg) * R_true[:, 1]).as_matrix()
    x = model.initial_state(R_true.T @ turn @ R_true, np.zeros(3))
    P = np.diag(np.r_[np.full(3, np.radians(2.0) ** 2), np.full(3, 0.002**2),
                      np.full(3, 0.01**2), np.full(3, 0.1**2)])
    return model, x, P


def test_the_update_turns_a_tilted_estimate_back_onto_the_skin():
    """An estimate 3 deg out of plane, corrected by one frame of noise-free flat skin alone:
    within 0.5 deg of the truth (a sigma point spread of 2 deg a priori)."""
    R, t = pose(15.0)
    flat_skin = surface.learn_surface(CAMERA, HandLayout.default(), R, t, [render_depth(R, t)],
                                      SETTINGS)
    model, x, P = _filter_state(R, t, 3.0)
    R_est = R @ x[:9].reshape(3, 3)
    reading = surface.read_patches(CAMERA, flat_skin, R_est, t, render_depth(R, t), SETTINGS)
    x1, P1, nis, dof = surface.surface_update(model, x, P, R, t, flat_skin, reading,
                                              MeasurementNoise(), SETTINGS, CAMERA,
                                              UKFParams(),
                                              nis_limit=np.inf)
    before = np.degrees(Rotation.from_matrix(x[:9].reshape(3, 3)).magnitude())
    after = np.degrees(Rotation.from_matrix(x1[:9].reshape(3, 3)).magnitude())
    assert before == pytest.approx(3.0) and after < 0.5, after
    assert dof == len(reading.depth) and P1[1, 1] < P[1, 1] / 4


def test_an_update_beyond_its_nis_limit_is_not_applied():
    R, t = pose(15.0)
    flat_skin = surface.learn_surface(CAMERA, HandLayout.default(), R, t, [render_depth(R, t)],
                                      SETTINGS)
    model, x, P = _filter_state(R, t, 3.0)
    reading = surface.read_patches(CAMERA, flat_skin, R @ x[:9].reshape(3, 3), t,
                                   render_depth(R, t), SETTINGS)
    x1, P1, nis, _ = surface.surface_update(model, x, P, R, t, flat_skin, reading,
                                            MeasurementNoise(), SETTINGS, CAMERA,
                                            UKFParams(),
                                            nis_limit=1.0)
    assert nis > 1.0 and x1 is x and P1 is P


def test_skin_read_through_a_misregistered_depth_map_tells_the_offset():
    """Depth images rolled 2 px left and 1 px down against the colour image (as the renderer
    misregisters them): the skin learned through them at a tilted W0, then read at two poses
    turned further, about the hand's y axis and about its x axis. Updates of a state that
    carries the offset (DepthOffsetModel), each at the true pose known closely, find the offset
    (2, -1) within 0.2 px from no offset known (1.5 px prior), and leave the pose where it was.
    One frame of flat skin tells only the offset along its slope (otherwise the offset is much
    like a move along the skin's normal); the second, turned the other way, tells the rest. The
    planes' shift learned at W0 is what makes the still start's own frame tell no offset."""
    def rolled(depth: np.ndarray) -> np.ndarray:
        return np.roll(depth, (1, -2), axis=(0, 1))  # its pixel (u, v) shows (u + 2, v - 1)

    def turned(about_y: float, about_x: float) -> tuple[np.ndarray, np.ndarray]:
        R = (Rotation.from_euler("X", np.pi) * Rotation.from_euler("yx", [about_y, about_x],
                                                                  degrees=True)).as_matrix()
        return R, np.array([-0.04, 0.0, 0.65])

    R0, t0 = turned(15.0, 10.0)
    skin = surface.learn_surface(CAMERA, HandLayout.default(), R0, t0,
                                 [rolled(render_depth(R0, t0))], SETTINGS)
    assert skin.offset_shift is not None and np.abs(skin.offset_shift).max() > 1e-4
    model = DepthOffsetModel()
    pose_prior = model.initial_covariance(np.diag([np.radians(0.02) ** 2] * 3 + [2e-5**2] * 3))
    x1, P1 = None, None
    for k, (R, t) in enumerate(((R0, t0), turned(45.0, 10.0), turned(10.0, 45.0))):
        x = model.initial_state(R0.T @ R, R0.T @ (t - t0))
        x, P = carry_offset(model, x, pose_prior, x1, P1)  # the offset found so far
        reading = surface.read_patches(CAMERA, skin, R, t, rolled(render_depth(R, t)), SETTINGS)
        x1, P1, _, _ = surface.surface_update(model, x, P, R0, t0, skin, reading,
                                              MeasurementNoise(), SETTINGS, CAMERA, UKFParams(),
                                              nis_limit=np.inf)
        moved = Rotation.from_matrix(x1[:9].reshape(3, 3) @ x[:9].reshape(3, 3).T).magnitude()
        assert np.degrees(moved) < 0.05 and np.linalg.norm(x1[9:12] - x[9:12]) < 1e-4
        if k == 0:  # the still start's own frame: the skin as learned, no offset to tell
            np.testing.assert_allclose(x1[20:], 0.0, atol=0.05)
    np.testing.assert_allclose(x1[20:], [2.0, -1.0], atol=0.2)


def test_the_tracker_learns_the_skin_and_tracks_closer_to_the_truth(every_effect):
    """A rendered recording with every camera and hand effect at its realistic strength
    (structured-light depth: Nguyen et al.'s noise, correlated over the matching window,
    quantised, misregistered): the tracker learns the skin over the still start and, using it,
    its orientation error against the rendered truth falls by at least a tenth (0.77 -> 0.61
    deg when measured; range of motion 0.92 -> 0.48). On structured light alone, where the
    sharp blobs carry the out-of-plane angles, it came out even (6 seeds, 0.236 -> 0.238 deg)."""
    from benchmarks.accuracy import recorded_detections, score
    from wristtrack.tracking.tracker import Tracker, TrackerConfig

    camera, hand, detections, truth = recorded_detections(every_effect)
    errors = []
    for config in (TrackerConfig(surface=None), TrackerConfig()):
        tracker = Tracker(camera, hand, config)
        errors.append(score([tracker.step(d) for d in detections], truth)["rot"])
    assert tracker.surface is not None and len(tracker.surface) >= 15
    assert np.abs(tracker.surface.points[:, 2]).max() < 0.01  # skin within 1 cm of markers
    assert errors[1] < 0.9 * errors[0], errors
