"""The tracker end to end on simulated detections: accuracy, consistency, states, bad input."""

import numpy as np
import pytest
from scipy.stats import chi2

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InputError
from wristtrack.filter import ukf
from wristtrack.geometry import rotation_distance
from wristtrack.hand import HandLayout
from wristtrack.sim.detections import NoiseModel, acceptance_noise, simulate_detections
from wristtrack.sim.motion import SCENARIOS, neutral_camera_pose, scenario
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import MarkerObservation, MeasurementNoise
from wristtrack.tracking.tracker import Status, Tracker, TrackerConfig


@pytest.fixture(scope="module")
def default_runs():
    return {name: track_scenario(name, TrackerConfig(), seed=1) for name in SCENARIOS}


@pytest.mark.parametrize("name", SCENARIOS)
def test_default_tracker_meets_acceptance_on_every_scenario(default_runs, name):
    run = default_runs[name]
    e = run.errors
    assert e.orientation_rmse_deg <= 1.5, e
    assert e.position_rmse_mm <= 3.0, e
    assert run.labelling["markers_correct"] >= 0.99, run.labelling
    assert run.lost_frames == 0
    assert e.coverage == 1.0
    # the acceptance noise really had clutter, misses and the occlusion in it
    n_clutter = sum(int((f.labels < 0).sum()) for f in run.frames)
    assert n_clutter > 2 * len(run.frames)


def test_velocities_are_estimated_against_truth(default_runs):
    run = default_runs["reach"]
    v = np.stack([r.v for r in run.results])
    w = np.stack([r.w for r in run.results])
    settle = 10  # frames for the rates to converge after initialisation
    v_err = np.linalg.norm(v[settle:] - run.truth.v[settle:], axis=1)
    w_err = np.linalg.norm(w[settle:] - run.truth.w[settle:], axis=1)
    peak = np.linalg.norm(run.truth.v, axis=1).max()
    # filtered (causal) rates: the smoother does better offline
    assert np.sqrt(np.mean(v_err**2)) < 0.1 * peak
    assert np.sqrt(np.mean(w_err**2)) < 0.4  # rad/s, during a 20 degree wrist turn


def test_paper_configuration_runs_and_default_beats_it(default_runs):
    for name in ("deviation", "reach"):
        paper = track_scenario(name, TrackerConfig.paper(), seed=1)
        assert len(paper.results) == len(paper.frames)
        assert any(r.status == Status.TRACKING for r in paper.results)
        for r in paper.results:
            if r.has_estimate:
                assert np.all(np.isfinite(r.t_ch))
        default = default_runs[name].errors
        assert default.orientation_rmse_deg < paper.errors.orientation_rmse_deg
        assert default.position_rmse_mm < paper.errors.position_rmse_mm


def test_jpda_association_also_meets_acceptance():
    run = track_scenario("flexion", TrackerConfig(association="jpda"), seed=2)
    assert run.errors.orientation_rmse_deg <= 1.5
    assert run.errors.position_rmse_mm <= 3.0
    assert run.labelling["markers_correct"] >= 0.99


def test_filter_is_consistent_nees_and_nis_in_chi_square_bands():
    """50 Monte Carlo runs on a model-matched simulation (truth driven by the motion model's
    own noise): the average NEES and NIS stay in their 95% chi-square bands."""
    runs, steps, dt = 50, 40, 1 / 30
    camera, layout = Camera.default(), HandLayout.default()
    R_c0, t_c0 = neutral_camera_pose()
    model = ConstantRateModel()
    # The noise shared between markers whose spread does not depend on the pose (the skin
    # slide); the misregistration's does, through the hand's slope, and is checked against its
    # own Monte Carlo in test_skin_slide.py.
    obs = MarkerObservation(camera, layout.points, R_c0, t_c0, model.pose, use_depth=True,
                            noise=MeasurementNoise(registration_px=0.0))
    rng = np.random.default_rng(7)
    nees = np.zeros((runs, steps))
    nis = np.zeros((runs, steps))
    x0 = ConstantRateModel.initial_state(np.eye(3), np.zeros(3))
    P0 = np.diag(np.repeat([1e-4, 1e-6, 1e-4, 1e-2], 3))
    Q = model.process_noise(dt)
    for r in range(runs):
        states = _model_matched_truth(model, x0, P0, Q, dt, steps, obs, camera, rng)
        x, P = x0.copy(), P0.copy()
        for k, truth in enumerate(states):
            y_true = obs(truth[None])[0]
            # the sensor's noise and the MCP markers' common skin slide
            z = rng.multivariate_normal(y_true, obs.noise_covariance(truth, y_true))
            x, P = ukf.predict(model, x, P, dt, Q)
            pred = ukf.predict_measurement(model, x, P, obs)
            res = ukf.update(model, x, P, pred, z, obs.noise_covariance(x, pred.y))
            x, P = res.x, res.P
            e = model.lift(x, truth[None])[0]
            nees[r, k] = e @ np.linalg.solve(P, e)
            nis[r, k] = res.nis
    for values, dof in ((nees, 12), (nis, 18)):
        lo, hi = chi2.ppf([0.025, 0.975], runs * dof) / runs
        mean = values.mean(axis=0)
        inside = np.mean((mean >= lo) & (mean <= hi))
        assert inside >= 0.9, (dof, lo, hi, mean.round(2))
        # and over all steps together (a much tighter band)
        lo_all, hi_all = chi2.ppf([0.025, 0.975], runs * steps * dof) / (runs * steps)
        assert lo_all <= values.mean() <= hi_all, (dof, values.mean(), lo_all, hi_all)


