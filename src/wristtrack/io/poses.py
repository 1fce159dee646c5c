"""poses.csv and truth.csv (DESIGN.md section 3, a contract): written row by row, read back whole.

One row per input frame. Poses are hand -> camera (``cam_*``) and relative to the fixed frame
W0 (``t*``, ``q*``); v and w in W0; wrist angles in degrees (ISB, intrinsic Y-Z-X relative to
W0). Columns after the contract's are extras: uncertainty and innovation statistics.
"""

from __future__ import annotations

import csv
import math
from array import array
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TextIO

import numpy as np

from wristtrack.errors import InputError
from wristtrack.geometry import matrix_from_quat, quat_from_matrix, wrist_angles

CONTRACT_COLUMNS = (
    "frame,timestamp,status,cam_tx,cam_ty,cam_tz,cam_qw,cam_qx,cam_qy,cam_qz,"
    "tx,ty,tz,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz,deviation_deg,flexion_deg,pronation_deg,"
    "n_visible,n_clutter"
).split(",")
EXTRA_COLUMNS = ("pos_sigma_mm", "rot_sigma_deg", "nis", "nis_dof")
COLUMNS = (*CONTRACT_COLUMNS, *EXTRA_COLUMNS)


def _fmt(value: float) -> str:
    return "nan" if not math.isfinite(value) else f"{value:.9g}"


def pose_row(
    frame: int,
    timestamp: float,
    status: str,
    R_ch: np.ndarray,
    t_ch: np.ndarray,
    R: np.ndarray,
    p: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    n_visible: int,
    n_clutter: int,
    pos_sigma_mm: float = math.nan,
    rot_sigma_deg: float = math.nan,
    nis: float = math.nan,
    nis_dof: int = 0,
    side: str = "right",
) -> list[str]:
    """The text cells of one poses.csv row; NaN poses give 'nan' cells throughout. ``side``
    (the hand's) signs the anatomical angles (geometry.wrist_angles)."""
    known = bool(np.all(np.isfinite(t_ch)) and np.all(np.isfinite(R_ch)))
    if known:
        q_cam, q_rel = quat_from_matrix(R_ch), quat_from_matrix(R)
        angles = np.degrees(wrist_angles(R, side)) + 0.0  # + 0.0: no "-0" from a sign flip
    else:
        q_cam = q_rel = np.full(4, np.nan)
        angles = np.full(3, np.nan)
    cells = [str(frame), repr(float(timestamp)), str(status)]
    numbers = (*t_ch, *q_cam, *p, *q_rel, *v, *w, *angles)
    cells += [_fmt(float(x)) for x in numbers]
    cells += [str(int(n_visible)), str(int(n_clutter))]
    cells += [_fmt(pos_sigma_mm), _fmt(rot_sigma_deg), _fmt(float(nis)), str(int(nis_dof))]
    return cells


class PosesWriter:
    """Streams rows to a poses.csv, flushing each one so an interrupted run keeps every frame."""

    def __init__(self, path: str | Path, append: bool = False):
        self.path = Path(path)
        fresh = not (append and self.path.exists() and self.path.stat().st_size > 0)
        self._fh: TextIO = open(self.path, "a" if not fresh else "w", newline="")  # noqa: SIM115
        self._csv = csv.writer(self._fh, lineterminator="\n")
        if fresh:
            self._csv.writerow(COLUMNS)
            self._fh.flush()

    def write(self, cells: list[str]) -> None:
        self._csv.writerow(cells)
        self._fh.flush()

    def write_result(self, result) -> None:
        """Write a tracker.FrameResult."""
        self.write(
            pose_row(
                result.frame, result.timestamp, str(result.status), result.R_ch, result.t_ch,
                result.R, result.p, result.v, result.w, result.n_visible, result.n_clutter,
                result.pos_sigma_mm, result.rot_sigma_deg, result.nis, result.nis_dof,
                getattr(result, "side", "right"),
            )
        )

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> PosesWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_truth(path: str | Path, trajectory, side: str = "right") -> None:
    """truth.csv of a simulated recording: the poses.csv columns from a sim Trajectory of a
    ``side`` hand."""
    with PosesWriter(path) as writer:
        for i in range(len(trajectory.t)):
            writer.write(
                pose_row(
                    i, trajectory.t[i], "truth", trajectory.R_ch[i], trajectory.t_ch[i],
                    trajectory.R_rel[i], trajectory.p_rel[i], trajectory.v[i], trajectory.w[i],
                    6, 0, side=side,
                )
            )


