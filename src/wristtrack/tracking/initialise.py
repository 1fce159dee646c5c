"""Initialisation: label the six markers and solve the camera-to-hand pose (paper section III-D).

The whole step: labels from the user or by fitting the layout (tracking/labelling.py), the pose
by least squares on marker projections and depths (tracking/pose_fit.py), and the subject's own
layout estimated from depth when there is no hand.json.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import ConfigError, InitialisationError
from wristtrack.hand import MARKER_NAMES, HandLayout, estimate_layout
from wristtrack.tracking.labelling import MAX_RMS_PX, label_and_fit
from wristtrack.tracking.pose_fit import initial_guess, refine_pose
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
    if fit.rms_px > max_rms_px:
        raise InitialisationError(
            f"initial pose fits the markers badly (RMS {fit.rms_px:.1f} px > {max_rms_px} px): "
            "wrong labels or hand layout; check the labels file and hand.json"
        )
    return InitResult(
        R_ch=fit.R_ch,
        t_ch=fit.t_ch,
        cov=fit.cov,
        labels=np.asarray(labels, dtype=int),
        rms_px=fit.rms_px,
        layout=layout,
        cost=fit.cost,
    )
