"""``track --smooth --smooth-noise learned`` tracks the recording again at the angular process
noise its smoothed rates show, and smooths that run (pipeline/refit.py): against the rendered
truth, and its files."""

import json
import subprocess
import sys

import numpy as np
import pytest

from wristtrack.analysis.evaluate import evaluate
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses
from wristtrack.io.run_folder import REFIT_DIR
from wristtrack.pipeline import refit
from wristtrack.pipeline.track import track_recording
from wristtrack.tracking.smoother_noise import FLOOR_FRACTION, rate_noise_density
from wristtrack.tracking.tracker import TrackerConfig

MODEL_Q = TrackerConfig().process.angular_accel
LEARNED = TrackerConfig(smoothing_noise="learned")


@pytest.fixture(scope="module")
def runs(every_effect, tmp_path_factory):
    """The every-effect recording smoothed at the model's noise and at the learned one."""
    out = {}
    for noise in ("model", "learned"):
        folder = tmp_path_factory.mktemp(noise)
        with open_recording(every_effect) as recording:
            track_recording(recording, folder, TrackerConfig(smoothing_noise=noise),
                            progress=False, smooth=True)
        out[noise] = folder
    return out


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


def _rates(poses):
    cols = read_poses(poses)
    w = np.column_stack([cols["wx"], cols["wy"], cols["wz"]])
    return w, cols["timestamp"], np.isin(cols["status"], ("tracking", "coasting"))


def test_the_learned_noise_is_the_first_runs_rate_density_and_the_refit_is_closer_to_the_truth(
        runs, every_effect, check_run):
    """On a slow, smooth rendered movement under every camera effect, the case the option is
    for (tracking/smoother_noise.py)."""
    model, learned = runs["model"], runs["learned"]
    # the first smoothed run is the run at the model's noise (smoothing_noise does not change
    # the tracker): its smoothed rates give the density the refit tracked at
    density = rate_noise_density(*_rates(model / "poses.csv"))
    note = _summary(learned)["smoothing_process_noise"]
    assert note["learned_angular_accel"] == pytest.approx(max(density, FLOOR_FRACTION * MODEL_Q))
    assert note["learned_angular_accel"] < 0.5 * MODEL_Q  # the rendered motion is far calmer
    assert note["refit_kept"] is True
    assert note["angular_accel_used"] == note["learned_angular_accel"]
    # the smoothed poses and the summary are the refit's; the filtered rows stay the filter's
    # at the model's noise, as a run without --smooth gives them
    settings = _summary(learned)["settings"]
    assert settings["process"]["angular_accel"] == note["angular_accel_used"]
    assert settings["smoothing_noise"] == "learned"
    assert "smoothing_process_noise" not in _summary(model)
    assert _summary(model)["settings"]["process"]["angular_accel"] == MODEL_Q
    assert (learned / "poses_filtered.csv").read_bytes() == (
        model / "poses_filtered.csv").read_bytes()
    assert not (learned / REFIT_DIR).exists()
    # closer to the rendered truth, with an estimate in as many frames
    truth = every_effect / "truth.csv"
    before, after = (evaluate(f / "poses.csv", truth) for f in (model, learned))
    assert after["coverage"] >= before["coverage"]
    assert after["orientation_rmse_deg"] < before["orientation_rmse_deg"]
    done = subprocess.run([sys.executable, str(check_run), str(learned)], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_a_refit_with_fewer_estimates_leaves_the_first_run(runs, every_effect, tmp_path,
                                                           monkeypatch):
    monkeypatch.setattr(refit, "keeps_refit", lambda first, again: False)
    out = tmp_path / "run"
    with open_recording(every_effect) as recording:
        summary = track_recording(recording, out, LEARNED, progress=False, smooth=True)
    model = runs["model"]
    for name in ("poses.csv", "poses_filtered.csv"):
        assert (out / name).read_bytes() == (model / name).read_bytes(), name
    note = summary["smoothing_process_noise"]
    assert note["refit_kept"] is False
    assert note["angular_accel_used"] == MODEL_Q
    assert note["learned_angular_accel"] < MODEL_Q
    assert _summary(out) == summary
    assert not (out / REFIT_DIR).exists()


def test_a_run_with_too_few_rates_is_not_tracked_again(rendered, tmp_path):
    rec = rendered("reach", seed=0, n_frames=20)  # 19 increments: too few to learn from
    with open_recording(rec) as recording:
        summary = track_recording(recording, tmp_path / "run", LEARNED, progress=False,
                                  smooth=True)
    note = summary["smoothing_process_noise"]
    assert note["learned_angular_accel"] is None and note["refit_kept"] is False
    assert summary["settings"]["process"]["angular_accel"] == MODEL_Q
