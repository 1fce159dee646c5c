"""``--live SOURCE``: which live source a SOURCE string names.

- ``realsense`` / ``realsense:SERIAL``: an Intel RealSense camera; ``realsense:FILE.bag`` or
  ``.db3``: a RealSense SDK recording played as the camera;
- ``openni`` / ``openni:URI``: an OpenNI2 camera (Xtion, Kinect v1, Orbbec); ``openni:FILE.oni``;
- ``replay:RECORDING``: a recording folder played at its own timestamps;
- an integer or a device path (``0``, ``/dev/video2``): an OpenCV camera, colour only;
- a bare ``FILE.bag``/``.db3`` or ``FILE.oni``: as ``realsense:FILE`` or ``openni:FILE``.

Each device library is imported only when its source is asked for.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wristtrack.camera import Camera
from wristtrack.errors import InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Recording

KINDS = "realsense[:SERIAL|:FILE.bag], openni[:URI|:FILE.oni], replay:RECORDING or a camera index"


def open_live(
    spec: str, camera: Camera | None = None, hand: HandLayout | None = None, **options: Any
) -> Recording:
    """The live source named by ``spec`` (see the module docstring)."""
    spec = str(spec).strip()
    kind, _, arg = spec.partition(":")
    kind = kind.lower()
    if kind == "replay":
        if not arg:
            raise InputError("replay: needs a recording folder, e.g. --live replay:rec/")
        from wristtrack.io.live.replay import ReplayRecording

        return ReplayRecording(arg, camera, hand, **options)
    if kind == "realsense":
        from wristtrack.io.live.realsense import RECORDING_SUFFIXES, RealSenseRecording

        if arg and (Path(arg).suffix.lower() in RECORDING_SUFFIXES or Path(arg).is_file()):
            return RealSenseRecording(None, camera, hand, file=arg, **options)
        return RealSenseRecording(arg or None, camera, hand, **options)
    if kind == "openni":
        from wristtrack.io.live.openni import OpenNIRecording

        if arg and (arg.lower().endswith(".oni") or Path(arg).is_file()):
            return OpenNIRecording(None, camera, hand, file=arg, **options)
        return OpenNIRecording(arg or None, camera, hand, **options)
    suffix = Path(spec).suffix.lower()
    if suffix in (".bag", ".db3", ".oni"):  # a device recording named on its own
        return open_live(f"{'openni' if suffix == '.oni' else 'realsense'}:{spec}", camera, hand,
                         **options)
    if spec.lstrip("-").isdigit() or spec.startswith(("/dev/", "rtsp://", "http://", "https://")):
        from wristtrack.io.live.opencv import LiveRecording

        return LiveRecording(spec, camera, hand, **options)
    raise InputError(f"--live {spec}: unknown source; give {KINDS}")
