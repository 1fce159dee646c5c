"""Rotations and rigid motions: SO(3)/SE(3) exp/log, quaternions, Euler and wrist angles.

Pure NumPy, float64, vectorised over any leading axes ("..."), except the single-quaternion
helpers ``*_into``, which the compiled tracker step compiles as they are. Conventions (DESIGN.md
section 2): quaternions are (w, x, y, z) with w >= 0; an SE(3) tangent vector is xi = (rho, phi),
translation part first; Euler sequences are intrinsic and uppercase, with scipy's
``Rotation.from_euler`` meaning; ``wrist_angles`` is the ISB intrinsic Y-Z-X decomposition in
hand axes.
"""

from __future__ import annotations

import math

import numpy as np

ISB_WRIST_SEQUENCE = "YZX"
PAPER_EULER_SEQUENCE = "ZYZ"

# Below this angle (rad) the trigonometric coefficients use their Taylor series: the closed forms
# divide by powers of theta and lose precision. Series kept to theta^6, so the truncation error
# at the threshold is < 1e-20.
_SMALL_ANGLE = 1e-2
# Middle Euler angle this close (rad) to its singular value counts as exact gimbal lock. Much
# tighter than scipy's 1e-7: away from exact lock the quaternion-based decomposition still
# reproduces the matrix to machine precision, so there is no reason to throw information away.
_GIMBAL_EPS = 1e-12

_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


