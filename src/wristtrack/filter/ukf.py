"""A generic augmented Unscented Kalman Filter whose state may live on a manifold.

The state is an array ``x`` of the model's ambient size D (e.g. a flattened rotation matrix
followed by vectors); its uncertainty is a covariance ``P`` on an n-dimensional tangent space.
A model supplies a retraction ``retract(x, xi) -> X`` mapping tangent offsets (S, n) to states
(S, D) and its inverse ``lift(x, X) -> xi`` (UKF on manifolds, Brossard et al. 2020). For a
Euclidean state both are plain addition and subtraction and this is the textbook UKF.

Process noise that enters non-linearly is appended to the state (the augmented UKF of Julier &
Uhlmann, as the paper uses): sigma points are drawn jointly over (state error, noise) and the
model's ``propagate(X, noise, dt)`` receives both. Every function handles all sigma points in
one vectorised call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
from scipy.linalg.blas import dtrsm
from scipy.linalg.lapack import dpotrf
from scipy.special import chdtri


class ManifoldModel(Protocol):
    """What the filter needs to know about a state space and its dynamics."""

    dim: int  # tangent (error-state) dimension n
    noise_dim: int  # dimension q of the non-additive process noise appended to the state

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """States (S, D) at tangent offsets xi (S, n) from x (D,)."""

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Tangent offsets (S, n) of states X (S, D) from x (D,): the inverse of retract."""

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        """States (S, D) one step of dt later, driven by noise samples (S, q)."""


@dataclass(frozen=True)
class SigmaWeights:
    """Scaled unscented transform weights (van der Merwe) for dimension n."""

    mean: np.ndarray  # (2n+1,)
    cov: np.ndarray  # (2n+1,)
    scale: float  # sqrt(n + lambda): sigma points sit at +- scale * columns of chol(P)


@lru_cache(maxsize=64)
def sigma_weights(
    n: int, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0
) -> SigmaWeights:
    """Weights of the 2n+1 scaled sigma points, defined as FilterPy's MerweScaledSigmaPoints."""
    lam = alpha**2 * (n + kappa) - n
    mean = np.full(2 * n + 1, 0.5 / (n + lam))
    cov = mean.copy()
    mean[0] = lam / (n + lam)
    cov[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)
    mean.setflags(write=False)
    cov.setflags(write=False)
    return SigmaWeights(mean, cov, float(np.sqrt(n + lam)))


@lru_cache(maxsize=64)
def chi2_quantile(prob: float, dof: int) -> float:
    """The chi-square quantile at ``prob`` for ``dof`` degrees of freedom: the NIS and gate
    bounds (scipy.special, not scipy.stats, which costs ~1 s to import)."""
    return float(chdtri(dof, 1.0 - prob))


_ONES = np.ones(256)


def all_finite(a: np.ndarray) -> bool:
    """np.isfinite(a).all() in one cheap call: a NaN or an inf anywhere makes the sum non-finite
    (finite entries could only overflow it beyond 1e308). The sum is a dot product with ones,
    which costs a fraction of a NumPy reduction's call overhead."""
    flat = a.ravel()
    if flat.size > _ONES.size:
        return bool(np.isfinite(flat).all())
    return math.isfinite(flat.dot(_ONES[: flat.size]))


def symmetrise(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.swapaxes(-1, -2))


def _lapack_cholesky(P: np.ndarray) -> np.ndarray | None:
    """Lower Cholesky factor straight from LAPACK (a fraction of np.linalg.cholesky's call
    overhead, which matters on the hot path), or None where P is not positive definite."""
    L, info = dpotrf(P, lower=1)
    return L if info == 0 else None


def safe_cholesky(P: np.ndarray) -> np.ndarray:
    """Lower factor L with L L^T ~= P, for a covariance that rounding may have made indefinite.

    Tries plain Cholesky, then Cholesky with growing diagonal jitter, then falls back to the
    eigen-decomposition with negative eigenvalues clipped, so it never raises on a finite P.
    Only the last resort gives a factor that is not triangular.
    """
    L = _lapack_cholesky(P)
    if L is not None:
        return L
    P = symmetrise(P)
    scale = max(float(np.max(np.abs(np.diag(P)))), 1e-300)
    for k in range(-12, -5, 2):
        try:
            return np.linalg.cholesky(P + np.eye(P.shape[0]) * scale * 10.0**k)
        except np.linalg.LinAlgError:
            continue
    values, vectors = np.linalg.eigh(P)
    return vectors * np.sqrt(np.clip(values, scale * 1e-12, None))


