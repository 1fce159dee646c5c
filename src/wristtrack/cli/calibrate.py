"""Commands that measure the camera from a recording: timing (readout_s, depth_delay_s)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path


def _timing(args: argparse.Namespace) -> int:
    from wristtrack.camera import Camera
    from wristtrack.errors import InputError
    from wristtrack.hand import HandLayout
    from wristtrack.io.folder import FolderRecording
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.camera_timing import (
        detect_all,
        estimate_depth_delay,
        estimate_readout,
    )

    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    with open_recording(args.input, camera=camera, hand=hand) as recording:
        detections = detect_all(recording)
        camera, found, refused = recording.camera, {}, []
        try:  # the readout first: the depth's delay is then measured through it
            found["readout_s"] = estimate_readout(recording, detections, camera)
            camera = replace(camera, readout=found["readout_s"].value or None)
        except InputError as exc:
            refused.append(str(exc))
        stamped = [d.depth_delay for d in detections if d.depth_delay is not None]
        if stamped:
            print(f"depth_delay_s: the camera stamps each frame ({1e3 * min(stamped):.1f} to "
                  f"{1e3 * max(stamped):.1f} ms); nothing to measure")
        elif any(d.depth is not None for d in detections):
            try:
                found["depth_delay_s"] = estimate_depth_delay(recording, detections, camera)
                camera = replace(camera, depth_delay=found["depth_delay_s"].value)
            except InputError as exc:
                refused.append(str(exc))
        is_folder = isinstance(recording, FolderRecording)
    for estimate in found.values():
        for value, nis in zip(estimate.tried, estimate.nis, strict=True):
            print(f"  {estimate.field} {1e3 * value:6.1f} ms: NIS per dof {nis:.4f}")
        print(f"{estimate.field}: {estimate.value:.4f} ({1e3 * estimate.value:.1f} ms, from the "
              f"{estimate.frames} frames where the hand moved fastest)")
    if not found:
        raise InputError(refused[0])
    for reason in refused:
        print(f"not measured: {reason}")
    if args.write:
        _write(camera, args, is_folder, found)
    return 0


def _write(camera, args: argparse.Namespace, is_folder: bool, found: dict) -> None:
    if args.camera:
        target = Path(args.camera)
    elif is_folder:
        target = Path(args.input) / "camera.json"
    else:
        print(f"not written: {args.input} keeps no camera.json; give --camera FILE to write "
              f"into, or add {' and '.join(found)} to the camera.json you track it with")
        return
    camera.save(target)
    print(f"wrote {' and '.join(found)} into {target}")


def add_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register this module's commands on the top-level parser's subparsers."""
    timing = sub.add_parser(
        "timing", help="measure the camera's timing from a recording of the hand moving fast: "
        "a rolling shutter's readout (readout_s) and the depth's delay (depth_delay_s)",
    )
    timing.add_argument("input", help="recording folder, bag or RealSense file")
    timing.add_argument("--camera", help="camera.json (required for a video); with --write, "
                        "the file written into")
    timing.add_argument("--hand", help="hand.json (default: the recording's, else measured)")
    timing.add_argument("--write", action="store_true",
                        help="write what was measured into the recording's camera.json (or "
                        "--camera's file)")
    timing.set_defaults(handler=_timing)
