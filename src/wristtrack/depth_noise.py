"""The depth sensor's noise: one function, used by the filter, the initialisation, the simulator
and the Cramer-Rao bound alike.

Structured-light and time-of-flight RGB-D cameras of the Kinect/Xtion generation measure depth
with an axial standard deviation that grows with the square of the distance. Khoshelham and
Elberink (2012, Sensors 12:1437) give sigma_z = 1.425e-3 z^2 m for the Kinect v1 (the plain
simulated scenarios' per-pixel noise); Nguyen, Izadi and Lovell (2012) measured about twice as
much at arm's length, 0.0012 + 0.0019 (z - 0.4)^2 m (:func:`depth_sigma_nguyen`): the
simulator's structured-light effect and the filter's model of a marker's depth
(``tracking.observation.MeasurementNoise``). Both are :func:`depth_sigma` with their constants.
"""

from __future__ import annotations

import numpy as np

KINECT_DEPTH_COEFF = 1.425e-3  # 1/m: sigma_z = coeff * z^2 (Khoshelham and Elberink 2012)


def depth_sigma(
    z: float | np.ndarray,
    coeff: float = KINECT_DEPTH_COEFF,
    floor: float = 0.0,
    offset: float = 0.0,
    z0: float = 0.0,
) -> float | np.ndarray:
    """Axial depth noise sigma (m) at depth ``z`` (m): max(offset + coeff (z - z0)^2, floor).

    Khoshelham and Elberink's model by default; Nguyen et al.'s with their offset and z0
    (:func:`depth_sigma_nguyen`). Plain arithmetic on scalars or arrays, so the compiled tracker
    step can compile it too.
    """
    d = z - z0
    s = offset + coeff * (d * d)  # with z0 = offset = 0, exactly coeff * (z * z)
    return np.maximum(s, floor)


NGUYEN_OFFSET = 0.0012  # m
NGUYEN_QUADRATIC = 0.0019  # 1/m
NGUYEN_Z0 = 0.4  # m


def depth_sigma_nguyen(z: float | np.ndarray) -> float | np.ndarray:
    """Axial depth noise sigma (m) of a Kinect v1 / Xtion at depth ``z`` (m), as measured by
    Nguyen, Izadi and Lovell (2012, 3DIMPVT): 0.0012 + 0.0019 (z - 0.4)^2, about 1.4 mm at
    0.7 m (twice :func:`depth_sigma` there), for surfaces facing the camera."""
    return depth_sigma(z, NGUYEN_QUADRATIC, 0.0, NGUYEN_OFFSET, NGUYEN_Z0)
