"""A Stone Soup tracker on wristtrack's motion and measurement models: the peer-library filter.

Stone Soup (``pip install wristtrack[bench]``) supplies the filter and the association: its
``UnscentedKalmanPredictor`` and ``UnscentedKalmanUpdater`` and its ``PDA`` data associator
(``PDAHypothesiser``: detection probability, chi-square gate, clutter density). Our models are
wrapped as Stone Soup transition and measurement models; initialisation (labelling and the first
pose, which Stone Soup does not do for a rigid marker set) is wristtrack's own ``initialise``.

State. Stone Soup's state is a plain vector, so the orientation cannot live on SO(3) as in our
filter. We use a rotation vector relative to the initial pose: x = (phi, p, v, w), 12-D, with
R = exp(phi) the hand orientation relative to W0 (the hand frame at initialisation) and p, v, w
as in ``motion.ConstantRateModel``. The motion is that model's: R+ = exp(w dt) R, p+ = p + v dt,
constant v and w driven by random-walk accelerations of the same densities; Stone Soup's UKF
takes additive noise, so the noise covariance is the discrete one of that model in these
coordinates (exact for p and v, first-order for the rotation vector).

Measurements. Each marker is one measurement model (u, v, depth z of its centre, noise as
``observation.MeasurementNoise`` at the predicted depth; pixels only for frames without depth).
Stone Soup's associators assume one measurement per target, so the six markers are updated in
turn, each by a PDA over all blobs of the frame (PDA does not keep two markers off one blob, our
GNN does). Blobs without a depth reading are left out of a depth frame. Updated marker by
marker, it can take only each marker's own noise (``MarkerObservation.noise_variance``), not the
noise the markers share (skin slide, misregistration, ``noise_covariance``): the right model for
a rigid hand and a perfectly registered depth map, as in the plain rendered scenarios.
"""

from __future__ import annotations

from datetime import datetime, timedelta

import numpy as np
from stonesoup.base import Property
from stonesoup.dataassociator.probability import PDA
from stonesoup.hypothesiser.probability import PDAHypothesiser
from stonesoup.models.base import GaussianModel
from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
from stonesoup.models.transition.base import TransitionModel
from stonesoup.predictor.kalman import UnscentedKalmanPredictor
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track
from stonesoup.types.update import GaussianStateUpdate
from stonesoup.updater.kalman import UnscentedKalmanUpdater

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError, InputError
from wristtrack.geometry import so3_exp, so3_log
from wristtrack.hand import HandLayout
from wristtrack.tracking.generic_step import expected_markers
from wristtrack.tracking.initialise import initialise
from wristtrack.tracking.models import ConstantRateModel, ProcessNoise
from wristtrack.tracking.observation import MarkerObservation, MeasurementNoise
from wristtrack.tracking.tracker import FrameResult, Status, TrackerConfig

_EPOCH = datetime(2000, 1, 1)


