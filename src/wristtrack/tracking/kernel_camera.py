"""How the camera sees a point of the moving hand, for the compiled step (kernel.py): functions
of scalars that call nothing compiled, which compiled.py compiles with the step. Each is the
scalar copy of an equation in tracking/observation.py (its NumPy form, the reference)."""

from __future__ import annotations

import math


def skin_slope(X, Y, Z, n0, n1, n2, grazing_cos):
    """-z^2 / (n . p) of observation.registration_depth_jacobian at the camera-frame point
    (X, Y, Z) on a surface of normal n (taken no steeper than at ``grazing_cos``): times n_x / fx
    (n_y / fy) the depth's change per pixel of offset along u (v)."""
    d = X * n0 + Y * n1 + Z * n2
    steepest = grazing_cos * math.sqrt(X * X + Y * Y + Z * Z)
    d = min(d, -steepest) if d < 0.0 else max(d, steepest)
    return -Z * Z / d


def rolling_shift(R_c0, vs, ws, ra, rb, rc, X, Y, Z, v, fx, fy, height, readout):
    """observation.rolling_shift of the camera-frame point (X, Y, Z), seen on row v, at arm
    (ra, rb, rc) (W0 axes) from the origin of a hand moving at vs and turning at ws (W0): the
    (du, dv) it moves on its image path until the row it has reached is read."""
    a = vs[0] + ws[1] * rc - ws[2] * rb  # the point's velocity, W0
    b = vs[1] + ws[2] * ra - ws[0] * rc
    c = vs[2] + ws[0] * rb - ws[1] * ra
    VX = R_c0[0, 0] * a + R_c0[0, 1] * b + R_c0[0, 2] * c  # and in the camera frame
    VY = R_c0[1, 0] * a + R_c0[1, 1] * b + R_c0[1, 2] * c
    VZ = R_c0[2, 0] * a + R_c0[2, 1] * b + R_c0[2, 2] * c
    du = fx * (VX * Z - X * VZ) / (Z * Z)
    dv = fy * (VY * Z - Y * VZ) / (Z * Z)
    when = ((v + 0.5) / height - 0.5) * readout / (1.0 - readout * dv / height)
    return when * du, when * dv
