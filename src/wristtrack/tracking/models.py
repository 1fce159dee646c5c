"""Motion models of the wrist relative to the fixed frame W0, in the form the UKF needs.

``ConstantRateModel`` (the default): orientation on SO(3) as an error state, position, linear
velocity and angular velocity (in W0) in the state; constant linear and angular velocity driven
by random-walk accelerations. The angular velocity is estimated, not differentiated.

``PaperModel``: the paper's model, state (T, v, Z-Y-Z Euler angles); translation constant
velocity with random-walk acceleration, orientation a random walk driven by angular-velocity
noise, R+ = R exp([n_w]x dt) (Cordella et al., section III-B). The Euler state is singular at
the neutral pose (middle angle 0), which is the paper's weakness the default model removes.

Both share the interface of :class:`wristtrack.filter.ukf.ManifoldModel` plus ``pose(X)`` (rotation
and position relative to W0 of states X) and ``process_noise(dt)``. ``SigmaPropagator`` is the
constant-rate model for the tracker's hot path (see there), with quaternion helpers in Python
floats for single rotations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wristtrack.geometry import (
    PAPER_EULER_SEQUENCE,
    euler_from_matrix,
    matrix_from_euler,
    so3_exp,
    so3_log,
)


@dataclass(frozen=True)
class ProcessNoise:
    """Spectral densities of the white noises driving the models (continuous time).

    The discrete noise variance is density / dt, so a model tuned at 30 fps stays right for
    irregular frame intervals.
    """

    # Tuned on the simulated scenarios (smooth range-of-motion cycles and reaches): lower values
    # trade lag in fast motion for less noise at rest; see docs/BENCHMARKS.md.
    linear_accel: float = 0.1  # (m/s^2)^2 s, random-walk linear acceleration
    angular_accel: float = 2.5  # (rad/s^2)^2 s, default model: random-walk angular acceleration
    angular_rate: float = 0.5  # (rad/s)^2 s, paper model: random-walk orientation


class ConstantRateModel:
    """State x = [R (9, row-major), p (3), v (3), w (3)]; tangent [dphi, dp, dv, dw] (12).

    The rotation error is on the left, R = exp(dphi) R_hat, so dphi is in W0 like w.
    Noise (6) = (linear acceleration, angular acceleration).
    """

    dim = 12
    rotation = slice(0, 3)  # tangent coordinates of the orientation error (rad)
    position = slice(3, 6)  # and of the position (m)
    velocity = slice(6, 9)  # m/s
    angular_velocity = slice(9, 12)  # rad/s
    noise_dim = 6
    name = "default"

    def __init__(self, noise: ProcessNoise = ProcessNoise()):
        self.noise = noise

    @staticmethod
    def initial_state(R: np.ndarray, p: np.ndarray, v=None, w=None) -> np.ndarray:
        zero = np.zeros(3)
        return np.concatenate(
            (np.asarray(R).reshape(9), p, zero if v is None else v, zero if w is None else w)
        )

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        out = np.empty((xi.shape[0], 18))
        R = x[:9].reshape(3, 3)
        out[:, :9] = (so3_exp(xi[:, :3]) @ R).reshape(-1, 9)
        out[:, 9:] = x[9:] + xi[:, 3:]
        return out

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        out = np.empty((X.shape[0], 12))
        R_hat_T = x[:9].reshape(3, 3).T
        out[:, :3] = so3_log(X[:, :9].reshape(-1, 3, 3) @ R_hat_T)
        out[:, 3:] = X[:, 9:] - x[9:]
        return out

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        a, alpha = noise[:, :3], noise[:, 3:]
        p, v, w = X[:, 9:12], X[:, 12:15], X[:, 15:18]
        out = np.empty_like(X)
        out[:, 9:12] = p + v * dt + (0.5 * dt * dt) * a
        out[:, 12:15] = v + a * dt
        out[:, 15:18] = w + alpha * dt
        # exact integration of a constant angular acceleration over dt would need a series; the
        # midpoint rate is second-order accurate, like the position update
        turn = so3_exp((w + (0.5 * dt) * alpha) * dt)
        out[:, :9] = (turn @ X[:, :9].reshape(-1, 3, 3)).reshape(-1, 9)
        return out

    def process_noise(self, dt: float) -> np.ndarray:
        return np.diag(
            np.repeat([self.noise.linear_accel / dt, self.noise.angular_accel / dt], 3)
        )

    def sigma_propagator(self) -> SigmaPropagator:
        """Retract + propagate + lift of whole sigma-point sets in one go (the hot path)."""
        return SigmaPropagator(self.noise)

    @staticmethod
    def pose(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return X[:, :9].reshape(-1, 3, 3), X[:, 9:12]

    @staticmethod
    def velocities(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[12:15], x[15:18]

    def initial_covariance(
        self, pose_cov: np.ndarray, v_sigma: float = 0.05, w_sigma: float = 0.3
    ) -> np.ndarray:
        """Covariance over the tangent from a (6,6) pose covariance (dphi, dp) in W0."""
        P = np.zeros((12, 12))
        P[:6, :6] = pose_cov
        P[6:9, 6:9] = np.eye(3) * v_sigma**2
        P[9:, 9:] = np.eye(3) * w_sigma**2
        return P


class PaperModel:
    """State x = [T (3), v (3), Z-Y-Z Euler angles (3)]; Euclidean tangent (9).

    Noise (6) = (linear acceleration n_v, angular velocity n_w). The Euler angles are the
    paper's parametrisation of R relative to W0.
    """

    dim = 9
    rotation = slice(6, 9)  # Euler angles: an approximation of the orientation error (rad)
    position = slice(0, 3)
    noise_dim = 6
    name = "paper"

    def __init__(self, noise: ProcessNoise = ProcessNoise()):
        self.noise = noise

    @staticmethod
    def initial_state(R: np.ndarray, p: np.ndarray, v=None, w=None) -> np.ndarray:
        euler = euler_from_matrix(np.asarray(R), PAPER_EULER_SEQUENCE)
        return np.concatenate((p, np.zeros(3) if v is None else v, euler))

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        return x + xi

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        d = X - x
        d[:, 6:] = continuous_euler(X[:, 6:], x[6:]) - x[6:]
        return d

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        n_v, n_w = noise[:, :3], noise[:, 3:]
        out = np.empty_like(X)
        out[:, :3] = X[:, :3] + X[:, 3:6] * dt
        out[:, 3:6] = X[:, 3:6] + n_v * dt
        R = matrix_from_euler(X[:, 6:], PAPER_EULER_SEQUENCE) @ so3_exp(n_w * dt)
        out[:, 6:] = continuous_euler(euler_from_matrix(R, PAPER_EULER_SEQUENCE), X[:, 6:])
        return out

    def process_noise(self, dt: float) -> np.ndarray:
        return np.diag(np.repeat([self.noise.linear_accel / dt, self.noise.angular_rate / dt], 3))

    @staticmethod
    def pose(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return matrix_from_euler(X[:, 6:], PAPER_EULER_SEQUENCE), X[:, :3]

    @staticmethod
    def velocities(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[3:6], np.full(3, np.nan)  # the paper's state has no angular velocity

    def initial_covariance(self, pose_cov: np.ndarray, v_sigma: float = 0.05, **_) -> np.ndarray:
        """Covariance from a (6,6) pose covariance (dphi, dp); at the neutral pose the Z-Y-Z
        angles cannot represent a small rotation error, so the rotation block is isotropic."""
        P = np.zeros((9, 9))
        P[:3, :3] = pose_cov[3:, 3:]
        P[3:6, 3:6] = np.eye(3) * v_sigma**2
        P[6:, 6:] = np.eye(3) * np.trace(pose_cov[:3, :3]) / 3
        return P


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def continuous_euler(euler: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Of the two Z-Y-Z triples of each rotation, (a, b, c) and (a + pi, -b, c + pi), the one
    closest to ``near``, unwrapped to it: keeps the Euler state continuous in time.

    Without this the state jumps by pi whenever the middle angle crosses 0 (every flexion
    through neutral), which no filter survives; with it the paper's model is as good as an
    Euler-angle state can be, and what remains is the singularity itself (at b = 0 only a + c
    is observable).
    """
    other = euler + np.array([np.pi, 0.0, np.pi])
    other[..., 1] = -euler[..., 1]
    d1, d2 = _wrap(euler - near), _wrap(other - near)
    pick = (d2 * d2).sum(-1) < (d1 * d1).sum(-1)
    return near + np.where(pick[..., None], d2, d1)


