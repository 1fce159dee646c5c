"""The native recording folder: its reader (FolderRecording) and its writer (RecordingWriter).

Native recording folder (DESIGN.md section 3, a contract): ``camera.json``; ``frames.csv`` with
the header ``timestamp,rgb,depth`` (seconds; paths relative to the folder; an empty depth cell
means no depth for that frame); ``rgb/*.png`` 8-bit colour; ``depth/*.png`` 16-bit raw depth
registered to the colour image, 0 = no reading; optional ``hand.json``.
"""

from __future__ import annotations

import csv
import math
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import ConfigError, InputError
from wristtrack.hand import HandLayout
from wristtrack.io.base import Frame, Recording, as_bgr, check_depth

FRAMES_HEADER = ("timestamp", "rgb", "depth")
PROBE_FRAMES = 3  # frames read at opening; if none is usable the recording is refused


# ------------------------------------------------------------------------------ image files


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

    def timestamps(self) -> np.ndarray:
        """Every frame's timestamp (s) as frames.csv lists it; no image is read."""
        return np.array([row.timestamp for row in self._rows()], dtype=float)

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
