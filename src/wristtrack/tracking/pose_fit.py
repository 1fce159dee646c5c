"""The initial camera-to-hand pose from labelled markers (paper section III-D, eq. 15-20).

- ``refine_pose``: damped Gauss-Newton on SO(3) x R^3 (left perturbation) on marker projections
  and depths, analytic Jacobian, per-marker depth weights from the sensor noise model,
  covariance of the estimate (the paper's least squares, beyond it in the weights and damping);
- ``initial_guess``: closed-form start (3-D alignment with depth, IPPE without);
- ``planar_twin``: without depth, the best pose and its mirror image about the line of sight
  (the flip ambiguity of issue 11), each refined, for the caller to weigh.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wristtrack import depth_noise
from wristtrack.camera import Camera
from wristtrack.errors import InitialisationError
from wristtrack.geometry import skew, so3_exp
from wristtrack.hand import HandLayout


@dataclass(frozen=True)
class PoseFit:
    """Result of ``refine_pose``.

    ``cov`` is the (6, 6) covariance of (dphi, dt) with R = so3_exp(dphi) R_ch, t = t_ch + dt;
    ``rms_px`` the RMS 2-D reprojection error over visible markers; ``cost`` the weighted
    chi-square; ``dof`` the number of residuals minus 6.
    """

    R_ch: np.ndarray
    t_ch: np.ndarray
    cov: np.ndarray
    rms_px: float
    cost: float
    dof: int
    iterations: int


def pinhole_jacobian(camera: Camera, X: np.ndarray) -> np.ndarray:
    """d(u, v)/dX of the undistorted pinhole at camera points X (N,3) -> (N,2,3)."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    J = np.zeros((X.shape[0], 2, 3))
    J[:, 0, 0] = camera.fx / z
    J[:, 0, 2] = -camera.fx * x / z**2
    J[:, 1, 1] = camera.fy / z
    J[:, 1, 2] = -camera.fy * y / z**2
    return J


