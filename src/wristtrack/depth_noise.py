"""The depth sensor's noise: one function, used by the filter, the initialisation, the simulator
and the Cramer-Rao bound alike.

Structured-light and time-of-flight RGB-D cameras of the Kinect/Xtion generation measure depth
with an axial standard deviation that grows with the square of the distance. Khoshelham and
Elberink (2012, Sensors 12:1437) give sigma_z = 1.425e-3 z^2 m for the Kinect v1 (the plain
simulated scenarios' per-pixel noise); Nguyen, Izadi and Lovell (2012) measured about twice as
much at arm's length, 0.0012 + 0.0019 (z - 0.4)^2 m (:func:`depth_sigma_nguyen`): the
simulator's structured-light effect and the filter's model of a marker's depth
(``tracking.observation.MeasurementNoise``). Both are :func:`depth_sigma` with their constants.
Nguyen et al.'s noise also grows where the surface is seen obliquely, beyond 60 deg from its
normal (:func:`oblique_sigma`, :func:`lateral_sigma_nguyen`): a hand turned edge-on.
At a depth edge (:func:`neighbour_jumps`) the matching window gives the nearer surface's depth
to 1-2 px of the farther one: the simulator spreads it there, the skin patches stay clear of it.
A structured-light camera finds each pixel's disparity by matching a window of the projected
pattern around it, so neighbouring pixels share their noise (:func:`window_correlation`): the
simulator draws it so, the skin patches' readings are weighed so.
"""

from __future__ import annotations

import numpy as np

KINECT_DEPTH_COEFF = 1.425e-3  # 1/m: sigma_z = coeff * z^2 (Khoshelham and Elberink 2012)
# The Kinect v1 / Xtion's block-matching window (px): its depth noise is correlated over it
# (../shared/realdata/README.md).
MATCH_WINDOW_PX = 9


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


# Nguyen et al.'s oblique term: + 1e-4 m^1.5 theta^2 / (sqrt(z) (pi/2 - theta)^2) beyond 60 deg
# between the surface's normal and the line of sight (at 0.65 m: 1.5 mm at 70 deg, 7.9 mm at
# 80 deg). It grows without bound at 90 deg, where a sensor gives no reading at all: the angle
# is taken no steeper than 80 deg (the edge of the angles they measured).
NGUYEN_OBLIQUE = 1e-4  # m^1.5


def oblique_sigma(z: float | np.ndarray, cos_incidence: float | np.ndarray,
                  coeff: float = NGUYEN_OBLIQUE) -> float | np.ndarray:
    """What seeing the surface obliquely adds to the axial sigma (m) at depth ``z`` (m),
    ``cos_incidence`` the cosine between its normal and the line of sight (either sign): zero up
    to 60 deg, ``coeff`` theta^2 / (sqrt(z) (pi/2 - theta)^2) beyond (Nguyen et al. 2012), theta
    at most 80 deg. Plain arithmetic on scalars or arrays (the compiled tracker step compiles it;
    its angles are literals, so that its code digest covers them)."""
    theta = np.minimum(np.arccos(np.minimum(np.abs(cos_incidence), 1.0)), 80.0 * np.pi / 180.0)
    steep = coeff * theta * theta / (np.sqrt(np.maximum(z, 1e-3)) * (np.pi / 2 - theta) ** 2)
    return steep * (theta > 60.0 * np.pi / 180.0)


def lateral_sigma_nguyen(cos_incidence: float | np.ndarray) -> float | np.ndarray:
    """Lateral noise (px) of where a Kinect v1 / Xtion reading comes from: 0.8 + 0.035
    theta / (pi/2 - theta) (Nguyen et al. 2012), theta at most 80 deg as in
    :func:`oblique_sigma`: 0.8 px facing the camera, 1.1 px at 80 deg."""
    theta = np.minimum(np.arccos(np.minimum(np.abs(cos_incidence), 1.0)), np.radians(80.0))
    return 0.8 + 0.035 * theta / (np.pi / 2 - theta)


def window_correlation(du: np.ndarray, dv: np.ndarray,
                       window: int = MATCH_WINDOW_PX) -> np.ndarray:
    """Correlation of the depth noise of two pixels (du, dv) px apart (arrays of any one shape)
    when the noise is white noise averaged over a ``window`` x ``window`` matching window: the
    windows' overlap, (1 - |du| / w)(1 - |dv| / w), zero from w px apart on."""
    w = float(window)
    return (np.maximum(1.0 - np.abs(du) / w, 0.0) * np.maximum(1.0 - np.abs(dv) / w, 0.0))


def neighbour_jumps(z: np.ndarray, threshold: float, jump_to_zero: bool) -> np.ndarray:
    """(H, W) bool: both pixels of each pair of neighbours (along a row or a column) of the depth
    map ``z`` (H, W) whose depths differ by more than ``threshold`` (z's units). A 0 is a pixel
    without depth: with ``jump_to_zero`` a step to it counts (a clean depth, 0 where there is
    no surface, as far as can be), otherwise not (a camera's hole says nothing of the surface).
    A slope needs ``threshold`` per pixel to count: at 0.7 m and 12 mm, a plane turned 84 deg."""
    jump = np.zeros(z.shape, bool)
    for axis in (0, 1):
        a, b = np.swapaxes(z, 0, axis)[1:], np.swapaxes(z, 0, axis)[:-1]
        step = np.abs(a - b) > threshold
        if not jump_to_zero:
            step &= (a > 0) & (b > 0)
        j = np.swapaxes(jump, 0, axis)
        j[1:] |= step
        j[:-1] |= step
    return jump
