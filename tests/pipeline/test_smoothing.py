"""``track --smooth`` on a written run: the smoothed rows against the truth and against the
smoother run on the tracker's own results."""

import numpy as np

from wristtrack.geometry import rotation_distance
from wristtrack.io.poses import PosesWriter, read_poses, rows_to_poses
from wristtrack.io.states import STATES_FILE, StateWriter
from wristtrack.pipeline.smoothing import smooth_run
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.tracking.smoothed_results import smooth_results
from wristtrack.tracking.tracker import Tracker, TrackerConfig


def test_the_smoothed_still_start_keeps_its_own_camera_poses(tmp_path):
    """A still start under structured-light depth noise ends with W0 refined by ~4 deg
    (seed 0); its rows were written before that. Smoothed from the files, they are as close to
    the true poses as the rows after it (rebuilt with the final W0 they were off by that
    correction), and every row equals the smoother run on the tracker's results in memory."""
    truth, camera, layout = scenario("flexion", rng=0)
    noise = NoiseModel(depth_sigma_coeff=4e-3, clutter_mean=0.0)
    frames = simulate_detections(truth, camera, layout, noise, np.random.default_rng(0))[:45]
    tracker = Tracker(camera, layout, TrackerConfig())
    model = tracker.model
    states = StateWriter(tmp_path / STATES_FILE, model.initial_state(np.eye(3), np.zeros(3)).size,
                         model.dim)
    with PosesWriter(tmp_path / "poses.csv") as poses:
        results = []
        for f in frames:
            r = tracker.step(f.detections)
            results.append(r)
            poses.write_result(r)
            states.write(r.frame, r.timestamp, r)
    states.close()
    end = [r.track_id for r in results].index(1)  # the still start's last row is end - 1

    smooth_run(tmp_path, tracker.model)
    R, t = rows_to_poses(read_poses(tmp_path / "poses.csv"))
    ok = np.isfinite(t).all(axis=1)
    err = np.degrees(rotation_distance(R[ok], truth.R_ch[: len(frames)][ok]))
    still = ok[:end].sum()
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert still >= 10 and rms(err[:still]) < 2 * rms(err[still:]), err.round(2)

    memory = smooth_results(tracker.model, [r for r in results if r.x is not None])
    R_mem = np.stack([r.R_ch for r in memory])
    t_mem = np.stack([r.t_ch for r in memory])
    np.testing.assert_allclose(R[ok], R_mem, atol=1e-6)
    np.testing.assert_allclose(t[ok], t_mem, atol=1e-8)


def test_predictions_not_reported_are_smoothed_from_the_files_as_in_memory(tmp_path,
                                                                             hidden_markers):
    """A third of a second without blobs (tests/tracking/test_coasting.py): the state log keeps
    the predictions the filter did not report, so ``track --smooth`` carries the track across
    and reports the gap's ends as the smoother in memory does, row for row."""
    config, (start, end) = TrackerConfig(), hidden_markers.hidden
    truth, results, tracker = hidden_markers.run(config)
    model = tracker.model
    states = StateWriter(tmp_path / STATES_FILE, model.initial_state(np.eye(3), np.zeros(3)).size,
                         model.dim)
    with PosesWriter(tmp_path / "poses.csv") as poses:
        for r in results:
            poses.write_result(r)
            states.write(r.frame, r.timestamp, r)
    states.close()
    smooth_run(tmp_path, model, config.ukf, coast_limit=config.coast_limit)
    rows = read_poses(tmp_path / "poses.csv")
    memory = smooth_results(model, results, config.ukf, config.coast_limit)
    status = [str(s.status) for s in memory]
    assert list(rows["status"]) == status
    gap = rows["status"][start:end]
    assert "coasting" in gap and "lost" in gap
    R, t = rows_to_poses(rows)
    shown = np.isfinite(t).all(axis=1)
    np.testing.assert_allclose(t[shown], np.stack([s.t_ch for s in memory])[shown], atol=1e-8)