MODELS = {"default": ConstantRateModel, "paper": PaperModel}


# ------------------------------------------------------------------------------------------------
# The constant-rate model on whole sigma-point sets, for the tracker's hot path.
#
# A frame's 37 sigma points are tiny arrays, so the cost is the number of NumPy calls, not the
# arithmetic. Sigma points are therefore columns (each call runs over all of them in its inner
# loop), rotations are unit quaternions (exp, composition and log in a handful of calls, and a
# rotation matrix is a fixed linear function of q q^T), and everything linear in the sigma offsets
# (retraction and propagation of p, v, w, the rotation vectors to exponentiate, the lifts of p, v,
# w) is one matrix product. Single rotations (means, corrections) are plain Python floats:
# below about 50 numbers a Python expression is cheaper than a NumPy call.

Quat = tuple[float, float, float, float]  # (w, x, y, z), Hamilton convention, R(p q) = R(p) R(q)


def quat_exp(x: float, y: float, z: float) -> Quat:
    """Unit quaternion of the rotation vector (x, y, z); exact at zero (sin h / h with h > 0)."""
    h = 0.5 * math.sqrt(x * x + y * y + z * z + 1e-300)
    s = 0.5 * math.sin(h) / h
    return (math.cos(h), s * x, s * y, s * z)


