"""Coarse time alignment of two recordings of one movement: the lag that best lines up their
speed profiles (cross-correlation), refined later jointly with the registration.

Speed is the one signal both systems share before anything is registered: it does not depend
on either system's frame. Convention (DESIGN.md section 3): reference time = our time + offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from wristtrack.errors import InputError

GRID_S = 0.002  # common sampling step of the profiles; the joint refinement goes below it


@dataclass(frozen=True)
class CoarseAlignment:
    offset_s: float  # reference time = our time + offset
    peak: float  # normalised cross-correlation at the chosen lag (1 = identical shapes)


def speed(times: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Speed (N,) m/s by central differences over consecutive valid samples; NaN elsewhere."""
    t = np.asarray(times, dtype=float)
    p = np.asarray(positions, dtype=float)
    out = np.full(len(t), np.nan)
    ok = np.isfinite(p).all(axis=1) & np.isfinite(t)
    both = ok[2:] & ok[:-2]
    dt = t[2:] - t[:-2]
    good = both & (dt > 0)
    v = np.linalg.norm(p[2:] - p[:-2], axis=1) / np.where(good, dt, 1.0)
    out[1:-1] = np.where(good, v, np.nan)
    return out


def _on_grid(t: np.ndarray, x: np.ndarray, step: float) -> tuple[float, np.ndarray]:
    """x resampled on a uniform grid from its first finite sample; 0 in gaps (after the mean is
    removed, so a gap adds nothing to the correlation)."""
    ok = np.isfinite(x)
    tt, xx = t[ok], x[ok]
    grid = np.arange(tt[0], tt[-1], step)
    y = np.interp(grid, tt, xx)
    # Samples in a gap longer than 3 source intervals are unknown, not interpolated.
    j = np.clip(np.searchsorted(tt, grid), 1, len(tt) - 1)
    gap = (tt[j] - tt[j - 1]) > 3.0 * np.median(np.diff(tt))
    y = (y - y[~gap].mean()) / (y[~gap].std() or 1.0)
    y[gap] = 0.0
    return float(tt[0]), y


def coarse_offset(
    t_ours: np.ndarray,
    speed_ours: np.ndarray,
    t_ref: np.ndarray,
    speed_ref: np.ndarray,
    max_lag_s: float | None = None,
) -> CoarseAlignment:
    """Offset (reference time = our time + offset) maximising the cross-correlation of the two
    speed profiles, to a fraction of GRID_S (parabolic peak interpolation)."""
    for name, v in (("our run", speed_ours), ("the reference", speed_ref)):
        if np.isfinite(v).sum() < 10:
            raise InputError(f"{name} has fewer than 10 speed samples; nothing to align")
        if np.nanstd(v) < 1e-4:
            raise InputError(
                f"{name} shows no movement (speed spread {np.nanstd(v) * 1e3:.2f} mm/s): time "
                "alignment needs the hand to move in both recordings"
            )
    t0_s, s = _on_grid(t_ours, speed_ours, GRID_S)
    t0_r, r = _on_grid(t_ref, speed_ref, GRID_S)
    xc = signal.correlate(r, s, mode="full", method="fft")
    lags = signal.correlation_lags(len(r), len(s), mode="full")
    # Normalise by the overlap so a short overlap at the edge cannot win by chance.
    overlap = np.minimum(len(r), lags + len(s)) - np.maximum(0, lags)
    need = 0.3 * min(len(r), len(s))
    score = np.where(overlap >= need, xc / np.maximum(overlap, 1), -np.inf)
    offsets = t0_r + lags * GRID_S - t0_s
    if max_lag_s is not None:
        score = np.where(np.abs(offsets) <= max_lag_s, score, -np.inf)
    k = int(np.argmax(score))
    if not np.isfinite(score[k]):
        raise InputError("the two recordings do not overlap in time enough to be aligned")
    frac = 0.0
    if 0 < k < len(score) - 1 and np.isfinite(score[k - 1]) and np.isfinite(score[k + 1]):
        a, b, c = score[k - 1], score[k], score[k + 1]
        den = a - 2 * b + c
        frac = 0.5 * (a - c) / den if den < 0 else 0.0
    return CoarseAlignment(float(offsets[k] + frac * GRID_S), float(score[k]))