def _f64(a: np.ndarray | float) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def _matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(...,n,n) @ (...,n) -> (...,n) with broadcasting over leading axes."""
    return (M @ v[..., None])[..., 0]


# --------------------------------------------------------------------------------------- SO(3)


def skew(w: np.ndarray) -> np.ndarray:
    """Cross-product matrices (...,3,3) of (...,3) vectors: skew(w) @ v == cross(w, v)."""
    w = _f64(w)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )


def vee(W: np.ndarray) -> np.ndarray:
    """Inverse of :func:`skew` (uses the antisymmetric part of W). (...,3,3) -> (...,3)."""
    W = _f64(W)
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        -1,
    )


def _coefficients(theta2: np.ndarray) -> tuple[np.ndarray, ...]:
    """A = sin t/t, B = (1-cos t)/t^2, C = (t-sin t)/t^3, D = 1/t^2 - cot(t/2)/(2t).

    Closed forms for t >= _SMALL_ANGLE, Taylor series below (all four are smooth in t^2).
    """
    t2 = theta2
    t = np.sqrt(t2)
    small = t < _SMALL_ANGLE
    ts = np.where(small, 1.0, t)  # safe divisor; the small branch is discarded by np.where
    t4, t6 = t2 * t2, t2 * t2 * t2
    A = np.where(small, 1 - t2 / 6 + t4 / 120 - t6 / 5040, np.sin(ts) / ts)
    # 2 sin^2(t/2) instead of 1 - cos t: no cancellation for moderate t.
    B = np.where(small, 0.5 - t2 / 24 + t4 / 720 - t6 / 40320, 2 * np.sin(ts / 2) ** 2 / ts**2)
    C = np.where(small, 1 / 6 - t2 / 120 + t4 / 5040 - t6 / 362880, (ts - np.sin(ts)) / ts**3)
    # cot(t/2) = cos/sin is 0 at t = pi, so D stays finite up to (and at) pi.
    D = np.where(
        small,
        1 / 12 + t2 / 720 + t4 / 30240 + t6 / 1209600,
        1 / ts**2 - np.cos(ts / 2) / (2 * ts * np.sin(ts / 2)),
    )
    return A, B, C, D


# Maps a vector a (3,) to its cross-product matrix, flattened row-major: skew(a).reshape(9).
_SKEW_MAP = np.array(
    [
        [0, 0, 0, 0, 0, -1, 0, 1, 0],
        [0, 0, 1, 0, 0, 0, -1, 0, 0],
        [0, -1, 0, 1, 0, 0, 0, 0, 0],
    ],
    dtype=np.float64,
)
_EYE9 = np.eye(3).reshape(9)


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix exp([phi]x) of rotation vectors (...,3) (Rodrigues). Returns (...,3,3).

    R = cos(t) I + (sin t / t) [phi]x + ((1 - cos t) / t^2) phi phi^T. Written as a few whole-
    array operations because it sits on the filter's hot path (every sigma point, every
    frame); 1 - cos t is computed as 2 sin^2(t/2) so small angles lose no digits.
    """
    phi = _f64(phi)
    t2 = np.einsum("...i,...i->...", phi, phi)
    # sin is accurate to the last bit for tiny arguments, so sin(t)/t and sin(t/2)/t are exact
    # down to t = 1e-150 (where they are 1 and 1/2): no branch for small angles is needed.
    t = np.sqrt(t2 + 1e-300)
    half = np.sin(0.5 * t) / t
    A = np.sin(t) / t  # sin t / t
    B = 2.0 * half * half  # (1 - cos t) / t^2
    outer = (B[..., None] * phi)[..., :, None] * phi[..., None, :]
    flat = (A[..., None] * phi) @ _SKEW_MAP + (1.0 - B * t2)[..., None] * _EYE9
    return outer + flat.reshape(phi.shape[:-1] + (3, 3))


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (...,3) of rotation matrices (...,3,3); angle in [0, pi].

    Up to about 150 degrees: the antisymmetric part gives sin(t) axis and the trace cos(t), and
    atan2 of the two is accurate at every angle in that range (the common case, on the
    filter's hot path). Beyond, the antisymmetric part fades and the axis comes from the
    quaternion (Shepperd's method picks the largest diagonal of the symmetric part), with the
    sign near pi from the antisymmetric part (w >= 0), not from noise.
    """
    R = _f64(R)
    v = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        -1,
    )
    s = np.sqrt(np.einsum("...i,...i->...", v, v))  # sin t
    c = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)  # cos t
    t = np.arctan2(s, c)
    # t / sin t, with its series below 1e-4 rad where the division loses digits
    ratio = np.where(s < 1e-4, 1.0 + t * t / 6.0, t / np.where(s < 1e-4, 1.0, s))
    out = v * ratio[..., None]
    far = c < -0.85
    if np.any(far):
        out[far] = _so3_log_quaternion(R[far])
    return out


def _so3_log_quaternion(R: np.ndarray) -> np.ndarray:
    """so3_log through the quaternion: accurate up to and at pi."""
    q = quat_from_matrix(R)
    w, v = q[..., 0], q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    return v * (2 * np.arctan2(s, w) / s)[..., None]


def so3_left_jacobian(phi: np.ndarray) -> np.ndarray:
    """Left Jacobian J(phi) of SO(3), (...,3) -> (...,3,3): exp(phi + d) ~ exp(J d) exp(phi)."""
    phi = _f64(phi)
    _, B, C, _ = _coefficients(np.sum(phi * phi, axis=-1))
    K = skew(phi)
    return np.eye(3) + B[..., None, None] * K + C[..., None, None] * (K @ K)


def so3_left_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    """Inverse of :func:`so3_left_jacobian` in closed form (finite for angles up to pi)."""
    phi = _f64(phi)
    _, _, _, D = _coefficients(np.sum(phi * phi, axis=-1))
    K = skew(phi)
    return np.eye(3) - 0.5 * K + D[..., None, None] * (K @ K)


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Rotation angle in [0, pi] of (...,3,3) matrices (accurate near 0 and pi)."""
    return np.linalg.norm(so3_log(R), axis=-1)


def rotation_distance(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Geodesic distance (rad) between rotations: angle of R_a^T R_b."""
    return rotation_angle(np.swapaxes(_f64(R_a), -1, -2) @ _f64(R_b))


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to (...,3,3) matrices, via SVD."""
    U, _, Vt = np.linalg.svd(_f64(M))
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


# --------------------------------------------------------------------------------------- SE(3)


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """4x4 rigid motion exp of twists xi = (rho, phi) (...,6). Returns (...,4,4)."""
    xi = _f64(xi)
    rho, phi = xi[..., :3], xi[..., 3:]
    return make_pose(so3_exp(phi), _matvec(so3_left_jacobian(phi), rho))


def se3_log(T: np.ndarray) -> np.ndarray:
    """Twist xi = (rho, phi) (...,6) of 4x4 rigid motions (...,4,4); rotation angle in [0, pi]."""
    T = _f64(T)
    phi = so3_log(T[..., :3, :3])
    rho = _matvec(so3_left_jacobian_inv(phi), T[..., :3, 3])
    return np.concatenate([rho, phi], axis=-1)


def make_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Homogeneous (...,4,4) transform from rotation (...,3,3) and translation (...,3)."""
    R, t = _f64(R), _f64(t)
    lead = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*lead, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def pose_inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid (...,4,4) transforms (uses R^T, no general matrix inverse)."""
    T = _f64(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return make_pose(Rt, -_matvec(Rt, T[..., :3, 3]))


def pose_compose(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A @ B for (...,4,4) transforms (apply B first)."""
    return _f64(A) @ _f64(B)


def transform_points(R: np.ndarray, t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """R p + t for points p (...,N,3) with R (...,3,3), t (...,3). Returns (...,N,3)."""
    return _f64(p) @ np.swapaxes(_f64(R), -1, -2) + _f64(t)[..., None, :]


def relative_pose(
    R_c0: np.ndarray, t_c0: np.ndarray, R_ch: np.ndarray, t_ch: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Hand pose relative to the fixed frame W0: R = R_c0^T R_ch, t = R_c0^T (t_ch - t_c0)."""
    R_0t = np.swapaxes(_f64(R_c0), -1, -2)
    return R_0t @ _f64(R_ch), _matvec(R_0t, _f64(t_ch) - _f64(t_c0))


# --------------------------------------------------------------------------------- quaternions


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) (...,4) of rotation matrices (...,3,3), w >= 0.

    Shepperd's method: build the candidate from the largest of 4w^2, 4x^2, 4y^2, 4z^2 so the
    division is never by a small number. Ties at w == 0 (180 degrees) are broken like scipy:
    the first non-zero of x, y, z is made positive.
    """
    R = _f64(R)
    d0, d1, d2 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = d0 + d1 + d2
    # Sums and differences of the off-diagonal pairs: 4wx, 4wy, 4wz and 4xy, 4xz, 4yz.
    wx, wy, wz = (
        R[..., 2, 1] - R[..., 1, 2],
        R[..., 0, 2] - R[..., 2, 0],
        R[..., 1, 0] - R[..., 0, 1],
    )
    xy, xz, yz = (
        R[..., 0, 1] + R[..., 1, 0],
        R[..., 0, 2] + R[..., 2, 0],
        R[..., 1, 2] + R[..., 2, 1],
    )
    cands = np.stack(
        [
            np.stack([wx, 1 + 2 * d0 - tr, xy, xz], -1),
            np.stack([wy, xy, 1 + 2 * d1 - tr, yz], -1),
            np.stack([wz, xz, yz, 1 + 2 * d2 - tr], -1),
            np.stack([1 + tr, wx, wy, wz], -1),
        ],
        -2,
    )
    choice = np.argmax(np.stack([d0, d1, d2, tr], -1), axis=-1)
    q = np.take_along_axis(cands, choice[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return _quat_canonical(q)


def _quat_canonical(q: np.ndarray) -> np.ndarray:
    """Sign-fix quaternions: w > 0, or at w == 0 the first non-zero of x, y, z > 0."""
    flip = q[..., 0] < 0
    tie = q[..., 0] == 0
    for k in (1, 2, 3):
        flip |= tie & (q[..., k] < 0)
        tie &= q[..., k] == 0
    return np.where(flip[..., None], -q, q)


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (...,3,3) of quaternions (w, x, y, z) (...,4); q is normalised first."""
    q = _f64(q)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


# ----------------------------------------------------------------- single quaternions, in place
# One rotation at a time in plain arithmetic, results written into ``out``: numba compiles these
# very functions into the tracker step (tracking/compiled.py). Hamilton convention, (w, x, y, z),
# R(p q) = R(p) R(q); no sign canonicalisation (the filter composes them).


def quat_exp_into(x: float, y: float, z: float, out: np.ndarray) -> None:
    """Unit quaternion of the rotation vector (x, y, z) into out (4,); exact at zero (the
    1e-300 keeps h > 0, and sin(h) / h is exact for tiny h)."""
    h = 0.5 * math.sqrt(x * x + y * y + z * z + 1e-300)
    s = 0.5 * math.sin(h) / h
    out[0] = math.cos(h)
    out[1] = s * x
    out[2] = s * y
    out[3] = s * z


def quat_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a b (out must not be a or b)."""
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2]
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1]
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]


def quat_of_rotation_into(r: np.ndarray, out: np.ndarray) -> None:
    """Unit quaternion of the row-major rotation r[:9] into out (4,), by Shepperd's method (as
    ``quat_from_matrix``, for one rotation and without fixing the sign)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
        r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]
    )  # fmt: skip
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(1.0 + tr)  # 4w
        out[0], out[1], out[2], out[3] = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r00 - tr)  # 4x
        out[0], out[1], out[2], out[3] = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r11 - tr)  # 4y
        out[0], out[1], out[2], out[3] = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r22 - tr)  # 4z
        out[0], out[1], out[2], out[3] = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s