def sigma_offsets(P: np.ndarray, weights: SigmaWeights) -> np.ndarray:
    """Tangent offsets (2n+1, n) of the sigma points: 0, +scale*L[:, k], -scale*L[:, k]."""
    cols = weights.scale * safe_cholesky(P).T  # row k = column k of L
    return np.concatenate((np.zeros((1, P.shape[0])), cols, -cols))


@dataclass(frozen=True)
class UKFParams:
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0


def propagate_sigma_points(model, x, P, dt, Q_noise, params):
    """Augmented sigma points of (x, P, Q_noise) pushed through the model: the propagated states
    X (S, D), their tangent offsets d (S, n) from the predicted mean, the mean, the weights and
    the sigma points' own offsets (S, n + q) before propagation (for cross-covariances, as the
    smoother needs)."""
    n, q = model.dim, model.noise_dim
    if q:
        Pa = np.zeros((n + q, n + q))
        Pa[:n, :n] = P
        Pa[n:, n:] = Q_noise
    else:
        Pa = P
    w = sigma_weights(n + q, params.alpha, params.beta, params.kappa)
    offsets = sigma_offsets(Pa, w)
    X = model.propagate(model.retract(x, offsets[:, :n]), offsets[:, n:], dt)
    # The propagated centre point is the reference about which the spread is measured.
    centre = X[0]
    xi = model.lift(centre, X)
    mean = w.mean @ xi
    x_new = model.retract(centre, mean[None])[0]
    return X, xi - mean, x_new, w, offsets


def predict(
    model: ManifoldModel,
    x: np.ndarray,
    P: np.ndarray,
    dt: float,
    Q_noise: np.ndarray | None = None,
    Q_additive: np.ndarray | None = None,
    params: UKFParams = UKFParams(),
) -> tuple[np.ndarray, np.ndarray]:
    """Augmented UKF prediction: (state error, process noise) sigma points through the model.

    ``Q_noise`` (q, q) is the covariance of the noise passed to ``model.propagate`` (augmented);
    ``Q_additive`` (n, n), if given, is added to the predicted tangent covariance (the classic
    additive-noise UKF; FilterPy's form).
    """
    _, d, x_new, w, _ = propagate_sigma_points(model, x, P, dt, Q_noise, params)
    P_new = (d.T * w.cov) @ d
    if Q_additive is not None:
        P_new = P_new + Q_additive
    return x_new, symmetrise(P_new)


@dataclass(frozen=True)
class MeasurementPrediction:
    """The unscented transform of the predicted state through a measurement function.

    ``Y`` (S, m) are the transformed sigma points; ``y`` (m,) their mean; ``Pyy`` (m, m) their
    spread (without measurement noise); ``Pxy`` (n, m) the state-measurement cross-covariance.
    Rows may later be selected (visible or associated markers) without transforming again, or
    combined linearly (``mapped``).
    """

    y: np.ndarray
    Pyy: np.ndarray
    Pxy: np.ndarray

    def mapped(self, A: np.ndarray) -> MeasurementPrediction:
        """The prediction of A y, A (r, m): exact for a linear map (A y's sigma points are A's
        image of y's), so no second unscented transform is needed."""
        return MeasurementPrediction(A @ self.y, A @ self.Pyy @ A.T, self.Pxy @ A.T)


def predict_measurement(
    model: ManifoldModel,
    x: np.ndarray,
    P: np.ndarray,
    h,
    params: UKFParams = UKFParams(),
) -> MeasurementPrediction:
    """Transform sigma points of (x, P) through h: states (S, D) -> measurements (S, m)."""
    w = sigma_weights(model.dim, params.alpha, params.beta, params.kappa)
    return _measurement_at(model, x, sigma_offsets(P, w), w, h)


def _measurement_at(model: ManifoldModel, x: np.ndarray, offsets: np.ndarray, w: SigmaWeights,
                    h) -> MeasurementPrediction:
    """predict_measurement from the sigma points' tangent ``offsets`` about x and weights w."""
    Y = h(model.retract(x, offsets))
    y = w.mean @ Y
    dY = Y - y
    wdY = dY * w.cov[:, None]
    # offsets have zero weighted mean by symmetry, so they are already centred
    return MeasurementPrediction(y, dY.T @ wdY, offsets.T @ wdY)


