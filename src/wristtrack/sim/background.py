"""The static background of a rendered recording: a wood-grain table below the hand and, in the
clutter scenarios, blue things lying on it. Drawn once per recording."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack.sim.primitives import Cones, Solid, box, cone, place_solid, prism
from wristtrack.sim.raycast import Layer, RayCaster
from wristtrack.sim.scenes import Scene
from wristtrack.sim.shading import AMBIENT, CLUTTER, DIFFUSE, LIGHT, TABLE

TABLE_GAP = 0.13  # table this far below the back of the neutral hand (m): room for flexion


@dataclass(frozen=True)
class Background:
    colour: np.ndarray  # (H,W,3) float32, shaded, before vignetting
    z: np.ndarray  # (H,W) depth, inf where nothing is hit
    ids: np.ndarray  # (H,W) uint8 surface ids
    blurred: np.ndarray  # (H,W,3) float32, vignetted and lens-blurred
    table_n: np.ndarray  # table normal (camera frame, towards the camera)
    table_p: np.ndarray  # a point of the table


def draw_background(scene: Scene, caster: RayCaster, vignette: np.ndarray) -> Background:
    cam = caster.cam
    H, W = cam.height, cam.width
    # Table plane: normal towards the camera (W0 +Z), TABLE_GAP below the back of the hand.
    table_n = scene.R_c0[:, 2]
    table_p = scene.t_c0 - TABLE_GAP * table_n
    with np.errstate(divide="ignore"):
        z = (table_n @ table_p) / (caster.rays @ table_n)
    z = np.where(z > 0, z, np.inf)
    hit_w0 = (z[:, None] * caster.rays - scene.t_c0) @ scene.R_c0  # table points in W0
    albedo = _table_texture(hit_w0[:, 0].reshape(H, W), hit_w0[:, 1].reshape(H, W))
    shade = AMBIENT + DIFFUSE * max(float(table_n @ LIGHT), 0.0)
    albedo[~caster.ray_ok.reshape(H, W)] = 0.0
    z[~caster.ray_ok] = np.inf
    colour = (albedo * shade).astype(np.float32)  # before vignetting
    z = z.reshape(H, W)
    ids = np.full((H, W), TABLE, dtype=np.uint8)
    if scene.clutter:
        solids, cones = _clutter(scene)
        caster.draw((0, 0, W, H), Layer(solids, cones, np.eye(3), np.zeros(3)), colour, z, ids)
    blurred = cv2.GaussianBlur(colour * vignette, (0, 0), 0.6)
    return Background(colour, z, ids, blurred, table_n, table_p)


def _table_texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Albedo (H,W,3) of a light wood-grain laminate at W0 table coordinates (H,W) (m)."""
    rng = np.random.default_rng(11)
    res, half = 0.002, 0.8
    n = int(2 * half / res)
    low = cv2.resize(rng.standard_normal((12, 12)).astype(np.float32), (n, n),
                     interpolation=cv2.INTER_CUBIC)
    fine = cv2.GaussianBlur(rng.standard_normal((n, n)).astype(np.float32), (0, 0), 1.2)
    gy = np.linspace(-half, half, n, dtype=np.float32)[:, None]
    grain = np.sin(2 * np.pi * (gy / 0.011 + 0.9 * low)) + 0.5 * np.sin(
        2 * np.pi * (gy / 0.0043 + 1.7 * low)
    )
    lum = 1.0 + 0.035 * grain + 0.05 * low + 0.035 * fine
    tex = lum[..., None] * np.array([150.0, 170.0, 188.0], dtype=np.float32)
    mx = ((x + half) / res).astype(np.float32)
    my = ((y + half) / res).astype(np.float32)
    return cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _clutter(scene: Scene) -> tuple[list[Solid], Cones]:
    """Blue things on the table: a box, a bottle cap and a pen cap (placed in W0)."""
    R0, t0 = scene.R_c0, scene.t_c0
    floor = -TABLE_GAP

    def place(planes, xyz, yaw_deg, albedo):
        c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return place_solid(planes, R0 @ Rz, R0 @ np.asarray(xyz) + t0, albedo, CLUTTER)

    box_ = place(box((0.07, 0.045, 0.03)), (0.03, -0.17, floor + 0.015), 20, [165.0, 92.0, 34.0])
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    disc = 0.016 * np.column_stack([np.cos(ang), np.sin(ang)])
    cap = place(prism(disc, 0.006, -0.006), (-0.08, 0.12, floor + 0.006), 0, [190.0, 98.0, 40.0])
    a = np.array([0.17, -0.09, floor + 0.0065])
    b = a + 0.05 * np.array([np.cos(1.0), np.sin(1.0), 0.0])
    pen_cap = cone(R0 @ a + t0, R0 @ b + t0, 0.0065, 0.0055, [178.0, 72.0, 26.0], CLUTTER)
    return [box_, cap], pen_cap
