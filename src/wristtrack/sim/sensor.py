"""The colour camera: exposure and white balance, shot and read noise, 8-bit quantisation, and
the optional real-camera stages (Bayer mosaic and demosaicing, JPEG or H.264 compression).

The plain scenarios have a slow sinusoidal brightness and white-balance drift (``gain_drift``);
the ``auto_exposure`` and ``white_balance`` effects add a real camera's exposure steps and AWB
drift (:class:`wristtrack.sim.realism.Exposure`).
"""

from __future__ import annotations

import cv2
import numpy as np

from wristtrack.sim import realism
from wristtrack.sim.scenes import Scene

NOISE_PAD = 64  # the noise banks are this much larger than the image: random offsets per frame


class ColourSensor:
    """Turns a frame's linear image (float32 BGR, 0..255 at full light) into the 8-bit frame.

    The noise level of the static background is precomputed (from the undrifted image); inside
    the re-rendered region it follows the frame.
    """

    def __init__(self, scene: Scene, bg_blurred: np.ndarray, noise_bank: np.ndarray,
                 phases: np.ndarray, rng: np.random.Generator, fx_rng: np.random.Generator,
                 t0: float):
        self.scene, self.bank, self.phases, self.rng, self.t0 = scene, noise_bank, phases, rng, t0
        self.cam = scene.camera
        self._read_var = np.float32((1.2 * scene.noise) ** 2)
        self._shot = np.float32((0.2 * scene.noise) ** 2)
        self.bg_sigma = np.sqrt(self._read_var + self._shot * bg_blurred)
        self._noise_buf = np.empty_like(bg_blurred)
        fx = scene.effects
        self.exposure = realism.Exposure(t0, scene.duration, fx_rng,
                                         "auto_exposure" in fx, "white_balance" in fx)
        self.h264 = None
        if "h264" in fx:
            from wristtrack.sim.codec import H264RoundTrip  # needs PyAV: only when asked for

            self.h264 = H264RoundTrip(self.cam.width, self.cam.height, scene.fps)

    def capture(self, img: np.ndarray, t: float, region) -> np.ndarray:
        """Gain and white-balance drift, shot and read noise, 8-bit quantisation (``img`` is
        modified), then the optional Bayer, JPEG and H.264 stages."""
        sc, ph = self.scene, self.phases
        tt = t - self.t0
        g = 1.0 + sc.gain_drift * (
            0.7 * np.sin(2 * np.pi * tt / 6.3 + ph[0]) + 0.3 * np.sin(2 * np.pi * tt / 2.1 + ph[1])
        )
        wb = 1.0 + 0.12 * sc.gain_drift * np.sin(2 * np.pi * tt / 9.0 + ph[2:5])
        if self.exposure.ae or self.exposure.wb:
            g = g * self.exposure.gain(t)
            wb = wb * self.exposure.white_balance(t)
        H, W = self.cam.height, self.cam.width
        rows = img.reshape(H, W * 3)  # a long inner axis: numpy broadcasts fast along it
        rows *= np.tile((g * wb).astype(np.float32), W)
        k = int(self.rng.integers(2))
        oy, ox = (int(x) for x in self.rng.integers(NOISE_PAD, size=2))
        noise = self.bank[k, oy:oy + H, ox:ox + W]
        term = np.multiply(self.bg_sigma, noise, out=self._noise_buf)
        x0, y0, x1, y1 = region
        roi = img[y0:y1, x0:x1]
        term[y0:y1, x0:x1] = np.sqrt(self._read_var + self._shot * roi) * noise[y0:y1, x0:x1]
        img += term
        bgr = cv2.convertScaleAbs(img)  # rounds and saturates at 255 (no value is negative)
        fx = sc.effects
        if "bayer" in fx:
            bgr = bayer_round_trip(bgr)
        if "jpeg" in fx:
            bgr = jpeg_round_trip(bgr, realism.JPEG_QUALITY)
        if self.h264 is not None:
            bgr = self.h264.round_trip(bgr)
        return bgr


def bayer_round_trip(bgr: np.ndarray) -> np.ndarray:
    """What a BGGR Bayer sensor and OpenCV's bilinear demosaicing make of ``bgr``: each pixel
    keeps only its filter's channel, the other two are interpolated from its neighbours."""
    H, W = bgr.shape[:2]
    raw = np.empty((H, W), np.uint8)
    raw[0::2, 0::2] = bgr[0::2, 0::2, 0]  # B
    raw[0::2, 1::2] = bgr[0::2, 1::2, 1]  # G
    raw[1::2, 0::2] = bgr[1::2, 0::2, 1]  # G
    raw[1::2, 1::2] = bgr[1::2, 1::2, 2]  # R
    # OpenCV names Bayer patterns from the second row's first two pixels: B G / G R is "RG".
    return cv2.cvtColor(raw, cv2.COLOR_BayerRG2BGR)


def jpeg_round_trip(bgr: np.ndarray, quality: int) -> np.ndarray:
    """``bgr`` JPEG-encoded at ``quality`` (OpenCV's libjpeg, 4:2:0 chroma) and decoded."""
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not JPEG-encode a frame")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)
