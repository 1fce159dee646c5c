"""The per-frame baseline a user would assemble from OpenCV: no temporal filter at all.

Each frame on its own: the blobs (the same detections the tracker gets) are labelled by the best
fit of the hand layout (3-D alignment to the back-projected blobs where there is depth, else
``labelling.label_markers``), then the pose is ``cv2.solvePnP`` with the planar IPPE solver on
the labelled pixels (it keeps the lower-error of IPPE's two solutions), polished by
``cv2.solvePnPRefineLM``. Pixels only in the pose, as PnP is: depth serves the labelling alone.
A frame where no labelling or no pose is found has no estimate.
"""

from __future__ import annotations

from itertools import combinations, permutations

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError
from wristtrack.hand import HandLayout
from wristtrack.tracking.initialise import initialise
from wristtrack.tracking.labelling import label_markers
from wristtrack.tracking.tracker import FrameResult, Status

_NAN3 = np.full(3, np.nan)
MIN_MARKERS = 4  # IPPE needs four coplanar points
TRIPLE_TOL = 0.01  # m: side lengths of a blob triple vs a marker triple (depth noise ~1 mm)
_LM_STOP = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)  # OpenCV's: 20, 1e-7
GATE = 0.01  # m: a blob this close to a predicted marker is that marker (markers >= 2 cm apart)


