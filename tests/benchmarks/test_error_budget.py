"""The error budget's corrections against hand-built truth, and the model-drawn blobs' noise."""

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.error_budget import OBLIQUE_EXACT, corrected, model_drawn
from wristtrack.depth_noise import depth_sigma_nguyen
from wristtrack.detect.detections import Detections

# Six markers on a flat hand 0.6 m in front of a pinhole camera (f 500 px, centre 320 px). The
# back of the hand faces the camera where its Z axis points at it (facing cosine -(p.n)/|p| ~ 1);
# TILTED turns it 60 deg away (cosine ~ 0.5).
LAYOUT = SimpleNamespace(points=np.array(
    [[0.0, 0.0, 0.0], [0.03, 0.02, 0.0], [0.02, 0.07, 0.0], [0.0, 0.075, 0.0],
     [-0.02, 0.07, 0.0], [-0.029, 0.07, 0.0]]))  # MCP4 and MCP5 overlap: 7.5 px apart
FACING = np.diag([1.0, -1.0, -1.0])
F = 500.0
TILTED = np.array([[1.0, 0.0, 0.0], [0.0, 0.5, -np.sqrt(0.75)], [0.0, np.sqrt(0.75), 0.5]])
TILTED = FACING @ TILTED


def _truth(rotations):
    n = len(rotations)
    return SimpleNamespace(R_ch=np.stack(rotations), t_ch=np.tile([0.0, 0.0, 0.6], (n, 1)))


def _true_uv(truth, layout=LAYOUT):
    pts = np.einsum("fij,mj->fmi", truth.R_ch, layout.points) + truth.t_ch[:, None, :]
    return F * pts[..., :2] / pts[..., 2:] + 320.0, pts[..., 2]


def test_exact_pixels_and_depth_put_each_blob_on_its_marker_and_merged_blobs_on_the_mean():
    truth = _truth([FACING])
    uv, z = _true_uv(truth)
    blobs = uv[0].copy()
    blobs[:3] += [[0.4, -0.3], [0.2, 0.5], [-0.6, 0.1]]  # detector error
    blobs = np.vstack([blobs[:4], (uv[0, 4] + uv[0, 5]) / 2 + 0.3, [10.0, 10.0]])  # 4+5 merged
    det = Detections(0.0, blobs, z[0, [0, 1, 2, 3, 4, 0]] + 0.002)
    (out,) = corrected([det], truth, LAYOUT, uv, "pixels and depth exact",
                       np.random.default_rng(0), F)
    np.testing.assert_allclose(out.uv[:4], uv[0, :4])
    np.testing.assert_allclose(out.uv[4], (uv[0, 4] + uv[0, 5]) / 2)
    np.testing.assert_allclose(out.uv[5], [10.0, 10.0])  # clutter untouched
    np.testing.assert_allclose(out.depth[:4], z[0, :4])
    assert out.depth[4] == pytest.approx((z[0, 4] + z[0, 5]) / 2)
    assert out.depth[5] == pytest.approx(z[0, 0] + 0.002)
    (same,) = corrected([det], truth, LAYOUT, uv, "as detected", np.random.default_rng(0), F)
    assert same is det


def test_a_blob_three_lined_up_markers_share_is_made_their_mean():
    """Three knuckles lined up (10 px discs, 7.5 and 5 px apart) in one blob at their mean: the
    outer two are more than a radius from it, and all three are the blob."""
    layout = SimpleNamespace(points=LAYOUT.points.copy())
    layout.points[3] = [-0.011, 0.07, 0.0]
    layout.points[5] = [-0.026, 0.07, 0.0]
    truth = _truth([FACING])
    uv, z = _true_uv(truth, layout)
    mean = uv[0, 3:].mean(axis=0)
    radius = F * 0.006 / 0.6
    assert min(np.linalg.norm(uv[0, [3, 5]] - mean, axis=1)) > radius
    det = Detections(0.0, np.vstack([uv[0, :3], mean + [0.4, -0.2]]), z[0, :4] + 0.003)
    (out,) = corrected([det], truth, layout, uv, "pixels and depth exact",
                       np.random.default_rng(0), F)
    np.testing.assert_allclose(out.uv[3], mean)
    assert out.depth[3] == pytest.approx(z[0, 3:].mean())


