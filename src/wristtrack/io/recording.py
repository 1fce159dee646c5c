"""Recordings: the Frame/Recording interface, the native folder reader and writer, dispatch.

Native recording folder (DESIGN.md section 3, a contract): ``camera.json``; ``frames.csv`` with
the header ``timestamp,rgb,depth`` (seconds; paths relative to the folder; an empty depth cell
means no depth for that frame); ``rgb/*.png`` 8-bit colour; ``depth/*.png`` 16-bit raw depth
registered to the colour image, 0 = no reading; optional ``hand.json``.

Every reader is a generator of :class:`Frame` holding one frame at a time, so memory does not grow
with the length of the recording. Problems with the input are one-line InputError/ConfigError
messages naming the file and saying how to fix it. A problem with the recording as a whole
(missing files, wrong camera.json, a first frame that cannot be used) is raised when it is
opened; a problem confined to one frame (a corrupt PNG in the middle) is not raised but yielded
as a bad frame (``Frame.error`` set, no image) so a long run can note it and go on. Timestamps
are passed through as given: a non-increasing timestamp is the tracker's to report.
"""

from __future__ import annotations

import csv
import math
import shutil
from collections.abc import Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout

FRAMES_HEADER = ("timestamp", "rgb", "depth")
VIDEO_SUFFIXES = frozenset(
    ".mp4 .m4v .avi .mov .mkv .webm .mpg .mpeg .wmv .flv .ogv .mjpeg .mjpg .h264 .ts".split()
)
LIVE_PREFIX = "live:"
PROBE_FRAMES = 3  # frames read at opening; if none is usable the recording is refused


_NO_IMAGE = np.zeros((0, 0, 3), np.uint8)
_NO_IMAGE.setflags(write=False)


@dataclass(frozen=True)
class Frame:
    """One frame: colour as OpenCV BGR uint8 (H,W,3); depth raw uint16 (H,W) or None.

    ``timestamp`` is in seconds; metres of depth = raw * camera.depth_scale (0 = no reading).
    A bad frame (unreadable, wrong size, ...) has ``error`` set to a one-line message and an
    empty (0,0,3) image: skip it. ``timestamp`` is then the listed one, or NaN if unknown.
    """

    index: int
    timestamp: float
    bgr: np.ndarray
    depth: np.ndarray | None = None
    error: str | None = None

    @classmethod
    def bad(cls, index: int, timestamp: float, error: str) -> Frame:
        """A frame that could not be read: its place in the recording and why."""
        return cls(index, timestamp, _NO_IMAGE, None, error)

    @property
    def ok(self) -> bool:
        return self.error is None


class Recording:
    """A source of frames: iterate it for :class:`Frame` s, one at a time.

    Subclasses implement :meth:`_frames` (a generator) and :meth:`__len__`. Iterating twice reads
    the recording twice (a live camera simply goes on streaming).
    """

    kind = "recording"
    has_depth = False  # whether frames can carry depth (subclasses set it)

    def __init__(self, source: str, camera: Camera, hand: HandLayout | None = None) -> None:
        self.source = source
        self.camera = camera
        self.hand = hand
        self._active: list[Generator[Frame, None, None]] = []

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def frames(self, start: int = 0) -> Iterator[Frame]:
        """Frames from index ``start`` on (``--resume``). Readers skip the frames before it
        without decoding them where the format allows (a recording folder, a bag); a video
        decodes its way forward; a live camera cannot start part-way."""
        frames = self._frames(start) if start else self._frames()
        # Keep unfinished iterations so close() can release what they hold.
        self._active = [g for g in self._active if g.gi_frame is not None]
        self._active.append(frames)
        return frames

    def _frames(self, start: int = 0) -> Generator[Frame, None, None]:  # pragma: no cover
        raise NotImplementedError  # abstract

    def __len__(self) -> int:  # pragma: no cover - abstract
        raise TypeError(f"{type(self).__name__} has no known length")

    def close(self) -> None:
        """Release files and devices held by iterations still in progress."""
        for frames in self._active:
            frames.close()  # runs the generator's finally blocks
        self._active.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.source}>"

    # ------------------------------------------------------------------------ shared checks

    def check_size(self, bgr: np.ndarray, where: str) -> None:
        """InputError if a colour image's size differs from the camera's (wrong camera.json)."""
        h, w = bgr.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            raise InputError(
                f"{where} is {w}x{h} but the camera is {self.camera.width}x{self.camera.height}; "
                "give the camera.json calibrated at this resolution"
            )


