"""``open_recording``: one entry point that picks the reader for any kind of recording.

The only module that knows every source; the sources themselves know only io.base.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wristtrack.camera import Camera
from wristtrack.errors import InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Recording, reject_options
from wristtrack.io.folder import FolderRecording
from wristtrack.io.live.opencv import LiveRecording
from wristtrack.io.rosbag import BagRecording, written_by_realsense_sdk
from wristtrack.io.video import VIDEO_SUFFIXES, VideoRecording

LIVE_PREFIX = "live:"


def open_recording(
    source: str | Path,
    camera: Camera | None = None,
    hand: HandLayout | None = None,
    **options: Any,
) -> Recording:
    """Open a recording of any supported kind; ``camera``/``hand`` override what it contains.

    - a folder with frames.csv (or that frames.csv): native recording folder;
    - a video file (.mp4 .avi .mov .mkv ...): RGB only, ``camera`` required;
    - a ROS 1 ``.bag`` file or a ROS 2 bag folder (metadata.yaml): options ``color_topic``,
      ``depth_topic``, ``info_topic``, ``sync_tolerance`` (seconds);
    - a RealSense Viewer/SDK recording (``.bag`` in the SDK's layout, or a lone ``.db3``);
    - ``"live:0"`` (or ``live=0``): an OpenCV camera, ``camera`` required; option ``max_frames``.
    """
    live = options.pop("live", None)
    text = str(source) if source is not None else ""
    if live is None and text.startswith(LIVE_PREFIX):
        live = text[len(LIVE_PREFIX):]
    if live is not None:
        return LiveRecording(live, camera, hand, **options)
    path = Path(source)
    if not path.exists():
        raise InputError(
            f"recording {path} not found; give a recording folder (with frames.csv), a video "
            "file, a ROS .bag file, a ROS 2 bag folder, or live:INDEX for a camera"
        )
    if path.is_file() and path.name in ("frames.csv", "metadata.yaml"):
        path = path.parent
    if path.is_dir():
        if (path / "frames.csv").is_file():
            reject_options("the recording folder", path, options)
            return FolderRecording(path, camera, hand)
        if (path / "metadata.yaml").is_file():
            return BagRecording(path, camera, hand, **options)
        raise InputError(
            f"folder {path} has no frames.csv (recording folder) and no metadata.yaml (ROS 2 "
            "bag); give the folder that contains one of them"
        )
    suffix = path.suffix.lower()
    if (suffix == ".bag" and written_by_realsense_sdk(path)) or \
            (suffix == ".db3" and not (path.parent / "metadata.yaml").is_file()):
        # RealSense Viewer/SDK recordings: read by the SDK as it plays them back, every frame
        # (not at the recorded pace), depth aligned to colour by the SDK.
        from wristtrack.io.live.realsense import RealSenseRecording

        return RealSenseRecording(None, camera, hand, file=path, real_time=False, **options)
    if suffix == ".bag":
        return BagRecording(path, camera, hand, **options)
    if suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        return BagRecording(path.parent, camera, hand, **options)
    if suffix in VIDEO_SUFFIXES:
        return VideoRecording(path, camera, hand, **options)
    raise InputError(
        f"{path}: unknown kind of recording ({suffix or 'no extension'}); give a recording "
        f"folder, a video ({', '.join(sorted(VIDEO_SUFFIXES))}), a .bag file or a ROS 2 bag folder"
    )
