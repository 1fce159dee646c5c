"""Pinhole RGB-D camera with OpenCV distortion: projection, back-projection, camera.json.

Camera frame (DESIGN.md section 2): OpenCV, x right, y down, z forward; pixels (u, v) with
integer values at pixel centres. ``dist`` follows OpenCV's ordering (k1, k2, p1, p2[, k3[, k4,
k5, k6]]), so the same numbers work in ``cv2.projectPoints``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.errors import ConfigError
from wristtrack.jsonfile import read_config, write_config

REQUIRED_FIELDS = ("fx", "fy", "cx", "cy", "width", "height", "depth_scale")
DIST_LENGTHS = (4, 5, 8)
# A depth frame paired with a colour frame by time stamp is at most half a frame interval away
# from it (10 fps is the slowest rate a depth camera streams at): longer is a unit mistake.
MAX_DEPTH_DELAY_S = 0.05
# A rolling shutter reads its rows within a frame interval (10 fps at the slowest): longer is a
# unit mistake.
MAX_READOUT_S = 0.1
# Coarsest plausible depth unit (1 cm): 16-bit depth then reaches 655 m. Larger values are
# inverted units (1000 for millimetres) and would make every depth reading absurd.
MAX_DEPTH_SCALE = 0.01

# Newton iterations for undistortion; it converges quadratically, a handful is normally enough.
_UNDISTORT_MAX_ITER = 30
_UNDISTORT_TOL = 1e-14  # normalised image units (~5e-12 px at f = 525)


def distorted(x, y, k1, k2, p1, p2, k3, k4, k5, k6):
    """OpenCV's distortion of normalised coordinates (x/z, y/z): (x_d, y_d), for scalars (the
    compiled tracker step, tracking/kernel.py) and arrays alike."""
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def _check_number(value: Any, field: str, where: str, *, positive: bool, integer: bool = False):
    """Validated float (or int) of one camera field; ConfigError naming file and field if not."""
    kind = "a positive integer" if integer else "a positive number" if positive else "a number"
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    if ok:
        ok = math.isfinite(value) and (not positive or value > 0)
    if ok and integer:
        ok = float(value).is_integer()
    if not ok:
        raise ConfigError(f"{where}: field '{field}' must be {kind}, got {value!r}; fix that value")
    return int(value) if integer else float(value)


def _check_dist(value: Any, where: str) -> tuple[float, ...] | None:
    if value is None:
        return None
    if isinstance(value, str | bytes) or not hasattr(value, "__len__"):
        raise ConfigError(
            f"{where}: field 'dist' must be a list [k1, k2, p1, p2, k3], got {value!r}"
        )
    if len(value) not in DIST_LENGTHS:
        raise ConfigError(
            f"{where}: field 'dist' has {len(value)} coefficients; give 4, 5 or 8 in OpenCV order "
            "[k1, k2, p1, p2, k3, (k4, k5, k6)] or leave it out"
        )
    return tuple(_check_number(v, "dist", where, positive=False) for v in value)


@dataclass(frozen=True)
class Camera:
    """Intrinsics of the (registered) colour camera, plus the depth unit.

    ``depth_scale`` is metres per raw depth unit (0.001 for millimetre depth images).
    ``depth_delay`` (s, camera.json ``depth_delay_s``, optional) is how long after the colour
    frame its depth frame was captured (negative: before). The depth and colour streams of a
    consumer RGB-D camera run on their own clocks, and each colour frame is paired with the
    depth frame nearest in time, up to half a frame interval away (io/rosbag.py); over a
    recording the pair keeps its phase. 0 for depth captured with the colour (synchronised
    sensors); None where it is not known (the tracker then reads the depth as simultaneous).
    ``readout`` (s, camera.json ``readout_s``, optional) is how long a rolling-shutter colour
    sensor takes to read its rows, top to bottom: each row is exposed that much later than the
    one above it in proportion, the middle row at the frame's time. 0 or None: a global
    shutter (every row at once).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    depth_scale: float = 0.001
    dist: tuple[float, ...] | None = None
    depth_delay: float | None = None
    readout: float | None = None

    def __post_init__(self) -> None:
        # Validate code-built cameras too, so a bad camera fails here and not deep in a filter.
        self._set_validated(self.__dict__, "camera parameters")

    def _set_validated(self, d: dict[str, Any], where: str) -> None:
        for field in ("fx", "fy", "depth_scale"):
            object.__setattr__(self, field, _check_number(d[field], field, where, positive=True))
        for field in ("cx", "cy"):
            object.__setattr__(self, field, _check_number(d[field], field, where, positive=False))
        for field in ("width", "height"):
            value = _check_number(d[field], field, where, positive=True, integer=True)
            object.__setattr__(self, field, value)
        object.__setattr__(self, "dist", _check_dist(d.get("dist"), where))
        delay = d.get("depth_delay")
        if delay is not None:
            delay = _check_number(delay, "depth_delay_s", where, positive=False)
        if delay is not None and abs(delay) > MAX_DEPTH_DELAY_S:
            raise ConfigError(
                f"{where}: field 'depth_delay_s' is {delay:g} s (at most {MAX_DEPTH_DELAY_S:g} "
                "either way); it is seconds from the colour frame to its depth frame, e.g. 0.008"
            )
        object.__setattr__(self, "depth_delay", delay)
        readout = d.get("readout")
        if readout is not None:
            readout = _check_number(readout, "readout_s", where, positive=False)
            if not 0.0 <= readout <= MAX_READOUT_S:
                raise ConfigError(
                    f"{where}: field 'readout_s' is {readout:g} s (0 to {MAX_READOUT_S:g}); it is "
                    "the seconds a rolling shutter takes from the top row to the bottom, e.g. 0.025"
                )
        object.__setattr__(self, "readout", readout)
        if not (0.0 <= self.cx <= self.width and 0.0 <= self.cy <= self.height):
            raise ConfigError(
                f"{where}: principal point ('cx', 'cy') = ({self.cx:g}, {self.cy:g}) lies outside "
                f"the {self.width}x{self.height} image; the calibration is for another resolution "
                "or cx and cy are swapped"
            )
        if self.depth_scale > MAX_DEPTH_SCALE:
            raise ConfigError(
                f"{where}: field 'depth_scale' is {self.depth_scale:g} m per depth unit (at most "
                f"{MAX_DEPTH_SCALE:g}); it is metres per unit, e.g. 0.001 for millimetre depth"
            )

    # ------------------------------------------------------------------------------ properties

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def area(self) -> float:
        """Image area in pixels^2 (the clutter likelihood is 1 / area)."""
        return float(self.width * self.height)

    @property
    def has_distortion(self) -> bool:
        return self.dist is not None and any(c != 0.0 for c in self.dist)

    # ---------------------------------------------------------------------------- distortion

    def distortion_terms(self) -> tuple[float, ...]:
        """(k1, k2, p1, p2, k3, k4, k5, k6), zeros for the terms not given."""
        c = tuple(self.dist or ())
        return c + (0.0,) * (8 - len(c))

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """OpenCV distortion of normalised coordinates (x/z, y/z) (...,2) -> (...,2)."""
        xy = np.asarray(xy, dtype=np.float64)
        if not self.has_distortion:
            return xy.copy()
        return self._distort(xy)[0]

    def _distort(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distorted coordinates (...,2), their Jacobian d(distorted)/d(xy) (...,2,2) and the
        radial factor (...)."""
        k1, k2, p1, p2, k3, k4, k5, k6 = self.distortion_terms()
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        radial = num / den
        d_radial = (
            (k1 + r2 * (2 * k2 + 3 * k3 * r2)) * den - num * (k4 + r2 * (2 * k5 + 3 * k6 * r2))
        ) / den**2  # d radial / d r2
        xd, yd = distorted(x, y, k1, k2, p1, p2, k3, k4, k5, k6)
        cross = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y  # d xd/dy == d yd/dx
        J = np.stack(
            [
                np.stack([radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x, cross], -1),
                np.stack([cross, radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x], -1),
            ],
            -2,
        )
        return np.stack([xd, yd], -1), J, radial

    def undistort_normalized(self, xy_d: np.ndarray) -> np.ndarray:
        """Invert :meth:`distort_normalized` by Newton's method (...,2) -> (...,2).

        Points with no physical preimage (far outside the calibrated field, where the distortion
        polynomial folds over) or where Newton does not converge come back as NaN rather than
        silently wrong.
        """
        xy_d = np.asarray(xy_d, dtype=np.float64)
        if not self.has_distortion:
            return xy_d.copy()
        xy = xy_d.copy()
        # Diverging points may overflow on their way to being flagged NaN; keep that quiet.
        with np.errstate(all="ignore"):
            for _ in range(_UNDISTORT_MAX_ITER):
                f, J, _ = self._distort(xy)
                residual = f - xy_d
                if not np.any(np.abs(residual) > _UNDISTORT_TOL):  # NaN never keeps it looping
                    break
                # Explicit 2x2 solve: a singular Jacobian makes that one point NaN instead of
                # raising for the whole batch (np.linalg.solve would).
                a, b, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
                r0, r1 = residual[..., 0], residual[..., 1]
                det = a * d - b * c
                xy = xy - np.stack([(d * r0 - b * r1) / det, (a * r1 - c * r0) / det], -1)
            f, J, radial = self._distort(xy)
        converged = np.all(np.abs(f - xy_d) <= 1e-10, axis=-1)  # False for NaN too
        # Accept only the physical branch: positive radial factor (not the mirrored point across
        # the centre) and an orientation-preserving map (not beyond the fold of the polynomial).
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        physical = (radial > 0) & (det > 0)
        bad = ~(converged & physical)
        xy[bad] = np.nan
        return xy

    # ------------------------------------------------------------------------- projections

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (u, v) (...,2) of camera-frame points (...,3), distortion applied.

        No visibility test: points with z <= 0 give meaningless (or infinite) pixels; check z.
        """
        p = np.asarray(points, dtype=np.float64)
        z = p[..., 2:3]
        if np.all(z != 0):  # the common case, without the cost of an errstate context
            xy = p[..., :2] / z
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                xy = p[..., :2] / z
        if self.has_distortion:
            xy = np.stack(distorted(xy[..., 0], xy[..., 1], *self.distortion_terms()), -1)
        return xy * np.array([self.fx, self.fy]) + np.array([self.cx, self.cy])

    def normalize(self, uv: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (x/z, y/z) (...,2) of pixels (...,2)."""
        uv = np.asarray(uv, dtype=np.float64)
        xy_d = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], -1)
        return self.undistort_normalized(xy_d)

    def backproject(self, uv: np.ndarray, depth: np.ndarray | float) -> np.ndarray:
        """Camera-frame points (...,3) of pixels (...,2) at depth z (...) in metres."""
        xy = self.normalize(uv)
        z = np.asarray(depth, dtype=np.float64)
        return np.concatenate([xy * z[..., None], np.broadcast_to(z, xy.shape[:-1])[..., None]], -1)

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """True where (u, v) (...,2) lies on the sensor: [-0.5, width-0.5) x [-0.5, height-0.5).

        Pixel centres are at integer coordinates, so a pixel covers +-0.5 around them. NaN is
        outside.
        """
        uv = np.asarray(uv, dtype=np.float64)
        u, v = uv[..., 0], uv[..., 1]
        return (u >= -0.5) & (u < self.width - 0.5) & (v >= -0.5) & (v < self.height - 0.5)

    def row_time(self, v: np.ndarray | float) -> np.ndarray | float:
        """When image row coordinate ``v`` was exposed, in s after the frame's time (its middle
        row's): ``readout`` ((v + 1/2) / height - 1/2), 0 for a global shutter."""
        return ((np.asarray(v, dtype=float) + 0.5) / self.height - 0.5) * (self.readout or 0.0)

    # --------------------------------------------------------------------------------- files

    def to_dict(self) -> dict[str, Any]:
        """camera.json content (DESIGN.md section 3)."""
        d: dict[str, Any] = {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
            "depth_scale": self.depth_scale,
        }
        if self.dist is not None:
            d["dist"] = list(self.dist)
        if self.depth_delay is not None:
            d["depth_delay_s"] = self.depth_delay
        if self.readout is not None:
            d["readout_s"] = self.readout
        return d

    @classmethod
    def from_dict(cls, d: Any, source: str = "camera.json") -> Camera:
        """Camera from parsed camera.json content; ConfigError naming ``source`` and the field."""
        where = f"camera file {source}"
        if not isinstance(d, dict):
            raise ConfigError(
                f"{where}: expected a JSON object with fields {', '.join(REQUIRED_FIELDS)}, "
                f"got {type(d).__name__}"
            )
        missing = [f for f in REQUIRED_FIELDS if f not in d]
        if missing:
            raise ConfigError(
                f"{where}: missing field {', '.join(repr(f) for f in missing)}; camera.json needs "
                f"{', '.join(REQUIRED_FIELDS)} (and optionally dist, depth_delay_s, readout_s)"
            )
        # Validate with the file name in the message, then build (which re-checks cheaply).
        cam = object.__new__(cls)
        cam._set_validated({**d, "depth_delay": d.get("depth_delay_s"),
                            "readout": d.get("readout_s")}, where)
        return cls(**{f: getattr(cam, f)
                      for f in (*REQUIRED_FIELDS, "dist", "depth_delay", "readout")})

    @classmethod
    def load(cls, path: str | Path) -> Camera:
        """Read camera.json; every problem is a one-line ConfigError naming the file."""
        d = read_config(path, "camera")
        return cls.from_dict(d, source=str(path))

    def save(self, path: str | Path) -> None:
        """Write camera.json (creates the parent folder if needed)."""
        write_config(path, self.to_dict())

    @classmethod
    def default(cls) -> Camera:
        """A 640x480 Kinect/Xtion-like camera without distortion, millimetre depth."""
        return cls(fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=640, height=480, depth_scale=0.001)
