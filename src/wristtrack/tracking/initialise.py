"""Initialisation: label the six markers and solve the camera-to-hand pose (paper section III-D).

The paper assumes the markers are already associated and solves the initial pose by Gauss-Newton
least squares on marker projections and depths (eq. 15-20). Here, beyond the paper:

- ``refine_pose``: damped Gauss-Newton on SO(3) x R^3 (left perturbation), analytic Jacobian,
  per-marker depth weights from the sensor noise model, covariance of the estimate;
- ``initial_guess``: closed-form start (3-D alignment with depth, IPPE without);
- ``label_markers``: automatic labelling by fitting the layout to every injective assignment of
  blobs to markers, pruned by triangle orientation, scored by a batched homography, refined, and
  refused when ambiguous;
- ``initialise``: the whole step, estimating the subject's layout from depth when there is no
  hand.json.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import ConfigError, InitialisationError
from wristtrack.geometry import skew, so3_exp
from wristtrack.hand import MARKER_NAMES, HandLayout, estimate_layout

# Kinect-style depth noise sigma_z = c z^2 (Khoshelham & Oude Elberink 2012: 1.425e-3 / m).
KINECT_DEPTH_COEFF = 1.425e-3
# A correct fit with 0.7 px blob noise has an RMS near 0.7 px; 5 px means a wrong model or labels.
MAX_RMS_PX = 5.0
# The runner-up assignment must cost this many times more (chi-square) than the best.
AMBIGUITY_RATIO = 4.0
# Markers sit on the back of the hand: a neutral pose seen more obliquely than this is not real.
MAX_TILT = np.radians(80.0)
# How far (m, in-plane) a subject's hand may differ from the default template after a best fit.
TEMPLATE_SHAPE_SIGMA = 0.004
# Assignment refinement budget and the blob count beyond which enumeration is refused.
N_REFINE = 12
MAX_BLOBS = 12

_MANUAL_HINT = "or label the markers by hand (`wristtrack label`, then pass the labels file)"


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


@dataclass(frozen=True)
class InitResult:
    """Result of ``initialise``: pose hand -> camera, its covariance, blob labels, the layout."""

    R_ch: np.ndarray
    t_ch: np.ndarray
    cov: np.ndarray
    labels: np.ndarray
    rms_px: float
    layout: HandLayout
    cost: float


# ----------------------------------------------------------------------------------------------
# Pose refinement


def _pinhole_jacobian(camera: Camera, X: np.ndarray) -> np.ndarray:
    """d(u, v)/dX of the undistorted pinhole at camera points X (N,3) -> (N,2,3)."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    J = np.zeros((X.shape[0], 2, 3))
    J[:, 0, 0] = camera.fx / z
    J[:, 0, 2] = -camera.fx * x / z**2
    J[:, 1, 1] = camera.fy / z
    J[:, 1, 2] = -camera.fy * y / z**2
    return J


def _point_jacobian(X: np.ndarray, t: np.ndarray) -> np.ndarray:
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
) -> PoseFit:
    """Weighted least-squares camera-to-hand pose from labelled marker projections and depths.

    Minimises sum ||(uv_j - project(R p_j + t)) / pixel_sigma||^2
    + sum ((z_j - (R p_j + t)_z) / depth_sigma_j)^2 (paper eq. 15) by Levenberg-Marquardt-damped
    Gauss-Newton, updating R <- so3_exp(dphi) R, t <- t + dt. ``uv`` (N,2) and ``depth`` (N,) are
    in layout order; non-finite entries (or ``visible`` False) are skipped. ``depth_sigma``
    defaults to the Kinect model 1.425e-3 z^2 per marker. The projection uses ``camera.project``
    (with distortion); the Jacobian is that of the undistorted pinhole, which only slows
    convergence slightly for mild distortion.
    """
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
    n_res = 2 * int(vis.sum()) + int(dvis.sum())
    if vis.sum() < 3 or n_res < 7:
        raise InitialisationError(
            f"pose unobservable: only {int(vis.sum())} markers visible ({int(dvis.sum())} with "
            "depth); initialise with all six markers in view"
        )
    Pv, uvv, Pd = P[vis], uv[vis], P[dvis]
    zd = depth[dvis] if depth is not None else np.zeros(0)
    if depth_sigma is None:
        sz = KINECT_DEPTH_COEFF * zd**2
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
        Jpx = (_pinhole_jacobian(camera, Xv) @ _point_jacobian(Xv, t)).reshape(-1, 6)
        Jz = _point_jacobian(Xd, t)[:, 2, :]
        J = np.concatenate([Jpx / pixel_sigma, Jz / sz[:, None]])
        return J.T @ J, J.T @ r

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
                delta = np.linalg.solve(A + lam * D, g)
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


