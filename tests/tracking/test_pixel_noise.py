"""The pixel noise the filter takes, learned from the recording (tracking/pixel_noise.py): the
correlation's inflation against its closed form for white, AR(1) and constant errors, the bounds,
and the tracker on sharp and on blurred blobs of the measurement-level simulator."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.detect.detections import Detections
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.sim.scenario_run import score_run
from wristtrack.tracking import noise_scale, pixel_noise
from wristtrack.tracking.observation import MarkerObservation
from wristtrack.tracking.pixel_noise import (
    EARLY_FRAMES,
    MARGIN,
    MIN_WINDOWS,
    SIGMA_FLOOR,
    WINDOW_S,
    BlobCorrelation,
    filter_sigma,
    prior_inflation,
    worst_inflation,
)
from wristtrack.tracking.tracker import Tracker, TrackerConfig

DT = 1 / 30
W = round(WINDOW_S / DT) + 1  # frames in a window: it closes once WINDOW_S has passed


def _inflation(errors: np.ndarray) -> float | None:
    """BlobCorrelation's inflation over errors (frames, 6, 2) at 30 fps, in windows of W."""
    correlation = BlobCorrelation()
    for start in range(0, len(errors) - W + 1, W):
        correlation.add(errors[start:start + W], (W - 1) * DT)
    return correlation.inflation


def _ar1(rng: np.random.Generator, rho: float, n: int) -> np.ndarray:
    e = np.empty((n, 6, 2))
    e[0] = rng.normal(size=(6, 2))
    for t in range(1, n):
        e[t] = rho * e[t - 1] + np.sqrt(1 - rho**2) * rng.normal(size=(6, 2))
    return e


def test_white_errors_are_not_inflated():
    assert _inflation(np.random.default_rng(0).normal(size=(900, 6, 2))) == pytest.approx(
        1.0, abs=0.15)


def test_correlated_errors_are_inflated_as_their_autocorrelation_says():
    """AR(1) errors: E[(sum_w e)^2] / E[sum_w e^2] = 1 + 2 sum_k (1 - k/w) rho^k over a window
    of w frames (hand-derived)."""
    rho = 0.8
    k = np.arange(1, W)
    expected = 1 + 2 * np.sum((1 - k / W) * rho**k)
    got = _inflation(_ar1(np.random.default_rng(1), rho, 3000))
    assert got == pytest.approx(expected, rel=0.15)


def test_a_constant_error_is_inflated_by_the_frames_in_a_window():
    errors = np.broadcast_to(np.random.default_rng(2).normal(size=(6, 2)), (300, 6, 2))
    assert _inflation(errors) == pytest.approx(W, rel=0.01)


def test_unseen_markers_and_the_first_windows():
    """Markers not measured (NaN) are left out; nothing is said before MIN_WINDOWS windows."""
    errors = np.random.default_rng(3).normal(size=(MIN_WINDOWS * W, 6, 2))
    errors[:, 2:] = np.nan
    assert _inflation(errors[:-W]) is None
    assert _inflation(errors) == pytest.approx(1.0, abs=0.3)