def point_jacobian(X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """dX/d(dphi, dt) for X = exp(dphi) R p + t + dt at dphi = 0: [-[R p]x, I] -> (N,3,6)."""
    J = np.empty((X.shape[0], 3, 6))
    J[:, :, :3] = -skew(X - t)
    J[:, :, 3:] = np.eye(3)
    return J


def refine_pose(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    R0: np.ndarray,
    t0: np.ndarray,
    pixel_sigma: float = 0.7,
    depth_sigma: float | np.ndarray | None = None,
    visible: np.ndarray | None = None,
    max_iter: int = 20,
    frozen_axis: np.ndarray | None = None,
) -> PoseFit:
    """Weighted least-squares camera-to-hand pose from labelled marker projections and depths.

    Minimises sum ||(uv_j - project(R p_j + t)) / pixel_sigma||^2
    + sum ((z_j - (R p_j + t)_z) / depth_sigma_j)^2 (paper eq. 15) by Levenberg-Marquardt-damped
    Gauss-Newton, updating R <- so3_exp(dphi) R, t <- t + dt. ``uv`` (N,2) and ``depth`` (N,) are
    in layout order; non-finite entries (or ``visible`` False) are skipped. ``depth_sigma``
    defaults to the sensor model (``depth_noise.depth_sigma``) per marker. The projection uses
    ``camera.project`` (with distortion); the Jacobian is that of the undistorted pinhole, which
    only slows convergence slightly for mild distortion.

    ``frozen_axis`` (3,) holds the rotation about that camera-frame axis at its start (steps
    keep dphi orthogonal to it): the planar twin's tilt, see ``planar_fits``.
    """
    P, uv, depth, vis, dvis = _observed(layout, uv, depth, visible)
    n = P.shape[0]
    n_res = 2 * int(vis.sum()) + int(dvis.sum())
    if vis.sum() < 3 or n_res < 7:
        raise InitialisationError(
            f"pose unobservable: only {int(vis.sum())} markers visible ({int(dvis.sum())} with "
            "depth); initialise with all six markers in view"
        )
    Pv, uvv, Pd = P[vis], uv[vis], P[dvis]
    zd = depth[dvis] if depth is not None else np.zeros(0)
    if depth_sigma is None:
        sz = depth_noise.depth_sigma(zd)
    else:
        sz = np.broadcast_to(np.asarray(depth_sigma, dtype=float), (n,))[dvis]

    def residuals(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Xv, Xd = Pv @ R.T + t, Pd @ R.T + t
        if (Xv[:, 2] <= 1e-6).any():
            # Behind the camera the pinhole model is meaningless: treat as an infinite cost.
            return np.full(n_res, np.inf), Xv, Xd
        e_px = uvv - camera.project(Xv)
        r = np.concatenate([e_px.ravel() / pixel_sigma, (zd - Xd[:, 2]) / sz])
        return r, Xv, Xd

    def normal_equations(
        t: np.ndarray, r: np.ndarray, Xv: np.ndarray, Xd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        Jpx = (pinhole_jacobian(camera, Xv) @ point_jacobian(Xv, t)).reshape(-1, 6)
        Jz = point_jacobian(Xd, t)[:, 2, :]
        J = np.concatenate([Jpx / pixel_sigma, Jz / sz[:, None]])
        return J.T @ J, J.T @ r

    free = None  # basis (6, 5) of the steps allowed when an axis is frozen
    if frozen_axis is not None:
        e = np.append(np.asarray(frozen_axis, dtype=float), np.zeros(3))
        free = np.linalg.svd(e[None, :])[2][1:].T
    R = np.asarray(R0, dtype=float)
    t = np.asarray(t0, dtype=float).reshape(3)
    r, Xv, Xd = residuals(R, t)
    cost = float(r @ r)
    if not np.isfinite(cost):
        raise InitialisationError(
            "initial pose puts markers behind the camera; check the labels and the camera file"
        )
    lam = 1e-6  # Marquardt damping: plain Gauss-Newton (the paper's) while steps keep helping
    iterations = 0
    for _ in range(max_iter):
        iterations += 1
        A, g = normal_equations(t, r, Xv, Xd)
        D = np.diag(np.diag(A))
        accepted = False
        while lam < 1e10:
            try:
                if free is None:
                    delta = np.linalg.solve(A + lam * D, g)
                else:
                    delta = free @ np.linalg.solve(free.T @ (A + lam * D) @ free, free.T @ g)
            except np.linalg.LinAlgError:
                lam = max(10.0 * lam, 1e-3)
                continue
            Rn, tn = so3_exp(delta[:3]) @ R, t + delta[3:]
            rn, Xvn, Xdn = residuals(Rn, tn)
            cost_n = float(rn @ rn)
            if cost_n <= cost:
                R, t, r, Xv, Xd, cost = Rn, tn, rn, Xvn, Xdn, cost_n
                lam = max(lam / 10.0, 1e-9)
                accepted = True
                break
            lam = max(10.0 * lam, 1e-3)  # jump straight to real damping after a failed step
        # Stop at a minimum (no step lowers the cost) or when steps fall below ~1e-10 rad / m.
        if not accepted or np.abs(delta).max() < 1e-10:
            break

    A, _ = normal_equations(t, r, Xv, Xd)
    if np.linalg.cond(A) > 1e14:
        raise InitialisationError(
            "pose unobservable from these markers (degenerate geometry); initialise with all "
            "six markers in view and the back of the hand facing the camera"
        )
    cov = np.linalg.inv(A)
    e_px = (r[: 2 * Pv.shape[0]] * pixel_sigma).reshape(-1, 2)
    return PoseFit(
        R_ch=R,
        t_ch=t,
        cov=0.5 * (cov + cov.T),
        rms_px=float(np.sqrt(np.mean(np.sum(e_px**2, axis=1)))),
        cost=cost,
        dof=n_res - 6,
        iterations=iterations,
    )


# ----------------------------------------------------------------------------------------------
# Closed-form starting guesses


def _kabsch(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Proper rotation R and t minimising sum ||R P_i + t - X_i||^2 (no scale)."""
    mp, mx = P.mean(axis=0), X.mean(axis=0)
    U, _, Vt = np.linalg.svd((X - mx).T @ (P - mp))
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ S @ Vt
    return R, mx - R @ mp


def facing_cos(R: np.ndarray, t: np.ndarray, layout: HandLayout) -> float:
    """Cosine between the back-of-hand normal (+Z) and the direction from the hand to the camera."""
    c = R @ layout.points.mean(axis=0) + t
    return float(-R[:, 2] @ c / np.linalg.norm(c))


def _observed(
    layout: HandLayout, uv: np.ndarray, depth: np.ndarray | None, visible: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """Layout points, pixels and depths as arrays in layout order, the markers seen (finite
    pixels, and ``visible`` where given) and those of them with a valid depth."""
    P = np.asarray(layout.points, dtype=float)
    n = P.shape[0]
    uv = np.asarray(uv, dtype=float).reshape(n, 2)
    vis = np.isfinite(uv).all(axis=1)
    if visible is not None:
        vis &= np.asarray(visible, dtype=bool).reshape(n)
    dvis = np.zeros(n, dtype=bool)
    if depth is not None:
        depth = np.asarray(depth, dtype=float).reshape(n)
        dvis = vis & np.isfinite(depth) & (depth > 0)
    return P, uv, depth, vis, dvis


def initial_guesses(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    visible: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Candidate starting poses, best first (see ``initial_guess``)."""
    P, uv, depth, vis, ok = _observed(layout, uv, depth, visible)
    if ok.sum() >= 3:
        return [_kabsch(P[ok], camera.backproject(uv[ok], depth[ok]))]
    if vis.sum() < 4:
        raise InitialisationError(
            f"only {int(vis.sum())} markers visible and too few depth readings to start the pose "
            "fit; initialise with all six markers in view"
        )
    planar = np.abs(P[vis, 2]).max() < 1e-9
    dist = None if camera.dist is None else np.asarray(camera.dist, dtype=float)
    _, rvecs, tvecs, errs = cv2.solvePnPGeneric(
        P[vis], uv[vis], camera.K, dist, flags=cv2.SOLVEPNP_IPPE if planar else cv2.SOLVEPNP_SQPNP
    )
    if not rvecs:
        raise InitialisationError("no pose fits the marker projections; check the labels")
    sols = [(cv2.Rodrigues(rv)[0], tv.reshape(3)) for rv, tv in zip(rvecs, tvecs, strict=True)]
    err = np.asarray(errs, dtype=float).reshape(-1)
    # A planar target has two poses (IPPE returns both); the markers are on the back of the hand,
    # so prefer poses facing the camera, then the lower reprojection error.
    order = sorted(range(len(sols)), key=lambda k: (facing_cos(*sols[k], layout) <= 0.0, err[k]))
    return [sols[k] for k in order]


def initial_guess(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    visible: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form start (R_ch, t_ch) for ``refine_pose`` from labelled markers (layout order).

    With depth at >= 3 markers: back-project and align the layout to the 3-D points (Kabsch, no
    scale). Otherwise: ``cv2.solvePnP`` IPPE on the planar layout (SQPnP if it is not planar),
    keeping the solution with the back of the hand facing the camera; the known layout fixes
    the scale.
    """
    return initial_guesses(uv, depth, camera, layout, visible)[0]


# ----------------------------------------------------------------------------------------------
# The planar flip

# Two fitted poses closer than this in orientation are the same minimum (noise moves a minimum by
# ~0.1-1 deg; the planar twin lies twice the tilt away, ~20 deg at 10 deg of tilt).
DISTINCT_DEG = 1.0


def _ippe_pair(
    P: np.ndarray, uv: np.ndarray, camera: Camera
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Both IPPE poses of the points P (N,3) flattened onto their z = 0 plane: the two
    mirror-image starts of a near-planar target (SQPnP would return one)."""
    dist = None if camera.dist is None else np.asarray(camera.dist, dtype=float)
    flat = np.column_stack([P[:, :2], np.zeros(P.shape[0])])
    _, rvecs, tvecs, _ = cv2.solvePnPGeneric(flat, uv, camera.K, dist, flags=cv2.SOLVEPNP_IPPE)
    return [(cv2.Rodrigues(rv)[0], tv.reshape(3)) for rv, tv in zip(rvecs, tvecs, strict=True)]


def mirrored(
    R: np.ndarray, t: np.ndarray, layout: HandLayout
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The planar twin of the pose (R, t): the back-of-hand normal reflected about the line of
    sight to the markers' centre, the centre kept (to first order the same image, exactly so
    under weak perspective). Returns (R', t', the axis of that tilt, unit or zero)."""
    c = R @ layout.points.mean(axis=0) + t
    u = c / np.linalg.norm(c)
    n = R[:, 2]
    axis = np.cross(n, 2.0 * (n @ u) * u - n)
    s = np.linalg.norm(axis)
    if s < 1e-12:  # fronto-parallel: the twin is the pose itself
        return R, t, np.zeros(3)
    angle = 2.0 * np.arccos(np.clip(-(n @ u), -1.0, 1.0))
    Rm = so3_exp(axis / s * angle) @ R
    return Rm, c - Rm @ layout.points.mean(axis=0), axis / s


def planar_twin(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    fit: PoseFit,
    pixel_sigma: float = 0.7,
    depth_sigma: float | np.ndarray | None = None,
    visible: np.ndarray | None = None,
    min_cos: float = 0.0,
) -> tuple[PoseFit, PoseFit | None]:
    """(the best pose, its planar twin or None) for labelled markers seen without depth
    (fewer than three readings; with more the 3-D alignment has one answer).

    The pose fit is started from ``fit`` and both IPPE poses (a non-planar layout from those of
    its flattened points, refined with its true heights); the lowest chi-square is the best.
    Its twin is the other local minimum when there is one. Near fronto-parallel, noise often
    merges the two minima into one on either side, and the twin is then the best pose mirrored
    (``mirrored``) and refined with that mirrored tilt held: the best fit the other side of the
    line of sight allows. None when the twin is within DISTINCT_DEG of the best (nothing to
    confuse) or faces the camera at a cosine below ``min_cos`` (not physical).
    """
    P, uvo, depth, vis, _ = _observed(layout, uv, depth, visible)

    def refined(R0, t0, axis=None) -> PoseFit | None:
        try:
            f = refine_pose(uv, depth, camera, layout, R0, t0, pixel_sigma, depth_sigma, vis,
                            frozen_axis=axis)  # fmt: skip
        except InitialisationError:
            return None
        return f if facing_cos(f.R_ch, f.t_ch, layout) >= min_cos else None

    starts = _ippe_pair(P[vis], uvo[vis], camera) if vis.sum() >= 4 else []
    fits = [fit, *filter(None, (refined(R0, t0) for R0, t0 in starts))]
    for _ in range(3):
        fits.sort(key=lambda f: f.cost)
        best = fits[0]
        far = [f for f in fits[1:] if angle_between_deg(f.R_ch, best.R_ch) >= DISTINCT_DEG]
        if far:
            return best, far[0]
        Rm, tm, axis = mirrored(best.R_ch, best.t_ch, layout)
        if angle_between_deg(Rm, best.R_ch) < DISTINCT_DEG:
            return best, None
        twin = refined(Rm, tm, axis)
        if twin is None or twin.cost >= best.cost:
            return best, twin
        # the mirror side holds a lower minimum than the starts found: free it and look again
        fits.append(refined(twin.R_ch, twin.t_ch) or twin)
    return best, twin


def angle_between_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The angle (degrees) of the rotation taking Ra to Rb."""
    c = 0.5 * (np.trace(Ra.T @ Rb) - 1.0)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def better_colour_fit(
    uv: np.ndarray,
    camera: Camera,
    layout: HandLayout,
    R_ch: np.ndarray,
    t_ch: np.ndarray,
    pixel_sigma: float,
    log_evidence: float,
) -> PoseFit | None:
    """A one-frame fit of labelled markers seen without depth (``uv`` (6, 2) in layout order,
    NaN where unseen) that explains them decisively better than the pose (R_ch, t_ch) a filter
    holds, and lies elsewhere (DISTINCT_DEG or more away); None otherwise.

    Decisively: half the drop in chi-square (the log-likelihood ratio of the fit over the held
    pose) above ``log_evidence``, and likewise over the fit's planar twin where there is one.
    Seen nearly fronto-parallel, the out-of-plane tilt rests on small perspective effects, and a
    filter's motion prior carries it past them during a fast turn; one frame's pixels say so.
    """
    P, uvo, _, vis, _ = _observed(layout, uv, None, None)
    if vis.sum() < 4:
        return None
    cam_pts = P[vis] @ R_ch.T + t_ch
    if np.any(cam_pts[:, 2] <= 0):
        return None
    r = (camera.project(cam_pts) - uvo[vis]) / pixel_sigma
    held = float(np.sum(r * r))
    if held / 2 <= log_evidence:  # no fit (chi-square >= 0) can beat it by the margin asked
        return None
    try:
        near = refine_pose(uv, None, camera, layout, R_ch, t_ch, pixel_sigma)
    except InitialisationError:
        return None
    best, twin = planar_twin(uv, None, camera, layout, near, pixel_sigma)
    decisive = (held - best.cost) / 2 > log_evidence
    if twin is not None:  # and the frame must rule out the other planar pose as well
        decisive = decisive and (twin.cost - best.cost) / 2 > log_evidence
    return best if decisive and angle_between_deg(best.R_ch, R_ch) >= DISTINCT_DEG else None
