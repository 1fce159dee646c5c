"""Settings of the kinematic analysis: the low-pass, the reach segmentation thresholds and the
smoothness measures' parameters (DESIGN.md section 6), checked when made."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from wristtrack.errors import ConfigError


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
