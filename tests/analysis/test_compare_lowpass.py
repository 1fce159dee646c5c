"""The reference's low-pass (analysis/compare/lowpass.py): its gain against the Butterworth's
defining -3 dB at the cutoff, no lag, gaps kept, bad cutoffs refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from wristtrack.analysis.compare.lowpass import lowpass_markers
from wristtrack.errors import ConfigError
from wristtrack.io.markers.data import MarkerData

RATE = 100.0


def _markers(xyz: np.ndarray) -> MarkerData:
    n, k = xyz.shape[:2]
    return MarkerData(tuple(f"M{i}" for i in range(k)), np.arange(n) / RATE, xyz, RATE, "m",
                      "test")


def _sine(freq_hz: float, n: int = 4000) -> np.ndarray:
    t = np.arange(n) / RATE
    xyz = np.zeros((n, 1, 3))
    xyz[:, 0, 0] = np.sin(2 * np.pi * freq_hz * t)
    return xyz


@pytest.mark.parametrize("cutoff", [6.0, 10.0, 15.0])
def test_the_two_passes_are_3_db_down_at_the_cutoff_with_no_lag(cutoff):
    """A sine at the cutoff comes out at 1/sqrt(2) of its amplitude, in phase (zero lag: the
    output is the input scaled); a sine at a fifth of it passes whole."""
    mid = slice(1000, 3000)  # clear of the edges' transients
    x = _sine(cutoff)
    y = lowpass_markers(_markers(x), cutoff).xyz
    gain = y[mid, 0, 0] @ x[mid, 0, 0] / (x[mid, 0, 0] @ x[mid, 0, 0])
    assert gain == pytest.approx(1 / np.sqrt(2), abs=0.01)
    assert np.abs(y[mid, 0, 0] - gain * x[mid, 0, 0]).max() < 0.01  # no phase shift
    slow = _sine(cutoff / 5)
    assert np.abs(lowpass_markers(_markers(slow), cutoff).xyz[mid] - slow[mid]).max() < 0.01


def test_white_noise_loses_what_lies_above_the_cutoff():
    """0.1 mm white noise at 100 Hz low-passed at 10 Hz keeps about the share of its variance
    below the cutoff (10 of 50 Hz)."""
    noise = np.random.default_rng(0).normal(0, 1e-4, (20000, 2, 3))
    out = lowpass_markers(_markers(noise), 10.0).xyz
    assert out.std() / noise.std() == pytest.approx(np.sqrt(10 / 50), rel=0.1)


def test_gaps_stay_gaps_and_short_stretches_stay_as_recorded():
    x = _sine(3.0, 400) + np.random.default_rng(1).normal(0, 1e-3, (400, 1, 3))
    x[100:120] = np.nan
    x[125:130] = np.nan  # leaves a 5-sample stretch between the gaps
    out = lowpass_markers(_markers(x), 8.0)
    assert np.array_equal(np.isnan(out.xyz), np.isnan(x))
    assert np.array_equal(out.xyz[120:125], x[120:125])
    assert not np.allclose(out.xyz[:100], x[:100])
    assert "1 gap-free stretch(es) too short to filter" in out.notes[-1]


@pytest.mark.parametrize("cutoff", [0.0, -5.0, float("nan"), 50.0, 80.0])
def test_a_cutoff_the_samples_cannot_give_is_refused(cutoff):
    """Positive and below the Nyquist frequency (50 Hz here)."""
    with pytest.raises(ConfigError, match="cutoff"):
        lowpass_markers(_markers(_sine(1.0, 100)), cutoff)