def test_the_learner_measures_windows_of_frames_as_they_come():
    """LearnedNoise gathers the tracked frames' fit residuals into windows of WINDOW_S and
    starts a new window where the observation changes (W0 or the layout moved), leaving out
    suspect blobs: frames at 30 fps with every blob off where the state puts it by a fixed
    offset no rigid motion or slide explains, but a suspect one, off by +-2 px in turn (with it
    the window's ratio would fall to 0.3, not W)."""
    truth, camera, layout = scenario("deviation", rng=np.random.default_rng(0))
    tracker = Tracker(camera, layout, TrackerConfig())
    model = tracker.model
    obs = MarkerObservation(camera, layout.points, np.eye(3), np.array([0.0, 0.0, 0.6]),
                            model.pose, False)
    x = model.initial_state(np.eye(3), np.zeros(3))
    offsets = 0.1 * np.random.default_rng(1).normal(size=(6, 2))
    uv = obs(x[None])[0].reshape(6, 2) + offsets
    suspect = np.arange(6) == 2
    frames = [Detections(0.0, uv + np.outer(suspect, [2.0 * (-1) ** k, 0.0]), suspect=suspect)
              for k in range(W)]
    labels = np.arange(6)
    learned = noise_scale.LearnedNoise()
    for k, det in enumerate(frames[:-1]):
        learned._add_frame(obs, x, labels, det, DT, 0.3)
        # the open window's frames give a provisional sigma from EARLY_FRAMES on
        assert (learned.pixel_sigma is None) == (k + 1 < EARLY_FRAMES)
    assert learned.correlation.windows == 0 and learned.spread.variance is None
    learned._add_frame(obs, x, labels, frames[-1], DT, 0.3)
    assert learned.correlation.windows == 1 and learned.spread.variance is not None
    # a constant error: the window's inflation is its number of frames
    assert learned.correlation._num / learned.correlation._den == pytest.approx(W)
    other = MarkerObservation(camera, layout.points, np.eye(3), np.array([0.0, 0.0, 0.6]),
                              model.pose, False)
    for _ in range(W - 1):
        learned._add_frame(obs, x, labels, frames[0], DT, 0.3)
    for _ in range(W - 1):  # the window restarts with the new observation
        learned._add_frame(other, x, labels, frames[0], DT, 0.3)
    assert learned.correlation.windows == 1


def _observation():
    """A colour-only MarkerObservation with the model's skin slide, and the state model."""
    truth, camera, layout = scenario("deviation", rng=np.random.default_rng(0))
    model = Tracker(camera, layout, TrackerConfig()).model
    obs = MarkerObservation(camera, layout.points, np.eye(3), np.array([0.0, 0.0, 0.6]),
                            model.pose, False)
    return obs, model


@pytest.mark.parametrize("slide", [True, False], ids=["with slide", "rigid"])
def test_fit_residuals_measure_the_blobs_scatter_about_a_rigid_hand(slide):
    """White blob noise of 0.04 px on blobs of a hand moved a little off the state (a small
    rotation and shift, and a skin slide of the MCPs where modelled): the motion and the slide
    leave the residuals, whose squares over the degrees of freedom (2n - 9 with the slide,
    2n - 6 without; hand-derived: the fit is a projection onto that many directions) give the
    noise's variance back."""
    obs, model = _observation()
    if not slide:
        obs.scale_slide(0.0)
    rng = np.random.default_rng(4)
    F = 400
    X = np.stack([model.initial_state(Rotation.from_rotvec(rng.normal(0, 0.2, 3)).as_matrix(),
                                      rng.normal(0, 0.02, 3)) for _ in range(F)])
    moved = X.copy()
    turn = Rotation.from_rotvec(rng.normal(0, 2e-3, (F, 3))).as_matrix()
    moved[:, :9] = (turn @ X[:, :9].reshape(F, 3, 3)).reshape(F, 9)
    moved[:, 9:12] += rng.normal(0, 5e-4, (F, 3))
    uv = obs(moved).reshape(F, 6, 2)
    if slide:
        for f in range(F):  # the MCPs slid together by up to ~0.5 px
            uv[f] += (obs.slide_jacobian(moved[f]) @ rng.normal(0, 0.5, 3)).reshape(6, 2)
    uv += rng.normal(0, 0.04, uv.shape)
    labels = np.tile(np.arange(6), (F, 1))
    labels[::3, 4] = -1  # a marker missed in every third frame
    residuals, dof = pixel_noise.fit_residuals(obs, X, labels, uv)
    expected = np.where(labels[:, 4] < 0, 10, 12) - (9 if slide else 6)
    np.testing.assert_array_equal(dof, expected)
    assert np.isnan(residuals[::3, 4]).all() and np.isfinite(residuals[1::3]).all()
    spread = pixel_noise.BlobSpread()
    spread.add(residuals, dof, np.zeros(F), 1.0)  # a still hand: all of it at rest
    assert np.sqrt(spread.variance) == pytest.approx(0.04, rel=0.06)
    # three markers say nothing: no residuals, no degrees of freedom
    few = labels.copy()
    few[:, 3:] = -1
    residuals, dof = pixel_noise.fit_residuals(obs, X, few, uv)
    assert (dof == 0).all() and np.isnan(residuals).all()


