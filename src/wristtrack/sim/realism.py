"""The simulator's realism effects: their names, their strengths and where each number comes from.

Every effect is a switch (``Scene.effects``); ``PRESET_REAL`` switches on the set a real
consumer RGB-D camera and a real hand give together. Strengths are fixed here from measured
devices and the literature (``../shared/realdata/README.md``), not tuned to the tracker:

- ``nonplanar``: the back of a real hand arches. Knuckles MCP2..MCP5 sit 4.5-7 mm above the
  wrist marker's plane (the third metacarpal head highest, the transverse metacarpal arch), the
  thumb base (CMC1) 4.5 mm below it. The layout is then expressed in the hand frame of the
  contract (least-squares palm plane, X towards MCP3), as a 3-D hand.json would give it.
- ``soft_tissue``: skin over the metacarpal heads slides as the fingers flex: 3 mm distally and
  1 mm towards the palm at 90 degrees of MCP flexion (a few mm), while the fingers flex and
  extend between 0 and 70 degrees every ~3.3 s.
- ``left_hand``: the layout and hand model mirrored (CMC1 on -Y).
- ``distortion``: a real Asus Xtion colour camera's radial distortion k1 0.033, k2 -0.108
  (ROS camera_info), written into camera.json ``dist`` and rendered through it.
- ``white_balance``: auto white balance drifting slowly: red and blue gains +-10 %, periods
  7-20 s.
- ``auto_exposure``: auto-exposure steps of up to +-30 % every 1.5-4 s, each settling over
  ~0.1 s.
- ``jpeg``: colour JPEG-compressed at quality 80 (ROS compressed image transport's default),
  OpenCV's encoder.
- ``h264``: colour H.264-compressed (libx264 through PyAV, CRF 23 = x264's default, yuv420p),
  as in an MP4 from a consumer camera; needs the ``video`` extra.
- ``bayer``: a Bayer (BGGR) sensor: one colour per pixel, demosaiced by OpenCV's bilinear
  ``cvtColor`` (``COLOR_BayerBG2BGR``).
- ``shutter``: a 1/30 s shutter (indoor auto-exposure runs at 1/60-1/30 s): motion blur.
- ``specular``: glossy, slightly domed markers (curvature radius 15 mm) show the mirror image
  of the light, a lamp of 0.15 rad angular radius: a near-saturated spot on the marker.
- ``structured_light``: Kinect v1 / Xtion depth: axial noise sigma_z = 0.0012 + 0.0019
  (z - 0.4)^2 m (Nguyen, Izadi & Lovell 2012) correlated over the 9x9 px matching window,
  lateral jitter 0.8 px at depth edges, both growing as Nguyen et al. measured where the surface
  is seen more than 60 deg from its normal (+1.5 mm at 70 deg at arm's length: a hand turned
  edge-on), disparity quantised to 1/8 px (depth steps 2.85e-3 z^2 m), the nearer surface's
  depth spread 1-2 px over the farther one at depth edges (foreground fattening, no holes
  there: 90-95 % of the real frames' depth jumps have none), holes in the projector's
  shadow, the registered depth map's invalid border as measured on real
  OpenNI frames (top 15, bottom 5, right 31 rows/columns, a ragged left band ~15 px), and
  colour-depth misregistration of 1-2 px.
- ``depth_lag``: the depth and colour streams run on their own clocks (the D435's colour sensor
  sits on a separate module; Kinect v1 / Xtion pair them in software), and each colour frame is
  paired with the depth frame nearest in time: up to half a frame interval apart, as OpenNI's
  frame sync, ROS's approximate-time pairing and our bag reader (io/rosbag.py) allow. Streams
  at one nominal rate keep their phase over a recording, so the depth is captured a fixed
  delay from the colour, drawn per recording uniformly within half a frame interval, and
  written into camera.json (``depth_delay_s``) as the two streams' time stamps tell it.
- ``rolling_shutter``: the colour sensor of a D415/D435 (OmniVision OV2740), a Kinect v1 or
  Xtion, and a webcam is a rolling shutter: its rows are exposed one after another, the bottom
  row a readout later than the top one (the depth imagers of the D435 are global shutters). The
  readout is tied to the frame rate, not the exposure (librealsense #3554: the artefacts grow
  as the rate falls, at a fixed exposure); the OV2740 reads 1080 rows at up to 60 frames/s, so
  at 30 frames/s a frame is read in 1/60 to 1/30 s. Drawn per recording uniformly in half to
  one frame interval and written into camera.json (``readout_s``) as a calibration gives it.

Without any effect the plain scenarios render exactly as before (Kinect depth noise
1.425e-3 z^2, flat layout, no distortion), so older figures stay comparable.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError
from wristtrack.hand import MCP3_INDEX, HandLayout

EFFECTS = (
    "nonplanar",
    "soft_tissue",
    "left_hand",
    "distortion",
    "white_balance",
    "auto_exposure",
    "jpeg",
    "h264",
    "bayer",
    "shutter",
    "specular",
    "structured_light",
    "depth_lag",
    "rolling_shutter",
)
# A real camera and hand at once. One compression (JPEG, as ROS records colour); the side of
# the hand is chosen separately.
PRESET_REAL = tuple(e for e in EFFECTS if e not in ("h264", "left_hand"))

# nonplanar: heights (m) above the wrist marker's plane, WRIST, CMC1, MCP2..MCP5.
ARCH_HEIGHTS = np.array([0.0, -0.0045, 0.006, 0.007, 0.006, 0.0045])
# soft_tissue
SKIN_SLIDE_AT_90 = np.array([0.003, 0.0, -0.001])  # hand frame: distal, -, towards the palm
FINGER_FLEXION_MAX_DEG = 70.0
FINGER_FLEXION_PERIOD_S = 3.3
# distortion (a real Xtion, OpenCV order k1 k2 p1 p2 k3)
XTION_DIST = (0.033, -0.108, 0.0, 0.0, 0.0)
# white balance, auto exposure
WB_AMPLITUDE = 0.10
AE_STEP = 0.30
AE_INTERVAL_S = (1.5, 4.0)
AE_SETTLE_S = 0.1
# compression
JPEG_QUALITY = 80
H264_CRF = 23
# shutter
LONG_SHUTTER_S = 1.0 / 30.0
# specular markers
DOME_RADIUS = 0.015
LAMP_ANGULAR_RADIUS = 0.15
HIGHLIGHT_PEAK = 230.0
# structured light (Kinect v1 / Xtion)
DISPARITY_STEP_PX = 1.0 / 8.0
FOCAL_BASELINE = 1.0 / (8.0 * 2.85e-3)  # px m: 1/8 px disparity = 2.85e-3 z^2 m
BORDER_TOP, BORDER_BOTTOM, BORDER_RIGHT, BORDER_LEFT_RAMP = 15, 5, 31, 15
EDGE_JUMP_M = 0.012
# Foreground fattening: the nearer surface's depth reaches 1-2 px past a depth edge (this many at
# most). Measured on the three real OpenNI frames (pcl_openni_frames): each row's depth jumps
# (> 5 %) against the strongest grey-level edge within 8 px, left and right edges of the nearer
# surface apart (their mean is the fattening; a misregistration moves both alike): 1.9, 1.5 and
# 1.0 px (tests/sim/test_realism.py).
FATTEN_PX = 2


def depth_delay(seed: int, fps: float) -> float:
    """The depth frames' delay after the colour frames (s) of the ``depth_lag`` effect: uniform
    within half a frame interval, drawn from the recording's seed."""
    half = 0.5 / fps
    return float(np.random.default_rng([seed, 6]).uniform(-half, half))