# ------------------------------------------------------------------------------ image helpers


def read_png(path: Path, what: str) -> np.ndarray:
    """Decode an image file as stored (no conversion); InputError naming it if that fails."""
    try:
        data = np.fromfile(path, dtype=np.uint8)  # imdecode also handles non-ASCII paths
    except OSError as e:
        raise InputError(f"{what} {path} cannot be read ({e.strerror}); restore the file") from None
    image = _quiet_imdecode(data) if data.size and not _truncated_png(data) else None
    if image is None:
        raise InputError(
            f"{what} {path} is not a readable image (corrupt or truncated); restore or re-export "
            "it, or remove its row from frames.csv"
        )
    return image


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _truncated_png(data: np.ndarray) -> bool:
    """A PNG that does not end with its IEND chunk was cut short (an interrupted copy): refuse
    it before libpng, which would print its own error line to stderr. (Looked for near the end,
    not at it: some tools append bytes after IEND, which decoders ignore.)"""
    return data[:8].tobytes() == _PNG_SIGNATURE and b"IEND" not in data[-4096:].tobytes()


def _quiet_imdecode(data: np.ndarray) -> np.ndarray | None:
    """cv2.imdecode without OpenCV's own warning line for a damaged file: the caller reports
    the problem as one line of its own."""
    logging = cv2.utils.logging
    level = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_ERROR)
    try:
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    finally:
        logging.setLogLevel(level)


def as_bgr(image: np.ndarray, where: str) -> np.ndarray:
    """8-bit colour as BGR (H,W,3); grayscale and BGRA are converted; anything else InputError."""
    if image.dtype != np.uint8:
        bits = image.dtype.itemsize * 8
        raise InputError(
            f"{where} is {bits}-bit ({image.dtype}); colour frames must be 8-bit (convert it, "
            "e.g. to an 8-bit PNG)"
        )
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    raise InputError(
        f"{where} has shape {image.shape}; expected 8-bit colour (H, W, 3)"
    )


def check_depth(depth: np.ndarray, bgr: np.ndarray, where: str) -> np.ndarray:
    """Raw 16-bit depth (H,W) the size of the colour image, else InputError."""
    if depth.dtype != np.uint16 or depth.ndim != 2:
        kind = f"{depth.dtype.itemsize * 8}-bit" if depth.dtype != np.uint16 else "16-bit"
        channels = depth.shape[2] if depth.ndim == 3 else 1
        raise InputError(
            f"{where} is {kind} with {channels} channel(s); depth must be 16-bit single-channel "
            "raw units (0 = no reading), registered to the colour image"
        )
    if depth.shape != bgr.shape[:2]:
        raise InputError(
            f"{where} is {depth.shape[1]}x{depth.shape[0]} but the colour image is "
            f"{bgr.shape[1]}x{bgr.shape[0]}; depth must be registered (aligned) to colour"
        )
    return depth


# --------------------------------------------------------------------------- native folder


@dataclass(frozen=True)
class _Row:
    line: int
    timestamp: float
    rgb: Path
    depth: Path | None


