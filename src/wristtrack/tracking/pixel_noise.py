"""The pixel noise the filter takes for this recording's blobs.

``MeasurementNoise.pixel_sigma``, 0.3 px, covers the worst of blur, compression and highlights
together; sharp blobs are good to 0.015 px (detect/blobs.py), and the filter that takes them
at 0.3 px leaves most of what their pixels say about the out-of-plane angles to depth.

The blobs' errors are measured frame by frame, on the blobs alone: each tracked frame's
labelled blobs against the markers at the filter's pose, less the rigid motion and the common
skin slide of the MCP markers that fit them best (:func:`fit_residuals`, linearised at the
pose; 2n - 9 degrees of freedom for n markers, 2n - 6 without the slide). What is left is the
blobs' own scatter around one rigid hand: on the rendered recordings (3 seeds) 0.012 px rms
against 0.015 from the truth (clean, structured light), 0.033 against 0.035 (Bayer), 0.095-0.146
against 0.108-0.115 (H.264); less under JPEG (0.045-0.050 against 0.058-0.061), whose blocks
shift all blobs alike, a shift the pose takes and the orientation hardly feels. The filter's
posterior residuals, which this replaced, also hold its own lag: on colour alone they kept the
learned sigma at the model's 0.3 px, and the lag that caused kept them there (0.35 deg, where
0.05 px gave 0.20).

The blob errors are correlated in time (the pixel grid, the codec's blocks and the blur change
slowly while the hand moves slowly): over half a second they do not average away, where most of
the depth's do (its errors less the colour-depth offset are nearly fresh each frame: an
inflation of 1.2 on the clean and structured-light renders, docs/BENCHMARKS.md). Taken at one
frame's scatter, the pixels would pull the pose towards their common error. (Not because the
filter remembers them: it forgets a blob's error within about two frames; one frame's error
moves the pose by 0.13-0.37 of itself the next frame and by nothing after, on the rendered
recordings. Capping the inflation at those two frames took the every-effect recordings 0.555 ->
0.504 deg, but a still hand's constant blob errors then pulled the pose: the clean reach 0.179
-> 0.195, its still end 0.15 -> 0.22.) So the sigma is the white-noise equivalent over
WINDOW_S: the per-frame variance (``BlobSpread``) times the inflation that windows of the
residuals show, (sum_w e)^2 / sum_w e^2 (1 for white noise, the number of frames for a
constant; ``BlobCorrelation``: 2.2-8.9 on the rendered recordings, 2.6-5.7 from the truth),
times MARGIN. Before the first window closes, its frames so far (from EARLY_FRAMES on) give the
per-frame variance (:func:`frame_variance`): the model's 0.3 px over the first half second had
left the still start's out-of-plane angles to the depth (structured light, 3 seeds: 0.308 ->
0.285 deg; clean 0.169 -> 0.162), and on colour alone the filter's first turns to the pixels'
mirror image (the rgb_only movement in 2 s: 5.2 -> 3.4 deg without the refit, 3.4 -> 2.6 with
it). The noisier blobs of every effect at once reach the model's sigma anyway. Offline, a run
starts from what a first pass over the recording's first seconds learned
(noise_scale.PRIMING_S): this start, and the prior inflation below, are then the priming pass's
and a live run's.

Until MIN_WINDOWS windows are measured the inflation is not known, only its bounds: 1 (white
noise) and the number of frames a window holds, N (errors constant over it;
:func:`worst_inflation`). It is taken at their geometric middle, sqrt(N)
(:func:`prior_inflation`), which is off by at most sqrt(N) whatever the truth; either bound can
be off by N. The worst case N, taken before, is what a still hand's blobs show (their errors are
the same in every frame), but a still hand's depth errors are just as constant, and inflating
the pixels' alone handed their weight to the depth; once the hand moves the blobs cross the
pixel grid and the rendered recordings' errors show 1.7-5 (truth, half-second windows moving
0.9-6 px per frame, clean and structured light). So N cost the first two seconds: orientation
RMSE, rendered recordings, 3 seeds, with sqrt(N) instead: structured light 0.286 -> 0.249 deg,
clean 0.162 -> 0.148, every effect at once 0.648 -> 0.644, left hands 0.594 -> 0.589; H.264,
whose blocks stay put for longer, 0.330 -> 0.341. Halfway in the figures too: 2.5 did better on
the sharp recordings and worse under H.264 (0.350), 6 the other way round.

A long shutter smears the blobs of the fast frames: under a 1/30-1/40 s shutter the scatter was
0.014 px below 2 px/frame of image speed, 0.024 at 2-5 and 0.091 at 5-10 (rendered, seed 0),
where the clean recording's stayed at 0.012-0.017. So the per-frame variance is a + b s^2, s
the markers' image speed from the state (:func:`image_speed2`; ``BlobSpread``): the filter
takes a (within the bounds below) for every blob, and each frame adds MARGIN^2 x inflation x
b s^2 at the frame's speed (:func:`motion_variance`), up to the model's sigma. With the average
alone the shutter cost 0.24 -> 0.29 deg; with the speed 0.20. Until the frames have moved, b is
a long shutter's (``BLUR_PRIOR``): a first movement's blobs are smeared before any frame shows
it. The scatter does not grow as s^2 all the way, though: hardly below ~2 px/frame, steeply
above (the figures above). A movement's first, slow frames take b to about 0 whatever the
shutter, and b is evidence only up to the fastest frames it was learned from
(``BlobSpread.growth``); a faster frame that the update then cannot explain is tried again with
the prior's growth beyond them (tracking/retries.py).

MARGIN: with the sigma fixed, the rendered recordings came out best at about twice the blobs'
white-noise equivalent (clean and structured light at 0.05 px or below for 0.027, Bayer at 0.1
for 0.07, JPEG at 0.15-0.2 for 0.10; 3 seeds each); 1.5 did better than 2.0 on all seven
conditions compared (clean 0.175 -> 0.163 deg, structured light 0.343 -> 0.305).

The sigma is kept within ``SIGMA_FLOOR`` and the model's. Above the model's, what the residuals
show is mostly the layout's error (without hand.json, a constant per marker), which is no noise:
raising the sigma for it made the every-effect recordings worse.

All of this is learned from, and taken for, the blobs the detector does not doubt. A suspect
blob (clipped, split, elongated, on the border, a streak: ``Detections.suspect``) is taken at the
model's sigma whatever is learned (``MarkerObservation.suspect_variance``) and left out of the
learning (``noise_scale.undoubted``).
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.tracking.pose_fit import pinhole_jacobian, point_jacobian

WINDOW_S = 0.5  # the span of frames whose errors the filter weighs together
_SPAN_TOLERANCE = 1e-6  # s: 15 x 1/30 s sums to 0.5 - 6e-17, which closes a window
TIME_CONSTANT_S = 10.0  # memory of the inflation: ~20 windows
SPREAD_TIME_CONSTANT_S = 2.0  # memory of the per-frame spread: the light and the blur change
MIN_WINDOWS = 4  # windows measured before the inflation is (prior_inflation until then)
# Frames of the first window after which its frames so far give a provisional sigma (3 frames
# of six markers: 9 degrees of freedom, the sigma within about a quarter)
EARLY_FRAMES = 3
MARGIN = 1.5  # the sigma taken, on the blobs' white-noise equivalent (module doc)
SIGMA_FLOOR = 0.05  # px
_RANK_TOLERANCE = 1e-9  # of the largest singular value: a direction the markers cannot show
# The least variance a frame is weighted at (px^2): finer than any blob's scatter (sharp: 0.012 px)
_SPREAD_FLOOR = 0.005**2
# The prior on the blur's growth b (BlobSpread), in (px per px/s)^2, as sure as it is large: the
# blob centres' scatter under a 1/30 s shutter, the longest a consumer camera runs indoors
# (../shared/realdata/README.md), 0.018 px per px/frame of image speed at 30 fps (rendered
# reaches, 5 seeds: 0.025 px at rest, 0.18 at 6-20 px/frame).
BLUR_PRIOR = (0.018 / 30.0) ** 2


class BlobCorrelation:
    """The inflation of the blobs' error variance over WINDOW_S by its correlation in time,
    from the frames' fit residuals, one window of frames at a time (module doc)."""

    def __init__(self) -> None:
        self._num = self._den = 0.0  # forgetting sums of (sum_w e)^2 and sum_w e^2
        self.windows = 0
        self.frames = 0  # frames the last window held

    def add(self, residuals: np.ndarray, span: float) -> None:
        """One window's residuals (frames, markers, 2) in px, NaN for markers not measured,
        spanning ``span`` seconds."""
        keep = math.exp(-span / TIME_CONSTANT_S)
        self._num = keep * self._num + float(np.sum(np.nansum(residuals, axis=0) ** 2))
        self._den = keep * self._den + float(np.nansum(residuals**2))
        self.windows += 1
        self.frames = residuals.shape[0]

    @property
    def inflation(self) -> float | None:
        """(sum_w e)^2 / sum_w e^2 over the windows so far (at least 1), or None before
        MIN_WINDOWS windows."""
        if self.windows < MIN_WINDOWS or not self._den > 0:
            return None
        return max(self._num / self._den, 1.0)


