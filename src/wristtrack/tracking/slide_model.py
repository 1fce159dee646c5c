"""The default motion model with the skin's slide over the knuckles in the state.

The MCP markers ride on skin that slides over the metacarpal heads as the fingers flex (about
3 mm distally at 90 deg: tracking/observation.py). Taken as noise the four markers share, afresh
each frame, its pattern (the MCPs moving together against WRIST and CMC1) is also what a tilt of
the hand does to them. A hand seen face-on tells the two apart in one frame; turned edge-on, at
the extremes of a movement where the range of motion is read, it hardly can, and the update took
part of the slide as a rotation. With exact blob centres, the rendered right hands making the
left hand's movement came out at 0.98 deg range-of-motion error with the rendered slide and
0.64 without it.

The slide follows the fingers, which move over a second or two, so the frames before tell it.
``SlidingSkinModel`` carries it in the state, hand-frame coordinates after the constant-rate
model's (distal X and lateral Y: ``STATE_SLIDE_AXES``; the palmar slide stays noise the markers
share, tracking/observation.py), as a Gauss-Markov (Ornstein-Uhlenbeck) process about no
slide: its stationary sigmas the measurement model's ``skin_slide`` times ``slide_scale`` (the
recording's, learned as the track goes: tracking/noise_scale.py), its correlation time
``TIME_CONSTANT_S``. The observation moves the MCP markers by it (``MarkerObservation``'s
``slide_of``); the update then tells pose and slide apart with the help of their history, and
the smoother with the frames after too.
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.tracking.models import ConstantRateModel, ProcessNoise
from wristtrack.tracking.observation import SKIN_SLIDE_SIGMA, STATE_SLIDE_AXES

# The slide's correlation time (s). Over a frame at 30 fps the slide's prediction spreads by
# sigma sqrt(2 dt / tau): 0.12 mm for the 1.5 mm distal sigma, above the renderer's fastest
# slide (2.2 mm/s: 2.3 mm over half a 3.3 s flexion cycle), and a slide held still is kept for
# several seconds. 3 s forgot it too soon (range of motion 1.78 against 1.58 deg on the rendered
# right hands making the left hand's movement); 30 s did as well as 10 on them.
TIME_CONSTANT_S = 10.0
# A fresh fit takes the markers where the layout puts them: the slide starts at this share of
# its stationary sigmas, and reaches them over TIME_CONSTANT_S. Started at its full spread, the
# slide cost the rigid rendered hands (clean) 0.148 -> 0.165 deg in their first second.
INITIAL_SHARE = 0.1


_AXES = len(STATE_SLIDE_AXES)


class SlidingSkinModel(ConstantRateModel):
    """State x = [R (9), p, v, w, s (2)]; tangent [dphi, dp, dv, dw, ds] (14): the
    constant-rate model and the MCP markers' common skin slide ``s`` along the hand's
    STATE_SLIDE_AXES (distal, lateral; m). Noise (8) = (linear acceleration, angular
    acceleration, the slide's innovation)."""

    dim = 12 + _AXES
    noise_dim = 6 + _AXES
    slide = slice(12, 12 + _AXES)  # tangent coordinates of the slide (m)
    name = "default"

    def __init__(self, noise: ProcessNoise | None = None,
                 slide_sigma: tuple[float, float, float] = SKIN_SLIDE_SIGMA,
                 time_constant: float = TIME_CONSTANT_S):
        super().__init__(ProcessNoise() if noise is None else noise)
        self.slide_sigma = np.asarray(slide_sigma, dtype=float)  # (3,) hand X, Y, Z
        self.time_constant = time_constant
        self.slide_scale = 1.0  # the recording's slide against the model's, on the variance

    @property
    def stationary_variance(self) -> np.ndarray:
        """The slide's stationary variances (m^2) along the axes the state carries."""
        return self.slide_scale * self.slide_sigma[list(STATE_SLIDE_AXES)] ** 2

    @staticmethod
    def initial_state(R: np.ndarray, p: np.ndarray, v=None, w=None, s=None) -> np.ndarray:
        base = ConstantRateModel.initial_state(R, p, v, w)
        return np.concatenate((base, np.zeros(_AXES) if s is None else s))

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        out = np.empty_like(X)
        out[:, :18] = super().propagate(X[:, :18], noise[:, :6], dt)
        s = slice(18, 18 + _AXES)
        out[:, s] = math.exp(-dt / self.time_constant) * X[:, s] + noise[:, 6:6 + _AXES]
        return out

    def process_noise(self, dt: float) -> np.ndarray:
        Q = np.zeros((self.noise_dim, self.noise_dim))
        Q[:6, :6] = super().process_noise(dt)
        keep = math.exp(-dt / self.time_constant)
        Q[6:6 + _AXES, 6:6 + _AXES] = np.diag(self.stationary_variance * (1.0 - keep * keep))
        return Q

    @staticmethod
    def skin_slide(X: np.ndarray) -> np.ndarray:
        """(S, 3) the slide (hand frame X, Y, Z) of states X (S, 18 + axes), zero along the
        axes the state does not carry."""
        out = np.zeros((X.shape[0], 3))
        out[:, list(STATE_SLIDE_AXES)] = X[:, 18:18 + _AXES]
        return out

    def initial_covariance(self, pose_cov: np.ndarray, v_sigma: float = 0.05,
                           w_sigma: float = 0.3) -> np.ndarray:
        """Covariance over the tangent from a (6,6) pose covariance; the slide at
        INITIAL_SHARE of its stationary sigmas."""
        P = np.zeros((self.dim, self.dim))
        P[:12, :12] = super().initial_covariance(pose_cov, v_sigma, w_sigma)
        P[self.slide, self.slide] = np.diag(self.stationary_variance) * INITIAL_SHARE**2
        return P
