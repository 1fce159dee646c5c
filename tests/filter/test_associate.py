"""Association rules against brute-force enumeration and hand-derived values."""

import itertools

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from wristtrack.filter import associate as assoc

PARAMS = assoc.AssociationParams(image_area=640 * 480, depth_range=1.7, clutter_rate=3.0)


def _scene(rng, k=3, n_clutter=3):
    y_hat = np.column_stack((rng.uniform(200, 400, (6, 2)), rng.uniform(0.6, 0.7, (6, 1))))[:, :k]
    A = rng.standard_normal((6, k, k)) * 0.3
    S = A @ A.swapaxes(1, 2) + np.eye(k) * np.array([4.0, 4.0, 1e-6])[:k]
    markers = np.array([rng.multivariate_normal(y, s) for y, s in zip(y_hat, S, strict=True)])
    clutter = np.column_stack((rng.uniform(0, 640, n_clutter), rng.uniform(0, 480, n_clutter),
                               rng.uniform(0.3, 2.0, n_clutter)))[:, :k]
    z = np.vstack((markers, clutter))
    return z, y_hat, S


def test_log_likelihood_ratio_matches_scipy_density_over_clutter_density():
    rng = np.random.default_rng(0)
    z, y_hat, S = _scene(rng)
    llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, PARAMS)
    for i, j in [(0, 0), (2, 5), (7, 1)]:
        expected = multivariate_normal(y_hat[j], S[j]).logpdf(z[i]) + np.log(640 * 480 * 1.7)
        assert llr[i, j] == pytest.approx(expected, rel=1e-10)
        diff = z[i] - y_hat[j]
        assert d2[i, j] == pytest.approx(diff @ np.linalg.solve(S[j], diff), rel=1e-10)


def test_blob_without_depth_is_scored_on_pixels_against_pixel_clutter_density():
    rng = np.random.default_rng(1)
    z, y_hat, S = _scene(rng)
    z[0, 2] = np.nan
    llr, _ = assoc.log_likelihood_ratios(z, y_hat, S, PARAMS)
    expected = multivariate_normal(y_hat[3, :2], S[3, :2, :2]).logpdf(z[0, :2]) + np.log(640 * 480)
    assert llr[0, 3] == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("method", ["gnn", "paper", "jpda"])
def test_association_is_unchanged_by_a_change_of_depth_units(method):
    rng = np.random.default_rng(2)
    for _ in range(20):
        z, y_hat, S = _scene(rng)
        scale = np.array([1.0, 1.0, 1000.0])  # metres -> millimetres
        params_mm = assoc.AssociationParams(image_area=640 * 480, depth_range=1700.0)
        a = _labels(method, z, y_hat, S, PARAMS)
        b = _labels(method, z * scale, y_hat * scale, S * np.outer(scale, scale), params_mm)
        np.testing.assert_array_equal(a, b)


def _labels(method, z, y_hat, S, params):
    llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, params)
    gated = assoc.gate(d2, z, params)
    if method == "paper":
        return assoc.associate_paper(llr, params)
    scores = assoc.pair_scores(llr, params)
    if method == "gnn":
        return assoc.associate_gnn(scores, gated)
    return assoc.labels_from_marginals(assoc.jpda_marginals(scores, gated))


def _all_events(M, J, gated):
    """Every feasible joint event by brute force: tuple per marker of blob index or -1."""
    for event in itertools.product(range(-1, M), repeat=J):
        used = [i for i in event if i >= 0]
        if len(used) == len(set(used)) and all(gated[i, j] for j, i in enumerate(event) if i >= 0):
            yield event


