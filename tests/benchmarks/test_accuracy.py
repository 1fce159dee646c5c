"""The benchmark's scoring and table plumbing, with trackers whose answers are known."""

from __future__ import annotations

import numpy as np

from benchmarks.accuracy import DEFAULT, bound, score, sim_case, summary_lines
from wristtrack.sim.motion import Trajectory
from wristtrack.tracking.tracker import FrameResult, Status

NAN3 = np.full(3, np.nan)


def _results(truth: Trajectory, rot_err_deg: float = 0.0, every: int = 1) -> list[FrameResult]:
    """Results at the true poses, turned by rot_err_deg about camera z; only every n-th frame
    has an estimate."""
    a = np.radians(rot_err_deg)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    out = []
    for k in range(len(truth)):
        if k % every:
            out.append(FrameResult.empty(k, truth.t[k], Status.LOST))
            continue
        R_ch = Rz @ truth.R_ch[k]
        R_rel = truth.R_ch[0].T @ R_ch
        out.append(FrameResult(
            frame=k, timestamp=truth.t[k], status=Status.TRACKING, R_ch=R_ch, t_ch=truth.t_ch[k],
            R=R_rel, p=truth.p_rel[k], v=NAN3, w=NAN3, cov=None, labels=np.zeros(0, int),
            n_visible=6, n_clutter=0))
    return out


def test_score_against_known_errors():
    case = sim_case("flexion", 0)
    perfect = score(_results(case.truth), case.truth)
    assert perfect["rot"] < 1e-6 and perfect["pos"] < 1e-9 and perfect["cover"] == 1.0
    assert perfect["rom"] < 1e-6
    off = score(_results(case.truth, rot_err_deg=3.0, every=2), case.truth)
    assert abs(off["rot"] - 3.0) < 1e-9
    assert abs(off["cover"] - 0.5) < 0.01 and off["fail"] == 0.0


def test_bound_uses_the_detected_markers_of_each_frame():
    case = sim_case("deviation", 1)
    cov = bound(case, 30)
    seen = np.array([(f.labels >= 0).sum() for f in case.frames[:30]])
    std = np.sqrt(np.trace(cov[:, :3, :3], axis1=1, axis2=2))
    # fewer markers, less information: on average frames with all six are better bounded
    assert (seen < 6).any() and (seen == 6).any()
    assert std[seen == 6].mean() < std[seen < 6].mean()
    assert np.isfinite(cov[seen >= 3]).all()
    pixels_only = bound(case, 30, depth=False)
    assert (np.trace(pixels_only[:, :3, :3], axis1=1, axis2=2)
            > np.trace(cov[:, :3, :3], axis1=1, axis2=2)).all()


def test_summary_names_where_the_default_trails():
    row = {"rot": 1.0, "pos": 1.0, "rom": 0, "fail": 0, "cover": 1, "rot95": 1}
    acc = {
        "a": {DEFAULT: row, "peer": {**row, "rot": 0.5, "pos": 2.0}},
        "b": {DEFAULT: row, "peer": {**row, "rot": 1.005, "pos": 3.0}},
        "c": {DEFAULT: row, "peer": {**row, "rot": 4.0, "pos": 3.0}},
    }
    bounds = {"a": (1, 1, 1, 1, 1.0, 1.0, 0.9, 0.9)}
    text = "\n".join(summary_lines({"accuracy": acc, "bounds": bounds, "ours": [DEFAULT]}))
    assert "**not met**" in text
    assert "vs peer: ahead on 1, tied (within 1%) on 1, behind on 1 of 3" in text
    assert "worst: a, orientation 1.000 vs 0.500 deg" in text
    acc["a"]["peer"]["rot"] = 2.0
    acc["b"]["peer"]["rot"] = 2.5
    text = "\n".join(summary_lines({"accuracy": acc, "bounds": bounds, "ours": [DEFAULT]}))
    assert "every scenario, met" in text and "ahead of peer on all 3" in text
    assert "at least 2.00x ours" in text and "0.90-0.90x" in text