class BlobSpread:
    """The blobs' per-frame error variance (px^2 per coordinate) as a + b s^2, s the markers'
    image speed (px/s): the frames' squared fit residuals regressed on the frames' speed, a and b
    kept >= 0, forgetting old windows (SPREAD_TIME_CONSTANT_S). ``b`` is the blur of a long
    shutter: the fast frames' blobs are smeared, and their spread would not show in an average
    the slow frames dominate (module doc).

    A frame's sum of squares E over d degrees of freedom has mean d v and variance 2 d v^2 at
    variance v = a + b s^2, so the least squares are weighted by 1 / (d v^2), v at the estimate
    so far (one reweighting step per window; unweighted, a fast frame's large scatter swamped a:
    a 0.05-1.9x its truth where the blur dominates). The sums are those of a Gaussian
    approximation of E's likelihood, twice its information, so b's prior (mean and sigma
    BLUR_PRIOR, never forgotten) adds 2 / BLUR_PRIOR^2 to them.

    Without the prior b was 0 until the frames had moved: a recording that starts still and
    then reaches once, the usual task, met its movement before its blur was learned, and took
    its smeared blobs at the sharp ones' sigma. Rendered reaches under a 1/30 s shutter
    (5 seeds): orientation RMSE 0.330 -> 0.254 deg, worst range-of-motion error 2.49 -> 1.48
    (smoothed 1.29 -> 0.99); the robustness conditions, whose movements show their blur, within
    0.002 deg. The slow frames at the start of a movement then took b to 0 before the fast
    ones came (a window at up to 1 px/frame, where a 1/30 s shutter's blobs scatter about
    their rigid fit as at rest): hence ``fastest2`` and the long shutter's retry
    (tracking/retries.py), 0.254 -> 0.211 deg, 1.48 -> 1.04 (smoothed 0.99 -> 0.69) on the same
    reaches."""

    def __init__(self) -> None:
        # forgetting sums of d/v^2, d s^2/v^2, d s^4/v^2, E/v^2, E s^2/v^2
        self._sums = np.zeros(5)
        self.coefficients: tuple[float, float] | None = None  # (a, b) so far
        # the highest squared image speed (px/s)^2 of the frames learned from, forgotten as the
        # sums are: b is evidence up to it (:meth:`growth`)
        self.fastest2 = 0.0

    def add(self, residuals: np.ndarray, dof: np.ndarray, speed2: np.ndarray,
            span: float) -> None:
        """One window's residuals (frames, markers, 2), NaN where not measured, each frame's
        degrees of freedom (frames,) and squared image speed (frames,) in (px/s)^2, spanning
        ``span`` seconds."""
        keep = math.exp(-span / SPREAD_TIME_CONSTANT_S)
        d, s2 = dof.astype(float), np.asarray(speed2, dtype=float)
        learned = s2[d > 0]
        self.fastest2 = max(keep * self.fastest2, float(learned.max()) if learned.size else 0.0)
        E = np.nansum(residuals**2, axis=(1, 2))
        known = self.coefficients
        if known is None:  # the first window: its own spread at rest, the prior's growth
            rest = frame_variance(residuals, dof)
            known = (rest or 0.0), BLUR_PRIOR
        v = known[0] + known[1] * s2
        w = 1.0 / np.maximum(v, _SPREAD_FLOOR) ** 2
        self._sums = keep * self._sums + np.array(
            [w @ d, w @ (d * s2), w @ (d * s2 * s2), w @ E, w @ (E * s2)])
        self.coefficients = self._solve()

    def _solve(self) -> tuple[float, float] | None:
        """(a, b) of the sums, or None before a frame has shown any."""
        d, ds2, ds4, E, Es2 = self._sums
        if not d > 0:
            return None
        prior = 2.0 / BLUR_PRIOR**2  # b's prior, in the sums' units (class doc)
        ds4, Es2 = ds4 + prior, Es2 + prior * BLUR_PRIOR
        det = d * ds4 - ds2 * ds2
        a, b = (ds4 * E - ds2 * Es2) / det, (d * Es2 - ds2 * E) / det
        if b >= 0 and a >= 0:
            return a, b
        if a < 0:  # all of it grows with speed
            return 0.0, Es2 / ds4
        return E / d, 0.0

    def growth(self, speed2: float, long_shutter: bool = False) -> float:
        """The variance (px^2 per coordinate) the blur adds to a blob at squared image speed
        ``speed2`` (px/s)^2: b s^2 (0 before a frame has shown any). ``long_shutter``: b holds
        up to the fastest frames it was learned from (``fastest2``), and beyond them the
        prior's growth where it is the larger, a long shutter's blur that those frames were
        too slow to show (module doc)."""
        if self.coefficients is None:
            return 0.0
        b = self.coefficients[1]
        if not long_shutter:
            return b * speed2
        seen = min(speed2, self.fastest2)
        return b * seen + max(b, BLUR_PRIOR) * (speed2 - seen)

    @property
    def variance(self) -> float | None:
        """The variance at rest (a), or None before a frame has shown any."""
        c = self.coefficients
        return None if c is None else c[0]


