"""The tracker: one frame of detections in, one wrist estimate out.

A small state machine: ``initialising`` until the least-squares initialisation succeeds, then
``tracking`` (``coasting`` for a frame where no marker could be associated), ``lost`` after too
many frames with too few markers or too many updates in a row whose normalised innovation
squared is beyond its chi-square bound, from where it re-initialises by itself by fitting the
layout.
The fixed frame W0 is the hand frame of the first initialisation and never moves afterwards.

A tracking frame of the default configuration takes a fast path (_FastStep) that computes the
same filter in far fewer NumPy calls, or in one compiled call where numba is installed; every
other configuration and every unusual frame takes the generic path (Tracker._generic_frame),
which is the reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import StrEnum
from functools import lru_cache

import numpy as np
from scipy.special import chdtri

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError, InputError
from wristtrack.filter import associate as assoc
from wristtrack.filter import ukf
from wristtrack.geometry import so3_log
from wristtrack.hand import HandLayout
from wristtrack.tracking import compiled as fast_kernel
from wristtrack.tracking.initialise import initialise
from wristtrack.tracking.models import (
    MODELS,
    ConstantRateModel,
    ProcessNoise,
    quat_exp,
    quat_mul,
    quat_normalised,
    quat_of_matrix,
    quat_to_matrix,
)
from wristtrack.tracking.observation import MarkerObservation, MeasurementNoise


class Status(StrEnum):
    INITIALISING = "initialising"  # no estimate yet: waiting for all six markers
    TRACKING = "tracking"  # estimate updated with this frame's markers
    COASTING = "coasting"  # estimate predicted only: no marker associated in this frame
    LOST = "lost"  # too long without enough markers, or innovations inconsistent: no estimate


@dataclass(frozen=True)
class TrackerConfig:
    model: str = "default"  # "default" (SO(3) error state, constant rate) or "paper"
    association: str = "gnn"  # "gnn", "jpda" or "paper"
    use_depth: bool = True  # depth of each marker in every update (when the frame has depth)
    measurement: MeasurementNoise = MeasurementNoise()
    process: ProcessNoise = ProcessNoise()
    association_params: assoc.AssociationParams = assoc.AssociationParams()
    ukf: ukf.UKFParams = ukf.UKFParams()
    min_markers: int = 3  # fewer associated markers than this counts towards being lost
    lost_after: int = 15  # consecutive such frames before declaring the track lost
    max_gap: float = 0.5  # s; a longer gap between frames loses the track
    facing_cos: float = 0.05  # a marker whose palm faces away more than this is not expected
    # Innovation consistency: an update whose NIS exceeds this chi-square quantile is
    # inconsistent; this many in a row lose the track (0 = never). A consistent filter sees
    # such a run with probability (1 - quantile)^n, ~1e-15 here.
    nis_quantile: float = 0.999
    nis_lost_after: int = 5
    # Manoeuvres: a frame whose association fails (fewer than min_markers markers, or an
    # update beyond the NIS quantile) although enough blobs are there is associated again with
    # the prior's velocity variances raised by (a dt)^2, (alpha dt)^2 for each (a m/s^2,
    # alpha rad/s^2) in turn: an unmodelled acceleration (a fast reach peaks at ~15 m/s^2).
    # A retry is kept only if its update is consistent. () = off (the paper's method).
    manoeuvre_accel: tuple[tuple[float, float], ...] = ((15.0, 15.0), (45.0, 45.0))

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown model {self.model!r}; choose one of {', '.join(MODELS)}")
        if self.association not in assoc.METHODS:
            raise ValueError(
                f"unknown association {self.association!r}; choose one of "
                f"{', '.join(assoc.METHODS)}"
            )

    @classmethod
    def paper(cls, **kw) -> TrackerConfig:
        """The paper's method: Euler-angle state, per-blob association, depth only to initialise.

        No innovation-consistency loss: the paper has none (and its filter is not consistent).
        """
        kw.setdefault("nis_lost_after", 0)
        kw.setdefault("manoeuvre_accel", ())
        return cls(model="paper", association="paper", use_depth=False, **kw)


@dataclass(frozen=True)
class FrameResult:
    """The estimate for one frame. Poses are NaN where ``status`` has no estimate."""

    frame: int
    timestamp: float
    status: Status
    R_ch: np.ndarray  # (3,3) hand -> camera
    t_ch: np.ndarray  # (3,) wrist in camera coordinates, m
    R: np.ndarray  # (3,3) hand relative to W0
    p: np.ndarray  # (3,) wrist in W0, m
    v: np.ndarray  # (3,) m/s in W0
    w: np.ndarray  # (3,) rad/s in W0
    cov: np.ndarray | None  # tangent covariance of the state
    labels: np.ndarray  # (M,) marker index per blob, -1 = clutter
    n_visible: int  # markers associated in this frame
    n_clutter: int  # blobs taken as clutter
    nis: float = np.nan  # normalised innovation squared of the update
    nis_dof: int = 0
    pos_sigma_mm: float = np.nan  # 1-sigma position uncertainty (root of the variance trace)
    rot_sigma_deg: float = np.nan  # 1-sigma orientation uncertainty
    x: np.ndarray | None = None  # the filter state (model.initial_state layout); for smoothing
    track_id: int = -1  # which initialisation this estimate descends from (0 = the first)
    side: str = "right"  # the hand's side (from its layout): signs of the anatomical angles

    @property
    def has_estimate(self) -> bool:
        return self.status in (Status.TRACKING, Status.COASTING)


_NAN3 = np.full(3, np.nan)
_NAN33 = np.full((3, 3), np.nan)


@dataclass
class _Track:
    x: np.ndarray
    P: np.ndarray
    timestamp: float
    weak_frames: int = 0
    inconsistent_frames: int = 0  # consecutive updates with NIS above its chi-square quantile
    R_prev: np.ndarray | None = None


@dataclass
class Tracker:
    """Feed ``step`` one frame of detections at a time, in time order."""

    camera: Camera
    layout: HandLayout | None = None
    config: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self) -> None:
        self.model = MODELS[self.config.model](self.config.process)
        self.assoc_params = replace(self.config.association_params, image_area=self.camera.area)
        self.R_c0: np.ndarray | None = None
        self.t_c0: np.ndarray | None = None
        self._track: _Track | None = None
        self._obs: dict[bool, MarkerObservation] = {}
        self._fast: _FastStep | bool | None = None  # built on first use (W0 must be fixed)
        self._frame = -1
        self._last_timestamp = -np.inf
        self._initialisations = 0
        self.status = Status.INITIALISING
        self.last_init_error: str | None = None
        self.max_blobs_seen = 0  # most blobs in a frame offered for initialisation

    # ------------------------------------------------------------------------------- stepping

    def step(self, det: Detections, labels: np.ndarray | None = None) -> FrameResult:
        """Process one frame. ``labels`` (M,) optionally names the blobs for initialisation."""
        if det.timestamp <= self._last_timestamp:
            raise InputError(
                f"timestamp {det.timestamp} s does not follow {self._last_timestamp} s; "
                "frames must come in strictly increasing time"
            )
        self._frame += 1
        self._last_timestamp = det.timestamp
        track = self._track
        if track is not None and det.timestamp - track.timestamp > self.config.max_gap:
            self._lose()
            track = None
        if track is None:
            return self._try_initialise(det, labels)
        return self._track_frame(det, track)

    def _lose(self) -> None:
        self._track = None
        self.status = Status.LOST

    def _empty(self, det: Detections, status: Status) -> FrameResult:
        return FrameResult(
            self._frame, det.timestamp, status, _NAN33, _NAN3, _NAN33, _NAN3, _NAN3, _NAN3,
            None, np.full(det.count, assoc.CLUTTER), 0, det.count,
        )

    def _try_initialise(self, det: Detections, labels: np.ndarray | None) -> FrameResult:
        self.max_blobs_seen = max(self.max_blobs_seen, det.count)
        try:
            init = initialise(det, self.camera, self.layout, labels=labels)
        except InitialisationError as e:
            self.last_init_error = str(e)  # why the latest attempt failed, for the run's report
            return self._empty(det, self.status)
        if self.R_c0 is None:  # the first initialisation fixes W0 for good
            self.R_c0, self.t_c0 = init.R_ch, init.t_ch
            self.layout = init.layout
        R = self.R_c0.T @ init.R_ch
        p = self.R_c0.T @ (init.t_ch - self.t_c0)
        # the initialisation's covariance is over camera-frame perturbations; rotate it to W0
        rot = np.kron(np.eye(2), self.R_c0.T)
        pose_cov = rot @ init.cov @ rot.T
        x = self.model.initial_state(R, p)
        P = self.model.initial_covariance(pose_cov)
        self._track = _Track(x, P, det.timestamp, R_prev=R)
        self._initialisations += 1
        self.status = Status.TRACKING
        n_markers = int(np.sum(init.labels >= 0))
        return self._result(det, Status.TRACKING, init.labels, n_markers, np.nan, 0)

    def _observation(self, use_depth: bool) -> MarkerObservation:
        if use_depth not in self._obs:
            self._obs[use_depth] = MarkerObservation(
                self.camera, self.layout.points, self.R_c0, self.t_c0, self.model.pose,
                use_depth, self.config.measurement,
            )
        return self._obs[use_depth]

    def _track_frame(self, det: Detections, track: _Track) -> FrameResult:
        cfg = self.config
        dt = det.timestamp - track.timestamp
        out = self._filter_frame(det, track, dt)
        if det.count >= cfg.min_markers and hasattr(self.model, "angular_velocity"):
            out = self._manoeuvre_retry(det, track, dt, out)
        x, P, labels, n_assoc, nis, dof = out
        if not (_all_finite(x) and _all_finite(P)):  # never let a numerical failure leak out
            self._lose()
            return self._empty(det, Status.LOST)
        track.weak_frames = track.weak_frames + 1 if n_assoc < cfg.min_markers else 0
        if track.weak_frames > cfg.lost_after:
            self._lose()
            return self._empty(det, Status.LOST)
        if dof and cfg.nis_lost_after:  # frames without an update neither count nor reset
            high = nis > _nis_limit(cfg.nis_quantile, dof)
            track.inconsistent_frames = track.inconsistent_frames + 1 if high else 0
            if track.inconsistent_frames >= cfg.nis_lost_after:
                self._lose()  # the estimate no longer explains the markers: start again
                return self._empty(det, Status.LOST)
        track.x, track.P, track.timestamp = x, P, det.timestamp
        status = Status.TRACKING if n_assoc else Status.COASTING
        self.status = status
        one_to_one = cfg.association == "gnn"  # then the blobs not taken are the clutter
        n_clutter = len(labels) - n_assoc if one_to_one else int(np.sum(labels < 0))
        return self._result(det, status, labels, n_assoc, nis, dof, dt, n_clutter)

    def _filter_frame(self, det: Detections, track: _Track, dt: float) -> tuple:
        """Predict, associate, update: (x, P, labels, markers associated, NIS, its dof)."""
        fast = self._fast_step(det)
        out = fast.step(det, track.x, track.P, dt) if fast is not None else None
        return self._generic_frame(det, track, dt) if out is None else out

    def _manoeuvre_retry(self, det: Detections, track: _Track, dt: float, out: tuple) -> tuple:
        """``out``, or a consistent re-association assuming a manoeuvre (see TrackerConfig)."""
        cfg, model = self.config, self.model
        n_assoc, nis, dof = out[3], out[4], out[5]
        if n_assoc >= cfg.min_markers and not (dof and nis > _nis_limit(cfg.nis_quantile, dof)):
            return out
        for accel, angular in cfg.manoeuvre_accel:
            P = track.P.copy()
            for part, a in ((model.velocity, accel), (model.angular_velocity, angular)):
                i = np.arange(P.shape[0])[part]
                P[i, i] += (a * dt) ** 2
            retry = self._filter_frame(det, replace(track, P=P), dt)
            n, r_nis, r_dof = retry[3], retry[4], retry[5]
            if n >= max(cfg.min_markers, n_assoc) and r_nis <= _nis_limit(cfg.nis_quantile, r_dof):
                return retry
        return out

    def _fast_step(self, det: Detections) -> _FastStep | None:
        """The fast path where this configuration and frame allow it (see _FastStep)."""
        if self._fast is None:
            cfg = self.config
            obs = self._observation(True)
            usable = (
                type(self.model) is ConstantRateModel
                and cfg.association == "gnn"
                and cfg.use_depth
                and obs.has_column_path
            )
            self._fast = _FastStep(self.model, obs, cfg, self.assoc_params) if usable else False
        if not self._fast or det.depth is None or det.count == 0:
            return None
        if not _all_finite(det.depth):  # a blob without depth is scored on its pixels alone
            return None
        return self._fast

    def _generic_frame(self, det: Detections, track: _Track, dt: float) -> tuple:
        """Any configuration, any frame: (x, P, labels, markers associated, NIS, its dof)."""
        cfg, model = self.config, self.model
        use_depth = cfg.use_depth and det.depth is not None
        obs = self._observation(use_depth)
        k = obs.k
        x, P, pred = ukf.predict_with_measurement(
            model, track.x, track.P, dt, model.process_noise(dt), obs, params=cfg.ukf
        )
        r_var = obs.noise_variance(pred.y)
        expected = self._expected_markers(x, obs)

        n_markers = obs.n_markers
        y_hat = pred.y.reshape(n_markers, k)[expected]
        S = _diagonal_blocks(pred.Pyy, n_markers, k)[expected] + _diag_blocks(r_var, n_markers, k)[
            expected
        ]
        z = det.uv if k == 2 else np.column_stack((det.uv, det.depth))
        llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, self.assoc_params)
        gated = assoc.gate(d2, z, self.assoc_params)
        marker_ids = np.flatnonzero(expected)

        nis, dof = np.nan, 0
        if cfg.association == "jpda":
            beta = assoc.jpda_marginals(assoc.pair_scores(llr, self.assoc_params), gated)
            labels = assoc.labels_from_marginals(beta)
            x, P = self._jpda_update(x, P, pred, r_var, z, beta, marker_ids, k)
        else:
            if cfg.association == "gnn":
                local = assoc.associate_gnn(assoc.pair_scores(llr, self.assoc_params), gated)
            else:
                local = assoc.associate_paper(llr, self.assoc_params)
            labels = np.full(det.count, assoc.CLUTTER)
            labels[local >= 0] = marker_ids[local[local >= 0]]
            rows, values = _stack_rows(labels, z, k)
            if rows.size:
                res = ukf.update(model, x, P, pred, values, r_var[rows], rows=rows)
                x, P, nis, dof = res.x, res.P, res.nis, res.dof

        n_assoc = int(np.unique(labels[labels >= 0]).size)
        return x, P, labels, n_assoc, nis, dof

    def _expected_markers(self, x: np.ndarray, obs: MarkerObservation) -> np.ndarray:
        """Markers that can be seen at the predicted pose: in the image, palm not turned away."""
        pts = obs.marker_points(x[None])[0]
        R_rel, _ = self.model.pose(x[None])
        normal = self.R_c0 @ R_rel[0, :, 2]
        facing = -(pts @ normal) / np.sqrt(np.einsum("ij,ij->i", pts, pts))
        ok = (facing > self.config.facing_cos) & (pts[:, 2] > 0)
        return ok & self.camera.in_image(self.camera.project(pts))

    def _jpda_update(self, x, P, pred, r_var, z, beta, marker_ids, k):
        groups, candidates, weights = [], [], []
        for col, j in enumerate(marker_ids):
            hit = np.flatnonzero(beta[:, col] > 1e-6)
            if hit.size == 0:
                continue
            Z = z[hit].copy()
            if k == 3:  # a blob without depth carries no depth information: use the prediction
                missing = ~np.isfinite(Z[:, 2])
                Z[missing, 2] = pred.y[j * k + 2]
            groups.append(np.arange(j * k, j * k + k))
            candidates.append(Z)
            weights.append(beta[hit, col])
        if not groups:
            return x, P
        return ukf.pda_update(self.model, x, P, pred, r_var, groups, candidates, weights)

    # -------------------------------------------------------------------------------- output

    def _result(
        self, det, status, labels, n_assoc, nis, dof, dt=None, n_clutter=None
    ) -> FrameResult:
        track = self._track
        R_rel, p = self.model.pose(track.x[None])
        R_rel, p = R_rel[0], p[0]
        v, w = self.model.velocities(track.x)
        if math.isnan(w[0]):  # the paper's state has no rate (all NaN): differentiate R
            w = (
                so3_log(R_rel @ track.R_prev.T) / dt
                if dt and track.R_prev is not None
                else np.zeros(3)
            )
        track.R_prev = R_rel
        R_ch = self.R_c0.dot(R_rel)
        t_ch = self.R_c0.dot(p) + self.t_c0
        if n_clutter is None:
            n_clutter = int(np.sum(labels < 0))
        var = track.P.diagonal()
        rot_sigma = math.degrees(math.sqrt(max(var[self.model.rotation].sum(), 0.0)))
        pos_sigma = 1e3 * math.sqrt(max(var[self.model.position].sum(), 0.0))
        return FrameResult(
            self._frame, det.timestamp, status, R_ch, t_ch, R_rel, p, v.copy(), w, track.P.copy(),
            labels, n_assoc, n_clutter, nis, dof, pos_sigma, rot_sigma, track.x.copy(),
            self._initialisations - 1, self.layout.side,
        )


_ONES = np.ones(256)


@lru_cache(maxsize=64)
def _nis_limit(quantile: float, dof: int) -> float:
    return float(chdtri(dof, 1.0 - quantile))  # chi2 quantile without importing scipy.stats


def _all_finite(a: np.ndarray) -> bool:
    """np.isfinite(a).all() in one cheap call: a NaN or an inf anywhere makes the sum non-finite
    (finite entries could only overflow it beyond 1e308). The sum is a dot product with ones,
    which costs a fraction of a NumPy reduction's call overhead."""
    flat = a.ravel()
    if flat.size > _ONES.size:
        return bool(np.isfinite(flat).all())
    return math.isfinite(flat.dot(_ONES[: flat.size]))