def read_pose_table(path: str | Path) -> tuple[list[str], Iterator[list[str]]]:
    """The header of a poses.csv / truth.csv and an iterator over its body rows as text cells.

    The header is checked now (InputError if the file cannot be read or is not a poses.csv);
    rows are streamed, so a long run is never held as text. A last line cut short by an
    interrupted run is dropped, not an error: one without its newline (every row is written
    whole with its newline, so a cut one lacks it) or with too few cells. A row of the wrong
    length anywhere else is an InputError naming its line.
    """
    path = Path(path)
    try:
        fh = open(path, newline="")  # noqa: SIM115 (the row iterator closes it)
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    ended = [True]  # whether the line read last ended with its newline
    reader = csv.reader(_lines(fh, ended))
    try:
        header = next(reader, None)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        fh.close()
        raise InputError(f"cannot read {path}: {exc}") from None
    if header is None or header[: len(CONTRACT_COLUMNS)] != list(CONTRACT_COLUMNS):
        fh.close()
        raise InputError(f"{path} is not a poses.csv: its header lacks the contract's columns")
    return header, _body(path, fh, reader, len(header), ended)


def _lines(fh: TextIO, ended: list[bool]) -> Iterator[str]:
    for line in fh:
        ended[0] = line.endswith(("\n", "\r"))
        yield line


def _body(
    path: Path, fh: TextIO, reader: Iterator[list[str]], width: int, ended: list[bool]
) -> Iterator[list[str]]:
    """Rows one behind the reader: whether a row is the cut-short last one is known only when
    the next one comes (or the file ends)."""
    with fh:
        held: list[str] | None = None
        line = 1
        try:
            for row in reader:
                if held is not None:
                    if len(held) != width:
                        raise InputError(
                            f"{path} line {line}: {len(held)} cells, header has {width}"
                        )
                    yield held
                held = row
                line += 1
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"cannot read {path}: {exc}") from None
        if held is not None and len(held) == width and ended[0]:
            yield held


def read_poses(path: str | Path, columns: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Columns of a poses.csv / truth.csv as arrays (numbers as float, status as str): all of
    them, or only ``columns`` (8 bytes a row per numeric column kept: a long run read for a few
    columns stays small). Rows as :func:`read_pose_table` gives them."""
    path = Path(path)
    header, rows = read_pose_table(path)
    names = list(header if columns is None else columns)
    missing = [name for name in names if name not in header]
    if missing:
        raise InputError(f"{path} has no column {', '.join(missing)}; is it a poses.csv?")
    index = [header.index(name) for name in names]
    numbers = {name: array("d") for name in names if name != "status"}
    status: list[str] = []
    for row in rows:
        for name, j in zip(names, index, strict=True):
            if name == "status":
                status.append(row[j])
                continue
            cell = row[j]
            try:
                numbers[name].append(float(cell) if cell else math.nan)
            except ValueError:
                raise InputError(f"{path}: column {name} holds a non-number") from None
    out = {name: np.frombuffer(col, dtype=float).copy() if len(col) else np.empty(0)
           for name, col in numbers.items()}
    if "status" in names:
        out["status"] = np.array(status, dtype=str)
    return {name: out[name] for name in names}


def rows_to_poses(columns: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame rotations (N,3,3) and translations (N,3) from read_poses columns."""
    q = np.column_stack([columns[c] for c in ("cam_qw", "cam_qx", "cam_qy", "cam_qz")])
    t = np.column_stack([columns[c] for c in ("cam_tx", "cam_ty", "cam_tz")])
    R = np.full((len(t), 3, 3), np.nan)
    ok = np.isfinite(q).all(axis=1)
    if ok.any():
        R[ok] = matrix_from_quat(q[ok])
    return R, t
