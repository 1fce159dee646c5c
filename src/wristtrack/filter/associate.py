"""Which blob is which marker: the paper's per-blob rule, global nearest neighbour and JPDA.

All three score a blob i against marker j by the likelihood ratio of "blob i is marker j" to
"blob i is clutter": N(z_i; y_j, S_j) / c, with c the clutter density in the units of the
measurement: 1/(width x height) for pixel-only measurements and 1/(width x height x depth
range) when the depth is part of the measurement. The ratio is free of units, so changing
metres for millimetres (say) leaves every association unchanged.

- ``paper``: each blob independently takes the most probable of {clutter, marker 1..6} under
  the association priors (Cordella et al., eq. 12); two blobs may pick the same marker.
- ``gnn``: the most probable one-to-one joint assignment (no two blobs on one marker, no blob
  on two markers) with a chi-square gate, a detection probability and a Poisson clutter rate,
  solved exactly by ``scipy.optimize.linear_sum_assignment``.
- ``jpda``: the marginal probabilities beta_ij of the same joint events, enumerated exactly
  (six markers and a gate keep the events few), for a probabilistic-data-association update.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from wristtrack.filter.ukf import chi2_quantile

CLUTTER = -1
METHODS = ("gnn", "jpda", "paper")
MAX_CANDIDATES = 4  # per marker in the JPDA enumeration: at most 5^6 events


@dataclass(frozen=True)
class AssociationParams:
    p_detect: float = 0.9  # probability that a visible marker yields a blob
    clutter_rate: float = 3.0  # expected clutter blobs per frame (Poisson)
    gate_prob: float = 0.9999  # chi-square gate: a true marker falls inside with this probability
    image_area: float = 640.0 * 480.0  # px^2
    depth_range: float = 1.7  # m, span of depths a clutter blob may have


def log_likelihood_ratios(
    z: np.ndarray, y_hat: np.ndarray, S: np.ndarray, params: AssociationParams
) -> tuple[np.ndarray, np.ndarray]:
    """log[N(z_i; y_j, S_j) / clutter density] (M, J) and the squared Mahalanobis distances.

    z (M, k) blobs; y_hat (J, k) and S (J, k, k) the predicted markers and innovation
    covariances. With k = 3 a blob whose depth is NaN is scored on its pixels alone (and then
    against the pixel-only clutter density).
    """
    M, k = z.shape
    llr = np.empty((M, y_hat.shape[0]))
    d2 = np.empty_like(llr)
    has_depth = np.ones(M, bool) if k == 2 else np.isfinite(z[:, 2])
    for dims, rows in ((k, has_depth), (2, ~has_depth)):
        if not rows.any():
            continue
        Sd = S[:, :dims, :dims]
        Sinv = np.linalg.inv(Sd)
        _, logdet = np.linalg.slogdet(Sd)
        diff = z[rows, None, :dims] - y_hat[None, :, :dims]  # (m, J, dims)
        m2 = np.einsum("mja,jab,mjb->mj", diff, Sinv, diff)
        density = 1.0 / params.image_area
        if dims == 3:
            density /= params.depth_range
        d2[rows] = m2
        llr[rows] = -0.5 * (m2 + logdet + dims * np.log(2 * np.pi)) - np.log(density)
    return llr, d2


def gate(d2: np.ndarray, z: np.ndarray, params: AssociationParams) -> np.ndarray:
    """Which (blob, marker) pairs pass the chi-square gate (M, J); dof 3 with depth, else 2."""
    dof = np.full(z.shape[0], 2) if z.shape[1] == 2 else np.where(np.isfinite(z[:, 2]), 3, 2)
    limits = np.array([chi2_quantile(params.gate_prob, int(d)) for d in (2, 3)])
    return d2 <= limits[dof - 2][:, None]


def pair_scores(llr: np.ndarray, params: AssociationParams) -> np.ndarray:
    """log of P_D N_ij / ((1 - P_D) lambda_c): the gain of pairing i with j over clutter + miss."""
    return llr + np.log(params.p_detect / ((1 - params.p_detect) * params.clutter_rate))


def associate_paper(llr: np.ndarray, params: AssociationParams) -> np.ndarray:
    """The paper's rule: each blob takes its own most probable label; labels (M,)."""
    n_markers = llr.shape[1]
    if n_markers == 0 or llr.shape[0] == 0:
        return np.full(llr.shape[0], CLUTTER)
    # priors as expected shares of blobs: clutter_rate clutter blobs, P_D per marker
    total = params.clutter_rate + n_markers * params.p_detect
    log_marker = llr + np.log(params.p_detect / total)
    log_clutter = np.log(params.clutter_rate / total)
    best = np.argmax(log_marker, axis=1)
    return np.where(log_marker[np.arange(len(best)), best] > log_clutter, best, CLUTTER)


