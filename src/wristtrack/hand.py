"""Hand marker layout: the six marker centres in the hand frame, hand.json, estimation from depth.

Hand frame (DESIGN.md section 2): origin at the WRIST marker centre, +X from WRIST towards MCP3,
+Z normal to the palm plane out of the back of the hand (towards the camera in the neutral pose),
+Y = Z x X (the thumb side of a right hand). The paper's model is planar: marker k at
(L_k cos a_k, L_k sin a_k, 0), with a = 0 for MCP3 by definition. Real palms are not: for a
non-planar layout +X runs exactly from WRIST to MCP3 (MCP3 = (L, 0, 0)) and +Z is the normal of
the markers' least-squares plane made perpendicular to X; a layout estimated from depth keeps
the heights depth measured (averaged over the frames of a still hand, :func:`average_layout`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.errors import ConfigError, InitialisationError, InputError
from wristtrack.jsonfile import read_config, write_config

MARKER_NAMES = ("WRIST", "CMC1", "MCP2", "MCP3", "MCP4", "MCP5")
MCP3_INDEX = MARKER_NAMES.index("MCP3")
MARKER_DIAMETER_M = 0.012  # the paper's markers: discs of blue paper, 1.2 cm across

# Validation limits (metres). Why: closer markers merge into one blob; a layout farther than
# 25 cm is not a hand (usually millimetres written as metres); a (nearly) collinear layout leaves
# the rotation about its line unobservable.
MIN_MARKER_SPACING = 0.010
MAX_MARKER_DISTANCE = 0.25
MCP3_AXIS_TOLERANCE = 0.001
WRIST_ORIGIN_TOLERANCE = 1e-6
MIN_OFF_LINE_SPREAD = 0.010


def marker_image_diameter(fx: float, z):
    """A marker's diameter in the image (px) at depth ``z`` (m, scalar or array) for a camera
    of focal length ``fx`` (px)."""
    return fx * MARKER_DIAMETER_M / z


# An adult right hand (lengths in metres, angles in degrees), CMC1..MCP5.
_DEFAULT_LENGTHS = (0.045, 0.085, 0.088, 0.083, 0.076)
_DEFAULT_ANGLES_DEG = (50.0, 16.0, 0.0, -14.0, -28.0)


class LayoutEstimateError(InitialisationError, ConfigError):
    """The layout measured at initialisation is impossible (catchable as either parent)."""


@dataclass(frozen=True, eq=False)
class HandLayout:
    """Marker centres (6,3) in the hand frame, metres, in the order of MARKER_NAMES.

    Construction does not validate (so a bad layout can be reported with its file name): call
    :meth:`validate`. Loaders and estimators do.
    """

    points: np.ndarray

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=np.float64)  # own copy, then read-only: truly frozen
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, HandLayout):
            return NotImplemented
        return self.points.shape == other.points.shape and bool(
            np.array_equal(self.points, other.points)
        )

    def __hash__(self) -> int:
        return hash((self.points.shape, self.points.tobytes()))

    # ------------------------------------------------------------------------- construction

    @classmethod
    def from_paper(cls, lengths: np.ndarray, angles_rad: np.ndarray) -> HandLayout:
        """Planar layout (L cos a, L sin a, 0) for CMC1..MCP5; WRIST at the origin.

        ``lengths`` (5,) metres and ``angles_rad`` (5,) radians, in the order CMC1, MCP2, MCP3,
        MCP4, MCP5; the MCP3 angle must be 0 (it defines +X). The result is validated.
        """
        L = np.asarray(lengths, dtype=np.float64)
        a = np.asarray(angles_rad, dtype=np.float64)
        where = "hand layout from lengths and angles"
        if L.shape != (5,) or a.shape != (5,):
            raise ConfigError(
                f"{where}: need 5 lengths and 5 angles (CMC1, MCP2, MCP3, MCP4, MCP5), got "
                f"shapes {L.shape} and {a.shape}"
            )
        if not (np.all(np.isfinite(L)) and np.all(np.isfinite(a)) and np.all(L > 0)):
            raise ConfigError(f"{where}: lengths must be positive and angles finite, got {L}, {a}")
        if abs(a[MCP3_INDEX - 1]) > 1e-9:
            raise ConfigError(
                f"{where}: the MCP3 angle must be 0 (MCP3 defines the +X axis), got "
                f"{a[MCP3_INDEX - 1]!r} rad; subtract it from all angles"
            )
        pts = np.zeros((6, 3))
        pts[1:, 0] = L * np.cos(a)
        pts[1:, 1] = L * np.sin(a)
        pts[MCP3_INDEX, 1] = 0.0  # exactly on the axis
        layout = cls(pts)
        layout.validate(where)
        return layout

    @classmethod
    def default(cls) -> HandLayout:
        """An adult right hand (DESIGN.md / core API): used when nothing better is known."""
        return cls.from_paper(np.array(_DEFAULT_LENGTHS), np.radians(_DEFAULT_ANGLES_DEG))

    # ------------------------------------------------------------------------------ queries

    @property
    def lengths(self) -> np.ndarray:
        """(5,) distances WRIST -> CMC1..MCP5, metres."""
        return np.linalg.norm(self.points[1:], axis=-1)

    @property
    def angles(self) -> np.ndarray:
        """(5,) in-plane angles of CMC1..MCP5 from +X towards +Y, radians."""
        return np.arctan2(self.points[1:, 1], self.points[1:, 0])

    def marker(self, name: str) -> np.ndarray:
        """(3,) position of one marker by name."""
        return self.points[MARKER_NAMES.index(name)]

    @property
    def side(self) -> str:
        """'right' or 'left': which side of the hand frame the thumb (CMC1) is on. +Y = Z x X
        points to the thumb of a right hand, so a layout with CMC1 at -Y is a left hand."""
        return "right" if self.points[MARKER_NAMES.index("CMC1"), 1] >= 0 else "left"

    def mirrored(self) -> HandLayout:
        """The same layout mirrored across the XZ plane (left hand <-> right hand)."""
        return HandLayout(self.points * np.array([1.0, -1.0, 1.0]))

    # --------------------------------------------------------------------------- validation

    def validate(self, source: str = "hand.json") -> HandLayout:
        """Raise ConfigError (one line naming ``source``) if the layout cannot be tracked.

        Returns self so it can be chained.
        """
        where = source if source.startswith("hand ") else f"hand layout {source}"
        p = self.points
        if p.shape != (6, 3):
            raise ConfigError(
                f"{where}: expected 6 markers x 3 coordinates ({', '.join(MARKER_NAMES)}), got "
                f"shape {p.shape}"
            )
        if not np.all(np.isfinite(p)):
            bad = [MARKER_NAMES[i] for i in np.flatnonzero(~np.all(np.isfinite(p), axis=1))]
            raise ConfigError(f"{where}: marker {', '.join(bad)} has non-finite coordinates")
        dist = np.linalg.norm(p, axis=1)
        if dist.max() > MAX_MARKER_DISTANCE:
            k = int(np.argmax(dist))
            raise ConfigError(
                f"{where}: marker {MARKER_NAMES[k]} is {dist[k]:.3g} m from WRIST (limit "
                f"{MAX_MARKER_DISTANCE} m); coordinates must be in metres"
            )
        if dist[0] > WRIST_ORIGIN_TOLERANCE:
            raise ConfigError(
                f"{where}: WRIST must be at the origin [0, 0, 0] of the hand frame, got "
                f"{p[0].tolist()}"
            )
        mcp3 = p[MCP3_INDEX]
        if mcp3[0] <= 0 or np.hypot(mcp3[1], mcp3[2]) > MCP3_AXIS_TOLERANCE:
            raise ConfigError(
                f"{where}: MCP3 must lie on the +X axis (y = z = 0 within "
                f"{MCP3_AXIS_TOLERANCE * 1000:g} mm, x > 0), got {mcp3.tolist()}"
            )
        gaps = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        gaps[np.diag_indices(6)] = np.inf
        i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
        if gaps[i, j] < MIN_MARKER_SPACING:
            raise ConfigError(
                f"{where}: markers {MARKER_NAMES[i]} and {MARKER_NAMES[j]} are "
                f"{gaps[i, j] * 1000:.1f} mm apart; they must be at least "
                f"{MIN_MARKER_SPACING * 1000:g} mm apart to be told apart"
            )
        centred = p - p.mean(axis=0)
        direction = np.linalg.svd(centred)[2][0]
        off_line = np.linalg.norm(centred - np.outer(centred @ direction, direction), axis=1)
        if off_line.max() < MIN_OFF_LINE_SPREAD:
            raise ConfigError(
                f"{where}: the markers are (nearly) collinear (all within "
                f"{off_line.max() * 1000:.1f} mm of one line), so the rotation about that line "
                "cannot be observed; spread them over the back of the hand"
            )
        return self

    # -------------------------------------------------------------------------------- files

    def to_dict(self) -> dict[str, Any]:
        """hand.json content: {"markers": {"WRIST": [x, y, z], ...}} (metres, hand frame)."""
        pts = self.points.tolist()
        return {"markers": {name: pts[i] for i, name in enumerate(MARKER_NAMES)}}

    @classmethod
    def from_dict(cls, d: Any, source: str = "hand.json") -> HandLayout:
        """Validated layout from parsed hand.json; ConfigError naming ``source`` and the markers."""
        where = f"hand file {source}"
        markers = d.get("markers") if isinstance(d, dict) else None
        if not isinstance(markers, dict):
            raise ConfigError(
                f'{where}: expected {{"markers": {{"WRIST": [x, y, z], ...}}}} with the markers '
                f"{', '.join(MARKER_NAMES)}"
            )
        unknown = [k for k in markers if k not in MARKER_NAMES]
        missing = [k for k in MARKER_NAMES if k not in markers]
        if unknown or missing:
            parts = []
            if unknown:
                parts.append(f"unknown marker name(s) {', '.join(map(repr, unknown))}")
            if missing:
                parts.append(f"missing marker(s) {', '.join(missing)}")
            raise ConfigError(
                f"{where}: {'; '.join(parts)}; the markers are {', '.join(MARKER_NAMES)} "
                "(upper case)"
            )
        pts = []
        for name in MARKER_NAMES:
            value = markers[name]
            ok = isinstance(value, list | tuple) and len(value) == 3
            ok = ok and all(isinstance(c, int | float) and not isinstance(c, bool) for c in value)
            if not ok:
                raise ConfigError(
                    f"{where}: marker {name} must be [x, y, z] in metres, got {value!r}"
                )
            pts.append([float(c) for c in value])
        return cls(np.array(pts)).validate(where)

    @classmethod
    def load(cls, path: str | Path) -> HandLayout:
        """Read and validate hand.json; every problem is a one-line ConfigError naming the file."""
        d = read_config(path, "hand")
        return cls.from_dict(d, source=str(path))

    def save(self, path: str | Path) -> None:
        """Write hand.json (creates the parent folder if needed)."""
        write_config(path, self.to_dict())


# ----------------------------------------------------------------------------------- estimation


def hand_frame_from_points(points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hand frame (R_ch (3,3), t_ch (3,)) from 6 marker centres (6,3) in the camera frame.

    DESIGN.md section 2: origin WRIST; X exactly from WRIST to MCP3; Z the normal of the
    least-squares plane of the six markers made perpendicular to X, oriented towards the camera
    (Z . (camera - wrist) > 0, the camera being the origin); Y = Z x X. For coplanar markers Z
    is the plane's normal. Columns of R_ch are the hand axes in camera coordinates.
    """
    p = _check_points(points_cam)
    wrist = p[0]
    v = p[MCP3_INDEX] - wrist
    norm = np.linalg.norm(v)
    if norm < 1e-9:
        raise LayoutEstimateError(
            "markers measured at initialisation: MCP3 coincides with WRIST; check the marker "
            "labels"
        )
    x = v / norm
    # Smallest right-singular vector of the centred cloud = least-squares plane normal.
    n = np.linalg.svd(p - p.mean(axis=0))[2][2]
    z = n - (n @ x) * x
    z_norm = np.linalg.norm(z)
    if z_norm < 1e-9:  # the plane's normal along WRIST -> MCP3: not a hand
        raise LayoutEstimateError(
            "markers measured at initialisation: no palm plane across WRIST -> MCP3; check the "
            "marker labels"
        )
    z = z / z_norm
    if z @ (-wrist) < 0:
        z = -z
    y = np.cross(z, x)
    return np.column_stack([x, y, z]), wrist.copy()