def _diagonal_blocks(A: np.ndarray, n: int, k: int) -> np.ndarray:
    """The n diagonal (k, k) blocks of A (n*k, n*k) as an (n, k, k) array."""
    idx = np.arange(n)[:, None] * k + np.arange(k)
    return A[idx[:, :, None], idx[:, None, :]]


def _diag_blocks(d: np.ndarray, n: int, k: int) -> np.ndarray:
    out = np.zeros((n, k, k))
    out[:, np.arange(k), np.arange(k)] = d.reshape(n, k)
    return out


def _stack_rows(labels: np.ndarray, z: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Measurement rows and values of the associated blobs (a blob's NaN depth is left out)."""
    blobs = np.flatnonzero(labels >= 0)
    rows = labels[blobs, None] * k + np.arange(k)
    values = z[blobs]
    ok = np.isfinite(values)
    return rows[ok], values[ok]


class _FastStep:
    """One tracking frame of the default configuration in a few dozen whole-array operations.

    The same filter as ``Tracker._generic_frame`` (augmented UKF prediction with measurement,
    one-to-one association, Cholesky update), arranged for speed: a frame's arrays are so small
    that the cost is the number of NumPy calls and Python statements, not arithmetic. The 37
    sigma points are columns of one buffer (see SigmaColumns); the model writes its propagated
    points and lifts straight into it (SigmaPropagator), the observation its measurements, and
    one matrix product gives the joint covariance of measurements and state. The orientation
    is a quaternion, single poses are Python floats. Used for the constant-rate model with GNN
    association and depth on an undistorted camera, for frames whose blobs all have depth and
    whose markers are all expected in view; anything else goes the generic way (``step``
    returns None before changing anything). Where numba is installed, ``step`` runs the same
    computation as one compiled call (fast_kernel) and falls back to ``numpy_step``, the
    reference, for the frames that call declines.

    Rows of the sigma buffer (m = 3 x markers), the model's rows below the measurements:
      [0, m)         measurements, axis-major (u of each marker, then v, then z)
      [m, m+12)      tangent lifts (dphi, dp, dv, dw); with the measurements, the UT's input
      [m, m+46)      SigmaPropagator's rows, among them the measurement features
    """

    def __init__(
        self,
        model: ConstantRateModel,
        obs: MarkerObservation,
        config: TrackerConfig,
        assoc_params: assoc.AssociationParams,
    ):
        self.obs, self.facing_cos = obs, config.facing_cos
        self.n_markers = n = obs.n_markers
        self.m = m = 3 * n
        self.dim = d = model.dim
        self.sigma = ukf.SigmaColumns(d, model.noise_dim, config.ukf)
        self.propagator = prop = model.sigma_propagator()
        self.gate = assoc.BlockGate(n, assoc_params)
        rows = np.zeros((m + prop.ROWS, self.sigma.offsets.shape[1]))
        self._measured, self._ut_rows, self._model_rows = rows[:m], rows[: m + d], rows[m:]
        self._features = rows[m:][prop.FEATURES]
        self._centre_pvw = self._features[1:10, 0]  # the propagated centre's p, v, w
        self._cov = np.empty((m + d, m + d + 1))  # joint covariance, last column free
        self._noise = self._cov.reshape(-1)[: m * (m + d + 2) : m + d + 2]  # measured diagonal
        # the whole step compiled (fast_kernel) where numba is installed; the NumPy code below
        # is the reference and takes the frames the compiled step declines
        self._kernel = fast_kernel.compiled_step()
        self._kernel_args = self._compiled_constants(model, config) if self._kernel else None

    def _compiled_constants(self, model: ConstantRateModel, config: TrackerConfig) -> tuple:
        obs, gate, sigma = self.obs, self.gate, self.sigma
        par = fast_kernel.constants(
            sigma.scale, obs.camera, obs.noise, model.noise, config.facing_cos,
            gate.constant, gate.half_gate,
        )  # fmt: skip
        layout = np.ascontiguousarray(obs.layout_T.T)
        R_c0, t_c0 = np.ascontiguousarray(obs.R_c0), np.ascontiguousarray(obs.t_c0)
        return layout, R_c0, t_c0, sigma.mean_weights.copy(), sigma.cov_weights.copy(), par

    def step(self, det: Detections, x: np.ndarray, P: np.ndarray, dt: float) -> tuple | None:
        """(x, P, labels, markers associated, NIS, its dof) as _generic_frame, or None."""
        if self._kernel is not None:
            # contiguous blobs and a float dt: numba compiles once per argument type
            uv, depth = np.ascontiguousarray(det.uv), np.ascontiguousarray(det.depth)
            code, x_new, P_new, labels, n_pairs, nis = self._kernel(
                x, P, float(dt), uv, depth, *self._kernel_args
            )
            if code == fast_kernel.OK:
                return x_new, P_new, labels, n_pairs, nis, 3 * n_pairs
        return self.numpy_step(det, x, P, dt)

    def numpy_step(self, det: Detections, x: np.ndarray, P: np.ndarray, dt: float) -> tuple | None:
        """``step`` in NumPy calls only: the reference for the compiled step."""
        m, n, d, C, obs = self.m, self.n_markers, self.dim, self._cov, self.obs
        # predict: sigma points through the motion and the measurement, one set for both
        q_state = quat_of_matrix(x[:9].tolist())
        self.sigma.set_covariance(P)
        q_centre = self.propagator.propagate(
            x, self.sigma.offsets, dt, q_state, self._model_rows
        )
        obs.measure_columns(self._features, self._measured)
        means = self.sigma.moments(self._ut_rows, C)
        y = means.tolist()
        # the predicted state: the mean lift retracted about the propagated centre
        q = quat_mul(quat_exp(*y[m : m + 3]), quat_mul(q_centre, q_state))
        pvw = self._centre_pvw + means[m + 3 :]
        if not obs.all_visible(quat_to_matrix(q), pvw[:3].tolist(), self.facing_cos):
            return None
        self._noise += obs.noise_variances(y)  # C's measurement block is now Pyy + R

        # associate
        D = self._differences(det, means)
        found = self.gate.distances(C[:m, :m], D)
        if found is None:
            return None
        pairs = self.gate.assign(*found)

        # update with the associated markers' pixels and depths
        M = D.shape[1]
        labels = [assoc.CLUTTER] * M
        if not pairs:
            x = np.array(quat_to_matrix(quat_normalised(q)) + pvw.tolist())
            return x, ukf.symmetrise(C[m:, m : m + d]), np.array(labels), 0, np.nan, 0
        for j, b in pairs:
            labels[b] = j
        rows = [j + n * a for a in range(3) for j, _ in pairs]  # (axis, marker), axis-major
        # z_b - y_j of each associated pair: D's column-major storage is D.T, C-contiguous
        innovation = D.T.take([b * m + r for r, (_, b) in zip(rows, pairs * 3, strict=True)])
        if len(pairs) == n:  # all markers, in order
            rows = None
            C[:m, -1] = innovation
        else:
            C[rows, -1] = innovation
        dx, P, nis = ukf.joint_correct(C, m, rows)
        q = quat_normalised(quat_mul(quat_exp(*dx[:3].tolist()), q))
        pvw += dx[3:]
        x = np.array(quat_to_matrix(q) + pvw.tolist())
        return x, P, np.array(labels), len(pairs), nis, 3 * len(pairs)

    def _differences(self, det: Detections, means: np.ndarray) -> np.ndarray:
        """z_i - y_j for every blob i and measurement row j: (m, M) in the measurement's rows,
        stored column-major (blob-major), the layout the triangular solve works in."""
        n, M = self.n_markers, det.count
        Dt = np.empty((M, self.m))
        uv = Dt[:, : 2 * n].reshape(M, 2, n)
        np.subtract(det.uv[:, :, None], means[: 2 * n].reshape(2, n), out=uv)
        np.subtract(det.depth[:, None], means[2 * n : self.m], out=Dt[:, 2 * n :])
        return Dt.T