def frame_variance(residuals: np.ndarray, dof: np.ndarray) -> float | None:
    """The blobs' per-frame error variance (px^2 per coordinate) of ``residuals`` (frames,
    markers, 2; NaN where not measured) at ``dof`` (frames,) degrees of freedom, speed
    aside; None where they have none."""
    total = int(np.sum(dof))
    return float(np.nansum(residuals**2)) / total if total > 0 else None


def fit_residuals(obs, X: np.ndarray, labels: np.ndarray,
                  uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's blob residuals after its best rigid motion and common skin slide.

    ``obs`` the MarkerObservation the frames were tracked with, ``X`` (F, D) their posterior
    states, ``labels`` (F, J) the blob of each marker (-1: none) and ``uv`` (F, M, 2) the
    blobs (M the most blobs of any frame). Returns the residuals (F, J, 2), NaN for markers
    without a blob, and each frame's degrees of freedom (F,): 2n less the rank of the motion
    and the slide at n markers (0 where n < 4: too few to tell noise from the pose). The
    least-squares fit is linearised at the frame's pose (the blobs are within a pixel of it);
    the slide's pattern is the last frame's, which half a second hardly changes.
    """
    F, J = labels.shape
    y = obs(X).reshape(F, J, obs.k)[..., :2]
    seen = labels >= 0
    frames = np.arange(F)[:, None]
    r = np.where(seen[..., None], uv[frames, np.maximum(labels, 0)] - y, 0.0)
    A = np.concatenate((_motion_jacobian(obs, X), _slide_columns(obs, X[-1], F)), axis=3)
    A = np.where(seen[..., None, None], A, 0.0).reshape(F, 2 * J, -1)
    r = r.reshape(F, 2 * J)
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    rank = s > _RANK_TOLERANCE * s[:, :1]
    U = U * rank[:, None, :]
    e = r - np.einsum("fij,fkj,fk->fi", U, U, r)
    dof = 2 * seen.sum(axis=1) - rank.sum(axis=1)
    dof = np.where(seen.sum(axis=1) >= 4, dof, 0)
    e = np.where((seen & (dof > 0)[:, None])[..., None], e.reshape(F, J, 2), np.nan)
    return e, dof


def _motion_jacobian(obs, X: np.ndarray) -> np.ndarray:
    """(F, J, 2, 6) change of the markers' pixels per small rotation (about the camera's origin)
    and translation of the hand in the camera frame (pinhole: distortion hardly turns these
    directions)."""
    pts = obs.marker_points(X).reshape(-1, 3)  # (F*J, 3)
    J = pinhole_jacobian(obs.camera, pts) @ point_jacobian(pts, np.zeros(3))
    return J.reshape(*X.shape[:1], obs.n_markers, 2, 6)


def _slide_columns(obs, x: np.ndarray, frames: int) -> np.ndarray:
    """(frames, J, 2, 3) the skin slide's pixel pattern at state ``x`` (none: (frames, J, 2, 0))."""
    if not obs.slide.any():
        return np.zeros((frames, obs.n_markers, 2, 0))
    G = obs.slide_jacobian(x).reshape(obs.n_markers, obs.k, 3)[:, :2, :]
    return np.broadcast_to(G, (frames, *G.shape))