def test_exact_pixels_where_the_hand_turns_away_leaves_the_facing_frames_alone():
    truth = _truth([FACING, TILTED])
    uv, z = _true_uv(truth)
    dets = [Detections(float(k), uv[k] + 0.5, z[k]) for k in range(2)]
    facing, turned = corrected(dets, truth, LAYOUT, uv, OBLIQUE_EXACT, np.random.default_rng(0),
                               F)
    np.testing.assert_allclose(facing.uv, uv[0] + 0.5)
    np.testing.assert_allclose(turned.uv, uv[1])


def test_depth_drawn_from_the_model_has_the_models_sigma():
    truth = _truth([FACING] * 400)
    uv, z = _true_uv(truth)
    dets = [Detections(float(k), uv[k], z[k] + 0.01) for k in range(400)]
    out = corrected(dets, truth, LAYOUT, uv, "depth drawn from the model",
                    np.random.default_rng(1), F)
    err = np.array([d.depth for d in out]) - z
    sigma = depth_sigma_nguyen(z)
    assert abs(err.mean()) < 3 * sigma.mean() / np.sqrt(err.size)  # the offset is gone
    assert np.std(err / sigma) == pytest.approx(1.0, abs=0.05)


def test_model_drawn_blobs_sit_on_the_seen_markers_with_the_stated_noise():
    truth = _truth([FACING] * 300)
    uv, z = _true_uv(truth)
    vis = np.ones((300, 6))
    vis[:, 5] = 0.3  # MCP5 mostly hidden: no blob
    dets = [Detections(float(k), np.zeros((0, 2)), np.zeros(0)) for k in range(300)]
    out = model_drawn(dets, truth, LAYOUT, uv, vis, np.random.default_rng(2))
    assert all(d.count == 5 and d.suspect is None and d.depth_image is None for d in out)
    err = np.stack([d.uv for d in out]) - uv[:, :5]
    assert np.std(err) == pytest.approx(0.015, rel=0.05)
    zerr = (np.stack([d.depth for d in out]) - z[:, :5]) / depth_sigma_nguyen(z[:, :5])
    assert np.std(zerr) == pytest.approx(1.0, abs=0.05)


def test_model_drawn_depth_on_a_hand_turned_edge_on_has_nguyens_oblique_sigma():
    """Turned 75 deg about its X axis: sigma = Nguyen's facing sigma + 1e-4 theta^2 /
    (sqrt(z) (pi/2 - theta)^2), theta each marker's angle to its line of sight (worked out
    here, 2-3x the facing sigma)."""
    c, s_ = np.cos(np.radians(75.0)), np.sin(np.radians(75.0))
    turned = FACING @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s_], [0.0, s_, c]])
    truth = _truth([turned] * 300)
    uv, z = _true_uv(truth)
    dets = [Detections(float(k), np.zeros((0, 2)), np.zeros(0)) for k in range(300)]
    out = model_drawn(dets, truth, LAYOUT, uv, np.ones((300, 6)), np.random.default_rng(3))
    pts = np.einsum("ij,mj->mi", turned, LAYOUT.points) + [0.0, 0.0, 0.6]
    theta = np.arccos(-(pts @ turned[:, 2]) / np.linalg.norm(pts, axis=1))
    assert np.all(theta > np.radians(60.0))
    sigma = depth_sigma_nguyen(z[0]) + 1e-4 * theta**2 / (np.sqrt(z[0]) * (np.pi / 2 - theta) ** 2)
    assert np.all(sigma > 2.0 * depth_sigma_nguyen(z[0]))
    zerr = (np.stack([d.depth for d in out]) - z) / sigma
    assert np.std(zerr) == pytest.approx(1.0, abs=0.05)
