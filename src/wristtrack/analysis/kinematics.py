"""Kinematic measures of a run: range of motion, speeds, path length and reaching metrics.

Input is the column dict of a poses.csv (:func:`wristtrack.io.poses.read_poses`); output is a
JSON-ready dict (:func:`analyse`) that goes into summary.json under ``"kinematics"``. The numeric
core is pure NumPy functions on arrays, also used by the report figures.

Angles. ``deviation_deg``, ``flexion_deg`` and ``pronation_deg`` come from poses.csv as they are:
:func:`wristtrack.geometry.wrist_angles`, the intrinsic Y-Z-X decomposition of the hand rotation
relative to W0 (the neutral posture at initialisation) in the hand axes of DESIGN.md section 2
(+X wrist -> MCP3, +Z out of the back of the hand, +Y = Z x X), signed as the ISB recommends on
either hand: flexion(+)/extension(-), ulnar(+)/radial(-) deviation, pronation(+)/supination(-).
The side comes from the hand layout (thumb marker CMC1 on +Y: right hand; on -Y: left hand); on
a right hand +Y points to the thumb, so its deviation and pronation are the decomposition's Z and
X angles negated, on a left hand they are taken as they are.

Speeds. Linear speed is |v| from the tracker's filtered velocity (vx, vy, vz) where that is
finite; elsewhere central differences of the positions (tx, ty, tz) within runs of valid rows.
Angular speed likewise from (wx, wy, wz), else from neighbouring orientations (qw..qz). Rows
without a position are gaps: no path is drawn across them and they end a movement.

Filtering. Unless ``lowpass_hz`` is 0, the velocities, angular velocities and positions are
low-passed (zero-phase 2nd-order Butterworth, 6 Hz by default, a common cut-off for reaching
kinematics; each run between gaps on its own, irregular timing resampled) before speeds, path
lengths and reach metrics are taken. Without it the tracker's velocity noise, rectified by the
norm, keeps the speed above 2 % of the peak long after a reach and breaks it into spurious
movement units. The whole-run path length still accumulates some jitter of the hand at rest.

Reaches. A movement starts where the speed first rises above ``entry_speed_m_s`` (hysteresis:
noise at rest never gets that far); its onset and offset are the nearest samples, before and
after its peak, where the speed falls below ``onset_fraction`` (2 %) of that peak, or a gap.
Movements whose speed never fell below the threshold in between are one movement (the tallest
peak decides; smaller ones nearby are clipped at its boundary). Movements with a peak below
``min_peak_speed_m_s`` or shorter than ``min_duration_s`` are dropped. Frames are row indices
of poses.csv (one row per input frame), start and end inclusive.

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
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.errors import ConfigError, InputError
from wristtrack.io.poses import read_poses

AXES = ("deviation", "flexion", "pronation")
_ANGLE_COLUMNS = ("deviation_deg", "flexion_deg", "pronation_deg")


@dataclass(frozen=True)
class KinematicsSettings:
    """Thresholds of the reach segmentation and the smoothness measures (DESIGN.md section 6)."""

    lowpass_hz: float = 6.0  # zero-phase low-pass of the velocities before anything (0: off)
    onset_fraction: float = 0.02  # onset/offset where speed crosses this fraction of the peak
    entry_speed_m_s: float = 0.05  # a movement must exceed this (hysteresis against rest noise)
    min_peak_speed_m_s: float = 0.1  # slower "movements" are drift or noise, not reaches
    min_duration_s: float = 0.2  # shorter ones are jolts, not reaches
    unit_rise_m_s: float = 0.02  # movement unit: speed rise of more than 20 mm/s ...
    unit_min_interval_s: float = 0.15  # ... with peaks at least 150 ms apart
    sparc_cutoff_hz: float = 10.0  # upper limit of the adaptive SPARC cut-off
    sparc_amplitude_threshold: float = 0.05
    sparc_padlevel: int = 4  # zero padding: FFT length 2^(ceil(log2 N) + padlevel)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"kinematics setting {f.name} = {value!r}: give a number >= 0")
        if not 0.0 < self.onset_fraction < 1.0:
            raise ConfigError(
                f"kinematics setting onset_fraction = {self.onset_fraction}: give a fraction of "
                "the peak speed between 0 and 1 (0.02 is common)"
            )
        if not 0.0 < self.sparc_amplitude_threshold < 1.0 or self.sparc_cutoff_hz <= 0:
            raise ConfigError(
                "kinematics settings sparc_amplitude_threshold must lie in (0, 1) and "
                "sparc_cutoff_hz be positive (0.05 and 10 Hz are the published values)"
            )
        if self.entry_speed_m_s <= 0:
            raise ConfigError("kinematics setting entry_speed_m_s must be positive (e.g. 0.05)")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# ----------------------------------------------------------------------------- helpers


def _runs(valid: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) half-open index ranges of the runs of True in ``valid``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], valid.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _check_times(t: np.ndarray, valid: np.ndarray) -> None:
    """Timestamps must increase along each run of valid rows (they are differentiated)."""
    for a, b in _runs(valid):
        dt = np.diff(t[a:b])
        bad = np.flatnonzero(~(dt > 0))
        if bad.size:
            i = a + int(bad[0]) + 1
            raise InputError(
                f"timestamp of row {i} ({float(t[i])!r} s) does not increase on the row before; "
                "rows with a pose must be in time order"
            )


def _finite_or_none(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _position_valid(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.isfinite(p).all(axis=1) & np.isfinite(t)


def _as_xyz(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{name} must be an (N, 3) array, got shape {a.shape}")
    return a


# ----------------------------------------------------------------------------- speeds


def velocity_profile(t: np.ndarray, p: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """Linear velocity (N,3), m/s, at timestamps ``t`` (N,) of positions ``p`` (N,3).

    Where a velocity ``v`` (N,3) is given and finite it is used (the tracker's filtered
    estimate); elsewhere central differences of ``p`` within runs of finite rows (one-sided at a
    run's ends). NaN where the position is unknown or a run has a single row.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    p = _as_xyz(p, "positions")
    if len(p) != len(t):
        raise InputError(f"{len(t)} timestamps for {len(p)} positions")
    valid = _position_valid(t, p)
    _check_times(t, valid)
    out = np.full((len(t), 3), np.nan)
    if v is not None:
        v = _as_xyz(v, "velocities")
        use = valid & np.isfinite(v).all(axis=1)
        out[use] = v[use]
    need = valid & ~np.isfinite(out).all(axis=1)
    for a, b in _runs(valid):
        if b - a >= 2 and need[a:b].any():
            dp = np.gradient(p[a:b], t[a:b], axis=0, edge_order=1)
            out[a:b] = np.where(need[a:b, None], dp, out[a:b])
    return out


def speed_profile(t: np.ndarray, p: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """Linear speed (N,), m/s: the norm of :func:`velocity_profile` (NaN where unknown)."""
    return np.linalg.norm(velocity_profile(t, p, v), axis=1)


def angular_velocity_profile(
    t: np.ndarray, q: np.ndarray, w: np.ndarray | None = None
) -> np.ndarray:
    """Angular velocity (N,3), rad/s in W0: ``w`` where finite, else from the neighbouring
    orientations (unit quaternions ``q`` (N,4), w x y z, hand relative to W0) within runs of
    finite rows: log(R_next R_prev^T) / (t_next - t_prev). NaN where the orientation is unknown."""
    from wristtrack.geometry import matrix_from_quat, so3_log

    t = np.asarray(t, dtype=float).reshape(-1)
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != 4 or len(q) != len(t):
        raise InputError(f"quaternions must be ({len(t)}, 4), got shape {q.shape}")
    valid = np.isfinite(q).all(axis=1) & np.isfinite(t)
    _check_times(t, valid)
    out = np.full((len(t), 3), np.nan)
    if w is not None:
        w = _as_xyz(w, "angular velocities")
        use = valid & np.isfinite(w).all(axis=1)
        out[use] = w[use]
    need = valid & ~np.isfinite(out).all(axis=1)
    for a, b in _runs(valid):
        if b - a < 2 or not need[a:b].any():
            continue
        R = matrix_from_quat(q[a:b])
        idx = np.arange(b - a)
        lo, hi = np.maximum(idx - 1, 0), np.minimum(idx + 1, b - a - 1)
        rotvec = so3_log(R[hi] @ np.swapaxes(R[lo], -1, -2))
        diff = rotvec / (t[a:b][hi] - t[a:b][lo])[:, None]
        out[a:b] = np.where(need[a:b, None], diff, out[a:b])
    return out


def angular_speed_profile(
    t: np.ndarray, q: np.ndarray, w: np.ndarray | None = None
) -> np.ndarray:
    """Angular speed (N,), rad/s: the norm of :func:`angular_velocity_profile`."""
    return np.linalg.norm(angular_velocity_profile(t, q, w), axis=1)


def lowpass(t: np.ndarray, x: np.ndarray, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` (N,) or (N,k) sampled at ``t`` (N,), run by run.

    Rows with a NaN are gaps: each run of finite rows is filtered on its own (nothing leaks
    across a gap), and NaN rows stay NaN. A run with irregular timing (jitter, dropped frames)
    is resampled to its median frame interval, filtered and interpolated back. Runs of fewer
    than 4 rows, and runs whose Nyquist frequency is below the cut-off, are left as they are.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import butter, sosfiltfilt

    t = np.asarray(t, dtype=float).reshape(-1)
    x = np.asarray(x, dtype=float)
    flat = x.ndim == 1
    x2 = x[:, None] if flat else x
    if len(x2) != len(t):
        raise InputError(f"{len(t)} timestamps for {len(x2)} samples to filter")
    valid = np.isfinite(x2).all(axis=1) & np.isfinite(t)
    _check_times(t, valid)
    out = np.where(valid[:, None], x2, np.nan)
    for a, b in _runs(valid):
        if b - a < 4:
            continue
        tt, xx = t[a:b], x2[a:b]
        dt = float(np.median(np.diff(tt)))
        if cutoff_hz >= 0.5 / dt:
            continue
        sos = butter(order, cutoff_hz * 2.0 * dt, output="sos")
        regular = np.all(np.abs(np.diff(tt) / dt - 1.0) < 1e-3)
        # irregular: a uniform grid over the run (its last point may pass the end by < dt)
        grid = tt if regular else tt[0] + np.arange(math.ceil((tt[-1] - tt[0]) / dt) + 1) * dt
        # cubic, not linear: a few dropped frames in a row must not cut the corners of a reach
        xs = xx if regular else CubicSpline(tt, xx, axis=0)(grid)
        pad = min(3 * (2 * len(sos) + 1), len(grid) - 1)
        ys = sosfiltfilt(sos, xs, axis=0, padlen=pad)
        out[a:b] = ys if regular else CubicSpline(grid, ys, axis=0)(tt)
    return out[:, 0] if flat else out


def path_length(p: np.ndarray) -> float:
    """Length (m) of the polyline through the rows of ``p`` (N,3); rows with a NaN are gaps that
    split the path (no segment is drawn across them)."""
    p = _as_xyz(p, "positions")
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)  # NaN wherever either end is unknown
    return float(np.sum(step[np.isfinite(step)]))


def range_of_motion(angles_deg: np.ndarray) -> dict[str, dict[str, float | None]]:
    """Per anatomical axis (columns deviation, flexion, pronation of ``angles_deg`` (N,3)): min,
    max, range and the first and last known value, degrees; None where never known."""
    a = np.asarray(angles_deg, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"angles must be an (N, 3) array in degrees, got shape {a.shape}")
    out: dict[str, dict[str, float | None]] = {}
    for k, axis in enumerate(AXES):
        col = a[:, k]
        known = np.flatnonzero(np.isfinite(col))
        if known.size == 0:
            out[axis] = dict.fromkeys(("min_deg", "max_deg", "range_deg", "start_deg", "end_deg"))
            continue
        lo, hi = float(col[known].min()), float(col[known].max())
        out[axis] = {
            "min_deg": lo,
            "max_deg": hi,
            "range_deg": hi - lo,
            "start_deg": float(col[known[0]]),
            "end_deg": float(col[known[-1]]),
        }
    return out


# ----------------------------------------------------------------------------- segmentation


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
    cores = _runs(speed >= settings.entry_speed_m_s)
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


# ----------------------------------------------------------------------------- smoothness


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


# ----------------------------------------------------------------------------- per reach


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


# ----------------------------------------------------------------------------- whole run


def _column(columns: dict[str, np.ndarray], names: tuple[str, ...]) -> np.ndarray | None:
    if not all(n in columns for n in names):
        return None
    return np.column_stack([np.asarray(columns[n], dtype=float) for n in names])


def frame_rate(t: np.ndarray, valid: np.ndarray | None = None) -> float | None:
    """Median frame rate (Hz) over consecutive rows (both valid, if ``valid`` is given)."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    ok = np.isfinite(dt) & (dt > 0)
    if valid is not None:
        ok &= valid[1:] & valid[:-1]
    return float(1.0 / np.median(dt[ok])) if ok.any() else None


def _series(columns: dict[str, np.ndarray], settings: KinematicsSettings) -> dict[str, np.ndarray]:
    """Time, positions, raw and analysed speed (m/s), analysed angular speed (deg/s)."""
    missing = [c for c in ("timestamp", "tx", "ty", "tz") if c not in columns]
    if missing:
        raise InputError(f"pose columns lack {', '.join(missing)}; give a poses.csv / truth.csv")
    t = np.asarray(columns["timestamp"], dtype=float).reshape(-1)
    p = _column(columns, ("tx", "ty", "tz"))
    if len(p) != len(t):
        raise InputError(f"pose columns differ in length ({len(t)} timestamps, {len(p)} rows)")
    valid = _position_valid(t, p)
    velocity = velocity_profile(t, p, _column(columns, ("vx", "vy", "vz")))
    raw_speed = np.linalg.norm(velocity, axis=1)
    q = _column(columns, ("qw", "qx", "qy", "qz"))
    omega = (
        angular_velocity_profile(t, q, _column(columns, ("wx", "wy", "wz")))
        if q is not None
        else np.full((len(t), 3), np.nan)
    )
    if settings.lowpass_hz > 0:
        # Tracking noise rectified by |.| would otherwise hold the speed above the 2 % threshold
        # at rest, split reaches into spurious units and add jitter to the path length.
        velocity = lowpass(t, velocity, settings.lowpass_hz)
        omega = lowpass(t, omega, settings.lowpass_hz)
        p = lowpass(t, p, settings.lowpass_hz)
    return {
        "t": t,
        "valid": valid,
        "p": p,
        "raw_speed": raw_speed,
        "speed": np.linalg.norm(velocity, axis=1),
        "angular_speed": np.degrees(np.linalg.norm(omega, axis=1)),
    }


def speed_series(
    columns: dict[str, np.ndarray], settings: KinematicsSettings | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(as tracked, as analysed) wrist speed (N,), m/s, of poses.csv columns: |v| (differences
    of the positions where v is unknown), and that after the low-pass, the speed
    :func:`analyse` segments and measures the reaches on."""
    series = _series(columns, settings or KinematicsSettings())
    return series["raw_speed"], series["speed"]


def analyse(
    columns: dict[str, np.ndarray], settings: KinematicsSettings | None = None
) -> dict[str, Any]:
    """Kinematics of a run from poses.csv columns (read_poses); a JSON-ready dict (no NaN)."""
    settings = settings or KinematicsSettings()
    series = _series(columns, settings)
    t, p, valid, speed, rate = (
        series[k] for k in ("t", "p", "valid", "speed", "angular_speed")
    )
    angles = _column(columns, _ANGLE_COLUMNS)
    fs = frame_rate(t, valid)
    reaches = []
    if fs is not None:
        for index, (s, e) in enumerate(segment_reaches(t, speed, settings)):
            reaches.append({"index": index, **reach_metrics(t, p, speed, s, e, fs, settings)})
    known_t = t[np.isfinite(t)]

    def peak_mean(x: np.ndarray) -> tuple[float | None, float | None]:
        x = x[np.isfinite(x)]
        return (float(x.max()), float(x.mean())) if x.size else (None, None)

    v_peak, v_mean = peak_mean(speed)
    w_peak, w_mean = peak_mean(rate)
    return {
        "settings": settings.to_dict(),
        "range_of_motion": range_of_motion(
            angles if angles is not None else np.full((len(t), 3), np.nan)
        ),
        "speed": {"peak_m_s": v_peak, "mean_m_s": v_mean},
        "angular_speed": {"peak_deg_s": w_peak, "mean_deg_s": w_mean},
        "path_length_m": path_length(p),
        "duration_s": float(known_t[-1] - known_t[0]) if known_t.size else 0.0,
        "frame_rate_hz": fs,
        "reaches": reaches,
        "reach_summary": {
            "count": len(reaches),
            "mean_peak_speed_m_s": (
                float(np.mean([r["peak_speed_m_s"] for r in reaches])) if reaches else None
            ),
            "mean_movement_time_s": (
                float(np.mean([r["movement_time_s"] for r in reaches])) if reaches else None
            ),
        },
    }


_NEEDED = (
    "timestamp", "tx", "ty", "tz", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz",
    *_ANGLE_COLUMNS,
)


def analyse_file(
    poses_csv: str | Path, settings: KinematicsSettings | None = None
) -> dict[str, Any]:
    """:func:`analyse` of a poses.csv (or truth.csv) read back from disk."""
    # Only the columns analyse() needs: a long run's poses.csv read whole would break the
    # pipeline's flat memory.
    columns = read_poses(poses_csv, columns=_NEEDED)
    try:
        return analyse(columns, settings)
    except InputError as exc:
        raise InputError(f"{poses_csv}: {exc}") from None


def format_reaches(kinematics: dict[str, Any]) -> str:
    """One line for the console: number of reaches, mean peak speed and movement time."""
    s = kinematics["reach_summary"]
    if not s["count"]:
        return "  reaches    none detected"
    return (
        f"  reaches    {s['count']} detected: mean peak speed {s['mean_peak_speed_m_s']:.3f} m/s, "
        f"mean movement time {s['mean_movement_time_s']:.2f} s"
    )


__all__ = [
    "AXES",
    "KinematicsSettings",
    "analyse",
    "analyse_file",
    "angular_speed_profile",
    "angular_velocity_profile",
    "format_reaches",
    "frame_rate",
    "log_dimensionless_jerk",
    "lowpass",
    "movement_units",
    "path_length",
    "range_of_motion",
    "reach_metrics",
    "segment_reaches",
    "sparc",
    "speed_series",
    "speed_profile",
    "velocity_profile",
]
