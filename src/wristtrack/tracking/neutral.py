"""The still start: the subject's layout and the fixed frame W0 from several frames, not one.

The initialisation measures the layout (without hand.json) and W0 from a single frame. Kept as
measured (DESIGN section 2: a real palm arches), one frame's depth noise sits in every marker's
height and the hand frame built on them, and W0 is ~1 deg off: both leak into every relative
angle for the rest of the recording. The hand is still and neutral at the start (the paper's
assumption for initialisation), so :class:`StillStart` gathers the labelled markers' 3-D centres
over the first tracked frames while the filter says the hand is still, and then gives

- the layout averaged over those frames (:func:`wristtrack.hand.average_layout`, heights kept);
- W0 as one pose fitted to the pixels and depths of all those frames at once (Gauss-Newton,
  :func:`wristtrack.tracking.pose_fit.refine_pose` over the stacked markers), with its
  covariance, which the tracker adds to the uncertainty of every relative pose. (Not the
  filtered pose: at rest the filter, tuned to follow motion, is no better than one frame.)
  The pixels are weighed at what they are worth over the still frames (:func:`still_pixel_sigma`):
  a still hand's blobs are the same blobs in every frame, and the part of their errors that is
  the same in every frame does not average as the depth's fresh noise does.
- the frames' depth images, from which the tracker learns the shape of the skin between the
  markers (:func:`wristtrack.tracking.surface.learn_surface`).

:func:`reanchor` re-expresses the filter's state (default model) in the refined hand frame and
W0, so tracking goes on without a jump.
"""

from __future__ import annotations

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import ConfigError, InitialisationError, InputError
from wristtrack.filter.ukf import chi2_quantile
from wristtrack.geometry import skew
from wristtrack.hand import HandLayout, average_layout, fit_pose
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.pixel_noise import SIGMA_FLOOR
from wristtrack.tracking.pose_fit import refine_pose

STILL_FRAMES = 15  # frames averaged (0.5 s at 30 fps: the paper's still start)
# A frame that comes this long after the last one the still start took (or the first fix) ends
# it: frames were lost and the hand may have moved unseen (a live run that dropped most frames,
# a hand lost and found again). A run cut to frames 0, 39 and 49 had taken frame 49, 20 deg into
# the movement and 1.6 s after the fix, for the still start and reported its rows against it,
# 20 deg off. Frames a few hundred ms apart (a slow camera) still make one.
STILL_GAP_S = 0.5
MIN_FRAMES = 5  # fewer usable frames before the hand moves: keep the one-frame layout
STILL_PX = 2.5  # markers this far (px, median) from where the still start found them: moving
STILL_SPEED = 0.03  # m/s; or the filter sees the hand move this fast
STILL_RATE = 0.25  # rad/s
# ... and tells it from its own noise: a fresh track's velocities are uncertain (0.6 rad/s after
# its first update), and under realistic depth noise the estimate alone passed STILL_RATE in the
# first frame and ended a still start of 20 frames after one, leaving W0 2 deg off.
STILL_SIGNIFICANCE = chi2_quantile(0.99, 3)  # chi-square, 3 dof, 0.99 (11.34)


def _moving(velocity: np.ndarray, cov: np.ndarray | None, threshold: float) -> bool:
    """Whether a velocity says the hand moves: above ``threshold`` and, with its covariance,
    significantly different from zero (NaN, as the paper model's angular velocity: no)."""
    if not np.linalg.norm(velocity) > threshold:
        return False
    if cov is None:
        return True
    try:
        return float(velocity @ np.linalg.solve(cov, velocity)) > STILL_SIGNIFICANCE
    except np.linalg.LinAlgError:
        return True


