"""The reference's own noise (compare/reference_noise.py) against Monte Carlo draws of the very
operations it stands for: rigid fits of noisy markers, and cubic splines through (low-passed)
white noise read between the samples."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.signal import sosfiltfilt
from scipy.spatial.transform import Rotation

from wristtrack.analysis.compare.lowpass import butterworth
from wristtrack.analysis.compare.reference import rigid_fit
from wristtrack.analysis.compare.reference_noise import (
    marker_sigma,
    net_of,
    pose_noise,
    reference_noise,
    variance_factor,
)
from wristtrack.hand import HandLayout

CLUSTER = np.array([[0.0, 0.0, 0.0], [0.04, -0.01, 0.005], [0.02, 0.035, 0.0]])


def _fits(model: np.ndarray, sigma: float, n: int = 20000, seed: int = 0):
    """Rigid fits of ``model`` to itself with ``sigma`` of noise per coordinate: R, t, RMS."""
    noisy = model + np.random.default_rng(seed).normal(0.0, sigma, (n, *model.shape))
    return rigid_fit(model, noisy)


@pytest.mark.parametrize("model", [HandLayout.default().points, CLUSTER],
                         ids=["our six markers", "a three-marker cluster"])
def test_the_marker_noise_is_read_off_the_fit_residuals(model):
    _, _, rms = _fits(model, 5e-5)
    assert marker_sigma(rms, len(model)) == pytest.approx(5e-5, rel=0.02)


@pytest.mark.parametrize("model", [HandLayout.default().points, CLUSTER],
                         ids=["our six markers", "a three-marker cluster"])
def test_the_fitted_pose_noise_matches_drawn_fits(model):
    sigma = 5e-5
    R, t, _ = _fits(model, sigma)
    drawn_rot = np.sqrt(np.mean(Rotation.from_matrix(R).magnitude() ** 2))
    far = np.array([0.05, -0.08, 0.03])  # a point well off the markers: the lever counts
    for point in (np.zeros(3), far):
        moved = np.einsum("nij,j->ni", R, point) + t - point
        drawn_pos = np.sqrt(np.mean(np.sum(moved**2, axis=1)))
        rot, pos = pose_noise(model, sigma, point)
        assert rot == pytest.approx(drawn_rot, rel=0.03)
        assert pos == pytest.approx(drawn_pos, rel=0.03)


@pytest.mark.parametrize("cutoff", [None, 15.0, 6.0])
def test_the_variance_factor_matches_splines_through_drawn_noise(cutoff):
    rate, n = 100.0, 40000
    rng = np.random.default_rng(1)
    noise = rng.normal(0.0, 1.0, n)
    sos = None if cutoff is None else butterworth(cutoff, rate)
    if sos is not None:
        noise = sosfiltfilt(sos, noise)
    times = np.arange(n) / rate
    inner = noise[500:-500]
    queries = rng.uniform(times[600], times[-600], 20000)
    drawn = np.var(CubicSpline(times, noise)(queries)) / np.var(inner)
    assert variance_factor(queries, times[0], rate, sos) == pytest.approx(drawn, rel=0.03)


def test_the_variance_factor_is_one_on_the_samples_and_lowest_half_way():
    on = variance_factor(np.arange(10) / 100.0, 0.0, 100.0)
    half = variance_factor((np.arange(10) + 0.5) / 100.0, 0.0, 100.0)
    assert on == pytest.approx(1.0, abs=1e-9)
    assert 0.7 < half < 0.8
    assert variance_factor(np.array([]), 0.0, 100.0) == 1.0


def test_the_reference_noise_where_compared_scales_the_fit_by_the_factor():
    model = HandLayout.default().points
    _, _, rms = _fits(model, 5e-5, n=4000)
    queries = (np.arange(200) + 0.5) / 100.0
    noise = reference_noise(model, rms * 1e3, np.zeros(3), queries, 0.0, 100.0)
    rot, pos = pose_noise(model, noise.marker_mm * 1e-3, np.zeros(3))
    factor = variance_factor(queries, 0.0, 100.0)
    assert noise.variance_factor == pytest.approx(factor)
    assert noise.rotation_deg == pytest.approx(np.degrees(rot) * np.sqrt(factor))
    assert noise.position_mm == pytest.approx(pos * 1e3 * np.sqrt(factor))
    assert reference_noise(model, np.full(5, np.nan), np.zeros(3), queries, 0.0, 100.0) is None


def test_net_of_takes_the_noise_out_in_quadrature():
    assert net_of(0.5, 0.3) == pytest.approx(0.4)
    assert net_of(0.2, 0.3) == 0.0
    assert net_of(None, 0.3) is None and net_of(0.2, None) is None



def test_frames_missing_markers_count_their_own_degrees_of_freedom():
    """Six markers, one of them lost in half the frames: each frame's residuals over its own
    3K - 6 degrees of freedom still give the markers' noise (taking all frames as six-marker fits
    would read it 2.5 % low)."""
    model = HandLayout.default().points
    noisy = model + np.random.default_rng(8).normal(0.0, 5e-5, (20000, *model.shape))
    noisy[::2, 2] = np.nan
    _, _, rms = rigid_fit(model, noisy)
    counts = np.isfinite(noisy).all(axis=2).sum(axis=1)
    assert marker_sigma(rms, counts) == pytest.approx(5e-5, rel=0.02)
    assert marker_sigma(rms, 6) < 0.98 * 5e-5
