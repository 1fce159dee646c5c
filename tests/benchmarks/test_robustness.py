"""The robustness benchmark's own arithmetic (recall) and one small condition end to end."""

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.accuracy import DEFAULT
from benchmarks.robustness import (
    CONDITIONS,
    SMOOTHED,
    blob_errors,
    blob_table,
    depth_errors,
    depth_table,
    recall,
    robustness,
    robustness_sections,
    summary_lines,
    uncertainty_ratios,
)
from wristtrack.geometry import so3_exp
from wristtrack.sim.realism import EFFECTS, PRESET_REAL


def _res(labels, estimate=True, merged=None):
    return SimpleNamespace(labels=np.array(labels), has_estimate=estimate, merged=merged or {})


def test_recall_counts_rightly_labelled_visible_markers_only():
    uv = np.zeros((2, 6, 2))
    uv[:, :, 0] = np.arange(6) * 20.0  # marker k at (20 k, 0)
    vis = np.ones((2, 6))
    vis[1, 5] = 0.2  # MCP5 mostly hidden in frame 1: not counted as visible
    blobs = SimpleNamespace(uv=uv[0] + 0.5, count=6)
    # Frame 0: six blobs, CMC1/MCP2 swapped (mislabelled: not a use) -> 4 of 6.
    # Frame 1: no estimate -> 0 of 5.
    results = [_res([0, 2, 1, 3, 4, 5]), _res([0, 1, 2, 3, 4, 5], estimate=False)]
    assert recall(results, [blobs, blobs], uv, vis) == pytest.approx(4 / 11)


def test_recall_counts_the_markers_a_merged_blob_stood_for():
    """MCP4 and MCP5 merged into one blob labelled MCP4: on the mean of their centres it was
    used for both; on MCP4's own centre, 10 px from that mean, for neither (the filter took it
    as the mean)."""
    uv = np.zeros((2, 6, 2))
    uv[:, :, 0] = np.arange(6) * 20.0  # marker k at (20 k, 0)
    vis = np.ones((2, 6))
    on_mean = SimpleNamespace(uv=np.vstack((uv[0, :4], uv[0, 4:].mean(axis=0))), count=5)
    on_own = SimpleNamespace(uv=uv[0, :5].copy(), count=5)
    merged = {4: (4, 5)}
    labels = [0, 1, 2, 3, 4]
    assert recall([_res(labels, merged=merged)], [on_mean], uv[:1], vis[:1]) == 1.0
    assert recall([_res(labels, merged=merged)], [on_own], uv[:1], vis[:1]) == pytest.approx(4 / 6)
    assert recall([_res(labels)], [on_own], uv[:1], vis[:1]) == pytest.approx(5 / 6)  # no merge
    assert recall([_res(labels)], [on_mean], uv[:1], vis[:1]) == pytest.approx(4 / 6)


def test_blob_errors_against_hand_built_truth():
    uv = np.zeros((1, 6, 2))
    uv[0, :, 0] = np.arange(6) * 20.0  # marker k at (20 k, 0)
    vis = np.ones((1, 6))
    vis[0, 5] = 0.2  # MCP5 mostly hidden: not counted
    # WRIST 0.3 px off; CMC1 0.4 px off and doubted; MCP2 and MCP3 share one blob between them
    # (10 px from each: beyond 3 px, so neither has a blob); MCP4 1.2 px off; a far clutter blob
    blobs = SimpleNamespace(
        uv=np.array([[0.3, 0.0], [20.0, 0.4], [50.0, 0.0], [80.0, 1.2], [300.0, 0.0]]),
        count=5, suspect=np.array([False, True, False, False, False]))
    m = blob_errors([blobs], uv, vis)
    e = np.array([0.3, 0.4, 1.2])
    assert m["blob_rms"] == pytest.approx(np.sqrt(np.mean(e**2)))
    assert m["blob_rms_undoubted"] == pytest.approx(np.sqrt(np.mean(e[[0, 2]] ** 2)))
    assert m["blob_median"] == pytest.approx(0.4)
    assert m["blob_doubted"] == pytest.approx(1 / 3)
    assert m["blob_found"] == pytest.approx(3 / 5)
    # two overlapping markers 2 px apart share a blob between them: it counts for both
    uv[0, 1] = (2.0, 0.0)
    shared = SimpleNamespace(uv=np.array([[1.0, 0.0]]), count=1, suspect=None)
    m = blob_errors([shared], uv, vis)
    assert m["blob_rms"] == pytest.approx(1.0) and m["blob_found"] == pytest.approx(2 / 5)
    assert m["blob_doubted"] == 0.0
    line = blob_table({"clean": {"default": m}})[-2]
    assert line.startswith("| clean | 1.000 | 1.000 | 1.000 | 0.0% | 40.0% |"), line