def test_the_sigma_the_filter_takes_stays_within_its_bounds():
    assert filter_sigma(0.3, 0.0004, None) == 0.3  # nothing learned yet: the model's
    assert filter_sigma(0.3, None, 3.0) == 0.3
    assert filter_sigma(0.3, 0.01, 3.0) == pytest.approx(MARGIN * np.sqrt(0.03))
    assert filter_sigma(0.3, 1e-6, 2.0) == SIGMA_FLOOR
    assert filter_sigma(0.3, 1.0, 6.0) == 0.3  # never above the model's
    assert filter_sigma(0.03, 1e-4, 1.0) == 0.03  # a model sharper than the floor keeps its own


def test_the_bounds_of_the_inflation_are_what_the_correlation_measures_at_its_extremes():
    """Errors constant over a window: inflated by the number of frames a window holds, exactly
    what the correlation measures for them once it can; white errors: about 1."""
    assert worst_inflation(DT) == W
    assert _inflation(np.ones((MIN_WINDOWS * W, 6, 2))) == pytest.approx(worst_inflation(DT))
    white = np.random.default_rng(3).normal(size=(40 * W, 6, 2))
    assert _inflation(white) == pytest.approx(1.0, abs=0.2)
    assert worst_inflation(1 / 60) == 31
    assert worst_inflation(2.0) == 2.0  # a window closes on its second frame at the earliest
    assert worst_inflation(0.0) is None  # no frame rate yet: the model's sigma


def test_before_the_correlation_is_measured_it_is_taken_halfway_between_its_bounds():
    """sqrt(N), N the window's frames: off by at most sqrt(N) from a truth anywhere between
    white noise (1) and constant errors (N), where either bound is off by N at the other."""
    N = worst_inflation(DT)
    prior = prior_inflation(N)
    assert prior == pytest.approx(np.sqrt(W))
    truths = np.linspace(1.0, N, 200)
    def worst_ratio(taken):
        return np.max(np.maximum(taken / truths, truths / taken))
    assert worst_ratio(prior) == pytest.approx(np.sqrt(N))
    assert worst_ratio(prior) < min(worst_ratio(t) for t in (1.0, N, 0.8 * prior, 1.25 * prior))
    assert prior_inflation(None) is None


def test_the_learner_takes_the_prior_from_its_windows():
    """Before a window closes, sqrt of the frames the open one will hold at its spacing; then
    of the frames the last one held (60 fps here: 31)."""
    truth, camera, layout = scenario("deviation", rng=np.random.default_rng(0))
    model = Tracker(camera, layout, TrackerConfig()).model
    obs = MarkerObservation(camera, layout.points, np.eye(3), np.array([0.0, 0.0, 0.6]),
                            model.pose, False)
    x = model.initial_state(np.eye(3), np.zeros(3))
    det = Detections(0.0, obs(x[None])[0].reshape(6, 2))
    learned = noise_scale.LearnedNoise()
    learned._add_frame(obs, x, np.arange(6), det, 0.0, 0.3)
    assert learned._prior_inflation() is None  # one frame: no spacing yet
    for _ in range(5):
        learned._add_frame(obs, x, np.arange(6), det, 1 / 60, 0.3)
    assert learned._prior_inflation() == pytest.approx(np.sqrt(31))
    for _ in range(30):
        learned._add_frame(obs, x, np.arange(6), det, 1 / 60, 0.3)
    assert learned.correlation.windows == 1 and learned.correlation.frames == 31
    assert learned._inflation() == pytest.approx(np.sqrt(31))  # one window: not measured yet