class StillStart:
    """Collects a still hand's labelled marker centres frame by frame (see module doc)."""

    def __init__(self, camera: Camera, t0: float | None = None,
                 n_frames: int = STILL_FRAMES) -> None:
        self.camera = camera
        self.last_t = t0  # the last frame's (first: the fix's) timestamp (s); None: no limit
        self.n_frames = n_frames
        self.frames: list[np.ndarray] = []  # (6,3) camera-frame centres, all six with depth
        self.uv: list[np.ndarray] = []  # (6,2) and (6,) of every frame, NaN where unlabelled
        self.depth: list[np.ndarray] = []
        self.depth_images: list[np.ndarray] = []  # the frames' raw depth, for the skin's shape
        self.closed = False

    def add(self, det: Detections, labels: np.ndarray, v: np.ndarray, w: np.ndarray,
            cov_v: np.ndarray | None = None, cov_w: np.ndarray | None = None) -> bool:
        """Take one tracked frame (blob ``labels``, the filter's velocities ``v``, ``w`` and,
        where known, their covariances); True once the still start is over (enough frames, a
        frame more than STILL_GAP_S after the last, or the hand started moving: its markers
        moved, or the filter's velocity is above its threshold and, given its covariance,
        significantly so)."""
        if self.closed:
            return True
        blobs = np.flatnonzero(labels >= 0)
        uv, z = np.full((6, 2), np.nan), np.full(6, np.nan)
        uv[labels[blobs]] = det.uv[blobs]
        moved = 0.0
        if self.uv:  # the markers' median displacement: robust to one blob's noise
            d = np.linalg.norm(uv - self.uv[0], axis=1)
            if np.isfinite(d).any():
                moved = float(np.nanmedian(d))
        if (moved > STILL_PX or _moving(v, cov_v, STILL_SPEED) or _moving(w, cov_w, STILL_RATE)
                or len(self.uv) >= self.n_frames
                or (self.last_t is not None and det.timestamp - self.last_t > STILL_GAP_S)):
            self.closed = True
            return True
        if det.depth is not None:
            z[labels[blobs]] = det.depth[blobs]
        self.last_t = det.timestamp
        self.uv.append(uv)
        self.depth.append(z)
        if det.depth is not None and det.depth_image is not None:
            self.depth_images.append(det.depth_image)
        if np.isfinite(z).all():
            self.frames.append(self.camera.backproject(uv, z))
        return False

    def layout(self) -> HandLayout | None:
        """The averaged layout (heights kept), or None when too few frames were gathered or
        they do not make a valid layout (the one-frame layout then stays)."""
        if len(self.frames) < MIN_FRAMES:
            return None
        try:
            return average_layout(np.array(self.frames))[0]
        except (ConfigError, InputError):
            return None


    def w0(self, layout: HandLayout, R0: np.ndarray, t0: np.ndarray,
           noise: MeasurementNoise | None = None, min_frames: int = MIN_FRAMES):
        """(R_ch, t_ch, cov (6,6)) of the hand over the still start with ``layout``: one pose
        fitted to every frame's markers (start R0, t0), the depth weighted as the filter weighs
        it (``noise``'s depth model, floor included: a structured-light camera's depth errors
        are correlated in time too, so more frames do not make depth sharper than that floor),
        the pixels first at ``noise``'s pixel sigma, then again at what the fit shows them
        worth over the frames (:func:`still_pixel_sigma`); None with fewer than
        ``min_frames`` frames or no fit.
        """
        if len(self.uv) < max(min_frames, 1):
            return None
        n = len(self.uv)
        stacked = HandLayout(np.tile(layout.points, (n, 1)))  # the same markers, n times
        noise = noise or MeasurementNoise()
        frames = np.array(self.uv)  # (n, 6, 2)
        uv, depth = frames.reshape(-1, 2), np.concatenate(self.depth)
        sz = noise.depth_sigma(np.nan_to_num(depth, nan=1.0))
        try:
            fit = refine_pose(uv, depth, self.camera, stacked, R0, t0, noise.pixel_sigma, sz)
            at_fit = self.camera.project(layout.points @ fit.R_ch.T + fit.t_ch)
            pixel_sigma = still_pixel_sigma(frames - at_fit)
            if pixel_sigma is not None:
                fit = refine_pose(uv, depth, self.camera, stacked, fit.R_ch, fit.t_ch,
                                  pixel_sigma, sz)
        except InitialisationError:
            return None
        return fit.R_ch, fit.t_ch, fit.cov


def still_pixel_sigma(residuals: np.ndarray) -> float | None:
    """The pixel sigma (px) a still start's blobs are worth, each frame's taken once in one fit
    of the pose to all the frames: ``residuals`` (frames, markers, 2) the blobs less the
    markers' image at the fitted pose (NaN where a marker was not seen).

    A blob's error is partly fresh in every frame (the sensor's noise), partly the same in every
    frame of a still hand (the pixel grid, the shading, the codec's blocks) and partly slow (the
    skin sliding as the fingers move, the hand settling). The frames average the fresh part
    only: n frames are worth one blob at the variance of their mean plus the slow part's, so
    each of the n stacked is worth n times that. Per coordinate:

    - the markers' mean residuals about the fit give n (constant + slow mean) + fresh: sum_j
      n_j |mean_j|^2 over 2 per marker less the pose's 6 (more than the pixels give up where
      depth carries part of the pose: the sigma errs large);
    - the spread of each marker about its mean gives fresh + slow, its frame-to-frame
      differences fresh alone (half their mean square): the slow part's variance is the
      difference, which the frames do not average either, so it counts n times.

    White blob noise gives its own sigma back (a tenth more: the slow part's estimate is kept
    at 0 or more); errors the same in every frame, sqrt(n) times theirs. Until this, the
    pixels were taken at the filter's model (0.3 px), and sharp rendered blobs (0.015-0.025 px,
    the same in every frame: 0.07-0.13 px worth over 15 frames) left W0 to the depth, whose
    errors tilted it, and every relative angle with it. Worst range-of-motion error, rendered
    recordings (seeds 0-5): clean 0.129 -> 0.092 deg, structured light 0.187 -> 0.133, JPEG
    0.322 -> 0.306, shutter and specular (seeds 3-9) 0.215 -> 0.151 and 0.124 -> 0.087; every
    effect (seeds 0-9) 0.805 -> 0.785, smoothed 0.615 -> 0.584, left hands 1.108 -> 1.106;
    H.264 and Bayer within 0.005; orientation RMSE within 0.006 deg everywhere (soft tissue,
    whose fingers flex through the still start, 0.273 -> 0.267). At least SIGMA_FLOOR; None
    where the markers leave no residual to measure (3 or fewer).
    """
    seen = np.isfinite(residuals).all(axis=2)
    count = seen.sum(axis=0)
    markers = count > 0
    dof = 2 * int(markers.sum()) - 6
    if dof <= 0:
        return None
    r = np.where(seen[..., None], residuals, 0.0)
    mean = r.sum(axis=0) / np.maximum(count, 1)[:, None]
    variance = float(np.sum(count[:, None] * mean**2)) / dof  # n (constant + slow) + fresh
    spread_dof = 2 * int(np.sum(np.maximum(count - 1, 0)))
    both = seen[1:] & seen[:-1]
    if spread_dof > 0 and both.any():
        spread = float(np.sum(np.where(seen[..., None], r - mean, 0.0) ** 2)) / spread_dof
        step = np.where(both[..., None], r[1:] - r[:-1], 0.0)
        fresh = float(np.sum(step**2)) / (2 * 2 * int(both.sum()))
        variance += len(residuals) * max(spread - fresh, 0.0)  # the slow part, not averaged
    sigma = float(np.sqrt(variance))
    return max(sigma, SIGMA_FLOOR) if np.isfinite(sigma) else None


