"""Initialisation: label the six markers and solve the camera-to-hand pose (paper section III-D).

The whole step: labels from the user or by fitting the layout (tracking/labelling.py), the pose
by least squares on marker projections and depths (tracking/pose_fit.py), and the subject's own
layout estimated from depth when there is no hand.json.

Without depth a near-planar layout seen nearly fronto-parallel has two poses that reproject
almost alike (the planar flip, issue 11). Both are fitted; when the pixels cannot tell them
apart at error probability ``FLIP_ERROR_PROBABILITY`` the likelier is returned with the other
as ``InitResult.alternative``, for the tracker to keep both until the motion decides
(tracking/hypotheses.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import ConfigError, InitialisationError
from wristtrack.hand import MARKER_NAMES, HandLayout, estimate_layout
from wristtrack.tracking.labelling import MAX_RMS_PX, MAX_TILT, label_and_fit
from wristtrack.tracking.pose_fit import PoseFit, initial_guess, planar_twin, refine_pose
from wristtrack.tracking.side import label_either_side


@dataclass(frozen=True)
class InitResult:
    """Result of ``initialise``: pose hand -> camera, its covariance, blob labels, the layout."""

    R_ch: np.ndarray
    t_ch: np.ndarray
    cov: np.ndarray
    labels: np.ndarray
    rms_px: float
    layout: HandLayout
    cost: float
    # The planar twin (same labels, the mirror-image pose) when the pixels cannot rule it out,
    # and the log-likelihood ratio of this pose over it: (twin's chi-square - this one's) / 2.
    alternative: InitResult | None = None
    log_evidence: float = math.inf


# The planar twin is ruled out when, with equal priors, its posterior probability is below this:
# a log-likelihood ratio above log((1 - p) / p) (~6.9). The same bound ends the tracker's
# sequential test (tracking/hypotheses.py).
FLIP_ERROR_PROBABILITY = 1e-3
FLIP_LOG_EVIDENCE = math.log((1.0 - FLIP_ERROR_PROBABILITY) / FLIP_ERROR_PROBABILITY)


def _marker_blobs(labels: np.ndarray, M: int) -> np.ndarray:
    """Blob index per marker (6,), -1 where the marker has no blob; validates ``labels``."""
    labels = np.asarray(labels).reshape(-1)
    n = len(MARKER_NAMES)
    if labels.shape[0] != M or not np.isin(labels, np.arange(-1, n)).all():
        raise InitialisationError(
            f"labels must give one value in -1..{n - 1} per blob ({M} blobs), got {labels.tolist()}"
        )
    idx = np.full(n, -1, dtype=int)
    for k in range(n):
        hits = np.flatnonzero(labels == k)
        if hits.size > 1:
            raise InitialisationError(
                f"labels put marker {MARKER_NAMES[k]} on {hits.size} blobs; one blob per marker"
            )
        if hits.size:
            idx[k] = hits[0]
    return idx


def initialise(
    detections: Detections,
    camera: Camera,
    layout: HandLayout | None,
    labels: np.ndarray | None = None,
    *,
    pixel_sigma: float = 0.7,
    depth_sigma: float | None = None,
    max_rms_px: float = MAX_RMS_PX,
) -> InitResult:
    """Label the markers (unless ``labels`` is given) and solve the initial hand -> camera pose.

    Without ``layout`` (no hand.json) depth is required: the blobs are labelled with
    ``HandLayout.default()`` and its mirror image as shape templates (the side is found from
    the image), the subject's layout is estimated from the back-projected marker centres
    (``hand.estimate_layout``, heights kept), and the pose refined with it.
    """
    uv, depth = detections.uv, detections.depth
    M = uv.shape[0]
    depth_resolves = layout is None  # the layout measured from depth: no flip to fear
    if layout is None:
        if depth is None or np.isfinite(depth).sum() < len(MARKER_NAMES):
            raise InitialisationError(
                "no hand layout and no depth: give a hand.json (--hand) or a recording with "
                "registered depth so the layout can be measured"
            )
        if labels is None:
            # either hand: the right template and its mirror image (tracking/side.py)
            labels, _, _ = label_either_side(detections, camera, pixel_sigma=pixel_sigma,
                                             max_rms_px=max_rms_px)
        idx = _marker_blobs(labels, M)
        missing = [
            name
            for name, b in zip(MARKER_NAMES, idx, strict=True)
            if b < 0 or not np.isfinite(depth[b])
        ]
        if missing:
            raise InitialisationError(
                f"measuring the hand layout needs depth at all six markers; none for "
                f"{', '.join(missing)}: give a hand.json (--hand) or re-record"
            )
        try:
            layout, R0, t0 = estimate_layout(camera.backproject(uv[idx], depth[idx]))
        except ConfigError as err:  # an impossible measured layout: report it as such
            raise InitialisationError(str(err)) from err
        fit = refine_pose(uv[idx], depth[idx], camera, layout, R0, t0, pixel_sigma, depth_sigma)
    elif labels is None:
        labels, fit = label_and_fit(
            uv, depth, camera, layout, pixel_sigma=pixel_sigma, depth_sigma=depth_sigma,
            max_rms_px=max_rms_px,
        )  # fmt: skip
    else:
        idx = _marker_blobs(labels, M)
        vis = idx >= 0
        uvm = np.where(vis[:, None], uv[idx], np.nan)
        dm = None if depth is None else np.where(vis, depth[idx], np.nan)
        R0, t0 = initial_guess(uvm, dm, camera, layout, vis)
        fit = refine_pose(uvm, dm, camera, layout, R0, t0, pixel_sigma, depth_sigma, vis)
    twin = None
    if layout is not None and not depth_resolves:
        fit, twin = _planar_twin(uv, depth, labels, camera, layout, fit, pixel_sigma, depth_sigma)
        if twin is not None and twin.cost < fit.cost:  # the likelier first, always
            fit, twin = twin, fit
    if fit.rms_px > max_rms_px:
        raise InitialisationError(
            f"initial pose fits the markers badly (RMS {fit.rms_px:.1f} px > {max_rms_px} px): "
            "wrong labels or hand layout; check the labels file and hand.json"
        )
    result = InitResult(
        R_ch=fit.R_ch,
        t_ch=fit.t_ch,
        cov=fit.cov,
        labels=np.asarray(labels, dtype=int),
        rms_px=fit.rms_px,
        layout=layout,
        cost=fit.cost,
    )
    if twin is None:
        return result
    evidence = 0.5 * (twin.cost - fit.cost)
    if evidence > FLIP_LOG_EVIDENCE:
        return replace(result, log_evidence=evidence)
    alt = replace(result, R_ch=twin.R_ch, t_ch=twin.t_ch, cov=twin.cov, rms_px=twin.rms_px,
                  cost=twin.cost, log_evidence=-evidence)
    return replace(result, alternative=alt, log_evidence=evidence)


def _planar_twin(
    uv: np.ndarray,
    depth: np.ndarray | None,
    labels: np.ndarray,
    camera: Camera,
    layout: HandLayout,
    fit: PoseFit,
    pixel_sigma: float,
    depth_sigma: float | None,
) -> tuple[PoseFit, PoseFit | None]:
    """(the best pose, its planar twin or None) for labelled markers without enough depth for
    the 3-D alignment (fewer than three readings); a twin facing the camera more obliquely
    than MAX_TILT is not a hand's pose (pose_fit.planar_twin)."""
    idx = _marker_blobs(labels, uv.shape[0])
    vis = idx >= 0
    uvm = np.where(vis[:, None], uv[idx], np.nan)
    dm = None if depth is None else np.where(vis, depth[idx], np.nan)
    if dm is not None and (np.isfinite(dm) & (dm > 0)).sum() >= 3:
        return fit, None  # depth fixes the side of the plane (pose_fit.initial_guesses)
    return planar_twin(uvm, dm, camera, layout, fit, pixel_sigma, depth_sigma, vis,
                       min_cos=math.cos(MAX_TILT))  # fmt: skip