def _sigmas_before_the_correlation(blob_sigma: float) -> list[float]:
    """The pixel sigma the filter takes on each frame before MIN_WINDOWS windows are measured,
    on the measurement-level simulator's flexion recording with white blob noise."""
    rng = np.random.default_rng(6)
    truth, camera, layout = scenario("flexion", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(pixel_sigma=blob_sigma), rng)
    tracker = Tracker(camera, layout, TrackerConfig())
    sigmas = []
    for f in frames:
        tracker.step(f.detections)
        learned = tracker.learned_noise
        if learned.correlation.windows >= MIN_WINDOWS:
            break
        sigmas.append(learned.pixel_sigma or TrackerConfig().measurement.pixel_sigma)
    return sigmas


def test_sharp_blobs_are_trusted_more_before_their_correlation_is_known():
    """0.02 px blobs are taken at MARGIN x 2 x 0.02 px (the prior inflation, sqrt(16) = 4)
    from the first window on, and near it from the first window's EARLY_FRAMES-th frame (the
    initialisation's frame, then EARLY_FRAMES tracked: the estimate at 9 degrees of freedom,
    the filter still settling); 0.3 px blobs keep the model's sigma all along."""
    sharp = _sigmas_before_the_correlation(0.02)
    expected = MARGIN * 2 * 0.02
    assert len(sharp) > 30 and sharp[-1] == pytest.approx(expected, rel=0.2), sharp
    model = TrackerConfig().measurement.pixel_sigma
    assert sharp[0] == model  # nothing measured yet
    early = np.array(sharp[1 + EARLY_FRAMES:W])  # after the first fix, before the window closes
    assert np.all((early > 0.5 * expected) & (early < 2 * expected)), sharp
    noisy = _sigmas_before_the_correlation(0.3)
    assert len(noisy) > 30 and min(noisy) == TrackerConfig().measurement.pixel_sigma


def _run(name: str, seed: int, blob_sigma: float, adapt: bool):
    """A recording of the measurement-level simulator with white blob noise ``blob_sigma`` and
    depth twice Kinect's noise (pixels then carry more of the out-of-plane angles)."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario(name, rng=rng)
    noise = NoiseModel(pixel_sigma=blob_sigma, clutter_mean=1.0, p_miss=0.05,
                       depth_sigma_coeff=2 * NoiseModel().depth_sigma_coeff)
    frames = simulate_detections(truth, camera, layout, noise, rng)
    tracker = Tracker(camera, layout, TrackerConfig(adapt_pixel=adapt))
    results = [tracker.step(f.detections) for f in frames]
    run = score_run(name, truth, frames, results)
    assert run.errors.coverage == 1.0
    return run.errors.orientation_rmse_deg, tracker.learned_noise.pixel_sigma


def test_sharp_blobs_are_trusted_more():
    """White 0.05 px blobs: the learned sigma is MARGIN times their white-noise equivalent,
    their own 0.05 px, and the orientation is more accurate than at the model's 0.3 px."""
    fixed, _ = _run("flexion", 6, 0.05, adapt=False)
    learned, sigma = _run("flexion", 6, 0.05, adapt=True)
    assert sigma == pytest.approx(MARGIN * 0.05, rel=0.15)
    assert learned < 0.95 * fixed, (learned, fixed)


def test_blobs_as_noisy_as_the_model_keep_its_sigma():
    """White 0.3 px blobs, the model's own: the learned sigma stays at the model's (within the
    estimate's spread), and so does the accuracy."""
    fixed, _ = _run("flexion", 5, 0.3, adapt=False)
    learned, sigma = _run("flexion", 5, 0.3, adapt=True)
    assert sigma == pytest.approx(TrackerConfig().measurement.pixel_sigma, rel=0.15)
    assert learned == pytest.approx(fixed, rel=0.1)


def test_the_floor_is_below_the_model():
    assert SIGMA_FLOOR < TrackerConfig().measurement.pixel_sigma
    assert pixel_noise.TIME_CONSTANT_S > MIN_WINDOWS * WINDOW_S


