"""Measurement model: where each marker appears in the image, and at what depth.

Marker j at T_j in the hand frame projects to y_j = pi(R_ch T_j + t_ch) (paper eq. 2-3), with
R_ch = R_c0 R and t_ch = R_c0 p + t_c0 for the pose (R, p) relative to W0. Where the sensor has
depth, the marker centre's depth z_j is a third component of y_j: the paper uses depth only to
initialise; using it in every update resolves the planar-target flip and sharpens the
out-of-plane angles.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.depth_noise import (
    NGUYEN_OBLIQUE,
    NGUYEN_OFFSET,
    NGUYEN_QUADRATIC,
    NGUYEN_Z0,
    depth_sigma,
    oblique_sigma,
)
from wristtrack.hand import MARKER_NAMES
from wristtrack.tracking import pixel_noise

# Skin over the metacarpal heads slides as the fingers flex, about 3 mm distally and 1 mm
# towards the palm over the full range (see sim.realism); WRIST and CMC1 sit over bone that does
# not move under them. The filter takes half of that range in each direction (and as much
# sideways as towards the palm) as the spread of the MCP markers' common slide: hand frame
# (distal X, lateral Y, palmar Z), metres.
SKIN_SLIDE_SIGMA = (0.0015, 0.0005, 0.0005)
# The slide's axes a state carries (tracking/slide_model.py): distal and lateral. The palmar
# slide runs along the line of sight of a hand that faces the camera, where the depth noise
# (1.3 mm at 0.65 m) dwarfs the whole of it (1 mm at 90 deg flexion): carried in the state, it
# wandered within its prior, slowly, and was read as a tilt (rendered rigid hands: smoothed range
# of motion 0.053 -> 0.084 deg). It stays noise the markers share afresh each frame.
STATE_SLIDE_AXES = (0, 1)
SLIDING_MARKERS = tuple(j for j, name in enumerate(MARKER_NAMES) if name.startswith("MCP"))
# A depth map registered to the colour image by the camera's factory calibration is 1-2 px off
# it (see sim.realism): each marker's depth is read that far from its blob.
REGISTRATION_PX = 1.5
GRAZING_COS = 0.05  # the steepest view of the hand's surface the depth gradient is taken at
# ... and the steepest its offset's depth change is predicted at (tracking/offset_model.py), as
# steep as skin patches are read (surface.SurfaceSettings.grazing_cos)
OFFSET_GRAZING_COS = 0.3


@dataclass(frozen=True)
class MeasurementNoise:
    """The sensor's noise and the hand's, as the filter models them.

    Pixels: the blob centre's own noise, independent between markers. Measured on rendered
    recordings it is 0.02-0.05 px on sharp frames and 0.13-0.26 px under every realism effect at
    once (blur, JPEG, Bayer, highlights); ``pixel_sigma`` covers the worst of it, and the tracker
    lowers it to what the recording's blobs show (tracking/pixel_noise.py).

    Skin: the MCP markers' common slide over the metacarpal heads (``skin_slide``, hand-frame
    standard deviations, ``SKIN_SLIDE_SIGMA``), a displacement shared by the four markers, so
    its noise is correlated between them (``MarkerObservation.noise_covariance``). Modelled as
    independent pixel noise instead, the ~1 px slide forced a 0.7 px sigma on every marker and
    the filter threw away most of what sharp blobs say; modelled as what it is, it removes one
    pattern of the measurements (the MCPs moving together against WRIST and CMC1) and keeps the
    rest at full weight. Zeros: a rigid hand. The tracker scales these sigmas by how much the
    recording shows the skin slide (tracking/noise_scale.py): fingers that stay still have
    none, and the slide's pattern would discount the pixels' evidence about a flexion tilt.

    Registration: the depth map's offset from the colour image (``registration_px`` per axis,
    the same for every marker), so each marker's depth is read off its blob, on the tilted back
    of the hand: a depth error shared by the markers through the surface's slope
    (``MarkerObservation.registration_jacobian``). Unmodelled, it moved the hand 1-2 mm along
    the line of sight.

    Depth: sigma_z = max(offset + coeff (z - z0)^2, floor) (``depth_noise.depth_sigma``), by
    default Nguyen, Izadi and Lovell's measurement of a Kinect v1 / Xtion (1.3 mm at 0.65 m).
    A blob's depth is a trimmed mean of its pixels, but structured-light noise is correlated over
    the ~9x9 px matching window, as large as a marker's image: the mean removes little of it,
    so the blob's sigma is the pixel's. (Khoshelham and Elberink's 1.425e-3 z^2, half of it at
    arm's length, had the filter trust depth twice too much: the out-of-plane angles took the
    depth noise, 2.2x the error of the same recording without structured-light noise.)
    Seen more than 60 deg from the back of the hand's normal, a marker's depth grows noisier as
    Nguyen et al. measured (``depth_oblique``, ``depth_noise.oblique_sigma``): taken facing,
    the three knuckles lined up at the extremes of a turned hand's movement gave the update an
    NIS of 65-80 on 9-12 dof for four frames and lost a track that was 1 deg off (rendered, every
    effect, a right hand making the left hand's movement, seed 9).
    """

    pixel_sigma: float = 0.3  # px, blob centre noise
    depth_coeff: float = NGUYEN_QUADRATIC  # 1/m
    depth_floor: float = 0.0  # m
    depth_offset: float = NGUYEN_OFFSET  # m
    depth_z0: float = NGUYEN_Z0  # m
    skin_slide: tuple[float, float, float] = SKIN_SLIDE_SIGMA  # m, hand frame X, Y, Z
    registration_px: float = REGISTRATION_PX  # px, colour-depth offset, each axis
    depth_oblique: float = NGUYEN_OBLIQUE  # m^1.5, the growth beyond 60 deg (0: none)

    def depth_sigma(self, z: float | np.ndarray,
                    cos_incidence: float | np.ndarray | None = None) -> float | np.ndarray:
        """The depth sigma (m) of a marker at depth ``z`` (m), seen at ``cos_incidence`` from
        the back of the hand's normal (None: facing the camera)."""
        sd = depth_sigma(z, self.depth_coeff, self.depth_floor, self.depth_offset, self.depth_z0)
        if cos_incidence is None:
            return sd
        return sd + oblique_sigma(z, cos_incidence, self.depth_oblique)


def hand_in_camera(R_rel: np.ndarray, p: np.ndarray, R_c0: np.ndarray,
                   t_c0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hand's camera-frame pose (R_ch, t_ch) from its pose (R_rel, p) relative to W0 =
    (R_c0, t_c0): R_ch = R_c0 R_rel, t_ch = R_c0 p + t_c0; single ((3, 3), (3,)) or stacked
    ((S, 3, 3), (S, 3))."""
    return R_c0 @ R_rel, p @ R_c0.T + t_c0


class MarkerObservation:
    """Maps states (S, D) to stacked marker measurements (S, 6*k), marker-major, k = 2 or 3."""

    def __init__(
        self,
        camera: Camera,
        layout_points: np.ndarray,
        R_c0: np.ndarray,
        t_c0: np.ndarray,
        pose: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        use_depth: bool,
        noise: MeasurementNoise = MeasurementNoise(),
        slide_of: Callable[[np.ndarray], np.ndarray] | None = None,
        offset_of: Callable[[np.ndarray], np.ndarray] | None = None,
        rates_of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
    ):
        self.camera = camera
        self.layout_T = np.asarray(layout_points, dtype=float).T.copy()  # (3, 6)
        self.n_markers = self.layout_T.shape[1]
        # the markers' mean squared distance from the hand's origin (m^2): their image speed
        # per turning rate (pixel_noise.image_speed2), fixed with the layout
        self.layout_r2 = pixel_noise.mean_square_radius(self.layout_T.T)
        self.R_c0 = np.asarray(R_c0, dtype=float)
        self.t_c0 = np.asarray(t_c0, dtype=float)
        self.pose = pose
        # states (S, D) -> (S, 3) the MCP markers' common skin slide (hand frame), where the
        # state carries it (tracking/slide_model.py) along STATE_SLIDE_AXES; the noise here is
        # then the slide along the other axes
        self.slide_of = slide_of
        self.k = 3 if use_depth else 2
        # states (S, D) -> (S, 2) the depth map's offset from the colour image (px), where the
        # state carries it (tracking/offset_model.py): the misregistration is then no noise
        self.offset_of = offset_of
        # states (S, D) -> their linear and angular velocities (S, 3) each, in W0: a depth frame
        # captured depth_delay after the colour reads the hand where they have moved it
        # (:func:`lag_depth_change`; an unknown delay is taken as none). A model without rates
        # (the paper's) reads it as still.
        self.rates_of = rates_of
        self.lagged = use_depth and rates_of is not None
        self.read_depth_at(camera.depth_delay or 0.0)
        # a rolling shutter's readout (s, Camera.readout), where the rates tell the image path
        self.readout = (camera.readout or 0.0) if rates_of is not None else 0.0
        if offset_of is not None:
            noise = replace(noise, registration_px=0.0)
        self.noise = noise
        self.model_pixel_sigma = noise.pixel_sigma  # what a suspect blob is taken at
        self.motion_variance = 0.0  # px^2 every blob adds this frame: its blur (pixel_noise.py)
        # (J, 3) hand-frame spread of each marker's share in the common skin slide: the
        # model's (slide_base), scaled by what the recording shows (tracking/noise_scale.py)
        self.slide_base = np.zeros((self.n_markers, 3))
        self.sliding = np.zeros(self.n_markers, dtype=bool)
        if self.n_markers == len(MARKER_NAMES):
            self.sliding[list(SLIDING_MARKERS)] = True
            self.slide_base[self.sliding] = noise.skin_slide
            if slide_of is not None:
                self.slide_base[:, list(STATE_SLIDE_AXES)] = 0.0
        self.slide = self.slide_base.copy()

    def scale_slide(self, sd_factor: float) -> None:
        """Take the skin slide's sigmas as ``sd_factor`` times the model's."""
        self.slide = self.slide_base * sd_factor

    def set_pixel_sigma(self, sigma: float) -> None:
        """Take the blobs' pixel noise as ``sigma`` (px) from now on (tracking/pixel_noise.py)."""
        self.noise = replace(self.noise, pixel_sigma=sigma)

    @property
    def suspect_variance(self) -> float:
        """The pixel variance (px^2) a suspect blob's centre gets on top of the noise every
        blob is taken at: back up to the model's sigma where a lower one was learned. The
        learned sigma is what the undoubted blobs show; a clipped or split blob's error is
        larger (against the truth: 0.05-0.06 against 0.02 px on sharp rendered recordings,
        0.22-0.37 against 0.15-0.18 under every effect), and partly hidden markers taken at a
        0.07 px floor had turned an occlusion into a 4.5 deg range-of-motion error."""
        return max(self.model_pixel_sigma**2 - self.noise.pixel_sigma**2, 0.0)

    def blob_variance(self, suspect: np.ndarray | None, count: int) -> np.ndarray:
        """(count,) the pixel variance each blob adds to its marker's in the update: the blur's
        ``motion_variance``, and the suspect ones' ``suspect_variance`` on top."""
        variance = np.full(count, self.motion_variance)
        if suspect is not None:
            variance += np.where(suspect, self.suspect_variance, 0.0)
        return variance

    def marker_points(self, X: np.ndarray) -> np.ndarray:
        """Marker centres (S, 6, 3) in the camera frame for states X (S, D)."""
        return self._placed(X, *hand_in_camera(*self.pose(X), self.R_c0, self.t_c0))

    def _placed(self, X: np.ndarray, R_ch: np.ndarray, t_ch: np.ndarray) -> np.ndarray:
        """Marker centres (S, 6, 3) of states X (S, D) at their camera-frame poses (R_ch, t_ch)
        (S, 3, 3), (S, 3): the layout, the MCP markers moved by the state's slide."""
        pts = (R_ch @ self.layout_T).swapaxes(1, 2) + t_ch[:, None, :]
        if self.slide_of is not None:
            pts[:, self.sliding] += (R_ch @ self.slide_of(X)[:, :, None])[:, None, :, 0]
        return pts

    def read_depth_at(self, delay: float) -> None:
        """The depth read ``delay`` s after the colour from now on (the frame's own delay:
        tracking/depth_timing.py); none where the observation reads no depth or no rates."""
        self.depth_delay = delay if self.lagged else 0.0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        R_ch, t_ch = hand_in_camera(*self.pose(X), self.R_c0, self.t_c0)
        pts = self._placed(X, R_ch, t_ch)
        out = np.empty((X.shape[0], self.n_markers, self.k))
        out[..., :2] = self.camera.project(pts)
        if self.readout or self.depth_delay:
            rates = point_rates(*self.rates_of(X), self.R_c0, pts - t_ch[:, None])
        if self.readout:  # a rolling shutter read each marker's row at its own time
            out[..., :2] += rolling_shift(self.camera, pts, rates, out[..., 1])
        if self.k == 3:
            out[..., 2] = pts[..., 2]
            if self.offset_of is not None:  # each depth read off its blob, on the skin's slope
                out[..., 2] += depth_offset_change(pts, R_ch[:, None, :, 2], self.offset_of(X),
                                                   self.camera.fx, self.camera.fy)
            if self.depth_delay:  # read in a depth frame captured before or after the colour
                out[..., 2] += lag_depth_change(pts, R_ch[:, None, :, 2], rates,
                                                self.depth_delay)
        return out.reshape(X.shape[0], -1)

    def noise_variance(self, x: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
        """Diagonal measurement noise (6*k,) at the predicted state ``x`` (D,) and measurement
        ``y_pred`` (6*k,)."""
        var = np.full((self.n_markers, self.k), self.noise.pixel_sigma**2)
        if self.k == 3:
            z = y_pred.reshape(self.n_markers, 3)[:, 2]
            var[:, 2] = self.noise.depth_sigma(z, self.facing(x)) ** 2
        return var.reshape(-1)

    def facing(self, x: np.ndarray) -> np.ndarray:
        """(6,) cosine between the back of the hand's normal and each marker's line of sight
        at state ``x`` (D,): 1 facing the camera, 0 edge-on, negative turned away."""
        R_ch, pts = self._hand_in_camera(x)
        return -(pts @ R_ch[:, 2]) / np.linalg.norm(pts, axis=1)

    def slide_jacobian(self, x: np.ndarray) -> np.ndarray:
        """(6*k, 3) change of the measurements at state ``x`` (D,) per standard deviation of the
        skin slide along each hand axis: half the difference of the measurements with the
        sliding markers moved one sigma either way (exact for depth, second order for pixels)."""
        return self._slide_jacobian(*self._hand_in_camera(x))

    def as_rigid(self, slide_sd: np.ndarray) -> MarkerObservation:
        """This observation with the markers where the layout puts them (the slide a state
        carries left out) and the skin slide as noise of sigmas ``slide_sd`` (3,) the markers
        share: the recording's slide measured as the model without the state measures it
        (tracking/noise_scale.py)."""
        out = copy.copy(self)
        out.slide_of = None
        out.slide = np.where(self.sliding[:, None], np.asarray(slide_sd, float)[None, :], 0.0)
        return out

    def registration_jacobian(self, x: np.ndarray) -> np.ndarray:
        """(6*k, 2) change of the measurements at state ``x`` (D,) per standard deviation of the
        colour-depth misregistration along u and v: the depth of the hand's surface plane at each
        marker (normal: the hand's Z axis) changes by dz/du = -n_x z^2 / (fx n.p) per pixel
        (and likewise in v). Zeros without depth."""
        return self._registration_jacobian(*self._hand_in_camera(x))

    def shared_covariance(self, x: np.ndarray) -> np.ndarray:
        """(6*k, 6*k) noise the markers share at state ``x``: G G^T with G the slide and the
        registration Jacobians side by side."""
        R_ch, pts = self._hand_in_camera(x)
        G = np.hstack((self._slide_jacobian(R_ch, pts), self._registration_jacobian(R_ch, pts)))
        return G @ G.T

    def noise_covariance(self, x: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
        """Full measurement noise (6*k, 6*k) at the predicted state ``x`` and measurement
        ``y_pred``: the independent sensor noise plus the noise the markers share, the skin
        slide of the MCPs and the colour-depth misregistration."""
        return np.diag(self.noise_variance(x, y_pred)) + self.shared_covariance(x)

    def _hand_in_camera(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The hand's camera-frame rotation (3, 3) and marker centres (6, 3) at state x (D,)."""
        R_ch, t_ch = hand_in_camera(*self.pose(x[None]), self.R_c0, self.t_c0)
        return R_ch[0], self._placed(x[None], R_ch, t_ch)[0]

    def _slide_jacobian(self, R_ch: np.ndarray, pts: np.ndarray) -> np.ndarray:
        G = np.zeros((self.n_markers, self.k, 3))
        moving = np.flatnonzero(self.slide.any(axis=1))
        if moving.size == 0:
            return G.reshape(-1, 3)
        step = R_ch[None] * self.slide[moving][:, None, :]  # (n, 3 camera, 3 slide axes)
        step = step.swapaxes(1, 2)  # (n, slide axis, camera xyz)
        uv_plus = self.camera.project(pts[moving][:, None, :] + step)
        uv_minus = self.camera.project(pts[moving][:, None, :] - step)
        G[moving, :2, :] = ((uv_plus - uv_minus) / 2).swapaxes(1, 2)
        if self.k == 3:
            G[moving, 2, :] = step[..., 2]
        return G.reshape(-1, 3)

    def _registration_jacobian(self, R_ch: np.ndarray, pts: np.ndarray) -> np.ndarray:
        G = np.zeros((self.n_markers, self.k, 2))
        if self.k == 3:
            G[:, 2, :] = registration_depth_jacobian(pts, R_ch[:, 2], self.noise.registration_px,
                                                     self.camera.fx, self.camera.fy)
        return G.reshape(-1, 2)


def registration_depth_jacobian(points: np.ndarray, normals: np.ndarray, registration_px: float,
                                fx: float, fy: float, grazing_cos: float = GRAZING_COS,
                                ) -> np.ndarray:
    """(K, 2) change of the depth read at camera-frame ``points`` (K, 3) on surfaces with
    ``normals`` ((K, 3) or (3,)) per ``registration_px`` of colour-depth offset along u and v:
    dz/du = -n_x z^2 / (fx n.p) (likewise in v), the slope taken no steeper than at
    ``grazing_cos``."""
    normals = np.broadcast_to(normals, points.shape)
    slope = registration_px * points[:, 2] ** 2 / _along_normal(points, normals, grazing_cos)
    return np.column_stack((-normals[:, 0] * slope / fx, -normals[:, 1] * slope / fy))


def _along_normal(points: np.ndarray, normals: np.ndarray, grazing_cos: float) -> np.ndarray:
    """n . p of camera-frame ``points`` (..., 3) on surfaces with ``normals`` (..., 3), no
    smaller in size than at ``grazing_cos``: the denominator of a depth read off a point along
    its surface, which grows without bound towards a grazing view."""
    d = np.einsum("...j,...j->...", points, normals)
    steepest = grazing_cos * np.linalg.norm(points, axis=-1)
    return np.where(d < 0.0, np.minimum(d, -steepest), np.maximum(d, steepest))


def point_rates(v: np.ndarray, w: np.ndarray, R_c0: np.ndarray, arms: np.ndarray) -> np.ndarray:
    """(S, K, 3) camera-frame velocities of points ``arms`` (S, K, 3) from the hand's origin
    (camera axes) on hands moving at v and turning at w ((S, 3) each, W0, a state's rates):
    R_c0 v + (R_c0 w) x arm."""
    return (v @ R_c0.T)[:, None] + np.cross((w @ R_c0.T)[:, None], arms)


def rolling_shift(camera: Camera, points: np.ndarray, rates: np.ndarray,
                  v: np.ndarray) -> np.ndarray:
    """(..., 2) where camera-frame ``points`` (..., 3) moving at ``rates`` (..., 3) m/s are
    seen by a rolling shutter, from where they are at the frame's time, seen on image rows ``v``
    (...): the point moves along its image path (at the pinhole's image velocity; the lens
    distortion changes it by its own few per cent) until the row it has reached is read. On a
    straight path at image speed (du, dv) that is t = row_time(v) / (1 - readout dv / height),
    row_time's fixed point."""
    z = points[..., 2]
    velocity = np.stack([camera.fx * (rates[..., 0] * z - points[..., 0] * rates[..., 2]),
                         camera.fy * (rates[..., 1] * z - points[..., 1] * rates[..., 2])], -1)
    velocity /= (z * z)[..., None]
    when = camera.row_time(v) / (1.0 - camera.readout * velocity[..., 1] / camera.height)
    return when[..., None] * velocity


def lag_depth_change(points: np.ndarray, normals: np.ndarray, rates: np.ndarray,
                     delay: float) -> np.ndarray:
    """(S, K) the change of the depth read at camera-frame ``points`` (S, K, 3), moving at
    ``rates`` (S, K, 3) m/s on surfaces with ``normals`` ((S, K, 3) or (S, 1, 3)), in a depth
    frame captured ``delay`` s after the colour frame (Camera.depth_delay): the surface moved by
    delay (n . rate) along its normal, read along the point's ray, z delay (n . rate) / (n . p),
    to first order in the delay (under 17 ms), no steeper than at OFFSET_GRAZING_COS, as the
    depth map's offset (:func:`depth_offset_change`)."""
    normals = np.broadcast_to(normals, points.shape)
    towards = np.einsum("...j,...j->...", normals, rates)
    return delay * points[..., 2] * towards / _along_normal(points, normals, OFFSET_GRAZING_COS)


def depth_offset_change(points: np.ndarray, normals: np.ndarray, offset: np.ndarray, fx: float,
                        fy: float) -> np.ndarray:
    """(S, K) the change of the depth read at camera-frame ``points`` (S, K, 3) on surfaces with
    ``normals`` ((S, K, 3) or (S, 1, 3)) where the depth map is ``offset`` (S, 2) px off the
    colour image (tracking/offset_model.py): the surface's slope per pixel
    (:func:`registration_depth_jacobian`, no steeper than at OFFSET_GRAZING_COS: beyond, the
    hand's plane is no guide to the skin under a marker) times it."""
    S, K = points.shape[:2]
    normals = np.broadcast_to(normals, points.shape)
    slope = registration_depth_jacobian(points.reshape(-1, 3), normals.reshape(-1, 3), 1.0, fx,
                                        fy, OFFSET_GRAZING_COS).reshape(S, K, 2)
    return np.einsum("skj,sj->sk", slope, offset)


def markers_on_blobs(obs: MarkerObservation, x: np.ndarray, labels: np.ndarray, uv: np.ndarray,
                     limit: float, suspect: np.ndarray | None = None) -> bool:
    """Whether the markers at state ``x`` lie on the blobs labelled as them: the squared
    Mahalanobis distance of the pixel residuals under the measurement noise (skin slide
    included) within ``limit`` (a chi-square quantile for 2 per labelled marker). A marker given
    several blobs (the paper's association) is judged on its nearest. An update can pass its NIS
    test with a wide prior (a manoeuvre retry, a fresh start) and still stop short of the blobs
    it was given. Each blob's noise is raised by ``obs.blob_variance`` (the frame's blur, and
    ``suspect`` (M,) blobs back to the model's sigma; None: none suspect)."""
    blobs = np.flatnonzero(labels >= 0)
    if blobs.size == 0:
        return False
    y = obs(x[None])[0]
    k = obs.k
    r = uv[blobs] - y.reshape(-1, k)[labels[blobs], :2]
    order = np.argsort(np.einsum("ij,ij->i", r, r))
    markers, first = np.unique(labels[blobs][order], return_index=True)
    r = r[order][first].ravel()
    rows = (markers[:, None] * k + np.arange(2)).ravel()
    R = obs.noise_covariance(x, y)[np.ix_(rows, rows)]
    nearest = blobs[order][first]
    R[np.diag_indices_from(R)] += np.repeat(obs.blob_variance(suspect, len(uv))[nearest], 2)
    return float(r @ np.linalg.solve(R, r)) <= limit
