"""Offline smoothing: the unscented Rauch-Tung-Striebel smoother on the filter's manifold state.

The forward filter estimates each frame from the past only. For the analysis of a finished
recording the future frames are known too, and the smoother uses them: a backward pass from the
last frame that corrects each filtered state with what the next smoothed state says about it
(Saerkkae 2008, "Unscented Rauch-Tung-Striebel smoother"). Here the state lives on a manifold
(orientation in SO(3)), so, as in the filter, every difference is taken in the tangent space
with the model's ``lift`` and applied with its ``retract``:

    sigma points of (x_k, P_k, process noise) -> propagated to k+1 -> x_pred, P_pred and the
    cross-covariance C of the tangent offsets at k with those at k+1;
    G = C P_pred^-1,   x_k^s = retract(x_k, G lift(x_pred, x_{k+1}^s)),
    P_k^s = P_k + G (P_{k+1}^s - P_pred) G^T.

The sigma points and weights are the filter's own (augmented, process noise appended), so the
prediction is exactly the one the filter made. Each track (from one initialisation to the loss
of the hand) is smoothed on its own; frames without an estimate stay without one.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from wristtrack.filter.ukf import ManifoldModel, UKFParams, propagate_sigma_points, symmetrise
from wristtrack.geometry import so3_log
from wristtrack.tracking.tracker import FrameResult

_DEFAULT_PARAMS = UKFParams()


def rts_smooth(
    model: ManifoldModel,
    xs: np.ndarray,
    Ps: np.ndarray,
    times: np.ndarray,
    params: UKFParams = _DEFAULT_PARAMS,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed states (N, D) and tangent covariances (N, n, n) of one track.

    ``xs`` (N, D) and ``Ps`` (N, n, n) are the filtered states of consecutive frames at
    ``times`` (N,), as the filter left them after each frame's update. The model must provide
    ``process_noise(dt)`` (the covariance of the noise appended to the state).
    """
    xs = np.asarray(xs, dtype=float)
    Ps = np.asarray(Ps, dtype=float)
    n = model.dim
    xs_s, Ps_s = xs.copy(), Ps.copy()
    for k in range(len(xs) - 2, -1, -1):
        dt = float(times[k + 1] - times[k])
        # the filter's own prediction (ukf.predict), with the sigma points it started from
        _, d, x_pred, weights, offsets = propagate_sigma_points(
            model, xs[k], Ps[k], dt, model.process_noise(dt), params
        )
        wd = d * weights.cov[:, None]
        P_pred = symmetrise(d.T @ wd)
        C = offsets[:, :n].T @ wd  # offsets at k have zero weighted mean by symmetry
        G = _right_divide(C, P_pred)
        delta = model.lift(x_pred, xs_s[k + 1][None])[0]
        xs_s[k] = model.retract(xs[k], (G @ delta)[None])[0]
        Ps_s[k] = symmetrise(Ps[k] + G @ (Ps_s[k + 1] - P_pred) @ G.T)
    return xs_s, Ps_s


def _right_divide(C: np.ndarray, P: np.ndarray) -> np.ndarray:
    """C P^-1 for a symmetric positive (semi)definite P; least squares if P is singular."""
    try:
        return cho_solve(cho_factor(P, lower=True, check_finite=False), C.T).T
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(P, C.T, rcond=None)[0].T


def track_segments(results: list[FrameResult]) -> list[np.ndarray]:
    """Frame indices of each run of estimates from one initialisation (one track), in order."""
    segments: list[list[int]] = []
    last_id = None
    for i, r in enumerate(results):
        if not r.has_estimate or r.x is None or r.cov is None:
            last_id = None
            continue
        if r.track_id != last_id:
            segments.append([])
            last_id = r.track_id
        segments[-1].append(i)
    return [np.asarray(s) for s in segments]


def smooth_results(
    model: ManifoldModel, results: list[FrameResult], params: UKFParams = _DEFAULT_PARAMS
) -> list[FrameResult]:
    """The run's results with every estimate replaced by its smoothed value.

    Poses, velocities, covariances and uncertainties are smoothed; everything the filter saw
    (labels, markers, clutter, NIS) is kept. W0 is recovered from the filtered results
    (R_ch = R_c0 R, t_ch = R_c0 p + t_c0), so the results are all that is needed.
    """
    out = list(results)
    for seg in track_segments(results):
        first = results[seg[0]]
        R_c0 = first.R_ch @ first.R.T
        t_c0 = first.t_ch - R_c0 @ first.p
        xs = np.stack([results[i].x for i in seg])
        Ps = np.stack([results[i].cov for i in seg])
        times = np.array([results[i].timestamp for i in seg])
        xs_s, Ps_s = rts_smooth(model, xs, Ps, times, params)
        R_all, p_all = model.pose(xs_s)
        R_prev = None
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
            out[i] = replace(
                results[i],
                R_ch=R_c0 @ R,
                t_ch=R_c0 @ p + t_c0,
                R=R.copy(),
                p=p.copy(),
                v=np.array(v, dtype=float),
                w=np.array(w, dtype=float),
                cov=Ps_s[j],
                x=xs_s[j],
                pos_sigma_mm=1e3 * math.sqrt(max(var[model.position].sum(), 0.0)),
                rot_sigma_deg=math.degrees(math.sqrt(max(var[model.rotation].sum(), 0.0))),
            )
    return out
