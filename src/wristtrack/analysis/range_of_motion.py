"""Range of motion per anatomical axis from the wrist angles of poses.csv.

Angles. ``deviation_deg``, ``flexion_deg`` and ``pronation_deg`` come from poses.csv as they are:
:func:`wristtrack.geometry.wrist_angles`, the intrinsic Y-Z-X decomposition of the hand rotation
relative to W0 (the neutral posture at initialisation) in the hand axes of DESIGN.md section 2
(+X wrist -> MCP3, +Z out of the back of the hand, +Y = Z x X), signed as the ISB recommends on
either hand: flexion(+)/extension(-), ulnar(+)/radial(-) deviation, pronation(+)/supination(-).
The side comes from the hand layout (thumb marker CMC1 on +Y: right hand; on -Y: left hand); on
a right hand +Y points to the thumb, so its deviation and pronation are the decomposition's Z and
X angles negated, on a left hand they are taken as they are.
"""

from __future__ import annotations

import numpy as np

from wristtrack.errors import InputError

AXES = ("deviation", "flexion", "pronation")
ANGLE_COLUMNS = ("deviation_deg", "flexion_deg", "pronation_deg")  # poses.csv, in AXES order


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