def test_the_spread_grows_with_the_image_speed_as_the_frames_show():
    """Residuals drawn with variance a + b s^2 per coordinate (a long shutter's blur grows with
    the image speed s): the weighted regression gives a and b back; frames that never move
    give all of their spread to a and leave b at the prior's, and a spread that only grows with
    speed gives a = 0."""
    rng = np.random.default_rng(5)
    a, b = 0.012**2, (0.09**2 - 0.012**2) / 250.0**2  # 0.09 px at 250 px/s
    speed2 = rng.uniform(0, 300, (40, 16)) ** 2
    spread = pixel_noise.BlobSpread()
    for window in speed2:
        e = rng.normal(size=(16, 6, 2)) * np.sqrt(a + b * window)[:, None, None]
        spread.add(e, np.full(16, 12), window, 1e-3)  # 12: no fit took any; a long memory
    got_a, got_b = spread.coefficients
    assert got_a == pytest.approx(a, rel=0.3) and got_b == pytest.approx(b, rel=0.1)
    assert spread.variance == got_a
    still = pixel_noise.BlobSpread()
    still.add(rng.normal(size=(16, 6, 2)) * 0.02, np.full(16, 12), np.zeros(16), WINDOW_S)
    assert still.coefficients[1] == pytest.approx(pixel_noise.BLUR_PRIOR)
    assert np.sqrt(still.variance) == pytest.approx(0.02, rel=0.1)
    smeared = pixel_noise.BlobSpread()
    s2 = np.linspace(1e4, 9e4, 16)
    for _ in range(4):  # a few windows: the prior on b weighs as a few frames
        blur = rng.normal(size=(16, 6, 2)) * np.sqrt(1e-6 * s2)[:, None, None]
        smeared.add(blur, np.full(16, 12), s2, WINDOW_S)
    at_rest, per_speed2 = smeared.coefficients
    assert at_rest < 0.1 * 1e-6 * s2.mean() and per_speed2 == pytest.approx(1e-6, rel=0.2)
    assert pixel_noise.BlobSpread().coefficients is None


@pytest.mark.parametrize("factor", [0.0, 4.0])
def test_the_frames_take_the_blur_over_from_its_prior(factor):
    """A first movement meets a long shutter's blur (the prior) before any frame has moved; once
    a few windows of moving frames are in, what they show wins: a sharp camera's blobs (no
    growth with speed) take b well below the prior, a longer blur's 4x the prior take it to
    within a fifth of theirs."""
    rng = np.random.default_rng(11)
    a, b = 0.02**2, factor * pixel_noise.BLUR_PRIOR
    spread = pixel_noise.BlobSpread()
    still = rng.normal(size=(16, 6, 2)) * np.sqrt(a)
    spread.add(still, np.full(16, 12), np.zeros(16), WINDOW_S)
    assert spread.coefficients[1] == pytest.approx(pixel_noise.BLUR_PRIOR)
    for _ in range(4):  # two seconds of a reach's speeds
        s2 = rng.uniform(0, 400, 16) ** 2
        e = rng.normal(size=(16, 6, 2)) * np.sqrt(a + b * s2)[:, None, None]
        spread.add(e, np.full(16, 12), s2, WINDOW_S)
    got_b = spread.coefficients[1]
    if factor == 0.0:
        assert got_b < 0.2 * pixel_noise.BLUR_PRIOR
    else:
        assert got_b == pytest.approx(b, rel=0.2)


