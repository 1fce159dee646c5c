"""Commands that measure the camera from a recording: readout (a rolling shutter's)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path


def _readout(args: argparse.Namespace) -> int:
    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.folder import FolderRecording
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.readout import detect_all, estimate_readout

    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    with open_recording(args.input, camera=camera, hand=hand) as recording:
        found = estimate_readout(recording, detect_all(recording))
        camera = recording.camera
        is_folder = isinstance(recording, FolderRecording)
    for readout, nis in zip(found.tried, found.nis, strict=True):
        print(f"  readout {1e3 * readout:5.1f} ms: NIS per dof {nis:.4f}")
    print(f"readout_s: {found.readout:.4f} ({1e3 * found.readout:.1f} ms, from the "
          f"{found.frames} frames where the hand turned fastest)")
    if not args.write:
        return 0
    if args.camera:
        target = Path(args.camera)
    elif is_folder:
        target = Path(args.input) / "camera.json"
    else:
        print(f"not written: {args.input} keeps no camera.json; give --camera FILE to write "
              "into, or add readout_s to the camera.json you track it with")
        return 0
    replace(camera, readout=found.readout).save(target)
    print(f"wrote readout_s into {target}")
    return 0


def add_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register this module's commands on the top-level parser's subparsers."""
    readout = sub.add_parser(
        "readout", help="measure a rolling-shutter colour sensor's readout (camera.json "
        "readout_s) from a recording of the hand turning fast",
    )
    readout.add_argument("input", help="recording folder, bag or RealSense file")
    readout.add_argument("--camera", help="camera.json (required for a video); with --write, "
                         "the file written into")
    readout.add_argument("--hand", help="hand.json (default: the recording's, else measured)")
    readout.add_argument("--write", action="store_true",
                         help="write readout_s into the recording's camera.json (or --camera)")
    readout.set_defaults(handler=_readout)