def window_full(span: float) -> bool:
    """Whether a window of frames spanning ``span`` s (first frame to last) is complete."""
    return span >= WINDOW_S - _SPAN_TOLERANCE


def worst_inflation(frame_interval: float) -> float | None:
    """The inflation of blob errors constant over a window: the number of frames a window
    holds (:func:`window_full`) for frames ``frame_interval`` s apart, 16 at 30 fps (None where
    the spacing is unknown, not positive)."""
    if not frame_interval > 0:
        return None
    return float(math.ceil((WINDOW_S - _SPAN_TOLERANCE) / frame_interval) + 1)


def prior_inflation(window_frames: float | None) -> float | None:
    """The inflation taken before it is measured: the geometric middle of its bounds, 1 (white
    noise) and ``window_frames`` (errors constant over a window; :func:`worst_inflation`), 4 at
    30 fps (module doc); None where the window's frames are not known."""
    return None if window_frames is None else math.sqrt(window_frames)


def mean_square_radius(points: np.ndarray) -> float:
    """The markers' mean squared distance (m^2) from the hand's origin, of a layout's
    ``points`` (K, 3): what :func:`image_speed2` takes as ``r2``; 0 for no points."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    return float(np.mean(np.sum(points**2, axis=1))) if len(points) else 0.0


def image_speed2(v: np.ndarray, w: np.ndarray, z: float, fx: float, r2: float) -> float:
    """The markers' squared image speed (px/s)^2 of a hand moving at ``v`` (m/s) and turning at
    ``w`` (rad/s) at depth ``z`` (m): (fx / z)^2 (|v|^2 + |w|^2 r^2), ``r2`` the markers' mean
    squared distance from the hand's origin (m^2, :func:`mean_square_radius`). A bound on the
    motion across the line of sight, from the state alone (no projection: a frame costs ~1 us);
    0 where the state has no speed (NaN, the paper's model)."""
    speed2 = (fx / z) ** 2 * (float(v @ v) + float(w @ w) * r2)
    return speed2 if math.isfinite(speed2) else 0.0


def motion_variance(growth: float, inflation: float | None) -> float:
    """The pixel variance (px^2) the filter takes for a frame's blur of per-frame variance
    ``growth`` (BlobSpread.growth at the frame's speed): MARGIN^2 x inflation x growth, none
    before the inflation is known."""
    if inflation is None:
        return 0.0
    return MARGIN**2 * inflation * growth


def filter_sigma(model_sigma: float, variance: float | None, inflation: float | None) -> float:
    """The pixel sigma the filter takes: MARGIN times the white-noise equivalent of the blobs'
    per-frame ``variance`` (px^2) under the correlation's ``inflation`` (measured, or
    :func:`prior_inflation`), within [SIGMA_FLOOR, model_sigma]; the model's where either is
    not known yet."""
    if inflation is None or variance is None:
        return model_sigma
    sigma = MARGIN * math.sqrt(variance * inflation)
    return min(max(sigma, min(SIGMA_FLOOR, model_sigma)), model_sigma)