def quat_mul(p: Quat, q: Quat) -> Quat:
    a0, a1, a2, a3 = p
    b0, b1, b2, b3 = q
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


def quat_normalised(q: Quat) -> Quat:
    w, x, y, z = q
    s = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return (w * s, x * s, y * s, z * s)


def quat_of_matrix(R: list[float]) -> Quat:
    """Unit quaternion of a row-major rotation matrix (9 floats), by Shepperd's method: the
    largest of 4w^2, 4x^2, 4y^2, 4z^2 is the one taken from the diagonal, so the division is
    never by a small number."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(1.0 + tr)  # 4w
        return (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    if r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r00 - tr)  # 4x
        return ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    if r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r11 - tr)  # 4y
        return ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    s = 2.0 * math.sqrt(1.0 + 2.0 * r22 - tr)  # 4z
    return ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)


def quat_to_matrix(q: Quat) -> list[float]:
    """Rotation matrix of a unit quaternion, row-major (9 floats)."""
    w, x, y, z = q
    return [
        w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z,
    ]  # fmt: skip


def mat3_mul(A: list[float], B: list[float]) -> list[float]:
    """Product of two row-major 3x3 matrices given as 9 floats."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return [
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    ]  # fmt: skip


def mat3_vec(A: list[float], v: list[float]) -> list[float]:
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    x, y, z = v
    return [a0 * x + a1 * y + a2 * z, a3 * x + a4 * y + a5 * z, a6 * x + a7 * y + a8 * z]


def _quat_tables() -> tuple[np.ndarray, np.ndarray]:
    """PRODUCT (4, 16): p q = PRODUCT @ vec(p q^T); TO_MATRIX (9, 16): vec(R(q)) = TO_MATRIX @
    vec(q q^T), both with vec(a b^T)[4 i + j] = a_i b_j. Built from the scalar formulas above by
    feeding them basis vectors, so the two forms cannot disagree."""
    product = np.zeros((4, 16))
    to_matrix = np.zeros((9, 16))
    e = np.eye(4)
    for i in range(4):
        for j in range(4):
            product[:, 4 * i + j] = quat_mul(tuple(e[i]), tuple(e[j]))
            # quat_to_matrix is a quadratic form; its bilinear form on (e_i, e_j), symmetrised
            both = np.array(quat_to_matrix(tuple(e[i] + e[j])))
            to_matrix[:, 4 * i + j] = 0.5 * (
                both - np.array(quat_to_matrix(tuple(e[i]))) - np.array(quat_to_matrix(tuple(e[j])))
            )
        to_matrix[:, 5 * i] = quat_to_matrix(tuple(e[i]))
    return product, to_matrix


QUAT_PRODUCT, QUAT_TO_MATRIX = _quat_tables()


