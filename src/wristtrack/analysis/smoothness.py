"""Smoothness of one movement's speed profile: SPARC, log dimensionless jerk, movement units.

Smoothness, per reach, on the speed resampled to a uniform grid at the run's median frame rate:

- SPARC (Balasubramanian et al. 2015, J NeuroEng Rehabil 12:112): minus the arc length of the
  magnitude spectrum of the zero-padded speed (FFT length 2^(ceil(log2 N) + 4)), normalised to
  its maximum, over [0, fc_adaptive] in frequency normalised by that band; fc_adaptive is the last
  frequency at or below min(10 Hz, Nyquist) whose magnitude reaches 0.05. Equals
  ``monalysa.quality.smoothness.sparc`` whenever fs >= 20 Hz (monalysa would read past Nyquist
  into the mirrored spectrum below that).
- Log dimensionless jerk (Hogan & Sternad 2009; Balasubramanian 2015) of the speed:
  -ln( T^3 / v_peak^2 * sum((d2v/dt2)^2) dt ), d2v/dt2 by second differences, with monalysa's
  conventions (``log_dimensionless_jerk(speed, fs, data_type="vel")``): T = N / fs for N
  samples, the integral a plain sum. A minimum-jerk speed profile gives -ln(204.8) = -5.32 in
  the continuous limit.
- Movement units (Alt Murphy et al. 2011): rises of the speed of more than ``unit_rise_m_s``
  (20 mm/s) from a local minimum to the next peak, peaks at least ``unit_min_interval_s``
  (150 ms) apart. Minima and maxima are confirmed with the same 20 mm/s hysteresis, so wiggles
  smaller than that neither count nor hide a real unit.
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.errors import InputError


def sparc(
    speed: np.ndarray,
    fs: float,
    padlevel: int = 4,
    fc: float = 10.0,
    amp_th: float = 0.05,
) -> float:
    """Spectral arc length (SPARC, Balasubramanian et al. 2015) of a speed profile sampled at
    ``fs`` Hz. Closer to 0 is smoother; a minimum-jerk reach scores about -1.4 to -1.6."""
    v = np.asarray(speed, dtype=float).reshape(-1)
    if v.size < 2 or not np.isfinite(v).all() or not fs > 0:
        raise InputError(f"SPARC needs >= 2 finite speed samples and fs > 0 (got {v.size}, {fs})")
    nfft = int(2 ** (math.ceil(math.log2(v.size)) + padlevel))
    mag = np.abs(np.fft.rfft(v, nfft))  # real input: the half spectrum to Nyquist is enough
    if not mag.max() > 0:
        raise InputError("SPARC of a speed profile that is zero throughout is undefined")
    mag /= mag.max()
    f = np.arange(mag.size) * (fs / nfft)
    band = f <= fc
    f, mag = f[band], mag[band]
    above = np.flatnonzero(mag >= amp_th)
    f, mag = f[above[0] : above[-1] + 1], mag[above[0] : above[-1] + 1]
    if f.size < 2:
        return 0.0  # a single spectral line: no arc
    df = np.diff(f) / (f[-1] - f[0])
    return float(-np.sum(np.sqrt(df**2 + np.diff(mag) ** 2)))


def log_dimensionless_jerk(speed: np.ndarray, fs: float) -> float:
    """Log dimensionless jerk of a speed profile sampled at ``fs`` Hz (monalysa's convention:
    T = N/fs, jerk integral a sum of squared second differences times 1/fs). Closer to 0 is
    smoother; +inf if the speed has no jerk at all (a constant or linear profile)."""
    v = np.asarray(speed, dtype=float).reshape(-1)
    if v.size < 3 or not np.isfinite(v).all() or not fs > 0:
        raise InputError(
            f"log dimensionless jerk needs >= 3 finite speed samples and fs > 0 "
            f"(got {v.size}, {fs})"
        )
    peak = float(np.max(np.abs(v)))
    if not peak > 0:
        raise InputError("log dimensionless jerk of a speed that is zero throughout is undefined")
    dt = 1.0 / fs
    jerk_cost = float(np.sum((np.diff(v, 2) / dt**2) ** 2) * dt)
    duration = v.size * dt
    if jerk_cost == 0.0:
        return math.inf
    return -(3.0 * math.log(duration) - 2.0 * math.log(peak) + math.log(jerk_cost))


def movement_units(
    t: np.ndarray, speed: np.ndarray, rise: float = 0.02, min_interval: float = 0.15
) -> int:
    """Number of movement units in one movement's speed (N,) at times ``t`` (N,): rises of more
    than ``rise`` m/s from a local minimum to the next peak, peaks ``min_interval`` s apart.

    Extrema are found with ``rise`` as hysteresis (a peak is confirmed once the speed has fallen
    ``rise`` below it, or the movement ends; a minimum once it has risen ``rise`` above it).
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    v = np.asarray(speed, dtype=float).reshape(-1)
    keep = np.isfinite(v) & np.isfinite(t)
    t, v = t[keep], v[keep]
    if v.size == 0:
        return 0
    peaks: list[int] = []
    low, high, rising = 0, 0, False  # current minimum / maximum candidates
    for i in range(1, v.size):
        if rising:
            if v[i] > v[high]:
                high = i
            elif v[i] < v[high] - rise:
                peaks.append(high)
                rising, low = False, i
        else:
            if v[i] < v[low]:
                low = i
            elif v[i] > v[low] + rise:
                rising, high = True, i
    if rising:
        peaks.append(high)  # the movement ended (or a gap came) before the speed fell again
    units, last = 0, -math.inf
    for k in peaks:
        if t[k] - last >= min_interval:
            units += 1
            last = t[k]
    return units