class OpenCVPnPTracker:
    """Per-frame labelling + ``cv2.solvePnP(SOLVEPNP_IPPE)``; ``step`` as ``Tracker.step``.

    W0 (for the pose relative to it) is the first frame's estimate, as in the tracker. The
    layout must be planar (z = 0), as IPPE requires; otherwise SQPnP is used. Without a layout
    it is measured from depth at the first frame that allows it (``initialise``).
    """

    def __init__(self, camera: Camera, layout: HandLayout | None, pixel_sigma: float = 0.7):
        self.camera = camera
        self.pixel_sigma = pixel_sigma
        self.dist = None if camera.dist is None else np.asarray(camera.dist, dtype=float)
        self.R_c0: np.ndarray | None = None
        self.t_c0: np.ndarray | None = None
        self._frame = -1
        if layout is not None:
            self._set_layout(layout)

    def _set_layout(self, layout: HandLayout) -> None:
        self.points = np.asarray(layout.points, dtype=float)
        self.planar = bool(np.abs(self.points[:, 2]).max() < 1e-9)
        n = self.points.shape[0]
        self._triples = np.array(list(combinations(range(n), 3)))
        P = self.points[self._triples]
        self._dL = np.linalg.norm(P[:, [0, 1, 0]] - P[:, [1, 2, 2]], axis=-1)  # (T,3)

    def label(self, det: Detections) -> np.ndarray:
        """Labels (M,) of the blobs, -1 = clutter; raises InitialisationError if none fit.

        With depth: the layout is aligned in 3-D (Kabsch) to every triple of back-projected
        blobs whose side lengths match a triple of markers within ``TRIPLE_TOL``; each
        alignment labels the blobs within ``GATE`` of its predicted markers; the alignment with
        the most markers, then the least squared residual, wins. Without depth:
        ``labelling.label_markers`` (all six markers needed).
        """
        n = self.points.shape[0]
        depth = det.depth
        if depth is None or np.isfinite(depth).sum() < 3:
            if det.count < n:
                raise InitialisationError(f"{det.count} blobs and no depth: cannot label")
            return label_markers(det, self.camera, HandLayout(points=self.points),
                                 pixel_sigma=self.pixel_sigma)
        good = np.flatnonzero(np.isfinite(depth) & (depth > 0))
        B = self.camera.backproject(det.uv[good], depth[good])  # (G,3)
        G = B.shape[0]
        if G < 3:
            raise InitialisationError(f"{G} blobs with depth at t={det.timestamp}: too few")
        q = _ordered_triples(G)
        dB = np.linalg.norm(B[q[:, [0, 1, 0]]] - B[q[:, [1, 2, 2]]], axis=-1)  # (Q,3)
        t_idx, q_idx = np.nonzero(
            (np.abs(self._dL[:, None, :] - dB[None]) < TRIPLE_TOL).all(axis=-1)
        )
        if t_idx.size == 0:
            raise InitialisationError(f"no three blobs at t={det.timestamp} match the layout")
        R, t = _kabsch_batch(self.points[self._triples[t_idx]], B[q[q_idx]])
        pred = np.einsum("kij,mj->kmi", R, self.points) + t[:, None, :]  # (K,n,3)
        d = np.linalg.norm(pred[:, :, None, :] - B[None, None], axis=-1)  # (K,n,G)
        nearest = d.argmin(axis=2)
        dmin = np.take_along_axis(d, nearest[..., None], 2)[..., 0]
        inlier = dmin < GATE
        score = inlier.sum(axis=1) - np.where(inlier, dmin**2, 0.0).sum(axis=1)  # count first
        best = int(np.argmax(score))
        labels = np.full(det.count, -1)
        for j in np.argsort(dmin[best]):  # nearer markers claim their blob first
            blob = good[nearest[best, j]]
            if inlier[best, j] and labels[blob] < 0:
                labels[blob] = j
        if np.sum(labels >= 0) < MIN_MARKERS:
            raise InitialisationError(
                f"only {int(np.sum(labels >= 0))} markers fit the layout at t={det.timestamp}"
            )
        return labels

    def solve(self, det: Detections, labels: np.ndarray) -> tuple | None:
        """(R_ch, t_ch, RMS px) from the labelled blobs by IPPE, or None."""
        blobs = np.flatnonzero(labels >= 0)
        if blobs.size < MIN_MARKERS:
            return None
        obj, img = self.points[labels[blobs]], det.uv[blobs]
        flag = cv2.SOLVEPNP_IPPE if self.planar else cv2.SOLVEPNP_SQPNP
        ok, rvec, tvec = cv2.solvePnP(obj, img, self.camera.K, self.dist, flags=flag)
        if not ok or not np.isfinite(tvec).all():
            return None
        # OpenCV's IPPE is only the closed form: ~0.4 deg off on exact projections (its
        # homography is not refined), so polish it by LM on the reprojection error, as OpenCV
        # suggests; IPPE still picks the branch of the planar ambiguity.
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.camera.K, self.dist, rvec, tvec, _LM_STOP)
        R = cv2.Rodrigues(rvec)[0]
        t = tvec.reshape(3)
        rms = float(np.sqrt(np.mean(np.sum((self.camera.project(obj @ R.T + t) - img) ** 2, 1))))
        return R, t, rms

    def step(self, det: Detections) -> FrameResult:
        self._frame += 1
        try:
            if not hasattr(self, "points"):
                # no hand.json: measure the layout from depth once, as the tracker does
                self._set_layout(initialise(det, self.camera, None).layout)
            labels = self.label(det)
            pose = self.solve(det, labels)
        except InitialisationError:
            pose = None
        if pose is None:
            return FrameResult.empty(self._frame, det.timestamp, Status.LOST, det.count)
        R_ch, t_ch, _ = pose
        if self.R_c0 is None:
            self.R_c0, self.t_c0 = R_ch, t_ch
        n_vis = int(np.sum(labels >= 0))
        return FrameResult(
            frame=self._frame, timestamp=det.timestamp, status=Status.TRACKING, R_ch=R_ch,
            t_ch=t_ch, R=self.R_c0.T @ R_ch, p=self.R_c0.T @ (t_ch - self.t_c0), v=_NAN3,
            w=_NAN3, cov=None, labels=labels, n_visible=n_vis, n_clutter=det.count - n_vis,
        )  # no velocities: a per-frame pose solver has no motion model


def _ordered_triples(m: int) -> np.ndarray:
    """All (m (m-1) (m-2), 3) ordered triples of distinct indices below m."""
    return np.array(list(permutations(range(m), 3)), dtype=int).reshape(-1, 3)


def _kabsch_batch(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (K,3,3) and translations (K,3) best mapping point sets P (K,m,3) onto X."""
    mp, mx = P.mean(axis=1), X.mean(axis=1)
    H = np.einsum("kmi,kmj->kij", X - mx[:, None], P - mp[:, None])
    U, _, Vt = np.linalg.svd(H)
    s = np.sign(np.linalg.det(U @ Vt))
    U[:, :, 2] *= s[:, None]
    R = U @ Vt
    return R, mx - np.einsum("kij,kj->ki", R, mp)
