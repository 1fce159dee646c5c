"""How much the skin over the knuckles slides in this recording, estimated as it goes.

``MeasurementNoise.skin_slide`` is the spread of the MCP markers' common slide over the
metacarpal heads when the fingers flex (tracking/observation.py). A hand whose fingers stay
still has none, and then the modelled slide costs accuracy: its pattern, the four MCP markers
shifted together along the hand, is also what a flexion tilt does to their pixels, so the filter
discounts the pixels' evidence about that tilt. On the rendered recordings without finger
movement the fixed model cost 0.30 against 0.28 deg (clean), 0.61 against 0.56 (structured-light
depth) and 0.77 against 0.63 on colour alone, where per-frame PnP, which models no slide, had
beaten the filter (docs/BENCHMARKS.md).

So the slide's covariance is scaled by a factor (on the variance) estimated from the recording:
variance-component estimation. For an innovation nu ~ N(0, S), S = A + lambda B with B the
modelled slide's share, the likelihood is stationary in lambda where
nu^T S^-1 B S^-1 nu = tr(S^-1 B); the fixed-point step

    lambda <- lambda * sum_t nu^T S^-1 B S^-1 nu / sum_t tr(S^-1 B)

climbs it (the EM step for a variance component). The sums forget old frames (time constant
``TIME_CONSTANT_S``), so the factor follows fingers that start or stop moving. Both terms are
computed from the update's posterior, which the tracker keeps (the compiled step returns nothing
else): with R the measurement noise, e = y - h(x+) the posterior residual and P+ the posterior,
S^-1 nu = R^-1 e and S^-1 = R^-1 - R^-1 H P+ H^T R^-1 (Woodbury), exact for a linear update.
(The posterior is the frame's, after the skin's depth update too: a little tighter than the
markers' alone, which lowers the factor a little.)

The slide moves slowly, so the prior has already followed part of it and the estimate comes out
below the slide's white-noise equivalent (0.55-0.8 of the model's sigma on the rendered
soft-tissue recordings, whose slide is the model's): 0.34 deg there, 0.33 with the model's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from wristtrack.filter import ukf
from wristtrack.tracking.observation import stacked_rows

# Memory of the estimate: the fingers' slide changes over a flexion cycle of a few seconds.
TIME_CONSTANT_S = 2.0
# The model's own sigma counts as this much evidence (a frame gives tr(S^-1 B) of up to ~3).
PRIOR_WEIGHT = 3.0
# Guard rails on the slide's sigma, as a factor on the model's: a tenth (no slide is ever
# ruled out) to twice it.
SD_FACTOR_RANGE = (0.1, 2.0)
MIN_MARKERS = 4  # fewer labelled markers hardly separate a slide from the pose
# Frames scored: at most one per this interval. Scoring costs about ten compiled tracker steps
# (an unscented transform and the noise model in NumPy), and the slide changes over a flexion
# cycle of seconds, not from frame to frame.
SCORE_INTERVAL_S = 0.25


def slide_scores(
    residual: np.ndarray, R: np.ndarray, HPH: np.ndarray, B: np.ndarray
) -> tuple[float, float]:
    """(nu^T S^-1 B S^-1 nu, tr(S^-1 B)) of one update from its posterior: ``residual`` (m,)
    y - h(x+), ``R`` (m, m) the measurement noise it was updated with, ``HPH`` (m, m) the
    posterior's spread in the measurements (H P+ H^T), ``B`` (m, m) the slide's covariance."""
    Ri = np.linalg.inv(R)
    a = Ri @ residual
    RiB = Ri @ B
    return float(a @ B @ a), float(np.trace(RiB) - np.sum((Ri @ HPH) * RiB.T))


def frame_scores(model, obs, x: np.ndarray, P: np.ndarray, labels: np.ndarray, det,
                 params: ukf.UKFParams, factor: float) -> tuple[float, float] | None:
    """``slide_scores`` of a frame's markers update: the posterior (x, P) of state model
    ``model``, the MarkerObservation ``obs`` it used (its slide at ``factor`` times the model's
    variance), the blobs ``det`` labelled ``labels``. B is the slide's covariance at the model's
    sigma. None where the frame cannot tell: no slide modelled, fewer than MIN_MARKERS markers,
    a marker given several blobs (the paper's association)."""
    taken = labels[labels >= 0]
    if (not obs.slide_base.any() or np.unique(taken).size != taken.size
            or taken.size < MIN_MARKERS):
        return None
    z = det.uv if obs.k == 2 else np.column_stack((det.uv, det.depth))
    rows, values = stacked_rows(labels, z, obs.k)
    pred = ukf.predict_measurement(model, x, P, obs, params)
    y_hat = obs(x[None])[0]
    R = obs.noise_covariance(x, y_hat)[np.ix_(rows, rows)]
    G = obs.slide_jacobian(x)[rows]
    try:
        return slide_scores(values - y_hat[rows], R, pred.Pyy[np.ix_(rows, rows)],
                            G @ G.T / factor)
    except np.linalg.LinAlgError:
        return None


@dataclass
class SlideScale:
    """The variance factor on the modelled skin slide, learned as the track goes (module doc).
    ``sd_factor`` scales the slide's sigmas."""

    time_constant: float = TIME_CONSTANT_S
    interval: float = SCORE_INTERVAL_S
    factor: float = 1.0
    _num: float = field(default=PRIOR_WEIGHT)
    _den: float = field(default=PRIOR_WEIGHT)
    _since: float = math.inf  # s since the last frame scored

    @property
    def sd_factor(self) -> float:
        return math.sqrt(self.factor)

    def due(self, dt: float) -> bool:
        """Whether the frame ``dt`` after the last one is to be scored."""
        self._since += max(dt, 0.0)
        return self._since >= self.interval

    def update(self, scores: tuple[float, float] | None) -> bool:
        """Fold in one scored frame's scores (at the model's sigma); whether they were taken
        (None, non-finite or uninformative scores are not, and the frame stays due)."""
        if scores is None or not (np.isfinite(scores).all() and scores[1] > 0):
            return False
        keep = math.exp(-self._since / self.time_constant) if math.isfinite(self._since) else 1.0
        self._since = 0.0
        # the fixed point of lambda * num / den, each frame's numerator taken at its lambda
        self._num = keep * self._num + self.factor * scores[0]
        self._den = keep * self._den + scores[1]
        lo, hi = (f * f for f in SD_FACTOR_RANGE)
        self.factor = min(max(self._num / self._den, lo), hi)
        return True