def reanchor(
    x: np.ndarray,
    P: np.ndarray,
    R_c0: np.ndarray,
    t_c0: np.ndarray,
    old: HandLayout,
    new: HandLayout,
    w0: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    slide_dims: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The default model's state (x (18,), P (12,12); or with the skin slide, (20,), (14,14);
    and the depth offset, (22,), (16,16)) and W0 re-expressed for layout ``new``. The slide
    along the hand's first ``slide_dims`` axes turns with the hand frame (None: every state
    after w is slide); the states after it (the depth offset: the camera's) do not change.

    The new hand frame is the old one moved by T (the rigid fit of ``new`` onto ``old``:
    p_old = T_R p_new + T_t). W0 moves with it, or becomes ``w0`` = (R_ch, t_ch, cov): a pose
    of the new hand frame in the camera with its (6,6) covariance over camera-frame
    perturbations (dphi, dt), e.g. :meth:`StillStart.w0`. Returns (x, P, R_c0, t_c0, w0_cov):
    ``w0_cov`` is W0's covariance in W0 axes (zero when W0 only moved). The state covariance is
    mapped by the Jacobian of the change of frame.
    """
    T_R, T_t = fit_pose(old, new.points)
    R, p = x[:9].reshape(3, 3), x[9:12]
    v, w = x[12:15], x[15:18]
    # hand -> camera in the new frame, then relative to the moved W0
    R_c0n, t_c0n = R_c0 @ T_R, t_c0 + R_c0 @ T_t
    Rn = T_R.T @ R @ T_R
    arm = R @ T_t  # the new origin's offset from the old one, in W0
    pn = T_R.T @ (p + arm - T_t)
    vn = T_R.T @ (v + np.cross(w, arm))
    wn = T_R.T @ w
    # with the skin slide, k states: the slide along the hand's first k axes
    # (observation.STATE_SLIDE_AXES), which W0 does not turn; its share along the others is
    # noise, not state, and is dropped
    n = P.shape[0]
    k = n - 12 if slide_dims is None else slide_dims
    J = np.eye(n)
    for i in range(4):
        J[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = T_R.T
    J[12 : 12 + k, 12 : 12 + k] = T_R.T[:k, :k]
    J[3:6, 0:3] = -T_R.T @ skew(arm)  # a turn of the hand moves the new origin
    Pn = J @ P @ J.T
    w0_cov = np.zeros((6, 6))
    if w0 is not None:
        # the current hand pose in the camera, then relative to the given W0; velocities and
        # every tangent block rotate from the moved W0's axes into the given one's
        R_w, t_w, cov_w = w0
        R_ch, t_ch = R_c0n @ Rn, R_c0n @ pn + t_c0n
        Q = R_w.T @ R_c0n
        Rn, pn = R_w.T @ R_ch, R_w.T @ (t_ch - t_w)
        vn, wn = Q @ vn, Q @ wn
        M = np.eye(n)
        M[:12, :12] = np.kron(np.eye(4), Q)
        Pn = M @ Pn @ M.T
        rot = np.kron(np.eye(2), R_w.T)  # camera-frame perturbations into W0 axes
        w0_cov = rot @ cov_w @ rot.T
        R_c0n, t_c0n = R_w, t_w
    xn = np.concatenate((Rn.reshape(9), pn, vn, wn, T_R.T[:k, :k] @ x[18 : 18 + k], x[18 + k :]))
    return xn, 0.5 * (Pn + Pn.T), R_c0n, t_c0n, w0_cov