def _tilted_hand(n: int = 300):
    """Six markers on a hand 0.65 m away turning about the camera's y axis (0-30 deg and
    back), their image positions (pinhole, fx = fy = 525), camera-frame points and normals."""
    from scipy.spatial.transform import Rotation

    layout = np.array([[0, 0, 0], [0.02, 0.03, 0], [0.07, 0.02, 0], [0.075, 0, 0],
                       [0.07, -0.015, 0], [0.06, -0.03, 0]], float)
    angle = np.radians(30) * np.sin(np.linspace(0, 2 * np.pi, n)) ** 2
    R = Rotation.from_euler("y", angle[:, None]).as_matrix() @ np.diag([1.0, -1.0, -1.0])
    points = np.einsum("nij,kj->nki", R, layout) + [0.0, 0.0, 0.65]
    uv = 525 * points[..., :2] / points[..., 2:] + [320, 240]
    return uv, points, R[:, :, 2], np.arange(n) / 30


def test_depth_errors_against_hand_built_truth():
    """White depth noise: its rms back, inflation 1, no offset. A fixed 2 px offset along u on
    top (the depth read off the blob on the tilted hand, G s by hand: the plane's depth slope
    z^2 n_x / (fx n.p) per px) and a 1 mm constant error of one marker: the offset comes back,
    the constant is taken out with the marker's mean, and the errors left are the noise."""
    from wristtrack.tracking.observation import registration_depth_jacobian

    rng = np.random.default_rng(0)
    uv, points, normals, t = _tilted_hand()
    vis = np.ones(uv.shape[:2])
    noise = rng.normal(0, 0.001, uv.shape[:2])

    def blobs(depth):
        return [SimpleNamespace(uv=uv[k] + 0.2, count=6, depth=depth[k]) for k in range(len(t))]

    m = depth_errors(blobs(points[..., 2] + noise), uv, vis, points, normals, t, 525.0, 525.0)
    assert m["depth_rms"] == pytest.approx(1.0, rel=0.1)
    assert m["depth_inflation"] == pytest.approx(1.0, abs=0.3)
    assert m["depth_offset"] < 0.4  # 30 draws of this noise: median 0.06 px, largest 0.22
    slope = np.stack([registration_depth_jacobian(points[k], normals[k], 1.0, 525.0, 525.0)
                      for k in range(len(t))])
    by_hand = (points[..., 2] ** 2 * -normals[:, None, 0]
               / (525.0 * np.einsum("nkj,nj->nk", points, normals)))
    np.testing.assert_allclose(slope[..., 0], by_hand)
    shifted = points[..., 2] + noise + 2.0 * slope[..., 0]
    shifted[:, 3] += 0.001
    m = depth_errors(blobs(shifted), uv, vis, points, normals, t, 525.0, 525.0)
    assert m["depth_offset"] == pytest.approx(2.0, abs=0.4)
    assert m["depth_inflation"] > 3  # the offset's error follows the slow turn
    assert m["depth_rms_offset"] == pytest.approx(1.0, rel=0.1)
    assert m["depth_inflation_offset"] == pytest.approx(1.0, abs=0.3)
    line = depth_table({"structured_light": {"default": m}})[-2]
    assert line.startswith("| structured_light | ") and line.count("|") == 7, line
    assert depth_errors(blobs(np.full(uv.shape[:2], np.nan)), uv, vis, points, normals, t,
                        525.0, 525.0) == {}