def predict_with_measurement(
    model: ManifoldModel,
    x: np.ndarray,
    P: np.ndarray,
    dt: float,
    Q_noise: np.ndarray,
    h,
    params: UKFParams = UKFParams(),
) -> tuple[np.ndarray, np.ndarray, MeasurementPrediction]:
    """Prediction and measurement prediction from one set of augmented sigma points.

    The propagated sigma points already carry the predicted mean and covariance (process noise
    included), so they are transformed through h directly instead of being drawn again: one
    Cholesky factor and one retraction less per frame. Returns (x, P, prediction).
    """
    X, d, x_new, w, _ = propagate_sigma_points(model, x, P, dt, Q_noise, params)
    wd = d * w.cov[:, None]
    P_new = symmetrise(d.T @ wd)
    Y = h(X)
    y = w.mean @ Y
    dY = Y - y
    return x_new, P_new, MeasurementPrediction(y, dY.T @ (dY * w.cov[:, None]), wd.T @ dY)


@dataclass(frozen=True)
class UpdateResult:
    x: np.ndarray
    P: np.ndarray
    nis: float  # normalised innovation squared
    dof: int  # measurement dimension used


def update(
    model: ManifoldModel,
    x: np.ndarray,
    P: np.ndarray,
    pred: MeasurementPrediction,
    z: np.ndarray,
    R: np.ndarray,
    rows: np.ndarray | None = None,
) -> UpdateResult:
    """Kalman correction with measurement z (k,) of rows ``rows`` of the prediction (all if None).

    R is (k, k) or the diagonal (k,). Solves with a Cholesky factor of the innovation covariance
    instead of forming its inverse.
    """
    if rows is None:
        y, Pyy, Pxy = pred.y, pred.Pyy, pred.Pxy
    else:
        y, Pyy, Pxy = pred.y[rows], pred.Pyy[np.ix_(rows, rows)], pred.Pxy[:, rows]
    S = Pyy + (np.diag(R) if R.ndim == 1 else R)
    Ae = cholesky_whiten(S, np.column_stack((Pxy.T, z - y)))
    # With S = L L^T, A = L^-1 Pxy^T and e = L^-1 nu (one solve for both):
    # K nu = Pxy S^-1 nu = A^T e, K S K^T = A^T A, and the NIS nu^T S^-1 nu = e^T e.
    A, e = Ae[:, :-1], Ae[:, -1]
    x_new = model.retract(x, (A.T @ e)[None])[0]
    P_new = P - A.T @ A
    return UpdateResult(x_new, symmetrise(P_new), float(e @ e), int(z.shape[0]))


def iterated_update(
    model: ManifoldModel,
    prior: tuple[np.ndarray, np.ndarray],
    posterior: tuple[np.ndarray, np.ndarray],
    h,
    z: np.ndarray,
    R: np.ndarray,
    rows: np.ndarray | None,
    params: UKFParams = UKFParams(),
    iterations: int = 1,
) -> UpdateResult:
    """The correction again, with h linearised over the posterior instead of the prior.

    Iterated posterior linearisation (Garcia-Fernandez et al., IEEE TSP 2015): the sigma points
    of the posterior (x1, P1) give a linear model of h(x) = y + H (x - x1) with residual
    covariance Omega, and the prior (x0, P0) is corrected with it. A prior far from the truth
    (a long gap) meets h where its curvature matters, and one unscented correction stops short;
    the posterior is near enough for the linear model to hold. ``rows`` select the measured rows
    of h (None: all), ``R`` (k, k) their noise; each iteration starts from the last posterior.
    The prior's covariance lives in the tangent space at its own mean, and is carried into the
    posterior's (:func:`transported`): on a manifold the two differ by the turn between the
    means, tens of degrees after a long gap, and taken as it is there the prior's axes turn with
    the posterior (a rotation 50 deg from its prior: 0.21 deg off the maximum a posteriori
    estimate, carried 0.001 deg, tests/filter/test_ukf.py)."""
    if iterations < 1:
        raise ValueError(f"iterated_update needs at least one iteration, got {iterations}")
    x0, P0 = prior
    x1, P1 = posterior
    w = sigma_weights(model.dim, params.alpha, params.beta, params.kappa)
    for _ in range(iterations):
        eps = sigma_offsets(P1, w)  # one set of sigma points for h and for the transport
        pred = _measurement_at(model, x1, eps, w, h)
        y, Pyy, Pxy = pred.y, pred.Pyy, pred.Pxy
        if rows is not None:
            y, Pyy, Pxy = y[rows], Pyy[np.ix_(rows, rows)], Pxy[:, rows]
        H = np.linalg.solve(P1, Pxy).T  # statistical linearisation: Pxy = P1 H^T
        d0, Pt = transported(model, (x0, P0), x1, P1, eps, w)
        S = H @ Pt @ H.T + (Pyy - H @ P1 @ H.T) + R
        Ae = cholesky_whiten(S, np.column_stack((H @ Pt, z - y - H @ d0)))
        A, e = Ae[:, :-1], Ae[:, -1]
        x1 = model.retract(x1, (d0 + A.T @ e)[None])[0]
        P1 = symmetrise(Pt - A.T @ A)
    return UpdateResult(x1, P1, float(e @ e), int(z.shape[0]))