def readout(seed: int, fps: float) -> float:
    """The rolling shutter's readout (s) of the ``rolling_shutter`` effect: uniform in half to
    one frame interval, drawn from the recording's seed."""
    return float(np.random.default_rng([seed, 7]).uniform(0.5 / fps, 1.0 / fps))


def check_effects(effects: object) -> frozenset[str]:
    """The effect names as a frozenset; ConfigError naming any unknown one."""
    names = [effects] if isinstance(effects, str) else list(effects or ())  # type: ignore[arg-type]
    unknown = sorted({str(e) for e in names} - set(EFFECTS))
    if unknown:
        raise ConfigError(
            f"unknown simulator effect(s) {', '.join(unknown)}; choose from {', '.join(EFFECTS)}"
        )
    return frozenset(str(e) for e in names)


def arched(layout: HandLayout) -> HandLayout:
    """``layout`` with the arch of a real hand (ARCH_HEIGHTS), in the contract's hand frame:
    origin WRIST, X exactly towards MCP3 (hand.json requires MCP3 on the X axis), Z the
    least-squares palm normal made perpendicular to X."""
    pts = layout.points.copy()
    pts[:, 2] = ARCH_HEIGHTS
    x = pts[MCP3_INDEX] / np.linalg.norm(pts[MCP3_INDEX])
    n = np.linalg.svd(pts - pts.mean(axis=0))[2][2]
    z = n - (n @ x) * x
    z = z / np.linalg.norm(z) * (1.0 if z[2] > 0 else -1.0)
    R = np.column_stack([x, np.cross(z, x), z])
    local = pts @ R
    local[MCP3_INDEX, 1:] = 0.0  # zero up to rounding by construction
    return HandLayout(local).validate("arched hand layout")


