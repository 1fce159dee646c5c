"""Markers whose blobs merge: one blob for two or three markers seen close together.

When the hand turns edge-on to the camera (a left hand in extension, supination and ulnar
deviation at once, say) the knuckle markers line up along the line of sight: their discs overlap
in the image and the detector sees one blob where three markers are. One-to-one association
gives that blob to one of them; taken as that marker's centre it is 2-3 px off, and with every
realism effect at once it moved the wrist angles by 1-2.5 deg at the extremes of the movement,
exactly where the range of motion is read (benchmarks/seed_spread.py, left hands).

The centre of such a blob is, to a fraction of a pixel, the mean of the merged markers' centres
(2.2 px from the marker it was given to, 0.2 px from the mean of the three, on the rendered
recordings), and its depth near the mean of theirs. So the blob is kept, as a measurement of
that mean (``measurement_map``), rather than dropped or down-weighted. (Its depth leans to the
front marker: on 154 merged blobs of markers 35 mm apart in depth it read 5 mm nearer than
their mean, 7.6 mm rms. Modelled as a front-weighted mean, or with noise that wide, the
extremes of the movement came out worse: range of motion 1.44 -> 1.6 deg.)

A marker the association left without a blob joins the blob of a marker whose disc overlaps
its own (predicted centres less than a marker diameter apart), unless a blob of its own lies
there (one the association turned away, for its depth say). Discs further apart are left to
the association: a blob between two markers that merely come close is more often one of them
under a poor prediction (a fast turn on colour alone) than both.

A marker can also go unseen beside one whose disc it barely overlaps: in the shade, or on the
hand's silhouette (a left hand making the right hand's movement, radial deviation with
pronation at extension, turns MCP2 edge-on 9 px from MCP3, 10.5 px discs). The blob is then
MCP3's alone, on MCP3's centre; taken as the mean of both it was 4.6 px off, put the hand 2-5
deg off and lost the track for a few frames. So a group stands only where its blob lies nearer
the group's mean than its own marker's centre, as far as the prediction can tell the two apart
(``MERGE_DECIDABLE``).
"""

from __future__ import annotations

import math

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
# A group's mean and its blob's own marker closer than this many marker diameters (three
# collinear knuckles: the middle one): the prediction cannot say which the blob shows, and the
# group stands. Further apart, the blob decides. Every effect, 45 rendered recordings of both
# hands making both movements: 0.24-0.33 diameters left the right hands' merges (blobs on the
# mean of three knuckles) as they were and took the left hand's wrong ones apart (making the
# right hand's movement: range of motion 1.78 -> 0.85 deg, smoothed 1.09 -> 0.73); 0.19 also
# took right-hand merges apart (1.44 -> 1.63 deg), 0.48 kept the wrong ones.
MERGE_DECIDABLE = 0.3


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
    return {b: np.sort(np.array(group)) for b, group in members.items()
            if _shows_group(uv[b], uv_hat, group, labels[b], diameter)}


def _shows_group(blob: np.ndarray, uv_hat: np.ndarray, group: list[int], own: int,
                 diameter: np.ndarray) -> bool:
    """Whether ``blob`` (2,) is the merged blob of markers ``group`` rather than marker
    ``own``'s alone: nearer their mean than its own centre along the line between the two,
    or those two too close to tell (MERGE_DECIDABLE)."""
    step = uv_hat[group].mean(axis=0) - uv_hat[own]
    length2 = float(step @ step)
    if length2 <= (MERGE_DECIDABLE * diameter[own, own]) ** 2:
        return True
    return float((blob - uv_hat[own]) @ step) >= 0.5 * length2


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


def may_merge(Rc: np.ndarray, tc: np.ndarray, layout: np.ndarray, mean: np.ndarray,
              blob_of: np.ndarray, reach: float) -> bool:
    """The compiled step's test (tracking/kernel.py: plain loops, compiled with it) of whether a
    marker left without a blob crowds one with a blob: predicted centres (``mean``'s u of each
    marker, then v) closer than ``reach`` (merge_reach; 0: never) over their mean depth, the
    hand at (Rc, tc) with markers ``layout`` (J, 3), ``blob_of`` (J,) each marker's blob or -1.
    The blob may then show both, which generic_step decides with merged_groups."""
    if reach <= 0.0:
        return False
    J = layout.shape[0]
    z = np.empty(J)
    for j in range(J):
        z[j] = Rc[2, 0] * layout[j, 0] + Rc[2, 1] * layout[j, 1] + Rc[2, 2] * layout[j, 2] + tc[2]
    for j in range(J):
        if blob_of[j] >= 0:
            continue
        for i in range(J):
            if blob_of[i] < 0:
                continue
            du, dv = mean[i] - mean[j], mean[J + i] - mean[J + j]
            if math.sqrt(du * du + dv * dv) * 0.5 * (z[i] + z[j]) < reach:
                return True
    return False