def transported(model: ManifoldModel, prior: tuple[np.ndarray, np.ndarray], x1: np.ndarray,
                P1: np.ndarray, eps: np.ndarray, w: SigmaWeights
                ) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian ``prior`` (x0, P0), P0 in the tangent space at x0, as a Gaussian in the
    tangent space at x1 of (x1, P1), whose sigma points are the tangent offsets ``eps`` with
    weights ``w``: its mean's offset from x1 (n,) and its covariance (n, n) there.

    The map from x1's tangent to x0's, eps -> lift(x0, retract(x1, eps)), is linearised
    statistically over those sigma points, as the iterated update linearises h: c + K eps.
    The prior N(0, P0) on it is N(-K^-1 c, K^-1 P0 K^-T) in eps. Linearised where the
    posterior is (not at x0), the iterated update's prior term has the gradient of the prior's
    own cost there, so its fixed point is the maximum a posteriori estimate's. Exact where lift
    and retract are linear (a Euclidean state: x0 - x1 and P0)."""
    x0, P0 = prior
    c = model.lift(x0, model.retract(x1, eps))
    mean = w.mean @ c
    K = np.linalg.solve(P1, (w.cov[:, None] * eps).T @ (c - mean)).T
    K_inv = np.linalg.inv(K)
    return -K_inv @ mean, symmetrise(K_inv @ P0 @ K_inv.T)


def cholesky_whiten(S: np.ndarray, B: np.ndarray, alpha: float = 1.0) -> np.ndarray:
    """alpha L^-1 B for the Cholesky factor L of S, by a triangular solve (safe_cholesky's
    fallbacks, which need not be triangular, by a general one)."""
    L = _lapack_cholesky(S)
    if L is not None:
        return dtrsm(alpha, L, B, lower=1)
    return alpha * np.linalg.solve(safe_cholesky(S), B)


class EuclideanModel:
    """A model on R^n given by a propagation function; the retraction is addition."""

    def __init__(self, dim: int, f, noise_dim: int = 0):
        self.dim, self.noise_dim, self._f = dim, noise_dim, f

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        return x + xi

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        return X - x

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        return self._f(X, noise, dt)


def pda_update(
    model: ManifoldModel,
    x: np.ndarray,
    P: np.ndarray,
    pred: MeasurementPrediction,
    R: np.ndarray,
    groups: list[np.ndarray],
    candidates: list[np.ndarray],
    weights: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Probabilistic data association update over several measurement groups (e.g. markers).

    Group g owns rows ``groups[g]`` of the prediction; ``candidates[g]`` (c, k) are the
    measurements that may be its, with association probabilities ``weights[g]`` (c,) (their
    sum is the probability the group was detected at all). The unscented prediction is turned
    into its statistical linear regression y ~ y_hat + H dx + e, cov(e) = Pyy - H P H^T + R,
    and the groups are absorbed one after another with the PDA formula (Bar-Shalom & Tse), so
    each group's spread of hypotheses widens the covariance instead of being ignored.
    Returns (x, P).
    """
    H = np.linalg.solve(P, pred.Pxy).T  # (m, n) regression of y on the tangent error
    E = pred.Pyy - H @ P @ H.T + (np.diag(R) if R.ndim == 1 else R)
    dx = np.zeros(model.dim)
    for rows, Z, beta in zip(groups, candidates, weights, strict=True):
        if len(beta) == 0 or beta.sum() <= 0:
            continue
        Hg = H[rows]
        S = Hg @ P @ Hg.T + E[np.ix_(rows, rows)]
        K = np.linalg.solve(S, Hg @ P).T
        nu_i = Z - (pred.y[rows] + Hg @ dx)  # (c, k) innovations under the current correction
        nu = beta @ nu_i
        spread = (nu_i.T * beta) @ nu_i - np.outer(nu, nu)
        dx = dx + K @ nu
        P = P - beta.sum() * (K @ S @ K.T) + K @ spread @ K.T
    return model.retract(x, dx[None])[0], symmetrise(P)