def _facing_cos(R: np.ndarray, t: np.ndarray, layout: HandLayout) -> float:
    """Cosine between the back-of-hand normal (+Z) and the direction from the hand to the camera."""
    c = R @ layout.points.mean(axis=0) + t
    return float(-R[:, 2] @ c / np.linalg.norm(c))


def _initial_guesses(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    visible: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Candidate starting poses, best first (see ``initial_guess``)."""
    P = np.asarray(layout.points, dtype=float)
    n = P.shape[0]
    uv = np.asarray(uv, dtype=float).reshape(n, 2)
    vis = np.isfinite(uv).all(axis=1)
    if visible is not None:
        vis &= np.asarray(visible, dtype=bool).reshape(n)
    if depth is not None:
        depth = np.asarray(depth, dtype=float).reshape(n)
        ok = vis & np.isfinite(depth) & (depth > 0)
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
    order = sorted(range(len(sols)), key=lambda k: (_facing_cos(*sols[k], layout) <= 0.0, err[k]))
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
    return _initial_guesses(uv, depth, camera, layout, visible)[0]


# ----------------------------------------------------------------------------------------------
# Labelling


def _normalised(uv: np.ndarray, camera: Camera) -> np.ndarray:
    """Undistorted normalised image coordinates (M,2)."""
    if camera.dist is None:
        return np.stack([(uv[:, 0] - camera.cx) / camera.fx, (uv[:, 1] - camera.cy) / camera.fy], 1)
    pts = cv2.undistortPoints(uv.reshape(-1, 1, 2), camera.K, np.asarray(camera.dist, float))
    return pts.reshape(-1, 2)


def _triangles(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orientation sign and smallest height of every triangle of points p (M,2) -> (M,M,M) each."""
    a, b, c = p[:, None, None, :], p[None, :, None, :], p[None, None, :, :]
    u, v = b - a, c - a
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    longest = np.maximum(
        np.maximum(np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)),
        np.linalg.norm(c - b, axis=-1),
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        height = np.where(longest > 0, np.abs(cross) / longest, 0.0)
    return np.sign(cross), height


@cache
def _triples(n: int) -> tuple[tuple[int, int, int], ...]:
    return tuple((i, j, k) for k in range(n) for j in range(k) for i in range(j))


def _enumerate(
    n: int, img_sign: np.ndarray, img_reliable: np.ndarray, tests: dict[int, list]
) -> np.ndarray:
    """All injective assignments (K, n) of blobs to markers passing the orientation tests.

    Built marker by marker so that a triangle is tested as soon as its three markers are
    assigned: this prunes early and keeps M = 9..12 blobs cheap.
    """
    M = img_sign.shape[0]
    cand = np.arange(M)[:, None]
    for k in range(1, n):
        rows = np.repeat(cand, M, axis=0)
        col = np.tile(np.arange(M), cand.shape[0])
        fresh = (rows != col[:, None]).all(axis=1)
        cand = np.column_stack([rows[fresh], col[fresh]])
        for i, j, expected in tests.get(k, []):
            a, b, c = cand[:, i], cand[:, j], cand[:, k]
            cand = cand[~img_reliable[a, b, c] | (img_sign[a, b, c] == expected)]
    return cand


_HOMOGRAPHY_CHUNK = 4096  # candidates per batched SVD: bounds memory (~5 MB) with many blobs


def _homography_scores(X: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_homography_chunk` over chunks of candidates, so memory stays bounded when many
    blobs give hundreds of thousands of assignments."""
    if x.shape[0] <= _HOMOGRAPHY_CHUNK:
        return _homography_chunk(X, x)
    parts = [
        _homography_chunk(X, x[s : s + _HOMOGRAPHY_CHUNK])
        for s in range(0, x.shape[0], _HOMOGRAPHY_CHUNK)
    ]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _homography_chunk(X: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched DLT plane->image homographies for candidates.

    X (n,2) layout plane points (normalised), x (K,n,2) image points (normalised camera coords).
    Returns the per-candidate sum of squared transfer errors (normalised units) and a mask of
    physically possible fits: every marker in front of the camera and the back of the hand
    facing it (det H < 0 once w > 0, since H ~ [r1 r2 t] and facing means r3 . t < 0).
    """
    K, n = x.shape[:2]
    Xh = np.column_stack([X, np.ones(n)])  # (n,3)
    A = np.zeros((K, 2 * n, 9))
    A[:, 0::2, 0:3] = Xh
    A[:, 0::2, 6:9] = -x[:, :, 0:1] * Xh
    A[:, 1::2, 3:6] = Xh
    A[:, 1::2, 6:9] = -x[:, :, 1:2] * Xh
    H = np.linalg.svd(A)[2][:, -1, :].reshape(K, 3, 3)
    w = H[:, 2, :] @ Xh.T  # (K,n)
    s = np.where(w.sum(axis=1) < 0, -1.0, 1.0)
    H, w = H * s[:, None, None], w * s[:, None]
    front = (w > 1e-12 * np.abs(w).max(axis=1, keepdims=True)).all(axis=1)
    facing = np.linalg.det(H) < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = np.einsum("kij,nj->kni", H[:, :2, :], Xh) / w[..., None]
    sse = np.sum((proj - x) ** 2, axis=(1, 2))
    return np.where(np.isfinite(sse), sse, np.inf), front & facing


def _label_and_fit(
    uv: np.ndarray,
    depth: np.ndarray | None,
    camera: Camera,
    layout: HandLayout,
    *,
    pixel_sigma: float = 0.7,
    depth_sigma: float | None = None,
    template: bool = False,
    max_rms_px: float = MAX_RMS_PX,
    ratio: float = AMBIGUITY_RATIO,
) -> tuple[np.ndarray, PoseFit]:
    """Label blobs by fitting ``layout`` to every plausible assignment; see ``label_markers``.

    With ``template`` the layout only stands for the subject's hand: each candidate gets the
    template scaled to the size its depths measure, and the residual weights include a shape
    tolerance of ``TEMPLATE_SHAPE_SIGMA``.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    M, n = uv.shape[0], layout.points.shape[0]
    if M < n:
        raise InitialisationError(
            f"need all six markers visible to initialise, found {M} blobs; show the back of the "
            f"hand in the neutral pose with every marker in view, {_MANUAL_HINT}"
        )
    if M > MAX_BLOBS:
        raise InitialisationError(
            f"{M} blobs found, too many to label automatically (max {MAX_BLOBS}); remove blue "
            f"objects from the scene or tighten the detector, {_MANUAL_HINT}"
        )
    if not np.isfinite(uv).all():
        raise InitialisationError("blob centres contain NaN; the detector output is corrupt")
    spread = np.linalg.svd(uv - uv.mean(axis=0), compute_uv=False)[1] / np.sqrt(M)
    if spread < 2.0:
        raise InitialisationError(
            f"the {M} blobs lie on a line (hand seen edge-on?), so their labels are ambiguous; "
            f"turn the back of the hand towards the camera, {_MANUAL_HINT}"
        )
    X3 = None
    if depth is not None:
        depth = np.asarray(depth, dtype=float).reshape(M)
        if np.isfinite(depth).sum() >= 3:
            X3 = camera.backproject(uv, depth)  # NaN rows where there is no reading
        else:
            depth = None

    P = np.asarray(layout.points, dtype=float)
    f = 0.5 * (camera.fx + camera.fy)
    xn = _normalised(uv, camera)
    # The working distance converts the template's shape tolerance into pixels.
    if depth is not None:
        z_ref = float(np.nanmedian(depth))
    else:
        z_ref = f * np.sqrt(np.var(P[:, :2], axis=0).sum() / np.var(uv, axis=0).sum())
    shape_sigma = TEMPLATE_SHAPE_SIGMA if template else 0.0
    shape_px = f * shape_sigma / z_ref
    sig_px = float(np.hypot(pixel_sigma, shape_px))

    # Triangle orientation: seen from its front (hand +Z towards the camera, against the
    # camera's +z) the palm plane maps every triangle to the opposite orientation in the image,
    # whatever the pose (det H < 0), so one sign test per triangle removes mirrored and scrambled
    # assignments before any fitting. Only sure signs are tested: image triangles well above the
    # blob noise; layout triangles tall enough that a non-planar layout or, for a template,
    # another hand's proportions cannot flip them (what remains is anatomical order: the MCPs
    # fan out in order around the wrist).
    lay_sign, lay_h = _triangles(P[:, :2])
    lay_tol = 0.002 + 2.0 * shape_sigma + 3.0 * np.abs(P[:, 2]).max()
    tests: dict[int, list] = {}
    for i, j, k in _triples(n):
        if lay_h[i, j, k] > lay_tol:
            tests.setdefault(k, []).append((i, j, -lay_sign[i, j, k]))
    img_sign, img_h = _triangles(xn * f)
    cand = _enumerate(n, img_sign, img_h > 6.0 * pixel_sigma, tests)

    # Cheap score of every surviving assignment: batched homography (scale-free), plus the
    # 3-D inter-marker distances when depth is there (very discriminative against clutter; for
    # a template, after removing each candidate's overall scale).
    h_score = np.zeros(0)
    if cand.shape[0]:
        c0 = P[:, :2].mean(axis=0)
        s0 = np.sqrt(np.mean(np.sum((P[:, :2] - c0) ** 2, axis=1)))
        sse, possible = _homography_scores((P[:, :2] - c0) / s0, xn[cand])
        h_score = sse * f**2 / sig_px**2
        score = h_score
        if X3 is not None:
            iu, ju = np.triu_indices(n, 1)
            DL = np.linalg.norm(P[iu] - P[ju], axis=-1)
            Dc = np.linalg.norm(X3[cand[:, iu]] - X3[cand[:, ju]], axis=-1)
            if template:
                with np.errstate(all="ignore"):
                    Dc = Dc / np.nanmedian(Dc / DL, axis=1, keepdims=True)
            res = (Dc - DL) / (0.003 + shape_sigma)
            score = score + np.nansum(res**2, axis=1)
        order = np.argsort(score[possible], kind="stable")[:N_REFINE]
        cand, h_score = cand[possible][order], h_score[possible][order]
    # A pose fit of a planar layout induces a homography, so its pixel chi-square is at least
    # the homography's (up to DLT's algebraic-vs-geometric slack, hence the factor 2): once every
    # remaining candidate's bound exceeds the ambiguity threshold, none can matter any more.
    bound = np.minimum.accumulate(h_score[::-1])[::-1] / 2.0
    if np.abs(P[:, 2]).max() > 1e-3:
        bound[:] = 0.0
    noise_floor = (pixel_sigma / sig_px) ** 2  # expected chi-square per dof from noise alone

    fits: list[tuple[float, np.ndarray, PoseFit]] = []
    threshold = np.inf  # ambiguity threshold set by the best fit so far
    for p, lower in zip(cand, bound, strict=True):
        if lower > threshold:
            break
        d, lay = None if depth is None else depth[p], layout
        if template and X3 is not None:
            # Scale the template to the hand size the depths measure; hands outside 0.6-1.6x
            # the default adult hand are not hands (clutter at another depth).
            ok = np.isfinite(d)
            if ok.sum() < 3:
                continue
            Xc, Pc = X3[p][ok], P[ok]
            scale = np.sqrt(
                np.sum((Xc - Xc.mean(axis=0)) ** 2) / np.sum((Pc - Pc.mean(axis=0)) ** 2)
            )
            if not 0.6 < scale < 1.6:
                continue
            lay = HandLayout(points=P * scale)
        dsig = depth_sigma
        if template and d is not None:
            dsig = np.hypot(KINECT_DEPTH_COEFF * np.nan_to_num(d) ** 2, shape_sigma)
        best: PoseFit | None = None
        try:
            guesses = _initial_guesses(uv[p], d, camera, lay)
        except InitialisationError:
            continue
        for R0, t0 in guesses:
            try:
                fit = refine_pose(uv[p], d, camera, lay, R0, t0, sig_px, dsig)
            except InitialisationError:
                continue
            if best is None or fit.cost < best.cost:
                best = fit
        # Physically impossible: markers behind the camera, or the back of the hand facing away
        # (a mirrored assignment) or seen almost edge-on.
        if best is None or _facing_cos(best.R_ch, best.t_ch, lay) < np.cos(MAX_TILT):
            continue
        fits.append((best.cost, p, best))
        threshold = min(threshold, ratio * max(best.cost, best.dof * noise_floor))
    if not fits:
        raise InitialisationError(
            f"no physically possible assignment of the {M} blobs to the six markers (mirrored, "
            f"collinear or wrong hand.json?); show the back of the hand to the camera, "
            f"{_MANUAL_HINT}"
        )
    fits.sort(key=lambda c: c[0])
    cost, p, fit = fits[0]
    rms_limit = float(np.hypot(max_rms_px, 3.0 * shape_px))
    if fit.rms_px > rms_limit:
        raise InitialisationError(
            f"the best marker labelling fits badly (RMS {fit.rms_px:.1f} px > {rms_limit:.1f} px): "
            f"markers missing or merged, palm towards the camera, or a wrong hand layout; "
            f"{_MANUAL_HINT}"
        )
    if len(fits) > 1 and fits[1][0] < ratio * max(cost, fit.dof * noise_floor):
        raise InitialisationError(
            f"ambiguous marker labelling: two assignments fit almost equally well (chi-square "
            f"{cost:.1f} vs {fits[1][0]:.1f}); keep blue clutter away from the hand, {_MANUAL_HINT}"
        )
    labels = np.full(M, -1, dtype=int)
    labels[p] = np.arange(n)
    return labels, fit


def label_markers(
    detections: Detections,
    camera: Camera,
    layout: HandLayout,
    *,
    pixel_sigma: float = 0.7,
    depth_sigma: float | None = None,
    max_rms_px: float = MAX_RMS_PX,
) -> np.ndarray:
    """Labels (M,) of the blobs: 0..5 = marker index (``MARKER_NAMES`` order), -1 = clutter.

    Assumes the initialisation posture: hand still and neutral, back of the hand towards the
    camera, all six markers visible, possibly with a few clutter blobs. Every injective
    assignment of 6 of the M blobs is considered; impossible ones (mirrored, scrambled) are
    pruned by triangle orientation, the rest scored by a batched homography fit (+ 3-D
    inter-marker distances with depth), and the best few refined with ``refine_pose``.
    Raises InitialisationError when fewer than six blobs, when nothing fits, when the best fit is
    implausible (RMS > ``max_rms_px``) or when the runner-up costs less than 4x the best.
    """
    return _label_and_fit(
        detections.uv,
        detections.depth,
        camera,
        layout,
        pixel_sigma=pixel_sigma,
        depth_sigma=depth_sigma,
        max_rms_px=max_rms_px,
    )[0]


# ----------------------------------------------------------------------------------------------
# The whole initialisation step


def _marker_blobs(labels: np.ndarray, M: int) -> np.ndarray:
    """Blob index per marker (6,), -1 where the marker has no blob; validates ``labels``."""
    labels = np.asarray(labels).reshape(-1)
    n = len(MARKER_NAMES)
    if labels.shape[0] != M or not np.isin(labels, np.arange(-1, n)).all():
        raise InitialisationError(
            f"labels must give one value in -1..{n - 1} per blob ({M} blobs), got {labels.tolist()}"
        )
    idx = np.full(n, -1, dtype=int)
    for k in range(n):
        hits = np.flatnonzero(labels == k)
        if hits.size > 1:
            raise InitialisationError(
                f"labels put marker {MARKER_NAMES[k]} on {hits.size} blobs; one blob per marker"
            )
        if hits.size:
            idx[k] = hits[0]
    return idx


def initialise(
    detections: Detections,
    camera: Camera,
    layout: HandLayout | None,
    labels: np.ndarray | None = None,
    *,
    pixel_sigma: float = 0.7,
    depth_sigma: float | None = None,
    max_rms_px: float = MAX_RMS_PX,
) -> InitResult:
    """Label the markers (unless ``labels`` is given) and solve the initial hand -> camera pose.

    Without ``layout`` (no hand.json) depth is required: the blobs are labelled with
    ``HandLayout.default()`` as a shape template, the subject's layout is estimated from the
    back-projected marker centres (``hand.estimate_layout``), and the pose refined with it.
    """
    uv, depth = detections.uv, detections.depth
    M = uv.shape[0]
    if layout is None:
        if depth is None or np.isfinite(depth).sum() < len(MARKER_NAMES):
            raise InitialisationError(
                "no hand layout and no depth: give a hand.json (--hand) or a recording with "
                "registered depth so the layout can be measured"
            )
        if labels is None:
            labels, _ = _label_and_fit(
                uv,
                depth,
                camera,
                HandLayout.default(),
                pixel_sigma=pixel_sigma,
                template=True,
                max_rms_px=max_rms_px,
            )
        idx = _marker_blobs(labels, M)
        missing = [
            name
            for name, b in zip(MARKER_NAMES, idx, strict=True)
            if b < 0 or not np.isfinite(depth[b])
        ]
        if missing:
            raise InitialisationError(
                f"measuring the hand layout needs depth at all six markers; none for "
                f"{', '.join(missing)}: give a hand.json (--hand) or re-record"
            )
        try:
            layout, R0, t0 = estimate_layout(camera.backproject(uv[idx], depth[idx]))
        except ConfigError as err:  # an impossible measured layout: report it as such
            raise InitialisationError(str(err)) from err
        fit = refine_pose(uv[idx], depth[idx], camera, layout, R0, t0, pixel_sigma, depth_sigma)
    elif labels is None:
        labels, fit = _label_and_fit(
            uv, depth, camera, layout, pixel_sigma=pixel_sigma, depth_sigma=depth_sigma,
            max_rms_px=max_rms_px,
        )  # fmt: skip
    else:
        idx = _marker_blobs(labels, M)
        vis = idx >= 0
        uvm = np.where(vis[:, None], uv[idx], np.nan)
        dm = None if depth is None else np.where(vis, depth[idx], np.nan)
        R0, t0 = initial_guess(uvm, dm, camera, layout, vis)
        fit = refine_pose(uvm, dm, camera, layout, R0, t0, pixel_sigma, depth_sigma, vis)
    if fit.rms_px > max_rms_px:
        raise InitialisationError(
            f"initial pose fits the markers badly (RMS {fit.rms_px:.1f} px > {max_rms_px} px): "
            "wrong labels or hand layout; check the labels file and hand.json"
        )
    return InitResult(
        R_ch=fit.R_ch,
        t_ch=fit.t_ch,
        cov=fit.cov,
        labels=np.asarray(labels, dtype=int),
        rms_px=fit.rms_px,
        layout=layout,
        cost=fit.cost,
    )