def associate_gnn(scores: np.ndarray, gated: np.ndarray) -> np.ndarray:
    """Most probable one-to-one assignment; labels (M,), CLUTTER where unassigned."""
    labels = np.full(scores.shape[0], CLUTTER)
    if scores.size == 0:
        return labels
    # Pairing is only ever worth it where the score is positive: leaving a blob as clutter and
    # its marker missed costs 0, so clip the rest to 0 and drop zero-cost pairs afterwards.
    cost = np.where(gated, np.minimum(-scores, 0.0), 0.0)
    rows, cols = linear_sum_assignment(cost)
    keep = cost[rows, cols] < 0
    labels[rows[keep]] = cols[keep]
    return labels


def jpda_marginals(scores: np.ndarray, gated: np.ndarray) -> np.ndarray:
    """Exact JPDA marginals beta (M, J): P(blob i is marker j | all blobs of the frame).

    Enumerates every feasible joint event (each marker: missed or one gated blob not used by
    another marker); an event's weight is exp(sum of its pair scores), relative to the event
    "all markers missed, all blobs clutter".
    """
    M, J = scores.shape
    beta = np.zeros((M, J))
    options = []
    for j in range(J):
        candidates = np.flatnonzero(gated[:, j])
        # Beyond a few candidates per marker the extra events carry negligible weight but
        # multiply the enumeration; keep the best-scoring ones.
        candidates = candidates[np.argsort(-scores[candidates, j])[:MAX_CANDIDATES]]
        options.append([-1, *candidates])
    events = np.array(list(itertools.product(*options)), dtype=int).reshape(-1, J)
    if M == 0 or len(events) == 0:
        return beta
    used = events[:, :, None] == np.arange(M)  # (E, J, M)
    feasible = used.sum(axis=1).max(axis=1, initial=0) <= 1
    events = events[feasible]
    padded = np.concatenate((scores, np.zeros((1, J))))  # row -1 (missed) scores 0
    logw = padded[events, np.arange(J)].sum(axis=1)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    for j in range(J):
        hit = events[:, j] >= 0
        np.add.at(beta[:, j], events[hit, j], w[hit])
    return beta


def labels_from_marginals(beta: np.ndarray) -> np.ndarray:
    """Most probable label per blob (for reporting): marker j if beta_ij > 0.5, else clutter."""
    labels = np.full(beta.shape[0], CLUTTER)
    if beta.size:
        best = np.argmax(beta, axis=1)
        sure = beta[np.arange(beta.shape[0]), best] > 0.5
        labels[sure] = best[sure]
    return labels


def full_measurement_constants(params: AssociationParams) -> tuple[float, float]:
    """For pixel + depth measurements (k = 3): the part of -pair_score that depends on neither
    the blob nor the marker, c, and the gate on half squared distances, g. Then
    -pair_score_ij = m2_ij / 2 + log(det S_j) / 2 + c, and the pair is gated where
    m2_ij / 2 <= g: the form the compiled tracker step scores pairs in."""
    density = 1.0 / (params.image_area * params.depth_range)
    constant = (
        1.5 * math.log(2 * math.pi)
        + math.log(density)
        - math.log(params.p_detect / ((1 - params.p_detect) * params.clutter_rate))
    )
    return constant, 0.5 * chi2_quantile(params.gate_prob, 3)