def estimate_layout(
    points_cam: np.ndarray, planar: bool = False
) -> tuple[HandLayout, np.ndarray, np.ndarray]:
    """Hand layout and pose from 3-D marker centres (6,3) measured in the camera frame.

    E.g. back-projected blob depths of a still hand. The frame is :func:`hand_frame_from_points`;
    the layout is the markers in that frame, with the heights (z) depth measured, or set to 0
    with ``planar`` (the paper's planar model). Returns (layout, R_ch, t_ch) with
    p_cam ~ R_ch @ p_hand + t_ch. Raises LayoutEstimateError (a ConfigError and an
    InitialisationError) if the measured layout fails :meth:`HandLayout.validate`.
    """
    p = _check_points(points_cam)
    R_ch, t_ch = hand_frame_from_points(p)
    local = (p - t_ch) @ R_ch
    if planar:
        local[:, 2] = 0.0
    local[0] = 0.0  # WRIST is the origin and MCP3 on +X by construction: make both exact
    local[MCP3_INDEX, 1:] = 0.0
    layout = HandLayout(local)
    try:
        layout.validate("hand layout measured at initialisation")
    except ConfigError as e:
        raise LayoutEstimateError(str(e)) from None
    return layout, R_ch, t_ch


def average_layout(
    frames_cam: np.ndarray, planar: bool = False
) -> tuple[HandLayout, np.ndarray, np.ndarray, float]:
    """Layout from the marker centres of several frames of a still hand (F,6,3), camera frame.

    One frame's depths are noisy (a structured-light camera: ~1.4 mm at 0.7 m, correlated over
    a marker), and a layout that keeps the measured heights keeps that noise: so the frames are
    aligned rigidly onto their mean shape (generalised Procrustes, two rounds, which also absorbs
    a little drift of a hand that is only nearly still) and averaged. Frames with a non-finite
    point are left out. Returns (layout, R_ch, t_ch, rms_m): the pose is that of the LAST usable
    frame (where a tracker stands when the still start ends), ``rms_m`` the RMS distance of the
    aligned frames from the mean shape (the depth noise that averaging removed, times
    sqrt(F)). Raises InputError when no frame is usable, LayoutEstimateError as
    :func:`estimate_layout`.
    """
    f = np.asarray(frames_cam, dtype=np.float64)
    if f.ndim != 3 or f.shape[1:] != (6, 3):
        raise InputError(
            f"marker centres of a still hand must be (frames, 6, 3), got shape {f.shape}"
        )
    f = f[np.isfinite(f).all(axis=(1, 2))]
    if len(f) == 0:
        raise InputError("no frame with all six marker centres finite (no depth?)")
    mean = f[-1]
    for _ in range(2):
        aligned = np.stack([_onto(frame, mean) for frame in f])
        mean = aligned.mean(axis=0)
    rms = float(np.sqrt(np.mean(np.sum((aligned - mean) ** 2, axis=-1))))
    layout, R_ch, t_ch = estimate_layout(mean, planar)
    return layout, R_ch, t_ch, rms