class FolderRecording(Recording):
    """Native recording folder (frames.csv + rgb/ + depth/ + camera.json [+ hand.json])."""

    kind = "recording folder"

    def __init__(
        self, folder: str | Path, camera: Camera | None = None, hand: HandLayout | None = None
    ) -> None:
        folder = Path(folder)
        if folder.name == "frames.csv" and folder.is_file():
            folder = folder.parent
        if not folder.is_dir():
            what = "is a file, not a folder" if folder.exists() else "not found"
            raise InputError(
                f"recording folder {folder} {what}; give a folder containing frames.csv"
            )
        self.folder = folder
        self.frames_csv = folder / "frames.csv"
        if not self.frames_csv.is_file():
            raise InputError(
                f"recording folder {folder} has no frames.csv; a recording needs frames.csv "
                "(header timestamp,rgb,depth), rgb/*.png and camera.json"
            )
        if camera is None:
            camera_json = folder / "camera.json"
            if not camera_json.is_file():
                raise ConfigError(
                    f"recording folder {folder} has no camera.json; add one (fx, fy, cx, cy, "
                    "width, height, depth_scale) or pass --camera camera.json"
                )
            camera = Camera.load(camera_json)
        if hand is None and (folder / "hand.json").is_file():
            hand = HandLayout.load(folder / "hand.json")
        super().__init__(str(folder), camera, hand)
        # One pass over the (small, text) index up front: bad rows and missing files fail now,
        # not an hour into tracking; the images themselves are only read while iterating.
        self._length = 0
        self.has_depth = False
        for row in self._rows():
            self._length += 1
            self.has_depth |= row.depth is not None
            for path, what in ((row.rgb, "rgb"), (row.depth, "depth")):
                if path is not None and not path.is_file():
                    problem = "is not a file" if path.exists() else "not found"
                    raise InputError(
                        f"{self.frames_csv} line {row.line}: {what} image {path} {problem}; "
                        "restore it or remove that row"
                    )
        if self._length == 0:
            raise InputError(
                f"{self.frames_csv} lists no frames; the recording is empty (record or copy "
                "frames into it)"
            )
        self._probe()

    def _probe(self) -> None:
        """Read the first frames now: if none of them can be used the fault is the recording's
        (8-bit depth, a camera.json of another resolution), not one frame's, so say so at once
        instead of reporting every frame of a long run as bad."""
        first_error = None
        for _, row in zip(range(PROBE_FRAMES), self._rows(), strict=False):
            try:
                self._read(row)
                return
            except InputError as e:
                first_error = first_error or e
        raise first_error

    def _read(self, row: _Row) -> tuple[np.ndarray, np.ndarray | None]:
        bgr = as_bgr(read_png(row.rgb, "colour image"), f"colour image {row.rgb}")
        self.check_size(bgr, f"colour image {row.rgb}")
        depth = None
        if row.depth is not None:
            depth = check_depth(read_png(row.depth, "depth image"), bgr, f"depth image {row.depth}")
        return bgr, depth

    def __len__(self) -> int:
        return self._length

    def _rows(self) -> Iterator[_Row]:
        where = str(self.frames_csv)
        try:
            with open(self.frames_csv, newline="", encoding="utf-8-sig") as f:
                reader = csv.reader(f)
                header = next(reader, None)
                if header is None:
                    raise InputError(
                        f"{where} is empty; its first line must be the header timestamp,rgb,depth"
                    )
                if tuple(c.strip() for c in header) != FRAMES_HEADER:
                    raise InputError(
                        f"{where}: header is {','.join(header)!r} but must be "
                        "'timestamp,rgb,depth'; fix the first line"
                    )
                for cells in reader:
                    if not cells or all(not c.strip() for c in cells):
                        continue  # blank lines (e.g. a trailing newline) are harmless
                    yield self._parse_row(reader.line_num, cells)
        except UnicodeDecodeError:
            raise InputError(f"{where} is not a UTF-8 text file; export it as CSV") from None
        except csv.Error as e:
            raise InputError(f"{where} is not valid CSV ({e}); fix the file") from None

    def _parse_row(self, line: int, cells: list[str]) -> _Row:
        where = f"{self.frames_csv} line {line}"
        if len(cells) not in (2, 3):
            raise InputError(
                f"{where}: expected 3 cells (timestamp,rgb,depth), got {len(cells)}; fix that row"
            )
        text, rgb, depth = (c.strip() for c in (*cells, "")[:3])
        try:
            timestamp = float(text)
        except ValueError:
            timestamp = math.nan
        if not math.isfinite(timestamp):
            raise InputError(
                f"{where}: timestamp {text!r} is not a number; give seconds, e.g. 0.0333"
            )
        if not rgb:
            raise InputError(f"{where}: the rgb cell is empty; give the colour image path")
        return _Row(line, timestamp, self.folder / rgb, self.folder / depth if depth else None)

    def _frames(self, start: int = 0) -> Iterator[Frame]:
        for index, row in enumerate(self._rows()):
            if index < start:  # resuming: the index row is enough, the images are not read
                continue
            try:
                bgr, depth = self._read(row)
            except InputError as e:  # this frame only: the caller notes it and goes on
                yield Frame.bad(index, row.timestamp, str(e))
                continue
            yield Frame(index, row.timestamp, bgr, depth)


