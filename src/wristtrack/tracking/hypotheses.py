"""The planar flip kept open: two tracks, one per planar pose, until the motion tells them apart.

Without depth a near-planar marker layout seen nearly fronto-parallel has two poses that
reproject almost alike (issue 11; tracking/initialise.py keeps the second as
``InitResult.alternative``). Rather than guess, the tracker runs one complete copy of itself per
pose on the same frames. Each frame adds to the log-likelihood ratio of the two the log of each
copy's predictive density of the blobs both associated alike (a Gaussian with the predicted
measurement covariance: NIS and log-determinant), so the evidence is always about the same data.
Perspective and motion separate the two: once the ratio passes ``FLIP_LOG_EVIDENCE`` (the
posterior of the other below ``FLIP_ERROR_PROBABILITY``) the likelier copy becomes the tracker.
A copy that loses its track has lost the argument; two copies that have come to the same pose
(within DISTINCT_DEG) have nothing left to argue about. If the ratio stays inside the bounds for
``WINDOW_FRAMES`` the likelier is kept and the run says so: ``Tracker.warnings``, and poses
whose ``rot_sigma_deg`` / ``pos_sigma_mm`` cover the other pose for the rest of that track.

While both are open the likelier copy reports, its uncertainty widened the same way. Each copy
reports under its own ``track_id`` (the smoother never mixes them): ids are 2 id + copy while
open, and the track that remains starts a fresh one.

Functions take the ``Tracker`` (duck-typed: this module imports no tracker code).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wristtrack.detect.detections import Detections
from wristtrack.filter import ukf
from wristtrack.tracking.initialise import FLIP_LOG_EVIDENCE, InitResult
from wristtrack.tracking.observation import hand_in_camera
from wristtrack.tracking.pose_fit import DISTINCT_DEG, better_colour_fit
from wristtrack.tracking.results import FrameResult

# How long the motion has to tell the two poses apart: 3 s at 30 fps. A still hand adds little
# evidence per frame; the first movements out of the fronto-parallel view add a lot.
WINDOW_FRAMES = 90
# Tracker attributes that stay with the tracker, not with the copy it currently shows.
_OWN = ("_flip", "warnings")


@dataclass
class PlanarHypotheses:
    """Two copies of a tracker on the two planar poses (``copies[0]`` the likelier at start),
    or after an unresolved window the one kept (``copies`` of length 1, ``spread`` fixed)."""

    copies: list[Any]
    log_ratio: float  # log-likelihood of copies[0] minus that of copies[1]
    first_frame: int
    frames: int = 0
    # (degrees, mm) between the two poses, added to the reported sigmas
    spread: tuple[float, float] = (0.0, 0.0)
    # each copy's count of initialisations when it started: a copy that re-initialised (after
    # losing its track) is no longer the hypothesis it was
    inits: list[int] = field(default_factory=list)


def start(tracker: Any, det: Detections, init: InitResult) -> FrameResult:
    """Start one copy of ``tracker`` (not yet started on this frame) per planar pose of
    ``init``; the tracker shows the likelier from now on. Returns this frame's result."""
    copies = [copy.deepcopy(tracker) for _ in range(2)]
    results = [copies[0].start_track(det, init), copies[1].start_track(det, init.alternative)]
    hyp = PlanarHypotheses(copies, init.log_evidence, tracker._frame)
    hyp.inits = [c._initialisations for c in copies]
    tracker._flip = hyp
    return _report(tracker, hyp, results)


