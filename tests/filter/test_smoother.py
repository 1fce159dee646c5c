"""The unscented RTS smoother: FilterPy's RTS smoother as the oracle on a linear model, the
simulator's ground truth on the manifold tracker, and the ``track --smooth`` outputs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from wristtrack.analysis.evaluate import evaluate
from wristtrack.cli import main
from wristtrack.filter import ukf
from wristtrack.filter.smoother import rts_smooth
from wristtrack.io.poses import read_poses
from wristtrack.io.states import STATES_FILE, StateWriter, read_states, truncate_states
from wristtrack.sim.render import render_recording
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking.tracker import TrackerConfig


class _LinearModel(ukf.EuclideanModel):
    """x+ = F x + G n with n ~ N(0, Qn): exact under the unscented transform."""

    def __init__(self, F: np.ndarray, G: np.ndarray, Qn: np.ndarray):
        super().__init__(F.shape[0], lambda X, N, dt: X @ F.T + N @ G.T, noise_dim=G.shape[1])
        self.Qn = Qn

    def process_noise(self, dt: float) -> np.ndarray:
        return self.Qn


def test_linear_model_matches_filterpy_rts_smoother():
    rng = np.random.default_rng(3)
    dt = 0.1
    F = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    G = np.array([[0.5 * dt**2, 0], [dt, 0], [0, 0.5 * dt**2], [0, dt]])
    Qn = np.diag([0.3, 0.7])
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R = F, H, G @ Qn @ G.T, np.eye(2) * 0.05
    kf.x, kf.P = np.zeros(4), np.eye(4)
    zs = np.cumsum(rng.normal(size=(60, 2)), axis=0) * 0.1
    means, covs, _, _ = kf.batch_filter(zs)
    expected_x, expected_P, _, _ = kf.rts_smoother(means, covs)

    xs, Ps = rts_smooth(_LinearModel(F, G, Qn), means, covs, np.arange(60) * dt)

    np.testing.assert_allclose(xs, expected_x, atol=1e-10)
    np.testing.assert_allclose(Ps, expected_P, atol=1e-10)


def test_state_log_round_trip_and_truncation(tmp_path):
    config = TrackerConfig()
    run = track_scenario("flexion", config, seed=0)
    path = tmp_path / STATES_FILE
    D, n = run.results[3].x.size, run.model.dim  # the default's state: 20 with the skin slide
    assert run.results[3].cov.shape == (n, n)
    with StateWriter(path, D, n) as writer:
        for r in run.results[:10]:
            writer.write(r.frame, r.timestamp, r)
        writer.write(10, 99.0, None)
    log = read_states(path)
    assert len(log.frame) == 11
    np.testing.assert_array_equal(log.x[3], run.results[3].x)
    np.testing.assert_array_equal(log.P[3], run.results[3].cov)
    assert log.track_id[10] == -1 and np.isnan(log.x[10]).all()
    truncate_states(path, 4)
    assert len(read_states(path).frame) == 4
    with open(path, "ab") as fh:  # an interrupted write leaves part of a record
        fh.write(b"\0" * 17)
    assert len(read_states(path).frame) == 4


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("smooth") / "rec"
    render_recording(out, "flexion", seed=1, n_frames=60)
    return out


def test_track_smooth_end_to_end(recording, tmp_path, check_run):
    plain, smooth = tmp_path / "plain", tmp_path / "smooth"
    assert main(["track", str(recording), "--out", str(plain), "--no-progress"]) == 0
    assert main(["track", str(recording), "--out", str(smooth), "--smooth", "--no-progress"]) == 0
    # the filtered rows are kept, identical to a run without smoothing
    assert (smooth / "poses_filtered.csv").read_text() == (plain / "poses.csv").read_text()
    assert not (smooth / STATES_FILE).exists()
    truth = recording / "truth.csv"
    before, after = evaluate(plain / "poses.csv", truth), evaluate(smooth / "poses.csv", truth)
    assert after["orientation_rmse_deg"] < before["orientation_rmse_deg"]
    rows = read_poses(smooth / "poses.csv")
    assert len(rows["frame"]) == 60
    assert np.array_equal(rows["status"], read_poses(plain / "poses.csv")["status"])
    import json

    summary = json.loads((smooth / "summary.json").read_text())
    assert summary["settings"]["smoothed"] is True
    flex = summary["range_of_motion"]["flexion"]
    assert flex["max_deg"] == pytest.approx(np.nanmax(rows["flexion_deg"]), abs=1e-6)
    check = subprocess.run(
        [sys.executable, str(check_run), str(smooth)], capture_output=True, text=True
    )
    assert check.returncode == 0, check.stdout + check.stderr
