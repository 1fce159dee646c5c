"""The smoother's angular process noise, learned from the recording (``track --smooth
--smooth-noise learned``).

The default model's angular acceleration density (ProcessNoise.angular_accel) is set for a
filter that must follow any hand's fastest turn as it happens. Offline the whole recording is
known, and a slow, smooth movement is far calmer: on the rendered robustness recordings the
rates of a first smoothed run put the density at 0.13-0.19 (rad/s^2)^2 s against the default's
2.5, and the true rates at 0.11. Tracking again at the learned density and smoothing gave a
lower smoothed orientation RMSE on every one of 19 such recordings tried, and a lower smoothed
range-of-motion error on average (docs/BENCHMARKS.md). Real recorded motions are another
matter: a tennis toss's true rates show 1.5, a racing glove's at 0.3x speed 0.9-2.3, and the
first smoothed run's rates fell short of the toss's (0.54: the fast detail is what the first
smoothing took out), whose smoothed orientation RMSE rose 0.23 -> 0.30 deg. Hence an option,
not the default. The filter's innovation likelihood does not settle it either: over a grid of
densities it peaks near the real motions' true ones (1.5), yet their smoother does best above
10. The likelihood scores one-frame predictions, and the innovation covariance is mostly the
prediction's spread: split by row (the generic step's updates on seven rendered recordings,
clean to every effect, real motion among them), the pixel rows' predicted spread is 93-100 % of
their innovation variance and their squared innovations average 0.01-0.3 of it (marker depths
0.06-0.4, skin patches 0.1-0.5: their noise is conservative by design, MeasurementNoise). A
smoother does best where its cut-off passes the motion's fastest content still above the
measurement noise; that meets the density of the rate increments only where the acceleration
is white, and a hand's is smooth (the pixel innovations' lag-1 correlation is +0.2 to +0.8,
tennis toss aside). Leaving frames out and predicting their blobs does not find it either: on
the still start and reach under every effect the held-out blobs' residual (0.58 px rms, mostly
the skin slide and the layout) moved by under 1 % between densities 0.1 and 2.5 while the
smoothed orientation error moved by 18 %, and on the tennis toss it picked 2.5 where 25 was
best.

The estimate: with the angular rate a random walk of density q, the rate's increment over dt
has variance q dt on each axis, so q = sum |dw|^2 / (3 sum dt) over consecutive frames that
both have an estimate. The smoothed rates carry a little noise, which biases it upwards (on
the rendered recordings it came out 1.1-1.7 times the density of the true rates), and miss
the true rates' fast detail, which biases it down (the tennis toss: 0.37 times).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from wristtrack.tracking.config import TrackerConfig
    from wristtrack.tracking.results import FrameResult

# Fewer rate increments than this (about a second at 30 frames/s) say too little of the motion.
MIN_INCREMENTS = 30
# The learned density is kept at least this fraction of the default: on rendered recordings a
# tenth of what their motion shows (0.025 against 0.11-0.19) lost up to 3 % of the frames.
FLOOR_FRACTION = 0.02
# A learned density above this fraction of the default is not worth a second pass.
REFIT_BELOW = 0.8


def rate_noise_density(w: np.ndarray, t: np.ndarray, ok: np.ndarray) -> float | None:
    """The random-walk density (rad/s^2)^2 s of the angular rates ``w`` (N, 3) rad/s at times
    ``t`` (N,) s, from the increments between consecutive frames both ``ok`` (N,) with a
    positive interval; None with fewer than MIN_INCREMENTS of them."""
    w, t, ok = np.asarray(w, float), np.asarray(t, float), np.asarray(ok, bool)
    ok = ok & np.isfinite(w).all(axis=1) & np.isfinite(t)
    dt = np.diff(t)
    pair = ok[:-1] & ok[1:] & (dt > 0)
    if pair.sum() < MIN_INCREMENTS:
        return None
    dw = np.diff(w, axis=0)[pair]
    return float(np.sum(dw**2) / (3.0 * np.sum(dt[pair])))


def smoothing_angular_accel(w: np.ndarray, t: np.ndarray, ok: np.ndarray,
                            default: float) -> float | None:
    """The angular acceleration density to track again at before smoothing (rates as for
    :func:`rate_noise_density`), kept within [FLOOR_FRACTION, 1] times ``default``; None where
    the rates say too little or a second pass would change little (above REFIT_BELOW times
    ``default``)."""
    q = rate_noise_density(w, t, ok)
    if q is None or q > REFIT_BELOW * default:
        return None
    return max(q, FLOOR_FRACTION * default)


def refits(config: TrackerConfig) -> bool:
    """Whether a smoothed run of ``config`` is tracked again at the learned density: asked for
    (TrackerConfig.smoothing_noise), with a model that has rates in its state (the paper's has
    none to learn from)."""
    return config.smoothing_noise == "learned" and config.model == "default"


def results_angular_accel(results: list[FrameResult], default: float) -> float | None:
    """:func:`smoothing_angular_accel` from a smoothed run's results."""
    if not results:
        return None
    w = np.stack([np.asarray(r.w, float) for r in results])
    t = np.array([r.timestamp for r in results])
    ok = np.array([r.has_estimate for r in results])
    return smoothing_angular_accel(w, t, ok, default)


def keeps_refit(first_tracked: int, refit_tracked: int) -> bool:
    """Whether the run tracked again at the learned density replaces the first: only if it has
    an estimate in as many frames (a calmer model must not lose a fast turn the first
    followed)."""
    return refit_tracked >= first_tracked
