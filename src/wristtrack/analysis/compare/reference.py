"""The reference system's view of the hand for ``wristtrack compare``: a pose per reference frame.

Three ways in:
- a truth.csv (our simulator's ground truth): the hand pose as written, in the camera frame;
- our markers mapped to the reference's labels (``--markers WRIST=RWRA,...``): the hand pose is
  the least-squares rigid fit of our hand layout to the mapped markers (three or more), or the
  WRIST position alone;
- a cluster of three or more markers on the back of the hand (``--cluster A,B,C``): the pose of
  the cluster (its mean shape fitted rigidly to each frame). The fixed offset from our hand
  frame to the cluster's frame is unknown here; the registration estimates it.

Positions in metres in the reference's lab frame; NaN where the reference has no pose (gaps).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from wristtrack.errors import InputError
from wristtrack.hand import MARKER_NAMES
from wristtrack.io.markers.data import MarkerData

KINDS = ("truth", "markers", "cluster")


@dataclass(frozen=True)
class ReferencePoses:
    """Poses of the hand (or of a cluster on it) as the reference system saw them."""

    kind: str  # one of KINDS
    times: np.ndarray  # (N,) s, the reference's clock
    R: np.ndarray  # (N, 3, 3) lab <- hand (or cluster); NaN without orientation
    p: np.ndarray  # (N, 3) m, lab frame
    rate: float  # Hz
    source: str
    has_rotation: bool
    fit_rms_mm: np.ndarray  # (N,) RMS residual of the rigid fit per frame (0 for truth)
    units: str = "m"
    labels: dict[str, str] | None = None  # our name (or cluster index) -> the file's label
    notes: tuple[str, ...] = ()
    model: np.ndarray | None = None  # (K, 3) m: the body points fitted, where a fit made the poses
    fit_markers: np.ndarray | None = None  # (N,) markers each frame's fit had, where fitted

    @property
    def valid(self) -> np.ndarray:
        ok = np.isfinite(self.p).all(axis=1)
        if self.has_rotation:
            ok &= np.isfinite(self.R).all(axis=(1, 2))
        return ok


def rigid_fit(model: np.ndarray, data: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame least-squares rigid transform (Kabsch, no scale) taking ``model`` (K,3) onto
    ``data`` (N,K,3), NaN markers left out. Returns R (N,3,3), t (N,3), RMS residual (N,) m;
    NaN for frames with fewer than three markers."""
    n, k = data.shape[:2]
    w = np.isfinite(data).all(axis=2).astype(float)  # (N,K)
    d = np.nan_to_num(data)
    count = w.sum(axis=1)
    ok = count >= 3
    safe = np.maximum(count, 1.0)[:, None]
    mc = (w @ model) / safe  # (N,3) weighted model centroid
    dc = np.einsum("nk,nkj->nj", w, d) / safe
    A = (model[None] - mc[:, None]) * w[..., None]
    B = (d - dc[:, None]) * w[..., None]
    H = np.einsum("nki,nkj->nij", B, A)  # sum (d - dc)(m - mc)^T
    U, _, Vt = np.linalg.svd(H)
    s = np.sign(np.linalg.det(U @ Vt))
    s[s == 0] = 1.0
    D = np.zeros((n, 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = s
    R = U @ D @ Vt
    t = dc - np.einsum("nij,nj->ni", R, mc)
    fitted = np.einsum("nij,kj->nki", R, model) + t[:, None]
    res = np.where(w > 0, np.linalg.norm(fitted - d, axis=2), 0.0)
    rms = np.sqrt((res**2).sum(axis=1) / safe[:, 0])
    # Three markers in a line leave the rotation about that line undetermined.
    sv = np.linalg.svd(B, compute_uv=False)  # (N, 3) spread of the markers
    ok &= sv[:, 1] > 1e-3 * np.maximum(sv[:, 0], 1e-12)
    R[~ok] = np.nan
    t[~ok] = np.nan
    rms[~ok] = np.nan
    return R, t, rms


def cluster_shape(xyz: np.ndarray) -> np.ndarray:
    """The mean shape (K,3) of a rigid cluster seen in frames (N,K,3), in a frame with origin
    at its first marker: frames with every marker, aligned to the first such one (Procrustes,
    two passes)."""
    full = np.isfinite(xyz).all(axis=(1, 2))
    if not full.any():
        raise InputError("no frame sees every cluster marker; cannot learn the cluster's shape")
    shape = xyz[np.flatnonzero(full)[0]]
    spread = np.linalg.svd(shape - shape.mean(axis=0), compute_uv=False)
    if not spread[1] > 1e-3 * spread[0]:
        raise InputError("the cluster's markers lie in a line: its rotation about that line is "
                         "unknown; give three markers that span a triangle")
    for _ in range(2):
        R, t, _ = rigid_fit(shape, xyz[full])
        local = np.einsum("nji,nkj->nki", R, xyz[full] - t[:, None])  # R^T (x - t)
        shape = local.mean(axis=0)
    return shape - shape[0]


def parse_mapping(text: str) -> dict[str, str]:
    """``WRIST=RWRA,MCP2=RFIN`` -> {"WRIST": "RWRA", "MCP2": "RFIN"}; our names checked."""
    out: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        name, sep, label = item.partition("=")
        name = name.strip().upper()
        if not sep or not label.strip():
            raise InputError(f"--markers item {item!r}: write OURNAME=LABEL, e.g. WRIST=RWRA")
        if name not in MARKER_NAMES:
            raise InputError(
                f"--markers: {name!r} is not one of our markers ({', '.join(MARKER_NAMES)})"
            )
        out[name] = label.strip()
    if not out:
        raise InputError("--markers is empty; write e.g. WRIST=RWRA,MCP3=RFIN,MCP5=RWRB")
    return out


def from_markers(data: MarkerData, mapping: dict[str, str], layout: np.ndarray) -> ReferencePoses:
    """The hand pose from our markers as the reference labels them; ``layout`` (6,3) is the hand
    layout of the run (metres, hand frame, MARKER_NAMES order)."""
    names = list(mapping)
    xyz = data.select([mapping[n] for n in names])
    if len(names) >= 3:
        model = np.stack([layout[MARKER_NAMES.index(n)] for n in names])
        R, p, rms = rigid_fit(model, xyz)
        has_rotation = True
    elif "WRIST" in mapping:
        p = xyz[:, names.index("WRIST")]
        R = np.full((len(p), 3, 3), np.nan)
        rms = np.zeros(len(p))
        has_rotation, model = False, None
    else:
        raise InputError(
            "--markers maps fewer than three markers and not WRIST: map WRIST, or three or more"
        )
    return ReferencePoses(
        "markers", data.times, R, p, data.rate, data.source, has_rotation, rms * 1e3,
        data.units, dict(mapping), data.notes, model,
        None if model is None else np.isfinite(xyz).all(axis=2).sum(axis=1),
    )


def from_cluster(data: MarkerData, labels: list[str]) -> ReferencePoses:
    """The pose of a rigid cluster of three or more markers (``labels``) on the hand."""
    if len(labels) < 3:
        raise InputError(f"--cluster needs three or more marker labels, got {len(labels)}")
    xyz = data.select(labels)
    shape = cluster_shape(xyz)
    R, p, rms = rigid_fit(shape, xyz)
    return ReferencePoses(
        "cluster", data.times, R, p, data.rate, data.source, True, rms * 1e3, data.units,
        {str(i): label for i, label in enumerate(labels)}, data.notes, shape,
        np.isfinite(xyz).all(axis=2).sum(axis=1),
    )


def from_truth(path: str | Path) -> ReferencePoses:
    """A simulated recording's truth.csv as a reference: its camera frame is the 'lab'."""
    from wristtrack.io.markers.trajectories import frame_rate
    from wristtrack.io.poses import read_poses, rows_to_poses

    cols = read_poses(path)
    R, p = rows_to_poses(cols)
    rate, _ = frame_rate(cols["timestamp"], str(path))
    return ReferencePoses(
        "truth", cols["timestamp"], R, p, rate, str(path), True, np.zeros(len(p)),
    )


class Interpolator:
    """The reference pose at any time inside its valid spans: cubic spline positions, rotation
    spline orientations (both through the valid samples only). A query is usable when the valid
    samples around it are at most 1.5 sample intervals apart (never across a gap)."""

    def __init__(self, ref: ReferencePoses):
        ok = ref.valid
        if ok.sum() < 4:
            raise InputError(f"{ref.source}: fewer than four frames with a reference pose")
        self.t = ref.times[ok]
        self.has_rotation = ref.has_rotation
        self._pos = CubicSpline(self.t, ref.p[ok])
        self._rot = RotationSpline(self.t, Rotation.from_matrix(ref.R[ok])) if ref.has_rotation \
            else None
        self._max_gap = 1.5 / ref.rate

    def usable(self, tq: np.ndarray) -> np.ndarray:
        tq = np.asarray(tq, dtype=float)
        # Both ends count as inside (to a nanosecond: the clock fit is not exact to the bit).
        inside = (tq >= self.t[0] - 1e-9) & (tq <= self.t[-1] + 1e-9)
        jj = np.clip(np.searchsorted(self.t, tq), 1, len(self.t) - 1)
        return inside & (self.t[jj] - self.t[jj - 1] <= self._max_gap)

    def __call__(self, tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tq = np.clip(tq, self.t[0], self.t[-1])
        p = self._pos(tq)
        R = self._rot(tq).as_matrix() if self._rot is not None else np.full((len(tq), 3, 3),
                                                                            np.nan)
        return R, p
