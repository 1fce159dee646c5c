"""Low-pass filtering of the reference's marker trajectories, as motion-capture labs filter them.

An optoelectronic system's marker noise (0.05-0.1 mm per coordinate) is small for a position
but not for the orientation of markers a few centimetres apart: on our six markers, 0.05 mm
is 0.07 deg of orientation per frame (their rigid fit), a third of what the tracker's error
is, and it adds to every orientation RMSE ``compare`` reports. Labs remove it before anything
is computed from the markers with a fourth-order zero-lag Butterworth low-pass, 3 dB down at
the cutoff asked for (Winter, Biomechanics and Motor Control of Human Movement, 2009, ch. 3;
``motion_profiles.dual_pass_butterworth``, the kinematics' low-pass too).

Gaps (NaN) are not bridged: each marker's gap-free stretches are filtered on their own, and a
stretch too short for the filter's edge padding is kept as recorded.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.signal import sosfiltfilt

from wristtrack.analysis.motion_profiles import dual_pass_butterworth, true_spans
from wristtrack.errors import ConfigError
from wristtrack.io.markers.data import MarkerData


def butterworth(cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Second-order sections of the per-pass filter whose forward-backward run is 3 dB down at
    ``cutoff_hz`` for samples at ``rate_hz``; ConfigError where the cutoff cannot be had."""
    if not np.isfinite(cutoff_hz) or cutoff_hz <= 0.0:
        raise ConfigError(f"the low-pass cutoff must be a positive frequency, got {cutoff_hz} Hz")
    if cutoff_hz >= 0.5 * rate_hz:
        raise ConfigError(
            f"a {cutoff_hz:g} Hz low-pass cutoff is at or above the reference's Nyquist "
            f"frequency ({0.5 * rate_hz:g} Hz at {rate_hz:g} Hz): give a lower cutoff"
        )
    return dual_pass_butterworth(cutoff_hz, rate_hz)


def lowpass_markers(data: MarkerData, cutoff_hz: float) -> MarkerData:
    """``data`` with every marker's trajectory low-passed at ``cutoff_hz`` (module doc), and a
    note saying so (and how many stretches were too short to filter)."""
    sos = butterworth(cutoff_hz, data.rate)
    xyz = data.xyz.copy()
    short = 0
    for k in range(xyz.shape[1]):
        for start, stop in true_spans(np.isfinite(xyz[:, k]).all(axis=1)):
            try:
                xyz[start:stop, k] = sosfiltfilt(sos, xyz[start:stop, k], axis=0)
            except ValueError:  # shorter than the filter's padding
                short += 1
    note = (f"reference markers low-passed at {cutoff_hz:g} Hz (4th-order zero-lag "
            "Butterworth)")
    if short:
        note += f"; {short} gap-free stretch(es) too short to filter kept as recorded"
    return replace(data, xyz=xyz, notes=(*data.notes, note))