class RecordingWriter:
    """Writes a native recording folder frame by frame.

    camera.json (and hand.json) are written at construction; each :meth:`write` writes the PNGs
    first and then appends and flushes the frames.csv row, so a write interrupted at any point
    leaves a valid recording of the frames written so far. An existing non-empty folder is only
    replaced with ``overwrite=True`` (which removes the recording files, not other files).
    """

    def __init__(
        self,
        folder: str | Path,
        camera: Camera,
        hand: HandLayout | None = None,
        *,
        overwrite: bool = False,
    ) -> None:
        folder = Path(folder)
        if folder.exists() and not folder.is_dir():
            raise InputError(f"cannot write a recording to {folder}: it is a file; give a folder")
        if folder.is_dir() and any(folder.iterdir()):
            if not overwrite:
                raise InputError(
                    f"recording folder {folder} already exists and is not empty; choose a new "
                    "folder or pass overwrite=True (--overwrite) to replace it"
                )
            for name in ("rgb", "depth"):
                if (folder / name).is_dir():
                    shutil.rmtree(folder / name)
            for name in ("frames.csv", "camera.json", "hand.json"):
                (folder / name).unlink(missing_ok=True)
        (folder / "rgb").mkdir(parents=True, exist_ok=True)
        (folder / "depth").mkdir(exist_ok=True)
        self.folder = folder
        self.camera = camera
        self.hand = hand
        self.count = 0
        camera.save(folder / "camera.json")
        if hand is not None:
            hand.save(folder / "hand.json")
        self._csv = open(folder / "frames.csv", "w", newline="", encoding="utf-8")
        self._csv.write(",".join(FRAMES_HEADER) + "\n")
        self._csv.flush()

    def write(self, timestamp: float, bgr: np.ndarray, depth: np.ndarray | None = None) -> None:
        """Append one frame: BGR uint8 (H,W,3) at the camera size, raw uint16 depth (H,W)."""
        if self._csv.closed:
            raise InputError(f"recording writer for {self.folder} is closed")
        t = float(timestamp)
        if not math.isfinite(t):
            raise InputError(f"frame {self.count} for {self.folder}: timestamp {timestamp!r} is "
                             "not a finite number of seconds")
        where = f"frame {self.count} for {self.folder}"
        bgr = np.asarray(bgr)
        if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3:
            raise InputError(f"{where}: colour must be BGR uint8 (H, W, 3), got {bgr.dtype} "
                             f"{bgr.shape}")
        h, w = bgr.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            raise InputError(f"{where}: colour is {w}x{h} but the camera is "
                             f"{self.camera.width}x{self.camera.height}")
        name = f"{self.count:06d}.png"
        self._save(self.folder / "rgb" / name, bgr)
        depth_cell = ""
        if depth is not None:
            depth = check_depth(np.asarray(depth), bgr, where)
            self._save(self.folder / "depth" / name, depth)
            depth_cell = f"depth/{name}"
        # repr() of a float is the shortest string that reads back to exactly the same value.
        self._csv.write(f"{t!r},rgb/{name},{depth_cell}\n")
        self._csv.flush()
        self.count += 1

    @staticmethod
    def _save(path: Path, image: np.ndarray) -> None:
        ok, buf = cv2.imencode(".png", image)
        if not ok:
            raise InputError(f"could not encode {path} as PNG")
        try:
            buf.tofile(path)
        except OSError as e:
            raise InputError(f"could not write {path} ({e.strerror}); check disk space") from None

    def close(self) -> None:
        self._csv.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ------------------------------------------------------------------------------- dispatch


def reject_options(kind: str, source: Any, options: dict[str, Any]) -> None:
    """InputError for options the kind of recording does not take (e.g. a topic for a video)."""
    if options:
        raise InputError(
            f"option(s) {', '.join(sorted(options))} do not apply to {kind} {source}; "
            "remove them"
        )


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
    - ``"live:0"`` (or ``live=0``): an OpenCV camera, ``camera`` required; option ``max_frames``.
    """
    live = options.pop("live", None)
    text = str(source) if source is not None else ""
    if live is None and text.startswith(LIVE_PREFIX):
        live = text[len(LIVE_PREFIX):]
    if live is not None:
        from wristtrack.io.live import LiveRecording

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
            from wristtrack.io.rosbag import BagRecording

            return BagRecording(path, camera, hand, **options)
        raise InputError(
            f"folder {path} has no frames.csv (recording folder) and no metadata.yaml (ROS 2 "
            "bag); give the folder that contains one of them"
        )
    suffix = path.suffix.lower()
    if suffix == ".bag":
        from wristtrack.io.rosbag import BagRecording

        return BagRecording(path, camera, hand, **options)
    if suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        from wristtrack.io.rosbag import BagRecording

        return BagRecording(path.parent, camera, hand, **options)
    if suffix in VIDEO_SUFFIXES:
        from wristtrack.io.video import VideoRecording

        return VideoRecording(path, camera, hand, **options)
    raise InputError(
        f"{path}: unknown kind of recording ({suffix or 'no extension'}); give a recording "
        f"folder, a video ({', '.join(sorted(VIDEO_SUFFIXES))}), a .bag file or a ROS 2 bag folder"
    )
