"""Reaches in a speed profile, and the metrics of each (DESIGN.md section 6).

Reaches. A movement starts where the speed first rises above ``entry_speed_m_s`` (hysteresis:
noise at rest never gets that far); its onset and offset are the nearest samples, before and
after its peak, where the speed falls below ``onset_fraction`` (2 %) of that peak, or a gap.
Movements whose speed never fell below the threshold in between are one movement (the tallest
peak decides; smaller ones nearby are clipped at its boundary). Movements with a peak below
``min_peak_speed_m_s`` or shorter than ``min_duration_s`` are dropped. Frames are row indices
of poses.csv (one row per input frame), start and end inclusive.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wristtrack.analysis.kinematics_settings import KinematicsSettings
from wristtrack.analysis.motion_profiles import path_length, true_spans
from wristtrack.analysis.smoothness import log_dimensionless_jerk, movement_units, sparc
from wristtrack.errors import InputError


def _extent(speed: np.ndarray, peak: int, threshold: float, lo: int, hi: int) -> tuple[int, int]:
    """Inclusive [start, end] around ``peak`` of samples >= threshold, within [lo, hi]; NaN
    (a gap) counts as below."""
    below = ~(speed[lo : hi + 1] >= threshold)
    k = peak - lo
    left = np.flatnonzero(below[:k])
    right = np.flatnonzero(below[k + 1 :])
    start = lo + int(left[-1]) + 1 if left.size else lo
    end = peak + int(right[0]) if right.size else hi
    return start, end


def segment_reaches(
    t: np.ndarray, speed: np.ndarray, settings: KinematicsSettings | None = None
) -> list[tuple[int, int]]:
    """Movements in a speed profile (N,) at timestamps ``t`` (N,), as inclusive (start, end)
    sample indices in time order (see the module docstring for the rule)."""
    settings = settings or KinematicsSettings()
    t = np.asarray(t, dtype=float).reshape(-1)
    speed = np.asarray(speed, dtype=float).reshape(-1)
    if len(t) != len(speed):
        raise InputError(f"{len(t)} timestamps for {len(speed)} speed samples")
    n = len(speed)
    cores = true_spans(speed >= settings.entry_speed_m_s)
    # Tallest first: its extent claims every core inside it; smaller movements are clipped at
    # the boundaries of those already claimed, so movements never overlap.
    order = sorted(cores, key=lambda c: -float(np.max(speed[c[0] : c[1]])))
    taken: list[tuple[int, int]] = []
    for a, b in order:
        peak = a + int(np.argmax(speed[a:b]))
        if any(s <= peak <= e for s, e in taken):
            continue
        lo = max([e + 1 for s, e in taken if e < peak], default=0)
        hi = min([s - 1 for s, e in taken if s > peak], default=n - 1)
        taken.append(_extent(speed, peak, settings.onset_fraction * speed[peak], lo, hi))
    reaches = []
    for s, e in sorted(taken):
        if np.max(speed[s : e + 1]) < settings.min_peak_speed_m_s:
            continue
        if not t[e] - t[s] >= settings.min_duration_s:
            continue
        reaches.append((s, e))
    return reaches


def _finite_or_none(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _uniform(t: np.ndarray, v: np.ndarray, fs: float) -> np.ndarray:
    """``v`` at times ``t`` resampled to a grid of step 1/fs from t[0] (as is when already)."""
    dt = np.diff(t)
    if np.all(np.abs(dt * fs - 1.0) < 1e-3):
        return v
    n = int(math.floor((t[-1] - t[0]) * fs + 1e-6)) + 1
    return np.interp(t[0] + np.arange(n) / fs, t, v)


def reach_metrics(
    t: np.ndarray,
    p: np.ndarray,
    speed: np.ndarray,
    start: int,
    end: int,
    fs: float,
    settings: KinematicsSettings | None = None,
) -> dict[str, Any]:
    """Metrics of the movement over samples ``start``..``end`` (inclusive) of a run."""
    settings = settings or KinematicsSettings()
    sl = slice(start, end + 1)
    tt, vv, pp = t[sl], speed[sl], p[sl]
    peak = int(np.argmax(vv))
    movement_time = float(tt[-1] - tt[0])
    path = path_length(pp)
    straight = float(np.linalg.norm(pp[-1] - pp[0]))
    uniform = _uniform(tt, vv, fs)
    sp = ldlj = None
    if uniform.size >= 3:
        sp = sparc(
            uniform, fs, settings.sparc_padlevel, settings.sparc_cutoff_hz,
            settings.sparc_amplitude_threshold,
        )
        ldlj = _finite_or_none(log_dimensionless_jerk(uniform, fs))
    truncated = bool(
        start == 0 or end == len(t) - 1 or not np.isfinite(speed[start - 1])
        or not np.isfinite(speed[end + 1])
    )
    return {
        "start_frame": int(start),
        "end_frame": int(end),
        "peak_frame": int(start + peak),
        "onset_s": float(tt[0]),
        "offset_s": float(tt[-1]),
        "movement_time_s": movement_time,
        "peak_speed_m_s": float(vv[peak]),
        "time_to_peak_s": float(tt[peak] - tt[0]),
        "time_to_peak_pct": (
            100.0 * float(tt[peak] - tt[0]) / movement_time if movement_time > 0 else None
        ),
        "path_length_m": path,
        "straight_line_m": straight,
        "path_length_ratio": path / straight if straight > 1e-9 else None,
        "sparc": sp,
        "log_dimensionless_jerk": ldlj,
        "movement_units": movement_units(
            tt, vv, settings.unit_rise_m_s, settings.unit_min_interval_s
        ),
        # Cut by a gap or the recording's edge before the speed fell below the threshold:
        # its time-based metrics describe only the part that was seen.
        "truncated": truncated,
    }
