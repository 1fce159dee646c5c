"""Motion models of the wrist relative to the fixed frame W0, in the form the UKF needs.

``ConstantRateModel`` (the default): orientation on SO(3) as an error state, position, linear
velocity and angular velocity (in W0) in the state; constant linear and angular velocity driven
by random-walk accelerations. The angular velocity is estimated, not differentiated.

``PaperModel``: the paper's model, state (T, v, Z-Y-Z Euler angles); translation constant
velocity with random-walk acceleration, orientation a random walk driven by angular-velocity
noise, R+ = R exp([n_w]x dt) (Cordella et al., section III-B). The Euler state is singular at
the neutral pose (middle angle 0), which is the paper's weakness the default model removes.

Both share the interface of :class:`wristtrack.filter.ukf.ManifoldModel` plus ``pose(X)`` (rotation
and position relative to W0 of states X) and ``process_noise(dt)``. The compiled tracker step
(tracking/compiled.py) carries the constant-rate model written out for one frame's sigma points;
this is its reference.
"""

from __future__ import annotations

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

    # retract and lift as written hold for any Euclidean coordinates after w (a subclass's
    # extra states: tracking/slide_model.py): the widths are the state's and the tangent's

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        out = np.empty((xi.shape[0], x.size))
        R = x[:9].reshape(3, 3)
        out[:, :9] = (so3_exp(xi[:, :3]) @ R).reshape(-1, 9)
        out[:, 9:] = x[9:] + xi[:, 3:]
        return out

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        out = np.empty((X.shape[0], self.dim))
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

    @staticmethod
    def pose(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return X[:, :9].reshape(-1, 3, 3), X[:, 9:12]

    @staticmethod
    def velocities(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[12:15], x[15:18]

    @staticmethod
    def rates(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The linear and angular velocities (S, 3) each, in W0, of states X (S, D)."""
        return X[:, 12:15], X[:, 15:18]

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
    paper's parametrisation of R relative to W0 (``sequence``, intrinsic).
    """

    dim = 9
    rotation = slice(6, 9)  # Euler angles: an approximation of the orientation error (rad)
    position = slice(0, 3)
    noise_dim = 6
    name = "paper"
    sequence = PAPER_EULER_SEQUENCE
    proper = True  # a proper Euler sequence (first axis = last): singular at middle angle 0

    def __init__(self, noise: ProcessNoise = ProcessNoise()):
        self.noise = noise

    @classmethod
    def initial_state(cls, R: np.ndarray, p: np.ndarray, v=None, w=None) -> np.ndarray:
        euler = euler_from_matrix(np.asarray(R), cls.sequence)
        return np.concatenate((p, np.zeros(3) if v is None else v, euler))

    def retract(self, x: np.ndarray, xi: np.ndarray) -> np.ndarray:
        return x + xi

    def lift(self, x: np.ndarray, X: np.ndarray) -> np.ndarray:
        d = X - x
        d[:, 6:] = continuous_euler(X[:, 6:], x[6:], self.proper) - x[6:]
        return d

    def propagate(self, X: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        n_v, n_w = noise[:, :3], noise[:, 3:]
        out = np.empty_like(X)
        out[:, :3] = X[:, :3] + X[:, 3:6] * dt
        out[:, 3:6] = X[:, 3:6] + n_v * dt
        R = matrix_from_euler(X[:, 6:], self.sequence) @ so3_exp(n_w * dt)
        out[:, 6:] = continuous_euler(euler_from_matrix(R, self.sequence), X[:, 6:], self.proper)
        return out

    def process_noise(self, dt: float) -> np.ndarray:
        return np.diag(np.repeat([self.noise.linear_accel / dt, self.noise.angular_rate / dt], 3))

    @classmethod
    def pose(cls, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return matrix_from_euler(X[:, 6:], cls.sequence), X[:, :3]

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


class PaperRPYModel(PaperModel):
    """The paper's model with roll-pitch-yaw angles, the convention its figure legend implies:
    intrinsic Z-Y-X (yaw about Z = deviation, pitch about Y = flexion, roll about X =
    pronation), singular at pitch +-90 deg, far from the neutral start pose (issue 12 item 4:
    the paper at its best, beside Z-Y-Z)."""

    name = "paper_rpy"
    sequence = "ZYX"
    proper = False


def continuous_euler(euler: np.ndarray, near: np.ndarray, proper: bool = True) -> np.ndarray:
    """Of the two triples of each rotation, (a, b, c) and (a + pi, -b, c + pi) for a proper
    sequence such as Z-Y-Z ((a + pi, pi - b, c + pi) for a Tait-Bryan one such as Z-Y-X), the
    one closest to ``near``, unwrapped to it: keeps the Euler state continuous in time.

    Without this the state jumps by pi whenever the middle angle crosses 0 (every flexion
    through neutral), which no filter survives; with it the paper's model is as good as an
    Euler-angle state can be, and what remains is the singularity itself (at b = 0 only a + c
    is observable).
    """
    other = euler + np.array([np.pi, 0.0, np.pi])
    other[..., 1] = -euler[..., 1] if proper else np.pi - euler[..., 1]
    d1, d2 = _wrap(euler - near), _wrap(other - near)
    pick = (d2 * d2).sum(-1) < (d1 * d1).sum(-1)
    return near + np.where(pick[..., None], d2, d1)


MODELS = {"default": ConstantRateModel, "paper": PaperModel, "paper_rpy": PaperRPYModel}


def reads_camera_timing(model: str) -> bool:
    """Whether model ``model`` reads a marker where the hand moved it between the frame's time
    and its capture (a rolling shutter's row, a depth frame's delay): a state with rates. The
    paper's models have none."""
    return hasattr(MODELS[model], "rates")


def unmodelled_timing(model: str, readout: float | None) -> list[str]:
    """The warning for a rolling shutter's readout (s, camera.json readout_s) that ``model``
    has to ignore."""
    if not readout or reads_camera_timing(model):
        return []
    return [f"model {model} has no rates in its state, so it took the rolling shutter's "
            f"readout ({1e3 * readout:.1f} ms, camera.json readout_s) as none: each marker read "
            "at the frame's time, where the default model (--model default) reads it where the "
            "hand was when its row was read"]