def left(layout: HandLayout) -> HandLayout:
    """The left hand of ``layout`` (whichever side it is): CMC1 on -Y."""
    return layout if layout.side == "left" else layout.mirrored()


def distorted(camera: Camera) -> Camera:
    """``camera`` with the Xtion's lens distortion."""
    return replace(camera, dist=XTION_DIST)


def finger_flexion_deg(t: np.ndarray | float, t0: float) -> np.ndarray | float:
    """Finger (MCP) flexion at time t: 0 .. FINGER_FLEXION_MAX_DEG, smooth, starting extended."""
    phase = 2 * np.pi * (np.asarray(t, dtype=float) - t0) / FINGER_FLEXION_PERIOD_S
    return 0.5 * FINGER_FLEXION_MAX_DEG * (1.0 - np.cos(phase))


def skin_slide(flexion_deg: float, layout: HandLayout) -> np.ndarray:
    """(6,3) hand-frame displacement of the markers by soft tissue at this finger flexion: the
    four MCP markers slide with the skin, WRIST and CMC1 stay."""
    out = np.zeros((6, 3))
    out[2:] = SKIN_SLIDE_AT_90 * (flexion_deg / 90.0)
    return out


class Exposure:
    """Auto-exposure gain steps and white-balance drift over time, drawn once per recording."""

    def __init__(self, t0: float, duration: float, rng: np.random.Generator,
                 auto_exposure: bool, white_balance: bool):
        self.t0 = t0
        self.ae = auto_exposure
        self.wb = white_balance
        times, levels, t = [0.0], [1.0], 0.0
        while t < duration:
            t += rng.uniform(*AE_INTERVAL_S)
            times.append(t)
            levels.append(1.0 + rng.uniform(-AE_STEP, AE_STEP))
        self.step_times, self.levels = np.array(times), np.array(levels)
        self.wb_period = rng.uniform(7.0, 20.0, 2)
        self.wb_phase = rng.uniform(0, 2 * np.pi, 2)

    def gain(self, t: float) -> float:
        """Overall exposure factor at time t (1 without auto exposure)."""
        if not self.ae:
            return 1.0
        tt = t - self.t0
        k = int(np.searchsorted(self.step_times, tt, side="right")) - 1
        if k <= 0:
            return float(self.levels[0])
        settle = min((tt - self.step_times[k]) / AE_SETTLE_S, 1.0)
        return float(self.levels[k - 1] + settle * (self.levels[k] - self.levels[k - 1]))

    def white_balance(self, t: float) -> np.ndarray:
        """(3,) BGR channel gains at time t (ones without drift); green is the reference."""
        if not self.wb:
            return np.ones(3)
        s = np.sin(2 * np.pi * (t - self.t0) / self.wb_period + self.wb_phase)
        return np.array([1.0 + WB_AMPLITUDE * s[0], 1.0, 1.0 + WB_AMPLITUDE * s[1]])
