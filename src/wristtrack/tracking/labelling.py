"""Automatic labelling of the six markers by fitting the hand layout (beyond the paper, which
assumes the markers are associated at initialisation).

``label_markers``: every injective assignment of blobs to markers, pruned by triangle
orientation, scored by a batched homography (and 3-D inter-marker distances with depth), the best
few refined with the pose fit (tracking/pose_fit.py), and refused when ambiguous. With a
template layout (no hand.json) each candidate is scaled to the hand size its depths measure.
"""

from __future__ import annotations

from functools import cache

import cv2
import numpy as np

from wristtrack import depth_noise
from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError
from wristtrack.hand import HandLayout
from wristtrack.tracking.pose_fit import PoseFit, facing_cos, initial_guesses, refine_pose

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

MANUAL_HINT = "or label the markers by hand (`wristtrack label`, then pass the labels file)"


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


def label_and_fit(
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
            f"hand in the neutral pose with every marker in view, {MANUAL_HINT}"
        )
    if M > MAX_BLOBS:
        raise InitialisationError(
            f"{M} blobs found, too many to label automatically (max {MAX_BLOBS}); remove blue "
            f"objects from the scene or tighten the detector, {MANUAL_HINT}"
        )
    if not np.isfinite(uv).all():
        raise InitialisationError("blob centres contain NaN; the detector output is corrupt")
    spread = np.linalg.svd(uv - uv.mean(axis=0), compute_uv=False)[1] / np.sqrt(M)
    if spread < 2.0:
        raise InitialisationError(
            f"the {M} blobs lie on a line (hand seen edge-on?), so their labels are ambiguous; "
            f"turn the back of the hand towards the camera, {MANUAL_HINT}"
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
            dsig = np.hypot(depth_noise.depth_sigma(np.nan_to_num(d)), shape_sigma)
        best: PoseFit | None = None
        try:
            guesses = initial_guesses(uv[p], d, camera, lay)
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
        if best is None or facing_cos(best.R_ch, best.t_ch, lay) < np.cos(MAX_TILT):
            continue
        fits.append((best.cost, p, best))
        threshold = min(threshold, ratio * max(best.cost, best.dof * noise_floor))
    if not fits:
        raise InitialisationError(
            f"no physically possible assignment of the {M} blobs to the six markers (mirrored, "
            f"collinear or wrong hand.json?); show the back of the hand to the camera, "
            f"{MANUAL_HINT}"
        )
    fits.sort(key=lambda c: c[0])
    cost, p, fit = fits[0]
    rms_limit = float(np.hypot(max_rms_px, 3.0 * shape_px))
    if fit.rms_px > rms_limit:
        raise InitialisationError(
            f"the best marker labelling fits badly (RMS {fit.rms_px:.1f} px > {rms_limit:.1f} px): "
            f"markers missing or merged, palm towards the camera, or a wrong hand layout; "
            f"{MANUAL_HINT}"
        )
    if len(fits) > 1 and fits[1][0] < ratio * max(cost, fit.dof * noise_floor):
        raise InitialisationError(
            f"ambiguous marker labelling: two assignments fit almost equally well (chi-square "
            f"{cost:.1f} vs {fits[1][0]:.1f}); keep blue clutter away from the hand, {MANUAL_HINT}"
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
    return label_and_fit(
        detections.uv,
        detections.depth,
        camera,
        layout,
        pixel_sigma=pixel_sigma,
        depth_sigma=depth_sigma,
        max_rms_px=max_rms_px,
    )[0]
