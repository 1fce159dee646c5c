"""The markers' noise learned from the recording (tracking/noise_scale.py): the variance components'
scores from the posterior against the innovation form on a linear-Gaussian update, their fixed
point against the variance the innovations were drawn with, and the tracker on markers that slide
and that do not (the pixel noise's own use: test_pixel_noise.py)."""

from __future__ import annotations

import numpy as np
import pytest

from wristtrack.hand import HandLayout
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.sim.scenario_run import score_run
from wristtrack.tracking import noise_scale
from wristtrack.tracking.noise_scale import (
    SD_FACTOR_RANGE,
    LearnedNoise,
    VarianceFactor,
    component_scores,
)
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.tracker import Tracker, TrackerConfig

from .test_skin_slide import _sliding_skin_frames


def _spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(n, n))
    return scale * (a @ a.T / n + 0.1 * np.eye(n))


def test_posterior_scores_equal_the_innovation_form():
    """A linear update: nu^T S^-1 B S^-1 nu and tr(S^-1 B) computed from the innovation and S
    directly equal component_scores of the posterior residual, R and H P+ H^T."""
    rng = np.random.default_rng(0)
    n, m = 6, 10
    P0, H = _spd(rng, n), rng.normal(size=(m, n))
    G = rng.normal(size=(m, 3))
    B = G @ G.T
    R = _spd(rng, m, 0.5) + 0.3 * B
    nu = rng.multivariate_normal(np.zeros(m), H @ P0 @ H.T + R)
    S = H @ P0 @ H.T + R
    K = P0 @ H.T @ np.linalg.inv(S)
    x_post = K @ nu
    P_post = (np.eye(n) - K @ H) @ P0
    residual = nu - H @ x_post
    Si = np.linalg.inv(S)
    num, den = component_scores(residual, R, H @ P_post @ H.T, B)
    assert num == pytest.approx(nu @ Si @ B @ Si @ nu, rel=1e-9)
    assert den == pytest.approx(np.trace(Si @ B), rel=1e-9)


@pytest.mark.parametrize("true_factor", [0.3, 1.5, 0.0])
def test_the_factor_settles_where_the_innovations_were_drawn(true_factor):
    """Innovations drawn from N(0, A + f B): scored at the current factor, the factor settles at
    f (within sampling error; a long memory here), or at its floor when there is no slide."""
    rng = np.random.default_rng(1)
    m = 12
    A = _spd(rng, m, 0.2)
    G = rng.normal(size=(m, 3)) * 0.8
    B = G @ G.T
    L = np.linalg.cholesky(A + true_factor * B)
    scale = VarianceFactor(time_constant=200.0)
    for _ in range(6000):
        nu = L @ rng.normal(size=m)
        Si = np.linalg.inv(A + scale.factor * B)
        scale.update((float(nu @ Si @ B @ Si @ nu), float(np.trace(Si @ B))), 0.3)
    expected = max(true_factor, SD_FACTOR_RANGE[0] ** 2)
    assert scale.factor == pytest.approx(expected, rel=0.1, abs=0.003)


def test_a_slide_that_starts_is_taken_up_from_the_floor():
    """Fingers still, then moving: innovations without the slide run the factor down to below a
    thirtieth of the slide's sigma (a thousandth of its variance) in 20 s; drawn with the full
    slide after that, the factor is back at half of it within 6 s of scored
    frames (0.25 s apart), at the module's memory."""
    rng = np.random.default_rng(2)
    m = 12
    A = _spd(rng, m, 0.2)
    G = rng.normal(size=(m, 3)) * 0.8
    B = G @ G.T
    scale = VarianceFactor()

    def update(L: np.ndarray) -> None:
        nu = L @ rng.normal(size=m)
        Si = np.linalg.inv(A + scale.factor * B)
        scale.update((float(nu @ Si @ B @ Si @ nu), float(np.trace(Si @ B))), 0.25)

    still = np.linalg.cholesky(A)
    for _ in range(240):
        update(still)
    assert scale.factor < 1e-3
    moving = np.linalg.cholesky(A + B)
    updates = 0
    while scale.factor < 0.5:
        update(moving)
        updates += 1
        assert updates * 0.25 <= 10.0, f"factor {scale.factor:.4f} after {updates} updates"


