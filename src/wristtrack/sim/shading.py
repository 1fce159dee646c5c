"""Materials and light of the image simulator: surface ids, albedos, the light, Lambert shading
with a little gloss, and the specular highlight of a glossy marker.

One light, above and up-left of the camera; colours are BGR, 0..255 at full light.
"""

from __future__ import annotations

import numpy as np

# Surface ids in the id buffer. Markers are visible only where the back of the palm is in front.
TABLE, CLUTTER, ARM, DORSUM, HAND, OCCLUDER = range(6)

# Albedos, BGR, 0..255 at full light.
SKIN = np.array([118.0, 148.0, 204.0])
PALM_SIDE = np.array([138.0, 166.0, 218.0])
ARM_SKIN = np.array([112.0, 142.0, 198.0])
MARKER_BLUE = np.array([196.0, 84.0, 22.0])
PEN = np.array([46.0, 44.0, 50.0])
HIGHLIGHT_WHITE = np.ones(3, np.float32)  # the lamp's colour, as the camera sees it

# Light direction towards the light, camera frame: above, up-left of the camera.
LIGHT = np.array([-0.25, -0.35, -1.0]) / np.linalg.norm([-0.25, -0.35, -1.0])
HALF = (LIGHT + np.array([0.0, 0.0, -1.0])) / np.linalg.norm(LIGHT + [0.0, 0.0, -1.0])
AMBIENT, DIFFUSE = 0.38, 0.62
SHADOW_DARKNESS = 0.35


def shade(idf: np.ndarray, cf: np.ndarray, pix: np.ndarray, normal: np.ndarray,
          albedo: np.ndarray, part: np.ndarray) -> None:
    """Lambert shading with a little gloss (not on the matte clutter) into flat buffers."""
    if len(pix) == 0:
        return
    lam = np.maximum(normal @ LIGHT, 0.0)
    h = np.maximum(normal @ HALF, 0.0)
    h *= h
    h *= h
    h *= h
    h *= h  # ^16
    gloss = np.where(part != CLUTTER, 22.0 * h, 0.0)
    cf[pix] = albedo * (AMBIENT + DIFFUSE * lam)[:, None] + gloss[:, None]
    idf[pix] = part


def highlight_offset(normal: np.ndarray, centre: np.ndarray, dome_radius: float,
                     rim_radius: float) -> np.ndarray | None:
    """Where the mirror reflection of the light sits on a slightly domed marker, as an offset
    (3,) from its centre (camera frame), or None when it falls off the marker.

    The marker is a spherical cap of curvature radius ``dome_radius`` around its normal; the
    highlight is where the cap's normal is the half vector between the light and the view
    direction, i.e. ``dome_radius`` times the half vector's tilt from the marker normal.
    """
    view = -centre / np.linalg.norm(centre)
    half = LIGHT + view
    half = half / np.linalg.norm(half)
    tangential = half - (half @ normal) * normal
    offset = dome_radius * tangential
    if half @ normal <= 0 or np.linalg.norm(offset) > rim_radius:
        return None
    return offset
