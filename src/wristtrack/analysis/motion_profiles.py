"""Velocity and speed profiles, the low-pass and path length of a pose series: pure NumPy on
arrays (timestamps (N,), positions (N,3), quaternions (N,4)), gaps as NaN rows.

Speeds. Linear speed is |v| from the tracker's filtered velocity (vx, vy, vz) where that is
finite; elsewhere central differences of the positions (tx, ty, tz) within runs of valid rows.
Angular speed likewise from (wx, wy, wz), else from neighbouring orientations (qw..qz). Rows
without a position are gaps: no path is drawn across them and they end a movement.

Filtering. Unless ``lowpass_hz`` is 0, the velocities, angular velocities and positions are
low-passed (a 4th-order zero-lag Butterworth, 3 dB down at 6 Hz by default, a common cut-off
for reaching kinematics: :func:`dual_pass_butterworth`; each run between gaps on its own,
irregular timing resampled) before speeds, path
lengths and reach metrics are taken. Without it the tracker's velocity noise, rectified by the
norm, keeps the speed above 2 % of the peak long after a reach and breaks it into spurious
movement units. The whole-run path length still accumulates some jitter of the hand at rest.
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.errors import InputError
from wristtrack.geometry import matrix_from_quat, so3_log


def true_spans(valid: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) half-open index ranges of the runs of True in ``valid``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], valid.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _check_times(t: np.ndarray, valid: np.ndarray) -> None:
    """Timestamps must increase along each run of valid rows (they are differentiated)."""
    for a, b in true_spans(valid):
        dt = np.diff(t[a:b])
        bad = np.flatnonzero(~(dt > 0))
        if bad.size:
            i = a + int(bad[0]) + 1
            raise InputError(
                f"timestamp of row {i} ({float(t[i])!r} s) does not increase on the row before; "
                "rows with a pose must be in time order"
            )


def position_valid(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.isfinite(p).all(axis=1) & np.isfinite(t)


def _as_xyz(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{name} must be an (N, 3) array, got shape {a.shape}")
    return a


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
    valid = position_valid(t, p)
    _check_times(t, valid)
    out = np.full((len(t), 3), np.nan)
    if v is not None:
        v = _as_xyz(v, "velocities")
        use = valid & np.isfinite(v).all(axis=1)
        out[use] = v[use]
    need = valid & ~np.isfinite(out).all(axis=1)
    for a, b in true_spans(valid):
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
    for a, b in true_spans(valid):
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


# The two passes square a pass's gain, so the -3 dB point falls below the design cutoff by
# (sqrt(2) - 1) ** (1 / (2 ORDER)) = 0.802 in warped frequency (Winter's correction).
BUTTERWORTH_ORDER = 2  # per pass: forward and backward make a fourth-order zero-lag filter
DUAL_PASS = (np.sqrt(2.0) - 1.0) ** (1.0 / (2 * BUTTERWORTH_ORDER))


def dual_pass_butterworth(cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Second-order sections of the per-pass Butterworth low-pass whose forward-backward run
    (``scipy.signal.sosfiltfilt``) is 3 dB down at ``cutoff_hz`` (0 < cutoff < rate / 2) for
    samples at ``rate_hz``: Winter (Biomechanics and Motor Control of Human Movement, 2009,
    ch. 3) raises the design cutoff so that the two passes together, a pass's gain squared
    1 / (1 + (w / w_d)^4) at the warped frequency w = tan(pi f / rate), meet the one asked for:
    w_d = w_c / DUAL_PASS."""
    from scipy.signal import butter

    warped = np.tan(np.pi * cutoff_hz / rate_hz) / DUAL_PASS
    return butter(BUTTERWORTH_ORDER, rate_hz / np.pi * np.arctan(warped), fs=rate_hz,
                  output="sos")


def lowpass(t: np.ndarray, x: np.ndarray, cutoff_hz: float) -> np.ndarray:
    """Zero-lag Butterworth low-pass (:func:`dual_pass_butterworth`) of ``x`` (N,) or (N,k)
    sampled at ``t`` (N,), run by run.

    Rows with a NaN are gaps: each run of finite rows is filtered on its own (nothing leaks
    across a gap), and NaN rows stay NaN. A run with irregular timing (jitter, dropped frames)
    is resampled to its median frame interval, filtered and interpolated back. Runs of fewer
    than 4 rows, and runs whose Nyquist frequency is below the cut-off, are left as they are.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import sosfiltfilt

    t = np.asarray(t, dtype=float).reshape(-1)
    x = np.asarray(x, dtype=float)
    flat = x.ndim == 1
    x2 = x[:, None] if flat else x
    if len(x2) != len(t):
        raise InputError(f"{len(t)} timestamps for {len(x2)} samples to filter")
    valid = np.isfinite(x2).all(axis=1) & np.isfinite(t)
    _check_times(t, valid)
    out = np.where(valid[:, None], x2, np.nan)
    for a, b in true_spans(valid):
        if b - a < 4:
            continue
        tt, xx = t[a:b], x2[a:b]
        dt = float(np.median(np.diff(tt)))
        if cutoff_hz >= 0.5 / dt:
            continue
        sos = dual_pass_butterworth(cutoff_hz, 1.0 / dt)
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


def median_frame_rate(t: np.ndarray, valid: np.ndarray | None = None) -> float | None:
    """Median frame rate (Hz) over consecutive rows (both valid, if ``valid`` is given)."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    ok = np.isfinite(dt) & (dt > 0)
    if valid is not None:
        ok &= valid[1:] & valid[:-1]
    return float(1.0 / np.median(dt[ok])) if ok.any() else None