def _onto(points: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``points`` (6,3) moved rigidly onto ``target`` (6,3) (least squares, no scale)."""
    R, t = fit_pose(HandLayout(points), target)
    return points @ R.T + t


def fit_pose(layout: HandLayout, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid pose (R_ch, t_ch) mapping layout points onto measured (6,3) points.

    Kabsch/Umeyama without scale: minimises sum |R_ch p_hand + t_ch - p_cam|^2.
    """
    p = _check_points(points_cam)
    q = layout.points
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    U, _, Vt = np.linalg.svd((p - pc).T @ (q - qc))
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ np.diag([1.0, 1.0, d]) @ Vt
    return R, pc - R @ qc


def _check_points(points_cam: np.ndarray) -> np.ndarray:
    p = np.asarray(points_cam, dtype=np.float64)
    if p.shape != (6, 3):
        raise InputError(
            f"marker centres must be 6 points x 3 coordinates ({', '.join(MARKER_NAMES)}), got "
            f"shape {p.shape}"
        )
    if not np.all(np.isfinite(p)):
        bad = [MARKER_NAMES[i] for i in np.flatnonzero(~np.all(np.isfinite(p), axis=1))]
        raise InputError(f"marker centres of {', '.join(bad)} are not finite (no depth?)")
    return p