def _model_matched_truth(model, x0, P0, Q, dt, steps, obs, camera, rng):
    """States driven by the model's own noise; a draw whose hand leaves the field of view (the
    random walk is unbounded) is drawn again, since there is nothing to measure there."""
    while True:
        truth = model.retract(x0, rng.multivariate_normal(np.zeros(12), P0)[None])[0]
        states = []
        for _ in range(steps):
            noise = rng.multivariate_normal(np.zeros(6), Q)[None]
            truth = model.propagate(truth[None], noise, dt)[0]
            states.append(truth)
        pts = obs.marker_points(np.array(states))
        if pts[..., 2].min() > 0.3 and camera.in_image(camera.project(pts)).all():
            return states


def test_irregular_timestamps_use_the_real_dt():
    # "mix" has jittered timing and dropped frames
    run = track_scenario("mix", TrackerConfig(), seed=3)
    assert np.ptp(np.diff(run.truth.t)) > 0.02
    assert run.errors.orientation_rmse_deg <= 1.5
    assert run.lost_frames == 0


def test_lost_when_markers_vanish_and_reinitialised_when_they_return():
    rng = np.random.default_rng(4)
    truth, camera, layout = scenario("deviation", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(p_miss=0.0), rng)
    config = TrackerConfig(lost_after=5)
    tracker = Tracker(camera, layout, config)
    statuses, results = [], []
    gone = range(40, 60)
    for i, f in enumerate(frames):
        det = f.detections
        if i in gone:  # the hand leaves the view: only clutter remains
            det = Detections(det.timestamp, rng.uniform(0, 400, (2, 2)), rng.uniform(0.5, 1, 2))
        res = tracker.step(det)
        statuses.append(res.status)
        results.append(res)
    assert statuses[0] == Status.TRACKING
    assert Status.LOST in statuses[40:60]
    lost = [r for r in results if r.status == Status.LOST]
    assert all(np.isnan(r.t_ch).all() for r in lost)  # no extrapolation once lost
    back = next(i for i in range(60, len(frames)) if statuses[i] == Status.TRACKING)
    assert back - 60 <= 3
    # W0 is the first initialisation's frame: poses after re-initialisation still match truth
    R_c0 = tracker.R_c0
    np.testing.assert_allclose(R_c0, truth.R_ch[0], atol=0.02)
    late = results[back + 10]
    assert np.linalg.norm(late.t_ch - truth.t_ch[back + 10]) < 0.005
    assert np.linalg.norm(late.p - truth.p_rel[back + 10]) < 0.005


def test_timestamps_that_do_not_increase_are_refused():
    rng = np.random.default_rng(5)
    truth, camera, layout = scenario("deviation", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(), rng)
    tracker = Tracker(camera, layout)
    tracker.step(frames[0].detections)
    tracker.step(frames[1].detections)
    with pytest.raises(InputError, match="increasing"):
        tracker.step(frames[1].detections)


def test_estimates_are_finite_and_covariances_positive_definite_whenever_tracking():
    run = track_scenario("mix", TrackerConfig(), seed=6, noise=acceptance_noise(240))
    for r in run.results:
        if r.has_estimate:
            assert np.all(np.isfinite(r.t_ch)) and np.all(np.isfinite(r.R_ch))
            np.testing.assert_allclose(r.cov, r.cov.T)
            assert np.linalg.eigvalsh(r.cov).min() > 0
            q = r.R_ch @ r.R_ch.T
            np.testing.assert_allclose(q, np.eye(3), atol=1e-9)


