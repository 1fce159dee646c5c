"""The rendered hand: a palm solid around the marker layout, fingers and thumb as chains of
round cones, the forearm, and the marker rims, all in the hand frame (the forearm in W0 axes).

A planar layout gets a flat-topped, bevelled palm (the markers lie on its top); a 3-D layout
(knuckles above, thumb base below the wrist marker's plane) gets convex hulls of discs at
each marker's height, so every marker still sits on the skin. Fingers can flex: their chains
curl further, which is what moves the skin over the knuckles (soft-tissue motion, see
:mod:`wristtrack.sim.realism`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import ConvexHull

from wristtrack.hand import HandLayout
from wristtrack.sim.primitives import prism, signed_area
from wristtrack.sim.shading import DORSUM, HAND, PALM_SIDE, SKIN

MARKER_RADIUS = 0.006  # 12 mm discs
PALM_THICKNESS = 0.03
# Fingers from MCP2..MCP5: relative lengths; each chain's (MCP, PIP, DIP) curl at rest and its
# share of a flexion (a full fist is about 90/100/70 degrees at the three joints).
_FINGER_SCALE = (0.95, 1.0, 0.97, 0.8)
_REST_CURL = (12.0, 20.0, 12.0)
_FLEX_SHARE = (1.0, 1.1, 0.75)
# Arched palm: the hulls stay this far below the markers, each marker on a round pad.
_PAD_HEIGHT = 0.0025
_PAD_RADIUS = 0.0078


@dataclass(frozen=True)
class HandModel:
    """Hand geometry in the hand frame, forearm in W0 axes (it moves with the wrist only)."""

    layout: HandLayout
    palm: list[tuple[np.ndarray, np.ndarray, np.ndarray]]  # convex solids: planes, vertices
    palm_albedo: list[np.ndarray]  # (P,3) per solid
    palm_part: list[np.ndarray]  # (P,) per solid
    cones: np.ndarray  # (N,8): ax ay az bx by bz ra rb, hand frame, fingers at rest
    forearm: np.ndarray  # (8,) the same, W0 axes, relative to the wrist
    rim: np.ndarray  # (6,M,3) marker rim points, hand frame

    def finger_cones(self, flexion_deg: float) -> np.ndarray:
        """(N,8) cones with the four fingers flexed by ``flexion_deg`` at the MCP joints."""
        if flexion_deg == 0.0:
            return self.cones
        return np.array(_hand_cones(self.layout.points, flexion_deg))


def hand_model(layout: HandLayout) -> HandModel:
    p = layout.points
    if np.any(p[:, 2] != 0.0):
        palm, albedo, part = _arched_palm(p)
    else:
        palm, albedo, part = _flat_palm(p)
    # Forearm: tapered, sloping down towards the elbow; its top stays below the WRIST marker.
    a = np.array([-0.012, 0.0, -0.032])
    elbow = a + 0.45 * np.array([-np.cos(np.deg2rad(12)), 0.0, -np.sin(np.deg2rad(12))])
    forearm = np.concatenate([a, elbow, [0.026, 0.040]])

    phi = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    circle = MARKER_RADIUS * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    return HandModel(layout, palm, albedo, part, np.array(_hand_cones(p, 0.0)), forearm,
                     p[:, None, :] + circle)


def _outline(p: np.ndarray) -> np.ndarray:
    """The palm's outline points (K,2): 13 mm discs around the markers (every marker clear of
    the edge) plus the width of the wrist."""
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = 0.013 * np.column_stack([np.cos(ang), np.sin(ang)])
    return np.vstack([(p[:, None, :2] + ring).reshape(-1, 2), [[-0.024, 0.027], [-0.024, -0.027]]])


def _flat_palm(p: np.ndarray) -> tuple[list[tuple[np.ndarray, ...]], list, list]:
    """Convex prism around the outline, 3 cm thick under the back (z = 0), 4 mm top bevel."""
    hull = cv2.convexHull(_outline(p).astype(np.float32))[:, 0].astype(float)
    hull = cv2.approxPolyDP(hull.astype(np.float32), 0.001, True)[:, 0].astype(float)
    if signed_area(hull) < 0:
        hull = hull[::-1]
    palm = prism(hull, 0.0, -PALM_THICKNESS, bevel=0.004)
    n_faces = len(palm[0])
    albedo = np.tile(SKIN, (n_faces, 1))
    albedo[1] = PALM_SIDE
    part = np.full(n_faces, HAND, dtype=np.uint8)
    part[0] = DORSUM
    return [palm], [albedo], [part]


def _arched_palm(p: np.ndarray) -> tuple[list[tuple[np.ndarray, ...]], list, list]:
    """Convex solids over a flat underside: the back of the hand (the hull of 13 mm discs
    around WRIST, MCP2..MCP5 and the wrist's width), the thenar side around CMC1, both kept
    _PAD_HEIGHT below the markers, and a low round pad under each marker whose top is exactly at
    the marker's height. A hull of discs at different heights would bury a marker that lies
    below the hull of its neighbours (the thumb base, the ulnar knuckles) by a millimetre or
    more, and its depth would then read the skin above it, not the marker."""
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = 0.013 * np.column_stack([np.cos(ang), np.sin(ang)])
    thumb = 1.0 if p[1, 1] >= 0 else -1.0
    bottom = p[:, 2].min() - PALM_THICKNESS

    def hull(idx: list[int], extra: list[list[float]]) -> np.ndarray:
        top = np.vstack([np.column_stack([p[k, :2] + ring, np.full(12, p[k, 2])]) for k in idx]
                        + [np.array(extra)])
        top[:, 2] -= _PAD_HEIGHT
        return np.vstack([top, np.column_stack([top[:, :2], np.full(len(top), bottom)])])

    # The back's thumb-side wrist corner is kept clear of the CMC1 marker's disc.
    back = hull([0, 2, 3, 4, 5], [[-0.024, 0.020 * thumb, p[0, 2]],
                                  [-0.024, -0.027 * thumb, p[0, 2]]])
    thenar = hull([1], [[-0.024, 0.027 * thumb, p[1, 2]]])
    planes, albedo, part = [], [], []
    for pts in (back, thenar):
        h = ConvexHull(pts)
        eq = np.unique(np.round(h.equations, 9), axis=0)  # coplanar triangles: one plane
        planes.append((eq[:, :3], -eq[:, 3], pts[h.vertices]))
    disc = _PAD_RADIUS * np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
                                          np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))])
    for k in range(6):
        n, d, v = prism(p[k, :2] + disc, p[k, 2], p[k, 2] - 2 * _PAD_HEIGHT)
        planes.append((n, d, v))
    for normals, _, _ in planes:
        alb = np.tile(SKIN, (len(normals), 1))
        alb[normals[:, 2] < -0.9] = PALM_SIDE
        albedo.append(alb)
        part.append(np.where(normals[:, 2] > 0.5, DORSUM, HAND).astype(np.uint8))
    return planes, albedo, part


def _hand_cones(p: np.ndarray, flexion_deg: float) -> list[np.ndarray]:
    cones: list[np.ndarray] = []
    # Fingers from the MCP knuckles: three phalanges, slightly curled towards the palm.
    for k, s in zip(range(2, 6), _FINGER_SCALE, strict=True):
        d = 0.55 * p[k, :2] / np.linalg.norm(p[k, :2]) + [0.45, 0.0]
        start = np.array([p[k, 0], p[k, 1], p[k, 2] - 0.0105])
        curl = [c + flexion_deg * f for c, f in zip(_REST_CURL, _FLEX_SHARE, strict=True)]
        cones += _chain(start, d / np.linalg.norm(d), [0.044 * s, 0.027 * s, 0.021 * s],
                        curl, [0.0095, 0.0088, 0.0078, 0.0066])
    # Thumb from CMC1 (metacarpal, proximal, distal), turned towards the fingers, lower.
    c = p[1, :2]
    turn = np.deg2rad(-25.0) * (np.sign(c[1]) or 1.0)  # towards +X for either hand
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    cones += _chain(np.array([c[0], c[1], p[1, 2] - 0.016]), rot @ c / np.linalg.norm(c),
                    [0.036, 0.030, 0.024], [18, 10, 15], [0.0125, 0.0105, 0.0095, 0.0082])
    return cones


def _chain(start, direction2d, lengths, curl_deg, radii) -> list[np.ndarray]:
    """Round cones of a finger: segments of ``lengths`` bending down by ``curl_deg`` each."""
    out, pos, pitch = [], np.asarray(start, dtype=float), 0.0
    for i, (length, curl) in enumerate(zip(lengths, curl_deg, strict=True)):
        pitch += np.deg2rad(curl)
        step = length * np.array(
            [np.cos(pitch) * direction2d[0], np.cos(pitch) * direction2d[1], -np.sin(pitch)]
        )
        out.append(np.concatenate([pos, pos + step, [radii[i], radii[i + 1]]]))
        pos = pos + step
    return out
