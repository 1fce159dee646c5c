"""The tracker: one frame of detections in, one wrist estimate out.

A small state machine: ``initialising`` until the least-squares initialisation succeeds, then
``tracking`` (``coasting`` for a frame where no marker could be associated, while the
prediction is worth a pose: TrackerConfig.coast_rot_sigma_deg; ``lost`` beyond), ``lost`` after
too many frames with too few markers or updates in a row whose normalised innovation squared is
beyond its chi-square bound, from where it re-initialises by itself by fitting the layout.
The fixed frame W0 is the hand frame of the first initialisation, refined once at the end of
the still start that follows it (tracking/neutral.py: W0 fitted to all the still frames, and
without hand.json the layout averaged over them); it never moves afterwards.

Each tracking frame is one filter step: predict, associate, update; then, once the still start
has taught it the shape of the skin between the markers, a second update with that skin's depth
(tracking/surface.py). The generic path (tracking/generic_step.py) is the reference and reads
like the paper; for the default configuration the same step runs as one compiled call
(tracking/compiled.py, numba) where numba loads, and the generic path takes every other
configuration and every frame the compiled step declines. The retries of a frame the update
cannot explain (tracking/retries.py: a long shutter's blur, a manoeuvre) and the
innovation-consistency (NIS) logic sit above both; each update then tells how much the skin
over the knuckles slides and how sharp the blobs are (tracking/noise_scale.py). After a gap
(frames dropped) the update is iterated over its posterior, and an update that leaves the
markers off their blobs' discs, where no fresh fit does better, is not taken (the frame coasts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError, InputError
from wristtrack.filter import ukf
from wristtrack.filter.ukf import chi2_quantile
from wristtrack.geometry import relative_pose, so3_log
from wristtrack.hand import HandLayout, fit_pose, marker_image_diameter
from wristtrack.tracking import compiled, hypotheses, noise_scale, retries, surface
from wristtrack.tracking.config import TrackerConfig
from wristtrack.tracking.depth_timing import DepthTiming
from wristtrack.tracking.generic_step import fit_covariance, generic_step
from wristtrack.tracking.initialise import InitResult, initialise
from wristtrack.tracking.models import ConstantRateModel, unmodelled_timing
from wristtrack.tracking.neutral import MIN_FRAMES, StillStart, reanchor
from wristtrack.tracking.observation import MarkerObservation, hand_in_camera, markers_on_blobs
from wristtrack.tracking.offset_model import carry_offset, registration_estimate
from wristtrack.tracking.restart import moving_start
from wristtrack.tracking.results import FrameResult, Status, within_coast_limit

__all__ = ["FrameResult", "Status", "Tracker", "TrackerConfig"]

# This long (s) since the last frame with enough markers is a gap (frames dropped, undelivered
# or without markers): the prediction may be far off, and the update is iterated over its
# posterior (TrackerConfig.gap_iterations, in the generic step: the compiled one declines).
LONG_GAP_S = 0.2
_MIN_REFIT = 4  # markers a re-fit keeps at least: a pose from their pixels alone (pose_fit)


@dataclass
class _Track:
    x: np.ndarray
    P: np.ndarray
    timestamp: float
    weak_frames: int = 0
    inconsistent_frames: int = 0  # consecutive updates with NIS above its chi-square quantile
    R_prev: np.ndarray | None = None
    updated_sigma: tuple = (0.0, 0.0)  # (rot_sigma_deg, pos_sigma_mm) with min_markers last
    unmeasured_s: float = 0.0  # time since then, to the frame before


@dataclass
class Tracker:
    """Feed ``step`` one frame of detections at a time, in time order."""

    camera: Camera
    layout: HandLayout | None = None
    config: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self) -> None:
        self.model = self.config.make_model()
        self.assoc_params = replace(self.config.association_params, image_area=self.camera.area)
        self.R_c0: np.ndarray | None = None
        self.t_c0: np.ndarray | None = None
        self._track: _Track | None = None
        self._obs: dict[bool, MarkerObservation] = {}
        # (step, its constants): built on first use and again when W0, the layout or the noise
        # learned change; whether the configuration and this process can compile it at all
        self._compiled: tuple | None = None
        self._compiled_usable: bool | None = None
        self._frame = -1
        self._last_timestamp = -np.inf
        self._initialisations = 0
        self.status = Status.INITIALISING
        self.last_init_error: str | None = None
        self.max_blobs_seen = 0  # most blobs in a frame offered for initialisation
        # the still start (tracking/neutral.py): the layout measured without hand.json and W0
        # averaged over the first still frames; W0's covariance joins every relative pose's
        self._still: StillStart | None = None
        self._layout_measured = self.layout is None
        self.w0_cov = np.zeros((6, 6))
        # the skin between the markers, learned over the still start (tracking/surface.py)
        self.surface: surface.DorsumSurface | None = None
        if self.config.skin_depth:
            surface.pixel_rays(self.camera)  # its table built now, not in mid-recording
        # results' track_id: a new one at every initialisation and where the still start moves
        # W0, so a consumer that treats one track_id as one continuous state (the RTS smoother)
        # never smooths across the change of frame
        self._track_id = -1
        # the skin slide and the blobs' noise in this recording (tracking/noise_scale)
        self.learned_noise = noise_scale.LearnedNoise()
        # colour only: the two planar poses tracked until the motion decides (tracking/hypotheses)
        self._flip: hypotheses.PlanarHypotheses | None = None
        self._camera_state: tuple = (None, None)  # the last track's (x, P), for its depth offset
        # what the run must say about its poses (summary.json)
        self.warnings: list[str] = unmodelled_timing(self.config.model, self.camera.readout)
        self.depth_timing = DepthTiming(self.camera.depth_delay)  # each frame's depth delay

    def __getstate__(self) -> dict:
        """Pickled without the compiled step: a numba function whose helpers are compiled only
        in the process that loaded it. It holds no state between frames; the restored tracker
        loads it again on its next frame."""
        state = self.__dict__.copy()
        state["_compiled"] = state["_compiled_usable"] = None
        return state

    def start_from(self, learned: noise_scale.LearnedNoise) -> None:
        """Before the first frame: start from what an earlier pass over this recording learned
        of its markers' noise (``LearnedNoise.carried_over``; pipeline/priming.py primes so)."""
        self.learned_noise = learned.carried_over()
        self.learned_noise.scale_model(self.model)
        self._obs, self._compiled = {}, None

    # ------------------------------------------------------------------------------- stepping

    def step(self, det: Detections, labels: np.ndarray | None = None) -> FrameResult:
        """Process one frame. ``labels`` (M,) optionally names the blobs for initialisation."""
        if getattr(self, "_flip", None) is not None:  # (getattr: checkpoints from before it)
            return hypotheses.step(self, det, labels)
        if det.timestamp <= self._last_timestamp:
            raise InputError(
                f"timestamp {det.timestamp} s does not follow {self._last_timestamp} s; "
                "frames must come in strictly increasing time"
            )
        self._frame += 1
        self._last_timestamp = det.timestamp
        delay = self.depth_timing.delay(det)  # this frame's depth, read at its own delay
        for obs in self._obs.values():
            obs.read_depth_at(delay)
        track = self._track
        if track is not None and det.timestamp - track.timestamp > self.config.max_gap:
            self._lose()
            track = None
        if track is None:
            return self._try_initialise(det, labels)
        return self._track_frame(det, track)

    def _lose(self) -> None:
        if self._track is not None:
            self._camera_state = (self._track.x, self._track.P)
        self._track = None
        self.status = Status.LOST

    @property
    def depth_registration(self) -> dict | None:
        """offset_model.registration_estimate of the camera's last state (None: not carried)."""
        return registration_estimate(self.model, *self._last_state())

    def _last_state(self) -> tuple:
        """(x, P) of the running track, else the last lost one's (for the camera's offset)."""
        last = getattr(self, "_camera_state", (None, None))  # (checkpoints from before it)
        return (self._track.x, self._track.P) if self._track else last

    def _empty(self, det: Detections, status: Status) -> FrameResult:
        return FrameResult.empty(self._frame, det.timestamp, status, det.count)

    def _try_initialise(self, det: Detections, labels: np.ndarray | None) -> FrameResult:
        self.max_blobs_seen = max(self.max_blobs_seen, det.count)
        try:
            init = self._fit(det, labels)
        except InitialisationError as e:
            self.last_init_error = str(e)  # why the latest attempt failed, for the run's report
            return self._empty(det, self.status)
        if init.alternative is not None:  # the planar twin fits as well: keep both
            return hypotheses.start(self, det, init)
        return self.start_track(det, init)

    def _reacquire(self, det: Detections) -> FrameResult | None:
        """A new track fitted to this frame (W0 and layout kept), or None where none fits.

        For a frame with fewer than ``min_markers`` markers associated among that many blobs,
        or whose inconsistent or retried update left the markers off their blobs: the
        prediction has left the markers (a stalled camera, a frame rate too low for the motion,
        a long gap after a fresh start with no velocity yet). Coasting on it would
        drift further while they are in plain view, and one unscented update from that far
        off lands short of them (a 45 deg jump left 20 deg)."""
        # A fit that leaves the blobs off the markers is no better than the prediction (a hand
        # that no longer matches the layout): the innovation check is left to judge it.
        try:
            init = self._fit(det)
            if not self._explains(self._state_of(init), init.labels, det):
                # Suspect blobs (clipped, smeared) can pull the fit off the others (two blobs
                # 2.4-3 px off on a fast reach left the fit 1.4 px rms): fit the others alone.
                labels = noise_scale.undoubted(init.labels, det)
                if np.array_equal(labels, init.labels) or (labels >= 0).sum() < _MIN_REFIT:
                    return None
                init = self._fit(det, labels)
                if not self._explains(self._state_of(init), init.labels, det):
                    return None
        except InitialisationError:
            return None
        return self.start_track(det, init)

    def _fit(self, det: Detections, labels: np.ndarray | None = None) -> InitResult:
        """A fresh fit of this frame (tracking/initialise.py), its blobs taken at the filter's
        pixel noise, as the still start and the colour re-fit take them. At initialise's own
        0.7 px the fit leaned on depth for the out-of-plane angles: fresh fits after a long
        gap with every realism effect were up to 6.8 deg off in pronation; at 0.3 px, 4.9
        (benchmarks/dropped.py's cuts)."""
        return initialise(det, self.camera, self.layout, labels=labels,
                          pixel_sigma=self.config.measurement.pixel_sigma)

    def _state_of(self, init: InitResult) -> np.ndarray:
        """The state of an initialisation's pose (at rest), relative to W0."""
        return self.model.initial_state(self.R_c0.T @ init.R_ch,
                                        self.R_c0.T @ (init.t_ch - self.t_c0))

    def _beside_blobs(self, x: np.ndarray, labels: np.ndarray, det: Detections) -> bool:
        """Whether the markers at state ``x`` lie further than a marker's radius from the blobs
        labelled as them (the median over the labelled markers): off the blobs' discs."""
        blobs = np.flatnonzero(labels >= 0)
        if blobs.size == 0:
            return False
        pts = self._observation(False).marker_points(x[None])[0, labels[blobs]]
        radius = marker_image_diameter(self.camera.fx, pts[:, 2]) / 2
        offset = np.linalg.norm(det.uv[blobs] - self.camera.project(pts), axis=1)
        return bool(np.median(offset / radius) > 1.0)

    def _explains(self, x: np.ndarray, labels: np.ndarray, det: Detections) -> bool:
        limit = chi2_quantile(self.config.nis_quantile, 2 * np.unique(labels[labels >= 0]).size)
        return markers_on_blobs(self._observation(False), x, labels, det.uv, limit, det.suspect)

    def start_track(self, det: Detections, init: InitResult) -> FrameResult:
        """A new track (and track_id) from the initialisation ``init`` of this frame, its pose
        expressed in W0."""
        if self.R_c0 is None:  # the first initialisation fixes W0 (refined by the still start)
            self.R_c0, self.t_c0 = init.R_ch, init.t_ch
            self.layout = init.layout
            if isinstance(self.model, ConstantRateModel):
                self._still = StillStart(self.camera, det.timestamp)
        x = self._state_of(init)
        if self._initialisations:  # a fresh fit in W0: its uncertainty as the filter sees it
            P = fit_covariance(self.model, self._observation(det.depth is not None), x, det,
                               init.labels, self.config)
            old = self._track  # restarted within a track: at the velocity since its last frame
            if old is not None and det.timestamp - old.timestamp <= LONG_GAP_S:
                x = moving_start(self.model, x, old.x, det.timestamp - old.timestamp)
            # the depth offset is the camera's: kept from the track before, even a lost one
            x, P = carry_offset(self.model, x, P, *self._last_state())
        else:  # the first fixes W0; its uncertainty is carried apart (_result)
            # the initialisation's covariance is over camera-frame perturbations; rotate it to W0
            rot = np.kron(np.eye(2), self.R_c0.T)
            P = self.model.initial_covariance(rot @ init.cov @ rot.T)
        self._track = _Track(x, P, det.timestamp, R_prev=self.R_c0.T @ init.R_ch)
        self._initialisations += 1
        self._track_id += 1
        self.status = Status.TRACKING
        n_markers = int(np.sum(init.labels >= 0))
        return self._result(det, Status.TRACKING, init.labels, n_markers, np.nan, 0)

    def _end_still_start(self, track: _Track) -> None:
        """The layout averaged over the still start (when it was measured, not given) and W0
        fitted to all its frames at once; the state re-expressed in them (tracking/neutral.py).
        Rows already written keep the first frame's W0 (they differ by W0's correction)."""
        still, self._still = self._still, None
        new = (still.layout() if self._layout_measured else None) or self.layout
        # the start of the W0 fit: W0 moved into the new layout's hand frame
        T_R, T_t = fit_pose(self.layout, new.points)
        slide = getattr(self.model, "slide", None)
        w0 = still.w0(new, self.R_c0 @ T_R, self.t_c0 + self.R_c0 @ T_t, self.config.measurement)
        track.x, track.P, self.R_c0, self.t_c0, self.w0_cov = reanchor(
            track.x, track.P, self.R_c0, self.t_c0, self.layout, new, w0,
            0 if slide is None else slide.stop - slide.start)
        track.R_prev = track.x[:9].reshape(3, 3)
        self.layout = new
        if self.config.skin_depth and len(still.depth_images) >= MIN_FRAMES:
            self.surface = surface.learn_surface(self.camera, new, self.R_c0, self.t_c0,
                                                 still.depth_images, self.config.surface)
        self._obs = {}  # observation and compiled constants hold the layout and W0
        self._compiled = None
        self._track_id += 1

    def _observation(self, use_depth: bool) -> MarkerObservation:
        if use_depth not in self._obs:
            self._obs[use_depth] = MarkerObservation(
                self.camera, self.layout.points, self.R_c0, self.t_c0, self.model.pose,
                use_depth, self.config.measurement, getattr(self.model, "skin_slide", None),
                getattr(self.model, "depth_offset", None), getattr(self.model, "rates", None))
            self.learned_noise.apply(self._obs[use_depth])
            self._obs[use_depth].read_depth_at(self.depth_timing.current)
        return self._obs[use_depth]

    def _learn_noise(self, det: Detections, x, P, labels: np.ndarray, dt: float) -> None:
        """The skin slide and the blobs' pixel noise followed (tracking/noise_scale.py)."""
        cfg, learned = self.config, self.learned_noise
        obs = self._observation(cfg.use_depth and det.depth is not None)
        if learned.follow(self.model, obs, x, P, labels, det, dt, cfg.ukf, cfg.measurement,
                          cfg.adapt_slide, cfg.learns_pixel_noise):
            for o in self._obs.values():
                learned.apply(o)
            self._compiled = None  # the compiled step's constants made again

    def _track_frame(self, det: Detections, track: _Track) -> FrameResult:
        cfg = self.config
        dt = det.timestamp - track.timestamp
        out = plain = self._filter_frame(det, track, dt)
        if _undoubted(det) >= cfg.min_markers and hasattr(self.model, "angular_velocity"):
            out = retries.retried(self, det, track, dt, plain)
        x, P, labels, n_assoc, nis, dof, merged_markers = out
        if not (ukf.all_finite(x) and ukf.all_finite(P)):  # never let a numerical failure leak out
            self._lose()
            return self._empty(det, Status.LOST)
        # Only if its markers are off their blobs: realistic frames have harmless NIS outliers,
        # and a one-frame fit in their place cost accuracy on the preset-real recordings.
        doubtful = out is not plain or bool(dof and nis > chi2_quantile(cfg.nis_quantile, dof))
        off_blobs = doubtful and not self._explains(x, labels, det)
        if (n_assoc < cfg.min_markers or off_blobs) and cfg.reacquire \
                and det.count >= cfg.min_markers:
            again = self._reacquire(det)
            if again is not None:
                return again
        if off_blobs and cfg.reacquire and self._beside_blobs(x, labels, det):
            # Neither the update nor a fresh fit explains the blobs, and the markers are not even
            # on their blobs' discs: an association gone wrong, not noisy centres (after a long
            # gap, a fresh start's zero velocity met a fast reach: labels shifted by one marker,
            # the update 44 deg off, the markers 10-37 px from their blobs, where updates that
            # merely fail the test on rendered recordings leave them 1-3 px off). Take none of
            # them: coast on the prediction, as for a frame without markers.
            x, P = ukf.predict(self.model, track.x, track.P, dt, self.model.process_noise(dt),
                               params=cfg.ukf)
            labels, n_assoc, nis, dof = np.full(det.count, -1), 0, np.nan, 0
            merged_markers = {}
        if cfg.reacquire and det.depth is None and n_assoc >= 4:
            refit = hypotheses.colour_refit(self, det, x, labels)
            if refit is not None:
                return self.start_track(det, refit)
        track.weak_frames = track.weak_frames + 1 if n_assoc < cfg.min_markers else 0
        track.unmeasured_s = track.unmeasured_s + dt if n_assoc < cfg.min_markers else 0.0
        if track.weak_frames > cfg.lost_after:
            self._lose()
            return self._empty(det, Status.LOST)
        if dof and cfg.nis_lost_after:  # frames without an update neither count nor reset
            high = nis > chi2_quantile(cfg.nis_quantile, dof)
            track.inconsistent_frames = track.inconsistent_frames + 1 if high else 0
            if track.inconsistent_frames >= cfg.nis_lost_after:
                self._lose()  # the estimate no longer explains the markers: start again
                return self._empty(det, Status.LOST)
        track.x, track.P, track.timestamp = x, P, det.timestamp
        self._learn_noise(det, x, P, labels, dt)
        if self._still is not None and self._still.add(det, labels, *self.model.velocities(x),
                                                       *self._velocity_covariances(P)):
            self._end_still_start(track)
        status = Status.TRACKING if n_assoc else Status.COASTING
        self.status = status
        one_to_one = cfg.association == "gnn"  # then the blobs not taken are the clutter
        n_clutter = len(labels) - n_assoc if one_to_one else int(np.sum(labels < 0))
        return self._result(det, status, labels, n_assoc, nis, dof, dt, n_clutter,
                            merged_markers)

    def _provisional_w0(self) -> tuple | None:
        """During the still start, W0 fitted to its frames so far, else None."""
        still = self._still
        if still is None or not still.uv:
            return None
        return still.w0(self.layout, self.R_c0, self.t_c0, self.config.measurement,
                        min_frames=1)

    def _velocity_covariances(self, P: np.ndarray) -> tuple:
        """The covariances of the state's velocity and angular velocity (None: not in it)."""
        return tuple(P[part, part] if part is not None else None
                     for part in (getattr(self.model, "velocity", None),
                                  getattr(self.model, "angular_velocity", None)))

    def _filter_frame(self, det: Detections, track: _Track, dt: float) -> tuple:
        """Predict, associate, update: (x, P, labels, markers associated, NIS, its dof,
        merged blobs: generic_step.StepResult). The markers' update, then the skin's where it
        is known (NIS and dof are the markers')."""
        out = self._compiled_frame(det, track, dt)
        if out is None:
            out = self._generic_frame(det, track, dt)
        if self.surface is None or det.depth is None or det.depth_image is None or not out[3]:
            return out
        x, P = surface.skin_update(self.model, out[0], out[1], self.R_c0, self.t_c0, self.surface,
                                   det.depth_image, self.config.measurement, self.config.surface,
                                   self.camera, self.config.ukf,
                                   self._observation(True).depth_delay)
        return (x, P, *out[2:])

    def _compiled_frame(self, det: Detections, track: _Track, dt: float) -> tuple | None:
        """``_generic_frame``'s result from the compiled step, or None where this configuration
        or frame is not one it takes (or it declines the frame, having changed nothing)."""
        cfg = self.config
        if self._compiled_usable is None:
            self._compiled_usable = (
                type(self.model) in compiled.MODELS
                and cfg.association == "gnn"
                and cfg.use_depth
                and compiled.load() is not None
            )
        if self._compiled_usable and self._compiled is None:
            args = compiled.frame_constants(
                self.model, self._observation(True), cfg.ukf, cfg.facing_cos, self.assoc_params,
                cfg.merged_blobs,
            )
            self._compiled = (compiled.load(), args)
        if (not self._compiled_usable or det.depth is None or det.count == 0
                or self._gap_iterations(dt + track.unmeasured_s)):
            return None
        if not ukf.all_finite(det.depth):  # a blob without depth is scored on its pixels alone
            return None
        step, args = self._compiled
        # contiguous blobs and a float dt: numba compiles once per argument type
        uv, depth = np.ascontiguousarray(det.uv), np.ascontiguousarray(det.depth)
        obs = self._observation(True)
        compiled.set_depth_delay(args, obs.depth_delay)
        var = obs.blob_variance(det.suspect, det.count)
        code, x, P, labels, n_pairs, nis = step(track.x, track.P, float(dt), uv, depth, var, *args)
        if code != compiled.OK:
            return None
        return x, P, labels, n_pairs, nis, 3 * n_pairs, {}  # merges: left to the generic step

    def _generic_frame(self, det: Detections, track: _Track, dt: float) -> tuple:
        """Any configuration, any frame: generic_step.StepResult as a tuple."""
        obs = self._observation(self.config.use_depth and det.depth is not None)
        iterations = self._gap_iterations(dt + track.unmeasured_s)
        return tuple(generic_step(self.model, obs, track.x, track.P, dt, det, self.config,
                                  self.assoc_params, self.camera, iterations))

    def _gap_iterations(self, gap: float) -> int:
        """How many times an update ``gap`` s after the last frame with enough markers iterates:
        after LONG_GAP_S (a long step, or frames without markers, widened the prior),
        TrackerConfig.gap_iterations; else none (the compiled step's frames). After a third of a
        second without markers the first update had been 6.3 deg off, iterated 1.2
        (tests/tracking/test_coasting.py)."""
        return self.config.gap_iterations if gap > LONG_GAP_S else 0

    # -------------------------------------------------------------------------------- output

    def _result(
        self, det, status, labels, n_assoc, nis, dof, dt=None, n_clutter=None, merged=None
    ) -> FrameResult:
        track = self._track
        R_rel, p = self.model.pose(track.x[None])
        R_rel, p = R_rel[0], p[0]
        v, w = self.model.velocities(track.x)
        if math.isnan(w[0]):  # the paper's state has no rate (all NaN): differentiate R
            ok = dt and track.R_prev is not None
            w = so3_log(R_rel @ track.R_prev.T) / dt if ok else np.zeros(3)
        track.R_prev = R_rel
        R_ch, t_ch = hand_in_camera(R_rel, p, self.R_c0, self.t_c0)
        if n_clutter is None:
            n_clutter = int(np.sum(labels < 0))
        var = track.P.diagonal()
        w0 = self.w0_cov.diagonal()  # W0's own uncertainty is part of every relative pose's
        provisional = self._provisional_w0()
        if provisional is not None:
            # reported against W0 as fitted to the still frames so far (the state stays in the
            # first frame's W0 until the still start ends): no step of the one-frame W0's
            # error in the angles when W0 is refined
            R_k, t_k, cov_k = provisional
            turn = R_k.T @ self.R_c0
            R_rel, p = relative_pose(R_k, t_k, R_ch, t_ch)
            v, w = turn @ v, turn @ w
            w0 = cov_k.diagonal()
        rot_sigma = math.degrees(math.sqrt(max(var[self.model.rotation].sum() + w0[:3].sum(), 0.0)))
        pos_sigma = 1e3 * math.sqrt(max(var[self.model.position].sum() + w0[3:].sum(), 0.0))
        if n_assoc >= self.config.min_markers:
            track.updated_sigma = (rot_sigma, pos_sigma)
        elif not within_coast_limit((rot_sigma, pos_sigma), track.updated_sigma,
                                    self.config.coast_limit):  # a guess no longer worth a pose
            return FrameResult.empty(self._frame, det.timestamp, Status.LOST, det.count,
                                     track_id=self._track_id, side=self.layout.side,
                                     x=track.x.copy(), cov=track.P.copy())  # for the smoother
        return FrameResult(
            frame=self._frame, timestamp=det.timestamp, status=status, R_ch=R_ch, t_ch=t_ch,
            R=R_rel, p=p, v=v.copy(), w=w, cov=track.P.copy(), labels=labels,
            n_visible=n_assoc + sum(len(group) - 1 for group in (merged or {}).values()),
            n_clutter=n_clutter, nis=nis, nis_dof=dof, pos_sigma_mm=pos_sigma,
            rot_sigma_deg=rot_sigma, x=track.x.copy(), track_id=self._track_id,
            side=self.layout.side, merged=merged or {},
        )


def _undoubted(det: Detections) -> int:
    """The blobs the detector does not doubt. A retry (tracking/retries.py) widens the prior or
    the pixel noise and leaves the labels to the blobs' pattern; among doubted blobs (taken at
    the model's pixel noise: in the lamp's shade, merged knuckles) a labelling shifted by one
    marker along the knuckles passes the consistency test too (a right hand in ulnar deviation
    and supination: 4 deg off, then 36)."""
    return det.count if det.suspect is None else int(det.count - np.count_nonzero(det.suspect))