def test_slow_frames_leave_the_faster_speeds_to_a_long_shutter():
    """The first frames of a movement, slow enough (up to 1 px/frame at 30 fps) that a long
    shutter's fit residuals are as small as at rest, take b well below the prior; their b holds
    up to their speed, and beyond it a long shutter's blur grows at the prior's rate, as it
    would if the frames had never moved. A recording whose fast frames showed a b above the
    prior keeps its own."""
    rng = np.random.default_rng(3)
    a = 0.02**2
    spread = pixel_noise.BlobSpread()
    spread.add(rng.normal(size=(16, 6, 2)) * np.sqrt(a), np.full(16, 12), np.zeros(16), WINDOW_S)
    slow2 = np.linspace(0.0, 30.0, 16) ** 2
    for _ in range(2):
        spread.add(rng.normal(size=(16, 6, 2)) * np.sqrt(a), np.full(16, 12), slow2, WINDOW_S)
    b = spread.coefficients[1]
    assert b < 0.3 * pixel_noise.BLUR_PRIOR  # the slow frames showed no growth
    assert spread.fastest2 == pytest.approx(30.0**2)
    fast2 = 270.0**2  # 9 px/frame
    assert spread.growth(fast2) == pytest.approx(b * fast2)
    assert spread.growth(fast2, long_shutter=True) == pytest.approx(
        b * 30.0**2 + pixel_noise.BLUR_PRIOR * (fast2 - 30.0**2))
    assert spread.growth(20.0**2, long_shutter=True) == spread.growth(20.0**2)  # as learned
    blurred = pixel_noise.BlobSpread()
    s2 = np.linspace(1e4, 9e4, 16)
    for _ in range(4):
        blurred.add(rng.normal(size=(16, 6, 2)) * np.sqrt(4 * pixel_noise.BLUR_PRIOR * s2)[
            :, None, None], np.full(16, 12), s2, WINDOW_S)
    assert blurred.coefficients[1] > pixel_noise.BLUR_PRIOR
    assert blurred.growth(4 * 9e4, long_shutter=True) == pytest.approx(blurred.growth(4 * 9e4))
    assert pixel_noise.BlobSpread().growth(fast2, long_shutter=True) == 0.0  # nothing learned


def test_the_blur_share_is_taken_at_the_frames_speed_up_to_the_model():
    assert pixel_noise.motion_variance(0.0, 3.0) == 0.0  # a still frame
    assert pixel_noise.motion_variance(1e-7 * 200.0**2, 3.0) == pytest.approx(
        MARGIN**2 * 3.0 * 1e-7 * 200.0**2)
    assert pixel_noise.motion_variance(1e-7 * 200.0**2, None) == 0.0  # nothing measured yet
    obs, _ = _observation()
    obs.set_pixel_sigma(0.05)
    learned = noise_scale.LearnedNoise()
    s2 = np.linspace(0, 1e6, 16)  # residuals of 0.01 px at rest, growing with the speed
    learned.spread.add(np.ones((16, 6, 2)) * np.sqrt(1e-4 + 1e-9 * s2)[:, None, None],
                       np.full(16, 12), s2, 0.5)
    learned.correlation.frames = 16  # the prior, sqrt(16), until measured
    learned.speed2 = 1e8  # far beyond what the model's sigma allows
    learned.apply(obs)
    assert obs.motion_variance == pytest.approx(0.3**2 - 0.05**2)
    np.testing.assert_allclose(obs.blob_variance(np.array([False, True]), 2),
                               [obs.motion_variance, obs.motion_variance + obs.suspect_variance])


@pytest.mark.parametrize("motion", ["slide across", "turn about the line of sight"])
def test_the_image_speed_from_the_state_matches_the_markers_projected_motion(motion):
    """The markers' mean squared image speed, by projecting them a millisecond apart (hand at
    0.6 m facing the camera, its origin on the optical axis), against image_speed2 from the
    velocities alone: exact for a slide across the line of sight and for a turn about it."""
    obs, _ = _observation()
    camera, layout = obs.camera, obs.layout_T.T
    v, w = (np.array([0.12, -0.05, 0.0]), np.zeros(3)) if motion == "slide across" \
        else (np.zeros(3), np.array([0.0, 0.0, 2.5]))
    t, dt = np.array([0.0, 0.0, 0.6]), 1e-3
    before = camera.project(layout + t)
    after = camera.project(layout @ Rotation.from_rotvec(w * dt).as_matrix().T + t + v * dt)
    projected = np.mean(np.sum((after - before) ** 2, axis=1)) / dt**2
    assert obs.layout_r2 == pytest.approx(np.mean(np.sum(layout**2, axis=1)))
    assert pixel_noise.image_speed2(v, w, 0.6, camera.fx, obs.layout_r2) == pytest.approx(
        projected, rel=0.02)
    assert pixel_noise.image_speed2(v, np.full(3, np.nan), 0.6, camera.fx, obs.layout_r2) == 0.0
