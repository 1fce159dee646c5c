"""One filter step of the markers for any configuration: predict, associate, update.

The reference the compiled step (tracking/compiled.py, kernel.py) is tested against, and the
path every configuration and frame it declines takes: any state model, the paper's association
or JPDA, colour alone. It reads like the paper: the unscented prediction of the state and of
each marker's measurement, each blob scored against each marker that can be seen, the pairs
chosen, and one update with all the chosen pairs (a blob where markers merged measuring the
mean of theirs: tracking/merged.py). The tracker (tracking/tracker.py) decides what to do
with the result (the retries of tracking/retries.py, the NIS test, the skin's depth update).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.filter import associate as assoc
from wristtrack.filter import ukf
from wristtrack.tracking import merged
from wristtrack.tracking.config import TrackerConfig
from wristtrack.tracking.observation import MarkerObservation


class StepResult(NamedTuple):
    """A frame's markers update: the posterior, each blob's marker (-1: clutter), how many
    markers were associated, the update's NIS with its degrees of freedom (NaN, 0 without
    an update or with JPDA's), and the blobs where markers merged (blob -> its markers,
    tracking/merged.py)."""

    x: np.ndarray
    P: np.ndarray
    labels: np.ndarray
    n_assoc: int
    nis: float
    dof: int
    merged: dict[int, tuple[int, ...]]


def generic_step(model, obs: MarkerObservation, x: np.ndarray, P: np.ndarray, dt: float,
                 det: Detections, config: TrackerConfig, assoc_params: assoc.AssociationParams,
                 camera: Camera, iterations: int = 0) -> StepResult:
    """The step of state model ``model`` from (x, P) over ``dt`` s with the blobs ``det``,
    measured by ``obs`` (with depth or colour alone, W0 its own); the one-to-one
    update corrected ``iterations`` more times over its posterior (ukf.iterated_update)."""
    k = obs.k
    x, P, pred = ukf.predict_with_measurement(
        model, x, P, dt, model.process_noise(dt), obs, params=config.ukf
    )
    prior = (x, P)
    own = obs.noise_variance(x, pred.y)
    shared = obs.shared_covariance(x)
    expected = expected_markers(obs, x, camera, config.facing_cos)

    n_markers = obs.n_markers
    y_hat = pred.y.reshape(n_markers, k)[expected]
    # Each marker is matched to a blob by its own noise: the noise the markers share (skin
    # slide, misregistration) moves them together, and counted in every marker's gate
    # alone it let clutter beside a marker in. The update takes all of it.
    S = diagonal_blocks(pred.Pyy + np.diag(own), n_markers, k)[expected]
    z = det.uv if k == 2 else np.column_stack((det.uv, det.depth))
    llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, assoc_params)
    gated = assoc.gate(d2, z, assoc_params)
    marker_ids = np.flatnonzero(expected)

    nis, dof, merged_markers = np.nan, 0, {}
    if config.association == "jpda":
        beta = assoc.jpda_marginals(assoc.pair_scores(llr, assoc_params), gated)
        labels = assoc.labels_from_marginals(beta)
        x, P = _jpda_update(model, x, P, pred, np.diag(own) + shared, z, beta, marker_ids, k)
    else:
        if config.association == "gnn":
            local = assoc.associate_gnn(assoc.pair_scores(llr, assoc_params), gated)
        else:
            local = assoc.associate_paper(llr, assoc_params)
        labels = np.full(det.count, assoc.CLUTTER)
        labels[local >= 0] = marker_ids[local[local >= 0]]
        groups = {}
        # only a marker left without a blob can share one (and most frames have none)
        unmatched = np.count_nonzero(expected) > np.count_nonzero(labels >= 0)
        if config.merged_blobs and config.association == "gnn" and unmatched:
            y_all = pred.y.reshape(n_markers, k)
            diameter = merged.marker_diameters(camera.fx, obs.marker_points(x[None])[0, :, 2])
            groups = merged.merged_groups(y_all[:, :2], diameter, expected, labels, det.uv)
        res = _labelled_update(model, obs, prior, pred, (own, shared), det, z, labels, config,
                               iterations, groups)
        if res is not None:
            x, P, nis, dof = res.x, res.P, res.nis, res.dof
            merged_markers = {int(b): tuple(int(m) for m in group) for b, group in groups.items()}

    n_assoc = int(np.unique(labels[labels >= 0]).size)
    return StepResult(x, P, labels, n_assoc, nis, dof, merged_markers)


# The prior a fit's covariance is taken from: far wider than what one frame's markers tell.
_FIT_PRIOR_ROT = np.radians(10.0)  # rad
_FIT_PRIOR_POS = 0.02  # m
_FIT_ITERATIONS = 2


def fit_covariance(model, obs: MarkerObservation, x: np.ndarray, det: Detections,
                   labels: np.ndarray, config: TrackerConfig) -> np.ndarray:
    """The covariance of state ``x``, a fit to the blobs ``det`` labelled ``labels``, under the
    filter's measurement model: one update from a prior at ``x`` too wide to matter, with the
    blobs' own noise and the noise the markers share (skin slide, misregistration). The fit's
    own covariance counts independent blob errors at a fixed pixel noise only: after a long
    gap with every realism effect, fresh fits 2-4 deg off said 0.5-0.8 deg; this says
    0.9-1.6 (benchmarks/dropped.py's cuts). The velocities keep the prior's spread."""
    pose = np.diag([_FIT_PRIOR_ROT**2] * 3 + [_FIT_PRIOR_POS**2] * 3)
    P = model.initial_covariance(pose)
    pred = ukf.predict_measurement(model, x, P, obs, config.ukf)
    noise = (obs.noise_variance(x, pred.y), obs.shared_covariance(x))
    z = det.uv if obs.k == 2 else np.column_stack((det.uv, det.depth))
    # Linearised over the wide prior, h's curvature there counts as noise (rotation sigmas
    # 1.5x too wide on a tilted hand): linearise it over the posterior instead.
    post = _labelled_update(model, obs, (x, P), pred, noise, det, z, labels, config,
                            _FIT_ITERATIONS)
    return P if post is None else post.P


def _labelled_update(model, obs: MarkerObservation, prior: tuple[np.ndarray, np.ndarray],
                     pred: ukf.MeasurementPrediction, noise: tuple[np.ndarray, np.ndarray],
                     det: Detections, z: np.ndarray, labels: np.ndarray, config: TrackerConfig,
                     iterations: int, groups: dict[int, np.ndarray] | None = None,
                     ) -> ukf.UpdateResult | None:
    """The update of ``prior`` (its measurement prediction ``pred``; ``noise``: each marker's
    own variances (6*k,) and the covariance the markers share (6*k, 6*k)) with the blobs ``z``
    of ``det`` that ``labels`` names as markers (a blob of ``groups`` as the mean of its
    markers, tracking/merged.py), corrected ``iterations`` more times over its posterior
    (ukf.iterated_update); None where no blob is a marker."""
    A, values, blob, component = merged.measurement_map(labels, z, obs.k, obs.n_markers, groups)
    if values.size == 0:
        return None
    own, shared = noise
    # Each blob's own noise is its own: two blobs the paper's rule gives one marker measure it
    # with independent errors. Mapped as A diag(own) A^T, their rows came out identical, the
    # innovation covariance singular along their difference (NIS 1e12) and the update forced
    # the two depths to agree. Without shared markers between rows, the two are the same.
    R_u = A @ shared @ A.T + np.diag((A**2) @ own
                                     + _blob_variance(obs, det, blob, component, pred, groups))
    res = ukf.update(model, *prior, pred.mapped(A), values, R_u)
    if iterations:
        res = ukf.iterated_update(model, prior, (res.x, res.P), lambda X: obs(X) @ A.T,
                                  values, R_u, None, config.ukf, iterations)
    return res


def _blob_variance(obs: MarkerObservation, det: Detections, blob: np.ndarray,
                   component: np.ndarray, pred: ukf.MeasurementPrediction,
                   groups: dict[int, np.ndarray] | None) -> np.ndarray:
    """(r,) what each row's blob adds to the update's noise: its pixel rows the blob's own
    ``obs.blob_variance``, a merged blob's rows the spread of its centre about its markers'
    mean (merged.merge_variance)."""
    added = obs.blob_variance(det.suspect, det.count)[blob] * (component < 2)
    if groups:
        y = pred.y.reshape(obs.n_markers, obs.k)
        extra = merged.merge_variance(y[:, :2], y[:, 2] if obs.k == 3 else None, groups)
        for b, var in extra.items():
            rows = blob == b
            added[rows] += var[component[rows]]
    return added


def expected_markers(obs: MarkerObservation, x: np.ndarray, camera: Camera,
                     facing_cos: float) -> np.ndarray:
    """(6,) bool: the markers that can be seen at state ``x``: in front of the camera, on the
    sensor, the back of the hand not turned further away than ``facing_cos``."""
    pts = obs.marker_points(x[None])[0]
    ok = (obs.facing(x) > facing_cos) & (pts[:, 2] > 0)
    return ok & camera.in_image(camera.project(pts))


def diagonal_blocks(A: np.ndarray, n: int, k: int) -> np.ndarray:
    """The n diagonal (k, k) blocks of A (n*k, n*k) as an (n, k, k) array."""
    idx = np.arange(n)[:, None] * k + np.arange(k)
    return A[idx[:, :, None], idx[:, None, :]]


def _jpda_update(model, x, P, pred, R, z, beta, marker_ids, k):
    """The probabilistic-data-association update: each marker against every blob it may have
    made, weighted by the association's marginals ``beta`` (blobs, markers)."""
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
    return ukf.pda_update(model, x, P, pred, R, groups, candidates, weights)