def step(tracker: Any, det: Detections, labels: np.ndarray | None) -> FrameResult:
    """One frame for every copy; the evidence, the decision and the result shown."""
    hyp = tracker._flip
    if len(hyp.copies) == 1:  # unresolved and kept: widen its sigmas until its track ends
        result = hyp.copies[0].step(det, labels)
        if not _alive(hyp, 0, result):
            return _end(tracker, hyp, 0, result)
        return _report(tracker, hyp, [result])
    preds = [_predicted(c, det) for c in hyp.copies]
    results = [c.step(det, labels) for c in hyp.copies]
    hyp.frames += 1
    alive = [_alive(hyp, i, r) for i, r in enumerate(results)]
    if not all(alive):  # a copy that lost its track could not explain the frames
        keep = alive.index(True) if any(alive) else 0
        return _end(tracker, hyp, keep, results[keep])
    hyp.log_ratio += _log_likelihood_ratio(preds, results, det)
    # decided; or the two copies have come to the same pose, so nothing is left to decide
    if abs(hyp.log_ratio) > FLIP_LOG_EVIDENCE or _spread(hyp.copies)[0] < DISTINCT_DEG:
        keep = 0 if hyp.log_ratio >= 0 else 1
        return _end(tracker, hyp, keep, results[keep])
    if hyp.frames >= WINDOW_FRAMES:
        return _unresolved(tracker, hyp, results)
    return _report(tracker, hyp, results)


def _alive(hyp: PlanarHypotheses, i: int, result: FrameResult) -> bool:
    """Copy i still tracks the pose it started from (not lost, not re-initialised)."""
    return result.has_estimate and hyp.copies[i]._initialisations == hyp.inits[i]


# ----------------------------------------------------------------------------------- evidence


def _predicted(tracker: Any, det: Detections) -> tuple | None:
    """(predicted measurement (6k,), its covariance with noise (6k, 6k), k) of the copy's track
    for this frame, as its generic filter step forms them; None without a track."""
    track = tracker._track
    if track is None:
        return None
    model, cfg = tracker.model, tracker.config
    obs = tracker._observation(cfg.use_depth and det.depth is not None)
    dt = det.timestamp - track.timestamp
    if dt <= 0:
        return None
    x, _, pred = ukf.predict_with_measurement(
        model, track.x, track.P, dt, model.process_noise(dt), obs, params=cfg.ukf
    )
    S = pred.Pyy + obs.noise_covariance(x, pred.y)
    return pred.y, S, obs.k


def _log_likelihood_ratio(preds: list, results: list[FrameResult], det: Detections) -> float:
    """log p(z | copy 0) - log p(z | copy 1) for the blobs both copies gave the same marker."""
    if preds[0] is None or preds[1] is None or preds[0][2] != preds[1][2]:
        return 0.0
    la, lb = results[0].labels, results[1].labels
    blobs = np.flatnonzero((la >= 0) & (la == lb))
    if blobs.size == 0:
        return 0.0
    k = preds[0][2]
    z = det.uv[blobs] if k == 2 else np.column_stack((det.uv[blobs], det.depth[blobs]))
    rows = (la[blobs, None] * k + np.arange(k)).ravel()
    z = z.ravel()
    ok = np.isfinite(z)
    rows, z = rows[ok], z[ok]
    ll = []
    for y, S, _ in preds:
        r, Ss = z - y[rows], S[np.ix_(rows, rows)]
        L = np.linalg.cholesky(Ss)
        w = np.linalg.solve(L, r)
        ll.append(-0.5 * float(w @ w) - float(np.log(np.diag(L)).sum()))
    return ll[0] - ll[1]


# --------------------------------------------------------------------------------- reporting


def _spread(copies: list[Any]) -> tuple[float, float]:
    """(degrees, mm) between the two copies' current hand -> camera poses."""
    (Ra, ta), (Rb, tb) = [(c.R_c0 @ c.model.pose(c._track.x[None])[0][0],
                           c.R_c0 @ c.model.pose(c._track.x[None])[1][0] + c.t_c0)
                          for c in copies]  # fmt: skip
    cos = np.clip(0.5 * (np.trace(Ra.T @ Rb) - 1.0), -1.0, 1.0)
    return math.degrees(math.acos(cos)), 1e3 * float(np.linalg.norm(ta - tb))


def _report(tracker: Any, hyp: PlanarHypotheses, results: list[FrameResult]) -> FrameResult:
    """Show the likelier copy (its state on the tracker, its result with widened sigmas)."""
    lead = 0 if len(results) == 1 or hyp.log_ratio >= 0 else 1
    if len(results) == 2:
        hyp.spread = _spread(hyp.copies)
    _show(tracker, hyp.copies[lead])
    r = results[lead]
    if not r.has_estimate:
        return r
    return replace(
        r,
        rot_sigma_deg=math.hypot(r.rot_sigma_deg, hyp.spread[0]),
        pos_sigma_mm=math.hypot(r.pos_sigma_mm, hyp.spread[1]),
        track_id=2 * r.track_id + lead,
    )


