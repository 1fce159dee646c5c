"""A track restarted while the hand moves: its linear velocity from the track it replaces.

A fresh fit inside a running track (a re-acquisition, a colour-only refit: tracker.py) gives a
pose and no motion. Started at rest, the next frame's prediction lags a moving hand by a
frame's travel: on the fast colour-only recording (the rgb_only movement in 2 s, up to 1 m/s)
the next update missed the markers, the fit was taken again, at rest again, for a dozen frames
in a row, and a frame whose fit failed coasted where the last one was (40-80 mm off).

The hand's position a frame before is known well even where its orientation is not (a track
carried towards the mirror image of a colour-only pose still has the wrist where it is), so the
restart moves at the two-point difference of the positions. On that recording, 6 seeds:
position RMSE 5.5 -> 0.8-0.9 mm (2 seeds) and 11.6 -> 3.3 mm (4), orientation 1.33 -> 0.47 deg
on the first two, the others unchanged.

Two things the difference is not taken for:
- its own spread. A colour-only fit's depth is uncertain to several mm, and the velocity at the
  difference's covariance let the next update follow the pixels into the mirror image (range
  of motion 14 deg off on 4 of the 6 seeds). The velocity keeps the spread every fresh fit
  starts with (``model.initial_covariance``), a prior that hands seldom move fast.
- the angular velocity: the orientation a fit replaces is the one found wrong, and the turn to
  it (a planar twin's mirror tilt) is no turn of the hand; taken as one, it sent a colour-only
  track 9 deg off in range of motion.
"""

from __future__ import annotations

import numpy as np


def moving_start(model, x: np.ndarray, previous_x: np.ndarray, dt: float) -> np.ndarray:
    """The state ``x`` of a fresh fit (at rest) moving at the linear velocity (p - p_prev) / dt
    from the position of the track it replaces (``previous_x``, ``dt`` s before). Models
    without a velocity (the paper's) keep the fit as it is."""
    if not (dt > 0 and hasattr(model, "velocity")):
        return x
    p = model.pose(x[None])[1][0]
    p_prev = model.pose(previous_x[None])[1][0]
    xi = np.zeros((1, model.dim))
    xi[0, model.velocity] = (p - p_prev) / dt - model.velocities(x)[0]
    return model.retract(x, xi)[0]
