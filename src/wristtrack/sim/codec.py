"""H.264 compression of the colour stream, as an MP4 from a consumer camera would carry it.

OpenCV's FFmpeg here has no H.264 encoder (VideoWriter refuses 'avc1'/'H264'), so this uses
PyAV's libx264 (the ``video`` extra). Each frame is encoded and decoded at once: x264's
zero-latency tuning (no B-frames, no look-ahead) gives every frame back immediately, so the
stream can be written frame by frame; the rate control is x264's default CRF 23, yuv420p.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from wristtrack.errors import ConfigError
from wristtrack.sim import realism


def require_pyav() -> ModuleType:
    """PyAV, or a ConfigError saying how to install it (before anything is written)."""
    try:
        import av
    except ImportError:
        raise ConfigError(
            "the h264 effect needs PyAV: pip install 'wristtrack[video]' (or pip install av)"
        ) from None
    return av


class H264RoundTrip:
    """Encode and decode frames one at a time through libx264 (PyAV)."""

    def __init__(self, width: int, height: int, fps: float):
        from fractions import Fraction

        av = require_pyav()
        self._av = av
        enc = av.CodecContext.create("libx264", "w")
        enc.width, enc.height = width, height
        enc.pix_fmt = "yuv420p"
        enc.time_base = Fraction(1, max(int(round(fps)), 1))
        enc.options = {"crf": str(realism.H264_CRF), "preset": "veryfast",
                       "tune": "zerolatency"}
        self.enc = enc
        self.dec = av.CodecContext.create("h264", "r")
        self.n = 0

    def round_trip(self, bgr: np.ndarray) -> np.ndarray:
        frame = self._av.VideoFrame.from_ndarray(np.ascontiguousarray(bgr), format="bgr24")
        frame.pts = self.n
        self.n += 1
        out = None
        for packet in self.enc.encode(frame):
            for decoded in self.dec.decode(packet):
                out = decoded.to_ndarray(format="bgr24")
        if out is None:
            raise RuntimeError("libx264 held a frame back despite zero-latency tuning")
        return out