def test_uncertainty_ratios_against_hand_derived_errors():
    """Every frame 1 deg and 3 mm off, reported at 2 deg and 1 mm: 0.5 (conservative) and 3
    (overconfident); frames without an estimate or a sigma do not count."""
    n = 5
    true_R = np.stack([so3_exp(np.array([0.1 * k, 0.2, 0.0])) for k in range(n)])
    true_t = np.tile([0.0, 0.0, 0.6], (n, 1))
    truth = SimpleNamespace(R_ch=true_R, t_ch=true_t)
    off = so3_exp(np.radians([0.0, 0.0, 1.0]))
    results = [SimpleNamespace(R_ch=true_R[k] @ off, t_ch=true_t[k] + [0.003, 0.0, 0.0],
                               rot_sigma_deg=2.0, pos_sigma_mm=1.0) for k in range(n)]
    results[1] = SimpleNamespace(R_ch=np.full((3, 3), np.nan), t_ch=np.full(3, np.nan),
                                 rot_sigma_deg=np.nan, pos_sigma_mm=np.nan)
    results[2] = SimpleNamespace(R_ch=true_R[2] @ off, t_ch=true_t[2] + 1.0,  # no sigma
                                 rot_sigma_deg=np.nan, pos_sigma_mm=np.nan)
    z = uncertainty_ratios(results, truth)
    assert z["rot_z"] == pytest.approx(0.5, rel=1e-9)
    assert z["pos_z"] == pytest.approx(3.0, rel=1e-9)
    none = uncertainty_ratios(results[1:2], truth)
    assert np.isnan(none["rot_z"]) and np.isnan(none["pos_z"])


def test_every_effect_has_a_condition_and_the_combined_ones_exist():
    alone = {tuple(c.get("effects", ())) for c in CONDITIONS.values()}
    for e in EFFECTS:
        if e != "left_hand":
            assert (e,) in alone
    assert CONDITIONS["left hand"] == {"hand_side": "left"}
    assert CONDITIONS["all (preset real)"]["effects"] == list(PRESET_REAL)


def test_one_condition_end_to_end(tmp_path):
    acc = robustness(tmp_path, n_frames=15, conditions=("clean",), trackers={"default": DEFAULT})
    m = acc["clean"]["default"]
    assert m["cover"] == 1.0 and m["recall"] == 1.0  # a still start, every marker in view
    assert m["rot"] < 1.5 and m["pos"] < 3.0
    lines = robustness_sections(tmp_path, n_frames=15, conditions=("clean",),
                                trackers={"default": DEFAULT})
    assert any(line.startswith("| clean | default |") for line in lines)
    # the reported uncertainty against the errors, filtered (no smoothed row for one effect)
    assert np.isfinite(m["rot_z"]) and np.isfinite(m["pos_z"])
    assert f"| clean | {m['rot_z']:.2f} | n/a | {m['pos_z']:.2f} | n/a |" in lines
    # the detector's own table: sharp blobs, every marker found
    assert m["blob_found"] == 1.0 and m["blob_rms"] < 0.1
    assert any(line.startswith("| clean | 0.0") for line in lines)


def test_summary_names_only_the_targets_a_combined_condition_misses():
    m = {"rot": 0.8, "pos": 1.3, "rom": 1.2, "recall": 0.999, "cover": 1.0, "wrong_side": 0.0}
    acc = {
        "clean": {"default": {**m, "rot": 0.4}},
        "all (preset real)": {"default": m, SMOOTHED: {**m, "rom": 0.5}},
        "all, left hand": {"default": {**m, "rom": 0.9}, SMOOTHED: {**m, "rom": 0.8}},
    }
    lines = summary_lines(acc)
    real = next(line for line in lines if line.startswith("- all (preset real)"))
    assert real.endswith("misses RoM <= 1.0 deg.") and "(smoothed 0.50)" in real
    left = next(line for line in lines if line.startswith("- all, left hand"))
    assert left.endswith("misses smoothed RoM <= 0.7 deg.")
    acc["all, left hand"][SMOOTHED]["rom"] = 0.6
    assert summary_lines(acc)[2].endswith("meets every target.")
