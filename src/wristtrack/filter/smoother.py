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
prediction is exactly the one the filter made. Arrays in, arrays out: the tracker's results are
smoothed track by track in wristtrack.tracking.smoothed_results.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from wristtrack.filter.ukf import ManifoldModel, UKFParams, propagate_sigma_points, symmetrise

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
