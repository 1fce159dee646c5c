"""Spatial registration and fine time alignment of our run to a reference, estimated jointly.

Unknowns: the rigid transform camera -> reference lab (R_LC, t_LC); the clock model
``reference time = offset + ratio * our time``; with a marker cluster, also the fixed pose of
our hand frame in the cluster's frame (X_R, x_t). Model per frame i (our time t_i):

    R_LC R_ch(t_i) = R_ref(tau_i) X_R             (orientation)
    R_LC t_ch(t_i) + t_LC = R_ref(tau_i) x_t + p_ref(tau_i)    (wrist position)
    tau_i = offset + ratio t_i

solved by scipy.optimize.least_squares from a closed-form start (rotation averaging, the
AX = XB rotation-axis fit for the cluster offset, linear least squares for the translations),
in two passes: the second drops gross outliers (beyond 5x the median error) and weights each
position (camera axes) and orientation (hand axes) residual component by its own scatter.
Uncertainties: each the larger of two. The Gauss-Newton covariance (J^T J)^-1 s^2 at the
optimum, inflated for the residuals' serial correlation (tracking errors are correlated from
frame to frame, so there are fewer independent frames than rows). And a delete-a-block
jackknife: the fit repeated with each of ``JACKKNIFE_BLOCKS`` stretches of the movement left
out. Our tracking errors depend on the pose (a tilt that grows with flexion), which no
residual-based covariance sees: they pull the fit one way in one part of the movement and
another way in the next. On a 2.8 s wheelchair-racing take registered through its three-marker
glove cluster, the recovered rotation was 0.117 deg off the planted one where the Gauss-Newton
sigma said 0.038 (the jackknife: 0.056).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from wristtrack.analysis.compare.reference import Interpolator
from wristtrack.errors import InputError
from wristtrack.geometry import project_to_so3, skew, so3_exp, so3_log

OUTLIER_FACTOR = 5.0
JACKKNIFE_BLOCKS = 8  # stretches of the movement left out in turn (module doc)
_MIN_BLOCK_FRAMES = 5  # fewer frames per stretch: no jackknife, the Gauss-Newton sigmas alone
_MARGIN_S = 0.05  # frames kept need the reference this far around them: the offset may move


@dataclass(frozen=True)
class Registration:
    R_lc: np.ndarray  # (3,3) reference lab <- camera
    t_lc: np.ndarray  # (3,) m
    offset_s: float  # reference time = offset + ratio * our time
    ratio: float
    X_R: np.ndarray  # (3,3) cluster <- hand (identity without a cluster)
    x_t: np.ndarray  # (3,) m, our wrist in the cluster's frame (0 without a cluster)
    sigma: dict[str, float]  # 1-sigma: offset_s, ratio, rotation_deg, translation_mm, ...
    used: np.ndarray  # (M,) bool, frames of the input the final fit used
    iterations: int
    hand_centre_cam: np.ndarray  # (3,) m, mean wrist position (camera) over the used frames

    def to_lab(self, R_ch: np.ndarray, t_ch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Our hand pose (cam) in the reference's lab frame."""
        return self.R_lc @ R_ch, t_ch @ self.R_lc.T + self.t_lc

    def ref_times(self, t: np.ndarray) -> np.ndarray:
        return self.offset_s + self.ratio * np.asarray(t, dtype=float)