def rotation_of_quat_into(q: np.ndarray, R: np.ndarray) -> None:
    """Rotation matrix of the unit quaternion q (4,) into R (3, 3) (``matrix_from_quat`` for one
    quaternion already of unit norm)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = w * w + x * x - y * y - z * z
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = w * w - x * x + y * y - z * z
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = w * w - x * x - y * y + z * z


# -------------------------------------------------------------------------------- Euler angles


def _parse_seq(seq: str) -> tuple[list[int], bool]:
    """Axis indices and 'intrinsic' flag; lowercase means extrinsic, as in scipy."""
    if not isinstance(seq, str) or len(seq) != 3 or not (seq.isupper() or seq.islower()):
        raise ValueError(f"Euler sequence must be 3 axes, all upper or all lower case, got {seq!r}")
    try:
        axes = [_AXIS_INDEX[c] for c in seq.upper()]
    except KeyError:
        raise ValueError(f"Euler sequence {seq!r} may only use the axes X, Y, Z") from None
    if axes[0] == axes[1] or axes[1] == axes[2]:
        raise ValueError(f"Euler sequence {seq!r} repeats an axis consecutively")
    return axes, seq.isupper()


def _axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotation matrix (...,3,3) about coordinate axis 0/1/2 by angle (...)."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*np.shape(angle), 3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., j, i] = s
    R[..., i, j] = -s
    return R


def matrix_from_euler(angles: np.ndarray, seq: str) -> np.ndarray:
    """Rotation matrices (...,3,3) from Euler angles (...,3) in radians.

    Uppercase ``seq`` is intrinsic: R = R_seq[0](a0) @ R_seq[1](a1) @ R_seq[2](a2), exactly
    scipy's ``Rotation.from_euler(seq, angles).as_matrix()``. Lowercase is extrinsic, as in scipy.
    """
    angles = _f64(angles)
    axes, intrinsic = _parse_seq(seq)
    if not intrinsic:  # extrinsic (a0, a1, a2) about x,y,z == intrinsic (a2, a1, a0) about Z,Y,X
        axes, angles = axes[::-1], angles[..., ::-1]
    R = _axis_rotation(axes[0], angles[..., 0])
    R = R @ _axis_rotation(axes[1], angles[..., 1])
    return R @ _axis_rotation(axes[2], angles[..., 2])


def euler_from_matrix(R: np.ndarray, seq: str) -> np.ndarray:
    """Euler angles (...,3), radians, of rotation matrices (...,3,3); inverse of matrix_from_euler.

    Same ranges as scipy's ``as_euler``: first and third angle in [-pi, pi), middle angle in
    [-pi/2, pi/2] (Tait-Bryan, e.g. "YZX", "ZYX") or [0, pi] (proper Euler, e.g. "ZYZ"). Uses the
    quaternion method of Bernardes & Viollet (2022), which stays accurate next to gimbal lock. At
    exact lock the whole rotation goes on the first angle and the third is 0 (like scipy).
    """
    axes, intrinsic = _parse_seq(seq)
    q = quat_from_matrix(R)
    qw, qv = q[..., 0], q[..., 1:]
    # The method is written for extrinsic sequences; intrinsic = extrinsic with axes reversed.
    i, j, k = axes[::-1] if intrinsic else axes
    proper = i == k
    if proper:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for an even permutation of (x, y, z), else -1
    if proper:
        a, b, c, d = qw, qv[..., i], qv[..., j], qv[..., k] * sign
    else:
        a = qw - qv[..., j]
        b = qv[..., i] + qv[..., k] * sign
        c = qv[..., j] + qw
        d = qv[..., k] * sign - qv[..., i]

    middle = 2 * np.arctan2(np.hypot(c, d), np.hypot(a, b))  # in [0, pi]
    half_sum = np.arctan2(b, a)
    half_diff = np.arctan2(d, c)
    lock0 = np.abs(middle) <= _GIMBAL_EPS
    lock_pi = np.abs(middle - np.pi) <= _GIMBAL_EPS
    regular = ~(lock0 | lock_pi)

    # "first"/"last" are in the extrinsic (reversed) order used by the method.
    locked = np.where(lock0, 2 * half_sum, 2 * half_diff * (-1 if not intrinsic else 1))
    first = np.where(regular, half_sum - half_diff, np.where(intrinsic, 0.0, locked))
    last = np.where(regular, half_sum + half_diff, np.where(intrinsic, locked, 0.0))
    if not proper:
        last = last * sign
        middle = middle - np.pi / 2
    # Intrinsic: the method's last angle is our first one.
    first, last = (first + np.pi) % (2 * np.pi) - np.pi, (last + np.pi) % (2 * np.pi) - np.pi
    # The middle angle is already in its range; not wrapping it keeps a proper sequence's pi
    # at +pi (scipy would report -pi, the same rotation).
    return np.stack([last, middle, first] if intrinsic else [first, middle, last], -1)


# ---------------------------------------------------------------------------------- wrist angles


# Signs that turn the Y-Z-X decomposition's (about Z, about Y, about X) angles into the ISB's
# (ulnar +, flexion +, pronation +). The hand axes are the same for both hands (+Y = Z x X), so
# +Y points to the thumb of a right hand and to the little finger of a left one: a positive turn
# about +Z is radial deviation on a right hand, and a positive turn about the distal +X lifts the
# thumb of a right hand, i.e. supinates it. The right hand's two angles are therefore negated.
HAND_SIDES = ("right", "left")
_SIDE_SIGNS = {"right": np.array([-1.0, 1.0, -1.0]), "left": np.array([1.0, 1.0, 1.0])}


def _side_signs(side: str) -> np.ndarray:
    try:
        return _SIDE_SIGNS[side]
    except KeyError:
        raise ValueError(f"unknown hand side {side!r}; choose 'right' or 'left'") from None


def wrist_angles(R_rel: np.ndarray, side: str = "right") -> np.ndarray:
    """ISB wrist angles (deviation, flexion, pronation) (...,3), radians, of R_rel (...,3,3).

    The intrinsic Y-Z-X decomposition in hand axes (DESIGN.md section 2),
    R_rel = Ry(a_y) @ Rz(a_z) @ Rx(a_x), signed as the ISB recommends for either hand:
    flexion(+)/extension(-), ulnar(+)/radial(-) deviation, pronation(+)/supination(-).
    For a right hand deviation = -a_z and pronation = -a_x; for a left hand the angles are
    a_z and a_x as they are (see _SIDE_SIGNS). Note the output ORDER differs from the rotation
    order.
    """
    a_y, a_z, a_x = np.moveaxis(euler_from_matrix(R_rel, ISB_WRIST_SEQUENCE), -1, 0)
    return np.stack([a_z, a_y, a_x], -1) * _side_signs(side)


def matrix_from_wrist_angles(
    deviation: np.ndarray | float,
    flexion: np.ndarray | float,
    pronation: np.ndarray | float,
    side: str = "right",
) -> np.ndarray:
    """Inverse of :func:`wrist_angles` for the same ``side``, (...,3,3)."""
    dev, flex, pron = np.broadcast_arrays(_f64(deviation), _f64(flexion), _f64(pronation))
    s_dev, _, s_pron = _side_signs(side)
    return matrix_from_euler(np.stack([flex, s_dev * dev, s_pron * pron], -1), ISB_WRIST_SEQUENCE)
