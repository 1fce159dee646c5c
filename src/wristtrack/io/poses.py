"""poses.csv and truth.csv (DESIGN.md section 3, a contract): written row by row, read back whole.

One row per input frame. Poses are hand -> camera (``cam_*``) and relative to the fixed frame
W0 (``t*``, ``q*``); v and w in W0; wrist angles in degrees (ISB, intrinsic Y-Z-X relative to
W0). Columns after the contract's are extras: uncertainty and innovation statistics.
"""

from __future__ import annotations

import csv
import math
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


def read_poses(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a poses.csv / truth.csv as arrays (numbers as float, status as str).

    A last line cut short by an interrupted run is dropped, not an error: one without its
    newline (every row is written whole with its newline, so a cut one lacks it) or with too
    few cells.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            text = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows or rows[0][: len(CONTRACT_COLUMNS)] != list(CONTRACT_COLUMNS):
        raise InputError(f"{path} is not a poses.csv: its header lacks the contract's columns")
    header, body = rows[0], rows[1:]
    if body and (len(body[-1]) != len(header) or not text.endswith("\n")):
        body = body[:-1]
    bad = next((i for i, r in enumerate(body) if len(r) != len(header)), None)
    if bad is not None:
        raise InputError(f"{path} line {bad + 2}: {len(body[bad])} cells, header has {len(header)}")
    out: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        cells = [r[j] for r in body]
        if name == "status":
            out[name] = np.array(cells, dtype=str)
            continue
        try:
            out[name] = np.array([float(c) if c else np.nan for c in cells], dtype=float)
        except ValueError:
            raise InputError(f"{path}: column {name} holds a non-number") from None
    return out


def rows_to_poses(columns: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame rotations (N,3,3) and translations (N,3) from read_poses columns."""
    q = np.column_stack([columns[c] for c in ("cam_qw", "cam_qx", "cam_qy", "cam_qz")])
    t = np.column_stack([columns[c] for c in ("cam_tx", "cam_ty", "cam_tz")])
    R = np.full((len(t), 3, 3), np.nan)
    ok = np.isfinite(q).all(axis=1)
    if ok.any():
        R[ok] = matrix_from_quat(q[ok])
    return R, t