def _increment_tables() -> np.ndarray:
    """(128, 8) map from (q_state, q_centre) to the two (4, 16) maps that take vec(t r^T) of a
    sigma point's turn t and retraction r to its orientation t r q_state and to its rotation
    relative to the centre, t r conj(q_centre), the latter with the vector part doubled (see
    SigmaPropagator._lift_rotations)."""
    gamma = QUAT_PRODUCT.T.reshape(4, 4, 4)  # (a b)_c = gamma[i, j, c] a_i b_j
    right = np.einsum("abc,ak->ckb", gamma, QUAT_PRODUCT)  # (c, k, b): times q_state[b]
    conj = np.array([1.0, -1.0, -1.0, -1.0])
    relative = np.einsum("abc,b,ak->ckb", gamma, conj, QUAT_PRODUCT)
    relative[1:] *= 2.0
    table = np.zeros((128, 8))
    table[:64, :4] = right.reshape(64, 4)
    table[64:, 4:] = relative.reshape(64, 4)
    return table


_INCREMENTS = _increment_tables()
# |v|^2 of a quaternion with doubled vector part (w, 2v), plus 1e-300 w^2: never 0 for a unit
# quaternion, so the log needs no branch at the identity.
_HALF_NORM = np.array([1e-300, 0.25, 0.25, 0.25])
_ONES4 = np.ones(4)
_TINY = 1e-150  # a constant fourth "component" of the half rotation vectors: |phi/2|^2 + 1e-300
_CONSTANT_ROWS = np.zeros(27)  # of the linear part: the two _TINY rows and the ones row
_CONSTANT_ROWS[15:18] = [_TINY, _TINY, 1.0]


