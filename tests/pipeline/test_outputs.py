"""poses.csv, truth.csv and summary.json keep the contracts (shared/tools/check_run.py)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.analysis.evaluate import evaluate
from wristtrack.analysis.summary import SummaryAccumulator
from wristtrack.errors import InputError
from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.poses import COLUMNS, PosesWriter, read_poses, rows_to_poses, write_truth
from wristtrack.sim.scenario_run import track_scenario


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A run written the way `wristtrack track` writes it, from the measurement-level tracker."""
    run = track_scenario("reach", seed=3)
    out = tmp_path_factory.mktemp("run")
    summary = SummaryAccumulator()
    with PosesWriter(out / "poses.csv") as writer:
        for r in run.results:
            writer.write_result(r)
            summary.add(r)
    write_json_atomic(out / "summary.json", summary.to_dict())
    write_truth(out / "truth.csv", run.truth)
    return out, run


def test_outputs_pass_the_contract_checker(run_dir, check_run):
    out, _ = run_dir
    proc = subprocess.run(
        [sys.executable, str(check_run), str(out)], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "contracts kept" in proc.stdout


def test_poses_round_trip_against_the_tracker_results(run_dir):
    out, run = run_dir
    cols = read_poses(out / "poses.csv")
    assert list(cols) == list(COLUMNS)
    assert len(cols["frame"]) == len(run.results)
    R, t = rows_to_poses(cols)
    for i, r in enumerate(run.results):
        if r.has_estimate:
            np.testing.assert_allclose(t[i], r.t_ch, atol=1e-9)
            np.testing.assert_allclose(R[i], r.R_ch, atol=1e-7)
        else:
            assert np.isnan(t[i]).all() and cols["status"][i] == str(r.status)
    # quaternions (w, x, y, z), unit, w >= 0, and the same rotation as scipy makes of R_ch
    q = np.column_stack([cols[c] for c in ("qw", "qx", "qy", "qz")])
    ok = np.isfinite(q).all(axis=1)
    assert (q[ok, 0] >= 0).all()
    r_last = [r for r in run.results if r.has_estimate][-1]
    expected = Rotation.from_matrix(r_last.R).as_quat(scalar_first=True)
    expected *= np.sign(expected[0])
    np.testing.assert_allclose(q[ok][-1], expected, atol=1e-8)


def test_truth_evaluates_to_zero_error_against_itself_and_run_matches_its_metrics(run_dir):
    out, run = run_dir
    self_eval = evaluate(out / "truth.csv", out / "truth.csv")
    assert self_eval["position_rmse_mm"] == pytest.approx(0, abs=1e-6)
    assert self_eval["orientation_rmse_deg"] == pytest.approx(0, abs=1e-4)
    assert self_eval["peak_speed_error_pct"] == pytest.approx(0, abs=1e-6)
    result = evaluate(out / "poses.csv", out / "truth.csv")
    assert result["position_rmse_mm"] == pytest.approx(run.errors.position_rmse_mm, rel=1e-5)
    expected_rot = run.errors.orientation_rmse_deg
    assert result["orientation_rmse_deg"] == pytest.approx(expected_rot, rel=1e-4)
    assert abs(result["rom"]["flexion"]["range_error_deg"]) < 2.0
    # net of the run's constant errors (what compare's registration takes up): no larger
    assert 0 < result["position_rmse_net_of_constant_mm"] <= result["position_rmse_mm"]
    assert 0 < result["orientation_rmse_net_of_constant_deg"] <= result["orientation_rmse_deg"]


def test_summary_has_range_of_motion_and_is_plain_json(run_dir):
    out, run = run_dir
    summary = json.loads((out / "summary.json").read_text())
    flex = summary["range_of_motion"]["flexion"]
    truth_flex = np.degrees(run.truth.angles[:, 1])
    assert flex["range_deg"] == pytest.approx(np.ptp(truth_flex), abs=2.0)
    peak = np.linalg.norm(run.truth.v, axis=1).max()
    assert summary["peak_speed_m_s"] == pytest.approx(peak, rel=0.1)
    assert summary["frames"]["total"] == len(run.results)


def test_interrupted_file_with_a_cut_last_line_still_reads(run_dir, tmp_path):
    out, run = run_dir
    text = (out / "poses.csv").read_text()
    cut = tmp_path / "poses.csv"
    cut.write_text(text[: len(text) - 40])  # a kill in the middle of writing the last row
    cols = read_poses(cut)
    assert len(cols["frame"]) == len(run.results) - 1


def test_read_poses_refuses_a_file_that_is_not_poses(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="not a poses.csv"):
        read_poses(bad)
    with pytest.raises(InputError, match="cannot read"):
        read_poses(tmp_path / "missing.csv")


def test_reported_uncertainty_matches_the_actual_errors(run_dir):
    """pos_sigma_mm / rot_sigma_deg are root-trace 1-sigma values: the errors' RMS over the run
    should be of the same size (a consistent filter), not 10x off either way."""
    out, run = run_dir
    cols = read_poses(out / "poses.csv")
    tracking = cols["status"] == "tracking"
    R, t = rows_to_poses(cols)
    pos_err = np.linalg.norm(t[tracking] - run.truth.t_ch[tracking], axis=1) * 1e3
    ratio = np.sqrt(np.mean(pos_err**2) / np.mean(cols["pos_sigma_mm"][tracking] ** 2))
    assert 0.4 < ratio < 2.5, ratio
    rel = np.einsum("nji,njk->nik", R[tracking], run.truth.R_ch[tracking])
    rot_err = np.degrees(Rotation.from_matrix(rel).magnitude())
    ratio = np.sqrt(np.mean(rot_err**2) / np.mean(cols["rot_sigma_deg"][tracking] ** 2))
    assert 0.4 < ratio < 2.5, ratio
