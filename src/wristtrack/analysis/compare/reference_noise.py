"""How much of the disagreement ``wristtrack compare`` reports is the reference's own noise.

An optoelectronic system's markers are not exact (0.05-0.1 mm per coordinate), and on markers a
few centimetres apart that is a few hundredths of a degree of orientation per frame, a third of
what the tracker's own error is on our six markers. Independent of ours, it adds in quadrature
to every RMSE ``compare`` reports, so the error net of it, sqrt(RMSE^2 - noise^2), is the
estimate of ours.

The noise is read off the reference itself, from the rigid fits that make its poses
(compare/reference.py): with K markers of independent noise sigma per coordinate, a fit leaves
residuals whose squares sum to sigma^2 (3K - 6) on average. From sigma and the markers'
geometry follows the fitted pose's noise (a least-squares rigid fit, small noise): the
rotation's covariance is sigma^2 J^-1, J = sum_k (|a_k|^2 I - a_k a_k^T) over the markers' arms
a_k from their centroid, and a point q of the body moves with the centroid (sigma^2 / K per
axis) and with the rotation about it (arm q - centroid).

The reference is compared where our frames fall, between its samples: its splines there pass
on a little less of the noise than its samples hold (white noise: 0.87 of the variance on
average over the phase between two samples, 0.76 half-way), and nearly all of it once its
markers were low-passed (the noise is then smooth from one sample to the next). The factor is
computed for the spline, the low-pass and the phases at hand.

A marker that moves on the skin against the others (soft tissue, a knock) counts here as noise,
so on a real hand this is an upper bound of the instrument's noise, and the net error a lower
bound of ours.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import sosfiltfilt

# Samples each side of the query that the variance factor's spline and low-pass are worked out
# over: beyond the reach of a cubic spline's weights (x0.27 a sample) and of a zero-lag
# Butterworth at the cutoffs labs use (6 Hz and up at 100-200 Hz: a few tens of samples).
_HALF_WINDOW = 128
_PHASES = 65  # phases between two samples at which the factor is tabulated


@dataclass(frozen=True)
class ReferenceNoise:
    """The reference's noise, per frame compared (root mean squares)."""

    marker_mm: float  # each marker coordinate's sigma, mm
    rotation_deg: float  # the fitted orientation's RMS error, deg
    position_mm: float  # the compared point's RMS position error, mm
    variance_factor: float  # the share of the samples' noise variance left where compared

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def marker_sigma(fit_rms: np.ndarray, n_markers: np.ndarray | int) -> float:
    """Each marker coordinate's noise sigma from per-frame rigid fits of ``n_markers`` markers
    (each frame's, or one count for all) whose RMS residuals (root of the mean over the markers
    of the squared 3-D distance) are ``fit_rms`` (NaN: no fit): their squares summed over the
    markers, over the degrees of freedom 3K - 6 they leave; NaN without a fit of three or more."""
    rms = np.asarray(fit_rms, dtype=float)
    k = np.broadcast_to(np.asarray(n_markers, dtype=float), rms.shape)
    ok = np.isfinite(rms) & (k >= 3)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.sum(rms[ok] ** 2 * k[ok]) / np.sum(3 * k[ok] - 6)))


def pose_noise(model: np.ndarray, sigma: float, point: np.ndarray) -> tuple[float, float]:
    """(rotation RMS, rad; RMS position error of body ``point`` (3,)) of a least-squares rigid fit
    of the body points ``model`` (K, 3) to markers with noise ``sigma`` per coordinate (the
    position in ``sigma``'s units): the module doc's covariances."""
    model = np.asarray(model, dtype=float)
    centroid = model.mean(axis=0)
    arms = model - centroid
    J = (arms**2).sum() * np.eye(3) - arms.T @ arms
    rot_cov = sigma**2 * np.linalg.inv(J)
    q = np.asarray(point, dtype=float) - centroid
    lever = np.array([[0.0, -q[2], q[1]], [q[2], 0.0, -q[0]], [-q[1], q[0], 0.0]])
    pos_var = 3 * sigma**2 / len(model) + np.trace(lever @ rot_cov @ lever.T)
    return float(np.sqrt(np.trace(rot_cov))), float(np.sqrt(pos_var))


@functools.lru_cache(maxsize=32)
def _factor_table(lowpass_sos: tuple[tuple[float, ...], ...] | None) -> np.ndarray:
    """(_PHASES,) variance factor at phases 0..1 between two samples: a cubic spline through
    white noise, low-passed first by the second-order sections ``lowpass_sos`` (zero-lag) where
    given, against the variance at a sample."""
    n = 2 * _HALF_WINDOW + 1
    F = np.eye(n)
    if lowpass_sos is not None:
        F = sosfiltfilt(np.array(lowpass_sos), F, axis=0)
    cov = F @ F.T  # the samples' noise covariance, per unit of white noise
    weights = CubicSpline(np.arange(n), np.eye(n))(
        _HALF_WINDOW + np.linspace(0.0, 1.0, _PHASES))  # (phases, n)
    at_sample = cov[_HALF_WINDOW, _HALF_WINDOW]
    return np.einsum("pi,ij,pj->p", weights, cov, weights) / at_sample


def variance_factor(times: np.ndarray, first: float, rate: float,
                    lowpass_sos: np.ndarray | None = None) -> float:
    """The mean over the query ``times`` (s, the reference's clock) of the share of its samples'
    noise variance that a cubic spline through samples at ``rate`` Hz from ``first`` s passes on
    (after the zero-lag low-pass ``lowpass_sos`` where given); 1 without queries."""
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        return 1.0
    key = None if lowpass_sos is None else tuple(map(tuple, np.asarray(lowpass_sos).tolist()))
    table = _factor_table(key)
    phase = np.mod((times - first) * rate, 1.0)
    return float(np.mean(np.interp(phase, np.linspace(0.0, 1.0, _PHASES), table)))


def reference_noise(model: np.ndarray, fit_rms_mm: np.ndarray, point: np.ndarray,
                    times: np.ndarray, first: float, rate: float,
                    lowpass_sos: np.ndarray | None = None,
                    fit_markers: np.ndarray | None = None) -> ReferenceNoise | None:
    """The reference's noise where compared (``times``, its clock), from its rigid fits of the body
    points ``model`` (K, 3; metres) with per-frame RMS residuals ``fit_rms_mm`` over
    ``fit_markers`` markers each (None: all K), at the body ``point`` whose position is
    compared; None without a rigid fit of three or more markers."""
    sigma_mm = marker_sigma(fit_rms_mm, len(model) if fit_markers is None else fit_markers)
    if not np.isfinite(sigma_mm):
        return None
    factor = variance_factor(times, first, rate, lowpass_sos)
    rot, pos_m = pose_noise(model, sigma_mm * 1e-3, point)
    scale = float(np.sqrt(factor))
    return ReferenceNoise(sigma_mm, float(np.degrees(rot)) * scale, pos_m * 1e3 * scale, factor)


def net_of(rmse: float | None, noise: float | None) -> float | None:
    """sqrt(rmse^2 - noise^2), 0 where the noise explains all of it; None without both."""
    if rmse is None or noise is None or not np.isfinite(rmse) or not np.isfinite(noise):
        return None
    return float(np.sqrt(max(rmse**2 - noise**2, 0.0)))