def test_one_to_one_association_beats_the_paper_rule_with_clutter_beside_the_markers():
    import dataclasses

    n = len(scenario("flexion")[0].t)
    noise = dataclasses.replace(acceptance_noise(n), near_clutter_mean=1.5, near_clutter_px=6.0)
    gnn = track_scenario("flexion", TrackerConfig(association="gnn"), noise=noise, seed=4)
    paper = track_scenario("flexion", TrackerConfig(association="paper"), noise=noise, seed=4)
    assert gnn.labelling["clutter_as_marker"] < 0.5 * paper.labelling["clutter_as_marker"]
    assert gnn.errors.orientation_rmse_deg < paper.errors.orientation_rmse_deg
    assert gnn.labelling["markers_correct"] >= 0.99
    assert gnn.errors.orientation_rmse_deg <= 1.5


def test_frame_result_empty_is_a_result_without_an_estimate():
    from wristtrack.tracking.results import FrameResult

    r = FrameResult.empty(4, 0.5, Status.LOST, 3)
    assert not r.has_estimate and r.cov is None and r.x is None
    assert np.isnan(r.R_ch).all() and np.isnan(r.t_ch).all() and np.isnan(r.w).all()
    assert r.labels.tolist() == [-1, -1, -1] and r.n_clutter == 3 and r.n_visible == 0
    labelled = FrameResult.empty(5, 0.6, Status.INITIALISING, np.array([0, -1]), side="left")
    assert labelled.n_clutter == 1 and labelled.side == "left"


@pytest.mark.parametrize("reacquire", [True, False])
def test_a_prediction_that_left_the_markers_is_fitted_afresh_at_once(reacquire):
    """One frame period later the hand is where it would be 1 s later (frames skipped by a
    camera that kept its clock: a jump no motion model predicts). No blob lies in the gates
    although all six markers are in view: the tracker fits the layout to that frame at once
    instead of coasting on the stale prediction (the paper's way, ``reacquire=False``)."""
    rng = np.random.default_rng(11)
    truth, camera, layout = scenario("flexion", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(p_miss=0.0, clutter_mean=2.0),
                                  rng)
    tracker = Tracker(camera, layout, TrackerConfig(reacquire=reacquire))
    jump, skip = 60, 30
    for f in frames[:jump]:
        tracker.step(f.detections)
    period = truth.t[1] - truth.t[0]
    results = []
    for k in range(jump + skip, jump + skip + 5):
        det = frames[k].detections
        det = Detections(det.timestamp - skip * period, det.uv, det.depth)
        results.append((k, tracker.step(det)))
    k, after = results[0]
    assert (frames[k].labels >= 0).sum() == 6  # all six in view (among clutter)
    assert np.degrees(rotation_distance(truth.R_ch[jump - 1], truth.R_ch[k])) > 30
    if reacquire:
        for k, res in results:
            assert res.status == Status.TRACKING and res.n_visible == 6
            assert np.degrees(rotation_distance(res.R_ch, truth.R_ch[k])) < 2.0
    else:
        # too few markers in the gates: it drifts on the prediction, towards `lost_after`
        assert after.n_visible < TrackerConfig().min_markers
        assert np.degrees(rotation_distance(after.R_ch, truth.R_ch[k])) > 20


def test_a_fresh_start_mid_reach_is_not_dragged_off_by_its_zero_velocity():
    """A live run that dropped frames: initialised at frame 0, lost over a long gap, started
    afresh mid-reach (no velocity yet), next frame 0.2 s later. The prediction lags the hand,
    the association takes 4 markers with an update far beyond its NIS bound, and that pose was
    kept (34 deg off, seen in CI as a live/offline disagreement). The update leaves the
    markers off their blobs, so the frame is fitted afresh."""
    rng = np.random.default_rng(2)
    truth, camera, layout = scenario("reach", rng=rng)
    frames = simulate_detections(truth, camera, layout,
                                 NoiseModel(p_miss=0.0, clutter_mean=1.0), rng)
    for k in (54, 57, 60, 63, 66, 69):
        errors = {}
        for reacquire in (True, False):
            tracker = Tracker(camera, layout, TrackerConfig(reacquire=reacquire))
            for i in (0, k, k + 6):
                res = tracker.step(frames[i].detections)
            errors[reacquire] = np.degrees(rotation_distance(res.R_ch, truth.R_ch[k + 6]))
        assert errors[True] < 2.0
    assert errors[False] > 20  # k = 69: without re-acquisition the wrong update stays
