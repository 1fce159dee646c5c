"""The tracker's results smoothed: the unscented RTS smoother (filter/smoother.py) run over each
track of a finished run, with the poses, velocities and uncertainties rebuilt from the smoothed
states. Each track (from one initialisation to the loss of the hand) is smoothed on its own;
frames without an estimate stay without one, but for the frames of a track the filter predicted
and did not report (too few markers, too uncertain: TrackerConfig.coast_limit). Those carry the
track across (the smoother uses the frames after them for those before) and are reported
(``coasting``) where the smoothed uncertainty is within the same bounds, against the last
reported frame before them: within a short gap the frames after it pin the pose down again.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from wristtrack.filter.smoother import rts_smooth
from wristtrack.filter.ukf import ManifoldModel, UKFParams
from wristtrack.geometry import relative_pose, so3_log
from wristtrack.tracking.observation import hand_in_camera
from wristtrack.tracking.results import FrameResult, Status, within_coast_limit

_DEFAULT_PARAMS = UKFParams()


def track_segments(results: list[FrameResult]) -> list[np.ndarray]:
    """Frame indices of each run of filter states from one initialisation (one track), in
    order: the estimates, and the predictions not reported between them."""
    segments: list[list[int]] = []
    last_id = None
    for i, r in enumerate(results):
        if r.x is None or r.cov is None or r.track_id < 0:
            last_id = None
            continue
        if r.track_id != last_id:
            segments.append([])
            last_id = r.track_id
        segments[-1].append(i)
    return [np.asarray(s) for s in segments]


def smooth_results(
    model: ManifoldModel, results: list[FrameResult], params: UKFParams = _DEFAULT_PARAMS,
    coast_limit: tuple[float, float] | None = None,
) -> list[FrameResult]:
    """The run's results with every estimate replaced by its smoothed value, and the unreported
    predictions of a track whose smoothed 1-sigma adds at most ``coast_limit`` (deg, mm;
    TrackerConfig.coast_limit; None: none is reported) to that of the last frame tracked
    before them reported as ``coasting``.

    Poses, velocities, covariances and uncertainties are smoothed; everything the filter saw
    (labels, markers, clutter, NIS) is kept. The frames are recovered from the filtered results,
    so the results are all that is needed: the states' W0 from the camera pose and the state
    of the first (R_ch = R_c0 R(x), t_ch = R_c0 p(x) + t_c0), and the W0 the track's poses are
    reported in from the camera and relative pose of its last. The two differ only in a still
    start, whose rows are reported against W0 as refined so far (Tracker._provisional_w0):
    the smoothed still start is reported against the W0 of its last frame, the refined one.
    """
    out = list(results)
    for seg in track_segments(results):
        shown = [i for i in seg if results[i].has_estimate]  # a track starts with a fix
        if not shown:
            continue
        first, last = results[shown[0]], results[shown[-1]]
        R_c0, t_c0 = _w0(first, *(a[0] for a in model.pose(first.x[None])))
        R_rep, t_rep = _w0(last, last.R, last.p)
        turn = R_rep.T @ R_c0
        xs = np.stack([results[i].x for i in seg])
        Ps = np.stack([results[i].cov for i in seg])
        times = np.array([results[i].timestamp for i in seg])
        xs_s, Ps_s = rts_smooth(model, xs, Ps, times, params)
        R_all, p_all = model.pose(xs_s)
        R_prev, reported = None, (math.inf, math.inf)
        for j, i in enumerate(seg):
            R, p = R_all[j], p_all[j]
            v, w = model.velocities(xs_s[j])
            if not np.isfinite(w).all():  # a state without rates (the paper's): differentiate R
                w = (
                    so3_log(R @ R_prev.T) / (times[j] - times[j - 1])
                    if R_prev is not None
                    else np.zeros(3)
                )
            R_prev = R
            var = Ps_s[j].diagonal()
            sigmas = (math.degrees(math.sqrt(max(var[model.rotation].sum(), 0.0))),
                      1e3 * math.sqrt(max(var[model.position].sum(), 0.0)))
            status = results[i].status
            if status == Status.TRACKING:
                reported = sigmas
            elif not results[i].has_estimate:  # a prediction the filter did not report
                if coast_limit is None or not within_coast_limit(sigmas, reported, coast_limit):
                    continue  # still too uncertain to report
                status = Status.COASTING
            R_ch, t_ch = hand_in_camera(R, p, R_c0, t_c0)
            R_out, p_out = relative_pose(R_rep, t_rep, R_ch, t_ch)
            out[i] = replace(
                results[i],
                status=status,
                R_ch=R_ch,
                t_ch=t_ch,
                R=R_out,
                p=p_out,
                v=turn @ np.asarray(v, dtype=float),
                w=turn @ np.asarray(w, dtype=float),
                cov=Ps_s[j],
                x=xs_s[j],
                pos_sigma_mm=sigmas[1],
                rot_sigma_deg=sigmas[0],
            )
    return out


def _w0(result: FrameResult, R: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The W0 (R_c0, t_c0) in which relative pose (R, p) is ``result``'s camera pose."""
    R_c0 = result.R_ch @ R.T
    return R_c0, result.t_ch - R_c0 @ p