def _show(tracker: Any, shown: Any) -> None:
    tracker.__dict__.update({k: v for k, v in shown.__dict__.items() if k not in _OWN})


def _end(tracker: Any, hyp: PlanarHypotheses, keep: int, result: FrameResult) -> FrameResult:
    """Make copy ``keep`` the tracker again, on a fresh track_id; this frame's result
    (``result``, that copy's)."""
    kept = hyp.copies[keep]
    fresh = 2 * max(c._track_id for c in hyp.copies) + 2  # above every id shown so far
    if result.has_estimate and result.track_id == kept._track_id:
        result = replace(result, track_id=fresh)
    kept._track_id = fresh
    _show(tracker, kept)
    tracker._flip = kept.__dict__.get("_flip")  # a copy re-initialised ambiguously: its pair
    return result


def _unresolved(tracker: Any, hyp: PlanarHypotheses, results: list[FrameResult]) -> FrameResult:
    """The window is over and the two poses still explain the frames alike: keep the likelier,
    say so, and keep widening its sigmas for the rest of its track."""
    keep = 0 if hyp.log_ratio >= 0 else 1
    hyp.spread = _spread(hyp.copies)
    tracker.warnings.append(
        f"frames {hyp.first_frame}-{results[keep].frame}: colour-only initialisation could not "
        f"tell the hand's pose from its planar mirror image ({hyp.spread[0]:.0f} deg apart; "
        f"log-likelihood ratio {abs(hyp.log_ratio):.1f} < {FLIP_LOG_EVIDENCE:.1f} after "
        f"{hyp.frames} frames); kept the likelier, so the orientation may be the mirrored one "
        "(rot_sigma_deg covers both): record with depth, or tilt the back of the hand "
        "towards the camera at the start"
    )
    # the kept copy goes on under an id above both copies' (reported as 2 id + 0): shown under
    # the other's id, its rows would join the mirror image's in one track for the smoother
    kept = hyp.copies[keep]
    kept._track_id = max(c._track_id for c in hyp.copies) + 1
    hyp.copies, hyp.inits = [kept], [hyp.inits[keep]]
    hyp.log_ratio = 0.0
    result = replace(results[keep], track_id=kept._track_id) if results[keep].has_estimate \
        else results[keep]
    return _report(tracker, hyp, [result])


# -------------------------------------------------------------------------- while tracking


def colour_refit(tracker: Any, det: Detections, x: np.ndarray,
                 labels: np.ndarray) -> InitResult | None:
    """For a colour-only frame: the one-frame fit of the markers labelled in it when it explains
    them decisively better than the updated state ``x`` and lies elsewhere
    (``pose_fit.better_colour_fit``, at the bound that ends the planar test), else None.

    The pair of planar poses is kept open at initialisation; later, a fast turn through the
    fronto-parallel view can carry the filter's out-of-plane tilt towards the mirror image
    while every blob stays within its gate (10-19 deg off on a fast colour-only recording).
    """
    blobs = np.flatnonzero(labels >= 0)
    if blobs.size < 4:
        return None
    uv = np.full((tracker.layout.points.shape[0], 2), np.nan)
    uv[labels[blobs]] = det.uv[blobs]
    R_rel, p = tracker.model.pose(x[None])
    R_ch, t_ch = hand_in_camera(R_rel[0], p[0], tracker.R_c0, tracker.t_c0)
    fit = better_colour_fit(uv, tracker.camera, tracker.layout, R_ch, t_ch,
                            tracker.config.measurement.pixel_sigma, FLIP_LOG_EVIDENCE)
    if fit is None:
        return None
    return InitResult(fit.R_ch, fit.t_ch, fit.cov, labels, fit.rms_px, tracker.layout, fit.cost)
