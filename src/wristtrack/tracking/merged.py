"""Markers whose blobs merge: one blob for two or three markers seen close together.

When the hand turns edge-on to the camera (a left hand in extension, supination and ulnar
deviation at once, say) the knuckle markers line up along the line of sight: their discs overlap
in the image and the detector sees one blob where three markers are. One-to-one association
gives that blob to one of them; taken as that marker's centre it is 2-3 px off, and with every
realism effect at once it moved the wrist angles by 1-2.5 deg at the extremes of the movement,
exactly where the range of motion is read (benchmarks/seed_spread.py, left hands).

The centre of such a blob is, to a fraction of a pixel, the mean of the merged markers' centres
(2.2 px from the marker it was given to, 0.2 px from the mean of the three, on the rendered
recordings), and its depth the mean of theirs. So the blob is kept, as a measurement of that
mean (``measurement_map``), rather than dropped or down-weighted.

A marker the association left without a blob joins the blob of a marker whose disc overlaps
its own (predicted centres less than a marker diameter apart), unless a blob of its own lies
there (one the association turned away, for its depth say). Discs further apart are left to
the association: a blob between two markers that merely come close is more often one of them
under a poor prediction (a fast turn on colour alone) than both.
"""

from __future__ import annotations

import numpy as np

from wristtrack.hand import marker_image_diameter

# Two markers whose predicted centres are closer than this many marker diameters show as one
# blob: their discs overlap.
MERGE_DIAMETERS = 1.0
# The merged blob's centre against the mean of its markers' centres: the union of overlapping
# discs is not quite symmetric about that mean (the front marker hides part of the one behind).
# Its standard deviation, as a share of the distance between the merged markers' centres: on
# the rendered left hands with every realism effect, 29 merged blobs of two or three markers
# 7-18 px apart were 0.07-0.53 px (0.5-6 %) off that mean, as far as a single blob is off its
# marker under those effects.
MERGE_SPREAD_SHARE = 0.03


def merge_reach(fx: float) -> float:
    """MERGE_DIAMETERS marker diameters (px) times depth (m): two markers whose predicted
    centres are closer than this over their mean depth may merge."""
    return MERGE_DIAMETERS * marker_image_diameter(fx, 1.0)


def marker_diameters(fx: float, z: np.ndarray) -> np.ndarray:
    """(J, J) a marker's image diameter (px) at the mean depth of each pair of markers at
    depths ``z`` (J,)."""
    return marker_image_diameter(fx, 0.5 * (z[:, None] + z[None, :]))


def merged_groups(uv_hat: np.ndarray, diameter: np.ndarray, expected: np.ndarray,
                  labels: np.ndarray, uv: np.ndarray) -> dict[int, np.ndarray]:
    """Blob -> the markers (ascending, two or more) it is taken to show at once.

    ``uv_hat`` (J, 2) the markers' predicted centres, ``diameter`` (J, J)
    ``marker_diameters``, ``expected`` (J,) the markers that can be seen, ``labels`` (M,) each
    blob's marker from the association (-1: clutter), ``uv`` (M, 2) the blobs."""
    blob_of = np.full(len(uv_hat), -1)
    blob_of[labels[labels >= 0]] = np.flatnonzero(labels >= 0)
    members: dict[int, list[int]] = {}
    d = np.linalg.norm(uv_hat[:, None] - uv_hat[None], axis=-1) / diameter
    free = uv[labels < 0]  # the blobs the association left to clutter
    for j in np.flatnonzero(expected & (blob_of < 0)):
        near = np.flatnonzero((blob_of >= 0) & (d[j] < MERGE_DIAMETERS))
        if near.size == 0 or (np.linalg.norm(free - uv_hat[j], axis=1) < diameter[j, j]).any():
            continue
        # of two neighbours with blobs, the one whose blob sits nearer the middle of the two
        mid = 0.5 * (uv_hat[near] + uv_hat[j])
        i = near[np.argmin(np.linalg.norm(uv[blob_of[near]] - mid, axis=1))]
        members.setdefault(int(blob_of[i]), [int(i)]).append(int(j))
    return {b: np.sort(np.array(group)) for b, group in members.items()}


def measurement_map(labels: np.ndarray, z: np.ndarray, k: int, n_markers: int,
                    groups: dict[int, np.ndarray] | None = None,
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A (r, n_markers*k), values (r,), blob (r,), component (r,)): the update's measurements
    as linear combinations of the predicted ones, y_used = A y. A blob labelled a marker
    measures that marker's rows; a blob of ``groups`` the mean of its markers' rows. ``blob``
    and ``component`` (0 u, 1 v, 2 depth) name each row's; a NaN value (a blob without depth)
    is left out."""
    blobs = np.flatnonzero(labels >= 0)
    groups = groups or {}
    A = np.zeros((len(blobs) * k, n_markers * k))
    for n, b in enumerate(blobs):
        markers = groups.get(int(b), labels[b:b + 1])
        for c in range(k):
            A[n * k + c, markers * k + c] = 1.0 / len(markers)
    values = z[blobs].reshape(-1)
    ok = np.isfinite(values)
    return A[ok], values[ok], np.repeat(blobs, k)[ok], np.tile(np.arange(k), len(blobs))[ok]


def merge_variance(uv_hat: np.ndarray, z_hat: np.ndarray | None,
                   groups: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Blob -> (k,) the variance its merged centre (and depth) has about the mean of its
    markers': (MERGE_SPREAD_SHARE x the largest distance between them)^2."""
    out = {}
    for b, group in groups.items():
        spread = np.max(np.linalg.norm(uv_hat[group][:, None] - uv_hat[group][None], axis=-1))
        var = [(MERGE_SPREAD_SHARE * spread) ** 2] * 2
        if z_hat is not None:
            var.append((MERGE_SPREAD_SHARE * np.ptp(z_hat[group])) ** 2)
        out[b] = np.array(var)
    return out