def _rotvec_pose(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R relative to W0 (S,3,3), p (S,3)) of rotation-vector states X (S,12)."""
    return so3_exp(X[:, :3]), X[:, 3:6]


class RotvecConstantRate(TransitionModel, GaussianModel):
    """``ConstantRateModel`` in rotation-vector coordinates, additive discrete noise."""

    noise: ProcessNoise = Property(default=ProcessNoise(), doc="acceleration densities")

    @property
    def ndim_state(self) -> int:
        return 12

    def function(self, state, noise=False, **kwargs):
        dt = kwargs["time_interval"].total_seconds()
        X = np.asarray(state.state_vector, dtype=float).T  # (S, 12)
        out = X.copy()
        if dt:
            out[:, :3] = so3_log(so3_exp(X[:, 9:12] * dt) @ so3_exp(X[:, :3]))
            out[:, 3:6] += X[:, 6:9] * dt
        out = StateVectors(out.T)
        if noise is None or isinstance(noise, bool):
            noise = self.rvs(num_samples=out.shape[1], **kwargs) if noise else 0
        return out + noise

    def covar(self, time_interval, **kwargs) -> CovarianceMatrix:
        dt = time_interval.total_seconds()
        Q = np.zeros((12, 12))
        # noise a (density q) enters as v += a dt, p += a dt^2 / 2 with Var(a) = q / dt; the
        # angular acceleration likewise into w and (midpoint rule) the rotation
        for pos, vel, q in ((3, 6, self.noise.linear_accel), (0, 9, self.noise.angular_accel)):
            for i in range(3):
                Q[pos + i, pos + i] = q * dt**3 / 4
                Q[pos + i, vel + i] = Q[vel + i, pos + i] = q * dt**2 / 2
                Q[vel + i, vel + i] = q * dt
        return CovarianceMatrix(Q)


class MarkerMeasurement(NonLinearGaussianMeasurement):
    """One marker's (u, v[, z]) through wristtrack's ``MarkerObservation``."""

    observation: MarkerObservation = Property(doc="the measurement model of all markers")
    marker: int = Property(doc="marker index, MARKER_NAMES order")

    @property
    def ndim_meas(self) -> int:
        return self.observation.k

    def function(self, state, noise=False, **kwargs):
        X = np.asarray(state.state_vector, dtype=float).T
        k = self.observation.k
        y = self.observation(X)[:, self.marker * k : (self.marker + 1) * k]
        out = StateVectors(y.T)
        if noise is None or isinstance(noise, bool):
            noise = self.rvs(num_samples=out.shape[1], **kwargs) if noise else 0
        return out + noise


class StoneSoupTracker:
    """Per-frame tracker (``step`` as ``Tracker.step``) built from Stone Soup's UKF and PDA."""

    def __init__(
        self, camera: Camera, layout: HandLayout | None, config: TrackerConfig | None = None
    ):
        self.camera, self.layout = camera, layout
        self.config = config or TrackerConfig()
        p = self.config.ukf
        self.ukf_params = {"alpha": p.alpha, "beta": p.beta, "kappa": p.kappa}
        self.transition = RotvecConstantRate(noise=self.config.process)
        self.predictor = UnscentedKalmanPredictor(self.transition, **self.ukf_params)
        a = self.config.association_params
        self.p_detect, self.gate_prob = a.p_detect, a.gate_prob
        self.clutter_density = {  # expected clutter blobs per unit measurement volume
            3: a.clutter_rate / (camera.area * a.depth_range),
            2: a.clutter_rate / camera.area,
        }
        self.noise: MeasurementNoise = self.config.measurement
        self.R_c0: np.ndarray | None = None
        self.t_c0: np.ndarray | None = None
        self.track: Track | None = None
        self._obs: dict[bool, MarkerObservation] = {}
        self._frame = -1
        self._last = -np.inf

    def _observation(self, use_depth: bool) -> MarkerObservation:
        if use_depth not in self._obs:
            self._obs[use_depth] = MarkerObservation(
                self.camera, self.layout.points, self.R_c0, self.t_c0, _rotvec_pose, use_depth,
                self.noise,
            )
        return self._obs[use_depth]

    def step(self, det: Detections) -> FrameResult:
        if det.timestamp <= self._last:
            raise InputError(
                f"timestamp {det.timestamp} s does not follow {self._last} s; frames must come "
                "in strictly increasing time"
            )
        self._frame += 1
        self._last = det.timestamp
        when = _EPOCH + timedelta(seconds=det.timestamp)
        if self.track is None:
            return self._initialise(det, when)
        use_depth = self.config.use_depth and det.depth is not None
        obs = self._observation(use_depth)
        k = obs.k
        z = det.uv if k == 2 else np.column_stack((det.uv, det.depth))
        usable = np.flatnonzero(np.isfinite(z).all(axis=1))
        detections = [Detection(StateVector(z[i]), timestamp=when) for i in usable]
        blob_of = {id(d): int(i) for d, i in zip(detections, usable, strict=True)}

        prediction = self.predictor.predict(self.track[-1], timestamp=when)
        x_pred = np.asarray(prediction.state_vector, float)[:, 0]
        # markers in view at the predicted pose, by the tracker's own rule
        expected = expected_markers(obs, x_pred, self.camera, self.config.facing_cos)
        y_pred = obs(x_pred[None])[0]
        var = obs.noise_variance(x_pred, y_pred).reshape(obs.n_markers, k)
        labels = np.full(det.count, -1)
        n_assoc = 0
        for j in np.flatnonzero(expected):
            model = MarkerMeasurement(
                ndim_state=12, mapping=tuple(range(12)), noise_covar=np.diag(var[j]),
                observation=obs, marker=int(j),
            )
            updater = UnscentedKalmanUpdater(model, **self.ukf_params)
            hypothesiser = PDAHypothesiser(
                self.predictor, updater, clutter_spatial_density=self.clutter_density[k],
                prob_detect=self.p_detect, prob_gate=self.gate_prob,
            )
            hypotheses = PDA(hypothesiser).associate({self.track}, detections, when)[self.track]
            states, weights, best, best_w = [], [], None, -1.0
            for hyp in hypotheses:
                w = float(hyp.probability)
                states.append(updater.update(hyp) if hyp else hyp.prediction)
                weights.append(w)
                if hyp and w > best_w:
                    best, best_w = hyp, w
            mean, covar = _reduce_mixture(states, weights)
            self.track.append(GaussianStateUpdate(mean, covar, hypotheses, timestamp=when))
            missed = 1.0 - sum(weights[1:]) if len(weights) > 1 else 1.0
            if best is not None and best_w > missed:
                blob = blob_of[id(best.measurement)]
                n_assoc += 1
                if labels[blob] < 0:
                    labels[blob] = j
        if len(self.track) > 12:  # only the last state is needed: keep memory flat
            del self.track.states[:-2]
        status = Status.TRACKING if n_assoc else Status.COASTING
        if n_assoc == 0 and len(self.track) and self.track[-1].timestamp != when:
            self.track.append(GaussianState(prediction.state_vector, prediction.covar, when))
        return self._result(det, status, labels, n_assoc)

    def _initialise(self, det: Detections, when: datetime) -> FrameResult:
        try:
            init = initialise(det, self.camera, self.layout)
        except InitialisationError:
            return FrameResult.empty(self._frame, det.timestamp, Status.INITIALISING, det.count)
        self.R_c0, self.t_c0, self.layout = init.R_ch, init.t_ch, init.layout
        rot = np.kron(np.eye(2), self.R_c0.T)  # camera-frame pose covariance -> W0
        P0 = ConstantRateModel().initial_covariance(rot @ init.cov @ rot.T)
        self.track = Track([GaussianState(StateVector(np.zeros(12)), CovarianceMatrix(P0), when)])
        return self._result(det, Status.TRACKING, init.labels, int(np.sum(init.labels >= 0)))

    def _result(self, det, status, labels, n_assoc) -> FrameResult:
        state = self.track[-1]
        x = np.asarray(state.state_vector, dtype=float).ravel()
        R = so3_exp(x[:3])
        P = np.asarray(state.covar, dtype=float)
        return FrameResult(
            frame=self._frame, timestamp=det.timestamp, status=status, R_ch=self.R_c0 @ R,
            t_ch=self.R_c0 @ x[3:6] + self.t_c0, R=R, p=x[3:6].copy(), v=x[6:9].copy(),
            w=x[9:12].copy(), cov=P, labels=labels, n_visible=n_assoc,
            n_clutter=int(np.sum(labels < 0)),
        )


def _reduce_mixture(states, weights) -> tuple[StateVector, CovarianceMatrix]:
    """The PDA's moment-matched Gaussian of the per-hypothesis posteriors: Stone Soup's
    ``gm_reduce_single`` formula in plain floats (that function divides by its Probability
    type, turning the weights into Python objects: ~25 ms a call)."""
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    means = np.column_stack([np.asarray(s.state_vector, dtype=float).ravel() for s in states])
    covs = np.stack([np.asarray(s.covar, dtype=float) for s in states])
    mean = means @ w
    d = means - mean[:, None]
    covar = np.einsum("k,kij->ij", w, covs) + (d * w) @ d.T
    return StateVector(mean), CovarianceMatrix(0.5 * (covar + covar.T))