def _chordal_mean(R: np.ndarray) -> np.ndarray:
    return project_to_so3(R.mean(axis=0))


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation Q minimising sum |Q b_i - a_i|^2 (no centring)."""
    U, _, Vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ np.diag([1.0, 1.0, d]) @ Vt


def initial_guess(
    R_ch: np.ndarray, t_ch: np.ndarray, R_ref: np.ndarray, p_ref: np.ndarray, cluster: bool,
    has_rotation: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form (R_LC, t_LC, X_R, x_t) from time-aligned pose pairs."""
    eye = np.eye(3)
    if not has_rotation:  # positions only: Kabsch with centring
        mc, mr = t_ch.mean(axis=0), p_ref.mean(axis=0)
        R_lc = _kabsch(p_ref - mr, t_ch - mc)
        return R_lc, mr - R_lc @ mc, eye, np.zeros(3)
    X_R = eye
    if cluster:
        # X^T A_i X = B_i for the relative motions A_i (cluster) and B_i (hand) from frame 0,
        # so their rotation vectors satisfy a_i = X b_i.
        a = so3_log(np.swapaxes(R_ref[0], -1, -2)[None] @ R_ref)
        b = so3_log(np.swapaxes(R_ch[0], -1, -2)[None] @ R_ch)
        if np.linalg.norm(a, axis=1).max() < np.radians(5.0):
            raise InputError(
                "the cluster barely rotates (< 5 deg): its offset from our hand frame cannot be "
                "found; record a movement that turns the hand"
            )
        X_R = _kabsch(a, b)
    R_lc = _chordal_mean(R_ref @ X_R @ np.swapaxes(R_ch, -1, -2))
    rhs = p_ref - t_ch @ R_lc.T
    if not cluster:
        return R_lc, rhs.mean(axis=0), X_R, np.zeros(3)
    n = len(rhs)
    A = np.zeros((n, 3, 6))
    A[:, :, :3] = eye
    A[:, :, 3:] = -R_ref
    sol, *_ = np.linalg.lstsq(A.reshape(-1, 6), rhs.reshape(-1), rcond=None)
    return R_lc, sol[:3], X_R, sol[3:]


