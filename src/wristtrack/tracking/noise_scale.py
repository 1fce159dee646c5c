"""How much noise this recording's markers carry, learned as it goes.

Two parts of the measurement noise differ from recording to recording, and the fixed model
costs accuracy wherever they are smaller than it says:

- the skin slide of the MCP markers (``MeasurementNoise.skin_slide``): a hand whose fingers stay
  still has none, and the modelled slide's pattern, the four MCP markers shifted together along
  the hand, is also what a flexion tilt does to their pixels, so the filter discounts the pixels'
  evidence about that tilt. On the rendered recordings without finger movement the fixed model
  cost 0.30 against 0.28 deg (clean), 0.61 against 0.56 (structured-light depth) and 0.77
  against 0.63 on colour alone, where per-frame PnP, which models no slide, had beaten the
  filter (docs/BENCHMARKS.md);
- the blobs' own pixel noise (``MeasurementNoise.pixel_sigma``), 0.3 px to cover the worst of
  blur, compression and highlights together, where sharp blobs are good to 0.015 px: measured
  on the blobs alone, each frame's scatter around its best rigid pose
  (tracking/pixel_noise.py), and gathered here (``LearnedNoise``).

The slide is scaled by a factor (on the variance) estimated from the recording:
variance-component estimation. For an innovation nu ~ N(0, S), S = A + lambda B with B the
component at its model value, the likelihood is stationary in lambda where
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

Learned as the recording goes, all of this arrives late: the first seconds were tracked at the
model's pixel noise, then at the first windows' guesses (pixel_noise.py), with a long shutter's
blur until the frames had moved, and the slide at the model's. Offline, the first seconds can
be tracked twice, so `track` primes the tracker (``LearnedNoise.carried_over``,
``Tracker.start_from``; pipeline/priming.py): a first pass over the first PRIMING_S learns the
noise and the run starts from it, on the same detections. Rendered
still start and one reach, 4 seeds each, orientation RMSE: clean 0.179 -> 0.147 deg,
1/30 s shutter 0.205 -> 0.170, structured-light depth 0.333 -> 0.270; every effect at once
level (0.554 -> 0.564), whose blobs reach the model's sigma anyway. A live camera is read once
and learns from its first frame on.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from wristtrack.filter import ukf
from wristtrack.tracking import pixel_noise
from wristtrack.tracking.merged import measurement_map
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.slide_model import SlidingSkinModel

# Memory of the estimate: the fingers' slide changes over a flexion cycle of a few seconds.
TIME_CONSTANT_S = 2.0
# The model's own value counts as this much evidence (a frame gives tr(S^-1 B) of up to ~3).
PRIOR_WEIGHT = 3.0
# Guard rails on the slide's sigma, as a factor on the model's: a hundredth to twice it. A hand
# whose fingers stay still runs the factor down (to about 0.01-0.04 of the sigma within a
# minute), and it climbs back as soon as the fingers move, about as fast as from the old floor
# of a tenth (half a full slide in 5.5-9.5 s against 4.3-6.8: test_noise_scale). That tenth kept
# 0.2 mm of slide modelled on rigid hands, and what it took from the pixels' evidence about a
# tilt cost them (rendered, 3-4 seeds, orientation RMSE): clean 0.132 -> 0.124 deg,
# structured-light depth 0.227 -> 0.201, Bayer 0.230 -> 0.224; the still start and reach
# 0.147 -> 0.137 clean, 0.270 -> 0.252 structured light; skin that slides (soft tissue alone,
# every effect at once) unchanged.
SD_FACTOR_RANGE = (0.01, 2.0)
# A slide the state carries (tracking/slide_model.py) is measured as if it were not (its
# spread against the layout, ``MarkerObservation.as_rigid``), where the prior follows part of
# it: the factor comes out at 0.55-0.8 of a slide's own sigma (this module's doc). The state's
# stationary variance is the factor over this share squared, at most the model's.
WHITE_SHARE = 0.7
MIN_MARKERS = 4  # fewer labelled markers hardly separate a slide from the pose
# Frames scored: at most one per this interval. Scoring costs about ten compiled tracker steps
# (an unscented transform and the noise model in NumPy), and the noise changes over seconds
# (a flexion cycle, the light), not from frame to frame.
SCORE_INTERVAL_S = 0.25
# Offline, a run starts from the noise an earlier pass learned over the recording's first
# PRIMING_S (pipeline/priming.py): the longest memory of what is learned, the blob errors'
# correlation's (pixel_noise.TIME_CONSTANT_S); a longer start would add little to it.
PRIMING_S = pixel_noise.TIME_CONSTANT_S


def primes(timestamp: float, first: float) -> bool:
    """Whether a frame at ``timestamp`` (s) belongs to the priming pass of a recording whose
    first frame is at ``first``: within PRIMING_S of it."""
    return timestamp - first <= PRIMING_S


def component_scores(
    residual: np.ndarray, R: np.ndarray, HPH: np.ndarray, B: np.ndarray
) -> tuple[float, float]:
    """(nu^T S^-1 B S^-1 nu, tr(S^-1 B)) of one update from its posterior:
    ``residual`` (m,) y - h(x+), ``R`` (m, m) the measurement noise it was updated with, ``HPH``
    (m, m) the posterior's spread in the measurements (H P+ H^T), ``B`` (m, m) the component's
    covariance."""
    Ri = np.linalg.inv(R)
    a = Ri @ residual
    SiB = (Ri - Ri @ HPH @ Ri) @ B
    return float(a @ B @ a), float(np.trace(SiB))


def slide_scores(model, obs, x: np.ndarray, P: np.ndarray, labels: np.ndarray, det,
                 params: ukf.UKFParams, slide_factor: float) -> tuple[float, float] | None:
    """``component_scores`` of a frame's markers update for the skin slide: the posterior
    (x, P) of state model ``model``, the MarkerObservation ``obs`` it used (its slide at
    ``slide_factor`` times the model's variance), the blobs ``det`` labelled ``labels``; B at
    the slide's model value. None where the frame cannot tell: no slide modelled, fewer than
    MIN_MARKERS markers, a marker given several blobs (the paper's association). Suspect blobs
    are left out (:func:`undoubted`)."""
    labels = undoubted(labels, det)
    taken = labels[labels >= 0]
    if isinstance(model, SlidingSkinModel):
        # The state carries the slide (tracking/slide_model.py): its spread is measured as
        # without it, against the layout, where the slide the state followed is in the
        # residuals. (Against the markers moved by it, the residuals hardly show whether the
        # state's slide moves too much or too little, and the factor stayed at 1 on rigid
        # hands.)
        obs = obs.as_rigid(model.slide_sigma * math.sqrt(slide_factor))
    if not obs.slide.any() or np.unique(taken).size != taken.size or taken.size < MIN_MARKERS:
        return None
    z = det.uv if obs.k == 2 else np.column_stack((det.uv, det.depth))
    A, values, _, _ = measurement_map(labels, z, obs.k, obs.n_markers)
    pred = ukf.predict_measurement(model, x, P, obs, params)
    y_hat = obs(x[None])[0]
    R = A @ obs.noise_covariance(x, y_hat) @ A.T
    residual, HPH = values - A @ y_hat, A @ pred.Pyy @ A.T
    G = A @ obs.slide_jacobian(x)
    try:
        return component_scores(residual, R, HPH, G @ G.T / slide_factor)
    except np.linalg.LinAlgError:
        return None


def undoubted(labels: np.ndarray, det) -> np.ndarray:
    """``labels`` with the suspect blobs of ``det`` (Detections) as clutter: they are taken at
    the model's pixel sigma whatever is learned (MarkerObservation.suspect_variance), and the
    noise is learned from the blobs it is taken for."""
    return labels if det.suspect is None else np.where(det.suspect, -1, labels)


@dataclass
class VarianceFactor:
    """A variance component's factor on its model value, learned as the track goes (module
    doc). ``sd_factor`` scales the component's sigmas; ``factor_range`` bounds the factor."""

    time_constant: float = TIME_CONSTANT_S
    factor_range: tuple[float, float] = tuple(f * f for f in SD_FACTOR_RANGE)
    prior_weight: float = PRIOR_WEIGHT
    factor: float = 1.0
    _num: float = field(init=False)  # the forgetting sums whose ratio is the factor
    _den: float = field(init=False)
    _since: float = math.inf  # s since the last scores taken

    def __post_init__(self) -> None:
        self._num = self._den = self.prior_weight

    @property
    def sd_factor(self) -> float:
        return math.sqrt(self.factor)

    def update(self, scores: tuple[float, float] | None, elapsed: float) -> bool:
        """Fold in one scored frame's ``component_scores`` (B at the model value), ``elapsed`` s
        after the previous frame scored; whether they were taken (None, non-finite or
        uninformative scores are not): the fixed point of lambda * num / den, each frame's at
        its lambda."""
        self._since += max(elapsed, 0.0)
        if scores is None or not (np.isfinite(scores).all() and scores[1] > 0):
            return False
        keep = math.exp(-self._since / self.time_constant) if math.isfinite(self._since) else 1.0
        self._since = 0.0
        num, den = scores
        self._num = keep * self._num + self.factor * num
        self._den = keep * self._den + den
        lo, hi = self.factor_range
        self.factor = min(max(self._num / self._den, lo), hi)
        return True


@dataclass
class LearnedNoise:
    """What the tracker learns of its markers' noise: the skin slide's factor and the blobs'
    pixel sigma (module doc; tracking/pixel_noise.py)."""

    slide: VarianceFactor = field(default_factory=VarianceFactor)
    spread: pixel_noise.BlobSpread = field(default_factory=pixel_noise.BlobSpread)
    correlation: pixel_noise.BlobCorrelation = field(default_factory=pixel_noise.BlobCorrelation)
    pixel_sigma: float | None = None  # what the filter takes (None: the model's)
    interval: float = SCORE_INTERVAL_S
    _since: float = math.inf  # s since the last frame scored
    speed2: float = 0.0  # the markers' squared image speed at the last frame, (px/s)^2
    # the open window of frames for the blob errors: (x, each marker's blob, uv, speed2) each,
    # the observation they were tracked with and the time they span
    _window: list = field(default_factory=list)
    _window_obs: object = None
    _window_span: float = 0.0

    def follow(self, model, obs, x: np.ndarray, P: np.ndarray, labels: np.ndarray, det,
               dt: float, params: ukf.UKFParams, noise: MeasurementNoise, slide: bool,
               pixel: bool) -> bool:
        """Learn from one tracked frame (posterior x, P; MarkerObservation ``obs``; the blobs
        ``det`` labelled ``labels``, ``dt`` after the last frame) with the model's ``noise``,
        learning the slide and/or the pixel sigma; whether what the filter should take
        changed. Suspect blobs are left out (:func:`undoubted`)."""
        changed = False
        if pixel:
            v, w = model.velocities(x)
            z = obs.R_c0[2] @ model.pose(x[None])[1][0] + obs.t_c0[2]
            self.speed2 = pixel_noise.image_speed2(v, w, z, obs.camera.fx, obs.layout_r2)
            changed = self._add_frame(obs, x, labels, det, dt, noise.pixel_sigma)
            obs.motion_variance = self._blur_variance(obs)  # this frame's, for the next update
        self._since += max(dt, 0.0)
        if self._since < self.interval or not slide:
            return changed
        scores = slide_scores(model, obs, x, P, labels, det, params, self.slide.factor)
        if scores is None:
            return changed  # the frame stays due
        elapsed, self._since = self._since, 0.0
        taken = self.slide.update(scores, elapsed)
        if taken:
            self.scale_model(model)
        return taken or changed

    def scale_model(self, model) -> None:
        """Give a state model that carries the slide (SlidingSkinModel) the slide's factor
        learned so far: its process noise from now on."""
        if isinstance(model, SlidingSkinModel):
            model.slide_scale = min(1.0, self.slide.factor / WHITE_SHARE**2)

    def carried_over(self) -> LearnedNoise:
        """What was learned, for another pass over the same recording to start from
        (PRIMING_S): the slide's factor, the blobs' spread and correlation, the sigma taken. Not
        the open window of frames, nor the last frame's speed: they belong to the frames they
        came from."""
        learned = copy.deepcopy(self)
        learned._window, learned._window_obs, learned._window_span = [], None, 0.0
        learned._since, learned.speed2 = math.inf, 0.0
        learned.slide._since = math.inf
        return learned

    def describe(self, noise: MeasurementNoise) -> dict[str, float | None]:
        """What was learned against the model's ``noise``, for summary.json: the pixel sigma
        the filter took last and the model's, the blob errors' rms per frame at rest and its
        growth with the image speed (px per px/s), their inflation by their correlation in time
        (None: not measured), the skin slide's sigma as a factor on the model's."""
        a, b = self.spread.coefficients or (None, None)
        return {
            "pixel_sigma_px": self.pixel_sigma or noise.pixel_sigma,
            "pixel_sigma_model_px": noise.pixel_sigma,
            "blob_error_px": None if a is None else math.sqrt(a),
            "blob_blur_px_per_px_s": None if b is None else math.sqrt(b),
            "blob_error_inflation": self.correlation.inflation,
            "skin_slide_sd_factor": self.slide.sd_factor,
        }

    def apply(self, obs) -> None:
        """Give the MarkerObservation ``obs`` the slide and the pixel sigma learned so far, and
        the blur's share at the last frame's speed (up to the model's sigma)."""
        obs.scale_slide(self.slide.sd_factor)
        if self.pixel_sigma is not None:
            obs.set_pixel_sigma(self.pixel_sigma)
        obs.motion_variance = self._blur_variance(obs)

    def long_shutter_variance(self, obs) -> float | None:
        """The pixel variance the blur adds at the last frame's image speed if beyond the
        speeds the blobs' spread was learned at it is a long shutter's
        (pixel_noise.BlobSpread.growth), up to the model's sigma for ``obs``; None where that
        is no more than ``obs`` takes."""
        variance = self._blur_variance(obs, long_shutter=True)
        return variance if variance > obs.motion_variance else None

    def _blur_variance(self, obs, long_shutter: bool = False) -> float:
        """The pixel variance the blur adds at the last frame's image speed (pixel_noise.
        motion_variance), up to the model's sigma for ``obs``."""
        if not self.speed2:
            return 0.0
        growth = self.spread.growth(self.speed2, long_shutter)
        return min(pixel_noise.motion_variance(growth, self._inflation()), obs.suspect_variance)

    def _inflation(self) -> float | None:
        """The correlation's inflation as measured, or until it is, the prior's
        (pixel_noise.prior_inflation)."""
        measured = self.correlation.inflation
        return measured if measured is not None else self._prior_inflation()

    def _prior_inflation(self) -> float | None:
        """pixel_noise.prior_inflation of the frames a window holds (:meth:`_window_frames`)."""
        return pixel_noise.prior_inflation(self._window_frames())

    def _window_frames(self) -> float | None:
        """The frames a window holds (the inflation of errors constant over it,
        pixel_noise.worst_inflation): the frames the last window held, or before one closed,
        the frames the open one will hold at its spacing so far (None before it has two
        frames)."""
        if self.correlation.frames:
            return float(self.correlation.frames)
        if len(self._window) < 2:
            return None
        return pixel_noise.worst_inflation(self._window_span / (len(self._window) - 1))

    def _add_frame(self, obs, x: np.ndarray, labels: np.ndarray, det, dt: float,
                   model_sigma: float) -> bool:
        """Keep one frame for the blob errors; measure the window once it spans WINDOW_S and
        take the sigma it gives (whether it changed). A new observation (W0 or the layout
        changed) starts a new window. Until the first window is measured, the open one's frames
        so far give a provisional sigma (pixel_noise.EARLY_FRAMES)."""
        if obs is not self._window_obs:
            self._window, self._window_obs = [], obs
        self._window_span = self._window_span + max(dt, 0.0) if self._window else 0.0
        labels = undoubted(labels, det)
        blob_of = np.full(obs.n_markers, -1)
        blobs = np.flatnonzero(labels >= 0)
        blob_of[labels[blobs]] = blobs
        self._window.append((x, blob_of, det.uv, self.speed2))
        if not pixel_noise.window_full(self._window_span):
            if self.spread.variance is None and len(self._window) >= pixel_noise.EARLY_FRAMES:
                residuals, dof = self._window_residuals(obs)
                return self._take_sigma(pixel_noise.filter_sigma(
                    model_sigma, pixel_noise.frame_variance(residuals, dof),
                    self._prior_inflation()))
            return False
        residuals, dof = self._window_residuals(obs)
        speed2 = np.array([frame[3] for frame in self._window])
        self.spread.add(residuals, dof, speed2, self._window_span)
        self.correlation.add(residuals, self._window_span)
        self._window = []
        return self._take_sigma(pixel_noise.filter_sigma(model_sigma, self.spread.variance,
                                                         self._inflation()))

    def _window_residuals(self, obs) -> tuple[np.ndarray, np.ndarray]:
        """The open window's blob residuals and degrees of freedom (pixel_noise.fit_residuals),
        its frames in one batch (~2 ms per half second), not frame by frame."""
        X = np.stack([frame[0] for frame in self._window])
        uv = np.zeros((len(X), max(1, max(len(f[2]) for f in self._window)), 2))
        for i, frame in enumerate(self._window):
            uv[i, :len(frame[2])] = frame[2]
        return pixel_noise.fit_residuals(
            obs, X, np.stack([frame[1] for frame in self._window]), uv)

    def _take_sigma(self, sigma: float) -> bool:
        """Take ``sigma`` (px) as the filter's pixel sigma; whether it changed."""
        changed, self.pixel_sigma = sigma != self.pixel_sigma, sigma
        return changed