def test_gnn_finds_the_most_probable_joint_event():
    rng = np.random.default_rng(3)
    for _ in range(10):
        J, M = 4, 5  # small enough to enumerate everything
        scores = rng.normal(1.0, 3.0, (M, J))
        gated = rng.random((M, J)) < 0.7
        labels = assoc.associate_gnn(scores, gated)
        best = max(
            _all_events(M, J, gated),
            key=lambda e: sum(scores[i, j] for j, i in enumerate(e) if i >= 0),
        )
        best_score = sum(scores[i, j] for j, i in enumerate(best) if i >= 0)
        ours = sum(scores[i, labels[i]] for i in range(M) if labels[i] >= 0)
        assert ours == pytest.approx(best_score)
        # one-to-one
        assigned = labels[labels >= 0]
        assert len(assigned) == len(set(assigned))


def test_jpda_marginals_match_brute_force():
    rng = np.random.default_rng(4)
    J, M = 4, 4
    scores = rng.normal(0.0, 2.0, (M, J))
    gated = rng.random((M, J)) < 0.8
    beta = assoc.jpda_marginals(scores, gated)
    expected = np.zeros((M, J))
    total = 0.0
    for event in _all_events(M, J, gated):
        w = np.exp(sum(scores[i, j] for j, i in enumerate(event) if i >= 0))
        total += w
        for j, i in enumerate(event):
            if i >= 0:
                expected[i, j] += w
    np.testing.assert_allclose(beta, expected / total, atol=1e-12)
    assert np.all(beta.sum(axis=0) <= 1 + 1e-12) and np.all(beta.sum(axis=1) <= 1 + 1e-12)


def test_paper_rule_takes_each_blob_independently_and_may_double_assign():
    # two blobs right on marker 0, nothing near marker 1: both take marker 0
    y_hat = np.array([[100.0, 100.0], [400.0, 400.0]])
    S = np.stack([np.eye(2) * 4.0] * 2)
    z = np.array([[100.5, 100.0], [99.5, 100.2], [600.0, 50.0]])
    llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, PARAMS)
    np.testing.assert_array_equal(assoc.associate_paper(llr, PARAMS), [0, 0, -1])
    # the one-to-one rule keeps only one of them
    gnn = assoc.associate_gnn(assoc.pair_scores(llr, PARAMS), assoc.gate(d2, z, PARAMS))
    assert sorted(gnn.tolist()) == [-1, -1, 0]


def test_clutter_threshold_is_where_likelihood_ratio_beats_priors():
    """Hand-derived: with S = s^2 I (2-D), a blob at distance r from the prediction is taken as
    the marker by the paper rule iff N(r) * P_D > (1/A) * clutter_rate."""
    s2 = 4.0
    y_hat, S = np.array([[300.0, 200.0]]), np.eye(2)[None] * s2
    params = assoc.AssociationParams(image_area=640 * 480, clutter_rate=3.0, p_detect=0.9)
    r_star = np.sqrt(-2 * s2 * np.log(3.0 / (640 * 480) / 0.9 * 2 * np.pi * s2))
    inside = np.array([[300.0 + r_star - 0.01, 200.0]])
    outside = np.array([[300.0 + r_star + 0.01, 200.0]])
    for blob, label in ((inside, 0), (outside, -1)):
        llr, _ = assoc.log_likelihood_ratios(blob, y_hat, S, params)
        assert assoc.associate_paper(llr, params)[0] == label


def test_full_measurement_constants_give_the_pair_scores_and_the_gate():
    """-pair_score = m2 / 2 + log(det S_j) / 2 + c, and gated exactly where m2 / 2 <= g: the
    form the compiled tracker step scores pairs in, against the reference functions."""
    rng = np.random.default_rng(9)
    z, y_hat, S = _scene(rng, k=3, n_clutter=20)
    llr, d2 = assoc.log_likelihood_ratios(z, y_hat, S, PARAMS)
    c, g = assoc.full_measurement_constants(PARAMS)
    logdet = np.linalg.slogdet(S)[1]
    np.testing.assert_allclose(
        -assoc.pair_scores(llr, PARAMS), d2 / 2 + logdet / 2 + c, rtol=1e-12, atol=1e-9
    )
    gated = assoc.gate(d2, z, PARAMS)
    assert gated.any() and not gated.all()
    np.testing.assert_array_equal(gated, d2 / 2 <= g)
