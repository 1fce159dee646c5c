"""The sliding-skin model with the depth map's offset from the colour image in the state too
(``track --follow-offset``; off by default, see below).

A depth map registered to the colour image by the camera's factory calibration is 1-2 px off
it (sim/realism.py; observation.REGISTRATION_PX): every depth is read that far from where the
colour image puts it. On the tilted back of a hand that is a depth error of the surface's
slope times the offset, shared by the markers and by the skin between them
(tracking/surface.py). Taken as noise drawn afresh each frame (``MeasurementNoise``'s
``registration_px``), a fixed offset became a pose error wherever the slope is steep: at the
extremes of a turned hand's movement, where the range of motion is read, and along the line of
sight everywhere (1-2 mm). The offset is a property of the camera and does not change within a
recording, so the frames before tell it.

``DepthOffsetModel`` carries it in the state after the sliding-skin model's (du, dv, px: the
depth image's pixel (u, v) shows the surface the colour image shows at (u + du, v + dv)), a
nearly static random walk from a prior of REGISTRATION_PX per axis. The observations add
slope x offset to each sigma point's depths (``observation.depth_offset_change``; the slope no
steeper than skin patches are read at), and the shared registration noise is dropped
(``observation.MarkerObservation``). The skin's planes, learned through the same offset over the
still start, are moved back onto the skin by it (``surface.DorsumSurface.offset_shift``). Left
where they were learned, they read the still start's own pose as no offset: patches alone found
about half the rendered offset, and arched hands with the markers too 1.35 and 0.40 px of the
rendered 2 (2.18 and 2.13 with the planes moved). The estimate outlives the track: a track found
again after a loss starts from it (``carry_offset``). summary.json reports the last estimate
(``registration_estimate``): a camera whose depth sits pixels off its colour image wants its
registration redone.

Measured on rendered recordings (structured-light depth 1-2 px off the colour image). Structured
light alone (3 seeds): the offset found within 0.05-0.21 px, orientation 0.248 -> 0.219 deg,
position 0.47 -> 0.23 mm; clean recordings unchanged. Every effect at once (benchmarks' spread,
10 seeds a condition, run with the offset on at 350293a): position better in four of six
conditions (preset real 0.98 -> 0.79 mm, without hand.json 1.05 -> 0.90), but the estimate is
0.5-2 px off: it takes up the depth errors of the hand itself (the skin's shape changing as the
fingers flex, the knuckles' arch under the markers), which move the depths as the offset does.
The range of motion came out no better (right hand making the left hand's movement 1.54 ->
1.56 deg, smoothed 0.86 -> 0.89) and worse on the left hands (0.95 -> 1.02, smoothed 0.56 ->
0.62), so the default leaves the offset as noise (TrackerConfig.follow_offset).
"""

from __future__ import annotations

import numpy as np

from wristtrack.tracking.observation import REGISTRATION_PX
from wristtrack.tracking.slide_model import SlidingSkinModel

# The offset's drift (px^2/s): a calibration error does not move; this keeps the filter from
# freezing it entirely over a long recording (1 px would take ~3 h to wander in).
OFFSET_DRIFT = 1e-4


class DepthOffsetModel(SlidingSkinModel):
    """State x = [R (9), p, v, w, s (2), o (2)]; tangent [dphi, dp, dv, dw, ds, do] (16): the
    sliding-skin model and the depth map's offset ``o`` from the colour image (du, dv, px).
    Noise (10) = (linear acceleration, angular acceleration, the slide's innovation, the
    offset's drift)."""

    dim = SlidingSkinModel.dim + 2
    noise_dim = SlidingSkinModel.noise_dim + 2
    offset = slice(SlidingSkinModel.dim, SlidingSkinModel.dim + 2)  # tangent coordinates (px)
    _state = slice(6 + SlidingSkinModel.dim, 8 + SlidingSkinModel.dim)  # where x holds it

    def __init__(self, *args, prior_px: float = REGISTRATION_PX,
                 drift: float = OFFSET_DRIFT, **kw):
        super().__init__(*args, **kw)
        self.prior_px = prior_px
        self.drift = drift

    @staticmethod
    def initial_state(R: np.ndarray, p: np.ndarray, v=None, w=None, s=None,
                      o=None) -> np.ndarray:
        base = SlidingSkinModel.initial_state(R, p, v, w, s)
        return np.concatenate((base, np.zeros(2) if o is None else o))

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        out = np.empty_like(X)
        k = self._state.start
        out[:, :k] = super().propagate(X[:, :k], noise[:, :-2], dt)
        out[:, k:] = X[:, k:] + noise[:, -2:]
        return out

    def process_noise(self, dt: float) -> np.ndarray:
        Q = super().process_noise(dt)  # (self.noise_dim, self.noise_dim)
        Q[-2:, -2:] = np.eye(2) * self.drift * dt
        return Q

    def depth_offset(self, X: np.ndarray) -> np.ndarray:
        """(S, 2) the offset (du, dv, px) of states X (S, D)."""
        return X[:, self._state]

    def initial_covariance(self, pose_cov: np.ndarray, v_sigma: float = 0.05,
                           w_sigma: float = 0.3) -> np.ndarray:
        """Covariance over the tangent from a (6,6) pose covariance; the offset at its prior."""
        P = super().initial_covariance(pose_cov, v_sigma, w_sigma)  # (self.dim, self.dim)
        P[self.offset, self.offset] = np.eye(2) * self.prior_px**2
        return P


def carry_offset(model, x: np.ndarray, P: np.ndarray, previous_x: np.ndarray | None,
                 previous_P: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(x, P) of a fresh fit with the offset and its variance of the track before (the camera's,
    not the track's: it survives a loss), uncorrelated with the rest. Unchanged for models
    without the offset or without a track before."""
    if previous_x is None or not isinstance(model, DepthOffsetModel):
        return x, P
    x, P = x.copy(), P.copy()
    x[model._state] = previous_x[model._state]
    P[model.offset, :] = 0.0
    P[:, model.offset] = 0.0
    P[model.offset, model.offset] = previous_P[model.offset, model.offset]
    return x, P


def registration_estimate(model, x: np.ndarray | None,
                          P: np.ndarray | None) -> dict[str, object] | None:
    """The depth map's offset from the colour image in state ``x`` (covariance ``P``) as
    summary.json reports it: ``du_px``, ``dv_px``, their standard deviations ``sd_px`` and the
    prior's (``prior_sd_px``). None where the model does not carry the offset or no track ran."""
    if x is None or P is None or not isinstance(model, DepthOffsetModel):
        return None
    du, dv = (float(c) for c in x[model._state])
    sd = np.sqrt(np.maximum(np.diag(P)[model.offset], 0.0))
    return {"du_px": du, "dv_px": dv, "sd_px": [float(s) for s in sd],
            "prior_sd_px": float(model.prior_px),
            "convention": "depth pixel (u, v) shows what colour pixel (u + du, v + dv) shows"}
