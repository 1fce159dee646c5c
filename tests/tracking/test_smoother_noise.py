"""The smoother's angular process noise learned from a run's rates (tracking/smoother_noise.py),
against random walks of known density."""

import numpy as np
import pytest

from wristtrack.tracking.config import TrackerConfig
from wristtrack.tracking.smoother_noise import (
    FLOOR_FRACTION,
    MIN_INCREMENTS,
    REFIT_BELOW,
    keeps_refit,
    rate_noise_density,
    refits,
    smoothing_angular_accel,
)


def _random_walk(q: float, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Rates (n, 3) of a random walk of density q (rad/s^2)^2 s at irregular frame times."""
    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.02, 0.05, n - 1)  # 20-50 frames/s, jittered
    t = np.concatenate([[0.0], np.cumsum(dt)])
    steps = rng.standard_normal((n - 1, 3)) * np.sqrt(q * dt)[:, None]
    w = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)]) + [0.3, -0.1, 0.2]
    return w, t


@pytest.mark.parametrize("q", [0.05, 0.4, 3.0])
def test_the_density_of_a_random_walk_is_recovered(q):
    w, t = _random_walk(q, 20_000)
    # 60 000 squared increments: a relative standard error of sqrt(2 / 60 000) = 0.6 %
    assert rate_noise_density(w, t, np.ones(len(t), bool)) == pytest.approx(q, rel=0.03)


def test_increments_across_frames_without_an_estimate_are_left_out():
    w, t = _random_walk(0.2, 4000, seed=1)
    ok = np.ones(len(t), bool)
    ok[1000:1010] = False  # the hand lost for ten frames ...
    w[1010:] += 5.0  # ... and found turning at another rate: not a step of the walk
    w[1000:1010] = np.nan
    assert rate_noise_density(w, t, ok) == pytest.approx(0.2, rel=0.1)
    # frames with an estimate but repeated timestamps give no increment either
    t2 = t.copy()
    t2[2000] = t2[1999]
    assert rate_noise_density(w, t2, ok) == pytest.approx(0.2, rel=0.1)


def test_too_few_increments_say_nothing():
    w, t = _random_walk(0.2, MIN_INCREMENTS + 1)
    ok = np.ones(len(t), bool)
    assert rate_noise_density(w, t, ok) is not None
    ok[MIN_INCREMENTS // 2] = False  # two increments fewer
    assert rate_noise_density(w, t, ok) is None


def test_the_density_to_track_again_at_is_bounded():
    default = 2.5
    ok = np.ones(3000, bool)
    calm, t = _random_walk(0.2, 3000)
    assert smoothing_angular_accel(calm, t, ok, default) == pytest.approx(0.2, rel=0.1)
    still, _ = _random_walk(1e-4, 3000)
    assert smoothing_angular_accel(still, t, ok, default) == FLOOR_FRACTION * default
    busy, _ = _random_walk(1.1 * REFIT_BELOW * default, 3000)
    assert smoothing_angular_accel(busy, t, ok, default) is None  # not worth a second pass


def test_which_runs_are_tracked_again_and_which_refit_is_kept():
    assert refits(TrackerConfig(smoothing_noise="learned"))
    assert not refits(TrackerConfig())  # the model's noise: the default
    assert not refits(TrackerConfig.paper(smoothing_noise="learned"))  # no rates in its state
    with pytest.raises(ValueError, match="smoothing noise"):
        TrackerConfig(smoothing_noise="fitted")
    assert keeps_refit(120, 120) and keeps_refit(118, 120)
    assert not keeps_refit(120, 119)