class _Problem:
    """Parameters: rotation increment (3), translation (3), clock (``n_clock``: 0 = offset
    fixed, 1 = offset, 2 = offset and ratio), cluster rotation increment and offset (3 + 3)."""

    def __init__(self, t, R_ch, t_ch, interp: Interpolator, cluster: bool, n_clock: int,
                 start, offset0: float):
        self.t, self.R_ch, self.t_ch, self.interp = t, R_ch, t_ch, interp
        self.cluster, self.n_clock, self.offset0 = cluster, n_clock, offset0
        self.tm = float(np.mean(t))
        self.R0, self.X0 = start[0], start[2]
        self.sp, self.sr = np.ones(3), np.ones(3)  # residual scales per axis: mm, deg
        self.rows = np.ones(len(t), bool)

    def unpack(self, x):
        R_lc = so3_exp(x[:3]) @ self.R0
        t_lc = x[3:6]
        a = x[6] if self.n_clock else self.offset0
        k = x[7] if self.n_clock == 2 else 0.0
        X_R, x_t = self.X0, np.zeros(3)
        if self.cluster:
            i = 6 + self.n_clock
            X_R = self.X0 @ so3_exp(x[i : i + 3])
            x_t = x[i + 3 : i + 6]
        ratio = 1.0 + k
        offset = self.tm + a - ratio * self.tm  # tau = tm + a + ratio (t - tm)
        if self.n_clock == 0:
            offset = self.offset0  # as given, to the last bit
        return R_lc, t_lc, offset, ratio, X_R, x_t

    def errors(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame position error (M,3) mm in camera axes and orientation error (M,3) deg in
        hand axes, of all frames. Camera axes because a camera's depth error is several times
        its lateral error: each axis gets its own weight."""
        R_lc, t_lc, offset, ratio, X_R, x_t = self.unpack(x)
        R_ref, p_ref = self.interp(offset + ratio * self.t)
        pos = ((self.t_ch @ R_lc.T + t_lc) - (p_ref + R_ref @ x_t)) @ R_lc
        if not self.interp.has_rotation:
            return pos * 1e3, np.zeros_like(pos)
        E = np.swapaxes(R_ref @ X_R, -1, -2) @ (R_lc @ self.R_ch)
        return pos * 1e3, np.degrees(so3_log(E))

    def residuals(self, x) -> np.ndarray:
        pos, rot = self.errors(x)
        parts = [pos[self.rows] / self.sp]
        if self.interp.has_rotation:
            parts.append(rot[self.rows] / self.sr)
        return np.concatenate(parts, axis=1).reshape(-1)


def _correlation_inflation(res: np.ndarray) -> float:
    """sqrt((1 + rho) / (1 - rho)) for the mean lag-1 autocorrelation rho of the residual
    components (an AR(1) effective-sample-size correction), at least 1."""
    r = res - res.mean(axis=0)
    num = (r[1:] * r[:-1]).sum(axis=0)
    den = (r * r).sum(axis=0)
    rho = float(np.clip(np.mean(num / np.where(den > 0, den, 1.0)), 0.0, 0.95))
    return float(np.sqrt((1.0 + rho) / (1.0 - rho)))


def register(
    t: np.ndarray,
    R_ch: np.ndarray,
    t_ch: np.ndarray,
    interp: Interpolator,
    coarse_offset_s: float,
    cluster: bool,
    fit_ratio: bool = True,
    fit_offset: bool = True,
) -> Registration:
    """Joint registration and clock fit of our frames (times t (M,), poses in the camera frame)
    to the reference, starting from the coarse offset; see the module docstring. Without
    ``fit_offset`` the offset is taken as given (synchronised systems) and the ratio as 1."""
    margin = interp.usable(t + coarse_offset_s - _MARGIN_S) & interp.usable(
        t + coarse_offset_s + _MARGIN_S
    )
    use = interp.usable(t + coarse_offset_s) & margin
    if use.sum() < 10:
        raise InputError(
            f"only {int(use.sum())} of our frames fall inside the reference's recording after "
            "alignment; are they recordings of the same movement?"
        )
    t, R_ch, t_ch = t[use], R_ch[use], t_ch[use]
    R_ref, p_ref = interp(t + coarse_offset_s)
    start = initial_guess(R_ch, t_ch, R_ref, p_ref, cluster, interp.has_rotation)
    n_clock = (1 + int(fit_ratio)) if fit_offset else 0
    prob = _Problem(t, R_ch, t_ch, interp, cluster, n_clock, start, coarse_offset_s)
    x0 = np.zeros(6 + n_clock + (6 if cluster else 0))
    x0[3:6] = start[1]
    if n_clock:
        x0[6] = coarse_offset_s
    if cluster:
        x0[-3:] = start[3]
    iterations = 0
    for _ in range(2):
        sol = least_squares(prob.residuals, x0, method="trf", x_scale="jac")
        iterations += int(sol.nfev)
        x0 = sol.x
        pos, rot = prob.errors(x0)
        ep, er = np.linalg.norm(pos, axis=1), np.linalg.norm(rot, axis=1)
        rows = (ep <= OUTLIER_FACTOR * max(np.median(ep), 0.1)) & (
            er <= OUTLIER_FACTOR * max(np.median(er), 0.05)
        )
        if rows.sum() < 10:
            raise InputError("the registration fits fewer than 10 frames; check the mapping")
        prob.rows = rows
        prob.sp = np.maximum(np.sqrt(np.mean(pos[rows] ** 2, axis=0)), 1e-3)
        prob.sr = np.maximum(np.sqrt(np.mean(rot[rows] ** 2, axis=0)), 1e-3)
    sol = least_squares(prob.residuals, x0, method="trf", x_scale="jac")
    iterations += int(sol.nfev)
    R_lc, t_lc, offset, ratio, X_R, x_t = prob.unpack(sol.x)
    sigma = _uncertainty(prob, sol, cluster)
    used = np.zeros(len(use), bool)
    used[np.flatnonzero(use)[prob.rows]] = True
    return Registration(R_lc, t_lc, offset, ratio, X_R, x_t, sigma, used, iterations,
                        t_ch[prob.rows].mean(axis=0))


def _jackknife_covariance(prob: _Problem, x: np.ndarray) -> np.ndarray | None:
    """The delete-a-block jackknife covariance of the parameters about the fit ``x`` (module
    doc): refitted from ``x`` with each of JACKKNIFE_BLOCKS contiguous stretches of the frames
    it used left out. None where the stretches would be too short to stand for a movement."""
    used = np.flatnonzero(prob.rows)
    if used.size < JACKKNIFE_BLOCKS * _MIN_BLOCK_FRAMES:
        return None
    rows, fits = prob.rows, []
    try:
        for part in np.array_split(used, JACKKNIFE_BLOCKS):
            prob.rows = rows.copy()
            prob.rows[part] = False
            fits.append(least_squares(prob.residuals, x, method="trf", x_scale="jac").x)
    finally:
        prob.rows = rows
    d = np.array(fits) - np.mean(fits, axis=0)
    return (JACKKNIFE_BLOCKS - 1) / JACKKNIFE_BLOCKS * d.T @ d


def _uncertainty(prob: _Problem, sol, cluster: bool) -> dict[str, float]:
    J = sol.jac
    m, n = J.shape
    res = sol.fun
    s2 = float(res @ res) / max(m - n, 1)
    try:
        cov = np.linalg.pinv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov = np.full((n, n), np.nan)
    per_frame = res.reshape(int(prob.rows.sum()), -1)
    inflate = _correlation_inflation(per_frame)
    out = _sigmas(prob, sol.x, cov * inflate**2, cluster)
    jackknife = _jackknife_covariance(prob, sol.x)
    if jackknife is not None:
        wide = _sigmas(prob, sol.x, jackknife, cluster)
        out = {k: max(v, wide[k]) for k, v in out.items()}
    return {
        **out,
        "serial_correlation_inflation": inflate,
        "jackknife_blocks": JACKKNIFE_BLOCKS if jackknife is not None else 0,
        "residual_position_mm": float(np.linalg.norm(prob.sp)),
        "residual_orientation_deg": float(np.linalg.norm(prob.sr)),
    }


def _sigmas(prob: _Problem, x: np.ndarray, cov: np.ndarray, cluster: bool) -> dict[str, float]:
    """The 1-sigma figures comparison.json reports from a covariance ``cov`` of the parameters
    ``x``."""
    n = len(x)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # offset = tm + a - ratio tm = a - k tm: its variance includes the a-k covariance.
    sd_offset = sd_ratio = 0.0  # a given offset (and ratio) is exact as far as we know
    if prob.n_clock == 2:
        g = np.zeros(n)
        g[6], g[7] = 1.0, -prob.tm
        sd_offset = float(np.sqrt(max(g @ cov @ g, 0.0)))
        sd_ratio = float(sd[7])
    elif prob.n_clock == 1:
        sd_offset = float(sd[6])
    # A rotation error moves the lab image of a far point a lot (0.1 deg = 1.1 mm at 0.65 m):
    # what matters is the error where the hand was, at the centre of the tracked positions.
    R_lc = so3_exp(x[:3]) @ prob.R0
    c = R_lc @ prob.t_ch[prob.rows].mean(axis=0)
    G = np.zeros((3, n))
    G[:, :3] = -skew(c)
    G[:, 3:6] = np.eye(3)
    out = {
        "offset_s": sd_offset,
        "translation_at_hand_mm": float(np.sqrt(max(np.trace(G @ cov @ G.T), 0.0)) * 1e3),
        "ratio": sd_ratio,
        "rotation_deg": float(np.degrees(np.linalg.norm(sd[:3]))),
        "translation_mm": float(np.linalg.norm(sd[3:6]) * 1e3),
    }
    if cluster:
        i = 6 + prob.n_clock
        out["cluster_rotation_deg"] = float(np.degrees(np.linalg.norm(sd[i : i + 3])))
        out["cluster_translation_mm"] = float(np.linalg.norm(sd[i + 3 : i + 6]) * 1e3)
    return out
