"""The depth sensor's noise: one function, used by the filter, the initialisation, the simulator
and the Cramer-Rao bound alike.

Structured-light and time-of-flight RGB-D cameras of the Kinect/Xtion generation measure depth
with an axial standard deviation that grows with the square of the distance (Khoshelham and
Elberink 2012, Sensors 12:1437: sigma_z = 1.425e-3 z^2 m for the Kinect v1): :func:`depth_sigma`,
the model of the filter and of the plain simulated scenarios. :func:`depth_sigma_nguyen` is the
later, larger measurement the simulator's structured-light effect uses.
"""

from __future__ import annotations

import numpy as np

KINECT_DEPTH_COEFF = 1.425e-3  # 1/m: sigma_z = coeff * z^2 (Khoshelham and Elberink 2012)


def depth_sigma(
    z: float | np.ndarray, coeff: float = KINECT_DEPTH_COEFF, floor: float = 0.0
) -> float | np.ndarray:
    """Axial depth noise sigma (m) at depth ``z`` (m): max(coeff z^2, floor).

    Plain arithmetic on scalars or arrays, so the compiled tracker step can compile it too.
    """
    s = coeff * (z * z)  # z^2 first: the rounding of every former copy but the filter's own
    return np.maximum(s, floor)


NGUYEN_OFFSET = 0.0012  # m
NGUYEN_QUADRATIC = 0.0019  # 1/m
NGUYEN_Z0 = 0.4  # m


def depth_sigma_nguyen(z: float | np.ndarray) -> float | np.ndarray:
    """Axial depth noise sigma (m) of a Kinect v1 / Xtion at depth ``z`` (m), as measured by
    Nguyen, Izadi and Lovell (2012, 3DIMPVT): 0.0012 + 0.0019 (z - 0.4)^2, about 1.4 mm at
    0.7 m (twice :func:`depth_sigma` there), for surfaces facing the camera."""
    return NGUYEN_OFFSET + NGUYEN_QUADRATIC * (z - NGUYEN_Z0) ** 2