class SigmaPropagator:
    """Retract, propagate and lift the constant-rate model's augmented sigma points as columns.

    Input: offsets O (19, S): rows 0-11 the tangent offsets (dphi, dp, dv, dw), rows 12-17 the
    noise offsets (linear, angular acceleration) in units of their standard deviations, row 18
    all ones. Output: ``ROWS`` rows of a buffer, one column per sigma point:

    - [0, 12) ``LIFTS``: the lifts about the propagated centre, log(R_sigma R_centre^T) and the
      differences of p, v, w;
    - [12, 20): the half rotation vectors of retraction and turn, interleaved by axis, and two
      constant rows (see ``_TINY``);
    - [20, 46) ``FEATURES``: 1, p, v, w and vec(q q^T) of the orientation quaternion q: all a
      measurement needs, since R(q) is linear in vec(q q^T).

    Rows [3, 30) are linear in the offsets and come from one matrix product.
    """

    ROWS, LIFTS, FEATURES = 46, slice(0, 12), slice(20, 46)

    def __init__(self, noise: ProcessNoise, n_sigma: int = 37):
        self.n_sigma = S = n_sigma
        self._coefficients = self._map_coefficients(noise)
        self._maps: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._quats = np.empty((4, 2 * S))  # retraction (first S) and turn quaternions
        self._pairs = np.empty((4, 4, S))  # vec(t r^T) of turn t and retraction r
        self._products = np.empty((8, 16))  # vec(t r^T) -> orientation, relative rotation
        self._q = np.empty((8, S))

    @staticmethod
    def _map_coefficients(noise: ProcessNoise) -> np.ndarray:
        """The linear part (rows 3-29) as a (27, 19) matrix on (offsets, 1) whose entries are
        polynomials in (1, dt, sqrt(dt), dt^1.5): (4, 27 * 19 + 27 * 9).

        Column 18 (times the ones row) carries the constants and the state's contribution, the
        latter filled per step from the (27, 9) map on (p, v, w) that follows. The noise offsets n
        are scaled by their standard deviations sqrt(q / dt) here, so a linear acceleration
        a = sqrt(q_a / dt) n moves p by dt^2 a / 2 = sqrt(q_a) dt^1.5 n / 2.
        """
        sa, sw = math.sqrt(noise.linear_accel), math.sqrt(noise.angular_accel)
        c = np.zeros((4, 27, 19))  # [power of dt, output row, offset row]
        on_state = np.zeros((4, 27, 9))  # [power of dt, output row, (p, v, w)]
        ONE, DT, SQRT, DT15 = range(4)
        for first in (0, 18):  # the lifts of p, v, w and the propagated p, v, w
            for i in range(3):
                p, v, w = first + i, first + 3 + i, first + 6 + i
                c[ONE, p, 3 + i] = 1.0  # p' = p + dp + (v + dv) dt + dt^2 a / 2
                c[DT, p, 6 + i] = 1.0
                c[DT15, p, 12 + i] = 0.5 * sa
                c[ONE, v, 6 + i] = 1.0  # v' = v + dv + a dt
                c[SQRT, v, 12 + i] = sa
                c[ONE, w, 9 + i] = 1.0  # w' = w + dw + alpha dt
                c[SQRT, w, 15 + i] = sw
                if first:  # the lifts are differences: the state cancels
                    on_state[ONE, p, i] = on_state[DT, p, 3 + i] = 1.0
                    on_state[ONE, v, 3 + i] = on_state[ONE, w, 6 + i] = 1.0
        for i in range(3):
            c[ONE, 9 + 2 * i, i] = 0.5  # retraction: dphi / 2
            c[DT, 10 + 2 * i, 9 + i] = 0.5  # turn: (w + dw + alpha dt / 2) dt / 2
            c[DT15, 10 + 2 * i, 15 + i] = 0.25 * sw
            on_state[DT, 10 + 2 * i, 6 + i] = 0.5
        return np.concatenate((c.reshape(4, -1), on_state.reshape(4, -1)), axis=1)

    def _linear_map(self, x: np.ndarray, dt: float) -> np.ndarray:
        """The linear part's (27, 19) matrix for state x and step dt. The dt part is cached:
        frame intervals take a handful of distinct values."""
        maps = self._maps.get(dt)
        if maps is None:
            if len(self._maps) > 32:
                self._maps.clear()
            r = math.sqrt(dt)
            both = np.array([1.0, dt, r, dt * r]).dot(self._coefficients)
            M = np.asfortranarray(both[: 27 * 19].reshape(27, 19))  # column 18 contiguous
            maps = self._maps[dt] = (M, both[27 * 19 :].reshape(27, 9))
        M, on_state = maps
        on_state.dot(x[9:], out=M[:, 18])
        M[:, 18] += _CONSTANT_ROWS
        return M

    def propagate(
        self, x: np.ndarray, offsets: np.ndarray, dt: float, q_state: Quat, out: np.ndarray
    ) -> Quat:
        """Fill the ``ROWS`` rows of ``out`` (see the class) for the sigma points ``offsets``
        about x, whose rotation is R(q_state). Returns the centre's rotation increment: the
        centre's orientation is that times q_state, its (p, v, w) are out[21:30, 0]."""
        self._linear_map(x, dt).dot(offsets, out=out[3:30])
        w0, w1, w2 = x[15:18].tolist()
        q_centre = quat_exp(w0 * dt, w1 * dt, w2 * dt)  # the centre turns by w dt
        self._rotations(out[12:20].reshape(4, -1), q_state, q_centre)
        q = self._q[:4]
        np.multiply(q[:, None, :], q[None, :, :], out=out[30:46].reshape(4, 4, -1))
        self._lift_rotations(out[:3])
        return q_centre

    def _rotations(self, half_rotvecs: np.ndarray, q_state: Quat, q_centre: Quat) -> None:
        """Orientations exp(turn) exp(retraction) q_state and the rotations relative to the
        centre, from the half rotation vectors (4, 2S) (rows x, y, z and the constant _TINY)."""
        S = self.n_sigma
        h = np.sqrt(_ONES4.dot(half_rotvecs * half_rotvecs))
        quats = self._quats
        np.cos(h, out=quats[0])
        np.multiply(half_rotvecs[:3], np.sin(h) / h, out=quats[1:])
        np.multiply(quats[:, None, S:], quats[None, :, :S], out=self._pairs)
        _INCREMENTS.dot(np.array(q_state + q_centre), out=self._products.reshape(128))
        self._products.dot(self._pairs.reshape(16, S), out=self._q)

    def _lift_rotations(self, out: np.ndarray) -> None:
        """log of the relative quaternions (w, 2v): 2 atan(|v| / w) v / |v|, which is right for
        either sign of w (a w < 0 quaternion is the same rotation as -q, whose angle is < pi)."""
        rel = self._q[4:]
        n = np.sqrt(_HALF_NORM.dot(rel * rel))
        r = np.arctan(n / rel[0])
        r /= n
        np.multiply(rel[1:], r, out=out)