def test_scores_that_say_nothing_change_nothing():
    scale = VarianceFactor()
    assert not scale.update(None, 0.3)
    assert not scale.update((np.nan, 1.0), 0.3)
    assert not scale.update((0.5, 0.0), 0.3)
    assert scale.factor == 1.0


def test_frames_are_scored_at_most_once_an_interval(monkeypatch):
    """LearnedNoise scores its first frame, then the first one SCORE_INTERVAL_S after it."""
    scored, now = [], [0]

    def scores(*_):
        scored.append(now[0])
        return 3.0, 1.0

    monkeypatch.setattr(noise_scale, "slide_scores", scores)
    learned = LearnedNoise()
    for frame in range(17):
        now[0] = frame
        learned.follow(None, None, None, None, None, None, 1 / 30, None, MeasurementNoise(),
                       slide=True, pixel=False)
    assert scored == [0, 8, 16]  # 8 frames of 1/30 s: 0.267 s


def _rigid_frames(name: str, seed: int):
    """Rigid markers, blobs as sharp as the renderer's (0.05 px: 0.04 px measured on its clean
    recordings), where the pixels' evidence is worth keeping."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario(name, rng=rng)
    return truth, camera, layout, simulate_detections(
        truth, camera, layout, NoiseModel(pixel_sigma=0.05, clutter_mean=1.0, p_miss=0.05), rng)


def _run(truth, camera, layout: HandLayout, frames, name: str, adapt: bool, depth: bool,
         follow_slide: bool = True):
    tracker = Tracker(camera, layout, TrackerConfig(adapt_slide=adapt, adapt_pixel=False,
                                                    use_depth=depth, follow_slide=follow_slide))
    results = [tracker.step(f.detections) for f in frames]
    run = score_run(name, truth, frames, results)
    assert run.errors.coverage == 1.0
    return run.errors.orientation_rmse_deg, tracker.learned_noise.slide.sd_factor


@pytest.mark.parametrize("depth", [True, False], ids=["depth", "colour-only"])
@pytest.mark.parametrize(("follow_slide", "gain"), [(False, 0.93), (True, 0.97)],
                         ids=["slide-as-noise", "slide-in-state"])
def test_a_hand_whose_skin_does_not_slide_is_tracked_without_one(depth, follow_slide, gain):
    """Rigid markers: the learned slide falls to its floor, and the orientation is more accurate
    than with the model's slide kept throughout. Taken as noise afresh each frame, the slide's
    pattern discounts the pixels' evidence about a flexion tilt: 10-17 % here. Carried in the
    state (the default), the slide moves slowly and costs rigid hands less: 5 % here."""
    truth, camera, layout, frames = _rigid_frames("flexion", 2)
    fixed, _ = _run(truth, camera, layout, frames, "flexion", False, depth, follow_slide)
    adapted, sd = _run(truth, camera, layout, frames, "flexion", True, depth, follow_slide)
    assert sd < 0.2
    assert adapted < gain * fixed, (adapted, fixed)


def test_a_hand_whose_skin_slides_keeps_its_slide():
    """The renderer's soft-tissue slide (up to 2.3 mm): the learned slide stays well above its
    floor, and the orientation is as accurate as with the model's slide."""
    truth, camera, layout, frames = _sliding_skin_frames("flexion", 1)
    fixed, _ = _run(truth, camera, layout, frames, "flexion", False, True)
    adapted, sd = _run(truth, camera, layout, frames, "flexion", True, True)
    assert sd > 0.3
    assert adapted < 1.1 * fixed, (adapted, fixed)
